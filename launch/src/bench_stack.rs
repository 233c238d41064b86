//! `mole bench stack`: runs the full stack and reports how fast it went and where time went;
//! with `--targets`, measures the loop against raw iceoryx2 in one run (issue #13's targets).

use crate::Failure;
use crate::stats::{HopLatency, ProcessUsage};
use crate::up::{UpArgs, up};
use clap::Args;
use mole_monitor::LatencyUs;
use serde::Serialize;
use std::fmt::Write as _;
use std::path::PathBuf;

#[derive(Debug, Args)]
pub struct BenchStackArgs {
    #[command(flatten)]
    pub up: UpArgs,
    /// Also write the report as JSON here.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Measure the wake-up targets in one run: raw iceoryx2's and the runtime's five-hop chain
    /// and event hop, then the stack in realtime and in lockstep (the clock mode and length
    /// given are replaced); prints the ratios next to their figures.
    #[arg(long)]
    pub targets: bool,
    /// With --targets: how long the realtime run lasts (s).
    #[arg(long, default_value_t = 20.0)]
    pub realtime_secs: f64,
    /// With --targets: how many steps the lockstep run takes.
    #[arg(long, default_value_t = 20_000)]
    pub lockstep_ticks: u64,
    /// Run the stack split in two over the bridge (launch/stacks/split: the on-board half in a
    /// `mole up` of its own, the off-board half here) and, with the same settings, on one host;
    /// prints both loops and steps/s and their ratio. The launch file given is the one-host run's.
    #[arg(long, conflicts_with = "targets")]
    pub split: bool,
}

/// The report of one stack run.
#[derive(Debug, Clone, Serialize)]
pub struct StackReport {
    pub mode: String,
    pub ticks: u64,
    /// Wall time from the first to the last step (s).
    pub wall_time_s: f64,
    /// Steps per wall-clock second (the lockstep throughput).
    pub steps_per_s: f64,
    /// Loop latency, the world's state to the command back at the world (µs).
    pub loop_latency_us: LatencyUs,
    /// Origin → receipt at every subscriber, per topic.
    pub hops: Vec<HopLatency>,
    /// CPU time and peak memory per process.
    pub processes: Vec<ProcessUsage>,
    pub summary: PathBuf,
}

/// Runs the stack (no progress bar) and prints the report; `--json` writes it too. With
/// `--targets` it runs [`bench_targets`] instead.
pub fn bench_stack(args: &BenchStackArgs) -> Result<(), Failure> {
    if let Some(path) = &args.json {
        check_writable(path)?;
    }
    if args.targets {
        return bench_targets(args).map(drop);
    }
    if args.split {
        return bench_split(args).map(drop);
    }
    let report = run_stack(&args.up)?;
    print!("{}", render(&report));
    write_json(args.json.as_deref(), &report)
}

/// Writes `report` as JSON to `path`, if given.
fn write_json(path: Option<&std::path::Path>, report: &impl Serialize) -> Result<(), Failure> {
    let Some(path) = path else {
        return Ok(());
    };
    let json = serde_json::to_string_pretty(report).map_err(|e| Failure::run(e.to_string()))?;
    std::fs::write(path, json + "\n")
        .map_err(|e| Failure::input(format!("cannot write {}: {e}", path.display())))
}

/// Runs the stack with `up_args`, quietly, and gathers its report.
fn run_stack(up_args: &UpArgs) -> Result<StackReport, Failure> {
    let mut up_args = up_args.clone();
    up_args.quiet = true;
    let outcome = up(&up_args)?;
    let summary = outcome.summary.as_ref().ok_or_else(|| {
        Failure::input(
            "this stack has no monitor, so it reports no loop latency; bench the half that has it",
        )
    })?;
    let (ticks, wall_time_s) = (summary.ticks, summary.wall_time_s);
    let report = StackReport {
        mode: summary.mode.clone(),
        ticks,
        wall_time_s,
        steps_per_s: if wall_time_s > 0.0 {
            ticks as f64 / wall_time_s
        } else {
            0.0
        },
        loop_latency_us: summary.loop_latency_us.clone(),
        hops: outcome.stats.hops(),
        processes: outcome.stats.processes(),
        summary: outcome.summary_path.clone(),
    };
    Ok(report)
}

