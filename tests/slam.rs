//! The SLAM estimators in the whole stack, lockstep, on the ring corridor of
//! scenarios/slam_loop.toml (24 beacons, 1.5 m beacon range, no position fix): frontier
//! exploration drives round the ring while the estimator builds the beacon map, and the
//! monitor's `slam` section scores that map against the true beacons (and GraphSLAM's smoothed
//! trajectory against the truth). The same ring with the beacon ids hidden is written per test
//! from that file, so the two cannot drift apart.

use mole_integration_tests::*;
use mole_monitor::SlamSummary;
use mole_types::{EndReason, EstimatorKind, PlannerKind};
use std::path::{Path, PathBuf};
use std::time::Duration;

/// Steps allowed: frontier exploration finishes the ring in about 5,100 (seed 1).
const TICKS: &str = "6000";
/// The ring, relative to the workspace.
const RING: &str = "scenarios/slam_loop.toml";

/// A scenario file written for one test, removed when the test ends, passed or failed.
struct ScenarioFile(PathBuf);

impl Drop for ScenarioFile {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.0);
    }
}

/// The ring with `[sensors.beacons] anonymous = true`: every reading hides its beacon id.
fn anonymous_ring(test: &str) -> ScenarioFile {
    let ring = std::fs::read_to_string(workspace().join(RING)).expect("read the ring");
    let section = "[sensors.beacons]\n";
    assert_eq!(
        ring.matches(section).count(),
        1,
        "one beacon section in {RING}"
    );
    let hidden = ring.replace(section, &format!("{section}anonymous = true\n"));
    let path = std::env::temp_dir().join(format!("{}.toml", unique_namespace(test)));
    std::fs::write(&path, hidden).expect("write the anonymous ring");
    ScenarioFile(path)
}

/// Runs `estimator` on `scenario` with frontier exploration, seed 1, and returns the summary.
fn run_on_the_ring(test: &str, estimator: EstimatorKind, scenario: &Path) -> Summary {
    run_on_the_ring_with_seed(test, estimator, scenario, "1")
}

/// [`run_on_the_ring`] at `seed`.
fn run_on_the_ring_with_seed(
    test: &str,
    estimator: EstimatorKind,
    scenario: &Path,
    seed: &str,
) -> Summary {
    let _serial = serial();
    let scenario = scenario.to_str().expect("a UTF-8 scenario path");
    let stack = Stack::start(
        test,
        &[
            "launch/stacks/lockstep.toml",
            "--seed",
            seed,
            "--scenario",
            scenario,
            "--planner",
            PlannerKind::Frontier.name(),
            "--estimator",
            estimator.name(),
            "--ticks",
            TICKS,
        ],
    );
    stack.succeeded(Duration::from_secs(900))
}

/// The run ended by itself (exploration complete or out of steps) and scored a landmark map.
fn finished_with_a_map(s: &Summary) -> &SlamSummary {
    assert!(
        [
            EndReason::ExplorationComplete.name(),
            EndReason::Ticks.name()
        ]
        .contains(&s.exit_reason.as_str()),
        "{s:#?}"
    );
    let slam = s
        .slam
        .as_ref()
        .expect("a slam section for a SLAM estimator");
    assert_eq!(slam.true_beacons, 24, "{slam:#?}");
    assert!(slam.tick.is_some() && slam.landmarks > 0, "{slam:#?}");
    println!("{} steps: {slam:#?}", s.ticks);
    slam
}

/// Highest landmark RMSE accepted on the ring with known ids (m): twice the beacon range noise
/// σ (0.05 m). Room for other seeds and for the noise, while a broken map update (a wrong
/// Jacobian, a bearing of the wrong sign, a landmark never corrected after it was founded, a
/// particle weight left out) puts landmarks decimetres to metres off.
const LANDMARK_RMSE: f64 = 0.10;

