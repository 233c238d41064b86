//! The whole stack, started by `mole up` as a user would: lockstep runs, determinism, Ctrl-C,
//! and a process killed mid-run.

use mole_integration_tests::*;
use mole_types::{
    ClockMode, EndReason, EstimatorKind, GRAPH, PACE_PAUSE, PACE_RUN, PACE_STEP, PlannerKind, Role,
    Truth, topics,
};
use nix::sys::signal::{Signal, kill};
use nix::unistd::Pid;
use std::time::Duration;

const RUN_TIMEOUT: Duration = Duration::from_secs(240);

fn lockstep_run(test: &str, ticks: u64, seed: u64) -> Summary {
    let ticks = ticks.to_string();
    let seed = seed.to_string();
    let stack = Stack::start(
        test,
        &["--mode", "lockstep", "--ticks", &ticks, "--seed", &seed],
    );
    let out = stack.out.clone();
    let namespace = stack.namespace.clone();
    let output = stack_wait_keep(stack, &out);
    assert!(
        output.0.status.success(),
        "mole up failed: {}\n{}",
        String::from_utf8_lossy(&output.0.stderr),
        output.1
    );
    assert!(processes_of(&namespace).is_empty(), "processes left behind");
    output.2.expect("a summary")
}

/// Waits, and reads the summary and logs before the stack's directory is removed.
fn stack_wait_keep(
    stack: Stack,
    out: &std::path::Path,
) -> (std::process::Output, String, Option<Summary>) {
    let keep = out.with_extension("kept");
    let _ = std::fs::remove_dir_all(&keep);
    let output = stack.wait_and_copy(&keep, RUN_TIMEOUT);
    let logs = logs(&keep);
    let summary = keep.join("summary.json").exists().then(|| summary(&keep));
    let _ = std::fs::remove_dir_all(&keep);
    (output, logs, summary)
}

/// A summary value that must be there and finite.
fn finite(summary: &Summary, field: &str, value: Option<f64>) -> f64 {
    match value {
        Some(v) if v.is_finite() => v,
        _ => panic!("summary field `{field}` is {value:?}: {summary:#?}"),
    }
}

#[test]
fn lockstep_run_explores_without_penetrating_and_reports_every_field() {
    let _serial = serial();
    let before = shm_files();
    let short = lockstep_run("short", 300, 11);
    let long = lockstep_run("long", 3000, 11);

    assert_eq!(long.ticks, 3000, "{long:#?}");
    assert_eq!(long.mode, ClockMode::Lockstep.name());
    assert_eq!(long.exit_reason, EndReason::Ticks.name());
    assert!(long.path_length_m > 2.0, "the robot moved: {long:#?}");
    assert!(long.max_penetration_m <= 0.001, "{long:#?}");
    assert!(
        long.coverage > short.coverage + 0.05,
        "coverage rises: {} then {}",
        short.coverage,
        long.coverage
    );
    // Contact precision is undefined (null) while the robot has touched nothing, which
    // bounce-back on lidar usually achieves; the dark-room test checks it.
    assert!(long.contact_map_precision.is_none_or(f64::is_finite));
    for (field, value) in [
        ("sim_time_s", long.sim_time_s),
        ("wall_time_s", long.wall_time_s),
        ("path_length_m", long.path_length_m),
        ("coverage", long.coverage),
        ("max_penetration_m", long.max_penetration_m),
    ] {
        finite(&long, field, Some(value));
    }
    finite(&long, "map_iou", long.map_iou);
    finite(&long, "localization_rmse_m", long.localization_rmse_m);
    finite(&long, "launcher_wall_time_s", long.launcher_wall_time_s);
    assert_eq!(long.planner, PlannerKind::RandomWalk.name());
    assert_eq!(long.estimator, EstimatorKind::Ekf.name());
    let latency = &long.loop_latency_us;
    for (p, value) in [
        ("p50", latency.p50),
        ("p99", latency.p99),
        ("max", latency.max),
    ] {
        finite(&long, p, value);
    }
    assert!(
        long.topics.contains_key(topics::WORLD_TRUTH.name),
        "{long:#?}"
    );
    assert!(long.restarts.values().all(|n| *n == 0), "{long:#?}");
    assert_eq!(
        left_behind(&before),
        Vec::<String>::new(),
        "shared memory left behind"
    );
}

#[test]
fn two_lockstep_runs_with_the_same_seed_are_identical() {
    let _serial = serial();
    let first = lockstep_run("det-a", 1500, 42);
    let second = lockstep_run("det-b", 1500, 42);
    let other = lockstep_run("det-c", 1500, 43);
    assert_eq!(deterministic(&first), deterministic(&second));
    assert_eq!(first.grid_hash, second.grid_hash);
    assert_eq!(first.contact_hash, second.contact_hash);
    assert_ne!(
        first.grid_hash, other.grid_hash,
        "another seed gives another run"
    );
}

