//! `mole up`: start the stack, supervise it, wait for the end, and complete the summary.

use crate::RestartWhen;
use crate::hot_swap::{SwapEnv, SwapError, SwapReport, check_swappable, hot_swap};
use crate::stats::StatsCollector;
use crate::supervisor::EXIT_BAD_INPUT;
use crate::{
    ChildSpec, DEFAULT_LAUNCH_FILE, ExitStatus, LaunchFile, Mode, StackOverrides, Supervisor,
    SupervisorEvent, apply_swaps, load_launch_file, parse_swap, resolve_program, start_order,
    stop_order,
};
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use mole_runtime::{ClockMode, CommonArgs, Context, cleanup_dead_nodes, live_nodes_in_namespace};
use mole_types::{
    CONTROL_FAILED, CONTROL_OK, CONTROL_REFUSED, CONTROL_STATUS, CONTROL_STOP, ControlRequest,
    Stats, read_name, topics, write_name,
};
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// How long a process may take to announce that its ports exist.
const READY_TIMEOUT: Duration = Duration::from_secs(20);
/// How long the monitor may take to write its files once the world has finished.
const FINISH_TIMEOUT: Duration = Duration::from_secs(30);
/// A ready process that publishes no statistics for this long is hung: alive but not serving.
const HANG_TIMEOUT: Duration = Duration::from_secs(5);
/// Lockstep: no new step for this long, every process alive, is a stall the run cannot leave by
/// itself (the world resends a step every second, a hung process is restarted after
/// `HANG_TIMEOUT`); the run ends instead of waiting forever.
const STALL_TIMEOUT: Duration = Duration::from_secs(15);
/// The launcher's wake-up period (supervision and progress).
const POLL: Duration = Duration::from_millis(50);

#[derive(Debug, Clone, Args)]
pub struct UpArgs {
    /// Launch file (default: launch/stacks/default.toml).
    pub launch: Option<PathBuf>,
    /// Scenario file, instead of the launch file's.
    #[arg(long)]
    pub scenario: Option<PathBuf>,
    /// Planner, instead of the launch file's.
    #[arg(long)]
    pub planner: Option<String>,
    /// Estimator, instead of the launch file's.
    #[arg(long)]
    pub estimator: Option<String>,
    /// Clock mode: realtime or lockstep.
    #[arg(long)]
    pub mode: Option<Mode>,
    /// Steps to run.
    #[arg(long, conflicts_with = "duration")]
    pub ticks: Option<u64>,
    /// Simulated seconds to run.
    #[arg(long)]
    pub duration: Option<f64>,
    /// Goal X,Y (m) for the goal-seeking planners (apf, dwa), instead of the scenario's.
    #[arg(long, value_name = "X,Y", value_parser = mole_runtime::parse_point)]
    pub goal: Option<(f64, f64)>,
    /// Local planner that follows frontier paths: dwa or apf.
    #[arg(long, value_name = "dwa|apf")]
    pub local_planner: Option<String>,
    /// Seed for every random number of the run.
    #[arg(long)]
    pub seed: Option<u64>,
    /// Namespace: services are mole/<namespace>/<topic>.
    #[arg(long, default_value = "robot0")]
    pub namespace: String,
    /// Output directory for summary.json, map.png and the process logs.
    #[arg(long, default_value = "runs/latest")]
    pub out: PathBuf,
    /// Run another executable in a role's place: ROLE=COMMAND (repeatable).
    #[arg(long = "swap", value_name = "ROLE=COMMAND")]
    pub swaps: Vec<String>,
    /// No progress bar (logs only).
    #[arg(long)]
    pub quiet: bool,
}

/// A failure of `mole up`, with the exit code it deserves.
pub struct Failure {
    pub code: u8,
    pub message: String,
}

impl Failure {
    pub fn input(message: impl Into<String>) -> Self {
        Self {
            code: 2,
            message: message.into(),
        }
    }
    pub fn run(message: impl Into<String>) -> Self {
        Self {
            code: 1,
            message: message.into(),
        }
    }
}

