use super::*;

fn temp_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("mole-sup-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    d
}

fn policy(when: RestartWhen, backoff_ms: u64, max: u32) -> RestartPolicy {
    RestartPolicy {
        policy: when,
        backoff_ms,
        max_backoff_ms: 10_000,
        max,
        stable_after_ms: 10_000,
    }
}

fn sh(role: &str, script: &str, restart: RestartPolicy, dir: &Path) -> ChildSpec {
    ChildSpec {
        role: role.to_owned(),
        program: PathBuf::from("/bin/sh"),
        args: vec!["-c".to_owned(), script.to_owned()],
        env: vec![("MOLE_TEST".to_owned(), "yes".to_owned())],
        restart,
        log_path: dir.join("logs").join(format!("{role}.log")),
        cwd: None,
    }
}

/// Polls until `done` says so or 10 s pass; returns the events with the time each was seen.
fn poll_until(
    sup: &mut Supervisor,
    mut done: impl FnMut(&[(Instant, SupervisorEvent)]) -> bool,
) -> Vec<(Instant, SupervisorEvent)> {
    let deadline = Instant::now() + Duration::from_secs(10);
    let mut seen = Vec::new();
    while Instant::now() < deadline {
        for e in sup.poll() {
            seen.push((Instant::now(), e));
        }
        if done(&seen) {
            return seen;
        }
        std::thread::sleep(Duration::from_millis(2));
    }
    panic!("timed out; events so far: {seen:?}");
}

fn gone(pid: u32) -> bool {
    kill(Pid::from_raw(pid as i32), None) == Err(Errno::ESRCH)
}

/// Processes of group `pgid` that are not zombies (an orphaned grandchild may stay a zombie when
/// the container's init does not reap it; it no longer runs).
fn live_group_members(pgid: u32) -> Vec<u32> {
    let mut live = Vec::new();
    for entry in std::fs::read_dir("/proc").unwrap().flatten() {
        let Ok(pid) = entry.file_name().to_string_lossy().parse::<u32>() else {
            continue;
        };
        let Ok(stat) = std::fs::read_to_string(entry.path().join("stat")) else {
            continue;
        };
        // pid (comm) state ppid pgrp ...; comm may contain spaces, so split after the last ')'.
        let Some((_, rest)) = stat.rsplit_once(')') else {
            continue;
        };
        let fields: Vec<&str> = rest.split_whitespace().collect();
        if fields.len() > 2 && fields[2] == pgid.to_string() && fields[0] != "Z" {
            live.push(pid);
        }
    }
    live
}

/// Group members still alive after waiting up to 2 s: a signal to a group is delivered at once,
/// but a grandchild finishes dying asynchronously, later still on a loaded 2-core machine.
fn group_members_after_grace(pgid: u32) -> Vec<u32> {
    let deadline = Instant::now() + Duration::from_secs(2);
    loop {
        let live = live_group_members(pgid);
        if live.is_empty() || Instant::now() >= deadline {
            return live;
        }
        std::thread::sleep(Duration::from_millis(10));
    }
}

fn exited(role: &str, status: ExitStatus, expected: bool) -> SupervisorEvent {
    SupervisorEvent::Exited {
        role: role.to_owned(),
        status,
        expected,
    }
}

