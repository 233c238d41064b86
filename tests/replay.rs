//! Replay, as a user runs it: a recorded lockstep run replayed with the world and sensing played
//! from the file gives the live roles' outputs again, byte for byte (`mole replay --check`); a
//! changed mapping parameter is caught at the tick where its output first differs; a window
//! ends where it is told; bad input is refused before anything starts.

use mole_integration_tests::*;
use mole_types::{Role, topics};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Output;
use std::time::Duration;

const RUN_TIMEOUT: Duration = Duration::from_secs(300);
/// Lockstep steps of the recorded run: in the dark room (touch alone, no lidar) with seed 1 the
/// robot first presses on an obstacle hard enough to mark the grids at tick 2,080.
const TICKS: &str = "3000";

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
    let (namespace, out) = (stack.namespace.clone(), stack.out.clone());
    let output = stack.wait(RUN_TIMEOUT);
    let _ = std::fs::remove_dir_all(&out);
    assert!(
        output.status.success(),
        "recording failed: {}",
        String::from_utf8_lossy(&output.stderr)
    );
    (file, namespace)
}

/// `mole replay FILE` into `namespace` and `out`, run to its end (for input it refuses).
fn replay_to_end(file: &Path, namespace: &str, out: &Path) -> Output {
    run_mole(&[
        "replay",
        &file.display().to_string(),
        "--namespace",
        namespace,
        "--quiet",
        "--out",
        &out.display().to_string(),
    ])
}

/// The samples of `topics` in a recording by (tick, topic), the first of each, with what two
/// runs of the same inputs may differ in zeroed (the docs' list: the header's `seq`, `stamp_ns`
/// and `origin_ns`, the pose's `update_ns`). Worked out here from the file, apart from the code
/// `--check` runs.
fn outputs(file: &Path, topics: &[&str]) -> BTreeMap<(u64, String), Vec<u8>> {
    use mole_types::{Header, Pose};
    let bytes = std::fs::read(file).expect("read a recording");
    let mut samples = BTreeMap::new();
    for message in mcap::MessageStream::new(&bytes).expect("an MCAP file") {
        let message = message.expect("a finished recording");
        let topic = message.channel.topic.as_str();
        if !topics.contains(&topic) {
            continue;
        }
        let mut data = message.data.into_owned();
        let header: Header = bytemuck::pod_read_unaligned(&data[..size_of::<Header>()]);
        let mut wall_clock = vec![
            std::mem::offset_of!(Header, seq),
            std::mem::offset_of!(Header, stamp_ns),
            std::mem::offset_of!(Header, origin_ns),
        ];
        if topic == topics::LOCALIZATION_POSE.name {
            wall_clock.push(std::mem::offset_of!(Pose, update_ns));
        }
        for at in wall_clock {
            data[at..at + 8].fill(0);
        }
        samples
            .entry((header.tick, topic.to_string()))
            .or_insert(data);
    }
    samples
}

/// The first tick before `last` at which a sample the recording holds is missing from the
/// replay or differs from it, with the topics that do.
fn first_difference(
    recorded: &BTreeMap<(u64, String), Vec<u8>>,
    replayed: &BTreeMap<(u64, String), Vec<u8>>,
    last: u64,
) -> Option<(u64, Vec<String>)> {
    let mut differing: BTreeMap<u64, Vec<String>> = BTreeMap::new();
    for ((tick, topic), data) in recorded {
        if *tick < last && replayed.get(&(*tick, topic.clone())) != Some(data) {
            differing.entry(*tick).or_default().push(topic.clone());
        }
    }
    differing.into_iter().next()
}

/// What `--check` compares: every output of the roles in the loop that the replay runs live.
fn live_outputs() -> Vec<&'static str> {
    let played = [Role::World, Role::Sensing];
    mole_types::GRAPH
        .iter()
        .filter(|spec| spec.in_loop && !played.contains(&spec.role))
        .flat_map(|spec| spec.outputs.iter().copied())
        .collect()
}

