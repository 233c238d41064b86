//! The recorder's side of IPC: a subscriber on every topic of the namespace, each drained into
//! [`Record`]s for the writer.
//!
//! In lockstep a full queue makes its publisher wait, so the recorder must read every queue
//! each step: the world's truth (published once a step) wakes it and it drains them all, as the
//! launcher's keeper does (one wake-up a step; every other topic is published at most once a
//! step, so its queue never fills). In realtime nothing wakes it: it drains at its own pace.

use crate::{Event, Every, Gaps, ProcessWatch, Record, every::due};
use mole_runtime::{ClockMode, Context, RuntimeError, Subscriber, Waker};
use mole_types::topics::{self, OpenTopic};
use mole_types::{Fault, Message, ParamChange, Processes, Topic, Truth, WorldMap};
use std::any::Any;
use std::collections::BTreeMap;

/// What the samples read so far say about the run.
#[derive(Default)]
pub struct Seen {
    /// The newest world tick: the time of samples whose header counts no step (statistics,
    /// the launcher's process table) and of events.
    newest_tick: u64,
    /// The first and last world tick recorded.
    ticks: Option<(u64, u64)>,
    /// The simulated step (ns), once the world's map came.
    pub period_ns: Option<u64>,
    watch: ProcessWatch,
    /// Records for the writer, in the order they were read.
    pub out: Vec<Record>,
    /// Whether samples become records: off, only the world's map does (its one sample), and
    /// the rest is read and forgotten (a Foxglove server with no client).
    pub skip_samples: bool,
}

impl Seen {
    /// Takes what a sample says about the run: the map's step and seed, the truth's tick, the
    /// launcher's process table.
    fn interpret<M: Message>(&mut self, message: &M) {
        let any = message as &dyn Any;
        if let Some(map) = any.downcast_ref::<WorldMap>() {
            let period_ns = (map.dt * 1e9).round() as u64;
            self.period_ns = Some(period_ns);
            self.out.push(Record::World {
                period_ns,
                seed: map.seed,
            });
        } else if let Some(truth) = any.downcast_ref::<Truth>() {
            let tick = truth.header.tick;
            self.newest_tick = tick;
            self.ticks = Some(match self.ticks {
                Some((first, last)) => (first.min(tick), last.max(tick)),
                None => (tick, tick),
            });
        } else if let Some(report) = any.downcast_ref::<Processes>() {
            for event in self.watch.update(report) {
                self.event(&event);
            }
        } else if let Some(fault) = any.downcast_ref::<Fault>() {
            self.event(&Event::of_fault(fault));
        } else if let Some(event) = any.downcast_ref::<ParamChange>().and_then(Event::of_param) {
            self.event(&event);
        }
    }

    fn event(&mut self, event: &Event) {
        self.out.push(Record::Event {
            tick: self.newest_tick,
            json: event.to_json(self.newest_tick),
        });
    }
}

/// One recorded topic, whatever its message type.
trait Tap {
    fn topic(&self) -> &'static str;
    /// Its waker, when it wakes the recorder.
    fn waker(&self) -> Option<Waker>;
    /// Reads every new sample; the due ones become records.
    fn drain(&mut self, seen: &mut Seen);
    /// The newest sample, if it was read but not written (a decimated topic at the end).
    fn last_sample(&mut self, seen: &mut Seen);
    /// Samples lost before they were read, and how many of them were already reported.
    fn lost(&mut self) -> (u64, &mut u64);
    /// Samples read but not written (decimation).
    fn decimated(&self) -> u64;
}

struct Typed<M: Message> {
    subscriber: Subscriber<M>,
    wakes: bool,
    every: u64,
    /// Whether the header's tick is a simulation step (not for statistics and the launcher's
    /// process table).
    stepped: bool,
    last_written: Option<u64>,
    newest_written: bool,
    gaps: Gaps,
    reported_lost: u64,
    decimated: u64,
}

/// The wall clock (ns since the Unix epoch): a record's `publish_time`.
fn wall_ns() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos() as u64)
}

fn record<M: Message>(topic: &'static str, message: &M, tick: u64) -> Record {
    Record::Message {
        topic,
        seq: message.header().seq,
        tick,
        publish_time: wall_ns(),
        data: bytemuck::bytes_of(message).to_vec(),
    }
}

