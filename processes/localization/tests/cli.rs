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
