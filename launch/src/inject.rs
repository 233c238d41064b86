//! The launcher's side of `mole fault`: a fault request that came through `stack/control` is
//! checked against the running stack, carried out (a kill or a stop on the role's process, which
//! the launcher holds), published on `stack/faults` (the runtime of the faulted topic's
//! publisher does a delay, a drop or a corruption; the recorder and the view show every fault)
//! and kept for summary.json.

use crate::Supervisor;
use mole_monitor::FaultRecord;
use mole_runtime::{Context, Publisher, RuntimeError, now_ns};
use mole_types::{ClockMode, Fault, FaultKind, FaultSpec, topics};
use nix::sys::signal::{Signal, kill};
use nix::unistd::Pid;
use std::time::{Duration, Instant};

/// Carries out faults and remembers them.
pub struct Injector {
    faults: Publisher<Fault>,
    mode: ClockMode,
    /// The run's seed: each fault's stream of hits is derived from it and the fault's id.
    seed: u64,
    /// Processes stopped by a fault, and when they are to go on.
    stopped: Vec<(u32, Instant)>,
    records: Vec<FaultRecord>,
}

impl Injector {
    /// An injector publishing on the launcher's `ctx`.
    pub fn new(ctx: &Context, mode: ClockMode, seed: u64) -> Result<Injector, RuntimeError> {
        Ok(Injector {
            faults: ctx.publisher(topics::STACK_FAULTS)?,
            mode,
            seed,
            stopped: Vec::new(),
            records: Vec::new(),
        })
    }

    /// Injects `spec` at the world's step `tick`: refused (one sentence) when it breaks the rules
    /// or aims at a role that is not running; otherwise the sentence that says what was done.
    pub fn inject(
        &mut self,
        spec: &FaultSpec,
        supervisor: &Supervisor,
        tick: u64,
    ) -> Result<String, String> {
        spec.check(self.mode).map_err(|e| e.0)?;
        if spec.kind.targets_a_role() {
            let pid = supervisor.pid(&spec.target).ok_or_else(|| {
                format!(
                    "{}: `{}` has no running process (not in this stack, or restarting)",
                    spec.kind, spec.target
                )
            })?;
            let signal = match spec.kind {
                FaultKind::Kill => Signal::SIGKILL,
                _ => Signal::SIGSTOP,
            };
            kill(Pid::from_raw(pid as i32), signal)
                .map_err(|e| format!("{}: cannot signal pid {pid}: {e}", spec.kind))?;
            // A killed process that a stop held is gone: its pid is not to be continued.
            self.stopped.retain(|&(stopped, _)| stopped != pid);
            if spec.kind == FaultKind::Stop {
                let until = Instant::now() + Duration::from_secs_f64(spec.duration_s);
                self.stopped.push((pid, until));
            }
        }
        let id = self.records.len() as u32 + 1;
        let (seed, now) = (
            self.seed ^ u64::from(id).wrapping_mul(0x9e37_79b9),
            now_ns(),
        );
        if let Err(e) = self
            .faults
            .publish(tick, now, |m| spec.to_message(m, id, now, seed))
        {
            // A kill or a stop is done already; the topic faults would not happen: say so.
            if !spec.kind.targets_a_role() {
                return Err(format!("{}: cannot publish it: {e}", spec.kind));
            }
            tracing::warn!("cannot publish fault {id} on stack/faults: {e}");
        }
        self.records.push(FaultRecord {
            id,
            kind: spec.kind.name().to_owned(),
            target: spec.target.clone(),
            tick,
            duration_s: spec.duration_s,
            delay_ms: spec.delay_ms,
            fraction: spec.fraction,
        });
        Ok(format!("fault {id} at tick {tick}: {spec}"))
    }

    /// Lets every process whose stop is over go on (SIGCONT).
    pub fn release_due(&mut self) {
        let now = Instant::now();
        self.stopped.retain(|&(pid, until)| {
            if until > now {
                return true;
            }
            let _ = kill(Pid::from_raw(pid as i32), Signal::SIGCONT);
            false
        });
    }

    /// Lets every stopped process go on, whatever is left of its stop (the stack is stopping;
    /// a stopped process could not take its SIGTERM); returns the faults injected.
    pub fn finish(mut self) -> Vec<FaultRecord> {
        for (pid, _) in self.stopped.drain(..) {
            let _ = kill(Pid::from_raw(pid as i32), Signal::SIGCONT);
        }
        self.records
    }
}
