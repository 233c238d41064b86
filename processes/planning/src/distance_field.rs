//! A Euclidean distance field over the occupied cells of the frontier grid (algorithms §5.2 code 2),
//! each cell a square of side = resolution (algorithms §1.3's square obstacles).
//!
//! Exact feature transform by Felzenszwalb & Huttenlocher, "Distance Transforms of Sampled
//! Functions" (2012): a 1-D pass down every column, then the lower envelope of parabolas along
//! every row, tracking which occupied cell is nearest to each cell centre. A query then measures
//! the distance from the point to that cell's square, and its direction, in O(1).
//!
//! The field is rebuilt only when the set of occupied cells (or the grid's geometry) changes; the
//! buffers are sized on the first grid and on a change of size, so steady-state updates and every
//! query are allocation-free.

use mole_types::{CELL_OCCUPIED, Grid};

/// "No occupied cell in this column / row" in the squared-distance passes.
const FAR: f64 = 1.0e18;
/// "No nearest cell".
const NONE: u32 = u32::MAX;

/// Distance from a point to the nearest occupied cell, and the unit direction away from it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Clearance {
    /// Distance (m) from the point to the nearest occupied cell's square; 0 inside one,
    /// +∞ when the grid has no occupied cell.
    pub distance: f64,
    /// Unit vector from the nearest point of that square toward the query point (the direction
    /// of ∇distance); (0, 0) inside a square or without obstacles.
    pub away: [f64; 2],
}

/// Whether `cells` (0/1/2) has its occupied cells exactly where `occupied` (0/1) has ones;
/// branch-free inner loop over 64-cell chunks, so the per-step check vectorizes.
fn same_occupancy(cells: &[u8], occupied: &[u8]) -> bool {
    cells.len() == occupied.len()
        && cells.chunks(64).zip(occupied.chunks(64)).all(|(a, b)| {
            a.iter().zip(b).fold(0u8, |acc, (c, o)| {
                acc | (((*c == CELL_OCCUPIED) as u8) ^ *o)
            }) == 0
        })
}

/// The distance field of a grid's occupied cells. See the module docs.
#[derive(Debug, Clone, Default)]
pub struct DistanceField {
    width: usize,
    height: usize,
    resolution: f64,
    origin: [f64; 2],
    /// Occupancy (0/1) the field was built from.
    occupied: Vec<u8>,
    /// Per cell, the index of the nearest occupied cell (by centre), or `NONE`.
    nearest: Vec<u32>,
    /// Per cell, the lower-left corner (world, m) of that cell's square (+∞ for none): the fast
    /// [`DistanceField::distance`] reads it without an integer division.
    corner: Vec<[f32; 2]>,
    inv_resolution: f64,
    /// Pass 1: squared row distance (cells²) to the nearest occupied cell in the column.
    g: Vec<f64>,
    /// Pass 1: that cell's row.
    g_row: Vec<u32>,
    // Envelope scratch of the row pass.
    v: Vec<usize>,
    z: Vec<f64>,
    builds: u64,
}

impl DistanceField {
    /// An empty field (no grid yet: every query reads +∞).
    pub fn new() -> Self {
        Self::default()
    }

    /// A field with buffers for a grid of `cells` cells, so that the first build does not
    /// allocate either.
    pub fn with_capacity(cells: usize) -> Self {
        let mut f = Self::new();
        f.occupied.reserve(cells);
        f.nearest.reserve(cells);
        f.corner.reserve(cells);
        f.g.reserve(cells);
        f.g_row.reserve(cells);
        f
    }

    /// Brings the field up to date with `grid`; rebuilds only when the grid's geometry or its
    /// set of occupied cells changed. Returns whether it rebuilt. A grid with a bad resolution
    /// or origin empties the field.
    pub fn update(&mut self, grid: &Grid) -> bool {
        let ok = grid.resolution.is_finite()
            && grid.resolution > 0.0
            && grid.origin_x.is_finite()
            && grid.origin_y.is_finite();
        let (w, h) = if ok {
            (grid.width as usize, grid.height as usize)
        } else {
            (0, 0)
        };
        let cells = grid.cells();
        let n = cells.len().min(w * h);
        let (w, h) = if n == w * h { (w, h) } else { (0, 0) };
        let same_geometry = w == self.width
            && h == self.height
            && grid.resolution == self.resolution
            && grid.origin_x == self.origin[0]
            && grid.origin_y == self.origin[1];
        if same_geometry && self.builds > 0 && same_occupancy(&cells[..w * h], &self.occupied) {
            return false;
        }
        self.width = w;
        self.height = h;
        self.resolution = if ok { grid.resolution } else { 1.0 };
        self.origin = if ok {
            [grid.origin_x, grid.origin_y]
        } else {
            [0.0; 2]
        };
        self.occupied.clear();
        self.occupied
            .extend(cells[..w * h].iter().map(|c| (*c == CELL_OCCUPIED) as u8));
        self.rebuild();
        true
    }

