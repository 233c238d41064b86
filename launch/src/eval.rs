//! `mole eval`: one planner and estimator over a family of generated worlds, each run in
//! lockstep by its own `mole up` (parallel jobs, one namespace each); per-world metrics and their
//! aggregates with 95% confidence intervals, as a table and as JSON, and `--check` against a
//! stored baseline.
//!
//! The worlds are ordinary scenario files (`OUT/worlds/NAME.toml`), so any run can be repeated
//! by hand with `mole up --mode lockstep --scenario OUT/worlds/NAME.toml --seed SEED`.

pub mod baselines;
pub mod check;
pub mod metrics;
pub mod plot;

use crate::Failure;
use crate::parse_swap;
use crate::sidecar::build_process_binaries;
use crate::up::{RunEnd, choices};
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use metrics::{Aggregate, WorldInfo, WorldMetrics, aggregate, regressions};
use mole_monitor::read_summary;
use mole_types::{EstimatorKind, PlannerKind, Role};
use mole_world::{FreeSpace, Scenario, WorldSpec, generate, world_toml};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

/// Exploration runs (no goal to reach) end by themselves or after this many steps (300 s at
/// 100 Hz).
pub const EXPLORATION_TICKS: u64 = 30_000;
/// A navigation run's limit is this many optimal times (BARN's upper clip, beyond which a run
/// scores as slow as it can) plus [`NAVIGATION_SLACK_S`].
const NAVIGATION_LIMIT_T_OPT: f64 = 8.0;
/// Seconds added to a navigation limit, so a short world still leaves time to turn and start.
const NAVIGATION_SLACK_S: f64 = 10.0;

#[derive(Debug, Clone, Args)]
pub struct EvalArgs {
    /// The world family: maze, rooms, clutter, cellular or corridors, each also `-dark` (no
    /// lidar, no fix), e.g. `maze-dark`.
    #[arg(long, required_unless_present = "baselines")]
    pub family: Option<String>,
    /// How many worlds, seeds `--first-seed` onwards.
    #[arg(long, default_value_t = 50)]
    pub worlds: u64,
    /// The first world's seed.
    #[arg(long, default_value_t = 0)]
    pub first_seed: u64,
    /// The planner (default: the launch file's).
    #[arg(long, value_parser = choices(PlannerKind::NAMES, str::parse::<PlannerKind>))]
    pub planner: Option<PlannerKind>,
    /// The estimator (default: the launch file's).
    #[arg(long, value_parser = choices(EstimatorKind::NAMES, str::parse::<EstimatorKind>))]
    pub estimator: Option<EstimatorKind>,
    /// Frontier's local planner, as `mole up --local-planner`.
    #[arg(long, value_name = "dwa|apf")]
    pub local_planner: Option<PlannerKind>,
    /// What the runs are judged on (default: navigate for a planner that drives to a goal, apf
    /// and dwa; explore otherwise). Say it for a planner of your own swapped in with --swap.
    #[arg(long, value_enum)]
    pub task: Option<Task>,
    /// Replace a role's process in every run, as `mole up --swap`.
    #[arg(long = "swap", value_name = "ROLE=COMMAND")]
    pub swaps: Vec<String>,
    /// Set a setting in every run, as `mole up --set ROLE.KEY=VALUE` (docs/settings.md).
    #[arg(long = "set", value_name = "ROLE.KEY=VALUE")]
    pub sets: Vec<String>,
    /// Worlds run at once (default: the machine's cores).
    #[arg(long)]
    pub jobs: Option<usize>,
    /// Steps per run (default: exploration 30,000; navigation 8 optimal times + 10 s).
    #[arg(long)]
    pub ticks: Option<u64>,
    /// Where the worlds, the runs and their logs go.
    #[arg(long, default_value = "runs/eval")]
    pub out: PathBuf,
    /// Write the per-world metrics and the aggregates as JSON.
    #[arg(long, value_name = "FILE")]
    pub json: Option<PathBuf>,
    /// Compare with a stored result (an earlier `--json`): exit 1 naming each metric whose mean
    /// is worse than the baseline's 95% interval.
    #[arg(long, value_name = "BASELINE")]
    pub check: Option<PathBuf>,
    /// Draw the metrics' distributions as a PNG: one panel per metric, this run beside the
    /// `--beside` reports and the `--check` baseline.
    #[arg(long, value_name = "FILE")]
    pub plot: Option<PathBuf>,
    /// A stored report (an earlier `--json`, e.g. another planner on the same family) drawn
    /// beside this run in `--plot`; repeatable.
    #[arg(long, value_name = "REPORT", requires = "plot")]
    pub beside: Vec<PathBuf>,
    /// Run every stored suite (every planner on every family, every estimator on its
    /// families) and write their reports and plots under DIR, as `eval/baselines/` holds them
    /// (`scripts/eval-baselines.sh`); with `--family`, only that family's suites.
    #[arg(
        long,
        value_name = "DIR",
        conflicts_with_all = ["planner", "estimator", "local_planner", "task", "swaps", "sets", "ticks", "json", "check", "plot"]
    )]
    pub baselines: Option<PathBuf>,
    /// With `--baselines`: run nothing, draw the plots again from the stored reports (after
    /// suites were run one by one with `--json`).
    #[arg(long, requires = "baselines")]
    pub redraw: bool,
}

