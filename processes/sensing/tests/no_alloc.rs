//! Steady-state sensing allocates nothing per step.

use mole_runtime::{CountingAllocator, allocations_during};
use mole_sensing::Sensing;
use mole_types::*;

#[global_allocator]
static ALLOCATOR: CountingAllocator = CountingAllocator;

/// Every sensor model's step allocates nothing once running.
#[test]
fn a_sensing_step_does_not_allocate() {
    // A broken counter would pass everything below: it must see this Box first.
    let boxed = allocations_during(|| {
        std::hint::black_box(Box::new([0u8; 64]));
    });
    assert!(boxed >= 1, "a Box was allocated, the counter saw {boxed}");
    let scenario = mole_world::load_scenario(std::path::Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../scenarios/default.toml"
    )))
    .expect("default scenario");
    let mut map: Box<WorldMap> = bytemuck::zeroed_box();
    scenario.write_world_map(&mut map);
    let mut world = mole_world::World::new(&scenario);
    let mut sensing = Sensing::new(&map, 7).expect("sensing");
    let mut truth: Box<Truth> = bytemuck::zeroed_box();
    let mut scan: Box<Scan> = bytemuck::zeroed_box();
    let mut tactile: Box<Tactile> = bytemuck::zeroed_box();
    let mut odom: Box<Odom> = bytemuck::zeroed_box();
    let mut beacons: Box<Beacons> = bytemuck::zeroed_box();
    let mut fix: Box<Fix> = bytemuck::zeroed_box();
    for tick in 0..500u64 {
        world.step(0.4, if tick % 200 < 100 { 0.3 } else { -0.5 });
        world.write_truth(&mut truth);
        truth.header.tick = tick;
        let n = allocations_during(|| {
            sensing.scan(&truth, &mut scan);
            sensing.tactile(&truth, &mut tactile);
            sensing.odom(&truth, &mut odom);
            sensing.beacons(&truth, &mut beacons);
            sensing.fix(&truth, &mut fix);
        });
        assert_eq!(n, 0, "tick {tick}: {n} allocations");
    }
}