/// A copy of the recording `from` at `to`, written with the `mcap` crate: every message, the
/// schema names passed through `schema_name(topic, name)`, every metadata record through
/// `metadata`.
fn rewrite(
    from: &Path,
    to: &Path,
    schema_name: impl Fn(&str, &str) -> String,
    metadata: impl Fn(&mut mcap::records::Metadata),
) {
    let bytes = std::fs::read(from).expect("read the recording");
    let file = std::fs::File::create(to).expect("create the copy");
    let mut writer = mcap::WriteOptions::new()
        .profile("mole")
        .compression(Some(mcap::Compression::Lz4))
        .create(std::io::BufWriter::new(file))
        .expect("an MCAP writer");
    let mut channels = BTreeMap::new();
    for message in mcap::MessageStream::new(&bytes).expect("an MCAP file") {
        let mut message = message.expect("a finished recording");
        let channel = channels.entry(message.channel.id).or_insert_with(|| {
            let mut channel = (*message.channel).clone();
            if let Some(schema) = &channel.schema {
                let mut schema = (**schema).clone();
                schema.name = schema_name(&channel.topic, &schema.name);
                channel.schema = Some(std::sync::Arc::new(schema));
            }
            std::sync::Arc::new(channel)
        });
        message.channel = channel.clone();
        writer.write(&message).expect("write a message");
    }
    let summary = mcap::Summary::read(&bytes)
        .expect("a summary")
        .expect("a finished recording");
    for index in &summary.metadata_indexes {
        let mut record = mcap::read::metadata(&bytes, index).expect("a metadata record");
        metadata(&mut record);
        writer.write_metadata(&record).expect("write metadata");
    }
    writer.finish().expect("finish the copy");
}

