//! `mole eval`: a suite of generated worlds runs end to end, each world's scenario file repeats
//! its run with a plain `mole up`, a baseline it does worse than fails it naming the metric, and
//! bad input is refused before any world runs.

use mole_integration_tests::*;
use std::path::Path;
use std::process::Command;

/// Two clutter worlds with DWA: small enough for the suite, a navigation family (a goal, T_opt).
const SUITE: [&str; 8] = [
    "eval",
    "--family",
    "clutter",
    "--worlds",
    "2",
    "--planner",
    "dwa",
    "--jobs",
];

/// `mole`, run from the workspace as a user would: not under cargo's environment, so it builds
/// nothing.
fn mole() -> Command {
    let mut command = Command::new(bin_dir().join("mole"));
    command
        .current_dir(workspace())
        .env_remove("CARGO")
        .env_remove("CARGO_MANIFEST_DIR");
    command
}

fn eval_command(out: &Path, extra: &[&str]) -> Command {
    let mut command = mole();
    command
        .args(SUITE)
        .arg("2")
        .arg("--out")
        .arg(out)
        .args(extra);
    command
}

fn report(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).expect("the report")).expect("JSON")
}

/// The suite runs both worlds, reports them and their aggregates; a world's file, run again by
/// `mole up`, ends as the suite's run did; a baseline whose RMSE interval the run misses fails
/// `--check` with exit 1 naming that metric.
#[test]
fn a_suite_runs_reports_repeats_and_checks_against_a_baseline() {
    let _serial = serial();
    let before = shm_files();
    let dir = TempDir::new("eval");
    let out = dir.0.join("suite");
    let json = dir.0.join("report.json");
    let output = eval_command(&out, &["--json", json.to_str().unwrap()])
        .output()
        .expect("run mole eval");
    assert!(output.status.success(), "{}", output_text(&output));
    let r = report(&json);
    let worlds = r["worlds"].as_array().expect("worlds");
    assert_eq!(worlds.len(), 2, "{r}");
    for w in worlds {
        assert_eq!(w["exit_code"], 0, "{w}");
        assert!(
            w["barn_score"].as_f64().is_some(),
            "a navigation world has a score: {w}"
        );
    }
    assert_eq!(r["aggregate"]["finished"]["n"], 2);
    assert_eq!(r["aggregate"]["finished"]["mean"], 1.0);

    // The first world again, by hand, from its scenario file: the same summary.
    let name = worlds[0]["world"].as_str().unwrap();
    let scenario = out.join("worlds").join(format!("{name}.toml"));
    let again = dir.0.join("again");
    let ns = unique_namespace("eval-again");
    let status = mole_command(
        &ns,
        &again,
        &[
            "--mode",
            "lockstep",
            "--planner",
            "dwa",
            "--scenario",
            scenario.to_str().unwrap(),
            "--seed",
            &worlds[0]["seed"].to_string(),
            "--ticks",
            &worlds[0]["ticks_limit"].to_string(),
        ],
    )
    .status()
    .expect("run mole up");
    assert!(status.success());
    let first = deterministic(&summary(&out.join("runs").join(name)));
    let by_hand = deterministic(&summary(&again));
    assert_eq!(differing_fields(&first, &by_hand), Vec::<String>::new());

    // A baseline that claims a far better RMSE than this run's fails the check, naming it.
    let mut baseline = r.clone();
    let rmse = &mut baseline["aggregate"]["localization_rmse_m"];
    let mean = rmse["mean"].as_f64().expect("an RMSE");
    rmse["ci95"] = serde_json::json!([mean * 0.1, mean * 0.5]);
    let baseline_path = dir.0.join("baseline.json");
    std::fs::write(&baseline_path, baseline.to_string()).unwrap();
    let checked = eval_command(
        &dir.0.join("checked"),
        &["--check", baseline_path.to_str().unwrap()],
    )
    .output()
    .expect("run mole eval --check");
    let text = output_text(&checked);
    assert_eq!(checked.status.code(), Some(1), "{text}");
    assert!(
        text.contains("worse than the baseline: localization_rmse_m"),
        "{text}"
    );
    assert!(!text.contains("worse than the baseline: success"), "{text}");
    // Against its own report, the same suite passes, and draws itself beside the baseline.
    let plot = dir.0.join("suites.png");
    let same = eval_command(
        &dir.0.join("same"),
        &[
            "--check",
            json.to_str().unwrap(),
            "--plot",
            plot.to_str().unwrap(),
            "--beside",
            json.to_str().unwrap(),
        ],
    )
    .output()
    .expect("run mole eval --check --plot");
    assert!(same.status.success(), "{}", output_text(&same));
    let png = std::fs::read(&plot).expect("the plot");
    assert!(png.starts_with(b"\x89PNG\r\n\x1a\n"), "not a PNG");
    // A slice (its first world alone) is compared world by world with the baseline's own run
    // of that world (check.rs), and passes.
    let slice = mole()
        .args([
            "eval",
            "--family",
            "clutter",
            "--worlds",
            "1",
            "--planner",
            "dwa",
        ])
        .args(["--jobs", "1", "--out"])
        .arg(dir.0.join("slice"))
        .args(["--check", json.to_str().unwrap()])
        .output()
        .expect("run a slice");
    assert!(slice.status.success(), "{}", output_text(&slice));
    assert_eq!(left_behind(&before), Vec::<String>::new());
}

