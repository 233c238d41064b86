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
