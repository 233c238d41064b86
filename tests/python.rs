//! A process in another language: the Python planner of `examples/python_planner` (the iceoryx2
//! package from PyPI, ctypes layouts generated from shared-types) in the planning role of the
//! real stack. Skipped (failed under CI), with the reason on stderr, where no Python has the
//! iceoryx2 package at the stack's version (`scripts/python-env.sh` installs it; `.ci/run` calls
//! it).

use mole_integration_tests::*;
use mole_types::{
    DIRECTION_PUBLISH, DIRECTION_SUBSCRIBE, EndReason, Role, Stats, read_name, topics,
};
use std::collections::BTreeMap;
use std::process::Command;
use std::time::{Duration, Instant};

const RUN_TIMEOUT: Duration = Duration::from_secs(240);
const PLANNER: &str = "examples/python_planner/planner.py";

/// The iceoryx2 version the Rust side is built against: services record it, and a process of
/// another version cannot open them.
fn iceoryx2_version() -> Option<String> {
    let lock = std::fs::read_to_string(workspace().join("Cargo.lock")).ok()?;
    let mut lines = lock.lines();
    while let Some(line) = lines.next() {
        if line == "name = \"iceoryx2\"" {
            let version = lines
                .next()?
                .strip_prefix("version = \"")?
                .strip_suffix('"')?;
            return Some(version.to_string());
        }
    }
    None
}

/// A Python that imports iceoryx2 at the stack's version (target/python-env first, then
/// python3 on PATH), or why there is none.
fn python() -> Result<String, String> {
    let version = iceoryx2_version().ok_or("Cargo.lock names no iceoryx2 version")?;
    let venv = workspace().join("target/python-env/bin/python3");
    let mut reasons = Vec::new();
    for candidate in [venv.display().to_string(), "python3".to_string()] {
        let probe = "import importlib.metadata as m, iceoryx2; print(m.version('iceoryx2'))";
        match Command::new(&candidate).args(["-c", probe]).output() {
            Err(e) => reasons.push(format!("{candidate}: {e}")),
            Ok(out) if !out.status.success() => {
                reasons.push(format!("{candidate} cannot import iceoryx2"));
            }
            Ok(out) => {
                let found = String::from_utf8_lossy(&out.stdout).trim().to_string();
                if found == version {
                    return Ok(candidate);
                }
                reasons.push(format!("{candidate} has iceoryx2 {found}"));
            }
        }
    }
    Err(format!(
        "no Python with iceoryx2 {version} ({}); scripts/python-env.sh installs one",
        reasons.join("; ")
    ))
}

/// The Python to run the planner with, or `None` after [`skip`] said why there is none.
fn python_or_skip(test: &str) -> Option<String> {
    python().map_err(|reason| skip(test, &reason)).ok()
}

/// `--swap planning=...` running the planner with `python`.
fn swap(python: &str) -> String {
    format!("{}='{python}' {PLANNER}", Role::Planning)
}

/// The planning role's log of a run's output directory.
fn planning_log(out: &std::path::Path) -> String {
    let log = out.join("logs").join(format!("{}.log", Role::Planning));
    std::fs::read_to_string(log).unwrap_or_default()
}

/// Runs a stack to its end; returns its summary and its logs (checked for success).
fn run(test: &str, args: &[&str]) -> (Summary, String) {
    let stack = Stack::start(test, args);
    let namespace = stack.namespace.clone();
    let keep = stack.out.with_extension("kept");
    let output = stack.wait_and_copy(&keep, RUN_TIMEOUT);
    let logs = logs(&keep);
    let summary = summary(&keep);
    let planning_log = planning_log(&keep);
    let _ = std::fs::remove_dir_all(&keep);
    assert!(
        output.status.success(),
        "mole up failed: {}\n{logs}",
        String::from_utf8_lossy(&output.stderr)
    );
    assert!(processes_of(&namespace).is_empty(), "processes left behind");
    (summary, planning_log)
}

/// The ticks of a recording whose planning/cmd does not carry the origin_ns of the
/// localization/pose of its tick (all of them when none was recorded).
fn commands_without_their_pose_origin(file: &std::path::Path) -> Vec<u64> {
    use mole_types::Header;
    let bytes = std::fs::read(file).expect("a recording");
    let mut poses = BTreeMap::new();
    let mut commands = Vec::new();
    for message in mcap::MessageStream::new(&bytes).expect("an MCAP file") {
        let message = message.expect("a finished recording reads to its end");
        let header: Header =
            bytemuck::pod_read_unaligned(&message.data[..std::mem::size_of::<Header>()]);
        match message.channel.topic.as_str() {
            t if t == topics::LOCALIZATION_POSE.name => {
                poses.insert(header.tick, header.origin_ns);
            }
            t if t == topics::PLANNING_CMD.name => commands.push(header),
            _ => {}
        }
    }
    if commands.is_empty() {
        return vec![u64::MAX];
    }
    commands
        .iter()
        .filter(|c| poses.get(&c.tick) != Some(&c.origin_ns))
        .map(|c| c.tick)
        .collect()
}

