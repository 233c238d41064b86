//! Sleeping until an input arrives, a deadline passes or a shutdown is requested.

use crate::clock::ClockMode;
use crate::context::Context;
use crate::doorbell::Doorbell;
use crate::error::RuntimeError;
use crate::harness::Bench;
use crate::ports::Waker;
use iceoryx2::prelude::*;
use nix::poll::{PollFd, PollFlags, PollTimeout};
use std::os::fd::{AsFd, AsRawFd, BorrowedFd, RawFd};
use std::rc::Rc;
use std::time::{Duration, Instant};

/// Lockstep: the longest a process sleeps without looking at its inputs (see
/// [`WaitSet::wait`]); costs ten idle wake-ups a second.
pub const LOCKSTEP_RECHECK: Duration = Duration::from_millis(100);

/// Why a process woke up.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Wake {
    /// At least one attached subscriber has new data.
    Data,
    /// The deadline passed with no data.
    Timeout,
    /// SIGINT or SIGTERM arrived: finish up and exit.
    Shutdown,
}

/// Sleeps until data on an attached subscriber, a deadline, or a shutdown.
///
/// It sleeps in poll(2) on the node's doorbell, which every mole publisher of a topic the node
/// listens to rings, and on the sockets of the attached listeners, which only publishers that
/// are not mole Rust processes notify (`doorbell.rs`). It polls rather than using iceoryx2's
/// WaitSet, which allocates on every wake-up: a step of a process allocates nothing.
pub struct WaitSet {
    /// The node's doorbell; always the first entry of `sockets`. `None` on a test harness.
    doorbell: Option<Rc<Doorbell>>,
    /// A test harness (`harness.rs`): a wait makes its next delivery instead of sleeping.
    bench: Option<Rc<Bench>>,
    /// What poll(2) watches: the doorbell, then the sockets of the attached listeners, kept
    /// between waits.
    sockets: core::cell::RefCell<Vec<PollFd<'static>>>,
    /// Every listener ever attached, by socket: the one whose socket fired is drained on a
    /// wake-up, all of them when a wait ends without a signal. Holding them keeps their sockets
    /// open for as long as the WaitSet lives.
    listeners:
        core::cell::RefCell<Vec<(RawFd, Rc<iceoryx2::port::listener::Listener<ipc::Service>>)>>,
    /// The queues of the attached subscribers, looked at when a wait ends without a signal.
    pending: core::cell::RefCell<Vec<Rc<dyn crate::ports::Pending>>>,
    /// Whether a sample without its signal was reported already.
    missed_signal: core::cell::Cell<bool>,
}

/// Keeps a subscriber attached to a [`WaitSet`] while it lives.
pub struct Attachment<'w, 'a> {
    waitset: &'w WaitSet,
    socket: RawFd,
    _waker: core::marker::PhantomData<&'a Waker>,
}

impl Drop for Attachment<'_, '_> {
    fn drop(&mut self) {
        self.waitset
            .sockets
            .borrow_mut()
            .retain(|s| s.as_fd().as_raw_fd() != self.socket);
    }
}

impl WaitSet {
    pub(crate) fn new(doorbell: Rc<Doorbell>) -> WaitSet {
        // SAFETY: the pipe belongs to the doorbell, which the WaitSet holds for as long as it,
        // and so `sockets`, lives.
        let pipe = unsafe { BorrowedFd::borrow_raw(doorbell.fd().as_raw_fd()) };
        WaitSet {
            sockets: core::cell::RefCell::new(vec![PollFd::new(pipe, PollFlags::POLLIN)]),
            doorbell: Some(doorbell),
            bench: None,
            listeners: core::cell::RefCell::new(Vec::new()),
            pending: core::cell::RefCell::new(Vec::new()),
            missed_signal: core::cell::Cell::new(false),
        }
    }

    /// A WaitSet on a test harness: each wait makes the harness's next delivery.
    pub(crate) fn on_bench(bench: Rc<Bench>) -> WaitSet {
        WaitSet {
            doorbell: None,
            bench: Some(bench),
            sockets: Default::default(),
            listeners: Default::default(),
            pending: Default::default(),
            missed_signal: Default::default(),
        }
    }

    /// Wakes this WaitSet whenever the waker's topic is published.
    pub fn attach<'w, 'a>(&'w self, waker: &'a Waker) -> Result<Attachment<'w, 'a>, RuntimeError> {
        if self.bench.is_some() {
            // Every delivery wakes the process: nothing to listen to.
            return Ok(Attachment {
                waitset: self,
                socket: -1,
                _waker: core::marker::PhantomData,
            });
        }
        let Some(listener) = &waker.listener else {
            return Err(RuntimeError::Wait(format!(
                "{} was opened passive: it cannot wake a WaitSet",
                waker.topic
            )));
        };
        // SAFETY: the socket belongs to the listener, which `listeners` keeps alive (and the
        // socket open) for as long as this WaitSet, and so its `sockets`, lives.
        let socket = unsafe { listener.file_descriptor().native_handle() };
        let mut sockets = self.sockets.borrow_mut();
        if sockets.iter().any(|s| s.as_fd().as_raw_fd() == socket) {
            return Err(RuntimeError::Wait(format!(
                "{} is attached already",
                waker.topic
            )));
        }
        // SAFETY: see above; the entry leaves `sockets` when the attachment is dropped.
        let fd = unsafe { BorrowedFd::borrow_raw(socket) };
        sockets.push(PollFd::new(fd, PollFlags::POLLIN));
        self.listeners.borrow_mut().push((socket, listener.clone()));
        self.pending.borrow_mut().push(waker.pending.clone());
        Ok(Attachment {
            waitset: self,
            socket,
            _waker: core::marker::PhantomData,
        })
    }

