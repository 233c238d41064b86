//! The recorder's and the player's command lines: help works, bad arguments exit 2 with a
//! message. (Being integration tests of this package, they also make `cargo test --workspace`
//! build both binaries, which the stack tests start.)

#[test]
fn the_recorders_command_line_works() {
    mole_integration_tests::check_process_cli(env!("CARGO_BIN_EXE_mole-recorder"));
}

#[test]
fn the_players_command_line_works() {
    mole_integration_tests::check_process_cli(env!("CARGO_BIN_EXE_mole-player"));
}
