//! What every integration test needs: the built binaries, a unique namespace, a `mole up` that
//! is killed with all its children whatever happens, and a check that nothing is left behind.

pub use mole_monitor::Summary;
pub mod operator;
pub use operator::Operator;

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::sync::{Mutex, MutexGuard};
use std::time::{Duration, Instant};

/// Stacks share two cores and /dev/shm: one at a time, so leftovers can be counted exactly.
static SERIAL: Mutex<()> = Mutex::new(());

/// Holds the one-stack-at-a-time lock for a test.
pub fn serial() -> MutexGuard<'static, ()> {
    SERIAL
        .lock()
        .unwrap_or_else(|poisoned| poisoned.into_inner())
}

/// The workspace root.
pub fn workspace() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// The directory of the built binaries (the test executable lives in its `deps/`).
pub fn bin_dir() -> PathBuf {
    let exe = std::env::current_exe().expect("test executable path");
    let dir = exe
        .parent()
        .and_then(Path::parent)
        .expect("target/<profile>")
        .to_path_buf();
    let programs = mole_types::GRAPH.iter().map(|r| r.program);
    let beside = [
        "mole",
        "mole-recorder",
        "mole-player",
        "mole-view",
        "mole-bridge",
    ];
    for name in beside.into_iter().chain(programs) {
        assert!(
            dir.join(name).exists(),
            "{} is missing: run the README's test command (it builds every binary first)",
            dir.join(name).display()
        );
    }
    dir
}

/// A namespace no other test or stack uses.
pub fn unique_namespace(test: &str) -> String {
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.subsec_nanos())
        .unwrap_or(0);
    format!("t-{test}-{}-{nanos}", std::process::id())
}

/// A recorded lockstep run of `ticks` steps (seed 5, and `more` arguments of `mole up`) that
/// must succeed within 240 s and leave no process behind: the directory it left, with the
/// recording `run.mcap` in it.
pub fn recorded_lockstep_run(test: &str, ticks: u64, more: &[&str]) -> TempDir {
    let namespace = unique_namespace(test);
    let out = std::env::temp_dir().join(format!("mole-{namespace}"));
    let file = out.join("run.mcap").display().to_string();
    let ticks = ticks.to_string();
    let args = ["--mode", "lockstep", "--ticks", &ticks, "--seed", "5"];
    let args: Vec<&str> = args
        .iter()
        .copied()
        .chain(more.iter().copied())
        .chain(["--record", &file])
        .collect();
    let stack = Stack::start_in(&namespace, &args);
    let kept = TempDir(out.with_extension("kept"));
    let output = stack.wait_and_copy(&kept.0, Duration::from_secs(240));
    assert!(
        output.status.success(),
        "mole up failed: {}\n{}",
        String::from_utf8_lossy(&output.stderr),
        logs(&kept.0)
    );
    assert!(processes_of(&namespace).is_empty(), "processes left behind");
    kept
}

/// A directory of the test's own in the temp directory, removed whatever happens.
pub struct TempDir(pub PathBuf);

