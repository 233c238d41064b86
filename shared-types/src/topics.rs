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
    _message: PhantomData<fn() -> M>,
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
    /// A topic with the default service settings (history 0, buffer 16, 2 publishers, 8
    /// subscribers). The stack's topics are the constants below; tools (benchmarks) may define
    /// their own.
    pub const fn new(name: &'static str) -> Self {
        Self {
            name,
            history: 0,
            buffer: 16,
            max_publishers: 2,
            max_subscribers: 8,
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
}

pub const WORLD_MAP: Topic<WorldMap> = Topic::new("world/map").history(1).buffer(2);
pub const WORLD_TRUTH: Topic<Truth> = Topic::new("world/truth").buffer(64);
pub const SENSING_SCAN: Topic<Scan> = Topic::new("sensing/scan");
pub const SENSING_TACTILE: Topic<Tactile> = Topic::new("sensing/tactile");
pub const SENSING_ODOM: Topic<Odom> = Topic::new("sensing/odom");
pub const SENSING_BEACONS: Topic<Beacons> = Topic::new("sensing/beacons");
pub const SENSING_FIX: Topic<Fix> = Topic::new("sensing/fix");
pub const LOCALIZATION_POSE: Topic<Pose> = Topic::new("localization/pose").buffer(64);
pub const LOCALIZATION_PARTICLES: Topic<Particles> = Topic::new("localization/particles").buffer(2);
pub const MAPPING_GRID: Topic<Grid> = Topic::new("mapping/grid").buffer(4);
pub const MAPPING_CONTACT: Topic<Grid> = Topic::new("mapping/contact").buffer(4);
pub const PLANNING_CMD: Topic<Cmd> = Topic::new("planning/cmd");
pub const PLANNING_STATUS: Topic<PlanStatus> = Topic::new("planning/status").buffer(4);
pub const STACK_TICK: Topic<Tick> = Topic::new("stack/tick");
pub const STACK_STATS: Topic<Stats> = Topic::new("stack/stats").buffer(64).max_publishers(32);
pub const MONITOR_STATUS: Topic<RunStatus> = Topic::new("monitor/status").history(1).buffer(4);
pub const STACK_PROCESSES: Topic<Processes> = Topic::new("stack/processes").history(1).buffer(4);

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

/// Every publish-subscribe topic with its message's type name, in table order.
pub const ALL: &[(&str, &str)] = &[
    (WORLD_MAP.name, "mole.WorldMap.v1"),
    (WORLD_TRUTH.name, "mole.Truth.v1"),
    (SENSING_SCAN.name, "mole.Scan.v1"),
    (SENSING_TACTILE.name, "mole.Tactile.v1"),
    (SENSING_ODOM.name, "mole.Odom.v1"),
    (SENSING_BEACONS.name, "mole.Beacons.v1"),
    (SENSING_FIX.name, "mole.Fix.v1"),
    (LOCALIZATION_POSE.name, "mole.Pose.v1"),
    (LOCALIZATION_PARTICLES.name, "mole.Particles.v1"),
    (MAPPING_GRID.name, "mole.Grid.v1"),
    (MAPPING_CONTACT.name, "mole.Grid.v1"),
    (PLANNING_CMD.name, "mole.Cmd.v1"),
    (PLANNING_STATUS.name, "mole.PlanStatus.v1"),
    (STACK_TICK.name, "mole.Tick.v1"),
    (STACK_STATS.name, "mole.Stats.v1"),
    (MONITOR_STATUS.name, "mole.RunStatus.v1"),
    (STACK_PROCESSES.name, "mole.Processes.v1"),
];

/// The full service name of a topic in a namespace.
pub fn service_name(namespace: &str, topic: &str) -> String {
    format!("mole/{namespace}/{topic}")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Message;

    fn type_name_of<M: Message>(_: Topic<M>) -> &'static str {
        M::TYPE_NAME
    }

    #[test]
    fn table_matches_the_topic_constants() {
        let from_types = [
            type_name_of(WORLD_MAP),
            type_name_of(WORLD_TRUTH),
            type_name_of(SENSING_SCAN),
            type_name_of(SENSING_TACTILE),
            type_name_of(SENSING_ODOM),
            type_name_of(SENSING_BEACONS),
            type_name_of(SENSING_FIX),
            type_name_of(LOCALIZATION_POSE),
            type_name_of(LOCALIZATION_PARTICLES),
            type_name_of(MAPPING_GRID),
            type_name_of(MAPPING_CONTACT),
            type_name_of(PLANNING_CMD),
            type_name_of(PLANNING_STATUS),
            type_name_of(STACK_TICK),
            type_name_of(STACK_STATS),
            type_name_of(MONITOR_STATUS),
            type_name_of(STACK_PROCESSES),
        ];
        let table: Vec<&str> = ALL.iter().map(|(_, t)| *t).collect();
        assert_eq!(table, from_types);
        let mut names: Vec<&str> = ALL.iter().map(|(n, _)| *n).collect();
        names.sort_unstable();
        names.dedup();
        assert_eq!(names.len(), ALL.len(), "topic names are unique");
    }

    #[test]
    fn service_names_carry_the_namespace() {
        assert_eq!(
            service_name("robot0", SENSING_SCAN.name),
            "mole/robot0/sensing/scan"
        );
    }
}
