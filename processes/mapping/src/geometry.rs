//! Grid geometry: world ↔ cell conversions and exact grid traversal of a segment.

use crate::MappingError;
use mole_types::MAX_GRID_CELLS;

/// A row-major grid over `[origin_x, origin_x + width·resolution] × [origin_y, …]`; cell
/// `(col, row)` has index `row·width + col`, row along y (the layout of `mole_types::Grid`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GridGeometry {
    /// Cells along x.
    pub width: u32,
    /// Cells along y.
    pub height: u32,
    /// Cell side (m).
    pub resolution: f64,
    /// World x of the grid's lower-left corner (m).
    pub origin_x: f64,
    /// World y of the grid's lower-left corner (m).
    pub origin_y: f64,
}

impl GridGeometry {
    /// Whether `grid` has exactly this geometry (size, resolution, origin): a grid written by
    /// another mapping process of the same arena.
    pub fn matches(&self, grid: &mole_types::Grid) -> bool {
        grid.width == self.width
            && grid.height == self.height
            && grid.resolution == self.resolution
            && grid.origin_x == self.origin_x
            && grid.origin_y == self.origin_y
    }

    /// Writes this geometry, `kind` and `cells` (`width × height`, row-major) into a (loaned)
    /// message; the header and the unused tail of `cells` are left alone.
    pub fn write_grid(&self, kind: u32, cells: &[u8], out: &mut mole_types::Grid) {
        out.width = self.width;
        out.height = self.height;
        out.resolution = self.resolution;
        out.origin_x = self.origin_x;
        out.origin_y = self.origin_y;
        out.kind = kind;
        out._pad = 0;
        out.cells[..cells.len()].copy_from_slice(cells);
    }

    /// The grid over the arena `[0, width_m] × [0, height_m]`: `ceil(W/res) × ceil(H/res)` cells,
    /// origin (0, 0); refused when a size is not positive and finite or there are more than
    /// `MAX_GRID_CELLS` cells.
    pub fn for_arena(width_m: f64, height_m: f64, resolution: f64) -> Result<Self, MappingError> {
        for (what, value) in [
            ("arena width", width_m),
            ("arena height", height_m),
            ("grid resolution", resolution),
        ] {
            if !(value.is_finite() && value > 0.0) {
                return Err(MappingError::NotPositive { what, value });
            }
        }
        // A hair below the ceiling so that 10 m / 0.1 m (= 100.000…01 in floating point) is 100.
        let cells_along = |extent: f64| (extent / resolution - 1e-9).ceil().max(1.0);
        let (w, h) = (cells_along(width_m), cells_along(height_m));
        if w * h > MAX_GRID_CELLS as f64 {
            return Err(MappingError::TooManyCells {
                width: w,
                height: h,
                max: MAX_GRID_CELLS,
            });
        }
        Ok(Self {
            width: w as u32,
            height: h as u32,
            resolution,
            origin_x: 0.0,
            origin_y: 0.0,
        })
    }

    /// Number of cells, `width × height`.
    pub fn len(&self) -> usize {
        self.width as usize * self.height as usize
    }

    /// Whether the grid has no cells (never true for a grid built by `for_arena`).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Index of cell `(col, row)`: `row·width + col`.
    #[inline]
    pub fn index(&self, col: u32, row: u32) -> usize {
        row as usize * self.width as usize + col as usize
    }

    /// The cell `(col, row)` of index `index`.
    #[inline]
    pub fn cell_of_index(&self, index: usize) -> (u32, u32) {
        let w = self.width as usize;
        ((index % w) as u32, (index / w) as u32)
    }

    /// Continuous grid coordinates (in cells) of a world point.
    #[inline]
    pub fn to_grid(&self, x: f64, y: f64) -> (f64, f64) {
        (
            (x - self.origin_x) / self.resolution,
            (y - self.origin_y) / self.resolution,
        )
    }