/// What a suite's runs are judged on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Task {
    /// Reach the world's goal: success, time, path length, BARN's score.
    Navigate,
    /// Explore the world: coverage, ending by itself, steps to 90/95/99%.
    Explore,
}

impl Task {
    /// The task asked for, or the one the planner does (the launch file's planner, random
    /// walk, explores).
    pub fn of(task: Option<Task>, planner: Option<PlannerKind>) -> Task {
        match (task, planner) {
            (Some(task), _) => task,
            (None, Some(p)) if p.needs_goal() => Task::Navigate,
            (None, _) => Task::Explore,
        }
    }
}

/// What `--json` writes and `--check` reads.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct EvalReport {
    /// `maze`, `maze-dark`, …
    pub family: String,
    /// The family's parameters, `key = value`.
    pub parameters: String,
    /// The planner and estimator every run used (`default`: the launch file's; `ROLE=COMMAND`:
    /// the command swapped in for it).
    pub planner: String,
    pub estimator: String,
    pub first_seed: u64,
    pub worlds: Vec<WorldMetrics>,
    pub aggregate: BTreeMap<String, Aggregate>,
    /// Wall time of the whole suite (s) and the jobs it ran at once.
    pub wall_time_s: f64,
    pub jobs: usize,
}

/// One generated world, ready to run.
struct Job {
    info: WorldInfo,
    scenario: PathBuf,
}

