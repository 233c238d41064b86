//! Typed ports: a publisher writes a loaned sample in place and wakes the topic's listeners (the
//! doorbells of mole nodes, the event service for the others); a subscriber drains its queue,
//! validates every message, and keeps the newest one borrowed.

use crate::doorbell::Rings;
use crate::error::RuntimeError;
use crate::faults::{Action, FaultBoard};
use crate::harness::{Bench, Fed, Outbox};
use crate::stats::PortHandle;
use crate::time::now_ns;
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::prelude::*;
use iceoryx2::sample::Sample;
use mole_types::Message;
use std::rc::Rc;
use std::time::{Duration, Instant};

/// Minimum spacing of the warnings an invalid message causes (each one is still counted).
const WARN_EVERY: Duration = Duration::from_secs(5);

/// A typed publisher bound to one topic.
pub struct Publisher<M: Message> {
    pub(crate) topic: &'static str,
    sink: Sink<M>,
    pub(crate) stats: PortHandle,
    pub(crate) seq: u64,
    /// The process's faults on demand (`mole fault`), looked up before every send.
    faults: Option<Rc<FaultBoard>>,
    /// Lockstep: a corrupted sample is followed by the good one (lockstep delivers every
    /// sample); realtime: the corrupted one is all the readers get.
    lockstep: bool,
}

/// Where a publisher's samples go.
enum Sink<M: Message> {
    /// The topic's iceoryx2 ports; shared with the context, which offers late subscribers the
    /// history while the process waits ([`crate::Context::offer_history`]).
    Shm(Rc<PublisherPorts<M>>),
    /// A test harness's record (`harness.rs`).
    Fed(Rc<Outbox<M>>, Rc<Bench>),
}

/// A publisher's iceoryx2 ports.
pub(crate) struct PublisherPorts<M: Message> {
    topic: &'static str,
    publisher: iceoryx2::port::publisher::Publisher<ipc::Service, M, ()>,
    notifier: Notifier<ipc::Service>,
    /// The doorbells of the nodes listening on the topic's event service.
    rings: core::cell::RefCell<Rings>,
}

impl<M: Message> PublisherPorts<M> {
    /// Wakes every listener of the topic: a mole node by its doorbell, once however many of its
    /// subscribers listen, any other program through the event service.
    fn wake_listeners(&self) {
        self.rings.borrow_mut().notify(&self.notifier);
    }
}

/// A publisher that can hand its history to subscribers that joined since it last sent.
pub(crate) trait OfferHistory {
    fn update_connections(&self);
}

impl<M: Message> OfferHistory for PublisherPorts<M> {
    fn update_connections(&self) {
        use iceoryx2::port::update_connections::UpdateConnections;
        match self.publisher.update_connections() {
            Ok(()) => self.wake_listeners(),
            Err(e) => tracing::debug!(topic = self.topic, "update_connections failed: {e:?}"),
        }
    }
}

impl<M: Message> Publisher<M> {
    pub(crate) fn new(
        topic: &'static str,
        publisher: iceoryx2::port::publisher::Publisher<ipc::Service, M, ()>,
        notifier: Notifier<ipc::Service>,
        stats: PortHandle,
        faults: Option<(Rc<FaultBoard>, bool)>,
    ) -> Self {
        let lockstep = faults.as_ref().is_some_and(|(_, lockstep)| *lockstep);
        Self {
            topic,
            sink: Sink::Shm(Rc::new(PublisherPorts {
                topic,
                publisher,
                notifier,
                rings: Default::default(),
            })),
            stats,
            seq: 0,
            faults: faults.map(|(board, _)| board),
            lockstep,
        }
    }

    /// A publisher on a test harness: what it sends goes to `outbox`.
    pub(crate) fn on_bench(topic: &'static str, bench: Rc<Bench>, stats: PortHandle) -> Self {
        Self {
            topic,
            sink: Sink::Fed(bench.outbox(topic), bench),
            stats,
            seq: 0,
            faults: None,
            lockstep: true,
        }
    }