impl<M: Message> Tap for Typed<M> {
    fn topic(&self) -> &'static str {
        self.subscriber.topic()
    }
    fn waker(&self) -> Option<Waker> {
        self.wakes.then(|| self.subscriber.waker())
    }
    fn drain(&mut self, seen: &mut Seen) {
        let topic = self.subscriber.topic();
        let Typed {
            subscriber,
            every,
            stepped,
            last_written,
            newest_written,
            gaps,
            decimated,
            ..
        } = self;
        subscriber.drain(|message| {
            gaps.observe(message.header().seq);
            seen.interpret(message);
            let tick = if *stepped {
                message.header().tick
            } else {
                seen.newest_tick
            };
            *newest_written = due(tick, *last_written, *every);
            if *newest_written {
                *last_written = Some(tick);
                if !seen.skip_samples || topic == topics::WORLD_MAP.name {
                    seen.out.push(record(topic, message, tick));
                }
            } else {
                *decimated += 1;
            }
        });
    }
    fn last_sample(&mut self, seen: &mut Seen) {
        if self.newest_written {
            return;
        }
        if let Some(message) = self.subscriber.latest() {
            let tick = if self.stepped {
                message.header().tick
            } else {
                seen.newest_tick
            };
            seen.out
                .push(record(self.subscriber.topic(), message, tick));
            self.newest_written = true;
            self.decimated -= 1;
        }
    }
    fn lost(&mut self) -> (u64, &mut u64) {
        (self.gaps.lost(), &mut self.reported_lost)
    }
    fn decimated(&self) -> u64 {
        self.decimated
    }
}

/// A subscriber on every topic of the namespace.
pub struct Taps {
    taps: Vec<Box<dyn Tap>>,
    pub seen: Seen,
}

impl Taps {
    /// Subscribes to every topic of `mole_types::topics`, passively but for the world's truth in
    /// lockstep, which wakes the recorder once a step.
    pub fn open(ctx: &Context, every: &Every) -> Result<Taps, RuntimeError> {
        struct Open<'a> {
            ctx: &'a Context,
            every: &'a Every,
        }
        impl OpenTopic for Open<'_> {
            type Port = Box<dyn Tap>;
            type Error = RuntimeError;
            fn open<M: Message>(&mut self, topic: Topic<M>) -> Result<Self::Port, RuntimeError> {
                let wakes = self.ctx.mode() == ClockMode::Lockstep
                    && topic.name == topics::WORLD_TRUTH.name;
                let subscriber = match wakes {
                    true => self.ctx.subscriber(topic)?,
                    false => self.ctx.passive_subscriber(topic)?,
                };
                let stepped =
                    ![topics::STACK_STATS.name, topics::STACK_PROCESSES.name].contains(&topic.name);
                Ok(Box::new(Typed {
                    subscriber,
                    wakes,
                    every: self.every.of(topic.name),
                    stepped,
                    last_written: None,
                    newest_written: true,
                    gaps: Gaps::default(),
                    reported_lost: 0,
                    decimated: 0,
                }))
            }
        }
        let taps = topics::open_each(|_| true, &mut Open { ctx, every })?;
        Ok(Taps {
            taps,
            seen: Seen::default(),
        })
    }

    /// The wakers of the topics that wake the recorder.
    pub fn wakers(&self) -> Vec<Waker> {
        self.taps.iter().filter_map(|t| t.waker()).collect()
    }

    /// Reads every queue; the records are in `seen.out`, with an event for samples lost since
    /// the last drain.
    pub fn drain(&mut self) {
        for tap in &mut self.taps {
            tap.drain(&mut self.seen);
        }
        for tap in &mut self.taps {
            let topic = tap.topic();
            let (lost, reported) = tap.lost();
            if lost > *reported {
                let count = lost - *reported;
                *reported = lost;
                tracing::warn!(topic, count, "samples lost before the recorder read them");
                self.seen.event(&Event::Lost {
                    topic: topic.to_string(),
                    count,
                });
            }
        }
    }

    /// The newest sample of every decimated topic that was not written, so the file ends with
    /// the final grids.
    pub fn last_samples(&mut self) {
        for tap in &mut self.taps {
            tap.last_sample(&mut self.seen);
        }
    }

    /// The recording's own metadata: the world ticks it spans, samples lost and decimated per
    /// topic.
    pub fn totals(&mut self) -> BTreeMap<String, String> {
        let mut totals = BTreeMap::new();
        if let Some((first, last)) = self.seen.ticks {
            totals.insert("first_tick".into(), first.to_string());
            totals.insert("last_tick".into(), last.to_string());
        }
        for tap in &mut self.taps {
            let topic = tap.topic();
            let (lost, _) = tap.lost();
            if lost > 0 {
                totals.insert(format!("lost.{topic}"), lost.to_string());
            }
            if tap.decimated() > 0 {
                totals.insert(format!("decimated.{topic}"), tap.decimated().to_string());
            }
        }
        totals
    }
}
