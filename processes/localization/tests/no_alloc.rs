//! Zero allocation per step: a counting global allocator (this test binary only) counts the
//! allocations of this thread while each estimator takes steps through the `Estimator` trait in
//! steady state (for GraphSLAM: the step path; its smoother thread has its own workspace).

use mole_localization::{Estimator, EstimatorKind, GraphSlamEstimator, Readings};
use mole_runtime::{CountingAllocator, allocations_during};
use mole_types::{
    BeaconReading, Beacons, Fix, LANDMARK_ANONYMOUS, Landmarks, Odom, Trajectory, WorldMap,
};

#[global_allocator]
static ALLOCATOR: CountingAllocator = CountingAllocator;

/// Beacons of the test world; the last one comes into view only at step [`LATE_BEACON_STEP`].
const BEACONS: [(f64, f64); 4] = [(1.0, 1.0), (9.0, 1.0), (9.0, 9.0), (1.0, 9.0)];
/// The step from which the last beacon is seen: inside the counted steps, so a SLAM estimator
/// founds a landmark there.
const LATE_BEACON_STEP: usize = 15;

fn map() -> Box<WorldMap> {
    let mut m: Box<WorldMap> = bytemuck::zeroed_box();
    m.arena_width = 10.0;
    m.arena_height = 10.0;
    m.dt = 0.01;
    m.seed = 1;
    m.start_x = 5.0;
    m.start_y = 5.0;
    m.sensors.odom_v_std = 0.05;
    m.sensors.odom_omega_std = 0.05;
    m.sensors.beacon_range_std = 0.05;
    m.sensors.beacon_bearing_std = 0.02;
    m.sensors.fix_std = 0.5;
    m.place_beacons(&BEACONS);
    m
}

/// The inputs of one step, reused: nothing is allocated to make them.
struct Step {
    odom: Odom,
    beacons: Box<Beacons>,
    fix: Fix,
}

impl Step {
    fn new() -> Self {
        Self {
            odom: bytemuck::Zeroable::zeroed(),
            beacons: bytemuck::zeroed_box(),
            fix: bytemuck::Zeroable::zeroed(),
        }
    }

    /// Step k of a drive along +x at 0.5 m/s: noise-free readings of the beacons in view (ids
    /// hidden when `anonymous`), a garbage reading, a fix every 10th step; then `est` takes it.
    fn run(&mut self, est: &mut dyn Estimator, k: usize, anonymous: bool) {
        let (x, y, th) = (5.0 + 0.005 * k as f64, 5.0, 0.0);
        (self.odom.v, self.odom.omega, self.odom.dt) = (0.5, 0.0, 0.01);
        let seen = if k >= LATE_BEACON_STEP { 4 } else { 3 };
        let b = &mut self.beacons;
        b.n_readings = 0;
        for (i, &(bx, by)) in BEACONS[..seen].iter().enumerate() {
            let (dx, dy) = (bx - x, by - y);
            b.readings[b.n_readings as usize] = BeaconReading {
                id: if anonymous {
                    LANDMARK_ANONYMOUS
                } else {
                    i as u32
                },
                _pad: 0,
                range: dx.hypot(dy),
                bearing: dy.atan2(dx) - th,
            };
            b.n_readings += 1;
        }
        // A garbage reading too: refusals must not allocate either.
        b.readings[b.n_readings as usize] = BeaconReading {
            id: 30,
            _pad: 0,
            range: 0.0,
            bearing: 0.0,
        };
        b.n_readings += 1;
        let f = &mut self.fix;
        (f.x, f.y, f.std, f.valid) = (x, y, 0.5, u32::from(k.is_multiple_of(10)));
        est.step(
            &Readings::of(&self.odom)
                .with_beacons(Some(&self.beacons))
                .with_fix(Some(&self.fix)),
        );
    }
}

/// Allocations of steps 5..25 after 5 warm-up steps (the late beacon is founded in them).
fn allocations_per_step(est: &mut dyn Estimator, anonymous: bool) -> f64 {
    let mut step = Step::new();
    for k in 0..5 {
        step.run(est, k, anonymous);
    }
    let n = allocations_during(|| {
        for k in 5..25 {
            step.run(est, k, anonymous);
        }
    });
    n as f64 / 20.0
}

