use super::*;
use mole_types::GRAPH;
use proptest::prelude::*;

const VALID: &str = r#"[stack]
scenario = "scenarios/default.toml"
mode = "realtime"
rate_hz = 100
ticks = 3000
planner = "random-walk"
estimator = "ekf"
shutdown_timeout_ms = 3000

[[process]]
role = "sensing"
command = "mole-sensing"
restart = { policy = "on-failure", backoff_ms = 200, max = 5 }

[[process]]
role = "planning"
command = "mole-planning"
args = ["--verbose"]
env = { RUST_LOG = "info" }
restart = { policy = "always" }

[[process]]
role = "world"
command = "mole-world"
depends_on = ["sensing", "planning"]
"#;

fn parse(text: &str) -> Result<LaunchFile, LaunchError> {
    parse_launch_file(text, Path::new("launch/stacks/x.toml"))
}

fn err(text: &str) -> String {
    match parse(text) {
        Ok(_) => panic!("expected an error for:\n{text}"),
        Err(e) => {
            assert_eq!(e.exit_code(), 2);
            let msg = e.to_string();
            assert!(!msg.contains('\n'), "one line: {msg}");
            msg
        }
    }
}

#[test]
fn valid_file_parses_with_defaults() {
    let lf = parse(VALID).unwrap();
    assert_eq!(lf.stack.mode, ClockMode::Realtime);
    assert_eq!(lf.stack.rate_hz, 100.0);
    assert_eq!(lf.stack.ticks, Some(3000));
    assert_eq!(lf.stack.duration_s, None);
    assert_eq!(
        lf.stack.scenario.as_deref(),
        Some(Path::new("scenarios/default.toml"))
    );
    assert_eq!(lf.roles(), ["sensing", "planning", "world"]);
    let s = lf.process("sensing").unwrap();
    assert_eq!(s.restart.policy, RestartWhen::OnFailure);
    assert_eq!((s.restart.backoff_ms, s.restart.max), (200, 5));
    assert_eq!(s.restart.max_backoff_ms, 5000);
    let p = lf.process("planning").unwrap();
    assert_eq!(p.args, ["--verbose"]);
    assert_eq!(p.env.get("RUST_LOG").map(String::as_str), Some("info"));
    assert_eq!(p.restart.policy, RestartWhen::Always);
    let w = lf.process("world").unwrap();
    assert_eq!(w.restart, RestartPolicy::default());
    assert_eq!(w.restart.policy, RestartWhen::Never);
    assert_eq!(w.depends_on, ["sensing", "planning"]);
}

#[test]
fn empty_file_is_an_empty_stack_with_defaults() {
    let lf = parse("").unwrap();
    assert!(lf.processes.is_empty());
    assert_eq!(lf.stack, StackSpec::default());
}

#[test]
fn unknown_policy_names_file_line_column_field_and_choices() {
    let text = VALID.replace("policy = \"always\"", "policy = \"sometimes\"");
    let msg = err(&text);
    // line 20: `restart = { policy = "sometimes" }`, the value starts at column 22.
    assert_eq!(
        msg,
        "launch/stacks/x.toml:20:22: field `process[1].restart.policy`: unknown variant \
         `sometimes`, expected one of `never`, `on-failure`, `always`"
    );
}

#[test]
fn unknown_field_is_denied() {
    let msg = err(&VALID.replace("args = [", "argz = ["));
    assert!(
        msg.starts_with("launch/stacks/x.toml:18:1: field `process[1].argz`"),
        "{msg}"
    );
    assert!(msg.contains("process[1]"), "{msg}");
    assert!(msg.contains("unknown field `argz`"), "{msg}");
    assert!(msg.contains("expected one of"), "{msg}");

    let msg = err(&VALID.replace("planner =", "plannr ="));
    assert!(msg.starts_with("launch/stacks/x.toml:6:"), "{msg}");
    assert!(msg.contains("unknown field `plannr`"), "{msg}");

    let msg = err(&format!("{VALID}\n[extra]\nx = 1\n"));
    assert!(msg.contains("unknown field `extra`"), "{msg}");
}

