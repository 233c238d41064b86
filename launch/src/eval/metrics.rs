//! What `mole eval` measures of one world's run, and of a suite of them: per-world metrics read
//! off the run's summary.json, their aggregates with 95% confidence intervals, and the
//! comparison with a stored baseline. Pure: no process is started here.

use mole_monitor::Summary;
use mole_monitor::mean_nees_interval;
use serde::{Deserialize, Serialize};
use statrs::distribution::{ContinuousCDF, StudentsT};
use std::collections::BTreeMap;

/// BARN's time score clips the run time to [2, 8]·T_opt (Perille et al. 2020, §IV).
const BARN_CLIP: (f64, f64) = (2.0, 8.0);

/// What the suite knows of a world before it runs: from its generator and its free space.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct WorldInfo {
    /// The scenario's name, e.g. `maze-0007`.
    pub name: String,
    pub seed: u64,
    /// The shortest path from start to goal on the grid inflated by the robot's radius, at full
    /// speed (s); `null` for a world without a goal.
    pub t_opt_s: Option<f64>,
    /// The run's time limit (s).
    pub time_limit_s: f64,
    /// The same limit in steps (`mole up --ticks`).
    pub ticks_limit: u64,
}

/// One world's outcome. Fields a run cannot have (a navigation time without a goal, landmark
/// errors without SLAM) are `null`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct WorldMetrics {
    pub world: String,
    pub seed: u64,
    /// `mole up`'s exit code; anything but 0 is a failed run (its metrics are `null`).
    pub exit_code: i32,
    /// The steps the run was given (`mole up --ticks`, to repeat it).
    pub ticks_limit: u64,
    /// Goal within tolerance, no contact, within the time limit (worlds with a goal).
    pub success: Option<bool>,
    /// Time to the goal (s), reached or not: the limit when it was not.
    pub time_s: Option<f64>,
    pub path_length_m: Option<f64>,
    /// BARN's score: success × T_opt / clip(T, 2·T_opt, 8·T_opt).
    pub barn_score: Option<f64>,
    /// Fraction of the reachable free area explored at the end.
    pub coverage: Option<f64>,
    /// The planner ended the run itself, having found nothing left to explore.
    pub exploration_ended: Option<bool>,
    /// Ended by itself with at least 99% covered.
    pub explored: Option<bool>,
    /// Steps until 90% / 95% / 99% coverage (`null`: never).
    pub steps_to_90: Option<u64>,
    pub steps_to_95: Option<u64>,
    pub steps_to_99: Option<u64>,
    pub localization_rmse_m: Option<f64>,
    pub mean_nees: Option<f64>,
    /// The run's mean pose NEES inside χ²₃'s two-sided 95% interval, taking the run's mean as
    /// one draw (its samples are correlated in time, so a count of them would give a far too
    /// narrow interval).
    pub nees_consistent: Option<bool>,
    pub landmark_rmse_m: Option<f64>,
    pub landmark_nees: Option<f64>,
    /// The mean landmark NEES inside its 95% interval for the landmarks mapped.
    pub landmark_nees_consistent: Option<bool>,
    pub association_errors: Option<u32>,
    pub contact_events: Option<u64>,
    pub stalls: Option<u32>,
    /// Frontier targets the planner gave up (not approached in time or unreachable).
    #[serde(default)]
    pub give_ups: Option<u32>,
    /// Stretches of 30 s without progress (no new area, no approach to the target).
    pub livelocks: Option<u32>,
    /// The longest stretch without progress (s).
    pub longest_without_progress_s: Option<f64>,
    pub restarts: Option<u32>,
    /// Simulated steps per second of wall time.
    pub steps_per_s: Option<f64>,
}

/// BARN's score of one run (0 for a failure).
pub fn barn_score(success: bool, time_s: f64, t_opt_s: f64) -> f64 {
    if !success || t_opt_s.is_nan() || t_opt_s <= 0.0 {
        return 0.0;
    }
    let t = time_s.clamp(BARN_CLIP.0 * t_opt_s, BARN_CLIP.1 * t_opt_s);
    t_opt_s / t
}

impl WorldMetrics {
    /// A run that did not finish: only who it was and how it ended.
    pub fn failed(info: &WorldInfo, exit_code: i32) -> WorldMetrics {
        WorldMetrics {
            world: info.name.clone(),
            seed: info.seed,
            exit_code,
            ticks_limit: info.ticks_limit,
            ..WorldMetrics::default()
        }
    }

