//! The operator's topics in a running lockstep stack, published by a program of the test's own
//! as the view would: a goal redirects a goal-seeking planner; pause, step and run pace the world.

use mole_integration_tests::*;
use mole_runtime::ClockMode;
use mole_types::{PACE_PAUSE, PACE_RUN, PACE_STEP, Role, STATUS_HAS_GOAL, Truth};
use std::collections::BTreeSet;
use std::time::Duration;

/// The launcher ends a lockstep run that makes no step for 15 s (`STALL_TIMEOUT`) and restarts
/// a process silent for 5 s (`HANG_TIMEOUT`); a pause must outlast both.
const LONG_PAUSE: Duration = Duration::from_secs(17);

/// Every log line of a kept run that says a lockstep step waited for its inputs, or that a
/// process hung.
fn held_step_reports(keep: &std::path::Path) -> Vec<String> {
    let mut lines = Vec::new();
    for entry in std::fs::read_dir(keep.join("logs")).unwrap().flatten() {
        let text = std::fs::read_to_string(entry.path()).unwrap_or_default();
        lines.extend(
            text.lines()
                .filter(|l| l.contains("not all its inputs") || l.contains("hung"))
                .map(|l| format!("{}: {l}", entry.path().display())),
        );
    }
    lines
}

/// A goal published on operator/goal mid-run takes the DWA away from the scenario's goal: the
/// planner reports it in planning/status, and the robot drives to it and stands there waiting
/// for the next one: the run ends at its tick limit, not as arrived (only the scenario's goal
/// ends a run). (The run is held while the goal is sent, so that the robot is still far
/// from both goals however late the test joins.)
#[test]
fn an_operator_goal_redirects_a_goal_seeking_planner() {
    let _serial = serial();
    let stack = Stack::start(
        "op-goal",
        &[
            "--mode",
            "lockstep",
            "--scenario",
            "scenarios/open.toml",
            "--planner",
            "dwa",
            "--ticks",
            "5000",
            "--seed",
            "3",
        ],
    );
    let mut operator = Operator::join(&stack, ClockMode::Lockstep);
    operator.send_pace(PACE_PAUSE, 0);
    operator.follow_until("a truth", Duration::from_secs(60), |o| o.tick() > 0);
    operator.follow(Duration::from_millis(300));
    // The scenario's goal is (8.5, 8); the operator's lies along the bottom edge, more than 4 m
    // from any point of the way there from the start (1, 1).
    let (goal, tolerance) = ([8.5, 1.5], 0.4);
    let from_goal = |t: &Truth| (t.x - goal[0]).hypot(t.y - goal[1]);
    let held = *operator.truth();
    assert!(!held.is_end(), "held before the run's end: {held:?}");
    operator.send_goal(goal[0], goal[1], tolerance);
    operator.send_pace(PACE_RUN, 0);
    operator.follow_until(
        "the goal in planning/status",
        Duration::from_secs(30),
        |o| {
            o.status
                .latest()
                .is_some_and(|s| s.flags & STATUS_HAS_GOAL != 0 && [s.goal_x, s.goal_y] == goal)
        },
    );
    operator.follow_until("the run's end", Duration::from_secs(300), |o| {
        o.truth.latest().is_some_and(Truth::is_end)
    });
    let end = *operator.truth();
    drop(operator);
    let keep = std::env::temp_dir().join(format!("mole-keep-{}", stack.namespace));
    let output = stack.wait_and_copy(&keep, Duration::from_secs(60));
    let s = summary(&keep);
    let _ = std::fs::remove_dir_all(&keep);
    assert!(output.status.success(), "{s:#?}");
    assert!(
        from_goal(&held) - from_goal(&end) > 3.0 && from_goal(&end) < 1.0,
        "from {:.2} m to {:.2} m of the operator's goal: {held:?} to {end:?}",
        from_goal(&held),
        from_goal(&end)
    );
    assert!(
        (end.x - 8.5).hypot(end.y - 8.0) > 4.0,
        "the scenario's goal was not the one driven to: {end:?}"
    );
    assert!(
        end.v.abs() < 1e-9 && end.omega.abs() < 1e-9,
        "standing at the operator's goal: {end:?}"
    );
    assert_eq!(s.end_reason.as_deref(), Some("ticks"), "{s:#?}");
}

