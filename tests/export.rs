//! `mole export FILE OUT --foxglove`, as a user runs it: a recorded lockstep run exported with
//! Foxglove's well-known schemas reads back, with the `mcap` package from PyPI, as the run the
//! stack published; every exported message of a particle filter's and of an EKF-SLAM run is
//! valid against Foxglove's published schemas (`@foxglove/schemas`, with ajv), which the file
//! holds; what is not a recording is refused.

use mole_integration_tests::*;
use mole_types::{
    Cmd, EstimatorKind, Grid, Landmarks, Odom, Particles, Pose, Scan, Truth, WorldMap, topics,
};
use std::collections::BTreeMap;
use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

/// The tick whose truth is compared.
const TICK: u64 = 150;

/// Every message of `topic` in the recording at `path`, as (log time, bytes).
fn recorded(path: &Path, topic: &str) -> Vec<(u64, Vec<u8>)> {
    mcap_messages(path, topic)
}

/// Exports the recording `run.mcap` of `run` into `foxglove.mcap` beside it with `mole export
/// --foxglove`, which must succeed: (recording, export).
fn exported(run: &TempDir) -> (PathBuf, PathBuf) {
    exported_as(run, "--foxglove")
}

/// As [`exported`], with `mole export`'s `target` (`--foxglove`, `--ros2`), into `<target>.mcap`.
fn exported_as(run: &TempDir, target: &str) -> (PathBuf, PathBuf) {
    let name = format!("{}.mcap", target.trim_start_matches('-'));
    let (recording, export) = (run.0.join("run.mcap"), run.0.join(name));
    let output = run_mole(&[
        "export",
        &recording.display().to_string(),
        &export.display().to_string(),
        target,
    ]);
    assert!(
        output.status.success(),
        "mole export failed: {}",
        String::from_utf8_lossy(&output.stderr)
    );
    (recording, export)
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
    let run = recorded_lockstep_run("export", 200, &[]);
    let (recording, export) = exported(&run);

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

/// Each channel an export writes and its schema (docs/recording.md's table).
const EXPORTED_CHANNELS: [(&str, &str); 11] = [
    ("/truth", "foxglove.PoseInFrame"),
    ("/tf", "foxglove.FrameTransform"),
    ("/pose", "foxglove.PoseInFrame"),
    ("/pose/ellipse", "foxglove.SceneUpdate"),
    ("/scan", "foxglove.LaserScan"),
    ("/grid", "foxglove.Grid"),
    ("/contact", "foxglove.Grid"),
    ("/map", "foxglove.SceneUpdate"),
    ("/path", "foxglove.SceneUpdate"),
    ("/particles", "foxglove.SceneUpdate"),
    ("/landmarks", "foxglove.SceneUpdate"),
];

/// The validator's input for the export at `path`: each channel (its schema name, encodings and
/// schema text) before its first message, then every message with its index on its channel;
/// and each channel's schema name and count of messages.
fn validator_input(path: &Path) -> (Vec<u8>, BTreeMap<String, (String, u64)>) {
    let bytes = std::fs::read(path).expect("read the export");
    let (mut input, mut counts) = (Vec::new(), BTreeMap::<String, (String, u64)>::new());
    for message in mcap::MessageStream::new(&bytes).expect("an MCAP file") {
        let message = message.expect("a complete export");
        let channel = &message.channel;
        let schema = channel.schema.as_ref().expect("every channel has a schema");
        let index = counts.get(&channel.topic).map(|(_, n)| *n);
        if index.is_none() {
            let line = serde_json::json!({
                "channel": channel.topic, "schema_name": schema.name,
                "schema_encoding": schema.encoding, "message_encoding": channel.message_encoding,
                "schema": String::from_utf8_lossy(&schema.data),
            });
            writeln!(input, "{line}").expect("a line");
        }
        let line = serde_json::json!({
            "channel": channel.topic, "index": index.unwrap_or(0),
            "data": String::from_utf8_lossy(&message.data),
        });
        writeln!(input, "{line}").expect("a line");
        counts
            .entry(channel.topic.clone())
            .or_insert_with(|| (schema.name.clone(), 0))
            .1 += 1;
    }
    (input, counts)
}

/// Every message of an export — of a particle filter's run and of an EKF-SLAM run, frontier
/// exploration both, so that every channel is written — is valid against the published schema
/// of its channel's schema name (`@foxglove/schemas` with ajv), and every schema the file holds
/// is the published one. Failures name the channel, the message's index on it and ajv's error.
#[test]
fn every_exported_message_is_valid_against_foxgloves_published_schemas() {
    let test = "every_exported_message_is_valid_against_foxgloves_published_schemas";
    if let Err(reason) = foxglove_validator() {
        return skip(test, &reason);
    }
    let _serial = serial();
    let mut seen = BTreeMap::new();
    for (estimator, ticks) in [(EstimatorKind::Pf, 300), (EstimatorKind::EkfSlam, 150)] {
        let args = ["--estimator", estimator.name(), "--planner", "frontier"];
        let run = recorded_lockstep_run(&format!("export-valid-{estimator}"), ticks, &args);
        let (_, export) = exported(&run);
        let (input, counts) = validator_input(&export);
        let mut node = foxglove_validator()
            .expect("the validator ran a moment ago")
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("start node");
        let mut stdin = node.stdin.take().expect("stdin");
        let feeder = std::thread::spawn(move || stdin.write_all(&input));
        let output = node.wait_with_output().expect("node ran");
        feeder
            .join()
            .expect("the feeder")
            .expect("node read its input");
        let stdout = String::from_utf8_lossy(&output.stdout);
        assert!(
            output.status.success(),
            "{estimator}: the validator failed: {stdout}\n{}",
            String::from_utf8_lossy(&output.stderr)
        );
        let report: serde_json::Value = serde_json::from_str(stdout.trim())
            .unwrap_or_else(|e| panic!("the validator printed no JSON ({e}): {stdout}"));
        let failed: u64 = report["failed"]
            .as_object()
            .expect("failed")
            .values()
            .filter_map(serde_json::Value::as_u64)
            .sum();
        assert_eq!(
            (failed, &report["failures"]),
            (0, &serde_json::json!([])),
            "{estimator}: messages that are not valid (channel, index, ajv's errors), of {counts:?}: {:#}",
            report["failures"]
        );
        for (channel, (schema, count)) in counts {
            assert_eq!(
                report["schemas"][&channel], "published",
                "{estimator}: {channel}: {}",
                report["schemas"]
            );
            assert_eq!(
                report["validated"][&channel], count,
                "{estimator}: {channel}"
            );
            seen.insert(channel, schema);
        }
    }
    let expected: BTreeMap<String, String> = EXPORTED_CHANNELS
        .iter()
        .map(|(c, s)| (c.to_string(), s.to_string()))
        .collect();
    assert_eq!(seen, expected, "the channels of the two exports");
}

/// `mole export` refuses a file that is not a recording: exit 2, a message naming the file and
/// what was expected, no output file.
#[test]
fn a_file_that_is_not_a_recording_is_refused() {
    let dir = TempDir(std::env::temp_dir().join(format!("mole-export-bad-{}", std::process::id())));
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

/// Reads the ROS 2 export `argv[1]` knowing only ROS 2's message definitions, through
/// mcap-ros2-support's CDR decoder: the file's profile, every channel's schema, encodings, QoS
/// metadata and message count, what each stamped channel holds at the stamp `argv[2]`.`argv[3]`,
/// every `/cmd_vel`, the `/tf` frame pairs, the last `/map` and the last `/landmarks`.
const READ_ROS2: &str = r#"
import json, math, sys
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

path, sec, nsec = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
r = repr
def yaw(q):
    return math.atan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y ** 2 + q.z ** 2))
