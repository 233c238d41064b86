//! The mapping process's settings: the `[mapping]` table of a launch file (docs/settings.md
//! lists every key).

use crate::LogOddsParams;
use mole_types::Setting;
use serde::{Deserialize, Serialize};

/// How touch and range readings become the grids.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, Setting)]
#[serde(default, deny_unknown_fields)]
pub struct Settings {
    /// A tactile reading above this force (N) is a touch (algorithms §2).
    #[setting(min = 0.0)]
    pub touch_threshold: f64,
    /// The frontier grid's inverse sensor models (algorithms §5.2).
    pub log_odds: LogOddsParams,
}

impl Default for Settings {
    fn default() -> Self {
        Self {
            touch_threshold: 0.5,
            log_odds: LogOddsParams::default(),
        }
    }
}