    /// The cell holding world point `(x, y)`, or `None` outside the grid or for a non-finite
    /// point; a point on the grid's upper edge belongs to the last cell.
    #[inline]
    pub fn world_to_cell(&self, x: f64, y: f64) -> Option<(u32, u32)> {
        let (gx, gy) = self.to_grid(x, y);
        // Also false for NaN.
        if !(gx >= 0.0 && gx <= self.width as f64 && gy >= 0.0 && gy <= self.height as f64) {
            return None;
        }
        Some((
            (gx.floor() as u32).min(self.width - 1),
            (gy.floor() as u32).min(self.height - 1),
        ))
    }

    /// Index of the cell holding world point `(x, y)`, or `None` outside the grid.
    #[inline]
    pub fn world_to_index(&self, x: f64, y: f64) -> Option<usize> {
        self.world_to_cell(x, y).map(|(c, r)| self.index(c, r))
    }

    /// World coordinates of the centre of cell `(col, row)`.
    #[inline]
    pub fn cell_center(&self, col: u32, row: u32) -> (f64, f64) {
        (
            self.origin_x + (col as f64 + 0.5) * self.resolution,
            self.origin_y + (row as f64 + 0.5) * self.resolution,
        )
    }

    /// Visits, in order from `(x0, y0)`, every cell the segment to `(x1, y1)` crosses, clipped to
    /// the grid (exact traversal: Amanatides & Woo, "A Fast Voxel Traversal Algorithm", 1987).
    ///
    /// Consecutive cells share an edge, so `|Δcol| + |Δrow| + 1` cells are visited; where the
    /// segment passes exactly through a cell corner, one of the two side cells is taken. Does
    /// not allocate; a non-finite segment visits nothing.
    pub fn traverse(&self, x0: f64, y0: f64, x1: f64, y1: f64, mut visit: impl FnMut(u32, u32)) {
        let (gx0, gy0) = self.to_grid(x0, y0);
        let (gx1, gy1) = self.to_grid(x1, y1);
        let Some((ax, ay, bx, by)) = self.clip(gx0, gy0, gx1, gy1) else {
            return;
        };
        let (w, h) = (self.width as i64, self.height as i64);
        let cell = |g: f64, n: i64| (g.floor() as i64).clamp(0, n - 1);
        let (mut col, mut row) = (cell(ax, w), cell(ay, h));
        let (col_end, row_end) = (cell(bx, w), cell(by, h));
        let (dx, dy) = (bx - ax, by - ay);
        let step_col: i64 = if col_end >= col { 1 } else { -1 };
        let step_row: i64 = if row_end >= row { 1 } else { -1 };
        // Parameter t ∈ [0, 1] along the clipped segment at which the next vertical (horizontal)
        // cell edge is crossed, and the increment of t per cell.
        let first_crossing = |g: f64, c: i64, d: f64| {
            if d > 0.0 {
                ((c + 1) as f64 - g) / d
            } else if d < 0.0 {
                (g - c as f64) / -d
            } else {
                f64::INFINITY
            }
        };
        let mut t_max_x = first_crossing(ax, col, dx);
        let mut t_max_y = first_crossing(ay, row, dy);
        let t_delta_x = if dx != 0.0 {
            1.0 / dx.abs()
        } else {
            f64::INFINITY
        };
        let t_delta_y = if dy != 0.0 {
            1.0 / dy.abs()
        } else {
            f64::INFINITY
        };
        // Counting the steps (rather than comparing t against 1) guarantees the walk ends in the
        // end cell whatever the rounding.
        let mut left_x = (col_end - col).abs();
        let mut left_y = (row_end - row).abs();
        visit(col as u32, row as u32);
        while left_x + left_y > 0 {
            if left_x > 0 && (left_y == 0 || t_max_x < t_max_y) {
                col += step_col;
                t_max_x += t_delta_x;
                left_x -= 1;
            } else {
                row += step_row;
                t_max_y += t_delta_y;
                left_y -= 1;
            }
            visit(col as u32, row as u32);
        }
    }

