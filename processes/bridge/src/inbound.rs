//! A sample from the peer: checked against this host's layout of the topic, and ordered.
//!
//! Every sample travels with its message's layout (type name, size, alignment) as its zenoh
//! attachment, so hosts built from different message definitions are refused with the same
//! sentence as two processes on one machine. A topic with history is also fetched from the peer
//! when the link comes up (a host that joins late gets `world/map`); such a reply may repeat or
//! trail what already came live, and is forwarded only when it is newer.

use mole_runtime::PayloadLayout;
use mole_types::{Header, Message};

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
