//! Two robots exchange their landmark maps (algorithms §6.9): each offers its map to the other
//! on [`PEER_LANDMARKS`] and, every few steps, fuses the newest map the other offered into its
//! own by covariance intersection ([`crate::Estimator::fuse_landmarks`]; EKF-SLAM only).
//!
//! Why CI and not the naive information sum: after the first exchange each robot's map already
//! holds some of the other's information, so the two maps are correlated by an amount nobody
//! tracks; summing their information counts it twice at every exchange and the covariances
//! shrink without bound (over-confident, NEES far above its χ² interval). CI is consistent for
//! every cross-correlation (Julier & Uhlmann 1997).
//!
//! Both robots must share the map frame: each EKF-SLAM starts at its scenario's start pose with
//! Σ = 0, so robots whose scenarios place them in the same world coordinates do.

use crate::Estimator;
use crate::slam::FuseReport;
use mole_runtime::{BadInput, In, Process, Publisher, RuntimeError, Step};
use mole_types::{EstimatorKind, Landmarks};
use thiserror::Error;

pub use mole_types::topics::PEER_LANDMARKS;

/// Steps between two fusions of the peer's map by default: 1 s at 100 Hz.
pub const DEFAULT_FUSE_EVERY: u64 = 100;

/// The estimator that fuses a peer's map.
pub const FUSING_ESTIMATOR: EstimatorKind = EstimatorKind::EkfSlam;

/// Why `--peer` is refused at start.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum PeerRefused {
    /// The estimator cannot fuse another robot's map.
    #[error(
        "--peer needs --estimator {}, the estimator that fuses a peer's landmark map by \
         covariance intersection; {got} cannot",
        FUSING_ESTIMATOR.name()
    )]
    Estimator {
        /// The estimator asked for.
        got: &'static str,
    },
    /// The namespace is empty or has characters a service name cannot carry.
    #[error("--peer `{0}`: expected a namespace of letters, digits, '-', '_' or '.'")]
    Namespace(String),
    /// The namespace is this robot's own.
    #[error("--peer `{0}` is this robot's own namespace: a peer is another robot's stack")]
    Own(String),
}

/// Two robots: the command-line options of a robot that exchanges its landmark map.
#[derive(Debug, Clone, clap::Args)]
pub struct PeerArgs {
    /// Another robot's namespace: offer it this robot's landmark map and fuse the one it offers
    /// by covariance intersection (ekf-slam only).
    #[arg(long, value_name = "NAMESPACE")]
    pub peer: Option<String>,
    /// With --peer: fuse the peer's newest map every this many steps.
    #[arg(long, value_name = "TICKS", default_value_t = DEFAULT_FUSE_EVERY,
          value_parser = clap::value_parser!(u64).range(1..))]
    pub fuse_every: u64,
}

impl PeerArgs {
    /// The peer's namespace, checked for a robot in namespace `own` running `kind`.
    pub fn checked(&self, kind: EstimatorKind, own: &str) -> Result<Option<&str>, PeerRefused> {
        match self.peer.as_deref() {
            Some(peer) => check_peer(kind, own, peer).map(|()| Some(peer)),
            None => Ok(None),
        }
    }
}

/// Checks `--peer peer` for a robot in namespace `own` running estimator `kind`.
pub fn check_peer(kind: EstimatorKind, own: &str, peer: &str) -> Result<(), PeerRefused> {
    if kind != FUSING_ESTIMATOR {
        return Err(PeerRefused::Estimator { got: kind.name() });
    }
    let valid = |c: char| c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.');
    if peer.is_empty() || !peer.chars().all(valid) {
        return Err(PeerRefused::Namespace(peer.to_string()));
    }
    if peer == own {
        return Err(PeerRefused::Own(peer.to_string()));
    }
    Ok(())
}

