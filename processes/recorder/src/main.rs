//! The recorder process: every topic of the namespace → one MCAP file.
//!
//! Every topic's queue (drained once a step in lockstep, woken by the truth; every
//! [`mole_recorder::reading::REALTIME_DRAIN`] in realtime, never woken) → records (the samples'
//! own bytes) → a bounded queue → the writer thread (chunks, LZ4, the file; a chunk closed every
//! [`mole_recorder::reading::FLUSH_EVERY`]) → on SIGINT/SIGTERM: the last samples, the
//! recording's metadata, the summary and the footer.
//!
//! It publishes no statistics: it is an observer beside the stack, not one of its roles, and the
//! run's summary.json is the same with and without it.

use clap::Parser;
use mole_recorder::{Every, Recording, Taps, WriterThread, read_until_shutdown, run_metadata_of};
use mole_runtime::{BadInput, CommonArgs, Context};
use mole_types::{env, topics};
use std::path::PathBuf;
use std::process::ExitCode;

/// mole's recorder: every topic of a stack into one MCAP file
#[derive(Debug, Parser)]
struct Args {
    /// The MCAP file to write (replaced if it exists).
    file: PathBuf,
    #[command(flatten)]
    common: CommonArgs,
    /// Write TOPIC's samples every N ticks only (repeatable; default mapping/grid=10 and
    /// mapping/contact=10; N = 1 writes every sample).
    #[arg(long = "every", value_name = "TOPIC=N")]
    every: Vec<String>,
    /// The launch file the stack runs: its path and text go into the file's metadata.
    #[arg(long)]
    launch_file: Option<PathBuf>,
    /// The scenario the world runs: its path and text go into the file's metadata.
    #[arg(long, env = env::SCENARIO)]
    scenario: Option<PathBuf>,
    /// The source revision (default: `git describe --always --dirty` of the working
    /// directory, `unknown` outside a git checkout).
    #[arg(long)]
    revision: Option<String>,
}

fn main() -> ExitCode {
    mole_runtime::exit_code(run(&Args::parse()))
}

fn run(args: &Args) -> Result<(), Box<dyn std::error::Error>> {
    let every = Every::parse(&args.every).map_err(|e| BadInput(format!("--every {e}")))?;
    let run_facts = run_metadata_of(
        &args.common,
        args.launch_file.as_deref(),
        args.scenario.as_deref(),
        args.revision.as_deref(),
        &every,
    )?;

    let mut ctx = Context::new(mole_types::graph::nodes::RECORDER, &args.common)?;
    ctx.silence_stats();
    let mut taps = Taps::open(&ctx, &every)?;
    // The file appears once every subscription is open: `mole up --record` waits for it before
    // it starts the stack, so no step goes unrecorded.
    let recording = Recording::create(&args.file, &topics::all(), run_facts)?;
    let mut writer = WriterThread::start(recording)?;

    let waitset = ctx.waitset()?;
    let wakers = taps.wakers();
    let _attached = waitset.attach_all(&wakers)?;
    ctx.ready();
    let reading = read_until_shutdown(&waitset, &mut ctx, &mut taps, &mut writer)?;

    let written = writer.finish(&mut taps, args.common.rate_hz)?;
    tracing::info!(
        file = %args.file.display(),
        messages = written.messages,
        megabytes = written.bytes as f64 / 1e6,
        woken = reading.woken,
        drains = reading.drains,
        "recording finished"
    );
    Ok(())
}
