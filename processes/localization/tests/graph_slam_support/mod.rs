//! Simulated drives for the GraphSLAM tests and bench: a robot laps a circle among beacons,
//! its odometry perturbed by the control noise M_t and its readings by Q_t of the same
//! [`NoiseModel`] the graph assumes (Thrun et al. 2005, §5.3 and §6.6).

use mole_localization::graph_slam::{GraphCapacity, GraphSlamConfig, PoseGraph};
use mole_localization::models::{range_bearing_h, unicycle_g};
use mole_localization::noise::NoiseModel;
use mole_types::{BeaconReading, Odom, Pose2, wrap_angle};
use nalgebra::{Vector2, Vector3};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

/// The shape of a drive.
#[derive(Debug, Clone, Copy)]
pub struct Drive {
    /// Radius of the circle the robot laps (m).
    pub radius: f64,
    /// Steps per lap.
    pub steps_per_lap: usize,
    /// Laps; the drive ends where it started.
    pub laps: usize,
    /// Step length (s).
    pub dt: f64,
    /// Beacons, evenly spread over a ring inside and one outside the circle.
    pub beacons: usize,
    /// Beacons farther than this (m) are not seen.
    pub range_max: f64,
}

/// Truth and measurements of one drive.
pub struct Simulation {
    /// The start pose (the graph's prior).
    pub start: Pose2,
    /// True poses, one more than odometry steps.
    pub truth: Vec<Vector3<f64>>,
    /// Measured odometry, step k moving pose k to pose k + 1.
    pub odometry: Vec<Odom>,
    /// Readings taken at each pose.
    pub readings: Vec<Vec<BeaconReading>>,
    /// True beacon positions, indexed by id.
    pub beacons: Vec<Vector2<f64>>,
}

/// The noise of the default scenario's sensors.
pub fn default_noise() -> NoiseModel {
    NoiseModel::new(0.02, 0.02, 0.05, 0.02, 0.3)
}

/// A zeroed odometry message carrying (v, ω, dt).
pub fn odom(v: f64, omega: f64, dt: f64) -> Odom {
    let mut o: Odom = bytemuck::Zeroable::zeroed();
    (o.v, o.omega, o.dt) = (v, omega, dt);
    o
}

/// A reading of beacon `id`.
pub fn reading(id: u32, range: f64, bearing: f64) -> BeaconReading {
    BeaconReading {
        id,
        _pad: 0,
        range,
        bearing,
    }
}

fn gauss(rng: &mut ChaCha8Rng) -> f64 {
    StandardNormal.sample(rng)
}

/// Simulates `drive`; with `seed` None the odometry and readings are exact.
pub fn simulate(drive: &Drive, noise: &NoiseModel, seed: Option<u64>) -> Simulation {
    let mut rng = ChaCha8Rng::seed_from_u64(seed.unwrap_or(0));
    let centre = Vector2::new(0.0, 0.0);
    let start = Pose2::new(centre[0], centre[1] - drive.radius, 0.0);
    let lap_time = drive.steps_per_lap as f64 * drive.dt;
    let omega = core::f64::consts::TAU / lap_time;
    let v = omega * drive.radius;
    let beacons: Vec<Vector2<f64>> = (0..drive.beacons)
        .map(|i| {
            let a = core::f64::consts::TAU * (i as f64 + 0.25) / drive.beacons as f64;
            let r = drive.radius + if i % 2 == 0 { -1.5 } else { 1.5 };
            centre + r * Vector2::new(a.cos(), a.sin())
        })
        .collect();
    let steps = drive.steps_per_lap * drive.laps;
    let mut truth = Vec::with_capacity(steps + 1);
    let mut odometry = Vec::with_capacity(steps);
    let mut readings = Vec::with_capacity(steps + 1);
    truth.push(Vector3::new(start.x, start.y, start.theta));
    let noisy = seed.is_some();
    let jitter = |rng: &mut ChaCha8Rng, std: f64| if noisy { std * gauss(rng) } else { 0.0 };
    for k in 0..=steps {
        let x = truth[k];
        let mut seen = Vec::new();
        for (id, b) in beacons.iter().enumerate() {
            let z = range_bearing_h(&x, (b[0], b[1]));
            if z[0] <= drive.range_max {
                let range = z[0] + jitter(&mut rng, noise.beacon_range_std);
                let bearing = wrap_angle(z[1] + jitter(&mut rng, noise.beacon_bearing_std));
                seen.push(reading(id as u32, range, bearing));
            }
        }
        readings.push(seen);
        if k < steps {
            truth.push(unicycle_g(&x, v, omega, drive.dt));
            odometry.push(odom(
                v + jitter(&mut rng, noise.odom_v_std),
                omega + jitter(&mut rng, noise.odom_omega_std),
                drive.dt,
            ));
        }
    }
    Simulation {
        start,
        truth,
        odometry,
        readings,
        beacons,
    }
}

impl Simulation {
    /// Number of readings over the whole drive.
    pub fn reading_count(&self) -> usize {
        self.readings.iter().map(Vec::len).sum()
    }

    /// A graph with every pose and reading of the drive added, not yet optimised: its estimate
    /// is the dead-reckoned odometry chain.
    pub fn graph(&self, noise: &NoiseModel) -> PoseGraph {
        let capacity = GraphCapacity {
            poses: self.truth.len(),
            landmarks: self.beacons.len(),
            observations: self.reading_count(),
        };
        let mut graph = PoseGraph::new(self.start, GraphSlamConfig::new(*noise), capacity);
        for (k, readings) in self.readings.iter().enumerate() {
            if k > 0 {
                graph
                    .add_pose(&self.odometry[k - 1])
                    .expect("valid odometry");
            }
            for r in readings {
                graph.add_observation(k, r).expect("valid reading");
            }
        }
        graph
    }
}

/// Root-mean-square position error of `estimate` against `truth` (m).
pub fn position_rmse(estimate: &[Vector3<f64>], truth: &[Vector3<f64>]) -> f64 {
    assert_eq!(estimate.len(), truth.len());
    let sum: f64 = estimate
        .iter()
        .zip(truth)
        .map(|(e, t)| (e.xy() - t.xy()).norm_squared())
        .sum();
    (sum / truth.len() as f64).sqrt()
}
