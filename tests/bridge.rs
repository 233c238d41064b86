//! One stack on two "machines": the two halves of launch/stacks/split, each started by its own
//! `mole up` in its own namespace, joined by their bridges over zenoh on loopback TCP.

use mole_integration_tests::*;
use mole_monitor::Summary;
use mole_runtime::{ClockMode, Subscriber};
use mole_types::{Truth, topics};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// Where the on-board bridge of the tests listens: any port the system gives, which it reports.
const ANY_PORT: &str = "tcp/127.0.0.1:0";

/// How long a half may take to say where its bridge listens (it builds the binaries first).
const REPORT_TIMEOUT: Duration = Duration::from_secs(120);

/// One half's launch file (`onboard` or `offboard`) written to `dir`: its peer's namespace
/// `peer`, its one endpoint `endpoint` (the on-board half listens on it, the off-board half
/// connects to it); `bridge_backoff_ms`: how long a killed bridge stays down.
fn half_file(
    dir: &Path,
    half: &str,
    peer: &str,
    endpoint: &str,
    bridge_backoff_ms: u64,
) -> PathBuf {
    let split = workspace().join("launch/stacks/split");
    let text =
        std::fs::read_to_string(split.join(format!("{half}.toml"))).expect("split launch file");
    let peer_was = if half == "onboard" {
        "offboard"
    } else {
        "onboard"
    };
    let text = text
        .replace(
            &format!("peer_namespace = \"{peer_was}\""),
            &format!("peer_namespace = \"{peer}\""),
        )
        .replace("tcp/127.0.0.1:7447", endpoint)
        // The bridge is the first process of both files.
        .replacen(
            "backoff_ms = 200,",
            &format!("backoff_ms = {bridge_backoff_ms},"),
            1,
        );
    let path = dir.join(format!("{half}.toml"));
    std::fs::write(&path, text).expect("write launch file");
    path
}

/// `mole up FILE ARGS…` in `namespace`.
fn start_half(namespace: &str, file: &Path, args: &[&str]) -> Stack {
    let mut all = vec![file.to_str().expect("utf-8 path")];
    all.extend(args);
    Stack::start_in(namespace, &all)
}

/// Where the on-board half's bridge listens, as it reports it.
fn listening(onboard: &Stack) -> String {
    bridge_listening(&onboard.out, REPORT_TIMEOUT).unwrap_or_else(|| {
        panic!(
            "the on-board bridge never said where it listens:\n{}",
            logs(&onboard.out)
        )
    })
}

/// Both halves, the on-board one first: its bridge listens on port 0, and the off-board half
/// connects to the port it reports.
struct Split {
    onboard: Stack,
    offboard: Stack,
    _dir: TempDir,
}

impl Split {
    fn start(test: &str, args: &[&str], bridge_backoff_ms: u64) -> Split {
        let dir = TempDir::new(test);
        let (on_ns, off_ns) = (
            unique_namespace(&format!("{test}-on")),
            unique_namespace(&format!("{test}-off")),
        );
        let on_file = half_file(&dir.0, "onboard", &off_ns, ANY_PORT, bridge_backoff_ms);
        let onboard = start_half(&on_ns, &on_file, args);
        let endpoint = listening(&onboard);
        let off_file = half_file(&dir.0, "offboard", &on_ns, &endpoint, bridge_backoff_ms);
        let offboard = start_half(&off_ns, &off_file, args);
        Split {
            onboard,
            offboard,
            _dir: dir,
        }
    }
}

/// A lockstep summary without what differs from run to run or from one host to two (the
/// roles that ran here): what the scenario and seed alone decide.
fn deterministic_across_hosts(summary: &Summary) -> Summary {
    Summary {
        restarts: Default::default(),
        ..deterministic(summary)
    }
}

#[test]
fn a_split_lockstep_run_matches_the_single_host_run() {
    let _serial = serial();
    let before = shm_files();
    let args = ["--mode", "lockstep", "--ticks", "1500", "--seed", "7"];

    let single = Stack::start("split-single", &args);
    let single_out = single.out.clone();
    let keep = TempDir::new("split-single-keep");
    let output = single.wait_and_copy(&keep.0, Duration::from_secs(300));
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    let single = summary(&keep.0);
    drop(single_out);

    let split = Split::start("split-lockstep", &args, 200);
    let Split {
        onboard,
        offboard,
        _dir,
    } = split;
    let on_keep = TempDir::new("split-on-keep");
    let off_keep = TempDir::new("split-off-keep");
    let on_output = onboard.wait_and_copy(&on_keep.0, Duration::from_secs(300));
    let off_output = offboard.wait_and_copy(&off_keep.0, Duration::from_secs(300));
    assert!(
        off_output.status.success() && on_output.status.success(),
        "off board: {}\non board: {}\n{}\n{}",
        String::from_utf8_lossy(&off_output.stderr),
        String::from_utf8_lossy(&on_output.stderr),
        logs(&off_keep.0),
        logs(&on_keep.0)
    );
    assert!(
        String::from_utf8_lossy(&on_output.stdout).contains("this half has no monitor"),
        "{}",
        String::from_utf8_lossy(&on_output.stdout)
    );
    let split = summary(&off_keep.0);
    assert_eq!(split.ticks, 1500, "{split:#?}");
    assert_eq!(split.grid_hash, single.grid_hash, "frontier grids differ");
    assert_eq!(
        split.contact_hash, single.contact_hash,
        "contact grids differ"
    );
    assert_eq!(
        deterministic_across_hosts(&split),
        deterministic_across_hosts(&single)
    );
    assert_eq!(split.restarts.get("bridge"), Some(&0), "{split:#?}");
    assert_eq!(
        left_behind(&before),
        Vec::<String>::new(),
        "shared memory left behind"
    );
}

