//! A smoother's trajectory (GraphSLAM's `localization/trajectory`) against the truth, beside the
//! filter's own poses (`localization/pose`) at the same ticks, for summary.json's `slam` section
//! and the smoothed path of map.png.
//!
//! The truth and the filter's pose of every tick are kept in a bounded ring of [`TICK_HISTORY`]
//! ticks, more than the smoother's graph spans plus its lag behind the run. When a trajectory
//! arrives it is scored at once: each smoothed pose whose tick still has both the truth and the
//! filter's pose in the ring adds its squared position error, and the filter's pose of that tick
//! adds its own, so the two RMSEs cover exactly the same ticks. A pose whose tick left the ring
//! or lacks either (a dropped message) is not scored; the sample count says how many were.
//!
//! Each is also scored after the rigid motion that brings it closest to the truth is taken out
//! (the absolute trajectory error of Sturm et al. 2012, "A benchmark for the evaluation of RGB-D
//! SLAM systems"): a SLAM estimate's frame is only as good as the start's prior and the
//! odometry before the first landmarks, and a rotation of a few milliradians of the whole
//! estimate, which no later reading can observe, can outweigh everything smoothing corrects.

use crate::slam::SlamSummary;
use mole_types::{MAX_TRAJECTORY_POSES, Trajectory};

/// Ticks of truth and filter pose kept: 5.5 min at 100 Hz, room for a trajectory of
/// [`MAX_TRAJECTORY_POSES`] steps that arrives up to 12,000 steps after its newest pose.
pub const TICK_HISTORY: usize = 32_768;

/// What the ring holds for one tick: the true and the filter's position, when they arrived.
#[derive(Debug, Clone, Copy, Default)]
struct TickRecord {
    tick: u64,
    truth: Option<[f64; 2]>,
    filter: Option<[f64; 2]>,
}

/// The newest trajectory's score.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
struct Score {
    tick: u64,
    samples: u32,
    smoothed_squared: f64,
    filter_squared: f64,
    smoothed_aligned: RigidAlignment,
    filter_aligned: RigidAlignment,
}

/// The sums that give, in closed form, the least squared error of estimated positions against
/// true ones over every rotation and translation of the estimate (Umeyama 1991 without scale, in
/// 2D): with both sets centred, `a = Σ ê·t̂` and `b = Σ ê×t̂`, the best rotation is atan2(b, a)
/// and the error left is `Σ|ê|² + Σ|t̂|² − 2·√(a² + b²)`. Positions are taken relative to the
/// first truth, so the sums stay small on any arena.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(crate) struct RigidAlignment {
    origin: Option<[f64; 2]>,
    n: f64,
    sum_e: [f64; 2],
    sum_t: [f64; 2],
    dot: f64,
    cross: f64,
    squared_e: f64,
    squared_t: f64,
}

impl RigidAlignment {
    /// Adds one estimated position and its truth.
    pub fn add(&mut self, estimate: [f64; 2], truth: [f64; 2]) {
        let o = *self.origin.get_or_insert(truth);
        let e = [estimate[0] - o[0], estimate[1] - o[1]];
        let t = [truth[0] - o[0], truth[1] - o[1]];
        self.n += 1.0;
        for i in 0..2 {
            self.sum_e[i] += e[i];
            self.sum_t[i] += t[i];
        }
        self.dot += e[0] * t[0] + e[1] * t[1];
        self.cross += e[0] * t[1] - e[1] * t[0];
        self.squared_e += e[0] * e[0] + e[1] * e[1];
        self.squared_t += t[0] * t[0] + t[1] * t[1];
    }

    /// √(mean squared error) after the best rigid motion (`None` before two positions).
    pub fn rmse(&self) -> Option<f64> {
        if self.n < 2.0 {
            return None;
        }
        let n = self.n;
        let (me, mt) = (self.sum_e, self.sum_t);
        let a = self.dot - (me[0] * mt[0] + me[1] * mt[1]) / n;
        let b = self.cross - (me[0] * mt[1] - me[1] * mt[0]) / n;
        let see = self.squared_e - (me[0] * me[0] + me[1] * me[1]) / n;
        let stt = self.squared_t - (mt[0] * mt[0] + mt[1] * mt[1]) / n;
        let left = (see + stt - 2.0 * a.hypot(b)).max(0.0);
        Some((left / n).sqrt()).filter(|v| v.is_finite())
    }
}

