//! Mapping's hot kernels: the log-odds update of a scan, the footprint, the contact grid.

use criterion::{Criterion, criterion_group, criterion_main};
use mole_mapping::{ContactGrid, FrontierGrid};
use mole_types::*;
use std::hint::black_box;

fn benches(c: &mut Criterion) {
    let mut frontier = FrontierGrid::new(10.0, 10.0, 0.05).expect("grid");
    let mut scan: Box<Scan> = bytemuck::zeroed_box();
    scan.n_beams = 180;
    scan.angle_min = -std::f32::consts::PI;
    scan.angle_increment = std::f32::consts::TAU / 180.0;
    scan.range_max = 4.0;
    for (i, r) in scan.ranges.iter_mut().take(180).enumerate() {
        *r = 1.5 + (i % 30) as f32 * 0.08;
    }
    let pose = Pose2::new(5.0, 5.0, 0.4);
    c.bench_function("log_odds_scan_180_beams_4m_200x200", |b| {
        b.iter(|| frontier.integrate_scan(black_box(pose), &scan))
    });
    c.bench_function("footprint_r0.2", |b| {
        b.iter(|| frontier.integrate_footprint(black_box(pose), 0.2))
    });
    let mut grid: Box<Grid> = bytemuck::zeroed_box();
    c.bench_function("write_frontier_grid_200x200", |b| {
        b.iter(|| frontier.write(&mut grid))
    });
    let mut contact = ContactGrid::new(10.0, 10.0, 0.05).expect("grid");
    let mut tactile: Box<Tactile> = bytemuck::zeroed_box();
    tactile.n_sensors = 8;
    tactile.radius = 0.2;
    tactile.sensors[0] = TactileReading {
        angle: 0.0,
        fx: -3.0,
        fy: 0.5,
        _pad: 0.0,
    };
    c.bench_function("contact_grid_one_touch", |b| {
        b.iter(|| {
            contact
                .integrate_tactile(black_box(pose), &tactile, 0.5)
                .len()
        })
    });
}

criterion_group!(grids, benches);
criterion_main!(grids);
