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

        impl serde::Serialize for $name {
            fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
                serializer.serialize_str(self.name())
            }
        }

        impl<'de> serde::Deserialize<'de> for $name {
            fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
                let text = <std::borrow::Cow<'de, str>>::deserialize(deserializer)?;
                text.parse().map_err(serde::de::Error::custom)
            }
        }

        impl $crate::settings::Setting for $name {
            fn kind() -> String {
                format!("one of: {}", $name::NAMES.join(", "))
            }
            fn check_at(&self, _at: &str) -> Result<(), $crate::settings::SettingError> {
                Ok(())
            }
            fn keys_at(
                at: &str,
                about: $crate::settings::About,
                out: &mut Vec<$crate::settings::Key>,
            ) {
                out.push($crate::settings::Key::leaf::<Self>(at, about));
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

/// Every estimator, once: its variant, the name `--estimator` takes, its wire code (which
/// `localization/pose` carries), whether it estimates the beacon map itself (`SLAM`) or reads
/// the true one (`LOCALISER`), and the type in processes/localization that implements it. A new
/// estimator is its file there and one line here: `EstimatorKind` is made of this table below,
/// and mole-localization's registry (`build_estimator`) of the same table. Invoked with the name
/// of a macro that takes the rows.
#[macro_export]
macro_rules! estimators {
    ($then:ident) => {
        $then! {
            /// Histogram Bayes filter (algorithms §6.3).
            Bayes = ("bayes", 0, HistogramFilter, LOCALISER),
            /// Linear Kalman filter on the position fix (algorithms §6.5).
            Kf = ("kf", 1, Kf, LOCALISER),
            /// Extended Kalman filter on odometry, beacons and the fix (algorithms §6.6).
            Ekf = ("ekf", 2, Ekf, LOCALISER),
            /// Particle filter (algorithms §6.7).
            Pf = ("pf", 3, ParticleFilter, LOCALISER),
            /// EKF-SLAM: pose and beacon map in one state (algorithms §6.9.2).
            EkfSlam = ("ekf-slam", 4, EkfSlamEstimator, SLAM),
            /// FastSLAM 1.0: particles, each with its own landmark EKFs (algorithms §6.9.3).
            FastSlam = ("fastslam", 5, FastSlamEstimator, SLAM),
            /// GraphSLAM: a filter in front, a pose graph smoothed behind (algorithms §6.9.4).
            GraphSlam = ("graph-slam", 6, GraphSlamEstimator, SLAM),
        }
    };
}

macro_rules! estimator_kind {
    ($( $(#[$meta:meta])* $variant:ident = ($name:literal, $code:literal, $ty:ident, $class:ident) ),+ $(,)?) => {
        choice! {
            /// The pose estimators of algorithms §6, as `--estimator` names them
            /// ([`estimators!`]); `localization/pose` carries the code.
            pub enum EstimatorKind: "estimator" {
                $( $(#[$meta])* $variant = ($name, $code) ),+
            }
        }

        impl EstimatorKind {
            /// Whether it estimates the beacon map itself (and never reads the true one).
            pub const fn is_slam(self) -> bool {
                match self {
                    $( EstimatorKind::$variant => estimator_kind!(@slam $class) ),+
                }
            }
        }
    };
    (@slam SLAM) => { true };
    (@slam LOCALISER) => { false };
}

estimators!(estimator_kind);

/// What a planner needs of a world to run at all.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Needs {
    /// A goal to drive to (`--goal` or the scenario's).
    pub goal: bool,
    /// A range sensor: frontier cells are the edge between the free space a scan shows and the
    /// unknown (algorithms §5), so with no lidar there is never a frontier.
    pub range_sensor: bool,
}

impl Needs {
    pub const NOTHING: Needs = Needs {
        goal: false,
        range_sensor: false,
    };
    pub const GOAL: Needs = Needs {
        goal: true,
        range_sensor: false,
    };
    pub const RANGE_SENSOR: Needs = Needs {
        goal: false,
        range_sensor: true,
    };
}

/// Every planner, once: its variant, the name `--planner` takes, its code, what it needs of a
/// world, and the type in processes/planning that implements it. A new planner is its file
/// there and one line here: `PlannerKind` (with the CLI's choices and `mole up --help`) is made
/// of this table below, and mole-planning's registry (`build_planner`) of the same table.
/// Invoked with the name of a macro that takes the rows.
#[macro_export]
macro_rules! planners {
    ($then:ident) => {
        $then! {
            /// Random walk with bounce-back (algorithms §3, §4).
            RandomWalk = ("random-walk", 0, RandomWalk, NOTHING),
            /// Artificial potential field towards a goal (algorithms §1).
            Apf = ("apf", 1, Apf, GOAL),
            /// Dynamic window approach towards a goal (algorithms §4.2).
            Dwa = ("dwa", 2, Dwa, GOAL),
            /// Frontier exploration (algorithms §5).
            Frontier = ("frontier", 3, FrontierExplorer, RANGE_SENSOR),
        }
    };
}

macro_rules! planner_kind {
    ($( $(#[$meta:meta])* $variant:ident = ($name:literal, $code:literal, $ty:ident, $needs:ident) ),+ $(,)?) => {
        choice! {
            /// The planners, as `--planner` names them ([`planners!`]).
            pub enum PlannerKind: "planner" {
                $( $(#[$meta])* $variant = ($name, $code) ),+
            }
        }

        impl PlannerKind {
            /// What it needs of a world.
            pub const fn needs(self) -> Needs {
                match self {
                    $( PlannerKind::$variant => Needs::$needs ),+
                }
            }
        }
    };
}

planners!(planner_kind);

impl PlannerKind {
    /// Whether it drives to a goal, so a run needs one (`--goal` or the scenario's); these are
    /// the planners that can follow another's path (`--local-planner`).
    pub const fn needs_goal(self) -> bool {
        self.needs().goal
    }

    /// Whether it explores what the range sensor sees, so it would report an exploration it did
    /// not do without one.
    pub const fn needs_range_sensor(self) -> bool {
        self.needs().range_sensor
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
