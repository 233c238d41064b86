//! The stack's graph, once: every role, the program that plays it, the topics it reads and
//! writes, whether `mole swap` may replace it, what it resumes from after a swap or a restart,
//! whether it is in the control loop, and when it stops. The launcher, `mole swap`, `mole top`,
//! the integration tests and the process table of docs/architecture.md all follow [`GRAPH`].

use crate::kinds::UnknownChoice;
use crate::topics::*;
use core::fmt;
use core::str::FromStr;

choice! {
    /// A role of the stack: one process each. The code is the role's row in [`GRAPH`].
    pub enum Role: "role" {
        /// The simulation: steps the robot on each command, publishes the truth.
        World = ("world", 0),
        /// Turns the truth into noisy readings.
        Sensing = ("sensing", 1),
        /// Estimates the pose from odometry and corrections.
        Localization = ("localization", 2),
        /// Builds the frontier and contact grids.
        Mapping = ("mapping", 3),
        /// Decides the command.
        Planning = ("planning", 4),
        /// Measures the run against the truth; writes summary.json and map.png.
        Monitor = ("monitor", 5),
    }
}

/// The node names of the stack's processes that are not roles of the graph: they take no part
/// in a step, but logs, statistics, `mole top` and the launcher name them.
pub mod nodes {
    /// `mole up` itself.
    pub const LAUNCHER: &str = "launcher";
    /// `mole top`: it does not count as a stack in the namespace.
    pub const TOP: &str = "top";
    /// `mole-recorder`, started by `mole up --record` or `mole record`.
    pub const RECORDER: &str = "recorder";
    /// `mole-player`, in the place of the roles `mole replay` plays back.
    pub const PLAYER: &str = "player";
    /// `mole-view`, started by `mole up --view` or `mole view`.
    pub const VIEW: &str = "view";
    /// `mole-bridge`: one in each half of a split stack.
    pub const BRIDGE: &str = "bridge";
    /// `mole-foxglove`, started by `mole up --foxglove` or `mole foxglove`.
    pub const FOXGLOVE: &str = "foxglove";
}

/// Whether `mole swap` may replace a role while the stack runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Swap {
    /// A new process may take the role over (make before break).
    Allowed,
    /// Refused, and why.
    Refused(&'static str),
}

/// What a role's replacement (a swap, or a restart after a crash) starts from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Resume {
    /// The last message its predecessor published on each of these topics.
    From(&'static [&'static str]),
    /// Nothing, and why nothing is lost.
    Fresh(&'static str),
}

/// One row of the graph.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RoleSpec {
    pub role: Role,
    /// The program that plays the role (found next to `mole`, then on PATH).
    pub program: &'static str,
    /// The topics it reads (besides `stack/stats`, which only the monitor reads).
    pub inputs: &'static [&'static str],
    /// The topics it writes (besides `stack/stats`, which every process writes), in the order a
    /// step publishes them: a process woken by one finds those before it already in (each
    /// role's harness test in its `main.rs` checks the order).
    pub outputs: &'static [&'static str],
    /// The output that shows it at work: one message per handled step.
    pub step_output: Option<&'static str>,
    pub swap: Swap,
    pub resume: Resume,
    /// Whether a step waits for it: truth → readings → pose → command → the next step.
    pub in_loop: bool,
    /// When it stops at the end of a run: 0 first. The world first, so nothing new is
    /// produced; the monitor last, so it still sees the final truth and writes its files.
    pub stop_rank: u8,
}

