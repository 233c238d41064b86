//! Localization and SLAM: histogram Bayes filter, KF, EKF, PF (algorithms §6) and EKF-SLAM,
//! FastSLAM, GraphSLAM (algorithms §6.9).
//!
//! Every estimator implements [`Estimator`]: the process main hands it each step's
//! [`Readings`] (`step` = `predict` with the odometry, then `correct` with whatever correction
//! readings the step has), then `write_pose` into the loaned `localization/pose` sample and, for
//! the SLAM estimators, `write_landmarks` into `localization/landmarks`. The pieces the
//! estimators share live beside them: the motion and measurement models ([`models`]), the noise
//! ([`NoiseModel`]), the generic Kalman correction ([`kalman`]) and the beacon lookup
//! ([`BeaconTable`]; the localisers only: a SLAM estimator never reads the beacon positions).
//!
//! Naming follows algorithms.md (after Thrun, *Probabilistic Robotics*): R_t is the PROCESS noise
//! covariance, Q_t the MEASUREMENT noise covariance.

pub mod bayes;
pub mod contact;
pub mod ekf;
pub mod graph_slam;
pub mod kalman;
pub mod kf;
pub mod models;
pub mod noise;
pub mod pf;
pub mod settings;
pub mod slam;
pub mod ziggurat;

pub use bayes::{BayesConfig, HistogramFilter};
pub use ekf::Ekf;
pub use kalman::{KalmanError, kalman_correct};
pub use kf::{KalmanFilter, Kf};
pub use models::BeaconTable;
pub use noise::NoiseModel;
pub use pf::{ParticleFilter, PfConfig, low_variance_resample};

pub use contact::Slide;
pub use graph_slam::GraphSlamEstimator;
pub use mole_types::EstimatorKind;
use mole_types::{
    Beacons, Fix, Landmarks, Odom, Particles, Pose, Pose2, Tactile, Trajectory, WorldMap,
    arc_between,
};
use nalgebra::Vector2;
pub use settings::Settings;
pub use slam::{EkfSlamEstimator, FastSlamEstimator};
use thiserror::Error;

/// The readings of one step: the odometry, and each correction sensor's reading when it has one
/// of this step (`None`: no reading of that sensor this step). Built with [`Readings::of`] and
/// the `with_` methods, so a new sensor is one more field and one more method here, and no
/// estimator, test or bench that does not use it changes.
#[derive(Debug, Clone, Copy)]
#[non_exhaustive]
pub struct Readings<'a> {
    /// The control u_t = (v, ω) over dt that moved the robot into this step.
    pub odom: &'a Odom,
    /// The beacon readings (range, bearing) of this step.
    pub beacons: Option<&'a Beacons>,
    /// The position fix of this step (it may still say `valid == 0`: no fix).
    pub fix: Option<&'a Fix>,
    /// The motion of this step when contacts blocked the wheels ([`contact`]): predicted instead
    /// of `odom`.
    pub slide: Option<Slide>,
}

impl<'a> Readings<'a> {
    /// A step's odometry, with no correction reading.
    pub fn of(odom: &'a Odom) -> Self {
        Self {
            odom,
            beacons: None,
            fix: None,
            slide: None,
        }
    }

    /// With the step's beacon readings, if any.
    pub fn with_beacons(self, beacons: Option<&'a Beacons>) -> Self {
        Self { beacons, ..self }
    }

    /// With the step's position fix, if any.
    pub fn with_fix(self, fix: Option<&'a Fix>) -> Self {
        Self { fix, ..self }
    }

    /// With the step's tactile ring, if any, read with the sensors' force σ (N): when its
    /// contacts blocked the wheels, the step predicts their [`Slide`] instead of `odom`.
    pub fn with_contacts(self, tactile: Option<&Tactile>, force_std: f64) -> Self {
        let slide = tactile.and_then(|t| contact::slide_along_contacts(self.odom, t, force_std));
        Self { slide, ..self }
    }
}

/// Publish the particle set every this many steps: plenty for a picture or a viewer, and it
/// keeps 256 KiB per step off the bus.
pub const PARTICLES_EVERY: u64 = 10;

/// The odometry pose of the step handled last and the world's step: what [`odometry_since`]
/// needs from one step to the next.
#[derive(Debug, Clone, Copy)]
pub struct Odometer {
    before: Option<[f64; 3]>,
    tick_dt: f64,
}