/// What the fusions of a run did, summed.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct FusionTotals {
    /// Peer maps fused (one per round that found a new map).
    pub rounds: u64,
    /// Landmarks both maps had, fused by covariance intersection (ω < 1).
    pub fused: u64,
    /// Landmarks both maps had that CI left as they were (ω = 1).
    pub kept: u64,
    /// Landmarks only the peer had, left for this robot to map.
    pub unmapped: u64,
    /// Peer landmarks refused: not finite, not positive definite, or beyond the capacity.
    pub refused: u64,
}

/// When to fuse the peer's map: every `every` steps, and only a map not fused before.
#[derive(Debug, Clone)]
pub struct PeerFusion {
    every: u64,
    /// The first step at which the next round is due.
    due: u64,
    /// `stamp_ns` of the last map fused: the peer publishes a new one each of its steps.
    last_stamp: Option<u64>,
    totals: FusionTotals,
}

impl PeerFusion {
    /// A round every `every` steps (at least 1), the first one after `every` steps.
    pub fn new(every: u64) -> Self {
        let every = every.max(1);
        Self {
            every,
            due: every,
            last_stamp: None,
            totals: FusionTotals::default(),
        }
    }

    /// At step `tick`: when a round is due and `offer`, the peer's newest map, is one not fused
    /// before, fuses it into `estimator` and returns what that did. Allocates nothing.
    pub fn step(
        &mut self,
        tick: u64,
        offer: Option<&Landmarks>,
        estimator: &mut dyn Estimator,
    ) -> Option<FuseReport> {
        if tick < self.due {
            return None;
        }
        self.due = tick + self.every;
        let map = offer.filter(|m| Some(m.header.stamp_ns) != self.last_stamp)?;
        self.last_stamp = Some(map.header.stamp_ns);
        let report = estimator.fuse_landmarks(map)?;
        self.totals.rounds += 1;
        self.totals.fused += report.fused as u64;
        self.totals.kept += report.kept as u64;
        self.totals.unmapped += report.unmapped as u64;
        self.totals.refused += report.refused as u64;
        Some(report)
    }

    /// What the rounds so far did.
    pub fn totals(&self) -> FusionTotals {
        self.totals
    }

    /// Logs the totals, at the end of a run with `peer`.
    pub fn log_totals(&self, peer: &str) {
        let t = self.totals;
        tracing::info!(
            peer,
            rounds = t.rounds,
            fused = t.fused,
            kept = t.kept,
            unmapped = t.unmapped,
            refused = t.refused,
            "peer fusion totals"
        );
    }
}

/// A robot's link to its peer (`--peer`): the peer's offered landmark map read each step and
/// fused by [`PeerFusion`], this robot's map offered after each step. Without `--peer` it does
/// nothing.
pub struct PeerLink {
    link: Option<Link>,
}

struct Link {
    peer: String,
    offered: In<Landmarks>,
    offer_out: Publisher<Landmarks>,
    fusion: PeerFusion,
}

impl PeerLink {
    /// The link `args` ask for, opened on `p`'s ports. A peer refused ([`PeerArgs::checked`])
    /// is bad input.
    pub fn open(
        p: &mut Process,
        args: &PeerArgs,
        kind: EstimatorKind,
        own: &str,
    ) -> Result<PeerLink, Box<dyn std::error::Error>> {
        let Some(peer) = args
            .checked(kind, own)
            .map_err(|e| BadInput(e.to_string()))?
        else {
            return Ok(PeerLink { link: None });
        };
        let link = Link {
            offered: p.peer_input(peer, PEER_LANDMARKS)?,
            offer_out: p.peer_output(PEER_LANDMARKS)?,
            peer: peer.to_string(),
            fusion: PeerFusion::new(args.fuse_every),
        };
        Ok(PeerLink { link: Some(link) })
    }

    /// Before the step's estimate is published: fuses the peer's newest map when a round is due.
    pub fn fuse(&mut self, step: &Step, estimator: &mut dyn Estimator) {
        if let Some(link) = self.link.as_mut() {
            link.fusion
                .step(step.tick(), step.get(link.offered), estimator);
        }
    }

