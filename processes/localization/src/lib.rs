//! Localization: histogram Bayes filter, KF, EKF, PF (algorithms §6).
//!
//! Every estimator implements [`Estimator`]: the process main calls `predict` with the odometry
//! of a step, then `correct` with that step's beacon readings and position fix, then
//! `write_pose` into the loaned `localization/pose` sample. The pieces the four estimators share
//! live beside them: the motion and measurement models ([`models`]), the noise ([`NoiseModel`]),
//! the generic Kalman correction ([`kalman`]) and the beacon lookup ([`BeaconTable`]).
//!
//! Naming follows the seed (after Thrun, *Probabilistic Robotics*): R_t is the PROCESS noise
//! covariance, Q_t the MEASUREMENT noise covariance.

pub mod bayes;
pub mod ekf;
pub mod graph_slam;
pub mod kalman;
pub mod kf;
pub mod models;
pub mod noise;
pub mod pf;
pub mod slam;

pub use bayes::{BayesConfig, HistogramFilter};
pub use ekf::Ekf;
pub use kalman::{KalmanError, kalman_correct};
pub use kf::{KalmanFilter, Kf};
pub use models::BeaconTable;
pub use noise::NoiseModel;
pub use pf::{ParticleFilter, PfConfig, low_variance_resample};

pub use mole_types::EstimatorKind;
use mole_types::{Beacons, Fix, Odom, Particles, Pose, Pose2, WorldMap};
use thiserror::Error;

/// What every estimator does each step; the process main calls predict, then correct, then
/// write_pose.
pub trait Estimator {
    /// The estimator's id, `mole_types::ESTIMATOR_EKF` etc.
    fn id(&self) -> u32;
    /// Prediction step (algorithms §6.3): moves the belief by the control u_t = (v, ω) over `odom.dt`.
    fn predict(&mut self, odom: &Odom);
    /// Correction step (algorithms §6.3): folds in this step's beacon readings and, when valid, the fix.
    fn correct(&mut self, beacons: &Beacons, fix: &Fix);
    /// The mean pose, θ wrapped to (−π, π].
    fn pose(&self) -> Pose2;
    /// Σ over (x, y, θ), row-major.
    fn covariance(&self) -> [f64; 9];
    /// Fills x, y, theta, covariance, estimator (not header, not update_ns).
    fn write_pose(&self, out: &mut Pose) {
        let p = self.pose();
        out.x = p.x;
        out.y = p.y;
        out.theta = p.theta;
        out.covariance = self.covariance();
        out.estimator = self.id();
    }
    /// Readings refused as outliers by the χ² gate so far.
    fn rejected(&self) -> u64 {
        0
    }
    /// Inputs ignored so far as unusable: unknown beacon ids, non-finite values, bad flags.
    fn ignored(&self) -> u64 {
        0
    }
    /// Fills `n_particles` and the particles of the loaned `localization/particles` sample (never
    /// its header) and returns true, for estimators that have a particle set (the PF); the
    /// others return false and leave `out` alone, and nothing should be published.
    fn write_particles(&self, out: &mut Particles) -> bool {
        let _ = out;
        false
    }
}

/// Why one reading or control was not used. Gated readings count as rejected, the rest as
/// ignored.
#[derive(Debug, Clone, Copy, PartialEq, Error)]
pub enum ReadingError {
    /// The reading names a beacon the map does not have.
    #[error("unknown beacon id {0}")]
    UnknownBeacon(u32),
    /// A value is NaN or infinite, or out of its range (negative range or dt, unknown flag,
    /// odometry beyond `models::MAX_ODOM_SPEED`, `MAX_ODOM_TURN_RATE` or `MAX_ODOM_DT`).
    #[error("reading is not finite or out of range")]
    Invalid,
    /// The predicted beacon range is ~0, where the bearing is undefined.
    #[error("predicted range to the beacon is too small for a bearing")]
    TooClose,
    /// The innovation failed the χ² gate: an outlier.
    #[error("outlier: squared Mahalanobis distance {mahalanobis2} > gate {gate}")]
    Gated {
        /// νᵀ S⁻¹ ν.
        mahalanobis2: f64,
        /// The gate.
        gate: f64,
    },
    /// The innovation covariance was not positive definite.
    #[error("innovation covariance is not positive definite")]
    Singular,
}

impl ReadingError {
    /// Whether this is an outlier refused by the gate (as opposed to an unusable input).
    pub fn is_rejection(&self) -> bool {
        matches!(self, ReadingError::Gated { .. })
    }
}

impl From<KalmanError> for ReadingError {
    fn from(e: KalmanError) -> Self {
        match e {
            KalmanError::Gated { mahalanobis2, gate } => ReadingError::Gated { mahalanobis2, gate },
            KalmanError::NotPositiveDefinite => ReadingError::Singular,
            KalmanError::NotFinite => ReadingError::Invalid,
        }
    }
}

/// Errors of the localization library.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum LocalizationError {
    /// The SLAM estimators exist as libraries but do not run in the process yet (issue #12).
    #[error("estimator `{0}` does not run in the stack yet")]
    NotInTheStack(EstimatorKind),
}

/// Builds estimator `kind` for the world in `map` (start pose, sensor noise, beacons; the PF
/// also the seed) with its default configuration. All buffers are allocated here.
pub fn build_estimator(
    kind: EstimatorKind,
    map: &WorldMap,
) -> Result<Box<dyn Estimator>, LocalizationError> {
    Ok(match kind {
        EstimatorKind::Bayes => Box::new(HistogramFilter::from_map(map)),
        EstimatorKind::Kf => Box::new(Kf::from_map(map)),
        EstimatorKind::Ekf => Box::new(Ekf::from_map(map)),
        EstimatorKind::Pf => Box::new(ParticleFilter::from_map(map)),
        EstimatorKind::EkfSlam | EstimatorKind::FastSlam | EstimatorKind::GraphSlam => {
            return Err(LocalizationError::NotInTheStack(kind));
        }
    })
}

#[cfg(test)]
pub(crate) mod test_support {
    use mole_types::WorldMap;

    /// A zeroed, boxed map (it is ~50 kB: never on the stack).
    pub fn zeroed_map() -> Box<WorldMap> {
        bytemuck::zeroed_box()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn build_estimator_builds_every_filter() {
        let mut map = test_support::zeroed_map();
        map.arena_width = 4.0;
        map.arena_height = 3.0;
        map.start_x = 1.0;
        map.start_y = 1.0;
        let mut particles: Box<Particles> = bytemuck::zeroed_box();
        for kind in [
            EstimatorKind::Bayes,
            EstimatorKind::Kf,
            EstimatorKind::Ekf,
            EstimatorKind::Pf,
        ] {
            let est = build_estimator(kind, &map).unwrap();
            assert_eq!(est.id(), kind.code());
            let p = est.pose();
            assert!(
                (p.x - 1.0).abs() < 0.05 && (p.y - 1.0).abs() < 0.05,
                "{kind:?}: {p:?}"
            );
            assert_eq!(
                est.write_particles(&mut particles),
                kind == EstimatorKind::Pf
            );
        }
        assert_eq!(particles.n_particles as usize, pf::DEFAULT_PARTICLES);
    }
}
