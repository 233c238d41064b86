//! Recording, as a user runs it: `mole up --record FILE` does not change the run, `mole info`
//! describes the file, a recorder killed mid-run leaves every complete chunk readable, restarts
//! are in the file, and an independent MCAP implementation (the `mcap` package from PyPI)
//! decodes a message with the schema's field table alone.

use mole_integration_tests::*;
use mole_types::{Role, Truth, topics};
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::{Duration, Instant};

const RUN_TIMEOUT: Duration = Duration::from_secs(240);

/// A finished run: its summary, its recording (if any, read whole), logs and output.
struct Run {
    output: Output,
    logs: String,
    /// The recorder's whole log (empty when it did not run).
    recorder_log: String,
    summary: Option<Summary>,
    recording: Option<Vec<u8>>,
}

/// The recording's name in a run's output directory (removed with it, whatever happens).
const RECORDING: &str = "run.mcap";

/// Starts `mole up` with `args`, recording into its output directory when `record`.
fn start(test: &str, args: &[&str], record: bool) -> Stack {
    if !record {
        return Stack::start(test, args);
    }
    let namespace = unique_namespace(test);
    // Where `Stack::start_in` puts the output directory.
    let out = std::env::temp_dir().join(format!("mole-{namespace}"));
    let file = out.join(RECORDING).display().to_string();
    let args: Vec<&str> = args.iter().copied().chain(["--record", &file]).collect();
    let stack = Stack::start_in(&namespace, &args);
    assert_eq!(stack.out, out);
    stack
}

/// Where a stack started by [`start`] records.
fn recording_of(stack: &Stack) -> PathBuf {
    stack.out.join(RECORDING)
}

/// Waits for the run to end and keeps what it left.
fn finish(stack: Stack) -> Run {
    let (namespace, out) = (stack.namespace.clone(), stack.out.clone());
    let keep = out.with_extension("kept");
    let _ = std::fs::remove_dir_all(&keep);
    let output = stack.wait_and_copy(&keep, RUN_TIMEOUT);
    let _ = std::fs::remove_dir_all(&out);
    let logs = logs(&keep);
    let summary = keep.join("summary.json").exists().then(|| summary(&keep));
    let recording = std::fs::read(keep.join(RECORDING)).ok();
    let recorder_log = std::fs::read_to_string(keep.join("logs/recorder.log")).unwrap_or_default();
    let _ = std::fs::remove_dir_all(&keep);
    assert!(
        processes_of(&namespace).is_empty(),
        "processes left behind\n{logs}"
    );
    Run {
        output,
        logs,
        recorder_log,
        summary,
        recording,
    }
}

/// A lockstep run of `ticks` steps with `seed`, recorded or not, that must succeed.
fn lockstep_run(test: &str, ticks: u64, seed: u64, record: bool) -> Run {
    let (ticks, seed) = (ticks.to_string(), seed.to_string());
    let args = ["--mode", "lockstep", "--ticks", &ticks, "--seed", &seed];
    let run = finish(start(test, &args, record));
    assert!(
        run.output.status.success(),
        "mole up failed: {}\n{}",
        String::from_utf8_lossy(&run.output.stderr),
        run.logs
    );
    run
}

/// A recorded message: its channel's topic, its log time and its bytes.
type Message = (String, u64, Vec<u8>);

/// Every message of a finished recording, as a streaming reader reads it (any error fails).
fn stream(bytes: &[u8]) -> Vec<Message> {
    mcap::MessageStream::new(bytes)
        .expect("an MCAP file")
        .map(|m| m.expect("a finished recording reads to its end"))
        .map(|m| (m.channel.topic.clone(), m.log_time, m.data.into_owned()))
        .collect()
}

/// The truths among `messages`, in file order.
fn truths_of(messages: &[Message]) -> Vec<(u64, Truth)> {
    messages
        .iter()
        .filter(|(topic, _, _)| topic == topics::WORLD_TRUTH.name)
        .map(|(_, time, data)| (*time, bytemuck::pod_read_unaligned::<Truth>(data)))
        .collect()
}

/// The truths of a finished recording, in file order.
fn truths(bytes: &[u8]) -> Vec<(u64, Truth)> {
    truths_of(&stream(bytes))
}

