//! `mole-observer`: reads every topic of the stack and does next to nothing with it, as a
//! monitor or a viewer would; a launch file adds N of them to measure what observers cost.
//!
//! ```toml
//! [[process]]
//! role = "observer-1"
//! command = "mole-observer"
//! args = ["--role", "observer-1"]
//! ```

use clap::Parser;
use mole_bench::observer::EveryTopic;
use mole_runtime::{CommonArgs, Flow, Process};
use std::process::ExitCode;
use std::time::Duration;

/// Wake at least this often even when no step closes (a stalled stack, the end of a run).
const PERIOD: Duration = Duration::from_millis(200);

/// an observer that reads every topic of the stack (cost measurements)
#[derive(Debug, Parser)]
#[command(name = "mole-observer")]
struct Args {
    #[command(flatten)]
    common: CommonArgs,
    /// Its role: a name of its own in the stack, as the launch file's `role` (`observer-3`).
    #[arg(long, default_value = "observer")]
    role: String,
}

fn main() -> ExitCode {
    mole_runtime::exit_code(run(&Args::parse()))
}

fn run(args: &Args) -> Result<(), Box<dyn std::error::Error>> {
    let mut p = Process::new(&args.role, &args.common)?;
    let every = EveryTopic::subscribe(&mut p)?;
    p.observe(
        PERIOD,
        |start| {
            let mut every = every;
            every.on_map(start.map);
            Ok(every)
        },
        |every, seen| {
            every.drain(seen);
            if seen.shutdown() {
                log_tally(every);
            }
            Ok(Flow::Continue)
        },
    )
}

/// Logs what the observer read, per topic, at its end.
fn log_tally(every: &EveryTopic) {
    let tally = every.tally();
    let read: Vec<String> = every
        .names
        .iter()
        .zip(&tally.samples)
        .map(|(name, n)| format!("{name} {n}"))
        .collect();
    tracing::info!(
        checksum = tally.checksum,
        "read: world/map {}, {}",
        tally.map_samples,
        read.join(", ")
    );
}
