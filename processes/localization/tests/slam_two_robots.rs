//! Two robots running EKF-SLAM on the ring of `slam_sim`, each fusing the other's newest landmark
//! map by covariance intersection (`PeerFusion`, as `mole-localization --peer` does), over
//! [`RUNS`] seeded runs: the fused maps are more accurate than either robot's alone, EKF-SLAM
//! alone is consistent, and the fused maps are not over-confident.

mod slam_sim;

use mole_localization::slam::PeerFusion;
use mole_localization::{EkfSlamEstimator, Estimator, Readings};
use mole_types::{Beacons, Landmarks, Odom};
use nalgebra::{Matrix2, Vector2};
use slam_sim::{Step, landmarks, messages, simulate_from, world_map};
use statrs::distribution::{ChiSquared, ContinuousCDF};

/// Monte Carlo runs.
const RUNS: u64 = 50;
/// Steps of the leading robot: one lap of the ring (31.4 s) and a little.
const STEPS: usize = 360;
/// Steps between two fusions.
const FUSE_EVERY: u64 = 20;

/// Landmark errors of one map against the truth: (Σ squared error, Σ NEES, landmarks).
fn landmark_errors(map: &Landmarks) -> (f64, f64, usize) {
    let truth = landmarks();
    map.landmarks()
        .iter()
        .fold((0.0, 0.0, 0), |(se, nees, n), l| {
            let (x, y) = truth[l.id as usize];
            let e = Vector2::new(l.x - x, l.y - y);
            let p = Matrix2::from_row_slice(&l.covariance);
            let p_inv = p
                .try_inverse()
                .expect("a positive definite landmark covariance");
            (se + e.norm_squared(), nees + e.dot(&(p_inv * e)), n + 1)
        })
}

/// Landmark RMSE and mean landmark NEES of each robot at the end, over the runs.
#[derive(Debug, Default)]
struct Score {
    squared_error: [f64; 2],
    landmarks: [usize; 2],
    /// Σ over the runs of the run's mean landmark NEES.
    run_nees: [f64; 2],
    runs: usize,
}

impl Score {
    fn rmse(&self, r: usize) -> f64 {
        (self.squared_error[r] / self.landmarks[r] as f64).sqrt()
    }
    /// The mean over the runs of robot `r`'s mean landmark NEES.
    fn nees(&self, r: usize) -> f64 {
        self.run_nees[r] / self.runs as f64
    }
}

/// The two-sided 95% interval of [`Score::nees`] for a consistent filter: [χ²₂ᵣ(0.025)/R,
/// χ²₂ᵣ(0.975)/R] over R runs. A run's landmark errors are not independent: every landmark
/// carries the robot's drift, so a run's mean NEES spreads between χ²(2n)/n (independent
/// errors, variance 4/n) and χ²(2) (one error shared by all, variance 4); its variance is at
/// most 4 whatever the correlation, and the runs are independent, so the sum over R runs has
/// mean 2R and variance at most 4R, as χ²(2R) has (measured: a run's mean NEES has a standard
/// deviation of 1.5–1.8 against the 2 of one shared error and the 0.67 of nine independent
/// ones). The interval of n·R independent errors, the one the summary reports for one run, is
/// too narrow for this statistic.
fn nees_interval(runs: usize) -> (f64, f64) {
    let chi2 = ChiSquared::new(2.0 * runs as f64).expect("positive dof");
    (
        chi2.inverse_cdf(0.025) / runs as f64,
        chi2.inverse_cdf(0.975) / runs as f64,
    )
}