#[test]
fn spawn_reap_and_log() {
    let dir = temp_dir("log");
    let mut sup = Supervisor::new();
    sup.spawn(sh(
        "talker",
        "echo hello $MOLE_TEST; echo oops >&2; read x; echo \"stdin:$x\"; exit 0",
        policy(RestartWhen::Never, 10, 3),
        &dir,
    ))
    .unwrap();
    assert!(sup.is_running("talker"));
    assert!(sup.pid("talker").is_some());
    let events = poll_until(&mut sup, |e| !e.is_empty());
    assert_eq!(events[0].1, exited("talker", ExitStatus::Code(0), false));
    assert!(!sup.is_running("talker"));
    assert_eq!(sup.pid("talker"), None);
    assert_eq!(sup.last_exit("talker"), Some(ExitStatus::Code(0)));
    let log = std::fs::read_to_string(dir.join("logs/talker.log")).unwrap();
    assert!(
        log.starts_with("--- mole: start of `talker`: /bin/sh"),
        "{log}"
    );
    assert!(log.contains("hello yes\n"), "{log}");
    assert!(log.contains("oops\n"), "{log}");
    assert!(log.contains("stdin:\n"), "stdin is null: {log}");
    // A second spawn of the same role appends to the same log.
    sup.spawn(sh(
        "talker",
        "echo again",
        policy(RestartWhen::Never, 10, 3),
        &dir,
    ))
    .unwrap();
    assert!(matches!(
        sup.spawn(sh(
            "talker",
            "sleep 5",
            policy(RestartWhen::Never, 10, 3),
            &dir
        )),
        Err(LaunchError::AlreadyRunning { .. })
    ));
    poll_until(&mut sup, |e| !e.is_empty());
    let log = std::fs::read_to_string(dir.join("logs/talker.log")).unwrap();
    assert!(
        log.contains("hello yes\n") && log.ends_with("again\n"),
        "{log}"
    );
    assert_eq!(sup.restarts().get("talker"), Some(&0));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn on_failure_restarts_with_growing_backoff_then_gives_up() {
    let dir = temp_dir("onfail");
    let mut sup = Supervisor::new();
    let backoff_ms = 20;
    sup.spawn(sh(
        "crash",
        "exit 3",
        policy(RestartWhen::OnFailure, backoff_ms, 3),
        &dir,
    ))
    .unwrap();
    let events = poll_until(&mut sup, |e| {
        e.iter()
            .any(|(_, ev)| matches!(ev, SupervisorEvent::GaveUp { .. }))
    });
    let kinds: Vec<&SupervisorEvent> = events.iter().map(|(_, e)| e).collect();
    let restarted = |attempt| SupervisorEvent::Restarted {
        role: "crash".to_owned(),
        attempt,
    };
    let crash = exited("crash", ExitStatus::Code(3), false);
    assert_eq!(
        kinds,
        [
            &crash,
            &restarted(1),
            &crash,
            &restarted(2),
            &crash,
            &restarted(3),
            &crash,
            &SupervisorEvent::GaveUp {
                role: "crash".to_owned()
            },
        ]
    );
    // Restart k comes no sooner than backoff · 2^(k-1) after the exit before it.
    for k in 0..3 {
        let gap = events[2 * k + 1].0 - events[2 * k].0;
        let min = Duration::from_millis(backoff_ms << k);
        assert!(gap >= min, "restart {}: gap {gap:?} < {min:?}", k + 1);
    }
    assert_eq!(sup.restarts().get("crash"), Some(&3));
    assert!(!sup.is_running("crash"));
    assert!(!sup.restart_pending("crash"));
    // Nothing more happens.
    std::thread::sleep(Duration::from_millis(50));
    assert!(sup.poll().is_empty());
    let log = std::fs::read_to_string(dir.join("logs/crash.log")).unwrap();
    assert!(log.contains("restart 3 of `crash`"), "{log}");
    // Spawning the role again (e.g. a swap) keeps the count and gives a fresh budget.
    sup.spawn(sh(
        "crash",
        "exit 3",
        policy(RestartWhen::OnFailure, 1, 1),
        &dir,
    ))
    .unwrap();
    poll_until(&mut sup, |e| {
        e.iter()
            .any(|(_, ev)| matches!(ev, SupervisorEvent::GaveUp { .. }))
    });
    assert_eq!(sup.restarts().get("crash"), Some(&4));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn on_failure_restarts_after_a_signal_but_not_after_success() {
    let dir = temp_dir("signal");
    let mut sup = Supervisor::new();
    sup.spawn(sh(
        "killed",
        "kill -9 $$",
        policy(RestartWhen::OnFailure, 1, 1),
        &dir,
    ))
    .unwrap();
    sup.spawn(sh(
        "clean",
        "exit 0",
        policy(RestartWhen::OnFailure, 1, 1),
        &dir,
    ))
    .unwrap();
    let events = poll_until(&mut sup, |e| {
        e.iter()
            .any(|(_, ev)| matches!(ev, SupervisorEvent::GaveUp { .. }))
    });
    let evs: Vec<SupervisorEvent> = events.into_iter().map(|(_, e)| e).collect();
    assert!(evs.contains(&exited("killed", ExitStatus::Signal(9), false)));
    assert!(evs.contains(&exited("clean", ExitStatus::Code(0), false)));
    assert!(evs.contains(&SupervisorEvent::Restarted {
        role: "killed".to_owned(),
        attempt: 1
    }));
    assert_eq!(sup.restarts().get("clean"), Some(&0));
    assert_eq!(ExitStatus::Signal(9).to_string(), "signal 9 (SIGKILL)");
    assert_eq!(ExitStatus::Code(3).to_string(), "exit code 3");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn never_policy_does_not_restart() {
    let dir = temp_dir("never");
    let mut sup = Supervisor::new();
    sup.spawn(sh("once", "exit 7", policy(RestartWhen::Never, 1, 5), &dir))
        .unwrap();
    let events = poll_until(&mut sup, |e| !e.is_empty());
    assert_eq!(events.len(), 1);
    assert_eq!(events[0].1, exited("once", ExitStatus::Code(7), false));
    std::thread::sleep(Duration::from_millis(30));
    assert!(sup.poll().is_empty());
    assert!(!sup.is_running("once"));
    assert_eq!(sup.restarts().get("once"), Some(&0));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn always_restarts_after_exit_zero() {
    let dir = temp_dir("always");
    let mut sup = Supervisor::new();
    sup.spawn(sh("loop", "true", policy(RestartWhen::Always, 1, 2), &dir))
        .unwrap();
    let events = poll_until(&mut sup, |e| {
        e.iter()
            .any(|(_, ev)| matches!(ev, SupervisorEvent::GaveUp { .. }))
    });
    let restarts = events
        .iter()
        .filter(|(_, e)| matches!(e, SupervisorEvent::Restarted { .. }))
        .count();
    assert_eq!(restarts, 2);
    assert_eq!(sup.restarts().get("loop"), Some(&2));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn mark_stopping_makes_the_exit_expected_and_cancels_restarts() {
    let dir = temp_dir("stopping");
    let mut sup = Supervisor::new();
    sup.spawn(sh("s", "sleep 30", policy(RestartWhen::Always, 1, 5), &dir))
        .unwrap();
    let pid = sup.pid("s").unwrap();
    sup.mark_stopping("s");
    kill(Pid::from_raw(pid as i32), Signal::SIGTERM).unwrap();
    let events = poll_until(&mut sup, |e| !e.is_empty());
    assert_eq!(events[0].1, exited("s", ExitStatus::Signal(15), true));
    std::thread::sleep(Duration::from_millis(20));
    assert!(sup.poll().is_empty());
    assert!(!sup.is_running("s"));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn backoff_doubles_and_is_capped() {
    let p = RestartPolicy {
        backoff_ms: 200,
        max_backoff_ms: 1000,
        ..RestartPolicy::default()
    };
    let ms: Vec<u128> = (0..5).map(|k| backoff(&p, k).as_millis()).collect();
    assert_eq!(ms, [200, 400, 800, 1000, 1000]);
    assert_eq!(backoff(&p, u32::MAX).as_millis(), 1000);
}

#[test]
fn shutdown_terms_then_kills_and_leaves_nothing() {
    let dir = temp_dir("shutdown");
    let mut sup = Supervisor::new();
    sup.spawn(sh(
        "polite",
        "sleep 30",
        policy(RestartWhen::Always, 1, 5),
        &dir,
    ))
    .unwrap();
    sup.spawn(sh(
        "stubborn",
        "trap '' TERM; sleep 30",
        policy(RestartWhen::Always, 1, 5),
        &dir,
    ))
    .unwrap();
    sup.spawn(sh("done", "exit 0", policy(RestartWhen::Never, 1, 5), &dir))
        .unwrap();
    let polite = sup.pid("polite").unwrap();
    let stubborn = sup.pid("stubborn").unwrap();
    // Let the shell install its trap before the signal comes.
    std::thread::sleep(Duration::from_millis(300));
    assert!(live_group_members(stubborn).contains(&stubborn));
    let t0 = Instant::now();
    let killed = sup.shutdown(
        &["stubborn".to_owned(), "polite".to_owned()],
        Duration::from_millis(300),
    );
    assert_eq!(killed, ["stubborn"]);
    assert!(t0.elapsed() >= Duration::from_millis(300));
    assert!(gone(polite) && gone(stubborn));
    // The stubborn shell's `sleep` was in its process group and died with it.
    assert_eq!(group_members_after_grace(stubborn), Vec::<u32>::new());
    assert_eq!(group_members_after_grace(polite), Vec::<u32>::new());
    assert_eq!(sup.last_exit("polite"), Some(ExitStatus::Signal(15)));
    assert_eq!(sup.last_exit("stubborn"), Some(ExitStatus::Signal(9)));
    for role in ["polite", "stubborn", "done"] {
        assert!(!sup.is_running(role));
        assert!(!sup.restart_pending(role));
    }
    // Always-policy children stay down after shutdown.
    std::thread::sleep(Duration::from_millis(20));
    assert!(sup.poll().is_empty());
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn drop_kills_children() {
    let dir = temp_dir("drop");
    let pid = {
        let mut sup = Supervisor::new();
        sup.spawn(sh(
            "s",
            "trap '' TERM; sleep 30",
            policy(RestartWhen::Always, 1, 5),
            &dir,
        ))
        .unwrap();
        sup.pid("s").unwrap()
    };
    assert!(gone(pid));
    assert_eq!(group_members_after_grace(pid), Vec::<u32>::new());
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn spawn_failure_is_an_error() {
    let dir = temp_dir("spawnfail");
    let mut sup = Supervisor::new();
    let mut spec = sh("x", "", policy(RestartWhen::Never, 1, 1), &dir);
    spec.program = dir.join("no-such-program");
    let e = sup.spawn(spec).unwrap_err();
    assert!(matches!(e, LaunchError::Spawn { .. }));
    assert_eq!(e.exit_code(), 1);
    assert!(e.to_string().starts_with("cannot start `x`"), "{e}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn resolve_program_looks_beside_then_path() {
    let dir = temp_dir("resolve");
    let beside = dir.join("bin");
    std::fs::create_dir_all(&beside).unwrap();
    let exe = beside.join("sh");
    std::fs::copy("/bin/sh", &exe).unwrap();
    let path = [PathBuf::from("/bin"), PathBuf::from("/usr/bin")];
    // Next to the launcher wins over PATH.
    assert_eq!(resolve_program_in("sh", &beside, &path).unwrap(), exe);
    // Then PATH.
    let found = resolve_program_in("true", &beside, &path).unwrap();
    assert!(found.ends_with("true"), "{}", found.display());
    // A path is taken as it is.
    assert_eq!(
        resolve_program_in("/bin/sh", &beside, &path).unwrap(),
        PathBuf::from("/bin/sh")
    );
    // A non-executable file does not count.
    std::fs::write(beside.join("data"), "x").unwrap();
    assert!(resolve_program_in("data", &beside, &[]).is_err());

    let e = resolve_program_in("mole-nonexistent", &beside, &path).unwrap_err();
    assert_eq!(
        e.to_string(),
        format!(
            "command `mole-nonexistent` not found (looked in: {} (next to mole), then PATH /bin:/usr/bin)",
            beside.display()
        )
    );
    assert_eq!(e.exit_code(), 2);
    let e = resolve_program_in("./nope/prog", &beside, &path).unwrap_err();
    assert!(
        e.to_string()
            .contains("./nope/prog (not an executable file)"),
        "{e}"
    );
    assert!(resolve_program("mole-surely-missing-program", &beside).is_err());
    let _ = std::fs::remove_dir_all(&dir);
}
