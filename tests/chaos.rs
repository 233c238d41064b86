//! Faults on demand, as a user injects them into a running stack: `mole fault` kills or stops a
//! role, delays, drops or corrupts a topic's samples, and `mole fault chaos` injects a seeded
//! sequence of them. Each fault is carried out, counted in summary.json and recorded as an
//! event; bad requests are refused with exit 2; a chaos session ends its run without a stall
//! or a panic and leaves nothing behind.

use mole_integration_tests::*;
use mole_types::Role;
use std::process::Output;
use std::time::{Duration, Instant};

const RUN_TIMEOUT: Duration = Duration::from_secs(300);

/// `mole fault ARGS` against the stack in `namespace`.
fn fault(namespace: &str, args: &[&str]) -> Output {
    let mut all = vec!["fault", "--namespace", namespace];
    all.extend_from_slice(args);
    run_mole(&all)
}

/// Injects a fault that must be accepted; returns what `mole fault` said.
fn inject(stack: &Stack, args: &[&str]) -> String {
    let output = fault(&stack.namespace, args);
    let said = output_text(&output);
    assert!(
        output.status.success(),
        "mole fault {args:?}: {said}\n{}",
        logs(&stack.out)
    );
    said
}

/// A finished run: how `mole up` ended, its summary and its logs.
struct Finished {
    output: Output,
    summary: Summary,
    logs: String,
}

/// Waits for the stack to end and reads what it left.
fn finish(stack: Stack) -> Finished {
    let keep = stack.out.with_extension("kept");
    let output = stack.wait_and_copy(&keep, RUN_TIMEOUT);
    let logs = logs(&keep);
    let summary = summary(&keep);
    let _ = std::fs::remove_dir_all(&keep);
    Finished {
        output,
        summary,
        logs,
    }
}

/// The state letter of a process (`R`, `S`, `T` when stopped...), `None` once it is gone.
fn state_of(pid: u32) -> Option<char> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    stat.rsplit(')').next()?.trim_start().chars().next()
}

/// Waits until `pid`'s state is `wanted` (or not, with `is = false`).
fn wait_for_state(pid: u32, wanted: char, is: bool, timeout: Duration) {
    let deadline = Instant::now() + timeout;
    while state_of(pid).is_some_and(|s| s == wanted) != is {
        assert!(
            Instant::now() < deadline,
            "pid {pid} never {}{wanted}",
            if is { "" } else { "left " }
        );
        std::thread::sleep(Duration::from_millis(5));
    }
}

/// Without a stack, with a role or topic the stack does not have, with a duration out of range,
/// or a drop in lockstep: refused with exit 2 and one line saying why, nothing injected.
#[test]
fn bad_fault_requests_are_refused_and_inject_nothing() {
    let _serial = serial();
    let output = fault("t-nobody-runs-here", &["kill", "planning"]);
    assert_eq!(output.status.code(), Some(2), "{}", output_text(&output));
    assert!(output_text(&output).contains("no stack runs in namespace `t-nobody-runs-here`"));

    let stack = Stack::start("fault-bad", &["--mode", "lockstep", "--ticks", "1000000"]);
    stack.wait_for_log(Role::World.name(), "ready", Duration::from_secs(60));
    for (args, why) in [
        (
            &["kill", "navigator"][..],
            "unknown role `navigator`, expected one of: world",
        ),
        (
            &["delay", "sensing/scna", "--by", "5", "--for", "1"],
            "unknown topic `sensing/scna`",
        ),
        (
            &["stop", "planning", "--for", "0"],
            "--for: expected a duration",
        ),
        (
            &["corrupt", "sensing/scan", "--fraction", "2", "--for", "1"],
            "--fraction",
        ),
        (
            &["drop", "sensing/scan", "--for", "1"],
            "drop needs a realtime stack",
        ),
    ] {
        let output = fault(&stack.namespace, args);
        assert_eq!(
            output.status.code(),
            Some(2),
            "{args:?}: {}",
            output_text(&output)
        );
        assert!(
            output_text(&output).contains(why),
            "{args:?}: {}",
            output_text(&output)
        );
    }
    signal(stack.pid(), nix::sys::signal::Signal::SIGINT);
    let run = finish(stack);
    assert!(run.summary.faults.is_empty(), "{:#?}", run.summary.faults);
}

