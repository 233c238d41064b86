//! Starts, watches, restarts and stops the processes of a stack (Unix).
//!
//! Each child runs in its own process group, so a Ctrl-C in the terminal reaches only the
//! launcher, which then stops the children in order; signals go to the whole group so helpers a
//! child started (e.g. a shell's children) stop with it.

use std::collections::BTreeMap;
use std::fmt;
use std::fs::OpenOptions;
use std::io::Write;
use std::os::unix::fs::PermissionsExt;
use std::os::unix::process::{CommandExt, ExitStatusExt};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use nix::errno::Errno;
use nix::sys::signal::{Signal, kill, killpg};
use nix::unistd::Pid;

use crate::LaunchError;
use crate::launch_file::{ProcessSpec, RestartPolicy, RestartWhen};

/// How often `shutdown` looks whether the children are gone.
const SHUTDOWN_POLL: Duration = Duration::from_millis(5);

/// Everything needed to start (and restart) one child.
#[derive(Debug, Clone, PartialEq)]
pub struct ChildSpec {
    /// Role name, the key of every supervisor query.
    pub role: String,
    /// Resolved program (see [`resolve_program`]).
    pub program: PathBuf,
    /// Arguments after the program.
    pub args: Vec<String>,
    /// Extra environment variables (the launcher's own environment is inherited).
    pub env: Vec<(String, String)>,
    /// Restart policy.
    pub restart: RestartPolicy,
    /// stdout and stderr of every run are appended here.
    pub log_path: PathBuf,
    /// Working directory (the launcher's when `None`).
    pub cwd: Option<PathBuf>,
}

impl ChildSpec {
    /// The child spec of a launch-file process; add stack arguments to `args` afterwards.
    #[must_use]
    pub fn from_process(process: &ProcessSpec, program: PathBuf, log_path: PathBuf) -> Self {
        Self {
            role: process.role.clone(),
            program,
            args: process.args.clone(),
            env: process
                .env
                .iter()
                .map(|(k, v)| (k.clone(), v.clone()))
                .collect(),
            restart: process.restart,
            log_path,
            cwd: None,
        }
    }
}

/// How a child ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ExitStatus {
    /// It exited with this code.
    Code(i32),
    /// A signal with this number killed it.
    Signal(i32),
}

impl ExitStatus {
    /// Exit code 0.
    #[must_use]
    pub fn success(self) -> bool {
        self == Self::Code(0)
    }
}

impl From<std::process::ExitStatus> for ExitStatus {
    fn from(s: std::process::ExitStatus) -> Self {
        match (s.code(), s.signal()) {
            (Some(c), _) => Self::Code(c),
            (None, Some(sig)) => Self::Signal(sig),
            (None, None) => Self::Code(-1),
        }
    }
}

impl fmt::Display for ExitStatus {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Self::Code(c) => write!(f, "exit code {c}"),
            Self::Signal(s) => match Signal::try_from(s) {
                Ok(sig) => write!(f, "signal {s} ({sig})"),
                Err(_) => write!(f, "signal {s}"),
            },
        }
    }
}

/// What [`Supervisor::poll`] saw.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum SupervisorEvent {
    /// A child ended; `expected` when the launcher asked it to stop.
    Exited {
        /// Role.
        role: String,
        /// How it ended.
        status: ExitStatus,
        /// Whether the launcher asked for it ([`Supervisor::mark_stopping`]).
        expected: bool,
    },
    /// A child was started again; `attempt` counts restarts of this role from 1.
    Restarted {
        /// Role.
        role: String,
        /// Restart number.
        attempt: u32,
    },
    /// A restart failed to start the program; a `GaveUp` follows.
    RestartFailed {
        /// Role.
        role: String,
        /// The error, one line.
        message: String,
    },
    /// The role used up its restarts (or could not be restarted) and stays down.
    GaveUp {
        /// Role.
        role: String,
    },
}

/// One role under supervision.
#[derive(Debug)]
struct Slot {
    spec: ChildSpec,
    child: Option<Child>,
    started: Instant,
    /// Restarts over the whole run (kept when the role is spawned again, e.g. after a swap).
    restarts: u32,
    /// Restarts since the last `spawn`; limited by `RestartPolicy::max`.
    restarts_since_spawn: u32,
    /// Restarts since the last stable run; the backoff doubles with it.
    streak: u32,
    restart_at: Option<Instant>,
    /// Environment added to the pending restart only (where its kept outputs are).
    restart_env: Vec<(String, String)>,
    stopping: bool,
    last_exit: Option<ExitStatus>,
    /// A hot swap's new process, running beside `child` until it takes over.
    replacement: Option<(Child, ChildSpec)>,
}

