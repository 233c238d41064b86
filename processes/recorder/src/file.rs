//! The recording: one MCAP file, one channel per topic, written by the `mcap` crate.
//!
//! - Each channel's schema is the message's layout ([`crate::schema`]); each message is the
//!   sample's own bytes, its `sequence` the header's `seq` (so a reader sees gaps), its
//!   `log_time` the simulated time `tick × period` (the world's `dt`, from `world/map`) and its
//!   `publish_time` the wall clock when the recorder read it.
//! - Chunks are LZ4-compressed and built in memory (`disable_seeking`): the file only ever grows
//!   by whole chunks, so a recorder killed at any moment leaves every chunk but the one it was
//!   writing readable. [`Recording::flush`] closes the current chunk (the recorder does so every
//!   second), bounding what a kill loses.
//! - Metadata [`RUN_METADATA`] (launch file, scenario, seed, clock mode, namespace, source
//!   revision, period) is written as soon as the world's map gives seed and period;
//!   [`RECORDING_METADATA`] (ticks, samples lost and decimated per topic) when the file is
//!   finished.

use crate::events::{EVENT_SCHEMA, EVENT_SCHEMA_NAME, EVENTS_TOPIC};
use crate::schema::{MESSAGE_ENCODING, SCHEMA_ENCODING, schema_json};
use mcap::records::{MessageHeader, Metadata};
use mcap::{Compression, WriteOptions, Writer};
use std::collections::BTreeMap;
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

/// The metadata record that describes the run.
pub const RUN_METADATA: &str = "mole";
/// The metadata record that describes the recording itself, written when it is finished.
pub const RECORDING_METADATA: &str = "mole.recording";
/// The MCAP profile of a mole recording.
pub const PROFILE: &str = "mole";
/// Uncompressed bytes a chunk holds before it is compressed and written (the crate's default,
/// a few dozen steps of the default stack).
pub const CHUNK_SIZE: u64 = 1024 * 1024;

/// What the recorder hands the writer.
#[derive(Debug, Clone, PartialEq)]
pub enum Record {
    /// A sample of `topic`: its header's `seq`, the tick that times it, when it was read.
    Message {
        topic: &'static str,
        seq: u64,
        tick: u64,
        publish_time: u64,
        data: Vec<u8>,
    },
    /// The world's map came: the simulated step (ns) and the run's seed.
    World { period_ns: u64, seed: u64 },
    /// An event ([`crate::events`]) at `tick`.
    Event { tick: u64, json: String },
    /// Close the current chunk and hand it to the file.
    Flush,
}

/// Why the recording cannot go on.
#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{}: {source}", path.display())]
    Mcap {
        path: PathBuf,
        source: mcap::McapError,
    },
    #[error(
        "{}: no layout for the message type `{}` (shared-types' layout table lacks it)",
        .0.display(),
        .1
    )]
    NoSchema(PathBuf, String),
    #[error("{}: no channel for the topic `{}`", .0.display(), .1)]
    NoChannel(PathBuf, String),
}

/// What a finished recording holds.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Written {
    pub messages: u64,
    pub bytes: u64,
}

/// An MCAP file being written.
pub struct Recording {
    writer: Writer<BufWriter<File>>,
    path: PathBuf,
    channels: BTreeMap<&'static str, u16>,
    events: u16,
    /// The run's metadata, completed with the seed and the period once the world's map came.
    run: BTreeMap<String, String>,
    period_ns: Option<u64>,
    /// Messages and events that came before the period, written once it is known.
    waiting: Vec<Record>,
    messages: u64,
}

