//! The localization process's settings: the `[localization.…]` tables of a launch file
//! (docs/settings.md lists every key).

use crate::graph_slam::SolverConfig;
use crate::slam::{FastSlamConfig, SlamConfig};
use crate::{BayesConfig, PfConfig};
use mole_types::{Setting, WorldMap};
use serde::{Deserialize, Serialize};

/// Every tunable of every estimator, with its defaults.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize, Setting)]
#[serde(default, deny_unknown_fields)]
pub struct Settings {
    /// The sensor noise the estimators assume.
    pub noise: AssumedNoise,
    /// The histogram Bayes filter (algorithms §6.3).
    #[setting(fixed = "it shapes the filter when it is built")]
    pub bayes: BayesConfig,
    /// The particle filter (algorithms §6.7).
    #[setting(fixed = "it shapes the filter when it is built")]
    pub pf: PfConfig,
    /// What EKF-SLAM, FastSLAM and GraphSLAM's front-end do with a reading (algorithms §6.9.1).
    #[setting(fixed = "it shapes the filter when it is built")]
    pub slam: SlamConfig,
    /// FastSLAM's particles (algorithms §6.9.3).
    #[setting(fixed = "it shapes the filter when it is built")]
    pub fastslam: FastSlamConfig,
    /// GraphSLAM's Levenberg–Marquardt solver (algorithms §6.9.4).
    #[serde(rename = "graph-slam")]
    #[setting(fixed = "the smoother thread takes it when it starts")]
    pub graph_slam: SolverConfig,
}

/// The noise σ an estimator assumes; each one unset is what the world's sensor has, as the
/// scenario sets it (a filter tuned otherwise than its sensors shows what mistuning costs).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize, Setting)]
#[serde(default, deny_unknown_fields)]
pub struct AssumedNoise {
    /// Odometry σ on v (m/s).
    #[setting(above = 0.0)]
    #[serde(skip_serializing_if = "Option::is_none")]
    pub odom_v_std: Option<f64>,
    /// Odometry σ on ω (rad/s).
    #[setting(above = 0.0)]
    #[serde(skip_serializing_if = "Option::is_none")]
    pub odom_omega_std: Option<f64>,
    /// Beacon range σ (m).
    #[setting(above = 0.0)]
    #[serde(skip_serializing_if = "Option::is_none")]
    pub beacon_range_std: Option<f64>,
    /// Beacon bearing σ (rad).
    #[setting(above = 0.0)]
    #[serde(skip_serializing_if = "Option::is_none")]
    pub beacon_bearing_std: Option<f64>,
    /// Position-fix σ per coordinate (m).
    #[setting(above = 0.0)]
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fix_std: Option<f64>,
}

impl AssumedNoise {
    /// The world as the estimators take it: `map` with its sensors' σ replaced where these
    /// settings set them.
    pub fn assumed(&self, map: &WorldMap) -> Box<WorldMap> {
        let mut assumed = Box::new(*map);
        let s = &mut assumed.sensors;
        for (value, set) in [
            (&mut s.odom_v_std, self.odom_v_std),
            (&mut s.odom_omega_std, self.odom_omega_std),
            (&mut s.beacon_range_std, self.beacon_range_std),
            (&mut s.beacon_bearing_std, self.beacon_bearing_std),
            (&mut s.fix_std, self.fix_std),
        ] {
            if let Some(v) = set {
                *value = v;
            }
        }
        assumed
    }
}