impl TempDir {
    /// A new, empty directory named after `test` and unique to this run.
    pub fn new(test: &str) -> TempDir {
        let dir = std::env::temp_dir().join(format!("mole-{}", unique_namespace(test)));
        std::fs::create_dir_all(&dir).expect("temp dir");
        TempDir(dir)
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// iceoryx2's files: shared memory in /dev/shm and its node and service records in
/// /tmp/iceoryx2, by path. Not its global node counter (`…_node.<version>.global_mgmt`): the
/// first node on a machine makes it and iceoryx2 keeps it for good, by design, so a test that
/// makes the first node (in a fresh /dev/shm) would see it as left behind.
pub fn shm_files() -> Vec<String> {
    let mut names = Vec::new();
    for dir in ["/dev/shm", "/tmp/iceoryx2/nodes", "/tmp/iceoryx2/services"] {
        if let Ok(entries) = std::fs::read_dir(dir) {
            for entry in entries.flatten() {
                let name = entry.file_name().to_string_lossy().into_owned();
                // iceoryx2 keeps one management segment per machine and version for every
                // node on it (`…global_mgmt`); it is not a stack's and outlives every run.
                let stack_file = name.starts_with("iox2_") && !name.ends_with(".global_mgmt");
                if dir != "/dev/shm" || stack_file {
                    names.push(format!("{dir}/{name}"));
                }
            }
        }
    }
    names.sort();
    names
}

/// PIDs of live processes started for `namespace` (their environment names it).
pub fn processes_of(namespace: &str) -> Vec<u32> {
    let needle = format!("{}={namespace}", mole_types::env::NAMESPACE);
    let mut pids = Vec::new();
    let Ok(entries) = std::fs::read_dir("/proc") else {
        return pids;
    };
    for entry in entries.flatten() {
        let Some(pid) = entry
            .file_name()
            .to_str()
            .and_then(|s| s.parse::<u32>().ok())
        else {
            continue;
        };
        let Ok(environ) = std::fs::read(entry.path().join("environ")) else {
            continue;
        };
        let is_zombie = std::fs::read_to_string(entry.path().join("stat"))
            .map(|s| {
                s.rsplit(')')
                    .next()
                    .is_some_and(|rest| rest.trim_start().starts_with('Z'))
            })
            .unwrap_or(false);
        if !is_zombie && environ.split(|b| *b == 0).any(|kv| kv == needle.as_bytes()) {
            pids.push(pid);
        }
    }
    pids
}

/// A running `mole up`; on drop (a failed test included) it and every process of its namespace
/// are killed.
pub struct Stack {
    pub namespace: String,
    pub out: PathBuf,
    child: Option<Child>,
}

impl Stack {
    /// Starts `mole up` with `args` in a fresh namespace and output directory.
    pub fn start(test: &str, args: &[&str]) -> Stack {
        let namespace = unique_namespace(test);
        let out = std::env::temp_dir().join(format!("mole-{namespace}"));
        let _ = std::fs::remove_dir_all(&out);
        let child = mole_command(&namespace, &out, args)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("start mole up");
        Stack {
            namespace,
            out,
            child: Some(child),
        }
    }

    pub fn pid(&self) -> u32 {
        self.child.as_ref().map_or(0, Child::id)
    }

    /// Waits for `mole up` to exit (or kills it after `timeout`).
    pub fn wait(mut self, timeout: Duration) -> Output {
        self.wait_inner(timeout)
    }

    fn wait_inner(&mut self, timeout: Duration) -> Output {
        let mut child = self.child.take().expect("running");
        let deadline = Instant::now() + timeout;
        while child.try_wait().ok().flatten().is_none() {
            if Instant::now() > deadline {
                let _ = child.kill();
                let output = child.wait_with_output().expect("reap");
                panic!(
                    "mole up did not finish within {timeout:?}\nstdout:\n{}\nstderr:\n{}\nlogs:\n{}",
                    String::from_utf8_lossy(&output.stdout),
                    String::from_utf8_lossy(&output.stderr),
                    logs(&self.out)
                );
            }
            std::thread::sleep(Duration::from_millis(50));
        }
        child.wait_with_output().expect("collect output")
    }

    /// Waits like [`Stack::wait`], then copies the output directory to `keep` before the stack
    /// (and its directory) is dropped.
    pub fn wait_and_copy(mut self, keep: &Path, timeout: Duration) -> Output {
        let output = self.wait_inner(timeout);
        copy_dir(&self.out, keep);
        output
    }

    /// Waits for the run to end, and requires that it succeeded: its summary, or a panic with
    /// its stderr and the tail of every log.
    pub fn succeeded(self, timeout: Duration) -> Summary {
        let keep = self.out.with_extension("kept");
        let output = self.wait_and_copy(&keep, timeout);
        let (logs, summary) = (logs(&keep), summary(&keep));
        let _ = std::fs::remove_dir_all(&keep);
        assert!(
            output.status.success(),
            "{}\n{logs}",
            String::from_utf8_lossy(&output.stderr)
        );
        summary
    }

    /// Waits until a role's log contains `needle`.
    pub fn wait_for_log(&self, role: &str, needle: &str, timeout: Duration) {
        let path = self.out.join("logs").join(format!("{role}.log"));
        let deadline = Instant::now() + timeout;
        loop {
            if std::fs::read_to_string(&path).is_ok_and(|t| t.contains(needle)) {
                return;
            }
            assert!(
                Instant::now() < deadline,
                "{} never said `{needle}`:\n{}",
                path.display(),
                logs(&self.out)
            );
            std::thread::sleep(Duration::from_millis(50));
        }
    }
}

impl Drop for Stack {
    fn drop(&mut self) {
        stop_and_clean(self.child.take(), &self.namespace);
    }
}

/// Stops a launcher (`mole up`, `mole replay`) however a test ends: SIGINT first (it stops its
/// children in order), SIGKILL after 15 s; then kills whatever of `namespace` is left and cleans
/// the dead nodes' resources.
pub fn stop_and_clean(child: Option<std::process::Child>, namespace: &str) {
    use nix::sys::signal::{Signal, kill};
    use nix::unistd::Pid;
    if let Some(mut child) = child {
        let _ = kill(Pid::from_raw(child.id() as i32), Signal::SIGINT);
        let deadline = Instant::now() + Duration::from_secs(15);
        while child.try_wait().ok().flatten().is_none() && Instant::now() < deadline {
            std::thread::sleep(Duration::from_millis(50));
        }
        let _ = child.kill();
        let _ = child.wait();
    }
    let leftovers = processes_of(namespace);
    for pid in &leftovers {
        let _ = kill(Pid::from_raw(*pid as i32), Signal::SIGKILL);
    }
    if !leftovers.is_empty() {
        std::thread::sleep(Duration::from_millis(200));
        mole_runtime::cleanup_dead_nodes();
    }
}

/// `mole up` for a namespace and output directory, run from the workspace root.
pub fn mole_command(namespace: &str, out: &Path, args: &[&str]) -> Command {
    let mut command = Command::new(bin_dir().join("mole"));
    command
        .current_dir(workspace())
        .env(mole_types::env::NAMESPACE, namespace)
        .env_remove("CARGO")
        .env_remove("CARGO_MANIFEST_DIR")
        .arg("up")
        .args(args)
        .args(["--namespace", namespace, "--out"])
        .arg(out)
        .arg("--quiet")
        .stdin(Stdio::null());
    command
}

/// Runs `mole` with raw arguments (for bad-input tests) and returns its output.
pub fn run_mole(args: &[&str]) -> Output {
    Command::new(bin_dir().join("mole"))
        .current_dir(workspace())
        .env_remove("CARGO")
        .env_remove("CARGO_MANIFEST_DIR")
        .args(args)
        .stdin(Stdio::null())
        .output()
        .expect("run mole")
}

/// What a finished command wrote, stdout then stderr, as text.
pub fn output_text(output: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&output.stdout),
        String::from_utf8_lossy(&output.stderr)
    )
}