    /// After it: offers this robot's map of step `k`.
    pub fn offer(
        &mut self,
        k: u64,
        origin: u64,
        estimator: &dyn Estimator,
    ) -> Result<(), RuntimeError> {
        match self.link.as_mut() {
            Some(link) => link
                .offer_out
                .publish(k, origin, |out| _ = estimator.write_landmarks(out)),
            None => Ok(()),
        }
    }

    /// Logs what the fusions did, at the end of the run.
    pub fn log_totals(&self) {
        if let Some(link) = &self.link {
            link.fusion.log_totals(&link.peer);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::build_estimator;
    use crate::test_support::zeroed_map;

    /// A peer map of `n` landmarks (ids 0..n, 5 cm σ) stamped `stamp_ns`.
    fn peer_map(n: usize, stamp_ns: u64) -> Box<Landmarks> {
        let mut map: Box<Landmarks> = bytemuck::zeroed_box();
        map.header.stamp_ns = stamp_ns;
        map.estimator = EstimatorKind::EkfSlam.code();
        map.n_landmarks = n as u32;
        for (i, l) in map.landmarks.iter_mut().take(n).enumerate() {
            l.id = i as u32;
            (l.x, l.y) = (i as f64, 1.0);
            l.covariance = [0.0025, 0.0, 0.0, 0.0025];
        }
        map
    }

    /// `--peer` is accepted exactly for the estimators that can fuse a peer's map, and
    /// refused, naming the valid choice, for the others; bad and own namespaces are refused.
    #[test]
    fn check_peer_accepts_exactly_the_estimators_that_fuse() {
        let mut map = zeroed_map();
        (map.arena_width, map.arena_height) = (4.0, 3.0);
        for &kind in EstimatorKind::ALL {
            let mut est = build_estimator(kind, &map).unwrap();
            let fuses = est.fuse_landmarks(&peer_map(1, 1)).is_some();
            let check = check_peer(kind, "robot0", "robot1");
            assert_eq!(check.is_ok(), fuses, "{kind:?}: {check:?}");
            if let Err(e) = check {
                assert!(e.to_string().contains("--estimator ekf-slam"), "{e}");
            }
        }
        let kind = EstimatorKind::EkfSlam;
        assert_eq!(
            check_peer(kind, "robot0", "robot0"),
            Err(PeerRefused::Own("robot0".into()))
        );
        for bad in ["", "robot 1", "a/b"] {
            assert_eq!(
                check_peer(kind, "robot0", bad),
                Err(PeerRefused::Namespace(bad.into()))
            );
        }
    }

    /// Rounds come every `every` steps and fuse only a map not fused before: a repeat of the
    /// same map is skipped, a new one is a round. (This robot has mapped nothing yet, so every
    /// peer landmark is left unmapped; the fusion itself is tested in tests/slam_ci.rs.)
    #[test]
    fn a_round_every_n_steps_fuses_only_a_new_map() {
        let mut map = zeroed_map();
        (map.arena_width, map.arena_height) = (4.0, 3.0);
        let mut est = build_estimator(EstimatorKind::EkfSlam, &map).unwrap();
        let mut fusion = PeerFusion::new(10);
        let first = peer_map(3, 1);
        assert_eq!(fusion.step(9, Some(&first), est.as_mut()), None, "not due");
        let report = fusion.step(10, Some(&first), est.as_mut()).expect("due");
        assert_eq!(
            (report.fused + report.kept, report.unmapped, report.refused),
            (0, 3, 0)
        );
        assert_eq!(fusion.step(15, Some(&first), est.as_mut()), None, "not due");
        assert_eq!(
            fusion.step(20, Some(&first), est.as_mut()),
            None,
            "same map"
        );
        assert_eq!(fusion.step(30, None, est.as_mut()), None, "no map");
        let second = fusion
            .step(40, Some(&peer_map(4, 2)), est.as_mut())
            .unwrap();
        assert_eq!((second.fused + second.kept, second.unmapped), (0, 4));
        let totals = fusion.totals();
        assert_eq!((totals.rounds, totals.unmapped, totals.refused), (2, 7, 0));
    }
}
