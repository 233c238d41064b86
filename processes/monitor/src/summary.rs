//! summary.json: the run's outcome in one file (the fields README.md lists, which users and
//! tests rely on), with a fixed field order so two runs diff cleanly. One schema for its three
//! users: the monitor writes it, the launcher reads it, fills its own part (restarts, hangs,
//! swaps, why the run ended, its wall time) and writes it back, the tests read it.

use crate::MonitorError;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::Path;

/// What the launcher knows and the monitor cannot see.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RunMeta {
    pub planner: String,
    pub estimator: String,
    /// `realtime` or `lockstep`.
    pub mode: String,
    pub seed: u64,
    pub wall_time_s: f64,
    pub exit_reason: String,
    /// Restarts per process role.
    pub restarts: BTreeMap<String, u32>,
}

/// Loop latency over the run (µs); `null` when no command latency was seen.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct LatencyUs {
    pub p50: Option<f64>,
    pub p99: Option<f64>,
    pub max: Option<f64>,
    /// The distribution: `[upper bound (µs), count]` per doubling bucket from 1 µs.
    #[serde(default)]
    pub histogram: Vec<[f64; 2]>,
}

/// Estimator update time per step (µs); `null` when no pose was seen.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct UpdateUs {
    pub p50: Option<f64>,
    pub p99: Option<f64>,
}

/// One topic over every process's ports.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct TopicSummary {
    /// The highest subscriber-side rate any process reported (the publisher rate when no
    /// subscriber reported the topic).
    pub rate_hz: f64,
    /// Lost messages summed over every port of every process.
    pub dropped: u64,
    /// Messages refused by `validate()`, summed over every port of every process.
    pub invalid: u64,
}

/// The content of summary.json, fields in the order they are written.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Summary {
    /// Steps simulated (the last truth's tick).
    pub ticks: u64,
    /// `ticks · dt`.
    pub sim_time_s: f64,
    pub wall_time_s: f64,
    pub planner: String,
    pub estimator: String,
    pub mode: String,
    pub seed: u64,
    pub goal_reached: bool,
    /// Tick of the first truth within the goal tolerance, times dt.
    pub time_to_goal_s: Option<f64>,
    /// Length of the true trajectory (every step, not the decimated one).
    pub path_length_m: f64,
    /// Fraction of the reachable free cells the final frontier grid marks explored.
    pub coverage: f64,
    /// Contact cells within one cell of a truly occupied cell, over all contact cells.
    pub contact_map_precision: Option<f64>,
    /// IoU of occupied cells over the explored cells (see `Monitor::map_iou`).
    pub map_iou: Option<f64>,
    /// √(mean squared position error) of the pose estimate against the truth of the same tick.
    pub localization_rmse_m: Option<f64>,
    pub max_penetration_m: f64,
    pub loop_latency_us: LatencyUs,
    pub topics: BTreeMap<String, TopicSummary>,
    pub restarts: BTreeMap<String, u32>,
    pub exit_reason: String,
    /// Mean normalised estimation error squared over (x, y, θ); 3 for a consistent filter.
    pub mean_nees: Option<f64>,
    pub estimator_update_us: UpdateUs,
    pub bounces: u32,
    /// Frontier targets given up so far: not approached in time or unreachable (the last
    /// `PlanStatus::give_ups`).
    #[serde(default)]
    pub give_ups: u32,
    /// Times the planner reported a stall in a local minimum.
    pub stalls: u32,
    /// The longest stretch without progress (no new explored area, no approach of 0.25 m to the
    /// planner's target) (s).
    #[serde(default)]
    pub longest_without_progress_s: f64,
    /// Stretches without progress of at least `LIVELOCK_S` (30 s): the robot circling or
    /// switching targets it never reaches.
    #[serde(default)]
    pub livelocks: u32,
    /// FNV-1a 64 of the final frontier grid's cells, 16 hex digits.
    pub grid_hash: Option<String>,
    /// FNV-1a 64 of the final contact grid's cells, 16 hex digits.
    pub contact_hash: Option<String>,
    pub reachable_free_cells: u64,
    /// Step at which coverage first reached 0.5, 0.9, 0.95 and 0.99 (`null`: never), checked every
    /// `COVERAGE_EVERY` (10) steps and on the last grid.
    pub coverage_steps: BTreeMap<String, Option<u64>>,
    /// Why the world ended the run (`ticks`, `goal_reached`, `stopped`,
    /// `exploration_complete`); `null` when no final truth arrived.
    pub end_reason: Option<String>,
    /// The planner reported that no reachable frontier is left.
    pub exploration_complete: bool,
    /// Times the robot came into contact (rising edges of the contact flag).
    pub contact_events: u64,
    /// Steps spent in contact.
    pub contact_ticks: u64,
    /// Poses matched to a truth of the same tick (the RMSE's sample count).
    pub pose_samples: u64,
    /// Poses whose covariance was positive definite (the NEES's sample count).
    pub nees_samples: u64,
    /// Grids refused for their size, resolution, origin or kind, and stats beyond capacity.
    pub ignored_messages: u64,
    /// A SLAM estimator's landmark map against the true beacons (`null` for the others).
    #[serde(default)]
    pub slam: Option<crate::SlamSummary>,
    /// The particle filter's set size over the run (`null` for the other estimators).
    #[serde(default)]
    pub particles: Option<crate::ParticleSummary>,
    /// The launcher's part: processes found hung (alive, silent for 5 s), per role.
    #[serde(default)]
    pub hangs: BTreeMap<String, u32>,
    /// The launcher's part: every `mole swap` done during the run, in order.
    #[serde(default)]
    pub swaps: Vec<SwapRecord>,
    /// The launcher's part: every fault `mole fault` injected during the run, in order.
    #[serde(default)]
    pub faults: Vec<FaultRecord>,
    /// The launcher's part: from its start to the end of the stack (`null` until it wrote it).
    #[serde(default)]
    pub launcher_wall_time_s: Option<f64>,
    /// The launcher's part: every role's settings in force at the start (docs/settings.md).
    #[serde(default)]
    pub settings: serde_json::Value,
    /// The launcher's part: every setting changed while the stack ran (`mole param set`), each
    /// with the step its process took it before: `[{tick, role, key, value}]`.
    #[serde(default)]
    pub settings_changes: serde_json::Value,
}