    /// The ports, for the context's list of publishers that offer history.
    pub(crate) fn history_offer(&self) -> std::rc::Weak<dyn OfferHistory>
    where
        M: 'static,
    {
        match &self.sink {
            Sink::Shm(ports) => {
                let ports: Rc<dyn OfferHistory> = ports.clone();
                Rc::downgrade(&ports)
            }
            Sink::Fed(..) => std::rc::Weak::<PublisherPorts<M>>::new(),
        }
    }

    /// Sets the header of a message about to be sent (`seq`, `tick`, `stamp_ns`, `origin_ns`);
    /// returns the stamp.
    fn stamp(&self, message: &mut M, tick: u64, origin_ns: u64) -> u64 {
        let stamp_ns = now_ns();
        let header = message.header_mut();
        header.seq = self.seq;
        header.tick = tick;
        header.stamp_ns = stamp_ns;
        header.origin_ns = origin_ns;
        stamp_ns
    }

    /// Loans a sample in shared memory, lets `fill` write the payload in place, stamps the
    /// header (`seq`, `tick`, `stamp_ns`, `origin_ns`), sends it and wakes the subscribers.
    ///
    /// `fill` sees the previous contents of the slot (stale but valid values: every bit pattern
    /// of a message is valid); it must write every field it means to send.
    pub fn publish(
        &mut self,
        tick: u64,
        origin_ns: u64,
        fill: impl FnOnce(&mut M),
    ) -> Result<(), RuntimeError> {
        let ports = match &self.sink {
            Sink::Shm(ports) => ports.clone(),
            Sink::Fed(outbox, bench) => {
                let mut message: Box<M> = bytemuck::zeroed_box();
                fill(&mut message);
                self.stamp(&mut message, tick, origin_ns);
                bench.keep(self.topic, outbox, message);
                self.seq += 1;
                self.stats.counted(None);
                return Ok(());
            }
        };
        let sample = match ports.publisher.loan_uninit() {
            Ok(sample) => sample,
            Err(e) => {
                self.stats.dropped(1);
                return Err(RuntimeError::Port(format!("loan on {}: {e:?}", self.topic)));
            }
        };
        // SAFETY: the sample lives in a shared-memory segment that the OS zero-filled when it
        // was mapped and that only ever holds whole messages afterwards, so every byte is
        // initialised; `M: Pod` makes any byte pattern a valid `M`.
        let mut sample = unsafe { sample.assume_init() };
        fill(sample.payload_mut());
        let stamp_ns = self.stamp(sample.payload_mut(), tick, origin_ns);
        let action = self
            .faults
            .as_ref()
            .map_or(Action::Send, |board| board.action(self.topic, stamp_ns));
        match action {
            Action::Send => {}
            Action::Delay(ns) => {
                std::thread::sleep(Duration::from_nanos(ns));
                sample.payload_mut().header_mut().stamp_ns = now_ns();
            }
            Action::Drop => {
                // Never sent: the readers see the sequence gap and count the loss.
                self.seq += 1;
                self.stats.dropped(1);
                return Ok(());
            }
            Action::Corrupt(seed) if self.lockstep => {
                self.send_corrupted_copy(sample.payload(), seed)?
            }
            Action::Corrupt(seed) => {
                crate::faults::corrupt(sample.payload_mut(), seed);
            }
        }
        if let Err(e) = sample.send() {
            self.stats.dropped(1);
            return Err(RuntimeError::Port(format!("send on {}: {e:?}", self.topic)));
        }
        self.seq += 1;
        self.stats.counted(None);
        ports.wake_listeners();
        Ok(())
    }