/// When started through `cargo run`, builds every process binary too (cargo builds only the
/// package it runs), so `mole` never starts a stale or missing process.
fn build_process_binaries() -> Result<(), Failure> {
    let (Some(cargo), Ok(exe)) = (std::env::var_os("CARGO"), std::env::current_exe()) else {
        return Ok(());
    };
    let Some(manifest_dir) = std::env::var_os("CARGO_MANIFEST_DIR") else {
        return Ok(());
    };
    let profile = exe
        .parent()
        .and_then(|d| d.file_name())
        .and_then(|n| n.to_str())
        .unwrap_or("debug");
    let mut command = std::process::Command::new(cargo);
    command
        .current_dir(manifest_dir)
        .args(["build", "--workspace", "--bins", "--quiet"]);
    if profile != "debug" {
        command.args([
            "--profile",
            if profile == "release" {
                "release"
            } else {
                profile
            },
        ]);
    }
    tracing::info!("building the process binaries ({profile})");
    let status = command
        .status()
        .map_err(|e| Failure::run(format!("cannot run cargo: {e}")))?;
    if status.success() {
        Ok(())
    } else {
        Err(Failure::run(
            "building the process binaries failed (see cargo's output above)",
        ))
    }
}

fn default_launch_file() -> PathBuf {
    let relative = Path::new(DEFAULT_LAUNCH_FILE);
    if relative.exists() {
        return relative.to_path_buf();
    }
    Path::new(env!("CARGO_MANIFEST_DIR")).join("stacks/default.toml")
}

/// What a run leaves besides its files.
pub struct RunOutcome {
    /// summary.json of the run.
    pub summary_path: PathBuf,
    /// What the processes reported on stack/stats.
    pub stats: StatsCollector,
}