/// Issue #13's targets from one run: the figures and their ratios.
#[derive(Debug, Clone, Serialize)]
pub struct TargetsReport {
    /// Raw iceoryx2 and the runtime: event hop and five-hop chain (`mole bench ipc`'s points).
    pub ipc: mole_bench::IpcReport,
    /// The stack at 100 Hz (the default rate) in realtime: its `mole bench stack --json` report.
    pub realtime: serde_json::Value,
    /// The stack as fast as it goes: its report.
    pub lockstep: serde_json::Value,
    pub figures: TargetFigures,
    pub ratios: Vec<TargetRatio>,
}

/// The absolute figures the ratios divide (µs, steps or loops per second, % of one core).
#[derive(Debug, Clone, Default, Serialize)]
pub struct TargetFigures {
    pub raw_chain_100hz_p50_us: f64,
    pub raw_chain_flat_out_p50_us: f64,
    /// One loop through the raw chain flat out, per second: 1 / its p50.
    pub raw_chain_flat_out_loops_per_s: f64,
    pub runtime_chain_100hz_p50_us: f64,
    pub raw_event_hop_p50_us: f64,
    pub runtime_event_hop_p50_us: f64,
    pub realtime_loop_p50_us: f64,
    pub realtime_loop_p99_us: f64,
    /// Every role's CPU time over the realtime run, in % of one core.
    pub realtime_stack_cpu_percent: f64,
    pub lockstep_steps_per_s: f64,
}

/// One target: the measured value and the bound it is held to.
#[derive(Debug, Clone, Serialize)]
pub struct TargetRatio {
    pub what: String,
    pub value: f64,
    /// `at most` or `at least`.
    pub bound: String,
    pub limit: f64,
    pub met: bool,
}

/// Measures raw iceoryx2 and the runtime (event hop, five-hop chain flat out and at 100 Hz),
/// then the stack in realtime and in lockstep, and prints the targets' ratios; `--json` writes
/// everything.
pub fn bench_targets(args: &BenchStackArgs) -> Result<TargetsReport, Failure> {
    if !(args.realtime_secs.is_finite() && args.realtime_secs > 0.0) || args.lockstep_ticks == 0 {
        return Err(Failure::input(
            "--realtime-secs and --lockstep-ticks must be positive",
        ));
    }
    let ipc = mole_bench::IpcBenchConfig {
        namespace: format!("targets-{}", std::process::id()),
        sizes: vec![64],
        fanout: Vec::new(),
        throughput_secs: 0.2,
        floor_samples: 500,
        floor_paced_samples: 100,
        ..mole_bench::IpcBenchConfig::default()
    };
    let ipc = mole_bench::run_ipc_bench(&ipc).map_err(|e| Failure::run(e.to_string()))?;
    let length = format!("--duration={}", args.realtime_secs);
    let realtime = run_stack_child(args, "realtime", &length)?;
    let length = format!("--ticks={}", args.lockstep_ticks);
    let lockstep = run_stack_child(args, "lockstep", &length)?;
    let figures = figures(&ipc, &realtime, &lockstep);
    let report = TargetsReport {
        ratios: ratios(&figures),
        ipc,
        realtime,
        lockstep,
        figures,
    };
    print!("{}", render_targets(&report));
    write_json(args.json.as_deref(), &report)?;
    Ok(report)
}

/// The options of this `mole bench stack --targets` that a stack run takes too: all but those
/// the targets set themselves.
fn forwarded_options() -> Vec<String> {
    options_but(&[
        "--json",
        "--out",
        "--mode",
        "--ticks",
        "--duration",
        "--namespace",
        "--realtime-secs",
        "--lockstep-ticks",
    ])
}

/// The options this `mole bench stack` was given, without `--targets`, `--split` and the
/// options (with their values) named in `set_here`.
fn options_but(set_here: &[&str]) -> Vec<String> {
    let mut forwarded = Vec::new();
    let mut options = std::env::args().skip_while(|a| a != "stack").skip(1);
    while let Some(option) = options.next() {
        let name = option.split('=').next().unwrap_or_default();
        if option == "--targets" || option == "--split" {
            continue;
        }
        if set_here.contains(&name) {
            if !option.contains('=') {
                options.next();
            }
            continue;
        }
        forwarded.push(option);
    }
    forwarded
}