/// A known-ids map: every beacon of the ring mapped, each once (no association error), the
/// landmarks within [`LANDMARK_RMSE`].
fn check_known_ids_map(s: &Summary) -> &SlamSummary {
    let slam = finished_with_a_map(s);
    assert_eq!(slam.beacons_mapped, 24, "{slam:#?}");
    assert_eq!(slam.association_errors, 0, "{slam:#?}");
    let rmse = slam.landmark_rmse_m.expect("landmarks matched");
    assert!(rmse < LANDMARK_RMSE, "landmark RMSE {rmse} m\n{slam:#?}");
    slam
}

/// EKF-SLAM maps every beacon of the ring, each once (known ids: no association error), with a
/// landmark RMSE below [`LANDMARK_RMSE`]. Measured at seed 1: 0.024 m over 4,176 steps.
#[test]
fn ekf_slam_maps_the_ring_within_a_decimetre() {
    let s = run_on_the_ring("slam_ekf", EstimatorKind::EkfSlam, Path::new(RING));
    check_known_ids_map(&s);
}

/// FastSLAM maps every beacon of the ring, each once, with a landmark RMSE below
/// [`LANDMARK_RMSE`]. Measured at seed 1: 0.039 m over 4,182 steps.
#[test]
fn fastslam_maps_the_ring_within_a_decimetre() {
    let s = run_on_the_ring("slam_fast", EstimatorKind::FastSlam, Path::new(RING));
    check_known_ids_map(&s);
}

/// Seeds of the smoother's claim: one run's smoothed and filtered errors differ by a few per
/// cent either way, so the claim is on their mean.
const SMOOTHER_SEEDS: [&str; 6] = ["1", "2", "3", "4", "5", "6"];

/// GraphSLAM maps every beacon of the ring, each once, with a landmark RMSE below
/// [`LANDMARK_RMSE`] (measured at seed 1: 0.024 m), and its smoothed trajectory
/// (`localization/trajectory`, most of the run's ticks) is, in shape, as close to the truth as
/// its front-end filter's poses over the same ticks: its absolute trajectory error (the RMSE
/// after the best rigid alignment, `slam.smoothed_ate_m`) is below the filter's on the mean over
/// [`SMOOTHER_SEEDS`], and on no seed more than 5% above it.
///
/// Why the shape and not the raw RMSE: the raw error of both is mostly a rotation of the whole
/// estimate (1–16 mrad here) left by the start's prior and the odometry before the first
/// beacons, which no later reading observes; which of the two it favours is a coin toss per
/// seed (seed 5: raw 0.0103 m smoothed against 0.0082 m, aligned 0.0028 against 0.0029 m).
/// Why only "as close": frontier exploration ends once the lidar has seen the last frontier,
/// and the trajectory scored (up to the smoother's last solve before the end) comes no closer
/// than 1.9–2.2 m to the beacons seen from the start, 1.5 m being their range: no loop closes
/// in it, and with a beacon always in sight the filter's poses are nearly as good as the
/// smoother's. What smoothing gains after a loop closes is measured without IPC
/// (`processes/localization/tests/graph_slam.rs`). Measured (the same on every run: which steps
/// the smoother solves after depends on the step count only), aligned, smoothed/filter (m):
/// 0.0072/0.0072, 0.0065/0.0069, 0.0036/0.0039, 0.0127/0.0122, 0.0028/0.0029, 0.0035/0.0038;
/// mean 0.0060 against 0.0061.
#[test]
fn graph_slam_smooths_the_ring_as_closely_as_its_filter() {
    let (mut smoothed_sum, mut filter_sum) = (0.0, 0.0);
    for seed in SMOOTHER_SEEDS {
        let s = run_on_the_ring_with_seed(
            "slam_graph",
            EstimatorKind::GraphSlam,
            Path::new(RING),
            seed,
        );
        let slam = if seed == "1" {
            check_known_ids_map(&s)
        } else {
            finished_with_a_map(&s)
        };
        assert!(
            u64::from(slam.smoothed_samples) > s.ticks / 2,
            "seed {seed}: a trajectory over most of the {} steps\n{slam:#?}",
            s.ticks
        );
        let smoothed = slam.smoothed_ate_m.expect("a smoothed trajectory scored");
        let filter = slam.filter_ate_same_ticks_m.expect("the filter scored");
        println!(
            "seed {seed}: smoothed ATE {smoothed:.4} m, filter {filter:.4} m (raw RMSE {:?} m, \
             {:?} m)",
            slam.smoothed_rmse_m, slam.filter_rmse_same_ticks_m
        );
        assert!(
            smoothed <= 1.05 * filter,
            "seed {seed}: smoothed ATE {smoothed} m, more than 5% above the filter's {filter} m"
        );
        smoothed_sum += smoothed;
        filter_sum += filter;
    }
    let n = SMOOTHER_SEEDS.len() as f64;
    let (smoothed, filter) = (smoothed_sum / n, filter_sum / n);
    println!("mean over {n} seeds: smoothed ATE {smoothed:.4} m, filter {filter:.4} m");
    assert!(
        smoothed < filter,
        "mean smoothed ATE {smoothed} m ≥ mean filter ATE {filter} m"
    );
}

