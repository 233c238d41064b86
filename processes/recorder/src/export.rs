//! A recording rewritten for other tools: [`export`] streams it one message at a time through a
//! [`Format`] (Foxglove's well-known schemas, `foxglove.rs`; a ROS 2 bag, `ros2.rs`) into a new
//! MCAP file. Both share what is checked on the way: the file is an MCAP recording of mole's
//! layouts, every sample has its type's size, and the output is never the input.

use crate::schema::SCHEMA_ENCODING;
use mole_types::topics;
use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufReader, BufWriter, Read as _};
use std::path::{Path, PathBuf};

/// One message of an export: its channel, its schema (as the [`Format`] names it) and its
/// encoded bytes.
#[derive(Debug, Clone, PartialEq)]
pub struct Exporting {
    pub topic: &'static str,
    pub schema: &'static str,
    pub data: Vec<u8>,
}

/// What an export writes: the messages a recorded sample becomes, and how their channels are
/// described.
pub trait Format {
    /// The MCAP profile of the file.
    fn profile(&self) -> &'static str;
    /// The export's name, in the file's `library` record.
    fn name(&self) -> &'static str;
    /// The schema record of the schema `name`: its name in the file, its encoding and its text.
    fn schema(&self, name: &str) -> (String, &'static str, Vec<u8>);
    /// The message encoding of every channel.
    fn message_encoding(&self) -> &'static str;
    /// The metadata of every channel.
    fn channel_metadata(&self) -> BTreeMap<String, String>;
    /// The messages the sample `data` of `topic`, recorded at `log_time` (ns), becomes; `data`
    /// is the topic's whole message (checked before).
    fn convert(&mut self, topic: &str, log_time: u64, data: &[u8]) -> Vec<Exporting>;
}

/// Why a recording cannot be exported.
#[derive(Debug, thiserror::Error)]
pub enum ExportError {
    #[error("{}: cannot read: {}", .0.display(), .1)]
    Unreadable(PathBuf, String),
    #[error(
        "{}: not an MCAP file (expected a recording made by `mole up --record` or `mole record`)",
        .0.display()
    )]
    NotMcap(PathBuf),
    #[error(
        "{}: not a mole recording (expected channels of schema encoding `{SCHEMA_ENCODING}`)",
        .0.display()
    )]
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
    #[error("{}: `{topic}`: a message of {size} bytes, expected {expected}", path.display())]
    BadSample {
        path: PathBuf,
        topic: String,
        size: usize,
        expected: usize,
    },
    #[error("{}: truncated or corrupt after {messages} messages: {reason}", path.display())]
    Corrupt {
        path: PathBuf,
        messages: u64,
        reason: String,
    },
    #[error("{}: is the recording itself; export into another file", .0.display())]
    SameFile(PathBuf),
    #[error("cannot write {}: {}", .0.display(), .1)]
    Write(PathBuf, String),
}

/// What an export wrote.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Exported {
    /// Messages read from the recording.
    pub read: u64,
    /// Messages written, per exported channel.
    pub written: BTreeMap<&'static str, u64>,
}

/// Exports the recording `input` into the new MCAP file `output` (replaced if it exists) in
/// `format`, reading and writing one message at a time. On any error `output` is removed.
pub fn export(
    input: &Path,
    output: &Path,
    format: &mut dyn Format,
) -> Result<Exported, ExportError> {
    check_is_mcap(input)?;
    if let (Ok(a), Ok(b)) = (input.canonicalize(), output.canonicalize())
        && a == b
    {
        return Err(ExportError::SameFile(output.to_path_buf()));
    }
    let result = export_into(input, output, format);
    if result.is_err() {
        let _ = std::fs::remove_file(output);
    }
    result
}

