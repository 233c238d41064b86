//! `mole up` in four stages: [`prepare`] (launch file, scenario, overrides, environment: every
//! refusal happens here, before anything starts), [`start`] (the processes in dependency
//! order), [`supervise`] (until the run ends: a typed [`RunEnd`]) and [`finish`] (stop in the
//! graph's order, complete summary.json).

mod prepare;

use crate::hot_swap::{SwapEnv, SwapError, SwapReport, check_swappable, hot_swap};
use crate::inject::Injector;
use crate::keeper::ResumeKeeper;
use crate::param::Tuner;
use crate::record::{RecordPlan, Recorder};
use crate::stats::StatsCollector;
use crate::supervisor::EXIT_BAD_INPUT;
use crate::view::{UpViewArgs, View, ViewPlan};
use crate::{
    ChildSpec, ExitStatus, LaunchFile, RestartWhen, Supervisor, SupervisorEvent, resolve_program,
    start_order, stop_order,
};
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use mole_monitor::{Summary, SwapRecord, read_summary, write_summary};
use mole_runtime::{CommonArgs, Context, ControlServer, Publisher, Subscriber, cleanup_dead_nodes};
use mole_types::{
    CONTROL_FAILED, CONTROL_FAULT, CONTROL_OK, CONTROL_PARAM, CONTROL_REFUSED, CONTROL_STATUS,
    CONTROL_STOP, ClockMode, ControlRequest, EndReason, EstimatorKind, FaultSpec, PlannerKind,
    Processes, Role, RunStatus, Stats, read_name, topics, write_name,
};
use prepare::{Plan, prepare};
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
/// The launcher's own node name; its statistics are not a role's.
pub const LAUNCHER_NODE: &str = "launcher";
/// Where, in the run's directory, the keeper writes a crashed role's last outputs for its
/// restart (removed at the end of the run).
const RESUME_DIR: &str = "resume";

/// A command-line value that is one of `names`, listed in `--help` and in the error for any
/// other (the names come from the kind's one declaration, `mole_types::kinds`).
pub(crate) fn choices<T: Clone + Send + Sync + 'static, E: std::fmt::Debug + 'static>(
    names: &'static [&'static str],
    parse: fn(&str) -> Result<T, E>,
) -> impl clap::builder::TypedValueParser<Value = T> {
    use clap::builder::TypedValueParser;
    clap::builder::PossibleValuesParser::new(names)
        .map(move |name| parse(&name).expect("a name from the kind's own list parses"))
}

#[derive(Debug, Clone, Args)]
pub struct UpArgs {
    /// Launch file (default: launch/stacks/default.toml).
    pub launch: Option<PathBuf>,
    /// Scenario file, instead of the launch file's.
    #[arg(long)]
    pub scenario: Option<PathBuf>,
    /// Planner, instead of the launch file's.
    #[arg(long, value_parser = choices(PlannerKind::NAMES, str::parse::<PlannerKind>))]
    pub planner: Option<PlannerKind>,
    /// Estimator, instead of the launch file's.
    #[arg(long, value_parser = choices(EstimatorKind::NAMES, str::parse::<EstimatorKind>))]
    pub estimator: Option<EstimatorKind>,
    /// Clock mode.
    #[arg(long, value_parser = choices(ClockMode::NAMES, str::parse::<ClockMode>))]
    pub mode: Option<ClockMode>,
    /// Steps to run.
    #[arg(long, conflicts_with = "duration")]
    pub ticks: Option<u64>,
    /// Simulated seconds to run.
    #[arg(long)]
    pub duration: Option<f64>,
    /// Lockstep: hold after step 0 until an operator (the view, a script) paces the run.
    #[arg(long)]
    pub paused: bool,
    /// Goal X,Y (m) for the goal-seeking planners (apf, dwa), instead of the scenario's.
    #[arg(long, value_name = "X,Y", value_parser = mole_runtime::parse_point)]
    pub goal: Option<(f64, f64)>,
    /// Local planner that follows frontier paths: dwa or apf.
    #[arg(long, value_name = "dwa|apf")]
    pub local_planner: Option<PlannerKind>,
    /// Seed for every random number of the run.
    #[arg(long)]
    pub seed: Option<u64>,
    /// Namespace: services are mole/<namespace>/<topic>.
    #[arg(long, default_value = mole_types::env::DEFAULT_NAMESPACE)]
    pub namespace: String,
    /// Output directory for summary.json, map.png and the process logs.
    #[arg(long, default_value = "runs/latest")]
    pub out: PathBuf,
    /// Run another executable in a role's place: ROLE=COMMAND (repeatable).
    #[arg(long = "swap", value_name = "ROLE=COMMAND")]
    pub swaps: Vec<String>,
    /// Set a setting for this run, over the launch file's: ROLE.KEY=VALUE, e.g.
    /// planning.dwa.critics.heading=0.4 (repeatable; docs/settings.md lists the keys).
    #[arg(long = "set", value_name = "ROLE.KEY=VALUE")]
    pub sets: Vec<String>,
    /// Settings that replace the launch file's before `--set` (`mole replay`: the recording's).
    #[arg(skip)]
    pub settings: Option<Box<crate::settings::StackSettings>>,
    /// Settings changes each process applies before a step (`mole replay`: the recording's).
    #[arg(skip)]
    pub settings_changes: Vec<mole_runtime::ScheduledChange>,
    /// No progress bar (logs only).
    #[arg(long)]
    pub quiet: bool,
    /// Record every topic of the run into this MCAP file (`mole info FILE` describes it).
    #[arg(long, value_name = "FILE")]
    pub record: Option<PathBuf>,
    /// With --record: write TOPIC's samples every N ticks only (repeatable; default
    /// mapping/grid=10 and mapping/contact=10; N = 1 writes every sample).
    #[arg(long = "record-every", value_name = "TOPIC=N", requires = "record")]
    pub record_every: Vec<String>,
    #[command(flatten)]
    pub view: UpViewArgs,
    /// `mole replay`: the player in the place of the roles it plays back.
    #[arg(skip)]
    pub stand_in: Option<Box<crate::replay::StandIn>>,
}