    /// Lockstep's corruption: a corrupted copy of `message`, with its sequence number, goes
    /// ahead of it, so every reader's validation must refuse one sample and the run still gets
    /// the good one (lockstep delivers every sample; a lost one would stall it).
    fn send_corrupted_copy(&mut self, message: &M, seed: u64) -> Result<(), RuntimeError> {
        let Sink::Shm(ports) = &self.sink else {
            return Ok(());
        };
        let copy = ports
            .publisher
            .loan_uninit()
            .map_err(|e| RuntimeError::Port(format!("loan on {}: {e:?}", self.topic)))?;
        // SAFETY: as in `publish`: the slot only ever holds whole messages of this `Pod` type.
        let mut copy = unsafe { copy.assume_init() };
        bytemuck::bytes_of_mut(copy.payload_mut()).copy_from_slice(bytemuck::bytes_of(message));
        crate::faults::corrupt(copy.payload_mut(), seed);
        copy.send()
            .map_err(|e| RuntimeError::Port(format!("send on {}: {e:?}", self.topic)))?;
        Ok(())
    }

    /// Connects subscribers that appeared since the last send and delivers them the history
    /// (world/map keeps one sample for late joiners); wakes them if anything was delivered.
    pub fn update_connections(&self) {
        if let Sink::Shm(ports) = &self.sink {
            ports.update_connections();
        }
    }

    /// The topic name (without the namespace).
    pub fn topic(&self) -> &'static str {
        self.topic
    }

    /// Counts `n` samples lost before this publisher could send them (a bridge: samples its
    /// peer sent that never crossed the link), in this port's `dropped` statistics.
    pub fn count_lost(&self, n: u64) {
        self.stats.dropped(n);
    }

    /// Counts one sample refused before it was sent (a bridge: a malformed one from its peer),
    /// in this port's `invalid` statistics.
    pub fn count_invalid(&self) {
        self.stats.invalid();
    }
}

/// A typed subscriber bound to one topic.
pub struct Subscriber<M: Message> {
    pub(crate) topic: &'static str,
    /// Shared with the [`Waker`], whose WaitSet looks at it when a signal went missing.
    queue: Queue<M>,
    /// `None` for a passive subscriber: no publisher signals it.
    pub(crate) listener: Option<Rc<Listener<ipc::Service>>>,
    pub(crate) stats: PortHandle,
    latest: Option<Held<M>>,
    /// Samples newer than [`Subscriber::update_through`] asked for, held for a later call:
    /// one per publisher (two while a hot swap runs both side by side).
    pending: [Option<Held<M>>; 2],
    last_seq: Option<u64>,
    last_warning: Option<Instant>,
}

/// Where a subscriber's samples come from.
pub(crate) enum Queue<M: Message> {
    /// The topic's iceoryx2 service.
    Shm(Rc<iceoryx2::port::subscriber::Subscriber<ipc::Service, M, ()>>),
    /// A test harness's queue (`harness.rs`).
    Fed(Rc<Fed<M>>),
}

/// A received sample, held: borrowed from shared memory, or owned on a test harness.
enum Held<M: Message> {
    Shm(Sample<ipc::Service, M, ()>),
    Fed(Box<M>),
}

impl<M: Message> Held<M> {
    fn payload(&self) -> &M {
        match self {
            Held::Shm(sample) => sample.payload(),
            Held::Fed(message) => message,
        }
    }
}

impl<M: Message> Subscriber<M> {
    pub(crate) fn new(
        topic: &'static str,
        queue: Queue<M>,
        listener: Option<Rc<Listener<ipc::Service>>>,
        stats: PortHandle,
    ) -> Self {
        Subscriber {
            topic,
            queue,
            listener,
            stats,
            latest: None,
            pending: [None, None],
            last_seq: None,
            last_warning: None,
        }
    }

    /// A look at the queue, for a WaitSet.
    pub(crate) fn pending(&self) -> Rc<dyn Pending> {
        match &self.queue {
            Queue::Shm(subscriber) => subscriber.clone(),
            Queue::Fed(fed) => fed.clone(),
        }
    }

