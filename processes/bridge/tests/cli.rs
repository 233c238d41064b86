//! The bridge's command line: help works, bad arguments exit 2 with a message. (Being an
//! integration test of this package, it also makes `cargo test --workspace` build `mole-bridge`,
//! which the split-stack tests start.)

#[test]
fn the_bridges_command_line_works() {
    mole_integration_tests::check_process_cli(env!("CARGO_BIN_EXE_mole-bridge"));
}
