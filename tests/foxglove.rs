//! Foxglove live, as a Foxglove user meets it: `mole up --foxglove` serves the stack over the
//! Foxglove WebSocket protocol, and an independent client (`@foxglove/ws-protocol`'s, in
//! Node.js, tests/support/foxglove_client.mjs) connects, lists the channels and their schemas,
//! subscribes, decodes, publishes the operator's pace, reads and sets a parameter, reads the
//! connection graph and calls a service. What it decoded is checked against the stack's own
//! topics at the same tick: the run's recording, and its `mole export --foxglove`. The same
//! recording served by `mole foxglove FILE` and played by the client reaches it as exported.

use mole_integration_tests::*;
use serde_json::Value;
use std::collections::BTreeMap;
use std::path::Path;
use std::process::Command;
use std::time::{Duration, Instant};

const TICKS: u64 = 1000;
/// The simulated step of the default scenario (ns).
const PERIOD_NS: u64 = 10_000_000;

/// The URL `mole up` printed as `foxglove: URL`.
fn foxglove_url(lines: &std::sync::mpsc::Receiver<String>) -> String {
    let deadline = Instant::now() + Duration::from_secs(120);
    while Instant::now() < deadline {
        if let Ok(line) = lines.recv_timeout(Duration::from_millis(200))
            && let Some(url) = line.strip_prefix("foxglove: ")
        {
            return url.trim().to_string();
        }
    }
    panic!("mole up printed no `foxglove: URL`");
}

/// Every message of `topic` in the MCAP file `path`, by log time.
fn by_time(path: &Path, topic: &str) -> BTreeMap<u64, Vec<u8>> {
    mcap_messages(path, topic).into_iter().collect()
}

/// Whether two JSON values are the same, numbers compared as numbers (JavaScript writes the
/// float 1.0 as 1).
fn same(a: &Value, b: &Value) -> bool {
    match (a, b) {
        (Value::Number(x), Value::Number(y)) => x.as_f64() == y.as_f64(),
        (Value::Array(x), Value::Array(y)) => {
            x.len() == y.len() && x.iter().zip(y).all(|(x, y)| same(x, y))
        }
        (Value::Object(x), Value::Object(y)) => {
            x.len() == y.len() && x.iter().all(|(k, v)| y.get(k).is_some_and(|w| same(v, w)))
        }
        _ => a == b,
    }
}

fn base64_decode(text: &str) -> Vec<u8> {
    use base64::Engine as _;
    base64::engine::general_purpose::STANDARD
        .decode(text)
        .expect("base64")
}