    /// Takes every new message in arrival order; invalid ones are dropped and counted. The last
    /// valid one stays available through [`Subscriber::latest`]. Returns how many were valid.
    ///
    /// No system call: the wake-up signals are consumed by [`crate::WaitSet::wait`], so a busy
    /// poller pays only for reading shared memory.
    pub fn drain(&mut self, mut on_message: impl FnMut(&M)) -> usize {
        let mut valid = 0;
        while let Some(sample) = self.take_pending().or_else(|| self.next_valid()) {
            on_message(sample.payload());
            self.latest = Some(sample);
            valid += 1;
        }
        valid
    }

    /// Keeps only the newest valid message (the highest tick); returns whether a new one
    /// arrived.
    ///
    /// Newest by tick, not by arrival: while a hot swap runs two publishers side by side, the
    /// old one may still send step k−1 after the new one sent step k, and a lockstep consumer
    /// that took the late k−1 would wait for a step k nobody sends again.
    pub fn update(&mut self) -> bool {
        self.update_through(u64::MAX)
    }

    /// [`Subscriber::update`] up to step `tick`: keeps the newest valid message whose tick is
    /// at most `tick`. A newer one stays held, unread, for a later call, so a consumer that
    /// must use step k−1 (lockstep planning) is not handed step k because it came early.
    ///
    /// iceoryx2 hands out one publisher's queue before the next one's, so while a hot swap
    /// runs two publishers, step k of one may come before step k−1 of the other: one early
    /// sample is held per publisher (in lockstep no publisher is more than a step ahead), and
    /// receiving goes on past it.
    pub fn update_through(&mut self, tick: u64) -> bool {
        let mut fresh = false;
        while self.lowest_pending().is_some_and(|(held, _)| held <= tick)
            && let Some(sample) = self.take_pending()
        {
            fresh |= self.keep_if_newest(sample);
        }
        while let Some(free) = self.pending.iter().position(Option::is_none) {
            let Some(sample) = self.next_valid() else {
                break;
            };
            if sample.payload().header().tick > tick {
                self.pending[free] = Some(sample);
            } else {
                fresh |= self.keep_if_newest(sample);
            }
        }
        fresh
    }

    /// Keeps `sample` as the latest unless an older step; returns whether it was kept.
    fn keep_if_newest(&mut self, sample: Held<M>) -> bool {
        if self
            .tick()
            .is_some_and(|newest| sample.payload().header().tick < newest)
        {
            return false;
        }
        self.hold(sample);
        true
    }

    /// Makes `sample` the latest, releasing the older one first (at most two are borrowed).
    fn hold(&mut self, sample: Held<M>) {
        self.latest = None;
        self.latest = Some(sample);
    }

    /// Lockstep, for a consumer that may run behind the loop: moves on to the oldest message
    /// newer than step `after` (`None`: the oldest there is) and leaves the rest queued, so
    /// that every step is handled, in order. Older ones (resends) are dropped. Returns whether
    /// the message now held is newer than `after`; one already held is kept.
    pub fn update_next(&mut self, after: Option<u64>) -> bool {
        let newer = |tick: u64| after.is_none_or(|a| tick > a);
        if self.tick().is_some_and(newer) {
            return true;
        }
        while let Some(sample) = self.take_pending().or_else(|| self.next_valid()) {
            if newer(sample.payload().header().tick) {
                self.hold(sample);
                return true;
            }
        }
        false
    }

    /// The highest step seen so far: the latest message's or a held-back one's. A lockstep
    /// consumer that joined mid-run learns from it that an older step's message will not come.
    pub fn newest_seen(&self) -> Option<u64> {
        self.pending
            .iter()
            .flatten()
            .map(|s| s.payload().header().tick)
            .chain(self.tick())
            .max()
    }

    /// The newest valid message received so far.
    pub fn latest(&self) -> Option<&M> {
        self.latest.as_ref().map(|s| s.payload())
    }

    /// The tick of the newest valid message.
    pub fn tick(&self) -> Option<u64> {
        self.latest().map(|m| m.header().tick)
    }

