//! A recording read back: its run metadata and the samples of the topics a player publishes,
//! step by step. A file that is not a finished recording of this build's message layouts is
//! refused naming what is wrong.

use crate::file::{RECORDING_METADATA, RUN_METADATA};
use crate::info::{InfoError, read_info};
use mole_types::{Header, topics};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// Where a message's header keeps its tick.
const TICK_OFFSET: usize = core::mem::offset_of!(Header, tick);

/// One recorded sample.
#[derive(Debug, Clone, PartialEq)]
pub struct Sample {
    pub topic: String,
    /// The header's tick.
    pub tick: u64,
    /// The simulated time it was recorded at (ns).
    pub log_time: u64,
    /// The message's own bytes.
    pub data: Vec<u8>,
}

/// The ticks to play, both included.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Window {
    pub from: u64,
    pub to: u64,
}

impl Window {
    /// Every tick.
    pub const ALL: Window = Window {
        from: 0,
        to: u64::MAX,
    };

    pub fn contains(&self, tick: u64) -> bool {
        (self.from..=self.to).contains(&tick)
    }
}

/// Why a file cannot be played or checked.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum TapeError {
    #[error(transparent)]
    File(#[from] InfoError),
    #[error("{}: not a mole recording (no `{RUN_METADATA}` metadata)", .0.display())]
    NotMole(PathBuf),
    #[error(
        "{}: recorded with other message layouts: `{topic}` holds `{recorded}`, this build reads \
         `{expected}`",
        path.display()
    )]
    OtherLayout {
        path: PathBuf,
        topic: String,
        recorded: String,
        expected: String,
    },
    #[error("{}: `{topic}` at tick {tick}: {size} bytes, expected {expected}", path.display())]
    BadSample {
        path: PathBuf,
        topic: String,
        tick: u64,
        size: usize,
        expected: usize,
    },
    #[error("{}: {}", .0.display(), .1)]
    Corrupt(PathBuf, String),
}

/// A recording's facts and the samples of the topics asked for.
#[derive(Debug, Clone, PartialEq)]
pub struct Tape {
    /// The run's metadata (`mole`): launch file, scenario, seed, clock mode …
    pub run: BTreeMap<String, String>,
    /// The recorder's own (`mole.recording`): first and last tick, lost and decimated counts.
    pub recording: BTreeMap<String, String>,
    /// The samples in the window, by tick, in the order they were recorded.
    pub steps: BTreeMap<u64, Vec<Sample>>,
    /// The world's map (published once, before the first step), whatever the window.
    pub map: Option<Sample>,
}

impl Tape {
    /// The first and last world tick recorded.
    pub fn ticks(&self) -> Option<(u64, u64)> {
        let tick = |key: &str| self.recording.get(key)?.parse().ok();
        Some((tick("first_tick")?, tick("last_tick")?))
    }

    /// A run fact (`None` when absent or `unknown`, as for a recorder attached to a running
    /// stack).
    pub fn fact(&self, key: &str) -> Option<&str> {
        self.run
            .get(key)
            .map(String::as_str)
            .filter(|v| *v != "unknown")
    }
}

/// The header tick of a message's bytes (`None` when it is too short to hold a header).
pub fn tick_of(data: &[u8]) -> Option<u64> {
    let bytes = data.get(TICK_OFFSET..TICK_OFFSET + 8)?;
    Some(u64::from_le_bytes(bytes.try_into().ok()?))
}