    /// The metrics of a finished run of `info`'s world.
    pub fn of(info: &WorldInfo, summary: &Summary, exit_code: i32) -> WorldMetrics {
        let contact_free = summary.contact_events == 0;
        let (success, time_s, barn) = match info.t_opt_s {
            Some(t_opt) => {
                let time = summary.time_to_goal_s;
                let success = summary.goal_reached
                    && contact_free
                    && time.is_some_and(|t| t <= info.time_limit_s);
                let time_s = time.unwrap_or(info.time_limit_s);
                (
                    Some(success),
                    Some(time_s),
                    Some(barn_score(success, time_s, t_opt)),
                )
            }
            None => (None, None, None),
        };
        // Exploration is judged on runs without a goal to reach; a navigation run's coverage is
        // a by-product.
        let exploring = info.t_opt_s.is_none();
        let step = |key: &str| {
            let step = summary.coverage_steps.get(key).copied().flatten();
            step.filter(|_| exploring)
        };
        let slam = summary.slam.as_ref();
        let ended = summary.exploration_complete;
        WorldMetrics {
            world: info.name.clone(),
            seed: info.seed,
            exit_code,
            ticks_limit: info.ticks_limit,
            success,
            time_s,
            path_length_m: Some(summary.path_length_m),
            barn_score: barn,
            coverage: exploring.then_some(summary.coverage),
            exploration_ended: exploring.then_some(ended),
            explored: exploring.then_some(ended && summary.coverage >= 0.99),
            steps_to_90: step("0.9"),
            steps_to_95: step("0.95"),
            steps_to_99: step("0.99"),
            localization_rmse_m: summary.localization_rmse_m,
            mean_nees: summary.mean_nees,
            nees_consistent: summary.mean_nees.and_then(|nees| {
                mean_nees_interval(3, 1).map(|[lo, hi]| (lo..=hi).contains(&nees))
            }),
            landmark_rmse_m: slam.and_then(|s| s.landmark_rmse_m),
            landmark_nees: slam.and_then(|s| s.landmark_nees),
            landmark_nees_consistent: slam.and_then(|s| {
                let (nees, [lo, hi]) = (s.landmark_nees?, s.landmark_nees_interval?);
                Some((lo..=hi).contains(&nees))
            }),
            association_errors: slam.map(|s| s.association_errors),
            contact_events: Some(summary.contact_events),
            stalls: Some(summary.stalls),
            give_ups: Some(summary.give_ups),
            livelocks: Some(summary.livelocks),
            longest_without_progress_s: Some(summary.longest_without_progress_s),
            restarts: Some(summary.restarts.values().sum()),
            steps_per_s: (summary.wall_time_s > 0.0)
                .then(|| summary.ticks as f64 / summary.wall_time_s),
        }
    }

    /// Every metric as a number, by name, for the aggregates: a yes/no as 0 or 1 (a fraction).
    pub(crate) fn values(&self) -> Vec<(&'static str, Option<f64>, Kind)> {
        use Kind::{Fraction, Mean};
        let b = |v: Option<bool>| v.map(|x| if x { 1.0 } else { 0.0 });
        let u = |v: Option<u64>| v.map(|x| x as f64);
        let w = |v: Option<u32>| v.map(f64::from);
        vec![
            ("finished", b(Some(self.exit_code == 0)), Fraction),
            ("success", b(self.success), Fraction),
            ("time_s", self.time_s, Mean),
            ("path_length_m", self.path_length_m, Mean),
            ("barn_score", self.barn_score, Mean),
            ("coverage", self.coverage, Mean),
            ("exploration_ended", b(self.exploration_ended), Fraction),
            ("explored", b(self.explored), Fraction),
            ("steps_to_90", u(self.steps_to_90), Mean),
            ("steps_to_95", u(self.steps_to_95), Mean),
            ("steps_to_99", u(self.steps_to_99), Mean),
            ("localization_rmse_m", self.localization_rmse_m, Mean),
            ("mean_nees", self.mean_nees, Mean),
            ("nees_consistent", b(self.nees_consistent), Fraction),
            ("landmark_rmse_m", self.landmark_rmse_m, Mean),
            ("landmark_nees", self.landmark_nees, Mean),
            (
                "landmark_nees_consistent",
                b(self.landmark_nees_consistent),
                Fraction,
            ),
            ("association_errors", w(self.association_errors), Mean),
            ("contact_events", u(self.contact_events), Mean),
            ("stalls", w(self.stalls), Mean),
            ("give_ups", w(self.give_ups), Mean),
            ("livelocks", w(self.livelocks), Mean),
            (
                "longest_without_progress_s",
                self.longest_without_progress_s,
                Mean,
            ),
            ("restarts", w(self.restarts), Mean),
            ("steps_per_s", self.steps_per_s, Mean),
        ]
    }
}

