//! `mole bench ipc`: the runtime against raw iceoryx2, a Unix socket, TCP and the floor under
//! them (a plain pipe wake-up between two processes), and zenoh over loopback TCP, in one run.
//!
//! The launcher does not link zenoh: the zenoh rows come from mole-bridge's `mole-zenoh-bench`
//! (found next to `mole`, like the stack's programs), which prints its samples as JSON.

use crate::Failure;
use crate::bench_stack::check_writable;
use crate::supervisor::resolve_program;
use clap::Args;
use mole_bench::{
    BenchError, IpcBenchConfig, IpcReport, Summary, ZenohLatencyPoint, ZenohReport,
    ZenohThroughput, print_table, run_ipc_bench, write_plot,
};
use serde::Deserialize;
use std::path::{Path, PathBuf};

/// mole-bridge's zenoh benchmark, which `mole bench ipc` runs for its zenoh rows.
pub const ZENOH_BENCH: &str = "mole-zenoh-bench";

#[derive(Debug, Args)]
pub struct BenchIpcArgs {
    /// Payload sizes in bytes, comma-separated (default: 64,1024,16384,262144,1048576,4194304).
    #[arg(long, value_delimiter = ',')]
    pub sizes: Option<Vec<usize>>,
    /// A short run (few samples, 64 B and 1 MiB, fan-out 1 and 2).
    #[arg(long)]
    pub quick: bool,
    /// Write the report as JSON here.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Write the latency plot (SVG) here.
    #[arg(long)]
    pub plot: Option<PathBuf>,
    /// Namespace prefix of the probe processes.
    #[arg(long, default_value = "bench")]
    pub namespace: String,
}

/// Runs the IPC benchmark, prints the table, writes the JSON and the plot if asked.
pub fn bench_ipc(args: &BenchIpcArgs) -> Result<IpcReport, Failure> {
    for path in args.json.iter().chain(args.plot.iter()) {
        check_writable(path)?;
    }
    let mut config = if args.quick {
        IpcBenchConfig::quick()
    } else {
        IpcBenchConfig::default()
    };
    config.namespace = format!("{}-{}", args.namespace, std::process::id());
    if let Some(sizes) = &args.sizes {
        config.sizes = sizes.clone();
    }
    let mut report = run_ipc_bench(&config).map_err(|e| match e {
        BenchError::UnsupportedSize(_) | BenchError::Config(_) => Failure::input(e.to_string()),
        other => Failure::run(other.to_string()),
    })?;
    let zenoh = bench_zenoh(&config);
    report.zenoh = zenoh.as_ref().ok().cloned().flatten();
    print_table(&report);
    if let Some(path) = &args.json {
        let json =
            serde_json::to_string_pretty(&report).map_err(|e| Failure::run(e.to_string()))?;
        std::fs::write(path, json + "\n")
            .map_err(|e| Failure::input(format!("cannot write {}: {e}", path.display())))?;
    }
    if let Some(path) = &args.plot {
        write_plot(&report, path).map_err(|e| Failure::input(e.to_string()))?;
    }
    zenoh?;
    Ok(report)
}

/// Runs `mole-zenoh-bench` with the run's sizes, sample counts, throughput time and timeout;
/// `None` (said on standard error) when it is not there, an error when it fails.
fn bench_zenoh(config: &IpcBenchConfig) -> Result<Option<ZenohReport>, Failure> {
    let exe = std::env::current_exe().map_err(|e| Failure::run(e.to_string()))?;
    let beside = exe.parent().unwrap_or(Path::new("."));
    let program = match resolve_program(ZENOH_BENCH, beside) {
        Ok(program) => program,
        Err(e) => {
            eprintln!(
                "no zenoh rows: {e}; build it with `cargo build --release -p mole-bridge` \
                 (`cargo build -p mole-bridge` for a debug mole)"
            );
            return Ok(None);
        }
    };
    let sizes: Vec<String> = config.sizes.iter().map(usize::to_string).collect();
    let output = std::process::Command::new(&program)
        .arg(format!("--sizes={}", sizes.join(",")))
        .arg(format!("--samples={}", config.samples))
        .arg(format!("--samples-large={}", config.samples_large))
        .arg(format!("--throughput-secs={}", config.throughput_secs))
        .arg(format!("--timeout-ms={}", config.timeout_ms))
        .stderr(std::process::Stdio::inherit())
        .output()
        .map_err(|e| Failure::run(format!("cannot start {}: {e}", program.display())))?;
    if !output.status.success() {
        return Err(Failure::run(format!(
            "{} failed ({}): no zenoh rows",
            program.display(),
            output.status
        )));
    }
    zenoh_report(&output.stdout)
        .map(Some)
        .map_err(|e| Failure::run(format!("{}'s report: {e}", program.display())))
}

