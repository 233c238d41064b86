//! The recorder: every topic of a stack into one MCAP file, and what `mole info` reads back.
//!
//! The pure part lives here and is tested without IPC: the channels' schemas from the layout
//! table ([`schema`]), which samples of a topic are written ([`every`]), samples lost before
//! they were read ([`gaps`]), the processes' events ([`events`]), the file itself ([`file`]),
//! the run's metadata ([`metadata`]) and the description of a finished file ([`info`]). The
//! `mole-recorder` binary (src/main.rs) reads the stack's topics and feeds these.

pub mod events;
pub mod every;
pub mod file;
pub mod gaps;
pub mod info;
pub mod metadata;
pub mod schema;

pub use events::{EVENTS_TOPIC, Event, ProcessWatch};
pub use every::Every;
pub use file::{RECORDING_METADATA, RUN_METADATA, Record, RecordError, Recording, Written};
pub use gaps::Gaps;
pub use info::{Info, InfoError, read_info};
pub use metadata::{RunFacts, run_metadata, source_revision};
pub use schema::{MESSAGE_ENCODING, SCHEMA_ENCODING, schema_json};