/// What a metric's values are, which decides its interval.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// A yes/no per world: the interval is Wilson's, of a proportion.
    Fraction,
    /// A quantity per world: the interval is Student's t, of a mean.
    Mean,
}

/// Which way a metric is better, for `--check`; `None`: it is reported, not judged.
pub fn better(metric: &str) -> Option<Direction> {
    use Direction::{Higher, Lower};
    match metric {
        "finished"
        | "success"
        | "barn_score"
        | "coverage"
        | "exploration_ended"
        | "explored"
        | "nees_consistent"
        | "landmark_nees_consistent" => Some(Higher),
        "time_s"
        | "steps_to_90"
        | "steps_to_95"
        | "steps_to_99"
        | "localization_rmse_m"
        | "landmark_rmse_m"
        | "association_errors"
        | "contact_events"
        | "stalls"
        | "restarts" => Some(Lower),
        // Path length, NEES (better is closer to its expected value, not lower) and speed (the
        // machine's, not the algorithm's) are context.
        _ => None,
    }
}

/// Which way a metric improves.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Direction {
    Higher,
    Lower,
}

/// One metric over the suite's worlds.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Aggregate {
    /// Worlds with a value.
    pub n: usize,
    pub mean: f64,
    /// The 95% confidence interval of the mean: Wilson's for a fraction (0/1 values), Student's
    /// t otherwise (cut at 0: every metric is ≥ 0).
    pub ci95: [f64; 2],
    pub median: f64,
    pub min: f64,
    pub max: f64,
}

impl Aggregate {
    /// The aggregate of `values` (`None` when there are none).
    pub fn of(values: &[f64], kind: Kind) -> Option<Aggregate> {
        let n = values.len();
        if n == 0 {
            return None;
        }
        let mut sorted = values.to_vec();
        sorted.sort_by(f64::total_cmp);
        let mean = values.iter().sum::<f64>() / n as f64;
        let median = if n % 2 == 1 {
            sorted[n / 2]
        } else {
            0.5 * (sorted[n / 2 - 1] + sorted[n / 2])
        };
        let ci95 = match kind {
            Kind::Fraction => wilson_interval(mean, n),
            Kind::Mean => student_interval(values, mean),
        };
        Some(Aggregate {
            n,
            mean,
            ci95,
            median,
            min: sorted[0],
            max: sorted[n - 1],
        })
    }
}

/// Wilson's score interval of a proportion `p` of `n` trials at 95% (z = 1.96).
pub fn wilson_interval(p: f64, n: usize) -> [f64; 2] {
    let (n, z) = (n as f64, 1.959_963_984_540_054);
    let denom = 1.0 + z * z / n;
    let centre = (p + z * z / (2.0 * n)) / denom;
    let half = z * (p * (1.0 - p) / n + z * z / (4.0 * n * n)).sqrt() / denom;
    // At p = 0 (p = 1) centre and half are equal in exact arithmetic; rounding left 7e-18.
    let lo = if p <= 0.0 {
        0.0
    } else {
        (centre - half).max(0.0)
    };
    let hi = if p >= 1.0 {
        1.0
    } else {
        (centre + half).min(1.0)
    };
    [lo, hi]
}

/// The 95% interval of the mean from Student's t with n − 1 degrees of freedom (the mean itself
/// for one value).
fn student_interval(values: &[f64], mean: f64) -> [f64; 2] {
    let n = values.len();
    if n < 2 {
        return [mean, mean];
    }
    let var = values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1) as f64;
    let t = StudentsT::new(0.0, 1.0, (n - 1) as f64)
        .map(|d| d.inverse_cdf(0.975))
        .unwrap_or(1.96);
    let half = t * (var / n as f64).sqrt();
    // Every metric measured is ≥ 0 (times, lengths, errors, counts), so is its mean.
    [(mean - half).max(0.0), mean + half]
}

