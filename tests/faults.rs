//! Faults: a rogue publisher writing random bytes into every topic, killed and hung processes,
//! a killed stack, a hundred kill-and-restart cycles, and who may open the stack's memory.

use mole_integration_tests::*;
use mole_runtime::{ClockMode, CommonArgs, Context, Publisher};
use mole_types::{EndReason, GRAPH, Message, Role, topics};
use std::os::unix::process::CommandExt;
use std::time::Duration;

/// xorshift64*: reproducible garbage.
struct Garbage(u64);

impl Garbage {
    fn fill(&mut self, bytes: &mut [u8]) {
        for chunk in bytes.chunks_mut(8) {
            self.0 ^= self.0 >> 12;
            self.0 ^= self.0 << 25;
            self.0 ^= self.0 >> 27;
            let word = self.0.wrapping_mul(0x2545_F491_4F6C_DD1D).to_le_bytes();
            chunk.copy_from_slice(&word[..chunk.len()]);
        }
    }
}

fn spray<M: Message>(publisher: &mut Publisher<M>, garbage: &mut Garbage, count: usize) {
    for _ in 0..count {
        // Tick 0: the steps are long past, so the garbage competes on content, not on time.
        if let Err(e) = publisher.publish(0, 0, |m| garbage.fill(bytemuck::bytes_of_mut(m))) {
            eprintln!("rogue publish failed: {e}");
        }
    }
}

/// Random bytes sprayed on twelve topics crash no process and are counted invalid on each one.
#[test]
fn random_bytes_on_every_topic_crash_nothing_and_are_counted() {
    let _serial = serial();
    let stack = Stack::start("rogue", &["--mode", "realtime", "--ticks", "700"]);
    stack.wait_for_log(Role::World.name(), "ready", Duration::from_secs(60));
    let rogue = join_realtime_stack(&stack.namespace, "rogue");
    let mut garbage = Garbage(0x9E37_79B9_7F4A_7C15);
    let mut truth = rogue.publisher(topics::WORLD_TRUTH).unwrap();
    let mut scan = rogue.publisher(topics::SENSING_SCAN).unwrap();
    let mut tactile = rogue.publisher(topics::SENSING_TACTILE).unwrap();
    let mut odom = rogue.publisher(topics::SENSING_ODOM).unwrap();
    let mut beacons = rogue.publisher(topics::SENSING_BEACONS).unwrap();
    let mut fix = rogue.publisher(topics::SENSING_FIX).unwrap();
    let mut pose = rogue.publisher(topics::LOCALIZATION_POSE).unwrap();
    let mut grid = rogue.publisher(topics::MAPPING_GRID).unwrap();
    let mut contact = rogue.publisher(topics::MAPPING_CONTACT).unwrap();
    let mut cmd = rogue.publisher(topics::PLANNING_CMD).unwrap();
    let mut status = rogue.publisher(topics::PLANNING_STATUS).unwrap();
    let mut stats = rogue.publisher(topics::STACK_STATS).unwrap();
    // A trickle rather than one burst: every subscriber sees garbage between real messages.
    for _ in 0..20 {
        let n = 3;
        spray(&mut truth, &mut garbage, n);
        spray(&mut scan, &mut garbage, n);
        spray(&mut tactile, &mut garbage, n);
        spray(&mut odom, &mut garbage, n);
        spray(&mut beacons, &mut garbage, n);
        spray(&mut fix, &mut garbage, n);
        spray(&mut pose, &mut garbage, n);
        spray(&mut grid, &mut garbage, n);
        spray(&mut contact, &mut garbage, n);
        spray(&mut cmd, &mut garbage, n);
        spray(&mut status, &mut garbage, n);
        spray(&mut stats, &mut garbage, n);
        std::thread::sleep(Duration::from_millis(100));
    }
    std::thread::sleep(Duration::from_millis(500));
    let sprayed = [
        truth.topic(),
        scan.topic(),
        tactile.topic(),
        odom.topic(),
        beacons.topic(),
        fix.topic(),
        pose.topic(),
        grid.topic(),
        contact.topic(),
        cmd.topic(),
        status.topic(),
        stats.topic(),
    ];
    drop(rogue);

    let out = stack.out.clone();
    let keep = out.with_extension("kept");
    let output = stack.wait_and_copy(&keep, Duration::from_secs(240));
    let logs = logs(&keep);
    let summary = summary(&keep);
    let _ = std::fs::remove_dir_all(&keep);
    assert!(output.status.success(), "{logs}");
    assert_eq!(summary.exit_reason, EndReason::Ticks.name(), "{summary:#?}");
    for (role, restarts) in &summary.restarts {
        assert_eq!(*restarts, 0, "{role} crashed:\n{logs}");
    }
    let uncounted: Vec<&str> = sprayed
        .into_iter()
        .filter(|topic| summary.topics.get(*topic).is_none_or(|t| t.invalid == 0))
        .collect();
    assert!(
        uncounted.is_empty(),
        "garbage was sprayed on every topic, yet none was counted invalid on {uncounted:?}: {:#?}",
        summary.topics
    );
}

