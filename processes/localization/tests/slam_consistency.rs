//! NEES of EKF-SLAM, as the process runs it (through the `Estimator` trait), over 50 seeded runs
//! against the 95% χ² interval (statrs): consistent on a short run; on a long run the
//! over-confidence the literature reports for EKF-SLAM.

mod slam_sim;

use mole_localization::{EkfSlamEstimator, Estimator, Readings};
use mole_types::{Beacons, Odom};
use nalgebra::Matrix3;
use slam_sim::{landmarks, messages, pose_error, simulate, world_map};
use statrs::distribution::{ChiSquared, ContinuousCDF};

/// Monte Carlo runs.
const RUNS: usize = 50;

/// The average pose NEES over `RUNS` seeded runs after each of `steps` steps.
fn average_nees(steps: usize) -> Vec<f64> {
    let mut sum = vec![0.0; steps];
    let mut odom: Odom = bytemuck::Zeroable::zeroed();
    let mut beacons: Box<Beacons> = bytemuck::zeroed_box();
    for seed in 0..RUNS as u64 {
        let mut slam = EkfSlamEstimator::from_map(&world_map(seed, &landmarks()));
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
    let anees = average_nees(100);
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

/// Over 3000 steps (about ten loops) the filter becomes over-confident, as the literature
/// reports for EKF-SLAM: the heading is linearised at its estimate, so the Jacobians of every
/// later step are evaluated at the wrong heading and the filter gains information it does not
/// have along the unobservable heading direction (Julier & Uhlmann 2001; Bailey, Nieto,
/// Guivant, Stevens & Nebot 2006; Huang & Dissanayake 2007). Measured here: the average NEES
/// stays inside the interval through the first loop, leaves it after about 500 steps and is
/// about 5–6 (expected 3, upper bound 3.72) over the last 500 steps; the test asserts that the
/// last 500 steps average above the upper bound and the first 300 below it.
#[test]
fn long_run_nees_shows_ekf_slam_over_confidence() {
    let (_, hi) = interval();
    let anees = average_nees(3000);
    let mean = |w: &[f64]| w.iter().sum::<f64>() / w.len() as f64;
    let (first, last) = (mean(&anees[..300]), mean(&anees[2500..]));
    println!("long run: upper bound {hi:.3}, first 300 steps {first:.3}, last 500 steps {last:.3}");
    assert!(first < hi, "first loop already over-confident: {first:.3}");
    assert!(last > hi, "last 500 steps not over-confident: {last:.3}");
}