/// What `mole-zenoh-bench` prints: every one-way sample, the flood's counts.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct ZenohRun {
    setup: String,
    latency: Vec<ZenohRunLatency>,
    throughput: ZenohRunThroughput,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct ZenohRunLatency {
    size: usize,
    one_way_ns: Vec<u64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct ZenohRunThroughput {
    size: usize,
    sent: u64,
    send_ns: u64,
    received: u64,
    span_ns: u64,
}

/// Summarises `mole-zenoh-bench`'s JSON; a point without samples or a flood that lost
/// messages (Block is reliable) is an error, not a row.
fn zenoh_report(json: &[u8]) -> Result<ZenohReport, String> {
    let run: ZenohRun = serde_json::from_slice(json).map_err(|e| e.to_string())?;
    let latency = run
        .latency
        .into_iter()
        .map(|mut p| {
            Summary::from_ns(&mut p.one_way_ns)
                .map(|latency| ZenohLatencyPoint {
                    size: p.size,
                    latency,
                })
                .ok_or(format!("no latency samples at {} B", p.size))
        })
        .collect::<Result<Vec<_>, _>>()?;
    let t = run.throughput;
    if t.sent == 0 || t.send_ns == 0 {
        return Err("the throughput run sent nothing".to_owned());
    }
    if t.received != t.sent {
        return Err(format!(
            "the throughput run sent {} messages with CongestionControl::Block but {} arrived",
            t.sent, t.received
        ));
    }
    let received_per_s = if t.received >= 2 && t.span_ns > 0 {
        (t.received - 1) as f64 / (t.span_ns as f64 / 1e9)
    } else {
        t.sent as f64 / (t.send_ns as f64 / 1e9)
    };
    Ok(ZenohReport {
        setup: run.setup,
        latency,
        throughput: ZenohThroughput {
            size: t.size,
            sent: t.sent,
            received: t.received,
            sent_per_s: t.sent as f64 / (t.send_ns as f64 / 1e9),
            received_per_s,
            megabytes_per_s: received_per_s * t.size as f64 / 1e6,
        },
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The samples become percentiles of the one-way latency, the counts rates.
    #[test]
    fn the_zenoh_run_becomes_rows() {
        let json = br#"{"setup":"two processes","latency":[{"size":64,"one_way_ns":[3000,1000,2000]}],
            "throughput":{"size":1048576,"sent":11,"send_ns":1000000000,"received":11,"span_ns":500000000}}"#;
        let report = zenoh_report(json).expect("a report");
        assert_eq!(report.latency.len(), 1);
        assert_eq!(report.latency[0].size, 64);
        assert_eq!(report.latency[0].latency.p50_us, 2.0);
        assert_eq!(report.latency[0].latency.count, 3);
        let t = &report.throughput;
        assert_eq!((t.sent_per_s, t.received_per_s), (11.0, 20.0));
        assert!((t.megabytes_per_s - 20.0 * 1.048576).abs() < 1e-9);
    }

    /// Missing samples, lost messages and garbage are errors that say what is wrong.
    #[test]
    fn a_broken_zenoh_run_is_refused_with_a_reason() {
        let empty = br#"{"setup":"","latency":[{"size":64,"one_way_ns":[]}],
            "throughput":{"size":64,"sent":1,"send_ns":1,"received":1,"span_ns":0}}"#;
        assert!(
            zenoh_report(empty)
                .unwrap_err()
                .contains("no latency samples at 64 B")
        );
        let lost = br#"{"setup":"","latency":[],
            "throughput":{"size":64,"sent":10,"send_ns":1,"received":9,"span_ns":1}}"#;
        assert!(zenoh_report(lost).unwrap_err().contains("but 9 arrived"));
        assert!(zenoh_report(b"not json").is_err());
    }
}
