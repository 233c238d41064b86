//! The stack's settings: each role's `[ROLE.…]` tables of the launch file (`[planning.dwa]`,
//! `[localization.pf]`, `[mapping]`), overridden by `mole up --set ROLE.KEY=VALUE`, checked
//! before any process starts and handed to every process as JSON (`MOLE_SETTINGS`); each reads
//! its own role's table. docs/settings.md is generated from them ([`markdown`]).

use mole_types::Setting;
use mole_types::settings::{Key, SettingError, Settings};
use serde::{Deserialize, Serialize};

/// Every role's settings.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize, Setting)]
#[serde(default, deny_unknown_fields)]
pub struct StackSettings {
    /// The planners.
    pub planning: mole_planning::Settings,
    /// The estimators.
    pub localization: mole_localization::Settings,
    /// The grids.
    pub mapping: mole_mapping::Settings,
}

impl StackSettings {
    /// These settings with every `KEY=VALUE` of `mole up --set` applied in order; the error
    /// names the flag.
    pub fn with_sets(self, sets: &[String]) -> Result<Self, String> {
        let mut settings = self;
        for set in sets {
            let Some((key, value)) = set.split_once('=') else {
                return Err(format!(
                    "--set {set}: expected KEY=VALUE, e.g. planning.dwa.critics.heading=0.4 \
                     (docs/settings.md lists the keys)"
                ));
            };
            settings = settings
                .with(key.trim(), value.trim())
                .map_err(|e| format!("--set {set}: {e}"))?;
        }
        Ok(settings)
    }

    /// The JSON every process gets as `MOLE_SETTINGS`.
    pub fn to_json(&self) -> String {
        self.to_json_with(&[])
    }

    /// [`StackSettings::to_json`] with the changes a replay schedules (`changes`: each role's
    /// process applies its own before their steps).
    pub fn to_json_with(&self, changes: &[mole_runtime::ScheduledChange]) -> String {
        let mut json = serde_json::to_value(self).expect("settings serialize");
        if !changes.is_empty() {
            json["changes"] = serde_json::to_value(changes).expect("changes serialize");
        }
        json.to_string()
    }
}

/// Where a checked launch file's setting went wrong, for [`crate::LaunchError::Invalid`].
pub fn located(error: &SettingError, text: &str) -> Option<std::ops::Range<usize>> {
    let table = toml::de::DeTable::parse(text).ok()?;
    let mut at = table.get_ref();
    let mut span = None;
    let parts: Vec<&str> = error.key.split('.').collect();
    for (i, part) in parts.iter().enumerate() {
        let (_, value) = at.iter().find(|(k, _)| k.get_ref() == part)?;
        span = Some(value.span());
        match value.get_ref() {
            toml::de::DeValue::Table(t) => at = t,
            _ if i + 1 == parts.len() => {}
            _ => return span,
        }
    }
    span
}

