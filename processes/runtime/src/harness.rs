//! A process's own main, stepped in a unit test without IPC (as dora's `init_testing` or
//! copper's `run_one_iteration`).
//!
//! A [`Harness`] is a stack of one: the test delivers samples it made (or read from a
//! recording), in the order the stack would publish them, and runs the process's main on
//! [`Harness::process`] instead of [`Process::new`]. Everything between the ports and the step
//! is the runtime's own: each delivered sample wakes the process once, inputs are validated
//! (an invalid sample is dropped and counted), steps are gated by their [`crate::Rule`]s in
//! lockstep, settings go through [`crate::Tuning`], and the loop ends, as on a shutdown, when
//! every delivery is made. Only iceoryx2 and the wake-up system calls are left out. The test
//! then reads what the process published with [`Harness::published`].
//!
//! ```text
//! let harness = Harness::new();
//! harness.deliver(topics::WORLD_MAP, 0, |m| scenario.write_world_map(m));
//! harness.deliver(topics::WORLD_TRUTH, 0, |t| world.write_step(t, 0, None));
//! run(harness.process(Role::Sensing, &args.common)?, &args)?;
//! let scans = harness.published(topics::SENSING_SCAN);
//! ```

use crate::clock::ClockMode;
use crate::context::{CommonArgs, Context};
use crate::error::RuntimeError;
use crate::stats::StatsRegistry;
use crate::step::Process;
use mole_types::{Message, Role, Topic};
use std::any::Any;
use std::cell::{Cell, RefCell};
use std::collections::{HashMap, VecDeque};
use std::rc::Rc;

/// A stack of one process, fed by a test: see the module's documentation.
#[derive(Default)]
pub struct Harness {
    bench: Rc<Bench>,
    last: RefCell<Option<Box<dyn Any>>>,
}

impl Harness {
    pub fn new() -> Harness {
        Harness::default()
    }

    /// The process `role` on this harness, with the arguments its main parsed (settings, seed;
    /// the clock mode is always lockstep, whose steps follow from their inputs alone). Hand it
    /// to the main's dataflow in the place of [`Process::new`]'s.
    pub fn process(&self, role: Role, args: &CommonArgs) -> Result<Process, RuntimeError> {
        Process::on(Context::on_bench(role.name(), args, self.bench.clone()))
    }

    /// Delivers a sample of `topic` stamped with step `tick` (and the topic's next sequence
    /// number), after every delivery made before it; `fill` writes it from zeroes. Returns the
    /// delivery's place in the order (from 0), for [`Harness::published_after`].
    pub fn deliver<M: Message>(
        &self,
        topic: Topic<M>,
        tick: u64,
        fill: impl FnOnce(&mut M),
    ) -> usize {
        let mut message: Box<M> = bytemuck::zeroed_box();
        fill(&mut message);
        let seq = self.bench.next_seq(topic.name);
        let header = message.header_mut();
        (header.tick, header.seq) = (tick, seq);
        self.deliver_as_is(topic, message)
    }

    /// Delivers `message` with its header as it is (a sample from a recording, one with a
    /// sequence gap, one that is invalid on purpose).
    pub fn deliver_as_is<M: Message>(&self, topic: Topic<M>, message: Box<M>) -> usize {
        let name = topic.name;
        *self.last.borrow_mut() = Some(Box::new(message.clone()));
        let mut script = self.bench.script.borrow_mut();
        script.push_back(Box::new(move |bench: &Bench| {
            bench.inbox::<M>(name).queue.borrow_mut().push_back(message);
        }));
        self.bench.made.get() + script.len() - 1
    }

    /// A copy of the last sample delivered (to compute with what the process was given).
    pub fn delivered_last<M: Message>(&self) -> Box<M> {
        self.last
            .borrow()
            .as_ref()
            .and_then(|m| m.downcast_ref::<Box<M>>())
            .cloned()
            .expect("the last delivery was of another message type")
    }

    /// Every sample the process published on `topic`, in order.
    pub fn published<M: Message>(&self, topic: Topic<M>) -> Vec<Box<M>> {
        let outbox = self.bench.outbox::<M>(topic.name);
        let sent = outbox.sent.borrow();
        sent.iter().map(|(_, message)| message.clone()).collect()
    }

    /// For each sample the process published on `topic`, how many deliveries had been made
    /// when it did: a sample published after delivery `i` ([`Harness::deliver`]'s return) has
    /// a number above `i`. How a test sees what a step waited for.
    pub fn published_after<M: Message>(&self, topic: Topic<M>) -> Vec<usize> {
        let outbox = self.bench.outbox::<M>(topic.name);
        let sent = outbox.sent.borrow();
        sent.iter().map(|(made, _)| *made).collect()
    }

    /// What the process published, in order: each sample's tick and topic.
    pub fn publish_order(&self) -> Vec<(u64, &'static str)> {
        self.bench.order.borrow().clone()
    }

    /// Checks that each step published its topics in the order of `outputs` (a role's row of
    /// the graph, `RoleSpec::outputs`), each once at most: the order the stack relies on (the
    /// output that wakes the next process goes last).
    pub fn check_publish_order(&self, outputs: &[&str]) -> Result<(), String> {
        let order = self.bench.order.borrow();
        let mut ticks: Vec<u64> = order.iter().map(|(tick, _)| *tick).collect();
        ticks.sort_unstable();
        ticks.dedup();
        for tick in ticks {
            let step: Vec<&str> = order
                .iter()
                .filter(|(t, _)| *t == tick)
                .map(|(_, n)| *n)
                .collect();
            let places: Vec<Option<usize>> = step
                .iter()
                .map(|topic| outputs.iter().position(|o| o == topic))
                .collect();
            if places.iter().any(Option::is_none) || !places.windows(2).all(|w| w[0] < w[1]) {
                return Err(format!(
                    "step {tick} published {step:?}, not in the order of the graph's {outputs:?}"
                ));
            }
        }
        Ok(())
    }

