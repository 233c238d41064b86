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
    let readme = std::fs::read_to_string(README).expect("read README.md");
    let start = readme
        .find(START)
        .expect("the environment table's start marker")
        + START.len();
    let end = start + readme[start..].find(END).expect("its end marker");
    if std::env::var_os("MOLE_BLESS").is_some() {
        let blessed = format!("{}{}{}", &readme[..start], table(), &readme[end..]);
        std::fs::write(README, blessed).expect("write README.md");
        return;
    }
    let listed: Vec<&str> = readme[start..end]
        .lines()
        .filter_map(|row| row.strip_prefix("| `")?.split_once('`'))
        .map(|(name, _)| name)
        .collect();
    let all: Vec<&str> = env::ALL.iter().map(|v| v.name).collect();
    assert_eq!(listed, all, "the README's environment variables");
    assert_eq!(
        &readme[start..end],
        table(),
        "README.md's environment table differs from mole_types::env::ALL: regenerate it with \
         `MOLE_BLESS=1 cargo test -p mole-launch --test readme`"
    );
}