/// A failure of `mole up`, with the exit code it deserves.
#[derive(Debug)]
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

/// How a run ended, as the launcher saw it.
#[derive(Debug)]
pub enum RunEnd {
    /// The world ended the run (its end reason stands) and the monitor wrote its files.
    Finished,
    /// `mole stop` asked for it.
    Stopped,
    /// Ctrl-C.
    Interrupted,
    /// The lockstep run made no step for [`STALL_TIMEOUT`].
    Stalled(Failure),
    /// A process failed beyond what its restart policy mends.
    ProcessFailed(Failure),
}

impl RunEnd {
    /// summary.json's `exit_reason` for this end; `None` keeps the monitor's (the world's).
    pub fn exit_reason(&self) -> Option<&'static str> {
        match self {
            RunEnd::Finished => None,
            RunEnd::Stopped => Some(EndReason::Stopped.name()),
            RunEnd::Interrupted => Some("interrupted"),
            RunEnd::Stalled(_) => Some("stalled"),
            RunEnd::ProcessFailed(_) => Some("process_failed"),
        }
    }

    /// The failure `mole up` exits with, if the run failed.
    fn into_failure(self) -> Option<Failure> {
        match self {
            RunEnd::Stalled(f) | RunEnd::ProcessFailed(f) => Some(f),
            RunEnd::Finished | RunEnd::Stopped | RunEnd::Interrupted => None,
        }
    }
}