    /// The topic name (without the namespace).
    pub fn topic(&self) -> &'static str {
        self.topic
    }

    /// A handle that wakes a [`crate::WaitSet`] when this topic is published; attach it with
    /// [`crate::WaitSet::attach`] (the subscriber itself stays free to be drained). Attaching
    /// the waker of a passive subscriber fails.
    pub fn waker(&self) -> Waker {
        Waker {
            topic: self.topic,
            listener: self.listener.clone(),
            pending: self.pending(),
        }
    }

    /// The lowest step held back, and its slot.
    fn lowest_pending(&self) -> Option<(u64, usize)> {
        self.pending
            .iter()
            .enumerate()
            .filter_map(|(slot, s)| s.as_ref().map(|s| (s.payload().header().tick, slot)))
            .min()
    }

    /// The held-back sample of the lowest step, if any.
    fn take_pending(&mut self) -> Option<Held<M>> {
        let (_, slot) = self.lowest_pending()?;
        self.pending[slot].take()
    }

    /// The next sample in the queue, if any.
    fn receive(&self) -> Option<Held<M>> {
        match &self.queue {
            Queue::Shm(subscriber) => match subscriber.receive() {
                Ok(sample) => sample.map(Held::Shm),
                Err(e) => {
                    tracing::debug!(topic = self.topic, "receive failed: {e:?}");
                    None
                }
            },
            Queue::Fed(fed) => fed.queue.borrow_mut().pop_front().map(Held::Fed),
        }
    }

    fn next_valid(&mut self) -> Option<Held<M>> {
        loop {
            let sample = self.receive()?;
            let message = sample.payload();
            if let Err(why) = message.validate() {
                self.stats.invalid();
                let now = Instant::now();
                if self
                    .last_warning
                    .is_none_or(|t| now.duration_since(t) >= WARN_EVERY)
                {
                    self.last_warning = Some(now);
                    tracing::warn!(
                        topic = self.topic,
                        "dropped an invalid {}: {why}",
                        M::wire_type_name()
                    );
                }
                continue;
            }
            let header = *message.header();
            // A sequence gap means the queue overflowed (or a publisher lost samples); a step
            // backwards means a new publisher (a restart or a swap) and starts over.
            if let Some(last) = self.last_seq
                && header.seq > last + 1
            {
                self.stats.dropped(header.seq - last - 1);
            }
            self.last_seq = Some(header.seq);
            let latency = (header.origin_ns > 0).then(|| now_ns().saturating_sub(header.origin_ns));
            self.stats.counted(latency);
            return Some(sample);
        }
    }
}

/// The wake-up side of a subscriber: the listener of the topic's event service.
pub struct Waker {
    pub(crate) topic: &'static str,
    pub(crate) listener: Option<Rc<Listener<ipc::Service>>>,
    pub(crate) pending: Rc<dyn Pending>,
}

impl Waker {
    /// The listener's socket, for tests that lose a wake-up signal on purpose (reading its
    /// datagram behind iceoryx2's back); `None` for a passive subscriber.
    #[doc(hidden)]
    pub fn listener_fd(&self) -> Option<std::os::fd::BorrowedFd<'_>> {
        use iceoryx2::prelude::FileDescriptorBased;
        self.listener.as_ref().map(|listener| {
            // SAFETY: the descriptor belongs to the listener, which outlives the borrow.
            unsafe {
                std::os::fd::BorrowedFd::borrow_raw(listener.file_descriptor().native_handle())
            }
        })
    }
}

/// Whether a subscriber's queue holds a sample: a look at shared memory, no system call.
pub(crate) trait Pending {
    fn has_data(&self) -> bool;
}

impl<M: Message> Pending for iceoryx2::port::subscriber::Subscriber<ipc::Service, M, ()> {
    fn has_data(&self) -> bool {
        self.has_samples().unwrap_or(false)
    }
}
