//! The recorder: every topic of a stack into one MCAP file, and what `mole info` reads back.
//!
//! The pure part lives here and is tested without IPC: the channels' schemas from the layout
//! table ([`schema`]), which samples of a topic are written ([`every`]), samples lost before
//! they were read ([`gaps`]), the processes' events ([`events`]), the file itself ([`file`]),
//! the run's metadata ([`metadata`]), the description of a finished file ([`info`]), a
//! recording read back for playback ([`tape`]), a recording exported with Foxglove's
//! well-known schemas ([`foxglove`]), who plays what in a replay ([`cast`]) and a
//! replay checked against it ([`check`]). The `mole-recorder` binary (src/main.rs) reads the
//! stack's topics ([`taps`]) in its loop ([`reading`]) and hands them to the file's writer thread
//! ([`writer`]); the `mole-player` binary (src/bin/mole-player.rs) publishes a recording's roles
//! into a live stack ([`player`]).

pub mod cast;
pub mod check;
pub mod events;
pub mod every;
pub mod export;
pub mod file;
pub mod foxglove;
pub mod gaps;
pub mod info;
pub mod metadata;
pub mod player;
pub mod reading;
pub mod ros2;
pub mod schema;
pub mod tape;
pub mod taps;
pub mod writer;

pub use cast::Cast;
pub use check::{Compared, Difference, compare};
pub use events::{EVENTS_TOPIC, Event, ProcessWatch};
pub use every::Every;
pub use export::{ExportError, Exported, Format, export};
pub use file::{RECORDING_METADATA, RUN_METADATA, Record, RecordError, Recording, Written};
pub use gaps::Gaps;
pub use info::{Info, InfoError, read_info};
pub use metadata::{RunFacts, run_metadata, run_metadata_of, source_revision};
pub use reading::{Reading, RecordSink, read_until_shutdown};
pub use schema::{MESSAGE_ENCODING, SCHEMA_ENCODING, schema_json};
pub use tape::{Sample, Tape, TapeError, Window, read_tape};
pub use taps::Taps;
pub use writer::WriterThread;