/// When started through `cargo run`, builds every process binary too (cargo builds only the
/// package it runs), so `mole` never starts a stale or missing process.
pub(crate) fn build_process_binaries(with_bridge: bool) -> Result<(), Failure> {
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
    // The bridge brings zenoh: built only for a stack split across machines.
    if !with_bridge {
        command.args(["--exclude", "mole-bridge"]);
    }
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

/// What a run leaves besides its files.
pub struct RunOutcome {
    /// summary.json of the run.
    pub summary_path: PathBuf,
    /// The summary as the launcher completed it; `None` for a half of a split stack without the
    /// monitor (the other half writes it).
    pub summary: Option<Summary>,
    /// What the processes reported on stack/stats.
    pub stats: StatsCollector,
}

/// Runs the stack to its end (or Ctrl-C); the summary is in `args.out`.
pub fn up(args: &UpArgs) -> Result<RunOutcome, Failure> {
    let mut plan = prepare(args)?;
    if let Some(stand_in) = &args.stand_in {
        stand_in.apply(&mut plan.launch, &mut plan.programs, &plan.beside)?;
    }
    let recording = match &args.record {
        Some(file) => Some(RecordPlan::new(
            file,
            &args.record_every,
            &plan.launch.path,
        )?),
        None => None,
    };
    let viewing = args.view.plan()?;
    let mut stack = start(args, plan, recording, viewing)?;
    let end = supervise(&mut stack);
    finish(stack, end)
}

/// The launcher's ports on the stack.
struct Ports {
    ctx: Context,
    stats: Subscriber<Stats>,
    status: Subscriber<RunStatus>,
    processes: Publisher<Processes>,
    control: ControlServer,
    /// The operator's pace (operator/pace): a run it holds is not stalled.
    pace: Subscriber<mole_types::Pace>,
}

/// What supervision keeps track of.
struct Watch {
    /// The newest step the monitor reported, and when it came (or supervision last looked
    /// away, for a swap).
    last_step: (u64, Instant),
    /// Roles that announced their ports.
    ready: BTreeSet<String>,
    /// When each role last published statistics.
    last_heard: BTreeMap<String, Instant>,
    hangs: BTreeMap<String, u32>,
    gave_up: BTreeSet<String>,
    swaps: Vec<SwapRecord>,
    collector: StatsCollector,
    /// When the world ended its run (the monitor writes its files next).
    world_done_at: Option<Instant>,
}

impl Watch {
    fn new() -> Self {
        Self {
            last_step: (0, Instant::now()),
            ready: BTreeSet::new(),
            last_heard: BTreeMap::new(),
            hangs: BTreeMap::new(),
            gave_up: BTreeSet::new(),
            swaps: Vec::new(),
            collector: StatsCollector::default(),
            world_done_at: None,
        }
    }

    /// A role's process was restarted: its hang timer starts over from now. The old process's
    /// last statistics are not the new one's: a restart that came late (the supervisor was busy,
    /// e.g. with a swap) would otherwise be killed as hung the moment it started.
    fn restarted(&mut self, role: &str) {
        self.last_heard.insert(role.to_string(), Instant::now());
    }

    /// A process's statistics sample: it is alive (hang detection), ready, and counted.
    fn record(&mut self, s: &Stats) {
        let role = read_name(&s.process).into_owned();
        self.last_heard.insert(role.clone(), Instant::now());
        self.ready.insert(role);
        self.collector.record(s);
    }
}

/// A started stack.
struct Stack<'a> {
    args: &'a UpArgs,
    plan: Plan,
    ports: Ports,
    /// Declared after `supervisor`'s users are done with it: see [`finish`].
    keeper: ResumeKeeper,
    supervisor: Supervisor,
    /// `--record`: the recorder beside the stack.
    recorder: Option<Recorder>,
    /// `--view`: the view beside the stack.
    view: Option<View>,
    /// `mole fault`: the faults injected, and the processes a fault holds stopped.
    faults: Injector,
    /// `mole param`: the settings in force, changed while the stack runs.
    tuner: Tuner,
    watch: Watch,
    interrupted: Arc<AtomicBool>,
    progress: ProgressBar,
    started: Instant,
}

/// Opens the launcher's ports, starts the recorder and the view (if any) and every process once
/// those it depends on are ready.
fn start(
    args: &UpArgs,
    plan: Plan,
    recording: Option<RecordPlan>,
    viewing: Option<ViewPlan>,
) -> Result<Stack<'_>, Failure> {
    let interrupted = Arc::new(AtomicBool::new(false));
    let flag = interrupted.clone();
    ctrlc::set_handler(move || flag.store(true, Ordering::SeqCst))
        .map_err(|e| Failure::run(format!("cannot install the Ctrl-C handler: {e}")))?;
    let common = common_args(args, &plan);
    let ports = open_ports(&common, interrupted.clone()).map_err(Failure::run)?;
    let keeper = ResumeKeeper::start(&common, args.out.join(RESUME_DIR)).map_err(Failure::run)?;
    let faults = Injector::new(&ports.ctx, plan.mode, plan.seed)
        .map_err(|e| Failure::run(format!("cannot open stack/faults: {e}")))?;
    let tuner = Tuner::new(
        &ports.ctx,
        plan.launch.settings,
        args.settings_changes.clone(),
    )
    .map_err(|e| Failure::run(format!("cannot open stack/params: {e}")))?;
    let recorder = recording
        .map(|r| r.start(&plan.env, log_of(args, "recorder")))
        .transpose()?;
    let view = viewing
        .map(|v| v.start(&plan.env, log_of(args, "view")))
        .transpose()?;
    let order = start_order(&plan.launch.processes).map_err(|e| Failure::input(e.to_string()))?;
    let mut stack = Stack {
        args,
        ports,
        keeper,
        supervisor: Supervisor::new(),
        recorder,
        view,
        faults,
        tuner,
        watch: Watch::new(),
        interrupted,
        progress: progress_bar(plan.ticks, args.quiet),
        started: Instant::now(),
        plan,
    };
    let Plan {
        mode, ticks, seed, ..
    } = stack.plan;
    tracing::info!(namespace = %args.namespace, %mode, ticks, seed, "starting the stack");
    for index in order {
        if let Err(failure) = start_process(&mut stack, index) {
            // The processes already started are killed (the supervisor's drop) before they
            // could clean up: what they leave in shared memory is swept.
            drop(stack);
            cleanup_dead_nodes();
            return Err(failure);
        }
    }
    Ok(stack)
}

