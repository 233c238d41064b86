//! Samples from the peer, waiting for the bridge's thread: filled by zenoh's threads in arrival
//! order, emptied by the thread that publishes them here.
//!
//! A reliable topic's sample waits for room when the inbox is full: zenoh's receiving thread
//! then stops reading, the link fills, and the peer's `Block` publisher waits, as a full queue
//! makes a lockstep publisher wait on one machine. A newest-only topic's sample (realtime bulk)
//! replaces its predecessor still waiting, so a slow side publishes the newest scan, not a
//! backlog.

use std::collections::VecDeque;
use std::sync::{Condvar, Mutex};
use std::time::Duration;

/// Samples the inbox holds before a reliable one waits for room.
pub const INBOX_CAPACITY: usize = 256;

/// One sample of topic `topic` (an index into the bridge's topics in).
#[derive(Debug)]
pub struct Entry<T> {
    pub topic: usize,
    pub item: T,
    /// A reply to a history request rather than a live sample.
    pub history: bool,
}

/// The inbox; `wake` tells the bridge's thread that something came.
pub struct Inbox<T> {
    entries: Mutex<VecDeque<Entry<T>>>,
    room: Condvar,
    wake: Box<dyn Fn() + Send + Sync>,
}

impl<T> Inbox<T> {
    #[must_use]
    pub fn new(wake: impl Fn() + Send + Sync + 'static) -> Inbox<T> {
        Inbox {
            entries: Mutex::new(VecDeque::with_capacity(INBOX_CAPACITY)),
            room: Condvar::new(),
            wake: Box::new(wake),
        }
    }

    /// Adds `entry` at the back; see the module docs for `newest_only` and a full inbox.
    pub fn push(&self, entry: Entry<T>, newest_only: bool) {
        let mut entries = self.entries.lock().unwrap_or_else(|e| e.into_inner());
        if newest_only {
            entries.retain(|e| e.topic != entry.topic);
        } else {
            while entries.len() >= INBOX_CAPACITY {
                entries = self
                    .room
                    .wait_timeout(entries, Duration::from_millis(100))
                    .unwrap_or_else(|e| e.into_inner())
                    .0;
            }
        }
        entries.push_back(entry);
        drop(entries);
        (self.wake)();
    }

    /// The oldest entry, if any.
    pub fn pop(&self) -> Option<Entry<T>> {
        let entry = self
            .entries
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .pop_front();
        self.room.notify_one();
        entry
    }

    /// Entries waiting.
    pub fn len(&self) -> usize {
        self.entries.lock().unwrap_or_else(|e| e.into_inner()).len()
    }

    /// Whether nothing waits.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Arc;
    use std::sync::atomic::{AtomicUsize, Ordering};

    fn entry(topic: usize, item: u32) -> Entry<u32> {
        Entry {
            topic,
            item,
            history: false,
        }
    }

    #[test]
    fn entries_leave_in_arrival_order_and_each_push_wakes() {
        let wakes = Arc::new(AtomicUsize::new(0));
        let counted = wakes.clone();
        let inbox = Inbox::new(move || {
            counted.fetch_add(1, Ordering::SeqCst);
        });
        for (topic, item) in [(1, 10), (0, 11), (1, 12)] {
            inbox.push(entry(topic, item), false);
        }
        let order: Vec<u32> = std::iter::from_fn(|| inbox.pop().map(|e| e.item)).collect();
        assert_eq!(order, [10, 11, 12]);
        assert_eq!(wakes.load(Ordering::SeqCst), 3);
    }

    #[test]
    fn a_newest_only_sample_replaces_its_waiting_predecessor_only() {
        let inbox = Inbox::new(|| {});
        inbox.push(entry(0, 1), true);
        inbox.push(entry(1, 2), false);
        inbox.push(entry(0, 3), true);
        let left: Vec<(usize, u32)> =
            std::iter::from_fn(|| inbox.pop().map(|e| (e.topic, e.item))).collect();
        assert_eq!(left, [(1, 2), (0, 3)]);
    }

    #[test]
    fn a_reliable_sample_waits_for_room_in_a_full_inbox() {
        let inbox = Arc::new(Inbox::new(|| {}));
        for i in 0..INBOX_CAPACITY {
            inbox.push(entry(0, i as u32), false);
        }
        let done = Arc::new(AtomicUsize::new(0));
        let (pusher_inbox, pusher_done) = (inbox.clone(), done.clone());
        let pusher = std::thread::spawn(move || {
            pusher_inbox.push(entry(0, u32::MAX), false);
            pusher_done.store(1, Ordering::SeqCst);
        });
        std::thread::sleep(Duration::from_millis(300));
        assert_eq!(
            done.load(Ordering::SeqCst),
            0,
            "the push waited: nothing was dropped"
        );
        assert_eq!(inbox.len(), INBOX_CAPACITY);
        assert_eq!(inbox.pop().map(|e| e.item), Some(0));
        pusher
            .join()
            .expect("the pusher finishes once there is room");
        assert_eq!(inbox.len(), INBOX_CAPACITY);
        let last = std::iter::from_fn(|| inbox.pop()).last().map(|e| e.item);
        assert_eq!(last, Some(u32::MAX));
    }
}
