//! Simultaneous localisation and mapping on range-bearing beacons: EKF-SLAM ([`EkfSlam`],
//! Thrun et al. 2005 §10.2), FastSLAM 1.0 ([`FastSlam`], §13.3), and covariance intersection
//! ([`covariance_intersection`], Julier & Uhlmann 1997) to merge another robot's landmarks
//! ([`PeerFusion`]: two robots exchanging their maps in the stack).
//!
//! Both filters take odometry (v, ω over dt) and `BeaconReading`s (range, bearing relative to
//! the heading). With [`Correspondence::Known`] the reading's id names the landmark; with
//! [`Correspondence::Unknown`] the id is ignored for association: each reading goes to the
//! maximum-likelihood landmark inside a χ² gate, or founds a new landmark when it lies outside a
//! second, looser gate around every landmark (readings between the two gates are discarded, so
//! an ambiguous reading never spawns a duplicate). A landmark founded that way keeps the id the
//! founding reading carried, as provenance only, so a caller that knows the true ids can score
//! the associations ([`Association`], [`AssociationStats`]). A reading whose id is
//! `mole_types::LANDMARK_ANONYMOUS` (a sensor that hides the ids) switches a filter to unknown
//! correspondences for the rest of the run.
//!
//! [`EkfSlamEstimator`] and [`FastSlamEstimator`] run the two filters in the process, behind
//! [`crate::Estimator`].
//!
//! Names follow Thrun et al.: R_t is the PROCESS noise covariance, Q_t the MEASUREMENT noise
//! covariance. Everything is allocated in the constructors; a step allocates nothing. Odometry
//! that [`crate::models::odometry_is_plausible`] refuses is ignored and counted, as by the
//! localisers.

mod ci;
mod ekf_slam;
mod estimators;
mod fastslam;
mod map_nees;
mod peer;

pub use ci::{Fused, covariance_intersection};
pub use ekf_slam::{EkfSlam, FuseReport, LandmarkInit, Linearisation, MotionModel, UnicycleMotion};
pub use estimators::{EkfSlamEstimator, FastSlamEstimator, SLAM_CAPACITY, write_landmarks};
pub use fastslam::{FastSlam, FastSlamConfig};
pub use map_nees::mean_nees_dof;
pub use peer::{
    DEFAULT_FUSE_EVERY, FUSING_ESTIMATOR, FusionTotals, PEER_LANDMARKS, PeerArgs, PeerFusion,
    PeerLink, PeerRefused, check_peer,
};

use crate::kalman::KalmanError;
use mole_types::Setting;
use nalgebra::{Matrix2, Matrix2x3, Vector2, Vector3};
use serde::{Deserialize, Serialize};
use statrs::distribution::{ChiSquared, ContinuousCDF};
use thiserror::Error;

/// How readings are matched to landmarks.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Setting)]
#[serde(rename_all = "kebab-case")]
pub enum Correspondence {
    /// The reading's id is the landmark's identity (Thrun §10.2, Table 10.1).
    Known,
    /// Maximum-likelihood association with Mahalanobis gates (Thrun §10.3, Table 10.3); the
    /// reading's id is kept only as provenance of the landmarks it founds.
    Unknown,
}

/// Tuning shared by [`EkfSlam`] and [`FastSlam`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, Setting)]
#[serde(default, deny_unknown_fields)]
pub struct SlamConfig {
    /// How readings find their landmark.
    pub correspondence: Correspondence,
    /// Unknown correspondences: a reading matches a landmark when its squared Mahalanobis
    /// distance is below the χ²(2 dof) quantile at this probability.
    #[setting(above = 0.0, max = 1.0)]
    pub association_probability: f64,
    /// Unknown correspondences: a reading founds a new landmark only when its squared
    /// Mahalanobis distance to every landmark exceeds the χ²(2 dof) quantile at this (larger)
    /// probability; in between it is discarded.
    #[setting(above = 0.0, max = 1.0)]
    pub new_landmark_probability: f64,
    /// Known correspondences: a reading beyond the χ²(2 dof) quantile at this probability is an
    /// outlier and refused; `None` takes every reading.
    #[setting(above = 0.0, max = 1.0)]
    pub outlier_probability: Option<f64>,
    /// Readings with a range above this (m) are ignored: no beacon sensor reaches that far.
    #[setting(above = 0.0)]
    pub max_range: f64,
}

