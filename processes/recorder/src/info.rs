//! What `mole info FILE` reports: duration, ticks, every topic with its count and rate, and the
//! metadata, from the file's summary section (a finished recording is not read through).

use crate::file::{RECORDING_METADATA, RUN_METADATA};
use std::collections::BTreeMap;
use std::fmt;
use std::path::{Path, PathBuf};

/// One channel of a recording.
#[derive(Debug, Clone, PartialEq)]
pub struct TopicInfo {
    pub topic: String,
    pub type_name: String,
    pub count: u64,
}

/// A finished recording, as its summary describes it.
#[derive(Debug, Clone, PartialEq)]
pub struct Info {
    pub path: PathBuf,
    pub bytes: u64,
    pub chunks: usize,
    /// The chunks' compression (`lz4`, or `none`).
    pub compression: String,
    pub messages: u64,
    /// First and last message time (ns of simulated time).
    pub start_ns: u64,
    pub end_ns: u64,
    /// The simulated step (ns), from the run's metadata.
    pub period_ns: Option<u64>,
    pub topics: Vec<TopicInfo>,
    /// Every metadata record by name.
    pub metadata: BTreeMap<String, BTreeMap<String, String>>,
}

/// Why a file is not a recording `mole info` can describe.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum InfoError {
    #[error("{}: {}", .0.display(), .1)]
    Unreadable(PathBuf, String),
    #[error(
        "{}: not an MCAP file (expected the MCAP magic bytes at its start, as `mole record` \
         writes)",
        .0.display()
    )]
    NotMcap(PathBuf),
    #[error(
        "{}: a truncated MCAP file (no footer and summary at its end; expected a file \
         `mole record` finished); {readable} messages in its complete chunks can still be read \
         with a streaming reader",
        path.display()
    )]
    Truncated { path: PathBuf, readable: u64 },
    #[error("{}: a corrupt MCAP file ({})", .0.display(), .1)]
    Corrupt(PathBuf, String),
}

impl Info {
    /// Simulated seconds the recording spans: from its first to its last world tick (a
    /// recorder attached mid-run read the world's map, from tick 0, too), else from its first
    /// to its last message.
    pub fn duration_s(&self) -> f64 {
        match (self.ticks(), self.period_ns) {
            (Some((first, last)), Some(period)) => (last - first) as f64 * period as f64 / 1e9,
            _ => self.end_ns.saturating_sub(self.start_ns) as f64 / 1e9,
        }
    }

    /// The count of `topic`'s messages (0 for a topic not in the file).
    pub fn count(&self, topic: &str) -> u64 {
        self.topics
            .iter()
            .find(|t| t.topic == topic)
            .map_or(0, |t| t.count)
    }

    /// Steps the recording spans (from the recorder's own metadata: first and last world tick).
    pub fn ticks(&self) -> Option<(u64, u64)> {
        let recording = self.metadata.get(RECORDING_METADATA)?;
        let first = recording.get("first_tick")?.parse().ok()?;
        let last = recording.get("last_tick")?.parse().ok()?;
        Some((first, last))
    }
}

/// Reads the summary of the recording at `path`.
pub fn read_info(path: &Path) -> Result<Info, InfoError> {
    let unreadable = |e: std::io::Error| InfoError::Unreadable(path.to_path_buf(), e.to_string());
    let bytes = std::fs::read(path).map_err(unreadable)?;
    if !bytes.starts_with(mcap::MAGIC) {
        return Err(InfoError::NotMcap(path.to_path_buf()));
    }
    let corrupt = |e: mcap::McapError| InfoError::Corrupt(path.to_path_buf(), e.to_string());
    let summary = match mcap::Summary::read(&bytes) {
        Ok(Some(summary)) => summary,
        Ok(None) | Err(mcap::McapError::BadFooter | mcap::McapError::BadMagic) => {
            return Err(InfoError::Truncated {
                path: path.to_path_buf(),
                readable: readable_messages(&bytes),
            });
        }
        Err(e) => return Err(corrupt(e)),
    };
    let stats = summary
        .stats
        .clone()
        .ok_or_else(|| InfoError::Corrupt(path.to_path_buf(), "no statistics record".into()))?;
    let mut topics: Vec<TopicInfo> = summary
        .channels
        .iter()
        .map(|(id, channel)| TopicInfo {
            topic: channel.topic.clone(),
            type_name: channel
                .schema
                .as_ref()
                .map_or_else(|| "-".to_string(), |s| s.name.clone()),
            count: stats.channel_message_counts.get(id).copied().unwrap_or(0),
        })
        .collect();
    topics.sort_by(|a, b| a.topic.cmp(&b.topic));
    let mut metadata = BTreeMap::new();
    for index in &summary.metadata_indexes {
        let record = mcap::read::metadata(&bytes, index).map_err(corrupt)?;
        metadata.insert(record.name, record.metadata);
    }
    let period_ns = metadata
        .get(RUN_METADATA)
        .and_then(|m| m.get("period_ns"))
        .and_then(|p| p.parse().ok());
    let compression = summary
        .chunk_indexes
        .first()
        .map(|c| c.compression.clone())
        .filter(|c| !c.is_empty())
        .unwrap_or_else(|| "none".to_string());
    Ok(Info {
        path: path.to_path_buf(),
        bytes: bytes.len() as u64,
        chunks: summary.chunk_indexes.len(),
        compression,
        messages: stats.message_count,
        start_ns: stats.message_start_time,
        end_ns: stats.message_end_time,
        period_ns,
        topics,
        metadata,
    })
}

