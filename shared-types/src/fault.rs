//! Faults on demand (`mole fault`, docs/architecture.md, "Faults on demand"): what can be done to
//! a running stack, the rules a fault must follow, and `stack/faults`, the message that tells
//! every process and observer about one.
//!
//! The launcher carries out a kill or a stop itself (it holds the pids) and publishes every
//! fault on `stack/faults`; the runtime of the process that publishes a faulted topic delays,
//! drops or corrupts that topic's samples while the fault lasts; the recorder writes each fault
//! as an event and the view shows it.

use crate::graph::{GRAPH, Role};
use crate::kinds::UnknownChoice;
use crate::messages::{Header, NAME_LEN};
use crate::{ClockMode, Invalid, Message, finite, read_name, write_name};
use bytemuck::{Pod, Zeroable};
use core::fmt;
use core::str::FromStr;
use iceoryx2_bb_derive_macros::ZeroCopySend;
use iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend;

choice! {
    /// What `mole fault` does; `stack/faults` carries the code.
    pub enum FaultKind: "fault" {
        /// SIGKILL a role's process; its restart policy brings it back.
        Kill = ("kill", 1),
        /// SIGSTOP a role's process for the duration, then SIGCONT.
        Stop = ("stop", 2),
        /// Hold every sample of a topic this long before it is sent, for the duration.
        Delay = ("delay", 3),
        /// Drop a fraction of a topic's samples at its publisher, for the duration.
        Drop = ("drop", 4),
        /// Corrupt a fraction of a topic's samples, for the duration, so that every reader's
        /// validation must refuse them.
        Corrupt = ("corrupt", 5),
    }
}

impl FaultKind {
    /// Whether the fault is aimed at a role's process (kill, stop) rather than a topic.
    pub const fn targets_a_role(self) -> bool {
        matches!(self, FaultKind::Kill | FaultKind::Stop)
    }
}

/// The longest a fault may last (s).
pub const FAULT_MAX_DURATION_S: f64 = 600.0;
/// The longest a delay may hold each sample (ms).
pub const FAULT_MAX_DELAY_MS: f64 = 10_000.0;

/// `stack/faults`: one fault the launcher injected.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable, ZeroCopySend, Message)]
#[type_name("mole.Fault.v1")]
#[layout(size = 112)]
#[message(check = Fault::check)]
pub struct Fault {
    /// `tick`: the world's newest step when the fault was injected.
    pub header: Header,
    /// 1 for the run's first fault, then counting up.
    pub id: u32,
    /// A [`FaultKind`] code.
    pub kind: u32,
    /// The role (kill, stop) or topic (delay, drop, corrupt), NUL-padded.
    pub target: [u8; NAME_LEN],
    /// When the fault starts and ends (CLOCK_MONOTONIC, ns); equal for a kill.
    pub start_ns: u64,
    pub end_ns: u64,
    /// How long each sample is held (delay), ns.
    pub delay_ns: u64,
    /// The fraction of samples dropped or corrupted, in [0, 1].
    pub fraction: f64,
    /// The seed of the stream that picks which samples (and which bytes) are hit.
    pub seed: u64,
}

impl Fault {
    /// The fault's kind (validated messages always have one).
    pub fn fault_kind(&self) -> Option<FaultKind> {
        FaultKind::from_code(self.kind)
    }

    /// The role or topic the fault is aimed at.
    pub fn target(&self) -> std::borrow::Cow<'_, str> {
        read_name(&self.target)
    }

    /// Whether the fault is in force at `now_ns`.
    pub fn active_at(&self, now_ns: u64) -> bool {
        (self.start_ns..self.end_ns).contains(&now_ns)
    }
}

impl Fault {
    /// Whether the values make sense (`Message::validate`).
    fn check(&self) -> Result<(), Invalid> {
        if self.fault_kind().is_none() {
            return Err(Invalid::UnknownCode("kind"));
        }
        let name = self.target.split(|b| *b == 0).next().unwrap_or_default();
        if name.is_empty() || std::str::from_utf8(name).is_err() {
            return Err(Invalid::OutOfRange("target"));
        }
        if self.end_ns < self.start_ns {
            return Err(Invalid::OutOfRange("end_ns"));
        }
        finite("fraction", self.fraction)?;
        if !(0.0..=1.0).contains(&self.fraction) {
            return Err(Invalid::OutOfRange("fraction"));
        }
        Ok(())
    }
}

/// A fault as a user asks for it: what, on which role or topic, for how long, how hard.
#[derive(Debug, Clone, PartialEq)]
pub struct FaultSpec {
    pub kind: FaultKind,
    /// A role (kill, stop) or one of the topics a role of the graph publishes.
    pub target: String,
    /// How long it lasts (s); 0 for a kill.
    pub duration_s: f64,
    /// How long each sample is held (ms), for a delay.
    pub delay_ms: f64,
    /// The fraction of samples hit, for a drop or a corruption.
    pub fraction: f64,
}

