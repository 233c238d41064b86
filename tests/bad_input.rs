//! Bad input never crashes anything and never passes silently: a clear one-line error, exit 2.

use mole_integration_tests::*;
use std::time::Duration;

fn stderr_of(output: &std::process::Output) -> String {
    String::from_utf8_lossy(&output.stderr).into_owned()
}

fn write_temp(name: &str, text: &str) -> std::path::PathBuf {
    let path = std::env::temp_dir().join(format!("mole-bad-{}-{name}", std::process::id()));
    std::fs::write(&path, text).expect("write temp file");
    path
}

#[test]
fn a_malformed_launch_file_names_file_line_and_field() {
    let good = std::fs::read_to_string(workspace().join("launch/stacks/default.toml")).unwrap();
    let bad = good.replacen("policy = \"on-failure\"", "policy = \"sometimes\"", 1);
    assert_ne!(
        good, bad,
        "the default launch file has an on-failure policy to break"
    );
    let path = write_temp("launch.toml", &bad);
    let output = run_mole(&["up", path.to_str().unwrap(), "--quiet"]);
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
    let output = run_mole(&["up", path.to_str().unwrap(), "--quiet"]);
    let err = stderr_of(&output);
    assert_eq!(output.status.code(), Some(2), "{err}");
    assert!(err.contains("bogus_field"), "{err}");
}

#[test]
fn a_malformed_scenario_names_file_line_and_field() {
    let good = std::fs::read_to_string(workspace().join("scenarios/default.toml")).unwrap();
    let (line_no, line) = good
        .lines()
        .enumerate()
        .find(|(_, l)| l.trim_start().starts_with("radius"))
        .expect("the default scenario sets the robot radius");
    let bad = good.replacen(line, "radius = \"big\"", 1);
    let path = write_temp("scenario.toml", &bad);
    let output = run_mole(&["up", "--scenario", path.to_str().unwrap(), "--quiet"]);
    let err = stderr_of(&output);
    assert_eq!(output.status.code(), Some(2), "{err}");
    assert!(
        err.contains(path.file_name().unwrap().to_str().unwrap()),
        "{err}"
    );
    assert!(err.contains("radius"), "{err}");
    assert!(
        err.contains(&format!(":{}:", line_no + 1)),
        "names line {}: {err}",
        line_no + 1
    );

    let output = run_mole(&["up", "--scenario", "/nonexistent/scenario.toml", "--quiet"]);
    assert_eq!(output.status.code(), Some(2), "{}", stderr_of(&output));
}

#[test]
fn swap_errors_are_one_clear_line() {
    let output = run_mole(&["up", "--swap", "navigator=/bin/true", "--quiet"]);
    let err = stderr_of(&output);
    assert_eq!(output.status.code(), Some(2), "{err}");
    assert!(
        err.contains("navigator") && err.contains("planning"),
        "names the role and the known ones: {err}"
    );
    assert_eq!(err.trim().lines().count(), 1, "{err}");

    let output = run_mole(&["up", "--swap", "planning=/nonexistent/planner", "--quiet"]);
    let err = stderr_of(&output);
    assert_eq!(output.status.code(), Some(2), "{err}");
    assert!(err.contains("/nonexistent/planner"), "{err}");

    let output = run_mole(&["up", "--swap", "planning", "--quiet"]);
    assert_eq!(output.status.code(), Some(2), "{}", stderr_of(&output));
}

#[test]
fn a_namespace_in_use_is_refused() {
    let _serial = serial();
    let stack = Stack::start("ns-busy", &["--mode", "realtime", "--ticks", "100000"]);
    stack.wait_for_log("world", "ready", Duration::from_secs(60));
    let out = std::env::temp_dir().join(format!("mole-{}-second", stack.namespace));
    let output = mole_command(&stack.namespace, &out, &["--ticks", "10"])
        .output()
        .expect("run");
    let err = stderr_of(&output);
    assert_eq!(output.status.code(), Some(2), "{err}");
    assert!(
        err.contains(&stack.namespace) && err.contains("in use"),
        "{err}"
    );
    let _ = std::fs::remove_dir_all(out);
}