/// Runs the stack in `mode` in a `mole bench stack` of its own (a launcher installs its Ctrl-C
/// handler once per process) and reads its JSON report.
fn run_stack_child(
    args: &BenchStackArgs,
    mode: &str,
    length: &str,
) -> Result<serde_json::Value, Failure> {
    let out = args.up.out.join(mode);
    std::fs::create_dir_all(&out)
        .map_err(|e| Failure::input(format!("cannot create {}: {e}", out.display())))?;
    let json = out.join("bench.json");
    let exe = std::env::current_exe().map_err(|e| Failure::run(e.to_string()))?;
    let status = std::process::Command::new(exe)
        .args(["bench", "stack", "--mode", mode, length])
        .arg(format!("--namespace={}-{mode}", args.up.namespace))
        .arg("--out")
        .arg(&out)
        .arg("--json")
        .arg(&json)
        .args(forwarded_options())
        .stdout(std::process::Stdio::null())
        .status()
        .map_err(|e| Failure::run(format!("cannot start the {mode} run: {e}")))?;
    if !status.success() {
        return Err(Failure::run(format!("the {mode} run failed: {status}")));
    }
    let text = std::fs::read_to_string(&json)
        .map_err(|e| Failure::run(format!("no report of the {mode} run: {e}")))?;
    serde_json::from_str(&text)
        .map_err(|e| Failure::run(format!("the {mode} run's report is unreadable: {e}")))
}

/// The figures of one targets run (0 where a point is missing).
fn figures(
    ipc: &mole_bench::IpcReport,
    realtime: &serde_json::Value,
    lockstep: &serde_json::Value,
) -> TargetFigures {
    use mole_bench::{Transport, WakeMode};
    let chain = |transport: Transport, paced: bool| {
        ipc.chain
            .iter()
            .find(|c| c.transport == transport && c.rate_hz.is_some() == paced)
            .map_or(0.0, |c| c.latency.p50_us)
    };
    let hop = |transport: Transport| {
        ipc.latency
            .iter()
            .find(|p| p.transport == transport && p.wake == WakeMode::Event)
            .map_or(0.0, |p| p.latency.p50_us)
    };
    let flat_out = chain(Transport::Raw, false);
    TargetFigures {
        raw_chain_100hz_p50_us: chain(Transport::Raw, true),
        raw_chain_flat_out_p50_us: flat_out,
        raw_chain_flat_out_loops_per_s: if flat_out > 0.0 { 1e6 / flat_out } else { 0.0 },
        runtime_chain_100hz_p50_us: chain(Transport::Runtime, true),
        raw_event_hop_p50_us: hop(Transport::Raw),
        runtime_event_hop_p50_us: hop(Transport::Runtime),
        realtime_loop_p50_us: number(&realtime["loop_latency_us"]["p50"]),
        realtime_loop_p99_us: number(&realtime["loop_latency_us"]["p99"]),
        realtime_stack_cpu_percent: realtime["processes"]
            .as_array()
            .map_or(0.0, |p| p.iter().map(|p| number(&p["cpu_percent"])).sum()),
        lockstep_steps_per_s: number(&lockstep["steps_per_s"]),
    }
}

/// A number of a report, 0 when absent.
fn number(value: &serde_json::Value) -> f64 {
    value.as_f64().unwrap_or(0.0)
}

