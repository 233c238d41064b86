//! The view process: a live picture of the stack in a browser.
//!
//! Every shown topic (read at the view's own pace: woken by the truth once a step in lockstep,
//! never woken in realtime) → the scene → every [`mole_view::FRAME_PERIOD`] a frame → the server
//! thread → each page (only what changed for it). A page's goals and paces → the main loop →
//! `operator/goal`, `operator/pace`.
//!
//! It publishes no statistics: like the recorder it is an observer beside the stack, not one of
//! its roles, and the run's summary.json is the same with and without it.
//!
//! With `--file FILE` it shows a recording instead: no IPC at all (no iceoryx2 node, nothing in
//! /dev/shm, no stack needed); the recording's samples feed the scene up to the tick of a
//! playback clock that the page plays, pauses, seeks and speeds up (`mole_view::Playback`).

use clap::Parser;
use mole_runtime::{CommonArgs, Context, Wake};
use mole_view::{Access, Controls, DEFAULT_PORT, FrameClock, Scene, ServerFlags, Taps};
use mole_view::{announce, listen, serve, show_recording};
use std::net::SocketAddr;
use std::process::ExitCode;
use std::time::Instant;

/// mole's live view: the running stack in a browser
#[derive(Debug, Parser)]
struct Args {
    #[command(flatten)]
    common: CommonArgs,
    /// Where it serves (default port 7777), whether pages steer, a recording with a timeline.
    #[command(flatten)]
    serve: ServerFlags,
}

fn main() -> ExitCode {
    mole_runtime::exit_code(run(&Args::parse()))
}

fn run(args: &Args) -> Result<(), Box<dyn std::error::Error>> {
    let address = args.serve.address(DEFAULT_PORT);
    match &args.serve.file {
        Some(file) => show_recording(file, address, args.serve.ready_file.as_deref()),
        None => live(args, address),
    }
}

/// The live view of the stack in the namespace `--namespace` names.
fn live(args: &Args, address: SocketAddr) -> Result<(), Box<dyn std::error::Error>> {
    let (listener, url) = listen(address)?;
    let mut ctx = Context::new(mole_types::graph::nodes::VIEW, &args.common)?;
    ctx.silence_stats();
    let (mode, controls) = (ctx.mode(), !args.serve.no_controls);
    let mut taps = Taps::open(&ctx)?;
    let mut operator = Controls::open(&ctx)?;
    let served = serve(listener, Access::Live { controls })?;
    let waitset = ctx.waitset()?;
    let wakers = taps.wakers(mode);
    let _attached = waitset.attach_all(&wakers)?;
    ctx.ready();
    announce(args.serve.ready_file.as_deref(), &url)?;
    tracing::info!(%url, %mode, controls, "serving the view");

    let (mut scene, mut frames, started) = (None, 0u64, Instant::now());
    let mut schedule = FrameClock::new(started);
    loop {
        let wake = waitset.wait(&mut ctx, Some(schedule.next()))?;
        taps.drain(&mut scene, mode.name(), controls);
        let tick = scene.as_ref().map_or(0, Scene::tick);
        operator.publish(served.commands.try_iter().collect(), tick)?;
        if schedule.due(Instant::now())
            && let Some(scene) = scene.as_mut()
        {
            served.frames.send(scene.frame(served.rejected()));
            frames += 1;
        }
        if wake == Wake::Shutdown {
            break;
        }
    }
    served.finished(frames, started);
    Ok(())
}