#[test]
fn ctrl_c_stops_everything_and_leaves_nothing_behind() {
    let _serial = serial();
    let before = shm_files();
    let stack = Stack::start("ctrlc", &["--mode", "realtime", "--ticks", "100000"]);
    stack.wait_for_log(Role::World.name(), "ready", Duration::from_secs(60));
    std::thread::sleep(Duration::from_millis(1500));
    let namespace = stack.namespace.clone();
    // mole top attaches to the running stack and shows every process and topic.
    let top = run_mole(&["top", "--namespace", &namespace, "--once"]);
    let screen = String::from_utf8_lossy(&top.stdout);
    assert!(
        top.status.success(),
        "{}",
        String::from_utf8_lossy(&top.stderr)
    );
    let roles = GRAPH.iter().map(|r| r.role.name());
    let needles = [
        topics::WORLD_TRUTH.name,
        topics::PLANNING_CMD.name,
        "running",
    ];
    for needle in roles.chain(needles) {
        assert!(
            screen.contains(needle),
            "mole top shows {needle}:\n{screen}"
        );
    }
    let out = stack.out.clone();
    kill(Pid::from_raw(stack.pid() as i32), Signal::SIGINT).expect("send SIGINT");
    let (output, logs, summary) = stack_wait_keep(stack, &out);
    assert!(
        output.status.success(),
        "exit status {:?}\n{logs}",
        output.status
    );
    assert!(
        processes_of(&namespace).is_empty(),
        "a child outlived the launcher"
    );
    let summary = summary.expect("a summary");
    assert_eq!(summary.exit_reason, "interrupted", "{summary:#?}");
    assert_eq!(
        left_behind(&before),
        Vec::<String>::new(),
        "shared memory left behind"
    );
}

#[test]
fn a_killed_process_is_restarted_and_the_run_completes() {
    let _serial = serial();
    let stack = Stack::start("restart", &["--mode", "realtime", "--ticks", "600"]);
    stack.wait_for_log(Role::World.name(), "ready", Duration::from_secs(60));
    std::thread::sleep(Duration::from_millis(1000));
    let sensing = Role::Sensing.spec().program;
    let victim = processes_of(&stack.namespace)
        .into_iter()
        .find(|pid| {
            std::fs::read_to_string(format!("/proc/{pid}/comm")).is_ok_and(|c| c.trim() == sensing)
        })
        .expect("a running sensing process");
    kill(Pid::from_raw(victim as i32), Signal::SIGKILL).expect("SIGKILL sensing");
    let out = stack.out.clone();
    let (output, logs, summary) = stack_wait_keep(stack, &out);
    assert!(output.status.success(), "{logs}");
    let summary = summary.expect("a summary");
    assert_eq!(summary.restarts[Role::Sensing.name()], 1, "{summary:#?}");
    assert_eq!(summary.exit_reason, EndReason::Ticks.name());
    assert_eq!(summary.ticks, 600);
}

#[test]
fn in_the_dark_room_touch_alone_builds_the_contact_grid() {
    let _serial = serial();
    let stack = Stack::start(
        "dark",
        &[
            "--mode",
            "lockstep",
            "--ticks",
            "6000",
            "--seed",
            "1",
            "--scenario",
            "scenarios/dark_room.toml",
        ],
    );
    let out = stack.out.clone();
    let (output, logs, summary) = stack_wait_keep(stack, &out);
    assert!(output.status.success(), "{logs}");
    let summary = summary.expect("a summary");
    assert!(
        summary.contact_events > 0,
        "the robot touched something: {summary:#?}"
    );
    let precision = finite(
        &summary,
        "contact_map_precision",
        summary.contact_map_precision,
    );
    assert!(
        precision >= 0.9,
        "contact cells lie on true obstacles: {precision}"
    );
    assert!(
        summary.coverage > 0.02,
        "the footprint alone explores: {summary:#?}"
    );
}

