//! Programs beside a stack that are none of its roles: the recorder and the view.
//!
//! Beside `mole up` each has a supervisor of its own, so the stack's supervision (restarts,
//! hangs, `mole status`, the stop order) never sees it; it is stopped after every role, and if
//! it dies the run goes on without it, with a warning. Attached to a running stack (`mole
//! record`, `mole view`) it runs until Ctrl-C or the stack ends.

use crate::Failure;
use crate::supervisor::EXIT_BAD_INPUT;
use crate::{ChildSpec, ExitStatus, RestartPolicy, Supervisor, SupervisorEvent, resolve_program};
use mole_runtime::{cleanup_dead_nodes, live_nodes_in_namespace, stack_clock_mode};
use mole_types::ClockMode;
use mole_types::graph::nodes::LAUNCHER;
use std::path::{Path, PathBuf};
use std::process::Child;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// How long a sidecar may take to open the stack's topics and say it is ready.
const READY_TIMEOUT: Duration = Duration::from_secs(20);
/// How often an attached sidecar's launcher looks whether the stack is still there.
const STACK_POLL: Duration = Duration::from_secs(1);

/// A sidecar's program, found next to `mole`, then on PATH; missing is refused with exit 2.
pub fn program(name: &str) -> Result<PathBuf, Failure> {
    let beside = std::env::current_exe()
        .ok()
        .and_then(|p| p.parent().map(Path::to_path_buf))
        .unwrap_or_default();
    resolve_program(name, &beside).map_err(|e| Failure::input(e.to_string()))
}

/// A sidecar beside a stack that `mole up` runs.
pub struct Sidecar {
    name: &'static str,
    /// What the run lacks once it died, for the warning.
    without: &'static str,
    supervisor: Supervisor,
    log_path: PathBuf,
    gone: bool,
}

/// How the sidecar ended while it started, if it did.
fn exit_of(supervisor: &mut Supervisor) -> Option<ExitStatus> {
    supervisor.poll().into_iter().find_map(|event| match event {
        SupervisorEvent::Exited { status, .. } => Some(status),
        _ => None,
    })
}

