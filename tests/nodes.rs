//! Processes killed while they start leave nothing behind: after many start-and-kill cycles and
//! one normal `mole up`, iceoryx2's node records and shared memory are as they were, and the
//! launcher does not warn about dead nodes it could not clean.

use mole_integration_tests::*;
use mole_types::GRAPH;
use nix::sys::signal::{Signal, kill};
use nix::unistd::Pid;
use std::collections::BTreeSet;
use std::process::{Child, Command, Stdio};
use std::time::Duration;

/// Start-and-kill cycles of the whole set of processes.
const CYCLES: u64 = 50;
/// The kills of a cycle are spread over this window after the processes are started: from
/// before their node exists, through their services and ports, to after they are ready.
const KILL_WINDOW_MS: u64 = 300;
const RUN_TIMEOUT: Duration = Duration::from_secs(240);

/// The processes of one cycle; on drop (a failed test included) every one is killed and reaped.
struct Cycle(Vec<Child>);

impl Drop for Cycle {
    fn drop(&mut self) {
        for child in &mut self.0 {
            let _ = child.kill();
            let _ = child.wait();
        }
    }
}

/// Starts every process of the graph in `namespace` and SIGKILLs each at its own moment (varied
/// by `cycle` and role); returns their PIDs.
fn start_and_kill(cycle: u64, namespace: &str) -> Vec<u32> {
    let bin = bin_dir();
    let mut processes = Cycle(Vec::new());
    for spec in GRAPH {
        let child = Command::new(bin.join(spec.program))
            .current_dir(workspace())
            .env(mole_types::env::NAMESPACE, namespace)
            .env_remove("CARGO")
            .env_remove("CARGO_MANIFEST_DIR")
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap_or_else(|e| panic!("start {}: {e}", spec.program));
        processes.0.push(child);
    }
    let pids: Vec<u32> = processes.0.iter().map(Child::id).collect();
    let mut kills: Vec<(u64, u32)> = pids
        .iter()
        .enumerate()
        .map(|(i, pid)| ((cycle * 37 + i as u64 * 53) % KILL_WINDOW_MS, *pid))
        .collect();
    kills.sort();
    let mut elapsed = 0;
    for (at, pid) in kills {
        std::thread::sleep(Duration::from_millis(at - elapsed));
        elapsed = at;
        let _ = kill(Pid::from_raw(pid as i32), Signal::SIGKILL);
    }
    pids
}

/// iceoryx2's node records and shared memory: the entries of /tmp/iceoryx2/nodes and the
/// iceoryx2 files of /dev/shm.
fn records() -> BTreeSet<String> {
    shm_files()
        .into_iter()
        .filter(|f| !f.starts_with("/tmp/iceoryx2/services/"))
        .collect()
}

/// 50 cycles of starting the six processes and killing them at varied early moments, then one
/// normal `mole up`, leave no node record or shared memory of the killed processes, and the
/// launcher warns about no dead node.
#[test]
fn killed_starts_leave_no_node_records_or_shared_memory() {
    let _serial = serial();
    let before = records();
    let prefix = unique_namespace("nodes");
    let mut pids = BTreeSet::new();
    let mut seen_while_cycling = false;
    for cycle in 0..CYCLES {
        pids.extend(start_and_kill(cycle, &format!("{prefix}-{cycle}")));
        seen_while_cycling |= !made_by(&records(), &pids).is_empty();
    }
    // The PIDs are read right: the killed processes' records are there before the clean-up.
    assert!(
        seen_while_cycling,
        "no record names a killed process's PID: the test cannot see what they leave"
    );
    // What a process was killed while making is removed only once it is older than this.
    std::thread::sleep(mole_runtime::HALF_MADE_AGE + Duration::from_secs(1));

    let stack = Stack::start("nodes", &["--mode", "lockstep", "--ticks", "20"]);
    let output = stack.wait(RUN_TIMEOUT);
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(output.status.success(), "mole up failed:\n{stderr}");

    let after = records();
    let left = made_by(&after, &pids);
    let services = services_naming(&format!("mole/{prefix}-"));
    let warnings: Vec<&str> = stderr
        .lines()
        .filter(|l| l.contains("could not clean"))
        .collect();
    assert!(
        left.is_empty() && services.is_empty() && warnings.is_empty(),
        "{} node records and shared-memory files of killed processes are left ({} entries \
         before the test, {} after):\n{}\n{} of their services are left:\n{}\nthe launcher \
         warns:\n{}",
        left.len(),
        before.len(),
        after.len(),
        left.join("\n"),
        services.len(),
        services.join("\n"),
        warnings.join("\n")
    );
}

/// The service records (static configs in /tmp/iceoryx2/services) whose text names a service
/// starting with `name`: a service is named by a hash, its static config holds the name.
fn services_naming(name: &str) -> Vec<String> {
    shm_files()
        .into_iter()
        .filter(|f| f.starts_with("/tmp/iceoryx2/services/"))
        .filter(|f| {
            std::fs::read(f)
                .is_ok_and(|text| text.windows(name.len()).any(|w| w == name.as_bytes()))
        })
        .collect()
}
