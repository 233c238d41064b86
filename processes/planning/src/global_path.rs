//! A global path for the local planners to follow (Nav2-style: a grid planner's path, a carrot
//! `lookahead` metres ahead of the robot's projection on it, and a path critic).
//!
//! [`GlobalPath::plan`] runs A* ([`GridSearch`]) over the frontier grid inflated by the robot
//! radius + a margin (cells whose centre is farther than that from every occupied cell, using the
//! [`DistanceField`]); first through known free cells only, then, when that fails, optimistically
//! through unexplored cells too, so the robot explores toward a goal it has not seen. The A*
//! path is shortened by line of sight to at most `MAX_PATH` waypoints. [`GlobalPath::set_path`]
//! loads a path planned elsewhere (the frontier planner's Dijkstra path) instead. Everything is
//! preallocated: planning and following allocate nothing once the buffers have the grid's size.

use crate::distance_field::DistanceField;
use crate::grid_search::GridSearch;
use mole_types::{CELL_FREE, CELL_OCCUPIED, Grid, MAX_GRID_CELLS, MAX_PATH};

/// Passable through known free cells.
const KNOWN: u8 = 1;
/// Passable when unexplored cells count as free (optimistic).
const OPTIMISTIC: u8 = 2;

/// How the last [`GlobalPath::plan`] found its path.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PathKind {
    /// No path.
    None,
    /// Through known free cells only.
    Known,
    /// Through unexplored cells too (optimistic planning).
    Optimistic,
    /// Loaded with [`GlobalPath::set_path`].
    External,
}

/// A global path and the follower's progress along it. See the module docs.
#[derive(Debug, Clone)]
pub struct GlobalPath {
    search: GridSearch,
    mask: Vec<u8>,
    clear: Vec<bool>,
    cells: Vec<u32>,
    path: Vec<[f64; 2]>,
    index: usize,
    kind: PathKind,
    w: usize,
    h: usize,
    res: f64,
    origin: [f64; 2],
    /// The inflation the last A* path was planned with.
    keep: f64,
    plans: u64,
}

impl Default for GlobalPath {
    fn default() -> Self {
        Self::new()
    }
}

impl GlobalPath {
    /// An empty path with buffers for the largest grid.
    pub fn new() -> Self {
        Self {
            search: GridSearch::with_capacity(MAX_GRID_CELLS),
            mask: Vec::with_capacity(MAX_GRID_CELLS),
            clear: Vec::with_capacity(MAX_GRID_CELLS),
            cells: Vec::with_capacity(MAX_GRID_CELLS),
            path: Vec::with_capacity(MAX_PATH),
            index: 0,
            kind: PathKind::None,
            w: 0,
            h: 0,
            res: 1.0,
            origin: [0.0; 2],
            keep: 0.0,
            plans: 0,
        }
    }

    /// The waypoints (world, m; the start first).
    pub fn points(&self) -> &[[f64; 2]] {
        &self.path
    }

    /// The waypoints not yet passed (from the segment the robot is on).
    pub fn remaining(&self) -> &[[f64; 2]] {
        let from = self.index.saturating_sub(1).min(self.path.len());
        &self.path[from..]
    }

    /// How the path was made.
    pub fn kind(&self) -> PathKind {
        self.kind
    }

    /// Whether there is a path to follow.
    pub fn is_empty(&self) -> bool {
        self.path.is_empty()
    }

    /// A* searches run so far.
    pub fn plans(&self) -> u64 {
        self.plans
    }

    /// Drops the path.
    pub fn clear(&mut self) {
        self.path.clear();
        self.cells.clear();
        self.index = 0;
        self.kind = PathKind::None;
    }

    /// Loads a path planned elsewhere (at most `MAX_PATH` points); it is not re-checked.
    pub fn set_path(&mut self, points: &[[f64; 2]]) {
        self.clear();
        self.path.extend(points.iter().take(MAX_PATH).copied());
        self.index = 1.min(self.path.len());
        self.kind = if self.path.is_empty() {
            PathKind::None
        } else {
            PathKind::External
        };
    }

