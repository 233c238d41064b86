//! EKF-SLAM and FastSLAM in the process (algorithms §6.9): the filters of this module behind
//! [`Estimator`], built from the world's start pose, sensor noise and seed only. The beacon
//! positions of `world/map` are never read: the landmarks are what the filter estimates.
//!
//! Each step's readings go in reading by reading; the decision for each (matched, new,
//! discarded, or why it was refused) is kept for the step ([`EkfSlamEstimator::decisions`]),
//! so a caller that knows the truth can score the associations. A valid position fix is a
//! linear reading of the pose (EKF-SLAM: a Kalman update gated like a beacon; FastSLAM: a
//! weight factor).

use super::{
    Association, AssociationStats, EkfSlam, FastSlam, FastSlamConfig, FuseReport, Landmark,
    SlamError,
};
use crate::Settings;
use crate::noise::NoiseModel;
use crate::{Estimator, Readings};
use mole_types::{
    Beacons, EstimatorKind, Fix, Landmarks, MAX_BEACONS, MAX_LANDMARKS, Odom, Pose, Pose2, WorldMap,
};
use nalgebra::{Matrix2, Matrix3, Vector2};

/// Landmarks a SLAM estimator has room for: as many as `localization/landmarks` carries.
pub const SLAM_CAPACITY: usize = MAX_LANDMARKS;

/// Fills `n_landmarks`, `estimator` (`kind`'s code), `nees_dof` and the landmarks of `out`
/// from `landmarks` (at most [`MAX_LANDMARKS`]), never its header; returns true.
pub fn write_landmarks(
    kind: EstimatorKind,
    landmarks: impl Iterator<Item = Landmark>,
    nees_dof: f64,
    out: &mut Landmarks,
) -> bool {
    let mut n = 0;
    for (slot, l) in out.landmarks.iter_mut().zip(landmarks) {
        *slot = mole_types::Landmark {
            id: l.id,
            _pad: 0,
            x: l.mean[0],
            y: l.mean[1],
            covariance: [l.cov[(0, 0)], l.cov[(0, 1)], l.cov[(1, 0)], l.cov[(1, 1)]],
        };
        n += 1;
    }
    out.n_landmarks = n;
    out.estimator = kind.code();
    out.nees_dof = nees_dof;
    true
}

/// The landmarks of a `localization/landmarks` message as the filters hold them.
pub(crate) fn landmarks_of(message: &Landmarks) -> impl Iterator<Item = Landmark> + '_ {
    message.landmarks().iter().map(|l| Landmark {
        id: l.id,
        mean: Vector2::new(l.x, l.y),
        cov: Matrix2::from_row_slice(&l.covariance),
    })
}

/// The pose (x, y, θ) and its 3×3 covariance of a `localization/pose` message.
pub(crate) fn pose_of(pose: &Pose) -> (Pose2, Matrix3<f64>) {
    (
        Pose2::new(pose.x, pose.y, pose.theta),
        Matrix3::from_row_slice(&pose.covariance),
    )
}

/// A 3×3 matrix as the row-major array of `Pose::covariance`.
fn row_major(m: &Matrix3<f64>) -> [f64; 9] {
    let mut out = [0.0; 9];
    for r in 0..3 {
        for c in 0..3 {
            out[3 * r + c] = m[(r, c)];
        }
    }
    out
}

/// Whether the step's beacon message claims more readings than it can hold (counted as one
/// ignored input; the readings it does hold are used).
fn overfull(beacons: &Beacons) -> bool {
    beacons.n_readings as usize > beacons.readings.len()
}

/// The position (x, y) and σ of a usable fix, `Ok(None)` when the fix says there is none,
/// `Err` when its flag or values are unusable.
fn usable_fix(fix: &Fix) -> Result<Option<(f64, f64, f64)>, SlamError> {
    match fix.valid {
        0 => Ok(None),
        1 if fix.x.is_finite() && fix.y.is_finite() => Ok(Some((fix.x, fix.y, fix.std))),
        _ => Err(SlamError::Invalid),
    }
}

/// EKF-SLAM ([`EkfSlam`], algorithms §6.9.2) as a process estimator.
#[derive(Debug, Clone)]
pub struct EkfSlamEstimator {
    slam: EkfSlam,
    noise: NoiseModel,
    decisions: Vec<Result<Association, SlamError>>,
    ignored: u64,
    /// A peer's landmarks being fused, as the filter takes them (room for a whole map).
    peer_landmarks: Vec<Landmark>,
}

impl EkfSlamEstimator {
    /// EKF-SLAM for the world in `map`: at the start pose with Σ = 0 (the start pose defines
    /// the map frame), the sensors' noise, room for [`SLAM_CAPACITY`] landmarks, an empty map.
    pub fn from_map(map: &WorldMap) -> Self {
        Self::with_settings(map, &Settings::default())
    }

