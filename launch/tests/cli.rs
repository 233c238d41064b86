//! The mole binary's command line (the stack itself is tested in tests/).

use std::process::Command;

const BIN: &str = env!("CARGO_BIN_EXE_mole");

/// The subcommands `mole ARGS --help` lists in its `Commands:` section: the first word of each
/// entry (an entry starts two spaces in; a wrapped description further in).
fn listed_subcommands(args: &[&str]) -> Vec<String> {
    let output = Command::new(BIN)
        .args(args)
        .arg("--help")
        .output()
        .expect("run mole");
    let text = String::from_utf8_lossy(&output.stdout);
    assert!(output.status.success(), "mole {args:?} --help: {text}");
    text.lines()
        .skip_while(|line| *line != "Commands:")
        .skip(1)
        .take_while(|line| !line.trim().is_empty())
        .filter_map(|line| line.strip_prefix("  "))
        .filter(|entry| !entry.starts_with(' '))
        .filter_map(|entry| entry.split_whitespace().next())
        .map(str::to_owned)
        .collect()
}

/// `--help` lists every subcommand by name, and each one answers its own `--help`.
#[test]
fn help_lists_every_subcommand() {
    assert_eq!(
        listed_subcommands(&[]),
        [
            "up", "swap", "stop", "status", "fault", "top", "record", "replay", "view", "info",
            "export", "eval", "bench", "help"
        ]
    );
    assert_eq!(listed_subcommands(&["bench"]), ["ipc", "stack", "help"]);
    assert_eq!(
        listed_subcommands(&["fault"]),
        ["kill", "stop", "delay", "drop", "corrupt", "chaos", "help"]
    );
    for command in [
        &["up"][..],
        &["swap"],
        &["stop"],
        &["status"],
        &["fault"],
        &["fault", "kill"],
        &["fault", "chaos"],
        &["top"],
        &["record"],
        &["replay"],
        &["view"],
        &["info"],
        &["export"],
        &["eval"],
        &["bench", "ipc"],
        &["bench", "stack"],
    ] {
        let output = Command::new(BIN)
            .args(command)
            .arg("--help")
            .output()
            .expect("run mole");
        let usage = format!("Usage: mole {}", command.join(" "));
        let text = String::from_utf8_lossy(&output.stdout);
        assert!(output.status.success(), "{command:?}: {text}");
        assert!(text.contains(&usage), "{command:?} --help: {text}");
    }
}

#[test]
fn bad_arguments_exit_2() {
    for args in [
        &["up", "--mode", "warp"][..],
        &["up", "--ticks", "-3"],
        &["fly"],
        &["up", "--duration", "nan"],
    ] {
        let output = Command::new(BIN)
            .args(args)
            .env_remove("CARGO")
            .output()
            .expect("run mole");
        assert_eq!(
            output.status.code(),
            Some(2),
            "{args:?}: {}",
            String::from_utf8_lossy(&output.stderr)
        );
    }
}

#[test]
fn bench_and_top_refuse_bad_input_with_exit_2() {
    let cases: [&[&str]; 4] = [
        &["bench", "ipc", "--sizes", "64,999"],
        &[
            "bench",
            "ipc",
            "--quick",
            "--json",
            "/nonexistent-dir/report.json",
        ],
        &["bench", "stack", "--json", "/nonexistent-dir/report.json"],
        &["top", "--namespace", "no-stack-runs-here", "--once"],
    ];
    for args in cases {
        let output = Command::new(BIN)
            .args(args)
            .env_remove("CARGO")
            .output()
            .expect("run mole");
        let err = String::from_utf8_lossy(&output.stderr);
        assert_eq!(output.status.code(), Some(2), "{args:?}: {err}");
        assert!(err.contains("error:"), "{args:?}: {err}");
    }
}
