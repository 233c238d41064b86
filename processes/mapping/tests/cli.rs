//! The mole-mapping binary's command line: help works, bad arguments exit 2 with a message.

const BIN: &str = env!("CARGO_BIN_EXE_mole-mapping");

#[test]
fn the_common_command_line_works() {
    mole_integration_tests::check_process_cli(BIN);
}