impl Sidecar {
    /// Starts `program` as `name` with the stack's environment and waits until `ready` exists
    /// (it creates it once it listens on every topic it needs); should it die later, `restart`
    /// says whether it is started again. `without` completes the sentence "the run goes on …"
    /// of the warning once it stays down.
    pub fn start(
        name: &'static str,
        without: &'static str,
        spec: (PathBuf, Vec<String>),
        restart: RestartPolicy,
        env: &[(String, String)],
        log_path: PathBuf,
        ready: &Path,
    ) -> Result<Sidecar, Failure> {
        let mut supervisor = Supervisor::new();
        let (program, args) = spec;
        let spec = ChildSpec {
            role: name.to_string(),
            program,
            args,
            env: env.to_vec(),
            restart,
            log_path: log_path.clone(),
            cwd: None,
        };
        supervisor
            .spawn(spec)
            .map_err(|e| Failure::run(e.to_string()))?;
        let deadline = Instant::now() + READY_TIMEOUT;
        while !ready.exists() {
            if let Some(status) = exit_of(&mut supervisor) {
                let line = crate::supervisor::last_error_line(&log_path);
                return Err(match status {
                    ExitStatus::Code(EXIT_BAD_INPUT) => {
                        Failure::input(format!("the {name} refused its input: {line}"))
                    }
                    status => Failure::run(format!("the {name} exited ({status}): {line}")),
                });
            }
            if Instant::now() > deadline {
                supervisor.shutdown(&[], Duration::ZERO);
                return Err(Failure::run(format!(
                    "the {name} did not open the stack's topics within {READY_TIMEOUT:?} (see {})",
                    log_path.display()
                )));
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        Ok(Sidecar {
            name,
            without,
            supervisor,
            log_path,
            gone: false,
        })
    }

    /// Releases what a dead sidecar's node held, says so, and, once its policy gives up (or at
    /// once under `never`), warns that the run goes on without it; a restart is the
    /// supervisor's, by the policy.
    pub fn check(&mut self) {
        if self.gone {
            return;
        }
        let (name, log) = (self.name, self.log_path.display());
        for event in self.supervisor.poll() {
            match event {
                SupervisorEvent::Exited { status, .. } => {
                    // Release its queues: a lockstep publisher would wait for them to be read.
                    cleanup_dead_nodes();
                    tracing::warn!("the {name} exited ({status}) (see {log})");
                }
                SupervisorEvent::Restarted { attempt, .. } => {
                    tracing::info!(attempt, "the {name} was started again");
                }
                SupervisorEvent::RestartFailed { message, .. } => {
                    tracing::warn!("the {name} could not be started again: {message}");
                }
                SupervisorEvent::GaveUp { .. } => self.gone = true,
            }
        }
        if !self.supervisor.is_running(name) && !self.supervisor.restart_pending(name) {
            self.gone = true;
        }
        if self.gone {
            tracing::warn!("the run goes on {}", self.without);
        }
    }

    /// Stops the sidecar (SIGTERM, SIGKILL after `timeout`); true when it needed SIGKILL.
    pub fn stop(mut self, timeout: Duration) -> bool {
        !self
            .supervisor
            .shutdown(&[self.name.to_string()], timeout)
            .is_empty()
    }
}

/// A running stack a sidecar attaches to (`mole record`, `mole view`).
pub struct Attached {
    pub mode: ClockMode,
    namespace: String,
    interrupted: Arc<AtomicBool>,
}

impl Attached {
    /// The stack running in `namespace` (exit 2 when there is none), with Ctrl-C caught.
    pub fn to(namespace: &str) -> Result<Attached, Failure> {
        let mode = stack_clock_mode(namespace)
            .filter(|_| stack_runs(namespace))
            .ok_or_else(|| {
                Failure::input(format!(
                    "no stack runs in namespace `{namespace}` (no `mole up` there); expected \
                     the namespace of a running stack"
                ))
            })?;
        let interrupted = Arc::new(AtomicBool::new(false));
        let flag = interrupted.clone();
        ctrlc::set_handler(move || flag.store(true, Ordering::SeqCst))
            .map_err(|e| Failure::run(format!("cannot install the Ctrl-C handler: {e}")))?;
        Ok(Attached {
            mode,
            namespace: namespace.to_string(),
            interrupted,
        })
    }

    /// Waits for `child` to exit, calling `on_poll` every 50 ms; asks it to finish (SIGTERM)
    /// once Ctrl-C came or the stack ended. An exit 2 is the child's refusal of its input
    /// (its error is above, on the shared stderr).
    pub fn wait(
        &self,
        name: &str,
        mut child: Child,
        mut on_poll: impl FnMut(),
    ) -> Result<std::process::ExitStatus, Failure> {
        let mut last_look = Instant::now();
        let mut stopping = false;
        let status = loop {
            if let Some(status) = child
                .try_wait()
                .map_err(|e| Failure::run(format!("cannot wait for the {name}: {e}")))?
            {
                break status;
            }
            on_poll();
            let ended = !stopping && last_look.elapsed() >= STACK_POLL && {
                last_look = Instant::now();
                !stack_runs(&self.namespace)
            };
            if !stopping && (ended || self.interrupted.load(Ordering::SeqCst)) {
                stopping = true;
                let pid = nix::unistd::Pid::from_raw(child.id() as i32);
                let _ = nix::sys::signal::kill(pid, nix::sys::signal::Signal::SIGTERM);
            }
            std::thread::sleep(Duration::from_millis(50));
        };
        match status.code() {
            Some(0) => Ok(status),
            Some(EXIT_BAD_INPUT) => Err(Failure::input(format!(
                "the {name} refused its input (see above)"
            ))),
            _ => Err(Failure::run(format!("the {name} failed ({status})"))),
        }
    }
}

/// Whether the launcher of the stack in `namespace` is alive.
fn stack_runs(namespace: &str) -> bool {
    let launcher = format!("mole/{namespace}/{LAUNCHER}");
    live_nodes_in_namespace(namespace).contains(&launcher)
}

/// The packages built only for a run that uses them: the bridge brings zenoh, the Foxglove
/// server Foxglove's SDK.
const OPTIONAL_PACKAGES: [&str; 2] = ["mole-bridge", "mole-foxglove"];

/// When started through `cargo run`, builds every process binary too (cargo builds only the
/// package it runs), so `mole` never starts a stale or missing process; of the
/// [`OPTIONAL_PACKAGES`] only those in `wanted`.
pub fn build_process_binaries(wanted: &[&str]) -> Result<(), Failure> {
    let (Some(cargo), Ok(exe)) = (std::env::var_os("CARGO"), std::env::current_exe()) else {
        return Ok(());
    };
    let Some(manifest_dir) = std::env::var_os("CARGO_MANIFEST_DIR") else {
        return Ok(());
    };
    let profile = exe
        .parent()
        .and_then(|d| d.file_name())
        .and_then(|n| n.to_str())
        .unwrap_or("debug");
    let mut command = std::process::Command::new(cargo);
    command
        .current_dir(manifest_dir)
        .args(["build", "--workspace", "--bins", "--quiet"]);
    for package in OPTIONAL_PACKAGES.iter().filter(|p| !wanted.contains(p)) {
        command.args(["--exclude", package]);
    }
    if profile != "debug" {
        command.args([
            "--profile",
            if profile == "release" {
                "release"
            } else {
                profile
            },
        ]);
    }
    tracing::info!("building the process binaries ({profile})");
    let status = command
        .status()
        .map_err(|e| Failure::run(format!("cannot run cargo: {e}")))?;
    if status.success() {
        Ok(())
    } else {
        Err(Failure::run(
            "building the process binaries failed (see cargo's output above)",
        ))
    }
}
