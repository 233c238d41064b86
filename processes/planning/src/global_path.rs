//! A global path for the local planners to follow (Nav2-style: a grid planner's path, a carrot
//! `lookahead` metres ahead of the robot's projection on it, and a path critic).
//!
//! [`GlobalPath::plan`] runs A* ([`GridSearch`]) over the frontier grid inflated by the robot
//! radius + a margin (cells whose centre is farther than that from every occupied cell, using the
//! [`DistanceField`]); first through known free cells only, then, when that fails, optimistically
//! through unexplored cells too, so the robot explores toward a goal it has not seen. The A*
//! path is shortened by line of sight to at most `MAX_PATH` waypoints; a shortcut must cross
//! only passable cells, every cell its segment touches ([`segment_cells`], no corner cutting, as
//! the A* itself), so the shortened path never runs through a cell the inflated grid blocks, and
//! [`GlobalPath::still_clear`] re-checks the same cells of the segments still ahead. Areas the
//! follower failed to get through can be closed to the next plans ([`GlobalPath::avoid`]), so
//! that it takes the next-best way round. [`GlobalPath::set_path`]
//! loads a path planned elsewhere (the frontier planner's Dijkstra path) instead. Everything is
//! preallocated: planning and following allocate nothing once the buffers have the grid's size.

use crate::distance_field::DistanceField;
use crate::grid_search::GridSearch;
use mole_types::{CELL_FREE, CELL_OCCUPIED, Grid, MAX_GRID_CELLS, MAX_PATH};

/// Passable through known free cells.
const KNOWN: u8 = 1;
/// Passable when unexplored cells count as free (optimistic).
const OPTIMISTIC: u8 = 2;
/// Areas closed to planning at most ([`GlobalPath::avoid`]; the oldest is replaced).
pub const MAX_AVOID: usize = 8;

