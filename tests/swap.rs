//! Hot swap through `mole swap` (stack/control): lockstep loses no step and no consumer handles
//! one twice, over ticks the launcher observed; realtime reports its gap, and every refusal
//! leaves the running stack untouched. The realtime run also checks that iceoryx2's service
//! listing shows every topic with its type name.

use mole_integration_tests::*;
use mole_types::graph::Swap;
use mole_types::{EndReason, EstimatorKind, GRAPH, PlannerKind, Role};
use std::process::Output;
use std::time::Duration;

fn mole_swap(namespace: &str, args: &[&str]) -> Output {
    let mut all = vec!["swap", "--namespace", namespace];
    all.extend_from_slice(args);
    run_mole(&all)
}

/// Whether a role's log shows its replacement going on from its predecessor's step output.
fn took_over(log: &str, role: Role) -> bool {
    let topic = role
        .spec()
        .step_output
        .expect("a swappable role has a step output");
    log.lines()
        .any(|line| line.contains("took over the last output") && line.contains(topic))
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
    stack.wait_for_log(Role::World.name(), "ready", Duration::from_secs(60));
    let ns = stack.namespace.clone();
    let (world, planning) = (Role::World.spec(), Role::Planning.spec());
    let Swap::Refused(why) = world.swap else {
        panic!("the graph lets the world be swapped");
    };

    // Refusals: exit 2, one line naming what was wrong.
    for (args, needle) in [
        (&[world.role.name(), world.program][..], why),
        (
            &["planer", planning.program][..],
            "no process has the role `planer`",
        ),
        (
            &[planning.role.name(), "./no/such/program"][..],
            "not found",
        ),
    ] {
        let out = mole_swap(&ns, args);
        assert_eq!(
            out.status.code(),
            Some(2),
            "{args:?}: {}",
            output_text(&out)
        );
        assert!(
            output_text(&out).contains(needle),
            "{args:?}: {}",
            output_text(&out)
        );
    }
    // A replacement that dies while starting: exit 1, and the old process keeps the role.
    let out = mole_swap(&ns, &[planning.role.name(), "/bin/false"]);
    assert_eq!(out.status.code(), Some(1), "{}", output_text(&out));
    assert!(
        output_text(&out).contains("keeps running"),
        "{}",
        output_text(&out)
    );

    // Real swaps of every swappable role, quoted commands and words. Mapping and
    // localization take over their predecessor's grids and estimate.
    let swappable: Vec<_> = GRAPH.iter().filter(|r| r.swap == Swap::Allowed).collect();
    for row in &swappable {
        let options = match row.role {
            Role::Planning => format!(" --planner {}", PlannerKind::RandomWalk),
            Role::Localization => format!(" --estimator {}", EstimatorKind::Pf),
            _ => String::new(),
        };
        let command = format!("{}{options}", row.program);
        let args = [row.role.name(), command.as_str()];
        let out = mole_swap(&ns, &args);
        assert!(out.status.success(), "{args:?}: {}", output_text(&out));
        assert!(
            output_text(&out).contains("lockstep: 0 steps lost, 0 repeated"),
            "{}\n{}",
            output_text(&out),
            logs(&stack.out)
        );
    }
    let out = run_mole(&["status", "--namespace", &ns]);
    assert!(out.status.success(), "{}", output_text(&out));
    let planning_line = format!("{} (pid", planning.role);
    assert!(
        output_text(&out).contains(&planning_line),
        "{}",
        output_text(&out)
    );

    let out = run_mole(&["stop", "--namespace", &ns]);
    assert!(out.status.success(), "{}", output_text(&out));
    let keep = std::env::temp_dir().join(format!("mole-keep-{ns}"));
    let output = stack.wait_and_copy(&keep, Duration::from_secs(60));
    assert!(output.status.success(), "{}", logs(&keep));
    let s = summary(&keep);
    let log = |role: &str| {
        std::fs::read_to_string(keep.join(format!("logs/{role}.log"))).unwrap_or_default()
    };
    let (mapping_log, localization_log) =
        (log(Role::Mapping.name()), log(Role::Localization.name()));
    let _ = std::fs::remove_dir_all(&keep);
    assert!(took_over(&mapping_log, Role::Mapping), "{mapping_log}");
    assert!(
        took_over(&localization_log, Role::Localization),
        "{localization_log}"
    );
    assert_eq!(s.exit_reason, EndReason::Stopped.name(), "{s:#?}");
    let swapped: Vec<&str> = s.swaps.iter().map(|w| w.role.as_str()).collect();
    let expected: Vec<&str> = swappable.iter().map(|r| r.role.name()).collect();
    assert_eq!(swapped, expected, "{s:#?}");
    for swap in &s.swaps {
        // "0 lost, 0 repeated" means something only over ticks the launcher saw.
        assert!(swap.ticks_observed > 0, "{swap:?}");
        assert_eq!((swap.steps_lost, swap.steps_repeated), (0, 0), "{swap:?}");
    }
    for row in &swappable {
        let role = row.role.name();
        assert_eq!(
            s.restarts.get(role),
            Some(&0),
            "a swap is not a restart: {s:#?}"
        );
    }
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
    let localization = Role::Localization.spec();
    stack.wait_for_log(
        localization.role.name(),
        "map received",
        Duration::from_secs(60),
    );
    // Another estimator, which takes over the running estimate instead of starting over.
    let command = format!("{} --estimator {}", localization.program, EstimatorKind::Pf);
    let out = mole_swap(&stack.namespace, &[localization.role.name(), &command]);
    assert!(out.status.success(), "{}", output_text(&out));
    assert!(
        output_text(&out).contains("localization/pose silent for at most"),
        "{}",
        output_text(&out)
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
        std::fs::read_to_string(keep.join("logs").join(format!("{}.log", localization.role)))
            .unwrap_or_default();
    let _ = std::fs::remove_dir_all(&keep);
    assert_eq!(s.ticks, 800);
    let [swap] = &s.swaps[..] else {
        panic!("one swap in summary.json: {s:#?}");
    };
    // Make before break: the pose skips few of the world's ticks (a second's worth at most;
    // a role lost for a restart or a timeout would skip many more), counted in ticks.
    let ticks_a_second = (s.ticks as f64 / s.sim_time_s).round() as u64;
    assert!(swap.gap_ticks < ticks_a_second, "{s:#?}");
    assert!(swap.gap_ms > 0.0 && swap.median_interval_ms > 0.0, "{s:#?}");
    assert!(swap.ticks_observed > 0, "{s:#?}");
    assert_eq!(
        s.restarts.get(localization.role.name()),
        Some(&0),
        "a swap is not a restart"
    );
    assert!(
        took_over(&localization_log, Role::Localization),
        "{localization_log}"
    );
    // Starting over at the start pose mid-run cost 0.9 m of RMSE; taking over costs nothing
    // the EKF's ~1 cm would notice. 0.2 m is a correctness bound, not a target.
    let rmse = s.localization_rmse_m.expect("an RMSE");
    assert!(rmse < 0.2, "localization RMSE {rmse} m after the swap");
    let leftovers = left_behind(&before);
    assert!(leftovers.is_empty(), "left behind: {leftovers:?}");
}

#[test]
fn swap_with_no_stack_in_the_namespace_is_bad_input() {
    let planning = Role::Planning.spec();
    let out = mole_swap(
        &unique_namespace("swap-none"),
        &[planning.role.name(), planning.program],
    );
    assert_eq!(out.status.code(), Some(2), "{}", output_text(&out));
    assert!(
        output_text(&out).contains("no stack is running"),
        "{}",
        output_text(&out)
    );
}
