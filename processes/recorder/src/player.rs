//! The player's side of IPC and its loop: a recording's samples of the roles it stands in for,
//! published on their topics with the recorded bytes (the header's tick from the file), in their
//! place (the `mole-player` binary, src/bin/mole-player.rs, says how it keeps the stack's time).

use crate::cast::{Cast, pace};
use crate::{Sample, Tape, Window, read_tape};
use mole_runtime::{
    BadInput, ClockMode, Context, LOCKSTEP_RESEND, Publisher, RuntimeError, Subscriber, WaitSet,
    Wake, Waker, now_ns,
};
use mole_types::topics::{self, OpenTopic};
use mole_types::{EndReason, Message, TICK_END, TRUTH_END, Tick, Topic, Truth};
use std::any::Any;
use std::path::Path;
use std::time::Instant;

/// How often late subscribers (a restarted process) are handed the map from history, as the
/// world does.
pub const MAP_REFRESH_TICKS: u64 = 25;

/// What the player plays, from its command line: who it stands in for, how fast, the steps.
pub struct Show {
    /// The roles it plays back (`--replace`).
    pub cast: Cast,
    /// Realtime: how many times as fast as recorded (`--rate`).
    pub rate: f64,
    /// The recording's steps in the window played (`--from`, `--to`).
    pub tape: Tape,
    /// The window's last step: its truth ends the run.
    pub last: u64,
}

impl Show {
    /// Checks the settings and reads the steps `from..=to` that `replace` plays from `file`; a
    /// bad setting, a file that is not a recording, or nothing to play is bad input.
    pub fn read(
        file: &Path,
        replace: &str,
        rate: f64,
        from: u64,
        to: u64,
    ) -> Result<Show, BadInput> {
        let cast = Cast::parse(replace).map_err(|e| BadInput(format!("--replace: {e}")))?;
        if !(rate.is_finite() && rate > 0.0) {
            return Err(BadInput(format!(
                "--rate: expected a positive factor, found {rate}"
            )));
        }
        let window = Window { from, to };
        let tape =
            read_tape(file, &cast.published(), window).map_err(|e| BadInput(e.to_string()))?;
        let Some(&last) = tape.steps.keys().next_back() else {
            return Err(BadInput(format!(
                "{}: nothing to play for {} in ticks {}..={}",
                file.display(),
                cast.names(),
                from,
                to
            )));
        };
        Ok(Show {
            cast,
            rate,
            tape,
            last,
        })
    }
}

/// Plays every step of `show` on `outlets`: as the clock in lockstep, step k+1 once `awaited`
/// reached step k (step k again after [`LOCKSTEP_RESEND`] without it); as the clock in
/// realtime, at the recorded times; else after the live world's truth of the step. False on a
/// shutdown.
pub fn play(
    show: &Show,
    outlets: &mut Outlets,
    awaited: &mut Awaited,
    waitset: &WaitSet,
    ctx: &mut Context,
) -> Result<bool, RuntimeError> {
    let Show {
        cast,
        rate,
        tape,
        last,
    } = show;
    let lockstep = ctx.mode() == ClockMode::Lockstep;
    let started = Instant::now();
    let first_log_time = tape.steps.values().flatten().map(|s| s.log_time).min();
    for (&tick, samples) in &tape.steps {
        let end = tick == *last;
        if cast.is_clock() {
            if !lockstep {
                let at = started + pace(first_log_time.unwrap_or(0), samples[0].log_time, *rate);
                if !sleep_until(waitset, ctx, at)? {
                    return Ok(false);
                }
            }
        } else if !awaited.until(waitset, ctx, tick, || Ok(()))? {
            return Ok(false);
        }
        outlets.publish_step(cast, samples, end)?;
        ctx.count_step();
        if tick.is_multiple_of(MAP_REFRESH_TICKS) {
            outlets.update_connections();
        }
        if cast.is_clock() && lockstep {
            let resend = || {
                tracing::warn!(
                    tick,
                    "no reply for {LOCKSTEP_RESEND:?}: playing the step again"
                );
                outlets.publish_step(cast, samples, end)
            };
            if !awaited.until(waitset, ctx, tick, resend)? {
                return Ok(false);
            }
        }
    }
    Ok(true)
}

/// Sleeps until `at` (statistics go on); false on a shutdown.
fn sleep_until(waitset: &WaitSet, ctx: &mut Context, at: Instant) -> Result<bool, RuntimeError> {
    while Instant::now() < at {
        if waitset.wait(ctx, Some(at))? == Wake::Shutdown {
            return Ok(false);
        }
    }
    Ok(true)
}

/// A topic the player publishes, whatever its message type.
trait Outlet {
    fn topic(&self) -> &'static str;
    /// Publishes `data` (a whole message) at `tick`; `end` marks the run's last step.
    fn publish(&mut self, tick: u64, data: &[u8], end: bool) -> Result<(), RuntimeError>;
    fn update_connections(&self);
}