/// One `mole swap`: what the launcher measured while the new process took the role over.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct SwapRecord {
    pub role: String,
    pub old_pid: u32,
    pub pid: u32,
    /// The world's tick when the old process was gone.
    pub tick: u64,
    /// The role's output whose silence is the gap.
    pub topic: String,
    /// Longest silence on `topic` during the swap.
    pub gap_ms: f64,
    /// Median interval on `topic` during the swap (its normal rhythm).
    pub median_interval_ms: f64,
    /// Longest run of world ticks `topic` skipped during the swap.
    #[serde(default)]
    pub gap_ticks: u64,
    /// Distinct ticks seen on `topic` during the swap.
    pub ticks_observed: u64,
    /// Lockstep: steps missing from the truth or from `topic`.
    pub steps_lost: u64,
    /// Lockstep: steps a consumer handled twice.
    pub steps_repeated: u64,
    /// The old process ignored SIGTERM and was killed.
    pub killed_old: bool,
    /// From the request to the end of the watch.
    pub duration_s: f64,
}

/// One fault `mole fault` injected (see `mole_types::fault`).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct FaultRecord {
    /// 1 for the run's first fault, then counting up.
    pub id: u32,
    /// `kill`, `stop`, `delay`, `drop` or `corrupt`.
    pub kind: String,
    /// The role or topic it was aimed at.
    pub target: String,
    /// The world's newest step when it was injected.
    pub tick: u64,
    /// How long it lasted (s; 0 for a kill).
    pub duration_s: f64,
    /// How long each sample was held (delay).
    pub delay_ms: f64,
    /// The fraction of samples dropped or corrupted.
    pub fraction: f64,
}

/// Reads a summary.json back (the launcher's and the tests' way in).
pub fn read_summary(path: &Path) -> Result<Summary, MonitorError> {
    let text = std::fs::read_to_string(path).map_err(|source| MonitorError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    Ok(serde_json::from_str(&text)?)
}

/// Writes the summary as pretty JSON (with a final newline).
pub fn write_summary(summary: &Summary, path: &Path) -> Result<(), MonitorError> {
    let mut text = serde_json::to_string_pretty(summary)?;
    text.push('\n');
    std::fs::write(path, text).map_err(|source| MonitorError::Io {
        path: path.to_path_buf(),
        source,
    })
}

/// FNV-1a 64 of a byte slice (Fowler, Noll, Vo).
pub fn fnv1a64(bytes: &[u8]) -> u64 {
    let mut hash = 0xcbf2_9ce4_8422_2325_u64;
    for b in bytes {
        hash ^= u64::from(*b);
        hash = hash.wrapping_mul(0x0000_0100_0000_01b3);
    }
    hash
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fnv1a64_matches_reference_vectors() {
        assert_eq!(fnv1a64(b""), 0xcbf29ce484222325);
        assert_eq!(fnv1a64(b"a"), 0xaf63dc4c8601ec8c);
        assert_eq!(fnv1a64(b"foobar"), 0x85944171f73967e8);
    }
}