/// Every metric's aggregate over `worlds`, by name (metrics no world has are left out).
pub fn aggregate(worlds: &[WorldMetrics]) -> BTreeMap<String, Aggregate> {
    let mut columns: BTreeMap<&'static str, (Kind, Vec<f64>)> = BTreeMap::new();
    for world in worlds {
        for (name, value, kind) in world.values() {
            let column = &mut columns.entry(name).or_insert((kind, Vec::new())).1;
            if let Some(v) = value.filter(|v| v.is_finite()) {
                column.push(v);
            }
        }
    }
    columns
        .into_iter()
        .filter_map(|(name, (kind, values))| {
            Aggregate::of(&values, kind).map(|a| (name.to_owned(), a))
        })
        .collect()
}

/// A metric that got worse than the baseline: its mean left the baseline's interval on the bad
/// side.
#[derive(Debug, Clone, PartialEq)]
pub struct Regression {
    pub metric: String,
    pub baseline: Aggregate,
    pub now: Aggregate,
}

impl std::fmt::Display for Regression {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let [lo, hi] = self.baseline.ci95;
        write!(
            f,
            "{}: {:.4} now, the baseline's 95% interval is [{lo:.4}, {hi:.4}] (mean {:.4})",
            self.metric, self.now.mean, self.baseline.mean
        )
    }
}