/// The targets of issue #13 held against `f`.
fn ratios(f: &TargetFigures) -> Vec<TargetRatio> {
    let ratio = |a: f64, b: f64| if b > 0.0 { a / b } else { f64::NAN };
    let target = |what: &str, value: f64, at_most: bool, limit: f64| TargetRatio {
        what: what.to_string(),
        value,
        bound: if at_most { "at most" } else { "at least" }.to_string(),
        limit,
        met: if at_most {
            value <= limit
        } else {
            value >= limit
        },
    };
    vec![
        target(
            "realtime loop p50 / raw iceoryx2 five-hop chain p50 at 100 Hz",
            ratio(f.realtime_loop_p50_us, f.raw_chain_100hz_p50_us),
            true,
            1.0 / 3.0,
        ),
        target(
            "realtime loop p99 / raw iceoryx2 five-hop chain p50 at 100 Hz",
            ratio(f.realtime_loop_p99_us, f.raw_chain_100hz_p50_us),
            true,
            1.0,
        ),
        target(
            "stack CPU at 100 Hz, % of one core",
            f.realtime_stack_cpu_percent,
            true,
            5.0,
        ),
        target(
            "lockstep steps/s / raw iceoryx2 five-hop chain loops/s flat out",
            ratio(f.lockstep_steps_per_s, f.raw_chain_flat_out_loops_per_s),
            false,
            2.0,
        ),
        target(
            "runtime / raw iceoryx2 p50 per event hop, 64 B",
            ratio(f.runtime_event_hop_p50_us, f.raw_event_hop_p50_us),
            true,
            1.2,
        ),
        target(
            "runtime / raw iceoryx2 p50, five-hop chain at 100 Hz",
            ratio(f.runtime_chain_100hz_p50_us, f.raw_chain_100hz_p50_us),
            true,
            1.2,
        ),
    ]
}

/// The figures and the targets as text.
fn render_targets(r: &TargetsReport) -> String {
    let f = &r.figures;
    let mut s = String::new();
    let _ = writeln!(
        s,
        "figures: raw iceoryx2 five-hop chain p50 {:.1} µs at 100 Hz, {:.1} µs flat out ({:.0} \
         loops/s); runtime chain p50 {:.1} µs at 100 Hz; event hop p50 raw {:.1} µs, runtime \
         {:.1} µs; realtime loop p50 {:.1} µs, p99 {:.1} µs, stack CPU {:.1}% of a core; \
         lockstep {:.0} steps/s",
        f.raw_chain_100hz_p50_us,
        f.raw_chain_flat_out_p50_us,
        f.raw_chain_flat_out_loops_per_s,
        f.runtime_chain_100hz_p50_us,
        f.raw_event_hop_p50_us,
        f.runtime_event_hop_p50_us,
        f.realtime_loop_p50_us,
        f.realtime_loop_p99_us,
        f.realtime_stack_cpu_percent,
        f.lockstep_steps_per_s
    );
    let _ = writeln!(s, "\n{:<66} {:>8}  target", "targets", "value");
    for t in &r.ratios {
        let _ = writeln!(
            s,
            "{:<66} {:>8.2}  {} {:.2}: {}",
            t.what,
            t.value,
            t.bound,
            t.limit,
            if t.met { "met" } else { "missed" }
        );
    }
    s
}

// ---------------------------------------------------------------------------------------------
// `--split`: one stack on two "machines" (two namespaces joined by their bridges) against the
// same stack on one host.

/// The split run next to the one-host run of the same settings.
#[derive(Debug, Clone, Serialize)]
pub struct SplitReport {
    /// The one-host run: its `mole bench stack --json` report.
    pub single: serde_json::Value,
    /// The off-board half's report (it has the monitor: the loop runs through both bridges).
    pub split: StackReport,
    /// The namespaces the halves ran in (on board, off board) and the bridge's endpoint.
    pub onboard_namespace: String,
    pub offboard_namespace: String,
    pub endpoint: String,
    pub figures: SplitFigures,
}

/// Loop latency and steps/s of both runs, and split / single.
#[derive(Debug, Clone, Default, Serialize)]
pub struct SplitFigures {
    pub single_loop_p50_us: f64,
    pub single_loop_p99_us: f64,
    pub single_steps_per_s: f64,
    pub split_loop_p50_us: f64,
    pub split_loop_p99_us: f64,
    pub split_steps_per_s: f64,
    pub loop_p50_ratio: f64,
    pub loop_p99_ratio: f64,
    pub steps_per_s_ratio: f64,
}

/// The on-board half's `mole up`, interrupted (then killed) if it is still running when the
/// split run ends, however it ends.
struct OnboardHalf(std::process::Child);