/// Runs the stack to its end (or Ctrl-C); the summary is in `args.out`.
pub fn up(args: &UpArgs) -> Result<RunOutcome, Failure> {
    let launch_path = args.launch.clone().unwrap_or_else(default_launch_file);
    let mut launch = load_launch_file(&launch_path).map_err(|e| Failure::input(e.to_string()))?;
    if let Some(d) = args.duration
        && !(d.is_finite() && d > 0.0)
    {
        return Err(Failure::input(format!(
            "--duration: expected a positive number of seconds, found {d}"
        )));
    }
    StackOverrides {
        scenario: args.scenario.clone(),
        planner: args.planner.clone(),
        estimator: args.estimator.clone(),
        mode: args.mode,
        ticks: args.ticks,
        duration_s: args.duration,
        ..StackOverrides::default()
    }
    .apply(&mut launch.stack);
    let swaps = args
        .swaps
        .iter()
        .map(|s| parse_swap(s))
        .collect::<Result<Vec<_>, _>>()
        .map_err(|e| Failure::input(e.to_string()))?;
    apply_swaps(&mut launch, &swaps).map_err(|e| Failure::input(e.to_string()))?;
    let scenario_path = match (&args.scenario, &launch.stack.scenario) {
        // A path given on the command line is taken as the user typed it.
        (Some(path), _) => path.clone(),
        (None, Some(path)) => launch
            .resolve_path("scenario", path)
            .map_err(|e| Failure::input(e.to_string()))?,
        (None, None) => {
            return Err(Failure::input(format!(
                "{}: no scenario: set `stack.scenario` or pass --scenario",
                launch.path.display()
            )));
        }
    };
    let scenario =
        mole_world::load_scenario(&scenario_path).map_err(|e| Failure::input(e.to_string()))?;
    // No length at all: run until Ctrl-C.
    let ticks = match (launch.stack.ticks, launch.stack.duration_s) {
        (Some(ticks), _) => ticks,
        (None, Some(d)) => (d / scenario.dt).round().max(1.0) as u64,
        (None, None) => u64::MAX,
    };
    let mode: ClockMode = launch
        .stack
        .mode
        .as_str()
        .parse()
        .map_err(|e: mole_types::UnknownChoice| Failure::input(e.to_string()))?;
    let seed = args.seed.unwrap_or(launch.stack.seed);

    let live: Vec<String> = live_nodes_in_namespace(&args.namespace)
        .into_iter()
        .filter(|n| !n.ends_with(&format!("/{}", crate::top::TOP_ROLE)))
        .collect();
    if !live.is_empty() {
        return Err(Failure::input(format!(
            "namespace `{}` is in use by {} live process(es) ({}); stop that stack or choose another --namespace",
            args.namespace,
            live.len(),
            live.join(", ")
        )));
    }
    build_process_binaries()?;
    let beside = std::env::current_exe()
        .ok()
        .and_then(|p| p.parent().map(Path::to_path_buf))
        .unwrap_or_default();
    let mut programs = BTreeMap::new();
    for process in &launch.processes {
        let program = resolve_program(&process.command, &beside)
            .map_err(|e| Failure::input(e.to_string()))?;
        programs.insert(process.role.clone(), program);
    }
    prepare_out_dir(&args.out)?;

    let interrupted = Arc::new(AtomicBool::new(false));
    let flag = interrupted.clone();
    ctrlc::set_handler(move || flag.store(true, Ordering::SeqCst))
        .map_err(|e| Failure::run(format!("cannot install the Ctrl-C handler: {e}")))?;
    let common = CommonArgs {
        namespace: args.namespace.clone(),
        mode,
        rate_hz: launch.stack.rate_hz,
        seed: Some(seed),
    };
    let ctx = Context::with_shutdown_flag("launcher", &common, interrupted.clone())
        .map_err(|e| Failure::run(e.to_string()))?;
    let mut stats_sub = ctx
        .subscriber(topics::STACK_STATS)
        .map_err(|e| Failure::run(e.to_string()))?;
    let mut status_sub = ctx
        .subscriber(topics::MONITOR_STATUS)
        .map_err(|e| Failure::run(e.to_string()))?;
    let mut processes_pub = ctx
        .publisher(topics::STACK_PROCESSES)
        .map_err(|e| Failure::run(e.to_string()))?;
    let mut control = ctx
        .control_server()
        .map_err(|e| Failure::run(e.to_string()))?;
    let mut swaps: Vec<serde_json::Value> = Vec::new();
    let mut collector = StatsCollector::default();
    let mut gave_up: BTreeSet<String> = BTreeSet::new();
    let mut last_report = Instant::now();
    let mut last_heard: BTreeMap<String, Instant> = BTreeMap::new();
    let mut hangs: BTreeMap<String, u32> = BTreeMap::new();

    let env = child_env(args, &launch, &scenario_path, ticks, seed);
    let order = start_order(&launch.processes).map_err(|e| Failure::input(e.to_string()))?;
    let mut supervisor = Supervisor::new();
    let mut ready = BTreeSet::new();
    let started = Instant::now();
    tracing::info!(namespace = %args.namespace, %mode, ticks, seed, "starting the stack");
    for &index in &order {
        let process = &launch.processes[index];
        for dependency in &process.depends_on {
            wait_ready(
                dependency,
                &mut ready,
                &mut stats_sub,
                &mut supervisor,
                &interrupted,
            )?;
        }
        let mut child_env = env.clone();
        child_env.extend(process.env.iter().map(|(k, v)| (k.clone(), v.clone())));
        let log_path = args.out.join("logs").join(format!("{}.log", process.role));
        let mut spec = ChildSpec::from_process(process, programs[&process.role].clone(), log_path);
        spec.env = child_env;
        supervisor
            .spawn(spec)
            .map_err(|e| Failure::run(e.to_string()))?;
    }

    let progress = progress_bar(ticks, args.quiet);
    let mut exit_reason = None;
    let mut world_done_at: Option<Instant> = None;
    let mut failure = None;
    // The newest step the monitor reported, and when it came.
    let mut last_step: (u64, Instant) = (0, Instant::now());
    while exit_reason.is_none() {
        std::thread::sleep(POLL);
        stats_sub.drain(|s| record_stats(s, &mut last_heard, &mut ready, &mut collector));
        if let Some(call) = control.receive() {
            let request = *call.request();
            match request.op {
                CONTROL_STOP => {
                    progress.suspend(|| tracing::info!("stop requested through stack/control"));
                    exit_reason = Some(Some("stopped"));
                    call.respond(|r| {
                        write_name(
                            &mut r.text,
                            &format!("stopping the stack in namespace `{}`", args.namespace),
                        );
                    });
                }
                CONTROL_STATUS => {
                    let tick = status_sub.latest().map_or(0, |s| s.header.tick);
                    let line = status_line(&launch, &supervisor, mode, tick, ticks);
                    call.respond(|r| write_name(&mut r.text, &line));
                }
                _ => {
                    let mut on_stats =
                        |s: &Stats| record_stats(s, &mut last_heard, &mut ready, &mut collector);
                    let result =
                        swap_spec(&launch, &supervisor, &request, &beside).and_then(|spec| {
                            hot_swap(
                                SwapEnv {
                                    ctx: &ctx,
                                    supervisor: &mut supervisor,
                                    stats_sub: &mut stats_sub,
                                    on_stats: &mut on_stats,
                                    mode,
                                    stop_timeout: Duration::from_millis(
                                        launch.stack.shutdown_timeout_ms,
                                    ),
                                },
                                spec,
                            )
                        });
                    let line = match &result {
                        Ok(report) => {
                            swaps.push(swap_json(report));
                            swap_sentence(report, mode)
                        }
                        Err(SwapError::Refused(why) | SwapError::Failed(why)) => why.clone(),
                    };
                    progress.suspend(|| match &result {
                        Ok(_) => tracing::info!("{line}"),
                        Err(_) => tracing::warn!("swap not done: {line}"),
                    });
                    call.respond(|r| write_swap_response(r, &result, &line));
                    // The loop did not watch the steps during the swap.
                    last_step.1 = Instant::now();
                }
            }
        }
        for role in hung_roles(&launch, &supervisor, &mut last_heard) {
            *hangs.entry(role.clone()).or_insert(0) += 1;
            let policy = launch.process(&role).map(|p| p.restart.policy);
            if policy.is_some_and(|p| p != RestartWhen::Never)
                && let Some(pid) = supervisor.pid(&role)
            {
                progress.suspend(|| {
                    tracing::warn!(
                        role,
                        "no statistics for {HANG_TIMEOUT:?}: hung, killing it for a restart"
                    )
                });
                let _ = nix::sys::signal::kill(
                    nix::unistd::Pid::from_raw(pid as i32),
                    nix::sys::signal::Signal::SIGKILL,
                );
            } else {
                progress
                    .suspend(|| tracing::warn!(role, "no statistics for {HANG_TIMEOUT:?}: hung"));
            }
        }
        if last_report.elapsed() >= Duration::from_secs(1) {
            last_report = Instant::now();
            publish_processes(&mut processes_pub, &launch, &supervisor, &gave_up);
        }
        status_sub.update();
        if let Some(status) = status_sub.latest() {
            progress.set_position(status.header.tick.min(ticks));
            progress.set_message(format!(
                "coverage {:>5.1}%  loop p50 {:.0} µs p99 {:.0} µs",
                status.coverage * 100.0,
                status.loop_p50_us,
                status.loop_p99_us
            ));
            if status.finished == 1 {
                exit_reason = Some(None);
            }
            if status.header.tick != last_step.0 {
                last_step = (status.header.tick, Instant::now());
            }
        }
        if mode == ClockMode::Lockstep
            && world_done_at.is_none()
            && exit_reason.is_none()
            && last_step.1.elapsed() > STALL_TIMEOUT
        {
            let steps: Vec<String> = collector
                .processes()
                .iter()
                .map(|p| format!("{} {}", p.role, p.steps))
                .collect();
            failure = Some(Failure::run(format!(
                "the lockstep run stalled: no step for {STALL_TIMEOUT:?} after step {}; steps \
                 handled per process: {} (see the logs in {})",
                last_step.0,
                steps.join(", "),
                args.out.join("logs").display()
            )));
            exit_reason = Some(Some("stalled"));
        }
        for event in supervisor.poll() {
            match event {
                SupervisorEvent::Exited {
                    role,
                    status,
                    expected,
                } => {
                    if role == "world" && status.success() {
                        world_done_at.get_or_insert_with(Instant::now);
                    } else if role == "monitor" && status.success() {
                        exit_reason = Some(None);
                    } else if !expected {
                        progress.suspend(
                            || tracing::warn!(role, %status, "process exited unexpectedly"),
                        );
                        // Release what the dead process held before its successor starts.
                        cleanup_dead_nodes();
                        let restarted = match launch.process(&role).map(|p| p.restart.policy) {
                            Some(RestartWhen::Always) => true,
                            Some(RestartWhen::OnFailure) => !status.success(),
                            _ => false,
                        };
                        // Exit code 2 ends the run through GaveUp; anything else that no policy
                        // restarts leaves the stack without the role: the run cannot go on.
                        if !restarted && status != ExitStatus::Code(EXIT_BAD_INPUT) {
                            let log = args.out.join("logs").join(format!("{role}.log"));
                            failure = Some(Failure::run(format!(
                                "`{role}` exited ({status}) and its restart policy does not \
                                 restart it, so the run cannot go on (see {})",
                                log.display()
                            )));
                            exit_reason = Some(Some("process_failed"));
                        }
                    }
                }
                SupervisorEvent::Restarted { role, attempt } => {
                    progress.suspend(|| tracing::warn!(role, attempt, "process restarted"));
                }
                SupervisorEvent::RestartFailed { role, message } => {
                    progress.suspend(|| tracing::warn!(role, "restart failed: {message}"));
                }
                SupervisorEvent::GaveUp { role } => {
                    gave_up.insert(role.clone());
                    let log = args.out.join("logs").join(format!("{role}.log"));
                    failure = Some(
                        if supervisor.last_exit(&role) == Some(ExitStatus::Code(EXIT_BAD_INPUT)) {
                            Failure::input(format!(
                                "`{role}` refused its input: {}",
                                last_error_line(&log)
                            ))
                        } else {
                            Failure::run(format!(
                                "`{role}` kept failing and its restart policy gave up (see {})",
                                log.display()
                            ))
                        },
                    );
                    exit_reason = Some(Some("process_failed"));
                }
            }
        }
        if interrupted.load(Ordering::SeqCst) {
            exit_reason = Some(Some("interrupted"));
        }
        if world_done_at.is_some_and(|t| t.elapsed() > FINISH_TIMEOUT) {
            tracing::warn!("the monitor did not finish within {FINISH_TIMEOUT:?}");
            exit_reason = Some(None);
        }
    }
    progress.finish_and_clear();

    // Stop the world first, so nothing new is produced; the monitor last, so it can still
    // write its files (it does so on SIGTERM too).
    let mut stopping: Vec<String> = stop_order(&launch.processes)
        .unwrap_or_default()
        .into_iter()
        .map(|i| launch.processes[i].role.clone())
        .collect();
    if let Some(pos) = stopping.iter().position(|r| r == "monitor") {
        let monitor = stopping.remove(pos);
        stopping.push(monitor);
    }
    let killed = supervisor.shutdown(
        &stopping,
        Duration::from_millis(launch.stack.shutdown_timeout_ms),
    );
    if !killed.is_empty() {
        tracing::warn!(?killed, "needed SIGKILL");
    }
    drop(control);
    drop(stats_sub);
    drop(processes_pub);
    drop(status_sub);
    drop(ctx);
    cleanup_dead_nodes();

    let restarts = supervisor.restarts();
    let summary_path = args.out.join("summary.json");
    let reason = exit_reason.flatten();
    if !summary_path.exists()
        && let Some(failure) = failure
    {
        // The run failed before the monitor could write anything: the failure is the news.
        return Err(failure);
    }
    finish_summary(
        &summary_path,
        &restarts,
        &hangs,
        &swaps,
        reason,
        started.elapsed().as_secs_f64(),
    )?;
    report(&summary_path, &args.out);
    match failure {
        Some(failure) => Err(failure),
        None => Ok(RunOutcome {
            summary_path,
            stats: collector,
        }),
    }
}