/// Refuses a file that does not start with MCAP's magic.
fn check_is_mcap(input: &Path) -> Result<(), ExportError> {
    let unreadable =
        |e: std::io::Error| ExportError::Unreadable(input.to_path_buf(), e.to_string());
    let mut magic = [0u8; 8];
    let mut file = File::open(input).map_err(unreadable)?;
    let mut got = 0;
    while got < magic.len() {
        match file.read(&mut magic[got..]).map_err(unreadable)? {
            0 => break,
            n => got += n,
        }
    }
    if magic[..got] != *mcap::MAGIC {
        return Err(ExportError::NotMcap(input.to_path_buf()));
    }
    Ok(())
}

fn export_into(
    input: &Path,
    output: &Path,
    format: &mut dyn Format,
) -> Result<Exported, ExportError> {
    let unreadable =
        |e: std::io::Error| ExportError::Unreadable(input.to_path_buf(), e.to_string());
    let cannot_write =
        |e: &dyn std::fmt::Display| ExportError::Write(output.to_path_buf(), e.to_string());
    let source = File::open(input).map_err(unreadable)?;
    let target = File::create(output).map_err(|e| cannot_write(&e))?;
    let mut writer = mcap::WriteOptions::new()
        .profile(format.profile())
        .library(format!(
            "mole-recorder {} ({} export)",
            env!("CARGO_PKG_VERSION"),
            format.name()
        ))
        .compression(Some(mcap::Compression::Lz4))
        .create(BufWriter::new(target))
        .map_err(|e| cannot_write(&e))?;
    let expected: BTreeMap<&str, &str> = topics::all().into_iter().collect();
    let sizes: BTreeMap<&str, usize> = mole_types::layout::all()
        .into_iter()
        .map(|t| (t.type_name, t.size))
        .collect();
    let mut channels: BTreeMap<&'static str, u16> = BTreeMap::new();
    let metadata = format.channel_metadata();
    let mut exported = Exported {
        read: 0,
        written: BTreeMap::new(),
    };
    let mut mole_channels = 0u64;
    for message in mcap::io::MessageReader::new(BufReader::new(source)) {
        let message = message.map_err(|e| ExportError::Corrupt {
            path: input.to_path_buf(),
            messages: exported.read,
            reason: e.to_string(),
        })?;
        exported.read += 1;
        let topic = message.channel.topic.as_str();
        let Some(schema) = message.channel.schema.as_ref() else {
            continue;
        };
        if schema.encoding != SCHEMA_ENCODING {
            continue;
        }
        mole_channels += 1;
        let Some(&type_name) = expected.get(topic) else {
            continue;
        };
        if schema.name != type_name {
            return Err(ExportError::OtherLayout {
                path: input.to_path_buf(),
                topic: topic.to_string(),
                recorded: schema.name.clone(),
                expected: type_name.to_string(),
            });
        }
        let size = sizes.get(type_name).copied().unwrap_or(0);
        if message.data.len() != size {
            return Err(ExportError::BadSample {
                path: input.to_path_buf(),
                topic: topic.to_string(),
                size: message.data.len(),
                expected: size,
            });
        }
        for converted in format.convert(topic, message.log_time, &message.data) {
            let channel = match channels.get(converted.topic) {
                Some(&id) => id,
                None => {
                    let (name, encoding, text) = format.schema(converted.schema);
                    let schema_id = writer
                        .add_schema(&name, encoding, &text)
                        .map_err(|e| cannot_write(&e))?;
                    let id = writer
                        .add_channel(
                            schema_id,
                            converted.topic,
                            format.message_encoding(),
                            &metadata,
                        )
                        .map_err(|e| cannot_write(&e))?;
                    channels.insert(converted.topic, id);
                    id
                }
            };
            let count = exported.written.entry(converted.topic).or_default();
            let header = mcap::records::MessageHeader {
                channel_id: channel,
                sequence: u32::try_from(*count).unwrap_or(u32::MAX),
                log_time: message.log_time,
                publish_time: message.publish_time,
            };
            writer
                .write_to_known_channel(&header, &converted.data)
                .map_err(|e| cannot_write(&e))?;
            *count += 1;
        }
    }
    if mole_channels == 0 {
        return Err(ExportError::NotMole(input.to_path_buf()));
    }
    writer.finish().map_err(|e| cannot_write(&e))?;
    Ok(exported)
}
