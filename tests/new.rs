//! `mole new planner|estimator NAME DIR`, as a user runs it: the crate it writes builds on its
//! own (outside mole's workspace, with mole's lock file) and runs in its role of a lockstep
//! stack (`mole up --swap planning=…`, `--swap localization=…`), whose recorded outputs are its
//! own.

use mole_integration_tests::*;
use mole_types::{Cmd, Odom, Pose, WorldMap, topics};
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