/// Each supervised role, SIGKILLed in turn, comes back under a new pid and is counted as one
/// restart, and the run still completes every one of its steps.
#[test]
fn every_role_killed_in_turn_comes_back_once_and_the_run_completes_its_steps() {
    let _serial = serial();
    let ticks = 2500;
    let stack = Stack::start(
        "kill-each",
        &["--mode", "realtime", "--ticks", &ticks.to_string()],
    );
    stack.wait_for_log(Role::World.name(), "ready", Duration::from_secs(60));
    let roles = GRAPH.iter();
    for row in roles.clone() {
        std::thread::sleep(Duration::from_millis(1200));
        let program = row.program;
        let old = pid_of(&stack.namespace, program).unwrap_or_else(|| panic!("{program} runs"));
        signal(old, nix::sys::signal::Signal::SIGKILL);
        // Only against hanging: how fast it comes back is not what this test judges.
        wait_for_new_pid(
            &stack.namespace,
            program,
            Some(old),
            Duration::from_secs(30),
            &stack.out,
        );
    }
    let out = stack.out.clone();
    let keep = out.with_extension("kept");
    let output = stack.wait_and_copy(&keep, Duration::from_secs(240));
    let logs = logs(&keep);
    let summary = summary(&keep);
    let _ = std::fs::remove_dir_all(&keep);
    assert!(output.status.success(), "{logs}");
    assert_eq!(summary.exit_reason, EndReason::Ticks.name(), "{summary:#?}");
    assert_eq!(summary.ticks, ticks, "every step ran: {summary:#?}");
    for row in roles {
        let role = row.role.name();
        assert_eq!(summary.restarts.get(role), Some(&1), "{role}: {summary:#?}");
    }
}

/// A process frozen with SIGSTOP is found hung by its silence, counted, and restarted.
#[test]
fn a_hung_process_is_detected_by_its_silence_and_restarted() {
    let _serial = serial();
    let stack = Stack::start("hang", &["--mode", "realtime", "--ticks", "100000"]);
    stack.wait_for_log(Role::World.name(), "ready", Duration::from_secs(60));
    std::thread::sleep(Duration::from_millis(1000));
    let frozen = pid_of(&stack.namespace, Role::Mapping.spec().program).expect("mapping runs");
    // Alive but doing nothing: SIGSTOP.
    signal(frozen, nix::sys::signal::Signal::SIGSTOP);
    wait_for_new_pid(
        &stack.namespace,
        Role::Mapping.spec().program,
        Some(frozen),
        Duration::from_secs(15),
        &stack.out,
    );
    stack.wait_for_log(Role::Mapping.name(), "restart 1", Duration::from_secs(5));
    std::thread::sleep(Duration::from_millis(500));
    signal(stack.pid(), nix::sys::signal::Signal::SIGINT);
    let out = stack.out.clone();
    let keep = out.with_extension("kept");
    let output = stack.wait_and_copy(&keep, Duration::from_secs(60));
    let summary = summary(&keep);
    let _ = std::fs::remove_dir_all(&keep);
    let launcher_log = String::from_utf8_lossy(&output.stderr).into_owned();
    assert!(
        launcher_log.contains("hung"),
        "the launcher reports the hang:\n{launcher_log}"
    );
    let mapping = Role::Mapping.name();
    assert_eq!(summary.hangs.get(mapping), Some(&1), "{summary:#?}");
    assert_eq!(summary.restarts.get(mapping), Some(&1), "{summary:#?}");
}