impl Default for SlamConfig {
    fn default() -> Self {
        Self {
            correspondence: Correspondence::Known,
            association_probability: 0.99,
            new_landmark_probability: 0.9999,
            outlier_probability: Some(0.999),
            max_range: 1e3,
        }
    }
}

/// The gates of a [`SlamConfig`] as squared Mahalanobis distances.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Gates {
    /// Match when d² ≤ this.
    pub associate: f64,
    /// Found a landmark when d² > this for every landmark.
    pub create: f64,
    /// Known correspondences: refuse when d² > this.
    pub outlier: f64,
}

impl Gates {
    /// The χ²(2 dof) quantiles of `config` (statrs); probabilities outside (0, 1) give no gate.
    pub fn new(config: &SlamConfig) -> Self {
        let associate = chi2_2dof_quantile(config.association_probability);
        Self {
            associate,
            // The creation gate is never tighter than the association gate.
            create: chi2_2dof_quantile(config.new_landmark_probability).max(associate),
            outlier: config
                .outlier_probability
                .map_or(f64::INFINITY, chi2_2dof_quantile),
        }
    }
}

/// The χ² quantile with 2 degrees of freedom at probability `p` (statrs); ∞ for p ∉ (0, 1).
pub fn chi2_2dof_quantile(p: f64) -> f64 {
    if !(p > 0.0 && p < 1.0) {
        return f64::INFINITY;
    }
    ChiSquared::new(2.0).map_or(f64::INFINITY, |d| d.inverse_cdf(p))
}

/// One mapped landmark: its identity and its Gaussian N(mean, cov).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Landmark {
    /// The beacon id (known correspondences) or the id the founding reading carried (unknown).
    pub id: u32,
    /// Position (x, y) in the map frame (m).
    pub mean: Vector2<f64>,
    /// Its 2×2 covariance.
    pub cov: Matrix2<f64>,
}

impl Landmark {
    /// Whether it can enter a map: finite, with a positive definite covariance.
    pub fn is_usable(&self) -> bool {
        self.mean
            .iter()
            .chain(self.cov.iter())
            .all(|v| v.is_finite())
            && nalgebra::Cholesky::new(self.cov).is_some()
    }
}

/// What became of one reading.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Association {
    /// It updated the landmark in `slot`, whose id is `id`.
    Matched {
        /// State slot of the landmark.
        slot: usize,
        /// The landmark's id.
        id: u32,
    },
    /// It founded the landmark in `slot` with id `id`.
    New {
        /// State slot of the new landmark.
        slot: usize,
        /// The new landmark's id.
        id: u32,
    },
    /// Unknown correspondences: between the association and the creation gates, unused.
    Discarded,
}

/// Association decisions so far (with [`FastSlam`]: those of the most likely particle).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct AssociationStats {
    /// Readings matched to a mapped landmark.
    pub matched: u64,
    /// Readings that founded a landmark.
    pub created: u64,
    /// Readings discarded between the two gates.
    pub discarded: u64,
}

impl AssociationStats {
    /// Counts one decision.
    pub(crate) fn count(&mut self, a: Association) {
        match a {
            Association::Matched { .. } => self.matched += 1,
            Association::New { .. } => self.created += 1,
            Association::Discarded => self.discarded += 1,
        }
    }
}

/// What a SLAM filter did with its inputs: association decisions, readings refused by a gate,
/// and inputs ignored as unusable.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub(crate) struct Tally {
    pub stats: AssociationStats,
    pub rejected: u64,
    pub ignored: u64,
}

