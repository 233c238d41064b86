//! The two clock modes and the rule that decides when a process handles a step.

pub use mole_types::ClockMode;

/// Parses `X,Y` (metres) from a command line or an environment variable, e.g. `--goal 8.5,9`.
pub fn parse_point(text: &str) -> Result<(f64, f64), String> {
    let parsed = text.split_once(',').and_then(|(x, y)| {
        let (x, y) = (x.trim().parse::<f64>().ok()?, y.trim().parse::<f64>().ok()?);
        (x.is_finite() && y.is_finite()).then_some((x, y))
    });
    parsed.ok_or_else(|| format!("expected X,Y in metres (e.g. 8.5,9), found `{text}`"))
}

/// Decides whether a step is due from the ticks of a process's inputs.
///
/// The first input is the trigger. Realtime: a step is due whenever the trigger carries a tick
/// not handled yet; the other inputs are used as they are (newest). Lockstep: a step is due when
/// every input carries the same tick k and k was not handled yet.
#[derive(Debug, Clone)]
pub struct StepGate {
    mode: ClockMode,
    last: Option<u64>,
}

impl StepGate {
    pub fn new(mode: ClockMode) -> Self {
        Self { mode, last: None }
    }

    /// The tick to handle now, if any; marks it handled.
    #[must_use]
    pub fn ready(&mut self, ticks: &[Option<u64>]) -> Option<u64> {
        let k = (*ticks.first()?)?;
        if self.last.is_some_and(|last| k <= last) {
            return None;
        }
        if self.mode == ClockMode::Lockstep && ticks.iter().any(|t| *t != Some(k)) {
            return None;
        }
        self.last = Some(k);
        Some(k)
    }

    /// Treats every tick up to `tick` as handled: a replacement resumes after the last step
    /// of the process it took over from.
    pub fn resume_after(&mut self, tick: u64) {
        self.last = Some(tick);
    }

    /// The last tick handled.
    pub fn last(&self) -> Option<u64> {
        self.last
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lockstep_waits_for_every_input_of_the_same_tick() {
        let mut gate = StepGate::new(ClockMode::Lockstep);
        assert_eq!(gate.ready(&[Some(0), None]), None);
        assert_eq!(gate.ready(&[Some(0), Some(1)]), None);
        assert_eq!(gate.ready(&[Some(0), Some(0)]), Some(0));
        assert_eq!(
            gate.ready(&[Some(0), Some(0)]),
            None,
            "a tick is handled once"
        );
        assert_eq!(gate.ready(&[Some(1), Some(0)]), None);
        assert_eq!(gate.ready(&[Some(1), Some(1)]), Some(1));
    }

    #[test]
    fn realtime_steps_on_every_new_trigger() {
        let mut gate = StepGate::new(ClockMode::Realtime);
        assert_eq!(gate.ready(&[None, Some(3)]), None);
        assert_eq!(gate.ready(&[Some(5), None]), Some(5));
        assert_eq!(gate.ready(&[Some(5), Some(9)]), None);
        assert_eq!(gate.ready(&[Some(7), Some(2)]), Some(7));
        assert_eq!(gate.last(), Some(7));
    }

    #[test]
    fn points_parse_and_bad_ones_are_named() {
        assert_eq!(parse_point("8.5, 9"), Ok((8.5, 9.0)));
        assert!(parse_point("8.5").unwrap_err().contains("`8.5`"));
        assert!(parse_point("nan,1").is_err());
    }
}