/// Robot A drives the ring from the start; robot B from the same start `delay` steps later (two
/// stacks started apart: A has mapped what lies ahead of B). With `fuse`, every
/// [`FUSE_EVERY`] steps each fuses the other's newest map.
fn two_robots(delay: usize, fuse: bool) -> Score {
    let mut score = Score::default();
    let (mut odom, mut beacons): (Odom, Box<Beacons>) =
        (bytemuck::Zeroable::zeroed(), bytemuck::zeroed_box());
    let mut maps: [Box<Landmarks>; 2] = [bytemuck::zeroed_box(), bytemuck::zeroed_box()];
    for seed in 0..RUNS {
        let mut robots = [0, 1].map(|_| EkfSlamEstimator::from_map(&world_map(seed, &landmarks())));
        let mut fusions = [0, 1].map(|_| PeerFusion::new(FUSE_EVERY));
        let drives: [Vec<Step>; 2] =
            [0, 1].map(|r| simulate_from(STEPS - r * delay, 2 * seed + r as u64, (0.0, 0.0, 0.0)));
        for k in 0..STEPS {
            for r in 0..2 {
                let Some(step) = k.checked_sub(r * delay).map(|k| &drives[r][k]) else {
                    continue;
                };
                messages(step, None, &mut odom, &mut beacons);
                robots[r].step(&Readings::of(&odom).with_beacons(Some(&beacons)));
                robots[r].write_landmarks(&mut maps[r]);
                maps[r].header.stamp_ns = k as u64 + 1;
            }
            for r in 0..2 {
                if fuse && k >= r * delay {
                    let (ours, theirs) = (&mut robots[r], &maps[1 - r]);
                    fusions[r].step(
                        k as u64,
                        Some(&**theirs).filter(|m| m.n_landmarks > 0),
                        ours,
                    );
                }
            }
        }
        for (r, map) in maps.iter().enumerate() {
            let (se, nees, n) = landmark_errors(map);
            score.squared_error[r] += se;
            score.landmarks[r] += n;
            score.run_nees[r] += nees / n as f64;
        }
        score.runs += 1;
    }
    score
}

/// Robot B a fifth of a lap behind A (60 steps, 6 s), so A's map holds landmarks B has not
/// seen yet, and both fuse every 2 s:
///
/// (a) each fused robot's landmark RMSE is below both robots' alone;
/// (b) EKF-SLAM alone is consistent: each robot's mean landmark NEES is inside the 95%
///     interval of [`nees_interval`];
/// (c) the fused maps are not over-confident: each fused robot's mean NEES is at most the
///     interval's upper end (CI is consistent whatever the two maps' correlation); and the
///     price of not knowing that correlation shows: it is even below the interval's lower end (under-confident: covariances about twice the squared
///     errors). The same below the lower end when fusing every 0.5 s or every 10 s (A 1.11,
///     1.26; B 0.92, 1.11): it is CI's, not the rounds'.
///
/// Measured (50 runs; interval 1.48–2.59): RMSE A 0.204 → 0.168 m, B 0.221 → 0.162 m; NEES A
/// 2.08 alone → 1.13 fused, B 1.89 → 0.98. Linearised at its estimates (Thrun's Table 10.1)
/// instead of its first estimates, EKF-SLAM alone was over-confident here (A 2.68, above the
/// interval), and so were the fused maps when the fusion added the peer's landmarks it had not
/// mapped as new independent ones (A 3.18, B 2.68).
#[test]
fn two_robots_fusing_by_ci_map_better_than_either_alone_and_are_not_over_confident() {
    let delay = 60;
    let (alone, fused) = (two_robots(delay, false), two_robots(delay, true));
    let (lo, hi) = nees_interval(alone.runs);
    for (r, robot) in ["A", "B"].iter().enumerate() {
        println!(
            "robot {robot}: landmark RMSE {:.4} m fused, {:.4} m alone; mean NEES {:.3} fused, \
             {:.3} alone (95% interval over {} runs {lo:.3}–{hi:.3})",
            fused.rmse(r),
            alone.rmse(r),
            fused.nees(r),
            alone.nees(r),
            alone.runs
        );
    }
    for (r, robot) in ["A", "B"].iter().enumerate() {
        assert_eq!(
            fused.landmarks[r], alone.landmarks[r],
            "robot {robot} mapped"
        );
        let best_alone = alone.rmse(0).min(alone.rmse(1));
        assert!(
            fused.rmse(r) < best_alone,
            "robot {robot} fused: landmark RMSE {} m, not below both alone ({} m, {} m)",
            fused.rmse(r),
            alone.rmse(0),
            alone.rmse(1)
        );
        assert!(
            (lo..=hi).contains(&alone.nees(r)),
            "robot {robot} alone: mean landmark NEES {} outside {lo}–{hi}",
            alone.nees(r)
        );
        assert!(
            fused.nees(r) <= hi,
            "robot {robot} fused: mean landmark NEES {} above {hi}, over-confident (alone {})",
            fused.nees(r),
            alone.nees(r)
        );
        assert!(
            fused.nees(r) < lo,
            "robot {robot} fused: mean landmark NEES {} not below {lo}, CI's conservative \
             (alone {})",
            fused.nees(r),
            alone.nees(r)
        );
    }
}
