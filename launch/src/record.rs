//! Recording: the recorder `mole up --record FILE` starts beside the stack, `mole record`
//! (attached to a running stack) and `mole info FILE`.
//!
//! The recorder is its own process (`mole-recorder`), an observer of the stack that is none of
//! its roles: it has a supervisor of its own, so the stack's supervision (restarts, hangs,
//! `mole status`, the stop order) never sees it, it is stopped after every role (it records up to
//! the last sample), and if it dies the run goes on, unrecorded from then, with a warning.

use crate::supervisor::EXIT_BAD_INPUT;
use crate::up::{Failure, LAUNCHER_NODE};
use crate::{ChildSpec, ExitStatus, RestartPolicy, Supervisor, SupervisorEvent, resolve_program};
use clap::Args;
use mole_recorder::{Every, read_info};
use mole_runtime::{cleanup_dead_nodes, live_nodes_in_namespace, stack_clock_mode};
use mole_types::env;
use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// The recorder's program, found next to `mole`, then on PATH.
pub const RECORDER_PROGRAM: &str = "mole-recorder";
/// The recorder's name in its log file and its supervisor.
const RECORDER: &str = "recorder";
/// How long the recorder may take to open every topic and create its file.
const READY_TIMEOUT: Duration = Duration::from_secs(20);
/// How often `mole record` looks whether the stack it records is still there.
const STACK_POLL: Duration = Duration::from_secs(1);

#[derive(Debug, Clone, Args)]
pub struct RecordArgs {
    /// Namespace of the running stack.
    #[arg(long, default_value = "robot0")]
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
    let beside = std::env::current_exe()
        .ok()
        .and_then(|p| p.parent().map(Path::to_path_buf))
        .unwrap_or_default();
    resolve_program(RECORDER_PROGRAM, &beside).map_err(|e| Failure::input(e.to_string()))
}

/// `FILE` as an absolute path whose directory exists (created if need be); a stale file there
/// is removed, so a file present later is this run's.
fn prepare_file(file: &Path) -> Result<PathBuf, Failure> {
    let failed =
        |e: std::io::Error| Failure::input(format!("cannot record to {}: {e}", file.display()));
    let file = std::path::absolute(file).map_err(failed)?;
    if let Some(dir) = file.parent() {
        std::fs::create_dir_all(dir).map_err(failed)?;
    }
    match std::fs::remove_file(&file) {
        Err(e) if e.kind() != std::io::ErrorKind::NotFound => Err(failed(e)),
        _ => Ok(file),
    }
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
        let mut supervisor = Supervisor::new();
        let spec = ChildSpec {
            role: RECORDER.to_string(),
            program: self.program,
            args: self.args,
            env: env.to_vec(),
            restart: RestartPolicy::default(),
            log_path: log_path.clone(),
            cwd: None,
        };
        supervisor
            .spawn(spec)
            .map_err(|e| Failure::run(e.to_string()))?;
        let deadline = Instant::now() + READY_TIMEOUT;
        while !self.file.exists() {
            if let Some(status) = exit_of(&mut supervisor) {
                let line = crate::up::last_error_line(&log_path);
                return Err(match status {
                    ExitStatus::Code(EXIT_BAD_INPUT) => {
                        Failure::input(format!("the recorder refused its input: {line}"))
                    }
                    status => Failure::run(format!("the recorder exited ({status}): {line}")),
                });
            }
            if Instant::now() > deadline {
                supervisor.shutdown(&[], Duration::ZERO);
                return Err(Failure::run(format!(
                    "the recorder did not open the stack's topics within {READY_TIMEOUT:?} \
                     (see {})",
                    log_path.display()
                )));
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        Ok(Recorder {
            supervisor,
            file: self.file,
            log_path,
            gone: false,
        })
    }
}

/// How the recorder ended, if it did.
fn exit_of(supervisor: &mut Supervisor) -> Option<ExitStatus> {
    supervisor.poll().into_iter().find_map(|event| match event {
        SupervisorEvent::Exited { status, .. } => Some(status),
        _ => None,
    })
}

/// The recorder beside a stack that `mole up` runs.
pub struct Recorder {
    supervisor: Supervisor,
    file: PathBuf,
    log_path: PathBuf,
    gone: bool,
}

impl Recorder {
    /// Warns, once, when the recorder died, and releases what its node held: the run goes on,
    /// unrecorded from then on (the file's complete chunks stay readable).
    pub fn check(&mut self) {
        if self.gone {
            return;
        }
        if let Some(status) = exit_of(&mut self.supervisor) {
            self.gone = true;
            // Release its queues: a lockstep publisher would wait for them to be read.
            cleanup_dead_nodes();
            tracing::warn!(
                "the recorder exited ({status}); the run goes on unrecorded from here (see {})",
                self.log_path.display()
            );
        }
    }

    /// Stops the recorder (SIGTERM: it reads the last samples and finishes the file) and says
    /// where the recording is.
    pub fn stop(mut self, timeout: Duration) {
        let killed = self.supervisor.shutdown(&[RECORDER.to_string()], timeout);
        if !killed.is_empty() {
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
    let launcher = format!("mole/{}/{LAUNCHER_NODE}", args.namespace);
    let stack_runs = || live_nodes_in_namespace(&args.namespace).contains(&launcher);
    let mode = stack_clock_mode(&args.namespace)
        .filter(|_| stack_runs())
        .ok_or_else(|| {
            Failure::input(format!(
                "no stack runs in namespace `{}` (no `mole up` there); expected the namespace \
                 of a running stack",
                args.namespace
            ))
        })?;
    let file = prepare_file(&args.file)?;
    let interrupted = Arc::new(AtomicBool::new(false));
    let flag = interrupted.clone();
    ctrlc::set_handler(move || flag.store(true, Ordering::SeqCst))
        .map_err(|e| Failure::run(format!("cannot install the Ctrl-C handler: {e}")))?;
    let mut command = Command::new(program);
    command
        .arg(&file)
        .args(args.every.iter().flat_map(|s| ["--every", s.as_str()]))
        .env(env::NAMESPACE, &args.namespace)
        .env(env::MODE, mode.name())
        .stdin(Stdio::null());
    let mut child = command
        .spawn()
        .map_err(|e| Failure::run(format!("cannot start {RECORDER_PROGRAM}: {e}")))?;
    println!(
        "recording the {mode} stack in `{}` to {} (Ctrl-C to stop)",
        args.namespace,
        file.display()
    );
    let mut last_look = Instant::now();
    let mut stopping = false;
    let status = loop {
        if let Some(status) = child
            .try_wait()
            .map_err(|e| Failure::run(format!("cannot wait for the recorder: {e}")))?
        {
            break status;
        }
        let ended = !stopping && last_look.elapsed() >= STACK_POLL && {
            last_look = Instant::now();
            !stack_runs()
        };
        if !stopping && (ended || interrupted.load(Ordering::SeqCst)) {
            stopping = true;
            let pid = nix::unistd::Pid::from_raw(child.id() as i32);
            let _ = nix::sys::signal::kill(pid, nix::sys::signal::Signal::SIGTERM);
        }
        std::thread::sleep(Duration::from_millis(50));
    };
    match status.code() {
        Some(0) => {
            let size = std::fs::metadata(&file).map_or(0, |m| m.len());
            println!("recorded {} ({:.1} MB)", file.display(), size as f64 / 1e6);
            Ok(())
        }
        Some(2) => Err(Failure::input("the recorder refused its input (see above)")),
        _ => Err(Failure::run(format!("the recorder failed ({status})"))),
    }
}