/// Starts the process `index` of the launch file once those it depends on are ready.
fn start_process(stack: &mut Stack<'_>, index: usize) -> Result<(), Failure> {
    let dependencies = stack.plan.launch.processes[index].depends_on.clone();
    for dependency in &dependencies {
        wait_ready(stack, dependency)?;
    }
    let process = &stack.plan.launch.processes[index];
    let program = stack.plan.programs[&process.role].clone();
    let mut spec = ChildSpec::from_process(process, program, log_of(stack.args, &process.role));
    let own = std::mem::take(&mut spec.env);
    spec.env = stack.plan.env.iter().cloned().chain(own).collect();
    stack
        .supervisor
        .spawn(spec)
        .map_err(|e| Failure::run(e.to_string()))
}

/// The stack's settings as its processes take them.
fn common_args(args: &UpArgs, plan: &Plan) -> CommonArgs {
    CommonArgs {
        namespace: args.namespace.clone(),
        mode: plan.mode,
        rate_hz: plan.launch.stack.rate_hz,
        seed: Some(plan.seed),
        takeover: false,
        resume: None,
        settings: None,
    }
}

/// The launcher's node in the stack's namespace and its ports: statistics and the monitor's
/// status in, stack/processes and stack/control out.
fn open_ports(common: &CommonArgs, interrupted: Arc<AtomicBool>) -> Result<Ports, String> {
    // The one sweep before the processes start (they do not sweep, see `Context::new`).
    cleanup_dead_nodes();
    let ctx = Context::with_shutdown_flag(LAUNCHER_NODE, common, interrupted)
        .map_err(|e| e.to_string())?;
    let open = || -> Result<_, mole_runtime::RuntimeError> {
        Ok((
            ctx.subscriber(topics::STACK_STATS)?,
            ctx.subscriber(topics::MONITOR_STATUS)?,
            ctx.publisher(topics::STACK_PROCESSES)?,
            ctx.control_server()?,
            ctx.passive_subscriber(topics::OPERATOR_PACE)?,
        ))
    };
    let (stats, status, processes, control, pace) = open().map_err(|e| e.to_string())?;
    Ok(Ports {
        ctx,
        stats,
        status,
        processes,
        control,
        pace,
    })
}

/// Serves `mole swap`, `mole stop` and `mole status`, restarts and reports, shows progress,
/// until the run ends.
fn supervise(stack: &mut Stack<'_>) -> RunEnd {
    let mut last_report = Instant::now();
    loop {
        std::thread::sleep(POLL);
        let watch = &mut stack.watch;
        stack.ports.stats.drain(|s| watch.record(s));
        if let Some(end) = serve_control(stack) {
            return end;
        }
        restart_hung(stack);
        stack.faults.release_due();
        if let Some(recorder) = stack.recorder.as_mut() {
            recorder.check();
        }
        if let Some(view) = stack.view.as_mut() {
            view.check();
        }
        if last_report.elapsed() >= Duration::from_secs(1) {
            last_report = Instant::now();
            publish_processes(stack);
            stack.tuner.follow(|_| false);
        }
        if let Some(end) = follow_progress(stack) {
            return end;
        }
        if let Some(end) = handle_events(stack) {
            return end;
        }
        if stack.interrupted.load(Ordering::SeqCst) {
            return RunEnd::Interrupted;
        }
        if stack
            .watch
            .world_done_at
            .is_some_and(|t| t.elapsed() > FINISH_TIMEOUT)
        {
            tracing::warn!("the monitor did not finish within {FINISH_TIMEOUT:?}");
            return RunEnd::Finished;
        }
    }
}

