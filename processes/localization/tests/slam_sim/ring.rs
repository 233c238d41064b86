//! The world of `scenarios/slam_loop.toml` offline, without the stack's IPC: its arena, block,
//! 24 beacons, start, beacon sensor and rate as the world's own loader (`mole-world`) reads them
//! from the file, the odometry noise it inherits from the world's defaults, the stack's own
//! sensor model (`mole-sensing`, which also hides the beacons behind the block), and a robot that
//! drives once round the corridor's centre line at 0.42 m/s and then stands, as frontier
//! exploration drives the ring in the stack (it ends in about 5,100–5,900 of the 6,000 steps
//! allowed).

use std::path::Path;

use mole_localization::models::unicycle_g;
use mole_sensing::Sensing;
use mole_types::{Beacons, Landmarks, Odom, Truth, WorldMap};
use mole_world::{Scenario, load_scenario};
use nalgebra::Vector3;

/// The scenario file the world below is read from.
pub const SCENARIO: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../../scenarios/slam_loop.toml"
);
/// Steps of a run, as many as the stack's slam_loop runs allow (60 s at 100 Hz).
pub const RING_STEPS: usize = 6_000;
/// The corridor's centre line: the square 0.75 m inside the arena's walls.
const CENTRE_INSET: f64 = 0.75;
/// Radius of the robot's turns at the corners (m).
const TURN_RADIUS: f64 = 0.5;
/// Its speed round the ring (m/s): 21.1 m of centre line in about 5,000 steps, within the
/// robot's 0.5 m/s (the world's default `[robot] max_speed`).
const SPEED: f64 = 0.42;

/// [`SCENARIO`], loaded as the world loads it.
fn scenario() -> Scenario {
    load_scenario(Path::new(SCENARIO)).unwrap_or_else(|e| panic!("{SCENARIO}: {e}"))
}

/// The beacons of the scenario, in order (the index is the beacon id).
pub fn ring_beacons() -> Vec<(f64, f64)> {
    scenario().beacons.iter().map(|b| (b.x, b.y)).collect()
}

/// `world/map` of slam_loop with `seed`, as the world publishes it from the scenario: arena,
/// obstacles, beacons, start, dt, robot, grid and every sensor (slam_loop has no
/// `[sensors.odometry]`, so the odometry noise is the world's default 0.02 m/s, 0.02 rad/s; no
/// fix), the seed replaced by `seed`.
pub fn ring_map(seed: u64) -> Box<WorldMap> {
    let mut m: Box<WorldMap> = bytemuck::zeroed_box();
    scenario().write_world_map(&mut m);
    m.seed = seed;
    m
}

/// The true controls (v, ω) of each step on `map`: once round the centre line anticlockwise
/// from the start (which slam_loop puts on it, heading along the bottom leg), straights and
/// quarter turns of [`TURN_RADIUS`] at the corners, each segment a whole number of steps; then
/// standing still until `steps`.
pub fn ring_controls(map: &WorldMap, steps: usize) -> Vec<(f64, f64)> {
    let quarter = core::f64::consts::FRAC_PI_2;
    let (lo, hi) = (CENTRE_INSET, map.arena_width - CENTRE_INSET);
    let mut out = Vec::with_capacity(steps);
    let mut segment = |length: f64, turn: f64| {
        let n = (length / (SPEED * map.dt)).round().max(1.0);
        let duration = n * map.dt;
        out.extend((0..n as usize).map(|_| (length / duration, turn / duration)));
    };
    segment(hi - TURN_RADIUS - map.start_x, 0.0);
    for _ in 0..3 {
        segment(quarter * TURN_RADIUS, quarter);
        segment(hi - lo - 2.0 * TURN_RADIUS, 0.0);
    }
    segment(quarter * TURN_RADIUS, quarter);
    segment(map.start_x - lo - TURN_RADIUS, 0.0);
    out.resize(steps, (0.0, 0.0));
    out
}

