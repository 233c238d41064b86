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
use mole_recorder::cast::{Cast, DEFAULT_REPLACED, pace};
use mole_recorder::{Sample, Window, read_tape};
use mole_runtime::{
    BadInput, ClockMode, CommonArgs, Context, LOCKSTEP_RESEND, Publisher, RuntimeError, Subscriber,
    Wake, Waker, now_ns,
};
use mole_types::topics::{self, TopicVisitor};
use mole_types::{EndReason, Message, TICK_END, TRUTH_END, Tick, Topic, Truth};
use std::any::Any;
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

/// How often late subscribers (a restarted process) are handed the map from history, as the
/// world does.
const MAP_REFRESH_TICKS: u64 = 25;

#[derive(Debug, Parser)]
#[command(
    name = "mole-player",
    about = "mole's player: a recording's roles played back into a live stack"
)]
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
    let cast = Cast::parse(&args.replace).map_err(|e| BadInput(format!("--replace: {e}")))?;
    if !(args.rate.is_finite() && args.rate > 0.0) {
        return Err(BadInput(format!(
            "--rate: expected a positive factor, found {}",
            args.rate
        ))
        .into());
    }
    let window = Window {
        from: args.from,
        to: args.to,
    };
    let tape =
        read_tape(&args.file, &cast.published(), window).map_err(|e| BadInput(e.to_string()))?;
    let Some(&last) = tape.steps.keys().next_back() else {
        return Err(BadInput(format!(
            "{}: nothing to play for {} in ticks {}..={}",
            args.file.display(),
            cast.names(),
            args.from,
            args.to
        ))
        .into());
    };

    let mut ctx = Context::new("player", &args.common)?;
    let mut outlets = Outlets::open(&ctx, &cast.published())?;
    let mut awaited = Awaited::open(&ctx, &cast)?;
    let waitset = ctx.waitset()?;
    let wakers = awaited.wakers();
    let _attached = waitset.attach_all(&wakers)?;
    if let Some(map) = &tape.map {
        outlets.publish(map, false)?;
    }
    ctx.ready();
    tracing::info!(replace = %cast.names(), steps = tape.steps.len(), last, "playing");

    let lockstep = ctx.mode() == ClockMode::Lockstep;
    let started = Instant::now();
    let first_log_time = tape.steps.values().flatten().map(|s| s.log_time).min();
    for (&tick, samples) in &tape.steps {
        let end = tick == last;
        if cast.is_clock() {
            if !lockstep {
                let at =
                    started + pace(first_log_time.unwrap_or(0), samples[0].log_time, args.rate);
                if !sleep_until(&waitset, &mut ctx, at)? {
                    return Ok(());
                }
            }
        } else if !awaited.until(&waitset, &mut ctx, tick, || Ok(()))? {
            return Ok(());
        }
        outlets.publish_step(&cast, samples, end)?;
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
                outlets.publish_step(&cast, samples, end)
            };
            if !awaited.until(&waitset, &mut ctx, tick, resend)? {
                return Ok(());
            }
        }
    }
    tracing::info!(last, "played every step; waiting to be stopped");
    while waitset.wait(&mut ctx, None)? != Wake::Shutdown {}
    Ok(())
}

/// Sleeps until `at` (statistics go on); false on a shutdown.
fn sleep_until(
    waitset: &mole_runtime::WaitSet,
    ctx: &mut Context,
    at: Instant,
) -> Result<bool, RuntimeError> {
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
struct Outlets(Vec<Box<dyn Outlet>>);

impl Outlets {
    fn open(ctx: &Context, published: &[&'static str]) -> Result<Outlets, RuntimeError> {
        struct Open<'a> {
            ctx: &'a Context,
            published: &'a [&'static str],
            outlets: Vec<Box<dyn Outlet>>,
            error: Option<RuntimeError>,
        }
        impl TopicVisitor for Open<'_> {
            fn visit<M: Message>(&mut self, _constant: &'static str, topic: Topic<M>) {
                if self.error.is_none() && self.published.contains(&topic.name) {
                    match self.ctx.publisher(topic) {
                        Ok(p) => self.outlets.push(Box::new(p)),
                        Err(e) => self.error = Some(e),
                    }
                }
            }
        }
        let mut open = Open {
            ctx,
            published,
            outlets: Vec::new(),
            error: None,
        };
        topics::for_each(&mut open);
        match open.error {
            Some(e) => Err(e),
            None => Ok(Outlets(open.outlets)),
        }
    }

    fn publish(&mut self, sample: &Sample, end: bool) -> Result<(), RuntimeError> {
        match self.0.iter_mut().find(|o| o.topic() == sample.topic) {
            Some(outlet) => outlet.publish(sample.tick, &sample.data, end),
            None => Ok(()),
        }
    }

    /// A step's samples in the order the roles publish them (`Cast::published`).
    fn publish_step(
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

    fn update_connections(&self) {
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
struct Awaited(Vec<Box<dyn Newest>>);

impl Awaited {
    fn open(ctx: &Context, cast: &Cast) -> Result<Awaited, RuntimeError> {
        let names = match cast.is_clock() {
            true => cast.awaited(),
            false => vec![topics::WORLD_TRUTH.name],
        };
        struct Open<'a> {
            ctx: &'a Context,
            names: &'a [&'static str],
            subscribers: Vec<Box<dyn Newest>>,
            error: Option<RuntimeError>,
        }
        impl TopicVisitor for Open<'_> {
            fn visit<M: Message>(&mut self, _constant: &'static str, topic: Topic<M>) {
                if self.error.is_none() && self.names.contains(&topic.name) {
                    match self.ctx.subscriber(topic) {
                        Ok(s) => self.subscribers.push(Box::new(s)),
                        Err(e) => self.error = Some(e),
                    }
                }
            }
        }
        let mut open = Open {
            ctx,
            names: &names,
            subscribers: Vec::new(),
            error: None,
        };
        topics::for_each(&mut open);
        match open.error {
            Some(e) => Err(e),
            None => Ok(Awaited(open.subscribers)),
        }
    }

    fn wakers(&self) -> Vec<Waker> {
        self.0.iter().map(|s| s.waker()).collect()
    }

    /// Waits until every awaited topic reached `tick`, calling `idle` after each
    /// [`LOCKSTEP_RESEND`] without it; false on a shutdown.
    fn until(
        &mut self,
        waitset: &mole_runtime::WaitSet,
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