impl Drop for OnboardHalf {
    fn drop(&mut self) {
        if matches!(self.0.try_wait(), Ok(None)) {
            let pid = nix::unistd::Pid::from_raw(self.0.id() as i32);
            let _ = nix::sys::signal::kill(pid, nix::sys::signal::Signal::SIGINT);
            let deadline = std::time::Instant::now() + std::time::Duration::from_secs(15);
            while matches!(self.0.try_wait(), Ok(None)) && std::time::Instant::now() < deadline {
                std::thread::sleep(std::time::Duration::from_millis(50));
            }
            let _ = self.0.kill();
        }
        let _ = self.0.wait();
    }
}

/// One of launch/stacks/split's files, from the current directory or this crate's.
fn split_file(half: &str) -> PathBuf {
    let relative = PathBuf::from(format!("launch/stacks/split/{half}.toml"));
    if relative.exists() {
        return relative;
    }
    std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("stacks/split/{half}.toml"))
}

/// A copy of a split half's launch file for this run: the peer's namespace `peer`, every
/// endpoint on `port`, the scenario's path absolute (the copy lives elsewhere).
fn split_copy(original: &std::path::Path, peer: &str, port: u16) -> Result<String, Failure> {
    let bad = |why: String| Failure::input(format!("{}: {why}", original.display()));
    let text = std::fs::read_to_string(original).map_err(|e| bad(e.to_string()))?;
    let mut table: toml::Table = toml::from_str(&text).map_err(|e| bad(e.to_string()))?;
    let stack = table
        .get_mut("stack")
        .and_then(toml::Value::as_table_mut)
        .ok_or_else(|| bad("no [stack] table".to_owned()))?;
    if let Some(toml::Value::String(scenario)) = stack.get_mut("scenario") {
        let cwd = std::env::current_dir().map_err(|e| bad(e.to_string()))?;
        let found = crate::resolve_data_path("scenario", scenario.as_ref(), original, &cwd)
            .map_err(|e| bad(e.to_string()))?;
        let absolute = std::path::absolute(&found).map_err(|e| bad(e.to_string()))?;
        *scenario = absolute.display().to_string();
    }
    let bridge = table
        .get_mut("bridge")
        .and_then(toml::Value::as_table_mut)
        .ok_or_else(|| bad("no [bridge] table".to_owned()))?;
    bridge.insert("peer_namespace".to_owned(), peer.into());
    let mut endpoints = 0;
    for side in ["listen", "connect"] {
        let Some(list) = bridge.get_mut(side).and_then(toml::Value::as_array_mut) else {
            continue;
        };
        for endpoint in list {
            let moved = endpoint
                .as_str()
                .and_then(|e| e.rsplit_once(':'))
                .map(|(host, _)| format!("{host}:{port}"))
                .ok_or_else(|| bad(format!("bridge.{side}: {endpoint} is not HOST:PORT")))?;
            *endpoint = moved.into();
            endpoints += 1;
        }
    }
    if endpoints == 0 {
        return Err(bad("the bridge neither listens nor connects".to_owned()));
    }
    toml::to_string(&table).map_err(|e| bad(e.to_string()))
}

/// The `mole up` options that make the on-board half run like this one: clock mode, length,
/// seed, scenario, planners, estimator, goal, settings.
fn stack_options(up: &UpArgs) -> Vec<String> {
    let mut options = Vec::new();
    let mut add = |flag: &str, value: Option<String>| {
        if let Some(value) = value {
            options.push(format!("--{flag}={value}"));
        }
    };
    add("mode", up.mode.map(|m| m.to_string()));
    add("ticks", up.ticks.map(|t| t.to_string()));
    add("duration", up.duration.map(|d| d.to_string()));
    add("seed", up.seed.map(|s| s.to_string()));
    add("planner", up.planner.map(|p| p.to_string()));
    add("local-planner", up.local_planner.map(|p| p.to_string()));
    add("estimator", up.estimator.map(|e| e.to_string()));
    add("goal", up.goal.map(|(x, y)| format!("{x},{y}")));
    add(
        "scenario",
        up.scenario.as_ref().map(|s| s.display().to_string()),
    );
    for set in &up.sets {
        add("set", Some(set.clone()));
    }
    options
}