/// Answers one `stack/control` request, if one came; a stop request ends the run.
fn serve_control(stack: &mut Stack<'_>) -> Option<RunEnd> {
    let call = stack.ports.control.receive()?;
    let request = *call.request();
    match request.op {
        CONTROL_STOP => {
            stack
                .progress
                .suspend(|| tracing::info!("stop requested through stack/control"));
            let text = format!("stopping the stack in namespace `{}`", stack.args.namespace);
            call.respond(|r| write_name(&mut r.text, &text));
            return Some(RunEnd::Stopped);
        }
        CONTROL_STATUS => {
            let tick = stack.ports.status.latest().map_or(0, |s| s.header.tick);
            let line = status_line(stack, tick);
            call.respond(|r| write_name(&mut r.text, &line));
        }
        CONTROL_FAULT => {
            let tick = stack.ports.status.latest().map_or(0, |s| s.header.tick);
            let result = request
                .argv()
                .ok_or_else(|| "the fault's words are not valid UTF-8".to_string())
                .and_then(|words| FaultSpec::from_words(&words).map_err(|e| e.0))
                .and_then(|spec| stack.faults.inject(&spec, &stack.supervisor, tick));
            stack.progress.suspend(|| match &result {
                Ok(line) => tracing::warn!("{line}"),
                Err(why) => tracing::warn!("fault refused: {why}"),
            });
            call.respond(|r| match &result {
                Ok(line) => {
                    r.status = CONTROL_OK;
                    r.tick = tick;
                    write_name(&mut r.text, line);
                }
                Err(why) => {
                    r.status = CONTROL_REFUSED;
                    write_name(&mut r.text, why);
                }
            });
        }
        CONTROL_PARAM => {
            let (status, text) = match request.argv() {
                Some(words) => stack.tuner.handle(&words),
                None => (CONTROL_REFUSED, "the words are not valid UTF-8".to_owned()),
            };
            stack.progress.suspend(|| match status {
                CONTROL_OK if request.argv().is_some_and(|w| w[0] == "set") => {
                    tracing::info!("setting changed: {text}")
                }
                CONTROL_OK => {}
                _ => tracing::warn!("setting not changed: {text}"),
            });
            // Supervision did not watch the steps while the process took it.
            stack.watch.last_step.1 = Instant::now();
            call.respond(|r| {
                r.status = status;
                write_name(&mut r.text, &text);
            });
        }
        _ => {
            let result = swap(stack, &request);
            let line = match &result {
                Ok(report) => {
                    stack.watch.swaps.push(swap_record(report));
                    swap_sentence(report, stack.plan.mode)
                }
                Err(SwapError::Refused(why) | SwapError::Failed(why)) => why.clone(),
            };
            stack.progress.suspend(|| match &result {
                Ok(_) => tracing::info!("{line}"),
                Err(_) => tracing::warn!("swap not done: {line}"),
            });
            call.respond(|r| write_swap_response(r, &result, &line));
            // Supervision did not watch the steps during the swap.
            stack.watch.last_step.1 = Instant::now();
        }
    }
    None
}

/// Replaces a role's process as `request` asks, while the stack runs.
fn swap(stack: &mut Stack<'_>, request: &ControlRequest) -> Result<SwapReport, SwapError> {
    let spec = swap_spec(
        &stack.plan.launch,
        &stack.supervisor,
        request,
        &stack.plan.beside,
    )?;
    let watch = &mut stack.watch;
    let mut on_stats = |s: &Stats| watch.record(s);
    hot_swap(
        SwapEnv {
            ctx: &stack.ports.ctx,
            supervisor: &mut stack.supervisor,
            stats_sub: &mut stack.ports.stats,
            on_stats: &mut on_stats,
            mode: stack.plan.mode,
            stop_timeout: Duration::from_millis(stack.plan.launch.stack.shutdown_timeout_ms),
        },
        spec,
    )
}

/// Counts every hung role and kills it for a restart where its policy restarts it.
fn restart_hung(stack: &mut Stack<'_>) {
    for role in hung_roles(
        &stack.plan.launch,
        &stack.supervisor,
        &mut stack.watch.last_heard,
    ) {
        *stack.watch.hangs.entry(role.clone()).or_insert(0) += 1;
        let policy = stack.plan.launch.process(&role).map(|p| p.restart.policy);
        match (policy, stack.supervisor.pid(&role)) {
            (Some(p), Some(pid)) if p != RestartWhen::Never => {
                stack.progress.suspend(|| {
                    tracing::warn!(
                        role,
                        "no statistics for {HANG_TIMEOUT:?}: hung, killing it for a restart"
                    )
                });
                let _ = nix::sys::signal::kill(
                    nix::unistd::Pid::from_raw(pid as i32),
                    nix::sys::signal::Signal::SIGKILL,
                );
            }
            _ => stack
                .progress
                .suspend(|| tracing::warn!(role, "no statistics for {HANG_TIMEOUT:?}: hung")),
        }
    }
}

