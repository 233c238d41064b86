//! `mole-bench-probe`: one probe process of `mole bench ipc`, started by the driver.

use clap::Parser;
use mole_bench::{ProbeArgs, run_probe};

fn main() -> std::process::ExitCode {
    // iceoryx2's warnings (e.g. "no config file") only at IOX2_LOG_LEVEL's request.
    iceoryx2::prelude::set_log_level_from_env_or(iceoryx2::prelude::LogLevel::Error);
    let args = ProbeArgs::parse();
    match run_probe(&args) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("mole-bench-probe ({} {}): {e}", args.namespace, args.id);
            std::process::ExitCode::FAILURE
        }
    }
}
