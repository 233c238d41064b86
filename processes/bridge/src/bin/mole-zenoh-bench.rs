//! `mole-zenoh-bench`: zenoh's latency and throughput on loopback TCP, for `mole bench ipc`
//! (the launcher does not link zenoh, so it runs this and reads its JSON from standard output).
//!
//! Two zenoh sessions in two processes, both peers that find nobody by multicast: this one
//! listens on `tcp/127.0.0.1:<free port>` and starts a copy of itself (`--echo`) that connects
//! to it. Every sample goes with CongestionControl::Block and express.
//! - latency: ping → echo → pong, one at a time; each round trip / 2 is one sample;
//! - throughput: one publisher flat out for a fixed time, the echo counts what arrives and
//!   answers with its count when the end marker comes (after every sample: Block is reliable
//!   and in order).

use clap::Parser;
use mole_bridge::zenoh_bench::{BenchPlan, bench, echo};
use std::process::ExitCode;

#[derive(Debug, Parser)]
#[command(
    name = "mole-zenoh-bench",
    about = "zenoh over loopback TCP between two processes: latency by payload size and throughput, as JSON (for `mole bench ipc`)"
)]
struct Args {
    /// Payload sizes in bytes, comma-separated.
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "64,1024,16384,262144,1048576,4194304"
    )]
    sizes: Vec<usize>,
    /// Measured round trips per size below 1 MiB.
    #[arg(long, default_value_t = 2000)]
    samples: usize,
    /// Measured round trips per size at 1 MiB and above.
    #[arg(long, default_value_t = 300)]
    samples_large: usize,
    /// How long the throughput publisher sends, at the largest size (s).
    #[arg(long, default_value_t = 1.0)]
    throughput_secs: f64,
    /// How long to wait for one answer of the echo before giving up (ms).
    #[arg(long, default_value_t = 5000)]
    timeout_ms: u64,
    /// Be the echo: connect to this endpoint and answer every ping (started by the benchmark).
    #[arg(long, hide = true, requires = "prefix")]
    echo_of: Option<String>,
    /// The keys' common prefix (the benchmark's own, so two runs never meet).
    #[arg(long, hide = true)]
    prefix: Option<String>,
}

fn main() -> ExitCode {
    let args = Args::parse();
    let result = match (&args.echo_of, &args.prefix) {
        (Some(endpoint), Some(prefix)) => echo(endpoint, prefix),
        _ => bench(&BenchPlan {
            sizes: &args.sizes,
            samples: args.samples,
            samples_large: args.samples_large,
            throughput_secs: args.throughput_secs,
            timeout_ms: args.timeout_ms,
        })
        .map(|report| println!("{report}")),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("mole-zenoh-bench: {e}");
            ExitCode::FAILURE
        }
    }
}
