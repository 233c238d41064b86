//! Hot swap through `mole swap` (stack/control): lockstep loses no step and no consumer handles
//! one twice, over ticks the launcher observed; realtime reports its gap, and every refusal
//! leaves the running stack untouched. The realtime run also checks that iceoryx2's service
//! listing shows every topic with its type name.

use mole_integration_tests::*;
use std::process::Output;
use std::time::Duration;

fn mole_swap(namespace: &str, args: &[&str]) -> Output {
    let mut all = vec!["swap", "--namespace", namespace];
    all.extend_from_slice(args);
    run_mole(&all)
}

fn text(output: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&output.stdout),
        String::from_utf8_lossy(&output.stderr)
    )
}

/// Lockstep swaps of every swappable role observe ticks and lose none, no consumer handles one
/// twice, and refused or failed swaps leave the old process in its role.
#[test]
fn lockstep_swaps_lose_and_repeat_no_step_and_refusals_change_nothing() {
    let _serial = serial();
    let before = shm_files();
    // Long enough never to end by itself: `mole stop` ends it.
    let stack = Stack::start(
        "swap-lockstep",
        &["--mode", "lockstep", "--ticks", "10000000"],
    );
    stack.wait_for_log("world", "ready", Duration::from_secs(60));
    let ns = stack.namespace.clone();

    // Refusals: exit 2, one line naming what was wrong.
    for (args, needle) in [
        (
            &["world", "mole-world"][..],
            "cannot be swapped while it runs",
        ),
        (
            &["planer", "mole-planning"][..],
            "no process has the role `planer`",
        ),
        (&["planning", "./no/such/program"][..], "not found"),
    ] {
        let out = mole_swap(&ns, args);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {}", text(&out));
        assert!(text(&out).contains(needle), "{args:?}: {}", text(&out));
    }
    // A replacement that dies while starting: exit 1, and the old process keeps the role.
    let out = mole_swap(&ns, &["planning", "/bin/false"]);
    assert_eq!(out.status.code(), Some(1), "{}", text(&out));
    assert!(text(&out).contains("keeps running"), "{}", text(&out));

    // Real swaps of every swappable role, quoted commands and words. Mapping and
    // localization take over their predecessor's grids and estimate.
    for args in [
        &["planning", "mole-planning --planner random-walk"][..],
        &["sensing", "mole-sensing"][..],
        &["mapping", "mole-mapping"][..],
        &["localization", "mole-localization --estimator pf"][..],
    ] {
        let out = mole_swap(&ns, args);
        assert!(out.status.success(), "{args:?}: {}", text(&out));
        assert!(
            text(&out).contains("lockstep: 0 steps lost, 0 repeated"),
            "{}\n{}",
            text(&out),
            logs(&stack.out)
        );
    }
    let out = run_mole(&["status", "--namespace", &ns]);
    assert!(out.status.success(), "{}", text(&out));
    assert!(text(&out).contains("planning (pid"), "{}", text(&out));

    let out = run_mole(&["stop", "--namespace", &ns]);
    assert!(out.status.success(), "{}", text(&out));
    let keep = std::env::temp_dir().join(format!("mole-keep-{ns}"));
    let output = stack.wait_and_copy(&keep, Duration::from_secs(60));
    assert!(output.status.success(), "{}", logs(&keep));
    let s = summary(&keep);
    let log = |role: &str| {
        std::fs::read_to_string(keep.join(format!("logs/{role}.log"))).unwrap_or_default()
    };
    let (mapping_log, localization_log) = (log("mapping"), log("localization"));
    let _ = std::fs::remove_dir_all(&keep);
    assert!(
        mapping_log.contains("took over the running grids"),
        "{mapping_log}"
    );
    assert!(
        localization_log.contains("took over the running estimate"),
        "{localization_log}"
    );
    assert_eq!(s["exit_reason"], "stopped", "{s}");
    let swaps = s["swaps"].as_array().expect("swaps in summary.json");
    assert_eq!(swaps.len(), 4, "{s}");
    for swap in swaps {
        // "0 lost, 0 repeated" means something only over ticks the launcher saw.
        assert!(
            swap["ticks_observed"].as_u64().is_some_and(|n| n > 0),
            "{swap}"
        );
        assert_eq!(swap["steps_lost"], 0, "{swap}");
        assert_eq!(swap["steps_repeated"], 0, "{swap}");
    }
    assert_eq!(s["restarts"]["planning"], 0, "a swap is not a restart: {s}");
    let leftovers = left_behind(&before);
    assert!(leftovers.is_empty(), "left behind: {leftovers:?}");
}

