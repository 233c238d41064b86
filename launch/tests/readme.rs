//! The README's environment table is `mole_types::env::ALL`, no more, no less.

use mole_types::env;

const README: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../README.md");
const START: &str = "<!-- generated from mole_types::env::ALL; a test checks it -->\n";
const END: &str = "<!-- end of the environment table -->";

/// The table as `env::ALL` says it: every variable with its meaning, in the list's order.
fn table() -> String {
    let mut text = String::from("| variable | what it carries |\n| --- | --- |\n");
    for var in env::ALL {
        text.push_str(&format!("| `{}` | {} |\n", var.name, var.meaning));
    }
    text
}

/// The README lists exactly the launcher's environment (`MOLE_BLESS=1` rewrites the table).
#[test]
fn readme_environment_table_is_env_all() {
    let between_markers = |readme: &str| {
        let start = readme.find(START)? + START.len();
        Some(start..start + readme[start..].find(END)?)
    };
    mole_types::golden::check(
        README.as_ref(),
        &table(),
        between_markers,
        "cargo test -p mole-launch --test readme",
    );
}

/// The README's lists of planners and estimators (`--planner a|b`, `--estimator a|b`,
/// `--local-planner a|b`) are the registries' tables, in their order.
#[test]
fn readme_lists_every_planner_and_estimator_of_the_tables() {
    use mole_types::{EstimatorKind, PlannerKind};
    let readme = std::fs::read_to_string(README).expect("README.md");
    let followers: Vec<&str> = PlannerKind::ALL
        .iter()
        .filter(|p| p.needs_goal())
        .map(|p| p.name())
        .collect();
    for (flag, names) in [
        ("--planner ", PlannerKind::NAMES.join("|")),
        ("--estimator ", EstimatorKind::NAMES.join("|")),
        ("--local-planner ", followers.join("|")),
    ] {
        let listed = format!("`{flag}{names}`");
        assert!(
            readme.contains(&listed),
            "README.md does not list {listed}: the table of {flag}changed"
        );
    }
}