/// PAUSE holds a lockstep run before its next step for longer than the launcher's hang and
/// stall timeouts, STEP 5 takes exactly five steps and holds again, RUN goes on to the end of
/// `--ticks`; nothing is restarted, no process reports a held step, and the stack stops cleanly.
#[test]
fn pause_step_and_run_pace_a_lockstep_run() {
    let _serial = serial();
    let before = shm_files();
    let ticks = 3000;
    let stack = Stack::start(
        "op-pace",
        &[
            "--mode",
            "lockstep",
            "--ticks",
            &ticks.to_string(),
            "--seed",
            "1",
        ],
    );
    let mut operator = Operator::join(&stack, ClockMode::Lockstep);
    operator.follow_until("step 100", Duration::from_secs(60), |o| o.tick() >= 100);
    operator.send_pace(PACE_PAUSE, 0);
    // The step under way when the pause came finishes; then the truth stands still.
    operator.follow(Duration::from_millis(500));
    let held = operator.tick();
    operator.follow(Duration::from_millis(1500));
    assert_eq!(operator.tick(), held, "paused");
    assert!(held < ticks, "the pause came before the run's end");

    operator.send_pace(PACE_STEP, 5);
    operator.follow_until("five steps", Duration::from_secs(30), |o| {
        o.tick() >= held + 5
    });
    operator.follow(LONG_PAUSE);
    assert_eq!(operator.tick(), held + 5, "five steps, then held");
    // Whose iceoryx2 files to look for at the end (other programs may share the machine).
    let makers: BTreeSet<u32> = processes_of(&stack.namespace)
        .into_iter()
        .chain([std::process::id()])
        .collect();

    operator.send_pace(PACE_RUN, 0);
    operator.follow_until("the run's end", Duration::from_secs(300), |o| {
        o.truth.latest().is_some_and(Truth::is_end)
    });
    assert_eq!(operator.tick(), ticks);
    drop(operator);
    let keep = std::env::temp_dir().join(format!("mole-keep-{}", stack.namespace));
    let output = stack.wait_and_copy(&keep, Duration::from_secs(60));
    let s = summary(&keep);
    let reports = held_step_reports(&keep);
    let _ = std::fs::remove_dir_all(&keep);
    assert!(output.status.success(), "{s:#?}");
    assert_eq!(s.ticks, ticks, "{s:#?}");
    assert!(s.restarts.values().all(|n| *n == 0), "{:?}", s.restarts);
    assert!(s.hangs.is_empty(), "{:?}", s.hangs);
    assert!(reports.is_empty(), "{reports:#?}");
    let leftovers = made_by(&left_behind(&before), &makers);
    assert!(leftovers.is_empty(), "left behind: {leftovers:?}");
}

/// Realtime ignores the operator's pace, and an explorer its goals: the run goes on to its end,
/// and each says so once and counts what it ignored.
#[test]
fn realtime_ignores_a_pace_and_an_explorer_a_goal_counting_them() {
    let _serial = serial();
    let stack = Stack::start("op-realtime", &["--mode", "realtime", "--ticks", "500"]);
    let mut operator = Operator::join(&stack, ClockMode::Realtime);
    for _ in 0..2 {
        operator.send_pace(PACE_PAUSE, 0);
        operator.send_goal(2.0, 2.0, 0.0);
        operator.follow(Duration::from_millis(300));
    }
    drop(operator);
    let keep = std::env::temp_dir().join(format!("mole-keep-{}", stack.namespace));
    let output = stack.wait_and_copy(&keep, Duration::from_secs(60));
    let s = summary(&keep);
    let log = |role: Role| {
        let path = keep.join("logs").join(format!("{role}.log"));
        without_colours(&std::fs::read_to_string(path).unwrap_or_default())
    };
    let (world, planning) = (log(Role::World), log(Role::Planning));
    let _ = std::fs::remove_dir_all(&keep);
    assert!(output.status.success(), "{s:#?}");
    assert_eq!(s.ticks, 500, "not paused: {s:#?}");
    assert_eq!(
        world.matches("paces lockstep runs only").count(),
        1,
        "{world}"
    );
    assert!(world.contains("ignored=2"), "{world}");
    assert_eq!(planning.matches("seeks no goals").count(), 1, "{planning}");
    assert!(planning.contains("ignored=2"), "{planning}");
}
