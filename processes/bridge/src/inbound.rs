//! A sample from the peer: checked against this host's layout of the topic, and ordered.
//!
//! Every sample travels with its message's layout (type name, size, alignment) as its zenoh
//! attachment, so hosts built from different message definitions are refused with the same
//! sentence as two processes on one machine. A topic with history is also fetched from the peer
//! when the link comes up (a host that joins late gets `world/map`); such a reply may repeat or
//! trail what already came live, and is forwarded only when it is newer.
//!
//! [`Ins`] are the bridge's topics in: a zenoh subscriber on `mole/<peer>/<topic>` each, whose
//! samples join one inbox in arrival order (zenoh's thread rings the bridge's doorbell) and are
//! published here once [`Forwarding`] lets them.

use crate::{BridgeSpec, Delivery, Entry, Failed, Inbox, delivery, key_expr};
use mole_runtime::{BadInput, Context, PayloadLayout, Publisher, Ringer, layout_mismatch};
use mole_types::topics::{self, OpenTopic};
use mole_types::{Header, Message, Topic};
use std::sync::Arc;
use std::time::Duration;
use zenoh::Wait;
use zenoh::bytes::ZBytes;
use zenoh::sample::Sample;

/// The layout a sample carries and is checked against, as the runtime names layouts in its
/// errors: `` `mole.Scan.v1` (4144 bytes, aligned to 8) ``.
#[must_use]
pub fn descriptor<M: Message>() -> String {
    PayloadLayout::of::<M>().to_string()
}

/// What becomes of a sample from the peer.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Forward {
    /// Publish it here; `lost` samples of the peer's publisher never came before it.
    Publish { lost: u64 },
    /// The very sample forwarded last (a history reply that crossed a live one): skip it.
    Duplicate,
    /// A history reply older than what was forwarded already: skip it.
    Stale,
    /// Not a whole message of this topic (`len` bytes): drop and count it.
    Malformed { len: usize },
    /// Another layout than this host's (the peer's descriptor, or why there is none): the
    /// hosts cannot exchange this topic.
    Mismatch { found: String },
}

/// The order of one topic's samples from the peer.
#[derive(Debug, Clone)]
pub struct Forwarding {
    expected: String,
    size: usize,
    /// `(seq, stamp_ns, tick)` of the sample forwarded last.
    last: Option<(u64, u64, u64)>,
}

impl Forwarding {
    /// The order of a topic carrying `M`.
    #[must_use]
    pub fn new<M: Message>() -> Forwarding {
        Forwarding {
            expected: descriptor::<M>(),
            size: core::mem::size_of::<M>(),
            last: None,
        }
    }

    /// The descriptor this host expects.
    #[must_use]
    pub fn expected(&self) -> &str {
        &self.expected
    }

    /// Judges a sample: its `attachment` (the sender's descriptor), its `payload`, and whether
    /// it is a reply to a history request rather than a live sample.
    pub fn judge(&mut self, attachment: Option<&[u8]>, payload: &[u8], history: bool) -> Forward {
        match attachment {
            Some(found) if found == self.expected.as_bytes() => {}
            Some(found) => {
                return Forward::Mismatch {
                    found: String::from_utf8_lossy(found).into_owned(),
                };
            }
            None => {
                return Forward::Mismatch {
                    found: "a sample without its layout (not sent by a mole bridge)".to_owned(),
                };
            }
        }
        if payload.len() != self.size {
            return Forward::Malformed { len: payload.len() };
        }
        let header: Header =
            bytemuck::pod_read_unaligned(&payload[..core::mem::size_of::<Header>()]);
        let this = (header.seq, header.stamp_ns, header.tick);
        let lost = match self.last {
            Some((seq, stamp, _)) if (seq, stamp) == (this.0, this.1) => return Forward::Duplicate,
            Some((_, _, tick)) if history && this.2 <= tick => return Forward::Stale,
            // A gap in the sender's sequence; a lower one is a new publisher (a restart).
            Some((seq, _, _)) if !history && this.0 > seq + 1 => this.0 - seq - 1,
            _ => 0,
        };
        self.last = Some(this);
        Forward::Publish { lost }
    }
}

/// What zenoh's threads leave for the bridge's: samples from the peer, in arrival order.
pub type PeerInbox = Inbox<Sample>;

/// Every topic from the peer, the inbox their samples wait in, and the peer's namespace.
pub struct Ins {
    ins: Vec<Box<dyn In>>,
    inbox: Arc<PeerInbox>,
    peer: String,
}

