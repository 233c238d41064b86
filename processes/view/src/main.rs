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

mod server;
mod taps;

use clap::Parser;
use mole_runtime::{BadInput, CommonArgs, Context, Publisher, Wake, now_ns};
use mole_types::{Goal, PACE_PAUSE, PACE_RUN, PACE_STEP, Pace, topics};
use mole_view::{Access, DEFAULT_PORT, FrameClock, PageInput, Playback, Reel, Scene};
use std::net::{IpAddr, Ipv4Addr, SocketAddr};
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;
use taps::Taps;

#[derive(Debug, Parser)]
#[command(
    name = "mole-view",
    about = "mole's live view: the running stack in a browser"
)]
struct Args {
    #[command(flatten)]
    common: CommonArgs,
    /// The port to serve on (0: any free port).
    #[arg(long, default_value_t = DEFAULT_PORT)]
    port: u16,
    /// The address to serve on. Anyone who can reach it sees the run and, unless
    /// --no-controls, can steer the robot.
    #[arg(long, default_value_t = IpAddr::V4(Ipv4Addr::LOCALHOST))]
    bind: IpAddr,
    /// Refuse goals, pauses and steps from the page (it only watches).
    #[arg(long)]
    no_controls: bool,
    /// Show this recording (`mole up --record FILE`) instead of a running stack, with a
    /// timeline; no IPC.
    #[arg(long, conflicts_with = "no_controls")]
    file: Option<PathBuf>,
    /// Once serving, write the page's URL into this file (the launcher waits for it).
    #[arg(long)]
    ready_file: Option<PathBuf>,
}

fn main() -> ExitCode {
    mole_runtime::exit_code(run(&Args::parse()))
}

/// The operator topics the page's controls publish on.
struct Controls {
    goal: Publisher<Goal>,
    pace: Publisher<Pace>,
}

impl Controls {
    /// Publishes `command` at `tick`; of several goals at once only the newest counts.
    fn publish(
        &mut self,
        commands: Vec<PageInput>,
        tick: u64,
    ) -> Result<(), mole_runtime::RuntimeError> {
        let newest_goal = commands
            .iter()
            .rposition(|c| matches!(c, PageInput::Goal { .. }));
        for (i, command) in commands.into_iter().enumerate() {
            tracing::info!(?command, tick, "from the page");
            let (op, steps) = match command {
                PageInput::Goal { x, y } if Some(i) == newest_goal => {
                    self.goal
                        .publish(tick, now_ns(), |g| (g.x, g.y, g.tolerance) = (x, y, 0.0))?;
                    continue;
                }
                PageInput::Goal { .. } => continue,
                PageInput::Run => (PACE_RUN, 0),
                PageInput::Pause => (PACE_PAUSE, 0),
                PageInput::Step { steps } => (PACE_STEP, steps),
                // The server refuses timeline ops in a live view.
                PageInput::Timeline(_) => continue,
            };
            self.pace
                .publish(tick, now_ns(), |p| (p.op, p.steps) = (op, steps))?;
        }
        Ok(())
    }
}

fn run(args: &Args) -> Result<(), Box<dyn std::error::Error>> {
    match &args.file {
        Some(file) => recording(file, args),
        None => live(args),
    }
}

/// The listener on `--bind`:`--port` (in use → bad input) and the page's URL.
fn listen(args: &Args) -> Result<(std::net::TcpListener, String), Box<dyn std::error::Error>> {
    let address = SocketAddr::new(args.bind, args.port);
    let listener = std::net::TcpListener::bind(address)
        .map_err(|e| BadInput(format!("cannot serve the view on {address}: {e}")))?;
    let url = format!("http://{}/", listener.local_addr()?);
    Ok((listener, url))
}

/// Says the page is served: its URL into `--ready-file`, for the launcher.
fn announce(args: &Args, url: &str) -> std::io::Result<()> {
    if let Some(file) = &args.ready_file {
        std::fs::write(file, url)?;
    }
    Ok(())
}