/// What the `mcap` crate's linear reader finds in a file a killed recorder left, record by
/// record, chunks whole, each chunk then read on its own (CRCs checked, every message decoded
/// against its channel's schema).
struct Salvage {
    /// Every message of every chunk that reads whole, in file order.
    messages: Vec<Message>,
    /// The starts of the chunk records (for a test to damage one).
    chunks: Vec<usize>,
    /// Where the last chunk record that lies whole in the file ends.
    last_chunk_end: usize,
    /// The first byte from which nothing reads: the start of the record where the walk stopped
    /// or of the first record that does not read whole, whichever comes first.
    first_unreadable: usize,
    /// Why the walk stopped.
    stop: Option<mcap::McapError>,
    /// Why the first record (a chunk with what it holds) that does not read whole does not.
    bad_record: Option<String>,
}

/// Walks `bytes` with the linear reader, fed exactly the bytes it asks for, so that what it was
/// fed ends where the record it yields ends.
fn salvage(bytes: &[u8]) -> Salvage {
    use mcap::records::Record;
    use mcap::sans_io::{LinearReadEvent, LinearReader, LinearReaderOptions};
    let sizes: std::collections::BTreeMap<&str, usize> = mole_types::layout::all()
        .into_iter()
        .map(|t| (t.type_name, t.size))
        .collect();
    let mut reader =
        LinearReader::new_with_options(LinearReaderOptions::default().with_emit_chunks(true));
    let (mut fed, mut start) = (0, mcap::MAGIC.len());
    let mut schemas = std::collections::BTreeMap::new();
    let mut channels = std::collections::BTreeMap::new();
    let mut found = Salvage {
        messages: Vec::new(),
        chunks: Vec::new(),
        last_chunk_end: 0,
        first_unreadable: bytes.len(),
        stop: None,
        bad_record: None,
    };
    // A record at the top level or inside a chunk: schemas and channels are kept, a message is
    // decoded (its size is its schema's type's, an event is JSON).
    let mut take = |record: Record, out: &mut Vec<Message>| -> Result<(), String> {
        match record {
            Record::Schema { header, .. } => {
                schemas.insert(header.id, header.name);
            }
            Record::Channel(channel) => {
                channels.insert(channel.id, (channel.topic, channel.schema_id));
            }
            Record::Message { header, data } => {
                let (topic, schema) = channels.get(&header.channel_id).ok_or(format!(
                    "a message of unknown channel {}",
                    header.channel_id
                ))?;
                let type_name = schemas.get(schema).map_or("", String::as_str);
                let decodes = match sizes.get(type_name) {
                    Some(size) => data.len() == *size,
                    None => serde_json::from_slice::<serde_json::Value>(&data).is_ok(),
                };
                if !decodes {
                    return Err(format!("a {topic} message of {} bytes", data.len()));
                }
                out.push((topic.clone(), header.log_time, data.into_owned()));
            }
            _ => {}
        }
        Ok(())
    };
    while let Some(event) = reader.next_event() {
        match event {
            Ok(LinearReadEvent::ReadRequest(need)) => {
                let n = need.min(bytes.len() - fed);
                reader.insert(n).copy_from_slice(&bytes[fed..fed + n]);
                reader.notify_read(n);
                fed += n;
            }
            Ok(LinearReadEvent::Record { opcode, data }) => {
                let record = match mcap::parse_record(opcode, data) {
                    Ok(record) => record,
                    Err(e) => {
                        found.stop = Some(e);
                        break;
                    }
                };
                let end = fed;
                let mut messages = Vec::new();
                let read = match record {
                    Record::Chunk { header, data } => {
                        found.chunks.push(start);
                        found.last_chunk_end = end;
                        mcap::read::ChunkReader::new(header, &data)
                            .map_err(|e| e.to_string())
                            .and_then(|records| {
                                records.into_iter().try_for_each(|r| {
                                    take(r.map_err(|e| e.to_string())?, &mut messages)
                                })
                            })
                    }
                    record => take(record, &mut messages),
                };
                match read {
                    _ if found.bad_record.is_some() => {}
                    Ok(()) => found.messages.extend(messages),
                    Err(why) => {
                        found.bad_record = Some(format!("the record at {start}: {why}"));
                        found.first_unreadable = start;
                    }
                }
                start = end;
            }
            Err(e) => {
                found.stop = Some(e);
                break;
            }
        }
    }
    if found.stop.is_some() && found.bad_record.is_none() {
        found.first_unreadable = start;
    }
    found
}