    /// Builds the field from an occupancy mask (row-major, nonzero = occupied) of `width ×
    /// height` cells of `resolution` m at `origin` (tests and benches).
    pub fn build_from_mask(
        &mut self,
        width: usize,
        height: usize,
        resolution: f64,
        origin: [f64; 2],
        mask: &[u8],
    ) {
        let n = (width * height).min(mask.len());
        let (w, h) = if n == width * height {
            (width, height)
        } else {
            (0, 0)
        };
        self.width = w;
        self.height = h;
        self.resolution = if resolution.is_finite() && resolution > 0.0 {
            resolution
        } else {
            1.0
        };
        self.origin = origin;
        self.occupied.clear();
        self.occupied
            .extend(mask[..w * h].iter().map(|c| (*c != 0) as u8));
        self.rebuild();
    }

    /// How many times the field was rebuilt.
    pub fn builds(&self) -> u64 {
        self.builds
    }

    /// Grid width and height (cells).
    pub fn dims(&self) -> (usize, usize) {
        (self.width, self.height)
    }

    /// Cell size (m).
    pub fn resolution(&self) -> f64 {
        self.resolution
    }

    /// The grid's extent `[x0, y0, x1, y1]` (m); `None` without a grid.
    pub fn extent(&self) -> Option<[f64; 4]> {
        (self.width > 0 && self.height > 0).then(|| {
            [
                self.origin[0],
                self.origin[1],
                self.origin[0] + self.width as f64 * self.resolution,
                self.origin[1] + self.height as f64 * self.resolution,
            ]
        })
    }

    fn rebuild(&mut self) {
        self.builds += 1;
        let (w, h) = (self.width, self.height);
        let n = w * h;
        self.g.clear();
        self.g.resize(n, FAR);
        self.g_row.clear();
        self.g_row.resize(n, NONE);
        self.nearest.clear();
        self.nearest.resize(n, NONE);
        let m = w.max(h) + 1;
        if self.v.len() < m {
            self.v.resize(m, 0);
            self.z.resize(m + 1, 0.0);
        }
        // Pass 1: per column, the nearest occupied row above or below (two sweeps).
        for col in 0..w {
            let mut last: Option<usize> = None;
            for row in 0..h {
                let i = row * w + col;
                if self.occupied[i] != 0 {
                    last = Some(row);
                }
                if let Some(r) = last {
                    let d = (row - r) as f64;
                    self.g[i] = d * d;
                    self.g_row[i] = r as u32;
                }
            }
            let mut last: Option<usize> = None;
            for row in (0..h).rev() {
                let i = row * w + col;
                if self.occupied[i] != 0 {
                    last = Some(row);
                }
                if let Some(r) = last {
                    let d = (r - row) as f64;
                    if d * d < self.g[i] {
                        self.g[i] = d * d;
                        self.g_row[i] = r as u32;
                    }
                }
            }
        }
        // Pass 2: per row, the lower envelope of the parabolas (x − q)² + g(q).
        for row in 0..h {
            let base = row * w;
            let f = |q: usize| self.g[base + q];
            let (v, z) = (&mut self.v, &mut self.z);
            let mut k = 0usize;
            let mut first = None;
            for q in 0..w {
                if f(q) < FAR {
                    first = Some(q);
                    break;
                }
            }
            let Some(q0) = first else { continue };
            v[0] = q0;
            z[0] = f64::NEG_INFINITY;
            z[1] = f64::INFINITY;
            for q in q0 + 1..w {
                if f(q) >= FAR {
                    continue;
                }
                let s = loop {
                    let p = v[k];
                    let s = ((f(q) + (q * q) as f64) - (f(p) + (p * p) as f64))
                        / (2.0 * (q as f64 - p as f64));
                    // z[0] = −∞, so k never goes below 0.
                    if s <= z[k] && k > 0 {
                        k -= 1;
                    } else {
                        break s;
                    }
                };
                k += 1;
                v[k] = q;
                z[k] = s;
                z[k + 1] = f64::INFINITY;
            }
            let mut k = 0usize;
            for x in 0..w {
                while z[k + 1] < x as f64 {
                    k += 1;
                }
                let q = v[k];
                let r = self.g_row[base + q];
                self.nearest[base + x] = r * w as u32 + q as u32;
            }
        }
        self.corner.clear();
        let (res, o) = (self.resolution, self.origin);
        self.inv_resolution = 1.0 / res;
        self.corner.extend(self.nearest.iter().map(|&k| {
            if k == NONE {
                [f32::INFINITY; 2]
            } else {
                let (c, r) = ((k as usize % w) as f64, (k as usize / w) as f64);
                [(o[0] + c * res) as f32, (o[1] + r * res) as f32]
            }
        }));
    }

