//! `mole bench stack`: runs the full stack and reports how fast it went and where time went.

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

/// Runs the stack (no progress bar) and prints the report; `--json` writes it too.
pub fn bench_stack(args: &BenchStackArgs) -> Result<StackReport, Failure> {
    if let Some(path) = &args.json {
        check_writable(path)?;
    }
    let mut up_args = args.up.clone();
    up_args.quiet = true;
    let outcome = up(&up_args)?;
    let summary = &outcome.summary;
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
    print!("{}", render(&report));
    if let Some(path) = &args.json {
        let json =
            serde_json::to_string_pretty(&report).map_err(|e| Failure::run(e.to_string()))?;
        std::fs::write(path, json + "\n")
            .map_err(|e| Failure::input(format!("cannot write {}: {e}", path.display())))?;
    }
    Ok(report)
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