    /// [`EkfSlamEstimator::from_map`] with `settings.slam`.
    pub fn with_settings(map: &WorldMap, settings: &Settings) -> Self {
        Self::starting(
            map,
            settings,
            Pose2::new(map.start_x, map.start_y, map.start_theta),
            Matrix3::zeros(),
        )
    }

    /// EKF-SLAM going on from another estimator's output: N(pose, its covariance) and every
    /// usable landmark of `landmarks`, uncorrelated (see [`crate::resume`]).
    pub fn resume(map: &WorldMap, pose: &Pose, landmarks: Option<&Landmarks>) -> Self {
        Self::resume_with(map, &Settings::default(), pose, landmarks)
    }

    /// [`EkfSlamEstimator::resume`] with `settings.slam`.
    pub fn resume_with(
        map: &WorldMap,
        settings: &Settings,
        pose: &Pose,
        landmarks: Option<&Landmarks>,
    ) -> Self {
        let (mean, sigma) = pose_of(pose);
        let mut est = Self::starting(map, settings, mean, sigma);
        for l in landmarks.into_iter().flat_map(landmarks_of) {
            if est.slam.insert_landmark(&l).is_err() {
                est.ignored += 1;
            }
        }
        est
    }

    fn starting(map: &WorldMap, settings: &Settings, pose: Pose2, sigma: Matrix3<f64>) -> Self {
        let noise = NoiseModel::from_map(map);
        Self {
            slam: EkfSlam::new(pose, sigma, noise, SLAM_CAPACITY, settings.slam),
            noise,
            decisions: Vec::with_capacity(MAX_BEACONS),
            ignored: 0,
            peer_landmarks: Vec::with_capacity(MAX_LANDMARKS),
        }
    }

    /// The filter.
    pub fn filter(&self) -> &EkfSlam {
        &self.slam
    }

    /// The filter, to change its settings (its linearisation, say) before a run.
    pub fn filter_mut(&mut self) -> &mut EkfSlam {
        &mut self.slam
    }

    /// What became of each beacon reading of the last correction, in the message's order.
    pub fn decisions(&self) -> &[Result<Association, SlamError>] {
        &self.decisions
    }

    /// Association decisions so far.
    pub fn association_stats(&self) -> AssociationStats {
        self.slam.association_stats()
    }
}

impl Estimator for EkfSlamEstimator {
    fn set_noise(&mut self, noise: &NoiseModel) -> Result<(), String> {
        (self.noise, self.slam.motion.noise) = (*noise, *noise);
        self.slam.q_t = noise.q_beacon();
        Ok(())
    }

    fn id(&self) -> u32 {
        EstimatorKind::EkfSlam.code()
    }

    fn predict(&mut self, odom: &Odom) {
        // A refused control is counted inside.
        let _ = self.slam.predict(odom.v, odom.omega, odom.dt);
    }

    fn predict_sliding(&mut self, odom: &Odom, sideways: &Vector2<f64>) {
        // A refused control is counted inside.
        let _ = self
            .slam
            .predict_sliding(odom.v, odom.omega, odom.dt, sideways);
    }

    /// Every beacon reading in order (association, first sight or update), then the fix.
    fn correct(&mut self, readings: &Readings<'_>) {
        self.decisions.clear();
        if let Some(beacons) = readings.beacons {
            self.ignored += u64::from(overfull(beacons));
            for reading in beacons.readings() {
                self.decisions.push(self.slam.correct_reading(reading));
            }
        }
        match readings.fix.map(usable_fix) {
            Some(Ok(Some((x, y, std)))) => {
                // Refusals are counted inside.
                let _ = self.slam.correct_fix(x, y, &self.noise.q_fix(std));
            }
            Some(Err(_)) => self.ignored += 1,
            Some(Ok(None)) | None => {}
        }
    }

    fn pose(&self) -> Pose2 {
        self.slam.pose()
    }

    fn covariance(&self) -> [f64; 9] {
        row_major(&self.slam.pose_covariance())
    }

    fn rejected(&self) -> u64 {
        self.slam.rejected()
    }

    fn ignored(&self) -> u64 {
        self.slam.ignored() + self.ignored
    }

    fn write_landmarks(&self, out: &mut Landmarks) -> bool {
        let dof = self.slam.mean_nees_dof();
        write_landmarks(EstimatorKind::EkfSlam, self.slam.landmarks(), dof, out)
    }

    fn fuse_landmarks(&mut self, other: &Landmarks) -> Option<FuseReport> {
        self.peer_landmarks.clear();
        self.peer_landmarks.extend(landmarks_of(other));
        Some(self.slam.fuse_landmarks(&self.peer_landmarks))
    }
}

/// FastSLAM 1.0 ([`FastSlam`], algorithms §6.9.3) as a process estimator.
#[derive(Debug, Clone)]
pub struct FastSlamEstimator {
    slam: FastSlam,
    decisions: Vec<Result<Association, SlamError>>,
    ignored: u64,
}

