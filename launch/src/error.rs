//! The launcher's errors, at the bottom of its layers: [`LaunchError`] for the library's
//! operations and [`Failure`], what a `mole` command exits with.

use std::io;
use std::path::PathBuf;

/// Everything that can go wrong while reading a launch file, ordering or supervising a stack.
///
/// Every message is one line and names what was wrong and where; bad input exits with code 2.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum LaunchError {
    /// The launch file could not be read.
    #[error("{}: cannot read launch file: {source}", path.display())]
    Read {
        /// The launch file.
        path: PathBuf,
        /// Why it could not be read.
        source: io::Error,
    },
    /// The launch file is not valid TOML, does not match the format, or fails validation.
    #[error("{}", located(file, *line, *column, field, message))]
    Invalid {
        /// The launch file.
        file: PathBuf,
        /// 1-based line of the offending key or value.
        line: usize,
        /// 1-based column (in characters) of the offending key or value.
        column: usize,
        /// Field path such as `process[2].restart.policy`; empty for syntax errors.
        field: String,
        /// What was wrong and what was expected.
        message: String,
    },
    /// The processes depend on each other in a circle; `cycle` starts and ends with the same role.
    #[error("dependency cycle: {} (each depends on the next)", cycle.join(" -> "))]
    Cycle {
        /// The roles of the cycle, first one repeated at the end.
        cycle: Vec<String>,
    },
    /// A process depends on a role no process has.
    #[error("process `{role}` depends on `{dependency}`, which no process provides")]
    UnknownDependency {
        /// The dependent process.
        role: String,
        /// The missing role.
        dependency: String,
    },
    /// Two processes share a role.
    #[error("two processes have the role `{role}`")]
    DuplicateRole {
        /// The shared role.
        role: String,
    },
    /// A `--swap ROLE=COMMAND` argument could not be parsed.
    #[error("--swap `{arg}`: {reason}")]
    BadSwap {
        /// The argument as given.
        arg: String,
        /// What is wrong with it.
        reason: String,
    },
    /// A `--swap` names a role the launch file does not have.
    #[error("--swap {role}=...: no process has the role `{role}` (known roles: {})", known.join(", "))]
    UnknownRole {
        /// The role asked for.
        role: String,
        /// The roles of the launch file, in file order.
        known: Vec<String>,
    },
    /// A process command is neither next to the launcher nor on `PATH`.
    #[error("command `{command}` not found (looked in: {looked})")]
    ProgramNotFound {
        /// The command as written.
        command: String,
        /// Where the launcher looked, human-readable.
        looked: String,
    },
    /// A file named in the launch file (e.g. the scenario) was not found.
    #[error("{what} `{}` not found (looked in: {looked})", path.display())]
    PathNotFound {
        /// What the file is for, e.g. "scenario".
        what: String,
        /// The path as written.
        path: PathBuf,
        /// Where the launcher looked, human-readable.
        looked: String,
    },
    /// The operating system refused to start a process.
    #[error("cannot start `{role}` ({}): {source}", program.display())]
    Spawn {
        /// The role of the process.
        role: String,
        /// The program that failed to start.
        program: PathBuf,
        /// The OS error.
        source: io::Error,
    },
    /// The log file of a process could not be created.
    #[error("cannot open log file {} for `{role}`: {source}", path.display())]
    Log {
        /// The role of the process.
        role: String,
        /// The log file.
        path: PathBuf,
        /// The OS error.
        source: io::Error,
    },
    /// `spawn` was called for a role whose process is still running.
    #[error("process `{role}` is already running")]
    AlreadyRunning {
        /// The role.
        role: String,
    },
    /// A hot swap asked for a role that is not running (or is being swapped already).
    #[error("process `{role}` is not running (or a swap of it is under way)")]
    NotRunning {
        /// The role.
        role: String,
    },
}

impl LaunchError {
    /// Bad input (files, arguments, a swap of a role that is not running) or a failure of the
    /// operating system while running the stack.
    #[must_use]
    pub fn kind(&self) -> FailureKind {
        match self {
            Self::Spawn { .. } | Self::Log { .. } | Self::AlreadyRunning { .. } => {
                FailureKind::Failed
            }
            _ => FailureKind::BadInput,
        }
    }

    /// Process exit code for this error: 2 for bad input, 1 for a failure while running.
    #[must_use]
    pub fn exit_code(&self) -> i32 {
        i32::from(self.kind().exit_code())
    }
}

/// `file:line:column: field `path`: message`, without the field part when there is none.
fn located(
    file: &std::path::Path,
    line: usize,
    column: usize,
    field: &str,
    message: &str,
) -> String {
    if field.is_empty() {
        format!("{}:{line}:{column}: {message}", file.display())
    } else {
        format!(
            "{}:{line}:{column}: field `{field}`: {message}",
            file.display()
        )
    }
}

/// Why a `mole` command failed; the exit code follows from it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FailureKind {
    /// Bad input: a file, an argument or a setting was wrong. Exit code 2, before anything starts
    /// where the input can be checked up front; running again unchanged cannot help.
    BadInput,
    /// The run itself failed: a process beyond its restart policy, a stall, the operating system.
    /// Exit code 1.
    Failed,
}

impl FailureKind {
    /// 2 for bad input, 1 for a failed run.
    #[must_use]
    pub fn exit_code(self) -> u8 {
        match self {
            FailureKind::BadInput => 2,
            FailureKind::Failed => 1,
        }
    }
}

/// A failure of a `mole` command: its kind and one line naming what and where.
#[derive(Debug)]
pub struct Failure {
    pub kind: FailureKind,
    pub message: String,
}

impl Failure {
    /// Bad input (exit code 2).
    pub fn input(message: impl Into<String>) -> Self {
        Self {
            kind: FailureKind::BadInput,
            message: message.into(),
        }
    }

    /// A failure of the run (exit code 1).
    pub fn run(message: impl Into<String>) -> Self {
        Self {
            kind: FailureKind::Failed,
            message: message.into(),
        }
    }

    /// The process exit code this failure deserves.
    #[must_use]
    pub fn exit_code(&self) -> u8 {
        self.kind.exit_code()
    }

    /// How a `mole` command ends: success, or `error: …` on stderr and the failure's exit code.
    pub fn exit(result: Result<(), Failure>) -> std::process::ExitCode {
        match result {
            Ok(()) => std::process::ExitCode::SUCCESS,
            Err(f) => {
                eprintln!("error: {}", f.message);
                std::process::ExitCode::from(f.exit_code())
            }
        }
    }
}

impl From<LaunchError> for Failure {
    fn from(error: LaunchError) -> Self {
        Self {
            kind: error.kind(),
            message: error.to_string(),
        }
    }
}