    fn cell_of(&self, p: [f64; 2]) -> Option<usize> {
        let col = ((p[0] - self.origin[0]) / self.res).floor();
        let row = ((p[1] - self.origin[1]) / self.res).floor();
        (col >= 0.0 && row >= 0.0 && col < self.w as f64 && row < self.h as f64)
            .then(|| row as usize * self.w + col as usize)
    }

    fn centre(&self, i: usize) -> [f64; 2] {
        [
            self.origin[0] + ((i % self.w) as f64 + 0.5) * self.res,
            self.origin[1] + ((i / self.w) as f64 + 0.5) * self.res,
        ]
    }

    /// A* from `start` to `goal` over `grid` inflated by `keep` m (the field must be up to date
    /// with the grid): known free cells first, then optimistic. Returns whether a path exists.
    pub fn plan(
        &mut self,
        grid: &Grid,
        field: &DistanceField,
        start: [f64; 2],
        goal: [f64; 2],
        keep: f64,
    ) -> bool {
        self.clear();
        let res = grid.resolution;
        let (w, h) = (grid.width as usize, grid.height as usize);
        let cells = grid.cells();
        if !(res.is_finite() && res > 0.0 && grid.origin_x.is_finite() && grid.origin_y.is_finite())
            || w == 0
            || h == 0
            || cells.len() != w * h
        {
            return false;
        }
        (self.w, self.h, self.res, self.origin) = (w, h, res, [grid.origin_x, grid.origin_y]);
        let (Some(source), Some(target)) = (self.cell_of(start), self.cell_of(goal)) else {
            return false;
        };
        self.plans += 1;
        let mut keep = keep;
        for attempt in 0..2 {
            field.clear_of(keep, &mut self.clear);
            if self.clear.len() != cells.len() {
                return false;
            }
            self.mask.clear();
            self.mask
                .extend(cells.iter().zip(&self.clear).map(|(c, clear)| {
                    if *c == CELL_OCCUPIED || !clear {
                        0
                    } else if *c == CELL_FREE {
                        KNOWN | OPTIMISTIC
                    } else {
                        OPTIMISTIC
                    }
                }));
            // The goal cell counts as passable (it may sit in the inflation of a wall).
            self.mask[target] |= OPTIMISTIC | if cells[target] == CELL_FREE { KNOWN } else { 0 };
            for (bit, kind) in [(KNOWN, PathKind::Known), (OPTIMISTIC, PathKind::Optimistic)] {
                let mask = &self.mask;
                if self
                    .search
                    .astar(w, h, &|i| mask[i] & bit != 0, source, target)
                    .is_some()
                {
                    self.kind = kind;
                    self.keep = keep;
                    self.extract(source, target, bit, start, goal);
                    return true;
                }
            }
            // Nothing even optimistically: the robot may sit inside the inflation (pressed to a
            // wall); plan once more without it.
            if attempt == 0 && field.cell_clearance(source) <= keep {
                keep = 0.0;
            } else {
                break;
            }
        }
        false
    }

    /// Whether the segment between cells a and b crosses only cells with `bit`.
    fn line_of_sight(&self, a: usize, b: usize, bit: u8) -> bool {
        let w = self.w;
        let (ax, ay) = ((a % w) as f64 + 0.5, (a / w) as f64 + 0.5);
        let (bx, by) = ((b % w) as f64 + 0.5, (b / w) as f64 + 0.5);
        let n = ((bx - ax).abs().max((by - ay).abs()) * 3.0).ceil() as usize;
        (0..=n).all(|k| {
            let t = if n == 0 { 0.0 } else { k as f64 / n as f64 };
            let (x, y) = (ax + t * (bx - ax), ay + t * (by - ay));
            let i = y as usize * w + x as usize;
            i == a || self.mask.get(i).is_some_and(|m| m & bit != 0)
        })
    }