impl Ins {
    /// Opens every topic of `spec.inbound`: a zenoh subscriber into the inbox, whose every
    /// sample rings `ringer`, and a publisher here.
    pub fn open(
        ctx: &Context,
        session: &zenoh::Session,
        spec: &BridgeSpec,
        ringer: &Ringer,
    ) -> Result<Ins, Failed> {
        let wake = ringer.clone();
        let inbox = Arc::new(PeerInbox::new(move || wake.ring()));
        let ins = open_ins(ctx, session, spec, &inbox)?;
        Ok(Ins {
            ins,
            inbox,
            peer: spec.peer_namespace.clone(),
        })
    }

    /// Asks the peer for the newest sample of every topic in that keeps history; the replies
    /// join the inbox and are forwarded only where they are news.
    pub fn ask_history(&self, session: &zenoh::Session) {
        ask_history(session, &self.peer, &self.ins, &self.inbox);
    }

    /// Publishes here every sample waiting in the inbox, in arrival order, that [`Forwarding`]
    /// lets through; a layout mismatch ends the bridge.
    pub fn forward_waiting(&mut self) -> Result<(), BadInput> {
        while let Some(entry) = self.inbox.pop() {
            self.ins[entry.topic].forward(&entry.item, entry.history)?;
        }
        Ok(())
    }
}

/// A topic from the peer, whatever its message type.
trait In {
    /// Publishes `sample` here if [`Forwarding`] says so; a layout mismatch ends the bridge.
    fn forward(&mut self, sample: &Sample, history: bool) -> Result<(), BadInput>;
    /// Its key on the peer's side, if it keeps history.
    fn history_key(&self) -> Option<&str>;
}

struct TypedIn<M: Message> {
    publisher: Publisher<M>,
    forwarding: Forwarding,
    peer_key: String,
    history: bool,
    _subscriber: zenoh::pubsub::Subscriber<()>,
    malformed: u64,
}

impl<M: Message> In for TypedIn<M> {
    fn forward(&mut self, sample: &Sample, history: bool) -> Result<(), BadInput> {
        let payload = sample.payload().to_bytes();
        let attachment = sample.attachment().map(ZBytes::to_bytes);
        match self
            .forwarding
            .judge(attachment.as_deref(), &payload, history)
        {
            Forward::Publish { lost } => {
                if lost > 0 {
                    self.publisher.count_lost(lost);
                }
                let header: Header =
                    bytemuck::pod_read_unaligned(&payload[..core::mem::size_of::<Header>()]);
                let published = self.publisher.publish(header.tick, header.origin_ns, |m| {
                    bytemuck::bytes_of_mut(m).copy_from_slice(&payload);
                });
                if let Err(e) = published {
                    tracing::warn!(topic = self.publisher.topic(), "{e}");
                }
            }
            Forward::Duplicate | Forward::Stale => {}
            Forward::Malformed { len } => {
                self.publisher.count_invalid();
                self.malformed += 1;
                if self.malformed.is_power_of_two() {
                    tracing::warn!(
                        topic = self.publisher.topic(),
                        len,
                        dropped = self.malformed,
                        "dropped a sample from the peer that is not one whole message"
                    );
                }
            }
            Forward::Mismatch { found } => {
                return Err(BadInput(format!(
                    "cannot open topic `{}` from the peer's bridge ({}): {}",
                    self.publisher.topic(),
                    self.peer_key,
                    layout_mismatch(&PayloadLayout::of::<M>(), &found)
                )));
            }
        }
        Ok(())
    }
    fn history_key(&self) -> Option<&str> {
        self.history.then_some(self.peer_key.as_str())
    }
}

fn open_ins(
    ctx: &Context,
    session: &zenoh::Session,
    spec: &BridgeSpec,
    inbox: &Arc<PeerInbox>,
) -> Result<Vec<Box<dyn In>>, Failed> {
    struct Open<'a> {
        ctx: &'a Context,
        session: &'a zenoh::Session,
        spec: &'a BridgeSpec,
        inbox: &'a Arc<PeerInbox>,
        /// The inputs opened so far: the next one's index in the inbox's entries.
        opened: usize,
    }
    impl OpenTopic for Open<'_> {
        type Port = Box<dyn In>;
        type Error = Failed;
        fn open<M: Message>(&mut self, topic: Topic<M>) -> Result<Box<dyn In>, Failed> {
            let peer_key = key_expr(&self.spec.peer_namespace, topic.name);
            let newest_only = delivery(topic.name, self.ctx.mode()) == Delivery::Newest;
            let (inbox, index) = (self.inbox.clone(), self.opened);
            self.opened += 1;
            let subscriber = self
                .session
                .declare_subscriber(peer_key.clone())
                .callback(move |sample| {
                    let entry = Entry {
                        topic: index,
                        item: sample,
                        history: false,
                    };
                    inbox.push(entry, newest_only);
                })
                .wait()?;
            Ok(Box::new(TypedIn {
                publisher: self.ctx.publisher(topic)?,
                forwarding: Forwarding::new::<M>(),
                peer_key,
                history: topic.history > 0,
                _subscriber: subscriber,
                malformed: 0,
            }))
        }
    }
    let wanted = |name: &str| spec.inbound.contains(&name);
    let mut open = Open {
        ctx,
        session,
        spec,
        inbox,
        opened: 0,
    };
    topics::open_each(wanted, &mut open)
}

