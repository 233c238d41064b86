//! Hot swap: replace one role's process while the others run (`mole swap`).
//!
//! Make before break. The new process starts beside the old one and reads the same inputs; once
//! it announces its first handled step (its first `stack/stats` sample with `steps > 0`), the old
//! one gets SIGTERM. Inputs are never unread, so in lockstep no step is lost; every consumer
//! handles each tick once ([`mole_runtime::StepGate`]), so the overlap repeats none. The
//! launcher watches the role's output topic and world/truth during the swap and reports the
//! longest silence and, in lockstep, any lost or repeated world step.

use crate::ChildSpec;
use crate::Supervisor;
use mole_runtime::{ClockMode, Context, Subscriber, cleanup_dead_nodes};
use mole_types::{Message, Stats, Topic, read_name, topics};
use std::time::{Duration, Instant};

/// Roles whose state is the run itself: swapping them would restart the simulation or its
/// bookkeeping, so a swap refuses them (`mole up --swap` can still replace them at start).
pub const UNSWAPPABLE: &[&str] = &["world", "monitor"];

/// How long the new process may take to handle its first step.
const TAKEOVER_TIMEOUT: Duration = Duration::from_secs(20);
/// How long the topics are watched after the old process is gone.
const SETTLE: Duration = Duration::from_millis(300);

/// What a swap measured.
#[derive(Debug, Clone, PartialEq)]
pub struct SwapReport {
    pub role: String,
    pub old_pid: u32,
    pub pid: u32,
    /// The topic whose silence is the gap.
    pub topic: &'static str,
    /// Longest interval between consecutive messages on `topic` during the swap.
    pub gap: Duration,
    /// Median interval on `topic` during the swap (the normal rhythm, for comparison).
    pub period: Duration,
    /// Lockstep: world steps missing from world/truth or from `topic` during the swap.
    pub steps_lost: u64,
    /// Lockstep: world steps the world published twice during the swap.
    pub steps_repeated: u64,
    /// The world's tick when the old process was gone.
    pub tick: u64,
    /// Whether the old process ignored SIGTERM and needed SIGKILL.
    pub killed_old: bool,
    /// From the request to the end of the settle window.
    pub duration: Duration,
}

/// Why a swap did not happen.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum SwapError {
    /// The request was wrong; nothing changed.
    Refused(String),
    /// The new process failed; the old one keeps the role.
    Failed(String),
}

/// What the swap borrows from the running launcher.
pub struct SwapEnv<'a> {
    pub ctx: &'a Context,
    pub supervisor: &'a mut Supervisor,
    pub stats_sub: &'a mut Subscriber<Stats>,
    /// Every stats sample read during the swap is handed on (hang detection, the collector).
    pub on_stats: &'a mut dyn FnMut(&Stats),
    pub mode: ClockMode,
    /// How long the old process gets between SIGTERM and SIGKILL.
    pub stop_timeout: Duration,
}

/// The topic that shows a role at work: one message per handled step.
pub fn output_topic(role: &str) -> Option<&'static str> {
    Some(match role {
        "sensing" => topics::SENSING_SCAN.name,
        "localization" => topics::LOCALIZATION_POSE.name,
        "mapping" => topics::MAPPING_GRID.name,
        "planning" => topics::PLANNING_CMD.name,
        _ => return None,
    })
}

/// Refuses the roles a running stack cannot swap.
pub fn check_swappable(role: &str) -> Result<(), SwapError> {
    if UNSWAPPABLE.contains(&role) {
        return Err(SwapError::Refused(format!(
            "`{role}` holds the run's state and cannot be swapped while it runs; restart the \
             stack with `mole up --swap {role}=COMMAND` instead"
        )));
    }
    Ok(())
}

/// Header stamps and ticks of one topic, read as they come.
trait Watch {
    fn poll(&mut self, stamps: &mut Vec<u64>, ticks: &mut Vec<u64>);
}

struct TopicWatch<M: Message>(Subscriber<M>);

impl<M: Message> Watch for TopicWatch<M> {
    fn poll(&mut self, stamps: &mut Vec<u64>, ticks: &mut Vec<u64>) {
        self.0.drain(|m| {
            stamps.push(m.header().stamp_ns);
            ticks.push(m.header().tick);
        });
    }
}

