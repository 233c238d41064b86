//! The Foxglove server's command line: help works, bad arguments exit 2 with a message, a file
//! that is not a recording is refused naming it. (Being an integration test of this package, it
//! also makes `cargo test --workspace` build `mole-foxglove`, which tests/foxglove.rs starts.)

const BIN: &str = env!("CARGO_BIN_EXE_mole-foxglove");

#[test]
fn the_foxglove_servers_command_line_works() {
    mole_integration_tests::check_process_cli(BIN);
    let output = std::process::Command::new(BIN)
        .args(["--file", "/nonexistent/run.mcap", "--port", "0"])
        .output()
        .expect("run the process");
    assert_eq!(output.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&output.stderr).contains("/nonexistent/run.mcap"));
}