impl Odometer {
    /// From a predecessor's last odometry pose (a swap, a restart), or none on a fresh start.
    pub fn new(before: Option<[f64; 3]>, tick_dt: f64) -> Self {
        Self { before, tick_dt }
    }

    /// The odometry this step predicts with ([`odometry_since`], `ticks` since the step handled
    /// last); remembers `measured`'s pose for the next.
    pub fn step(&mut self, measured: &Odom, ticks: Option<u64>) -> Odom {
        let odom = odometry_since(measured, self.before, ticks, self.tick_dt);
        self.before = Some([measured.x, measured.y, measured.theta]);
        odom
    }

    /// The odometry pose of the step handled last (zero before the first).
    pub fn pose(&self) -> [f64; 3] {
        self.before.unwrap_or_default()
    }
}

/// The odometry a step predicts with, given the odometry pose of the step handled before
/// (`before`; none on a fresh start) and how many world steps of `tick_dt` ago that was. One
/// step: the velocities measured over it. After a gap (this process stopped or restarted, a
/// realtime step skipped under load): the one arc between the two odometry poses, so the
/// estimate moves as far as the wheels did, over the gap's time, dt capped at
/// [`models::MAX_ODOM_DT`] (the arc is kept whole: its velocities grow instead). Without an
/// odometry pose to start from, the newest velocities are held over the gap. (Predicting one
/// step left the estimate behind and the χ² gate then refused every correction: a 0.3 s gap
/// took the EKF's RMSE from 0.015 m to 0.16 m for the rest of the run; holding the newest
/// velocities lost the motion before the robot stopped.)
pub fn odometry_since(
    odom: &Odom,
    before: Option<[f64; 3]>,
    ticks: Option<u64>,
    tick_dt: f64,
) -> Odom {
    let steps = ticks.unwrap_or(1).max(1);
    if steps == 1 {
        return *odom;
    }
    let gap = steps as f64 * tick_dt;
    let Some([x, y, theta]) = before.filter(|_| gap > 0.0) else {
        return Odom {
            dt: (odom.dt * steps as f64).min(models::MAX_ODOM_DT),
            ..*odom
        };
    };
    let (s, dtheta) = arc_between(
        Pose2::new(x, y, theta),
        Pose2::new(odom.x, odom.y, odom.theta),
    );
    let dt = gap.min(models::MAX_ODOM_DT);
    Odom {
        v: s / dt,
        omega: dtheta / dt,
        dt,
        ..*odom
    }
}