#[test]
fn an_independent_client_sees_the_stack_as_its_recording_has_it() {
    let test = "an_independent_client_sees_the_stack_as_its_recording_has_it";
    let client = match foxglove_client() {
        Ok(client) => client,
        Err(why) => return skip(test, &why),
    };
    let dir = TempDir::new("foxglove-live");
    let recording = dir.0.join("run.mcap");
    let ticks = TICKS.to_string();
    let record = recording.display().to_string();
    let args = [
        "--mode",
        "lockstep",
        "--ticks",
        &ticks,
        "--seed",
        "5",
        "--paused",
        "--foxglove=0",
        "--record",
        &record,
    ];
    let mut stack = Stack::start("foxglove_live", &args);
    let lines = stack.stdout_lines().expect("stdout");
    let url = foxglove_url(&lines);

    // The client runs the held stack (after a malformed message, which is refused), sets a
    // setting, and stops once it saw the truth of tick 200.
    let until = (200 * PERIOD_NS).to_string();
    let mut client = client;
    let output = client
        .args([&url, "--run", "--until", &until, "--timeout", "90"])
        .args(["--set", "mapping.touch_threshold=0.6"])
        .output()
        .expect("run the client");
    assert!(
        output.status.success(),
        "client: {}",
        String::from_utf8_lossy(&output.stderr)
    );
    let seen: Value = serde_json::from_slice(&output.stdout).expect("the client's JSON");
    let summary = stack.succeeded(Duration::from_secs(240));
    assert_eq!(seen["errors"], serde_json::json!([]), "{seen:#}");

    // Channels: the mapping's, in Foxglove's well-known schemas as JSON, and every topic's raw
    // layout with its layout schema.
    let channels: BTreeMap<String, (String, String, String)> = seen["channels"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| {
            let s = |k: &str| c[k].as_str().unwrap_or_default().to_string();
            (
                s("topic"),
                (s("schemaName"), s("schemaEncoding"), s("encoding")),
            )
        })
        .collect();
    for mapped in mole_recorder::foxglove::CHANNELS {
        let expected = (
            mapped.schema.to_string(),
            "jsonschema".into(),
            "json".into(),
        );
        assert_eq!(channels[mapped.channel], expected, "{}", mapped.channel);
    }
    for (topic, type_name) in mole_types::topics::all() {
        let expected = (
            type_name.to_string(),
            "mole-layout".into(),
            "mole-layout".into(),
        );
        assert_eq!(channels[&format!("/mole/{topic}")], expected, "{topic}");
    }

    // The client's pace ran the held stack to its end; the setting it set was taken.
    assert_eq!(summary.ticks, TICKS);
    let changes = summary.settings_changes.to_string();
    assert!(
        changes.contains("touch_threshold") && changes.contains("0.6"),
        "{changes}"
    );
    let set = &seen["setParameters"][0];
    assert_eq!(set["name"], "mapping.touch_threshold");
    assert_eq!(set["value"], 0.6);
    let names: Vec<&str> = seen["parameters"]
        .as_array()
        .unwrap()
        .iter()
        .filter_map(|p| p["name"].as_str())
        .collect();
    for role in ["planning.", "localization.", "mapping."] {
        assert!(names.iter().any(|n| n.starts_with(role)), "{names:?}");
    }

    // The connection graph: the world publishes the truth, the monitor reads it.
    let graph = &seen["graph"];
    let ends = |kind: &str, ids: &str, topic: &str| -> Vec<String> {
        graph[kind]
            .as_array()
            .unwrap()
            .iter()
            .find(|t| t["name"] == topic)
            .map(|t| serde_json::from_value(t[ids].clone()).unwrap())
            .unwrap_or_default()
    };
    assert_eq!(
        ends("publishedTopics", "publisherIds", "/mole/world/truth"),
        ["world"]
    );
    assert!(
        ends("subscribedTopics", "subscriberIds", "/mole/world/truth")
            .contains(&"monitor".to_string())
    );
    assert!(seen["status"].as_str().unwrap().starts_with("lockstep"));

    // Raw layouts: the truth's bytes at each tick are the recorded bytes of that tick.
    let recorded_truth = by_time(&recording, mole_types::topics::WORLD_TRUTH.name);
    let raw = seen["rawTruth"].as_array().unwrap();
    assert!(raw.len() >= 150, "{} raw truths", raw.len());
    for sample in raw {
        let time: u64 = sample["logTime"].as_str().unwrap().parse().unwrap();
        let tick: u64 = sample["tick"].as_str().unwrap().parse().unwrap();
        assert_eq!(time, tick * PERIOD_NS);
        assert_eq!(
            recorded_truth.get(&time),
            Some(&base64_decode(sample["base64"].as_str().unwrap())),
            "the raw truth of tick {tick}"
        );
    }

    // Foxglove's schemas: each decoded message equals the export's at the same log time.
    let export = dir.0.join("foxglove.mcap");
    let out = run_mole(&[
        "export",
        &recording.display().to_string(),
        &export.display().to_string(),
        "--foxglove",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    for channel in ["/truth", "/tf", "/pose", "/pose/ellipse", "/scan", "/path"] {
        let exported = by_time(&export, channel);
        let live = seen["messages"][channel].as_array().unwrap();
        assert!(live.len() >= 150, "{channel}: {} messages", live.len());
        for m in live {
            let time: u64 = m["logTime"].as_str().unwrap().parse().unwrap();
            let expected: Value = serde_json::from_slice(&exported[&time]).unwrap();
            assert!(
                same(&m["message"], &expected),
                "{channel} at {time} ns: {} live, {expected} exported",
                m["message"]
            );
        }
    }
    let maps = seen["messages"]["/map"].as_array().unwrap();
    let map = by_time(&export, "/map");
    let exported_map: Value = serde_json::from_slice(map.values().next().unwrap()).unwrap();
    assert!(same(&maps[0]["message"], &exported_map));

    served_recording_plays_as_exported(&recording, &export);
}

/// `mole foxglove FILE`: the recording, played from a seek at 5× by the protocol's playback
/// control, reaches the client as its export has it.
fn served_recording_plays_as_exported(recording: &Path, export: &Path) {
    let mut server = Command::new(bin_dir().join("mole"))
        .env_remove("CARGO")
        .env_remove("CARGO_MANIFEST_DIR")
        .args(["foxglove", &recording.display().to_string(), "--port", "0"])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::null())
        .spawn()
        .expect("start mole foxglove FILE");
    let stdout = server.stdout.take().expect("stdout");
    let (lines, received) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        use std::io::BufRead;
        for line in std::io::BufReader::new(stdout)
            .lines()
            .map_while(Result::ok)
        {
            let _ = lines.send(line);
        }
    });
    let url = foxglove_url(&received);
    let (seek, until) = ((100 * PERIOD_NS).to_string(), (250 * PERIOD_NS).to_string());
    let output = foxglove_client()
        .expect("the client ran before")
        .args([
            &url,
            "--play",
            "5",
            "--seek",
            &seek,
            "--until",
            &until,
            "--timeout",
            "60",
        ])
        .output()
        .expect("run the client");
    // SIGKILL to the launcher: its server must not outlive it (it serves with a ready file
    // named after the launcher's pid).
    let ready = format!("mole-foxglove-{}.url", server.id());
    let _ = server.kill();
    let _ = server.wait();
    let orphans = || {
        std::fs::read_dir("/proc")
            .into_iter()
            .flatten()
            .flatten()
            .filter(|e| {
                std::fs::read(e.path().join("cmdline"))
                    .is_ok_and(|c| String::from_utf8_lossy(&c).contains(&ready))
            })
            .count()
    };
    let deadline = Instant::now() + Duration::from_secs(10);
    while orphans() > 0 && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(50));
    }
    assert_eq!(orphans(), 0, "mole-foxglove outlived its killed launcher");
    let seen: Value = serde_json::from_slice(&output.stdout).expect("the client's JSON");
    // This client package predates the playback state message; it only says so.
    let errors: Vec<&Value> = seen["errors"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|e| !e.as_str().unwrap().contains("opcode in binary message: 5"))
        .collect();
    assert!(errors.is_empty(), "{errors:?}");
    let exported = by_time(export, "/truth");
    let truths = seen["messages"]["/truth"].as_array().unwrap();
    let played: Vec<u64> = truths
        .iter()
        .map(|m| m["logTime"].as_str().unwrap().parse().unwrap())
        .filter(|&t| t >= 100 * PERIOD_NS)
        .collect();
    assert!(played.len() >= 140, "{} truths played", played.len());
    assert!(played.windows(2).all(|w| w[0] < w[1]), "played in order");
    for m in truths {
        let time: u64 = m["logTime"].as_str().unwrap().parse().unwrap();
        let expected: Value = serde_json::from_slice(&exported[&time]).unwrap();
        assert!(same(&m["message"], &expected), "/truth at {time} ns");
    }
}