/// The child spec of a hot swap: the role's current spec with the requested program,
/// arguments and working directory (a relative program path is taken from that directory).
fn swap_spec(
    launch: &LaunchFile,
    supervisor: &Supervisor,
    request: &ControlRequest,
    beside: &Path,
) -> Result<ChildSpec, SwapError> {
    let role = read_name(&request.role).into_owned();
    if launch.process(&role).is_none() {
        return Err(SwapError::Refused(format!(
            "no process has the role `{role}` (known roles: {})",
            launch.roles().join(", ")
        )));
    }
    check_swappable(&role)?;
    let argv = request
        .argv()
        .ok_or_else(|| SwapError::Refused("the command is not valid UTF-8".to_string()))?;
    let Some((program, arguments)) = argv.split_first() else {
        return Err(SwapError::Refused("the command is empty".to_string()));
    };
    let cwd = PathBuf::from(read_name(&request.cwd).into_owned());
    if !cwd.is_absolute() {
        return Err(SwapError::Refused(format!(
            "the working directory `{}` is not an absolute path",
            cwd.display()
        )));
    }
    let program = if program.contains('/') {
        cwd.join(program).display().to_string()
    } else {
        program.clone()
    };
    let program =
        resolve_program(&program, beside).map_err(|e| SwapError::Refused(e.to_string()))?;
    let mut spec = supervisor
        .spec(&role)
        .cloned()
        .ok_or_else(|| SwapError::Refused(format!("`{role}` is not running")))?;
    spec.program = program;
    spec.args = arguments.to_vec();
    spec.cwd = Some(cwd);
    Ok(spec)
}

