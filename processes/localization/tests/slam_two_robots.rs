//! Two robots running EKF-SLAM on the ring of `slam_sim`, each fusing the other's newest landmark
//! map by covariance intersection (`PeerFusion`, as `mole-localization --peer` does), over
//! [`RUNS`] seeded runs: the fused maps are more accurate than either robot's alone and no more
//! over-confident than EKF-SLAM alone.

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
    nees: [f64; 2],
    landmarks: [usize; 2],
}

impl Score {
    fn rmse(&self, r: usize) -> f64 {
        (self.squared_error[r] / self.landmarks[r] as f64).sqrt()
    }
    fn nees(&self, r: usize) -> f64 {
        self.nees[r] / self.landmarks[r] as f64
    }
    /// The upper end of the 95% χ² interval of robot `r`'s mean landmark NEES (2 dof each),
    /// as if the landmark errors were independent (within a run they are not: all share the
    /// robot's drift, so this interval is narrower than the statistic's true spread).
    fn nees_upper(&self, r: usize) -> f64 {
        let n = self.landmarks[r] as f64;
        let chi2 = ChiSquared::new(2.0 * n).expect("positive dof");
        chi2.inverse_cdf(0.975) / n
    }
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
            score.nees[r] += nees;
            score.landmarks[r] += n;
        }
    }
    score
}

/// Robot B a fifth of a lap behind A (60 steps, 6 s), so A's map holds landmarks B has not
/// seen yet, and both fuse every 2 s: each fused robot's landmark RMSE is below both robots'
/// alone (the "no worse than either alone"), and its mean landmark NEES is no higher
/// than its own alone: fusion by CI adds no over-confidence to EKF-SLAM's. Measured (50 runs):
/// RMSE A 0.246 → 0.215 m, B 0.239 → 0.180 m; NEES A 2.68 → 2.21, B 2.29 → 1.29 (the 95% upper
/// end for independent errors is 2.19: EKF-SLAM alone is already over it on this noisy ring,
/// the over-confidence tests/slam_consistency.rs shows). When the fusion added the peer's
/// landmarks it had not mapped as new independent ones, NEES rose to A 3.18, B 2.68.
#[test]
fn two_robots_fusing_by_ci_map_better_than_either_alone_and_no_more_over_confident() {
    let delay = 60;
    let (alone, fused) = (two_robots(delay, false), two_robots(delay, true));
    for (r, robot) in ["A", "B"].iter().enumerate() {
        println!(
            "robot {robot}: landmark RMSE {:.4} m fused, {:.4} m alone; NEES {:.3} fused, {:.3} \
             alone (95% upper end for independent errors {:.3})",
            fused.rmse(r),
            alone.rmse(r),
            fused.nees(r),
            alone.nees(r),
            fused.nees_upper(r)
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
            fused.nees(r) <= alone.nees(r),
            "robot {robot} fused: landmark NEES {} above its own alone {}",
            fused.nees(r),
            alone.nees(r)
        );
    }
}
