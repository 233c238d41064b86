//! Ground truth at the mapping grid's resolution: which cells are occupied, which lie next to
//! something occupied, and which the robot centre can reach from the start.
//!
//! The grid convention is the mapping process's: origin (0, 0), cell size `grid_resolution`,
//! `width = ceil(W/res)`, `height = ceil(H/res)`, cell (col, row) at index `row·width + col`,
//! row along y.

use crate::MonitorError;
use mole_types::{MAX_GRID_CELLS, WorldMap};

/// Cell flag: a square obstacle or the outside of the arena overlaps the cell.
pub(crate) const OCCUPIED: u8 = 1;
/// Cell flag: the cell or one of its 8 neighbours is occupied, or it touches the arena edge.
pub(crate) const NEAR_OCCUPIED: u8 = 2;
/// Cell flag: a free cell the robot centre can reach from the start.
pub(crate) const REACHABLE: u8 = 4;

/// A stand-in for +∞ in the squared distance transform that keeps the arithmetic finite.
const FAR: f64 = 1e18;

/// The true occupancy of the arena, rasterised once from `world/map`.
#[derive(Debug, Clone)]
pub(crate) struct TruthRaster {
    pub width: usize,
    pub height: usize,
    pub resolution: f64,
    /// Per cell, a set of `OCCUPIED | NEAR_OCCUPIED | REACHABLE`.
    pub flags: Vec<u8>,
    pub reachable_free: u64,
}

/// Cells along one axis: `ceil(extent/res)`, forgiving floating-point noise of 1e-9 of a cell.
fn cells_along(extent: f64, resolution: f64) -> f64 {
    (extent / resolution - 1e-9).ceil().max(1.0)
}

impl TruthRaster {
    /// Rasterises the map and flood-fills the reachable free area (see [`crate::Monitor::new`]).
    pub fn new(map: &WorldMap) -> Result<TruthRaster, MonitorError> {
        let res = map.grid_resolution;
        let (arena_w, arena_h) = (map.arena_width, map.arena_height);
        let (wf, hf) = (cells_along(arena_w, res), cells_along(arena_h, res));
        if !(wf.is_finite() && hf.is_finite()) || wf * hf > MAX_GRID_CELLS as f64 {
            return Err(MonitorError::GridTooLarge {
                width: wf,
                height: hf,
            });
        }
        let (width, height) = (wf as usize, hf as usize);
        let mut flags = vec![0u8; width * height];

        // A cell is occupied if the outside of the arena overlaps it (a partial last column/row).
        let tol = 1e-6 * res;
        for row in 0..height {
            for col in 0..width {
                let outside = (col + 1) as f64 * res > arena_w + tol
                    || (row + 1) as f64 * res > arena_h + tol;
                if outside {
                    flags[row * width + col] |= OCCUPIED;
                }
            }
        }
        // ...or a square overlaps it with positive area: col·res < max_x and (col+1)·res > min_x.
        for sq in map.obstacles() {
            let (min_x, min_y) = sq.min();
            let (max_x, max_y) = sq.max();
            let Some((c0, c1)) = cell_span(min_x, max_x, res, width) else {
                continue;
            };
            let Some((r0, r1)) = cell_span(min_y, max_y, res, height) else {
                continue;
            };
            for row in r0..=r1 {
                for col in c0..=c1 {
                    flags[row * width + col] |= OCCUPIED;
                }
            }
        }

        // Near-occupied: the 8-neighbourhood (itself included) holds an occupied or outside cell.
        for row in 0..height {
            for col in 0..width {
                let mut near = false;
                for dr in -1i64..=1 {
                    for dc in -1i64..=1 {
                        let (r, c) = (row as i64 + dr, col as i64 + dc);
                        near |= r < 0
                            || c < 0
                            || r >= height as i64
                            || c >= width as i64
                            || flags[r as usize * width + c as usize] & OCCUPIED != 0;
                    }
                }
                if near {
                    flags[row * width + col] |= NEAR_OCCUPIED;
                }
            }
        }

        let mut raster = TruthRaster {
            width,
            height,
            resolution: res,
            flags,
            reachable_free: 0,
        };
        raster.flood_reachable(map.start_x, map.start_y, map.robot.radius);
        Ok(raster)
    }