/// Every role of the stack, in the row order of [`Role`]'s codes.
pub const GRAPH: &[RoleSpec] = &[
    RoleSpec {
        role: Role::World,
        program: "mole-world",
        inputs: &[PLANNING_CMD.name, OPERATOR_PACE.name],
        outputs: &[WORLD_MAP.name, WORLD_TRUTH.name, STACK_TICK.name],
        step_output: Some(WORLD_TRUTH.name),
        swap: Swap::Refused("its state is the run: a new world would start another one"),
        resume: Resume::From(&[WORLD_TRUTH.name]),
        in_loop: true,
        stop_rank: 0,
    },
    RoleSpec {
        role: Role::Sensing,
        program: "mole-sensing",
        inputs: &[WORLD_MAP.name, WORLD_TRUTH.name],
        outputs: &[
            SENSING_FIX.name,
            SENSING_BEACONS.name,
            SENSING_TACTILE.name,
            SENSING_SCAN.name,
            SENSING_ODOM.name,
        ],
        step_output: Some(SENSING_SCAN.name),
        swap: Swap::Allowed,
        resume: Resume::From(&[SENSING_ODOM.name]),
        in_loop: true,
        stop_rank: 4,
    },
    RoleSpec {
        role: Role::Localization,
        program: "mole-localization",
        inputs: &[
            WORLD_MAP.name,
            SENSING_ODOM.name,
            SENSING_BEACONS.name,
            SENSING_FIX.name,
            SENSING_TACTILE.name,
        ],
        outputs: &[
            LOCALIZATION_POSE.name,
            LOCALIZATION_PARTICLES.name,
            LOCALIZATION_LANDMARKS.name,
            LOCALIZATION_TRAJECTORY.name,
        ],
        step_output: Some(LOCALIZATION_POSE.name),
        swap: Swap::Allowed,
        resume: Resume::From(&[LOCALIZATION_POSE.name, LOCALIZATION_LANDMARKS.name]),
        in_loop: true,
        stop_rank: 3,
    },
    RoleSpec {
        role: Role::Mapping,
        program: "mole-mapping",
        inputs: &[
            WORLD_MAP.name,
            LOCALIZATION_POSE.name,
            SENSING_SCAN.name,
            SENSING_TACTILE.name,
        ],
        outputs: &[MAPPING_CONTACT.name, MAPPING_GRID.name],
        step_output: Some(MAPPING_GRID.name),
        swap: Swap::Allowed,
        resume: Resume::From(&[MAPPING_GRID.name, MAPPING_CONTACT.name]),
        in_loop: true,
        stop_rank: 2,
    },
    RoleSpec {
        role: Role::Planning,
        program: "mole-planning",
        inputs: &[
            WORLD_MAP.name,
            LOCALIZATION_POSE.name,
            SENSING_SCAN.name,
            SENSING_TACTILE.name,
            MAPPING_GRID.name,
            OPERATOR_GOAL.name,
        ],
        outputs: &[PLANNING_CMD.name, PLANNING_STATUS.name],
        step_output: Some(PLANNING_CMD.name),
        swap: Swap::Allowed,
        resume: Resume::Fresh("it plans each step anew from the newest pose and grid"),
        in_loop: true,
        stop_rank: 1,
    },
    RoleSpec {
        role: Role::Monitor,
        program: "mole-monitor",
        inputs: &[
            WORLD_MAP.name,
            WORLD_TRUTH.name,
            LOCALIZATION_POSE.name,
            LOCALIZATION_PARTICLES.name,
            LOCALIZATION_LANDMARKS.name,
            LOCALIZATION_TRAJECTORY.name,
            MAPPING_GRID.name,
            MAPPING_CONTACT.name,
            PLANNING_STATUS.name,
            STACK_STATS.name,
        ],
        outputs: &[MONITOR_STATUS.name],
        step_output: None,
        swap: Swap::Refused("its metrics cover the whole run: a new monitor would miss its start"),
        resume: Resume::Fresh("its metrics are the run's outcome, not an input of any role"),
        in_loop: false,
        stop_rank: 5,
    },
];

impl Role {
    /// This role's row of [`GRAPH`].
    pub fn spec(self) -> &'static RoleSpec {
        &GRAPH[self.code() as usize]
    }
}

impl RoleSpec {
    /// The topics a role's replacement watches for its predecessor's last output.
    pub fn resumes_from(&self) -> &'static [&'static str] {
        match self.resume {
            Resume::From(topics) => topics,
            Resume::Fresh(_) => &[],
        }
    }
}

/// The row of a role by name; `None` for a name the graph does not have.
pub fn spec(role: &str) -> Option<&'static RoleSpec> {
    role.parse::<Role>().ok().map(Role::spec)
}

/// The roles in the order they stop: [`RoleSpec::stop_rank`] ascending.
pub fn stop_order() -> Vec<Role> {
    let mut rows: Vec<&RoleSpec> = GRAPH.iter().collect();
    rows.sort_by_key(|r| r.stop_rank);
    rows.into_iter().map(|r| r.role).collect()
}

/// What the in-loop roles that read `role`'s outputs publish once per handled step, the world's
/// truth aside (a swap watches it anyway). A tick twice on one of these during a swap of `role`
/// is a step a consumer handled twice.
pub fn consumer_outputs(role: Role) -> Vec<&'static str> {
    let outputs = role.spec().outputs;
    GRAPH
        .iter()
        .filter(|c| c.role != role && c.in_loop)
        .filter(|c| c.inputs.iter().any(|t| outputs.contains(t)))
        .filter_map(|c| c.step_output)
        .filter(|t| *t != WORLD_TRUTH.name)
        .collect()
}

/// The process table of docs/architecture.md, generated from [`GRAPH`].
pub fn markdown() -> String {
    let mut text = String::from(
        "| process | in | out | `mole swap` | resumes from | in the loop | stops |\n\
         | --- | --- | --- | --- | --- | --- | --- |\n",
    );
    for r in GRAPH {
        let swap = match r.swap {
            Swap::Allowed => "yes".to_owned(),
            Swap::Refused(why) => format!("no: {why}"),
        };
        let resume = match r.resume {
            Resume::From(topics) => topics.join(", "),
            Resume::Fresh(why) => format!("nothing: {why}"),
        };
        let in_loop = if r.in_loop { "yes" } else { "no" };
        text.push_str(&format!(
            "| {} (`{}`) | {} | {} | {swap} | {resume} | {in_loop} | {} |\n",
            r.role,
            r.program,
            r.inputs.join(", "),
            r.outputs.join(", "),
            ordinal(r.stop_rank),
        ));
    }
    text.push_str(&format!(
        "| every process | | {}, once a second | | | | |\n",
        STACK_STATS.name
    ));
    text
}