    /// Attaches every waker in `wakers`; they stay attached while the attachments live.
    pub fn attach_all<'w>(
        &'w self,
        wakers: &'w [Waker],
    ) -> Result<Vec<Attachment<'w, 'w>>, RuntimeError> {
        wakers.iter().map(|w| self.attach(w)).collect()
    }

    /// Consumes what woke poll(2): the doorbell's rings, and the signals of the listeners whose
    /// sockets fired (the others have nothing: a mole publisher rings the doorbell instead).
    fn take_signals(&self) {
        for socket in self.sockets.borrow().iter() {
            if socket.revents().is_none_or(|r| r.is_empty()) {
                continue;
            }
            self.take(socket.as_fd().as_raw_fd());
        }
    }

    /// Empties the doorbell if `socket` is its pipe, else drains the listener of `socket`.
    fn take(&self, socket: RawFd) {
        if let Some(doorbell) = &self.doorbell
            && socket == doorbell.fd().as_raw_fd()
        {
            doorbell.empty();
            return;
        }
        if let Some((_, listener)) = self.listeners.borrow().iter().find(|(s, _)| *s == socket) {
            let _ = listener.try_wait(|_| {});
        }
    }

    /// Consumes every signal, of the doorbell and of every listener ever attached. Besides
    /// emptying the sockets, `try_wait` resets iceoryx2's "notified" state: in iceoryx2 0.10 a
    /// notification that lands while the listener empties its socket leaves that state set with
    /// no datagram behind, and every later notification is then coalesced away. Only a
    /// `try_wait` clears it again, so a wait that ends without a signal drains them all. (Related
    /// upstream report: eclipse-iceoryx/iceoryx2#1811.) It concerns only the listeners' sockets,
    /// which programs other than mole's notify; a doorbell ring is a byte in a pipe and cannot be
    /// coalesced away.
    fn take_all(&self) {
        if let Some(doorbell) = &self.doorbell {
            doorbell.empty();
        }
        for (_, listener) in self.listeners.borrow().iter() {
            let _ = listener.try_wait(|_| {});
        }
    }

    /// Sleeps until data, `deadline` (if any) or a shutdown; publishes the statistics on the
    /// way when they are due.
    pub fn wait(&self, ctx: &mut Context, deadline: Option<Instant>) -> Result<Wake, RuntimeError> {
        if let Some(bench) = &self.bench {
            // A harness runs out of deliveries as a stack is shut down.
            return Ok(match !ctx.shutdown_requested() && bench.deliver_next() {
                true => Wake::Data,
                false => Wake::Shutdown,
            });
        }
        // Lockstep never sleeps longer than LOCKSTEP_RECHECK without looking at its inputs: a
        // step whose wake-up went missing costs that long instead of stopping the stack.
        let deadline = match (deadline, ctx.mode()) {
            (None, ClockMode::Lockstep) => Some(Instant::now() + LOCKSTEP_RECHECK),
            (deadline, _) => deadline,
        };
        loop {
            if ctx.shutdown_requested() {
                return Ok(Wake::Shutdown);
            }
            let until_stats = ctx.tick_stats();
            let now = Instant::now();
            let until_deadline = deadline.map(|d| d.saturating_duration_since(now));
            // poll(2) waits in whole milliseconds: the last fraction of a deadline is slept
            // precisely, so a 100 Hz world ticks on time.
            if let Some(left) = until_deadline
                && left < Duration::from_millis(1)
            {
                std::thread::sleep(left);
                self.take_all();
                // Idle in lockstep: a subscriber that joined late (a restart) may be waiting
                // for a step this process sent before it came.
                if ctx.mode() == ClockMode::Lockstep {
                    ctx.offer_history();
                }
                return Ok(Wake::Timeout);
            }
            let mut timeout = until_deadline.map_or(until_stats, |d| d.min(until_stats));
            if ctx.mode() == ClockMode::Lockstep {
                // Idle slices end every LOCKSTEP_RECHECK with an offer of history, however
                // far the deadline: the world waits a second for a reply, and a swapped-in
                // planner that has not yet been handed the map cannot give it one.
                timeout = timeout.min(LOCKSTEP_RECHECK);
            }
            let timeout =
                PollTimeout::try_from(timeout.as_millis().max(1)).unwrap_or(PollTimeout::MAX);
            let woke = match nix::poll::poll(&mut self.sockets.borrow_mut(), timeout) {
                Ok(ready) => ready > 0,
                Err(nix::errno::Errno::EINTR) if ctx.shutdown_requested() => {
                    return Ok(Wake::Shutdown);
                }
                Err(nix::errno::Errno::EINTR) => false,
                Err(e) => return Err(RuntimeError::Wait(e.desc().to_string())),
            };
            if woke {
                self.take_signals();
                return Ok(Wake::Data);
            }
            // No signal: reset a stuck "notified" state (see `take_all`), and if a sample came
            // without its signal, wake up for it now.
            self.take_all();
            // Idle as on the deadline: a subscriber that joined late may wait for our history
            // (a sample left queued must not starve the offer either).
            if ctx.mode() == ClockMode::Lockstep {
                ctx.offer_history();
            }
            if self.pending.borrow().iter().any(|p| p.has_data()) {
                if !self.missed_signal.replace(true) {
                    tracing::warn!(
                        "a sample came without its wake-up signal; found by looking (warned once)"
                    );
                }
                return Ok(Wake::Data);
            }
        }
    }
}
