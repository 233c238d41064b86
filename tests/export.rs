//! `mole export FILE OUT --foxglove`, as a user runs it: a recorded lockstep run exported with
//! Foxglove's well-known schemas reads back, with the `mcap` package from PyPI, as the run the
//! stack published; what is not a recording is refused.

use mole_integration_tests::*;
use mole_types::{Grid, Truth, topics};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

const RUN_TIMEOUT: Duration = Duration::from_secs(240);
/// The tick whose truth is compared.
const TICK: u64 = 150;

/// A directory of the test's own, removed whatever happens.
struct Kept(PathBuf);
impl Drop for Kept {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// A recorded lockstep run of `ticks` steps that must succeed: the directory it left, with the
/// recording `run.mcap` in it.
fn recorded_lockstep_run(test: &str, ticks: u64) -> Kept {
    let namespace = unique_namespace(test);
    let out = std::env::temp_dir().join(format!("mole-{namespace}"));
    let file = out.join("run.mcap").display().to_string();
    let ticks = ticks.to_string();
    let args = ["--mode", "lockstep", "--ticks", &ticks, "--seed", "5"];
    let args: Vec<&str> = args.iter().copied().chain(["--record", &file]).collect();
    let stack = Stack::start_in(&namespace, &args);
    let kept = Kept(out.with_extension("kept"));
    let output = stack.wait_and_copy(&kept.0, RUN_TIMEOUT);
    assert!(
        output.status.success(),
        "mole up failed: {}\n{}",
        String::from_utf8_lossy(&output.stderr),
        logs(&kept.0)
    );
    assert!(processes_of(&namespace).is_empty(), "processes left behind");
    kept
}

/// Every message of `topic` in the recording at `path`, as (log time, bytes).
fn recorded(path: &Path, topic: &str) -> Vec<(u64, Vec<u8>)> {
    let bytes = std::fs::read(path).expect("read the recording");
    mcap::MessageStream::new(&bytes)
        .expect("an MCAP file")
        .map(|m| m.expect("a complete recording"))
        .filter(|m| m.channel.topic == topic)
        .map(|m| (m.log_time, m.data.into_owned()))
        .collect()
}

/// Reads the export `argv[1]` knowing only Foxglove's schemas: every channel's schema name and
/// encodings, the `/truth` pose at log time `argv[2]` (x, y and the yaw of its quaternion) and
/// the last `/grid`'s columns and rows (its base64 data's length over the row stride).
const READ_EXPORT: &str = r#"
import base64, json, math, sys
from mcap.reader import make_reader

path, at = sys.argv[1], int(sys.argv[2])
channels, truth, grid = {}, None, None
with open(path, "rb") as f:
    for schema, channel, message in make_reader(f).iter_messages():
        channels[channel.topic] = [schema.name, schema.encoding, channel.message_encoding]
        value = json.loads(message.data)
        if channel.topic == "/truth" and message.log_time == at:
            p, q = value["pose"]["position"], value["pose"]["orientation"]
            yaw = math.atan2(2 * (q["w"] * q["z"] + q["x"] * q["y"]),
                             1 - 2 * (q["y"] ** 2 + q["z"] ** 2))
            truth = {"x": repr(p["x"]), "y": repr(p["y"]), "yaw": repr(yaw),
                     "frame_id": value["frame_id"]}
        if channel.topic == "/grid":
            data = base64.b64decode(value["data"])
            grid = {"columns": value["column_count"], "rows": len(data) // value["row_stride"]}
print(json.dumps({"channels": channels, "truth": truth, "grid": grid}))
"#;

/// A recorded run exported with `mole export --foxglove` holds only `foxglove.*` JSON channels;
/// the `mcap` package from PyPI finds in it the recorded truth of a tick (x, y and the yaw of
/// its quaternion) and a grid of the recorded width × height.
#[test]
fn an_exported_recording_reads_back_as_the_recorded_run() {
    let test = "an_exported_recording_reads_back_as_the_recorded_run";
    let python = match python_with_mcap() {
        Ok(python) => python,
        Err(reason) => return skip(test, &reason),
    };
    let _serial = serial();
    let run = recorded_lockstep_run("export", 200);
    let (recording, export) = (run.0.join("run.mcap"), run.0.join("foxglove.mcap"));
    let output = run_mole(&[
        "export",
        &recording.display().to_string(),
        &export.display().to_string(),
        "--foxglove",
    ]);
    assert!(
        output.status.success(),
        "mole export failed: {}",
        String::from_utf8_lossy(&output.stderr)
    );

    let (at, truth) = recorded(&recording, topics::WORLD_TRUTH.name)
        .into_iter()
        .map(|(time, data)| (time, bytemuck::pod_read_unaligned::<Truth>(&data)))
        .find(|(_, t)| t.header.tick == TICK)
        .expect("the recorded truth of the tick");
    let (_, last_grid) = recorded(&recording, topics::MAPPING_GRID.name)
        .pop()
        .expect("a recorded grid");
    let grid = bytemuck::pod_read_unaligned::<Grid>(&last_grid);

    let read = Command::new(&python)
        .args([
            "-c",
            READ_EXPORT,
            &export.display().to_string(),
            &at.to_string(),
        ])
        .output()
        .expect("run python");
    let stdout = String::from_utf8_lossy(&read.stdout);
    assert!(
        read.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&read.stderr)
    );
    let decoded: serde_json::Value = serde_json::from_str(stdout.trim())
        .unwrap_or_else(|e| panic!("python printed no JSON ({e}): {stdout}"));

    let channels = decoded["channels"].as_object().expect("channels");
    for wanted in ["/truth", "/pose", "/scan", "/grid", "/map", "/path"] {
        assert!(channels.contains_key(wanted), "no {wanted} in {channels:?}");
    }
    for (topic, encodings) in channels {
        let name = encodings[0].as_str().unwrap_or_default();
        assert!(name.starts_with("foxglove."), "{topic}: schema {name}");
        assert_eq!(encodings[1], "jsonschema", "{topic}");
        assert_eq!(encodings[2], "json", "{topic}");
    }

    let exported = &decoded["truth"];
    assert_eq!(exported["frame_id"], "map", "{decoded}");
    let number = |field: &str| -> f64 {
        let text = exported[field].as_str().unwrap_or_default();
        text.parse()
            .unwrap_or_else(|_| panic!("{field}: `{text}` is not a number: {decoded}"))
    };
    assert_eq!(number("x"), truth.x);
    assert_eq!(number("y"), truth.y);
    let yaw_error = (number("yaw") - truth.theta).sin().abs();
    assert!(
        yaw_error < 1e-9,
        "yaw {} against θ {}",
        number("yaw"),
        truth.theta
    );
    assert!(truth.x != 0.0 || truth.y != 0.0, "a real pose: {truth:?}");

    let columns = decoded["grid"]["columns"].as_u64().expect("a grid");
    let rows = decoded["grid"]["rows"].as_u64().expect("a grid");
    assert_eq!(columns, u64::from(grid.width));
    assert_eq!(
        columns * rows,
        u64::from(grid.width) * u64::from(grid.height)
    );
}

/// `mole export` refuses a file that is not a recording: exit 2, a message naming the file and
/// what was expected, no output file.
#[test]
fn a_file_that_is_not_a_recording_is_refused() {
    let dir = Kept(std::env::temp_dir().join(format!("mole-export-bad-{}", std::process::id())));
    std::fs::create_dir_all(&dir.0).expect("a directory");
    let (garbage, out) = (dir.0.join("notes.mcap"), dir.0.join("out.mcap"));
    std::fs::write(&garbage, "shopping list: bolts, wheels").expect("write");
    let garbage_path = garbage.display().to_string();
    let output = run_mole(&[
        "export",
        &garbage_path,
        &out.display().to_string(),
        "--foxglove",
    ]);
    let error = String::from_utf8_lossy(&output.stderr);
    assert_eq!(output.status.code(), Some(2), "{error}");
    assert!(error.contains(&garbage_path), "{error}");
    assert!(error.contains("not an MCAP file"), "{error}");
    assert!(error.contains("expected a recording"), "{error}");
    assert!(!out.exists(), "an output file was left");
}