/// Truths read from a running stack, kept in order.
struct TruthTap {
    subscriber: Subscriber<Truth>,
    _ctx: mole_runtime::Context,
}

impl TruthTap {
    fn open(namespace: &str) -> TruthTap {
        let ctx = join_stack(namespace, "test-truth", ClockMode::Realtime);
        let subscriber = ctx
            .passive_subscriber(topics::WORLD_TRUTH)
            .expect("subscribe to world/truth");
        TruthTap {
            subscriber,
            _ctx: ctx,
        }
    }

    /// Reads truths until `done` says so over the truths read in this call (`None`: not yet),
    /// or fails after `timeout` naming `what`.
    fn until<T>(
        &mut self,
        what: &str,
        timeout: Duration,
        logs_of: &[&Path],
        mut done: impl FnMut(&[Truth]) -> Option<T>,
    ) -> T {
        let deadline = Instant::now() + timeout;
        let mut seen: Vec<Truth> = Vec::new();
        loop {
            self.subscriber.drain(|t| seen.push(*t));
            if let Some(found) = done(&seen) {
                return found;
            }
            assert!(
                Instant::now() < deadline,
                "{what}: not within {timeout:?} ({} truths read)\n{}",
                seen.len(),
                logs_of.iter().map(|p| logs(p)).collect::<String>()
            );
            std::thread::sleep(Duration::from_millis(10));
        }
    }
}

/// `n` truths in a row that applied no command (none came: the link is down) and left the robot
/// standing.
fn stopped_for(truths: &[Truth], n: usize) -> Option<()> {
    let standing = |t: &Truth| t.cmd_latency_ns == 0 && t.v == 0.0 && t.omega == 0.0;
    truths
        .windows(n)
        .any(|w| w.iter().all(standing))
        .then_some(())
}

/// `n` truths in a row that applied a command that came back across the link.
fn commanded_for(truths: &[Truth], n: usize) -> Option<()> {
    truths
        .windows(n)
        .any(|w| w.iter().all(|t| t.cmd_latency_ns > 0))
        .then_some(())
}

/// Which half's bridge a fault test kills.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Side {
    OnBoard,
    OffBoard,
}

/// Kills `side`'s bridge mid-run (realtime): the launcher on that side restarts it, the other
/// side's bridge reports the link going and coming back, the robot stands while the link is
/// down (the world stops on a stale command) and goes on after.
fn a_killed_bridge_stops_the_robot_until_the_link_is_back(side: Side) {
    let _serial = serial();
    let before = shm_files();
    // A killed bridge comes back after 2 s: longer than the 0.5 s after which the world stops
    // the robot on a stale command.
    let split = Split::start(
        "split-faults",
        &["--mode", "realtime", "--ticks", "100000"],
        2000,
    );
    let (on_out, off_out) = (split.onboard.out.clone(), split.offboard.out.clone());
    let both: [&Path; 2] = [&on_out, &off_out];
    split
        .onboard
        .wait_for_log("world", "ready", Duration::from_secs(60));
    let mut truth = TruthTap::open(&split.onboard.namespace);
    truth.until(
        "commands arrive across the link",
        Duration::from_secs(30),
        &both,
        |t| commanded_for(t, 50),
    );

    let (killed, out, peer_out) = match side {
        Side::OnBoard => (&split.onboard, &on_out, &off_out),
        Side::OffBoard => (&split.offboard, &off_out, &on_out),
    };
    let old = pid_of(&killed.namespace, "mole-bridge").expect("a bridge running");
    signal(old, nix::sys::signal::Signal::SIGKILL);
    truth.until(
        "bridge killed: the robot stops",
        Duration::from_secs(20),
        &both,
        |t| stopped_for(t, 20),
    );
    wait_for_new_pid(
        &killed.namespace,
        "mole-bridge",
        Some(old),
        Duration::from_secs(30),
        out,
    );
    truth.until(
        "bridge back: commands again",
        Duration::from_secs(30),
        &both,
        |t| commanded_for(t, 50),
    );
    let peer_log = std::fs::read_to_string(peer_out.join("logs/bridge.log")).unwrap_or_default();
    assert!(
        peer_log.contains("link down") && peer_log.matches("link up").count() >= 2,
        "the peer bridge did not report the link going and coming back:\n{peer_log}"
    );

    drop(truth);
    let Split {
        onboard,
        offboard,
        _dir,
    } = split;
    let (on_output, _on_keep) = interrupt(onboard);
    let (_off_output, off_keep) = interrupt(offboard);
    // The launcher of the killed side reported the death and restarted the bridge once.
    let off = summary(&off_keep.0);
    match side {
        Side::OnBoard => {
            let on_err = String::from_utf8_lossy(&on_output.stderr);
            assert!(
                on_err.contains("process restarted") && on_err.contains("bridge"),
                "the on-board launcher reports the restart:\n{on_err}"
            );
            assert_eq!(off.restarts.get("bridge"), Some(&0), "{off:#?}");
        }
        Side::OffBoard => assert_eq!(off.restarts.get("bridge"), Some(&1), "{off:#?}"),
    }
    assert_eq!(
        left_behind(&before),
        Vec::<String>::new(),
        "shared memory left behind"
    );
}