/// A process's program name as the kernel keeps it, for messages.
fn program_of(pid: u32) -> String {
    std::fs::read_to_string(format!("/proc/{pid}/comm"))
        .map_or_else(|_| "?".to_string(), |c| c.trim().to_string())
}

/// SIGKILL of the launcher takes every child with it (the kernel's parent-death signal), and a
/// new stack in the same namespace cleans what the dead launcher left and runs to the end.
#[test]
fn a_killed_launcher_leaves_no_child_behind_and_a_new_stack_in_its_namespace_cleans_up() {
    let _serial = serial();
    let before = shm_files();
    let stack = Stack::start("killall", &["--mode", "realtime", "--ticks", "100000"]);
    stack.wait_for_log(Role::World.name(), "ready", Duration::from_secs(60));
    std::thread::sleep(Duration::from_millis(800));
    let namespace = stack.namespace.clone();
    for program in GRAPH.iter().map(|r| r.program) {
        assert!(
            pid_of(&namespace, program).is_some(),
            "{program} runs before the kill\n{}",
            logs(&stack.out)
        );
    }
    signal(stack.pid(), nix::sys::signal::Signal::SIGKILL);
    // Only against hanging: the children get SIGTERM from the kernel and stop on their own.
    let deadline = std::time::Instant::now() + Duration::from_secs(10);
    while !processes_of(&namespace).is_empty() && std::time::Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(50));
    }
    let survivors: Vec<String> = processes_of(&namespace)
        .into_iter()
        .map(|pid| format!("{} (pid {pid})", program_of(pid)))
        .collect();
    // On failure, dropping `stack` kills the survivors.
    assert!(
        survivors.is_empty(),
        "children outlived their SIGKILLed launcher by 10 s: {survivors:?}"
    );
    drop(stack);

    let again = Stack::start_in(&namespace, &["--mode", "lockstep", "--ticks", "300"]);
    let summary = again.succeeded(Duration::from_secs(120));
    assert_eq!(summary.exit_reason, EndReason::Ticks.name(), "{summary:#?}");
    assert!(processes_of(&namespace).is_empty());
    assert_eq!(
        left_behind(&before),
        Vec::<String>::new(),
        "stale resources of the killed stack were cleaned"
    );
}

/// Turns the probe below on: the namespace of the stack to probe.
const PROBE_NAMESPACE: &str = "MOLE_PROBE_NAMESPACE";
/// The stack's shared-memory files for the probe to open, one a line.
const PROBE_FILES: &str = "MOLE_PROBE_FILES";
/// Starts every line the probe prints.
const PROBE_MARK: &str = "other-user probe:";

/// The stack's files are its user's alone: no access for group or others, and another user
/// (nobody) can neither subscribe to nor publish on a topic, nor read or write its memory.
#[test]
fn the_stacks_shared_memory_belongs_to_its_user_alone() {
    use std::os::unix::fs::{MetadataExt, PermissionsExt};
    let _serial = serial();
    let before = shm_files();
    let stack = Stack::start("owner", &["--mode", "realtime", "--ticks", "100000"]);
    stack.wait_for_log(Role::World.name(), "ready", Duration::from_secs(60));
    let uid = nix::unistd::getuid().as_raw();
    // Shared memory and service records (iceoryx2's node directories are 0750, its default).
    let ours: Vec<String> = shm_files()
        .into_iter()
        .filter(|f| !before.contains(f) && !f.starts_with("/tmp/iceoryx2/nodes"))
        .collect();
    assert!(!ours.is_empty(), "the stack created shared memory");
    for file in &ours {
        let meta = std::fs::metadata(file).expect("stat");
        assert_eq!(
            meta.uid(),
            uid,
            "{file} belongs to the user who started the stack"
        );
        assert_eq!(
            meta.permissions().mode() & 0o077,
            0,
            "{file} is closed to group and others"
        );
    }
    if !nix::unistd::getuid().is_root() {
        skip(
            "the_stacks_shared_memory_belongs_to_its_user_alone",
            "running the probe as another user needs root",
        );
        return;
    }
    let memory: Vec<&str> = ours
        .iter()
        .map(String::as_str)
        .filter(|f| f.starts_with("/dev/shm/"))
        .collect();
    assert!(!memory.is_empty(), "the stack's topics live in /dev/shm");
    let nobody = 65534;
    let report = run_probe_as(nobody, &stack.namespace, &memory);
    // The test harness may print its own words before the probe's first line.
    let said: Vec<&str> = report
        .lines()
        .filter_map(|l| l.split_once(PROBE_MARK).map(|(_, said)| said.trim()))
        .collect();
    let line = |what: &str| {
        said.iter()
            .find(|l| l.starts_with(what))
            .unwrap_or_else(|| panic!("the probe reported no `{what}`:\n{report}"))
    };
    line(&format!("ran as uid {nobody}"));
    for port in ["subscriber", "publisher"] {
        let outcome = line(&format!("{port} on sensing/scan:"));
        assert!(
            outcome.contains(": refused"),
            "user nobody opened a {port}:\n{report}"
        );
    }
    let file_attempts: Vec<&&str> = said
        .iter()
        .filter(|l| l.starts_with("read ") || l.starts_with("write "))
        .collect();
    assert_eq!(
        file_attempts.len(),
        2 * memory.len(),
        "the probe tried to read and to write every file:\n{report}"
    );
    for attempt in file_attempts {
        assert!(
            attempt.contains(": refused"),
            "user nobody opened the stack's memory: {attempt}"
        );
    }
}