    /// Distance from world point (x, y) to the nearest occupied cell's square, with its
    /// direction; +∞ without occupied cells. Points off the grid use the nearest border cell's
    /// nearest obstacle. O(1), no allocation.
    #[inline]
    pub fn clearance(&self, x: f64, y: f64) -> Clearance {
        const FREE: Clearance = Clearance {
            distance: f64::INFINITY,
            away: [0.0, 0.0],
        };
        if self.width == 0 || !(x.is_finite() && y.is_finite()) {
            return FREE;
        }
        let res = self.resolution;
        let col = ((x - self.origin[0]) / res)
            .floor()
            .clamp(0.0, (self.width - 1) as f64) as usize;
        let row = ((y - self.origin[1]) / res)
            .floor()
            .clamp(0.0, (self.height - 1) as f64) as usize;
        let nearest = self.nearest[row * self.width + col];
        if nearest == NONE {
            return FREE;
        }
        let (nc, nr) = (
            (nearest as usize % self.width) as f64,
            (nearest as usize / self.width) as f64,
        );
        // Nearest point of that square [x0, x0+res] × [y0, y0+res].
        let x0 = self.origin[0] + nc * res;
        let y0 = self.origin[1] + nr * res;
        let px = x.clamp(x0, x0 + res);
        let py = y.clamp(y0, y0 + res);
        let (dx, dy) = (x - px, y - py);
        let d = dx.hypot(dy);
        if d > 0.0 {
            Clearance {
                distance: d,
                away: [dx / d, dy / d],
            }
        } else {
            Clearance {
                distance: 0.0,
                away: [0.0, 0.0],
            }
        }
    }

    /// Distance (m) from world point (x, y) to the nearest occupied cell's square, as
    /// [`DistanceField::clearance`] without the direction (to f32 rounding of the square's
    /// corner, ~1 µm): the rollout hot path, with no division, `floor` call or `hypot`.
    #[inline]
    pub fn distance(&self, x: f64, y: f64) -> f64 {
        if self.width == 0 || !(x.is_finite() && y.is_finite()) {
            return f64::INFINITY;
        }
        let inv = self.inv_resolution;
        // Truncation is floor for the non-negative values left after the max.
        let col = (((x - self.origin[0]) * inv).max(0.0) as usize).min(self.width - 1);
        let row = (((y - self.origin[1]) * inv).max(0.0) as usize).min(self.height - 1);
        let [cx, cy] = self.corner[row * self.width + col];
        let (x0, y0) = (cx as f64, cy as f64);
        if x0.is_infinite() {
            return f64::INFINITY;
        }
        let res = self.resolution;
        let dx = x - x.max(x0).min(x0 + res);
        let dy = y - y.max(y0).min(y0 + res);
        (dx * dx + dy * dy).sqrt()
    }