/// What the Python planner says when SIGTERM stopped it cleanly: `stopped after N steps`.
fn steps_at_stop(planning_log: &str) -> Option<u64> {
    let line = planning_log
        .lines()
        .find_map(|l| l.split_once("stopped after ").map(|(_, rest)| rest))?;
    line.split_whitespace().next()?.parse().ok()
}

/// The Python planner handles every tick of a lockstep run without touching a wall, and two
/// runs of one seed are identical.
#[test]
fn the_python_planner_drives_the_lockstep_stack_deterministically() {
    let Some(python) =
        python_or_skip("the_python_planner_drives_the_lockstep_stack_deterministically")
    else {
        return;
    };
    let _serial = serial();
    let before = shm_files();
    let swap = swap(&python);
    let args = [
        "--mode", "lockstep", "--ticks", "1500", "--seed", "3", "--swap", &swap,
    ];
    let recording = TempDir::new("py-record");
    let file = recording.0.join("run.mcap");
    let file_arg = file.to_string_lossy().into_owned();
    let recorded: Vec<&str> = args
        .iter()
        .copied()
        .chain(["--record", &file_arg])
        .collect();
    let (first, log) = run("py-a", &recorded);
    let (second, _) = run("py-b", &args);

    assert_eq!(first.ticks, 1500, "every step completed: {first:#?}");
    assert_eq!(first.exit_reason, EndReason::Ticks.name(), "{first:#?}");
    assert!(first.path_length_m > 2.0, "the robot moved: {first:#?}");
    // The world keeps any command within 1 mm of penetration; keeping off the walls is the
    // wanderer's own doing.
    assert_eq!(first.contact_events, 0, "{first:#?}");
    let planning = Role::Planning.name();
    assert_eq!(first.restarts.get(planning), Some(&0), "{first:#?}");
    // The world measures the loop latency from the origin_ns the planner copies from the
    // pose of its step: every recorded command carries its pose's origin.
    let mismatched = commands_without_their_pose_origin(&file);
    assert!(
        mismatched.is_empty(),
        "{} commands carry another origin than their pose's, from tick {:?}",
        mismatched.len(),
        mismatched.first()
    );
    // One command per tick: the world steps only once the command of the step before arrived.
    let steps = steps_at_stop(&log).unwrap_or(0);
    assert!(
        steps >= 1500,
        "the planner stopped cleanly after {steps} steps:\n{log}"
    );
    let outcome = |s: &Summary| {
        (
            s.path_length_m,
            s.grid_hash.clone(),
            s.contact_hash.clone(),
            s.coverage,
        )
    };
    assert_eq!(outcome(&first), outcome(&second), "same seed, same run");
    assert_eq!(left_behind(&before), Vec::<String>::new(), "left behind");
}

/// The latest stack/stats of the Python planner: pid, steps handled, and per topic (direction,
/// count over the whole run).
#[derive(Debug, Default)]
struct PlannerStats {
    pid: u32,
    steps: u64,
    cpu_ns: u64,
    topics: BTreeMap<String, (u32, u64)>,
}

impl PlannerStats {
    /// Messages published on `topic` so far.
    fn published(&self, topic: &str) -> u64 {
        match self.topics.get(topic) {
            Some(&(direction, count)) if direction == DIRECTION_PUBLISH => count,
            _ => 0,
        }
    }

    /// Whether the planner has handled steps and published one command for each.
    fn commanding(&self) -> bool {
        self.steps > 0 && self.published(topics::PLANNING_CMD.name) == self.steps
    }
}

/// The monitor's planning/status subscriber in its latest stack/stats: (received, invalid),
/// both counted over the whole run.
fn status_at_monitor(stats: &Stats) -> Option<(u64, u64)> {
    stats
        .topics()
        .iter()
        .find(|t| {
            t.direction == DIRECTION_SUBSCRIBE
                && read_name(&t.topic) == topics::PLANNING_STATUS.name
        })
        .map(|t| (t.count, t.invalid))
}