    /// How many deliveries the process has not been woken for yet (0 once its loop ended by
    /// running out of them).
    pub fn undelivered(&self) -> usize {
        self.bench.script.borrow().len()
    }

    /// How many samples of the process's input `topic` it dropped as invalid, as its
    /// statistics count them.
    pub fn invalid(&self, topic: &str) -> u64 {
        self.bench.stats.invalid(topic)
    }
}

/// Whether two messages carry the same payload, whatever their headers (a sample a process
/// published and the one a test computed for it).
pub fn same_payload<M: Message>(a: &M, b: &M) -> bool {
    let blank = |m: &M| {
        let mut copy: Box<M> = bytemuck::zeroed_box();
        bytemuck::bytes_of_mut(&mut *copy).copy_from_slice(bytemuck::bytes_of(m));
        *copy.header_mut() = Default::default();
        copy
    };
    bytemuck::bytes_of(&*blank(a)) == bytemuck::bytes_of(&*blank(b))
}

type Delivery = Box<dyn FnOnce(&Bench)>;

/// The harness's side of the ports: the queues the process reads and writes.
#[derive(Default)]
pub(crate) struct Bench {
    /// The deliveries not made yet: one per wake-up of the process.
    script: RefCell<VecDeque<Delivery>>,
    /// Per topic, the queue of what was delivered and not yet read (an `Rc<Fed<M>>`).
    inboxes: RefCell<HashMap<&'static str, Rc<dyn Any>>>,
    /// Per topic, what the process published (an `Rc<Outbox<M>>`).
    outboxes: RefCell<HashMap<&'static str, Rc<dyn Any>>>,
    seqs: RefCell<HashMap<&'static str, u64>>,
    /// Deliveries made so far.
    made: Cell<usize>,
    /// Every sample published, in order: its tick and topic.
    order: RefCell<Vec<(u64, &'static str)>>,
    /// The process's statistics (its context's).
    pub(crate) stats: StatsRegistry,
}

impl Bench {
    /// Makes the next delivery; `false` when none is left (the process then ends its loop).
    pub(crate) fn deliver_next(&self) -> bool {
        let Some(delivery) = self.script.borrow_mut().pop_front() else {
            return false;
        };
        delivery(self);
        self.made.set(self.made.get() + 1);
        true
    }

    /// The queue a subscriber of `topic` reads (one per topic, made by whichever side comes
    /// first).
    pub(crate) fn inbox<M: Message>(&self, topic: &'static str) -> Rc<Fed<M>> {
        Self::typed(&self.inboxes, topic, || Fed {
            queue: RefCell::new(VecDeque::new()),
        })
    }

    /// Where a publisher of `topic` puts what it sends.
    pub(crate) fn outbox<M: Message>(&self, topic: &'static str) -> Rc<Outbox<M>> {
        Self::typed(&self.outboxes, topic, || Outbox {
            sent: RefCell::new(Vec::new()),
        })
    }

    /// Keeps what a publisher sent, with the number of deliveries made by then.
    pub(crate) fn keep<M: Message>(
        &self,
        topic: &'static str,
        outbox: &Outbox<M>,
        message: Box<M>,
    ) {
        self.order.borrow_mut().push((message.header().tick, topic));
        outbox.sent.borrow_mut().push((self.made.get(), message));
    }

    fn next_seq(&self, topic: &'static str) -> u64 {
        let mut seqs = self.seqs.borrow_mut();
        let seq = seqs.entry(topic).or_default();
        *seq += 1;
        *seq - 1
    }

    fn typed<T: Any>(
        map: &RefCell<HashMap<&'static str, Rc<dyn Any>>>,
        topic: &'static str,
        make: impl FnOnce() -> T,
    ) -> Rc<T> {
        let any = map
            .borrow_mut()
            .entry(topic)
            .or_insert_with(|| Rc::new(make()))
            .clone();
        any.downcast::<T>()
            .unwrap_or_else(|_| panic!("{topic} is used with two message types in one harness"))
    }
}

/// A subscriber's queue on a harness.
pub(crate) struct Fed<M> {
    pub(crate) queue: RefCell<VecDeque<Box<M>>>,
}

/// A publisher's record on a harness.
pub(crate) struct Outbox<M> {
    sent: RefCell<Vec<(usize, Box<M>)>>,
}

impl<M: Message> crate::ports::Pending for Fed<M> {
    fn has_data(&self) -> bool {
        !self.queue.borrow().is_empty()
    }
}

impl Context {
    /// A context whose ports are `bench`'s queues: no node, no doorbell, no statistics.
    pub(crate) fn on_bench(role: &str, args: &CommonArgs, bench: Rc<Bench>) -> Context {
        let mut args = args.clone();
        args.mode = ClockMode::Lockstep;
        (args.takeover, args.resume) = (false, None);
        let stats = bench.stats.clone();
        let wire = crate::context::Wire::Bench(bench);
        Context::on_wire(wire, role, &args, Default::default(), stats)
    }
}