/// Why a fault cannot be injected: one sentence naming the field and what was expected.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct BadFault(pub String);

impl fmt::Display for BadFault {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for BadFault {}

/// Every topic a role of the graph publishes: what a delay, drop or corruption may aim at.
pub fn faultable_topics() -> Vec<&'static str> {
    let mut topics: Vec<&'static str> = GRAPH.iter().flat_map(|r| r.outputs).copied().collect();
    topics.sort_unstable();
    topics.dedup();
    topics
}

impl FaultSpec {
    /// Checks the fault against the rules, for a stack of clock `mode`.
    pub fn check(&self, mode: ClockMode) -> Result<(), BadFault> {
        let bad = |s: String| Err(BadFault(s));
        if self.kind.targets_a_role() {
            if Role::from_str(&self.target).is_err() {
                return bad(format!(
                    "{}: unknown role `{}`, expected one of: {}",
                    self.kind,
                    self.target,
                    Role::NAMES.join(", ")
                ));
            }
        } else if !faultable_topics().contains(&self.target.as_str()) {
            return bad(format!(
                "{}: unknown topic `{}`, expected one of the topics the stack's roles publish: {}",
                self.kind,
                self.target,
                faultable_topics().join(", ")
            ));
        }
        let seconds = self.duration_s;
        match self.kind {
            FaultKind::Kill => {}
            _ if !(seconds.is_finite() && seconds > 0.0 && seconds <= FAULT_MAX_DURATION_S) => {
                return bad(format!(
                    "{}: --for: expected a duration in seconds above 0 and at most \
                     {FAULT_MAX_DURATION_S}, found {seconds}",
                    self.kind
                ));
            }
            _ => {}
        }
        if self.kind == FaultKind::Delay
            && !(self.delay_ms.is_finite()
                && self.delay_ms > 0.0
                && self.delay_ms <= FAULT_MAX_DELAY_MS)
        {
            return bad(format!(
                "delay: --by: expected milliseconds above 0 and at most {FAULT_MAX_DELAY_MS}, \
                 found {}",
                self.delay_ms
            ));
        }
        if matches!(self.kind, FaultKind::Drop | FaultKind::Corrupt)
            && !(self.fraction.is_finite() && self.fraction > 0.0 && self.fraction <= 1.0)
        {
            return bad(format!(
                "{}: --fraction: expected a fraction above 0 and at most 1, found {}",
                self.kind, self.fraction
            ));
        }
        if self.kind == FaultKind::Drop && mode == ClockMode::Lockstep {
            return bad(
                "drop: a lockstep stack delivers every sample (a lost one would only stall \
                 it); drop needs a realtime stack (use delay or corrupt in lockstep)"
                    .into(),
            );
        }
        Ok(())
    }

    /// The words a `stack/control` request carries the fault in (see [`FaultSpec::from_words`]).
    pub fn to_words(&self) -> Vec<String> {
        vec![
            self.kind.name().to_string(),
            self.target.clone(),
            self.duration_s.to_string(),
            self.delay_ms.to_string(),
            self.fraction.to_string(),
        ]
    }

    /// The fault a request's words describe: kind, target, duration (s), delay (ms), fraction.
    pub fn from_words(words: &[String]) -> Result<FaultSpec, BadFault> {
        let [kind, target, duration, delay, fraction] = words else {
            return Err(BadFault(format!(
                "a fault is five words (kind, target, seconds, milliseconds, fraction), found {}",
                words.len()
            )));
        };
        let number = |what: &str, word: &str| {
            word.parse::<f64>()
                .map_err(|_| BadFault(format!("{what}: expected a number, found `{word}`")))
        };
        Ok(FaultSpec {
            kind: kind
                .parse()
                .map_err(|e: UnknownChoice| BadFault(e.to_string()))?,
            target: target.clone(),
            duration_s: number("duration", duration)?,
            delay_ms: number("delay", delay)?,
            fraction: number("fraction", fraction)?,
        })
    }

    /// The `stack/faults` message of this fault, injected at `now_ns` as the run's fault `id`.
    pub fn to_message(&self, fault: &mut Fault, id: u32, now_ns: u64, seed: u64) {
        fault.id = id;
        fault.kind = self.kind.code();
        write_name(&mut fault.target, &self.target);
        fault.start_ns = now_ns;
        let duration_ns = match self.kind {
            FaultKind::Kill => 0,
            _ => (self.duration_s * 1e9) as u64,
        };
        fault.end_ns = now_ns.saturating_add(duration_ns);
        fault.delay_ns = match self.kind {
            FaultKind::Delay => (self.delay_ms * 1e6) as u64,
            _ => 0,
        };
        fault.fraction = match self.kind {
            FaultKind::Drop | FaultKind::Corrupt => self.fraction,
            _ => 0.0,
        };
        fault.seed = seed;
    }
}