fn watch<M: Message>(ctx: &Context, topic: Topic<M>) -> Result<Box<dyn Watch>, SwapError> {
    let sub = ctx
        .subscriber(topic)
        .map_err(|e| SwapError::Failed(format!("cannot watch {}: {e}", topic.name)))?;
    Ok(Box::new(TopicWatch(sub)))
}

fn watch_output(ctx: &Context, role: &str) -> Result<(&'static str, Box<dyn Watch>), SwapError> {
    let w = match role {
        "sensing" => watch(ctx, topics::SENSING_SCAN)?,
        "localization" => watch(ctx, topics::LOCALIZATION_POSE)?,
        "mapping" => watch(ctx, topics::MAPPING_GRID)?,
        "planning" => watch(ctx, topics::PLANNING_CMD)?,
        _ => {
            return Err(SwapError::Refused(format!(
                "`{role}` has no output topic the launcher knows; swappable roles: sensing, \
                 localization, mapping, planning"
            )));
        }
    };
    Ok((output_topic(role).unwrap_or("?"), w))
}

/// Everything the watchers saw.
#[derive(Default)]
struct Observed {
    out_stamps: Vec<u64>,
    out_ticks: Vec<u64>,
    truth_stamps: Vec<u64>,
    truth_ticks: Vec<u64>,
}

/// Replaces `role` by `spec` (same role, log and environment; new program, arguments and
/// working directory) while the stack runs.
pub fn hot_swap(env: SwapEnv<'_>, spec: ChildSpec) -> Result<SwapReport, SwapError> {
    let started = Instant::now();
    let role = spec.role.clone();
    check_swappable(&role)?;
    let Some(old_pid) = env.supervisor.pid(&role) else {
        return Err(SwapError::Refused(format!("`{role}` is not running")));
    };
    let (topic, mut out_watch) = watch_output(env.ctx, &role)?;
    let mut truth_watch = watch(env.ctx, topics::WORLD_TRUTH)?;
    let mut seen = Observed::default();
    let mut poll = |seen: &mut Observed| {
        out_watch.poll(&mut seen.out_stamps, &mut seen.out_ticks);
        truth_watch.poll(&mut seen.truth_stamps, &mut seen.truth_ticks);
    };

    // Tells a stateful replacement (localization) to start from its predecessor's state.
    let mut spec = spec;
    spec.env
        .push(("MOLE_TAKEOVER".to_owned(), "true".to_owned()));
    let pid = env
        .supervisor
        .start_replacement(spec)
        .map_err(|e| SwapError::Refused(e.to_string()))?;
    tracing::info!(
        role,
        old_pid,
        pid,
        "swap: the new process runs beside the old one"
    );

    // 1. Wait until the new process has handled a step.
    let deadline = Instant::now() + TAKEOVER_TIMEOUT;
    loop {
        poll(&mut seen);
        let mut took_over = false;
        env.stats_sub.drain(|s| {
            (env.on_stats)(s);
            took_over |= s.pid == pid && s.steps > 0 && read_name(&s.process) == role.as_str();
        });
        if took_over {
            break;
        }
        if let Some(status) = env.supervisor.replacement_exited(&role) {
            cleanup_dead_nodes();
            return Err(SwapError::Failed(format!(
                "the new `{role}` process ended ({status}) before handling a step; the old one \
                 (pid {old_pid}) keeps running; see its log"
            )));
        }
        if env.ctx.shutdown_requested() {
            env.supervisor.abandon_replacement(&role);
            cleanup_dead_nodes();
            return Err(SwapError::Failed(format!(
                "interrupted: the new `{role}` process was stopped, the old one (pid {old_pid}) \
                 keeps running until the stack stops"
            )));
        }
        if Instant::now() >= deadline {
            env.supervisor.abandon_replacement(&role);
            cleanup_dead_nodes();
            return Err(SwapError::Failed(format!(
                "the new `{role}` process handled no step within {TAKEOVER_TIMEOUT:?} (it must \
                 publish stack/stats with its step count); it was stopped, the old one (pid \
                 {old_pid}) keeps running"
            )));
        }
        std::thread::sleep(Duration::from_millis(1));
    }

    // 2. Retire the old process, draining the watchers meanwhile.
    let killed_old = env
        .supervisor
        .promote_replacement(&role, env.stop_timeout, || poll(&mut seen));
    if killed_old {
        cleanup_dead_nodes();
    }
    let tick = seen.truth_ticks.last().copied().unwrap_or(0);
    tracing::info!(role, pid, killed_old, "swap: the old process is gone");

    // 3. Watch a little longer, so a silence right after the old process left is measured.
    let settle_until = Instant::now() + SETTLE;
    while Instant::now() < settle_until {
        poll(&mut seen);
        env.stats_sub.drain(|s| (env.on_stats)(s));
        std::thread::sleep(Duration::from_millis(1));
    }
    poll(&mut seen);

    let (gap, period) = gap_and_period(&mut seen.out_stamps);
    let (steps_lost, steps_repeated) = if env.mode == ClockMode::Lockstep {
        let (truth_lost, repeated) = lost_and_repeated(&seen.truth_ticks);
        (truth_lost + missing_ticks(&mut seen.out_ticks), repeated)
    } else {
        (0, 0)
    };
    Ok(SwapReport {
        role,
        old_pid,
        pid,
        topic,
        gap,
        period,
        steps_lost,
        steps_repeated,
        tick,
        killed_old,
        duration: started.elapsed(),
    })
}

