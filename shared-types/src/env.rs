//! Every environment variable the launcher sets for its children and the processes read, in one
//! list. Processes take them as command-line flags too (`--namespace` for `MOLE_NAMESPACE`); the
//! launcher passes them as environment so a swapped-in process in any language sees the same.

/// An environment variable: its name and what it carries.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct EnvVar {
    pub name: &'static str,
    pub meaning: &'static str,
}

macro_rules! env_vars {
    ($( $constant:ident = $name:literal : $meaning:literal; )+) => {
        $( #[doc = $meaning] pub const $constant: &str = $name; )+
        /// Every variable, in the order the README lists them.
        pub const ALL: &[EnvVar] = &[$(EnvVar { name: $name, meaning: $meaning }),+];
    };
}

env_vars! {
    NAMESPACE = "MOLE_NAMESPACE": "the stack's namespace: services are `mole/<namespace>/<topic>`";
    MODE = "MOLE_MODE": "the clock mode, `realtime` or `lockstep`";
    RATE_HZ = "MOLE_RATE_HZ": "world steps per second in realtime";
    SEED = "MOLE_SEED": "the seed of every random stream (the scenario's otherwise)";
    SCENARIO = "MOLE_SCENARIO": "the scenario file (world)";
    TICKS = "MOLE_TICKS": "steps before the run ends (world)";
    PAUSED = "MOLE_PAUSED": "lockstep: hold after step 0 until an operator paces the run (world)";
    PLANNER = "MOLE_PLANNER": "the planner (planning, monitor)";
    LOCAL_PLANNER = "MOLE_LOCAL_PLANNER": "the local planner that follows frontier paths (planning)";
    GOAL = "MOLE_GOAL": "a goal `X,Y` in metres that overrides the scenario's (planning)";
    ESTIMATOR = "MOLE_ESTIMATOR": "the estimator (localization, monitor)";
    SETTINGS = "MOLE_SETTINGS": "the role's settings as JSON, from its `[ROLE.…]` tables and `--set` (planning, localization, mapping; docs/settings.md)";
    OUT = "MOLE_OUT": "the run's output directory: summary.json and map.png (monitor), where the bridge listens (bridge)";
    TAKEOVER = "MOLE_TAKEOVER": "start from the last output of the process this one replaces (a swap)";
    RESUME = "MOLE_RESUME": "a directory with the last outputs of the process this one restarts after a crash (set by the launcher)";
}

/// The namespace of a stack started without `--namespace` (or `MOLE_NAMESPACE`), and the one
/// every tool joins by default.
pub const DEFAULT_NAMESPACE: &str = "robot0";

#[cfg(test)]
mod tests {
    #[test]
    fn names_are_unique_and_prefixed() {
        let mut names: Vec<&str> = super::ALL.iter().map(|v| v.name).collect();
        assert!(names.iter().all(|n| n.starts_with("MOLE_")));
        names.sort_unstable();
        names.dedup();
        assert_eq!(names.len(), super::ALL.len());
    }
}
