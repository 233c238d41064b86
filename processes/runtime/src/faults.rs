//! Faults on demand, the runtime's side (`mole_types::fault`): before a publisher sends, it asks
//! its process's [`FaultBoard`] whether a fault on `stack/faults` is in force on its topic, and
//! holds, drops or corrupts the sample as the fault says. A process that publishes nothing
//! faulted pays one look at a flag per sample, and a look at `stack/faults` every
//! [`POLL_EVERY_NS`].

use crate::ports::Subscriber;
use mole_types::messages::NAME_LEN;
use mole_types::{Fault, FaultKind, Message, write_name};
use rand::{Rng, RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::cell::{Cell, RefCell};

/// Most faults in force at once that a process keeps track of.
const MAX_ACTIVE: usize = 8;
/// How often a process reads `stack/faults` (ns): a new fault takes effect within this.
const POLL_EVERY_NS: u64 = 5_000_000;
/// How many words a corruption tries before it gives up on a message that any word accepts.
const CORRUPT_TRIES: usize = 64;

/// What a publisher does with the sample it is about to send.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Action {
    Send,
    /// Hold it this long (ns), then send it.
    Delay(u64),
    /// Do not send it; the next sample's sequence number shows the gap.
    Drop,
    /// Send it corrupted; the value seeds which bytes.
    Corrupt(u64),
}

/// One fault in force on a topic.
#[derive(Debug, Clone)]
struct Active {
    id: u32,
    kind: FaultKind,
    topic: [u8; NAME_LEN],
    start_ns: u64,
    end_ns: u64,
    delay_ns: u64,
    fraction: f64,
    /// The stream that picks the samples hit.
    rng: ChaCha8Rng,
}

/// The faults in force on topics, without IPC: what [`FaultBoard`] keeps.
#[derive(Debug, Default)]
pub(crate) struct ActiveFaults {
    slots: [Option<Active>; MAX_ACTIVE],
}

impl ActiveFaults {
    /// Takes in a fault from `stack/faults`: the topic faults (delay, drop, corrupt), once per
    /// id; kills and stops are the launcher's. A full board makes room by forgetting the fault
    /// that ends first.
    pub(crate) fn add(&mut self, fault: &Fault) {
        let Some(kind) = fault.fault_kind().filter(|k| !k.targets_a_role()) else {
            return;
        };
        if self.slots.iter().flatten().any(|a| a.id == fault.id) {
            return;
        }
        let active = Active {
            id: fault.id,
            kind,
            topic: fault.target,
            start_ns: fault.start_ns,
            end_ns: fault.end_ns,
            delay_ns: fault.delay_ns,
            fraction: fault.fraction,
            rng: ChaCha8Rng::seed_from_u64(fault.seed ^ u64::from(fault.id).rotate_left(32)),
        };
        let slot = match self.slots.iter().position(Option::is_none) {
            Some(free) => free,
            None => (0..MAX_ACTIVE)
                .min_by_key(|&i| self.slots[i].as_ref().map_or(0, |a| a.end_ns))
                .unwrap_or(0),
        };
        self.slots[slot] = Some(active);
    }

    /// Whether any fault is kept (in force or not yet over).
    pub(crate) fn any(&self) -> bool {
        self.slots.iter().any(Option::is_some)
    }

    /// What to do with a sample of `topic` sent at `now_ns`: the longest delay in force, else a
    /// drop or a corruption if the fault's draw hits this sample. Faults that ended are
    /// forgotten.
    pub(crate) fn action(&mut self, topic: &str, now_ns: u64) -> Action {
        let mut name = [0u8; NAME_LEN];
        write_name(&mut name, topic);
        let mut action = Action::Send;
        for slot in &mut self.slots {
            let Some(active) = slot else { continue };
            if now_ns >= active.end_ns {
                *slot = None;
                continue;
            }
            if active.topic != name || now_ns < active.start_ns {
                continue;
            }
            action = match (active.kind, action) {
                (FaultKind::Delay, Action::Delay(held)) => Action::Delay(held.max(active.delay_ns)),
                (FaultKind::Delay, Action::Send) => Action::Delay(active.delay_ns),
                (FaultKind::Drop, Action::Send | Action::Delay(_))
                    if active.rng.random::<f64>() < active.fraction =>
                {
                    Action::Drop
                }
                (FaultKind::Corrupt, Action::Send | Action::Delay(_))
                    if active.rng.random::<f64>() < active.fraction =>
                {
                    Action::Corrupt(active.rng.next_u64())
                }
                (_, action) => action,
            };
        }
        action
    }
}

/// A process's view of `stack/faults`: a passive subscriber read every [`POLL_EVERY_NS`], and
/// the faults in force. Shared by all its publishers.
pub(crate) struct FaultBoard {
    subscriber: RefCell<Subscriber<Fault>>,
    active: RefCell<ActiveFaults>,
    next_poll_ns: Cell<u64>,
}

impl FaultBoard {
    pub(crate) fn new(subscriber: Subscriber<Fault>) -> FaultBoard {
        FaultBoard {
            subscriber: RefCell::new(subscriber),
            active: RefCell::default(),
            next_poll_ns: Cell::new(0),
        }
    }

    /// What to do with a sample of `topic` about to be sent at `now_ns`.
    pub(crate) fn action(&self, topic: &str, now_ns: u64) -> Action {
        if now_ns >= self.next_poll_ns.get() {
            self.next_poll_ns.set(now_ns + POLL_EVERY_NS);
            let mut active = self.active.borrow_mut();
            self.subscriber
                .borrow_mut()
                .drain(|fault| active.add(fault));
        }
        let mut active = self.active.borrow_mut();
        if !active.any() {
            return Action::Send;
        }
        active.action(topic, now_ns)
    }
}