/// In lockstep a delay only slows the run, and a corruption is caught by every reader's
/// validation while the good sample follows it: the run is the unfaulted one, tick for tick,
/// with the corrupted samples counted invalid.
#[test]
fn lockstep_delays_and_corruptions_change_nothing_but_the_invalid_counts() {
    let _serial = serial();
    let args = ["--mode", "lockstep", "--ticks", "8000", "--seed", "2"];
    let plain = finish(Stack::start("fault-plain", &args));
    let stack = Stack::start("fault-lockstep", &args);
    stack.wait_for_log(Role::World.name(), "ready", Duration::from_secs(60));
    inject(
        &stack,
        &["delay", "sensing/scan", "--by", "2", "--for", "1"],
    );
    inject(
        &stack,
        &[
            "corrupt",
            "localization/pose",
            "--fraction",
            "0.5",
            "--for",
            "1",
        ],
    );
    inject(
        &stack,
        &["corrupt", "planning/cmd", "--fraction", "1", "--for", "0.5"],
    );
    let faulted = finish(stack);
    assert!(faulted.output.status.success(), "{}", faulted.logs);
    let kinds: Vec<&str> = faulted
        .summary
        .faults
        .iter()
        .map(|f| f.kind.as_str())
        .collect();
    assert_eq!(kinds, ["delay", "corrupt", "corrupt"]);
    for topic in ["localization/pose", "planning/cmd"] {
        let invalid = faulted.summary.topics.get(topic).map_or(0, |t| t.invalid);
        assert!(
            invalid > 0,
            "{topic}: no corrupted sample was caught: {:#?}",
            faulted.summary.topics
        );
    }
    let comparable = |s: &Summary| Summary {
        faults: Vec::new(),
        ..deterministic(s)
    };
    assert_eq!(
        differing_fields(&comparable(&faulted.summary), &comparable(&plain.summary)),
        Vec::<String>::new(),
        "the faulted lockstep run differs from the plain one"
    );
}

/// In realtime a drop loses samples, which their readers count from the sequence gaps; a
/// corruption is refused by every reader; a kill is a restart like any crash; each fault is an
/// event of the run's recording.
#[test]
fn realtime_drops_corruptions_and_kills_are_counted() {
    let _serial = serial();
    let recording = TempDir::new("fault-recording");
    let file = recording.0.join("faults.mcap");
    let stack = Stack::start(
        "fault-realtime",
        &[
            "--mode",
            "realtime",
            "--ticks",
            "100000",
            "--record",
            &file.to_string_lossy(),
        ],
    );
    stack.wait_for_log(Role::World.name(), "ready", Duration::from_secs(60));
    std::thread::sleep(Duration::from_millis(500));
    let said = inject(
        &stack,
        &["drop", "sensing/odom", "--fraction", "0.5", "--for", "1"],
    );
    assert!(said.contains("fault 1 at tick "), "{said}");
    inject(
        &stack,
        &["corrupt", "sensing/scan", "--fraction", "0.5", "--for", "1"],
    );
    let old = pid_of(&stack.namespace, Role::Planning.spec().program).expect("planning runs");
    inject(&stack, &["kill", "planning"]);
    wait_for_new_pid(
        &stack.namespace,
        Role::Planning.spec().program,
        Some(old),
        RUN_TIMEOUT,
        &stack.out,
    );
    std::thread::sleep(Duration::from_millis(1500));
    signal(stack.pid(), nix::sys::signal::Signal::SIGINT);
    let run = finish(stack);
    assert!(run.output.status.success(), "{}", run.logs);
    let topic = |name: &str| run.summary.topics.get(name).cloned().unwrap_or_default();
    assert!(
        topic("sensing/odom").dropped > 0,
        "{:#?}",
        run.summary.topics
    );
    assert!(
        topic("sensing/scan").invalid > 0,
        "{:#?}",
        run.summary.topics
    );
    assert_eq!(run.summary.restarts.get(Role::Planning.name()), Some(&1));
    assert_eq!(run.summary.faults.len(), 3, "{:#?}", run.summary.faults);
    // Each fault is an event of the recording, with its number, kind and target.
    let bytes = std::fs::read(&file).expect("a recording");
    let events: Vec<(u64, String, String)> = mcap::MessageStream::new(&bytes)
        .expect("an MCAP file")
        .map(|m| m.expect("a finished recording reads to its end"))
        .filter(|m| m.channel.topic == "stack/events")
        .map(|m| serde_json::from_slice::<serde_json::Value>(&m.data).expect("JSON"))
        .filter(|e| e["kind"] == "fault")
        .map(|e| {
            let text = |key: &str| e[key].as_str().unwrap_or_default().to_string();
            (e["id"].as_u64().unwrap_or(0), text("fault"), text("target"))
        })
        .collect();
    let expected = [
        (1, "drop", "sensing/odom"),
        (2, "corrupt", "sensing/scan"),
        (3, "kill", "planning"),
    ]
    .map(|(id, kind, target)| (id, kind.to_string(), target.to_string()));
    assert_eq!(events, expected);
}