/// The recording's view: read the file (refused before anything is served), then every
/// [`mole_view::FRAME_PERIOD`] the pages' timeline ops, the clock, the frame at its tick; until Ctrl-C or
/// SIGTERM.
fn recording(file: &std::path::Path, args: &Args) -> Result<(), Box<dyn std::error::Error>> {
    mole_runtime::init_tracing("view");
    let reel = Reel::read(file).map_err(|e| BadInput(e.to_string()))?;
    let mut playback = Playback::new(reel)
        .ok_or_else(|| BadInput(format!("{}: no world map to draw", file.display())))?;
    let (listener, url) = listen(args)?;
    let stop = Arc::new(AtomicBool::new(false));
    let flag = stop.clone();
    ctrlc::set_handler(move || flag.store(true, Ordering::SeqCst))?;
    let served = server::serve(listener, Access::Recording)?;
    announce(args, &url)?;
    let timeline = playback.clock.timeline();
    tracing::info!(
        %url,
        file = %file.display(),
        first_tick = timeline.first_tick,
        last_tick = timeline.last_tick,
        "serving the recording's view"
    );
    let mut frames = 0u64;
    let mut last = Instant::now();
    let (started, mut schedule) = (last, FrameClock::new(last));
    while !stop.load(Ordering::SeqCst) {
        std::thread::sleep(schedule.next().saturating_duration_since(Instant::now()));
        if !schedule.due(Instant::now()) {
            continue;
        }
        for command in served.commands.try_iter() {
            if let PageInput::Timeline(op) = command {
                tracing::debug!(?op, "from the page");
                playback.clock.apply(op);
            }
        }
        let now = Instant::now();
        playback.clock.advance(now - last);
        last = now;
        let rejected = served.rejected.load(Ordering::Relaxed);
        served.frames.send(playback.frame(rejected));
        frames += 1;
    }
    tracing::info!(
        frames,
        elapsed_s = started.elapsed().as_secs_f64(),
        rejected_inputs = served.rejected.load(Ordering::Relaxed),
        "view finished"
    );
    Ok(())
}

/// The live view of the stack in the namespace `--namespace` names.
fn live(args: &Args) -> Result<(), Box<dyn std::error::Error>> {
    let (listener, url) = listen(args)?;
    let mut ctx = Context::new("view", &args.common)?;
    ctx.silence_stats();
    let mode = ctx.mode();
    let mut taps = Taps::open(&ctx)?;
    let mut controls = Controls {
        goal: ctx.publisher(topics::OPERATOR_GOAL)?,
        pace: ctx.publisher(topics::OPERATOR_PACE)?,
    };
    let served = server::serve(
        listener,
        Access::Live {
            controls: !args.no_controls,
        },
    )?;
    let waitset = ctx.waitset()?;
    let wakers = taps.wakers(mode);
    let _attached = waitset.attach_all(&wakers)?;
    ctx.ready();
    announce(args, &url)?;
    tracing::info!(%url, %mode, controls = !args.no_controls, "serving the view");

    let mut scene: Option<Scene> = None;
    let mut frames = 0u64;
    let started = Instant::now();
    let mut schedule = FrameClock::new(started);
    loop {
        let wake = waitset.wait(&mut ctx, Some(schedule.next()))?;
        taps.drain(&mut scene, mode.name(), !args.no_controls);
        let commands: Vec<PageInput> = served.commands.try_iter().collect();
        if !commands.is_empty() {
            let tick = scene.as_ref().map_or(0, Scene::tick);
            controls.publish(commands, tick)?;
        }
        if schedule.due(Instant::now())
            && let Some(scene) = scene.as_mut()
        {
            let rejected = served.rejected.load(Ordering::Relaxed);
            served.frames.send(scene.frame(rejected));
            frames += 1;
        }
        if wake == Wake::Shutdown {
            break;
        }
    }
    tracing::info!(
        frames,
        elapsed_s = started.elapsed().as_secs_f64(),
        rejected_inputs = served.rejected.load(Ordering::Relaxed),
        "view finished"
    );
    Ok(())
}