/// The counter works: it must see a Box, or a broken counter would pass everything below.
#[test]
fn the_counter_sees_an_allocation() {
    let boxed = allocations_during(|| {
        std::hint::black_box(Box::new([0u8; 64]));
    });
    assert!(boxed >= 1, "a Box was allocated, the counter saw {boxed}");
}

/// A step through the `Estimator` trait allocates nothing for every estimator, garbage
/// readings included; the SLAM kinds also with anonymous readings, and while founding a
/// landmark.
#[test]
fn steady_state_steps_do_not_allocate() {
    let map = map();
    for &kind in EstimatorKind::ALL {
        for anonymous in [false, true] {
            if anonymous && !kind.is_slam() {
                continue;
            }
            let mut est =
                mole_localization::build_estimator(kind, &map).expect("every estimator builds");
            let per_step = allocations_per_step(est.as_mut(), anonymous);
            assert_eq!(
                per_step,
                0.0,
                "{} (anonymous: {anonymous}): {per_step} allocations per step",
                kind.name()
            );
        }
    }
}

/// GraphSLAM's step path allocates nothing either in the steps that take a smoothed solution
/// over from the smoother thread, nor in writing that solution's trajectory into a message.
#[test]
fn graph_slam_steps_that_take_a_solution_over_do_not_allocate() {
    let map = map();
    let mut graph = GraphSlamEstimator::from_map(&map).expect("smoother thread starts");
    let mut step = Step::new();
    for k in 0..5 {
        step.run(&mut graph, k, false);
    }
    assert_eq!(graph.solves(), 0);
    // Steps until a solution has been taken over; the smoother solves every 100 steps, and the
    // short sleeps give it the time (the bound only guards against hanging).
    let mut k = 5;
    let mut trajectory: Box<Trajectory> = bytemuck::zeroed_box();
    let n = allocations_during(|| {
        while graph.solves() == 0 && k < 20_000 {
            step.run(&mut graph, k, false);
            std::thread::sleep(std::time::Duration::from_micros(200));
            k += 1;
        }
        graph.write_trajectory(&mut trajectory);
    });
    assert!(trajectory.n_poses > 0, "no trajectory written");
    assert!(graph.solves() > 0, "no solution taken over in {k} steps");
    assert_eq!(n, 0, "{n} allocations in {} steps", k - 5);
}

/// Fusing a peer robot's landmark map into EKF-SLAM (a `PeerFusion` round: its landmarks fused
/// by CI and one it lacks left unmapped) allocates nothing either.
#[test]
fn a_peer_fusion_round_does_not_allocate() {
    use mole_localization::slam::PeerFusion;
    let map = map();
    let mut est =
        mole_localization::build_estimator(EstimatorKind::EkfSlam, &map).expect("EKF-SLAM builds");
    let mut step = Step::new();
    for k in 0..10 {
        step.run(est.as_mut(), k, false);
    }
    // The peer's map: ours, twice as confident and 2 cm off, and a landmark we have not seen.
    let mut peer: Box<Landmarks> = bytemuck::zeroed_box();
    assert!(est.write_landmarks(&mut peer));
    let n = peer.n_landmarks as usize;
    for l in &mut peer.landmarks[..n] {
        l.x += 0.02;
        l.covariance.iter_mut().for_each(|c| *c *= 0.5);
    }
    peer.landmarks[n] = mole_types::Landmark {
        id: 3,
        _pad: 0,
        x: 1.0,
        y: 9.0,
        covariance: [0.01, 0.0, 0.0, 0.01],
    };
    peer.n_landmarks += 1;
    peer.header.stamp_ns = 1;
    let mut fusion = PeerFusion::new(1);
    let mut report = None;
    let allocations = allocations_during(|| {
        report = fusion.step(10, Some(&peer), est.as_mut());
    });
    let report = report.expect("a round with a new map");
    assert_eq!(
        (report.fused + report.kept, report.unmapped),
        (n, 1),
        "{report:?}"
    );
    assert_eq!(
        allocations, 0,
        "{allocations} allocations in a fusion round"
    );
}