/// Shows the monitor's progress; the run is over when the monitor says so, or stalled when a
/// lockstep run makes no step for [`STALL_TIMEOUT`].
fn follow_progress(stack: &mut Stack<'_>) -> Option<RunEnd> {
    let ticks = stack.plan.ticks;
    stack.ports.status.update();
    if let Some(status) = stack.ports.status.latest() {
        stack.progress.set_position(status.header.tick.min(ticks));
        stack.progress.set_message(format!(
            "coverage {:>5.1}%  loop p50 {:.0} µs p99 {:.0} µs",
            status.coverage * 100.0,
            status.loop_p50_us,
            status.loop_p99_us
        ));
        if status.finished == 1 {
            return Some(RunEnd::Finished);
        }
        if status.header.tick != stack.watch.last_step.0 {
            stack.watch.last_step = (status.header.tick, Instant::now());
        }
    }
    // A run the operator holds (paused, or held after its steps, or started `--paused` with no
    // pace yet) makes no step, and is no stall.
    stack.ports.pace.drain(|_| {});
    let pace = stack.ports.pace.latest();
    if pace.is_some_and(|p| p.op != mole_types::PACE_RUN) || (stack.args.paused && pace.is_none()) {
        stack.watch.last_step.1 = Instant::now();
    }
    let (step, since) = stack.watch.last_step;
    if stack.plan.mode != ClockMode::Lockstep
        || stack.watch.world_done_at.is_some()
        || since.elapsed() <= STALL_TIMEOUT
    {
        return None;
    }
    let steps: Vec<String> = stack
        .watch
        .collector
        .processes()
        .iter()
        .map(|p| format!("{} {}", p.role, p.steps))
        .collect();
    Some(RunEnd::Stalled(Failure::run(format!(
        "the lockstep run stalled: no step for {STALL_TIMEOUT:?} after step {step}; steps \
         handled per process: {} (see the logs in {})",
        steps.join(", "),
        stack.args.out.join("logs").display()
    ))))
}

/// What the supervisor saw; a role it restarts after a crash resumes from the outputs the
/// keeper kept, with the settings in force (those `mole param` changed included).
fn poll_supervisor(stack: &mut Stack<'_>) -> Vec<SupervisorEvent> {
    let (keeper, tuner) = (&stack.keeper, &stack.tuner);
    stack.supervisor.poll_with(|role, attempt| {
        let mut env = keeper.before_restart(role, attempt);
        env.push((mole_types::env::SETTINGS.to_owned(), tuner.settings_json()));
        env
    })
}

/// Acts on what the supervisor saw: exits, restarts, roles it gave up on.
fn handle_events(stack: &mut Stack<'_>) -> Option<RunEnd> {
    let mut end = None;
    for event in poll_supervisor(stack) {
        let this = match event {
            SupervisorEvent::Exited {
                role,
                status,
                expected,
            } => on_exit(stack, &role, status, expected),
            SupervisorEvent::Restarted { role, attempt } => {
                stack.watch.restarted(&role);
                stack
                    .progress
                    .suspend(|| tracing::warn!(role, attempt, "process restarted"));
                None
            }
            SupervisorEvent::RestartFailed { role, message } => {
                stack
                    .progress
                    .suspend(|| tracing::warn!(role, "restart failed: {message}"));
                None
            }
            SupervisorEvent::GaveUp { role } => Some(gave_up(stack, role)),
        };
        end = end.or(this);
    }
    end
}

/// A process exited: the world's clean end, the monitor's (the run is over), or a failure its
/// restart policy mends or not.
fn on_exit(
    stack: &mut Stack<'_>,
    role: &str,
    status: ExitStatus,
    expected: bool,
) -> Option<RunEnd> {
    let graph_role = role.parse::<Role>().ok();
    if status.success() && graph_role == Some(Role::World) {
        stack.watch.world_done_at.get_or_insert_with(Instant::now);
        return None;
    }
    if status.success() && graph_role == Some(Role::Monitor) {
        return Some(RunEnd::Finished);
    }
    if expected {
        return None;
    }
    stack
        .progress
        .suspend(|| tracing::warn!(role, %status, "process exited unexpectedly"));
    // Release what the dead process held before its successor starts.
    cleanup_dead_nodes();
    let restarted = match stack.plan.launch.process(role).map(|p| p.restart.policy) {
        Some(RestartWhen::Always) => true,
        Some(RestartWhen::OnFailure) => !status.success(),
        _ => false,
    };
    // Exit code 2 ends the run through GaveUp; anything else that no policy restarts leaves the
    // stack without the role: the run cannot go on.
    if restarted || status == ExitStatus::Code(EXIT_BAD_INPUT) {
        return None;
    }
    Some(RunEnd::ProcessFailed(Failure::run(format!(
        "`{role}` exited ({status}) and its restart policy does not restart it, so the run \
         cannot go on (see {})",
        log_of(stack.args, role).display()
    ))))
}