/// Owns the child processes of a stack. Dropping it kills and reaps every child still alive.
#[derive(Debug, Default)]
pub struct Supervisor {
    slots: Vec<Slot>,
}

impl Supervisor {
    /// An empty supervisor.
    #[must_use]
    pub fn new() -> Self {
        Self { slots: Vec::new() }
    }

    /// Spawns the child in its own process group, stdin null, stdout and stderr appended to
    /// `log_path` (parent directories are created). A role that ran before and is down is
    /// replaced (its restart count carries on; its restart budget starts afresh).
    pub fn spawn(&mut self, spec: ChildSpec) -> Result<(), LaunchError> {
        let index = self.slots.iter().position(|s| s.spec.role == spec.role);
        if let Some(i) = index
            && self.slots[i].child.is_some()
        {
            return Err(LaunchError::AlreadyRunning { role: spec.role });
        }
        let child = start(&spec, 0, &[])?;
        let slot = Slot {
            spec,
            child: Some(child),
            started: Instant::now(),
            restarts: index.map_or(0, |i| self.slots[i].restarts),
            restarts_since_spawn: 0,
            streak: 0,
            restart_at: None,
            restart_env: Vec::new(),
            stopping: false,
            last_exit: None,
            replacement: None,
        };
        match index {
            Some(i) => self.slots[i] = slot,
            None => self.slots.push(slot),
        }
        Ok(())
    }

    /// Non-blocking: reaps exited children, applies the restart policies and starts children
    /// whose backoff has elapsed. Call it regularly (e.g. every 10-100 ms).
    pub fn poll(&mut self) -> Vec<SupervisorEvent> {
        self.poll_with(|_, _| Vec::new())
    }

    /// [`Supervisor::poll`], calling `before_restart(role, attempt)` as soon as a role that its
    /// policy restarts is found dead, before anything else happens; the environment it returns
    /// is added to that restart only (the launcher points it at the outputs it kept).
    pub fn poll_with(
        &mut self,
        mut before_restart: impl FnMut(&str, u32) -> Vec<(String, String)>,
    ) -> Vec<SupervisorEvent> {
        let mut events = Vec::new();
        let now = Instant::now();
        for slot in &mut self.slots {
            let exited = match slot.child.as_mut().map(Child::try_wait) {
                Some(Ok(Some(status))) => Some(ExitStatus::from(status)),
                // The OS lost track of it (should not happen with our own children): count it as
                // killed so the policy still applies.
                Some(Err(_)) => Some(ExitStatus::Signal(Signal::SIGKILL as i32)),
                Some(Ok(None)) | None => None,
            };
            if let Some(status) = exited {
                slot.child = None;
                slot.last_exit = Some(status);
                let expected = slot.stopping;
                events.push(SupervisorEvent::Exited {
                    role: slot.spec.role.clone(),
                    status,
                    expected,
                });
                let policy = slot.spec.restart;
                if !expected && status == ExitStatus::Code(EXIT_BAD_INPUT) {
                    events.push(SupervisorEvent::GaveUp {
                        role: slot.spec.role.clone(),
                    });
                } else if !expected && wants_restart(policy.policy, status) {
                    if now.duration_since(slot.started)
                        >= Duration::from_millis(policy.stable_after_ms)
                    {
                        slot.streak = 0;
                    }
                    if slot.restarts_since_spawn >= policy.max {
                        events.push(SupervisorEvent::GaveUp {
                            role: slot.spec.role.clone(),
                        });
                    } else {
                        slot.restart_env = before_restart(&slot.spec.role, slot.restarts + 1);
                        slot.restart_at = Some(now + backoff(&policy, slot.streak));
                    }
                }
            }
            if slot.child.is_none()
                && let Some(at) = slot.restart_at
                && now >= at
            {
                slot.restart_at = None;
                let env = std::mem::take(&mut slot.restart_env);
                match start(&slot.spec, slot.restarts + 1, &env) {
                    Ok(child) => {
                        slot.child = Some(child);
                        slot.started = now;
                        slot.restarts += 1;
                        slot.restarts_since_spawn += 1;
                        slot.streak += 1;
                        events.push(SupervisorEvent::Restarted {
                            role: slot.spec.role.clone(),
                            attempt: slot.restarts,
                        });
                    }
                    Err(e) => {
                        events.push(SupervisorEvent::RestartFailed {
                            role: slot.spec.role.clone(),
                            message: e.to_string(),
                        });
                        events.push(SupervisorEvent::GaveUp {
                            role: slot.spec.role.clone(),
                        });
                    }
                }
            }
        }
        events
    }