/// What `mole foxglove` cannot serve is refused with exit 2 and a line naming it, before
/// anything serves: a file that is not a recording, a port something else holds, controls to
/// turn off on a recording.
#[test]
fn what_cannot_be_served_is_refused_before_serving() {
    let dir = TempDir::new("foxglove-refused");
    let text = dir.0.join("notes.mcap");
    std::fs::write(&text, "not a recording").expect("write");
    let refused = run_mole(&["foxglove", &text.display().to_string(), "--port", "0"]);
    assert_eq!(refused.status.code(), Some(2));
    let stderr = String::from_utf8_lossy(&refused.stderr);
    assert!(stderr.contains("notes.mcap: not an MCAP file"), "{stderr}");

    let held = std::net::TcpListener::bind("127.0.0.1:0").expect("a port");
    let port = held.local_addr().expect("its address").port().to_string();
    let in_use = run_mole(&["foxglove", &text.display().to_string(), "--port", &port]);
    assert_eq!(in_use.status.code(), Some(2));
    let stderr = String::from_utf8_lossy(&in_use.stderr);
    assert!(
        stderr.contains(&format!("--port={port}: cannot serve the Foxglove server")),
        "{stderr}"
    );

    let controls = run_mole(&["foxglove", &text.display().to_string(), "--no-controls"]);
    assert_eq!(controls.status.code(), Some(2));
}