/// The stop position as the table shows it: 1 for the first to stop.
fn ordinal(rank: u8) -> String {
    let position = usize::from(rank) + 1;
    match position {
        1 => "1 (first)".to_owned(),
        p if p == GRAPH.len() => format!("{p} (last)"),
        p => p.to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Each row sits at its role's code, so `Role::spec` finds it.
    #[test]
    fn every_role_has_its_row() {
        assert_eq!(GRAPH.len(), Role::ALL.len());
        for &role in Role::ALL {
            assert_eq!(role.spec().role, role);
        }
    }

    /// Every topic the graph names is a topic of the table, and every topic but the launcher's
    /// and the operator's has one writer among the roles.
    #[test]
    fn every_topic_named_is_a_topic_and_has_its_writer() {
        let known: Vec<&str> = all().iter().map(|(n, _)| *n).collect();
        for r in GRAPH {
            let named = r.inputs.iter().chain(r.outputs).chain(r.resumes_from());
            for topic in named.chain(r.step_output.iter()) {
                assert!(known.contains(topic), "{}: `{topic}`", r.role);
            }
            for topic in r.resumes_from().iter().chain(r.step_output.iter()) {
                assert!(
                    r.outputs.contains(topic),
                    "{}: `{topic}` is not its",
                    r.role
                );
            }
        }
        for topic in known {
            let writers = GRAPH.iter().filter(|r| r.outputs.contains(&topic)).count();
            let outside = [
                STACK_STATS.name,
                STACK_PROCESSES.name,
                STACK_FAULTS.name,
                STACK_PARAMS.name,
                OPERATOR_GOAL.name,
                OPERATOR_PACE.name,
            ];
            assert_eq!(writers, usize::from(!outside.contains(&topic)), "{topic}");
        }
    }

    /// The stop ranks order every role once: the world first, the monitor last.
    #[test]
    fn stop_order_is_world_first_monitor_last() {
        let order = stop_order();
        assert_eq!(order.len(), GRAPH.len());
        let mut ranks: Vec<u8> = GRAPH.iter().map(|r| r.stop_rank).collect();
        ranks.sort_unstable();
        assert!(ranks.iter().enumerate().all(|(i, r)| usize::from(*r) == i));
        assert_eq!(order.first(), Some(&Role::World));
        assert_eq!(order.last(), Some(&Role::Monitor));
    }

    /// A swap of sensing is watched on every in-loop reader's step output; one of planning on
    /// none (the world, its reader, shows up in the truth).
    #[test]
    fn consumer_outputs_follow_the_readers_of_a_role() {
        assert_eq!(
            consumer_outputs(Role::Sensing),
            [LOCALIZATION_POSE.name, MAPPING_GRID.name, PLANNING_CMD.name]
        );
        assert_eq!(
            consumer_outputs(Role::Localization),
            [MAPPING_GRID.name, PLANNING_CMD.name]
        );
        assert_eq!(consumer_outputs(Role::Mapping), [PLANNING_CMD.name]);
        assert!(consumer_outputs(Role::Planning).is_empty());
    }

    /// Only a swappable role may be swapped, and each has a step output to watch the swap on.
    #[test]
    fn swappable_roles_have_a_step_output() {
        for r in GRAPH {
            if r.swap == Swap::Allowed {
                assert!(r.step_output.is_some(), "{}", r.role);
            }
        }
        assert!(matches!(Role::World.spec().swap, Swap::Refused(_)));
        assert!(matches!(Role::Monitor.spec().swap, Swap::Refused(_)));
    }

    /// A name that is no role is refused naming every role.
    #[test]
    fn an_unknown_role_names_every_role() {
        let e = "navigator".parse::<Role>().unwrap_err();
        assert_eq!(
            e.to_string(),
            "unknown role `navigator`, expected one of: world, sensing, localization, mapping, \
             planning, monitor"
        );
        assert!(spec("navigator").is_none());
    }

    /// docs/architecture.md's process table is this graph's (`MOLE_BLESS=1` rewrites it).
    #[test]
    fn docs_process_table_matches_the_graph() {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../docs/architecture.md");
        let table = |doc: &str| {
            let start = doc.find("| process |")?;
            let end = doc[start..]
                .find("\n\n")
                .map_or(doc.len(), |n| start + n + 1);
            Some(start..end)
        };
        crate::golden::check(
            path.as_ref(),
            &markdown(),
            table,
            "cargo test -p mole-types graph",
        );
    }
}