/// Visits every cell that the segment from `a` to `b` (in cell units: cell (i, j) covers
/// [i, i+1) × [j, j+1)) touches, in order, both side cells where it passes exactly through a
/// corner (a supercover, so a shortcut cannot cut a corner the A* would not; algorithms §4.2;
/// Amanatides & Woo 1987). Stops and returns false at the first cell `f` refuses or off the `w × h` grid.
pub fn segment_cells(
    a: [f64; 2],
    b: [f64; 2],
    w: usize,
    h: usize,
    mut f: impl FnMut(usize) -> bool,
) -> bool {
    if !(a[0].is_finite() && a[1].is_finite() && b[0].is_finite() && b[1].is_finite()) {
        return false;
    }
    let (wi, hi) = (w as i64, h as i64);
    let mut visit =
        |cx: i64, cy: i64| cx >= 0 && cy >= 0 && cx < wi && cy < hi && f((cy * wi + cx) as usize);
    let (mut cx, mut cy) = (a[0].floor() as i64, a[1].floor() as i64);
    let (ex, ey) = (b[0].floor() as i64, b[1].floor() as i64);
    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
    let (sx, sy) = (dx.signum() as i64, dy.signum() as i64);
    let step = |d: f64| {
        if d != 0.0 {
            1.0 / d.abs()
        } else {
            f64::INFINITY
        }
    };
    let (tdx, tdy) = (step(dx), step(dy));
    let first = |p: f64, c: i64, d: f64| {
        if d > 0.0 {
            (c as f64 + 1.0 - p) / d
        } else if d < 0.0 {
            (p - c as f64) / -d
        } else {
            f64::INFINITY
        }
    };
    let (mut tx, mut ty) = (first(a[0], cx, dx), first(a[1], cy, dy));
    let most = (cx.abs_diff(ex) + cy.abs_diff(ey)) as usize + 2;
    if !visit(cx, cy) {
        return false;
    }
    for _ in 0..most {
        if cx == ex && cy == ey {
            return true;
        }
        if (tx - ty).abs() < 1e-9 {
            // Through a corner: both side cells count.
            if !(visit(cx + sx, cy) && visit(cx, cy + sy)) {
                return false;
            }
            (cx, cy, tx, ty) = (cx + sx, cy + sy, tx + tdx, ty + tdy);
        } else if tx < ty {
            (cx, tx) = (cx + sx, tx + tdx);
        } else {
            (cy, ty) = (cy + sy, ty + tdy);
        }
        if !visit(cx, cy) {
            return false;
        }
    }
    cx == ex && cy == ey
}

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
    /// The cell of each waypoint (the source's for the start, the target's for the goal).
    waypoint_cells: Vec<u32>,
    /// Disks (x, y, radius; m) closed to planning, and how many there are.
    avoid: [[f64; 3]; MAX_AVOID],
    n_avoid: usize,
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
            waypoint_cells: Vec::with_capacity(MAX_PATH),
            avoid: [[0.0; 3]; MAX_AVOID],
            n_avoid: 0,
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
        self.waypoint_cells.clear();
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

    /// Closes the disk of `radius` m around `p` to the next plans (the start's and the goal's
    /// cells stay open), so that they go another way round; at most [`MAX_AVOID`] disks, the
    /// oldest replaced.
    pub fn avoid(&mut self, p: [f64; 2], radius: f64) {
        if !(p[0].is_finite() && p[1].is_finite() && radius.is_finite() && radius > 0.0) {
            return;
        }
        if self.n_avoid == MAX_AVOID {
            self.avoid.rotate_left(1);
            self.n_avoid -= 1;
        }
        self.avoid[self.n_avoid] = [p[0], p[1], radius];
        self.n_avoid += 1;
    }

    /// The disks closed to planning.
    pub fn avoided(&self) -> &[[f64; 3]] {
        &self.avoid[..self.n_avoid]
    }

    /// Opens every disk [`GlobalPath::avoid`] closed.
    pub fn forget_avoided(&mut self) {
        self.n_avoid = 0;
    }

    /// A* from `start` to `goal` over `grid` inflated by `keep` m (the field must be up to date
    /// with the grid), outside the disks [`GlobalPath::avoid`] closed: known free cells first,
    /// then optimistic. Returns whether a path exists.
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
            self.close_avoided();
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
            // wall); plan once more with the inflation its own cell clears, so that the path
            // leaves through gaps no narrower than where it stands (none at all would let it run
            // through gaps it cannot pass).
            let own = field.cell_clearance(source);
            if attempt == 0 && own <= keep {
                keep = (own - 1e-6).max(0.0);
            } else {
                break;
            }
        }
        false
    }

    /// Zeroes the mask in the disks [`GlobalPath::avoid`] closed.
    fn close_avoided(&mut self) {
        let (w, h, res) = (self.w, self.h, self.res);
        for &[x, y, r] in &self.avoid[..self.n_avoid] {
            let lo = |c: f64, o: f64| (((c - r - o) / res).floor().max(0.0)) as usize;
            let hi =
                |c: f64, o: f64, n: usize| ((((c + r - o) / res).ceil().max(0.0)) as usize).min(n);
            for row in lo(y, self.origin[1])..hi(y, self.origin[1], h) {
                for col in lo(x, self.origin[0])..hi(x, self.origin[0], w) {
                    let q = self.centre(row * w + col);
                    if (q[0] - x).hypot(q[1] - y) <= r {
                        self.mask[row * w + col] = 0;
                    }
                }
            }
        }
    }

    /// The segment between the centres of cells a and b, in cell units.
    fn cell_segment(&self, a: usize, b: usize) -> ([f64; 2], [f64; 2]) {
        let w = self.w;
        (
            [(a % w) as f64 + 0.5, (a / w) as f64 + 0.5],
            [(b % w) as f64 + 0.5, (b / w) as f64 + 0.5],
        )
    }

    /// Whether the segment between the centres of cells a and b touches only cells with `bit`
    /// (cell a aside: the robot may stand in the inflation).
    fn line_of_sight(&self, a: usize, b: usize, bit: u8) -> bool {
        let (pa, pb) = self.cell_segment(a, b);
        segment_cells(pa, pb, self.w, self.h, |i| {
            i == a || self.mask.get(i).is_some_and(|m| m & bit != 0)
        })
    }

    fn extract(&mut self, source: usize, target: usize, bit: u8, start: [f64; 2], goal: [f64; 2]) {
        let mut cells = core::mem::take(&mut self.cells);
        self.search.path_to(target, &mut cells);
        self.path.push(start);
        self.waypoint_cells.push(source as u32);
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
                self.waypoint_cells.push(cells[next]);
            } else {
                // Out of waypoints (not on the grids this stack uses): the last leg to the goal
                // is then unchecked.
                break;
            }
            anchor = next;
        }
        if let (Some(last), Some(cell)) = (self.path.last_mut(), self.waypoint_cells.last_mut())
            && *cell != target as u32
        {
            (*last, *cell) = (goal, target as u32);
        }
        if source == target {
            self.path.push(goal);
            self.waypoint_cells.push(target as u32);
        }
        self.cells = cells;
        self.index = 1.min(self.path.len());
    }

    /// Whether the segments of an A* path still ahead of the robot touch only passable cells
    /// (not occupied, not within the inflation it was planned with of an occupied cell) in the
    /// current field: the cells the line-of-sight shortcut checked, now that unexplored ones
    /// may have turned out occupied. The start's and the goal's cells may sit in the inflation;
    /// external paths are always clear.
    pub fn still_clear(&self, grid: &Grid, field: &DistanceField) -> bool {
        let keep = self.keep;
        if self.kind == PathKind::External || self.kind == PathKind::None {
            return true;
        }
        let cells = grid.cells();
        if cells.len() != self.w * self.h {
            return false;
        }
        let (Some(&source), Some(&target)) =
            (self.waypoint_cells.first(), self.waypoint_cells.last())
        else {
            return true;
        };
        let from = self.index.saturating_sub(1);
        self.waypoint_cells[from.min(self.waypoint_cells.len())..]
            .windows(2)
            .all(|s| {
                let (pa, pb) = self.cell_segment(s[0] as usize, s[1] as usize);
                segment_cells(pa, pb, self.w, self.h, |c| {
                    c == source as usize
                        || c == target as usize
                        || (cells[c] != CELL_OCCUPIED && field.cell_clearance(c) > keep)
                })
            })
    }

    /// The inflation (m) the last A* path was planned with.
    pub fn inflation(&self) -> f64 {
        self.keep
    }

    /// Length (m) of the path left from the robot's projection on its current segment.
    pub fn remaining_length(&self, p: [f64; 2]) -> f64 {
        let n = self.path.len();
        if n < 2 {
            return self
                .path
                .first()
                .map_or(0.0, |q| (q[0] - p[0]).hypot(q[1] - p[1]));
        }
        let i = self.index.clamp(1, n - 1);
        let (a, b) = (self.path[i - 1], self.path[i]);
        let (_, t) = project(a, b, p);
        let len = |a: [f64; 2], b: [f64; 2]| (b[0] - a[0]).hypot(b[1] - a[1]);
        len(a, b) * (1.0 - t)
            + self.path[i..]
                .windows(2)
                .map(|s| len(s[0], s[1]))
                .sum::<f64>()
    }

    /// The centre of the cell of least clearance that the path touches within `within` m
    /// ahead of waypoint `index − 1` (the tightest spot ahead), if the path has one.
    pub fn tightest_ahead(&self, field: &DistanceField, within: f64) -> Option<[f64; 2]> {
        let (w, h) = (self.w, self.h);
        if self.waypoint_cells.len() < 2 || w == 0 {
            return None;
        }
        let from = self
            .index
            .saturating_sub(1)
            .min(self.waypoint_cells.len() - 1);
        let start = self.centre(self.waypoint_cells[from] as usize);
        let mut best = (f64::INFINITY, None);
        for s in self.waypoint_cells[from..].windows(2) {
            let (pa, pb) = self.cell_segment(s[0] as usize, s[1] as usize);
            segment_cells(pa, pb, w, h, |c| {
                let q = self.centre(c);
                if (q[0] - start[0]).hypot(q[1] - start[1]) > within {
                    return false;
                }
                let d = field.cell_clearance(c);
                if d < best.0 {
                    best = (d, Some(q));
                }
                true
            });
        }
        best.1
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

    /// A start inside the inflation plans with the inflation its own cell clears, not none:
    /// the path leaves by a gap at least as wide as where the robot stands. 4 m × 4 m at
    /// 0.05 m; a wall at x = 2 m with a gap of 0.45 m (y ∈ [1, 1.45)) and one of 0.8 m
    /// (y ∈ [2.6, 3.4)); the start 0.3 m from a post, the goal just across the narrow gap.
    #[test]
    fn a_start_inside_the_inflation_does_not_plan_through_a_gap_narrower_than_its_own() {
        let mut grid = grid_free(80, 80, 0.05);
        for r in (0..80).filter(|r| !(20..29).contains(r) && !(52..68).contains(r)) {
            grid.cells[r * 80 + 40] = CELL_OCCUPIED;
        }
        // A post whose face is at x = 1.3 m beside the start (1.0, 1.2).
        for r in 20..29 {
            grid.cells[r * 80 + 26] = CELL_OCCUPIED;
        }
        let mut field = DistanceField::new();
        field.update(&grid);
        let keep = 0.37;
        let start = [1.025, 1.225];
        let own = field.cell_clearance(p_cell(&grid, start));
        assert!(own < keep && own > 0.225, "{own}");
        let mut p = GlobalPath::new();
        assert!(p.plan(&grid, &field, start, [3.0, 1.225], keep));
        assert!(
            (p.inflation() - own).abs() < 1e-5,
            "inflation {}, own {own}",
            p.inflation()
        );
        let crosses = |lo: f64, hi: f64| {
            p.points().windows(2).any(|s| {
                let t = (2.025 - s[0][0]) / (s[1][0] - s[0][0]);
                let y = s[0][1] + t * (s[1][1] - s[0][1]);
                (0.0..=1.0).contains(&t) && (lo..hi).contains(&y)
            })
        };
        assert!(
            crosses(2.6, 3.4) && !crosses(1.0, 1.45),
            "not through the wide gap alone: {:?}",
            p.points()
        );
    }

    fn p_cell(grid: &Grid, q: [f64; 2]) -> usize {
        let (c, r) = (
            ((q[0] - grid.origin_x) / grid.resolution) as usize,
            ((q[1] - grid.origin_y) / grid.resolution) as usize,
        );
        r * grid.width as usize + c
    }

    /// Whether the segment between two points (cell units) stays in cells `ok` accepts,
    /// sampled every 1/200 cell: an independent check of [`segment_cells`].
    fn sampled_clear(a: [f64; 2], b: [f64; 2], w: usize, ok: impl Fn(usize) -> bool) -> bool {
        let n = (((b[0] - a[0]).abs() + (b[1] - a[1]).abs()) * 200.0).ceil() as usize + 1;
        (0..=n).all(|k| {
            let t = k as f64 / n as f64;
            let (x, y) = (a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1]));
            ok(y as usize * w + x as usize)
        })
    }

    #[test]
    fn segment_cells_is_a_supercover_and_closes_corners() {
        let mut seen = Vec::new();
        assert!(segment_cells([0.5, 0.5], [2.5, 2.5], 4, 4, |c| {
            seen.push(c);
            true
        }));
        // Through the corners at (1, 1) and (2, 2): both side cells each time.
        assert_eq!(seen, [0, 1, 4, 5, 6, 9, 10]);
        seen.clear();
        assert!(segment_cells([0.5, 0.5], [3.5, 1.5], 4, 4, |c| {
            seen.push(c);
            true
        }));
        // Through the corner at (2, 1).
        assert_eq!(seen, [0, 1, 2, 5, 6, 7]);
        assert!(
            !segment_cells([0.5, 0.5], [4.5, 0.5], 4, 4, |_| true),
            "off the grid"
        );
    }

    /// Random fields: every segment of every shortened path touches only cells the inflated
    /// grid leaves passable (the start's and the goal's cells aside), by dense sampling.
    #[test]
    fn shortened_paths_never_cross_a_cell_the_inflation_blocks() {
        let (w, h, res, keep) = (40usize, 40usize, 0.1, 0.22);
        let mut state = 0x2545_f491_4f6c_dd1du64;
        let mut rand = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            state
        };
        let (mut planned, mut segments) = (0, 0);
        for _ in 0..200 {
            let mut grid = grid_free(w as u32, h as u32, res);
            for _ in 0..25 {
                grid.cells[(rand() % (w * h) as u64) as usize] = CELL_OCCUPIED;
            }
            let mut field = DistanceField::new();
            field.update(&grid);
            let mut clear = Vec::new();
            field.clear_of(keep, &mut clear);
            let mut pick = || {
                let i = (rand() % (w * h) as u64) as usize;
                [((i % w) as f64 + 0.5) * res, ((i / w) as f64 + 0.5) * res]
            };
            let (start, goal) = (pick(), pick());
            let mut p = GlobalPath::new();
            if !p.plan(&grid, &field, start, goal, keep) || p.inflation() != keep {
                continue;
            }
            planned += 1;
            let (source, target) = (
                p.waypoint_cells[0],
                p.waypoint_cells[p.waypoint_cells.len() - 1],
            );
            for s in p.waypoint_cells.windows(2) {
                segments += 1;
                let (a, b) = p.cell_segment(s[0] as usize, s[1] as usize);
                assert!(
                    sampled_clear(a, b, w, |c| c == source as usize
                        || c == target as usize
                        || (clear[c] && grid.cells[c] != CELL_OCCUPIED)),
                    "segment {a:?} → {b:?} crosses a blocked cell"
                );
            }
            assert!(p.still_clear(&grid, &field));
        }
        assert!(
            planned > 50 && segments > planned,
            "{planned} plans, {segments} segments"
        );
    }

    /// A shortcut runs through cells off the A* path's own cells: an obstacle that appears
    /// there blocks the path (and a re-plan is due), though every A* cell stays passable.
    #[test]
    fn a_cell_occupied_under_a_shortcut_blocks_the_path() {
        let (w, res, keep) = (60usize, 0.1, 0.05);
        let mut grid = grid_free(w as u32, 30, res);
        let mut field = DistanceField::new();
        field.update(&grid);
        let mut p = GlobalPath::new();
        assert!(p.plan(&grid, &field, [0.25, 0.25], [5.45, 2.05], keep));
        assert_eq!(
            p.points().len(),
            2,
            "one straight shortcut: {:?}",
            p.points()
        );
        // The cell under the shortcut farthest from every A* cell.
        let (a, b) = p.cell_segment(p.waypoint_cells[0] as usize, p.waypoint_cells[1] as usize);
        let mut under = Vec::new();
        segment_cells(a, b, w, 30, |c| {
            under.push(c);
            true
        });
        let apart = |c: usize| {
            p.cells
                .iter()
                .map(|&q| {
                    let q = q as usize;
                    (q % w).abs_diff(c % w).max((q / w).abs_diff(c / w))
                })
                .min()
                .unwrap_or(0)
        };
        let far = under.iter().copied().max_by_key(|&c| apart(c)).unwrap_or(0);
        assert!(apart(far) >= 3, "the shortcut stays near the A* cells");
        grid.cells[far] = CELL_OCCUPIED;
        field.update(&grid);
        assert!(
            p.cells
                .iter()
                .all(|&c| field.cell_clearance(c as usize) > keep),
            "every A* cell is still passable"
        );
        assert!(!p.still_clear(&grid, &field), "the shortcut is blocked");
        // The re-plan goes round it.
        assert!(p.plan(&grid, &field, [0.25, 0.25], [5.45, 2.05], keep));
        assert!(p.still_clear(&grid, &field));
    }

    /// A closed disk sends the next plan the other way round; forgetting it opens it again.
    #[test]
    fn an_avoided_gap_is_planned_around() {
        // A wall at x = 2 m with gaps at y ∈ [1, 1.6) and y ∈ [3, 3.6).
        let mut grid = grid_free(40, 40, 0.1);
        for r in (0..40).filter(|r| !(10..16).contains(r) && !(30..36).contains(r)) {
            grid.cells[r * 40 + 20] = CELL_OCCUPIED;
        }
        let mut field = DistanceField::new();
        field.update(&grid);
        let mut p = GlobalPath::new();
        let through = |p: &GlobalPath, y: f64| {
            p.points().windows(2).any(|s| {
                let t = (2.05 - s[0][0]) / (s[1][0] - s[0][0]);
                (0.0..=1.0).contains(&t) && (s[0][1] + t * (s[1][1] - s[0][1]) - y).abs() < 0.4
            })
        };
        assert!(p.plan(&grid, &field, [1.0, 1.3], [3.0, 1.3], 0.2));
        assert!(through(&p, 1.3), "{:?}", p.points());
        p.avoid([2.05, 1.3], 0.3);
        assert!(p.plan(&grid, &field, [1.0, 1.3], [3.0, 1.3], 0.2));
        assert!(through(&p, 3.3) && !through(&p, 1.3), "{:?}", p.points());
        p.forget_avoided();
        assert!(p.plan(&grid, &field, [1.0, 1.3], [3.0, 1.3], 0.2));
        assert!(through(&p, 1.3));
    }
}
