//! The stack's closed sets of choices, each declared once: its variants, the name a user types
//! (`--estimator ekf`), and where it travels on the wire, the code it is written as.
//!
//! Codes are decoded into these enums at the edge (`from_code`), and validation bounds follow
//! from them (`from_code(c).is_some()`), so a new estimator or end reason is one line here.

use core::fmt;
use core::str::FromStr;

/// A name that is none of a choice's names; the message lists the valid ones.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct UnknownChoice {
    /// What is being chosen, e.g. `estimator`.
    pub what: &'static str,
    /// What was asked for.
    pub found: String,
    /// Every valid name.
    pub expected: &'static [&'static str],
}

impl fmt::Display for UnknownChoice {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "unknown {} `{}`, expected one of: {}",
            self.what,
            self.found,
            self.expected.join(", ")
        )
    }
}

impl std::error::Error for UnknownChoice {}

/// Declares an enum whose variants have a user-facing name and a wire code, with `ALL`,
/// `NAMES`, `name`, `code`, `from_code`, `Display` and a `FromStr` that names the choices.
macro_rules! choice {
    (
        $(#[$meta:meta])*
        $vis:vis enum $name:ident: $what:literal {
            $( $(#[$vmeta:meta])* $variant:ident = ($text:literal, $code:literal) ),+ $(,)?
        }
    ) => {
        $(#[$meta])*
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
        $vis enum $name {
            $( $(#[$vmeta])* $variant ),+
        }

        impl $name {
            /// Every variant, in declaration order.
            pub const ALL: &'static [$name] = &[$($name::$variant),+];
            /// Every name, in declaration order.
            pub const NAMES: &'static [&'static str] = &[$($text),+];

            /// The name a user types and a summary shows.
            pub const fn name(self) -> &'static str {
                match self { $($name::$variant => $text),+ }
            }

            /// The code this is written as in a message.
            pub const fn code(self) -> u32 {
                match self { $($name::$variant => $code),+ }
            }

            /// The variant a message's code stands for, if this version knows it.
            pub const fn from_code(code: u32) -> Option<$name> {
                match code { $($code => Some($name::$variant),)+ _ => None }
            }
        }

        impl fmt::Display for $name {
            fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.write_str(self.name())
            }
        }

        impl FromStr for $name {
            type Err = UnknownChoice;
            fn from_str(s: &str) -> Result<Self, Self::Err> {
                let wanted = s.trim();
                $name::ALL
                    .iter()
                    .copied()
                    .find(|v| v.name().eq_ignore_ascii_case(wanted))
                    .ok_or_else(|| UnknownChoice {
                        what: $what,
                        found: s.to_owned(),
                        expected: $name::NAMES,
                    })
            }
        }
    };
}

choice! {
    /// How the stack keeps time (docs/architecture.md, "Clock modes"); `stack/tick` carries it.
    #[derive(Default)]
    pub enum ClockMode: "clock mode" {
        /// The world steps at a fixed rate; every process reacts to its newest input.
        #[default]
        Realtime = ("realtime", 0),
        /// The world steps k only after the command for k−1 arrived; every process handles
        /// step k once all its inputs for k are in. Deterministic, as fast as the machine goes.
        Lockstep = ("lockstep", 1),
    }
}

choice! {
    /// The pose estimators of algorithms §6, as `--estimator` names them; `localization/pose`
    /// carries the code.
    pub enum EstimatorKind: "estimator" {
        /// Histogram Bayes filter (algorithms §6.3).
        Bayes = ("bayes", 0),
        /// Linear Kalman filter on the position fix (algorithms §6.5).
        Kf = ("kf", 1),
        /// Extended Kalman filter on odometry, beacons and the fix (algorithms §6.6).
        Ekf = ("ekf", 2),
        /// Particle filter (algorithms §6.7).
        Pf = ("pf", 3),
        /// EKF-SLAM: pose and beacon map in one state (algorithms §6.9).
        EkfSlam = ("ekf-slam", 4),
        /// FastSLAM 1.0: particles, each with its own landmark EKFs (algorithms §6.9).
        FastSlam = ("fastslam", 5),
        /// GraphSLAM: a filter in front, a pose graph smoothed behind (algorithms §6.9).
        GraphSlam = ("graph-slam", 6),
    }
}

impl EstimatorKind {
    /// Whether it estimates the beacon map itself (and never reads the true one).
    pub const fn is_slam(self) -> bool {
        matches!(
            self,
            EstimatorKind::EkfSlam | EstimatorKind::FastSlam | EstimatorKind::GraphSlam
        )
    }
}

choice! {
    /// The planners of algorithms §1, §3–§5, as `--planner` names them.
    pub enum PlannerKind: "planner" {
        /// Random walk with bounce-back (algorithms §1, §4).
        RandomWalk = ("random-walk", 0),
        /// Artificial potential field towards a goal (algorithms §3).
        Apf = ("apf", 1),
        /// Dynamic window approach towards a goal (algorithms §5.3).
        Dwa = ("dwa", 2),
        /// Frontier exploration (algorithms §5).
        Frontier = ("frontier", 3),
    }
}

impl PlannerKind {
    /// Whether it drives to a goal, so a run needs one (`--goal` or the scenario's).
    pub const fn needs_goal(self) -> bool {
        matches!(self, PlannerKind::Apf | PlannerKind::Dwa)
    }

    /// Whether it explores what the range sensor sees: frontier cells are the edge between the
    /// free space a scan shows and the unknown (algorithms §5), so with no lidar there is never
    /// a frontier and it would report an exploration it did not do.
    pub const fn needs_range_sensor(self) -> bool {
        matches!(self, PlannerKind::Frontier)
    }

    /// Why this planner cannot run with these sensors (`None`: it can), in one sentence for a
    /// world named `world`.
    pub fn refuses_sensors(self, sensors: &crate::SensorSpec, world: &str) -> Option<String> {
        (self.needs_range_sensor() && sensors.lidar_beams == 0).then(|| {
            format!(
                "--planner {self} explores the frontier of what the lidar sees, but `{world}` has \
                 no lidar ([sensors.lidar] beams = 0): explore it by touch with --planner {}",
                PlannerKind::RandomWalk
            )
        })
    }
}

choice! {
    /// Why a run ended; the world's final `world/truth` carries the code (0 while running).
    pub enum EndReason: "end reason" {
        /// The tick limit (`--ticks`, `--duration`) was reached.
        Ticks = ("ticks", 1),
        /// The robot reached the goal.
        GoalReached = ("goal_reached", 2),
        /// The stack was stopped (Ctrl-C, `mole stop`).
        Stopped = ("stopped", 3),
        /// The planner found nothing left worth exploring (algorithms §5).
        ExplorationComplete = ("exploration_complete", 4),
    }
}

impl EndReason {
    /// The end a planner asks for with its command's mode: at its goal (`MODE_ARRIVED`) or
    /// nothing left to explore (`MODE_DONE`); `None` while it goes on.
    pub const fn asked_by_planner(mode: u32) -> Option<EndReason> {
        match mode {
            crate::MODE_ARRIVED => Some(EndReason::GoalReached),
            crate::MODE_DONE => Some(EndReason::ExplorationComplete),
            _ => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_and_codes_round_trip_for_every_choice() {
        for &k in EstimatorKind::ALL {
            assert_eq!(k.name().parse::<EstimatorKind>(), Ok(k));
            assert_eq!(EstimatorKind::from_code(k.code()), Some(k));
        }
        for &k in PlannerKind::ALL {
            assert_eq!(k.name().parse::<PlannerKind>(), Ok(k));
            assert_eq!(PlannerKind::from_code(k.code()), Some(k));
        }
        for &k in EndReason::ALL {
            assert_eq!(EndReason::from_code(k.code()), Some(k));
        }
        assert_eq!(" Lockstep ".parse::<ClockMode>(), Ok(ClockMode::Lockstep));
        assert_eq!(ClockMode::from_code(7), None);
        assert_eq!(EndReason::from_code(0), None, "0 means the run goes on");
    }

    #[test]
    fn an_unknown_name_is_refused_naming_every_choice() {
        let e = "teleport".parse::<PlannerKind>().unwrap_err();
        assert_eq!(
            e.to_string(),
            "unknown planner `teleport`, expected one of: random-walk, apf, dwa, frontier"
        );
        let e = "oracle".parse::<EstimatorKind>().unwrap_err();
        assert!(
            e.to_string().contains("bayes, kf, ekf, pf, ekf-slam"),
            "{e}"
        );
    }
}