#[test]
fn wrong_type_names_the_field_and_expected_type() {
    let msg = err(&VALID.replace("ticks = 3000", "ticks = \"many\""));
    assert!(
        msg.starts_with("launch/stacks/x.toml:5:9: field `stack.ticks`"),
        "{msg}"
    );
    assert!(msg.contains("invalid type"), "{msg}");
    assert!(msg.contains("u64"), "{msg}");

    let msg = err(&VALID.replace("args = [\"--verbose\"]", "args = \"--verbose\""));
    assert!(
        msg.starts_with("launch/stacks/x.toml:18:8: field `process[1].args`"),
        "{msg}"
    );
    assert!(msg.contains("expected a sequence"), "{msg}");

    let msg = err(&VALID.replace("max = 5", "max = -1"));
    assert!(msg.contains("field `process[0].restart.max`"), "{msg}");
}

#[test]
fn missing_field_names_the_table() {
    let msg = err("[[process]]\nrole = \"a\"\n");
    assert!(
        msg.starts_with("launch/stacks/x.toml:1:1: field `process[0]`"),
        "{msg}"
    );
    assert!(msg.contains("missing field `command`"), "{msg}");
}

#[test]
fn syntax_error_has_a_location() {
    let msg = err("[stack]\nmode = \n");
    assert!(msg.starts_with("launch/stacks/x.toml:2:"), "{msg}");
    let msg = err("[stack\n");
    assert!(msg.starts_with("launch/stacks/x.toml:1:"), "{msg}");
}

#[test]
fn bad_mode() {
    let msg = err(&VALID.replace("\"realtime\"", "\"fast\""));
    assert!(
        msg.starts_with("launch/stacks/x.toml:3:8: field `stack.mode`"),
        "{msg}"
    );
    assert!(
        msg.ends_with("unknown clock mode `fast`, expected one of: realtime, lockstep"),
        "{msg}"
    );
}

#[test]
fn duplicate_role() {
    let msg = err(&VALID.replace("role = \"planning\"", "role = \"sensing\""));
    assert_eq!(
        msg,
        "launch/stacks/x.toml:16:8: field `process[1].role`: duplicate role `sensing` (first \
         defined on line 11), expected every role once"
    );
}

#[test]
fn unknown_depends_on() {
    let msg = err(&VALID.replace("[\"sensing\", \"planning\"]", "[\"sensing\", \"planing\"]"));
    assert_eq!(
        msg,
        "launch/stacks/x.toml:25:26: field `process[2].depends_on[1]`: unknown role `planing`, \
         expected one of: sensing, planning, world"
    );
}

#[test]
fn cycle_names_the_cycle_and_its_line() {
    let text = VALID.replace(
        "command = \"mole-sensing\"",
        "command = \"mole-sensing\"\ndepends_on = [\"world\"]",
    );
    let msg = err(&text);
    assert_eq!(
        msg,
        "launch/stacks/x.toml:13:15: field `process[0].depends_on[0]`: dependency cycle \
         sensing -> world -> sensing, expected processes that depend on each other without a circle"
    );
}

#[test]
fn empty_command_and_bad_role() {
    let msg = err(&VALID.replace("\"mole-planning\"", "\"  \""));
    assert!(
        msg.starts_with("launch/stacks/x.toml:17:11: field `process[1].command`: empty command"),
        "{msg}"
    );
    let msg = err(&VALID.replace("role = \"planning\"", "role = \"plan ning\""));
    assert_eq!(
        msg,
        "launch/stacks/x.toml:16:8: field `process[1].role`: unknown role `plan ning`, expected \
         one of: world, sensing, localization, mapping, planning, monitor, or observer-<name> \
         (an extra observer), or bridge (a split stack's link)"
    );
    for bad in [
        "../x",
        "observer-",
        "observer-../x",
        "observer-X",
        "observer",
    ] {
        let msg = err(&VALID.replace("role = \"planning\"", &format!("role = \"{bad}\"")));
        assert!(msg.contains(&format!("unknown role `{bad}`")), "{msg}");
    }
}