impl<M: Message> Outlet for Publisher<M> {
    fn topic(&self) -> &'static str {
        Publisher::topic(self)
    }
    fn publish(&mut self, tick: u64, data: &[u8], end: bool) -> Result<(), RuntimeError> {
        Publisher::publish(self, tick, now_ns(), |m| {
            *m = bytemuck::pod_read_unaligned(data);
            if end {
                mark_end(m as &mut dyn Any);
            }
        })
    }
    fn update_connections(&self) {
        Publisher::update_connections(self);
    }
}

/// Marks the truth and the tick of the window's last step as the run's end (the tick limit),
/// unless the recording already ended there.
fn mark_end(message: &mut dyn Any) {
    if let Some(truth) = message.downcast_mut::<Truth>()
        && !truth.is_end()
    {
        truth.flags |= TRUTH_END;
        truth.end_reason = EndReason::Ticks.code();
    } else if let Some(tick) = message.downcast_mut::<Tick>() {
        tick.flags |= TICK_END;
    }
}

/// A publisher on every topic the player plays.
pub struct Outlets(Vec<Box<dyn Outlet>>);

impl Outlets {
    /// Opens a publisher on every topic of `published`.
    pub fn open(ctx: &Context, published: &[&'static str]) -> Result<Outlets, RuntimeError> {
        struct Open<'a>(&'a Context);
        impl OpenTopic for Open<'_> {
            type Port = Box<dyn Outlet>;
            type Error = RuntimeError;
            fn open<M: Message>(&mut self, topic: Topic<M>) -> Result<Self::Port, RuntimeError> {
                Ok(Box::new(self.0.publisher(topic)?))
            }
        }
        let wanted = |name: &str| published.contains(&name);
        topics::open_each(wanted, &mut Open(ctx)).map(Outlets)
    }

    /// Publishes `sample` on its topic (if it is played); `end` marks the run's last step.
    pub fn publish(&mut self, sample: &Sample, end: bool) -> Result<(), RuntimeError> {
        match self.0.iter_mut().find(|o| o.topic() == sample.topic) {
            Some(outlet) => outlet.publish(sample.tick, &sample.data, end),
            None => Ok(()),
        }
    }

    /// A step's samples in the order the roles publish them (`Cast::published`).
    pub fn publish_step(
        &mut self,
        cast: &Cast,
        samples: &[Sample],
        end: bool,
    ) -> Result<(), RuntimeError> {
        for topic in cast.published() {
            for sample in samples.iter().filter(|s| s.topic == topic) {
                self.publish(sample, end)?;
            }
        }
        Ok(())
    }

    /// Hands late subscribers (a restarted process) what the topics keep in history.
    pub fn update_connections(&self) {
        for outlet in &self.0 {
            outlet.update_connections();
        }
    }
}

/// A topic whose newest tick the player waits for.
trait Newest {
    fn newest_tick(&mut self) -> Option<u64>;
    fn waker(&self) -> Waker;
}

impl<M: Message> Newest for Subscriber<M> {
    fn newest_tick(&mut self) -> Option<u64> {
        self.update();
        self.tick()
    }
    fn waker(&self) -> Waker {
        Subscriber::waker(self)
    }
}

/// What the player waits for before a step: as the clock, the live roles' outputs of the step
/// it played; following the live world, its truth of the step to play.
pub struct Awaited(Vec<Box<dyn Newest>>);

impl Awaited {
    /// Subscribes to what the player waits for as `cast` makes it: the clock or a follower.
    pub fn open(ctx: &Context, cast: &Cast) -> Result<Awaited, RuntimeError> {
        let names = match cast.is_clock() {
            true => cast.awaited(),
            false => vec![topics::WORLD_TRUTH.name],
        };
        struct Open<'a>(&'a Context);
        impl OpenTopic for Open<'_> {
            type Port = Box<dyn Newest>;
            type Error = RuntimeError;
            fn open<M: Message>(&mut self, topic: Topic<M>) -> Result<Self::Port, RuntimeError> {
                Ok(Box::new(self.0.subscriber(topic)?))
            }
        }
        let wanted = |name: &str| names.contains(&name);
        topics::open_each(wanted, &mut Open(ctx)).map(Awaited)
    }

    /// The wakers of the awaited topics: each wakes the player.
    pub fn wakers(&self) -> Vec<Waker> {
        self.0.iter().map(|s| s.waker()).collect()
    }

    /// Waits until every awaited topic reached `tick`, calling `idle` after each
    /// [`LOCKSTEP_RESEND`] without it; false on a shutdown.
    pub fn until(
        &mut self,
        waitset: &WaitSet,
        ctx: &mut Context,
        tick: u64,
        mut idle: impl FnMut() -> Result<(), RuntimeError>,
    ) -> Result<bool, RuntimeError> {
        let mut deadline = Instant::now() + LOCKSTEP_RESEND;
        loop {
            if self
                .0
                .iter_mut()
                .all(|s| s.newest_tick().is_some_and(|t| t >= tick))
            {
                return Ok(true);
            }
            match waitset.wait(ctx, Some(deadline))? {
                Wake::Shutdown => return Ok(false),
                Wake::Timeout if Instant::now() >= deadline => {
                    idle()?;
                    deadline = Instant::now() + LOCKSTEP_RESEND;
                }
                _ => {}
            }
        }
    }
}
