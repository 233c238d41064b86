//! Hot swap: replace one role's process while the others run (`mole swap`).
//!
//! Make before break. The new process starts beside the old one and reads the same inputs; once
//! it announces its first handled step (its first `stack/stats` sample with `steps > 0`), the old
//! one gets SIGTERM. Inputs are never unread, so in lockstep no step is lost; every consumer
//! handles each tick once (the runtime's step loop), so the overlap repeats none. The
//! launcher watches the role's output topic, world/truth and the outputs of the processes that
//! read the role's output during the swap, and reports how many ticks it observed, the longest
//! silence and, in lockstep, any lost step and any step a consumer handled twice.

use crate::ChildSpec;
use crate::Supervisor;
use mole_runtime::{ClockMode, Context, Subscriber, cleanup_dead_nodes};
use mole_types::graph::{self, Resume, RoleSpec, Swap};
use mole_types::topics::{self, TopicVisitor};
use mole_types::{GRAPH, Message, Stats, Topic, env, read_name};
use std::time::{Duration, Instant};

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
    /// Longest run of world ticks `topic` skipped during the swap: the gap as a count.
    pub gap_ticks: u64,
    /// Ticks seen on `topic` during the swap (each counted once, though both processes answer
    /// during the overlap): what `steps_lost` and `steps_repeated` are counted over.
    pub ticks_observed: u64,
    /// Lockstep: world steps missing from world/truth or from `topic` during the swap.
    pub steps_lost: u64,
    /// Lockstep: steps handled twice during the swap: published twice on world/truth, or
    /// twice on the output of a process that reads `topic` ([`graph::consumer_outputs`]).
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

/// The graph's row of a role `mole swap` may replace, with the step output a swap is watched on;
/// refuses a role the graph does not have or says may not be swapped, naming why (`mole up
/// --swap` can still replace it at start).
pub fn check_swappable(role: &str) -> Result<(&'static RoleSpec, &'static str), SwapError> {
    let swappable: Vec<&str> = GRAPH
        .iter()
        .filter(|r| r.swap == Swap::Allowed)
        .map(|r| r.role.name())
        .collect();
    let spec = graph::spec(role).ok_or_else(|| {
        SwapError::Refused(format!(
            "no role `{role}` in the stack's graph; swappable roles: {}",
            swappable.join(", ")
        ))
    })?;
    match (spec.swap, spec.step_output) {
        (Swap::Allowed, Some(topic)) => Ok((spec, topic)),
        (Swap::Allowed, None) => Err(SwapError::Refused(format!(
            "`{role}` has no step output to watch a swap on"
        ))),
        (Swap::Refused(why), _) => Err(SwapError::Refused(format!(
            "`{role}` cannot be swapped while the stack runs: {why}; restart the stack with \
             `mole up --swap {role}=COMMAND` instead (swappable roles: {})",
            swappable.join(", ")
        ))),
    }
}

/// Header stamps and ticks of one topic, read as they come.
trait Watch {
    fn poll(&mut self, seen: &mut Seen);
}

struct TopicWatch<M: Message>(Subscriber<M>);

impl<M: Message> Watch for TopicWatch<M> {
    fn poll(&mut self, seen: &mut Seen) {
        self.0.drain(|m| {
            seen.stamps.push(m.header().stamp_ns);
            seen.ticks.push(m.header().tick);
        });
    }
}

fn watch<M: Message>(ctx: &Context, topic: Topic<M>) -> Result<Box<dyn Watch>, SwapError> {
    let sub = ctx
        .subscriber(topic)
        .map_err(|e| SwapError::Failed(format!("cannot watch {}: {e}", topic.name)))?;
    Ok(Box::new(TopicWatch(sub)))
}

/// Finds a topic of the table by name and watches it, typed.
struct WatchByName<'a> {
    ctx: &'a Context,
    name: &'a str,
    found: Option<Result<Box<dyn Watch>, SwapError>>,
}

impl TopicVisitor for WatchByName<'_> {
    fn visit<M: Message>(&mut self, _constant: &'static str, topic: Topic<M>) {
        if self.found.is_none() && topic.name == self.name {
            self.found = Some(watch(self.ctx, topic));
        }
    }
}

/// A watcher of a topic of the table, by name.
fn watch_topic(ctx: &Context, name: &str) -> Result<Box<dyn Watch>, SwapError> {
    let mut finder = WatchByName {
        ctx,
        name,
        found: None,
    };
    topics::for_each(&mut finder);
    finder
        .found
        .unwrap_or_else(|| Err(SwapError::Failed(format!("no topic `{name}` to watch"))))
}

