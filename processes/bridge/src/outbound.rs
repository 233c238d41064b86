//! The order this host's samples leave in: the order they were published here, across topics.
//!
//! One machine's processes rely on that order: sensing publishes odometry last, so a process
//! woken by it finds the step's other readings in (docs/architecture.md), and an input that does
//! not wake its process must not arrive after the one that does. Draining the topics one by one
//! would break it (a topic looked at before its sample came, the next one after, or a topic's
//! backlog sent before an older sample of the next topic), so the samples are gathered until a
//! pass over every topic finds nothing new, and sent by their publication stamps.

/// A sample taken from a topic here, waiting to be sent in publication order.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Staged<B> {
    /// Its header's publication stamp (`Header::stamp_ns`).
    pub stamp_ns: u64,
    /// The index of its topic among the topics sent.
    pub topic: usize,
    /// What goes on the wire.
    pub bytes: B,
}

/// A topic sent to the peer, whatever its message type.
pub trait Outbound {
    /// What one sample is on the wire.
    type Bytes;
    /// Takes every new sample into `staged`, marked with `topic` (this topic's index).
    fn collect(&mut self, topic: usize, staged: &mut Vec<Staged<Self::Bytes>>);
    /// Sends one sample it collected.
    fn send(&mut self, bytes: Self::Bytes);
}

/// Sends every new sample of every topic in `outs`, in the order they were published here;
/// `staged` is the buffer they wait in (empty again on return, its capacity kept).
pub fn send_in_order<O: Outbound + ?Sized>(
    outs: &mut [Box<O>],
    staged: &mut Vec<Staged<O::Bytes>>,
) {
    loop {
        let before = staged.len();
        for (topic, out) in outs.iter_mut().enumerate() {
            out.collect(topic, staged);
        }
        if staged.len() == before {
            break;
        }
    }
    // Stable: a topic's samples keep their order should two stamps be equal.
    staged.sort_by_key(|s| s.stamp_ns);
    for sample in staged.drain(..) {
        outs[sample.topic].send(sample.bytes);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::cell::RefCell;
    use std::collections::VecDeque;
    use std::rc::Rc;

    /// What the fake topics share: samples published on each, in the order of a script, and
    /// everything sent, as (topic, stamp).
    #[derive(Default)]
    struct Host {
        /// Per topic, samples waiting in its subscriber.
        queued: Vec<VecDeque<u64>>,
        /// Samples still to be published: after the `n`-th look at any topic, one goes to
        /// its topic (`(n, topic, stamp)`, in order of `n`).
        later: VecDeque<(usize, usize, u64)>,
        looks: usize,
        sent: Vec<(usize, u64)>,
    }

    struct FakeTopic {
        index: usize,
        host: Rc<RefCell<Host>>,
    }

    impl Outbound for FakeTopic {
        type Bytes = u64;
        fn collect(&mut self, topic: usize, staged: &mut Vec<Staged<u64>>) {
            let mut host = self.host.borrow_mut();
            while let Some(stamp_ns) = host.queued[self.index].pop_front() {
                staged.push(Staged {
                    stamp_ns,
                    topic,
                    bytes: stamp_ns,
                });
            }
            host.looks += 1;
            while host.later.front().is_some_and(|&(n, _, _)| n <= host.looks) {
                let (_, topic, stamp) = host.later.pop_front().expect("just seen");
                host.queued[topic].push_back(stamp);
            }
        }
        fn send(&mut self, bytes: u64) {
            let index = self.index;
            self.host.borrow_mut().sent.push((index, bytes));
        }
    }

    /// `n` fake topics, boxed as the bridge's main boxes its topics of every message type.
    fn topics(host: &Rc<RefCell<Host>>, n: usize) -> Vec<Box<dyn Outbound<Bytes = u64>>> {
        host.borrow_mut().queued = vec![VecDeque::new(); n];
        (0..n)
            .map(|index| {
                Box::new(FakeTopic {
                    index,
                    host: host.clone(),
                }) as Box<dyn Outbound<Bytes = u64>>
            })
            .collect()
    }

    /// Two topics with a backlog each, published alternately (tactile 0, odometry 1: a step's
    /// tactile reading, then its odometry): they leave alternately, not one topic's backlog
    /// first.
    #[test]
    fn backlogs_leave_in_publication_order() {
        let host = Rc::new(RefCell::new(Host::default()));
        let mut outs = topics(&host, 2);
        {
            let mut h = host.borrow_mut();
            h.queued[0].extend([10, 30, 50]);
            h.queued[1].extend([20, 40, 60]);
        }
        let mut staged = Vec::new();
        send_in_order(&mut outs, &mut staged);
        assert_eq!(
            host.borrow().sent,
            vec![(0, 10), (1, 20), (0, 30), (1, 40), (0, 50), (1, 60)]
        );
        assert!(staged.is_empty());
    }

    /// A sample published on a topic already looked at, while the pass looks at the next one,
    /// still leaves before the next topic's later sample.
    #[test]
    fn a_sample_published_during_the_pass_leaves_in_its_place() {
        let host = Rc::new(RefCell::new(Host::default()));
        let mut outs = topics(&host, 2);
        {
            let mut h = host.borrow_mut();
            // Topic 0 looked at (nothing yet), then its sample 1 comes, then topic 1's sample 2.
            h.later.extend([(1, 0, 1), (1, 1, 2)]);
        }
        let mut staged = Vec::new();
        send_in_order(&mut outs, &mut staged);
        assert_eq!(host.borrow().sent, vec![(0, 1), (1, 2)]);
    }
}