    /// Restarts per role (every role ever spawned, 0 included).
    #[must_use]
    pub fn restarts(&self) -> BTreeMap<String, u32> {
        self.slots
            .iter()
            .map(|s| (s.spec.role.clone(), s.restarts))
            .collect()
    }

    /// Whether the role's process is running (as of the last `poll`).
    #[must_use]
    pub fn is_running(&self, role: &str) -> bool {
        self.slot(role).is_some_and(|s| s.child.is_some())
    }

    /// Whether the role is down but waiting for its restart backoff.
    #[must_use]
    pub fn restart_pending(&self, role: &str) -> bool {
        self.slot(role).is_some_and(|s| s.restart_at.is_some())
    }

    /// Process id of the role's running process.
    #[must_use]
    pub fn pid(&self, role: &str) -> Option<u32> {
        self.slot(role)?.child.as_ref().map(Child::id)
    }

    /// How the role's last run ended, if it ended.
    #[must_use]
    pub fn last_exit(&self, role: &str) -> Option<ExitStatus> {
        self.slot(role)?.last_exit
    }

    /// Its next exit is expected: no restart, and a pending restart is cancelled.
    pub fn mark_stopping(&mut self, role: &str) {
        if let Some(s) = self.slots.iter_mut().find(|s| s.spec.role == role) {
            s.stopping = true;
            s.restart_at = None;
        }
    }

    /// SIGTERM to every live child (roles in `order` first, then the others in spawn order),
    /// waits up to `timeout` for all of them, then SIGKILLs and reaps the rest. Returns the roles
    /// that needed SIGKILL. Afterwards nothing is running, unreaped or waiting to restart.
    pub fn shutdown(&mut self, order: &[String], timeout: Duration) -> Vec<String> {
        let deadline = Instant::now() + timeout;
        let mut sequence: Vec<usize> = order
            .iter()
            .filter_map(|r| self.slots.iter().position(|s| s.spec.role == *r))
            .collect();
        for i in 0..self.slots.len() {
            if !sequence.contains(&i) {
                sequence.push(i);
            }
        }
        for &i in &sequence {
            let slot = &mut self.slots[i];
            slot.stopping = true;
            slot.restart_at = None;
            if !reap_if_exited(slot)
                && let Some(child) = &slot.child
            {
                signal_group(child, Signal::SIGTERM);
            }
        }
        loop {
            let mut alive = false;
            for slot in &mut self.slots {
                alive |= !reap_if_exited(slot) && slot.child.is_some();
            }
            if !alive || Instant::now() >= deadline {
                break;
            }
            std::thread::sleep(SHUTDOWN_POLL);
        }
        let mut killed = Vec::new();
        for &i in &sequence {
            let slot = &mut self.slots[i];
            if reap_if_exited(slot) {
                continue;
            }
            if let Some(mut child) = slot.child.take() {
                signal_group(&child, Signal::SIGKILL);
                let _ = child.kill();
                if let Ok(status) = child.wait() {
                    slot.last_exit = Some(status.into());
                }
                killed.push(slot.spec.role.clone());
            }
        }
        killed
    }

    /// The spec the role runs with.
    #[must_use]
    pub fn spec(&self, role: &str) -> Option<&ChildSpec> {
        self.slot(role).map(|s| &s.spec)
    }

    /// Hot swap, first half: starts `spec` beside the role's running process (make before
    /// break, so the role's inputs are never unread). Returns the new pid.
    pub fn start_replacement(&mut self, spec: ChildSpec) -> Result<u32, LaunchError> {
        let Some(slot) = self.slots.iter_mut().find(|s| s.spec.role == spec.role) else {
            return Err(LaunchError::NotRunning { role: spec.role });
        };
        if slot.child.is_none() || slot.replacement.is_some() {
            return Err(LaunchError::NotRunning { role: spec.role });
        }
        let child = start(&spec, 0, &[])?;
        let pid = child.id();
        slot.replacement = Some((child, spec));
        Ok(pid)
    }

    /// How the replacement ended, if it exited while starting (it is then forgotten).
    pub fn replacement_exited(&mut self, role: &str) -> Option<ExitStatus> {
        let slot = self.slots.iter_mut().find(|s| s.spec.role == role)?;
        let (child, _) = slot.replacement.as_mut()?;
        let status = match child.try_wait() {
            Ok(Some(status)) => ExitStatus::from(status),
            Ok(None) => return None,
            Err(_) => ExitStatus::Signal(Signal::SIGKILL as i32),
        };
        slot.replacement = None;
        Some(status)
    }

