//! Sensing's hot kernels: a full lidar scan by ray casting, and the tactile model.

use criterion::{Criterion, criterion_group, criterion_main};
use mole_sensing::{RayCaster, Sensing};
use mole_types::*;
use std::hint::black_box;

fn scenario_map(name: &str) -> Box<WorldMap> {
    let name = name.trim_end_matches(".toml");
    mole_world::bundled_scenario(name)
        .expect("scenario")
        .world_map()
}

fn benches(c: &mut Criterion) {
    for name in ["default.toml", "maze.toml"] {
        let map = scenario_map(name);
        let mut sensing = Sensing::new(&map, 1).expect("sensing");
        let mut truth: Box<Truth> = bytemuck::zeroed_box();
        truth.x = map.start_x;
        truth.y = map.start_y;
        truth.theta = 0.3;
        let mut scan: Box<Scan> = bytemuck::zeroed_box();
        c.bench_function(
            &format!("lidar_scan_{}_beams_{name}", map.sensors.lidar_beams),
            |b| b.iter(|| sensing.scan(black_box(&truth), &mut scan)),
        );
        let caster = RayCaster::from_map(&map).expect("caster");
        c.bench_function(&format!("ray_cast_one_beam_{name}"), |b| {
            b.iter(|| {
                caster.cast(
                    black_box(map.start_x),
                    black_box(map.start_y),
                    black_box(0.7),
                    10.0,
                )
            })
        });
    }
    let map = scenario_map("default.toml");
    let mut sensing = Sensing::new(&map, 1).expect("sensing");
    let mut truth: Box<Truth> = bytemuck::zeroed_box();
    truth.n_contacts = 2;
    truth.contacts[0] = Contact {
        px: 1.2,
        py: 1.0,
        nx: -1.0,
        ny: 0.0,
        depth: 0.004,
    };
    truth.contacts[1] = Contact {
        px: 1.0,
        py: 1.2,
        nx: 0.0,
        ny: -1.0,
        depth: 0.002,
    };
    let mut tactile: Box<Tactile> = bytemuck::zeroed_box();
    c.bench_function("tactile_two_contacts", |b| {
        b.iter(|| sensing.tactile(black_box(&truth), &mut tactile))
    });
}

criterion_group!(sensors, benches);
criterion_main!(sensors);