/// A stopped process goes on where it was (the same pid, no restart) when its stop ends; one
/// stopped past the launcher's hang detection is found hung and restarted.
#[test]
fn a_stopped_role_goes_on_and_one_stopped_too_long_is_found_hung() {
    let _serial = serial();
    let stack = Stack::start("fault-stop", &["--mode", "realtime", "--ticks", "100000"]);
    stack.wait_for_log(Role::World.name(), "ready", Duration::from_secs(60));
    let program = Role::Localization.spec().program;
    let pid = pid_of(&stack.namespace, program).expect("localization runs");
    inject(&stack, &["stop", "localization", "--for", "1"]);
    wait_for_state(pid, 'T', true, Duration::from_secs(10));
    wait_for_state(pid, 'T', false, Duration::from_secs(10));
    assert_eq!(
        pid_of(&stack.namespace, program),
        Some(pid),
        "the same process goes on"
    );
    inject(&stack, &["stop", "mapping", "--for", "8"]);
    let mapping = pid_of(&stack.namespace, Role::Mapping.spec().program).expect("mapping runs");
    wait_for_new_pid(
        &stack.namespace,
        Role::Mapping.spec().program,
        Some(mapping),
        RUN_TIMEOUT,
        &stack.out,
    );
    signal(stack.pid(), nix::sys::signal::Signal::SIGINT);
    let run = finish(stack);
    let s = &run.summary;
    assert_eq!(
        s.restarts.get(Role::Localization.name()),
        Some(&0),
        "{s:#?}"
    );
    assert_eq!(s.hangs.get(Role::Localization.name()), None, "{s:#?}");
    assert_eq!(s.hangs.get(Role::Mapping.name()), Some(&1), "{s:#?}");
    assert_eq!(s.restarts.get(Role::Mapping.name()), Some(&1), "{s:#?}");
}

/// A chaos session in each clock mode: a seeded sequence of every kind of fault on every role
/// and topic; the run ends as it was asked to (no stall, no panic, every kill a restart), and
/// nothing of the stack is left in shared memory.
#[test]
fn a_chaos_session_ends_its_run_cleanly_in_either_clock_mode() {
    let _serial = serial();
    for mode in ["realtime", "lockstep"] {
        let before = shm_files();
        let stack = Stack::start(
            "chaos",
            &["--mode", mode, "--ticks", "100000000", "--seed", "5"],
        );
        stack.wait_for_log(Role::World.name(), "ready", Duration::from_secs(60));
        let said = inject(
            &stack,
            &["chaos", "--duration", "20", "--seed", "5", "--every", "1.5"],
        );
        signal(stack.pid(), nix::sys::signal::Signal::SIGINT);
        let namespace = stack.namespace.clone();
        let run = finish(stack);
        println!("{mode}:\n{said}");
        assert!(
            run.output.status.success(),
            "{mode}: {}\n{}",
            output_text(&run.output),
            run.logs
        );
        assert_eq!(run.summary.exit_reason, "interrupted", "{mode}");
        assert!(!run.logs.contains("panicked"), "{mode}: {}", run.logs);
        let kills = run
            .summary
            .faults
            .iter()
            .filter(|f| f.kind == "kill")
            .count() as u32;
        let restarts: u32 = run.summary.restarts.values().sum();
        let hangs: u32 = run.summary.hangs.values().sum();
        assert!(
            run.summary.faults.len() >= 5,
            "{mode}: {:#?}",
            run.summary.faults
        );
        assert_eq!(
            restarts,
            kills + hangs,
            "{mode}: every kill and hang a restart: {:#?}",
            run.summary
        );
        assert_eq!(processes_of(&namespace), Vec::<u32>::new());
        assert_eq!(left_behind(&before), Vec::<String>::new(), "{mode}");
    }
}