    /// Clips the segment (grid coordinates) to `[0, width] × [0, height]` (Liang–Barsky).
    fn clip(&self, x0: f64, y0: f64, x1: f64, y1: f64) -> Option<(f64, f64, f64, f64)> {
        if !(x0.is_finite() && y0.is_finite() && x1.is_finite() && y1.is_finite()) {
            return None;
        }
        let (dx, dy) = (x1 - x0, y1 - y0);
        let (mut t0, mut t1) = (0.0_f64, 1.0_f64);
        for (p, q) in [
            (-dx, x0),
            (dx, self.width as f64 - x0),
            (-dy, y0),
            (dy, self.height as f64 - y0),
        ] {
            if p == 0.0 {
                if q < 0.0 {
                    return None;
                }
            } else {
                let r = q / p;
                if p < 0.0 {
                    if r > t1 {
                        return None;
                    }
                    t0 = t0.max(r);
                } else {
                    if r < t0 {
                        return None;
                    }
                    t1 = t1.min(r);
                }
            }
        }
        Some((x0 + t0 * dx, y0 + t0 * dy, x0 + t1 * dx, y0 + t1 * dy))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use std::collections::BTreeSet;

    fn geom(w: u32, h: u32, res: f64) -> GridGeometry {
        GridGeometry {
            width: w,
            height: h,
            resolution: res,
            origin_x: 0.0,
            origin_y: 0.0,
        }
    }

    #[test]
    fn arena_sizes_round_up_and_are_checked() {
        let g = GridGeometry::for_arena(10.0, 5.0, 0.1).unwrap();
        assert_eq!((g.width, g.height), (100, 50));
        let g = GridGeometry::for_arena(10.05, 5.0, 0.1).unwrap();
        assert_eq!((g.width, g.height), (101, 50));
        let g = GridGeometry::for_arena(0.01, 0.01, 1.0).unwrap();
        assert_eq!((g.width, g.height), (1, 1));
        assert!(GridGeometry::for_arena(512.0, 512.0, 1.0).is_ok());
        assert!(matches!(
            GridGeometry::for_arena(513.0, 512.0, 1.0),
            Err(MappingError::TooManyCells { .. })
        ));
        assert!(matches!(
            GridGeometry::for_arena(1e300, 1e300, 1e-300),
            Err(MappingError::TooManyCells { .. })
        ));
        for bad in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            assert!(matches!(
                GridGeometry::for_arena(10.0, 10.0, bad),
                Err(MappingError::NotPositive { .. })
            ));
            assert!(GridGeometry::for_arena(bad, 10.0, 0.1).is_err());
            assert!(GridGeometry::for_arena(10.0, bad, 0.1).is_err());
        }
    }

    #[test]
    fn world_cell_round_trip_and_edges() {
        let g = geom(10, 5, 0.5);
        assert_eq!(g.world_to_cell(0.0, 0.0), Some((0, 0)));
        assert_eq!(g.world_to_cell(0.74, 1.26), Some((1, 2)));
        // The upper edges belong to the last cells.
        assert_eq!(g.world_to_cell(5.0, 2.5), Some((9, 4)));
        assert_eq!(g.world_to_cell(5.01, 1.0), None);
        assert_eq!(g.world_to_cell(-0.01, 1.0), None);
        assert_eq!(g.world_to_cell(f64::NAN, 1.0), None);
        assert_eq!(g.world_to_cell(1.0, f64::INFINITY), None);
        for i in 0..g.len() {
            let (c, r) = g.cell_of_index(i);
            assert_eq!(g.index(c, r), i);
            let (x, y) = g.cell_center(c, r);
            assert_eq!(g.world_to_index(x, y), Some(i));
        }
    }

