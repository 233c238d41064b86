//! What can go wrong, and the exit code it becomes.

/// What can go wrong in the runtime. Every variant carries a sentence a user can act on.
#[derive(Debug, thiserror::Error)]
pub enum RuntimeError {
    #[error("invalid name `{0}`: {1}")]
    Name(String, String),
    #[error("cannot create the node `{0}`: {1}")]
    Node(String, String),
    #[error("cannot open topic `{topic}`: {reason}")]
    Service { topic: String, reason: String },
    #[error("{0}")]
    Port(String),
    #[error("waiting failed: {0}")]
    Wait(String),
    #[error("cannot install the Ctrl-C handler: {0}")]
    Signal(String),
    #[error("{0}")]
    Setting(String),
    #[error("cannot resume from {path}: {reason}", path = .0.display(), reason = .1)]
    Resume(std::path::PathBuf, String),
}

/// Input a process refuses (a goal-seeking planner without a goal...): exit code 2, which no
/// restart policy retries.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct BadInput(pub String);

/// The exit code of a process's run: 0 on success, 2 for [`BadInput`] (printed as
/// `error: ...` for the launcher to report), 1 for anything else (logged).
pub fn exit_code(result: Result<(), Box<dyn std::error::Error>>) -> std::process::ExitCode {
    match result {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e)
            if e.is::<BadInput>()
                || matches!(
                    e.downcast_ref::<RuntimeError>(),
                    Some(RuntimeError::Setting(_) | RuntimeError::Resume(..))
                ) =>
        {
            eprintln!("error: {e}");
            std::process::ExitCode::from(2)
        }
        Err(e) => {
            tracing::error!("{e}");
            std::process::ExitCode::FAILURE
        }
    }
}
