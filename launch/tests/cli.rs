//! The mole binary's command line (the stack itself is tested in tests/).

use std::process::Command;

const BIN: &str = env!("CARGO_BIN_EXE_mole");

#[test]
fn help_lists_up() {
    let output = Command::new(BIN).arg("--help").output().expect("run mole");
    assert!(output.status.success());
    assert!(String::from_utf8_lossy(&output.stdout).contains("up"));
}

#[test]
fn bad_arguments_exit_2() {
    for args in [
        &["up", "--mode", "warp"][..],
        &["up", "--ticks", "-3"],
        &["fly"],
        &["up", "--duration", "nan"],
    ] {
        let output = Command::new(BIN)
            .args(args)
            .env_remove("CARGO")
            .output()
            .expect("run mole");
        assert_eq!(
            output.status.code(),
            Some(2),
            "{args:?}: {}",
            String::from_utf8_lossy(&output.stderr)
        );
    }
}

#[test]
fn bench_and_top_refuse_bad_input_with_exit_2() {
    let cases: [&[&str]; 4] = [
        &["bench", "ipc", "--sizes", "64,999"],
        &[
            "bench",
            "ipc",
            "--quick",
            "--json",
            "/nonexistent-dir/report.json",
        ],
        &["bench", "stack", "--json", "/nonexistent-dir/report.json"],
        &["top", "--namespace", "no-stack-runs-here", "--once"],
    ];
    for args in cases {
        let output = Command::new(BIN)
            .args(args)
            .env_remove("CARGO")
            .output()
            .expect("run mole");
        let err = String::from_utf8_lossy(&output.stderr);
        assert_eq!(output.status.code(), Some(2), "{args:?}: {err}");
        assert!(err.contains("error:"), "{args:?}: {err}");
    }
}
