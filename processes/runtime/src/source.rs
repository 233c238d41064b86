//! The loop of the process that keeps the stack's time (the world): it publishes step k and
//! advances when the reply to it (the command) allows, by the clock mode's rule. In lockstep an
//! operator paces it (`operator/pace`): it holds before its next step, takes a number of steps
//! and holds, or runs on.

use crate::clock::ClockMode;
use crate::context::{Context, thread_cpu_ns};
use crate::error::RuntimeError;
use crate::ports::{Subscriber, Waker};
use crate::step::{Process, Trigger};
use crate::time::now_ns;
use crate::waitset::Wake;
use mole_types::{Header, Message, PACE_PAUSE, PACE_RUN, PACE_STEP, Pace, topics};
use std::time::{Duration, Instant};

/// Realtime: a reply older than this no longer counts (a planner that died must not leave the
/// robot driving).
pub const REPLY_TIMEOUT: Duration = Duration::from_millis(500);
/// Lockstep: with no reply for this long, publish the step again (a consumer restarted).
pub const LOCKSTEP_RESEND: Duration = Duration::from_secs(1);
/// Lockstep: how long a clock resumed after a crash waits for the reply to its last step (the
/// planner hands it from history within its 100 ms offer) before it steps without one.
const RESUMED_REPLY_GRACE: Duration = Duration::from_secs(2);

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
    ///
    /// Lockstep follows `operator/pace` before each step: a pause holds the next step, a step
    /// order of n takes n steps (replacing one under way) and holds, run goes on. While held the
    /// clock sleeps until a pace message or a shutdown, publishing its statistics as any waiting
    /// process does. A step order published before this clock started was its predecessor's and
    /// holds. Realtime ignores pace messages, warning once and counting them.
    pub fn run_clock<M: Message>(
        mut self,
        reply: Trigger<M>,
        mut on: impl FnMut(ClockEvent<M>) -> Result<Flow, BoxError>,
    ) -> Result<(), BoxError> {
        // The clock publishes the map it follows, and its operator reads the pace.
        self.check_ports_against_the_graph(&[topics::OPERATOR_PACE.name])?;
        let waitset = self.ctx.waitset()?;
        let mut operator = Operator::open(&self.ctx, self.start_held)?;
        let mut wakers = std::mem::take(&mut self.wakers);
        wakers.push(operator.waker());
        let _attached = waitset.attach_all(&wakers)?;
        self.ctx.ready();
        let mode = self.ctx.mode();
        let period = Duration::from_secs_f64(1.0 / self.ctx.rate_hz().max(1e-3));
        let mut tick = self.resume_after.unwrap_or(0);
        let mut latency_ns = 0;
        let mut received = Instant::now();
        let mut applied: Option<u64> = None;
        // A clock resumed after a crash owes the step after its last truth; every consumer has
        // handled that truth already. Lockstep waits for the reply to it, which its planner
        // sent to the dead clock and hands this one from history (it offers its history while
        // it waits), so the run goes on as if nothing happened; with none within
        // RESUMED_REPLY_GRACE, and in realtime at once, the step is taken without a reply (the
        // robot stopped), unless an operator holds the run (the pace from history).
        let resumed = self.resume_after.is_some();
        let mut owed = resumed && mode == ClockMode::Realtime;
        let mut awaiting_reply =
            (resumed && mode == ClockMode::Lockstep).then(|| Instant::now() + RESUMED_REPLY_GRACE);
        if owed {
            applied = Some(tick);
        } else if !resumed && on(ClockEvent::Publish { tick })? == Flow::End {
            return Ok(());
        }
        let (mut next_step, mut last_publish) = (Instant::now() + period, Instant::now());
        loop {
            if let Some(grace) = awaiting_reply
                && Instant::now() >= grace
            {
                awaiting_reply = None;
                if self.subscriber_mut(reply).tick() != Some(tick) {
                    tracing::warn!(
                        tick,
                        "resumed: no reply to step {tick} within {RESUMED_REPLY_GRACE:?}; \
                         taking the next step with the robot stopped"
                    );
                    owed = true;
                    applied = Some(tick);
                }
            }
            if owed && operator.read(mode).lets_step(mode, tick) {
                owed = false;
                operator.took_step();
                tick += 1;
                self.ctx.count_step();
                let event = ClockEvent::Advance {
                    tick,
                    reply: None,
                    latency_ns: 0,
                };
                let start = thread_cpu_ns();
                let flow = on(event)?;
                self.ctx.add_step_cpu(start);
                if flow == Flow::End {
                    return operator.finish(Ok(()));
                }
                (next_step, last_publish) = (Instant::now() + period, Instant::now());
                continue;
            }
            // Held by the operator with this step's reply in (or owed): nothing to resend, so
            // sleep until the operator (or a shutdown) wakes it, publishing statistics on the
            // way like any waiting process.
            let replied = self.subscriber_mut(reply).tick() == Some(tick);
            let held = mode == ClockMode::Lockstep && (owed || replied);
            let deadline = match mode {
                ClockMode::Realtime => Some(next_step),
                ClockMode::Lockstep if held => None,
                ClockMode::Lockstep => Some(
                    awaiting_reply.map_or(last_publish + LOCKSTEP_RESEND, |grace| {
                        grace.min(last_publish + LOCKSTEP_RESEND)
                    }),
                ),
            };
            let wake = waitset.wait(&mut self.ctx, deadline)?;
            if wake == Wake::Shutdown {
                on(ClockEvent::Stop { tick })?;
                return operator.finish(Ok(()));
            }
            if owed {
                continue;
            }
            operator.read(mode);
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
            // Lockstep: this step's reply is in, whether it came now or while the run was held.
            let due = match mode {
                ClockMode::Realtime => Instant::now() >= next_step,
                ClockMode::Lockstep => replies.tick() == Some(tick) && applied != Some(tick),
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
            if !operator.lets_step(mode, tick) {
                continue;
            }
            operator.took_step();
            let stale = mode == ClockMode::Realtime && received.elapsed() > REPLY_TIMEOUT;
            applied = Some(tick);
            awaiting_reply = None;
            tick += 1;
            self.ctx.count_step();
            let event = ClockEvent::Advance {
                tick,
                reply: self.subscriber_mut(reply).latest().filter(|_| !stale),
                latency_ns: std::mem::take(&mut latency_ns),
            };
            let start = thread_cpu_ns();
            let flow = on(event)?;
            self.ctx.add_step_cpu(start);
            if flow == Flow::End {
                tracing::info!(tick, "run complete");
                return operator.finish(Ok(()));
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

/// How an operator paces a lockstep run.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Pacing {
    /// Step whenever the reply is in.
    Run,
    /// Hold before the next step.
    Hold,
    /// Take this many more steps (at least one), then hold.
    Steps(u32),
}

/// The clock's side of `operator/pace`: the pacing the newest pace message asks for.
struct Operator {
    pace: Subscriber<Pace>,
    pacing: Pacing,
    /// When this clock started (CLOCK_MONOTONIC, ns): a step order stamped before it was its
    /// predecessor's (a clock restarted after a crash), and holds instead.
    started_ns: u64,
    /// Whether the hold was reported (once per hold).
    reported_hold: bool,
    /// Pace messages ignored in realtime.
    ignored: u64,
}

impl Operator {
    /// The operator's pace, holding from the start when `held` ([`Process::start_held`]).
    fn open(ctx: &Context, held: bool) -> Result<Operator, RuntimeError> {
        Ok(Operator {
            pace: ctx.subscriber(topics::OPERATOR_PACE)?,
            pacing: if held { Pacing::Hold } else { Pacing::Run },
            started_ns: now_ns(),
            reported_hold: false,
            ignored: 0,
        })
    }

    fn waker(&self) -> Waker {
        self.pace.waker()
    }

    /// Takes every pace message that came, in order: lockstep follows the last; realtime ignores
    /// them, warning once and counting.
    fn read(&mut self, mode: ClockMode) -> &mut Operator {
        let mut pacing = self.pacing;
        let started_ns = self.started_ns;
        let came = self.pace.drain(|pace| {
            pacing = Self::pacing_of(pace, started_ns);
        });
        if came == 0 {
            return self;
        }
        if mode == ClockMode::Realtime {
            if self.ignored == 0 {
                tracing::warn!(
                    "{} paces lockstep runs only: ignored in realtime (counted)",
                    topics::OPERATOR_PACE.name
                );
            }
            self.ignored += came as u64;
            return self;
        }
        if pacing != self.pacing {
            tracing::info!(?pacing, "the operator paces the run");
            self.reported_hold = false;
        }
        self.pacing = pacing;
        self
    }

    /// The pacing one (valid) pace message asks for.
    fn pacing_of(pace: &Pace, started_ns: u64) -> Pacing {
        let Header { stamp_ns, .. } = pace.header;
        match pace.op {
            PACE_RUN => Pacing::Run,
            PACE_PAUSE => Pacing::Hold,
            PACE_STEP if stamp_ns > 0 && stamp_ns < started_ns => Pacing::Hold,
            PACE_STEP => Pacing::Steps(pace.steps),
            _ => unreachable!("a pace with an unknown op fails validation"),
        }
    }

    /// Whether the clock may take the step after `tick` now; a hold is reported once.
    fn lets_step(&mut self, mode: ClockMode, tick: u64) -> bool {
        if mode == ClockMode::Realtime || self.pacing != Pacing::Hold {
            return true;
        }
        if !self.reported_hold {
            self.reported_hold = true;
            tracing::info!(tick, "held by the operator after step {tick}");
        }
        false
    }

    /// Counts a step taken against a step order.
    fn took_step(&mut self) {
        if let Pacing::Steps(n) = self.pacing {
            self.pacing = match n {
                0 | 1 => Pacing::Hold,
                n => Pacing::Steps(n - 1),
            };
        }
    }

    /// Ends the clock's loop with `result`, saying how many pace messages realtime ignored.
    fn finish(self, result: Result<(), BoxError>) -> Result<(), BoxError> {
        if self.ignored > 0 {
            tracing::info!(
                ignored = self.ignored,
                "{} messages ignored (realtime)",
                topics::OPERATOR_PACE.name
            );
        }
        result
    }
}