/// Runs the suite (or, with `--baselines`, every stored suite); exit 1 when a run failed or
/// `--check` found a regression, 2 for bad input.
pub fn eval(args: &EvalArgs) -> Result<(), Failure> {
    if let Some(dir) = &args.baselines {
        return run_baselines(args, dir);
    }
    let family = args.family.as_deref().unwrap_or_default();
    let spec = WorldSpec::parse(family).map_err(Failure::input)?;
    for swap in &args.swaps {
        parse_swap(swap).map_err(|e| Failure::input(e.to_string()))?;
    }
    crate::settings::StackSettings::default()
        .with_sets(&args.sets)
        .map_err(Failure::input)?;
    if args.worlds == 0 {
        return Err(Failure::input("--worlds: expected at least 1"));
    }
    let baseline = args
        .check
        .as_deref()
        .map(|path| read_report("--check", path))
        .transpose()?;
    if let Some(b) = baseline.as_ref().filter(|b| b.family != spec.label()) {
        return Err(Failure::input(format!(
            "--check: the baseline is of `{}`, this suite of `{}`",
            b.family,
            spec.label()
        )));
    }
    let beside = args
        .beside
        .iter()
        .map(|path| read_report("--beside", path))
        .collect::<Result<Vec<_>, _>>()?;
    if beside.len() + 1 + usize::from(baseline.is_some()) > plot::MAX_SUITES {
        return Err(Failure::input(format!(
            "--beside: at most {} suites fit in one plot, with this run and the baseline",
            plot::MAX_SUITES
        )));
    }
    let jobs = args
        .jobs
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()))
        .max(1);
    let navigation = Task::of(args.task, args.planner) == Task::Navigate;
    let mut scenarios = Vec::new();
    for seed in args.first_seed..args.first_seed + args.worlds {
        let scenario = generate(&spec, seed).map_err(|e| Failure::run(e.to_string()))?;
        let refusal = args
            .planner
            .and_then(|p| p.refuses_sensors(&scenario.sensors, &scenario.name));
        if let Some(why) = refusal {
            return Err(Failure::input(why));
        }
        scenarios.push((seed, scenario));
    }
    let worlds_dir = args.out.join("worlds");
    std::fs::create_dir_all(&worlds_dir)
        .map_err(|e| Failure::input(format!("{}: {e}", worlds_dir.display())))?;
    let mut suite = Vec::new();
    for (seed, scenario) in scenarios {
        let path = worlds_dir.join(format!("{}.toml", scenario.name));
        std::fs::write(&path, world_toml(&spec, seed, &scenario))
            .map_err(|e| Failure::run(format!("{}: {e}", path.display())))?;
        suite.push(job(&scenario, path, seed, navigation, args.ticks));
    }
    // Named before the build: under `cargo run -p mole-launch` the workspace build relinks this
    // very binary, and the running one's own path then reads as deleted.
    let mole = std::env::current_exe().unwrap_or_else(|_| PathBuf::from("mole"));
    build_process_binaries(&[])?;
    let started = std::time::Instant::now();
    let (results, interrupted) = run_all(args, &mole, &suite, jobs);
    let report = EvalReport {
        family: spec.label(),
        parameters: spec.describe(),
        planner: role_label(args, Role::Planning, args.planner.map(|p| p.to_string())),
        estimator: role_label(
            args,
            Role::Localization,
            args.estimator.map(|e| e.to_string()),
        ),
        first_seed: args.first_seed,
        aggregate: aggregate(&results),
        worlds: results,
        wall_time_s: started.elapsed().as_secs_f64(),
        jobs,
    };
    print_report(&report);
    if let Some(path) = &args.json {
        let text = serde_json::to_string_pretty(&report).expect("a report serialises");
        std::fs::write(path, text + "\n")
            .map_err(|e| Failure::run(format!("{}: {e}", path.display())))?;
    }
    let mut problems = Vec::new();
    if let Some(path) = &args.plot {
        let baseline = baseline.as_ref().map(|b| EvalReport {
            planner: format!("{} (baseline)", b.planner),
            ..b.clone()
        });
        let suites: Vec<&EvalReport> = std::iter::once(&report)
            .chain(&beside)
            .chain(&baseline)
            .collect();
        if let Err(e) = plot::write_plot(&suites, path) {
            problems.push(e);
        }
    }
    let failed = report.worlds.iter().filter(|w| w.exit_code != 0).count();
    if interrupted {
        problems.push(format!(
            "interrupted: {} of {} worlds ran to their end; the report holds only those",
            report.worlds.len(),
            suite.len()
        ));
    }
    if failed > 0 {
        problems.push(format!(
            "{failed} of {} runs failed (their logs are in {})",
            report.worlds.len(),
            args.out.join("runs").display()
        ));
    }
    if let Some(baseline) = &baseline {
        if check::is_slice(&baseline.worlds, &report.worlds) {
            let found =
                check::world_regressions(&baseline.worlds, &baseline.aggregate, &report.worlds);
            problems.extend(
                found
                    .into_iter()
                    .map(|r| format!("worse than the baseline: {r}")),
            );
        } else {
            for found in regressions(&baseline.aggregate, &report.aggregate) {
                problems.push(match found {
                    Ok(r) => format!("worse than the baseline: {r}"),
                    Err(e) => format!("worse than the baseline: {e}"),
                });
            }
        }
    }
    if problems.is_empty() {
        Ok(())
    } else {
        Err(Failure::run(problems.join("\n")))
    }
}

