//! How each topic crosses the link, per clock mode.
//!
//! Lockstep: every sample, in order, and a full link makes the sender wait (zenoh's `Block`
//! congestion control), which makes the iceoryx2 publisher on the sending host wait in turn, as a
//! full queue does on one machine: a split lockstep run stays deterministic. Realtime: the bulky
//! topics that every step supersedes (scans, grids, particle clouds, trajectories) may be dropped
//! to the newest under congestion, so a slow link delays nothing; commands, poses, truth and the
//! rest stay reliable, and the command goes first.

use mole_runtime::ClockMode;
use mole_types::topics;
use zenoh::qos::{CongestionControl, Priority};

/// How one topic crosses.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Delivery {
    /// Every sample, in order; a congested link makes the sender wait.
    Reliable {
        /// Sent ahead of everything else (the command: the loop waits for it).
        urgent: bool,
    },
    /// Dropped under congestion; the receiver keeps only the newest not yet forwarded.
    Newest,
}

/// The delivery of `topic` in `mode`, from the topic table's policy columns (`bulk`, `urgent`).
#[must_use]
pub fn delivery(topic: &str, mode: ClockMode) -> Delivery {
    let policy = topics::policies().into_iter().find(|p| p.name == topic);
    let (bulk, urgent) = policy.map_or((false, false), |p| (p.bulk, p.urgent));
    match mode {
        ClockMode::Realtime if bulk => Delivery::Newest,
        _ => Delivery::Reliable { urgent },
    }
}

/// zenoh's congestion control, priority and express flag for a delivery.
#[must_use]
pub fn qos(delivery: Delivery) -> (CongestionControl, Priority, bool) {
    match delivery {
        Delivery::Reliable { urgent: true } => {
            (CongestionControl::Block, Priority::InteractiveHigh, true)
        }
        Delivery::Reliable { urgent: false } => (CongestionControl::Block, Priority::Data, true),
        Delivery::Newest => (CongestionControl::Drop, Priority::DataLow, false),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lockstep_carries_every_topic_reliably() {
        for (name, _) in topics::all() {
            assert!(
                matches!(
                    delivery(name, ClockMode::Lockstep),
                    Delivery::Reliable { .. }
                ),
                "{name}"
            );
        }
    }

    #[test]
    fn realtime_drops_only_bulky_topics_and_hurries_the_command() {
        assert_eq!(
            delivery(topics::SENSING_SCAN.name, ClockMode::Realtime),
            Delivery::Newest
        );
        assert_eq!(
            delivery(topics::MAPPING_GRID.name, ClockMode::Realtime),
            Delivery::Newest
        );
        assert_eq!(
            delivery(topics::LOCALIZATION_POSE.name, ClockMode::Realtime),
            Delivery::Reliable { urgent: false }
        );
        assert_eq!(
            delivery(topics::PLANNING_CMD.name, ClockMode::Realtime),
            Delivery::Reliable { urgent: true }
        );
        assert_eq!(
            delivery(topics::WORLD_MAP.name, ClockMode::Realtime),
            Delivery::Reliable { urgent: false },
            "the map is sent once: never dropped"
        );
    }
}