/// `text` without the terminal colour codes tracing writes into the logs.
pub fn without_colours(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    let mut chars = text.chars();
    while let Some(c) = chars.next() {
        if c == '\u{1b}' {
            chars.by_ref().find(|&c| c == 'm');
        } else {
            out.push(c);
        }
    }
    out
}

/// The first endpoint a bridge listens on, once it wrote them (port 0 replaced by the port it
/// got) to [`mole_types::link::LISTENING_FILE`] in its output directory `out`; `None` if it
/// has not within `timeout`.
pub fn bridge_listening(out: &Path, timeout: Duration) -> Option<String> {
    let file = out.join(mole_types::link::LISTENING_FILE);
    let deadline = Instant::now() + timeout;
    loop {
        let first = std::fs::read_to_string(&file)
            .ok()
            .and_then(|text| text.lines().next().map(str::to_owned));
        if first.is_some() || Instant::now() > deadline {
            return first;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// Every process log of a run, for failure messages.
pub fn logs(out: &Path) -> String {
    let mut text = String::new();
    if let Ok(entries) = std::fs::read_dir(out.join("logs")) {
        for entry in entries.flatten() {
            let content = std::fs::read_to_string(entry.path()).unwrap_or_default();
            let tail: String = content
                .lines()
                .rev()
                .take(15)
                .collect::<Vec<_>>()
                .into_iter()
                .rev()
                .collect::<Vec<_>>()
                .join("\n");
            text.push_str(&format!("--- {} ---\n{tail}\n", entry.path().display()));
        }
    }
    text
}

/// A lockstep summary without what differs from run to run (wall time, latencies, wall-clock
/// rates): what the scenario and seed alone decide.
pub fn deterministic(summary: &Summary) -> Summary {
    Summary {
        wall_time_s: 0.0,
        launcher_wall_time_s: None,
        loop_latency_us: Default::default(),
        estimator_update_us: Default::default(),
        topics: Default::default(),
        ..summary.clone()
    }
}

/// The fields (JSON paths such as `slam.landmark_rmse_m` or `coverage_steps.0.9`) whose values
/// differ between two summaries, in order; empty when they are equal.
pub fn differing_fields(a: &Summary, b: &Summary) -> Vec<String> {
    fn walk(path: &str, a: &serde_json::Value, b: &serde_json::Value, out: &mut Vec<String>) {
        use serde_json::Value::Object;
        match (a, b) {
            (Object(a), Object(b)) => {
                let keys: std::collections::BTreeSet<&String> = a.keys().chain(b.keys()).collect();
                for key in keys {
                    let null = serde_json::Value::Null;
                    let child = match path {
                        "" => key.clone(),
                        _ => format!("{path}.{key}"),
                    };
                    walk(
                        &child,
                        a.get(key).unwrap_or(&null),
                        b.get(key).unwrap_or(&null),
                        out,
                    );
                }
            }
            _ if a != b => out.push(path.to_string()),
            _ => {}
        }
    }
    let json = |s: &Summary| serde_json::to_value(s).expect("a summary is JSON");
    let mut out = Vec::new();
    walk("", &json(a), &json(b), &mut out);
    out
}

/// Reads a run's summary.json into the schema the monitor and the launcher write.
pub fn summary(out: &Path) -> Summary {
    let path = out.join("summary.json");
    mole_monitor::read_summary(&path)
        .unwrap_or_else(|e| panic!("no summary at {}: {e}\n{}", path.display(), logs(out)))
}

fn copy_dir(from: &Path, to: &Path) {
    let _ = std::fs::create_dir_all(to.join("logs"));
    for sub in [Path::new(""), Path::new("logs")] {
        if let Ok(entries) = std::fs::read_dir(from.join(sub)) {
            for entry in entries.flatten() {
                if entry.path().is_file() {
                    let _ = std::fs::copy(entry.path(), to.join(sub).join(entry.file_name()));
                }
            }
        }
    }
}

/// What every process binary's command line must do: `--help` names the flags every process
/// shares, and a bad `--mode` exits 2 naming the value it refused.
pub fn check_process_cli(bin: &str) {
    let output = Command::new(bin)
        .arg("--help")
        .output()
        .expect("run the process");
    assert!(output.status.success(), "{bin} --help failed");
    let text = String::from_utf8_lossy(&output.stdout);
    assert!(
        text.contains("--namespace") && text.contains("--mode"),
        "{text}"
    );
    let output = Command::new(bin)
        .args(["--mode", "warp"])
        .output()
        .expect("run the process");
    assert_eq!(output.status.code(), Some(2), "{bin} --mode warp");
    assert!(String::from_utf8_lossy(&output.stderr).contains("warp"));
}

/// iceoryx2 files present now that were not in `before`: what a run left behind. (Files that
/// vanished are stale resources of earlier dead runs that this run's start-up cleaned.)
pub fn left_behind(before: &[String]) -> Vec<String> {
    shm_files()
        .into_iter()
        .filter(|f| !before.contains(f))
        .collect()
}

/// A context of the test's own in a running realtime stack (a rogue publisher, an observer).
pub fn join_realtime_stack(namespace: &str, role: &str) -> mole_runtime::Context {
    let args = mole_runtime::CommonArgs::attach(namespace, mole_runtime::ClockMode::Realtime);
    let shutdown = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    mole_runtime::Context::with_shutdown_flag(role, &args, shutdown)
        .unwrap_or_else(|e| panic!("{role} joins {namespace}: {e}"))
}

/// A test whose prerequisite is missing (the Python package, root for the other-user check).
/// Under CI (`CI` set) it fails, so a missing install step cannot pass as green; elsewhere it
/// prints `SKIPPED <test>: <reason>` straight to stderr, past the test harness's capture, so the
/// reason shows in `cargo test`'s normal output. Call it, then return from the test.
pub fn skip(test: &str, reason: &str) {
    use std::io::Write;
    if std::env::var_os("CI").is_some_and(|v| !v.is_empty()) {
        panic!("{test}: prerequisite missing under CI, where .ci/run provides it: {reason}");
    }
    let _ = writeln!(std::io::stderr().lock(), "SKIPPED {test}: {reason}");
}

impl Stack {
    /// Starts `mole up` with `args` in a given namespace (one a killed stack left behind) and a
    /// fresh output directory.
    pub fn start_in(namespace: &str, args: &[&str]) -> Stack {
        let out = std::env::temp_dir().join(format!("mole-{namespace}"));
        let _ = std::fs::remove_dir_all(&out);
        let child = mole_command(namespace, &out, args)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("start mole up");
        Stack {
            namespace: namespace.to_string(),
            out,
            child: Some(child),
        }
    }
}

/// The pid of `program` running in `namespace`.
pub fn pid_of(namespace: &str, program: &str) -> Option<u32> {
    // The kernel keeps the first 15 bytes of a program's name in `comm`.
    let comm = &program[..program.len().min(15)];
    processes_of(namespace).into_iter().find(|pid| {
        std::fs::read_to_string(format!("/proc/{pid}/comm")).is_ok_and(|c| c.trim() == comm)
    })
}

/// Waits until `program` runs in `namespace` with a pid other than `old`.
pub fn wait_for_new_pid(
    namespace: &str,
    program: &str,
    old: Option<u32>,
    timeout: Duration,
    out: &std::path::Path,
) -> u32 {
    let deadline = std::time::Instant::now() + timeout;
    loop {
        if let Some(pid) = pid_of(namespace, program).filter(|p| Some(*p) != old) {
            return pid;
        }
        assert!(
            std::time::Instant::now() < deadline,
            "{program} did not come back within {timeout:?}\n{}",
            logs(out)
        );
        std::thread::sleep(Duration::from_millis(10));
    }
}

/// Sends `signal` to `pid`.
pub fn signal(pid: u32, signal: nix::sys::signal::Signal) {
    nix::sys::signal::kill(nix::unistd::Pid::from_raw(pid as i32), signal).expect("signal");
}

/// The PIDs of the processes that made a record. iceoryx2 (0.10) names node records, services'
/// segments and ports' segments by system-wide ids whose bits 64..96 are the creating process's
/// PID; a name holds one or two such ids.
pub fn makers(record: &str) -> Vec<u32> {
    let name = record.rsplit('/').next().unwrap_or(record);
    name.split(|c: char| !c.is_ascii_digit())
        .filter(|digits| digits.len() >= 20)
        .filter_map(|digits| digits.parse::<u128>().ok())
        .map(|id| (id >> 64) as u32)
        .collect()
}

/// The records in `now` that processes of `pids` made.
pub fn made_by<'a>(
    now: impl IntoIterator<Item = &'a String>,
    pids: &std::collections::BTreeSet<u32>,
) -> Vec<String> {
    now.into_iter()
        .filter(|r| makers(r).iter().any(|pid| pids.contains(pid)))
        .cloned()
        .collect()
}

/// A Python with the `mcap` package (target/python-env first, then python3 on PATH), or why
/// there is none.
pub fn python_with_mcap() -> Result<String, String> {
    python_importing("mcap.reader, lz4", "the mcap package")
}

/// A Python that also has mcap-ros2-support's CDR decoder (`scripts/python-env.sh`), or why
/// there is none.
pub fn python_with_mcap_ros2() -> Result<String, String> {
    python_importing(
        "mcap.reader, lz4, mcap_ros2.decoder",
        "the mcap and mcap-ros2-support packages",
    )
}

/// target/python-env's Python, else the system's, if it imports `modules`.
fn python_importing(modules: &str, what: &str) -> Result<String, String> {
    let venv = workspace().join("target/python-env/bin/python3");
    let mut reasons = Vec::new();
    for candidate in [venv.display().to_string(), "python3".to_string()] {
        match std::process::Command::new(&candidate)
            .args(["-c", &format!("import {modules}")])
            .output()
        {
            Err(e) => reasons.push(format!("{candidate}: {e}")),
            Ok(out) if !out.status.success() => {
                reasons.push(format!("{candidate} cannot import {modules}"));
            }
            Ok(_) => return Ok(candidate),
        }
    }
    Err(format!(
        "no Python with {what} ({}); scripts/python-env.sh installs one",
        reasons.join("; ")
    ))
}

/// `node tests/support/validate_foxglove.mjs target/node-env`: Foxglove's published schemas and
/// ajv, as scripts/node-env.sh installs them, ready to validate an export; or why it cannot
/// run (no node, no packages).
pub fn foxglove_validator() -> Result<Command, String> {
    node_env_script("validate_foxglove.mjs", "@foxglove/schemas and ajv")
}

/// `node tests/support/foxglove_client.mjs target/node-env`: `@foxglove/ws-protocol`'s client
/// over `ws`, as scripts/node-env.sh installs them; or why it cannot run.
pub fn foxglove_client() -> Result<Command, String> {
    node_env_script("foxglove_client.mjs", "@foxglove/ws-protocol and ws")
}

/// `node tests/support/SCRIPT target/node-env`, once `SCRIPT … --versions` showed that node
/// loads its `packages` from there.
fn node_env_script(script: &str, packages: &str) -> Result<Command, String> {
    let script = workspace().join("tests/support").join(script);
    let env_dir = workspace().join("target/node-env");
    let command = || {
        let mut node = Command::new("node");
        node.arg(&script).arg(&env_dir);
        node
    };
    match command().arg("--versions").output() {
        Err(e) => Err(format!("no node ({e}); Debian: apt-get install nodejs npm")),
        Ok(out) if !out.status.success() => Err(format!(
            "node cannot load {packages} from {} ({}); scripts/node-env.sh installs them",
            env_dir.display(),
            String::from_utf8_lossy(&out.stderr)
                .lines()
                .find(|l| l.contains("Error"))
                .unwrap_or("")
        )),
        Ok(_) => Ok(command()),
    }
}

/// A context of the test's own in a running stack of clock `mode` (an operator, an observer).
/// Its statistics are silenced: it is no role of the stack.
pub fn join_stack(
    namespace: &str,
    role: &str,
    mode: mole_runtime::ClockMode,
) -> mole_runtime::Context {
    let args = mole_runtime::CommonArgs::attach(namespace, mode);
    let shutdown = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    let mut ctx = mole_runtime::Context::with_shutdown_flag(role, &args, shutdown)
        .unwrap_or_else(|e| panic!("{role} joins {namespace}: {e}"));
    ctx.silence_stats();
    ctx
}

impl Stack {
    /// `mole up`'s stdout, line by line, from a thread that reads it to its end (so the
    /// launcher never blocks on a full pipe); `None` when it was taken already.
    pub fn stdout_lines(&mut self) -> Option<std::sync::mpsc::Receiver<String>> {
        use std::io::BufRead;
        let stdout = self.child.as_mut()?.stdout.take()?;
        let (lines, received) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            for line in std::io::BufReader::new(stdout).lines() {
                let Ok(line) = line else { break };
                if lines.send(line).is_err() {
                    break;
                }
            }
        });
        Some(received)
    }
}