/// Runs the stack on one host (in a `mole bench stack` of its own), then split: the on-board
/// half in a child `mole up`, the off-board half here; prints both and their ratios.
pub fn bench_split(args: &BenchStackArgs) -> Result<SplitReport, Failure> {
    let namespace = &args.up.namespace;
    let (on_ns, off_ns) = (
        format!("{namespace}-onboard"),
        format!("{namespace}-offboard"),
    );
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .map_err(|e| Failure::run(format!("no free TCP port on 127.0.0.1: {e}")))?
        .port();
    let dir = args.up.out.join("split");
    std::fs::create_dir_all(&dir)
        .map_err(|e| Failure::input(format!("cannot create {}: {e}", dir.display())))?;
    let mut files = Vec::new();
    for (half, peer) in [("onboard", &off_ns), ("offboard", &on_ns)] {
        let copy = dir.join(format!("{half}.toml"));
        let text = split_copy(&split_file(half), peer, port)?;
        std::fs::write(&copy, text)
            .map_err(|e| Failure::input(format!("cannot write {}: {e}", copy.display())))?;
        files.push(copy);
    }

    let single = run_single_child(args)?;

    let exe = std::env::current_exe().map_err(|e| Failure::run(e.to_string()))?;
    let onboard_out = dir.join("onboard");
    let mut onboard = std::process::Command::new(exe);
    onboard
        .arg("up")
        .arg(&files[0])
        .arg(format!("--namespace={on_ns}"))
        .arg("--out")
        .arg(&onboard_out)
        .arg("--quiet")
        .args(stack_options(&args.up))
        .stdout(std::process::Stdio::null());
    crate::supervisor::dies_with_the_launcher(&mut onboard);
    let mut onboard = OnboardHalf(
        onboard
            .spawn()
            .map_err(|e| Failure::run(format!("cannot start the on-board half: {e}")))?,
    );
    let mut offboard = args.up.clone();
    offboard.launch = Some(files[1].clone());
    offboard.namespace = off_ns.clone();
    offboard.out = dir.join("offboard");
    let split = run_stack(&offboard)?;
    let onboard_end = wait_for(&mut onboard.0, std::time::Duration::from_secs(30));
    if !onboard_end.is_some_and(|s| s.success()) {
        return Err(Failure::run(format!(
            "the on-board half did not end well ({}); see {}",
            onboard_end.map_or(
                "still running after the off-board half ended".to_owned(),
                |s| s.to_string()
            ),
            onboard_out.display()
        )));
    }
    let figures = split_figures(&single, &split);
    let report = SplitReport {
        single,
        split,
        onboard_namespace: on_ns,
        offboard_namespace: off_ns,
        endpoint: format!("tcp/127.0.0.1:{port}"),
        figures,
    };
    print!("{}", render(&report.split));
    print!("{}", render_split(&report));
    write_json(args.json.as_deref(), &report)?;
    Ok(report)
}

/// Waits up to `patience` for `child` to end; its status, or `None` if it is still running.
fn wait_for(
    child: &mut std::process::Child,
    patience: std::time::Duration,
) -> Option<std::process::ExitStatus> {
    let deadline = std::time::Instant::now() + patience;
    loop {
        match child.try_wait() {
            Ok(Some(status)) => return Some(status),
            Ok(None) if std::time::Instant::now() < deadline => {
                std::thread::sleep(std::time::Duration::from_millis(50));
            }
            _ => return None,
        }
    }
}

/// The one-host run of `--split`: a `mole bench stack` of its own with every option of this one
/// but the output paths and the namespace.
fn run_single_child(args: &BenchStackArgs) -> Result<serde_json::Value, Failure> {
    let out = args.up.out.join("single");
    std::fs::create_dir_all(&out)
        .map_err(|e| Failure::input(format!("cannot create {}: {e}", out.display())))?;
    let json = out.join("bench.json");
    let exe = std::env::current_exe().map_err(|e| Failure::run(e.to_string()))?;
    let status = std::process::Command::new(exe)
        .args(["bench", "stack"])
        .arg(format!("--namespace={}-single", args.up.namespace))
        .arg("--out")
        .arg(&out)
        .arg("--json")
        .arg(&json)
        .args(options_but(&["--json", "--out", "--namespace"]))
        .stdout(std::process::Stdio::null())
        .status()
        .map_err(|e| Failure::run(format!("cannot start the one-host run: {e}")))?;
    if !status.success() {
        return Err(Failure::run(format!("the one-host run failed: {status}")));
    }
    let text = std::fs::read_to_string(&json)
        .map_err(|e| Failure::run(format!("no report of the one-host run: {e}")))?;
    serde_json::from_str(&text)
        .map_err(|e| Failure::run(format!("the one-host run's report is unreadable: {e}")))
}