/// Two lockstep stacks with different seeds, stepping in turns in two namespaces, each give
/// exactly their solo run of the same seed: neither reads, steals or cleans away anything of the
/// other. Both are held by the operator's pace once they are up, then step 50 ticks at a time
/// in turns (while one steps, the other is alive and mid-run), then run to their end.
#[test]
fn two_stacks_in_two_namespaces_run_side_by_side_without_interfering() {
    let _serial = serial();
    let before = shm_files();
    let ticks = 400;
    let args = |seed: &'static str| {
        [
            "--mode".to_string(),
            "lockstep".into(),
            "--ticks".into(),
            ticks.to_string(),
            "--seed".into(),
            seed.into(),
            "--estimator".into(),
            EstimatorKind::Bayes.name().into(),
        ]
    };
    let start = |test: &str, seed| {
        let args = args(seed);
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        Stack::start(test, &args)
    };
    let alone = |test: &str, seed| {
        let stack = start(test, seed);
        let out = stack.out.clone();
        let (output, logs, summary) = stack_wait_keep(stack, &out);
        assert!(output.status.success(), "{test}: {logs}");
        summary.expect("a summary")
    };
    let (alone_a, alone_b) = (alone("alone-a", "5"), alone("alone-b", "6"));
    assert_ne!(
        alone_a.grid_hash, alone_b.grid_hash,
        "the two seeds give two different runs, so a crossed topic would show"
    );

    let (a, b) = (start("robot-a", "5"), start("robot-b", "6"));
    let mut operators = [&a, &b].map(|stack| {
        let mut operator = Operator::join(stack, ClockMode::Lockstep);
        operator.send_pace(PACE_PAUSE, 0);
        operator
    });
    let held = |operator: &mut Operator| {
        operator.follow(Duration::from_millis(300));
        operator.tick()
    };
    let mut at = [held(&mut operators[0]), held(&mut operators[1])];
    const TURN: u32 = 50;
    for round in 0..3 {
        for i in 0..2 {
            let other = 1 - i;
            assert!(at[i] + u64::from(TURN) < ticks, "round {round}: {at:?}");
            operators[i].send_pace(PACE_STEP, TURN);
            let goal = at[i] + u64::from(TURN);
            operators[i].follow_until("a turn", Duration::from_secs(60), |o| o.tick() >= goal);
            at[i] = held(&mut operators[i]);
            assert_eq!(
                at[i], goal,
                "round {round}: stack {i} took its turn and held"
            );
            assert_eq!(held(&mut operators[other]), at[other], "the other one held");
        }
    }
    for operator in &mut operators {
        operator.send_pace(PACE_RUN, 0);
    }
    for operator in &mut operators {
        operator.follow_until("the run's end", Duration::from_secs(300), |o| {
            o.truth.latest().is_some_and(Truth::is_end)
        });
    }
    drop(operators);
    let (namespace_a, namespace_b) = (a.namespace.clone(), b.namespace.clone());
    let (out_a, out_b) = (a.out.clone(), b.out.clone());
    let (output_a, logs_a, side_a) = stack_wait_keep(a, &out_a);
    let (output_b, logs_b, side_b) = stack_wait_keep(b, &out_b);
    assert!(output_a.status.success(), "{logs_a}");
    assert!(output_b.status.success(), "{logs_b}");
    let (side_a, side_b) = (side_a.expect("a summary"), side_b.expect("a summary"));
    for (alone, side, name) in [(&alone_a, &side_a, "a"), (&alone_b, &side_b, "b")] {
        assert_eq!(side.ticks, ticks, "{name}: {side:#?}");
        assert_eq!(side.grid_hash, alone.grid_hash, "{name}");
        assert_eq!(side.contact_hash, alone.contact_hash, "{name}");
        assert_eq!(
            differing_fields(&deterministic(side), &deterministic(alone)),
            Vec::<String>::new(),
            "{name}"
        );
    }
    assert!(processes_of(&namespace_a).is_empty() && processes_of(&namespace_b).is_empty());
    assert_eq!(left_behind(&before), Vec::<String>::new(), "left behind");
}

/// Position RMSE bounds per estimator on 1500 lockstep steps of the default scenario: a quarter
/// of the robot radius (5 cm) for the filters that fuse beacons, which keeps the maps they
/// build within one grid cell; the KF sees only the position fix every second, so it gets 12 cm.
/// The particle filter with KLD-sampling keeps the same bound with a smaller set, whose size
/// over the run summary.json reports.
#[test]
fn every_estimator_localizes_within_its_bound() {
    let _serial = serial();
    let kld = ["--set", "localization.pf.kld=true"];
    for (estimator, bound, extra) in [
        (EstimatorKind::Ekf, 0.05, &[][..]),
        (EstimatorKind::Pf, 0.05, &[][..]),
        (EstimatorKind::Pf, 0.05, &kld[..]),
        (EstimatorKind::Bayes, 0.08, &[][..]),
        (EstimatorKind::Kf, 0.12, &[][..]),
    ] {
        let mut args = vec![
            "--mode",
            "lockstep",
            "--ticks",
            "1500",
            "--seed",
            "3",
            "--estimator",
            estimator.name(),
        ];
        args.extend_from_slice(extra);
        let stack = Stack::start(&format!("est-{estimator}-{}", extra.len()), &args);
        let out = stack.out.clone();
        let (output, logs, summary) = stack_wait_keep(stack, &out);
        assert!(output.status.success(), "{estimator}: {logs}");
        let summary = summary.expect("a summary");
        assert_eq!(summary.estimator, estimator.name());
        let rmse = finite(&summary, "localization_rmse_m", summary.localization_rmse_m);
        assert!(
            rmse < bound,
            "{estimator} {extra:?}: RMSE {rmse} m ≥ {bound} m"
        );
        finite(&summary, "mean_nees", summary.mean_nees);
        let particles = summary.particles.as_ref();
        match (estimator, extra.is_empty()) {
            (EstimatorKind::Pf, true) => {
                let p = particles.expect("the particle counts");
                assert_eq!((p.min, p.max, p.series.len()), (10_000, 10_000, 1), "{p:?}");
            }
            (EstimatorKind::Pf, false) => {
                // Sized by the belief from the first resampling on: the beacons keep it tight,
                // so the set stays far below the most, 10,000.
                let p = particles.expect("the particle counts");
                assert!(p.max <= 10_000 && p.mean < 5_000.0, "{p:?}");
            }
            _ => assert!(particles.is_none(), "{estimator}: {particles:?}"),
        }
    }
}