/// Asks the peer for the newest sample of every topic in that keeps history; the replies join
/// the inbox and are forwarded only where they are news.
fn ask_history(session: &zenoh::Session, peer: &str, ins: &[Box<dyn In>], inbox: &Arc<PeerInbox>) {
    for (index, input) in ins.iter().enumerate() {
        let Some(key) = input.history_key() else {
            continue;
        };
        let inbox = inbox.clone();
        let asked = session
            .get(key)
            .timeout(Duration::from_secs(2))
            .callback(move |reply| {
                if let Ok(sample) = reply.result() {
                    let entry = Entry {
                        topic: index,
                        item: sample.clone(),
                        history: true,
                    };
                    inbox.push(entry, false);
                }
            })
            .wait();
        if let Err(e) = asked {
            tracing::warn!(peer, key, "cannot ask for history: {e}");
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use mole_types::{Pose, Scan};

    fn sample(seq: u64, stamp_ns: u64, tick: u64) -> Vec<u8> {
        let mut pose: Pose = bytemuck::Zeroable::zeroed();
        pose.header = Header {
            seq,
            tick,
            stamp_ns,
            origin_ns: 1,
        };
        bytemuck::bytes_of(&pose).to_vec()
    }

    #[test]
    fn the_descriptor_names_type_size_and_alignment() {
        let d = descriptor::<Scan>();
        assert!(d.contains("mole.Scan.v1"), "{d}");
        assert!(
            d.contains(&format!("{} bytes", core::mem::size_of::<Scan>())),
            "{d}"
        );
    }

    #[test]
    fn another_layout_is_a_mismatch_naming_what_came() {
        let mut f = Forwarding::new::<Pose>();
        let theirs = descriptor::<Scan>();
        assert_eq!(
            f.judge(Some(theirs.as_bytes()), &sample(0, 1, 1), false),
            Forward::Mismatch { found: theirs }
        );
        assert!(matches!(
            f.judge(None, &sample(0, 1, 1), false),
            Forward::Mismatch { .. }
        ));
    }

    #[test]
    fn a_sample_of_the_wrong_length_is_malformed() {
        let mut f = Forwarding::new::<Pose>();
        let ours = descriptor::<Pose>();
        let mut short = sample(0, 1, 1);
        short.pop();
        assert_eq!(
            f.judge(Some(ours.as_bytes()), &short, false),
            Forward::Malformed { len: short.len() }
        );
    }

    #[test]
    fn live_samples_pass_and_gaps_count_as_lost() {
        let mut f = Forwarding::new::<Pose>();
        let ours = descriptor::<Pose>();
        let d = Some(ours.as_bytes());
        assert_eq!(
            f.judge(d, &sample(4, 10, 1), false),
            Forward::Publish { lost: 0 }
        );
        assert_eq!(
            f.judge(d, &sample(5, 11, 2), false),
            Forward::Publish { lost: 0 }
        );
        assert_eq!(
            f.judge(d, &sample(9, 12, 6), false),
            Forward::Publish { lost: 3 }
        );
        // A restarted sender counts from 0 again: nothing lost.
        assert_eq!(
            f.judge(d, &sample(0, 13, 7), false),
            Forward::Publish { lost: 0 }
        );
    }

    #[test]
    fn a_history_reply_is_forwarded_only_when_new() {
        let mut f = Forwarding::new::<Pose>();
        let ours = descriptor::<Pose>();
        let d = Some(ours.as_bytes());
        assert_eq!(
            f.judge(d, &sample(0, 10, 0), true),
            Forward::Publish { lost: 0 },
            "nothing came yet: the reply is the news"
        );
        assert_eq!(
            f.judge(d, &sample(0, 10, 0), false),
            Forward::Duplicate,
            "the same sample live"
        );
        assert_eq!(
            f.judge(d, &sample(1, 20, 1), false),
            Forward::Publish { lost: 0 }
        );
        assert_eq!(
            f.judge(d, &sample(0, 10, 0), true),
            Forward::Stale,
            "a late reply is older"
        );
    }
}
