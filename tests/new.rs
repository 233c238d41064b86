//! `mole new planner|estimator|observer NAME DIR`, as a user runs it: the crate it writes
//! builds on its own (outside mole's workspace, with mole's lock file) and runs in its role of a
//! lockstep stack (`mole up --swap planning=…`, `--swap localization=…`), whose recorded outputs
//! are its own, or beside one (an observer), whose error it measures as the recording has it.

use mole_integration_tests::operator::Operator;
use mole_integration_tests::*;
use mole_types::{ClockMode, Cmd, Odom, PACE_RUN, Pose, Truth, WorldMap, topics};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;

#[test]
fn a_new_planner_crate_builds_on_its_own_and_drives_the_stack() {
    let _serial = serial();
    let dir = TempDir::new("new");
    let made = run_mole(&["new", "planner", "careful", dir.0.to_str().expect("a path")]);
    assert!(
        made.status.success(),
        "{}",
        String::from_utf8_lossy(&made.stderr)
    );
    let krate = dir.0.join("careful");
    let main = std::fs::read_to_string(krate.join("src/main.rs")).expect("src/main.rs");
    let own = main.lines().filter(|l| !l.trim().is_empty()).count();
    assert!(own <= 100, "the generated planner is {own} lines");
    // A bad name and an existing directory are refused before anything is written.
    let bad = run_mole(&[
        "new",
        "planner",
        "Bad Name",
        dir.0.to_str().expect("a path"),
    ]);
    assert_eq!(bad.status.code(), Some(2));
    let again = run_mole(&["new", "planner", "careful", dir.0.to_str().expect("a path")]);
    assert_eq!(again.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&again.stderr).contains("exists already"));

    let program = built(&krate, "careful");

    let swap = format!("planning={}", program.display());
    let kept = recorded_lockstep_run("new-planner", 300, &["--swap", &swap]);
    let bytes = std::fs::read(kept.0.join("run.mcap")).expect("the recording");
    let commands: Vec<Cmd> = mcap::MessageStream::new(&bytes)
        .expect("an MCAP file")
        .map(|m| m.expect("a complete recording"))
        .filter(|m| m.channel.topic == topics::PLANNING_CMD.name)
        .map(|m| bytemuck::pod_read_unaligned::<Cmd>(&m.data))
        .collect();
    assert!(commands.len() >= 299, "{} commands", commands.len());
    // Its planner's commands alone: straight ahead at one speed, or turning in place.
    let straight = commands
        .iter()
        .filter(|c| c.omega == 0.0 && c.v > 0.0)
        .count();
    let turning = commands
        .iter()
        .filter(|c| c.v == 0.0 && c.omega > 0.0)
        .count();
    assert_eq!(
        straight + turning,
        commands.len(),
        "commands not the planner's own"
    );
    assert!(straight > 0, "it never drove");
    let speeds: std::collections::BTreeSet<u64> = commands
        .iter()
        .filter(|c| c.v > 0.0)
        .map(|c| c.v.to_bits())
        .collect();
    assert_eq!(speeds.len(), 1, "one cruise speed");
    let summary = summary(&kept.0);
    assert!(summary.path_length_m > 0.1, "{summary:?}");
}

/// Builds the generated crate at `krate` as its user would, in a target directory of its own
/// under the workspace's (so a second run reuses it), from the registry cache the workspace's
/// build filled: its program.
fn built(krate: &Path, name: &str) -> PathBuf {
    let cargo = std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into());
    let target = workspace().join("target/mole-new");
    let built = Command::new(cargo)
        .args(["build", "--offline", "--manifest-path"])
        .arg(krate.join("Cargo.toml"))
        .env("CARGO_TARGET_DIR", &target)
        .env_remove("CARGO_MANIFEST_DIR")
        .output()
        .expect("run cargo");
    assert!(
        built.status.success(),
        "the generated crate does not build:\n{}",
        String::from_utf8_lossy(&built.stderr)
    );
    target.join("debug").join(name)
}

/// The messages of `topic` in the recording at `path`, as `M`.
fn messages<M: bytemuck::Pod>(path: &Path, topic: &str) -> Vec<M> {
    mcap_messages(path, topic)
        .iter()
        .map(|(_, data)| bytemuck::pod_read_unaligned::<M>(data))
        .collect()
}

