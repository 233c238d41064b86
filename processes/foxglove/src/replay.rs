//! A recording served: its samples, read once, are written up to the tick of a playback clock
//! (the view's: play, pause, seek, speed, paced by the recorded simulated time) that clients
//! move through the protocol's playback control. After a seek, the newest sample at or before
//! the new tick of every topic is written first, so a client sees the map, the grids and the
//! pose of that moment at once.

use crate::server::{Served, playback_state};
use mole_recorder::tape::Tape;
use mole_view::Clock;
use std::collections::BTreeMap;
use std::ops::Bound;
use std::sync::atomic::Ordering;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// How often the clock is read and what it passed is written.
pub const PLAYBACK_PERIOD: Duration = Duration::from_millis(20);

/// A recording and where its playback is.
pub struct Replay {
    tape: Tape,
    pub clock: Arc<Mutex<Clock>>,
    pub period_ns: u64,
    /// The newest tick written.
    written: Option<u64>,
    seeks_seen: u64,
}

impl Replay {
    /// The playback of `tape`, paused at its first tick; `None` for a recording of no step.
    pub fn new(tape: Tape) -> Option<Replay> {
        let (first, last) = tape.ticks()?;
        let period_ns = tape.fact("period_ns")?.parse().ok()?;
        Some(Replay {
            clock: Arc::new(Mutex::new(Clock::new(first, last, period_ns))),
            tape,
            period_ns,
            written: None,
            seeks_seen: 0,
        })
    }

    /// Moves the clock on by `wall` and writes what it passed; after a seek (or at the start),
    /// the state at the clock's tick.
    pub fn advance(&mut self, served: &mut Served, wall: Duration) {
        let (tick, before) = {
            let Ok(mut clock) = self.clock.lock() else {
                return;
            };
            let before = playback_state(&clock, self.period_ns).status;
            clock.advance(wall);
            (clock.tick(), before)
        };
        let seeks = served.heard.seeked.load(Ordering::Relaxed);
        served.resend_subscribed();
        match self.written {
            Some(written) if seeks == self.seeks_seen && tick >= written => {
                let passed = (Bound::Excluded(written), Bound::Included(tick));
                for samples in self.tape.steps.range(passed).map(|(_, s)| s) {
                    for s in samples {
                        served.channels.log(&s.topic, s.log_time, &s.data);
                    }
                }
            }
            _ => self.write_state_at(served, tick),
        }
        self.seeks_seen = seeks;
        self.written = Some(tick);
        served.handle.broadcast_time(tick * self.period_ns);
        if let Ok(clock) = self.clock.lock() {
            let state = playback_state(&clock, self.period_ns);
            if state.status != before {
                served.handle.broadcast_playback_state(state);
            }
        }
    }

    /// Writes the map and the newest sample at or before `tick` of every other topic.
    fn write_state_at(&self, served: &mut Served, tick: u64) {
        if let Some(map) = &self.tape.map {
            served.channels.log(&map.topic, map.log_time, &map.data);
        }
        let mut newest = BTreeMap::new();
        for samples in self.tape.steps.range(..=tick).rev().map(|(_, s)| s) {
            for s in samples.iter().rev() {
                newest.entry(s.topic.as_str()).or_insert(s);
            }
        }
        let mut ordered: Vec<_> = newest.into_values().collect();
        ordered.sort_by_key(|s| s.log_time);
        for s in ordered {
            served.channels.log(&s.topic, s.log_time, &s.data);
        }
    }
}

/// Serves `replay` until `stop` says so.
pub fn play(replay: &mut Replay, served: &mut Served, stop: impl Fn() -> bool) {
    let mut last = Instant::now();
    while !stop() {
        std::thread::sleep(PLAYBACK_PERIOD);
        let now = Instant::now();
        replay.advance(served, now - last);
        last = now;
    }
}