    /// Sets `out[i]` (resized to the grid's cells) to whether the centre of cell i is farther
    /// than `keep` m from every occupied square and from the grid's edges: the inflation of the
    /// walls by `keep`, in one pass over the cells (squared distances, no division, `floor` or
    /// square root).
    pub fn clear_of(&self, keep: f64, out: &mut Vec<bool>) {
        let (w, h) = (self.width, self.height);
        out.clear();
        out.resize(w * h, true);
        let res = self.resolution;
        let keep2 = if keep > 0.0 { keep * keep } else { 0.0 };
        for row in 0..h {
            let y = self.origin[1] + (row as f64 + 0.5) * res;
            let base = row * w;
            for (col, (o, corner)) in out[base..base + w]
                .iter_mut()
                .zip(&self.corner[base..base + w])
                .enumerate()
            {
                let x = self.origin[0] + (col as f64 + 0.5) * res;
                let (x0, y0) = (corner[0] as f64, corner[1] as f64);
                let dx = x - x.max(x0).min(x0 + res);
                let dy = y - y.max(y0).min(y0 + res);
                // An infinite corner (no occupied cell) gives NaN/∞ here: clear.
                let d2 = dx * dx + dy * dy;
                *o = x0.is_infinite() || d2 > keep2;
            }
        }
        // The grid's edges are the arena's walls (see `clearance_in_arena`): cells within
        // `keep` of one are not clear.
        let band = |n: usize| ((keep / res - 0.5).max(-1.0).floor() + 1.0).min(n as f64) as usize;
        let (bx, by) = (band(w), band(h));
        for row in 0..h {
            let base = row * w;
            if row < by || row >= h - by {
                out[base..base + w].fill(false);
            } else {
                out[base..base + bx].fill(false);
                out[base + w - bx..base + w].fill(false);
            }
        }
    }

    /// Distance (m) from the centre of cell `idx` to the nearest wall: an occupied square or
    /// the grid's edge, the arena's wall (0 in a square, +∞ off the grid).
    #[inline]
    pub fn cell_clearance(&self, idx: usize) -> f64 {
        if idx >= self.width * self.height {
            return f64::INFINITY;
        }
        let res = self.resolution;
        let x = self.origin[0] + ((idx % self.width) as f64 + 0.5) * res;
        let y = self.origin[1] + ((idx / self.width) as f64 + 0.5) * res;
        self.clearance_in_arena(x, y).distance
    }

