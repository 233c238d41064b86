//! The view of a recording (`mole view FILE`, `--file`): no IPC at all (no iceoryx2 node,
//! nothing in /dev/shm, no stack needed); the recording's samples feed the scene up to the tick
//! of a playback clock ([`Playback`]) that the page plays, pauses, seeks and speeds up.

use crate::server::{announce, listen, serve};
use crate::{Access, FrameClock, PageInput, Playback, Reel};
use mole_runtime::BadInput;
use std::net::SocketAddr;
use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

/// The recording's view: read the file (refused before anything is served), serve it on
/// `address` (its URL into `ready_file`), then every [`crate::FRAME_PERIOD`] the pages' timeline
/// ops, the clock, the frame at its tick; until Ctrl-C or SIGTERM.
pub fn show_recording(
    file: &Path,
    address: SocketAddr,
    ready_file: Option<&Path>,
) -> Result<(), Box<dyn std::error::Error>> {
    mole_runtime::init_tracing("view");
    let reel = Reel::read(file).map_err(|e| BadInput(e.to_string()))?;
    let mut playback = Playback::new(reel)
        .ok_or_else(|| BadInput(format!("{}: no world map to draw", file.display())))?;
    let (listener, url) = listen(address)?;
    let stop = Arc::new(AtomicBool::new(false));
    let flag = stop.clone();
    ctrlc::set_handler(move || flag.store(true, Ordering::SeqCst))?;
    let served = serve(listener, Access::Recording)?;
    announce(ready_file, &url)?;
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
        served.frames.send(playback.frame(served.rejected()));
        frames += 1;
    }
    served.finished(frames, started);
    Ok(())
}
