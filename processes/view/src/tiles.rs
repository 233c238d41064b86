//! Grid deltas: a grid is sent as square tiles of cells, and after the first message only the
//! tiles whose cells changed.

use serde::Serialize;

/// Cells along a tile's side: 32 × 32 = 1 KiB of cells, about 1.4 KiB of base64.
pub const TILE: usize = 32;

/// A rectangle of a grid's cells, in cells: columns `x..x + w`, rows `y..y + h`. Tiles at the
/// grid's right and top edges are cut to the grid.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Tile {
    pub x: usize,
    pub y: usize,
    pub w: usize,
    pub h: usize,
}

/// One tile as the page gets it: its rectangle and its cells, row-major, base64.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct TileCells {
    pub x: usize,
    pub y: usize,
    pub w: usize,
    pub h: usize,
    /// The tile's cells (one byte each, row-major), standard base64.
    pub cells: String,
}

/// The tiles of `tile × tile` cells of a row-major `width × height` grid, row by row.
pub fn tiles(width: usize, height: usize, tile: usize) -> impl Iterator<Item = Tile> {
    let tile = tile.max(1);
    (0..height.div_ceil(tile)).flat_map(move |ty| {
        (0..width.div_ceil(tile)).map(move |tx| {
            let (x, y) = (tx * tile, ty * tile);
            Tile {
                x,
                y,
                w: tile.min(width - x),
                h: tile.min(height - y),
            }
        })
    })
}

/// The tiles in which `next` differs from `prev`, both row-major `width × height` grids.
pub fn changed_tiles(
    prev: &[u8],
    next: &[u8],
    width: usize,
    height: usize,
    tile: usize,
) -> Vec<Tile> {
    debug_assert!(prev.len() >= width * height && next.len() >= width * height);
    tiles(width, height, tile)
        .filter(|t| {
            (t.y..t.y + t.h).any(|row| {
                let start = row * width + t.x;
                prev[start..start + t.w] != next[start..start + t.w]
            })
        })
        .collect()
}

/// A tile's cells out of a row-major grid `width` cells wide, encoded for the page.
pub fn tile_cells(cells: &[u8], width: usize, t: Tile) -> TileCells {
    use base64::Engine as _;
    let mut bytes = Vec::with_capacity(t.w * t.h);
    for row in t.y..t.y + t.h {
        let start = row * width + t.x;
        bytes.extend_from_slice(&cells[start..start + t.w]);
    }
    TileCells {
        x: t.x,
        y: t.y,
        w: t.w,
        h: t.h,
        cells: base64::engine::general_purpose::STANDARD.encode(bytes),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// One changed cell gives exactly the tile that holds it.
    #[test]
    fn a_changed_cell_is_exactly_its_tile() {
        let (w, h) = (100, 70);
        let prev = vec![0u8; w * h];
        let mut next = prev.clone();
        next[40 * w + 65] = 2;
        assert_eq!(
            changed_tiles(&prev, &next, w, h, 32),
            vec![Tile {
                x: 64,
                y: 32,
                w: 32,
                h: 32
            }]
        );
    }

    /// The same grid twice has no changed tile.
    #[test]
    fn nothing_changed_is_no_tile() {
        let cells: Vec<u8> = (0..50 * 40).map(|i| (i % 3) as u8).collect();
        assert!(changed_tiles(&cells, &cells, 50, 40, 32).is_empty());
    }

    /// A grid whose sides are no multiple of the tile gets cut tiles at its edges, and a change
    /// in the last cell is the last, cut tile.
    #[test]
    fn edge_tiles_are_cut_to_the_grid() {
        let (w, h) = (70, 33);
        let all: Vec<Tile> = tiles(w, h, 32).collect();
        assert_eq!(all.len(), 3 * 2);
        assert_eq!(all.iter().map(|t| t.w * t.h).sum::<usize>(), w * h);
        assert_eq!(
            all[5],
            Tile {
                x: 64,
                y: 32,
                w: 6,
                h: 1
            }
        );
        let prev = vec![0u8; w * h];
        let mut next = prev.clone();
        next[w * h - 1] = 1;
        assert_eq!(changed_tiles(&prev, &next, w, h, 32), vec![all[5]]);
    }

    /// A tile's cells are its rectangle's, row by row.
    #[test]
    fn tile_cells_are_the_rectangle_row_by_row() {
        use base64::Engine as _;
        let cells: Vec<u8> = (0..6 * 4).map(|i| i as u8).collect();
        let t = Tile {
            x: 4,
            y: 2,
            w: 2,
            h: 2,
        };
        let encoded = tile_cells(&cells, 6, t);
        let bytes = base64::engine::general_purpose::STANDARD
            .decode(&encoded.cells)
            .expect("base64");
        assert_eq!(bytes, vec![16, 17, 22, 23]);
    }
}