/// docs/settings.md: every key of every role with its kind, default, bounds and meaning.
pub fn markdown() -> String {
    use core::fmt::Write;
    let defaults = StackSettings::default();
    let mut s = String::from(
        "# Settings\n\n\
         Generated from the settings structures (`launch/src/settings.rs` and the `Settings` of \
         each process crate; regenerate with `MOLE_BLESS=1 cargo test -p mole-launch settings`); \
         a test fails when this file and the code differ.\n\n\
         Set them in a launch file, one table per role (`[planning.dwa]`, `[localization.pf]`, \
         `[mapping]`):\n\n\
         ```toml\n[planning.dwa.critics]\nheading = 0.4\n\n[localization.pf]\nn_particles = 2000\n```\n\n\
         or for one run with `mole up --set planning.dwa.critics.heading=0.4` (repeatable; also \
         `mole eval --set`), or while the stack runs with `mole param set planning \
         dwa.critics.heading 0.4` (`mole param list ROLE` shows the values in force). An unknown key or a value of the wrong kind or out of its \
         bounds is refused before any process starts (exit 2), naming the file, line and key. \
         The values in force go into summary.json (`settings`) and a recording's metadata. A \
         key marked *fixed* cannot change while its process runs; any other is handed to its \
         process, which takes it before its next step or refuses it saying why (the histogram \
         filter and GraphSLAM keep the noise they started with), recorded (summary.json's `settings_changes`, an event on \
         `stack/events`) and replayed before the same step by `mole replay`.\n",
    );
    let roles: [(&str, &str, Vec<Key>); 3] = [
        (
            "planning",
            "the planners (algorithms §1, §3–§5)",
            mole_planning::Settings::keys(),
        ),
        (
            "localization",
            "the estimators (algorithms §6)",
            mole_localization::Settings::keys(),
        ),
        (
            "mapping",
            "the grids (algorithms §2, §5.2)",
            mole_mapping::Settings::keys(),
        ),
    ];
    for (role, what, keys) in roles {
        let _ = writeln!(
            s,
            "\n## {role}: {what}\n\n| key | takes | default | bounds | meaning |\n| --- | --- | --- | --- | --- |"
        );
        for k in keys {
            let full = format!("{role}.{}", k.path);
            let default = defaults.get(&full).unwrap_or_else(|| "unset".to_owned());
            let fixed = k
                .fixed
                .as_deref()
                .map_or(String::new(), |why| format!(" *Fixed:* {why}."));
            let _ = writeln!(
                s,
                "| `{}` | {} | `{}` | {} | {}{} |",
                k.path,
                k.kind.replace('|', "\\|"),
                default.replace('|', "\\|"),
                k.rule,
                k.doc
                    .replace('|', "\\|")
                    .replace("[`", "`")
                    .replace("`]", "`"),
                fixed
            );
        }
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    /// docs/settings.md is these structures' (`MOLE_BLESS=1` rewrites it).
    #[test]
    fn docs_settings_md_matches_the_code() {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../docs/settings.md");
        mole_types::golden::check(
            path.as_ref(),
            &markdown(),
            mole_types::golden::whole,
            "cargo test -p mole-launch settings",
        );
    }

    /// `--set` takes a key of any role, refuses an unknown key, a wrong kind, a value out of its
    /// bounds and a missing `=`, naming the flag; the defaults check.
    #[test]
    fn sets_are_applied_and_checked() {
        let base = StackSettings::default();
        assert!(base.check().is_ok());
        let set =
            |s: &[&str]| base.with_sets(&s.iter().map(|s| (*s).to_owned()).collect::<Vec<_>>());
        let s = set(&[
            "planning.dwa.critics.heading=0.4",
            "localization.pf.n_particles = 2000",
            "mapping.touch_threshold=1.5",
            "planning.replan_with=apf",
        ])
        .unwrap();
        assert_eq!(s.planning.dwa.critics.heading, 0.4);
        assert_eq!(s.localization.pf.n_particles, 2000);
        assert_eq!(s.mapping.touch_threshold, 1.5);
        assert_eq!(s.planning.replan_with, Some(mole_types::PlannerKind::Apf));
        for (bad, says) in [
            ("planning.dwa.heading=0.4", "one of the keys"),
            ("planning.dwa.critics.heading=\"high\"", "invalid type"),
            ("localization.pf.n_particles=0", "≥ 1"),
            ("localization.pf.n_particles=2000000", "≤ 1000000"),
            (
                "mapping.log_odds.threshold=9.0",
                "threshold < min(max, -min)",
            ),
            ("planning.replan_with=\"frontier\"", "drives to a goal"),
            ("planning.dwa.critics.heading", "KEY=VALUE"),
            ("planning.dwa.critics.heading=0.4.1", "a TOML value"),
        ] {
            let e = set(&[bad]).unwrap_err();
            assert!(e.starts_with(&format!("--set {bad}")), "{e}");
            assert!(e.contains(says), "{bad}: {e}");
        }
    }
}