/// In realtime the Python planner publishes its statistics (one command per handled step), the
/// monitor receives its status, and it handles no tick of the run twice.
#[test]
fn the_python_planner_reports_its_statistics_in_realtime() {
    let Some(python) = python_or_skip("the_python_planner_reports_its_statistics_in_realtime")
    else {
        return;
    };
    let _serial = serial();
    let before = shm_files();
    let swap = swap(&python);
    let stack = Stack::start(
        "py-rt",
        &[
            "--mode", "realtime", "--ticks", "800", "--seed", "3", "--swap", &swap,
        ],
    );
    stack.wait_for_log(Role::Planning.name(), "ready", Duration::from_secs(60));
    let observer = join_realtime_stack(&stack.namespace, "observer");
    let mut stats_sub = observer.subscriber(topics::STACK_STATS).expect("stats");
    // Watch until the planner has published one command per handled step, a second statistics
    // sample came, and the monitor reports planning/status received. No Rust planner runs
    // (the Python one took its place), so what the monitor received came from the Python one.
    let mut seen = PlannerStats::default();
    let mut at_monitor: Option<(u64, u64)> = None;
    let received = |at: Option<(u64, u64)>| at.is_some_and(|(count, _)| count > 0);
    let mut samples = 0;
    let mut cmdline = Vec::new();
    let deadline = Instant::now() + Duration::from_secs(30);
    while !(seen.commanding() && samples >= 2 && received(at_monitor)) && Instant::now() < deadline
    {
        stats_sub.drain(|s| {
            if read_name(&s.process) == Role::Monitor.name() {
                at_monitor = status_at_monitor(s);
            }
            if read_name(&s.process) == Role::Planning.name() {
                samples += 1;
                seen.pid = s.pid;
                seen.steps = s.steps;
                seen.cpu_ns = s.cpu_ns;
                seen.topics = s
                    .topics()
                    .iter()
                    .map(|t| {
                        let name = read_name(&t.topic).into_owned();
                        (name, (t.direction, t.count))
                    })
                    .collect();
            }
        });
        if seen.pid != 0 {
            cmdline = std::fs::read(format!("/proc/{}/cmdline", seen.pid)).unwrap_or_default();
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    drop(stats_sub);
    drop(observer);

    assert!(
        seen.commanding(),
        "one planning/cmd per handled step: {seen:?}"
    );
    assert!(samples >= 2, "statistics once a second: {samples} in 30 s");
    assert!(
        seen.published(topics::PLANNING_STATUS.name) > 0,
        "the planner publishes planning/status: {seen:?}"
    );
    assert!(
        received(at_monitor),
        "the monitor received planning/status: {at_monitor:?}"
    );
    assert_eq!(
        at_monitor.map(|(_, invalid)| invalid),
        Some(0),
        "every planning/status passed validate()"
    );
    assert!(
        String::from_utf8_lossy(&cmdline).contains("planner.py"),
        "the planning statistics come from the Python process (pid {})",
        seen.pid
    );
    assert!(seen.steps > 0 && seen.cpu_ns > 0, "{seen:?}");
    for input in [
        "localization/pose",
        "sensing/scan",
        "world/map",
        "stack/stats",
    ] {
        assert!(seen.topics.contains_key(input), "{input}: {seen:?}");
    }

    let namespace = stack.namespace.clone();
    let keep = stack.out.with_extension("kept");
    let output = stack.wait_and_copy(&keep, RUN_TIMEOUT);
    let logs = logs(&keep);
    let summary = summary(&keep);
    let planning_log = planning_log(&keep);
    let _ = std::fs::remove_dir_all(&keep);
    assert!(
        output.status.success(),
        "mole up failed: {}\n{logs}",
        String::from_utf8_lossy(&output.stderr)
    );
    assert!(processes_of(&namespace).is_empty(), "processes left behind");
    assert_eq!(summary.ticks, 800, "{summary:#?}");
    // The world steps on its clock with or without a new command, and the planner takes the
    // newest pose: it handles each of the run's 801 ticks (0 to 800) at most once. How many it
    // keeps up with depends on the machine: that is `mole bench`'s to measure, not a test's.
    let steps = steps_at_stop(&planning_log).unwrap_or(0);
    assert!(
        (1..=801).contains(&steps),
        "the planner handled {steps} of the 801 ticks:\n{planning_log}"
    );
    let planning = Role::Planning.name();
    assert!(!summary.hangs.contains_key(planning), "{summary:#?}");
    assert_eq!(summary.restarts.get(planning), Some(&0), "{summary:#?}");
    assert!(summary.max_penetration_m <= 0.001, "{summary:#?}");
    assert_eq!(left_behind(&before), Vec::<String>::new(), "left behind");
}

/// The Python runtime follows the Rust step rules: examples/python_planner/test_step_rules.py
/// checks mole_runtime.py against step_rules.json, which mole-runtime's tests keep equal to
/// what the Rust rules decide. Needs python3 only, not iceoryx2.
#[test]
fn the_python_runtime_follows_the_rust_step_rules() {
    let test = "the_python_runtime_follows_the_rust_step_rules";
    let unittest = Command::new("python3")
        .args(["-B", "-m", "unittest", "discover"])
        .args(["-s", "examples/python_planner", "-p", "test_*.py"])
        .current_dir(workspace())
        .output();
    let output = match unittest {
        Ok(output) => output,
        Err(e) => return skip(test, &format!("no python3: {e}")),
    };
    let report = String::from_utf8_lossy(&output.stderr);
    let ran: u32 = report
        .lines()
        .find_map(|l| l.strip_prefix("Ran ")?.split(' ').next()?.parse().ok())
        .unwrap_or(0);
    assert!(
        output.status.success() && ran > 0,
        "the Python step rules differ from the Rust ones ({ran} tests ran):\n{report}"
    );
}