/// Corrupts `message` so that its own validation refuses it: overwrites an aligned 8-byte word
/// of its payload (past the header, which stays intact) with 0xFF bytes, a NaN as a float and
/// a count beyond any capacity as an integer. The word is picked by `seed`; while the message
/// still validates (the word was unused capacity), the words right after the header (where every
/// message keeps its counts and scalars) are tried in turn, then more picked ones. False, with
/// the message as it was, when no word tried makes it invalid.
pub(crate) fn corrupt<M: Message>(message: &mut M, seed: u64) -> bool {
    /// Words right after the header tried when a picked one does not invalidate.
    const LEADING: usize = 8;
    let header = std::mem::size_of::<mole_types::Header>();
    let bytes = bytemuck::bytes_of_mut(message);
    let words = (bytes.len() - header) / 8;
    if words == 0 {
        return false;
    }
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    for attempt in 0..CORRUPT_TRIES {
        let word = match attempt {
            1..=LEADING => (attempt - 1) % words,
            _ => rng.random_range(0..words),
        };
        let at = header + 8 * word;
        let mut kept = [0u8; 8];
        kept.copy_from_slice(&bytes[at..at + 8]);
        bytes[at..at + 8].fill(0xFF);
        if bytemuck::from_bytes::<M>(bytes).validate().is_err() {
            return true;
        }
        bytes[at..at + 8].copy_from_slice(&kept);
    }
    false
}

#[cfg(test)]
mod tests {
    use super::*;
    use mole_types::topics::{self, TopicVisitor};
    use mole_types::{FaultSpec, Grid, Topic, WorldMap};

    fn fault(kind: FaultKind, topic: &str, id: u32, from_ns: u64, seconds: f64) -> Fault {
        let spec = FaultSpec {
            kind,
            target: topic.into(),
            duration_s: seconds,
            delay_ms: 20.0,
            fraction: 0.25,
        };
        let mut m: Fault = bytemuck::Zeroable::zeroed();
        spec.to_message(&mut m, id, from_ns, 99);
        m
    }

    /// A delay holds its topic's samples while it lasts and no others; it ends on time.
    #[test]
    fn a_delay_holds_its_topic_until_it_ends() {
        let mut board = ActiveFaults::default();
        board.add(&fault(FaultKind::Delay, "sensing/scan", 1, 1_000, 1.0));
        assert_eq!(board.action("sensing/scan", 500), Action::Send, "not yet");
        assert_eq!(
            board.action("sensing/scan", 1_000),
            Action::Delay(20_000_000)
        );
        assert_eq!(board.action("sensing/odom", 1_000), Action::Send);
        assert_eq!(
            board.action("sensing/scan", 1_000 + 1_000_000_000),
            Action::Send
        );
        assert!(!board.any(), "an ended fault is forgotten");
    }

    /// A drop of a quarter hits about a quarter of the samples, the same ones for the same
    /// seed; a fault seen twice (history, then live) counts once; kills are not the runtime's.
    #[test]
    fn a_drop_hits_its_fraction_reproducibly() {
        let run = || {
            let mut board = ActiveFaults::default();
            let f = fault(FaultKind::Drop, "planning/cmd", 3, 0, 100.0);
            board.add(&f);
            board.add(&f);
            board.add(&fault(FaultKind::Kill, "planning", 4, 0, 0.0));
            (0..10_000u64)
                .map(|i| board.action("planning/cmd", i) == Action::Drop)
                .collect::<Vec<bool>>()
        };
        let hits = run();
        let n = hits.iter().filter(|h| **h).count();
        assert!((2_300..2_700).contains(&n), "{n} of 10000 dropped");
        assert_eq!(hits, run(), "the same samples for the same seed");
    }

    /// Every message type, valid as zeroed or as a real one, is made invalid by a corruption,
    /// which leaves its header alone.
    #[test]
    fn a_corrupted_message_of_every_type_fails_its_validation() {
        struct Check(Vec<&'static str>);
        impl TopicVisitor for Check {
            fn visit<M: Message>(&mut self, _: &'static str, topic: Topic<M>) {
                let mut m: Box<M> = bytemuck::zeroed_box();
                m.header_mut().tick = 77;
                if let Some(grid) = (m.as_mut() as &mut dyn std::any::Any).downcast_mut::<Grid>() {
                    (grid.width, grid.height, grid.resolution) = (4, 4, 0.1);
                }
                if let Some(map) = (m.as_mut() as &mut dyn std::any::Any).downcast_mut::<WorldMap>()
                {
                    (map.arena_width, map.arena_height, map.dt) = (10.0, 10.0, 0.01);
                    (map.grid_resolution, map.robot.radius) = (0.1, 0.2);
                }
                if let Err(why) = m.validate() {
                    println!("{}: {why}", topic.name);
                    return;
                }
                for seed in 0..20 {
                    let mut c = m.clone();
                    assert!(
                        corrupt(&mut *c, seed),
                        "{}: no word made it invalid",
                        topic.name
                    );
                    assert!(c.validate().is_err(), "{}", topic.name);
                    assert_eq!(c.header().tick, 77, "{}: the header is intact", topic.name);
                }
                self.0.push(topic.name);
            }
        }
        let mut checked = Check(Vec::new());
        topics::for_each(&mut checked);
        for topic in mole_types::fault::faultable_topics() {
            assert!(
                checked.0.contains(&topic),
                "{topic}: a zeroed message does not validate, so its corruption is untested"
            );
        }
    }
}