impl Tally {
    /// Counts the outcome of one reading.
    pub(crate) fn record(&mut self, outcome: &Result<Association, SlamError>) {
        match outcome {
            Ok(a) => self.stats.count(*a),
            Err(e) if e.is_rejection() => self.rejected += 1,
            Err(_) => self.ignored += 1,
        }
    }

    /// Counts the refusal, if any, of an input that is not a beacon reading (a position fix).
    pub(crate) fn record_refusal(&mut self, outcome: &Result<(), SlamError>) {
        match outcome {
            Ok(()) => {}
            Err(e) if e.is_rejection() => self.rejected += 1,
            Err(_) => self.ignored += 1,
        }
    }
}

/// Why a reading or a control was not used.
#[derive(Debug, Clone, Copy, PartialEq, Error)]
pub enum SlamError {
    /// A value is NaN or infinite, or outside its plausible range.
    #[error("input is not finite or out of range")]
    Invalid,
    /// The predicted range to the landmark is ~0, where the bearing is undefined.
    #[error("predicted range to the landmark is too small for a bearing")]
    TooClose,
    /// Known correspondences: the innovation failed the outlier gate.
    #[error("outlier: squared Mahalanobis distance {mahalanobis2} > gate {gate}")]
    Outlier {
        /// νᵀ S⁻¹ ν.
        mahalanobis2: f64,
        /// The gate.
        gate: f64,
    },
    /// The innovation covariance was not positive definite.
    #[error("innovation covariance is not positive definite")]
    Singular,
    /// The reading would found a landmark but the map is at capacity.
    #[error("the map is full")]
    MapFull,
}

impl SlamError {
    /// Whether this is an outlier refused by the gate (as opposed to an unusable input).
    pub fn is_rejection(&self) -> bool {
        matches!(self, SlamError::Outlier { .. })
    }
}

impl From<KalmanError> for SlamError {
    fn from(e: KalmanError) -> Self {
        match e {
            KalmanError::Gated { mahalanobis2, gate } => SlamError::Outlier { mahalanobis2, gate },
            KalmanError::NotPositiveDefinite => SlamError::Singular,
            KalmanError::NotFinite => SlamError::Invalid,
        }
    }
}

/// A reading (range, bearing) if it is finite and plausible, the bearing wrapped.
pub(crate) fn checked_reading(range: f64, bearing: f64, max_range: f64) -> Option<Vector2<f64>> {
    (range.is_finite() && bearing.is_finite() && range >= 0.0 && range <= max_range)
        .then(|| Vector2::new(range, mole_types::wrap_angle(bearing)))
}

/// The inverse observation model m = h⁻¹(x, z) = (x + r cos(θ + b), y + r sin(θ + b)) with its
/// Jacobians ∂m/∂x (2×3) and ∂m/∂z (2×2), for landmark initialisation (Thrun §10.2.3).
pub(crate) fn inverse_range_bearing(
    pose: &Vector3<f64>,
    z: &Vector2<f64>,
) -> (Vector2<f64>, Matrix2x3<f64>, Matrix2<f64>) {
    let (sin_phi, cos_phi) = (pose[2] + z[1]).sin_cos();
    let (r_cos, r_sin) = (z[0] * cos_phi, z[0] * sin_phi);
    (
        Vector2::new(pose[0] + r_cos, pose[1] + r_sin),
        Matrix2x3::new(1.0, 0.0, -r_sin, 0.0, 1.0, r_cos),
        Matrix2::new(cos_phi, -r_sin, sin_phi, r_cos),
    )
}