/// A launch file may add observers (`observer-<name>`) beside the graph's roles; they stop last.
#[test]
fn extra_observers_are_accepted_and_stop_last() {
    let text = format!(
        "{VALID}\n[[process]]\nrole = \"observer-1\"\ncommand = \"mole-observer\"\n\
         \n[[process]]\nrole = \"observer-a-2\"\ncommand = \"mole-observer\"\n"
    );
    let file = parse(&text).unwrap();
    let roles: Vec<&str> = file.processes.iter().map(|p| p.role.as_str()).collect();
    assert_eq!(
        roles,
        ["sensing", "planning", "world", "observer-1", "observer-a-2"]
    );
    let stops = crate::stop_order(&file.processes);
    let last: Vec<&str> = stops[3..]
        .iter()
        .map(|&i| file.processes[i].role.as_str())
        .collect();
    assert_eq!(last, ["observer-1", "observer-a-2"]);
}

#[test]
fn rate_and_run_length_are_checked() {
    let msg = err(&VALID.replace("rate_hz = 100", "rate_hz = 0"));
    assert!(
        msg.starts_with("launch/stacks/x.toml:4:11: field `stack.rate_hz`"),
        "{msg}"
    );
    assert!(msg.contains("expected a number > 0"), "{msg}");
    let msg = err(&VALID.replace("rate_hz = 100", "rate_hz = -5.5"));
    assert!(msg.contains("stack.rate_hz"), "{msg}");
    let msg = err(&VALID.replace("ticks = 3000", "ticks = 3000\nduration_s = 30"));
    assert!(
        msg.starts_with("launch/stacks/x.toml:6:14: field `stack.duration_s`"),
        "{msg}"
    );
    assert!(msg.contains("both `ticks` and `duration_s`"), "{msg}");
    let msg = err(&VALID.replace("ticks = 3000", "ticks = 0"));
    assert!(msg.contains("stack.ticks"), "{msg}");
    let msg = err(&VALID.replace("ticks = 3000", "duration_s = nan"));
    assert!(msg.contains("stack.duration_s"), "{msg}");

    let lf = parse(&VALID.replace("ticks = 3000", "duration_s = 2.5")).unwrap();
    assert_eq!((lf.stack.ticks, lf.stack.duration_s), (None, Some(2.5)));
}

#[test]
fn backoff_bounds_are_checked() {
    let msg = err(&VALID.replace("backoff_ms = 200", "backoff_ms = 200, max_backoff_ms = 100"));
    assert!(
        msg.contains("field `process[0].restart.max_backoff_ms`"),
        "{msg}"
    );
}

#[test]
fn missing_file_is_a_read_error() {
    let e = load_launch_file(Path::new("/nonexistent/launch.toml")).unwrap_err();
    assert!(matches!(e, LaunchError::Read { .. }));
    assert!(
        e.to_string()
            .starts_with("/nonexistent/launch.toml: cannot read launch file")
    );
    assert_eq!(e.exit_code(), 2);
}

#[test]
fn line_column_counts_chars() {
    let t = "ab\ncäd\n";
    assert_eq!(line_column(t, 0), (1, 1));
    assert_eq!(line_column(t, 3), (2, 1));
    assert_eq!(line_column(t, 6), (2, 3)); // 'd' after the two-byte 'ä'
    assert_eq!(line_column(t, 1000), (3, 1));
}

#[test]
fn overrides_replace_the_run_length() {
    let mut stack = parse(VALID).unwrap().stack;
    StackOverrides {
        duration_s: Some(4.0),
        planner: Some(PlannerKind::Apf),
        mode: Some(ClockMode::Lockstep),
        ..Default::default()
    }
    .apply(&mut stack);
    assert_eq!((stack.ticks, stack.duration_s), (None, Some(4.0)));
    assert_eq!(stack.planner, PlannerKind::Apf);
    assert_eq!(stack.mode, ClockMode::Lockstep);
    assert_eq!(stack.estimator, EstimatorKind::Ekf);
}

