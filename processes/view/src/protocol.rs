//! What the server sends one page: each frame as one JSON text message. The first holds the
//! arena and the whole grids; after it, a grid is sent only as the tiles that changed since the
//! grid this page was sent last (a page that skipped frames gets every tile that changed
//! meanwhile). docs/view.md describes every field.

use crate::scene::{Arena, Frame, FrameState, GridImage};
use crate::tiles::{TILE, TileCells, changed_tiles, tile_cells, tiles};
use serde::Serialize;

/// A grid's update in one message: its geometry and the tiles to paint.
#[derive(Debug, Serialize)]
pub struct GridUpdate {
    pub tick: u64,
    pub width: usize,
    pub height: usize,
    pub resolution: f64,
    pub origin_x: f64,
    pub origin_y: f64,
    /// Cells along a tile's side.
    pub tile: usize,
    /// Whether `tiles` cover the whole grid (the page starts it afresh).
    pub whole: bool,
    pub tiles: Vec<TileCells>,
}

/// The grids that changed for this page.
#[derive(Debug, Default, Serialize)]
pub struct GridUpdates {
    #[serde(skip_serializing_if = "Option::is_none")]
    pub frontier: Option<GridUpdate>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub contact: Option<GridUpdate>,
}

/// One message to a page.
#[derive(Debug, Serialize)]
pub struct FrameMessage<'a> {
    /// Always `frame`.
    #[serde(rename = "type")]
    pub kind: &'static str,
    /// Whether this message holds everything (the page's first, or a new arena).
    pub full: bool,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub arena: Option<&'a Arena>,
    #[serde(flatten)]
    pub state: &'a FrameState,
    pub grids: GridUpdates,
}

/// What one page was sent so far.
#[derive(Debug, Default)]
pub struct Client {
    arena: Option<std::sync::Arc<Arena>>,
    frontier: Option<GridImage>,
    contact: Option<GridImage>,
}

/// The update that brings a page's `sent` grid to `next`, `None` when nothing changed.
fn update(sent: &mut Option<GridImage>, next: Option<&GridImage>) -> Option<GridUpdate> {
    let next = next?;
    let (whole, changed) = match sent.as_ref() {
        Some(old) if std::sync::Arc::ptr_eq(&old.cells, &next.cells) => return None,
        Some(old) if old.same_geometry(next) => (
            false,
            changed_tiles(&old.cells, &next.cells, next.width, next.height, TILE),
        ),
        _ => (true, tiles(next.width, next.height, TILE).collect()),
    };
    *sent = Some(next.clone());
    if changed.is_empty() && !whole {
        return None;
    }
    Some(GridUpdate {
        tick: next.tick,
        width: next.width,
        height: next.height,
        resolution: next.resolution,
        origin_x: next.origin_x,
        origin_y: next.origin_y,
        tile: TILE,
        whole,
        tiles: changed
            .into_iter()
            .map(|t| tile_cells(&next.cells, next.width, t))
            .collect(),
    })
}

impl Client {
    /// The message (JSON text) that shows `frame` to this page, given what it was sent before.
    pub fn message(&mut self, frame: &Frame) -> String {
        let full = self
            .arena
            .as_ref()
            .is_none_or(|a| !std::sync::Arc::ptr_eq(a, &frame.arena));
        if full {
            self.arena = Some(frame.arena.clone());
            self.frontier = None;
            self.contact = None;
        }
        let grids = GridUpdates {
            frontier: update(&mut self.frontier, frame.frontier.as_ref()),
            contact: update(&mut self.contact, frame.contact.as_ref()),
        };
        let message = FrameMessage {
            kind: "frame",
            full,
            arena: full.then_some(&*frame.arena),
            state: &frame.state,
            grids,
        };
        serde_json::to_string(&message).expect("a frame is plain data")
    }
}