/// The predicted reading ẑ = h(x, m) with ∂h/∂x (2×3, [`crate::models`]) and ∂h/∂m = −(∂h/∂x
/// restricted to x, y) (2×2), Thrun §10.2 eq. (10.18); `None` when the landmark is within
/// `MIN_RANGE` of the pose.
pub(crate) fn observe(
    pose: &Vector3<f64>,
    landmark: &Vector2<f64>,
) -> Option<(Vector2<f64>, Matrix2x3<f64>, Matrix2<f64>)> {
    let lm = (landmark[0], landmark[1]);
    let z_hat = crate::models::range_bearing_h(pose, lm);
    // NaN ranges fail this too.
    if z_hat[0].is_nan() || z_hat[0] < crate::models::MIN_RANGE {
        return None;
    }
    let h_pose = crate::models::range_bearing_jacobian_h(pose, lm);
    let h_lm = -h_pose.fixed_view::<2, 2>(0, 0).into_owned();
    Some((z_hat, h_pose, h_lm))
}

/// Id → state slot, a sorted table with room for `capacity` ids (lookups O(log n), inserts
/// within the capacity never allocate).
#[derive(Debug, Clone)]
pub(crate) struct SlotTable {
    entries: Vec<(u32, usize)>,
}

impl SlotTable {
    /// An empty table with room for `capacity` ids.
    pub fn with_capacity(capacity: usize) -> Self {
        Self {
            entries: Vec::with_capacity(capacity),
        }
    }

    /// The slot of `id`.
    pub fn get(&self, id: u32) -> Option<usize> {
        self.entries
            .binary_search_by_key(&id, |e| e.0)
            .ok()
            .map(|i| self.entries[i].1)
    }

    /// Records `id → slot`; false (and nothing recorded) when the table is full.
    pub fn insert(&mut self, id: u32, slot: usize) -> bool {
        if self.entries.len() == self.entries.capacity() {
            return false;
        }
        let at = self.entries.partition_point(|e| e.0 < id);
        self.entries.insert(at, (id, slot));
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn chi2_quantiles_come_from_statrs_and_match_the_closed_form() {
        // For 2 dof the quantile is −2 ln(1 − p).
        assert_relative_eq!(
            chi2_2dof_quantile(0.99),
            -2.0 * 0.01f64.ln(),
            epsilon = 1e-9
        );
        assert_eq!(chi2_2dof_quantile(1.0), f64::INFINITY);
        assert_eq!(chi2_2dof_quantile(f64::NAN), f64::INFINITY);
        let g = Gates::new(&SlamConfig {
            new_landmark_probability: 0.5,
            ..SlamConfig::default()
        });
        assert_eq!(g.create, g.associate);
    }

    #[test]
    fn inverse_observation_inverts_h_and_its_jacobians_match_differences() {
        let pose = Vector3::new(1.0, -2.0, 2.9);
        let z = Vector2::new(3.0, 0.7);
        let (m, j_pose, j_z) = inverse_range_bearing(&pose, &z);
        let (z_back, _, _) = observe(&pose, &m).unwrap();
        assert_relative_eq!(z_back, z, epsilon = 1e-12);
        let eps = 1e-6;
        for c in 0..3 {
            let mut d = Vector3::zeros();
            d[c] = eps;
            let fd = (inverse_range_bearing(&(pose + d), &z).0
                - inverse_range_bearing(&(pose - d), &z).0)
                / (2.0 * eps);
            assert_relative_eq!(fd, j_pose.column(c).into_owned(), epsilon = 1e-6);
        }
        for c in 0..2 {
            let mut d = Vector2::zeros();
            d[c] = eps;
            let fd = (inverse_range_bearing(&pose, &(z + d)).0
                - inverse_range_bearing(&pose, &(z - d)).0)
                / (2.0 * eps);
            assert_relative_eq!(fd, j_z.column(c).into_owned(), epsilon = 1e-6);
        }
    }

    #[test]
    fn slot_table_finds_ids_and_refuses_beyond_capacity() {
        let mut t = SlotTable::with_capacity(2);
        assert!(t.insert(9, 0));
        assert!(t.insert(3, 1));
        assert!(!t.insert(5, 2));
        assert_eq!((t.get(9), t.get(3), t.get(5)), (Some(0), Some(1), None));
    }
}