def planar(p):
    return [r(p.position.x), r(p.position.y), r(yaw(p.orientation))]
channels, at, cmds, frames, grid, markers = {}, {}, [], set(), None, None
with open(path, "rb") as f:
    reader = make_reader(f, decoder_factories=[DecoderFactory()])
    profile = reader.get_header().profile
    for schema, channel, message, m in reader.iter_decoded_messages():
        t = channel.topic
        seen = channels.setdefault(t, [schema.name, schema.encoding, channel.message_encoding,
                                       "offered_qos_profiles" in channel.metadata, 0])
        seen[4] += 1
        if t == "/cmd_vel":
            cmds.append([r(m.linear.x), r(m.angular.z)])
            continue
        if t == "/tf":
            for tr in m.transforms:
                frames.add(tr.header.frame_id + ">" + tr.child_frame_id)
                s = tr.header.stamp
                if (s.sec, s.nanosec) == (sec, nsec) and tr.child_frame_id == "base_link":
                    v = tr.transform.translation
                    at["/tf"] = [r(v.x), r(v.y), r(yaw(tr.transform.rotation))]
            continue
        if t == "/map":
            counts = {str(v): list(m.data).count(v) for v in (-1, 0, 100)}
            grid = [m.info.width, m.info.height, r(m.info.resolution), counts]
        if t == "/landmarks":
            markers = [[k.action, k.id, r(k.pose.position.x), r(k.pose.position.y)]
                       for k in m.markers]
            continue
        s = m.header.stamp
        if (s.sec, s.nanosec) != (sec, nsec):
            continue
        if t == "/truth":
            at[t] = planar(m.pose) + [m.header.frame_id]
        elif t == "/pose":
            at[t] = planar(m.pose.pose) + [[r(c) for c in m.pose.covariance]]
        elif t == "/odom":
            tw = m.twist.twist
            at[t] = planar(m.pose.pose) + [r(tw.linear.x), r(tw.angular.z), m.header.frame_id,
                                           m.child_frame_id]
        elif t == "/scan":
            at[t] = [r(m.angle_min), r(m.angle_increment), r(m.range_max),
                     [r(x) for x in m.ranges]]
        elif t == "/particles":
            at[t] = [len(m.poses)] + planar(m.poses[0])