/// The truth and filter ring, the newest smoothed trajectory and its score.
#[derive(Debug, Clone)]
pub(crate) struct SmoothedTrajectory {
    history: Vec<TickRecord>,
    points: Vec<[f32; 2]>,
    score: Option<Score>,
}

impl SmoothedTrajectory {
    /// An empty ring of [`TICK_HISTORY`] ticks and room for a whole trajectory.
    pub fn new() -> SmoothedTrajectory {
        SmoothedTrajectory {
            history: vec![TickRecord::default(); TICK_HISTORY],
            points: Vec::with_capacity(MAX_TRAJECTORY_POSES),
            score: None,
        }
    }

    /// The ring slot of `tick`, emptied first when it holds an older tick.
    fn slot(&mut self, tick: u64) -> &mut TickRecord {
        let record = &mut self.history[(tick % TICK_HISTORY as u64) as usize];
        if record.tick != tick {
            *record = TickRecord {
                tick,
                ..TickRecord::default()
            };
        }
        record
    }

    /// Keeps the true position of `tick`.
    pub fn on_truth(&mut self, tick: u64, x: f64, y: f64) {
        self.slot(tick).truth = finite(x, y);
    }

    /// Keeps the filter's published position of `tick`.
    pub fn on_filter(&mut self, tick: u64, x: f64, y: f64) {
        self.slot(tick).filter = finite(x, y);
    }

    /// Takes a trajectory as the newest: keeps its points for the picture and scores it, with
    /// the filter, at the ticks the ring has both for (see the module documentation).
    pub fn on_trajectory(&mut self, trajectory: &Trajectory) {
        let mut score = Score {
            tick: trajectory.header.tick,
            ..Score::default()
        };
        self.points.clear();
        for pose in trajectory.poses() {
            self.points.push([pose.x, pose.y]);
            let Some(tick) = trajectory
                .first_tick
                .checked_add(u64::from(pose.tick_offset))
            else {
                continue;
            };
            let record = self.history[(tick % TICK_HISTORY as u64) as usize];
            if record.tick != tick {
                continue;
            }
            let (Some(truth), Some(filter)) = (record.truth, record.filter) else {
                continue;
            };
            let smoothed = [f64::from(pose.x), f64::from(pose.y)];
            let (s, f) = (squared(smoothed, truth), squared(filter, truth));
            if s.is_finite() {
                score.samples += 1;
                score.smoothed_squared += s;
                score.filter_squared += f;
                score.smoothed_aligned.add(smoothed, truth);
                score.filter_aligned.add(filter, truth);
            }
        }
        self.score = Some(score);
    }

    /// Writes the newest trajectory's score into the `slam` section (its fields stay empty
    /// until a trajectory arrived).
    pub fn fill(&self, out: &mut SlamSummary) {
        let Some(score) = self.score else {
            return;
        };
        let rmse = |sum: f64| {
            (score.samples > 0)
                .then(|| (sum / f64::from(score.samples)).sqrt())
                .filter(|v| v.is_finite())
        };
        out.smoothed_tick = Some(score.tick);
        out.smoothed_samples = score.samples;
        out.smoothed_rmse_m = rmse(score.smoothed_squared);
        out.filter_rmse_same_ticks_m = rmse(score.filter_squared);
        out.smoothed_ate_m = score.smoothed_aligned.rmse();
        out.filter_ate_same_ticks_m = score.filter_aligned.rmse();
    }

    /// The newest trajectory's positions, in tick order.
    pub fn points(&self) -> &[[f32; 2]] {
        &self.points
    }
}

/// (x, y) when both are finite.
fn finite(x: f64, y: f64) -> Option<[f64; 2]> {
    (x.is_finite() && y.is_finite()).then_some([x, y])
}

/// Squared distance between two points.
fn squared(a: [f64; 2], b: [f64; 2]) -> f64 {
    (a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)
}

