//! Steady-state mapping allocates nothing per step.

use mole_mapping::{ContactGrid, FrontierGrid};
use mole_runtime::{CountingAllocator, allocations_during};
use mole_types::*;

#[global_allocator]
static ALLOCATOR: CountingAllocator = CountingAllocator;

/// Integrating a footprint, a scan and a touch and writing both grids allocates nothing.
#[test]
fn a_mapping_step_does_not_allocate() {
    // A broken counter would pass everything below: it must see this Box first.
    let boxed = allocations_during(|| {
        std::hint::black_box(Box::new([0u8; 64]));
    });
    assert!(boxed >= 1, "a Box was allocated, the counter saw {boxed}");
    let mut frontier = FrontierGrid::new(10.0, 10.0, 0.05).expect("grid");
    let mut contact = ContactGrid::new(10.0, 10.0, 0.05).expect("grid");
    let mut scan: Box<Scan> = bytemuck::zeroed_box();
    scan.n_beams = 360;
    scan.angle_min = -std::f32::consts::PI;
    scan.angle_increment = std::f32::consts::TAU / 360.0;
    scan.range_max = 4.0;
    for (i, r) in scan.ranges.iter_mut().take(360).enumerate() {
        *r = 1.0 + (i % 40) as f32 * 0.05;
    }
    let mut tactile: Box<Tactile> = bytemuck::zeroed_box();
    tactile.n_sensors = 8;
    tactile.radius = 0.2;
    tactile.sensors[0] = TactileReading {
        angle: 0.0,
        fx: -3.0,
        fy: 0.0,
        _pad: 0.0,
    };
    let mut grid: Box<Grid> = bytemuck::zeroed_box();
    for tick in 0..300u64 {
        let pose = Pose2::new(2.0 + tick as f64 * 0.01, 3.0, tick as f64 * 0.02);
        let n = allocations_during(|| {
            frontier.integrate_footprint(pose, 0.2);
            frontier.integrate_scan(pose, &scan);
            let touched = contact.integrate_tactile(pose, &tactile, 0.5);
            for &(x, y) in touched {
                frontier.mark_occupied(x, y);
            }
            frontier.write(&mut grid);
            contact.write(&mut grid);
        });
        assert_eq!(n, 0, "tick {tick}: {n} allocations");
    }
}