/// Every stored suite, one after the other, each report to `dir/FILE` and each family's suites
/// drawn side by side; the suites that fail are named at the end and the rest still run.
fn run_baselines(args: &EvalArgs, dir: &Path) -> Result<(), Failure> {
    let suites: Vec<_> = baselines::suites()
        .into_iter()
        .filter(|suite| args.family.as_ref().is_none_or(|f| *f == suite.family))
        .collect();
    if suites.is_empty() {
        return Err(Failure::input(format!(
            "--family {}: no stored suite is of that family",
            args.family.as_deref().unwrap_or_default()
        )));
    }
    let mut problems = Vec::new();
    for (i, suite) in suites.iter().enumerate() {
        if INTERRUPTED.load(Ordering::SeqCst) || args.redraw {
            break;
        }
        let json = dir.join(suite.file());
        if let Some(parent) = json.parent() {
            std::fs::create_dir_all(parent)
                .map_err(|e| Failure::input(format!("{}: {e}", parent.display())))?;
        }
        tracing::info!("suite {} of {}: {}", i + 1, suites.len(), suite.file());
        let one = EvalArgs {
            family: Some(suite.family.clone()),
            planner: Some(suite.planner),
            estimator: suite.estimator,
            task: Some(suite.task),
            ticks: suite.ticks,
            out: args.out.join(suite.file().trim_end_matches(".json")),
            json: Some(json),
            baselines: None,
            ..args.clone()
        };
        if let Err(e) = eval(&one) {
            problems.push(format!("{}: {}", suite.file(), e.message));
        }
    }
    let mut plots: BTreeMap<String, Vec<EvalReport>> = BTreeMap::new();
    for suite in baselines::suites()
        .iter()
        .filter(|s| suites.iter().any(|ran| ran.plot() == s.plot()))
    {
        if let Ok(report) = read_report("--baselines", &dir.join(suite.file())) {
            plots.entry(suite.plot()).or_default().push(report);
        }
    }
    for (file, reports) in &plots {
        let suites: Vec<&EvalReport> = reports.iter().collect();
        if let Err(e) = plot::write_plot(&suites, &dir.join(file)) {
            problems.push(e);
        }
    }
    if INTERRUPTED.load(Ordering::SeqCst) {
        problems.push("interrupted: the suites after it did not run".into());
    }
    if problems.is_empty() {
        Ok(())
    } else {
        Err(Failure::run(problems.join("\n")))
    }
}

/// What played a role in the runs: the command swapped in for it, else the kind chosen, else
/// the launch file's (`default`).
fn role_label(args: &EvalArgs, role: Role, kind: Option<String>) -> String {
    let swapped = args
        .swaps
        .iter()
        .find(|swap| parse_swap(swap).is_ok_and(|(r, _)| r == role.name()));
    match (swapped, kind) {
        (Some(swap), _) => swap.clone(),
        (None, Some(kind)) => kind,
        (None, None) => "default".to_owned(),
    }
}

/// A world's job: its limit and its optimal time, from its free space.
fn job(scenario: &Scenario, path: PathBuf, seed: u64, navigation: bool, ticks: Option<u64>) -> Job {
    let t_opt_s = scenario.goal.as_ref().and_then(|goal| {
        let length = FreeSpace::new(scenario)
            .shortest_path((scenario.start.x, scenario.start.y), (goal.x, goal.y))?;
        Some(length / scenario.robot.max_speed)
    });
    let ticks = ticks.unwrap_or_else(|| match t_opt_s {
        Some(t_opt) if navigation => {
            ((NAVIGATION_LIMIT_T_OPT * t_opt + NAVIGATION_SLACK_S) / scenario.dt).ceil() as u64
        }
        _ => EXPLORATION_TICKS,
    });
    Job {
        info: WorldInfo {
            name: scenario.name.clone(),
            seed,
            t_opt_s: t_opt_s.filter(|_| navigation),
            time_limit_s: ticks as f64 * scenario.dt,
            ticks_limit: ticks,
        },
        scenario: path,
    }
}