/// The supervisor gave up on a role: the run cannot go on.
fn gave_up(stack: &mut Stack<'_>, role: String) -> RunEnd {
    let failure = gave_up_failure(stack, &role);
    stack.watch.gave_up.insert(role);
    RunEnd::ProcessFailed(failure)
}

/// Why the supervisor gave up on `role`: its own refusal of its input (exit 2, its error line
/// shown), or failures beyond its restart policy.
fn gave_up_failure(stack: &Stack<'_>, role: &str) -> Failure {
    let log = log_of(stack.args, role);
    if stack.supervisor.last_exit(role) == Some(ExitStatus::Code(EXIT_BAD_INPUT)) {
        Failure::input(format!(
            "`{role}` refused its input: {}",
            last_error_line(&log)
        ))
    } else {
        Failure::run(format!(
            "`{role}` kept failing and its restart policy gave up (see {})",
            log.display()
        ))
    }
}

fn log_of(args: &UpArgs, role: &str) -> PathBuf {
    args.out.join("logs").join(format!("{role}.log"))
}

/// Stops the stack in the graph's order, releases the launcher's ports, completes summary.json.
fn finish(stack: Stack<'_>, end: RunEnd) -> Result<RunOutcome, Failure> {
    let Stack {
        args,
        plan,
        ports,
        keeper,
        mut supervisor,
        recorder,
        view,
        faults,
        tuner,
        watch,
        progress,
        started,
        ..
    } = stack;
    progress.finish_and_clear();
    // Before the stop: a process a fault holds stopped could not take its SIGTERM.
    let faults = faults.finish();
    let mut tuner = tuner;
    tuner.follow(|_| false);
    let settings_changes = tuner.changes;
    let stopping: Vec<String> = stop_order(&plan.launch.processes)
        .into_iter()
        .map(|i| plan.launch.processes[i].role.clone())
        .collect();
    let timeout = Duration::from_millis(plan.launch.stack.shutdown_timeout_ms);
    let killed = supervisor.shutdown(&stopping, timeout);
    if !killed.is_empty() {
        tracing::warn!(?killed, "needed SIGKILL");
    }
    // After every role: the recorder reads their last samples before it finishes its file.
    if let Some(recorder) = recorder {
        recorder.stop(timeout);
    }
    if let Some(view) = view {
        view.stop(timeout);
    }
    drop(ports);
    keeper.stop();
    cleanup_dead_nodes();

    let summary_path = args.out.join("summary.json");
    let exit_reason = end.exit_reason();
    let failure = end.into_failure();
    if plan.launch.process(Role::Monitor.name()).is_none() {
        // A half of a split stack without the monitor: the summary is written on the other side.
        if let Some(failure) = failure {
            return Err(failure);
        }
        println!(
            "{} ({}): this half has no monitor; the run's summary is written where the monitor runs \
             (logs: {})",
            exit_reason.unwrap_or("finished"),
            plan.mode,
            args.out.join("logs").display()
        );
        return Ok(RunOutcome {
            summary_path,
            summary: None,
            stats: watch.collector,
        });
    }
    if !summary_path.exists()
        && let Some(failure) = failure
    {
        // The run failed before the monitor could write anything: the failure is the news.
        return Err(failure);
    }
    let mut summary = read_summary(&summary_path).map_err(|e| {
        Failure::run(format!(
            "the monitor wrote no readable summary at {}: {e}",
            summary_path.display()
        ))
    })?;
    summary.restarts = supervisor.restarts();
    summary.hangs = watch.hangs;
    summary.swaps = watch.swaps;
    summary.faults = faults;
    if let Some(reason) = exit_reason {
        summary.exit_reason = reason.to_owned();
    }
    summary.launcher_wall_time_s = Some(started.elapsed().as_secs_f64());
    summary.settings = serde_json::to_value(plan.launch.settings).unwrap_or_default();
    summary.settings_changes = serde_json::to_value(&settings_changes).unwrap_or_default();
    write_summary(&summary, &summary_path)
        .map_err(|e| Failure::run(format!("cannot complete {}: {e}", summary_path.display())))?;
    report(&summary, &args.out);
    match failure {
        Some(failure) => Err(failure),
        None => Ok(RunOutcome {
            summary_path,
            summary: Some(summary),
            stats: watch.collector,
        }),
    }
}

