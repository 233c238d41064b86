//! The Foxglove server process: the stack (or a recording) as the Foxglove app sees it.
//!
//! Every topic's queue (the recorder's taps, drained once a step in lockstep, woken by the
//! truth; every 10 ms in realtime) → records → the channels a client subscribed to (raw
//! layouts, and Foxglove's well-known schemas) → the SDK's server. A client's goals and paces →
//! `operator/goal`, `operator/pace`; its parameters and service calls → the launcher's
//! `stack/control`, as `mole param`, `mole swap` and `mole stop` send them.
//!
//! It publishes no statistics: like the recorder it is an observer beside the stack, not one of
//! its roles. With `--file FILE` it serves a recording instead, with playback control and no
//! IPC at all.

use clap::Parser;
use mole_foxglove::{DEFAULT_PORT, Relay, Replay, Serving, play, serve};
use mole_recorder::tape::{Window, read_tape};
use mole_recorder::{Every, Taps, read_until_shutdown};
use mole_runtime::{BadInput, CommonArgs, Context};
use mole_types::{graph::nodes, topics};
use mole_view::{Controls, ServerFlags, announce};
use std::net::SocketAddr;
use std::path::Path;
use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

/// mole's Foxglove server: a running stack or a recording over the Foxglove WebSocket protocol
#[derive(Debug, Parser)]
struct Args {
    #[command(flatten)]
    common: CommonArgs,
    /// Where it serves (default port 8765), whether clients steer (goals, paces, settings,
    /// swaps), a recording with playback control.
    #[command(flatten)]
    serve: ServerFlags,
}

fn main() -> ExitCode {
    mole_runtime::exit_code(run(&Args::parse()))
}

fn run(args: &Args) -> Result<(), Box<dyn std::error::Error>> {
    let address = args.serve.address(DEFAULT_PORT);
    match &args.serve.file {
        Some(file) => serve_recording(file, address, args.serve.ready_file.as_deref()),
        None => live(args, address),
    }
}

/// The stack in the namespace `--namespace` names, until it ends.
fn live(args: &Args, address: SocketAddr) -> Result<(), Box<dyn std::error::Error>> {
    let mut ctx = Context::new(nodes::FOXGLOVE, &args.common)?;
    ctx.silence_stats();
    let controls = !args.serve.no_controls;
    let serving = Serving::Live {
        namespace: ctx.namespace().to_string(),
        controls,
    };
    let served = serve(address, serving)?;
    let every = Every::parse(&[
        format!("{}=1", topics::MAPPING_GRID.name),
        format!("{}=1", topics::MAPPING_CONTACT.name),
    ])
    .map_err(BadInput)?;
    let mut taps = Taps::open(&ctx, &every)?;
    let operator = controls.then(|| Controls::open(&ctx)).transpose()?;
    let url = served.url.clone();
    let mut relay = Relay::new(served, operator, args.common.rate_hz);
    let waitset = ctx.waitset()?;
    let wakers = taps.wakers();
    let _attached = waitset.attach_all(&wakers)?;
    ctx.ready();
    announce(args.serve.ready_file.as_deref(), &url)?;
    tracing::info!(%url, mode = %ctx.mode(), controls, "serving Foxglove");

    let reading = read_until_shutdown(&waitset, &mut ctx, &mut taps, &mut relay)?;
    tracing::info!(
        woken = reading.woken,
        drains = reading.drains,
        "the stack ended"
    );
    if let Some(e) = relay.failed.take() {
        return Err(e.into());
    }
    relay.served.finish();
    Ok(())
}

/// A recording, with playback control, until Ctrl-C or SIGTERM.
fn serve_recording(
    file: &Path,
    address: SocketAddr,
    ready_file: Option<&Path>,
) -> Result<(), Box<dyn std::error::Error>> {
    // No Context here (no IPC): the log is set up as a process's would be.
    mole_runtime::init_tracing(nodes::FOXGLOVE);
    let names: Vec<&str> = topics::all().into_iter().map(|(name, _)| name).collect();
    let tape = read_tape(file, &names, Window::ALL).map_err(|e| BadInput(e.to_string()))?;
    let mut replay = Replay::new(tape).ok_or_else(|| {
        BadInput(format!(
            "{}: a recording of no step (nothing to play)",
            file.display()
        ))
    })?;
    let stop = Arc::new(AtomicBool::new(false));
    let flag = stop.clone();
    ctrlc::set_handler(move || flag.store(true, Ordering::SeqCst))?;
    let serving = Serving::Recording {
        clock: replay.clock.clone(),
        period_ns: replay.period_ns,
    };
    let mut served = serve(address, serving)?;
    announce(ready_file, &served.url)?;
    tracing::info!(url = served.url, file = %file.display(), "serving a recording to Foxglove");
    play(&mut replay, &mut served, || stop.load(Ordering::SeqCst));
    served.finish();
    Ok(())
}
