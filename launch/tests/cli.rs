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
            "up", "swap", "stop", "status", "fault", "param", "top", "record", "replay", "view",
            "foxglove", "info", "export", "eval", "g2o", "bench", "doctor", "new", "help"
        ]
    );
    assert_eq!(
        listed_subcommands(&["bench"]),
        ["ipc", "stack", "peers", "help"]
    );
    assert_eq!(
        listed_subcommands(&["param"]),
        ["list", "get", "set", "help"]
    );
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
        &["param"],
        &["param", "set"],
        &["top"],
        &["record"],
        &["replay"],
        &["view"],
        &["info"],
        &["export"],
        &["eval"],
        &["g2o"],
        &["bench", "ipc"],
        &["bench", "stack"],
        &["bench", "peers"],
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
    let cases: [&[&str]; 6] = [
        &["bench", "ipc", "--sizes", "64,999"],
        &["bench", "peers", "--sizes", "64,100"],
        &["bench", "peers", "--rate-hz", "0"],
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

/// `mole g2o` optimises a graph, writes the optimum where asked (a graph that reads back and is
/// already at its optimum), and refuses a malformed file with exit 2 naming its line.
#[test]
fn g2o_optimises_a_graph_and_refuses_a_bad_one() {
    let data = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../processes/localization/tests/data/g2o/noisyToyGraph.g2o"
    );
    let dir = std::env::temp_dir().join(format!("mole-cli-g2o-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let out = dir.join("optimum.g2o");
    let output = Command::new(BIN)
        .args(["g2o", data, "--out", out.to_str().unwrap()])
        .output()
        .expect("run mole g2o");
    let text = String::from_utf8_lossy(&output.stdout).into_owned();
    assert!(
        output.status.success(),
        "{text}{}",
        String::from_utf8_lossy(&output.stderr)
    );
    assert!(text.contains("4 poses, 0 points, 5 edges"), "{text}");
    let final_error = |text: &str| -> f64 {
        let after = text.split("final ").nth(1).expect("a final error");
        after.split(';').next().unwrap().parse().expect("a number")
    };
    let optimum = final_error(&text);
    let again = Command::new(BIN)
        .args(["g2o", out.to_str().unwrap()])
        .output()
        .expect("run mole g2o on the optimum");
    let again_text = String::from_utf8_lossy(&again.stdout).into_owned();
    assert!(again.status.success(), "{again_text}");
    let initial = again_text.split("initial ").nth(1).unwrap();
    let initial: f64 = initial.split(',').next().unwrap().parse().unwrap();
    assert!(
        (initial - optimum).abs() <= 1e-9 * optimum.max(1.0),
        "the written optimum starts at {initial}, not {optimum}"
    );

    let bad = dir.join("bad.g2o");
    std::fs::write(
        &bad,
        "VERTEX_SE2 0 0 0 0\nEDGE_SE2 0 1 1 0 zero 1 0 0 1 0 1\n",
    )
    .unwrap();
    let refused = Command::new(BIN)
        .args(["g2o", bad.to_str().unwrap()])
        .output()
        .expect("run mole g2o on a bad file");
    let err = String::from_utf8_lossy(&refused.stderr).into_owned();
    assert_eq!(refused.status.code(), Some(2), "{err}");
    assert!(err.contains("bad.g2o line 2"), "{err}");
    std::fs::remove_dir_all(&dir).ok();
}