    /// Marks the free cells whose centre lies farther than r − res/2 from every occupied cell
    /// (the distance to a cell taken as centre-to-centre minus half a cell, i.e. centre distance
    /// > r) and that an 8-connected path of such cells joins to the start.
    fn flood_reachable(&mut self, start_x: f64, start_y: f64, radius: f64) {
        let (w, h) = (self.width, self.height);
        let d2 = squared_distance_to_occupied(w, h, |i| self.flags[i] & OCCUPIED != 0);
        let clearance_cells = radius / self.resolution;
        let threshold = clearance_cells * clearance_cells;
        let candidate: Vec<bool> = (0..w * h)
            .map(|i| self.flags[i] & OCCUPIED == 0 && d2[i] > threshold)
            .collect();

        let Some(seed) = self.seed_cell(start_x, start_y, radius, &candidate) else {
            return;
        };
        let mut stack = Vec::with_capacity(w * h);
        self.flags[seed] |= REACHABLE;
        stack.push(seed);
        let mut count = 1u64;
        while let Some(i) = stack.pop() {
            let (row, col) = ((i / w) as i64, (i % w) as i64);
            for dr in -1i64..=1 {
                for dc in -1i64..=1 {
                    let (r, c) = (row + dr, col + dc);
                    if r < 0 || c < 0 || r >= h as i64 || c >= w as i64 {
                        continue;
                    }
                    let j = r as usize * w + c as usize;
                    if candidate[j] && self.flags[j] & REACHABLE == 0 {
                        self.flags[j] |= REACHABLE;
                        count += 1;
                        stack.push(j);
                    }
                }
            }
        }
        self.reachable_free = count;
    }

    /// The start cell, or (when discretisation makes it a non-candidate) the nearest candidate
    /// within the robot radius plus two cells; `None` when there is none.
    fn seed_cell(&self, x: f64, y: f64, radius: f64, candidate: &[bool]) -> Option<usize> {
        let (w, h) = (self.width as i64, self.height as i64);
        let col = ((x / self.resolution).floor() as i64).clamp(0, w - 1);
        let row = ((y / self.resolution).floor() as i64).clamp(0, h - 1);
        let reach = (radius / self.resolution).ceil() as i64 + 2;
        let mut best: Option<(i64, usize)> = None;
        for dr in -reach..=reach {
            for dc in -reach..=reach {
                let (r, c) = (row + dr, col + dc);
                if r < 0 || c < 0 || r >= h || c >= w {
                    continue;
                }
                let j = (r * w + c) as usize;
                let d = dr * dr + dc * dc;
                if candidate[j] && best.is_none_or(|(bd, _)| d < bd) {
                    best = Some((d, j));
                }
            }
        }
        best.map(|(_, j)| j)
    }

    /// Cell index of a grid cell (col, row).
    #[cfg(test)]
    pub fn index(&self, col: usize, row: usize) -> usize {
        row * self.width + col
    }
}

/// The inclusive range of cells an interval `(lo, hi)` overlaps with positive length, clamped
/// to `0..n`; `None` when it misses the grid.
fn cell_span(lo: f64, hi: f64, res: f64, n: usize) -> Option<(usize, usize)> {
    let first = (lo / res).floor();
    let last = (hi / res).ceil() - 1.0;
    if last < 0.0 || first > (n - 1) as f64 || last < first {
        return None;
    }
    Some((first.max(0.0) as usize, last.min((n - 1) as f64) as usize))
}