/// Reads the finished recording at `path`, keeping the samples of `wanted` topics in `window`
/// (the world's map whatever its tick).
pub fn read_tape(path: &Path, wanted: &[&str], window: Window) -> Result<Tape, TapeError> {
    let info = read_info(path)?;
    let run = info
        .metadata
        .get(RUN_METADATA)
        .cloned()
        .ok_or_else(|| TapeError::NotMole(path.to_path_buf()))?;
    let recording = info
        .metadata
        .get(RECORDING_METADATA)
        .cloned()
        .unwrap_or_default();
    check_layouts(path, &info.topics)?;
    let mut tape = Tape {
        run,
        recording,
        steps: BTreeMap::new(),
        map: None,
    };
    for_each_sample(path, wanted, |sample| {
        if sample.topic == topics::WORLD_MAP.name {
            tape.map = Some(sample);
        } else if window.contains(sample.tick) {
            tape.steps.entry(sample.tick).or_default().push(sample);
        }
    })?;
    Ok(tape)
}

/// Hands every sample of `wanted` topics, in file order, to `on_sample`; a sample whose size
/// is not its type's is refused.
pub fn for_each_sample(
    path: &Path,
    wanted: &[&str],
    mut on_sample: impl FnMut(Sample),
) -> Result<(), TapeError> {
    let bytes = std::fs::read(path)
        .map_err(|e| InfoError::Unreadable(path.to_path_buf(), e.to_string()))?;
    let corrupt = |e: mcap::McapError| TapeError::Corrupt(path.to_path_buf(), e.to_string());
    let sizes: BTreeMap<&str, usize> = mole_types::layout::all()
        .into_iter()
        .map(|t| (t.type_name, t.size))
        .collect();
    for message in mcap::MessageStream::new(&bytes).map_err(corrupt)? {
        let message = message.map_err(corrupt)?;
        let topic = message.channel.topic.as_str();
        if !wanted.contains(&topic) {
            continue;
        }
        let type_name = message.channel.schema.as_ref().map(|s| s.name.as_str());
        let expected = type_name.and_then(|t| sizes.get(t)).copied().unwrap_or(0);
        let tick = tick_of(&message.data).unwrap_or(0);
        if message.data.len() != expected {
            return Err(TapeError::BadSample {
                path: path.to_path_buf(),
                topic: topic.to_string(),
                tick,
                size: message.data.len(),
                expected,
            });
        }
        on_sample(Sample {
            topic: topic.to_string(),
            tick,
            log_time: message.log_time,
            data: message.data.into_owned(),
        });
    }
    Ok(())
}