/// An unknown family, no worlds, a bad swap, a baseline that is not a report or is another
/// family's, a `--beside` that is not a report, `--baselines` with a suite's own options or a
/// family that has no suite:
/// exit 2, one line naming what was wrong, and no world written.
#[test]
fn bad_eval_input_is_refused_before_any_world_runs() {
    let dir = TempDir::new("eval-bad");
    let garbage = dir.0.join("garbage.json");
    std::fs::write(&garbage, "not json").unwrap();
    let rooms = dir.0.join("rooms.json");
    let report = serde_json::json!({
        "family": "rooms", "parameters": "", "planner": "dwa", "estimator": "default",
        "first_seed": 0, "worlds": [], "aggregate": {}, "wall_time_s": 1.0, "jobs": 1
    });
    std::fs::write(&rooms, report.to_string()).unwrap();
    for (args, expected) in [
        (
            vec!["eval", "--family", "mazes"],
            "unknown world `mazes`: expected a family",
        ),
        (
            vec!["eval", "--family", "maze", "--worlds", "0"],
            "--worlds: expected at least 1",
        ),
        (
            vec!["eval", "--family", "maze", "--swap", "planning"],
            "planning",
        ),
        (
            vec![
                "eval",
                "--family",
                "maze",
                "--check",
                garbage.to_str().unwrap(),
            ],
            "not a mole eval report",
        ),
        (
            vec![
                "eval",
                "--family",
                "maze",
                "--check",
                rooms.to_str().unwrap(),
            ],
            "the baseline is of `rooms`, this suite of `maze`",
        ),
        (
            vec![
                "eval",
                "--family",
                "maze",
                "--plot",
                "p.png",
                "--beside",
                garbage.to_str().unwrap(),
            ],
            "--beside",
        ),
        (
            vec!["eval", "--baselines", "b", "--planner", "dwa"],
            "cannot be used with",
        ),
        (
            vec!["eval", "--baselines", "b", "--family", "mazes"],
            "--family mazes: no stored suite is of that family",
        ),
    ] {
        let out = dir.0.join("out");
        let mut full = args.clone();
        full.extend(["--out", out.to_str().unwrap()]);
        let output = run_mole(&full);
        let text = output_text(&output);
        assert_eq!(output.status.code(), Some(2), "{args:?}: {text}");
        assert!(text.contains(expected), "{args:?}: {text}");
        assert!(
            !out.join("worlds").exists(),
            "{args:?}: worlds were generated"
        );
    }
}

