//! Zero allocation per SLAM step: a counting global allocator (this test binary only) counts
//! this thread's allocations while EKF-SLAM and FastSLAM predict and correct after warm-up,
//! with mapped landmarks updated and a new landmark founded inside the counted steps.

use mole_localization::NoiseModel;
use mole_localization::slam::{Correspondence, EkfSlam, FastSlam, FastSlamConfig, SlamConfig};
use mole_runtime::{CountingAllocator, allocations_during};
use mole_types::{BeaconReading, Pose2, wrap_angle};
use nalgebra::Matrix3;

#[global_allocator]
static ALLOCATOR: CountingAllocator = CountingAllocator;

/// Landmarks of the test world.
const LANDMARKS: [(f64, f64); 5] = [
    (3.0, 1.0),
    (4.0, -2.0),
    (-1.0, 3.0),
    (2.0, 4.0),
    (-3.0, -3.0),
];
/// Readings per step (the first three landmarks during warm-up, all five later).
const MAX_READINGS: usize = LANDMARKS.len() + 1;

/// The readings of step k into `out` (no allocation): noise-free readings of the first
/// `visible` landmarks from the pose of a slow circle, plus a garbage reading; returns how many.
fn readings(k: usize, visible: usize, out: &mut [BeaconReading; MAX_READINGS]) -> usize {
    let a = 0.01 * k as f64;
    let (x, y, th) = (a.sin(), 1.0 - a.cos(), a);
    for (i, &(lx, ly)) in LANDMARKS[..visible].iter().enumerate() {
        let (dx, dy) = (lx - x, ly - y);
        out[i] = BeaconReading {
            id: i as u32,
            _pad: 0,
            range: dx.hypot(dy),
            bearing: wrap_angle(dy.atan2(dx) - th),
        };
    }
    out[visible] = BeaconReading {
        id: 99,
        _pad: 0,
        range: f64::NAN,
        bearing: 0.0,
    };
    visible + 1
}

fn noise() -> NoiseModel {
    NoiseModel::new(0.1, 0.05, 0.1, 0.02, 0.5)
}

fn config(correspondence: Correspondence) -> SlamConfig {
    SlamConfig {
        correspondence,
        ..SlamConfig::default()
    }
}

/// Runs `step(k, visible)` for 10 warm-up steps with 3 landmarks, then counts the
/// allocations of 20 steps with all 5 (two founded inside the counted region).
fn allocations_in_steps(mut step: impl FnMut(usize, usize)) -> u64 {
    for k in 0..10 {
        step(k, 3);
    }
    allocations_during(|| {
        for k in 10..30 {
            step(k, LANDMARKS.len());
        }
    })
}

/// The counter works: a boxed value is seen.
#[test]
fn the_counter_sees_an_allocation() {
    let seen = allocations_during(|| {
        std::hint::black_box(Box::new(7u64));
    });
    assert!(seen > 0, "a Box was allocated, the counter saw {seen}");
}

/// EKF-SLAM, known and unknown correspondences: no allocation per step, including the steps
/// that found landmarks 3 and 4.
#[test]
fn ekf_slam_steps_do_not_allocate() {
    for correspondence in [Correspondence::Known, Correspondence::Unknown] {
        let mut slam = EkfSlam::new(
            Pose2::default(),
            Matrix3::zeros(),
            noise(),
            8,
            config(correspondence),
        );
        let mut buf = [BeaconReading::default(); MAX_READINGS];
        let n = allocations_in_steps(|k, visible| {
            let r = readings(k, visible, &mut buf);
            slam.predict(1.0, 1.0, 0.01).expect("plausible control");
            slam.correct(&buf[..r]);
        });
        assert_eq!(slam.len(), LANDMARKS.len(), "{correspondence:?}");
        assert_eq!(n, 0, "{correspondence:?}: {n} allocations in 20 steps");
    }
}

/// FastSLAM, known and unknown correspondences: no allocation per step, including founding
/// landmarks and resampling.
#[test]
fn fastslam_steps_do_not_allocate() {
    for correspondence in [Correspondence::Known, Correspondence::Unknown] {
        let mut slam = FastSlam::new(
            Pose2::default(),
            noise(),
            8,
            config(correspondence),
            FastSlamConfig {
                n_particles: 200,
                // Four islands, so that resampling one leaves the others as they are.
                islands: 4,
                seed: 5,
                // Resample whenever the weights are not uniform: every step that has readings.
                resample_threshold: 1.0,
            },
        );
        let mut buf = [BeaconReading::default(); MAX_READINGS];
        let mut resamples_before = 0;
        let n = allocations_in_steps(|k, visible| {
            if k == 10 {
                resamples_before = slam.resamples();
            }
            let r = readings(k, visible, &mut buf);
            slam.predict(1.0, 1.0, 0.01).expect("plausible control");
            slam.correct(&buf[..r]);
        });
        assert_eq!(
            slam.landmarks().count(),
            LANDMARKS.len(),
            "{correspondence:?}"
        );
        assert!(
            slam.resamples() > resamples_before,
            "{correspondence:?}: no resampling counted"
        );
        assert_eq!(n, 0, "{correspondence:?}: {n} allocations in 20 steps");
    }
}
