//! The view: a live picture of a running stack in a browser, served by mole itself.
//!
//! The pure part lives here and is tested without IPC: the [`frame_clock`] (a frame every
//! [`FRAME_PERIOD`]), the [`scene`] (what the view knows of the
//! stack, fed one sample of one topic at a time, and the [`Frame`] it makes), the grids' [`tiles`]
//! (only what changed is sent), what one page is sent ([`protocol`]) and what a page may send
//! back ([`input`]), and a recording's [`playback`] (its samples indexed per topic by tick, a
//! clock, the scene fed up to the clock's tick). The `mole-view` binary (src/main.rs) feeds the
//! scene from the stack's topics ([`taps`]), serves the page and the WebSocket ([`server`]) and
//! publishes the page's goals and paces on `operator/goal` and `operator/pace` ([`controls`]);
//! with `--file` it feeds it from a recording instead, with no IPC at all ([`recording`]).

pub mod controls;
pub mod flags;
pub mod frame_clock;
pub mod input;
pub mod playback;
pub mod protocol;
pub mod recording;
pub mod scene;
pub mod server;
pub mod taps;
pub mod tiles;

pub use controls::Controls;
pub use flags::ServerFlags;
pub use frame_clock::{FRAME_PERIOD, FRAMES_PER_SECOND, FrameClock};
pub use input::{
    Access, MAX_INPUT_BYTES, MAX_SPEED, MIN_SPEED, PageInput, Rejected, TimelineOp, admit,
    parse_input,
};
pub use playback::{Clock, Playback, Reel, ReelError, Timeline, Track};
pub use protocol::Client;
pub use recording::show_recording;
pub use scene::{Arena, Frame, FrameState, GridImage, MAX_PARTICLES_SENT, Scene};
pub use server::{Served, announce, listen, serve};
pub use taps::Taps;
pub use tiles::{TILE, Tile, changed_tiles};

/// The view's program, found next to `mole`, then on PATH.
pub const VIEW_PROGRAM: &str = "mole-view";
/// The port the view serves on unless told otherwise.
pub const DEFAULT_PORT: u16 = 7777;

#[cfg(test)]
mod tests;
