//! Replay, as a user runs it: a recorded lockstep run replayed with the world and sensing played
//! from the file gives the live roles' outputs again, byte for byte (`mole replay --check`); a
//! changed mapping parameter is caught at the tick where its output first differs; a window
//! ends where it is told; bad input is refused before anything starts.

use mole_integration_tests::*;
use mole_types::Role;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

const RUN_TIMEOUT: Duration = Duration::from_secs(300);
/// Lockstep steps of the recorded run: in the dark room (touch alone, no lidar) with seed 1 the
/// robot first presses on an obstacle hard enough to mark the grids at tick 2,080.
const TICKS: &str = "3000";

/// A running `mole replay`; on drop (a failed test included) it and every process of its
/// namespace are stopped.
struct Replay {
    namespace: String,
    out: PathBuf,
    child: Option<Child>,
}

impl Replay {
    /// `mole replay FILE` with `args` in a fresh namespace, its output under `dir`; `env` is
    /// added to its environment (and so to every process it starts).
    fn start(dir: &Path, file: &Path, args: &[&str], env: &[(&str, &str)]) -> Replay {
        let namespace = unique_namespace("replay");
        let out = dir.join(&namespace);
        let child = Command::new(bin_dir().join("mole"))
            .current_dir(workspace())
            .env_remove("CARGO")
            .env_remove("CARGO_MANIFEST_DIR")
            .envs(env.iter().copied())
            .arg("replay")
            .arg(file)
            .args(args)
            .args(["--namespace", &namespace, "--quiet", "--out"])
            .arg(&out)
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("start mole replay");
        Replay {
            namespace,
            out,
            child: Some(child),
        }
    }

    /// Waits for `mole replay` to exit (killing it after [`RUN_TIMEOUT`]); nothing of its
    /// namespace may be left running.
    fn wait(mut self) -> Output {
        let mut child = self.child.take().expect("running");
        let deadline = Instant::now() + RUN_TIMEOUT;
        while child.try_wait().ok().flatten().is_none() {
            assert!(
                Instant::now() < deadline,
                "mole replay did not finish within {RUN_TIMEOUT:?}\n{}",
                logs(&self.out)
            );
            std::thread::sleep(Duration::from_millis(50));
        }
        let output = child.wait_with_output().expect("collect output");
        assert!(
            processes_of(&self.namespace).is_empty(),
            "processes left behind\n{}",
            logs(&self.out)
        );
        output
    }
}

impl Drop for Replay {
    fn drop(&mut self) {
        stop_and_clean(self.child.take(), &self.namespace);
    }
}

/// iceoryx2's node and service records that name `namespace`: what its stack left behind (told
/// by name, so that stacks of others on the same machine do not count).
fn records_of(namespace: &str) -> Vec<String> {
    let needle = format!("\"mole/{namespace}/");
    let mut files = Vec::new();
    let nodes = std::fs::read_dir("/tmp/iceoryx2/nodes")
        .into_iter()
        .flatten();
    for node in nodes.flatten() {
        files.push(node.path().join("iox2_node.details"));
    }
    let services = std::fs::read_dir("/tmp/iceoryx2/services")
        .into_iter()
        .flatten();
    files.extend(services.flatten().map(|e| e.path()));
    files
        .into_iter()
        .filter(|f| std::fs::read_to_string(f).is_ok_and(|t| t.contains(&needle)))
        .map(|f| f.display().to_string())
        .collect()
}

/// Records a lockstep run of the dark room into `dir/run.mcap`; returns it and the namespace.
fn record(dir: &Path) -> (PathBuf, String) {
    let file = dir.join("run.mcap");
    let path = file.display().to_string();
    let stack = Stack::start(
        "replay-rec",
        &[
            "launch/stacks/lockstep.toml",
            "--scenario",
            "scenarios/dark_room.toml",
            "--ticks",
            TICKS,
            "--seed",
            "1",
            "--record",
            &path,
        ],
    );
    let namespace = stack.namespace.clone();
    let output = stack.wait(RUN_TIMEOUT);
    assert!(
        output.status.success(),
        "recording failed: {}",
        String::from_utf8_lossy(&output.stderr)
    );
    (file, namespace)
}

fn text(output: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&output.stdout),
        String::from_utf8_lossy(&output.stderr)
    )
}

