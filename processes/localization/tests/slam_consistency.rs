//! NEES of EKF-SLAM, as the process runs it (through the `Estimator` trait), over 50 seeded runs
//! against the 95% χ² interval (statrs): consistent on a short run and, with its first-estimates
//! Jacobians, on a long one; linearised at its estimates instead (Thrun's Table 10.1), the
//! over-confidence the literature reports for EKF-SLAM.

mod slam_sim;

use mole_localization::slam::{EkfSlam, Linearisation, SlamConfig};
use mole_localization::{EkfSlamEstimator, Estimator, Readings};
use mole_types::{Beacons, Odom, Pose2};
use nalgebra::{Matrix3, Vector3};
use slam_sim::{DT, landmarks, messages, noise, pose_error, simulate, world_map};
use statrs::distribution::{ChiSquared, ContinuousCDF};

/// Monte Carlo runs.
const RUNS: usize = 50;

/// The average pose NEES over `RUNS` seeded runs after each of `steps` steps, the filter
/// linearised as `linearisation` says.
fn average_nees(steps: usize, linearisation: Linearisation) -> Vec<f64> {
    let mut sum = vec![0.0; steps];
    let mut odom: Odom = bytemuck::Zeroable::zeroed();
    let mut beacons: Box<Beacons> = bytemuck::zeroed_box();
    for seed in 0..RUNS as u64 {
        let mut slam = EkfSlamEstimator::from_map(&world_map(seed, &landmarks()));
        slam.filter_mut().linearisation = linearisation;
        for (k, step) in simulate(steps, seed).iter().enumerate() {
            messages(step, None, &mut odom, &mut beacons);
            slam.step(&Readings::of(&odom).with_beacons(Some(&beacons)));
            let e = pose_error(slam.pose(), &step.truth);
            let p = Matrix3::from_row_slice(&slam.covariance());
            let nees = e.dot(&(p.try_inverse().expect("Σₓₓ is invertible") * e));
            sum[k] += nees;
        }
    }
    sum.iter().map(|s| s / RUNS as f64).collect()
}

/// The two-sided 95% interval of the average NEES of `RUNS` runs of a 3-dof state:
/// χ²(3·RUNS) quantiles at 2.5% and 97.5%, divided by RUNS.
fn interval() -> (f64, f64) {
    let chi2 = ChiSquared::new(3.0 * RUNS as f64).expect("positive dof");
    (
        chi2.inverse_cdf(0.025) / RUNS as f64,
        chi2.inverse_cdf(0.975) / RUNS as f64,
    )
}

/// Over a third of a loop (100 steps, 10 s) the average NEES stays inside the 95% interval:
/// at the end, on average, and at 95 of the 100 steps.
#[test]
fn short_run_nees_is_inside_the_95_percent_interval() {
    let (lo, hi) = interval();
    let anees = average_nees(100, Linearisation::FirstEstimates);
    let inside = anees.iter().filter(|a| (lo..=hi).contains(*a)).count();
    let mean = anees.iter().sum::<f64>() / anees.len() as f64;
    let last = anees[anees.len() - 1];
    println!(
        "short run: interval {lo:.3}..{hi:.3}, final {last:.3}, mean {mean:.3}, {inside}/100 inside"
    );
    assert!((lo..=hi).contains(&last), "final average NEES {last:.3}");
    assert!((lo..=hi).contains(&mean), "time-averaged NEES {mean:.3}");
    assert!(inside >= 95, "{inside}/100 steps inside");
}

/// Over 3000 steps (about ten loops), linearised at its estimates as in Thrun's Table 10.1, the
/// filter becomes over-confident, as the literature reports for EKF-SLAM: the Jacobians of
/// successive steps are evaluated at estimates the corrections in between have moved, so the
/// linearised system observes the map frame's heading, which nothing observes, and the filter
/// gains information it does not have (Julier & Uhlmann 2001; Bailey, Nieto, Guivant, Stevens
/// & Nebot 2006; Huang & Dissanayake 2007). With the first-estimates Jacobians the process uses
/// (Huang, Mourikis & Roumeliotis 2008: every Jacobian at the pose's predicted estimate and the
/// landmark's first estimate) it stays consistent. Measured here over the last 500 steps
/// (expected 3, interval 2.36–3.72): 5–6 linearised at the estimates, 2.82 at the first
/// estimates; both inside over the first 300 steps. The test asserts the first estimates'
/// inside the interval over the first 300 and the last 500 steps, and the estimates' above
/// its upper end over the last 500.
#[test]
fn long_run_nees_stays_consistent_with_first_estimates_jacobians_only() {
    let (lo, hi) = interval();
    let mean = |w: &[f64]| w.iter().sum::<f64>() / w.len() as f64;
    let first_estimates = average_nees(3000, Linearisation::FirstEstimates);
    let estimates = average_nees(3000, Linearisation::Estimate);
    let (first, last) = (
        mean(&first_estimates[..300]),
        mean(&first_estimates[2500..]),
    );
    let naive = mean(&estimates[2500..]);
    println!(
        "long run: interval {lo:.3}..{hi:.3}; first estimates: first 300 steps {first:.3}, last \
         500 steps {last:.3}; linearised at the estimates: last 500 steps {naive:.3}"
    );
    assert!((lo..=hi).contains(&first), "first loop: {first:.3}");
    assert!((lo..=hi).contains(&last), "last 500 steps: {last:.3}");
    assert!(
        naive > hi,
        "at the estimates, not over-confident: {naive:.3}"
    );
}

/// Why the first estimates keep the filter consistent, in one number: range-bearing readings of
/// landmarks say nothing about the map frame's heading, so the robot's heading variance can
/// never fall below what it was at the start (odometry only adds to it). Started with a heading
/// variance of 0.01 rad², over 1000 steps and 10 seeds, the first-estimates filter's heading
/// variance stays above 0.01 at every step (measured: lowest 0.0104); linearised at its
/// estimates, it falls below it in every run (lowest 0.0005): information the readings do not
/// carry.
#[test]
fn first_estimates_jacobians_never_learn_the_map_frames_heading() {
    let start_variance = 0.01;
    let lowest = |linearisation: Linearisation| {
        let mut lowest = f64::INFINITY;
        for seed in 0..10 {
            let sigma = Matrix3::from_diagonal(&Vector3::new(1e-4, 1e-4, start_variance));
            let mut slam = EkfSlam::new(Pose2::default(), sigma, noise(), 9, SlamConfig::default());
            slam.linearisation = linearisation;
            for step in simulate(1000, seed) {
                slam.predict(step.v, step.omega, DT)
                    .expect("a plausible control");
                slam.correct(&step.readings);
                lowest = lowest.min(slam.pose_covariance()[(2, 2)]);
            }
        }
        lowest
    };
    let (first, estimates) = (
        lowest(Linearisation::FirstEstimates),
        lowest(Linearisation::Estimate),
    );
    println!(
        "lowest heading variance (start {start_variance}): first estimates {first:.5}, at the estimates {estimates:.5}"
    );
    assert!(first >= start_variance, "first estimates: {first}");
    assert!(estimates < start_variance, "at the estimates: {estimates}");
}