/// Set by Ctrl-C: no more worlds (or suites) start.
static INTERRUPTED: AtomicBool = AtomicBool::new(false);

/// Runs every job, `jobs` at a time, with a progress bar. Ctrl-C starts no more and leaves out
/// the runs it cut short; the second value says whether that happened.
fn run_all(args: &EvalArgs, mole: &Path, suite: &[Job], jobs: usize) -> (Vec<WorldMetrics>, bool) {
    let bar = ProgressBar::new(suite.len() as u64).with_style(
        ProgressStyle::with_template(
            "{bar:40} {pos}/{len} worlds {elapsed_precise} eta {eta} {msg}",
        )
        .expect("a valid template"),
    );
    static HANDLER: std::sync::Once = std::sync::Once::new();
    HANDLER.call_once(|| {
        // A second handler cannot be set when the process already has one; Ctrl-C then just
        // reaches the children, which end their runs.
        let _ = ctrlc::set_handler(|| INTERRUPTED.store(true, Ordering::SeqCst));
    });
    let interrupted = &INTERRUPTED;
    let next = AtomicUsize::new(0);
    let results: Mutex<Vec<Option<WorldMetrics>>> = Mutex::new(vec![None; suite.len()]);
    std::thread::scope(|scope| {
        for _ in 0..jobs.min(suite.len()) {
            scope.spawn(|| {
                loop {
                    let i = next.fetch_add(1, Ordering::SeqCst);
                    if i >= suite.len() || interrupted.load(Ordering::SeqCst) {
                        break;
                    }
                    let Some(metrics) = run_one(args, mole, &suite[i], i) else {
                        break;
                    };
                    if metrics.exit_code != 0 {
                        bar.println(format!(
                            "{}: mole up exited with {}",
                            metrics.world, metrics.exit_code
                        ));
                    }
                    results.lock().expect("no job panics")[i] = Some(metrics);
                    bar.inc(1);
                }
            });
        }
    });
    bar.finish_and_clear();
    let results = results.into_inner().expect("no job panics");
    (
        results.into_iter().flatten().collect(),
        interrupted.load(Ordering::SeqCst),
    )
}

/// One world's run by a `mole up` of its own, in a namespace of its own; `None` when Ctrl-C
/// cut it short (its metrics would be those of a part of the run).
fn run_one(args: &EvalArgs, mole: &Path, job: &Job, index: usize) -> Option<WorldMetrics> {
    let out = args.out.join("runs").join(&job.info.name);
    let log_path = args.out.join("runs").join(format!("{}.log", job.info.name));
    let mut command = Command::new(mole);
    command
        .args(["up", "--quiet", "--mode", "lockstep", "--scenario"])
        .arg(&job.scenario)
        .args(["--ticks", &job.info.ticks_limit.to_string()])
        .args(["--seed", &job.info.seed.to_string()])
        .args([
            "--namespace",
            &format!("eval{}-{index}", std::process::id()),
        ])
        .arg("--out")
        .arg(&out);
    if let Some(planner) = args.planner {
        command.args(["--planner", &planner.to_string()]);
    }
    if let Some(estimator) = args.estimator {
        command.args(["--estimator", &estimator.to_string()]);
    }
    if let Some(local) = args.local_planner {
        command.args(["--local-planner", &local.to_string()]);
    }
    for swap in &args.swaps {
        command.args(["--swap", swap]);
    }
    for set in &args.sets {
        command.args(["--set", set]);
    }
    // The binaries were built once, before the first run; each run must not build again.
    command.env_remove("CARGO").stdin(Stdio::null());
    let log = std::fs::create_dir_all(out.parent().unwrap_or(Path::new(".")))
        .and_then(|()| std::fs::File::create(&log_path));
    let status = match log {
        Ok(log) => match log.try_clone() {
            Ok(err) => command.stdout(log).stderr(err).status(),
            Err(e) => Err(e),
        },
        Err(e) => Err(e),
    };
    let exit_code = match status {
        Ok(status) => status.code().unwrap_or(-1),
        Err(e) => {
            tracing::warn!(world = %job.info.name, "cannot run mole up: {e}");
            -1
        }
    };
    match read_summary(&out.join("summary.json")) {
        Ok(summary) if Some(summary.exit_reason.as_str()) == RunEnd::Interrupted.exit_reason() => {
            None
        }
        Ok(summary) if exit_code == 0 => Some(WorldMetrics::of(&job.info, &summary, exit_code)),
        _ => Some(WorldMetrics::failed(&job.info, exit_code)),
    }
}