/// A process's statistics sample: it is alive (hang detection), ready, and counted.
fn record_stats(
    s: &Stats,
    last_heard: &mut BTreeMap<String, Instant>,
    ready: &mut BTreeSet<String>,
    collector: &mut StatsCollector,
) {
    let role = read_name(&s.process).into_owned();
    last_heard.insert(role.clone(), Instant::now());
    ready.insert(role);
    collector.record(s);
}

/// The answer to `mole swap`: its status, what the swap measured, and `line`.
fn write_swap_response(
    r: &mut mole_types::ControlResponse,
    result: &Result<SwapReport, SwapError>,
    line: &str,
) {
    match result {
        Ok(report) => {
            r.status = CONTROL_OK;
            r.pid = report.pid;
            r.gap_ns = report.gap.as_nanos() as u64;
            r.period_ns = report.period.as_nanos() as u64;
            r.steps_lost = report.steps_lost;
            r.steps_repeated = report.steps_repeated;
            r.tick = report.tick;
        }
        Err(SwapError::Refused(_)) => r.status = CONTROL_REFUSED,
        Err(SwapError::Failed(_)) => r.status = CONTROL_FAILED,
    }
    write_name(&mut r.text, line);
}

fn swap_sentence(report: &SwapReport, mode: ClockMode) -> String {
    let ms = |d: Duration| d.as_secs_f64() * 1e3;
    let mut line = format!(
        "swapped `{}`: pid {} → {} at tick {}; {} silent for at most {:.1} ms (median interval \
         {:.2} ms) over {} ticks",
        report.role,
        report.old_pid,
        report.pid,
        report.tick,
        report.topic,
        ms(report.gap),
        ms(report.period),
        report.ticks_observed
    );
    if mode == ClockMode::Lockstep {
        line.push_str(&format!(
            "; lockstep: {} steps lost, {} repeated",
            report.steps_lost, report.steps_repeated
        ));
    }
    if report.killed_old {
        line.push_str("; the old process ignored SIGTERM and was killed");
    }
    line.push_str(&format!("; took {:.2} s", report.duration.as_secs_f64()));
    line
}