#[test]
fn a_new_estimator_crate_builds_on_its_own_and_estimates_in_the_stack() {
    let _serial = serial();
    let dir = TempDir::new("new-estimator");
    let made = run_mole(&[
        "new",
        "estimator",
        "reckoner",
        dir.0.to_str().expect("a path"),
    ]);
    assert!(
        made.status.success(),
        "{}",
        String::from_utf8_lossy(&made.stderr)
    );
    let krate = dir.0.join("reckoner");
    let main = std::fs::read_to_string(krate.join("src/main.rs")).expect("src/main.rs");
    let own = main.lines().filter(|l| !l.trim().is_empty()).count();
    assert!(own <= 100, "the generated estimator is {own} lines");
    let program = built(&krate, "reckoner");

    let swap = format!("localization={}", program.display());
    let kept = recorded_lockstep_run("new-estimator", 300, &["--swap", &swap]);
    let recording = kept.0.join("run.mcap");
    let map: WorldMap = messages(&recording, topics::WORLD_MAP.name).remove(0);
    let odoms: Vec<Odom> = messages(&recording, topics::SENSING_ODOM.name);
    let poses: Vec<Pose> = messages(&recording, topics::LOCALIZATION_POSE.name);
    assert!(poses.len() >= 299, "{} poses", poses.len());
    // Its estimate alone: the unicycle driven by the recorded odometry from the start pose.
    let (mut x, mut y, mut theta) = (map.start_x, map.start_y, map.start_theta);
    let mut odoms = odoms.iter();
    for pose in &poses {
        let odom = odoms
            .find(|o| o.header.tick == pose.header.tick)
            .expect("the odometry of the pose's tick");
        let d = odom.v * odom.dt;
        (x, y) = (x + d * theta.cos(), y + d * theta.sin());
        theta = (theta + odom.omega * odom.dt + std::f64::consts::PI)
            .rem_euclid(std::f64::consts::TAU)
            - std::f64::consts::PI;
        let tick = pose.header.tick;
        assert!(
            (pose.x - x).abs() < 1e-9 && (pose.y - y).abs() < 1e-9,
            "tick {tick}"
        );
        assert!((pose.theta - theta).abs() < 1e-9, "tick {tick}");
        assert_eq!(pose.odom, [odom.x, odom.y, odom.theta], "tick {tick}");
    }
    let last = poses.last().expect("a pose");
    assert!(
        last.covariance[0] > 0.0,
        "its variance grew with the distance"
    );
}

#[test]
fn a_new_observer_crate_builds_on_its_own_and_measures_the_run_beside_it() {
    let _serial = serial();
    let dir = TempDir::new("new-observer");
    let made = run_mole(&[
        "new",
        "observer",
        "watcher",
        dir.0.to_str().expect("a path"),
    ]);
    assert!(
        made.status.success(),
        "{}",
        String::from_utf8_lossy(&made.stderr)
    );
    let program = built(&dir.0.join("watcher"), "watcher");

    let recording = dir.0.join("run.mcap");
    let record = recording.display().to_string();
    let args = [
        "--mode", "lockstep", "--ticks", "300", "--seed", "5", "--paused", "--record", &record,
    ];
    let stack = Stack::start("new_observer", &args);
    let mut operator = Operator::join(&stack, ClockMode::Lockstep);
    let watcher = Command::new(&program)
        .args(["--namespace", &stack.namespace])
        .stdout(std::process::Stdio::piped())
        .spawn()
        .expect("start the observer");
    // The observer subscribes within a second; the run starts then.
    operator.follow(std::time::Duration::from_secs(1));
    operator.send_pace(PACE_RUN, 0);
    operator.follow_until("the run's end", std::time::Duration::from_secs(120), |o| {
        o.truth.latest().is_some_and(Truth::is_end)
    });
    drop(operator);
    let measured = watcher
        .wait_with_output()
        .expect("the observer ends with the run");
    assert!(measured.status.success(), "the observer failed");
    stack.succeeded(std::time::Duration::from_secs(120));
    let said: serde_json::Value =
        serde_json::from_slice(&measured.stdout).expect("the observer's JSON");

    // The same error, from the recording, over the steps it read.
    let (first, last) = (
        said["first_tick"].as_u64().unwrap(),
        said["last_tick"].as_u64().unwrap(),
    );
    let truths: BTreeMap<u64, Truth> = messages::<Truth>(&recording, topics::WORLD_TRUTH.name)
        .into_iter()
        .map(|t| (t.header.tick, t))
        .collect();
    let (mut sum, mut samples) = (0.0, 0u64);
    for pose in messages::<Pose>(&recording, topics::LOCALIZATION_POSE.name) {
        let tick = pose.header.tick;
        if let Some(t) = truths.get(&tick).filter(|_| (first..=last).contains(&tick)) {
            sum += (pose.x - t.x).powi(2) + (pose.y - t.y).powi(2);
            samples += 1;
        }
    }
    assert!(samples >= 250, "{samples} steps read of 300");
    assert_eq!(said["samples"].as_u64(), Some(samples), "{said}");
    let rmse = (sum / samples as f64).sqrt();
    let said_rmse = said["rmse_m"].as_f64().unwrap();
    assert!(
        (said_rmse - rmse).abs() <= 1e-9 * rmse.max(1e-9),
        "{said_rmse} vs {rmse}"
    );
}