/// A realtime swap reports its gap over the ticks it observed, and the run completes with the
/// estimate taken over.
#[test]
fn a_realtime_swap_reports_its_gap_and_the_run_completes() {
    let _serial = serial();
    let before = shm_files();
    let stack = Stack::start("swap-realtime", &["--mode", "realtime", "--ticks", "800"]);
    stack.wait_for_log("localization", "map received", Duration::from_secs(60));
    // Another estimator, which takes over the running estimate instead of starting over.
    let out = mole_swap(
        &stack.namespace,
        &["localization", "mole-localization --estimator pf"],
    );
    assert!(out.status.success(), "{}", text(&out));
    assert!(
        text(&out).contains("localization/pose silent for at most"),
        "{}",
        text(&out)
    );
    // Every topic of the stack is an iceoryx2 service listed with its documented type name
    // (what `iox2 service list` shows).
    let listed = mole_runtime::list_topics(&stack.namespace);
    for (topic, type_name) in mole_types::topics::all() {
        assert!(
            listed.contains(&(topic.to_string(), type_name.to_string())),
            "{topic} ({type_name}) is not listed: {listed:?}"
        );
    }
    let keep = std::env::temp_dir().join(format!("mole-keep-{}", stack.namespace));
    let output = stack.wait_and_copy(&keep, Duration::from_secs(120));
    assert!(output.status.success(), "{}", logs(&keep));
    let s = summary(&keep);
    let localization_log =
        std::fs::read_to_string(keep.join("logs/localization.log")).unwrap_or_default();
    let _ = std::fs::remove_dir_all(&keep);
    assert_eq!(s["ticks"], 800);
    let swaps = s["swaps"].as_array().expect("swaps in summary.json");
    assert_eq!(swaps.len(), 1, "{s}");
    let gap = swaps[0]["gap_ms"].as_f64().unwrap();
    let period = swaps[0]["median_interval_ms"].as_f64().unwrap();
    // Make before break: the pose never stops for long (no restart, no timeout); a bound of
    // a second is a correctness check (a lost role would stay silent), not a timing target.
    assert!(gap > 0.0 && gap < 1000.0, "gap {gap} ms");
    assert!(period > 0.0, "{s}");
    assert!(
        swaps[0]["ticks_observed"].as_u64().is_some_and(|n| n > 0),
        "{s}"
    );
    assert_eq!(s["restarts"]["localization"], 0, "a swap is not a restart");
    assert!(
        localization_log.contains("took over the running estimate"),
        "{localization_log}"
    );
    // Starting over at the start pose mid-run cost 0.9 m of RMSE; taking over costs nothing
    // the EKF's ~1 cm would notice. 0.2 m is a correctness bound, not a target.
    let rmse = s["localization_rmse_m"].as_f64().unwrap();
    assert!(rmse < 0.2, "localization RMSE {rmse} m after the swap");
    let leftovers = left_behind(&before);
    assert!(leftovers.is_empty(), "left behind: {leftovers:?}");
}

#[test]
fn swap_with_no_stack_in_the_namespace_is_bad_input() {
    let out = mole_swap(
        &unique_namespace("swap-none"),
        &["planning", "mole-planning"],
    );
    assert_eq!(out.status.code(), Some(2), "{}", text(&out));
    assert!(text(&out).contains("no stack is running"), "{}", text(&out));
}