/// Both runs' loop latency and steps/s, and split / single (NaN where single is 0).
fn split_figures(single: &serde_json::Value, split: &StackReport) -> SplitFigures {
    let ratio = |a: f64, b: f64| if b > 0.0 { a / b } else { f64::NAN };
    let lat = &split.loop_latency_us;
    let mut f = SplitFigures {
        single_loop_p50_us: number(&single["loop_latency_us"]["p50"]),
        single_loop_p99_us: number(&single["loop_latency_us"]["p99"]),
        single_steps_per_s: number(&single["steps_per_s"]),
        split_loop_p50_us: lat.p50.unwrap_or(0.0),
        split_loop_p99_us: lat.p99.unwrap_or(0.0),
        split_steps_per_s: split.steps_per_s,
        ..SplitFigures::default()
    };
    f.loop_p50_ratio = ratio(f.split_loop_p50_us, f.single_loop_p50_us);
    f.loop_p99_ratio = ratio(f.split_loop_p99_us, f.single_loop_p99_us);
    f.steps_per_s_ratio = ratio(f.split_steps_per_s, f.single_steps_per_s);
    f
}

/// The two runs side by side.
fn render_split(r: &SplitReport) -> String {
    let f = &r.figures;
    let mut s = String::new();
    let _ = writeln!(
        s,
        "\n{} run, one host against split in two (on board `{}`, off board `{}`, bridges over {})",
        r.split.mode, r.onboard_namespace, r.offboard_namespace, r.endpoint
    );
    let _ = writeln!(
        s,
        "{:<14} {:>12} {:>12} {:>14}",
        "", "one host", "split", "split / one"
    );
    for (what, single, split, ratio) in [
        (
            "loop p50 µs",
            f.single_loop_p50_us,
            f.split_loop_p50_us,
            f.loop_p50_ratio,
        ),
        (
            "loop p99 µs",
            f.single_loop_p99_us,
            f.split_loop_p99_us,
            f.loop_p99_ratio,
        ),
        (
            "steps/s",
            f.single_steps_per_s,
            f.split_steps_per_s,
            f.steps_per_s_ratio,
        ),
    ] {
        let _ = writeln!(s, "{what:<14} {single:>12.1} {split:>12.1} {ratio:>14.2}");
    }
    s
}

/// Fails early (exit 2) when the report could not be written at the end.
pub fn check_writable(path: &std::path::Path) -> Result<(), Failure> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    if !dir.is_dir() {
        return Err(Failure::input(format!(
            "cannot write {}: the directory {} does not exist",
            path.display(),
            dir.display()
        )));
    }
    let probe = dir.join(format!(".mole-write-test-{}", std::process::id()));
    std::fs::write(&probe, b"")
        .map_err(|e| Failure::input(format!("cannot write {}: {e}", path.display())))?;
    let _ = std::fs::remove_file(probe);
    Ok(())
}