/// Ctrl-C (SIGINT to the terminal's process group: the suite and its runs) ends the suite with
/// exit 1, saying how many worlds ran to their end; a run it cut short is left out of the report,
/// not counted as a finished world, and nothing is left behind.
#[test]
fn ctrl_c_ends_the_suite_and_leaves_out_the_runs_it_cut_short() {
    use nix::sys::signal::{Signal, killpg};
    use nix::unistd::Pid;
    use std::os::unix::process::CommandExt;
    use std::time::{Duration, Instant};
    let _serial = serial();
    let before = shm_files();
    let dir = TempDir::new("eval-int");
    let json = dir.0.join("report.json");
    let mut command = mole();
    command
        .args([
            "eval",
            "--family",
            "maze",
            "--worlds",
            "4",
            "--planner",
            "frontier",
        ])
        .args(["--jobs", "2", "--out"])
        .arg(dir.0.join("suite"))
        .arg("--json")
        .arg(&json)
        .process_group(0)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped());
    let child = command.spawn().expect("start mole eval");
    let group = Pid::from_raw(child.id() as i32);
    // Two maze runs under way (each takes tens of seconds): their logs exist.
    let runs = dir.0.join("suite").join("runs");
    let deadline = Instant::now() + Duration::from_secs(60);
    while std::fs::read_dir(&runs).map_or(0, |d| d.count()) < 2 && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(100));
    }
    std::thread::sleep(Duration::from_secs(2));
    killpg(group, Signal::SIGINT).expect("SIGINT to the suite's group");
    let output = child.wait_with_output().expect("mole eval ends");
    let text = output_text(&output);
    assert_eq!(output.status.code(), Some(1), "{text}");
    assert!(
        text.contains("interrupted: 0 of 4 worlds ran to their end"),
        "{text}"
    );
    assert_eq!(report(&json)["worlds"].as_array().map(Vec::len), Some(0));
    assert_eq!(left_behind(&before), Vec::<String>::new());
}

/// The slice the README's test command runs against the stored baselines (`eval/baselines/`):
/// the first worlds of each lit family with the planner built for it, and an estimator that
/// keeps its own map in the dark.
const SLICE: &[&str] = &[
    "maze/frontier-explore.json",
    "rooms/frontier-explore.json",
    "clutter/dwa-navigate.json",
    "cellular/dwa-navigate.json",
    "corridors/dwa-navigate.json",
    "rooms-dark/estimator-ekf-slam.json",
    "rooms/estimator-fastslam.json",
];
const SLICE_WORLDS: &str = "2";

/// Each suite of [`SLICE`], on its baseline's first worlds, does no worse than the baseline's own
/// runs of them (`--check` on a slice compares world by world): an algorithm that regresses on
/// a stored world fails the README's test command.
#[test]
fn a_slice_of_the_stored_baselines_does_no_worse_than_they_do() {
    let _serial = serial();
    let before = shm_files();
    let dir = TempDir::new("eval-slice");
    let suites = mole_launch::eval::baselines::suites();
    for file in SLICE {
        let suite = suites
            .iter()
            .find(|s| s.file() == *file)
            .unwrap_or_else(|| panic!("{file} is not a stored suite"));
        let mut command = mole();
        command
            .args(["eval", "--family", &suite.family])
            .args(["--planner", &suite.planner.to_string()])
            .args([
                "--task",
                mole_launch::eval::baselines::task_name(suite.task),
            ])
            .args(["--worlds", SLICE_WORLDS, "--jobs", "2", "--out"])
            .arg(dir.0.join(file.replace('/', "-")))
            .arg("--check")
            .arg(
                workspace()
                    .join(mole_launch::eval::baselines::DIR)
                    .join(file),
            );
        if let Some(estimator) = suite.estimator {
            command.args(["--estimator", &estimator.to_string()]);
        }
        if let Some(ticks) = suite.ticks {
            command.args(["--ticks", &ticks.to_string()]);
        }
        let output = command.output().expect("run mole eval");
        assert!(output.status.success(), "{file}: {}", output_text(&output));
    }
    assert_eq!(left_behind(&before), Vec::<String>::new());
}
