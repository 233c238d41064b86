//! Zero allocation per step: a counting global allocator (this test binary only) counts the
//! allocations of this thread while each estimator runs predict + correct in steady state.

use mole_localization::{Estimator, EstimatorKind};
use mole_runtime::{CountingAllocator, allocations_during};
use mole_types::{BeaconReading, BeaconSite, Beacons, Fix, Odom, WorldMap};

#[global_allocator]
static ALLOCATOR: CountingAllocator = CountingAllocator;

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
    for (i, &(x, y)) in [(1.0, 1.0), (9.0, 1.0), (9.0, 9.0)].iter().enumerate() {
        m.beacons[i] = BeaconSite {
            x,
            y,
            id: i as u32,
            _pad: 0,
        };
    }
    m.n_beacons = 3;
    m
}

/// Predict + correct allocates nothing for every estimator, garbage readings included.
#[test]
fn steady_state_steps_do_not_allocate() {
    // A broken counter would pass everything below: it must see this Box first.
    let boxed = allocations_during(|| {
        std::hint::black_box(Box::new([0u8; 64]));
    });
    assert!(boxed >= 1, "a Box was allocated, the counter saw {boxed}");
    let map = map();
    let mut beacons: Box<Beacons> = bytemuck::zeroed_box();
    let mut odom: Odom = bytemuck::Zeroable::zeroed();
    let mut fix: Fix = bytemuck::Zeroable::zeroed();
    for kind in [
        EstimatorKind::Bayes,
        EstimatorKind::Kf,
        EstimatorKind::Ekf,
        EstimatorKind::Pf,
    ] {
        let mut est =
            mole_localization::build_estimator(kind, &map).expect("every estimator builds");
        let mut step = |est: &mut dyn Estimator, k: usize| {
            let (x, y, th) = (5.0 + 0.005 * k as f64, 5.0, 0.0);
            (odom.v, odom.omega, odom.dt) = (0.5, 0.0, 0.01);
            beacons.n_readings = 0;
            for b in map.beacons() {
                let (dx, dy) = (b.x - x, b.y - y);
                beacons.readings[beacons.n_readings as usize] = BeaconReading {
                    id: b.id,
                    _pad: 0,
                    range: dx.hypot(dy),
                    bearing: dy.atan2(dx) - th,
                };
                beacons.n_readings += 1;
            }
            // A garbage reading too: refusals must not allocate either.
            beacons.readings[beacons.n_readings as usize].id = 30;
            beacons.n_readings += 1;
            (fix.x, fix.y, fix.std, fix.valid) = (x, y, 0.5, u32::from(k.is_multiple_of(10)));
            est.predict(&odom);
            est.correct(&beacons, &fix);
        };
        for k in 0..5 {
            step(est.as_mut(), k);
        }
        let n = allocations_during(|| {
            for k in 5..25 {
                step(est.as_mut(), k);
            }
        });
        let per_step = n as f64 / 20.0;
        assert_eq!(
            per_step,
            0.0,
            "{}: {per_step} allocations per step",
            kind.name()
        );
    }
}