/// A stored report, for `--check`: a file that is not one is bad input, named.
fn read_report(flag: &str, path: &Path) -> Result<EvalReport, Failure> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| Failure::input(format!("{flag} {}: {e}", path.display())))?;
    serde_json::from_str(&text).map_err(|e| {
        Failure::input(format!(
            "{flag} {}: not a mole eval report ({e}), expected a file `mole eval --json` wrote",
            path.display()
        ))
    })
}

/// The aggregates as a table on standard output.
fn print_report(report: &EvalReport) {
    println!(
        "{} worlds of `{}`, planner {}, estimator {}, {:.0} s on {} jobs",
        report.worlds.len(),
        report.family,
        report.planner,
        report.estimator,
        report.wall_time_s,
        report.jobs
    );
    println!(
        "{:<26} {:>4} {:>10} {:>23} {:>10}",
        "metric", "n", "mean", "95% interval", "median"
    );
    for (name, a) in &report.aggregate {
        println!(
            "{name:<26} {:>4} {:>10.4} [{:>10.4}, {:>10.4}] {:>10.4}",
            a.n, a.mean, a.ci95[0], a.ci95[1], a.median
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The report names a swapped-in command as the role's, else the kind chosen, else the
    /// launch file's.
    #[test]
    fn the_report_names_what_played_each_role() {
        #[derive(clap::Parser)]
        struct Cli {
            #[command(flatten)]
            eval: EvalArgs,
        }
        let parse = |args: &[&str]| {
            let base = ["mole-eval", "--family", "maze"];
            let all: Vec<&str> = base.iter().chain(args).copied().collect();
            <Cli as clap::Parser>::parse_from(all).eval
        };
        let a = parse(&["--planner", "dwa", "--swap", "planning=python3 mine.py"]);
        let kind = a.planner.map(|p| p.to_string());
        assert_eq!(
            role_label(&a, Role::Planning, kind),
            "planning=python3 mine.py"
        );
        let a = parse(&["--estimator", "pf", "--swap", "planning=python3 mine.py"]);
        let kind = a.estimator.map(|e| e.to_string());
        assert_eq!(role_label(&a, Role::Localization, kind), "pf");
        let a = parse(&[]);
        assert_eq!(role_label(&a, Role::Localization, None), "default");
    }

    /// The goal seekers navigate, the rest explore, and `--task` overrides either (a swapped-in
    /// planner is not known by its kind).
    #[test]
    fn the_task_follows_the_planner_unless_given() {
        assert_eq!(Task::of(None, Some(PlannerKind::Dwa)), Task::Navigate);
        assert_eq!(Task::of(None, Some(PlannerKind::Apf)), Task::Navigate);
        assert_eq!(Task::of(None, Some(PlannerKind::Frontier)), Task::Explore);
        assert_eq!(Task::of(None, None), Task::Explore);
        let given = Some(Task::Navigate);
        assert_eq!(
            Task::of(given, Some(PlannerKind::RandomWalk)),
            Task::Navigate
        );
        let given = Some(Task::Explore);
        assert_eq!(Task::of(given, Some(PlannerKind::Dwa)), Task::Explore);
    }
}
