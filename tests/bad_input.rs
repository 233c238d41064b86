//! Bad input never crashes anything and never passes silently: a clear one-line error, exit 2.

use mole_integration_tests::*;
use mole_types::{EstimatorKind, PlannerKind, Role};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

/// How long a `mole up` that must be refused may run: the refusal comes before any process
/// starts, so this only keeps a wrongly accepted run, or a hang, from stalling the test run.
const REFUSAL_TIMEOUT: Duration = Duration::from_secs(60);

fn stderr_of(output: &Output) -> String {
    String::from_utf8_lossy(&output.stderr).into_owned()
}

/// Runs a `mole up` that must be refused. Still running after [`REFUSAL_TIMEOUT`] (it accepted
/// the input, or hangs), it is stopped as Ctrl-C would (it stops its children and cleans up),
/// killed if that does not end it, and the test fails with what it printed.
fn refused(mut command: Command) -> Output {
    use nix::sys::signal::{Signal, kill};
    use nix::unistd::Pid;
    let mut child = command
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start mole up");
    let deadline = Instant::now() + REFUSAL_TIMEOUT;
    while child.try_wait().expect("poll mole up").is_none() {
        if Instant::now() > deadline {
            let _ = kill(Pid::from_raw(child.id() as i32), Signal::SIGINT);
            let stop_deadline = Instant::now() + Duration::from_secs(15);
            while child.try_wait().ok().flatten().is_none() && Instant::now() < stop_deadline {
                std::thread::sleep(Duration::from_millis(50));
            }
            let _ = child.kill();
            let output = child.wait_with_output().expect("reap mole up");
            panic!(
                "mole up was not refused within {REFUSAL_TIMEOUT:?}:\n{}",
                stderr_of(&output)
            );
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    child.wait_with_output().expect("collect mole up's output")
}

/// `mole up ARGS` in a namespace and output directory of its own, which must be refused before
/// any process starts (a started process leaves its log).
fn refused_up(test: &str, args: &[&str]) -> Output {
    let namespace = unique_namespace(test);
    let out = std::env::temp_dir().join(format!("mole-{namespace}"));
    let output = refused(mole_command(&namespace, &out, args));
    let started: Vec<_> = std::fs::read_dir(out.join("logs"))
        .into_iter()
        .flatten()
        .flatten()
        .map(|entry| entry.file_name())
        .collect();
    let _ = std::fs::remove_dir_all(&out);
    assert!(
        started.is_empty(),
        "{args:?} started {started:?}: {}",
        stderr_of(&output)
    );
    output
}

fn write_temp(name: &str, text: &str) -> std::path::PathBuf {
    let path = std::env::temp_dir().join(format!("mole-bad-{}-{name}", std::process::id()));
    std::fs::write(&path, text).expect("write temp file");
    path
}

/// A launch file with a bad value or an unknown field is refused naming the file, the line, the
/// field and the choices.
#[test]
fn a_malformed_launch_file_names_file_line_and_field() {
    let good = std::fs::read_to_string(workspace().join("launch/stacks/default.toml")).unwrap();
    let bad = good.replacen("policy = \"on-failure\"", "policy = \"sometimes\"", 1);
    assert_ne!(
        good, bad,
        "the default launch file has an on-failure policy to break"
    );
    let path = write_temp("launch.toml", &bad);
    let output = refused_up("bad-launch", &[path.to_str().unwrap()]);
    let _ = std::fs::remove_file(&path);
    let err = stderr_of(&output);
    assert_eq!(output.status.code(), Some(2), "{err}");
    assert!(
        err.contains(path.file_name().unwrap().to_str().unwrap()),
        "names the file: {err}"
    );
    assert!(err.contains("restart.policy"), "names the field: {err}");
    assert!(
        err.contains("sometimes") && err.contains("on-failure"),
        "says what was expected: {err}"
    );
    let line = bad.lines().position(|l| l.contains("sometimes")).unwrap() + 1;
    assert!(
        err.contains(&format!(":{line}:")),
        "names line {line}: {err}"
    );

    let path = write_temp(
        "unknown.toml",
        &good.replacen("[stack]", "[stack]\nbogus_field = 1", 1),
    );
    let output = refused_up("unknown-field", &[path.to_str().unwrap()]);
    let _ = std::fs::remove_file(&path);
    let err = stderr_of(&output);
    assert_eq!(output.status.code(), Some(2), "{err}");
    assert!(err.contains("bogus_field"), "{err}");
}

/// A scenario with a value of the wrong type is refused naming the file, the line, the field,
/// what it found and what was expected; a missing scenario is refused too.
#[test]
fn a_malformed_scenario_names_file_line_field_and_what_was_expected() {
    let good = std::fs::read_to_string(workspace().join("scenarios/default.toml")).unwrap();
    let (line_no, line) = good
        .lines()
        .enumerate()
        .find(|(_, l)| l.trim_start().starts_with("radius"))
        .expect("the default scenario sets the robot radius");
    let bad = good.replacen(line, "radius = \"big\"", 1);
    let path = write_temp("scenario.toml", &bad);
    let output = refused_up("bad-scenario", &["--scenario", path.to_str().unwrap()]);
    let _ = std::fs::remove_file(&path);
    let err = stderr_of(&output);
    assert_eq!(output.status.code(), Some(2), "{err}");
    assert!(
        err.contains(path.file_name().unwrap().to_str().unwrap()),
        "names the file: {err}"
    );
    assert!(err.contains("`robot.radius`"), "names the field: {err}");
    assert!(
        err.contains("\"big\"") && err.contains("expected f64"),
        "says what it found and what was expected: {err}"
    );
    assert!(
        err.contains(&format!(":{}:", line_no + 1)),
        "names line {}: {err}",
        line_no + 1
    );

    let output = refused_up("no-scenario", &["--scenario", "/nonexistent/scenario.toml"]);
    assert_eq!(output.status.code(), Some(2), "{}", stderr_of(&output));
}

/// An empty scenario and a file of NUL bytes are the wrong file, not the default arena: each is
/// refused before anything starts, naming the file and what is wrong with it.
#[test]
fn an_empty_or_binary_scenario_is_refused() {
    for (name, text, why) in [
        ("empty.toml", "", "the scenario sets nothing"),
        ("nul.toml", "\0\0\0\0\0\0\0\0", "not a text file"),
    ] {
        let path = write_temp(name, text);
        let output = refused_up("odd-scenario", &["--scenario", path.to_str().unwrap()]);
        let _ = std::fs::remove_file(&path);
        let err = stderr_of(&output);
        assert_eq!(output.status.code(), Some(2), "{name}: {err}");
        assert!(
            err.contains(&path.display().to_string()),
            "names the file: {err}"
        );
        assert!(err.contains(why), "{name}: {err}");
    }
}

/// A planner or an estimator the stack does not have is refused before anything starts, exit
/// 2, naming every valid choice.
#[test]
fn an_unknown_planner_or_estimator_is_refused_naming_the_choices() {
    for (flag, name, choices) in [
        ("--planner", "teleport", PlannerKind::NAMES),
        ("--estimator", "oracle", EstimatorKind::NAMES),
    ] {
        let output = refused_up("bad-kind", &[flag, name]);
        let err = stderr_of(&output);
        assert_eq!(output.status.code(), Some(2), "{flag} {name}: {err}");
        assert!(err.contains(name), "{err}");
        assert!(
            err.contains(&choices.join(", ")),
            "names the choices: {err}"
        );
    }
}

/// A goal outside the arena or in an obstacle, or a goal-seeking planner without a goal, is
/// refused before anything starts, exit 2, naming the goal and the bounds or the obstacle.
#[test]
fn a_goal_the_robot_cannot_reach_or_no_goal_is_refused() {
    let dwa = PlannerKind::Dwa.name();
    let output = refused_up("far-goal", &["--planner", dwa, "--goal", "500,500"]);
    let err = stderr_of(&output);
    assert_eq!(output.status.code(), Some(2), "{err}");
    assert!(
        err.contains("goal (500, 500) is outside the arena") && err.contains("10 m × 10 m"),
        "names the goal and the arena: {err}"
    );

    let boxed = write_temp(
        "boxed.toml",
        "name = \"boxed\"\nobstacles = [{ x = 5.0, y = 5.0, side = 1.0 }]\n",
    );
    let scenario = boxed.to_str().unwrap();
    let args = ["--planner", dwa, "--scenario", scenario, "--goal", "5.4,5"];
    let output = refused_up("boxed-goal", &args);
    let _ = std::fs::remove_file(&boxed);
    let err = stderr_of(&output);
    assert_eq!(output.status.code(), Some(2), "{err}");
    assert!(
        err.contains("goal (5.4, 5) is in an obstacle") && err.contains("side 1 m at (5, 5)"),
        "names the goal and the obstacle: {err}"
    );

    // The default scenario has no goal of its own.
    let apf = PlannerKind::Apf.name();
    let output = refused_up("no-goal", &["--planner", apf]);
    let err = stderr_of(&output);
    assert_eq!(output.status.code(), Some(2), "{err}");
    assert!(err.contains(apf) && err.contains("--goal"), "{err}");
}

/// Frontier exploration in a world with no lidar is refused before anything starts (it would
/// see no frontier and report an exploration it never did), naming the world and the planner
/// that explores by touch; the planning process refuses it too when started by hand.
#[test]
fn frontier_without_a_lidar_is_refused() {
    let frontier = PlannerKind::Frontier.name();
    let args = [
        "--planner",
        frontier,
        "--scenario",
        "scenarios/dark_room.toml",
    ];
    let output = refused_up("dark-frontier", &args);
    let err = stderr_of(&output);
    assert_eq!(output.status.code(), Some(2), "{err}");
    assert!(
        err.contains("`dark_room` has no lidar ([sensors.lidar] beams = 0)")
            && err.contains("--planner random-walk"),
        "{err}"
    );

    // Swapped in with its own --planner, the planning process refuses the map it is given.
    let namespace = unique_namespace("dark-frontier-swap");
    let out = std::env::temp_dir().join(format!("mole-{namespace}"));
    let swap = format!("planning=mole-planning --planner {frontier}");
    let args = ["--scenario", "scenarios/dark_room.toml", "--swap", &swap];
    let output = refused(mole_command(&namespace, &out, &args));
    let logs = logs(&out);
    let _ = std::fs::remove_dir_all(&out);
    assert_eq!(output.status.code(), Some(2), "{}", stderr_of(&output));
    assert!(
        logs.contains("has no lidar ([sensors.lidar] beams = 0)"),
        "{logs}"
    );
}

/// `--swap` with an unknown role, a missing program or no command is refused in one line.
#[test]
fn swap_errors_are_one_clear_line() {
    let output = refused_up("bad-role", &["--swap", "navigator=/bin/true"]);
    let err = stderr_of(&output);
    assert_eq!(output.status.code(), Some(2), "{err}");
    assert!(
        err.contains("navigator") && err.contains(Role::Planning.name()),
        "names the role and the known ones: {err}"
    );
    assert_eq!(err.trim().lines().count(), 1, "{err}");

    let output = refused_up("no-program", &["--swap", "planning=/nonexistent/planner"]);
    let err = stderr_of(&output);
    assert_eq!(output.status.code(), Some(2), "{err}");
    assert!(err.contains("/nonexistent/planner"), "{err}");

    let output = refused_up("no-command", &["--swap", "planning"]);
    assert_eq!(output.status.code(), Some(2), "{}", stderr_of(&output));
}

/// A second `mole up` in a namespace a running stack uses is refused, naming the namespace.
#[test]
fn a_namespace_in_use_is_refused() {
    let _serial = serial();
    let stack = Stack::start("ns-busy", &["--mode", "realtime", "--ticks", "100000"]);
    stack.wait_for_log(Role::World.name(), "ready", Duration::from_secs(60));
    let out = std::env::temp_dir().join(format!("mole-{}-second", stack.namespace));
    let output = refused(mole_command(&stack.namespace, &out, &["--ticks", "10"]));
    let err = stderr_of(&output);
    assert_eq!(output.status.code(), Some(2), "{err}");
    assert!(
        err.contains(&stack.namespace) && err.contains("in use"),
        "{err}"
    );
    let _ = std::fs::remove_dir_all(out);
}

/// `mole up --view=P` with P in use is refused before any process starts, naming the flag, the
/// address and what was expected.
#[test]
fn a_view_port_in_use_is_refused() {
    let taken = std::net::TcpListener::bind("127.0.0.1:0").expect("a port");
    let port = taken.local_addr().expect("its address").port();
    let flag = format!("--view={port}");
    let output = refused_up("view-port", &["--mode", "lockstep", "--ticks", "50", &flag]);
    let err = stderr_of(&output);
    assert_eq!(output.status.code(), Some(2), "{err}");
    assert!(
        err.contains(&format!(
            "{flag}: cannot serve the view on 127.0.0.1:{port}"
        )),
        "{err}"
    );
    assert!(err.contains("expected a free port"), "{err}");
    drop(taken);
}