    /// Kills (whole group) and reaps the replacement; the old process keeps the role.
    pub fn abandon_replacement(&mut self, role: &str) {
        if let Some(slot) = self.slots.iter_mut().find(|s| s.spec.role == role)
            && let Some((mut child, _)) = slot.replacement.take()
        {
            signal_group(&child, Signal::SIGKILL);
            let _ = child.kill();
            let _ = child.wait();
        }
    }

    /// Hot swap, second half: SIGTERM to the old process, SIGKILL after `timeout`, then the
    /// replacement owns the role (its restarts use the new command; the budget starts afresh).
    /// `while_waiting` runs between looks (the launcher keeps draining its queues, so a lockstep
    /// publisher the old process waits on is never blocked by the launcher). Returns whether
    /// the old process needed SIGKILL.
    pub fn promote_replacement(
        &mut self,
        role: &str,
        timeout: Duration,
        mut while_waiting: impl FnMut(),
    ) -> bool {
        let Some(slot) = self.slots.iter_mut().find(|s| s.spec.role == role) else {
            return false;
        };
        let Some((new_child, new_spec)) = slot.replacement.take() else {
            return false;
        };
        let mut killed = false;
        if let Some(mut old) = slot.child.take() {
            signal_group(&old, Signal::SIGTERM);
            let deadline = Instant::now() + timeout;
            loop {
                match old.try_wait() {
                    Ok(Some(_)) | Err(_) => break,
                    Ok(None) if Instant::now() >= deadline => {
                        signal_group(&old, Signal::SIGKILL);
                        let _ = old.kill();
                        let _ = old.wait();
                        killed = true;
                        break;
                    }
                    Ok(None) => {
                        while_waiting();
                        std::thread::sleep(Duration::from_millis(1));
                    }
                }
            }
        }
        slot.child = Some(new_child);
        slot.spec = new_spec;
        slot.started = Instant::now();
        slot.restarts_since_spawn = 0;
        slot.streak = 0;
        slot.restart_at = None;
        slot.stopping = false;
        killed
    }

    fn slot(&self, role: &str) -> Option<&Slot> {
        self.slots.iter().find(|s| s.spec.role == role)
    }
}

impl Drop for Supervisor {
    /// Kills (SIGKILL, whole group) and reaps every child still alive, so even a panic in the
    /// launcher leaves no orphan.
    fn drop(&mut self) {
        for slot in &mut self.slots {
            let replacement = slot.replacement.take().map(|(child, _)| child);
            for mut child in slot.child.take().into_iter().chain(replacement) {
                if matches!(child.try_wait(), Ok(None)) {
                    signal_group(&child, Signal::SIGKILL);
                    let _ = child.kill();
                }
                let _ = child.wait();
            }
        }
    }
}

/// Whether a policy restarts after this exit.
/// Exit code 2 is every mole process's "bad input" (a malformed scenario, an unknown planner):
/// running it again cannot help, so no policy restarts it.
pub const EXIT_BAD_INPUT: i32 = 2;

fn wants_restart(when: RestartWhen, status: ExitStatus) -> bool {
    if status == ExitStatus::Code(EXIT_BAD_INPUT) {
        return false;
    }
    match when {
        RestartWhen::Never => false,
        RestartWhen::OnFailure => !status.success(),
        RestartWhen::Always => true,
    }
}

/// `backoff_ms · 2^streak`, capped at `max_backoff_ms`.
fn backoff(policy: &RestartPolicy, streak: u32) -> Duration {
    let factor = 1u64.checked_shl(streak.min(63)).unwrap_or(u64::MAX);
    let ms = policy
        .backoff_ms
        .saturating_mul(factor)
        .min(policy.max_backoff_ms.max(policy.backoff_ms));
    Duration::from_millis(ms)
}

/// Reaps the slot's child if it has exited; true when the slot has no live child left to wait
/// for because it was just reaped.
fn reap_if_exited(slot: &mut Slot) -> bool {
    let Some(child) = slot.child.as_mut() else {
        return false;
    };
    match child.try_wait() {
        Ok(Some(status)) => {
            slot.last_exit = Some(status.into());
            slot.child = None;
            true
        }
        Ok(None) => false,
        Err(_) => {
            slot.child = None;
            true
        }
    }
}

/// Sends `signal` to the child's process group (its pid, as it leads its group); falls back to
/// the child alone when the group is gone.
fn signal_group(child: &Child, signal: Signal) {
    let Ok(raw) = i32::try_from(child.id()) else {
        return;
    };
    let pid = Pid::from_raw(raw);
    if killpg(pid, signal) == Err(Errno::ESRCH) {
        let _ = kill(pid, signal);
    }
}