/// What every estimator does each step; the process main calls step (predict, then correct),
/// then write_pose, and write_landmarks for the SLAM estimators.
pub trait Estimator {
    /// The estimator's id, `mole_types::ESTIMATOR_EKF` etc.
    fn id(&self) -> u32;
    /// Assumes `noise` from the next step on (`mole param set localization noise.…`), keeping
    /// its belief; `Err` says why it cannot. By default an estimator cannot (the histogram
    /// filter's likelihood tables and GraphSLAM's factors are built with the noise).
    fn set_noise(&mut self, _noise: &NoiseModel) -> Result<(), String> {
        Err("this estimator builds its tables with the noise at start".to_owned())
    }
    /// Prediction step (algorithms §6.3): moves the belief by the control u_t = (v, ω) over `odom.dt`.
    fn predict(&mut self, odom: &Odom);
    /// Correction step (algorithms §6.3): folds in every correction reading `readings` holds
    /// (beacons, fix), and nothing for the sensors that are `None`.
    fn correct(&mut self, readings: &Readings<'_>);
    /// Prediction with the motion of a step against a wall ([`contact`]): the arc of `odom`,
    /// then the translation `sideways` (robot frame at the arc's end, m) the wheels did not see.
    /// By default only the arc is predicted (the histogram filter and the KF); the EKF, the PF
    /// and the SLAM estimators carry the slide too.
    fn predict_sliding(&mut self, odom: &Odom, sideways: &Vector2<f64>) {
        let _ = sideways;
        self.predict(odom);
    }
    /// One step: predict with `readings.odom` (or its slide against contacts), then correct
    /// with the rest.
    fn step(&mut self, readings: &Readings<'_>) {
        match &readings.slide {
            Some(slide) => self.predict_sliding(&slide.odom, &slide.sideways),
            None => self.predict(readings.odom),
        }
        self.correct(readings);
    }
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
    /// Fills `n_landmarks`, `estimator` and the landmarks (id, mean, 2×2 covariance) of the
    /// loaned `localization/landmarks` sample (never its header) and returns true, for the
    /// SLAM estimators; the others return false and leave `out` alone, and nothing should be
    /// published.
    fn write_landmarks(&self, out: &mut Landmarks) -> bool {
        let _ = out;
        false
    }
    /// Fuses another robot's landmark map (its `localization/landmarks`, same map frame) into
    /// the estimate by covariance intersection and returns what became of its landmarks, for the
    /// estimators that can (EKF-SLAM, [`slam::FUSING_ESTIMATOR`]); the others return `None` and
    /// change nothing. Allocates nothing.
    fn fuse_landmarks(&mut self, other: &Landmarks) -> Option<slam::FuseReport> {
        let _ = other;
        None
    }
    /// Solves a background smoother has finished and handed over so far (GraphSLAM); 0 for the
    /// estimators without one. Each change brings a new trajectory for `write_trajectory`.
    fn smoother_solves(&self) -> u64 {
        0
    }
    /// Fills `first_tick`, `n_poses`, `estimator` and the poses of the loaned
    /// `localization/trajectory` sample (never its header) with the newest smoothed trajectory
    /// and returns true, for an estimator with a smoother (GraphSLAM); the others return false
    /// and leave `out` alone, and nothing should be published.
    fn write_trajectory(&self, out: &mut Trajectory) -> bool {
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
    /// GraphSLAM's smoother thread could not be started.
    #[error("cannot start the GraphSLAM smoother thread: {0}")]
    Smoother(String),
}

/// An estimator the registry builds: one row of [`mole_types::estimators!`] names its type.
pub trait Registered: Estimator + Sized + 'static {
    /// Built for the world in `map` (its sensors' noise as the settings assume it) with
    /// `settings`: the localisers from the start pose, noise and beacons (the PF also the seed);
    /// the SLAM estimators from the start pose, noise and seed only (never the beacons). All
    /// buffers are allocated here (GraphSLAM also starts its smoother thread).
    fn build(map: &WorldMap, settings: &Settings) -> Result<Self, LocalizationError>;

    /// Built to go on from another estimator's output (a swap or a restart), see [`resume`];
    /// by default built afresh at `pose`'s mean with its usual initial uncertainty.
    fn resume(
        map: &WorldMap,
        settings: &Settings,
        pose: &Pose,
        _landmarks: Option<&Landmarks>,
    ) -> Result<Self, LocalizationError> {
        Self::build(&starting_at(map, pose), settings)
    }
}

/// The dispatch of [`build_estimator_with`] and [`resume_with`], from the table of estimators
/// (`mole_types::estimators!`).
macro_rules! registry {
    ($( $(#[$meta:meta])* $variant:ident = ($name:literal, $code:literal, $ty:ident, $class:ident) ),+ $(,)?) => {
        /// Builds estimator `kind` for the world in `map` with `settings` (see [`Registered::build`]).
        pub fn build_estimator_with(
            kind: EstimatorKind,
            map: &WorldMap,
            settings: &Settings,
        ) -> Result<Box<dyn Estimator>, LocalizationError> {
            let map = settings.noise.assumed(map);
            Ok(match kind {
                $( EstimatorKind::$variant => Box::new(<$ty as Registered>::build(&map, settings)?), )+
            })
        }

        /// [`resume`] with `settings`.
        pub fn resume_with(
            kind: EstimatorKind,
            map: &WorldMap,
            settings: &Settings,
            pose: &Pose,
            landmarks: Option<&Landmarks>,
        ) -> Result<Box<dyn Estimator>, LocalizationError> {
            let map = settings.noise.assumed(map);
            Ok(match kind {
                $( EstimatorKind::$variant => {
                    Box::new(<$ty as Registered>::resume(&map, settings, pose, landmarks)?)
                } )+
            })
        }
    };
}
mole_types::estimators!(registry);

/// Builds estimator `kind` for the world in `map` with the default settings.
pub fn build_estimator(
    kind: EstimatorKind,
    map: &WorldMap,
) -> Result<Box<dyn Estimator>, LocalizationError> {
    build_estimator_with(kind, map, &Settings::default())
}

/// [`resume_with`] from `pose` when there is one (a swap or a restart), else
/// [`build_estimator_with`].
pub fn start_estimator(
    kind: EstimatorKind,
    map: &WorldMap,
    settings: &Settings,
    pose: Option<&Pose>,
    landmarks: Option<&Landmarks>,
) -> Result<Box<dyn Estimator>, LocalizationError> {
    match pose {
        Some(pose) => resume_with(kind, map, settings, pose, landmarks),
        None => build_estimator_with(kind, map, settings),
    }
}

/// Builds estimator `kind` to go on from another estimator's output (a swap or a restart),
/// with the default settings: from `pose` and, for the SLAM kinds, from `landmarks` too. The
/// EKF starts at N(pose, its covariance) (its whole belief: a restarted EKF goes on exactly);
/// the other localisers at the pose's mean with their usual initial uncertainty (as
/// [`build_estimator`] at the start pose); the SLAM estimators start at N(pose, its covariance)
/// with every usable landmark of `landmarks` (mean and 2×2 covariance, uncorrelated with the
/// pose and with each other: the message carries no cross-covariances). Landmarks that are not
/// finite and positive definite are skipped and counted as ignored.
pub fn resume(
    kind: EstimatorKind,
    map: &WorldMap,
    pose: &Pose,
    landmarks: Option<&Landmarks>,
) -> Result<Box<dyn Estimator>, LocalizationError> {
    resume_with(kind, map, &Settings::default(), pose, landmarks)
}

impl Registered for HistogramFilter {
    fn build(map: &WorldMap, settings: &Settings) -> Result<Self, LocalizationError> {
        Ok(HistogramFilter::from_map_with(map, settings.bayes))
    }
}

impl Registered for Kf {
    fn build(map: &WorldMap, _settings: &Settings) -> Result<Self, LocalizationError> {
        Ok(Kf::from_map(map))
    }
}

impl Registered for Ekf {
    fn build(map: &WorldMap, _settings: &Settings) -> Result<Self, LocalizationError> {
        Ok(Ekf::from_map(map))
    }
    fn resume(
        map: &WorldMap,
        _settings: &Settings,
        pose: &Pose,
        _landmarks: Option<&Landmarks>,
    ) -> Result<Self, LocalizationError> {
        Ok(Ekf::resume(map, pose))
    }
}

impl Registered for ParticleFilter {
    fn build(map: &WorldMap, settings: &Settings) -> Result<Self, LocalizationError> {
        Ok(ParticleFilter::from_map_with(map, settings.pf))
    }
}

/// The SLAM filters, built and resumed by their own `with_settings` and `resume_with`.
macro_rules! registered_slam_filter {
    ($($ty:ident),+) => {$(
        impl Registered for $ty {
            fn build(map: &WorldMap, settings: &Settings) -> Result<Self, LocalizationError> {
                Ok($ty::with_settings(map, settings))
            }
            fn resume(
                map: &WorldMap,
                settings: &Settings,
                pose: &Pose,
                landmarks: Option<&Landmarks>,
            ) -> Result<Self, LocalizationError> {
                Ok($ty::resume_with(map, settings, pose, landmarks))
            }
        }
    )+};
}
registered_slam_filter!(EkfSlamEstimator, FastSlamEstimator);

impl Registered for GraphSlamEstimator {
    fn build(map: &WorldMap, settings: &Settings) -> Result<Self, LocalizationError> {
        GraphSlamEstimator::with_settings(map, settings)
    }
    fn resume(
        map: &WorldMap,
        settings: &Settings,
        pose: &Pose,
        landmarks: Option<&Landmarks>,
    ) -> Result<Self, LocalizationError> {
        GraphSlamEstimator::resume_with(map, settings, pose, landmarks)
    }
}

/// The map with its start pose moved to `pose`.
fn starting_at(map: &WorldMap, pose: &Pose) -> Box<WorldMap> {
    let mut moved = Box::new(*map);
    moved.start_x = pose.x;
    moved.start_y = pose.y;
    moved.start_theta = pose.theta;
    moved
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

    /// No gap (or a fresh start) is the step's own odometry. A gap of n steps predicts the
    /// one arc between the two odometry poses over n·dt (capped at the longest dt odometry may
    /// cover, the arc kept whole); with no odometry pose to start from, the newest velocities
    /// over the gap.
    #[test]
    fn odometry_over_a_gap_covers_the_whole_gap() {
        let mut odom: Odom = bytemuck::Zeroable::zeroed();
        (odom.v, odom.omega, odom.dt) = (0.3, -0.2, 0.01);
        (odom.x, odom.y, odom.theta) = (1.0, 2.0, 0.5);
        let since = |odom: &Odom, before, ticks| odometry_since(odom, before, ticks, 0.01);
        for ticks in [None, Some(1), Some(0)] {
            assert_eq!(since(&odom, Some([0.0; 3]), ticks), odom);
        }
        let held = since(&odom, None, Some(30));
        assert!((held.dt - 0.3).abs() < 1e-12);
        assert_eq!((held.v, held.omega), (0.3, -0.2));
        assert_eq!(since(&odom, None, Some(5000)).dt, models::MAX_ODOM_DT);
        // The wheels went on while this process was away: from (0.7, 2.1, 0.6) along the arc.
        let before = Pose2::new(0.7, 2.1, 0.6);
        let (s, dtheta) = (0.4, -0.1);
        let here = mole_types::unicycle_arc(before, s, dtheta, 1.0);
        (odom.x, odom.y, odom.theta) = (here.x, here.y, here.theta);
        let bridged = since(&odom, Some([before.x, before.y, before.theta]), Some(30));
        assert!((bridged.dt - 0.3).abs() < 1e-12);
        assert!((bridged.v * bridged.dt - s).abs() < 1e-9, "{bridged:?}");
        assert!(
            (bridged.omega * bridged.dt - dtheta).abs() < 1e-9,
            "{bridged:?}"
        );
        let long = since(&odom, Some([before.x, before.y, before.theta]), Some(500));
        assert_eq!(long.dt, models::MAX_ODOM_DT);
        assert!((long.v * long.dt - s).abs() < 1e-9, "{long:?}");
    }

    /// Every kind builds, starts at the start pose, and publishes particles (PF) or landmarks
    /// (SLAM kinds) exactly when it has them.
    #[test]
    fn build_estimator_builds_every_filter() {
        let mut map = test_support::zeroed_map();
        map.arena_width = 4.0;
        map.arena_height = 3.0;
        map.start_x = 1.0;
        map.start_y = 1.0;
        let mut particles: Box<Particles> = bytemuck::zeroed_box();
        let mut landmarks: Box<Landmarks> = bytemuck::zeroed_box();
        for &kind in EstimatorKind::ALL {
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
            assert_eq!(est.write_landmarks(&mut landmarks), kind.is_slam());
        }
        assert_eq!(particles.n_particles as usize, pf::DEFAULT_PARTICLES);
    }

    /// A particle filter started fresh or after a swap runs the particle count its settings
    /// give it (`localization.pf.n_particles`).
    #[test]
    fn the_particle_filter_runs_the_count_it_is_given() {
        let mut map = test_support::zeroed_map();
        (map.arena_width, map.arena_height) = (4.0, 3.0);
        let mut pose: Box<Pose> = bytemuck::zeroed_box();
        (pose.x, pose.y) = (2.0, 1.5);
        let mut particles: Box<Particles> = bytemuck::zeroed_box();
        let mut settings = Settings::default();
        settings.pf.n_particles = 300;
        for from in [None, Some(&*pose)] {
            let est = start_estimator(EstimatorKind::Pf, &map, &settings, from, None).unwrap();
            assert!(est.write_particles(&mut particles));
            assert_eq!(particles.n_particles, 300, "resumed: {}", from.is_some());
        }
    }

    /// The settings an estimator assumes reach it: a σ set replaces the sensor's, the others stay
    /// the world's; a particle count out of its bounds is refused naming the key.
    #[test]
    fn settings_set_the_assumed_noise_and_bound_the_particle_count() {
        use mole_types::settings::Settings as _;
        let mut map = test_support::zeroed_map();
        (map.sensors.odom_v_std, map.sensors.beacon_range_std) = (0.02, 0.05);
        let mut settings = Settings::default();
        settings.noise.odom_v_std = Some(0.5);
        let assumed = settings.noise.assumed(&map);
        assert_eq!(assumed.sensors.odom_v_std, 0.5);
        assert_eq!(assumed.sensors.beacon_range_std, 0.05);
        for bad in ["0", "1000001"] {
            let e = Settings::default().with("pf.n_particles", bad).unwrap_err();
            assert_eq!(e.key, "pf.n_particles", "{bad}");
        }
        assert!(Settings::default().with("noise.fix_std", "-1.0").is_err());
        assert_eq!(
            Settings::default()
                .with("pf.n_particles", "7")
                .unwrap()
                .pf
                .n_particles,
            7
        );
    }
}
