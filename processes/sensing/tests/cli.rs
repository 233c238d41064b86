//! The mole-sensing binary's command line: help works, bad arguments exit 2 with a message.

use std::process::Command;

const BIN: &str = env!("CARGO_BIN_EXE_mole-sensing");

#[test]
fn help_describes_the_process() {
    let output = Command::new(BIN)
        .arg("--help")
        .output()
        .expect("run mole-sensing");
    assert!(output.status.success());
    let text = String::from_utf8_lossy(&output.stdout);
    assert!(
        text.contains("--namespace") && text.contains("--mode"),
        "{text}"
    );
}

#[test]
fn a_bad_argument_exits_2() {
    let output = Command::new(BIN)
        .args(["--mode", "warp"])
        .output()
        .expect("run mole-sensing");
    assert_eq!(output.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&output.stderr).contains("warp"));
}
