//! Garbage in never panics and never leaves a non-finite state: EKF-SLAM and FastSLAM take
//! arbitrary odometry and readings (NaN, infinities, absurd magnitudes, any id) in any order,
//! and count what they refuse.

use mole_localization::NoiseModel;
use mole_localization::slam::{
    Correspondence, EkfSlam, FastSlam, FastSlamConfig, Landmark, SlamConfig,
};
use mole_types::{BeaconReading, Pose2};
use nalgebra::Matrix3;
use proptest::prelude::*;

#[path = "common/garbage.rs"]
mod garbage_values;
use garbage_values::any_f64;

#[derive(Debug, Clone)]
enum Op {
    Predict(f64, f64, f64),
    Correct(Vec<(u32, f64, f64)>),
}

fn op() -> impl Strategy<Value = Op> {
    prop_oneof![
        (any_f64(), any_f64(), any_f64()).prop_map(|(v, w, dt)| Op::Predict(v, w, dt)),
        prop::collection::vec((0u32..12, any_f64(), any_f64()), 0..6).prop_map(Op::Correct),
    ]
}

fn readings(r: &[(u32, f64, f64)]) -> Vec<BeaconReading> {
    r.iter()
        .map(|&(id, range, bearing)| BeaconReading {
            id,
            _pad: 0,
            range,
            bearing,
        })
        .collect()
}

/// Whether a pose, its covariance and a map are all finite.
fn finite(pose: Pose2, cov: Matrix3<f64>, mut map: impl Iterator<Item = Landmark>) -> bool {
    pose.x.is_finite()
        && pose.y.is_finite()
        && pose.theta.is_finite()
        && cov.iter().all(|v| v.is_finite())
        && map.all(|l| l.mean.iter().chain(l.cov.iter()).all(|v| v.is_finite()))
}

fn config(correspondence: Correspondence) -> SlamConfig {
    SlamConfig {
        correspondence,
        ..SlamConfig::default()
    }
}

fn noise() -> NoiseModel {
    NoiseModel::new(0.1, 0.05, 0.1, 0.02, 0.5)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]
    /// Any sequence of garbage leaves both filters finite, with every correspondence mode.
    #[test]
    fn garbage_never_panics_and_the_state_stays_finite(ops in prop::collection::vec(op(), 1..30)) {
        for correspondence in [Correspondence::Known, Correspondence::Unknown] {
            let mut ekf = EkfSlam::new(Pose2::default(), Matrix3::identity() * 0.01, noise(), 6, config(correspondence));
            let mut fast = FastSlam::new(
                Pose2::default(),
                noise(),
                6,
                config(correspondence),
                FastSlamConfig { n_particles: 30, islands: 3, seed: 1, ..FastSlamConfig::default() },
            );
            for op in &ops {
                match op {
                    Op::Predict(v, w, dt) => {
                        let _ = ekf.predict(*v, *w, *dt);
                        let _ = fast.predict(*v, *w, *dt);
                    }
                    Op::Correct(r) => {
                        let r = readings(r);
                        ekf.correct(&r);
                        fast.correct(&r);
                    }
                }
                prop_assert!(finite(ekf.pose(), ekf.pose_covariance(), ekf.landmarks()), "EKF-SLAM {:?} after {:?}", correspondence, op);
                prop_assert!(finite(fast.pose(), fast.pose_covariance(), fast.landmarks()), "FastSLAM {:?} after {:?}", correspondence, op);
                prop_assert!(ekf.covariance().iter().all(|v| v.is_finite()));
            }
        }
    }
}

/// Each kind of garbage is refused and counted, never used: NaN, infinite and absurd odometry,
/// negative dt, NaN and absurd readings.
#[test]
fn garbage_is_counted_not_used() {
    let mut ekf = EkfSlam::new(
        Pose2::default(),
        Matrix3::zeros(),
        noise(),
        4,
        config(Correspondence::Known),
    );
    let mut fast = FastSlam::new(
        Pose2::default(),
        noise(),
        4,
        config(Correspondence::Known),
        FastSlamConfig::default(),
    );
    let controls = [
        (f64::NAN, 0.0, 0.1),
        (1.0, f64::INFINITY, 0.1),
        (1e300, 0.0, 0.1),
        (1.0, 1e9, 0.1),
        (1.0, 0.0, -0.1),
        (1.0, 0.0, 1e6),
    ];
    for (v, w, dt) in controls {
        assert!(ekf.predict(v, w, dt).is_err());
        assert!(fast.predict(v, w, dt).is_err());
    }
    let bad = readings(&[
        (0, f64::NAN, 0.0),
        (1, 1e300, 0.0),
        (2, -1.0, 0.0),
        (3, 2.0, f64::INFINITY),
    ]);
    ekf.correct(&bad);
    fast.correct(&bad);
    assert_eq!((ekf.ignored(), fast.ignored()), (10, 10));
    assert_eq!((ekf.len(), fast.landmarks().count()), (0, 0));
    assert_eq!(ekf.pose(), Pose2::default());
    assert_eq!(fast.pose(), Pose2::default());
    // A wild reading of a mapped landmark is an outlier: refused and counted as rejected.
    ekf.correct(&readings(&[(0, 3.0, 0.0)]));
    ekf.correct(&readings(&[(0, 30.0, 0.0)]));
    assert_eq!((ekf.len(), ekf.rejected()), (1, 1));
}