/// Stamps and ticks of one watched topic, in arrival order.
#[derive(Default)]
struct Seen {
    stamps: Vec<u64>,
    ticks: Vec<u64>,
}

/// Everything the watchers saw.
#[derive(Default)]
struct Observed {
    /// The swapped role's output: both processes answer while they overlap.
    output: Seen,
    truth: Seen,
    /// The outputs of the role's consumers ([`graph::consumer_outputs`]).
    consumers: Vec<Seen>,
}

/// Replaces `role` by `spec` (same role, log and environment; new program, arguments and
/// working directory) while the stack runs.
pub fn hot_swap(env: SwapEnv<'_>, spec: ChildSpec) -> Result<SwapReport, SwapError> {
    let started = Instant::now();
    let role = spec.role.clone();
    let (row, topic) = check_swappable(&role)?;
    let Some(old_pid) = env.supervisor.pid(&role) else {
        return Err(SwapError::Refused(format!("`{role}` is not running")));
    };
    let mut out_watch = watch_topic(env.ctx, topic)?;
    let mut truth_watch = watch(env.ctx, topics::WORLD_TRUTH)?;
    // Only lockstep counts repeats: a realtime consumer handles the newest tick it has.
    let consumers = match env.mode {
        ClockMode::Lockstep => graph::consumer_outputs(row.role),
        ClockMode::Realtime => Vec::new(),
    };
    let mut consumer_watches = consumers
        .iter()
        .map(|name| watch_topic(env.ctx, name))
        .collect::<Result<Vec<_>, _>>()?;
    let mut seen = Observed {
        consumers: consumer_watches.iter().map(|_| Seen::default()).collect(),
        ..Observed::default()
    };
    let mut poll = |seen: &mut Observed| {
        out_watch.poll(&mut seen.output);
        truth_watch.poll(&mut seen.truth);
        for (w, consumer) in consumer_watches.iter_mut().zip(&mut seen.consumers) {
            w.poll(consumer);
        }
    };

    // Tells a replacement that resumes (the graph says which) to start from its predecessor's
    // last output.
    let mut spec = spec;
    if matches!(row.resume, Resume::From(_)) {
        spec.env.push((env::TAKEOVER.to_owned(), "true".to_owned()));
    }
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
    let tick = seen.truth.ticks.last().copied().unwrap_or(0);
    tracing::info!(role, pid, killed_old, "swap: the old process is gone");

    // 3. Watch a little longer, so a silence right after the old process left is measured.
    let settle_until = Instant::now() + SETTLE;
    while Instant::now() < settle_until {
        poll(&mut seen);
        env.stats_sub.drain(|s| (env.on_stats)(s));
        std::thread::sleep(Duration::from_millis(1));
    }
    poll(&mut seen);

    let (gap, period) = gap_and_period(&mut seen.output.stamps);
    let ticks_observed = distinct(&seen.output.ticks);
    let gap_ticks = longest_skip(&seen.output.ticks);
    let (steps_lost, steps_repeated) = if env.mode == ClockMode::Lockstep {
        (steps_lost(&seen), steps_repeated(&seen))
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
        gap_ticks,
        ticks_observed,
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

/// The most ticks skipped between two consecutive distinct ticks of `ticks` (0 for none).
fn longest_skip(ticks: &[u64]) -> u64 {
    let mut sorted = ticks.to_vec();
    sorted.sort_unstable();
    sorted.dedup();
    sorted
        .windows(2)
        .map(|w| w[1] - w[0] - 1)
        .max()
        .unwrap_or(0)
}

/// Lockstep: world steps skipped on world/truth, and ticks missing between the first and last
/// the role's output showed (it may show a tick twice: during the overlap both processes answer).
fn steps_lost(seen: &Observed) -> u64 {
    let truth_skipped: u64 = seen
        .truth
        .ticks
        .windows(2)
        .filter(|w| w[1] > w[0])
        .map(|w| w[1] - w[0] - 1)
        .sum();
    let mut output = seen.output.ticks.clone();
    output.sort_unstable();
    output.dedup();
    let output_missing: u64 = output.windows(2).map(|w| w[1] - w[0] - 1).sum();
    truth_skipped + output_missing
}

/// Lockstep: steps handled twice: a world/truth tick that does not follow the one before (the
/// world stepped back or published a step again), and every extra time a consumer published a
/// tick. The role's own output is not looked at: its overlap duplicates are the make before
/// break, not a repeat.
fn steps_repeated(seen: &Observed) -> u64 {
    let truth_again = seen.truth.ticks.windows(2).filter(|w| w[1] <= w[0]).count() as u64;
    let consumers_again: u64 = seen
        .consumers
        .iter()
        .map(|c| c.ticks.len() as u64 - distinct(&c.ticks))
        .sum();
    truth_again + consumers_again
}

/// How many different ticks `ticks` holds.
fn distinct(ticks: &[u64]) -> u64 {
    ticks
        .iter()
        .collect::<std::collections::BTreeSet<_>>()
        .len() as u64
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
    fn the_gap_in_ticks_is_the_longest_skip_whatever_the_order() {
        assert_eq!(longest_skip(&[3, 4, 4, 9, 5, 10]), 3);
        assert_eq!(longest_skip(&[1, 2, 3]), 0);
        assert_eq!(longest_skip(&[]), 0);
    }

    /// What the watchers of a swap saw, by tick (the stamps do not matter here).
    fn observed(output: &[u64], truth: &[u64], consumers: &[&[u64]]) -> Observed {
        let seen = |ticks: &[u64]| Seen {
            stamps: Vec::new(),
            ticks: ticks.to_vec(),
        };
        Observed {
            output: seen(output),
            truth: seen(truth),
            consumers: consumers.iter().map(|c| seen(c)).collect(),
        }
    }

    #[test]
    fn world_ticks_count_losses_and_repeats() {
        let steady = observed(&[1, 2, 3, 4], &[1, 2, 3, 4], &[]);
        assert_eq!((steps_lost(&steady), steps_repeated(&steady)), (0, 0));
        let skipped = observed(&[1, 2, 5, 6], &[1, 2, 5, 6], &[]);
        assert_eq!((steps_lost(&skipped), steps_repeated(&skipped)), (4, 0));
        let again = observed(&[1, 2, 3], &[1, 2, 2, 3], &[]);
        assert_eq!((steps_lost(&again), steps_repeated(&again)), (0, 1));
        let nothing = observed(&[], &[], &[]);
        assert_eq!((steps_lost(&nothing), steps_repeated(&nothing)), (0, 0));
    }

    #[test]
    fn overlap_duplicates_of_the_output_are_neither_lost_nor_repeated_but_holes_are_lost() {
        let overlap = observed(&[4, 5, 5, 6, 6, 7], &[4, 5, 6, 7], &[&[4, 5, 6, 7]]);
        assert_eq!((steps_lost(&overlap), steps_repeated(&overlap)), (0, 0));
        assert_eq!(distinct(&overlap.output.ticks), 4);
        let hole = observed(&[4, 7, 5], &[4, 5, 6, 7], &[]);
        assert_eq!(steps_lost(&hole), 1);
    }

    #[test]
    fn a_consumer_that_handles_a_tick_twice_is_one_repeat() {
        // A localization swap: both estimators publish poses 11 and 12; mapping handles every
        // tick once, planning handles tick 11 twice (one command for each of the two poses).
        let swap = observed(
            &[10, 11, 11, 12, 12, 13],
            &[10, 11, 12, 13, 14],
            &[&[10, 11, 12, 13], &[10, 11, 11, 12, 13]],
        );
        assert_eq!(steps_repeated(&swap), 1);
        assert_eq!(steps_lost(&swap), 0);
        // A tick handled three times is two repeats.
        let thrice = observed(&[10, 11, 12], &[10, 11, 12], &[&[10, 11, 11, 11, 12]]);
        assert_eq!(steps_repeated(&thrice), 2);
    }

    /// `mole swap` follows the graph: a swappable role is accepted, the world and the monitor
    /// are refused naming why, a name that is no role is refused naming the swappable ones.
    #[test]
    fn swaps_are_refused_where_the_graph_says() {
        for row in GRAPH {
            match (row.swap, check_swappable(row.role.name())) {
                (Swap::Allowed, Ok((spec, topic))) => {
                    assert_eq!(spec.role, row.role);
                    assert_eq!(Some(topic), row.step_output);
                }
                (Swap::Refused(why), Err(SwapError::Refused(text))) => {
                    assert!(text.contains(why), "{text}")
                }
                (swap, result) => panic!("{}: {swap:?} but {result:?}", row.role),
            }
        }
        let Err(SwapError::Refused(text)) = check_swappable("navigator") else {
            panic!("an unknown role is refused");
        };
        assert!(
            text.contains("sensing, localization, mapping, planning"),
            "{text}"
        );
    }
}