    #[test]
    fn traversal_along_a_row_and_outside() {
        let g = geom(10, 10, 1.0);
        let mut cells = Vec::new();
        g.traverse(0.5, 3.5, 6.5, 3.5, |c, r| cells.push((c, r)));
        assert_eq!(cells, (0..=6).map(|c| (c, 3)).collect::<Vec<_>>());
        // Leaving the grid stops at its edge; a segment beside it visits nothing.
        cells.clear();
        g.traverse(8.5, 8.5, 8.5, 100.0, |c, r| cells.push((c, r)));
        assert_eq!(cells, vec![(8, 8), (8, 9)]);
        cells.clear();
        g.traverse(-5.0, -1.0, 20.0, -1.0, |c, r| cells.push((c, r)));
        assert!(cells.is_empty());
        g.traverse(f64::NAN, 1.0, 2.0, 2.0, |c, r| cells.push((c, r)));
        assert!(cells.is_empty());
        // Entering from outside starts at the entry cell.
        g.traverse(-3.0, 0.5, 1.5, 0.5, |c, r| cells.push((c, r)));
        assert_eq!(cells, vec![(0, 0), (1, 0)]);
        // A point segment visits its own cell.
        cells.clear();
        g.traverse(2.2, 7.7, 2.2, 7.7, |c, r| cells.push((c, r)));
        assert_eq!(cells, vec![(2, 7)]);
    }

    /// Length of the part of segment a→b inside the axis-aligned box (grid coordinates).
    fn overlap(a: (f64, f64), b: (f64, f64), lo: (f64, f64), hi: (f64, f64)) -> Option<f64> {
        let g = GridGeometry {
            width: 1,
            height: 1,
            resolution: 1.0,
            origin_x: 0.0,
            origin_y: 0.0,
        };
        let (sx, sy) = (hi.0 - lo.0, hi.1 - lo.1);
        let f = |p: (f64, f64)| ((p.0 - lo.0) / sx, (p.1 - lo.1) / sy);
        let (fa, fb) = (f(a), f(b));
        g.clip(fa.0, fa.1, fb.0, fb.1)
            .map(|(x0, y0, x1, y1)| ((x1 - x0) * sx).hypot((y1 - y0) * sy))
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(200))]

        /// The traversal visits exactly the cells the segment crosses: every cell a supersampled
        /// point of the line falls in, and every cell the segment overlaps by more than a hair;
        /// and nothing the segment misses.
        #[test]
        fn traversal_matches_brute_force(
            x0 in 0.0..12.0f64, y0 in 0.0..9.0f64, x1 in 0.0..12.0f64, y1 in 0.0..9.0f64,
        ) {
            let g = geom(16, 12, 0.75);
            let mut visited = Vec::new();
            g.traverse(x0, y0, x1, y1, |c, r| visited.push((c, r)));
            let set: BTreeSet<_> = visited.iter().copied().collect();
            prop_assert_eq!(set.len(), visited.len(), "a cell visited twice");
            let start = g.world_to_cell(x0, y0).unwrap();
            let end = g.world_to_cell(x1, y1).unwrap();
            prop_assert_eq!(visited[0], start);
            prop_assert_eq!(*visited.last().unwrap(), end);
            for pair in visited.windows(2) {
                let d = (pair[0].0 as i64 - pair[1].0 as i64).abs()
                    + (pair[0].1 as i64 - pair[1].1 as i64).abs();
                prop_assert_eq!(d, 1, "not edge-connected: {:?}", pair);
            }
            // Supersampled line.
            let n = 4000;
            for k in 0..=n {
                let t = k as f64 / n as f64;
                let c = g.world_to_cell(x0 + t * (x1 - x0), y0 + t * (y1 - y0)).unwrap();
                prop_assert!(set.contains(&c), "sample cell {:?} missed", c);
            }
            // Exact brute force over all cells.
            let (a, b) = (g.to_grid(x0, y0), g.to_grid(x1, y1));
            for row in 0..g.height {
                for col in 0..g.width {
                    let (lo, hi) = ((col as f64, row as f64), (col as f64 + 1.0, row as f64 + 1.0));
                    let inside = overlap(a, b, lo, hi);
                    if inside.is_some_and(|l| l > 1e-9) {
                        prop_assert!(set.contains(&(col, row)), "crossed cell {:?} missed", (col, row));
                    }
                    if set.contains(&(col, row)) {
                        let e = 1e-9;
                        prop_assert!(
                            overlap(a, b, (lo.0 - e, lo.1 - e), (hi.0 + e, hi.1 + e)).is_some(),
                            "visited cell {:?} not on the segment", (col, row)
                        );
                    }
                }
            }
        }
    }
}
