//! Every topic: its name and the message type it carries, bound together so that a typo or a
//! type mismatch does not compile. Service names are `mole/<namespace>/<topic>`.

use crate::messages::*;
use core::marker::PhantomData;

/// A topic: a name, the message type it carries, and what its service must hold.
pub struct Topic<M> {
    /// The name below the namespace, e.g. `sensing/scan`.
    pub name: &'static str,
    /// Samples a late subscriber receives on connecting (world/map: 1).
    pub history: usize,
    /// Samples a subscriber can queue before the oldest is dropped (realtime) or the publisher
    /// waits (lockstep).
    pub buffer: usize,
    /// Publishers the service admits (2 leaves room for a hot swap; stack/stats: every process).
    pub max_publishers: usize,
    /// Subscribers the service admits.
    pub max_subscribers: usize,
    /// Whether a full queue drops its oldest sample in lockstep too (a notice every process
    /// reads only now and then, which must never hold its publisher back).
    pub never_waits: bool,
    /// Policy: what the tools around the stack do with the topic.
    pub policy: Policy,
    _message: PhantomData<fn() -> M>,
}

/// What the tools around the stack do with a topic: columns of the topic table, so that a
/// topic's treatment is written where the topic is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Policy {
    /// The topic's name.
    pub name: &'static str,
    /// Bridge, realtime: large and superseded by the next step's, so a congested link may drop
    /// it to the newest (lockstep carries every sample of every topic).
    pub bulk: bool,
    /// Bridge: the loop waits for it, so it crosses ahead of everything else.
    pub urgent: bool,
    /// Recorder: written once every this many ticks by default (1: every sample; the recorder's
    /// `--every TOPIC=N` overrides).
    pub record_every: u64,
    /// View: drawn by the view, live and from a recording (a recording's other topics are not
    /// read for it).
    pub shown: bool,
}

impl<M> Clone for Topic<M> {
    fn clone(&self) -> Self {
        *self
    }
}
impl<M> Copy for Topic<M> {}

impl<M> core::fmt::Debug for Topic<M> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("Topic").field("name", &self.name).finish()
    }
}

impl<M> Topic<M> {
    /// A topic with the default service settings (history 0, buffer 16, 2 publishers, 16
    /// subscribers: the stack's own, a swap's replacement, a recorder and up to 8 observers
    /// such as `mole-observer`). The stack's topics are the constants below; tools (benchmarks)
    /// may define their own.
    pub const fn new(name: &'static str) -> Self {
        Self {
            name,
            history: 0,
            buffer: 16,
            max_publishers: 2,
            max_subscribers: 16,
            never_waits: false,
            policy: Policy {
                name,
                bulk: false,
                urgent: false,
                record_every: 1,
                shown: false,
            },
            _message: PhantomData,
        }
    }
    pub const fn history(mut self, history: usize) -> Self {
        self.history = history;
        self
    }
    pub const fn buffer(mut self, buffer: usize) -> Self {
        self.buffer = buffer;
        self
    }
    pub const fn max_publishers(mut self, n: usize) -> Self {
        self.max_publishers = n;
        self
    }
    pub const fn max_subscribers(mut self, n: usize) -> Self {
        self.max_subscribers = n;
        self
    }
    pub const fn never_waits(mut self) -> Self {
        self.never_waits = true;
        self
    }
    /// See [`Policy::bulk`].
    pub const fn bulk(mut self) -> Self {
        self.policy.bulk = true;
        self
    }
    /// See [`Policy::urgent`].
    pub const fn urgent(mut self) -> Self {
        self.policy.urgent = true;
        self
    }
    /// See [`Policy::shown`].
    pub const fn shown(mut self) -> Self {
        self.policy.shown = true;
        self
    }
    /// See [`Policy::record_every`].
    pub const fn record_every(mut self, ticks: u64) -> Self {
        self.policy.record_every = ticks;
        self
    }
}

