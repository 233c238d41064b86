//! The mole launcher library: launch files, start order, `--swap` and process supervision.
//!
//! The `mole` binary (src/main.rs) wires these to the command line and to the stack's IPC:
//! [`load_launch_file`] → [`apply_swaps`] → [`start_order`] → [`Supervisor::spawn`] each process
//! → [`Supervisor::poll`] while running (serving `mole swap` through [`hot_swap`]; a crashed
//! role restarts from the last outputs the [`keeper::ResumeKeeper`] kept) →
//! [`Supervisor::shutdown`] in [`stop_order`].

pub mod bench;
pub mod bench_ipc;
pub mod bench_peers;
pub mod bench_stack;
pub mod control;
pub mod doctor;
mod error;
pub mod eval;
pub mod export;
pub mod fault;
pub mod g2o;
pub mod hot_swap;
pub mod inject;
pub mod keeper;
pub mod launch_file;
pub mod new;
pub mod param;
pub mod record;
pub mod replay;
pub mod servers;
pub mod settings;
pub mod sidecar;
pub mod stand_in;
pub mod stats;
pub mod supervisor;
pub mod swap;
pub mod top;
pub mod up;

pub use error::{Failure, FailureKind, LaunchError};
pub use launch_file::order::{start_order, stop_order};
pub use launch_file::{
    DEFAULT_LAUNCH_FILE, LaunchFile, ProcessSpec, RestartPolicy, RestartWhen, StackOverrides,
    StackSpec, load_launch_file, parse_launch_file, resolve_data_path,
};
pub use supervisor::{
    ChildSpec, ExitStatus, Supervisor, SupervisorEvent, resolve_program, resolve_program_in,
};
pub use swap::{apply_swaps, parse_swap};
