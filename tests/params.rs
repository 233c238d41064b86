//! Settings at run time, as a user changes them: `mole param` lists, reads and sets a running
//! lockstep stack's settings; a change is taken at a step boundary, in summary.json and in the
//! recording as an event, and the recording replays it at the same step (`mole replay --check`
//! identical); a bad key, a bad value and a fixed key are refused with exit 2, a change the
//! process refuses with exit 1.

use mole_integration_tests::*;
use mole_types::Role;
use std::process::{Command, Output, Stdio};
use std::time::Duration;

const RUN_TIMEOUT: Duration = Duration::from_secs(300);

/// `mole param ARGS --namespace NS`.
fn param(namespace: &str, args: &[&str]) -> Output {
    Command::new(bin_dir().join("mole"))
        .current_dir(workspace())
        .arg("param")
        .args(args)
        .args(["--namespace", namespace])
        .stdin(Stdio::null())
        .output()
        .expect("run mole param")
}

/// The events of kind `param` in a recording.
fn param_events(recording: &[u8]) -> Vec<serde_json::Value> {
    mcap::MessageStream::new(recording)
        .expect("an MCAP file")
        .map(|m| m.expect("a finished recording reads to its end"))
        .filter(|m| m.channel.topic == "stack/events")
        .map(|m| serde_json::from_slice::<serde_json::Value>(&m.data).expect("JSON"))
        .filter(|e| e["kind"] == "param")
        .collect()
}

#[test]
fn a_setting_changed_while_running_is_taken_at_a_step_recorded_and_replayed() {
    let _serial = serial();
    let dir = TempDir::new("params");
    let recording = dir.0.join("run.mcap");
    let stack = Stack::start(
        "params",
        &[
            "launch/stacks/lockstep.toml",
            "--scenario",
            "scenarios/dark_room.toml",
            "--seed",
            "1",
            "--ticks",
            "6000",
            "--record",
            recording.to_str().expect("UTF-8 path"),
        ],
    );
    stack.wait_for_log(Role::Planning.name(), "ready", Duration::from_secs(60));
    let ns = stack.namespace.clone();

    let listed = param(&ns, &["list", "planning"]);
    let text = output_text(&listed);
    assert!(listed.status.success(), "{text}");
    assert!(text.contains("random-walk.stride = 1.0\n"), "{text}");
    assert!(text.contains("replan_with = unset  (fixed)"), "{text}");

    let set = param(&ns, &["set", "planning", "random-walk.stride", "0.6"]);
    let said = output_text(&set);
    assert!(set.status.success(), "{said}");
    let tick: u64 = said
        .trim()
        .strip_prefix("planning.random-walk.stride = 0.6 from step ")
        .and_then(|t| t.parse().ok())
        .unwrap_or_else(|| panic!("no step in: {said}"));
    let got = param(&ns, &["get", "planning", "random-walk.stride"]);
    assert_eq!(output_text(&got).trim(), "0.6");

    for (args, says) in [
        (
            &["set", "planning", "random-walk.strid", "0.6"][..],
            "one of the keys",
        ),
        (&["set", "planning", "dwa.critics.heading", "-1"], "≥ 0.0"),
        (
            &["set", "mapping", "log_odds.threshold", "9.0"],
            "threshold",
        ),
        (
            &["set", "localization", "pf.n_particles", "5"],
            "cannot change while",
        ),
        (&["set", "world", "x", "1"], "has no settings"),
    ] {
        let refused = param(&ns, args);
        let text = output_text(&refused);
        assert_eq!(refused.status.code(), Some(2), "{args:?}: {text}");
        assert!(text.contains(says), "{args:?}: {text}");
    }

    let output = stack.wait_and_copy(&dir.0.join("run"), RUN_TIMEOUT);
    assert!(output.status.success(), "{}", output_text(&output));
    let run = summary(&dir.0.join("run"));
    let changes = run.settings_changes.as_array().expect("a list of changes");
    assert_eq!(changes.len(), 1, "{changes:?}");
    assert_eq!(changes[0]["tick"], tick);
    assert_eq!(changes[0]["key"], "random-walk.stride");

    let bytes = std::fs::read(&recording).expect("the recording");
    let events = param_events(&bytes);
    assert_eq!(events.len(), 1, "{events:?}");
    assert_eq!(events[0]["applied"], true, "{events:?}");
    assert_eq!(events[0]["at"], tick, "{events:?}");
    assert_eq!(events[0]["value"], "0.6", "{events:?}");

    // The replay takes the change before the same step: the live roles' outputs are the
    // recording's, byte for byte.
    let replay = Replay::start(&dir.0, &recording, &["--check"], &[]);
    let out = replay.out.clone();
    let replayed = replay.wait();
    let said = output_text(&replayed);
    assert!(replayed.status.success(), "{said}\n{}", logs(&out));
    assert!(said.contains("check: identical"), "{said}");
    let changes = summary(&out).settings_changes;
    assert_eq!(changes[0]["tick"], tick, "{changes}");
}

/// A change the process cannot take (the histogram filter builds its tables with the noise) is
/// refused by it, with its reason and exit 1, and nothing changes; a change taken survives a
/// crash: the restarted process starts with it.
#[test]
fn a_change_the_process_cannot_take_is_refused_and_one_taken_survives_a_crash() {
    let _serial = serial();
    let stack = Stack::start(
        "params-refused",
        &[
            "--mode",
            "realtime",
            "--duration",
            "60",
            "--estimator",
            "bayes",
        ],
    );
    stack.wait_for_log(Role::Localization.name(), "ready", Duration::from_secs(60));
    let ns = stack.namespace.clone();
    let refused = param(&ns, &["set", "localization", "noise.odom_v_std", "0.2"]);
    let text = output_text(&refused);
    assert_eq!(refused.status.code(), Some(1), "{text}");
    assert!(text.contains("localization refused"), "{text}");
    assert!(text.contains("tables"), "{text}");
    let got = param(&ns, &["get", "localization", "noise.odom_v_std"]);
    assert_eq!(output_text(&got).trim(), "unset");

    let set = param(&ns, &["set", "planning", "random-walk.stride", "0.6"]);
    assert!(set.status.success(), "{}", output_text(&set));
    let planning = Role::Planning.spec().program;
    let victim = pid_of(&ns, planning).expect("a planning process");
    let killed = run_mole(&["fault", "kill", "planning", "--namespace", &ns]);
    assert!(killed.status.success(), "{}", output_text(&killed));
    wait_for_new_pid(
        &ns,
        planning,
        Some(victim),
        Duration::from_secs(30),
        &stack.out,
    );
    stack.wait_for_log(
        Role::Planning.name(),
        "settings other than the defaults: random-walk.stride = 0.6",
        Duration::from_secs(30),
    );
    let stopped = run_mole(&["stop", "--namespace", &ns]);
    assert!(stopped.status.success(), "{}", output_text(&stopped));
    let output = stack.wait(RUN_TIMEOUT);
    assert!(output.status.success(), "{}", output_text(&output));
}