/// Longest and median interval between consecutive stamps (two publishers interleave during
/// the overlap, so the stamps are sorted first).
fn gap_and_period(stamps: &mut [u64]) -> (Duration, Duration) {
    stamps.sort_unstable();
    let mut intervals: Vec<u64> = stamps.windows(2).map(|w| w[1] - w[0]).collect();
    if intervals.is_empty() {
        return (Duration::ZERO, Duration::ZERO);
    }
    intervals.sort_unstable();
    let longest = intervals[intervals.len() - 1];
    let median = intervals[intervals.len() / 2];
    (Duration::from_nanos(longest), Duration::from_nanos(median))
}

/// World ticks in arrival order: ticks skipped, and ticks published again.
fn lost_and_repeated(ticks: &[u64]) -> (u64, u64) {
    let (mut lost, mut repeated) = (0, 0);
    for w in ticks.windows(2) {
        if w[1] <= w[0] {
            repeated += 1;
        } else {
            lost += w[1] - w[0] - 1;
        }
    }
    (lost, repeated)
}

/// Ticks between the first and last seen that never appeared (duplicates are fine: during the
/// overlap both processes answer).
fn missing_ticks(ticks: &mut Vec<u64>) -> u64 {
    ticks.sort_unstable();
    ticks.dedup();
    ticks.windows(2).map(|w| w[1] - w[0] - 1).sum()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gap_is_the_longest_interval_and_period_the_median() {
        let mut stamps = vec![30, 0, 10, 20, 75, 85];
        let (gap, period) = gap_and_period(&mut stamps);
        assert_eq!(gap, Duration::from_nanos(45));
        assert_eq!(period, Duration::from_nanos(10));
        assert_eq!(gap_and_period(&mut []), (Duration::ZERO, Duration::ZERO));
    }

    #[test]
    fn world_ticks_count_losses_and_repeats() {
        assert_eq!(lost_and_repeated(&[1, 2, 3, 4]), (0, 0));
        assert_eq!(lost_and_repeated(&[1, 2, 5, 6]), (2, 0));
        assert_eq!(lost_and_repeated(&[1, 2, 2, 3]), (0, 1));
        assert_eq!(lost_and_repeated(&[]), (0, 0));
    }

    #[test]
    fn duplicate_outputs_are_not_missing_but_holes_are() {
        assert_eq!(missing_ticks(&mut vec![4, 5, 5, 6, 6, 7]), 0);
        assert_eq!(missing_ticks(&mut vec![4, 7, 5]), 1);
    }

    #[test]
    fn every_swappable_role_has_an_output_topic() {
        for role in ["sensing", "localization", "mapping", "planning"] {
            assert!(output_topic(role).is_some(), "{role}");
        }
        for role in UNSWAPPABLE {
            assert!(output_topic(role).is_none(), "{role}");
        }
    }
}
