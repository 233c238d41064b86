//! The pose graph's hot paths do not allocate: a counting global allocator (this test binary
//! only) counts this thread's allocations while poses and readings are appended within the
//! reserved capacity, and while a graph whose structure did not change is solved again (the
//! symbolic factorisation and the numeric storage are reused).

#[allow(
    dead_code,
    reason = "shared with the accuracy tests and the bench; this test uses the simulator only"
)]
mod graph_slam_support;

use graph_slam_support::{Drive, default_noise, simulate};
use mole_localization::graph_slam::{GraphCapacity, GraphSlamConfig, PoseGraph};
use mole_runtime::{CountingAllocator, allocations_during};

#[global_allocator]
static ALLOCATOR: CountingAllocator = CountingAllocator;

/// Appending every pose and reading of a lap into a graph with that much capacity reserved
/// allocates nothing; nor does re-solving the unchanged graph, which only the first solve
/// after growth (the symbolic analysis) may do.
#[test]
fn appends_within_capacity_and_resolves_do_not_allocate() {
    let noise = default_noise();
    let drive = Drive {
        radius: 4.0,
        steps_per_lap: 120,
        laps: 1,
        dt: 0.1,
        beacons: 10,
        range_max: 4.0,
    };
    let sim = simulate(&drive, &noise, Some(9));
    let capacity = GraphCapacity {
        poses: sim.truth.len(),
        landmarks: sim.beacons.len(),
        observations: sim.reading_count(),
    };
    let mut graph = PoseGraph::new(sim.start, GraphSlamConfig::new(noise), capacity);

    // A broken counter would pass everything below: it must see this Box first.
    let boxed = allocations_during(|| {
        std::hint::black_box(Box::new(7u64));
    });
    assert!(boxed > 0, "a Box was allocated, the counter saw {boxed}");

    let appends = allocations_during(|| {
        for (k, readings) in sim.readings.iter().enumerate() {
            if k > 0 {
                graph.add_pose(&sim.odometry[k - 1]).unwrap();
            }
            for r in readings {
                graph.add_observation(k, r).unwrap();
            }
        }
    });
    assert_eq!(appends, 0, "appends within capacity allocated");

    let report = graph.optimize(2).unwrap().report;
    assert!(report.reanalysed);
    let mut report = None;
    let during = allocations_during(|| report = Some(graph.optimize(30).unwrap().report));
    let report = report.expect("solved");
    assert!(!report.reanalysed && report.iterations > 0, "{report:?}");
    assert_eq!(
        during, 0,
        "re-solving an unchanged graph allocated: {report:?}"
    );
}
