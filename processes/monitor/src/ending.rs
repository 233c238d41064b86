//! When the monitor writes its files: once the world has published its last step, and, in
//! lockstep, once the last step's estimate and grids are in too (a publisher blocked on the
//! monitor's full queue may still be delivering them after the world's final step), so the
//! summary is the same on every run; never later than [`LOCKSTEP_DRAIN`] after the end.

use mole_types::{ClockMode, EndReason, Truth};
use std::time::{Duration, Instant};

/// Lockstep: how long to wait for the last step's messages after the world's final step.
pub const LOCKSTEP_DRAIN: Duration = Duration::from_secs(2);

/// What the monitor does after a wake-up.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Ending {
    /// The run goes on.
    Running,
    /// The world ended the run but the last step's outputs are still coming: look again soon.
    Draining,
    /// Write the files: the run ended for this reason (`interrupted` on a shutdown).
    Finished(&'static str),
}

/// Follows the world's end flag and the last outputs of a run.
#[derive(Debug, Clone)]
pub struct RunEnding {
    mode: ClockMode,
    end: Option<u32>,
    end_seen: Option<Instant>,
    started: Option<Instant>,
}

impl RunEnding {
    pub fn new(mode: ClockMode) -> Self {
        Self {
            mode,
            end: None,
            end_seen: None,
            started: None,
        }
    }

    /// Takes a truth: the run starts with the first, and ends with the one flagged as the end.
    pub fn on_truth(&mut self, truth: &Truth) {
        self.started.get_or_insert_with(Instant::now);
        if truth.is_end() {
            self.end = self.end.or(Some(truth.end_reason));
        }
    }

    /// After a wake-up: `last` is the newest truth's tick, `outputs` the newest ticks of the
    /// estimate and the grids; `shutdown` whether the monitor was asked to stop.
    pub fn decide(&mut self, last: u64, outputs: &[Option<u64>], shutdown: bool) -> Ending {
        if shutdown {
            return Ending::Finished(self.reason());
        }
        let Some(_) = self.end else {
            return Ending::Running;
        };
        let behind = outputs.iter().any(|t| t.is_some_and(|t| t + 1 < last));
        let waited = self.end_seen.get_or_insert_with(Instant::now).elapsed();
        if self.mode == ClockMode::Lockstep && behind && waited < LOCKSTEP_DRAIN {
            return Ending::Draining;
        }
        Ending::Finished(self.reason())
    }

    /// Wall time from the first truth.
    pub fn wall_time(&self) -> Duration {
        self.started.map_or(Duration::ZERO, |s| s.elapsed())
    }

    fn reason(&self) -> &'static str {
        self.end
            .and_then(EndReason::from_code)
            .map_or("interrupted", EndReason::name)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn truth(end: Option<EndReason>) -> Box<Truth> {
        let mut t: Box<Truth> = bytemuck::zeroed_box();
        if let Some(reason) = end {
            t.flags = mole_types::TRUTH_END;
            t.end_reason = reason.code();
        }
        t
    }

    /// Lockstep waits for the last step's outputs after the end; realtime does not; a
    /// shutdown finishes at once, as `interrupted` when the world never ended the run.
    #[test]
    fn the_end_waits_in_lockstep_for_outputs_behind_the_last_truth() {
        let mut lockstep = RunEnding::new(ClockMode::Lockstep);
        lockstep.on_truth(&truth(None));
        assert_eq!(lockstep.decide(9, &[Some(3)], false), Ending::Running);
        lockstep.on_truth(&truth(Some(EndReason::Ticks)));
        assert_eq!(
            lockstep.decide(10, &[Some(8), Some(9)], false),
            Ending::Draining
        );
        assert_eq!(
            lockstep.decide(10, &[Some(9), None], false),
            Ending::Finished("ticks")
        );
        let mut realtime = RunEnding::new(ClockMode::Realtime);
        realtime.on_truth(&truth(Some(EndReason::GoalReached)));
        assert_eq!(
            realtime.decide(10, &[Some(2)], false),
            Ending::Finished("goal_reached")
        );
        let mut stopped = RunEnding::new(ClockMode::Lockstep);
        assert_eq!(
            stopped.decide(0, &[], true),
            Ending::Finished("interrupted")
        );
    }
}
