//! The recorder process: every topic of the namespace → one MCAP file.
//!
//! Every topic's queue (drained once a step in lockstep, woken by the truth; every
//! [`REALTIME_DRAIN`] in realtime, never woken) → records (the samples' own bytes) → a bounded
//! queue → the writer thread (chunks, LZ4, the file; a chunk closed every [`FLUSH_EVERY`]) → on
//! SIGINT/SIGTERM: the last samples, the recording's metadata, the summary and the footer.
//!
//! It publishes no statistics: it is an observer beside the stack, not one of its roles, and the
//! run's summary.json is the same with and without it.

mod taps;

use clap::Parser;
use mole_recorder::{
    Every, Record, RecordError, Recording, RunFacts, run_metadata, source_revision,
};
use mole_runtime::{BadInput, ClockMode, CommonArgs, Context, Wake};
use mole_types::{env, topics};
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::mpsc::{SyncSender, sync_channel};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};
use taps::Taps;

/// How often a realtime recorder drains its queues. The smallest queue of a topic published
/// every step holds 2 samples (`localization/particles`, `world/map`), 20 ms at 100 Hz: draining
/// every 10 ms leaves a scheduling delay of 10 ms before a sample is lost (and counted).
const REALTIME_DRAIN: Duration = Duration::from_millis(10);
/// How often the current chunk is closed and handed to the file: what a killed recorder loses.
const FLUSH_EVERY: Duration = Duration::from_secs(1);
/// Records between the reader and the writer: about 70 steps of the default stack. Full, it
/// holds the reader back, and then (lockstep) the stack, rather than losing samples.
const WRITER_QUEUE: usize = 1024;

#[derive(Debug, Parser)]
#[command(
    name = "mole-recorder",
    about = "mole's recorder: every topic of a stack into one MCAP file"
)]
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
    let cwd = std::env::current_dir()?;
    let facts = RunFacts {
        namespace: &args.common.namespace,
        clock_mode: args.common.mode.name(),
        rate_hz: args.common.rate_hz,
        launch_file: args.launch_file.as_deref(),
        scenario: args.scenario.as_deref(),
        revision: args
            .revision
            .clone()
            .unwrap_or_else(|| source_revision(&cwd)),
        every: every.describe(),
        settings: args.common.settings.as_deref().unwrap_or_default(),
    };
    let run_facts = run_metadata(&facts).map_err(BadInput)?;

    let mut ctx = Context::new("recorder", &args.common)?;
    ctx.silence_stats();
    let lockstep = ctx.mode() == ClockMode::Lockstep;
    let mut taps = Taps::open(&ctx, &every)?;
    // The file appears once every subscription is open: `mole up --record` waits for it before
    // it starts the stack, so no step goes unrecorded.
    let recording = Recording::create(&args.file, &topics::all(), run_facts)?;
    let (records, writer) = start_writer(recording)?;

    let waitset = ctx.waitset()?;
    let wakers = taps.wakers();
    let _attached = waitset.attach_all(&wakers)?;
    ctx.ready();
    let mut next_drain = Instant::now();
    let mut next_flush = Instant::now() + FLUSH_EVERY;
    let mut writing = true;
    // Wake-ups by a publisher (the truth in lockstep; none in realtime) and drains, for the log.
    let (mut woken, mut drains) = (0u64, 0u64);
    while writing {
        let wake = waitset.wait(&mut ctx, Some(next_drain.min(next_flush)))?;
        woken += u64::from(wake == Wake::Data);
        if lockstep || Instant::now() >= next_drain {
            drains += 1;
            taps.drain();
            writing = send(&records, &mut taps.seen.out);
            next_drain = Instant::now() + REALTIME_DRAIN;
        }
        if writing && Instant::now() >= next_flush {
            writing = records.send(Record::Flush).is_ok();
            next_flush = Instant::now() + FLUSH_EVERY;
        }
        if wake == Wake::Shutdown {
            break;
        }
    }

    taps.drain();
    taps.last_samples();
    send(&records, &mut taps.seen.out);
    let totals = taps.totals();
    let fallback_period_ns = (1e9 / args.common.rate_hz).round() as u64;
    let period_ns = taps.seen.period_ns.unwrap_or(fallback_period_ns);
    drop(records);
    let recording = writer
        .join()
        .map_err(|_| "the recorder's writer thread panicked")??;
    let written = recording.finish(period_ns, totals)?;
    tracing::info!(
        file = %args.file.display(),
        messages = written.messages,
        megabytes = written.bytes as f64 / 1e6,
        woken,
        drains,
        "recording finished"
    );
    Ok(())
}

/// Hands `out` to the writer; false when the writer has stopped (its error comes with `join`).
fn send(records: &SyncSender<Record>, out: &mut Vec<Record>) -> bool {
    out.drain(..).all(|record| records.send(record).is_ok())
}

/// The writer thread, which hands the file back to be finished once the reader hung up.
type Writer = JoinHandle<Result<Recording, RecordError>>;

/// The writer thread: applies every record to the file until the reader hangs up.
fn start_writer(mut recording: Recording) -> std::io::Result<(SyncSender<Record>, Writer)> {
    let (records, received) = sync_channel(WRITER_QUEUE);
    let writer = std::thread::Builder::new()
        .name("writer".into())
        .spawn(move || {
            for record in received {
                recording.apply(record)?;
            }
            Ok(recording)
        })?;
    Ok((records, writer))
}