/// Runs this test executable's probe as user and group `id` against `namespace` and `files`,
/// and returns what it printed. The executable is copied where any user may run it (the build
/// directory may be closed to others).
fn run_probe_as(id: u32, namespace: &str, files: &[&str]) -> String {
    use std::os::unix::fs::PermissionsExt;
    let dir = TempDir(std::env::temp_dir().join(format!("mole-probe-{namespace}")));
    std::fs::create_dir_all(&dir.0).expect("create the probe's directory");
    std::fs::set_permissions(&dir.0, std::fs::Permissions::from_mode(0o755)).expect("chmod");
    let exe = dir.0.join("faults-probe");
    std::fs::copy(std::env::current_exe().expect("test executable"), &exe)
        .expect("copy the test executable");
    std::fs::set_permissions(&exe, std::fs::Permissions::from_mode(0o755)).expect("chmod");
    let child = std::process::Command::new(&exe)
        .args([
            "--ignored",
            "--exact",
            "other_user_probe",
            "--nocapture",
            "--test-threads=1",
        ])
        .env(PROBE_NAMESPACE, namespace)
        .env(PROBE_FILES, files.join("\n"))
        .current_dir(&dir.0)
        .uid(id)
        .gid(id)
        .stdin(std::process::Stdio::null())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("start the probe");
    let pid = child.id();
    let (done, finished) = std::sync::mpsc::channel();
    std::thread::spawn(move || done.send(child.wait_with_output()));
    // Only against hanging: the probe tries a few opens and returns.
    let output = match finished.recv_timeout(Duration::from_secs(60)) {
        Ok(output) => output.expect("the probe's output"),
        Err(_) => {
            signal(pid, nix::sys::signal::Signal::SIGKILL);
            panic!("the probe did not finish within 60 s");
        }
    };
    let stdout = String::from_utf8_lossy(&output.stdout).into_owned();
    assert!(
        output.status.success(),
        "the probe failed:\n{stdout}\n{}",
        String::from_utf8_lossy(&output.stderr)
    );
    stdout
}