impl Recording {
    /// Creates `path` (replacing a file there) with a channel for each `(topic, type name)`
    /// and the events' channel; `run` is the run's metadata, written when the world's map
    /// completes it.
    pub fn create(
        path: &Path,
        topics: &[(&'static str, &'static str)],
        run: BTreeMap<String, String>,
    ) -> Result<Recording, RecordError> {
        let mcap = |source| RecordError::Mcap {
            path: path.to_path_buf(),
            source,
        };
        let file = File::create(path).map_err(|source| RecordError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        let mut writer = WriteOptions::new()
            .profile(PROFILE)
            .library(format!("mole-recorder {}", env!("CARGO_PKG_VERSION")))
            .compression(Some(Compression::Lz4))
            .chunk_size(Some(CHUNK_SIZE))
            .disable_seeking(true)
            .create(BufWriter::new(file))
            .map_err(mcap)?;
        let mut channels = BTreeMap::new();
        for &(topic, type_name) in topics {
            let schema = schema_json(type_name)
                .ok_or_else(|| RecordError::NoSchema(path.to_path_buf(), type_name.into()))?;
            let schema = writer
                .add_schema(type_name, SCHEMA_ENCODING, schema.as_bytes())
                .map_err(mcap)?;
            let channel = writer
                .add_channel(schema, topic, MESSAGE_ENCODING, &BTreeMap::new())
                .map_err(mcap)?;
            channels.insert(topic, channel);
        }
        let schema = writer
            .add_schema(EVENT_SCHEMA_NAME, "jsonschema", EVENT_SCHEMA.as_bytes())
            .map_err(mcap)?;
        let events = writer
            .add_channel(schema, EVENTS_TOPIC, "json", &BTreeMap::new())
            .map_err(mcap)?;
        Ok(Recording {
            writer,
            path: path.to_path_buf(),
            channels,
            events,
            run,
            period_ns: None,
            waiting: Vec::new(),
            messages: 0,
        })
    }

    fn mcap_error(&self, source: mcap::McapError) -> RecordError {
        RecordError::Mcap {
            path: self.path.clone(),
            source,
        }
    }

    /// Writes one record (a message before the world's map waits for it).
    pub fn apply(&mut self, record: Record) -> Result<(), RecordError> {
        match record {
            Record::World { period_ns, seed } => self.world(period_ns, seed),
            Record::Flush => self.flush(),
            record => match self.period_ns {
                Some(period_ns) => self.write(record, period_ns),
                None => {
                    self.waiting.push(record);
                    Ok(())
                }
            },
        }
    }

    /// The world's map came: the run's metadata is complete, and what waited is written.
    fn world(&mut self, period_ns: u64, seed: u64) -> Result<(), RecordError> {
        let first = self.period_ns.is_none();
        self.period_ns = Some(period_ns);
        if first {
            self.run.insert("seed".into(), seed.to_string());
            self.run.insert("period_ns".into(), period_ns.to_string());
            let metadata = Metadata {
                name: RUN_METADATA.into(),
                metadata: self.run.clone(),
            };
            self.writer
                .write_metadata(&metadata)
                .map_err(|e| self.mcap_error(e))?;
        }
        for record in std::mem::take(&mut self.waiting) {
            self.write(record, period_ns)?;
        }
        Ok(())
    }

    fn write(&mut self, record: Record, period_ns: u64) -> Result<(), RecordError> {
        let (channel_id, sequence, tick, publish_time, data) = match &record {
            Record::Message {
                topic,
                seq,
                tick,
                publish_time,
                data,
            } => {
                let channel = *self
                    .channels
                    .get(topic)
                    .ok_or_else(|| RecordError::NoChannel(self.path.clone(), topic.to_string()))?;
                (channel, *seq as u32, *tick, *publish_time, data.as_slice())
            }
            Record::Event { tick, json } => (self.events, 0, *tick, 0, json.as_bytes()),
            Record::World { .. } | Record::Flush => return Ok(()),
        };
        let header = MessageHeader {
            channel_id,
            sequence,
            log_time: tick.saturating_mul(period_ns),
            publish_time,
        };
        self.writer
            .write_to_known_channel(&header, data)
            .map_err(|e| self.mcap_error(e))?;
        self.messages += 1;
        Ok(())
    }

    /// Closes the current chunk and pushes it to the file: a kill from now on loses nothing
    /// written so far.
    pub fn flush(&mut self) -> Result<(), RecordError> {
        self.writer.flush().map_err(|e| self.mcap_error(e))
    }

    /// Writes what still waits (timed by `fallback_period_ns` if the world's map never came),
    /// the recording's metadata, the summary and the footer.
    pub fn finish(
        mut self,
        fallback_period_ns: u64,
        recording: BTreeMap<String, String>,
    ) -> Result<Written, RecordError> {
        if self.period_ns.is_none() {
            let metadata = Metadata {
                name: RUN_METADATA.into(),
                metadata: self.run.clone(),
            };
            self.writer
                .write_metadata(&metadata)
                .map_err(|e| self.mcap_error(e))?;
            for record in std::mem::take(&mut self.waiting) {
                self.write(record, fallback_period_ns)?;
            }
        }
        let metadata = Metadata {
            name: RECORDING_METADATA.into(),
            metadata: recording,
        };
        self.writer
            .write_metadata(&metadata)
            .map_err(|e| self.mcap_error(e))?;
        self.writer.finish().map_err(|e| self.mcap_error(e))?;
        let bytes = std::fs::metadata(&self.path)
            .map(|m| m.len())
            .map_err(|source| RecordError::Io {
                path: self.path.clone(),
                source,
            })?;
        Ok(Written {
            messages: self.messages,
            bytes,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use mole_types::{Truth, topics};

    /// A file of its own in the temp directory, removed at the end of the test.
    struct TempFile(PathBuf);
    impl TempFile {
        fn new(name: &str) -> TempFile {
            TempFile(
                std::env::temp_dir()
                    .join(format!("mole-recorder-{name}-{}.mcap", std::process::id())),
            )
        }
    }
    impl Drop for TempFile {
        fn drop(&mut self) {
            let _ = std::fs::remove_file(&self.0);
        }
    }

    fn truth(tick: u64, x: f64) -> Record {
        let mut t: Truth = bytemuck::Zeroable::zeroed();
        (t.header.tick, t.header.seq, t.x) = (tick, tick, x);
        Record::Message {
            topic: topics::WORLD_TRUTH.name,
            seq: tick,
            tick,
            publish_time: 1,
            data: bytemuck::bytes_of(&t).to_vec(),
        }
    }

    fn recording(path: &Path) -> Recording {
        let topics = [(topics::WORLD_TRUTH.name, "mole.Truth.v1")];
        let run = BTreeMap::from([("namespace".to_string(), "robot0".to_string())]);
        Recording::create(path, &topics, run).expect("create")
    }

    /// Messages that came before the world's map are timed by its period; the metadata holds
    /// the seed; the bytes read back are the message's own.
    #[test]
    fn messages_are_timed_by_the_simulated_step_and_read_back_whole() {
        let file = TempFile::new("timed");
        let mut r = recording(&file.0);
        r.apply(truth(0, 1.5)).unwrap();
        r.apply(Record::World {
            period_ns: 10_000_000,
            seed: 42,
        })
        .unwrap();
        r.apply(truth(1, 2.5)).unwrap();
        r.apply(Record::Event {
            tick: 1,
            json: "{\"kind\":\"started\"}".into(),
        })
        .unwrap();
        let written = r.finish(1, BTreeMap::new()).unwrap();
        assert_eq!(written.messages, 3);
        let bytes = std::fs::read(&file.0).unwrap();
        let messages: Vec<mcap::Message> = mcap::MessageStream::new(&bytes)
            .unwrap()
            .collect::<Result<_, _>>()
            .unwrap();
        let truths: Vec<(u64, f64)> = messages
            .iter()
            .filter(|m| m.channel.topic == topics::WORLD_TRUTH.name)
            .map(|m| {
                let t: Truth = bytemuck::pod_read_unaligned(&m.data);
                (m.log_time, t.x)
            })
            .collect();
        assert_eq!(truths, vec![(0, 1.5), (10_000_000, 2.5)]);
        let schema = messages[0].channel.schema.as_ref().expect("a schema");
        assert_eq!(schema.encoding, SCHEMA_ENCODING);
        assert_eq!(schema.name, "mole.Truth.v1");
        let summary = mcap::Summary::read(&bytes).unwrap().expect("a summary");
        let index = &summary.metadata_indexes[0];
        let meta = mcap::read::metadata(&bytes, index).unwrap();
        assert_eq!(meta.name, RUN_METADATA);
        assert_eq!(meta.metadata["seed"], "42");
        assert_eq!(meta.metadata["period_ns"], "10000000");
    }

    /// A file cut anywhere after a flushed chunk still yields that chunk's messages to a
    /// streaming reader (what a killed recorder leaves), then an error for the cut.
    #[test]
    fn a_cut_file_still_yields_its_complete_chunks() {
        let file = TempFile::new("cut");
        let mut r = recording(&file.0);
        r.apply(Record::World {
            period_ns: 10_000_000,
            seed: 1,
        })
        .unwrap();
        for tick in 0..50 {
            r.apply(truth(tick, tick as f64)).unwrap();
        }
        r.flush().unwrap();
        let flushed = std::fs::metadata(&file.0).unwrap().len();
        for tick in 50..100 {
            r.apply(truth(tick, tick as f64)).unwrap();
        }
        r.finish(1, BTreeMap::new()).unwrap();
        let whole = std::fs::read(&file.0).unwrap();
        for cut in [flushed as usize, flushed as usize + 100, whole.len() - 30] {
            let mut ticks = Vec::new();
            let mut failed = false;
            for m in mcap::MessageStream::new(&whole[..cut]).unwrap() {
                match m {
                    Ok(m) => ticks.push(bytemuck::pod_read_unaligned::<Truth>(&m.data).header.tick),
                    Err(_) => {
                        failed = true;
                        break;
                    }
                }
            }
            assert!(failed, "a cut at {cut} of {} is an error", whole.len());
            assert!(ticks.len() >= 50, "cut at {cut}: {} messages", ticks.len());
            assert_eq!(ticks, (0..ticks.len() as u64).collect::<Vec<_>>());
        }
    }
}