print(json.dumps({"profile": profile, "channels": channels, "at": at, "cmds": cmds,
                  "frames": sorted(frames), "grid": grid, "markers": markers}))
"#;

/// The newest recorded sample of `topic` at `tick`, as its message.
fn at_tick<M: bytemuck::Pod + mole_types::Message>(path: &Path, topic: &str, tick: u64) -> M {
    recorded(path, topic)
        .into_iter()
        .map(|(_, data)| bytemuck::pod_read_unaligned::<M>(&data))
        .find(|m| m.header().tick == tick)
        .unwrap_or_else(|| panic!("no recorded {topic} at {tick}"))
}

/// A recorded run exported with `mole export --ros2` is a ROS 2 bag that mcap-ros2-support
/// decodes in full: the `ros2` profile, `ros2msg` schemas with the QoS rosbag2 needs, CDR
/// messages stamped with the simulated time of their step, holding the recorded values (the
/// truth, the estimate and its covariance, odometry and its transform, every range of the scan,
/// every command, the particles, the landmarks and the last frontier grid, cell by cell).
#[test]
fn a_ros2_export_decodes_with_the_recorded_values() {
    let test = "a_ros2_export_decodes_with_the_recorded_values";
    let python = match python_with_mcap_ros2() {
        Ok(python) => python,
        Err(reason) => return skip(test, &reason),
    };
    let _serial = serial();
    for estimator in [EstimatorKind::Pf, EstimatorKind::EkfSlam] {
        let args = ["--estimator", estimator.name(), "--planner", "frontier"];
        let run = recorded_lockstep_run(&format!("export-ros2-{estimator}"), 200, &args);
        let (recording, export) = exported_as(&run, "--ros2");
        let (_, map) = recorded(&recording, topics::WORLD_MAP.name).remove(0);
        let dt_ns = (bytemuck::pod_read_unaligned::<WorldMap>(&map).dt * 1e9).round() as u64;
        let ns = TICK * dt_ns;
        let read = Command::new(&python)
            .args(["-c", READ_ROS2, &export.display().to_string()])
            .args([
                (ns / 1_000_000_000).to_string(),
                (ns % 1_000_000_000).to_string(),
            ])
            .output()
            .expect("run python");
        let stdout = String::from_utf8_lossy(&read.stdout);
        assert!(
            read.status.success(),
            "{estimator}: {stdout}\n{}",
            String::from_utf8_lossy(&read.stderr)
        );
        let d: serde_json::Value = serde_json::from_str(stdout.trim())
            .unwrap_or_else(|e| panic!("python printed no JSON ({e}): {stdout}"));
        let at = &d["at"];
        let number = |v: &serde_json::Value| -> f64 {
            let text = v.as_str().unwrap_or_default();
            text.parse()
                .unwrap_or_else(|_| panic!("`{text}` is not a number: {d}"))
        };
        let same_yaw = |a: f64, b: f64| (a - b).sin().abs() < 1e-9;

        assert_eq!(d["profile"], "ros2");
        let count = |topic: &str| recorded(&recording, topic).len() as u64;
        let channels = d["channels"].as_object().expect("channels");
        for (channel, ty, n) in [
            (
                "/truth",
                "geometry_msgs/msg/PoseStamped",
                count(topics::WORLD_TRUTH.name),
            ),
            (
                "/pose",
                "geometry_msgs/msg/PoseWithCovarianceStamped",
                count(topics::LOCALIZATION_POSE.name),
            ),
            (
                "/odom",
                "nav_msgs/msg/Odometry",
                count(topics::SENSING_ODOM.name),
            ),
            (
                "/scan",
                "sensor_msgs/msg/LaserScan",
                count(topics::SENSING_SCAN.name),
            ),
            (
                "/cmd_vel",
                "geometry_msgs/msg/Twist",
                count(topics::PLANNING_CMD.name),
            ),
            (
                "/tf",
                "tf2_msgs/msg/TFMessage",
                count(topics::LOCALIZATION_POSE.name) + count(topics::SENSING_ODOM.name),
            ),
        ] {
            let c = &channels[channel];
            assert_eq!(c[0], ty, "{estimator}: {channel}: {c}");
            assert_eq!(
                (&c[1], &c[2], &c[3]),
                (&"ros2msg".into(), &"cdr".into(), &true.into()),
                "{channel}"
            );
            assert_eq!(c[4], n, "{estimator}: {channel}: every message decoded");
        }
        assert_eq!(channels["/map"][0], "nav_msgs/msg/OccupancyGrid");

        let truth: Truth = at_tick(&recording, topics::WORLD_TRUTH.name, TICK);
        let t = &at["/truth"];
        assert_eq!(
            (number(&t[0]), number(&t[1]), &t[3]),
            (truth.x, truth.y, &"map".into())
        );
        assert!(same_yaw(number(&t[2]), truth.theta));

        let pose: Pose = at_tick(&recording, topics::LOCALIZATION_POSE.name, TICK);
        let p = &at["/pose"];
        assert_eq!((number(&p[0]), number(&p[1])), (pose.x, pose.y));
        assert!(same_yaw(number(&p[2]), pose.theta));
        let cov: Vec<f64> = p[3].as_array().expect("36").iter().map(number).collect();
        for (i, &r) in [0, 1, 5].iter().enumerate() {
            for (j, &c) in [0, 1, 5].iter().enumerate() {
                assert_eq!(cov[r * 6 + c], pose.covariance[i * 3 + j], "Σ[{r}][{c}]");
            }
        }

        let odom: Odom = at_tick(&recording, topics::SENSING_ODOM.name, TICK);
        let o = &at["/odom"];
        assert_eq!((number(&o[0]), number(&o[1])), (odom.x, odom.y));
        assert!(same_yaw(number(&o[2]), odom.theta));
        assert_eq!((number(&o[3]), number(&o[4])), (odom.v, odom.omega));
        assert_eq!((&o[5], &o[6]), (&"odom".into(), &"base_link".into()));
        let tf = &at["/tf"];
        assert_eq!((number(&tf[0]), number(&tf[1])), (odom.x, odom.y));
        assert_eq!(
            d["frames"],
            serde_json::json!(["map>odom", "odom>base_link"])
        );

        let scan: Scan = at_tick(&recording, topics::SENSING_SCAN.name, TICK);
        let s = &at["/scan"];
        assert_eq!(number(&s[0]), f64::from(scan.angle_min));
        assert_eq!(number(&s[1]), f64::from(scan.angle_increment));
        assert_eq!(number(&s[2]), f64::from(scan.range_max));
        let ranges: Vec<f64> = s[3]
            .as_array()
            .expect("ranges")
            .iter()
            .map(number)
            .collect();
        let recorded_ranges: Vec<f64> = scan.ranges().iter().map(|&r| f64::from(r)).collect();
        assert_eq!(ranges, recorded_ranges);

        let cmds: Vec<(f64, f64)> = recorded(&recording, topics::PLANNING_CMD.name)
            .into_iter()
            .map(|(_, data)| bytemuck::pod_read_unaligned::<Cmd>(&data))
            .map(|c| (c.v, c.omega))
            .collect();
        let decoded: Vec<(f64, f64)> = d["cmds"]
            .as_array()
            .expect("cmds")
            .iter()
            .map(|c| (number(&c[0]), number(&c[1])))
            .collect();
        assert_eq!(decoded, cmds);

        let (_, last) = recorded(&recording, topics::MAPPING_GRID.name)
            .pop()
            .expect("a grid");
        let grid = bytemuck::pod_read_unaligned::<Grid>(&last);
        let g = &d["grid"];
        assert_eq!(
            (g[0].as_u64(), g[1].as_u64()),
            (Some(grid.width.into()), Some(grid.height.into()))
        );
        assert_eq!(number(&g[2]), f64::from(grid.resolution as f32));
        let cells = |v: u8| grid.cells().iter().filter(|&&c| c == v).count() as u64;
        let counts = &g[3];
        assert_eq!(counts["-1"], cells(mole_types::CELL_UNEXPLORED), "{g}");
        assert_eq!(counts["0"], cells(mole_types::CELL_FREE), "{g}");
        assert_eq!(counts["100"], cells(mole_types::CELL_OCCUPIED), "{g}");

        if estimator == EstimatorKind::Pf {
            let particles: Particles =
                at_tick(&recording, topics::LOCALIZATION_PARTICLES.name, TICK);
            let pa = &at["/particles"];
            assert_eq!(pa[0], particles.n_particles, "{pa}");
            let first = particles.particles()[0];
            assert_eq!(
                (number(&pa[1]), number(&pa[2])),
                (f64::from(first.x), f64::from(first.y))
            );
        } else {
            let (_, last) = recorded(&recording, topics::LOCALIZATION_LANDMARKS.name)
                .pop()
                .expect("landmarks");
            let landmarks = bytemuck::pod_read_unaligned::<Landmarks>(&last);
            let markers = d["markers"].as_array().expect("markers");
            assert!(landmarks.n_landmarks > 0, "a SLAM run maps beacons");
            assert_eq!(
                markers.len(),
                landmarks.landmarks().len() + 1,
                "DELETEALL first"
            );
            assert_eq!(markers[0][0], 3);
            for (m, l) in markers[1..].iter().zip(landmarks.landmarks()) {
                assert_eq!(
                    (m[0].as_i64(), m[1].as_i64()),
                    (Some(0), Some(i64::from(l.id)))
                );
                assert_eq!((number(&m[2]), number(&m[3])), (l.x, l.y));
            }
        }
    }
}
