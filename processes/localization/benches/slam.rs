//! Per-step cost of SLAM with 32 mapped landmarks and 8 readings a step: EKF-SLAM predict +
//! correct (target ≤ 50 µs), FastSLAM 1.0 with 1000 particles predict + correct + resampling
//! when due (target ≤ 1 ms); beside them, for scale, the localising EKF with the same readings
//! of the same 32 beacons, known to it (a step through the `Estimator` trait).

use criterion::{Criterion, criterion_group, criterion_main};
use mole_localization::slam::{EkfSlam, FastSlam, FastSlamConfig, SlamConfig};
use mole_localization::{Ekf, Estimator, NoiseModel, Readings};
use mole_types::{BeaconReading, BeaconSite, Beacons, Odom, Pose2, wrap_angle};
use nalgebra::Matrix3;
use std::hint::black_box;

/// Landmarks in the map.
const LANDMARKS: usize = 32;
/// Readings per step.
const READINGS: usize = 8;
/// Steps of precomputed input, cycled.
const STEPS: usize = 64;
/// Step length (s).
const DT: f64 = 0.1;

/// Landmark k on a ring of radius 10 m around the origin.
fn landmark(k: usize) -> (f64, f64) {
    let a = core::f64::consts::TAU * k as f64 / LANDMARKS as f64;
    (10.0 * a.cos(), 10.0 * a.sin())
}

/// Noise-free readings of step k: the robot circles at radius 3 m (v = 1 m/s, ω = 1/3 rad/s)
/// and sees READINGS landmarks, a window rotating through the ring.
fn readings(k: usize) -> Vec<BeaconReading> {
    let t = k as f64 * DT;
    let a = t / 3.0;
    let (x, y, th) = (3.0 * a.sin(), 3.0 - 3.0 * a.cos(), a);
    (0..READINGS)
        .map(|i| {
            let id = (k + 4 * i) % LANDMARKS;
            let (lx, ly) = landmark(id);
            let (dx, dy) = (lx - x, ly - y);
            BeaconReading {
                id: id as u32,
                _pad: 0,
                range: dx.hypot(dy),
                bearing: wrap_angle(dy.atan2(dx) - th),
            }
        })
        .collect()
}

fn noise() -> NoiseModel {
    NoiseModel::new(0.05, 0.02, 0.05, 0.01, 0.5)
}

fn bench(c: &mut Criterion) {
    let steps: Vec<Vec<BeaconReading>> = (0..STEPS).map(readings).collect();
    let mut ekf = EkfSlam::new(
        Pose2::default(),
        Matrix3::zeros(),
        noise(),
        LANDMARKS,
        SlamConfig::default(),
    );
    let mut fast = FastSlam::new(
        Pose2::default(),
        noise(),
        LANDMARKS,
        SlamConfig::default(),
        FastSlamConfig {
            n_particles: 1000,
            seed: 1,
            ..FastSlamConfig::default()
        },
    );
    // Map every landmark first: the benchmark measures steps with 32 mapped landmarks.
    for s in steps.iter().cycle().take(2 * STEPS) {
        ekf.predict(1.0, 1.0 / 3.0, DT).expect("plausible control");
        ekf.correct(s);
        fast.predict(1.0, 1.0 / 3.0, DT).expect("plausible control");
        fast.correct(s);
    }
    assert_eq!(ekf.len(), LANDMARKS);
    assert_eq!(fast.landmarks().count(), LANDMARKS);
    let sites: Vec<BeaconSite> = (0..LANDMARKS)
        .map(|id| {
            let (x, y) = landmark(id);
            BeaconSite {
                x,
                y,
                id: id as u32,
                _pad: 0,
            }
        })
        .collect();
    let mut ekf_localiser = Ekf::new(
        Pose2::default(),
        Matrix3::identity() * 1e-4,
        noise(),
        &sites,
    );
    let messages: Vec<Box<Beacons>> = steps
        .iter()
        .map(|s| {
            let mut b: Box<Beacons> = bytemuck::zeroed_box();
            b.readings[..s.len()].copy_from_slice(s);
            b.n_readings = s.len() as u32;
            b
        })
        .collect();
    let mut odom: Odom = bytemuck::Zeroable::zeroed();
    (odom.v, odom.omega, odom.dt) = (1.0, 1.0 / 3.0, DT);
    let mut k = 0;
    c.bench_function("ekf_step_8_of_32_known_beacons", |b| {
        b.iter(|| {
            ekf_localiser
                .step(&Readings::of(&odom).with_beacons(Some(black_box(&messages[k % STEPS]))));
            k += 1;
        })
    });
    c.bench_function("ekf_slam_step_32_landmarks", |b| {
        b.iter(|| {
            ekf.predict(1.0, 1.0 / 3.0, DT).expect("plausible control");
            ekf.correct(black_box(&steps[k % STEPS]));
            k += 1;
        })
    });
    c.bench_function("fastslam_step_1000_particles_32_landmarks", |b| {
        b.iter(|| {
            fast.predict(1.0, 1.0 / 3.0, DT).expect("plausible control");
            fast.correct(black_box(&steps[k % STEPS]));
            k += 1;
        })
    });
    black_box((ekf.pose(), fast.pose(), ekf_localiser.pose()));
}

criterion_group!(benches, bench);
criterion_main!(benches);
