//! One doorbell per node: a named pipe that mole publishers write a byte into instead of sending
//! an iceoryx2 event datagram to each of the node's listeners. The node sleeps in poll(2) on it
//! and empties it with one read, however many publishers rang: a wake-up costs a `write` and a
//! `read`, the pipe floor's pattern (docs/latency.md).
//!
//! A subscriber that wakes its node still creates a listener on the topic's event service, named
//! [`LISTENER_NAME`]: that listener is how publishers learn whom to ring (iceoryx2 lists every
//! listener with its node id), and it keeps waking the node for publishers that are not mole
//! Rust processes (the Python runtime, iceoryx2's tools), which notify the event service itself.

use crate::error::RuntimeError;
use iceoryx2::identifiers::UniqueListenerId;
use iceoryx2::prelude::*;
use nix::errno::Errno;
use nix::fcntl::OFlag;
use nix::sys::stat::Mode;
use std::os::fd::{AsFd, BorrowedFd, OwnedFd};
use std::path::PathBuf;

/// The port name of a listener whose node has a doorbell: a mole publisher rings the doorbell
/// instead of notifying the listener.
pub(crate) const LISTENER_NAME: &str = "mole.doorbell";

/// Where the doorbells live: beside iceoryx2's own records, so that a stack in another iceoryx2
/// root (another config) has its own.
pub(crate) fn doorbell_dir(config: &Config) -> PathBuf {
    use std::os::unix::ffi::OsStrExt;
    let root = config.global.root_path();
    PathBuf::from(std::ffi::OsStr::from_bytes(root.as_bytes())).join("mole-doorbells")
}

/// The doorbell of the node with id `node`.
pub(crate) fn doorbell_path(config: &Config, node: u128) -> PathBuf {
    doorbell_dir(config).join(node.to_string())
}

/// A node's doorbell: the read end of its named pipe (opened read-write, so the pipe never reports
/// a hang-up when the last publisher closes it). Removed when dropped.
pub(crate) struct Doorbell {
    path: PathBuf,
    pipe: OwnedFd,
}

impl Doorbell {
    /// Makes the doorbell of node `node` (a leftover of a dead node with the same id is replaced).
    pub(crate) fn create(node: u128) -> Result<Doorbell, RuntimeError> {
        let config = Config::global_config();
        let failed = |what: &str, e: String| {
            RuntimeError::Wait(format!("doorbell of node {node}: cannot {what}: {e}"))
        };
        let dir = doorbell_dir(config);
        std::fs::create_dir_all(&dir)
            .map_err(|e| failed(&format!("create {}", dir.display()), e.to_string()))?;
        let path = doorbell_path(config, node);
        let _ = std::fs::remove_file(&path);
        nix::unistd::mkfifo(&path, Mode::S_IRUSR | Mode::S_IWUSR)
            .map_err(|e| failed("make its named pipe", e.desc().to_string()))?;
        let pipe = nix::fcntl::open(
            &path,
            OFlag::O_RDWR | OFlag::O_NONBLOCK | OFlag::O_CLOEXEC,
            Mode::empty(),
        )
        .map_err(|e| {
            let _ = std::fs::remove_file(&path);
            failed("open its named pipe", e.desc().to_string())
        })?;
        Ok(Doorbell { path, pipe })
    }

    /// The pipe poll(2) watches.
    pub(crate) fn fd(&self) -> BorrowedFd<'_> {
        self.pipe.as_fd()
    }

    /// A handle that rings this doorbell from another thread (see [`Ringer`]).
    pub(crate) fn ringer(&self) -> Result<Ringer, RuntimeError> {
        let pipe = self
            .pipe
            .try_clone()
            .map_err(|e| RuntimeError::Wait(format!("doorbell: cannot share its pipe: {e}")))?;
        Ok(Ringer(std::sync::Arc::new(pipe)))
    }

    /// Takes every ring waiting in the pipe (usually one read).
    pub(crate) fn empty(&self) {
        let mut rings = [0u8; 64];
        while let Ok(n) = nix::unistd::read(&self.pipe, &mut rings) {
            if n < rings.len() {
                break;
            }
        }
    }
}

impl Drop for Doorbell {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.path);
    }
}

/// Rings a node's doorbell from any thread: how a thread that is not the node's (a network
/// callback in the bridge) wakes the node's [`crate::WaitSet`], which then returns
/// [`crate::Wake::Data`].
#[derive(Clone)]
pub struct Ringer(std::sync::Arc<OwnedFd>);

impl Ringer {
    /// Writes one byte; a full pipe already holds a ring, so a failed write loses nothing.
    pub fn ring(&self) {
        let _ = nix::unistd::write(&*self.0, &[1u8]);
    }
}

/// A publisher's view of the doorbells of the nodes listening to its topic.
#[derive(Default)]
pub(crate) struct Rings {
    /// One entry per listener named [`LISTENER_NAME`] seen at the last notification. Grows only
    /// when a listener comes: a notification in steady state allocates nothing.
    known: Vec<Ring>,
    /// Counts notifications; marks the entries seen by the current one.
    round: u64,
}

/// A listener of the topic and its node's doorbell.
struct Ring {
    listener: UniqueListenerId,
    node: u128,
    /// The doorbell's write end; `None` when it could not be opened (the node is gone, or has
    /// none): its listener is notified instead.
    pipe: Option<OwnedFd>,
    /// The notification that last saw this listener, and the last that rang its node.
    seen: u64,
    rang: u64,
}

impl Rings {
    /// Rings every node listening on `notifier`'s service once, and notifies the listeners that
    /// have no doorbell (those of other programs) through iceoryx2.
    pub(crate) fn notify(&mut self, notifier: &iceoryx2::port::notifier::Notifier<ipc::Service>) {
        self.round += 1;
        let round = self.round;
        let known = &mut self.known;
        notifier.for_each_listener(|listener, details| {
            if details.listener_name != LISTENER_NAME {
                let _ = listener.notify();
                return CallbackProgression::Continue;
            }
            let node = details.node_id.value();
            let index = match known.iter().position(|r| r.listener == details.listener_id) {
                Some(index) => index,
                None => {
                    known.push(Ring::open(details.listener_id, node));
                    known.len() - 1
                }
            };
            known[index].seen = round;
            if known.iter().any(|r| r.node == node && r.rang == round) {
                return CallbackProgression::Continue;
            }
            if !known[index].ring() {
                let _ = listener.notify();
            }
            known[index].rang = round;
            CallbackProgression::Continue
        });
        known.retain(|r| r.seen == round);
    }
}

impl Ring {
    fn open(listener: UniqueListenerId, node: u128) -> Ring {
        let path = doorbell_path(Config::global_config(), node);
        // Non-blocking: a node that is not reading (busy, or frozen with a full pipe) has been
        // rung already; the open fails unless the node holds the pipe open.
        let pipe = nix::fcntl::open(
            &path,
            OFlag::O_WRONLY | OFlag::O_NONBLOCK | OFlag::O_CLOEXEC,
            Mode::empty(),
        )
        .ok();
        Ring {
            listener,
            node,
            pipe,
            seen: 0,
            rang: 0,
        }
    }

    /// Writes one ring; whether the node has it (a full pipe holds rings already). A node that
    /// closed its pipe (ended) is not rung again.
    fn ring(&mut self) -> bool {
        let Some(pipe) = &self.pipe else {
            return false;
        };
        match nix::unistd::write(pipe, &[1]) {
            Ok(_) | Err(Errno::EAGAIN) => true,
            Err(_) => {
                self.pipe = None;
                false
            }
        }
    }
}