/// Highest association error rate accepted on the anonymous ring: a quarter of the landmarks
/// duplicates. Measured at seed 1: EKF-SLAM 0 of 24, FastSLAM 1 of 25 (0.04); an
/// association that founds a landmark for every reading it cannot match with certainty, or
/// merges neighbours, goes far beyond.
const ANONYMOUS_ERROR_RATE: f64 = 0.25;
/// Highest landmark RMSE accepted on the anonymous ring (m), the known-ids bound. Measured at
/// seed 1: EKF-SLAM 0.021 m, FastSLAM 0.051 m, duplicates included.
const ANONYMOUS_LANDMARK_RMSE: f64 = LANDMARK_RMSE;

/// An anonymous-ring map: at least 20 of the 24 beacons mapped, the association error rate
/// reported and below [`ANONYMOUS_ERROR_RATE`], the landmarks within
/// [`ANONYMOUS_LANDMARK_RMSE`].
fn check_anonymous_map(s: &Summary) {
    let slam = finished_with_a_map(s);
    assert_eq!(
        slam.anonymous_landmarks, slam.landmarks,
        "ids hidden\n{slam:#?}"
    );
    assert!(slam.beacons_mapped >= 20, "{slam:#?}");
    let rate = slam.association_error_rate.expect("an error rate reported");
    assert!(
        rate < ANONYMOUS_ERROR_RATE,
        "association error rate {rate}\n{slam:#?}"
    );
    let rmse = slam.landmark_rmse_m.expect("landmarks matched");
    assert!(
        rmse < ANONYMOUS_LANDMARK_RMSE,
        "landmark RMSE {rmse} m\n{slam:#?}"
    );
}

/// With the beacon ids hidden, EKF-SLAM associates every reading itself (maximum likelihood
/// behind a χ² gate) and still maps the ring: measured at seed 1, all 24 beacons with no
/// duplicate in 4,183 steps.
#[test]
fn ekf_slam_maps_the_anonymous_ring() {
    let ring = anonymous_ring("slam_ekf_anon");
    check_anonymous_map(&run_on_the_ring(
        "slam_ekf_anon",
        EstimatorKind::EkfSlam,
        &ring.0,
    ));
}

/// With the beacon ids hidden, FastSLAM associates per particle and still maps the ring:
/// measured at seed 1, all 24 beacons with 1 duplicate in 4,174 steps.
#[test]
fn fastslam_maps_the_anonymous_ring() {
    let ring = anonymous_ring("slam_fast_anon");
    check_anonymous_map(&run_on_the_ring(
        "slam_fast_anon",
        EstimatorKind::FastSlam,
        &ring.0,
    ));
}