/// The URL `mole up --view` or `mole view` printed (`view: URL`), read from `lines` within
/// `timeout`.
pub fn view_url(lines: &std::sync::mpsc::Receiver<String>, timeout: Duration) -> String {
    let deadline = Instant::now() + timeout;
    let mut seen = Vec::new();
    while let Some(left) = deadline.checked_duration_since(Instant::now()) {
        match lines.recv_timeout(left) {
            Ok(line) => match line.strip_prefix("view: ") {
                Some(url) => return url.trim().to_string(),
                None => seen.push(line),
            },
            Err(_) => break,
        }
    }
    panic!(
        "no `view: URL` line within {timeout:?}; stdout was:\n{}",
        seen.join("\n")
    )
}

/// How long a `mole replay` of a test may take.
pub const REPLAY_TIMEOUT: Duration = Duration::from_secs(300);

/// A running `mole replay`; on drop (a failed test included) it and every process of its
/// namespace are stopped.
pub struct Replay {
    pub namespace: String,
    pub out: PathBuf,
    child: Option<Child>,
}

impl Replay {
    /// `mole replay FILE` with `args` in a fresh namespace, its output under `dir`; `env` is
    /// added to its environment (and so to every process it starts).
    pub fn start(dir: &Path, file: &Path, args: &[&str], env: &[(&str, &str)]) -> Replay {
        let namespace = unique_namespace("replay");
        let out = dir.join(&namespace);
        let child = Command::new(bin_dir().join("mole"))
            .current_dir(workspace())
            .env_remove("CARGO")
            .env_remove("CARGO_MANIFEST_DIR")
            .envs(env.iter().copied())
            .arg("replay")
            .arg(file)
            .args(args)
            .args(["--namespace", &namespace, "--quiet", "--out"])
            .arg(&out)
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("start mole replay");
        Replay {
            namespace,
            out,
            child: Some(child),
        }
    }

