//! A seeded SLAM world for the slam_* tests: a unicycle circling among landmarks, with
//! odometry and range-bearing readings drawn from the crate's own models and noise.

#![allow(dead_code)] // Each test binary uses part of it.

pub mod ring;

use mole_localization::NoiseModel;
use mole_localization::models::unicycle_g;
use mole_types::{BeaconReading, Beacons, Odom, WorldMap, wrap_angle};
use nalgebra::Vector3;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

/// Step length (s).
pub const DT: f64 = 0.1;
/// True forward speed (m/s).
pub const V: f64 = 1.0;
/// True turn rate (rad/s): a circle of radius 5 m around (0, 5), once every 31.4 s.
pub const OMEGA: f64 = 0.2;
/// The sensor sees landmarks up to this range (m).
pub const SENSOR_RANGE: f64 = 7.0;

/// The landmarks: six on a ring of radius 8 m and three on a ring of radius 2 m around the
/// centre (0, 5) of the robot's circle.
pub fn landmarks() -> Vec<(f64, f64)> {
    let ring = |r: f64, n: usize, phase: f64| {
        (0..n).map(move |k| {
            let a = phase + core::f64::consts::TAU * k as f64 / n as f64;
            (r * a.cos(), 5.0 + r * a.sin())
        })
    };
    ring(8.0, 6, 0.3).chain(ring(2.0, 3, 1.0)).collect()
}

/// The noise of the world, which the filters are also told.
pub fn noise() -> NoiseModel {
    NoiseModel::new(0.2, 0.2, 0.2, 0.05, 0.5)
}

/// One step: the measured control, the readings after moving, and the true pose.
#[derive(Debug, Clone)]
pub struct Step {
    /// Measured speed (m/s).
    pub v: f64,
    /// Measured turn rate (rad/s).
    pub omega: f64,
    /// Readings of every landmark within range, ids = index in [`landmarks`].
    pub readings: Vec<BeaconReading>,
    /// The true pose after the step.
    pub truth: Vector3<f64>,
}

/// `steps` steps of the world with [`noise`] (see [`simulate_with`]).
pub fn simulate(steps: usize, seed: u64) -> Vec<Step> {
    simulate_with(steps, seed, &noise())
}

/// `steps` steps from the start (0, 0, 0): the truth moves by g with the true control, the
/// odometry reports it with N(0, M_t) noise, the readings carry N(0, Q_t) noise.
pub fn simulate_with(steps: usize, seed: u64, noise: &NoiseModel) -> Vec<Step> {
    simulate_with_from(steps, seed, noise, (0.0, 0.0, 0.0))
}

/// `steps` steps with [`noise`] from `start` (x, y, θ) instead of the origin.
pub fn simulate_from(steps: usize, seed: u64, start: (f64, f64, f64)) -> Vec<Step> {
    simulate_with_from(steps, seed, &noise(), start)
}

fn simulate_with_from(
    steps: usize,
    seed: u64,
    noise: &NoiseModel,
    start: (f64, f64, f64),
) -> Vec<Step> {
    let lms = landmarks();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut gauss = move || -> f64 { rng.sample(StandardNormal) };
    let mut truth = Vector3::new(start.0, start.1, start.2);
    (0..steps)
        .map(|_| {
            truth = unicycle_g(&truth, V, OMEGA, DT);
            let v = V + noise.odom_v_std * gauss();
            let omega = OMEGA + noise.odom_omega_std * gauss();
            let mut readings = Vec::new();
            for (i, &(lx, ly)) in lms.iter().enumerate() {
                let (dx, dy) = (lx - truth[0], ly - truth[1]);
                let r = dx.hypot(dy);
                let (er, eb) = (gauss(), gauss());
                if r <= SENSOR_RANGE {
                    readings.push(BeaconReading {
                        id: i as u32,
                        _pad: 0,
                        range: r + noise.beacon_range_std * er,
                        bearing: wrap_angle(
                            dy.atan2(dx) - truth[2] + noise.beacon_bearing_std * eb,
                        ),
                    });
                }
            }
            Step {
                v,
                omega,
                readings,
                truth,
            }
        })
        .collect()
}

/// Pose error (x, y, θ wrapped) of an estimate against the truth.
pub fn pose_error(est: mole_types::Pose2, truth: &Vector3<f64>) -> Vector3<f64> {
    Vector3::new(
        est.x - truth[0],
        est.y - truth[1],
        wrap_angle(est.theta - truth[2]),
    )
}

/// The `world/map` the process estimators are built from: start (0, 0, 0), the world's
/// [`noise`], the seed, and `beacons` as the beacon sites (the SLAM estimators must not read
/// them: pass scrambled ones to prove it).
pub fn world_map(seed: u64, beacons: &[(f64, f64)]) -> Box<WorldMap> {
    let mut m: Box<WorldMap> = bytemuck::zeroed_box();
    let n = noise();
    (m.arena_width, m.arena_height, m.dt, m.seed) = (30.0, 30.0, DT, seed);
    let s = &mut m.sensors;
    (s.odom_v_std, s.odom_omega_std) = (n.odom_v_std, n.odom_omega_std);
    (s.beacon_range_std, s.beacon_bearing_std) = (n.beacon_range_std, n.beacon_bearing_std);
    (s.beacon_range_max, s.fix_std) = (SENSOR_RANGE, n.fix_std);
    m.place_beacons(beacons);
    m
}

/// The step's control and readings as the `sensing/odom` and `sensing/beacons` messages; ids
/// replaced by `id` when given (e.g. `LANDMARK_ANONYMOUS`).
pub fn messages(step: &Step, id: Option<u32>, odom: &mut Odom, beacons: &mut Beacons) {
    (odom.v, odom.omega, odom.dt) = (step.v, step.omega, DT);
    for (slot, r) in beacons.readings.iter_mut().zip(&step.readings) {
        *slot = BeaconReading {
            id: id.unwrap_or(r.id),
            ..*r
        };
    }
    beacons.n_readings = step.readings.len() as u32;
}