fn swap_json(report: &SwapReport) -> serde_json::Value {
    serde_json::json!({
        "role": report.role,
        "old_pid": report.old_pid,
        "pid": report.pid,
        "tick": report.tick,
        "topic": report.topic,
        "gap_ms": report.gap.as_secs_f64() * 1e3,
        "median_interval_ms": report.period.as_secs_f64() * 1e3,
        "ticks_observed": report.ticks_observed,
        "steps_lost": report.steps_lost,
        "steps_repeated": report.steps_repeated,
        "killed_old": report.killed_old,
        "duration_s": report.duration.as_secs_f64(),
    })
}

/// `mole status`'s line: where the run is and every role's pid, state and restarts.
fn status_line(
    launch: &LaunchFile,
    supervisor: &Supervisor,
    mode: ClockMode,
    tick: u64,
    ticks: u64,
) -> String {
    let restarts = supervisor.restarts();
    let roles: Vec<String> = launch
        .processes
        .iter()
        .map(|p| {
            let state = match supervisor.pid(&p.role) {
                Some(pid) => format!("pid {pid}"),
                None if supervisor.restart_pending(&p.role) => "restarting".to_string(),
                None => "down".to_string(),
            };
            let n = restarts.get(&p.role).copied().unwrap_or(0);
            format!("{} ({state}, {n} restarts)", p.role)
        })
        .collect();
    let of = if ticks == u64::MAX {
        String::new()
    } else {
        format!(" of {ticks}")
    };
    format!("{mode}, tick {tick}{of}: {}", roles.join(", "))
}