    fn extract(&mut self, source: usize, target: usize, bit: u8, start: [f64; 2], goal: [f64; 2]) {
        let mut cells = core::mem::take(&mut self.cells);
        self.search.path_to(target, &mut cells);
        self.path.push(start);
        let mut anchor = 0usize;
        while anchor + 1 < cells.len() {
            let mut next = anchor + 1;
            // Bounded look-ahead keeps the shortening near-linear.
            let mut j = anchor + 2;
            while j < cells.len() && j - anchor <= 120 {
                if self.line_of_sight(cells[anchor] as usize, cells[j] as usize, bit) {
                    next = j;
                }
                j += 1;
            }
            let p = if next + 1 == cells.len() {
                goal
            } else {
                self.centre(cells[next] as usize)
            };
            if self.path.len() < MAX_PATH {
                self.path.push(p);
            } else if let Some(last) = self.path.last_mut() {
                *last = p;
            }
            anchor = next;
        }
        if source == target {
            self.path.push(goal);
        }
        self.cells = cells;
        self.index = 1.min(self.path.len());
    }

    /// Whether an A* path's cells are still passable (not occupied, not within the inflation it
    /// was planned with of an occupied cell) in the current field; external paths always are.
    pub fn still_clear(&self, grid: &Grid, field: &DistanceField) -> bool {
        let keep = self.keep;
        if self.kind == PathKind::External || self.kind == PathKind::None {
            return true;
        }
        let cells = grid.cells();
        // The goal cell may sit inside the inflation.
        let n = self.cells.len().saturating_sub(1);
        self.cells[..n].iter().skip(1).all(|&c| {
            let c = c as usize;
            cells.get(c).is_some_and(|v| *v != CELL_OCCUPIED) && field.cell_clearance(c) > keep
        })
    }

    /// Distance (m) from `p` to the remaining path (+∞ without a path).
    pub fn distance_to(&self, p: [f64; 2]) -> f64 {
        path_distance(self.remaining(), p)
    }

    /// Advances along the path past the robot at `p` and returns the carrot: the point of the
    /// path `lookahead` m ahead of the robot's projection on it (the last point at the end).
    pub fn carrot(&mut self, p: [f64; 2], lookahead: f64) -> Option<[f64; 2]> {
        let n = self.path.len();
        if n == 0 {
            return None;
        }
        if n == 1 {
            return Some(self.path[0]);
        }
        // Project on the segments from the current one, a few ahead (never backwards).
        let from = self.index.clamp(1, n - 1);
        let mut best = (f64::INFINITY, from, 0.0);
        for i in from..n.min(from + 8) {
            let (d, t) = project(self.path[i - 1], self.path[i], p);
            if d < best.0 - 1e-9 {
                best = (d, i, t);
            }
        }
        self.index = best.1;
        // Walk `lookahead` along the path from the projection.
        let (mut i, mut t) = (best.1, best.2);
        let mut left = lookahead.max(0.0);
        loop {
            let (a, b) = (self.path[i - 1], self.path[i]);
            let len = (b[0] - a[0]).hypot(b[1] - a[1]);
            let rest = len * (1.0 - t);
            if rest >= left && len > 0.0 {
                let s = t + left / len;
                return Some([a[0] + s * (b[0] - a[0]), a[1] + s * (b[1] - a[1])]);
            }
            left -= rest;
            if i + 1 >= n {
                return Some(b);
            }
            i += 1;
            t = 0.0;
        }
    }
}

