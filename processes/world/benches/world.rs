//! The world's hot path: one step (limits, sub-stepped arc, contact resolution) in an open
//! scenario, in the cluttered one, and through a maze of 1024 squares.

use criterion::{Criterion, criterion_group, criterion_main};
use mole_world::{World, parse_scenario};
use std::hint::black_box;
use std::path::Path;

/// 32 × 32 blocks of 0.1 m on a 0.5 m lattice: 1024 squares, lanes as wide as the robot.
fn lattice_maze() -> String {
    let mut text = String::from(
        "[robot]\nradius = 0.2\nmax_speed = 0.5\nmax_omega = 2.0\nmax_accel = 1000.0\nmax_alpha = 1000.0\n\
         [arena]\nwidth = 16.25\nheight = 16.25\n[start]\nx = 0.25\ny = 0.25\n",
    );
    for i in 0..32 {
        for j in 0..32 {
            let (x, y) = (0.75 + 0.5 * i as f64, 0.75 + 0.5 * j as f64);
            text.push_str(&format!("[[obstacles]]\nx = {x}\ny = {y}\nside = 0.1\n"));
        }
    }
    text
}

/// Steps `world` with the weaving command of the world's tests, one step per iteration.
fn bench_steps(c: &mut Criterion, name: &str, mut world: World) {
    let mut k = 0u32;
    c.bench_function(name, |b| {
        b.iter(|| {
            world.step(black_box(0.5), if k % 300 < 150 { 0.4 } else { -0.5 });
            k = k.wrapping_add(1);
            world.penetration()
        })
    });
}

fn benches(c: &mut Criterion) {
    for name in ["open", "cluttered"] {
        let s = mole_world::bundled_scenario(name).unwrap_or_else(|e| panic!("{e}"));
        bench_steps(c, &format!("step_{name}"), World::new(&s));
    }
    let maze = parse_scenario(&lattice_maze(), Path::new("lattice.toml"))
        .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(maze.obstacles.len(), 1024);
    bench_steps(c, "step_1024_square_lattice", World::new(&maze));
}

criterion_group!(world, benches);
criterion_main!(world);