#[cfg(test)]
mod tests {
    use super::RigidAlignment;

    /// A figure of eight on a 7 m arena with a deterministic wobble of a few centimetres.
    fn truth_and_wobble(k: usize) -> ([f64; 2], [f64; 2]) {
        let s = k as f64 * 0.01;
        let truth = [3.5 + 2.0 * s.sin(), 3.5 + 1.5 * (2.0 * s).sin()];
        let wobble = [0.03 * (7.3 * s).sin(), 0.02 * (5.1 * s + 1.0).cos()];
        (truth, wobble)
    }

    /// `estimate` turned by `phi` about the origin and moved by `shift`.
    fn moved(p: [f64; 2], phi: f64, shift: [f64; 2]) -> [f64; 2] {
        let (s, c) = phi.sin_cos();
        [
            c * p[0] - s * p[1] + shift[0],
            s * p[0] + c * p[1] + shift[1],
        ]
    }

    #[test]
    fn a_turned_and_moved_copy_of_the_truth_has_no_error_left() {
        let mut fit = RigidAlignment::default();
        let mut raw = 0.0;
        let n = 700;
        for k in 0..n {
            let (truth, _) = truth_and_wobble(k);
            let estimate = moved(truth, 0.01, [0.05, -0.02]);
            raw += (estimate[0] - truth[0]).powi(2) + (estimate[1] - truth[1]).powi(2);
            fit.add(estimate, truth);
        }
        let raw = (raw / n as f64).sqrt();
        assert!(raw > 0.02, "raw RMSE {raw}");
        let ate = fit.rmse().unwrap();
        assert!(ate < 1e-6, "aligned RMSE {ate}");
    }

    /// The closed form equals the least error found by searching every rotation (with the
    /// best translation for each, which is the difference of the centroids).
    #[test]
    fn the_closed_form_is_the_least_error_over_every_rotation() {
        let n = 500;
        let pairs: Vec<([f64; 2], [f64; 2])> = (0..n)
            .map(|k| {
                let (truth, wobble) = truth_and_wobble(k);
                let e = moved(
                    [truth[0] + wobble[0], truth[1] + wobble[1]],
                    -0.03,
                    [0.2, 0.1],
                );
                (e, truth)
            })
            .collect();
        let mut fit = RigidAlignment::default();
        for &(e, t) in &pairs {
            fit.add(e, t);
        }
        let rmse_at = |phi: f64| {
            let turned: Vec<[f64; 2]> = pairs
                .iter()
                .map(|&(e, _)| moved(e, phi, [0.0; 2]))
                .collect();
            let centroid = |pts: &mut dyn Iterator<Item = [f64; 2]>| {
                let (mut sx, mut sy) = (0.0, 0.0);
                for p in pts {
                    sx += p[0];
                    sy += p[1];
                }
                [sx / n as f64, sy / n as f64]
            };
            let ce = centroid(&mut turned.iter().copied());
            let ct = centroid(&mut pairs.iter().map(|&(_, t)| t));
            let sum: f64 = turned
                .iter()
                .zip(&pairs)
                .map(|(e, &(_, t))| {
                    (e[0] - ce[0] + ct[0] - t[0]).powi(2) + (e[1] - ce[1] + ct[1] - t[1]).powi(2)
                })
                .sum();
            (sum / n as f64).sqrt()
        };
        let best = (-2000..=2000)
            .map(|i| rmse_at(f64::from(i) * 1e-4))
            .fold(f64::INFINITY, f64::min);
        let ate = fit.rmse().unwrap();
        assert!(
            (ate - best).abs() < 1e-6,
            "closed form {ate}, search {best}"
        );
        assert!(ate > 0.01, "the wobble is left: {ate}");
    }

    #[test]
    fn fewer_than_two_positions_have_no_alignment() {
        let mut fit = RigidAlignment::default();
        assert_eq!(fit.rmse(), None);
        fit.add([1.0, 2.0], [1.5, 2.5]);
        assert_eq!(fit.rmse(), None);
        fit.add([2.0, 2.0], [2.5, 2.5]);
        assert!(fit.rmse().unwrap() < 1e-9);
    }
}
