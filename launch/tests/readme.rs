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
