//! The loop of the process that keeps the stack's time (the world): it publishes step k and
//! advances when the reply to it (the command) allows, by the clock mode's rule.

use crate::clock::ClockMode;
use crate::step::{Process, Trigger};
use crate::time::now_ns;
use crate::waitset::Wake;
use mole_types::Message;
use std::time::{Duration, Instant};

/// Realtime: a reply older than this no longer counts (a planner that died must not leave the
/// robot driving).
pub const REPLY_TIMEOUT: Duration = Duration::from_millis(500);
/// Lockstep: with no reply for this long, publish the step again (a consumer restarted).
pub const LOCKSTEP_RESEND: Duration = Duration::from_secs(1);

/// What the clock source is asked to do.
pub enum ClockEvent<'a, M> {
    /// Publish the state of step `tick`: the first one, or again because no reply came.
    Publish { tick: u64 },
    /// Advance one step with `reply` (`None` in realtime when none came for
    /// [`REPLY_TIMEOUT`]: stop the robot), then publish step `tick`. `latency_ns` is the loop
    /// latency of the reply received since the last step (0 if none).
    Advance {
        tick: u64,
        reply: Option<&'a M>,
        latency_ns: u64,
    },
    /// A shutdown was requested: publish step `tick` as the last one.
    Stop { tick: u64 },
}

/// Whether the run goes on after an event.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Flow {
    Continue,
    End,
}

type BoxError = Box<dyn std::error::Error>;

impl Process {
    /// Runs the clock (docs/architecture.md, "Clock modes"). Realtime: one step per period with
    /// the newest reply. Lockstep: step k+1 only once the reply for step k arrived; a later
    /// answer to an older step never counts. A clock restarted after a crash, resumed from step
    /// k (`resume_from`), goes on with step k+1 at once and without a reply: the reply to step
    /// k went to its predecessor, and every consumer has handled step k already.
    pub fn run_clock<M: Message>(
        mut self,
        reply: Trigger<M>,
        mut on: impl FnMut(ClockEvent<M>) -> Result<Flow, BoxError>,
    ) -> Result<(), BoxError> {
        let waitset = self.ctx.waitset()?;
        let wakers = std::mem::take(&mut self.wakers);
        let _attached = waitset.attach_all(&wakers)?;
        self.ctx.ready();
        let mode = self.ctx.mode();
        let period = Duration::from_secs_f64(1.0 / self.ctx.rate_hz().max(1e-3));
        let mut tick = self.resume_after.unwrap_or(0);
        let mut latency_ns = 0;
        let mut received = Instant::now();
        let mut applied: Option<u64> = None;
        let first = match self.resume_after {
            None => ClockEvent::Publish { tick },
            Some(_) => {
                (applied, tick) = (Some(tick), tick + 1);
                self.ctx.count_step();
                ClockEvent::Advance {
                    tick,
                    reply: None,
                    latency_ns: 0,
                }
            }
        };
        if on(first)? == Flow::End {
            return Ok(());
        }
        let (mut next_step, mut last_publish) = (Instant::now() + period, Instant::now());
        loop {
            let deadline = match mode {
                ClockMode::Realtime => next_step,
                ClockMode::Lockstep => last_publish + LOCKSTEP_RESEND,
            };
            let wake = waitset.wait(&mut self.ctx, Some(deadline))?;
            if wake == Wake::Shutdown {
                on(ClockEvent::Stop { tick })?;
                return Ok(());
            }
            // Newest by tick (Subscriber::update): a late answer to an older step never wins.
            let replies = self.subscriber_mut(reply);
            let fresh = replies.update().then(|| replies.tick()).flatten();
            if let Some(answered) = fresh {
                let origin = replies.latest().map_or(0, |m| m.header().origin_ns);
                latency_ns = now_ns().saturating_sub(origin);
                received = Instant::now();
                if mode == ClockMode::Lockstep && answered != tick {
                    // An answer to an older step (a resend answered twice): not this step's.
                    continue;
                }
            }
            let due = match mode {
                ClockMode::Realtime => Instant::now() >= next_step,
                ClockMode::Lockstep => fresh == Some(tick) && applied != Some(tick),
            };
            if !due {
                if mode == ClockMode::Lockstep && wake == Wake::Timeout {
                    tracing::warn!(
                        tick,
                        "no reply for {LOCKSTEP_RESEND:?}: publishing the step again"
                    );
                    on(ClockEvent::Publish { tick })?;
                    last_publish = Instant::now();
                }
                continue;
            }
            let stale = mode == ClockMode::Realtime && received.elapsed() > REPLY_TIMEOUT;
            applied = Some(tick);
            tick += 1;
            self.ctx.count_step();
            let event = ClockEvent::Advance {
                tick,
                reply: self.subscriber_mut(reply).latest().filter(|_| !stale),
                latency_ns: std::mem::take(&mut latency_ns),
            };
            if on(event)? == Flow::End {
                tracing::info!(tick, "run complete");
                return Ok(());
            }
            last_publish = Instant::now();
            next_step += period;
            if mode == ClockMode::Realtime && Instant::now() > next_step + period * 10 {
                // Far behind (the machine stalled): do not fire a burst of catch-up steps.
                next_step = Instant::now() + period;
            }
        }
    }
}
