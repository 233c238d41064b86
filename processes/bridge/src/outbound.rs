//! The order this host's samples leave in: the order they were published here, across topics.
//!
//! One machine's processes rely on that order: sensing publishes odometry last, so a process
//! woken by it finds the step's other readings in (docs/architecture.md), and an input that does
//! not wake its process must not arrive after the one that does. Draining the topics one by one
//! would break it (a topic looked at before its sample came, the next one after, or a topic's
//! backlog sent before an older sample of the next topic), so the samples are gathered until a
//! pass over every topic finds nothing new, and sent by their publication stamps.
//!
//! [`Outs`] are the bridge's topics out: an iceoryx2 subscriber here (it wakes the bridge) and a
//! zenoh publisher on `mole/<ns>/<topic>` each, the message's layout attached to every sample; a
//! topic with history also answers the peer's queries with its newest sample.

use crate::{BridgeSpec, Failed, delivery, descriptor, key_expr, qos};
use mole_runtime::{Context, Subscriber, Waker};
use mole_types::topics::{self, OpenTopic};
use mole_types::{Message, Topic};
use std::sync::{Arc, Mutex};
use zenoh::Wait;
use zenoh::bytes::ZBytes;

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

/// Every topic sent to the peer, and the buffer its samples wait in to leave in order.
pub struct Outs {
    outs: Vec<Box<dyn Out>>,
    staged: Vec<Staged<ZBytes>>,
}

impl Outs {
    /// Opens every topic of `spec.out`: a subscriber here, a zenoh publisher (and, for a topic
    /// with history, a queryable) on the session.
    pub fn open(
        ctx: &Context,
        session: &zenoh::Session,
        spec: &BridgeSpec,
    ) -> Result<Outs, Failed> {
        let outs = open_outs(ctx, session, spec)?;
        let staged = Vec::with_capacity(4 * outs.len());
        Ok(Outs { outs, staged })
    }

    /// The wakers of the topics sent: a sample of any wakes the bridge.
    #[must_use]
    pub fn wakers(&self) -> Vec<Waker> {
        self.outs.iter().map(|o| o.waker()).collect()
    }

    /// Sends every new sample of every topic, in the order they were published here
    /// ([`send_in_order`]).
    pub fn send_in_order(&mut self) {
        send_in_order(&mut self.outs, &mut self.staged);
    }
}

/// A topic sent to the peer, whatever its message type: it wakes the bridge, and its samples
/// leave in publication order ([`send_in_order`]).
trait Out: Outbound<Bytes = ZBytes> {
    fn waker(&self) -> Waker;
}

struct TypedOut<M: Message> {
    subscriber: Subscriber<M>,
    publisher: zenoh::pubsub::Publisher<'static>,
    /// The message's layout, attached to every sample.
    layout: ZBytes,
    /// The newest sample, which the queryable hands a peer that asks (topics with history).
    newest: Option<Arc<Mutex<Option<ZBytes>>>>,
    _queryable: Option<zenoh::query::Queryable<()>>,
    failed_sends: u64,
}

impl<M: Message> Out for TypedOut<M> {
    fn waker(&self) -> Waker {
        self.subscriber.waker()
    }
}

impl<M: Message> Outbound for TypedOut<M> {
    type Bytes = ZBytes;
    fn collect(&mut self, topic: usize, staged: &mut Vec<Staged<ZBytes>>) {
        self.subscriber.drain(|message| {
            staged.push(Staged {
                stamp_ns: message.header().stamp_ns,
                topic,
                // The one copy: the network needs bytes of its own.
                bytes: ZBytes::from(bytemuck::bytes_of(message).to_vec()),
            });
        });
    }
    fn send(&mut self, bytes: ZBytes) {
        if let Some(newest) = &self.newest {
            *newest.lock().unwrap_or_else(|e| e.into_inner()) = Some(bytes.clone());
        }
        if let Err(e) = self
            .publisher
            .put(bytes)
            .attachment(self.layout.clone())
            .wait()
        {
            self.failed_sends += 1;
            if self.failed_sends.is_power_of_two() {
                tracing::warn!(
                    key = self.publisher.key_expr().as_str(),
                    sends = self.failed_sends,
                    "send failed: {e}"
                );
            }
        }
    }
}

fn open_outs(
    ctx: &Context,
    session: &zenoh::Session,
    spec: &BridgeSpec,
) -> Result<Vec<Box<dyn Out>>, Failed> {
    struct Open<'a> {
        ctx: &'a Context,
        session: &'a zenoh::Session,
        spec: &'a BridgeSpec,
    }
    impl OpenTopic for Open<'_> {
        type Port = Box<dyn Out>;
        type Error = Failed;
        fn open<M: Message>(&mut self, topic: Topic<M>) -> Result<Box<dyn Out>, Failed> {
            let key = key_expr(&self.spec.namespace, topic.name);
            let (congestion, priority, express) = qos(delivery(topic.name, self.ctx.mode()));
            let publisher = self
                .session
                .declare_publisher(key.clone())
                .congestion_control(congestion)
                .priority(priority)
                .express(express)
                .wait()?;
            let layout = ZBytes::from(descriptor::<M>());
            let (newest, queryable) = if topic.history > 0 {
                let newest: Arc<Mutex<Option<ZBytes>>> = Arc::default();
                let (held, attached, reply_key) = (newest.clone(), layout.clone(), key.clone());
                let queryable = self
                    .session
                    .declare_queryable(key)
                    .callback(move |query| {
                        let sample = held.lock().unwrap_or_else(|e| e.into_inner()).clone();
                        if let Some(sample) = sample
                            && let Err(e) = query
                                .reply(reply_key.clone(), sample)
                                .attachment(attached.clone())
                                .wait()
                        {
                            tracing::warn!(key = %reply_key, "history reply failed: {e}");
                        }
                    })
                    .wait()?;
                (Some(newest), Some(queryable))
            } else {
                (None, None)
            };
            Ok(Box::new(TypedOut {
                subscriber: self.ctx.subscriber(topic)?,
                publisher,
                layout,
                newest,
                _queryable: queryable,
                failed_sends: 0,
            }))
        }
    }
    let wanted = |name: &str| spec.out.contains(&name);
    topics::open_each(wanted, &mut Open { ctx, session, spec })
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