/// Declares every topic once: its constant, its message type, its service settings and its
/// [`Policy`]. From this one table come the constants, [`all`] (name and type name, in table
/// order), [`policies`] and
/// [`for_each`], which hands every topic, typed, to a [`TopicVisitor`] (the layout table, the
/// Python classes, tools that treat topics generically).
macro_rules! topics {
    ($( $(#[$meta:meta])* $constant:ident: $message:ty = $topic:expr; )+) => {
        $( $(#[$meta])* pub const $constant: Topic<$message> = $topic; )+

        /// Every publish-subscribe topic with its message's type name, in table order.
        pub fn all() -> Vec<(&'static str, &'static str)> {
            vec![$(($constant.name, <$message as crate::Message>::wire_type_name())),+]
        }

        /// Every topic's policy, in table order.
        pub fn policies() -> [Policy; [$(stringify!($constant)),+].len()] {
            [$($constant.policy),+]
        }

        /// Hands every topic of the table, in order, to `visitor`.
        pub fn for_each(visitor: &mut impl TopicVisitor) {
            $( visitor.visit(stringify!($constant), $constant); )+
        }
    };
}

/// Something that handles every topic, whatever its message type (see [`for_each`]).
pub trait TopicVisitor {
    /// Called once per topic with its constant's name (`SENSING_SCAN`) and the topic.
    fn visit<M: crate::Message>(&mut self, constant: &'static str, topic: Topic<M>);
}

/// What a tool that treats topics generically opens on each topic it wants, typed by the
/// topic's message: a subscriber, a publisher, a bridge's port (see [`open_each`]).
pub trait OpenTopic {
    /// What opening one topic gives.
    type Port;
    /// Why a topic could not be opened.
    type Error;
    /// Opens `topic`.
    fn open<M: crate::Message>(&mut self, topic: Topic<M>) -> Result<Self::Port, Self::Error>;
}

/// Opens, with `opener`, every topic of the table whose name `wanted` accepts, in table order;
/// the first error ends it.
pub fn open_each<O: OpenTopic>(
    wanted: impl Fn(&str) -> bool,
    opener: &mut O,
) -> Result<Vec<O::Port>, O::Error> {
    struct Each<'o, O: OpenTopic, W> {
        opener: &'o mut O,
        wanted: W,
        ports: Vec<O::Port>,
        error: Option<O::Error>,
    }
    impl<O: OpenTopic, W: Fn(&str) -> bool> TopicVisitor for Each<'_, O, W> {
        fn visit<M: crate::Message>(&mut self, _constant: &'static str, topic: Topic<M>) {
            if self.error.is_none() && (self.wanted)(topic.name) {
                match self.opener.open(topic) {
                    Ok(port) => self.ports.push(port),
                    Err(e) => self.error = Some(e),
                }
            }
        }
    }
    let mut each = Each {
        opener,
        wanted,
        ports: Vec::new(),
        error: None,
    };
    for_each(&mut each);
    match each.error {
        Some(e) => Err(e),
        None => Ok(each.ports),
    }
}

// History 1 on the control loop's topics: a lockstep process restarted after a crash missed the
// step sent while it was down; its publisher hands it that step from history while it waits
// (`Context::offer_history`). History 2 on what mapping reads (pose, scan, tactile): mapping runs
// beside the loop, so when it dies the world may already be a step past the one it owes
// (planning needs only the grid of the step before), and a history of 1 no longer held that
// step's pose and scan for its restart, which then skipped it (the grid hash differed).
topics! {
    /// The arena, robot and sensor settings, once (history 1 for processes that join late).
    WORLD_MAP: WorldMap = Topic::new("world/map").history(1).buffer(2).shown();
    /// The true state after each step.
    WORLD_TRUTH: Truth = Topic::new("world/truth").history(1).buffer(64).shown();
    SENSING_SCAN: Scan = Topic::new("sensing/scan").history(2).bulk().shown();
    SENSING_TACTILE: Tactile = Topic::new("sensing/tactile").history(2);
    SENSING_ODOM: Odom = Topic::new("sensing/odom").history(1);
    SENSING_BEACONS: Beacons = Topic::new("sensing/beacons").history(1);
    SENSING_FIX: Fix = Topic::new("sensing/fix").history(1);
    LOCALIZATION_POSE: Pose = Topic::new("localization/pose").history(2).buffer(64).shown();
    LOCALIZATION_PARTICLES: Particles =
        Topic::new("localization/particles").buffer(2).bulk().shown();
    /// The SLAM estimators' beacon map.
    LOCALIZATION_LANDMARKS: Landmarks = Topic::new("localization/landmarks").buffer(4).shown();
    /// A smoother's optimised trajectory (GraphSLAM), after each finished solve.
    LOCALIZATION_TRAJECTORY: Trajectory = Topic::new("localization/trajectory").buffer(2).bulk();
    /// Recorded every 10 ticks by default: 0.1 s of simulated time at 100 Hz, what the
    /// monitor's coverage curve samples too; 1.7 MB of raw grid a second instead of 52 MB.
    MAPPING_GRID: Grid =
        Topic::new("mapping/grid").history(1).buffer(4).bulk().record_every(10).shown();
    MAPPING_CONTACT: Grid =
        Topic::new("mapping/contact").history(1).buffer(4).bulk().record_every(10).shown();
    PLANNING_CMD: Cmd = Topic::new("planning/cmd").history(1).urgent();
    PLANNING_STATUS: PlanStatus = Topic::new("planning/status").buffer(4).shown();
    STACK_TICK: Tick = Topic::new("stack/tick");
    STACK_STATS: Stats = Topic::new("stack/stats").buffer(64).max_publishers(32).shown();
    MONITOR_STATUS: RunStatus = Topic::new("monitor/status").history(1).buffer(4);
    STACK_PROCESSES: Processes = Topic::new("stack/processes").history(1).buffer(4).shown();
    /// Where an operator (the view, a script) sends a goal-seeking planner; history 1: a
    /// restarted planner picks up the current goal.
    OPERATOR_GOAL: Goal = Topic::new("operator/goal").history(1);
    /// An operator's pause, step or run of a lockstep world; history 1: a restarted world
    /// picks up the current pace.
    OPERATOR_PACE: Pace = Topic::new("operator/pace").history(1);
    /// The faults `mole fault` injected, from the launcher to every process (each one's runtime
    /// applies those aimed at the topics it publishes) and observer; the last 8 from history.
    STACK_FAULTS: crate::fault::Fault = Topic::new("stack/faults")
        .history(8)
        .buffer(16)
        .max_subscribers(64)
        .never_waits()
        .shown();
    /// Settings changed while the stack runs (`mole param set`): the launcher's requests and
    /// each process's outcome (applied at a step, or refused and why); the last 8 from history.
    STACK_PARAMS: crate::ParamChange = Topic::new("stack/params")
        .history(8)
        .buffer(16)
        .max_publishers(32)
        .max_subscribers(64)
        .never_waits()
        .shown();
}

/// The landmark map a robot offers to its peers (two robots, algorithms §6.9): its
/// `localization/landmarks`, on a topic of its own in its namespace whose queue keeps only the
/// newest map and never makes the robot wait for a reader. Between two stacks, so not in one
/// stack's table above (no recorder, bridge or view of a stack reads it).
pub const PEER_LANDMARKS: Topic<Landmarks> = Topic::new("peers/localization/landmarks").buffer(1);

/// The channel of a recording that holds what happened to the stack's processes (started,
/// exited, restarted, swapped, faults, settings changed), as the recorder writes it: not a
/// publish-subscribe topic (the recorder gathers it from `stack/processes`, `stack/faults` and
/// `stack/params`).
pub const STACK_EVENTS: &str = "stack/events";

/// A request-response service: its name and the types of its requests and responses.
pub struct RequestResponse<Req, Resp> {
    /// The name below the namespace, e.g. `stack/control`.
    pub name: &'static str,
    _types: PhantomData<fn() -> (Req, Resp)>,
}

impl<Req, Resp> Clone for RequestResponse<Req, Resp> {
    fn clone(&self) -> Self {
        *self
    }
}
impl<Req, Resp> Copy for RequestResponse<Req, Resp> {}

impl<Req, Resp> RequestResponse<Req, Resp> {
    pub const fn new(name: &'static str) -> Self {
        Self {
            name,
            _types: PhantomData,
        }
    }
}

/// The launcher's control service: swap a role, stop, status (`mole swap`, `mole stop`).
pub const STACK_CONTROL: RequestResponse<crate::ControlRequest, crate::ControlResponse> =
    RequestResponse::new("stack/control");

/// The full service name of a topic in a namespace.
pub fn service_name(namespace: &str, topic: &str) -> String {
    format!("mole/{namespace}/{topic}")
}

#[cfg(test)]
mod tests {
    use super::*;
    #[test]
    fn topic_names_are_unique() {
        let mut names: Vec<&str> = all().iter().map(|(n, _)| *n).collect();
        names.sort_unstable();
        names.dedup();
        assert_eq!(names.len(), all().len());
    }

    #[test]
    fn service_names_carry_the_namespace() {
        assert_eq!(
            service_name("robot0", SENSING_SCAN.name),
            "mole/robot0/sensing/scan"
        );
    }
}