fn temp_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("mole-launch-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

#[test]
fn data_paths_resolve_cwd_first_then_up_to_the_workspace_root() {
    let root = temp_dir("resolve");
    let ws = root.join("ws");
    std::fs::create_dir_all(ws.join("launch/stacks")).unwrap();
    std::fs::create_dir_all(ws.join("scenarios")).unwrap();
    std::fs::create_dir_all(root.join("elsewhere/scenarios")).unwrap();
    std::fs::write(ws.join("Cargo.toml"), "[workspace]\nmembers = []\n").unwrap();
    std::fs::write(ws.join("scenarios/a.toml"), "").unwrap();
    std::fs::write(root.join("elsewhere/scenarios/a.toml"), "").unwrap();
    std::fs::write(root.join("outside.toml"), "").unwrap();
    let launch = ws.join("launch/stacks/default.toml");
    let rel = Path::new("scenarios/a.toml");

    // From an unrelated directory: found by walking up from the launch file.
    let other = root.join("nowhere");
    std::fs::create_dir_all(&other).unwrap();
    assert_eq!(
        resolve_data_path("scenario", rel, &launch, &other).unwrap(),
        ws.join("scenarios/a.toml")
    );
    // The current directory wins.
    assert_eq!(
        resolve_data_path("scenario", rel, &launch, &root.join("elsewhere")).unwrap(),
        root.join("elsewhere/scenarios/a.toml")
    );
    // A relative launch file path resolves against cwd.
    assert_eq!(
        resolve_data_path("scenario", rel, Path::new("launch/stacks/x.toml"), &ws).unwrap(),
        ws.join("scenarios/a.toml")
    );
    // The walk stops at the workspace root.
    let e = resolve_data_path("scenario", Path::new("outside.toml"), &launch, &other).unwrap_err();
    let msg = e.to_string();
    assert!(
        msg.starts_with("scenario `outside.toml` not found (looked in: "),
        "{msg}"
    );
    assert!(msg.contains(&ws.display().to_string()), "{msg}");
    assert!(!msg.contains(&format!("{}, ", root.display())), "{msg}");
    assert_eq!(e.exit_code(), 2);
    let _ = std::fs::remove_dir_all(&root);
}

/// The shipped stacks run every role of the graph with its program, each restarted on failure
/// (the world too: it resumes from its last truth), the world started after every role that
/// reads what it writes, so no step goes unheard.
#[test]
fn shipped_stacks_are_the_graph() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("stacks");
    for (name, mode, ticks) in [
        ("default.toml", ClockMode::Realtime, 3000),
        ("lockstep.toml", ClockMode::Lockstep, 5000),
    ] {
        let lf = load_launch_file(&dir.join(name)).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(lf.stack.mode, mode);
        assert_eq!(lf.stack.ticks, Some(ticks));
        assert_eq!(lf.stack.rate_hz, 100.0);
        assert_eq!(lf.stack.planner, PlannerKind::RandomWalk);
        assert_eq!(lf.stack.estimator, EstimatorKind::Ekf);
        assert_eq!(
            lf.stack.scenario.as_deref(),
            Some(Path::new("scenarios/default.toml"))
        );
        let roles: Vec<&str> = GRAPH.iter().map(|r| r.role.name()).collect();
        assert_eq!(lf.roles(), roles, "{name}");
        for p in &lf.processes {
            let spec = mole_types::graph::spec(&p.role).expect("a graph role");
            assert_eq!(p.command, spec.program, "{name}");
            assert_eq!(
                p.restart.policy,
                RestartWhen::OnFailure,
                "{name}: {}",
                p.role
            );
            assert_eq!(p.restart.max, 5);
        }
        let order = crate::start_order(&lf.processes).unwrap();
        let started = |role: Role| {
            order
                .iter()
                .position(|&i| lf.processes[i].role == role.name())
                .unwrap()
        };
        let world = Role::World.spec();
        for reader in GRAPH.iter().filter(|r| r.role != Role::World) {
            if reader.inputs.iter().any(|t| world.outputs.contains(t)) {
                assert!(
                    started(reader.role) < started(Role::World),
                    "{name}: {}",
                    reader.role
                );
            }
        }
    }
}

