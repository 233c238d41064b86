//! `cargo run -p mole-launch` reuses what `cargo build --workspace` built, instead of compiling part
//! of the tree again: cargo shares a built crate only between builds that resolve it to the same
//! features, so the launcher alone must resolve every crate it needs as the whole workspace does.
//! The bridge (`mole-bridge`, zenoh) and the Foxglove server (`mole-foxglove`, Foxglove's SDK)
//! are left out of both: `mole up` builds each only for a run that uses it, so their choice of
//! features is not forced on every other build.

use std::collections::{BTreeMap, BTreeSet};
use std::process::Command;

/// Every crate `cargo tree` resolves for the build that `selection` names (dev-dependencies left
/// out, as `cargo build` and `cargo run` leave them out), with the feature sets it is built with:
/// one set per build of it (a crate can be built once for build scripts and once for the binaries).
fn resolved_features(selection: &[&str]) -> BTreeMap<String, BTreeSet<String>> {
    let cargo = std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into());
    let output = Command::new(cargo)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .args(["tree", "--locked"])
        .args(selection)
        .args(["--edges", "normal,build"])
        .args(["--prefix", "none", "--format", "{p}|{f}"])
        .output()
        .expect("run cargo tree");
    let text = String::from_utf8_lossy(&output.stdout);
    assert!(
        output.status.success(),
        "cargo tree {selection:?}: {}",
        String::from_utf8_lossy(&output.stderr)
    );
    let mut crates: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    for line in text.lines().filter(|line| !line.is_empty()) {
        let (package, features) = line
            .split_once('|')
            .unwrap_or_else(|| panic!("cargo tree {selection:?}: unexpected line {line:?}"));
        let features = features.trim_end_matches(" (*)").to_owned();
        crates
            .entry(package.to_owned())
            .or_default()
            .insert(features);
    }
    crates
}

/// Each crate the launcher's own build needs has the same features as in the workspace build, so
/// `cargo run -p mole-launch` after `cargo build --workspace` compiles nothing but the launcher.
#[test]
fn launcher_resolves_each_crate_as_the_workspace_does() {
    let launcher = resolved_features(&["--package=mole-launch"]);
    let workspace = resolved_features(&[
        "--workspace",
        "--exclude=mole-bridge",
        "--exclude=mole-foxglove",
    ]);
    assert!(
        launcher.contains_key(&format!(
            "mole-launch v{} ({})",
            env!("CARGO_PKG_VERSION"),
            env!("CARGO_MANIFEST_DIR")
        )),
        "cargo tree did not list the launcher: {launcher:?}"
    );
    let diverging: Vec<String> = launcher
        .iter()
        .filter(|(package, features)| workspace.get(*package) != Some(*features))
        .map(|(package, features)| {
            format!(
                "{package}: launcher {features:?}, workspace {:?}",
                workspace.get(package)
            )
        })
        .collect();
    assert!(
        diverging.is_empty(),
        "these crates would be compiled again for `cargo run -p mole-launch`; name the missing \
         features in [workspace.dependencies]:\n{}",
        diverging.join("\n")
    );
}