/// Runs `steps` steps of slam_loop with `seed`: the truth moves by [`ring_controls`], the
/// stack's sensing draws each step's odometry and beacon readings from it (streams seeded by
/// `seed`, as in the stack), and `each` gets them with the truth (its pose and true v, ω).
pub fn run_ring(seed: u64, steps: usize, mut each: impl FnMut(&Odom, &Beacons, &Truth)) {
    let map = ring_map(seed);
    let mut sensing = Sensing::new(&map, seed).expect("a valid map");
    let mut truth: Box<Truth> = bytemuck::zeroed_box();
    let mut pose = Vector3::new(map.start_x, map.start_y, map.start_theta);
    let mut odom: Odom = bytemuck::Zeroable::zeroed();
    let mut beacons: Box<Beacons> = bytemuck::zeroed_box();
    for (k, (v, omega)) in ring_controls(&map, steps).into_iter().enumerate() {
        pose = unicycle_g(&pose, v, omega, map.dt);
        (truth.x, truth.y, truth.theta) = (pose[0], pose[1], pose[2]);
        (truth.v, truth.omega) = (v, omega);
        truth.header.tick = k as u64 + 1;
        sensing.odom(&truth, &mut odom);
        sensing.beacons(&truth, &mut beacons);
        each(&odom, &beacons, &truth);
    }
}

/// A published landmark map scored as the monitor scores it (processes/monitor/src/slam.rs),
/// each landmark against the beacon its id names.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MapScore {
    /// Landmarks in the map.
    pub landmarks: usize,
    /// √(mean squared distance) from landmark to beacon (m).
    pub rmse: f64,
    /// Mean 2-D NEES eᵀΣ⁻¹e over the landmarks whose Σ is positive definite.
    pub nees: f64,
    /// How many landmarks that mean is over.
    pub nees_samples: usize,
    /// The degrees of freedom ν the estimator published with its map (`Landmarks::nees_dof`).
    pub nees_dof: f64,
}

impl MapScore {
    /// Whether the mean NEES lies in the interval the monitor judges a map by, that of the
    /// degrees of freedom the estimator published (docs/algorithms.md §6.9.6).
    pub fn nees_inside_monitors_interval(&self) -> bool {
        mole_monitor::mean_nees_interval_of_dof(self.nees_dof)
            .is_some_and(|[lo, hi]| (lo..=hi).contains(&self.nees))
    }
}

/// Scores `map` against `beacons` (indexed by id).
pub fn score_map(map: &Landmarks, beacons: &[(f64, f64)]) -> MapScore {
    let (mut squared, mut nees, mut samples) = (0.0, 0.0, 0);
    let landmarks = map.landmarks();
    for l in landmarks {
        let (x, y) = beacons[l.id as usize];
        let e = [l.x - x, l.y - y];
        squared += e[0] * e[0] + e[1] * e[1];
        if let Some(v) = mole_monitor::nees_2d(&e, &l.covariance) {
            nees += v;
            samples += 1;
        }
    }
    MapScore {
        landmarks: landmarks.len(),
        rmse: (squared / landmarks.len().max(1) as f64).sqrt(),
        nees: if samples > 0 {
            nees / samples as f64
        } else {
            f64::NAN
        },
        nees_samples: samples,
        nees_dof: map.nees_dof,
    }
}

/// The two-sided 95% interval of the mean of n independent 2-DOF NEES values, the monitor's
/// `mean_nees_interval` (Bar-Shalom, Li & Kirubarajan 2001, §5.4): n·mean ~ χ²₂ₙ, so
/// [χ²₂ₙ(0.025)/n, χ²₂ₙ(0.975)/n]; [1.28, 2.88] for the 24 landmarks of the ring. The same
/// formula bounds the mean over n runs of each run's mean NEES, whose variance is at most that
/// of one χ²₂ however its landmarks' errors are correlated (docs/algorithms.md §6.9.5).
pub fn mean_nees_interval(n: usize) -> (f64, f64) {
    let n = u32::try_from(n.max(1)).expect("a count of landmarks or runs");
    let [lo, hi] = mole_monitor::mean_nees_interval(2, n).expect("an interval for n ≥ 1");
    (lo, hi)
}