    /// Waits for `mole replay` to exit (killing it after [`REPLAY_TIMEOUT`]); nothing of its
    /// namespace may be left running.
    pub fn wait(mut self) -> Output {
        let mut child = self.child.take().expect("running");
        let deadline = Instant::now() + REPLAY_TIMEOUT;
        while child.try_wait().ok().flatten().is_none() {
            assert!(
                Instant::now() < deadline,
                "mole replay did not finish within {REPLAY_TIMEOUT:?}\n{}",
                logs(&self.out)
            );
            std::thread::sleep(Duration::from_millis(50));
        }
        let output = child.wait_with_output().expect("collect output");
        assert!(
            processes_of(&self.namespace).is_empty(),
            "processes left behind\n{}",
            logs(&self.out)
        );
        output
    }
}

impl Drop for Replay {
    fn drop(&mut self) {
        stop_and_clean(self.child.take(), &self.namespace);
    }
}

/// Every message of `topic` in the MCAP file at `path`, in file order, as (log time, bytes).
pub fn mcap_messages(path: &Path, topic: &str) -> Vec<(u64, Vec<u8>)> {
    let bytes = std::fs::read(path).expect("read the MCAP file");
    mcap::MessageStream::new(&bytes)
        .expect("an MCAP file")
        .map(|m| m.expect("a complete MCAP file"))
        .filter(|m| m.channel.topic == topic)
        .map(|m| (m.log_time, m.data.into_owned()))
        .collect()
}
