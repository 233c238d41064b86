//! Recording: the recorder `mole up --record FILE` starts beside the stack, `mole record`
//! (attached to a running stack) and `mole info FILE`.
//!
//! The recorder is its own process (`mole-recorder`), an observer of the stack that is none of
//! its roles: a [`Sidecar`], stopped after every role (it records up to the last sample); if it
//! dies the run goes on, unrecorded from then, with a warning.

use crate::Failure;
use crate::RestartPolicy;
use crate::sidecar::{self, Attached, Sidecar};
use clap::Args;
use mole_recorder::{Every, read_info};
use mole_types::env;
use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Duration;

/// The recorder's program, found next to `mole`, then on PATH.
pub const RECORDER_PROGRAM: &str = "mole-recorder";
/// The recorder's name in its log file and its supervisor.
const RECORDER: &str = mole_types::graph::nodes::RECORDER;

#[derive(Debug, Clone, Args)]
pub struct RecordArgs {
    /// Namespace of the running stack.
    #[arg(long, default_value = mole_types::env::DEFAULT_NAMESPACE)]
    pub namespace: String,
    /// The MCAP file to write (replaced if it exists).
    pub file: PathBuf,
    /// Write TOPIC's samples every N ticks only (repeatable; default mapping/grid=10 and
    /// mapping/contact=10; N = 1 writes every sample).
    #[arg(long = "every", value_name = "TOPIC=N")]
    pub every: Vec<String>,
}

#[derive(Debug, Clone, Args)]
pub struct InfoArgs {
    /// A recording (`mole up --record FILE`, `mole record`).
    pub file: PathBuf,
}

/// `mole info FILE`: duration, ticks, topics with counts and rates, metadata.
pub fn info(args: &InfoArgs) -> Result<(), Failure> {
    let info = read_info(&args.file).map_err(|e| Failure::input(e.to_string()))?;
    // A reader that went away (`mole info FILE | head`) is no failure.
    let _ = write!(std::io::stdout().lock(), "{info}");
    Ok(())
}

/// The recorder's program beside `mole` (or on PATH), its decimation settings (given as `flag`)
/// checked: refused with exit 2 before anything starts.
fn recorder_program(flag: &str, every: &[String]) -> Result<PathBuf, Failure> {
    Every::parse(every).map_err(|e| Failure::input(format!("{flag} {e}")))?;
    sidecar::program(RECORDER_PROGRAM)
}

/// `FILE` as an absolute path the recorder can write: its directory exists (created if need
/// be) and a file can be created in it; a stale file there is removed, so a file present later
/// is this run's. A place that cannot be written is refused (exit 2, naming it) before anything
/// starts, not by a recorder that dies once the stack runs.
fn prepare_file(file: &Path) -> Result<PathBuf, Failure> {
    let failed =
        |e: std::io::Error| Failure::input(format!("cannot record to {}: {e}", file.display()));
    let file = std::path::absolute(file).map_err(failed)?;
    if let Some(dir) = file.parent() {
        std::fs::create_dir_all(dir).map_err(failed)?;
    }
    if let Err(e) = std::fs::remove_file(&file)
        && e.kind() != std::io::ErrorKind::NotFound
    {
        return Err(failed(e));
    }
    // The recorder creates the file only once it listens on every topic; whether it can is
    // known now.
    std::fs::File::create(&file).map_err(failed)?;
    std::fs::remove_file(&file).map_err(failed)?;
    Ok(file)
}

/// What `mole up --record FILE` records with, checked before anything starts.
pub struct RecordPlan {
    program: PathBuf,
    file: PathBuf,
    args: Vec<String>,
}

impl RecordPlan {
    /// The recorder of `file` for the stack of `launch_file`; `every` as `--every` takes it.
    pub fn new(file: &Path, every: &[String], launch_file: &Path) -> Result<RecordPlan, Failure> {
        let program = recorder_program("--record-every", every)?;
        let file = prepare_file(file)?;
        let mut args = vec![file.display().to_string(), "--launch-file".to_string()];
        args.push(
            std::path::absolute(launch_file)
                .unwrap_or_else(|_| launch_file.to_path_buf())
                .display()
                .to_string(),
        );
        for setting in every {
            args.extend(["--every".to_string(), setting.clone()]);
        }
        Ok(RecordPlan {
            program,
            file,
            args,
        })
    }

    /// Starts the recorder with the stack's environment and waits until it listens on every
    /// topic (its file appears then), so the stack started next is recorded from its first step.
    pub fn start(self, env: &[(String, String)], log_path: PathBuf) -> Result<Recorder, Failure> {
        let sidecar = Sidecar::start(
            RECORDER,
            "unrecorded from here (the file's complete chunks stay readable)",
            (self.program, self.args),
            // A file cannot be taken up where a dead recorder left it.
            RestartPolicy::default(),
            env,
            log_path,
            &self.file,
        )?;
        Ok(Recorder {
            sidecar,
            file: self.file,
        })
    }
}

/// The recorder beside a stack that `mole up` runs.
pub struct Recorder {
    sidecar: Sidecar,
    file: PathBuf,
}

impl Recorder {
    /// Warns, once, when the recorder died: the run goes on, unrecorded from then on.
    pub fn check(&mut self) {
        self.sidecar.check();
    }

    /// Stops the recorder (SIGTERM: it reads the last samples and finishes the file) and says
    /// where the recording is.
    pub fn stop(self, timeout: Duration) {
        if self.sidecar.stop(timeout) {
            tracing::warn!("the recorder needed SIGKILL: its file has no summary");
        }
        let size = std::fs::metadata(&self.file).map_or(0, |m| m.len());
        println!(
            "recorded {} ({:.1} MB; `mole info {}`)",
            self.file.display(),
            size as f64 / 1e6,
            self.file.display()
        );
    }
}

/// `mole record --namespace NS FILE`: records the running stack in NS until Ctrl-C or the stack
/// ends.
pub fn record(args: &RecordArgs) -> Result<(), Failure> {
    let program = recorder_program("--every", &args.every)?;
    let stack = Attached::to(&args.namespace)?;
    let file = prepare_file(&args.file)?;
    let mut command = Command::new(program);
    command
        .arg(&file)
        .args(args.every.iter().flat_map(|s| ["--every", s.as_str()]))
        .env(env::NAMESPACE, &args.namespace)
        .env(env::MODE, stack.mode.name())
        .stdin(Stdio::null());
    crate::supervisor::dies_with_the_launcher(&mut command);
    let child = command
        .spawn()
        .map_err(|e| Failure::run(format!("cannot start {RECORDER_PROGRAM}: {e}")))?;
    println!(
        "recording the {} stack in `{}` to {} (Ctrl-C to stop)",
        stack.mode,
        args.namespace,
        file.display()
    );
    stack.wait(RECORDER, child, || {})?;
    let size = std::fs::metadata(&file).map_or(0, |m| m.len());
    println!("recorded {} ({:.1} MB)", file.display(), size as f64 / 1e6);
    Ok(())
}