/// Roles that are running, were heard from, and have been silent for [`HANG_TIMEOUT`]; each is
/// reported once per silence.
fn hung_roles(
    launch: &LaunchFile,
    supervisor: &Supervisor,
    last_heard: &mut BTreeMap<String, Instant>,
) -> Vec<String> {
    let mut hung = Vec::new();
    for process in &launch.processes {
        let role = &process.role;
        if let Some(heard) = last_heard.get(role)
            && heard.elapsed() > HANG_TIMEOUT
            && supervisor.is_running(role)
        {
            hung.push(role.clone());
            last_heard.remove(role);
        }
    }
    hung
}

/// The last `error:` line of a process log (or where the log is).
fn last_error_line(log: &Path) -> String {
    std::fs::read_to_string(log)
        .ok()
        .and_then(|text| {
            text.lines()
                .rev()
                .find_map(|l| l.strip_prefix("error: ").map(str::to_string))
        })
        .unwrap_or_else(|| format!("see {}", log.display()))
}

/// Publishes every role's state and restarts on stack/processes (for `mole top`).
fn publish_processes(
    publisher: &mut mole_runtime::Publisher<mole_types::Processes>,
    launch: &LaunchFile,
    supervisor: &Supervisor,
    gave_up: &BTreeSet<String>,
) {
    use mole_types::{
        MAX_PROCESSES, PROCESS_EXITED, PROCESS_FAILED, PROCESS_RESTARTING, PROCESS_RUNNING,
        PROCESS_STARTING,
    };
    let restarts = supervisor.restarts();
    let result = publisher.publish(0, mole_runtime::now_ns(), |m| {
        let n = launch.processes.len().min(MAX_PROCESSES);
        m.n_processes = n as u32;
        for (slot, process) in m.processes.iter_mut().zip(&launch.processes).take(n) {
            mole_types::write_name(&mut slot.role, &process.role);
            slot.pid = supervisor.pid(&process.role).unwrap_or(0);
            slot.state = if gave_up.contains(&process.role) {
                PROCESS_FAILED
            } else if supervisor.is_running(&process.role) {
                PROCESS_RUNNING
            } else if supervisor.restart_pending(&process.role) {
                PROCESS_RESTARTING
            } else if supervisor.last_exit(&process.role).is_some() {
                PROCESS_EXITED
            } else {
                PROCESS_STARTING
            };
            slot.restarts = restarts.get(&process.role).copied().unwrap_or(0);
            slot._pad = 0;
        }
    });
    if let Err(e) = result {
        tracing::debug!("cannot publish stack/processes: {e}");
    }
}

fn child_env(
    args: &UpArgs,
    launch: &LaunchFile,
    scenario: &Path,
    ticks: u64,
    seed: u64,
) -> Vec<(String, String)> {
    let absolute = |p: &Path| std::fs::canonicalize(p).unwrap_or_else(|_| p.to_path_buf());
    let mut env = vec![
        ("MOLE_NAMESPACE".to_string(), args.namespace.clone()),
        ("MOLE_MODE".to_string(), launch.stack.mode.to_string()),
        ("MOLE_RATE_HZ".to_string(), launch.stack.rate_hz.to_string()),
        (
            "MOLE_SCENARIO".to_string(),
            absolute(scenario).display().to_string(),
        ),
        ("MOLE_TICKS".to_string(), ticks.to_string()),
        ("MOLE_PLANNER".to_string(), launch.stack.planner.clone()),
        ("MOLE_ESTIMATOR".to_string(), launch.stack.estimator.clone()),
        (
            "MOLE_OUT".to_string(),
            absolute(&args.out).display().to_string(),
        ),
    ];
    env.push(("MOLE_SEED".to_string(), seed.to_string()));
    // Exploring planners ignore the scenario's goal, so passing it must not end their run.
    if matches!(launch.stack.planner.as_str(), "random-walk" | "frontier") {
        env.push(("MOLE_NO_STOP_AT_GOAL".to_string(), "true".to_string()));
    }
    if let Some((x, y)) = args.goal {
        env.push(("MOLE_GOAL".to_string(), format!("{x},{y}")));
    }
    if let Some(local) = &args.local_planner {
        env.push(("MOLE_LOCAL_PLANNER".to_string(), local.clone()));
    }
    env
}

