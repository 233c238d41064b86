//! `mole-observer`: an observer that reads every topic of the stack, as a monitor or a viewer
//! would, to measure what each one more costs the stack (`scripts/cost-growth.sh`).
//!
//! It reads every topic of [`topics::for_each`] (so a topic added to the table is read too):
//! `world/map` through the runtime, which subscribes every process to it and hands it to the
//! observer's start ([`EveryTopic::on_map`]), every other topic as an input. It is woken once a
//! step (realtime: after the loop's step closes; lockstep: by the step's
//! truth, as the monitor is), drains every topic on each wake-up and folds each sample's header
//! into a checksum: the trivial work a viewer does before it draws.

use mole_runtime::{Observation, Process, RuntimeError};
use mole_types::topics::{self, TopicVisitor};
use mole_types::{Header, Message, Topic};

/// Drains one topic's new samples into the tally; returns how many there were.
type Reader = Box<dyn FnMut(&mut Observation, &mut Tally) -> usize>;

/// What an observer has read: samples per topic and a checksum over their headers.
#[derive(Debug, Default, Clone, PartialEq, Eq)]
pub struct Tally {
    /// Samples read, per topic of [`EveryTopic::names`].
    pub samples: Vec<u64>,
    /// World maps read (the runtime reads it once).
    pub map_samples: u64,
    /// Every header read, folded (FNV-1a over tick and stamps).
    pub checksum: u64,
}

impl Tally {
    /// Folds one sample's header into the checksum.
    fn fold(&mut self, header: &Header) {
        const FNV_PRIME: u64 = 0x0000_0100_0000_01b3;
        for word in [header.tick, header.stamp_ns, header.origin_ns] {
            self.checksum = (self.checksum ^ word).wrapping_mul(FNV_PRIME);
        }
    }
}

/// The inputs of an observer of every topic.
pub struct EveryTopic {
    /// The topics read as inputs, in the table's order.
    pub names: Vec<&'static str>,
    readers: Vec<Reader>,
    tally: Tally,
}

impl EveryTopic {
    /// Declares every topic of the table but `world/map` (the runtime's own input of every
    /// process) as an input of `process`; the step's truth wakes it.
    pub fn subscribe(process: &mut Process) -> Result<EveryTopic, RuntimeError> {
        let mut visitor = Subscriber {
            process,
            every: EveryTopic {
                names: Vec::new(),
                readers: Vec::new(),
                tally: Tally {
                    checksum: 0xcbf2_9ce4_8422_2325,
                    ..Tally::default()
                },
            },
            failed: None,
        };
        topics::for_each(&mut visitor);
        match visitor.failed {
            Some(e) => Err(e),
            None => Ok(visitor.every),
        }
    }

    /// Reads every new sample of every topic; returns how many there were.
    pub fn drain(&mut self, seen: &mut Observation) -> usize {
        let tally = &mut self.tally;
        self.readers.iter_mut().map(|read| read(seen, tally)).sum()
    }

    /// Counts the world's map, read once by the runtime at the start.
    pub fn on_map(&mut self, map: &mole_types::WorldMap) {
        self.tally.fold(map.header());
        self.tally.map_samples += 1;
    }

    /// What was read so far.
    pub fn tally(&self) -> &Tally {
        &self.tally
    }
}

/// Subscribes the process to each topic it is handed.
struct Subscriber<'a> {
    process: &'a mut Process,
    every: EveryTopic,
    failed: Option<RuntimeError>,
}

impl TopicVisitor for Subscriber<'_> {
    fn visit<M: Message>(&mut self, _constant: &'static str, topic: Topic<M>) {
        if self.failed.is_some() || topic.name == topics::WORLD_MAP.name {
            return;
        }
        let wakes = topic.name == topics::WORLD_TRUTH.name;
        let input = match self.process.observed(topic, wakes) {
            Ok(input) => input,
            Err(e) => {
                self.failed = Some(e);
                return;
            }
        };
        let slot = self.every.readers.len();
        self.every.names.push(topic.name);
        self.every.tally.samples.push(0);
        self.every.readers.push(Box::new(move |seen, tally| {
            let n = seen.drain(input, |m: &M| tally.fold(m.header()));
            tally.samples[slot] += n as u64;
            n
        }));
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use mole_runtime::CommonArgs;
    use std::sync::Arc;
    use std::sync::atomic::AtomicBool;

    /// The observer reads every topic of the table once, in the table's order: world/map
    /// through the runtime, the others as its inputs.
    #[test]
    fn an_observer_subscribes_to_every_topic() {
        let args = CommonArgs::attach(
            &format!("observer-test-{}", std::process::id()),
            mole_runtime::ClockMode::Realtime,
        );
        let shutdown = Arc::new(AtomicBool::new(false));
        let mut process = Process::with_shutdown_flag("observer-1", &args, shutdown).unwrap();
        let every = EveryTopic::subscribe(&mut process).unwrap();
        let table: Vec<&str> = topics::all().iter().map(|(name, _)| *name).collect();
        assert_eq!(table[0], topics::WORLD_MAP.name);
        assert_eq!(every.names, table[1..]);
        assert_eq!(every.readers.len() + 1, topics::all().len());
        assert_eq!(every.tally().samples, vec![0; table.len() - 1]);
    }

    /// The checksum depends on every header folded, in order.
    #[test]
    fn the_checksum_folds_each_header() {
        let header = |tick| Header {
            tick,
            ..Header::default()
        };
        let (mut a, mut b) = (Tally::default(), Tally::default());
        a.fold(&header(1));
        a.fold(&header(2));
        b.fold(&header(2));
        b.fold(&header(1));
        assert_ne!(a.checksum, b.checksum);
        assert_ne!(a.checksum, Tally::default().checksum);
    }
}