fn render(r: &StackReport) -> String {
    let mut s = String::new();
    let lat = &r.loop_latency_us;
    let us = |v: Option<f64>| v.map_or("-".to_owned(), |v| format!("{v:.1}"));
    let _ = writeln!(
        s,
        "{} run: {} steps in {:.2} s = {:.0} steps/s\nloop latency (world state → command at the world): p50 {} µs, p99 {} µs, max {} µs",
        r.mode,
        r.ticks,
        r.wall_time_s,
        r.steps_per_s,
        us(lat.p50),
        us(lat.p99),
        us(lat.max)
    );
    let total: f64 = lat.histogram.iter().map(|[_, count]| count).sum();
    for &[upper, count] in &lat.histogram {
        if count > 0.0 {
            let bar = "#".repeat(((count / total.max(1.0)) * 50.0).ceil() as usize);
            let _ = writeln!(s, "  ≤ {upper:>9.0} µs {count:>8.0} {bar}");
        }
    }
    let _ = writeln!(
        s,
        "\n{:<24} {:<14} {:>8} {:>10} {:>10} {:>10} {:>8}",
        "topic", "at", "rate Hz", "p50 µs", "p99 µs", "max µs", "dropped"
    );
    for h in &r.hops {
        let _ = writeln!(
            s,
            "{:<24} {:<14} {:>8.1} {:>10.1} {:>10.1} {:>10.1} {:>8}",
            h.topic, h.at, h.rate_hz, h.p50_us, h.p99_us, h.max_us, h.dropped
        );
    }
    let _ = writeln!(
        s,
        "\n{:<14} {:>9} {:>9} {:>10} {:>9} {:>10} {:>10} {:>10}",
        "process", "cpu s", "cpu %", "peak MiB", "steps", "step µs", "around µs", "kernel µs"
    );
    for p in &r.processes {
        let c = p.per_step;
        let _ = writeln!(
            s,
            "{:<14} {:>9.2} {:>9.1} {:>10.1} {:>9} {:>10.1} {:>10.1} {:>10.1}",
            p.role,
            p.cpu_s,
            p.cpu_percent,
            p.peak_rss_mib,
            p.steps,
            c.step_us,
            c.runtime_us,
            c.kernel_us
        );
    }
    let _ = writeln!(
        s,
        "(per step: in the process's step function, in the runtime around it, and the kernel's \
         share of both)"
    );
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The split half's copy names the run's peer namespace, moves every endpoint to the
    /// run's port and keeps the scenario findable from anywhere.
    #[test]
    fn a_split_copy_meets_its_peer_on_the_runs_port() {
        let copy = split_copy(&split_file("offboard"), "bench-onboard", 40123).expect("a copy");
        let table: toml::Table = toml::from_str(&copy).expect("TOML");
        let bridge = &table["bridge"];
        assert_eq!(bridge["peer_namespace"].as_str(), Some("bench-onboard"));
        assert_eq!(
            bridge["connect"].as_array().expect("connect")[0].as_str(),
            Some("tcp/127.0.0.1:40123")
        );
        let scenario = PathBuf::from(table["stack"]["scenario"].as_str().expect("scenario"));
        assert!(
            scenario.is_absolute() && scenario.is_file(),
            "{}",
            scenario.display()
        );
        let crate::LaunchFile { bridge, .. } =
            crate::parse_launch_file(&copy, std::path::Path::new("offboard.toml"))
                .expect("the copy is a valid launch file");
        assert_eq!(bridge.expect("a bridge").peer_namespace, "bench-onboard");
    }

    /// Each target divides the figures issue #13 names and says whether its bound holds.
    #[test]
    fn targets_divide_the_figures_the_issue_names() {
        let f = TargetFigures {
            raw_chain_100hz_p50_us: 300.0,
            raw_chain_flat_out_p50_us: 250.0,
            raw_chain_flat_out_loops_per_s: 4000.0,
            runtime_chain_100hz_p50_us: 330.0,
            raw_event_hop_p50_us: 10.0,
            runtime_event_hop_p50_us: 13.0,
            realtime_loop_p50_us: 90.0,
            realtime_loop_p99_us: 600.0,
            realtime_stack_cpu_percent: 4.0,
            lockstep_steps_per_s: 6000.0,
        };
        let got: Vec<(f64, bool)> = ratios(&f)
            .iter()
            .map(|t| ((t.value * 1000.0).round() / 1000.0, t.met))
            .collect();
        assert_eq!(
            got,
            vec![
                (0.3, true),
                (2.0, false),
                (4.0, true),
                (1.5, false),
                (1.3, false),
                (1.1, true)
            ]
        );
        let none = ratios(&TargetFigures::default());
        assert!(
            none.iter().filter(|t| t.what.contains('/')).all(|t| !t.met),
            "a missing figure never meets a target"
        );
    }
}
