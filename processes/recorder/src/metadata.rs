//! The run's metadata record ([`crate::RUN_METADATA`]): what a reader needs to know what was
//! run, and to run it again.

use crate::Every;
use mole_runtime::{BadInput, CommonArgs};
use std::collections::BTreeMap;
use std::path::Path;
use std::process::Command;

/// What the recorder knows of the run when it starts (seed and period come with the world's
/// map, see [`crate::Recording`]).
#[derive(Debug, Clone, Default)]
pub struct RunFacts<'a> {
    pub namespace: &'a str,
    pub clock_mode: &'a str,
    pub rate_hz: f64,
    pub launch_file: Option<&'a Path>,
    pub scenario: Option<&'a Path>,
    pub revision: String,
    /// The decimation settings (`crate::Every::describe`).
    pub every: String,
    /// Every role's settings in force at the start, as JSON (`MOLE_SETTINGS`, docs/settings.md);
    /// empty where the recorder was not told.
    pub settings: &'a str,
}

/// The metadata: every fact as text; the launch file and the scenario by path and by content
/// (`unknown` where the recorder was not told, e.g. attached to a running stack); an unreadable
/// file is an error naming it.
pub fn run_metadata(facts: &RunFacts) -> Result<BTreeMap<String, String>, String> {
    let mut m = BTreeMap::new();
    m.insert("namespace".into(), facts.namespace.to_string());
    m.insert("clock_mode".into(), facts.clock_mode.to_string());
    m.insert("rate_hz".into(), facts.rate_hz.to_string());
    m.insert("revision".into(), facts.revision.clone());
    m.insert("every".into(), facts.every.clone());
    m.insert(
        "settings".into(),
        if facts.settings.is_empty() {
            "unknown".to_owned()
        } else {
            facts.settings.to_owned()
        },
    );
    m.insert(
        mole_types::graph::nodes::RECORDER.into(),
        format!("mole-recorder {}", env!("CARGO_PKG_VERSION")),
    );
    for (key, path) in [
        ("launch_file", facts.launch_file),
        ("scenario", facts.scenario),
    ] {
        let (path_text, content) = match path {
            Some(path) => {
                let content = std::fs::read_to_string(path)
                    .map_err(|e| format!("cannot read the {key} {}: {e}", path.display()))?;
                (path.display().to_string(), content)
            }
            None => ("unknown".to_string(), "unknown".to_string()),
        };
        m.insert(format!("{key}_path"), path_text);
        m.insert(key.to_string(), content);
    }
    Ok(m)
}

/// The run's metadata from the recorder's command line: the stack's arguments (`common`), the
/// launch file and scenario it runs, the source `revision` (default: [`source_revision`] of the
/// working directory) and the decimation settings; an unreadable file is bad input.
pub fn run_metadata_of(
    common: &CommonArgs,
    launch_file: Option<&Path>,
    scenario: Option<&Path>,
    revision: Option<&str>,
    every: &Every,
) -> Result<BTreeMap<String, String>, Box<dyn std::error::Error>> {
    let cwd = std::env::current_dir()?;
    let facts = RunFacts {
        namespace: &common.namespace,
        clock_mode: common.mode.name(),
        rate_hz: common.rate_hz,
        launch_file,
        scenario,
        revision: revision.map_or_else(|| source_revision(&cwd), str::to_owned),
        every: every.describe(),
        settings: common.settings.as_deref().unwrap_or_default(),
    };
    Ok(run_metadata(&facts).map_err(BadInput)?)
}

/// The source revision of the checkout `dir` is in (`git describe --always --dirty`: the
/// commit, `-dirty` with uncommitted changes), or `unknown` outside a git checkout.
pub fn source_revision(dir: &Path) -> String {
    Command::new("git")
        .arg("-C")
        .arg(dir)
        .args(["describe", "--always", "--dirty", "--abbrev=40"])
        .output()
        .ok()
        .filter(|out| out.status.success())
        .map(|out| String::from_utf8_lossy(&out.stdout).trim().to_string())
        .filter(|rev| !rev.is_empty())
        .unwrap_or_else(|| "unknown".to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The launch file goes in by path and text; an unknown one says so; an unreadable one is
    /// refused naming it.
    #[test]
    fn the_launch_file_is_kept_by_path_and_text() {
        let launch = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/Cargo.toml"));
        let facts = RunFacts {
            namespace: "robot0",
            clock_mode: "lockstep",
            rate_hz: 100.0,
            launch_file: Some(launch),
            ..RunFacts::default()
        };
        let m = run_metadata(&facts).expect("metadata");
        assert!(m["launch_file"].contains("mole-recorder"));
        assert_eq!(m["launch_file_path"], launch.display().to_string());
        assert_eq!(m["scenario"], "unknown");
        assert_eq!(m["clock_mode"], "lockstep");
        let missing = RunFacts {
            scenario: Some(Path::new("/no/such/scenario.toml")),
            ..facts
        };
        let refused = run_metadata(&missing).expect_err("unreadable");
        assert!(refused.contains("/no/such/scenario.toml"), "{refused}");
    }

    /// Outside a git checkout the revision is `unknown`.
    #[test]
    fn outside_a_checkout_the_revision_is_unknown() {
        assert_eq!(source_revision(Path::new("/")), "unknown");
    }
}