impl FastSlamEstimator {
    /// FastSLAM for the world in `map`: every particle at the start pose (it defines the map
    /// frame), the sensors' noise, the map's seed, the default [`FastSlamConfig`], room for
    /// [`SLAM_CAPACITY`] landmarks per particle, an empty map.
    pub fn from_map(map: &WorldMap) -> Self {
        Self::with_settings(map, &Settings::default())
    }

    /// [`FastSlamEstimator::from_map`] with `settings.slam` and `settings.fastslam`.
    pub fn with_settings(map: &WorldMap, settings: &Settings) -> Self {
        Self::starting(
            map,
            settings,
            Pose2::new(map.start_x, map.start_y, map.start_theta),
        )
    }

    /// FastSLAM going on from another estimator's output: particles drawn from N(pose, its
    /// covariance), each with every usable landmark of `landmarks` (see [`crate::resume`]).
    pub fn resume(map: &WorldMap, pose: &Pose, landmarks: Option<&Landmarks>) -> Self {
        Self::resume_with(map, &Settings::default(), pose, landmarks)
    }

    /// [`FastSlamEstimator::resume`] with `settings.slam` and `settings.fastslam`.
    pub fn resume_with(
        map: &WorldMap,
        settings: &Settings,
        pose: &Pose,
        landmarks: Option<&Landmarks>,
    ) -> Self {
        let (mean, sigma) = pose_of(pose);
        let mut est = Self::starting(map, settings, mean);
        est.slam.scatter(&sigma);
        for l in landmarks.into_iter().flat_map(landmarks_of) {
            if est.slam.insert_landmark(&l).is_err() {
                est.ignored += 1;
            }
        }
        est
    }

    fn starting(map: &WorldMap, settings: &Settings, pose: Pose2) -> Self {
        Self {
            slam: FastSlam::new(
                pose,
                NoiseModel::from_map(map),
                SLAM_CAPACITY,
                settings.slam,
                FastSlamConfig {
                    seed: map.seed,
                    ..settings.fastslam
                },
            ),
            decisions: Vec::with_capacity(MAX_BEACONS),
            ignored: 0,
        }
    }

    /// The filter.
    pub fn filter(&self) -> &FastSlam {
        &self.slam
    }

    /// What became of each beacon reading of the last correction (the most likely particle's
    /// decision), in the message's order.
    pub fn decisions(&self) -> &[Result<Association, SlamError>] {
        &self.decisions
    }

    /// Association decisions so far (the most likely particle's).
    pub fn association_stats(&self) -> AssociationStats {
        self.slam.association_stats()
    }
}

impl Estimator for FastSlamEstimator {
    fn set_noise(&mut self, noise: &NoiseModel) -> Result<(), String> {
        self.slam.noise = *noise;
        Ok(())
    }

    fn id(&self) -> u32 {
        EstimatorKind::FastSlam.code()
    }

    fn predict(&mut self, odom: &Odom) {
        // A refused control is counted inside.
        let _ = self.slam.predict(odom.v, odom.omega, odom.dt);
    }

    fn predict_sliding(&mut self, odom: &Odom, sideways: &Vector2<f64>) {
        // A refused control is counted inside.
        let _ = self
            .slam
            .predict_sliding(odom.v, odom.omega, odom.dt, sideways);
    }

    /// Every beacon reading into every particle, the fix as a weight factor, then
    /// normalisation and resampling when due; a step without any correction reading changes
    /// nothing.
    fn correct(&mut self, readings: &Readings<'_>) {
        self.decisions.clear();
        if readings.beacons.is_none() && readings.fix.is_none() {
            return;
        }
        if let Some(beacons) = readings.beacons {
            self.ignored += u64::from(overfull(beacons));
            for reading in beacons.readings() {
                self.decisions.push(self.slam.correct_reading(reading));
            }
        }
        match readings.fix.map(usable_fix) {
            Some(Ok(Some((x, y, std)))) => {
                let q_t = self.slam.noise.q_fix(std);
                // Refusals are counted inside.
                let _ = self.slam.weigh_fix(x, y, &q_t);
            }
            Some(Err(_)) => self.ignored += 1,
            Some(Ok(None)) | None => {}
        }
        self.slam.finish_correction();
    }

    fn pose(&self) -> Pose2 {
        self.slam.pose()
    }

    fn covariance(&self) -> [f64; 9] {
        row_major(&self.slam.pose_covariance())
    }

    fn rejected(&self) -> u64 {
        self.slam.rejected()
    }

    fn ignored(&self) -> u64 {
        self.slam.ignored() + self.ignored
    }

    fn write_landmarks(&self, out: &mut Landmarks) -> bool {
        let dof = self.slam.mean_nees_dof();
        write_landmarks(EstimatorKind::FastSlam, self.slam.landmarks(), dof, out)
    }
}
