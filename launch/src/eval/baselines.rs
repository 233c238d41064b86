//! The stored baselines (`eval/baselines/`, `mole eval --baselines DIR`): which suites they are
//! (every planner on every family, every estimator on the estimator families), where each
//! report lives, and the README's tables drawn from them.

use super::{EvalReport, Task};
use mole_types::{EstimatorKind, PlannerKind};
use mole_world::{Family, WorldSpec};
use std::ops::Range;
use std::path::Path;

/// Where the stored reports live, from the workspace's root.
pub const DIR: &str = "eval/baselines";
/// The families every estimator runs on: an office floor with its fix and lidar, and in the
/// dark (odometry and beacons only), where the estimator alone keeps the pose.
pub const ESTIMATOR_FAMILIES: [&str; 2] = ["rooms", "rooms-dark"];
/// An estimator suite's planner and length: the random walk covers the floor, 60 s a run.
pub const ESTIMATOR_PLANNER: PlannerKind = PlannerKind::RandomWalk;
pub const ESTIMATOR_TICKS: u64 = 6_000;

/// One stored suite: what runs, and the file its report goes to.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Suite {
    /// `maze`, `maze-dark`, …
    pub family: String,
    pub planner: PlannerKind,
    /// `None`: the launch file's.
    pub estimator: Option<EstimatorKind>,
    pub task: Task,
    /// `None`: the task's limit (`mole eval`'s default).
    pub ticks: Option<u64>,
}

impl Suite {
    /// The report's path under the baselines directory: `FAMILY/PLANNER-TASK.json` or
    /// `FAMILY/estimator-NAME.json`.
    pub fn file(&self) -> String {
        match self.estimator {
            Some(e) => format!("{}/estimator-{e}.json", self.family),
            None => format!(
                "{}/{}-{}.json",
                self.family,
                self.planner,
                task_name(self.task)
            ),
        }
    }

    /// The plot this suite is drawn in, beside the others of its family and kind.
    pub fn plot(&self) -> String {
        match self.estimator {
            Some(_) => format!("{}/estimators.png", self.family),
            None => format!("{}/{}.png", self.family, task_name(self.task)),
        }
    }
}

/// A task as `--task` names it.
pub fn task_name(task: Task) -> &'static str {
    match task {
        Task::Navigate => "navigate",
        Task::Explore => "explore",
    }
}

/// Every family, lit then dark, in the docs' order.
pub fn families() -> Vec<String> {
    Family::ALL
        .iter()
        .flat_map(|f| [f.name().to_owned(), format!("{f}-dark")])
        .collect()
}

/// Every stored suite: on each family, each planner at its task (the goal seekers navigate, the
/// explorers explore) and the random walk at both, as the baseline of each; frontier only where
/// there is a lidar; then every estimator on [`ESTIMATOR_FAMILIES`].
pub fn suites() -> Vec<Suite> {
    let mut out = Vec::new();
    for family in families() {
        let dark = WorldSpec::parse(&family).is_ok_and(|s| s.dark);
        for task in [Task::Navigate, Task::Explore] {
            for &planner in PlannerKind::ALL {
                let own = Task::of(None, Some(planner)) == task;
                let baseline = planner == PlannerKind::RandomWalk;
                if !(own || baseline) || (dark && planner.needs_range_sensor()) {
                    continue;
                }
                out.push(Suite {
                    family: family.clone(),
                    planner,
                    estimator: None,
                    task,
                    ticks: None,
                });
            }
        }
    }
    for family in ESTIMATOR_FAMILIES {
        for &estimator in EstimatorKind::ALL {
            out.push(Suite {
                family: family.to_owned(),
                planner: ESTIMATOR_PLANNER,
                estimator: Some(estimator),
                task: Task::Explore,
                ticks: Some(ESTIMATOR_TICKS),
            });
        }
    }
    out
}

/// Every suite's stored report, in [`suites`]' order; a missing or unreadable one is named with
/// the command that makes it.
pub fn read_all(dir: &Path) -> Result<Vec<(Suite, EvalReport)>, String> {
    suites()
        .into_iter()
        .map(|suite| {
            let path = dir.join(suite.file());
            let text = std::fs::read_to_string(&path).map_err(|e| {
                format!(
                    "{}: {e} (scripts/eval-baselines.sh writes every baseline)",
                    path.display()
                )
            })?;
            let report: EvalReport = serde_json::from_str(&text)
                .map_err(|e| format!("{}: not a mole eval report: {e}", path.display()))?;
            Ok((suite, report))
        })
        .collect()
}

/// The README's tables, by the name of the block they fill (`<!-- eval:NAME -->`).
pub fn tables(reports: &[(Suite, EvalReport)]) -> Vec<(&'static str, String)> {
    vec![
        ("navigation", planner_table(reports, Task::Navigate)),
        ("exploration", planner_table(reports, Task::Explore)),
        ("estimators", estimator_table(reports)),
    ]
}

/// A fraction's mean and interval, `0.96 [0.87, 0.99]`.
fn fraction(report: &EvalReport, metric: &str) -> String {
    match report.aggregate.get(metric) {
        Some(a) => format!("{:.2} [{:.2}, {:.2}]", a.mean, a.ci95[0], a.ci95[1]),
        None => "—".into(),
    }
}

/// A mean, with `digits` decimals.
fn mean(report: &EvalReport, metric: &str, digits: usize) -> String {
    match report.aggregate.get(metric) {
        Some(a) => format!("{:.digits$}", a.mean),
        None => "—".into(),
    }
}

