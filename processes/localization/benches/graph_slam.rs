//! One GraphSLAM solve (target ≤ 100 ms): 10,001 poses from ten 100 s laps at 10 Hz among 30
//! beacons seen within 6 m (~7 readings a pose, ~70,000 in all), Levenberg–Marquardt from the
//! dead-reckoned odometry chain to convergence, symbolic analysis included. Also the landmark
//! marginal covariances of that graph, which `optimize` does not compute.

#[path = "../tests/graph_slam_support/mod.rs"]
#[allow(
    dead_code,
    reason = "shared with the tests; the bench needs no hand-made odometry or readings"
)]
mod graph_slam_support;

use criterion::{BatchSize, Criterion, criterion_group, criterion_main};
use graph_slam_support::{Drive, default_noise, position_rmse, simulate};
use std::hint::black_box;

/// Ten laps of an 8 m circle at 0.5 m/s among 30 beacons, seen within the default 6 m.
const DRIVE: Drive = Drive {
    radius: 8.0,
    steps_per_lap: 1000,
    laps: 10,
    dt: 0.1,
    beacons: 30,
    range_max: 6.0,
};

/// Iteration budget of the solve; it converges well before.
const MAX_ITERATIONS: usize = 20;

fn bench(c: &mut Criterion) {
    let noise = default_noise();
    let sim = simulate(&DRIVE, &noise, Some(1));
    let mut graph = sim.graph(&noise);
    let chain_rmse = position_rmse(graph.poses(), &sim.truth);
    let solution = graph.optimize(MAX_ITERATIONS).expect("solve");
    println!(
        "graph: {} poses, {} landmarks, {} readings; {:?}; RMSE odometry chain {chain_rmse:.3} m, \
         smoothed {:.4} m",
        solution.poses.len(),
        solution.landmarks.len(),
        sim.reading_count(),
        solution.report,
        position_rmse(solution.poses, &sim.truth),
    );

    let mut group = c.benchmark_group("graph_slam");
    group.sample_size(10);
    group.bench_function("solve_10k_poses_30_landmarks", |b| {
        b.iter_batched(
            || sim.graph(&noise),
            |mut graph| {
                let report = graph.optimize(MAX_ITERATIONS).expect("solve").report;
                black_box(report)
            },
            BatchSize::LargeInput,
        )
    });
    let mut covariances = Vec::new();
    group.bench_function("landmark_covariances_10k_poses", |b| {
        b.iter(|| {
            graph
                .landmark_covariances(&mut covariances)
                .expect("positive definite");
            black_box(covariances.len())
        })
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
