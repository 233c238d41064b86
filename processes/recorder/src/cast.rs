//! Who plays what in a replay: the roles the player stands in for, the topics it publishes in
//! their place, what it waits for in lockstep, and what `--check` compares.

use mole_types::Role;
use mole_types::graph::GRAPH;
use mole_types::kinds::UnknownChoice;
use std::time::Duration;

/// The roles a replay plays back unless told otherwise.
pub const DEFAULT_REPLACED: &str = "world,sensing";

/// The replaced roles and what follows from them.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Cast {
    /// The roles the player stands in for, in the graph's order.
    pub replaced: Vec<Role>,
}

impl Cast {
    /// `world,sensing` → the roles; an unknown name is refused naming it and every role.
    pub fn parse(list: &str) -> Result<Cast, UnknownChoice> {
        let mut replaced = Vec::new();
        for name in list.split(',').map(str::trim).filter(|n| !n.is_empty()) {
            let role: Role = name.parse()?;
            if !replaced.contains(&role) {
                replaced.push(role);
            }
        }
        replaced.sort_by_key(|r| r.code());
        Ok(Cast { replaced })
    }

    /// `world,sensing`.
    pub fn names(&self) -> String {
        let names: Vec<&str> = self.replaced.iter().map(|r| r.name()).collect();
        names.join(",")
    }

    /// Whether the player keeps the stack's time (the world is replaced).
    pub fn is_clock(&self) -> bool {
        self.replaced.contains(&Role::World)
    }

    /// The topics the player publishes, in the order a step publishes them: role by role along
    /// the graph, each role's outputs in its own order (sensing's odometry last, as sensing
    /// publishes it). Statistics are every process's own (the graph lists them as no role's
    /// output) and are not played.
    pub fn published(&self) -> Vec<&'static str> {
        self.replaced
            .iter()
            .flat_map(|r| r.spec().outputs.iter().copied())
            .collect()
    }

    /// Lockstep: what the live roles publish once they handled a step (the step outputs of the
    /// live roles in the loop); the player plays step k+1 once each has step k.
    pub fn awaited(&self) -> Vec<&'static str> {
        self.live()
            .filter(|spec| spec.in_loop)
            .filter_map(|spec| spec.step_output)
            .collect()
    }

    /// What `--check` compares: every output of the live roles in the loop. The monitor's
    /// status is left out: it is published on a wall-clock period and carries loop latencies.
    pub fn compared(&self) -> Vec<&'static str> {
        self.live()
            .filter(|spec| spec.in_loop)
            .flat_map(|spec| spec.outputs.iter().copied())
            .collect()
    }

    fn live(&self) -> impl Iterator<Item = &'static mole_types::graph::RoleSpec> + '_ {
        GRAPH
            .iter()
            .filter(|spec| !self.replaced.contains(&spec.role))
    }
}

/// Realtime: when, after the window's first sample, a sample recorded at `log_time` is played
/// at `rate` times the recorded speed.
pub fn pace(first_log_time: u64, log_time: u64, rate: f64) -> Duration {
    Duration::from_secs_f64(log_time.saturating_sub(first_log_time) as f64 / 1e9 / rate)
}

#[cfg(test)]
mod tests {
    use super::*;
    use mole_types::topics;

    /// By default the world and sensing are played: the player keeps the time, publishes the
    /// world's and sensing's outputs (odometry last), waits for the other loop roles and
    /// compares their outputs.
    #[test]
    fn world_and_sensing_are_played_by_default() {
        let cast = Cast::parse(DEFAULT_REPLACED).expect("roles");
        assert!(cast.is_clock());
        let published = cast.published();
        assert_eq!(published.first(), Some(&topics::WORLD_MAP.name));
        assert_eq!(published.last(), Some(&topics::SENSING_ODOM.name));
        assert_eq!(
            cast.awaited(),
            [
                topics::LOCALIZATION_POSE.name,
                topics::MAPPING_GRID.name,
                topics::PLANNING_CMD.name
            ]
        );
        let compared = cast.compared();
        assert!(compared.contains(&topics::MAPPING_CONTACT.name));
        assert!(!compared.contains(&topics::MONITOR_STATUS.name));
        assert!(!compared.contains(&topics::SENSING_SCAN.name));
    }

    /// A role the graph does not have is refused naming it and every role.
    #[test]
    fn an_unknown_role_is_refused_naming_it() {
        let refused = Cast::parse("world,sensors").expect_err("unknown");
        assert!(refused.to_string().contains("`sensors`"), "{refused}");
        assert!(refused.to_string().contains("localization"), "{refused}");
        let cast = Cast::parse("mapping, sensing,mapping").expect("roles");
        assert_eq!(cast.names(), "sensing,mapping");
        assert!(!cast.is_clock());
    }

    /// Twice the rate plays a recorded second in half a second.
    #[test]
    fn the_rate_scales_the_recorded_time() {
        assert_eq!(pace(1_000, 1_000_001_000, 2.0), Duration::from_millis(500));
        assert_eq!(pace(5, 0, 1.0), Duration::ZERO);
    }
}