    /// [`DistanceField::clearance`] with the grid's edges as walls too: the grid covers the
    /// arena, whose walls no scan maps as occupied cells (mapping's grids end at them).
    pub fn clearance_in_arena(&self, x: f64, y: f64) -> Clearance {
        let mut c = self.clearance(x, y);
        let Some([x0, y0, x1, y1]) = self.extent() else {
            return c;
        };
        for (d, away) in [
            (x - x0, [1.0, 0.0]),
            (x1 - x, [-1.0, 0.0]),
            (y - y0, [0.0, 1.0]),
            (y1 - y, [0.0, -1.0]),
        ] {
            if d < c.distance {
                c = Clearance {
                    distance: d.max(0.0),
                    away: if d > 0.0 { away } else { [0.0, 0.0] },
                };
            }
        }
        c
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn brute(w: usize, h: usize, res: f64, mask: &[u8], x: f64, y: f64) -> f64 {
        let mut best = f64::INFINITY;
        for (i, m) in mask.iter().enumerate() {
            if *m == 0 {
                continue;
            }
            let (x0, y0) = ((i % w) as f64 * res, (i / w) as f64 * res);
            let dx = (x0 - x).max(0.0).max(x - (x0 + res));
            let dy = (y0 - y).max(0.0).max(y - (y0 + res));
            best = best.min(dx.hypot(dy));
        }
        let _ = h;
        best
    }

    #[test]
    fn single_cell_distances_and_directions() {
        let mut f = DistanceField::new();
        let mut mask = vec![0u8; 100];
        mask[5 * 10 + 5] = 1; // square [0.5, 0.6] × [0.5, 0.6]
        f.build_from_mask(10, 10, 0.1, [0.0, 0.0], &mask);
        let c = f.clearance(0.85, 0.55);
        assert!((c.distance - 0.25).abs() < 1e-12, "{c:?}");
        assert!((c.away[0] - 1.0).abs() < 1e-12 && c.away[1].abs() < 1e-12);
        let c = f.clearance(0.3, 0.3);
        assert!((c.distance - 0.2f64.hypot(0.2)).abs() < 1e-12, "{c:?}");
        assert_eq!(f.clearance(0.55, 0.55).distance, 0.0);
        let mut empty = DistanceField::new();
        empty.build_from_mask(10, 10, 0.1, [0.0, 0.0], &[0u8; 100]);
        assert_eq!(empty.clearance(0.5, 0.5).distance, f64::INFINITY);
    }

    #[test]
    fn rebuilds_only_when_the_occupied_set_changes() {
        let mut g: Box<Grid> = bytemuck::zeroed_box();
        g.width = 20;
        g.height = 10;
        g.resolution = 0.1;
        let mut f = DistanceField::new();
        assert!(f.update(&g));
        g.cells[3] = mole_types::CELL_FREE;
        assert!(
            !f.update(&g),
            "a newly free cell does not move any obstacle"
        );
        g.cells[7] = CELL_OCCUPIED;
        assert!(f.update(&g));
        assert_eq!(f.builds(), 2);
        g.resolution = f64::NAN;
        assert!(f.update(&g));
        assert_eq!(f.clearance(0.5, 0.5).distance, f64::INFINITY);
    }

    /// The planning queries see the grid's edges as the arena's walls; the plain clearance
    /// (APF and the rollouts add the walls themselves) does not.
    #[test]
    fn the_grid_edges_are_walls_to_the_planning_queries() {
        // 2 m × 1 m at 0.1 m, nothing occupied.
        let mut f = DistanceField::new();
        f.build_from_mask(20, 10, 0.1, [0.0, 0.0], &[0; 200]);
        assert_eq!(f.clearance(0.02, 0.5).distance, f64::INFINITY);
        assert!((f.cell_clearance(0) - 0.05).abs() < 1e-12);
        assert!((f.cell_clearance(5 * 20 + 10) - 0.45).abs() < 1e-12);
        let c = f.clearance_in_arena(0.02, 0.5);
        assert!(
            (c.distance - 0.02).abs() < 1e-12 && c.away == [1.0, 0.0],
            "{c:?}"
        );
        let c = f.clearance_in_arena(1.9, 0.55);
        assert!(
            (c.distance - 0.1).abs() < 1e-12 && c.away == [-1.0, 0.0],
            "{c:?}"
        );
        // Inflated by 0.3 m: three cells deep along every edge.
        let mut clear = Vec::new();
        f.clear_of(0.3, &mut clear);
        for (i, c) in clear.iter().enumerate() {
            let (col, row) = (i % 20, i / 20);
            let inside = (3..17).contains(&col) && (3..7).contains(&row);
            assert_eq!(*c, inside, "cell ({col}, {row})");
        }
    }

    proptest! {
        #[test]
        fn matches_brute_force_within_half_a_cell_diagonal(
            w in 1usize..24, h in 1usize..24,
            seed in proptest::collection::vec(0u8..10, 24 * 24),
            px in 0.0f64..1.0, py in 0.0f64..1.0,
        ) {
            let res = 0.1;
            let mask: Vec<u8> = seed[..w * h].iter().map(|s| (*s == 0) as u8).collect();
            let mut f = DistanceField::new();
            f.build_from_mask(w, h, res, [0.0, 0.0], &mask);
            let (x, y) = (px * w as f64 * res, py * h as f64 * res);
            let exact = brute(w, h, res, &mask, x, y);
            let got = f.clearance(x, y).distance;
            // The fast path agrees with the full query (to the f32 corner, ~1e-6 m).
            let fast = f.distance(x, y);
            prop_assert!((fast.is_infinite() && got.is_infinite()) || (fast - got).abs() < 1e-5,
                "fast {} full {}", fast, got);
            // The one-pass inflation agrees with per-cell clearances.
            let mut clear = Vec::new();
            f.clear_of(0.15, &mut clear);
            for (i, c) in clear.iter().enumerate() {
                let d = f.cell_clearance(i);
                prop_assert!(*c == (d > 0.15) || (d - 0.15).abs() < 1e-5, "cell {} {} {}", i, c, d);
            }
            if exact.is_infinite() {
                prop_assert!(got.is_infinite());
            } else {
                // The nearest cell of the point's cell centre: never nearer than the truth, and
                // at most a cell diagonal farther.
                prop_assert!(got >= exact - 1e-9 && got <= exact + res * 2f64.sqrt() + 1e-9,
                    "got {} exact {}", got, exact);
            }
            // At cell centres the nearest centre's square is within half a cell of the truth.
            for idx in 0..w * h {
                let (cx, cy) = (((idx % w) as f64 + 0.5) * res, ((idx / w) as f64 + 0.5) * res);
                let edge = cx.min(cy).min(w as f64 * res - cx).min(h as f64 * res - cy);
                let e = brute(w, h, res, &mask, cx, cy).min(edge);
                let g = f.cell_clearance(idx);
                prop_assert!((e.is_infinite() && g.is_infinite()) || (g >= e - 1e-9 && g <= e + 0.5 * res),
                    "cell {} got {} exact {}", idx, g, e);
            }
        }
    }
}