/// Squared Euclidean distance (in cells², centre to centre) from every cell of a `w × h` grid to
/// the nearest occupied cell, where everything outside the grid counts as occupied.
///
/// Felzenszwalb & Huttenlocher, "Distance Transforms of Sampled Functions" (2012): the exact
/// squared distance transform as two passes of 1-D lower envelopes of parabolas, on a grid padded
/// with one occupied cell on every side.
pub(crate) fn squared_distance_to_occupied(
    w: usize,
    h: usize,
    occupied: impl Fn(usize) -> bool,
) -> Vec<f64> {
    let (pw, ph) = (w + 2, h + 2);
    let mut grid = vec![0.0f64; pw * ph];
    for row in 0..h {
        for col in 0..w {
            if !occupied(row * w + col) {
                grid[(row + 1) * pw + col + 1] = FAR;
            }
        }
    }
    let n = pw.max(ph);
    let (mut f, mut d) = (vec![0.0; n], vec![0.0; n]);
    let (mut v, mut z) = (vec![0usize; n], vec![0.0; n + 1]);
    for col in 0..pw {
        for row in 0..ph {
            f[row] = grid[row * pw + col];
        }
        lower_envelope(&f[..ph], &mut d[..ph], &mut v, &mut z);
        for row in 0..ph {
            grid[row * pw + col] = d[row];
        }
    }
    for row in 0..ph {
        f[..pw].copy_from_slice(&grid[row * pw..(row + 1) * pw]);
        lower_envelope(&f[..pw], &mut d[..pw], &mut v, &mut z);
        grid[row * pw..(row + 1) * pw].copy_from_slice(&d[..pw]);
    }
    let mut out = vec![0.0; w * h];
    for row in 0..h {
        for col in 0..w {
            out[row * w + col] = grid[(row + 1) * pw + col + 1];
        }
    }
    out
}

/// One 1-D pass: `d[q] = min_p (q − p)² + f[p]` (Felzenszwalb & Huttenlocher, Algorithm 1).
fn lower_envelope(f: &[f64], d: &mut [f64], v: &mut [usize], z: &mut [f64]) {
    let n = f.len();
    if n == 0 {
        return;
    }
    let sq = |q: usize| (q * q) as f64;
    let mut k = 0usize;
    v[0] = 0;
    z[0] = f64::NEG_INFINITY;
    z[1] = f64::INFINITY;
    for q in 1..n {
        let mut s;
        loop {
            let p = v[k];
            s = ((f[q] + sq(q)) - (f[p] + sq(p))) / (2.0 * (q as f64 - p as f64));
            if s <= z[k] && k > 0 {
                k -= 1;
            } else {
                break;
            }
        }
        k += 1;
        v[k] = q;
        z[k] = s;
        z[k + 1] = f64::INFINITY;
    }
    k = 0;
    for (q, dq) in d.iter_mut().enumerate() {
        while z[k + 1] < q as f64 {
            k += 1;
        }
        let p = v[k];
        let dx = q as f64 - p as f64;
        *dq = dx * dx + f[p];
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn brute_force(w: usize, h: usize, occ: &[bool]) -> Vec<f64> {
        let mut out = vec![f64::INFINITY; w * h];
        for r in 0..h as i64 {
            for c in 0..w as i64 {
                let mut best = f64::INFINITY;
                // Occupied cells, and the padding ring outside the grid.
                for rr in -1..=h as i64 {
                    for cc in -1..=w as i64 {
                        let inside = rr >= 0 && cc >= 0 && rr < h as i64 && cc < w as i64;
                        if !inside || occ[(rr * w as i64 + cc) as usize] {
                            let d = ((rr - r).pow(2) + (cc - c).pow(2)) as f64;
                            best = best.min(d);
                        }
                    }
                }
                out[(r * w as i64 + c) as usize] = best;
            }
        }
        out
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]
        /// The two-pass transform equals the brute-force nearest occupied cell, padding included.
        #[test]
        fn distance_transform_matches_brute_force(
            w in 1usize..12,
            h in 1usize..12,
            bits in proptest::collection::vec(proptest::bool::weighted(0.15), 144),
        ) {
            let occ = &bits[..w * h];
            let fast = squared_distance_to_occupied(w, h, |i| occ[i]);
            let slow = brute_force(w, h, occ);
            for i in 0..w * h {
                prop_assert!((fast[i] - slow[i]).abs() < 1e-6, "cell {i}: {} vs {}", fast[i], slow[i]);
            }
        }
    }

    #[test]
    fn cell_span_counts_positive_overlap_only() {
        // [1.75, 2.25] at 0.25 m cells: cols 7 and 8 (touching 6 and 9 only at their edges).
        assert_eq!(cell_span(1.75, 2.25, 0.25, 16), Some((7, 8)));
        assert_eq!(cell_span(-1.0, 0.1, 0.25, 16), Some((0, 0)));
        assert_eq!(cell_span(-2.0, -1.0, 0.25, 16), None);
        assert_eq!(cell_span(5.0, 6.0, 0.25, 16), None);
    }
}
