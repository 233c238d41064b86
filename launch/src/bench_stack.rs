//! `mole bench stack`: runs the full stack and reports how fast it went and where time went;
//! with `--targets`, measures the loop against raw iceoryx2 in one run (issue #13's targets).

use crate::stats::{HopLatency, ProcessUsage};
use crate::up::{Failure, UpArgs, up};
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
    const SET_HERE: [&str; 8] = [
        "--json",
        "--out",
        "--mode",
        "--ticks",
        "--duration",
        "--namespace",
        "--realtime-secs",
        "--lockstep-ticks",
    ];
    let mut forwarded = Vec::new();
    let mut options = std::env::args().skip_while(|a| a != "stack").skip(1);
    while let Some(option) = options.next() {
        let name = option.split('=').next().unwrap_or_default();
        if option == "--targets" {
            continue;
        }
        if SET_HERE.contains(&name) {
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
        "\n{:<14} {:>9} {:>9} {:>10} {:>9}",
        "process", "cpu s", "cpu %", "peak MiB", "steps"
    );
    for p in &r.processes {
        let _ = writeln!(
            s,
            "{:<14} {:>9.2} {:>9.1} {:>10.1} {:>9}",
            p.role, p.cpu_s, p.cpu_percent, p.peak_rss_mib, p.steps
        );
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

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