/// Replayed with the world and sensing played from the file, localization, mapping and
/// planning publish exactly what they recorded, tick by tick; with a mapping parameter changed
/// (the touch threshold, through the environment) the check fails at the first tick where the
/// replay's outputs differ from the recording's (found here from both files), naming a mapping
/// topic and field; `--to` ends the run at its tick. A real recording cut short, of other
/// message layouts, without its launch file or scenario, or replayed into a namespace in use,
/// is refused.
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
    let said = output_text(&output);
    assert!(output.status.success(), "{said}\n{}", logs(&out));
    assert!(said.contains("check: identical"), "{said}");
    let replayed = summary(&out);
    assert_eq!(replayed.ticks.to_string(), TICKS, "{replayed:#?}");
    assert_eq!(replayed.exit_reason, "ticks");

    let numb = ["--check", "--set", "mapping.touch_threshold=1e9"];
    let changed = Replay::start(&dir.0, &file, &numb, &[]);
    namespaces.push(changed.namespace.clone());
    let replayed = changed.out.join("replay/replayed.mcap");
    let changed_out = changed.out.clone();
    let changed = changed.wait();
    let said = output_text(&changed);
    assert_eq!(changed.status.code(), Some(1), "{said}");
    // The setting in force is the one given, in summary.json.
    let settings = &summary(&changed_out).settings;
    assert_eq!(settings["mapping"]["touch_threshold"], 1e9, "{settings}");
    let failure = said
        .lines()
        .find(|l| l.starts_with("error: check failed: tick "))
        .unwrap_or_else(|| panic!("no check failure in:\n{said}"));
    assert!(failure.contains(": mapping/"), "{failure}");
    assert!(failure.contains("differs in field `"), "{failure}");
    // The tick it names is the first at which the replay's own recording differs.
    let compared = live_outputs();
    let last: u64 = TICKS.parse().expect("a tick count");
    let (tick, differing) = first_difference(
        &outputs(&file, &compared),
        &outputs(&replayed, &compared),
        last,
    )
    .unwrap_or_else(|| panic!("the replay differs nowhere, yet: {failure}"));
    let named = failure
        .strip_prefix(&format!("error: check failed: tick {tick}: "))
        .unwrap_or_else(|| {
            panic!("the first difference is at tick {tick} ({differing:?}): {failure}")
        });
    assert!(
        differing
            .iter()
            .any(|topic| named.starts_with(&format!("{topic} "))),
        "at tick {tick} {differing:?} differ: {failure}"
    );

    let window = Replay::start(&dir.0, &file, &["--to", "120"], &[]);
    namespaces.push(window.namespace.clone());
    let out = window.out.clone();
    let output = window.wait();
    assert!(output.status.success(), "{}", output_text(&output));
    let cut = summary(&out);
    assert_eq!((cut.ticks, cut.exit_reason.as_str()), (120, "ticks"));
    for namespace in &namespaces {
        assert_eq!(records_of(namespace), Vec::<String>::new(), "{namespace}");
    }

    // Bad input with a real recording: cut short, of other layouts, without its launch file or
    // scenario, or into a namespace a stack is running in; each refused with exit 2, naming what is wrong,
    // and nothing of its own started.
    let cut = dir.0.join("cut.mcap");
    let bytes = std::fs::read(&file).expect("read the recording");
    std::fs::write(&cut, &bytes[..bytes.len() / 2]).expect("write a truncated copy");
    let output = run_mole(&["replay", &cut.display().to_string(), "--quiet"]);
    let said = output_text(&output);
    assert_eq!(output.status.code(), Some(2), "{said}");
    assert!(said.contains(&cut.display().to_string()), "{said}");
    assert!(said.contains("truncated"), "{said}");

    // Made from the real recording with the `mcap` crate: the truth of another layout, and the
    // launch file or the scenario left out (`mole record`, attached to a running stack, knows
    // neither).
    let other_layouts = dir.0.join("other-layouts.mcap");
    rewrite(
        &file,
        &other_layouts,
        |topic, name| match topic == topics::WORLD_TRUTH.name {
            true => name.replace(".v1", ".v0"),
            false => name.to_string(),
        },
        |_| {},
    );
    let without = |fact: &str| {
        let copy = dir.0.join(format!("no-{fact}.mcap"));
        rewrite(
            &file,
            &copy,
            |_, name| name.to_string(),
            |record| {
                record.metadata.remove(fact);
                record.metadata.remove(&format!("{fact}_path"));
            },
        );
        copy
    };
    let (no_launch_file, no_scenario) = (without("launch_file"), without("scenario"));
    for (copy, why) in [
        (
            &other_layouts,
            "recorded with other message layouts: `world/truth` holds `mole.Truth.v0`, this \
             build reads `mole.Truth.v1`",
        ),
        (
            &no_launch_file,
            "the recording does not hold its launch file",
        ),
        (&no_scenario, "the recording does not hold its scenario"),
    ] {
        let namespace = unique_namespace("replay-refused");
        let out = dir.0.join(&namespace);
        let output = replay_to_end(copy, &namespace, &out);
        let said = output_text(&output);
        assert_eq!(output.status.code(), Some(2), "{said}");
        assert!(
            said.contains(&format!("{}: {why}", copy.display())),
            "{said}"
        );
        assert!(!out.exists(), "nothing started, nothing written: {said}");
        assert_eq!(records_of(&namespace), Vec::<String>::new());
    }

    let busy = Stack::start("replay-busy", &["--mode", "realtime", "--ticks", "100000"]);
    busy.wait_for_log(Role::World.name(), "ready", Duration::from_secs(60));
    let running = processes_of(&busy.namespace);
    let out = dir.0.join("into-busy");
    let output = replay_to_end(&file, &busy.namespace, &out);
    let said = output_text(&output);
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
    let out = busy.out.clone();
    drop(busy);
    let _ = std::fs::remove_dir_all(&out);
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
        let said = output_text(&output);
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
    let said = output_text(&output);
    assert_eq!(output.status.code(), Some(2), "{said}");
    assert!(said.contains("unknown role `sensors`"), "{said}");
}