/// Not a check of its own, so ignored in a normal run (where it would pass without checking
/// anything): the test above runs it as another user (`--ignored --exact`), and it tries to
/// subscribe to and to publish on the stack's `sensing/scan`, and to read and to write the
/// stack's shared memory, and prints what happened.
#[test]
#[ignore = "a probe that the_stacks_shared_memory_belongs_to_its_user_alone runs as another user"]
fn other_user_probe() {
    let namespace = std::env::var(PROBE_NAMESPACE).unwrap_or_else(|_| {
        panic!(
            "{PROBE_NAMESPACE} is not set: this probe is run by \
             the_stacks_shared_memory_belongs_to_its_user_alone, not on its own"
        )
    });
    println!("{PROBE_MARK} ran as uid {}", nix::unistd::getuid());
    let join = || {
        let args = CommonArgs::attach(&namespace, ClockMode::Realtime);
        let shutdown = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
        Context::with_shutdown_flag("intruder", &args, shutdown)
            .map_err(|e| format!("joining the namespace: {e}"))
    };
    let outcome = |result: Result<(), String>| match result {
        Ok(()) => "opened".to_string(),
        Err(why) => format!("refused: {why}"),
    };
    let subscriber = join().and_then(|ctx| {
        ctx.subscriber(topics::SENSING_SCAN)
            .map(drop)
            .map_err(|e| e.to_string())
    });
    println!(
        "{PROBE_MARK} subscriber on sensing/scan: {}",
        outcome(subscriber)
    );
    let publisher = join().and_then(|ctx| {
        ctx.publisher(topics::SENSING_SCAN)
            .map(drop)
            .map_err(|e| e.to_string())
    });
    println!(
        "{PROBE_MARK} publisher on sensing/scan: {}",
        outcome(publisher)
    );
    let files = std::env::var(PROBE_FILES).unwrap_or_default();
    for file in files.lines() {
        for (access, write) in [("read", false), ("write", true)] {
            let opened = std::fs::OpenOptions::new()
                .read(!write)
                .write(write)
                .open(file)
                .map(drop)
                .map_err(|e| e.to_string());
            println!("{PROBE_MARK} {access} {file}: {}", outcome(opened));
        }
    }
}

/// Open file descriptors of a process.
/// What each of a process's open descriptors is (the target of its `/proc/PID/fd` link).
fn open_fds(pid: u32) -> Vec<String> {
    let entries = std::fs::read_dir(format!("/proc/{pid}/fd"))
        .into_iter()
        .flatten()
        .flatten();
    let mut targets: Vec<String> = entries
        .filter_map(|e| std::fs::read_link(e.path()).ok())
        .map(|t| t.display().to_string())
        .collect();
    targets.sort();
    targets
}

