//! The mole-world binary's command line: help works, bad arguments exit 2 with a message.

use std::process::Command;

const BIN: &str = env!("CARGO_BIN_EXE_mole-world");

#[test]
fn the_common_command_line_works() {
    mole_integration_tests::check_process_cli(BIN);
}

#[test]
fn a_malformed_scenario_exits_2_naming_file_line_and_field() {
    let path = std::env::temp_dir().join(format!("mole-world-cli-{}.toml", std::process::id()));
    std::fs::write(&path, "[robot]\nradius = -0.2\n").expect("write scenario");
    let output = Command::new(BIN)
        .arg("--scenario")
        .arg(&path)
        .output()
        .expect("run mole-world");
    let _ = std::fs::remove_file(&path);
    assert_eq!(output.status.code(), Some(2));
    let err = String::from_utf8_lossy(&output.stderr);
    assert!(err.contains(":2:") && err.contains("robot.radius"), "{err}");
}
