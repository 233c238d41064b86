//! `mole bench peers`: the same four-process loop on raw iceoryx2, mole's runtime and dora-rs,
//! measured in one run (mole_bench::peers says how).

use crate::Failure;
use crate::bench_stack::check_writable;
use clap::Args;
use mole_bench::BenchError;
use mole_bench::peers::{PeerBenchConfig, PeerReport, format_peer_table, run_peer_bench};
use std::path::PathBuf;

#[derive(Debug, Args)]
pub struct BenchPeersArgs {
    /// Payload sizes in bytes, comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "64,4096")]
    pub sizes: Vec<usize>,
    /// Loops measured flat out, per build and size.
    #[arg(long, default_value_t = 5000)]
    pub loops: usize,
    /// Loops measured at --rate-hz, per build and size.
    #[arg(long, default_value_t = 500)]
    pub paced_loops: usize,
    /// The paced source's rate.
    #[arg(long, default_value_t = 100.0)]
    pub rate_hz: f64,
    /// A short run: 200 loops flat out and 20 paced.
    #[arg(long)]
    pub quick: bool,
    /// Where scripts/dora-env.sh installed dora (default: target/dora-env beside this binary's
    /// target directory).
    #[arg(long)]
    pub dora_dir: Option<PathBuf>,
    /// Fail (exit 2) when dora is not installed instead of skipping its rows.
    #[arg(long)]
    pub require_dora: bool,
    /// Write the report as JSON here.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Namespace prefix of the probe processes.
    #[arg(long, default_value = "peers")]
    pub namespace: String,
}

/// target/dora-env beside the target directory this binary was built into.
fn default_dora_dir() -> PathBuf {
    std::env::current_exe()
        .ok()
        .and_then(|exe| Some(exe.parent()?.parent()?.join("dora-env")))
        .unwrap_or_else(|| PathBuf::from("target/dora-env"))
}

/// Runs the peer benchmark, prints the table and writes the JSON if asked.
pub fn bench_peers(args: &BenchPeersArgs) -> Result<PeerReport, Failure> {
    if let Some(path) = &args.json {
        check_writable(path)?;
    }
    let mut config = if args.quick {
        PeerBenchConfig::quick()
    } else {
        PeerBenchConfig {
            loops: args.loops,
            paced_loops: args.paced_loops,
            ..PeerBenchConfig::default()
        }
    };
    config.sizes = args.sizes.clone();
    config.rate_hz = args.rate_hz;
    config.namespace = format!("{}-{}", args.namespace, std::process::id());
    config.dora_dir = args.dora_dir.clone().unwrap_or_else(default_dora_dir);
    config.require_dora = args.require_dora;
    let report = run_peer_bench(&config).map_err(|e| match e {
        BenchError::UnsupportedSize(_) | BenchError::Config(_) => Failure::input(e.to_string()),
        other => Failure::run(other.to_string()),
    })?;
    print!("{}", format_peer_table(&report));
    if let Some(path) = &args.json {
        let json =
            serde_json::to_string_pretty(&report).map_err(|e| Failure::run(e.to_string()))?;
        std::fs::write(path, json + "\n")
            .map_err(|e| Failure::input(format!("cannot write {}: {e}", path.display())))?;
    }
    Ok(report)
}