/// A planner or estimator the stack does not have is refused naming every valid one.
#[test]
fn unknown_planner_and_estimator_name_the_choices() {
    let msg = err(&VALID.replace("\"random-walk\"", "\"teleport\""));
    assert_eq!(
        msg,
        "launch/stacks/x.toml:6:11: field `stack.planner`: unknown planner `teleport`, expected \
         one of: random-walk, apf, dwa, frontier"
    );
    let msg = err(&VALID.replace("\"ekf\"", "\"oracle\""));
    assert!(
        msg.contains("field `stack.estimator`: unknown estimator `oracle`"),
        "{msg}"
    );
    assert!(msg.ends_with(&EstimatorKind::NAMES.join(", ")), "{msg}");
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 512, ..ProptestConfig::default() })]

    #[test]
    fn random_text_never_panics(s in "\\PC{0,200}") {
        let _ = parse(&s);
    }

    /// Mutations of a valid file: delete, insert or replace a byte range.
    #[test]
    fn mutated_valid_file_never_panics(
        at in 0usize..VALID.len(),
        len in 0usize..12,
        insert in "[\\[\\]{}=\",.a-z0-9 \\n#'-]{0,6}",
    ) {
        let mut text: Vec<char> = VALID.chars().collect();
        let at = at.min(text.len());
        let end = (at + len).min(text.len());
        text.splice(at..end, insert.chars());
        let text: String = text.into_iter().collect();
        if let Err(e) = parse(&text) {
            let msg = e.to_string();
            prop_assert!(msg.starts_with("launch/stacks/x.toml:"), "{}", msg);
            prop_assert!(!msg.contains('\n'), "{}", msg);
            prop_assert_eq!(e.exit_code(), 2);
        }
    }
}

/// The two halves of launch/stacks/split are one stack: every role of the graph on exactly one
/// side, the same [stack] table, each side's bridge carrying in what the other carries out, and
/// every input a role reads from the other side's roles carried to it (derived from the graph).
#[test]
fn split_stacks_are_the_graph_carried_by_their_bridges() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("stacks/split");
    let on = load_launch_file(&dir.join("onboard.toml")).unwrap_or_else(|e| panic!("{e}"));
    let off = load_launch_file(&dir.join("offboard.toml")).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(on.stack, off.stack, "the halves run the same steps");
    let (on_bridge, off_bridge) = (on.bridge.clone().unwrap(), off.bridge.clone().unwrap());
    assert_eq!(on_bridge.out, off_bridge.inbound);
    assert_eq!(on_bridge.inbound, off_bridge.out);
    let graph_roles = |lf: &LaunchFile| -> Vec<Role> {
        lf.processes
            .iter()
            .filter_map(|p| p.role.parse::<Role>().ok())
            .collect()
    };
    let (on_roles, off_roles) = (graph_roles(&on), graph_roles(&off));
    for spec in GRAPH {
        assert!(
            on_roles.contains(&spec.role) != off_roles.contains(&spec.role),
            "{} runs on exactly one side",
            spec.role
        );
    }
    for (here, there, carried_in) in [
        (&on_roles, &off_roles, &on_bridge.inbound),
        (&off_roles, &on_roles, &off_bridge.inbound),
    ] {
        for role in here {
            for input in role.spec().inputs {
                let from_there = there.iter().any(|r| r.spec().outputs.contains(input));
                assert!(
                    !from_there || carried_in.iter().any(|t| t == input),
                    "{role} reads {input} from the other side: the bridge must carry it in"
                );
            }
        }
    }
}

