//! The player: a recording's samples of the roles it stands in for, published on their topics
//! with the recorded bytes (the header's tick from the file), in their place.
//!
//! With the world among them it keeps the stack's time, as the world does: in lockstep it
//! publishes step k and plays k+1 once every live role in the loop published its output of step
//! k (step k again after a second without them, as the world resends); in realtime it plays the
//! steps at their recorded times (`--rate` times as fast). Without the world it follows the live
//! world: each truth it publishes brings the recorded samples of its tick. The window's last
//! truth ends the run (marked as the end if the recording went on), so the monitor finishes
//! and writes its files; the player then waits to be stopped.

use clap::Parser;
use mole_recorder::cast::DEFAULT_REPLACED;
use mole_recorder::player::{Awaited, Outlets, Show, play};
use mole_runtime::{CommonArgs, Context, Wake};
use std::path::PathBuf;
use std::process::ExitCode;

/// mole's player: a recording's roles played back into a live stack
#[derive(Debug, Parser)]
#[command(name = "mole-player")]
struct Args {
    /// The recording (`mole up --record FILE`).
    file: PathBuf,
    #[command(flatten)]
    common: CommonArgs,
    /// The roles to play back, comma-separated.
    #[arg(long, default_value = DEFAULT_REPLACED)]
    replace: String,
    /// Realtime: play this many times as fast as recorded.
    #[arg(long, default_value_t = 1.0)]
    rate: f64,
    /// The first tick to play.
    #[arg(long, default_value_t = 0)]
    from: u64,
    /// The last tick to play.
    #[arg(long, default_value_t = u64::MAX)]
    to: u64,
}

fn main() -> ExitCode {
    mole_runtime::exit_code(run(&Args::parse()))
}

fn run(args: &Args) -> Result<(), Box<dyn std::error::Error>> {
    let show = Show::read(&args.file, &args.replace, args.rate, args.from, args.to)?;
    let mut ctx = Context::new(mole_types::graph::nodes::PLAYER, &args.common)?;
    let mut outlets = Outlets::open(&ctx, &show.cast.published())?;
    let mut awaited = Awaited::open(&ctx, &show.cast)?;
    let waitset = ctx.waitset()?;
    let wakers = awaited.wakers();
    let _attached = waitset.attach_all(&wakers)?;
    if let Some(map) = &show.tape.map {
        outlets.publish(map, false)?;
    }
    ctx.ready();
    let (replace, steps, last) = (show.cast.names(), show.tape.steps.len(), show.last);
    tracing::info!(%replace, steps, last, "playing");

    if !play(&show, &mut outlets, &mut awaited, &waitset, &mut ctx)? {
        return Ok(());
    }
    tracing::info!(last, "played every step; waiting to be stopped");
    while waitset.wait(&mut ctx, None)? != Wake::Shutdown {}
    Ok(())
}