/// Opens the log (creating its directory), writes a marker line and starts the program.
fn start(spec: &ChildSpec, attempt: u32, env: &[(String, String)]) -> Result<Child, LaunchError> {
    let log_err = |source| LaunchError::Log {
        role: spec.role.clone(),
        path: spec.log_path.clone(),
        source,
    };
    if let Some(dir) = spec.log_path.parent()
        && !dir.as_os_str().is_empty()
    {
        std::fs::create_dir_all(dir).map_err(log_err)?;
    }
    let mut log = OpenOptions::new()
        .create(true)
        .append(true)
        .open(&spec.log_path)
        .map_err(log_err)?;
    let what = if attempt == 0 {
        "start".to_owned()
    } else {
        format!("restart {attempt}")
    };
    writeln!(
        log,
        "--- mole: {what} of `{}`: {} {}",
        spec.role,
        spec.program.display(),
        spec.args.join(" ")
    )
    .map_err(log_err)?;
    let stderr = log.try_clone().map_err(log_err)?;
    let mut command = Command::new(&spec.program);
    command
        .args(&spec.args)
        .envs(spec.env.iter().chain(env).map(|(k, v)| (k, v)))
        .stdin(Stdio::null())
        .stdout(log)
        .stderr(stderr)
        .process_group(0);
    if let Some(cwd) = &spec.cwd {
        command.current_dir(cwd);
    }
    dies_with_the_launcher(&mut command);
    command.spawn().map_err(|source| LaunchError::Spawn {
        role: spec.role.clone(),
        program: spec.program.clone(),
        source,
    })
}

/// If the launcher dies, even by SIGKILL, the child `command` starts gets SIGTERM instead of
/// running on as an orphan that keeps its namespace or port busy.
pub fn dies_with_the_launcher(command: &mut Command) {
    // SAFETY: between fork and exec only async-signal-safe work happens: one prctl(2) call.
    unsafe {
        command.pre_exec(|| {
            nix::sys::prctl::set_pdeathsig(Signal::SIGTERM).map_err(std::io::Error::from)
        });
    }
}

/// Finds a process's program: a command with a `/` is a path (relative to the current
/// directory); a bare name is looked up next to the launcher (`beside`, the directory of the
/// `mole` binary) first, then in each directory of `PATH`.
pub fn resolve_program(command: &str, beside: &Path) -> Result<PathBuf, LaunchError> {
    let path_var = std::env::var_os("PATH").unwrap_or_default();
    let path_dirs: Vec<PathBuf> = std::env::split_paths(&path_var).collect();
    resolve_program_in(command, beside, &path_dirs)
}

/// [`resolve_program`] with an explicit search path.
pub fn resolve_program_in(
    command: &str,
    beside: &Path,
    path_dirs: &[PathBuf],
) -> Result<PathBuf, LaunchError> {
    if command.is_empty() {
        return Err(LaunchError::ProgramNotFound {
            command: String::new(),
            looked: "nowhere (the command is empty)".to_owned(),
        });
    }
    if command.contains('/') {
        let p = PathBuf::from(command);
        if is_executable(&p) {
            return Ok(p);
        }
        return Err(LaunchError::ProgramNotFound {
            command: command.to_owned(),
            looked: format!("{} (not an executable file)", p.display()),
        });
    }
    let candidate = beside.join(command);
    if is_executable(&candidate) {
        return Ok(candidate);
    }
    for dir in path_dirs {
        let candidate = dir.join(command);
        if is_executable(&candidate) {
            return Ok(candidate);
        }
    }
    let dirs: Vec<String> = path_dirs.iter().map(|d| d.display().to_string()).collect();
    Err(LaunchError::ProgramNotFound {
        command: command.to_owned(),
        looked: format!(
            "{} (next to mole), then PATH {}",
            beside.display(),
            if dirs.is_empty() {
                "(empty)".to_owned()
            } else {
                dirs.join(":")
            }
        ),
    })
}

/// A regular file with an execute bit.
fn is_executable(p: &Path) -> bool {
    std::fs::metadata(p).is_ok_and(|m| m.is_file() && m.permissions().mode() & 0o111 != 0)
}

#[cfg(test)]
mod tests;

/// The last `error:` line of a process log (or where the log is).
pub(crate) fn last_error_line(log: &Path) -> String {
    std::fs::read_to_string(log)
        .ok()
        .and_then(|text| {
            text.lines()
                .rev()
                .find_map(|l| l.strip_prefix("error: ").map(str::to_string))
        })
        .unwrap_or_else(|| format!("see {}", log.display()))
}