/// A hundred SIGKILLs of planning, each followed by a restart, grow neither the shared memory
/// nor the launcher's open descriptors.
#[test]
fn a_hundred_kill_and_restart_cycles_leak_no_shared_memory_and_no_descriptors() {
    let _serial = serial();
    let before = shm_files();
    // The default stack, with a planner that may restart 200 times without backing off long.
    let default = std::fs::read_to_string(workspace().join("launch/stacks/default.toml"))
        .expect("default launch file");
    let planning = "role = \"planning\"\ncommand = \"mole-planning\"\n";
    let start = default.find(planning).expect("planning in default.toml") + planning.len();
    let end = start + default[start..].find('\n').expect("its restart line");
    let launch = format!(
        "{}restart = {{ policy = \"always\", backoff_ms = 5, max_backoff_ms = 20, max = 200 }}{}",
        &default[..start],
        &default[end..]
    );
    let launch_path = std::env::temp_dir().join(format!("mole-cycles-{}.toml", std::process::id()));
    std::fs::write(&launch_path, launch).expect("write the launch file");
    let launch_arg = launch_path.display().to_string();
    let stack = Stack::start(
        "cycles",
        &[&launch_arg, "--mode", "realtime", "--ticks", "10000000"],
    );
    stack.wait_for_log(Role::World.name(), "ready", Duration::from_secs(60));
    let log = stack.out.join("logs").join("planning.log");
    let readies = || std::fs::read_to_string(&log).map_or(0, |t| t.matches(" ready ").count());
    let mut pid = pid_of(&stack.namespace, Role::Planning.spec().program).expect("planning runs");
    let (mut shm_at_10, mut fds_at_10) = (Vec::new(), Vec::new());
    let wait_ready = |starts: usize| {
        let deadline = std::time::Instant::now() + Duration::from_secs(20);
        while readies() < starts {
            assert!(
                std::time::Instant::now() < deadline,
                "start {starts}: planning never became ready\n{}",
                logs(&stack.out)
            );
            std::thread::sleep(Duration::from_millis(5));
        }
    };
    // Every process of this stack, the killed ones too: the files they made are the ones
    // counted (other stacks on the machine come and go as they like).
    let mut pids: std::collections::BTreeSet<u32> =
        processes_of(&stack.namespace).into_iter().collect();
    pids.insert(stack.pid());
    // Both snapshots in the same state: the restarted process ready, the dead one cleaned, and
    // the launcher's lazy connections to the new process's publishers made (its keeper connects
    // on its next read, a moment after the process is ready): the counts are read until they
    // hold still for a second (6 s at most).
    let snapshot = |starts: usize, pids: &mut std::collections::BTreeSet<u32>| {
        wait_ready(starts);
        let read = |pids: &mut std::collections::BTreeSet<u32>| {
            pids.extend(processes_of(&stack.namespace));
            (made_by(&shm_files(), pids), open_fds(stack.pid()))
        };
        let deadline = std::time::Instant::now() + Duration::from_secs(6);
        let mut last = read(pids);
        let mut still_since = std::time::Instant::now();
        while std::time::Instant::now() < deadline && still_since.elapsed() < Duration::from_secs(1)
        {
            std::thread::sleep(Duration::from_millis(200));
            let now = read(pids);
            if (now.0.len(), now.1.len()) != (last.0.len(), last.1.len()) {
                still_since = std::time::Instant::now();
            }
            last = now;
        }
        last
    };
    for cycle in 1..=100 {
        // Kill a running process, not one still creating its node: iceoryx2 0.10 cannot clean
        // a node killed before it wrote its details (see the README's fault notes).
        wait_ready(cycle);
        pids.insert(pid);
        signal(pid, nix::sys::signal::Signal::SIGKILL);
        pid = wait_for_new_pid(
            &stack.namespace,
            Role::Planning.spec().program,
            Some(pid),
            Duration::from_secs(10),
            &stack.out,
        );
        pids.insert(pid);
        if cycle == 10 {
            (shm_at_10, fds_at_10) = snapshot(cycle + 1, &mut pids);
        }
    }
    // A leak of one file a cycle is 90 files, which no settling hides.
    let (shm_at_100, fds_at_100) = snapshot(101, &mut pids);
    let grown: Vec<&String> = shm_at_100
        .iter()
        .filter(|f| !shm_at_10.contains(f))
        .collect();
    assert!(
        shm_at_100.len() <= shm_at_10.len(),
        "shared-memory files grew from {} (cycle 10) to {} (cycle 100); new since cycle 10: {grown:?}",
        shm_at_10.len(),
        shm_at_100.len(),
    );
    let new_fds: Vec<&String> = fds_at_100
        .iter()
        .filter(|f| !fds_at_10.contains(f))
        .collect();
    assert!(
        fds_at_100.len() <= fds_at_10.len(),
        "the launcher's descriptors grew from {} to {}; new since cycle 10: {new_fds:?}",
        fds_at_10.len(),
        fds_at_100.len()
    );
    drop(stack);
    let _ = std::fs::remove_file(&launch_path);
    let leftovers = left_behind(&before);
    assert!(leftovers.is_empty(), "left behind: {leftovers:?}");
}

/// A SIGKILLed world whose policy never restarts it ends the run with exit 1 and says why.
#[test]
fn a_killed_world_ends_the_run_as_failed_when_its_policy_never_restarts_it() {
    let _serial = serial();
    let before = shm_files();
    let launch = std::fs::read_to_string(workspace().join("launch/stacks/default.toml"))
        .expect("default.toml");
    let world = "role = \"world\"";
    let (head, tail) = launch.split_once(world).expect("a world process");
    let (restart, rest) = tail
        .split_once("\n[[process]]")
        .expect("a process after the world");
    let restart = restart
        .lines()
        .map(|l| match l.starts_with("restart") {
            true => "restart = { policy = \"never\" }",
            false => l,
        })
        .collect::<Vec<_>>()
        .join("\n");
    let launch = format!("{head}{world}{restart}\n\n[[process]]{rest}");
    assert!(
        launch.contains("restart = { policy = \"never\" }"),
        "{launch}"
    );
    let file = std::env::temp_dir().join(format!("mole-kill-world-{}.toml", std::process::id()));
    std::fs::write(&file, launch).expect("write the launch file");
    let stack = Stack::start(
        "kill-world",
        &[file.to_str().expect("utf-8 path"), "--ticks", "100000"],
    );
    stack.wait_for_log(Role::World.name(), "ready", Duration::from_secs(60));
    std::thread::sleep(Duration::from_millis(500));
    let world = pid_of(&stack.namespace, Role::World.spec().program).expect("mole-world runs");
    signal(world, nix::sys::signal::Signal::SIGKILL);
    let out = stack.out.clone();
    let keep = out.with_extension("kept");
    let output = stack.wait_and_copy(&keep, Duration::from_secs(60));
    let stderr = String::from_utf8_lossy(&output.stderr).into_owned();
    let summary = summary(&keep);
    let _ = std::fs::remove_dir_all(&keep);
    let _ = std::fs::remove_file(&file);
    assert_eq!(output.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains("`world` exited (signal 9") && stderr.contains("does not restart it"),
        "{stderr}"
    );
    assert_eq!(summary.exit_reason, "process_failed", "{summary:#?}");
    let leftovers = left_behind(&before);
    assert!(leftovers.is_empty(), "left behind: {leftovers:?}");
}