/// Distance from `p` to segment a–b and the projection's parameter t ∈ [0, 1].
#[inline]
fn project(a: [f64; 2], b: [f64; 2], p: [f64; 2]) -> (f64, f64) {
    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
    let l2 = dx * dx + dy * dy;
    let t = if l2 > 0.0 {
        (((p[0] - a[0]) * dx + (p[1] - a[1]) * dy) / l2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    let (qx, qy) = (a[0] + t * dx, a[1] + t * dy);
    ((p[0] - qx).hypot(p[1] - qy), t)
}

/// Distance (m) from `p` to a polyline (+∞ when empty; the distance to the point when one).
pub fn path_distance(path: &[[f64; 2]], p: [f64; 2]) -> f64 {
    match path.len() {
        0 => f64::INFINITY,
        1 => (path[0][0] - p[0]).hypot(path[0][1] - p[1]),
        _ => path
            .windows(2)
            .map(|s| project(s[0], s[1], p).0)
            .fold(f64::INFINITY, f64::min),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::obstacles::test_support::grid_free;
    use mole_types::CELL_UNEXPLORED;

    #[test]
    fn carrot_runs_lookahead_ahead_of_the_projection() {
        let mut g = GlobalPath::new();
        g.set_path(&[[0.0, 0.0], [2.0, 0.0], [2.0, 2.0]]);
        let c = g.carrot([0.5, 0.1], 0.6).unwrap_or_default();
        assert!((c[0] - 1.1).abs() < 1e-9 && c[1].abs() < 1e-9, "{c:?}");
        // Around the corner.
        let c = g.carrot([1.8, 0.0], 0.6).unwrap_or_default();
        assert!(
            (c[0] - 2.0).abs() < 1e-9 && (c[1] - 0.4).abs() < 1e-9,
            "{c:?}"
        );
        // Never backwards once on the second segment, and the end clamps.
        let c = g.carrot([2.0, 0.5], 0.6).unwrap_or_default();
        assert!((c[1] - 1.1).abs() < 1e-9, "{c:?}");
        let c = g.carrot([0.0, 0.0], 0.6).unwrap_or_default();
        assert!(c[0] >= 2.0 - 1e-9, "{c:?}");
        let c = g.carrot([2.0, 1.9], 0.6).unwrap_or_default();
        assert_eq!(c, [2.0, 2.0]);
        assert!((path_distance(g.points(), [1.0, 1.0]) - 1.0).abs() < 1e-12);
    }

    #[test]
    fn plans_around_a_wall_and_optimistically_through_the_unknown() {
        // 4 m × 4 m at 0.1 m; a wall at x = 2 from y = 0 to 3 m.
        let mut grid = grid_free(40, 40, 0.1);
        for r in 0..30 {
            grid.cells[r * 40 + 20] = CELL_OCCUPIED;
        }
        let mut field = DistanceField::new();
        field.update(&grid);
        let mut p = GlobalPath::new();
        assert!(p.plan(&grid, &field, [1.0, 1.0], [3.0, 1.0], 0.25));
        assert_eq!(p.kind(), PathKind::Known);
        // Goes over the wall's end (y > 3.25) and ends at the goal.
        assert!(p.points().iter().any(|q| q[1] > 3.2), "{:?}", p.points());
        assert_eq!(p.points().last(), Some(&[3.0, 1.0]));
        for w in p.points().windows(2) {
            // No segment crosses the wall.
            let crosses = (w[0][0] - 2.05) * (w[1][0] - 2.05) < 0.0;
            let y = w[0][1] + (w[1][1] - w[0][1]) * (2.05 - w[0][0]) / (w[1][0] - w[0][0]);
            assert!(!crosses || y > 3.25, "{w:?}");
        }
        assert!(p.still_clear(&grid, &field));
        // Close the gap with unexplored cells: only the optimistic search gets through.
        for r in 30..40 {
            grid.cells[r * 40 + 20] = CELL_UNEXPLORED;
        }
        field.update(&grid);
        assert!(p.plan(&grid, &field, [1.0, 1.0], [3.0, 1.0], 0.25));
        assert_eq!(p.kind(), PathKind::Optimistic);
        // Now wall it off: the old path is blocked, and no path exists.
        for r in 30..40 {
            grid.cells[r * 40 + 20] = CELL_OCCUPIED;
        }
        field.update(&grid);
        assert!(!p.still_clear(&grid, &field));
        assert!(!p.plan(&grid, &field, [1.0, 1.0], [3.0, 1.0], 0.25));
        assert!(p.is_empty());
    }
}