/// A process that refuses its input (here a swapped-in planner named wrongly, which the
/// launcher cannot check) fails the run with exit 2, its own message shown, and is not retried.
#[test]
fn a_process_that_refuses_its_input_fails_the_run_with_exit_2_without_restarts() {
    let _serial = serial();
    let planning = Role::Planning.spec();
    let swap = format!("{}={} --planner teleport", planning.role, planning.program);
    let stack = Stack::start(
        "child-refuses",
        &["--mode", "lockstep", "--ticks", "100", "--swap", &swap],
    );
    let out = stack.out.clone();
    let (output, logs, _) = stack_wait_keep(stack, &out);
    let err = String::from_utf8_lossy(&output.stderr);
    assert_eq!(output.status.code(), Some(2), "{err}\n{logs}");
    assert!(
        err.contains(planning.role.name()) && err.contains("teleport"),
        "{err}"
    );
    assert!(
        !logs.contains("restart"),
        "bad input is not retried:\n{logs}"
    );
}

/// `mole bench stack` splits each process's CPU per step: its own step function, the runtime
/// around it, and the kernel's share; the first two add up to the process's CPU.
#[test]
fn bench_stack_splits_each_process_cpu_per_step() {
    let _serial = serial();
    let namespace = unique_namespace("benchsplit");
    let out = std::env::temp_dir().join(format!("mole-{namespace}"));
    let json = out.with_extension("json");
    let output = std::process::Command::new(bin_dir().join("mole"))
        .current_dir(workspace())
        .env_remove("CARGO")
        .env_remove("CARGO_MANIFEST_DIR")
        .args(["bench", "stack", "--mode", "lockstep", "--ticks", "2000"])
        .args(["--namespace", &namespace, "--quiet", "--out"])
        .arg(&out)
        .arg("--json")
        .arg(&json)
        .stdin(std::process::Stdio::null())
        .output()
        .expect("run mole bench stack");
    let text = std::fs::read_to_string(&json);
    let _ = (std::fs::remove_dir_all(&out), std::fs::remove_file(&json));
    assert!(
        output.status.success(),
        "mole bench stack failed: {}",
        String::from_utf8_lossy(&output.stderr)
    );
    assert!(processes_of(&namespace).is_empty(), "processes left behind");
    let report: serde_json::Value = serde_json::from_str(&text.expect("the JSON")).expect("JSON");
    let stdout = String::from_utf8_lossy(&output.stdout);
    assert!(stdout.contains("around µs"), "{stdout}");
    let processes = report["processes"].as_array().expect("processes");
    let roles: Vec<&str> = processes
        .iter()
        .filter_map(|p| p["role"].as_str())
        .collect();
    for role in Role::ALL {
        assert!(
            roles.contains(&role.name()),
            "{role:?} missing from {roles:?}"
        );
    }
    for p in processes {
        let cost = &p["per_step"];
        let us = |field: &str| {
            cost[field]
                .as_f64()
                .unwrap_or_else(|| panic!("{field}: {p}"))
        };
        let (step, around, kernel) = (us("step_us"), us("runtime_us"), us("kernel_us"));
        assert!(step > 0.0 && around > 0.0 && kernel >= 0.0, "{p}");
        assert!(kernel <= step + around, "{p}");
        let steps = p["steps"].as_f64().expect("steps");
        let cpu_us = p["cpu_s"].as_f64().expect("cpu_s") * 1e6;
        assert!(
            ((step + around) * steps - cpu_us).abs() <= 1e-6 * cpu_us + 1.0,
            "{p}"
        );
    }
}