/// A lockstep run whose mapping freezes (and is never restarted) ends with exit 1 and a report
/// of the steps each process handled, mapping's behind those of every process of the loop.
#[test]
fn a_stalled_lockstep_run_ends_with_a_report_instead_of_waiting_forever() {
    let _serial = serial();
    // Mapping is never restarted here, so when it freezes nothing can move the run on.
    let launch = std::fs::read_to_string(workspace().join("launch/stacks/lockstep.toml"))
        .expect("lockstep.toml")
        .replace(
            "role = \"mapping\"\ncommand = \"mole-mapping\"\nrestart = { policy = \"on-failure\", backoff_ms = 200, max = 5 }",
            "role = \"mapping\"\ncommand = \"mole-mapping\"\nrestart = { policy = \"never\" }",
        );
    assert!(launch.contains("policy = \"never\" }\n\n[[process]]\nrole = \"planning\""));
    let file = std::env::temp_dir().join(format!("mole-stall-{}.toml", std::process::id()));
    std::fs::write(&file, launch).expect("write the launch file");
    let stack = Stack::start(
        "stall",
        &[file.to_str().expect("utf-8 path"), "--ticks", "100000000"],
    );
    stack.wait_for_log(Role::World.name(), "ready", Duration::from_secs(60));
    // Past mapping's second statistics (one a second), so the report carries a real count.
    std::thread::sleep(Duration::from_millis(1500));
    let frozen = pid_of(&stack.namespace, Role::Mapping.spec().program).expect("mapping runs");
    signal(frozen, nix::sys::signal::Signal::SIGSTOP);
    let output = stack.wait(Duration::from_secs(60));
    let _ = std::fs::remove_file(&file);
    let launcher_log = String::from_utf8_lossy(&output.stderr).into_owned();
    assert_eq!(output.status.code(), Some(1), "{launcher_log}");
    let steps = steps_per_process(&launcher_log);
    for role in GRAPH.iter().map(|r| r.role.name()) {
        assert!(
            steps.contains_key(role),
            "the stall report names `{role}` with its step: {steps:?}\n{launcher_log}"
        );
    }
    // Every other process of the loop ran on (the monitor is not in the loop).
    let mapping = steps[Role::Mapping.name()];
    let ran_on = GRAPH
        .iter()
        .filter(|r| r.in_loop && r.role != Role::Mapping)
        .map(|r| r.role.name());
    for role in ran_on {
        assert!(
            mapping < steps[role],
            "the frozen mapping is behind `{role}`: {steps:?}\n{launcher_log}"
        );
    }
}

/// The steps each process handled, from the launcher's report of a stalled lockstep run
/// (`... steps handled per process: mapping 41, planning 42, ... (see the logs in ...)`).
fn steps_per_process(launcher_log: &str) -> std::collections::BTreeMap<String, u64> {
    let list = launcher_log
        .split_once("stalled")
        .and_then(|(_, rest)| rest.split_once("steps handled per process: "))
        .and_then(|(_, rest)| rest.split_once(" (see the logs"))
        .map(|(list, _)| list)
        .unwrap_or_else(|| panic!("no stall report with steps per process:\n{launcher_log}"));
    list.split(", ")
        .map(|entry| {
            entry
                .rsplit_once(' ')
                .and_then(|(role, step)| Some((role.to_string(), step.parse().ok()?)))
                .unwrap_or_else(|| panic!("`{entry}` is not `<role> <step>`:\n{launcher_log}"))
        })
        .collect()
}