fn prepare_out_dir(out: &Path) -> Result<(), Failure> {
    let failed = |e: std::io::Error| {
        Failure::input(format!(
            "cannot use the output directory {}: {e}",
            out.display()
        ))
    };
    std::fs::create_dir_all(out.join("logs")).map_err(failed)?;
    for stale in ["summary.json", "map.png"] {
        let path = out.join(stale);
        if path.exists() {
            std::fs::remove_file(&path).map_err(failed)?;
        }
    }
    if let Ok(entries) = std::fs::read_dir(out.join("logs")) {
        for entry in entries.flatten() {
            let _ = std::fs::remove_file(entry.path());
        }
    }
    Ok(())
}

fn wait_ready(
    role: &str,
    ready: &mut BTreeSet<String>,
    stats_sub: &mut mole_runtime::Subscriber<mole_types::Stats>,
    supervisor: &mut Supervisor,
    interrupted: &AtomicBool,
) -> Result<(), Failure> {
    let deadline = Instant::now() + READY_TIMEOUT;
    loop {
        stats_sub.drain(|s| {
            ready.insert(read_name(&s.process).into_owned());
        });
        if ready.contains(role) {
            return Ok(());
        }
        for event in supervisor.poll() {
            if let SupervisorEvent::GaveUp { role: r } = event {
                return Err(Failure::run(format!("`{r}` failed while starting")));
            }
        }
        if interrupted.load(Ordering::SeqCst) {
            return Err(Failure::run("interrupted while starting"));
        }
        if Instant::now() > deadline {
            return Err(Failure::run(format!(
                "`{role}` did not become ready within {READY_TIMEOUT:?}"
            )));
        }
        std::thread::sleep(Duration::from_millis(10));
    }
}

fn progress_bar(ticks: u64, quiet: bool) -> ProgressBar {
    if quiet {
        return ProgressBar::hidden();
    }
    let bar = ProgressBar::new(ticks);
    if let Ok(style) = ProgressStyle::with_template(
        "{spinner} [{elapsed_precise}] {bar:30} {pos}/{len} ticks  {msg}",
    ) {
        bar.set_style(style);
    }
    bar.enable_steady_tick(Duration::from_millis(200));
    bar
}

/// Adds what only the launcher knows (restarts, why the run ended, its wall time) to the
/// monitor's summary.json.
fn finish_summary(
    path: &Path,
    restarts: &BTreeMap<String, u32>,
    hangs: &BTreeMap<String, u32>,
    swaps: &[serde_json::Value],
    reason: Option<&str>,
    launcher_wall_s: f64,
) -> Result<(), Failure> {
    let text = std::fs::read_to_string(path).map_err(|e| {
        Failure::run(format!(
            "the monitor wrote no summary at {}: {e}",
            path.display()
        ))
    })?;
    let mut summary: serde_json::Value = serde_json::from_str(&text)
        .map_err(|e| Failure::run(format!("{} is not valid JSON: {e}", path.display())))?;
    if let Some(object) = summary.as_object_mut() {
        object.insert(
            "hangs".into(),
            serde_json::to_value(hangs).unwrap_or_default(),
        );
        object.insert("swaps".into(), swaps.to_vec().into());
        object.insert(
            "restarts".into(),
            serde_json::to_value(restarts).unwrap_or_default(),
        );
        if let Some(reason) = reason {
            object.insert("exit_reason".into(), reason.into());
        }
        object.insert("launcher_wall_time_s".into(), launcher_wall_s.into());
    }
    let text = serde_json::to_string_pretty(&summary).map_err(|e| Failure::run(e.to_string()))?;
    std::fs::write(path, text + "\n")
        .map_err(|e| Failure::run(format!("cannot write {}: {e}", path.display())))
}

fn report(summary_path: &Path, out: &Path) {
    let Ok(text) = std::fs::read_to_string(summary_path) else {
        return;
    };
    let Ok(s) = serde_json::from_str::<serde_json::Value>(&text) else {
        return;
    };
    println!(
        "{} ticks ({}), coverage {:.1}%, loop latency p50 {} µs, max penetration {} m, exit: {} → {}",
        s["ticks"],
        s["mode"].as_str().unwrap_or("?"),
        s["coverage"].as_f64().unwrap_or(0.0) * 100.0,
        s["loop_latency_us"]["p50"],
        s["max_penetration_m"],
        s["exit_reason"].as_str().unwrap_or("?"),
        out.display()
    );
}
