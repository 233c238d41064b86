//! Broad phase: a uniform bucket grid of obstacle indices over the arena, built once, so a query
//! near the robot visits a few cells instead of every square of a maze.

use mole_types::Square;

/// Most cells the grid may have; the cell size grows for very large arenas.
const MAX_CELLS: usize = 1 << 18;

/// Obstacle indices bucketed by the cells their squares overlap (compressed rows: the indices of
/// cell `c` are `items[starts[c]..starts[c + 1]]`).
#[derive(Debug, Clone)]
pub(crate) struct BucketGrid {
    cell: f64,
    nx: usize,
    ny: usize,
    starts: Vec<u32>,
    items: Vec<u32>,
    /// Per obstacle: the query stamp that last reported it (deduplicates squares in many cells).
    seen: Vec<u32>,
    stamp: u32,
    /// The answer of the last query, sized for every obstacle so queries never allocate.
    found: Vec<u32>,
}

impl BucketGrid {
    /// Buckets `obstacles` over `[0, width] × [0, height]` with cells of at least `min_cell`.
    pub(crate) fn new(obstacles: &[Square], width: f64, height: f64, min_cell: f64) -> BucketGrid {
        let width = if width.is_finite() && width > 0.0 {
            width
        } else {
            1.0
        };
        let height = if height.is_finite() && height > 0.0 {
            height
        } else {
            1.0
        };
        let mut cell = if min_cell.is_finite() && min_cell > 0.0 {
            min_cell
        } else {
            1.0
        };
        let dims = |cell: f64| {
            (
                ((width / cell).ceil() as usize).max(1),
                ((height / cell).ceil() as usize).max(1),
            )
        };
        while dims(cell).0.saturating_mul(dims(cell).1) > MAX_CELLS {
            cell *= 2.0;
        }
        let (nx, ny) = dims(cell);
        let mut grid = BucketGrid {
            cell,
            nx,
            ny,
            starts: vec![0; nx * ny + 1],
            items: Vec::new(),
            seen: vec![0; obstacles.len()],
            stamp: 0,
            found: Vec::with_capacity(obstacles.len()),
        };
        // Count, prefix-sum, fill.
        for o in obstacles {
            let (cx0, cy0, cx1, cy1) = grid.cell_range(o.min(), o.max());
            for cy in cy0..=cy1 {
                for cx in cx0..=cx1 {
                    grid.starts[cy * nx + cx + 1] += 1;
                }
            }
        }
        for c in 0..nx * ny {
            grid.starts[c + 1] += grid.starts[c];
        }
        grid.items = vec![0; grid.starts[nx * ny] as usize];
        let mut next = grid.starts.clone();
        for (i, o) in obstacles.iter().enumerate() {
            let (cx0, cy0, cx1, cy1) = grid.cell_range(o.min(), o.max());
            for cy in cy0..=cy1 {
                for cx in cx0..=cx1 {
                    let slot = &mut next[cy * nx + cx];
                    grid.items[*slot as usize] = i as u32;
                    *slot += 1;
                }
            }
        }
        grid
    }

    /// Cells covering the box, clamped to the grid (things outside the arena land in edge cells).
    fn cell_range(&self, min: (f64, f64), max: (f64, f64)) -> (usize, usize, usize, usize) {
        let ix = |x: f64| ((x / self.cell).floor().max(0.0) as usize).min(self.nx - 1);
        let iy = |y: f64| ((y / self.cell).floor().max(0.0) as usize).min(self.ny - 1);
        (ix(min.0), iy(min.1), ix(max.0), iy(max.1))
    }

    /// Indices of every obstacle whose bucket overlaps the box `centre ± half` (each once; a
    /// superset of the obstacles the box touches). Does not allocate.
    pub(crate) fn query(&mut self, x: f64, y: f64, half: f64) -> &[u32] {
        self.found.clear();
        if !(x.is_finite() && y.is_finite() && half.is_finite()) {
            return &self.found;
        }
        self.stamp = self.stamp.wrapping_add(1);
        if self.stamp == 0 {
            self.seen.fill(0);
            self.stamp = 1;
        }
        let (cx0, cy0, cx1, cy1) = self.cell_range((x - half, y - half), (x + half, y + half));
        for cy in cy0..=cy1 {
            for cx in cx0..=cx1 {
                let c = cy * self.nx + cx;
                for &i in &self.items[self.starts[c] as usize..self.starts[c + 1] as usize] {
                    let seen = &mut self.seen[i as usize];
                    if *seen != self.stamp {
                        *seen = self.stamp;
                        self.found.push(i);
                    }
                }
            }
        }
        &self.found
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scenario::distance_to_square;
    use proptest::prelude::*;

    proptest! {
        #[test]
        fn query_finds_every_square_near_the_box(
            squares in proptest::collection::vec((-1.0f64..11.0, -1.0f64..11.0, 0.01f64..3.0), 0..60),
            x in 0.0f64..10.0, y in 0.0f64..10.0, half in 0.0f64..1.0, cell in 0.1f64..2.0,
        ) {
            let obstacles: Vec<Square> =
                squares.iter().map(|&(cx, cy, s)| Square::new(cx, cy, s)).collect();
            let mut grid = BucketGrid::new(&obstacles, 10.0, 10.0, cell);
            let found = grid.query(x, y, half).to_vec();
            let mut dedup = found.clone();
            dedup.sort_unstable();
            dedup.dedup();
            prop_assert_eq!(dedup.len(), found.len(), "no duplicates");
            for (i, o) in obstacles.iter().enumerate() {
                // Every square within `half` of the centre (a disk inside the box) is found.
                if distance_to_square(o, x, y) <= half {
                    prop_assert!(found.contains(&(i as u32)), "missed square {}", i);
                }
            }
        }
    }

    #[test]
    fn huge_arenas_get_coarser_cells() {
        let grid = BucketGrid::new(&[], 1e6, 1e6, 0.1);
        assert!(grid.nx * grid.ny <= MAX_CELLS);
        let mut grid = BucketGrid::new(&[Square::new(1.0, 1.0, 1.0)], f64::NAN, -1.0, 0.0);
        assert_eq!(grid.query(1.0, 1.0, 0.1), &[0]);
        assert!(grid.query(f64::NAN, 1.0, 0.1).is_empty());
    }

    #[test]
    fn stamps_survive_wrapping() {
        let mut grid = BucketGrid::new(&[Square::new(1.0, 1.0, 1.0)], 10.0, 10.0, 0.5);
        grid.stamp = u32::MAX - 1;
        for _ in 0..4 {
            assert_eq!(grid.query(1.0, 1.0, 0.1), &[0]);
        }
    }
}