/// A bad [bridge] table is refused naming the field and what was expected.
#[test]
fn bad_bridge_tables_name_the_field() {
    let bridge_process = "\n[[process]]\nrole = \"bridge\"\ncommand = \"mole-bridge\"\n";
    let with = |table: &str| format!("{VALID}{bridge_process}\n[bridge]\n{table}");
    let ok = parse(&with(
        "peer_namespace = \"b\"\nlisten = [\"tcp/127.0.0.1:7447\"]\nout = [\"world/truth\"]\nin = [\"planning/cmd\"]",
    ))
    .unwrap();
    assert_eq!(
        ok.bridge.unwrap().args(None),
        [
            "--peer-namespace",
            "b",
            "--out",
            "world/truth",
            "--in",
            "planning/cmd",
            "--listen",
            "tcp/127.0.0.1:7447"
        ]
    );
    for (table, field, expected) in [
        (
            "peer_namespace = \"b\"\nlisten = [\"tcp/127.0.0.1:7447\"]\nout = [\"world/truht\"]",
            "bridge.out[0]",
            "unknown topic `world/truht`",
        ),
        (
            "peer_namespace = \"b\"\nlisten = [\"tcp/127.0.0.1:7447\"]\nin = [\"stack/stats\"]",
            "bridge.in[0]",
            "per host",
        ),
        (
            "peer_namespace = \"b\"\nlisten = [\"udp/127.0.0.1:7447\"]",
            "bridge.listen[0]",
            "expected tcp/HOST:PORT or tls/HOST:PORT",
        ),
        (
            "peer_namespace = \"b\"",
            "bridge.listen",
            "expected at least one",
        ),
        (
            "peer_namespace = \"b\"\nlisten = [\"tls/127.0.0.1:7447\"]",
            "bridge.tls",
            "no TLS certificate",
        ),
        (
            "peer_namespace = \"b\"\nconnect = [\"tcp/10.0.0.2:0\"]",
            "bridge.connect",
            "port 0 is for listening",
        ),
        (
            "peer_namespace = \"b\"\nlisten = [\"tcp/127.0.0.1:0\", \"tcp/[::1]:0\"]",
            "bridge.listen",
            "expected at most one",
        ),
        (
            "peer_namespace = \"\"\nlisten = [\"tcp/127.0.0.1:7447\"]",
            "bridge.peer_namespace",
            "expected the namespace",
        ),
    ] {
        let msg = err(&with(table));
        assert!(
            msg.contains(field) && msg.contains(expected),
            "{table}: {msg}"
        );
    }
    assert!(err(&format!("{VALID}{bridge_process}")).contains("no [bridge] table"));
    assert!(
        err(&format!(
            "{VALID}\n[bridge]\npeer_namespace = \"b\"\nlisten = [\"tcp/127.0.0.1:7447\"]"
        ))
        .contains("no process with role = \"bridge\"")
    );
}

/// A role's settings tables are read, and an unknown key, a value of the wrong kind or out of
/// its bounds names the file, the line and the key.
#[test]
fn settings_tables_are_read_and_bad_ones_name_line_and_key() {
    let lf = parse(&format!(
        "{VALID}\n[planning.dwa.critics]\nheading = 0.4\n\n[localization.pf]\nn_particles = 2000\n\n[mapping]\ntouch_threshold = 1.5\n"
    ))
    .unwrap();
    assert_eq!(lf.settings.planning.dwa.critics.heading, 0.4);
    assert_eq!(lf.settings.localization.pf.n_particles, 2000);
    assert_eq!(lf.settings.mapping.touch_threshold, 1.5);
    assert_eq!(parse(VALID).unwrap().settings, StackSettings::default());

    // line 28 is the key's own line in each case below.
    let msg = err(&format!("{VALID}\n[planning.dwa]\nheading_weight = 0.4\n"));
    assert!(msg.starts_with("launch/stacks/x.toml:28:1:"), "{msg}");
    assert!(msg.contains("unknown field `heading_weight`"), "{msg}");
    let msg = err(&format!(
        "{VALID}\n[planning.dwa]\npredict_time = \"long\"\n"
    ));
    assert!(msg.starts_with("launch/stacks/x.toml:28:"), "{msg}");
    assert!(msg.contains("planning.dwa.predict_time"), "{msg}");
    assert!(msg.contains("invalid type"), "{msg}");
    let msg = err(&format!("{VALID}\n[localization.pf]\nn_particles = 0\n"));
    assert_eq!(
        msg,
        "launch/stacks/x.toml:28:15: field `localization.pf.n_particles`: 0 is out of bounds: \
         expected a value ≥ 1"
    );
}
