//! The mole-localization binary's command line: help works, bad arguments exit 2 with a message.

use std::process::Command;

const BIN: &str = env!("CARGO_BIN_EXE_mole-localization");

#[test]
fn the_common_command_line_works() {
    mole_integration_tests::check_process_cli(BIN);
}

#[test]
fn an_unknown_estimator_exits_2() {
    let output = Command::new(BIN)
        .args(["--estimator", "oracle"])
        .output()
        .expect("run");
    assert_eq!(output.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&output.stderr).contains("oracle"));
}

/// `--peer` is refused before the process joins any stack (exit 2, the reason on stderr): with
/// an estimator that cannot fuse a peer's map (naming the one that can), with this robot's own
/// namespace, and with `--fuse-every 0`.
#[test]
fn a_peer_the_process_cannot_fuse_with_exits_2() {
    let refusals: [(&[&str], &str); 3] = [
        (
            &["--estimator", "fastslam", "--peer", "robot1"],
            "--estimator ekf-slam",
        ),
        (
            &["--estimator", "ekf-slam", "--peer", "robot0"],
            "own namespace",
        ),
        (
            &[
                "--estimator",
                "ekf-slam",
                "--peer",
                "robot1",
                "--fuse-every",
                "0",
            ],
            "--fuse-every",
        ),
    ];
    for (args, reason) in refusals {
        let output = Command::new(BIN)
            .args(["--namespace", "robot0"])
            .args(args)
            .output()
            .expect("run");
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert_eq!(output.status.code(), Some(2), "{args:?}: {stderr}");
        assert!(stderr.contains(reason), "{args:?}: {stderr}");
    }
}
