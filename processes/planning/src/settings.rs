//! The planning process's settings: the `[planning.…]` tables of a launch file, one per
//! algorithm (docs/settings.md lists every key).

use crate::{ApfConfig, BounceBackConfig, DwaConfig, FrontierConfig, RandomWalkConfig};
use mole_types::{PlannerKind, Setting};
use serde::{Deserialize, Serialize};

/// Every tunable of every planner, with its defaults.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, Setting)]
#[serde(default, deny_unknown_fields)]
#[setting(check = Settings::check_replanner)]
pub struct Settings {
    /// The random walk (algorithms §3).
    #[serde(rename = "random-walk")]
    pub random_walk: RandomWalkConfig,
    /// The artificial potential field (algorithms §1).
    pub apf: ApfConfig,
    /// The dynamic window approach (algorithms §4.2).
    pub dwa: DwaConfig,
    /// Frontier exploration (algorithms §5).
    pub frontier: FrontierConfig,
    /// The reactive layer under every planner (algorithms §4).
    #[serde(rename = "bounce-back")]
    pub bounce_back: BounceBackConfig,
    /// After a bounce-back, this goal-seeking planner drives for `replan_time` before the
    /// planner itself plans again (algorithms §4, "path re-planning: APF or DWA"). Unset: the
    /// planner itself.
    #[serde(skip_serializing_if = "Option::is_none")]
    #[setting(fixed = "the planner it names is built at start")]
    pub replan_with: Option<PlannerKind>,
    /// How long (s) `replan_with` drives after a bounce.
    #[setting(min = 0.0)]
    pub replan_time: f64,
}

impl Default for Settings {
    fn default() -> Self {
        Self {
            random_walk: RandomWalkConfig::default(),
            apf: ApfConfig::default(),
            dwa: DwaConfig::default(),
            frontier: FrontierConfig::default(),
            bounce_back: BounceBackConfig::default(),
            replan_with: None,
            replan_time: 5.0,
        }
    }
}

impl Settings {
    /// Whether `replan_with` names a planner that can drive to a goal; the error says which can.
    pub fn check_replanner(&self) -> Result<(), mole_types::settings::SettingError> {
        match self.replan_with {
            Some(p) if !p.needs_goal() => Err(mole_types::settings::SettingError::new(
                "replan_with",
                &format!(
                    "a planner that drives to a goal: {}",
                    goal_seekers().join(", ")
                ),
                &p.name(),
            )),
            _ => Ok(()),
        }
    }
}

/// The planners that drive to a goal: those that can follow another's path.
pub fn goal_seekers() -> Vec<&'static str> {
    PlannerKind::ALL
        .iter()
        .filter(|p| p.needs_goal())
        .map(|p| p.name())
        .collect()
}