/// The line `mole up` prints at the end.
fn report(s: &Summary, out: &Path) {
    let p50 = s
        .loop_latency_us
        .p50
        .map_or("-".to_owned(), |v| format!("{v:.0}"));
    println!(
        "{} ticks ({}), coverage {:.1}%, loop latency p50 {p50} µs, max penetration {} m, exit: {} → {}",
        s.ticks,
        s.mode,
        s.coverage * 100.0,
        s.max_penetration_m,
        s.exit_reason,
        out.display()
    );
}

fn swap_record(report: &SwapReport) -> SwapRecord {
    SwapRecord {
        role: report.role.clone(),
        old_pid: report.old_pid,
        pid: report.pid,
        tick: report.tick,
        topic: report.topic.to_owned(),
        gap_ms: report.gap.as_secs_f64() * 1e3,
        gap_ticks: report.gap_ticks,
        median_interval_ms: report.period.as_secs_f64() * 1e3,
        ticks_observed: report.ticks_observed,
        steps_lost: report.steps_lost,
        steps_repeated: report.steps_repeated,
        killed_old: report.killed_old,
        duration_s: report.duration.as_secs_f64(),
    }
}

/// Publishes every role's state and restarts on stack/processes (for `mole top`).
fn publish_processes(stack: &mut Stack<'_>) {
    use mole_types::{
        MAX_PROCESSES, PROCESS_EXITED, PROCESS_FAILED, PROCESS_RESTARTING, PROCESS_RUNNING,
        PROCESS_STARTING,
    };
    let (launch, supervisor, gave_up) =
        (&stack.plan.launch, &stack.supervisor, &stack.watch.gave_up);
    let restarts = supervisor.restarts();
    let result = stack
        .ports
        .processes
        .publish(0, mole_runtime::now_ns(), |m| {
            let n = launch.processes.len().min(MAX_PROCESSES);
            m.n_processes = n as u32;
            for (slot, process) in m.processes.iter_mut().zip(&launch.processes).take(n) {
                write_name(&mut slot.role, &process.role);
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

/// `mole status`'s line: where the run is and every role's pid, state and restarts.
fn status_line(stack: &Stack<'_>, tick: u64) -> String {
    let (launch, supervisor) = (&stack.plan.launch, &stack.supervisor);
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
    let of = if stack.plan.ticks == u64::MAX {
        String::new()
    } else {
        format!(" of {}", stack.plan.ticks)
    };
    format!("{}, tick {tick}{of}: {}", stack.plan.mode, roles.join(", "))
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
pub(crate) fn last_error_line(log: &Path) -> String {
    std::fs::read_to_string(log)
        .ok()
        .and_then(|text| {
            text.lines()
                .rev()
                .find_map(|l| l.strip_prefix("error: ").map(str::to_string))
        })
        .unwrap_or_else(|| format!("see {}", log.display()))
}

/// Waits until `role` announced its ports (its first `stack/stats`).
fn wait_ready(stack: &mut Stack<'_>, role: &str) -> Result<(), Failure> {
    // A bridge waits up to PEER_TIMEOUT for the other half, then ends saying why: its reason,
    // not this timeout, is the news.
    let timeout = if role == mole_types::link::BRIDGE_ROLE {
        mole_types::link::PEER_TIMEOUT + READY_TIMEOUT
    } else {
        READY_TIMEOUT
    };
    let deadline = Instant::now() + timeout;
    loop {
        let ready = &mut stack.watch.ready;
        stack.ports.stats.drain(|s| {
            ready.insert(read_name(&s.process).into_owned());
        });
        if stack.watch.ready.contains(role) {
            return Ok(());
        }
        for event in poll_supervisor(stack) {
            if let SupervisorEvent::GaveUp { role } = event {
                return Err(gave_up_failure(stack, &role));
            }
        }
        if stack.interrupted.load(Ordering::SeqCst) {
            return Err(Failure::run("interrupted while starting"));
        }
        if Instant::now() > deadline {
            return Err(Failure::run(format!(
                "`{role}` did not become ready within {timeout:?}"
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

#[cfg(test)]
mod tests {
    use super::*;

    /// A restarted role's hang timer starts over: its old process's last statistics, however
    /// old, no longer count against the new one.
    #[test]
    fn a_restart_starts_the_hang_timer_over() {
        let mut watch = Watch::new();
        let long_ago = Instant::now()
            .checked_sub(2 * HANG_TIMEOUT)
            .expect("the clock runs longer than two hang timeouts");
        watch.last_heard.insert("sensing".into(), long_ago);
        watch.restarted("sensing");
        assert!(watch.last_heard["sensing"] > long_ago);
    }
}