/// Every topic of the stack in the file must carry the message type this build has for it.
fn check_layouts(path: &Path, recorded: &[crate::info::TopicInfo]) -> Result<(), TapeError> {
    for (topic, expected) in topics::all() {
        if let Some(t) = recorded.iter().find(|t| t.topic == topic)
            && t.type_name != expected
        {
            return Err(TapeError::OtherLayout {
                path: path.to_path_buf(),
                topic: topic.to_string(),
                recorded: t.type_name.clone(),
                expected: expected.to_string(),
            });
        }
    }
    Ok(())
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::{Record, Recording};
    use mole_types::{Truth, WorldMap};

    /// A file of its own in the temp directory, removed at the end of the test.
    pub struct TempFile(pub PathBuf);
    impl TempFile {
        pub fn new(name: &str) -> TempFile {
            TempFile(
                std::env::temp_dir().join(format!("mole-tape-{name}-{}.mcap", std::process::id())),
            )
        }
    }
    impl Drop for TempFile {
        fn drop(&mut self) {
            let _ = std::fs::remove_file(&self.0);
        }
    }

    /// A sample record of `message` at its header's tick.
    pub fn sample<M: mole_types::Message>(topic: &'static str, message: &M) -> Record {
        Record::Message {
            topic,
            seq: message.header().seq,
            tick: message.header().tick,
            publish_time: 1,
            data: bytemuck::bytes_of(message).to_vec(),
        }
    }

    /// A finished recording of `records` (its last tick the newest of theirs) with the run facts
    /// a player needs.
    pub fn write(path: &Path, records: Vec<Record>) {
        let run = BTreeMap::from([("clock_mode".to_string(), "lockstep".to_string())]);
        let mut r = Recording::create(path, &topics::all(), run).expect("create");
        r.apply(Record::World {
            period_ns: 10_000_000,
            seed: 7,
        })
        .unwrap();
        let ticks = records.iter().filter_map(|r| match r {
            Record::Message { tick, .. } => Some(*tick),
            _ => None,
        });
        let last = ticks.max().unwrap_or(0);
        for record in records {
            r.apply(record).unwrap();
        }
        let totals = BTreeMap::from([
            ("first_tick".to_string(), "0".to_string()),
            ("last_tick".to_string(), last.to_string()),
        ]);
        r.finish(10_000_000, totals).expect("finish");
    }

    pub fn truth(tick: u64, x: f64) -> Truth {
        let mut t: Truth = bytemuck::Zeroable::zeroed();
        (t.header.tick, t.x) = (tick, x);
        t
    }

    /// The window keeps its ticks and the world's map; the facts and the tick span come with
    /// them.
    #[test]
    fn a_window_keeps_its_ticks_and_the_map() {
        let file = TempFile::new("window");
        let map: WorldMap = bytemuck::Zeroable::zeroed();
        let mut records = vec![sample(topics::WORLD_MAP.name, &map)];
        records.extend((0..10).map(|k| sample(topics::WORLD_TRUTH.name, &truth(k, k as f64))));
        write(&file.0, records);
        let window = Window { from: 3, to: 5 };
        let tape = read_tape(
            &file.0,
            &[topics::WORLD_TRUTH.name, topics::WORLD_MAP.name],
            window,
        )
        .expect("tape");
        assert_eq!(tape.steps.keys().copied().collect::<Vec<_>>(), [3, 4, 5]);
        let x = bytemuck::pod_read_unaligned::<Truth>(&tape.steps[&4][0].data).x;
        assert_eq!(x, 4.0);
        assert_eq!(tape.steps[&4][0].log_time, 40_000_000);
        assert!(tape.map.is_some());
        assert_eq!(tape.ticks(), Some((0, 9)));
        assert_eq!(tape.fact("clock_mode"), Some("lockstep"));
        assert_eq!(tape.fact("seed"), Some("7"));
    }

    /// A recording whose topic carries another message type than this build's (here the truth
    /// recorded as odometry, as a build with other layouts would name it) is refused, naming
    /// the file, the topic and both type names.
    #[test]
    fn a_recording_of_other_message_layouts_is_refused_naming_them() {
        let file = TempFile::new("layouts");
        let mut names = topics::all();
        let truth = names
            .iter_mut()
            .find(|(topic, _)| *topic == topics::WORLD_TRUTH.name)
            .expect("world/truth is a topic");
        let expected = truth.1;
        truth.1 = <mole_types::Odom as mole_types::Message>::wire_type_name();
        let run = BTreeMap::from([("clock_mode".to_string(), "lockstep".to_string())]);
        let r = Recording::create(&file.0, &names, run).expect("create");
        r.finish(10_000_000, BTreeMap::new()).expect("finish");
        let refused = read_tape(&file.0, &[], Window::ALL).expect_err("other layouts");
        let said = refused.to_string();
        assert!(said.contains(&*file.0.to_string_lossy()), "{said}");
        assert!(said.contains("world/truth"), "{said}");
        assert!(
            said.contains(expected) && said.contains("mole.Odom"),
            "{said}"
        );
    }

    /// A file that is not MCAP is refused naming it.
    #[test]
    fn a_file_that_is_not_a_recording_is_refused_naming_it() {
        let file = TempFile::new("garbage");
        std::fs::write(&file.0, b"not a recording").unwrap();
        let refused = read_tape(&file.0, &[], Window::ALL).expect_err("garbage");
        assert!(
            refused.to_string().contains(&*file.0.to_string_lossy()),
            "{refused}"
        );
        assert!(
            refused.to_string().contains("not an MCAP file"),
            "{refused}"
        );
    }
}