/// The metrics of `now` that are worse than `baseline`'s beyond its interval, and the judged
/// metrics the baseline has that `now` lacks (a metric that vanished is a regression too).
pub fn regressions(
    baseline: &BTreeMap<String, Aggregate>,
    now: &BTreeMap<String, Aggregate>,
) -> Vec<Result<Regression, String>> {
    let mut out = Vec::new();
    for (metric, base) in baseline {
        let Some(direction) = better(metric) else {
            continue;
        };
        let Some(current) = now.get(metric) else {
            out.push(Err(format!(
                "{metric}: the baseline has it, this run has no value"
            )));
            continue;
        };
        // A mean equal to the bound but for rounding (reports stored before the Wilson bounds
        // were exact hold 7e-18 for 0) is not worse.
        let slack = |bound: f64| 1e-12 * bound.abs().max(1.0);
        let worse = match direction {
            Direction::Higher => current.mean < base.ci95[0] - slack(base.ci95[0]),
            Direction::Lower => current.mean > base.ci95[1] + slack(base.ci95[1]),
        };
        if worse {
            out.push(Ok(Regression {
                metric: metric.clone(),
                baseline: base.clone(),
                now: current.clone(),
            }));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn summary() -> Summary {
        Summary {
            ticks: 1000,
            wall_time_s: 2.0,
            goal_reached: true,
            time_to_goal_s: Some(12.0),
            path_length_m: 5.0,
            coverage: 0.995,
            exploration_complete: true,
            ..Summary::default()
        }
    }

    fn info(t_opt: Option<f64>) -> WorldInfo {
        WorldInfo {
            name: "maze-0001".into(),
            seed: 1,
            t_opt_s: t_opt,
            time_limit_s: 60.0,
            ticks_limit: 6000,
        }
    }

    /// BARN's score: T_opt / clip(T, 2 T_opt, 8 T_opt), 0 on failure.
    #[test]
    fn barn_score_clips_the_time_to_two_and_eight_optimal_times() {
        assert_eq!(barn_score(true, 1.0, 5.0), 0.5);
        assert_eq!(barn_score(true, 20.0, 5.0), 0.25);
        assert_eq!(barn_score(true, 100.0, 5.0), 0.125);
        assert_eq!(barn_score(false, 20.0, 5.0), 0.0);
    }

    /// Success needs the goal, no contact and the time limit; without a goal there is none.
    #[test]
    fn success_needs_the_goal_no_contact_and_the_time_limit() {
        let m = WorldMetrics::of(&info(Some(5.0)), &summary(), 0);
        assert_eq!(m.success, Some(true));
        assert_eq!(m.barn_score, Some(5.0 / 12.0));
        assert_eq!(m.steps_per_s, Some(500.0));
        let touched = Summary {
            contact_events: 1,
            ..summary()
        };
        assert_eq!(
            WorldMetrics::of(&info(Some(5.0)), &touched, 0).success,
            Some(false)
        );
        let late = Summary {
            time_to_goal_s: Some(61.0),
            ..summary()
        };
        let m = WorldMetrics::of(&info(Some(5.0)), &late, 0);
        assert_eq!((m.success, m.barn_score), (Some(false), Some(0.0)));
        let never = Summary {
            goal_reached: false,
            time_to_goal_s: None,
            ..summary()
        };
        let m = WorldMetrics::of(&info(Some(5.0)), &never, 0);
        assert_eq!((m.success, m.time_s), (Some(false), Some(60.0)));
        let m = WorldMetrics::of(&info(None), &summary(), 0);
        assert_eq!((m.success, m.barn_score), (None, None));
        assert_eq!(m.explored, Some(true));
    }

    /// Wilson's interval matches the textbook value (Newcombe 1998: 81 of 263 → [0.2553,
    /// 0.3662]) and stays inside [0, 1] at 0 and 1.
    #[test]
    fn wilson_interval_matches_the_textbook_and_stays_in_range() {
        let [lo, hi] = wilson_interval(81.0 / 263.0, 263);
        assert!(
            (lo - 0.2553).abs() < 5e-4 && (hi - 0.3662).abs() < 5e-4,
            "{lo} {hi}"
        );
        assert!((wilson_interval(1.0, 10)[1] - 1.0).abs() < 1e-12);
        assert!(wilson_interval(1.0, 10)[0] > 0.69 && wilson_interval(1.0, 10)[0] < 0.73);
        for n in [10, 50, 263] {
            assert_eq!(wilson_interval(0.0, n)[0], 0.0, "{n}");
            assert_eq!(wilson_interval(1.0, n)[1], 1.0, "{n}");
        }
    }

    /// Student's interval of 1..=5: mean 3, s = 1.5811, t(4) = 2.7764 → 3 ± 1.9632.
    #[test]
    fn the_interval_of_a_mean_is_students() {
        let a = Aggregate::of(&[1.0, 2.0, 3.0, 4.0, 5.0], Kind::Mean).unwrap();
        assert_eq!(
            (a.n, a.mean, a.median, a.min, a.max),
            (5, 3.0, 3.0, 1.0, 5.0)
        );
        assert!((a.ci95[0] - 1.0368).abs() < 1e-3, "{:?}", a.ci95);
        assert!((a.ci95[1] - 4.9632).abs() < 1e-3, "{:?}", a.ci95);
        assert_eq!(Aggregate::of(&[], Kind::Mean), None);
        // Counts that happen to be all 0 are still a mean: its interval is the point 0.
        let zeros = Aggregate::of(&[0.0, 0.0, 0.0], Kind::Mean).unwrap();
        assert_eq!(zeros.ci95, [0.0, 0.0]);
        // A mean of values ≥ 0 has no interval below 0 (two livelocks in ten runs).
        let rare = Aggregate::of(
            &[0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 1.0],
            Kind::Mean,
        );
        assert_eq!(rare.unwrap().ci95[0], 0.0);
    }

    /// A metric worse than the baseline's interval is named, one inside it or better is not, and
    /// context metrics are never judged.
    #[test]
    fn regressions_name_each_metric_that_got_worse() {
        let worlds = |success: [bool; 4], rmse: f64, length: f64| {
            success
                .iter()
                .map(|&s| WorldMetrics {
                    success: Some(s),
                    localization_rmse_m: Some(rmse),
                    path_length_m: Some(length),
                    ..WorldMetrics::default()
                })
                .collect::<Vec<_>>()
        };
        let mut base_worlds = worlds([true; 4], 0.02, 5.0);
        base_worlds[0].localization_rmse_m = Some(0.03);
        let base = aggregate(&base_worlds);
        assert!(regressions(&base, &base).is_empty());
        // A rate of 0 against a stored interval whose lower bound rounding left at 7e-18.
        let mut stored = aggregate(&worlds([false; 4], 0.02, 5.0));
        if let Some(success) = stored.get_mut("success") {
            success.ci95[0] = 6.938_893_903_907_228e-18;
        }
        let zero = aggregate(&worlds([false; 4], 0.02, 5.0));
        assert!(regressions(&stored, &zero).is_empty());
        let mut now = worlds([true, false, false, false], 0.05, 50.0);
        now[0].localization_rmse_m = Some(0.06);
        let found: Vec<String> = regressions(&base, &aggregate(&now))
            .into_iter()
            .map(|r| r.map_or_else(|e| e, |r| r.metric))
            .collect();
        assert_eq!(found, ["localization_rmse_m", "success"]);
        let better = worlds([true; 4], 0.01, 5.0);
        assert!(regressions(&base, &aggregate(&better)).is_empty());
        let mut gone = aggregate(&base_worlds);
        gone.remove("success");
        let found = regressions(&base, &gone);
        assert_eq!(
            found,
            [Err(
                "success: the baseline has it, this run has no value".to_owned()
            )]
        );
    }
}
