//! Which samples of a topic are written: every one, or one every N ticks for the large, slowly
//! changing ones (`--every TOPIC=N`).
//!
//! Default: the topic table's `record_every` column (the frontier and contact grids, 256 KiB
//! each, published every step, changing a few cells a step: once every 10 ticks), everything
//! else every sample. The world map is
//! published once and a smoother's trajectory after each solve, so they are already written only
//! when they change. The last sample of a decimated topic is always written at the end, so the
//! final grids (whose hashes summary.json holds) are in the file.

use mole_types::topics;
use std::collections::BTreeMap;

/// Per-topic decimation.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Every {
    ticks: BTreeMap<String, u64>,
}

impl Default for Every {
    fn default() -> Self {
        let ticks = topics::policies()
            .into_iter()
            .filter(|p| p.record_every > 1)
            .map(|p| (p.name.to_string(), p.record_every))
            .collect();
        Every { ticks }
    }
}

impl Every {
    /// The defaults with `settings` (`TOPIC=N`, N ≥ 1 ticks; 1 writes every sample) applied;
    /// an unknown topic or a bad N is refused, naming what was expected.
    pub fn parse(settings: &[String]) -> Result<Every, String> {
        let mut every = Every::default();
        for setting in settings {
            let (topic, n) = setting
                .split_once('=')
                .ok_or_else(|| format!("`{setting}`: expected TOPIC=N (e.g. mapping/grid=10)"))?;
            let known: Vec<&str> = topics::all().iter().map(|(name, _)| *name).collect();
            if !known.contains(&topic) {
                return Err(format!(
                    "`{setting}`: `{topic}` is not a topic; expected one of: {}",
                    known.join(", ")
                ));
            }
            let n = n.parse::<u64>().ok().filter(|n| *n >= 1).ok_or_else(|| {
                format!("`{setting}`: expected a whole number of ticks ≥ 1, found `{n}`")
            })?;
            every.ticks.insert(topic.to_string(), n);
        }
        Ok(every)
    }

    /// Ticks between two written samples of `topic` (1: every sample).
    pub fn of(&self, topic: &str) -> u64 {
        self.ticks.get(topic).copied().unwrap_or(1)
    }

    /// The settings that differ from "every sample", as `TOPIC=N` (for the file's metadata).
    pub fn describe(&self) -> String {
        let parts: Vec<String> = self
            .ticks
            .iter()
            .filter(|(_, n)| **n > 1)
            .map(|(t, n)| format!("{t}={n}"))
            .collect();
        parts.join(",")
    }
}

/// Whether a sample of tick `tick` is due when the last written one had tick `last` (`None`:
/// none written yet) and the topic is written every `every` ticks. Every sample is due at 1 (a
/// step sent twice too); a tick that goes back (a restarted publisher) is due at once.
pub fn due(tick: u64, last: Option<u64>, every: u64) -> bool {
    match last {
        _ if every <= 1 => true,
        None => true,
        Some(last) => tick < last || tick - last >= every,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Grids are decimated by default, the rest is written whole; a setting overrides it.
    #[test]
    fn grids_default_to_every_ten_ticks_and_a_setting_overrides_it() {
        let every = Every::parse(&[]).expect("defaults");
        assert_eq!(every.of("mapping/grid"), 10);
        assert_eq!(every.of("mapping/contact"), 10);
        assert_eq!(every.of("world/truth"), 1);
        let every = Every::parse(&["mapping/grid=1".into(), "sensing/scan=5".into()]).unwrap();
        assert_eq!(every.of("mapping/grid"), 1);
        assert_eq!(every.of("sensing/scan"), 5);
        assert_eq!(every.describe(), "mapping/contact=10,sensing/scan=5");
    }

    /// A bad setting is refused naming what was expected.
    #[test]
    fn bad_settings_are_refused_naming_what_was_expected() {
        let refused = |s: &str| Every::parse(&[s.to_string()]).expect_err(s);
        assert!(refused("mapping/grid").contains("expected TOPIC=N"));
        assert!(refused("mapping/gird=3").contains("expected one of: world/map"));
        assert!(refused("mapping/grid=0").contains("≥ 1, found `0`"));
        assert!(refused("mapping/grid=-2").contains("found `-2`"));
    }

    /// One sample every N ticks, whatever ticks were skipped; a restart starts over.
    #[test]
    fn a_sample_is_due_every_n_ticks() {
        assert!(due(7, None, 10));
        assert!(!due(16, Some(7), 10));
        assert!(due(17, Some(7), 10));
        assert!(due(40, Some(7), 10));
        assert!(due(3, Some(7), 10), "a restarted publisher");
        assert!(due(7, Some(7), 1), "a step sent twice, written whole");
    }
}
