//! Zero allocation per step: a counting global allocator (this test binary only) counts the
//! allocations of this thread while each estimator runs predict + correct in steady state.

use mole_localization::{Estimator, EstimatorKind};
use mole_types::{BeaconReading, BeaconSite, Beacons, Fix, Odom, WorldMap};
use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

struct Counting;

thread_local! {
    static ALLOCATIONS: Cell<u64> = const { Cell::new(0) };
}

// SAFETY: every call is forwarded unchanged to the system allocator; the counter is a
// const-initialised thread-local Cell, which neither allocates nor re-enters the allocator.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        let _ = ALLOCATIONS.try_with(|c| c.set(c.get() + 1));
        // SAFETY: forwarded with the caller's layout.
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: forwarded with the caller's pointer and layout.
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        let _ = ALLOCATIONS.try_with(|c| c.set(c.get() + 1));
        // SAFETY: forwarded with the caller's layout.
        unsafe { System.alloc_zeroed(layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        let _ = ALLOCATIONS.try_with(|c| c.set(c.get() + 1));
        // SAFETY: forwarded with the caller's pointer, layout and size.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

fn allocations() -> u64 {
    ALLOCATIONS.with(Cell::get)
}

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

#[test]
fn steady_state_steps_do_not_allocate() {
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
        let mut est = kind.from_map(&map).expect("every estimator builds");
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
        let before = allocations();
        for k in 5..25 {
            step(est.as_mut(), k);
        }
        let per_step = (allocations() - before) as f64 / 20.0;
        assert_eq!(
            per_step,
            0.0,
            "{}: {per_step} allocations per step",
            kind.name()
        );
    }
}