/// Waits for `child`; kills it and fails after `timeout` (it would hang otherwise).
fn wait_or_kill(mut child: std::process::Child, timeout: Duration) -> Output {
    let deadline = Instant::now() + timeout;
    while child.try_wait().ok().flatten().is_none() {
        if Instant::now() > deadline {
            let _ = child.kill();
            let output = child.wait_with_output().expect("reap");
            panic!(
                "still running after {timeout:?}: {}",
                String::from_utf8_lossy(&output.stderr)
            );
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    child.wait_with_output().expect("collect output")
}

/// Writes `bytes` to a file of the test's own and runs `mole info` on it.
fn mole_info(name: &str, bytes: &[u8]) -> Output {
    let path = std::env::temp_dir().join(format!("mole-info-{name}-{}.mcap", std::process::id()));
    std::fs::write(&path, bytes).expect("write the recording");
    let output = run_mole(&["info", &path.display().to_string()]);
    let _ = std::fs::remove_file(&path);
    output
}

/// Recording never changes the run: a recorded lockstep run has the summary, the grid hashes
/// and every seed-decided value of an unrecorded one.
#[test]
fn a_recorded_lockstep_run_is_the_run_an_unrecorded_one_is() {
    let _serial = serial();
    let before = shm_files();
    let plain = lockstep_run("plain", 1000, 5, false);
    let recorded = lockstep_run("recorded", 1000, 5, true);
    let (plain, recorded_summary) = (
        plain.summary.expect("a summary"),
        recorded.summary.expect("a summary"),
    );
    assert!(plain.grid_hash.is_some());
    assert_eq!(plain.grid_hash, recorded_summary.grid_hash);
    assert_eq!(plain.contact_hash, recorded_summary.contact_hash);
    assert_eq!(deterministic(&plain), deterministic(&recorded_summary));
    let recording = recorded.recording.expect("a recording");
    assert_eq!(
        truths(&recording).len() as u64,
        recorded_summary.ticks + 1,
        "every step is recorded"
    );
    assert_eq!(left_behind(&before), Vec::<String>::new());
}

/// `mole info` lists every topic with plausible counts: one truth a tick, one map, a grid every
/// ten ticks and the last one; and refuses a truncated file or one that is not MCAP, with
/// exit 2, naming the file and what was expected.
#[test]
fn mole_info_lists_every_topic_with_plausible_counts() {
    let _serial = serial();
    let run = lockstep_run("info", 300, 2, true);
    let ticks = run.summary.expect("a summary").ticks;
    let recording = run.recording.expect("a recording");
    let output = mole_info("whole", &recording);
    let text = String::from_utf8_lossy(&output.stdout);
    assert!(
        output.status.success(),
        "{text}\n{}",
        String::from_utf8_lossy(&output.stderr)
    );
    let count = |topic: &str| -> u64 {
        let line = text
            .lines()
            .find(|l| l.split_whitespace().next() == Some(topic))
            .unwrap_or_else(|| panic!("`mole info` does not list {topic}:\n{text}"));
        let words: Vec<&str> = line.split_whitespace().collect();
        words[2]
            .parse()
            .unwrap_or_else(|_| panic!("no count in `{line}`"))
    };
    for (topic, type_name) in topics::all() {
        count(topic);
        assert!(text.contains(type_name), "{type_name}:\n{text}");
    }
    assert_eq!(count(topics::WORLD_TRUTH.name), ticks + 1, "{text}");
    // Sensing answers every truth but the last (the run ends with it).
    assert_eq!(count(topics::SENSING_SCAN.name), ticks, "{text}");
    assert_eq!(count(topics::WORLD_MAP.name), 1, "{text}");
    let grids = count(topics::MAPPING_GRID.name);
    assert!(
        (ticks / 10..=ticks / 10 + 2).contains(&grids),
        "{grids} grids in {ticks} ticks:\n{text}"
    );
    assert!(count(topics::STACK_STATS.name) > 0, "{text}");
    assert!(
        text.contains(&format!("Ticks:      {}", ticks + 1)),
        "{text}"
    );
    assert!(text.contains("clock_mode: lockstep"), "{text}");
    assert!(text.contains("seed: 2"), "{text}");
    assert!(
        text.contains("launch_file: ("),
        "the launch file's text:\n{text}"
    );

    let output = mole_info("cut", &recording[..recording.len() * 2 / 3]);
    let error = String::from_utf8_lossy(&output.stderr);
    assert_eq!(output.status.code(), Some(2), "{error}");
    assert!(error.contains("mole-info-cut-"), "names the file: {error}");
    assert!(error.contains("truncated"), "{error}");
    assert!(
        error.contains("expected a file `mole record` finished"),
        "{error}"
    );
    let output = mole_info("toml", b"[stack]\nmode = \"lockstep\"\n");
    let error = String::from_utf8_lossy(&output.stderr);
    assert_eq!(output.status.code(), Some(2), "{error}");
    assert!(error.contains("not an MCAP file"), "{error}");
}

/// A recorder SIGKILLed mid-run does not stop the run, and leaves a file that reads up to the
/// record it was writing: the first byte that does not read lies after the last complete chunk,
/// every message of every complete chunk decodes, and the truths are of consecutive ticks from
/// 0, each at its simulated time.
#[test]
fn a_killed_recorder_leaves_every_complete_chunk_readable() {
    let _serial = serial();
    let stack = start("killed", &["--mode", "lockstep", "--ticks", "3000"], true);
    let file = recording_of(&stack);
    let deadline = Instant::now() + RUN_TIMEOUT;
    // A few chunks in (a chunk is 1 MiB before compression, closed at least once a second).
    while std::fs::metadata(&file).map_or(0, |m| m.len()) < 300_000 {
        assert!(
            Instant::now() < deadline,
            "the recording never grew\n{}",
            logs(&stack.out)
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    // Mid-run: the world still steps (a recorder that wrote only at the end would grow its
    // file only after the world stopped).
    let world = pid_of(&stack.namespace, Role::World.spec().program);
    let recorder = pid_of(&stack.namespace, "mole-recorder").expect("a running recorder");
    signal(recorder, nix::sys::signal::Signal::SIGKILL);
    assert!(
        world.is_some(),
        "the recording grew only after the run\n{}",
        logs(&stack.out)
    );
    let killed_at = std::fs::read(&file).expect("the recording");
    let run = finish(stack);
    assert!(
        run.output.status.success(),
        "the run goes on:\n{}",
        run.logs
    );
    assert_eq!(run.summary.expect("a summary").ticks, 3000);

    let found = salvage(&killed_at);
    assert!(
        matches!(found.stop, Some(mcap::McapError::UnexpectedEof)),
        "the walk stops at the cut, not at {:?} ({} bytes)",
        found.stop,
        killed_at.len()
    );
    assert!(
        found.first_unreadable >= found.last_chunk_end,
        "nothing reads from byte {} on ({}), yet a complete chunk ends at {} (chunks at {:?}, \
         {} bytes)",
        found.first_unreadable,
        found.bad_record.as_deref().unwrap_or("the cut"),
        found.last_chunk_end,
        found.chunks,
        killed_at.len()
    );
    assert!(found.chunks.len() > 1, "chunks at {:?}", found.chunks);
    let truths = truths_of(&found.messages);
    assert!(
        !truths.is_empty(),
        "no complete chunk in {} bytes",
        killed_at.len()
    );
    assert!(
        truths.len() < 3001,
        "the recorder was killed before the run's end"
    );
    for (i, (time, truth)) in truths.iter().enumerate() {
        assert_eq!(truth.header.tick, i as u64, "consecutive ticks from 0");
        assert_eq!(
            *time,
            truth.header.tick * 10_000_000,
            "log time = tick × dt"
        );
        assert!(truth.x.is_finite() && truth.y.is_finite());
    }
    let output = mole_info("killed", &killed_at);
    assert_eq!(output.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&output.stderr).contains("truncated"));
}

/// The count `name=N` in a log line (colour codes around it or not).
fn count_in(line: &str, name: &str) -> u64 {
    let plain: String = line
        .split('\x1b')
        .enumerate()
        .map(|(i, part)| match i {
            0 => part,
            _ => part.split_once('m').map_or("", |(_, rest)| rest),
        })
        .collect();
    plain
        .split_whitespace()
        .find_map(|word| word.strip_prefix(&format!("{name}=")))
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("no `{name}=N` in `{plain}`"))
}

/// In realtime nothing wakes the recorder: every subscription is passive, so however many
/// messages it records, no publisher signals it once; it drains its queues on its own timer.
#[test]
fn the_recorder_is_never_woken_by_a_publisher_in_realtime() {
    let _serial = serial();
    let run = finish(start(
        "realtime-wakes",
        &["--mode", "realtime", "--ticks", "300"],
        true,
    ));
    assert!(run.output.status.success(), "{}", run.logs);
    let messages = stream(&run.recording.expect("a recording")).len() as u64;
    let finished = run
        .recorder_log
        .lines()
        .find(|l| l.contains("recording finished"))
        .unwrap_or_else(|| panic!("the recorder did not finish:\n{}", run.recorder_log));
    assert_eq!(count_in(finished, "messages"), messages, "{finished}");
    let ticks = run.summary.expect("a summary").ticks;
    assert!(messages > 3 * ticks, "{messages} messages in {ticks} ticks");
    let (woken, drains) = (count_in(finished, "woken"), count_in(finished, "drains"));
    assert_eq!(
        woken, 0,
        "woken {woken} times by publishers for {messages} messages ({drains} drains)"
    );
    assert!(drains > 0, "{finished}");
}

/// A process killed mid-run is restarted and another swapped, the recording goes on across
/// both, and each is in the file as an event on `stack/events`.
#[test]
fn a_restart_and_a_swap_are_recorded_and_the_recording_goes_on_across_them() {
    let _serial = serial();
    let stack = start("restart", &["--mode", "realtime", "--ticks", "1000"], true);
    stack.wait_for_log(Role::World.name(), "ready", Duration::from_secs(60));
    std::thread::sleep(Duration::from_millis(1500));
    let planning = Role::Planning.spec();
    let swapped_out = pid_of(&stack.namespace, planning.program).expect("a planning process");
    let command = format!(
        "{} --planner {}",
        planning.program,
        mole_types::PlannerKind::RandomWalk
    );
    let swap = run_mole(&[
        "swap",
        "--namespace",
        &stack.namespace,
        planning.role.name(),
        &command,
    ]);
    assert!(
        swap.status.success(),
        "{}",
        String::from_utf8_lossy(&swap.stderr)
    );
    // After the swap: while a swap waits for its new process, the launcher restarts nothing.
    let sensing = Role::Sensing.spec().program;
    let victim = pid_of(&stack.namespace, sensing).expect("a running sensing process");
    signal(victim, nix::sys::signal::Signal::SIGKILL);
    let run = finish(stack);
    assert!(run.output.status.success(), "{}", run.logs);
    let recording = run.recording.expect("a recording");
    let messages = stream(&recording);
    let restart = messages
        .iter()
        .filter(|(topic, _, _)| topic == "stack/events")
        .map(|(_, _, data)| serde_json::from_slice::<serde_json::Value>(data).expect("JSON"))
        .find(|e| e["kind"] == "restarted" && e["role"] == Role::Sensing.name())
        .unwrap_or_else(|| panic!("no restart of sensing among the events\n{}", run.logs));
    assert_eq!(restart["old_pid"], victim, "{restart}");
    let swap = messages
        .iter()
        .filter(|(topic, _, _)| topic == "stack/events")
        .map(|(_, _, data)| serde_json::from_slice::<serde_json::Value>(data).expect("JSON"))
        .find(|e| e["kind"] == "swapped" && e["role"] == Role::Planning.name())
        .unwrap_or_else(|| panic!("no swap of planning among the events\n{}", run.logs));
    assert_eq!(swap["old_pid"], swapped_out, "{swap}");
    let restart_tick = restart["tick"].as_u64().expect("a tick");
    let scans_after = messages
        .iter()
        .filter(|(topic, time, _)| {
            topic == topics::SENSING_SCAN.name && *time > restart_tick * 10_000_000
        })
        .count();
    assert!(
        scans_after > 50,
        "{scans_after} scans after the restart at {restart_tick}"
    );
}

/// `mole record` attached to a running stack records it until the stack ends, then finishes
/// its file: every truth from the first it read to the run's last.
#[test]
fn mole_record_attaches_to_a_running_stack_until_it_ends() {
    let _serial = serial();
    let stack = start("attach", &["--mode", "realtime", "--ticks", "400"], false);
    stack.wait_for_log(Role::World.name(), "ready", Duration::from_secs(60));
    let file = stack.out.join(RECORDING);
    let recorder = Command::new(bin_dir().join("mole"))
        .current_dir(workspace())
        .args(["record", "--namespace", &stack.namespace])
        .arg(&file)
        .stdin(std::process::Stdio::null())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("start mole record");
    let recorded = wait_or_kill(recorder, RUN_TIMEOUT);
    let recording = std::fs::read(&file);
    let run = finish(stack);
    assert!(
        recorded.status.success(),
        "{}\n{}",
        String::from_utf8_lossy(&recorded.stderr),
        run.logs
    );
    assert!(run.output.status.success(), "{}", run.logs);
    let recording = recording.expect("a recording");
    assert!(recording.ends_with(mcap::MAGIC), "a finished file");
    let ticks: Vec<u64> = truths(&recording)
        .iter()
        .map(|(_, t)| t.header.tick)
        .collect();
    let (first, last) = (ticks[0], ticks[ticks.len() - 1]);
    assert_eq!(last, run.summary.expect("a summary").ticks);
    assert_eq!(ticks, (first..=last).collect::<Vec<_>>());
}

/// `mole up` with `args` in a fresh namespace, expected to refuse them: its output, and whether
/// it started nothing (no process of its namespace, no process's log).
fn refused_up(args: &[&str]) -> (Output, bool) {
    let namespace = unique_namespace("bad-record");
    let out = std::env::temp_dir().join(format!("mole-{namespace}"));
    let out_text = out.display().to_string();
    let mut up = vec!["up"];
    up.extend_from_slice(args);
    up.extend(["--namespace", &namespace, "--out", &out_text, "--quiet"]);
    let output = run_mole(&up);
    let logs = std::fs::read_dir(out.join("logs")).map_or(0, |entries| entries.count());
    let nothing = processes_of(&namespace).is_empty() && logs == 0;
    stop_and_clean(None, &namespace);
    let _ = std::fs::remove_dir_all(&out);
    (output, nothing)
}

/// Bad recording settings (a topic that is not one, a FILE that cannot be written: below a
/// file, a directory, in /proc, where not even root creates files), and `mole record` where no
/// stack runs, are refused with exit 2 before anything starts, naming what is wrong.
#[test]
fn bad_recording_settings_are_refused_before_anything_starts() {
    let dir = TempDir::new("bad-record");
    let file = dir.0.join(RECORDING).display().to_string();
    let (output, nothing) = refused_up(&["--record", &file, "--record-every", "mapping/gird=3"]);
    let error = String::from_utf8_lossy(&output.stderr);
    assert_eq!(output.status.code(), Some(2), "{error}");
    assert!(
        error.contains("--record-every `mapping/gird=3`: `mapping/gird` is not a topic"),
        "{error}"
    );
    assert!(nothing, "nothing started: {error}");
    assert!(!Path::new(&file).exists(), "nothing written");

    let plain = dir.0.join("plain");
    std::fs::write(&plain, b"a file, not a directory").expect("write a file");
    let below_a_file = plain.join(RECORDING).display().to_string();
    let a_directory = dir.0.display().to_string();
    let in_proc = format!("/proc/mole-{}.mcap", std::process::id());
    for path in [&below_a_file, &a_directory, &in_proc] {
        let (output, nothing) =
            refused_up(&["--mode", "lockstep", "--ticks", "50", "--record", path]);
        let error = String::from_utf8_lossy(&output.stderr);
        assert_eq!(output.status.code(), Some(2), "--record {path}: {error}");
        assert!(
            error.contains(&format!("cannot record to {path}: ")),
            "{error}"
        );
        assert!(nothing, "--record {path}: something started: {error}");
    }

    let namespace = unique_namespace("bad-record");
    let output = run_mole(&["record", "--namespace", &namespace, &file]);
    let error = String::from_utf8_lossy(&output.stderr);
    assert_eq!(output.status.code(), Some(2), "{error}");
    assert!(
        error.contains(&format!("no stack runs in namespace `{namespace}`")),
        "{error}"
    );
    assert!(!Path::new(&file).exists());
}

/// Decodes the truth of tick `argv[2]` from the recording `argv[1]` with nothing but the
/// channel's schema: the field table's offsets and types.
const DECODE_TRUTH: &str = r#"
import json, struct, sys
from mcap.reader import make_reader

PRIMITIVES = {"u8": "B", "u16": "H", "u32": "I", "u64": "Q", "i8": "b", "i16": "h",
              "i32": "i", "i64": "q", "f32": "f", "f64": "d"}

def read(layout, data, path):
    table, offset = layout, 0
    for name in path.split("."):
        field = next(f for f in table["fields"] if f["name"] == name)
        offset += field["offset"]
        if field["type"] in PRIMITIVES:
            return struct.unpack_from("<" + PRIMITIVES[field["type"]], data, offset)[0]
        table = layout["structs"][field["type"]]
    raise KeyError(path)

path, tick = sys.argv[1], int(sys.argv[2])
with open(path, "rb") as f:
    for schema, channel, message in make_reader(f).iter_messages(topics=["world/truth"]):
        assert schema.encoding == "mole-layout", schema.encoding
        layout = json.loads(schema.data)
        assert len(message.data) == layout["size"], (len(message.data), layout["size"])
        if read(layout, message.data, "header.tick") == tick:
            # repr: the shortest text that reads back as the same double.
            print(json.dumps({"type": schema.name, "log_time": message.log_time,
                              "x": repr(read(layout, message.data, "x")),
                              "y": repr(read(layout, message.data, "y")),
                              "theta": repr(read(layout, message.data, "theta"))}))
            break
"#;

/// The `mcap` package from PyPI, knowing nothing of mole but the schema, decodes a truth to the
/// values the Rust side reads from the same bytes.
#[test]
fn python_decodes_a_recorded_truth_with_the_schema_alone() {
    let test = "python_decodes_a_recorded_truth_with_the_schema_alone";
    let python = match python_with_mcap() {
        Ok(python) => python,
        Err(reason) => return skip(test, &reason),
    };
    let _serial = serial();
    let run = lockstep_run("python", 200, 3, true);
    let recording = run.recording.expect("a recording");
    let path = std::env::temp_dir().join(format!("mole-python-{}.mcap", std::process::id()));
    std::fs::write(&path, &recording).expect("write the recording");
    let tick = 150;
    let output = Command::new(&python)
        .args([
            "-c",
            DECODE_TRUTH,
            &path.display().to_string(),
            &tick.to_string(),
        ])
        .output()
        .expect("run python");
    let _ = std::fs::remove_file(&path);
    let stdout = String::from_utf8_lossy(&output.stdout);
    assert!(
        output.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&output.stderr)
    );
    let decoded: serde_json::Value = serde_json::from_str(stdout.trim())
        .unwrap_or_else(|e| panic!("python printed no truth of tick {tick} ({e}): {stdout}"));
    let (time, truth) = truths(&recording)
        .into_iter()
        .find(|(_, t)| t.header.tick == tick)
        .expect("the truth of the tick");
    assert_eq!(decoded["type"], "mole.Truth.v1");
    assert_eq!(decoded["log_time"], time);
    let double = |field: &str| -> f64 {
        let text = decoded[field].as_str().unwrap_or_default();
        text.parse()
            .unwrap_or_else(|_| panic!("{field}: `{text}` is not a number"))
    };
    assert_eq!(double("x"), truth.x);
    assert_eq!(double("y"), truth.y);
    assert_eq!(double("theta"), truth.theta);
    assert!(truth.x != 0.0 || truth.y != 0.0, "a real pose: {truth:?}");
}
