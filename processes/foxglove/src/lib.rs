//! Foxglove live: a running stack, or a recording, served over the Foxglove WebSocket protocol
//! by Foxglove's own SDK, so the Foxglove app or Lichtblick shows it with no plug-in.
//!
//! The pure part lives here and is tested without IPC: the [`channels`] a stack is served on
//! (the mapping to Foxglove's well-known schemas that `mole export --foxglove` writes, every
//! topic's raw layout, the events), what a client may publish ([`input`]), the settings and the
//! launcher's commands as parameters and services ([`control`]) and the stack's [`graph`] as
//! Foxglove's connection graph. The [`server`] offers them; the `mole-foxglove` binary
//! (src/main.rs) feeds it from the stack's topics ([`live`], with the recorder's taps) or from a
//! recording ([`replay`]).

pub mod channels;
pub mod control;
pub mod graph;
pub mod input;
pub mod live;
pub mod replay;
pub mod server;

pub use channels::{Channels, raw_channel};
pub use live::Relay;
pub use replay::{Replay, play};
pub use server::{Served, Serving, serve};

/// The Foxglove server's program, found next to `mole`, then on PATH.
pub const FOXGLOVE_PROGRAM: &str = "mole-foxglove";
/// The port it serves on unless told otherwise: the Foxglove app's default.
pub const DEFAULT_PORT: u16 = 8765;