/// Stops a half with Ctrl-C and keeps its output directory.
fn interrupt(stack: Stack) -> (std::process::Output, TempDir) {
    let keep = TempDir::new("split-faults-keep");
    signal(stack.pid(), nix::sys::signal::Signal::SIGINT);
    let output = stack.wait_and_copy(&keep.0, Duration::from_secs(60));
    (output, keep)
}

#[test]
fn killing_the_onboard_bridge_stops_the_robot_until_the_link_is_back() {
    a_killed_bridge_stops_the_robot_until_the_link_is_back(Side::OnBoard);
}

#[test]
fn killing_the_offboard_bridge_stops_the_robot_until_the_link_is_back() {
    a_killed_bridge_stops_the_robot_until_the_link_is_back(Side::OffBoard);
}

/// The off-board half started in a namespace the on-board half does not expect: each bridge
/// sees the other's liveliness token, says so with both namespaces, and gives up after the same
/// wait (`PEER_TIMEOUT`), so both `mole up` end with exit 2 (the bridge refused its input: the
/// two launch files and namespaces do not meet), each naming what its bridge saw on the link.
#[test]
fn halves_whose_namespaces_do_not_meet_both_end_saying_what_they_see() {
    let _serial = serial();
    let before = shm_files();
    let dir = TempDir::new("split-mismatch");
    let on_ns = unique_namespace("split-mismatch-on");
    // The namespace the on-board half expects, and the one the off-board half runs in.
    let (expected, wrong) = (
        unique_namespace("split-mismatch-off"),
        unique_namespace("split-mismatch-wrong"),
    );
    let args = ["--mode", "realtime", "--ticks", "100000"];
    let on_file = half_file(&dir.0, "onboard", &expected, ANY_PORT, 200);
    let onboard = start_half(&on_ns, &on_file, &args);
    let endpoint = listening(&onboard);
    let off_file = half_file(&dir.0, "offboard", &on_ns, &endpoint, 200);
    let offboard = start_half(&wrong, &off_file, &args);
    let (on_out, off_out) = (onboard.out.clone(), offboard.out.clone());

    // Against hanging only: both end on their own, on the bridges' deadline.
    let on_output = onboard.wait(Duration::from_secs(120));
    let off_output = offboard.wait(Duration::from_secs(120));
    for (half, output, out, own, own_peer, seen, seen_peer) in [
        (
            "on board", &on_output, &on_out, &on_ns, &expected, &wrong, &on_ns,
        ),
        (
            "off board",
            &off_output,
            &off_out,
            &wrong,
            &on_ns,
            &on_ns,
            &expected,
        ),
    ] {
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert_eq!(
            output.status.code(),
            Some(2),
            "{half}:\n{stderr}\n{}",
            logs(out)
        );
        for needle in [
            format!(
                "`bridge` refused its input: the peer's bridge did not come within {:?}",
                mole_types::link::PEER_TIMEOUT
            ),
            // The bridge that gives up second saw the other leave.
            format!("the bridge of namespace `{seen}` with peer_namespace `{seen_peer}`"),
            format!("this half is namespace `{own}` with peer_namespace `{own_peer}`"),
        ] {
            assert!(
                stderr.contains(&needle),
                "{half}: no `{needle}` in:\n{stderr}"
            );
        }
        let bridge_log = std::fs::read_to_string(out.join("logs/bridge.log")).unwrap_or_default();
        let warning = format!("another bridge on the link: namespace `{seen}`");
        assert!(
            bridge_log.contains(&warning),
            "{half}: the bridge did not say `{warning}` when it saw it:\n{bridge_log}"
        );
    }
    assert_eq!(
        left_behind(&before),
        Vec::<String>::new(),
        "shared memory left behind"
    );
}