/// Messages a streaming reader gets from a file before it fails (a truncated file's complete
/// chunks).
pub fn readable_messages(bytes: &[u8]) -> u64 {
    let Ok(stream) = mcap::MessageStream::new(bytes) else {
        return 0;
    };
    stream.take_while(Result::is_ok).count() as u64
}

impl fmt::Display for Info {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let duration = self.duration_s();
        writeln!(f, "File:       {}", self.path.display())?;
        writeln!(
            f,
            "Size:       {:.2} MB ({} chunks, {})",
            self.bytes as f64 / 1e6,
            self.chunks,
            self.compression
        )?;
        writeln!(f, "Duration:   {duration:.3} s simulated")?;
        match (self.ticks(), self.period_ns) {
            (Some((first, last)), Some(period)) => writeln!(
                f,
                "Ticks:      {} (tick {first} … {last}, {} ms a step)",
                last - first + 1,
                period as f64 / 1e6
            )?,
            (Some((first, last)), None) => writeln!(
                f,
                "Ticks:      {} (tick {first} … {last})",
                last - first + 1
            )?,
            (None, _) => writeln!(f, "Ticks:      unknown (no world/truth recorded)")?,
        }
        writeln!(f, "Messages:   {}", self.messages)?;
        writeln!(f, "Topics:")?;
        let width = self.topics.iter().map(|t| t.topic.len()).max().unwrap_or(0);
        let type_width = self
            .topics
            .iter()
            .map(|t| t.type_name.len())
            .max()
            .unwrap_or(0);
        for t in &self.topics {
            let rate = if t.count > 1 && duration > 0.0 {
                format!("{:8.2} Hz", t.count as f64 / duration)
            } else {
                format!("{:>8} Hz", "-")
            };
            writeln!(
                f,
                "  {:width$}  {:type_width$}  {:>8} msgs  {rate}",
                t.topic, t.type_name, t.count
            )?;
        }
        for (name, record) in &self.metadata {
            writeln!(f, "Metadata `{name}`:")?;
            for (key, value) in record {
                match value.lines().count() {
                    0 | 1 => writeln!(f, "  {key}: {value}")?,
                    n => writeln!(f, "  {key}: ({n} lines)")?,
                }
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::file::{Record, Recording};
    use mole_types::{Truth, topics};

    fn temp(name: &str) -> PathBuf {
        std::env::temp_dir().join(format!("mole-info-{name}-{}.mcap", std::process::id()))
    }

    /// A small finished recording: 100 truths at 10 ms, tick 0 … 99.
    fn write_recording(path: &Path) -> u64 {
        let topics = [(topics::WORLD_TRUTH.name, "mole.Truth.v1")];
        let mut r = Recording::create(path, &topics, BTreeMap::new()).unwrap();
        r.apply(Record::World {
            period_ns: 10_000_000,
            seed: 1,
        })
        .unwrap();
        for tick in 0..100 {
            let mut t: Truth = bytemuck::Zeroable::zeroed();
            t.header.tick = tick;
            r.apply(Record::Message {
                topic: topics::WORLD_TRUTH.name,
                seq: tick,
                tick,
                publish_time: 0,
                data: bytemuck::bytes_of(&t).to_vec(),
            })
            .unwrap();
        }
        let done = BTreeMap::from([
            ("first_tick".to_string(), "0".to_string()),
            ("last_tick".to_string(), "99".to_string()),
        ]);
        r.finish(1, done).unwrap().bytes
    }

    /// Counts, rates, duration and ticks come from the summary.
    #[test]
    fn a_finished_recording_is_described_from_its_summary() {
        let path = temp("finished");
        let bytes = write_recording(&path);
        let info = read_info(&path).expect("info");
        let _ = std::fs::remove_file(&path);
        assert_eq!(info.bytes, bytes);
        assert_eq!(info.count(topics::WORLD_TRUTH.name), 100);
        assert_eq!(info.count("stack/events"), 0);
        assert_eq!(info.ticks(), Some((0, 99)));
        assert_eq!(info.compression, "lz4");
        assert!((info.duration_s() - 0.99).abs() < 1e-9);
        let text = info.to_string();
        assert!(
            text.contains("Ticks:      100 (tick 0 … 99, 10 ms a step)"),
            "{text}"
        );
        let truth_line: Vec<&str> = text
            .lines()
            .find(|l| l.trim_start().starts_with("world/truth"))
            .expect("a line for world/truth")
            .split_whitespace()
            .collect();
        assert_eq!(
            truth_line,
            [
                "world/truth",
                "mole.Truth.v1",
                "100",
                "msgs",
                "101.01",
                "Hz"
            ]
        );
    }

    /// A truncated file, a file that is not MCAP and a missing file are refused, naming the
    /// file and what was expected.
    #[test]
    fn bad_files_are_refused_naming_the_file_and_what_was_expected() {
        let path = temp("bad");
        write_recording(&path);
        let whole = std::fs::read(&path).unwrap();
        std::fs::write(&path, &whole[..whole.len() - 40]).unwrap();
        let truncated = read_info(&path).expect_err("truncated");
        assert!(
            matches!(truncated, InfoError::Truncated { .. }),
            "{truncated}"
        );
        let text = truncated.to_string();
        assert!(text.contains(&path.display().to_string()), "{text}");
        assert!(
            text.contains("expected a file `mole record` finished"),
            "{text}"
        );
        std::fs::write(&path, "[stack]\nmode = \"lockstep\"\n").unwrap();
        let not_mcap = read_info(&path).expect_err("not MCAP").to_string();
        assert!(not_mcap.contains("not an MCAP file"), "{not_mcap}");
        let _ = std::fs::remove_file(&path);
        let missing = read_info(&path).expect_err("missing").to_string();
        assert!(missing.contains(&path.display().to_string()), "{missing}");
    }
}