/// Replayed with the world and sensing played from the file, localization, mapping and
/// planning publish exactly what they recorded, tick by tick; with a mapping parameter changed
/// (the touch threshold, through the environment) the check fails at the tick where mapping's
/// output first differs, naming its topic and field; `--to` ends the run at its tick.
#[test]
fn a_replayed_lockstep_run_publishes_what_it_recorded() {
    let _serial = serial();
    assert!(
        bin_dir().join("mole-player").exists(),
        "mole-player is not built"
    );
    let dir = TempDir::new("replay");
    let (file, recorded) = record(&dir.0);
    let mut namespaces = vec![recorded];

    let same = Replay::start(&dir.0, &file, &["--check"], &[]);
    namespaces.push(same.namespace.clone());
    let out = same.out.clone();
    let output = same.wait();
    let said = text(&output);
    assert!(output.status.success(), "{said}\n{}", logs(&out));
    assert!(said.contains("check: identical"), "{said}");
    let replayed = summary(&out);
    assert_eq!(replayed.ticks.to_string(), TICKS, "{replayed:#?}");
    assert_eq!(replayed.exit_reason, "ticks");

    let numb = [(mole_types::env::TOUCH_THRESHOLD, "1e9")];
    let changed = Replay::start(&dir.0, &file, &["--check"], &numb);
    namespaces.push(changed.namespace.clone());
    let changed = changed.wait();
    let said = text(&changed);
    assert_eq!(changed.status.code(), Some(1), "{said}");
    let failure = said
        .lines()
        .find(|l| l.starts_with("error: check failed: tick "))
        .unwrap_or_else(|| panic!("no check failure in:\n{said}"));
    assert!(failure.contains(": mapping/"), "{failure}");
    assert!(failure.contains("differs in field `"), "{failure}");

    let window = Replay::start(&dir.0, &file, &["--to", "120"], &[]);
    namespaces.push(window.namespace.clone());
    let out = window.out.clone();
    let output = window.wait();
    assert!(output.status.success(), "{}", text(&output));
    let cut = summary(&out);
    assert_eq!((cut.ticks, cut.exit_reason.as_str()), (120, "ticks"));
    for namespace in &namespaces {
        assert_eq!(records_of(namespace), Vec::<String>::new(), "{namespace}");
    }

    // Bad input with a real recording: cut short, or into a namespace a stack is running in;
    // each refused with exit 2, naming what is wrong, and nothing of its own started.
    let cut = dir.0.join("cut.mcap");
    let bytes = std::fs::read(&file).expect("read the recording");
    std::fs::write(&cut, &bytes[..bytes.len() / 2]).expect("write a truncated copy");
    let output = run_mole(&["replay", &cut.display().to_string(), "--quiet"]);
    let said = text(&output);
    assert_eq!(output.status.code(), Some(2), "{said}");
    assert!(said.contains(&cut.display().to_string()), "{said}");
    assert!(said.contains("truncated"), "{said}");

    let busy = Stack::start("replay-busy", &["--mode", "realtime", "--ticks", "100000"]);
    busy.wait_for_log(Role::World.name(), "ready", Duration::from_secs(60));
    let running = processes_of(&busy.namespace);
    let out = dir.0.join("into-busy");
    let output = run_mole(&[
        "replay",
        &file.display().to_string(),
        "--namespace",
        &busy.namespace,
        "--quiet",
        "--out",
        &out.display().to_string(),
    ]);
    let said = text(&output);
    assert_eq!(output.status.code(), Some(2), "{said}");
    assert!(
        said.contains(&busy.namespace) && said.contains("in use"),
        "{said}"
    );
    assert_eq!(
        processes_of(&busy.namespace),
        running,
        "a replay process started"
    );
}

/// A file that is not there, a file that is not a recording and a role the graph does not have
/// are refused with exit 2, naming what is wrong, before anything starts.
#[test]
fn bad_files_and_unknown_roles_are_refused_naming_them() {
    let dir = TempDir::new("replay-bad");
    let missing = dir.0.join("no-such.mcap");
    let garbage = dir.0.join("garbage.mcap");
    std::fs::write(&garbage, b"not a recording").unwrap();
    for (file, why) in [(&missing, "No such file"), (&garbage, "not an MCAP file")] {
        let output = run_mole(&["replay", &file.display().to_string()]);
        let said = text(&output);
        assert_eq!(output.status.code(), Some(2), "{said}");
        assert!(said.contains(&file.display().to_string()), "{said}");
        assert!(said.contains(why), "{said}");
    }
    let output = run_mole(&[
        "replay",
        &garbage.display().to_string(),
        "--replace",
        "world,sensors",
    ]);
    let said = text(&output);
    assert_eq!(output.status.code(), Some(2), "{said}");
    assert!(said.contains("unknown role `sensors`"), "{said}");
}
