//! `mole bench ipc`: the runtime against raw iceoryx2, a Unix socket, TCP and the floor under
//! them (a plain pipe wake-up between two processes), in one run.

use crate::bench_stack::check_writable;
use crate::up::Failure;
use clap::Args;
use mole_bench::{BenchError, IpcBenchConfig, IpcReport, print_table, run_ipc_bench, write_plot};
use std::path::PathBuf;

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
    let report = run_ipc_bench(&config).map_err(|e| match e {
        BenchError::UnsupportedSize(_) | BenchError::Config(_) => Failure::input(e.to_string()),
        other => Failure::run(other.to_string()),
    })?;
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
    Ok(report)
}