/// One row per family, one column per planner at `task`: navigation's success and BARN score,
/// exploration's ended-with-99%-covered fraction and mean coverage.
fn planner_table(reports: &[(Suite, EvalReport)], task: Task) -> String {
    let planners: Vec<PlannerKind> = PlannerKind::ALL
        .iter()
        .copied()
        .filter(|&p| {
            reports
                .iter()
                .any(|(s, _)| s.estimator.is_none() && s.task == task && s.planner == p)
        })
        .collect();
    let worlds = reports
        .iter()
        .filter(|(s, _)| s.estimator.is_none() && s.task == task)
        .map(|(_, r)| r.worlds.len())
        .min()
        .unwrap_or(0);
    let what = match task {
        Task::Navigate => "success [95% interval], BARN score",
        Task::Explore => "explored (ended by itself, ≥ 99% covered) [95% interval], coverage",
    };
    let mut out = format!("{worlds} worlds per cell; {what}.\n\n| family |");
    for p in &planners {
        out += &format!(" {p} |");
    }
    out += "\n| --- |";
    out += &" --- |".repeat(planners.len());
    out += "\n";
    for family in families() {
        out += &format!("| {family} |");
        for &p in &planners {
            let cell = reports
                .iter()
                .find(|(s, _)| {
                    s.family == family && s.estimator.is_none() && s.task == task && s.planner == p
                })
                .map(|(_, r)| match task {
                    Task::Navigate => {
                        format!("{}, {}", fraction(r, "success"), mean(r, "barn_score", 2))
                    }
                    Task::Explore => {
                        format!("{}, {}", fraction(r, "explored"), mean(r, "coverage", 3))
                    }
                })
                .unwrap_or_else(|| "not run".into());
            out += &format!(" {cell} |");
        }
        out += "\n";
    }
    out
}

/// One row per estimator and family: pose RMSE, NEES in its interval, and the landmarks'.
fn estimator_table(reports: &[(Suite, EvalReport)]) -> String {
    let rows: Vec<&(Suite, EvalReport)> = reports
        .iter()
        .filter(|(s, _)| s.estimator.is_some())
        .collect();
    let worlds = rows.iter().map(|(_, r)| r.worlds.len()).min().unwrap_or(0);
    let mut out = format!(
        "{worlds} worlds per row, {ESTIMATOR_PLANNER} for {ESTIMATOR_TICKS} steps; NEES \
         consistent: the fraction of runs whose mean NEES is inside its 95% interval.\n\n\
         | estimator | family | pose RMSE (m) | pose NEES consistent | landmark RMSE (m) | \
         landmark NEES consistent |\n| --- | --- | ---: | --- | ---: | --- |\n"
    );
    for (suite, r) in rows {
        let estimator = suite.estimator.map_or("default".into(), |e| e.to_string());
        out += &format!(
            "| {estimator} | {} | {} | {} | {} | {} |\n",
            suite.family,
            mean(r, "localization_rmse_m", 3),
            fraction(r, "nees_consistent"),
            mean(r, "landmark_rmse_m", 3),
            fraction(r, "landmark_nees_consistent"),
        );
    }
    out
}

/// Where `text`'s `<!-- eval:NAME -->` block holds its table: from the line after the opening
/// marker to the closing `<!-- /eval:NAME -->`.
pub fn block(text: &str, name: &str) -> Option<Range<usize>> {
    let open = format!("<!-- eval:{name} -->\n");
    let start = text.find(&open)? + open.len();
    let end = start + text[start..].find(&format!("<!-- /eval:{name} -->"))?;
    Some(start..end)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every planner on every family it can run on, the random walk as the baseline of both
    /// tasks, frontier never in the dark, every estimator on its families; one file each.
    #[test]
    fn the_suites_cover_every_planner_family_and_estimator() {
        let suites = suites();
        let n_families = Family::ALL.len() * 2;
        let explorers = |dark: bool| if dark { 1 } else { 2 };
        let per_family = |dark| 3 + explorers(dark); // apf, dwa, random walk; + frontier, random walk
        let expected = Family::ALL.len() * (per_family(false) + per_family(true))
            + ESTIMATOR_FAMILIES.len() * EstimatorKind::ALL.len();
        assert_eq!(suites.len(), expected);
        assert_eq!(families().len(), n_families);
        let mut files: Vec<String> = suites.iter().map(Suite::file).collect();
        files.sort();
        files.dedup();
        assert_eq!(files.len(), suites.len(), "two suites share a file");
        assert!(files.contains(&"maze/frontier-explore.json".to_owned()));
        assert!(files.contains(&"maze/random-walk-navigate.json".to_owned()));
        assert!(!files.contains(&"maze-dark/frontier-explore.json".to_owned()));
        assert!(files.contains(&"rooms-dark/estimator-fastslam.json".to_owned()));
    }

    /// A block is found between its markers; one that is missing or not closed is not.
    #[test]
    fn a_block_lies_between_its_markers() {
        let text = "a\n<!-- eval:navigation -->\nold\n<!-- /eval:navigation -->\nb\n";
        assert_eq!(&text[block(text, "navigation").unwrap()], "old\n");
        assert_eq!(block(text, "exploration"), None);
        assert_eq!(block("<!-- eval:navigation -->\nold", "navigation"), None);
    }
}