impl fmt::Display for FaultSpec {
    /// One line a user reads: `delay sensing/scan by 50 ms for 2 s`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.kind {
            FaultKind::Kill => write!(f, "kill {}", self.target),
            FaultKind::Stop => write!(f, "stop {} for {} s", self.target, self.duration_s),
            FaultKind::Delay => write!(
                f,
                "delay {} by {} ms for {} s",
                self.target, self.delay_ms, self.duration_s
            ),
            FaultKind::Drop | FaultKind::Corrupt => write!(
                f,
                "{} {} of {} for {} s",
                self.kind, self.fraction, self.target, self.duration_s
            ),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn spec(kind: FaultKind, target: &str) -> FaultSpec {
        FaultSpec {
            kind,
            target: target.into(),
            duration_s: 2.0,
            delay_ms: 50.0,
            fraction: 0.5,
        }
    }

    /// Roles for kill and stop, published topics for the rest; each refusal names what was
    /// wrong and the choices.
    #[test]
    fn a_fault_names_a_role_or_a_published_topic() {
        let rt = ClockMode::Realtime;
        assert_eq!(spec(FaultKind::Kill, "mapping").check(rt), Ok(()));
        assert_eq!(spec(FaultKind::Delay, "sensing/scan").check(rt), Ok(()));
        let e = spec(FaultKind::Kill, "sensing/scan").check(rt).unwrap_err();
        assert!(
            e.0.starts_with("kill: unknown role `sensing/scan`, expected one of: world"),
            "{e}"
        );
        let e = spec(FaultKind::Corrupt, "mapping").check(rt).unwrap_err();
        assert!(e.0.contains("unknown topic `mapping`"), "{e}");
        assert!(e.0.contains("sensing/scan"), "{e}");
        let e = spec(FaultKind::Drop, "stack/stats").check(rt).unwrap_err();
        assert!(e.0.contains("unknown topic `stack/stats`"), "{e}");
    }

    /// Durations, delays and fractions in their ranges; drop is refused in lockstep.
    #[test]
    fn numbers_are_checked_and_drop_needs_realtime() {
        let rt = ClockMode::Realtime;
        let mut s = spec(FaultKind::Stop, "planning");
        s.duration_s = 0.0;
        assert!(s.check(rt).unwrap_err().0.contains("--for"));
        s.duration_s = f64::NAN;
        assert!(s.check(rt).is_err());
        let mut s = spec(FaultKind::Delay, "planning/cmd");
        s.delay_ms = -1.0;
        assert!(s.check(rt).unwrap_err().0.contains("--by"));
        let mut s = spec(FaultKind::Corrupt, "planning/cmd");
        s.fraction = 1.5;
        assert!(s.check(rt).unwrap_err().0.contains("--fraction"));
        let mut kill = spec(FaultKind::Kill, "world");
        kill.duration_s = 0.0;
        assert_eq!(kill.check(ClockMode::Lockstep), Ok(()));
        let e = spec(FaultKind::Drop, "sensing/scan")
            .check(ClockMode::Lockstep)
            .unwrap_err();
        assert!(e.0.contains("drop needs a realtime stack"), "{e}");
        assert_eq!(
            spec(FaultKind::Corrupt, "sensing/scan").check(ClockMode::Lockstep),
            Ok(())
        );
    }

    /// A fault travels as words and comes back the same; its message validates and is in force
    /// from its start to its end.
    #[test]
    fn a_fault_round_trips_through_words_and_its_message() {
        let s = spec(FaultKind::Delay, "sensing/scan");
        assert_eq!(FaultSpec::from_words(&s.to_words()), Ok(s.clone()));
        assert!(FaultSpec::from_words(&["delay".into()]).is_err());
        let mut words = s.to_words();
        words[0] = "melt".into();
        let e = FaultSpec::from_words(&words).unwrap_err();
        assert!(e.0.contains("unknown fault `melt`"), "{e}");
        let mut m: Fault = Zeroable::zeroed();
        s.to_message(&mut m, 7, 1_000, 42);
        assert_eq!(m.validate(), Ok(()));
        assert_eq!(
            (m.id, m.fault_kind(), m.target().as_ref()),
            (7, Some(FaultKind::Delay), "sensing/scan")
        );
        assert_eq!((m.end_ns, m.delay_ns), (1_000 + 2_000_000_000, 50_000_000));
        assert!(m.active_at(1_000) && !m.active_at(m.end_ns));
        m.kind = 9;
        assert_eq!(m.validate(), Err(Invalid::UnknownCode("kind")));
    }
}
