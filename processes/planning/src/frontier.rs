//! Frontier exploration (algorithms §5; Yamauchi, "A frontier-based approach for autonomous
//! exploration", CIRA 1997).
//!
//! F = free cells with an unexplored 4-neighbour (§5.2), grouped into 8-connected clusters of at
//! least `min_cluster` cells. Each cluster is a candidate f, represented by its reachable cell
//! nearest its centroid; I(f) = unexplored cells within `gain_radius` (a square window, counted
//! with a summed-area table), L(f) from ONE Dijkstra search out of the robot's cell (octile, no
//! corner cutting, through free cells farther than the robot radius + margin from any occupied
//! cell, plus those near the robot when it stands inside that inflation), and
//! C(f) = −α·I/I_max + β·L/L_max with I_max, L_max over the current candidates (§5.3). The chosen
//! frontier's path comes from the Dijkstra predecessors, shortened by line of sight to at most
//! `MAX_PATH` waypoints, and a local planner (DWA or APF) follows a carrot on it. Re-selection:
//! when the frontier is reached, vanishes, or every `reselect_every` steps. A frontier reached
//! that is still there is exhausted (its cells count as no frontier from then on); a target
//! with neither approach nor new area for `give_up_s` is given up and counted (§5.3, "give
//! up"; with nothing else reachable the cells given up once are tried again, and a second
//! give-up holds). Done when no frontier is worth going to: none of `min_cluster` cells or more
//! that is reachable, not exhausted and not given up (algorithms §5, "complete"; `MODE_DONE`,
//! `STATUS_EXPLORATION_COMPLETE`, zero wish).

use crate::distance_field::DistanceField;
use crate::global_path::GlobalPath;
use crate::grid_search::GridSearch;
use crate::{Command, Planner, PlannerInput, RobotLimits, usable};
use mole_types::Setting;
use mole_types::{
    CELL_FREE, CELL_UNEXPLORED, Grid, MAX_GRID_CELLS, MAX_PATH, MODE_DONE, MODE_EXPLORE,
    PlanStatus, PlannerKind, STATUS_EXPLORATION_COMPLETE, STATUS_HAS_FRONTIER, STATUS_HAS_GOAL,
    wrap_angle,
};
use serde::{Deserialize, Serialize};

/// Settings of the frontier planner.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, Setting)]
#[serde(default, deny_unknown_fields)]
pub struct FrontierConfig {
    /// Clusters smaller than this (cells) are ignored.
    #[setting(min = 1)]
    pub min_cluster: usize,
    /// Radius (m) of the information-gain window N(f).
    #[setting(above = 0.0)]
    pub gain_radius: f64,
    /// α: weight of the information gain.
    #[setting(min = 0.0)]
    pub alpha: f64,
    /// β: weight of the path length.
    #[setting(min = 0.0)]
    pub beta: f64,
    /// Re-select at least every this many steps.
    #[setting(min = 1)]
    pub reselect_every: u64,
    /// The frontier counts as reached within this distance (m).
    #[setting(above = 0.0)]
    pub reached_distance: f64,
    /// Carrot distance (m) along the path.
    #[setting(above = 0.0)]
    pub lookahead: f64,
    /// Extra inflation (m) over the robot radius (above the DWA's hard margin, so that the
    /// path leaves the local planner room).
    #[setting(min = 0.0)]
    pub inflation_margin: f64,
    /// Selections in a row without a reachable frontier before exploration is declared done.
    #[setting(min = 1)]
    pub done_after: u32,
    /// APPROACH (m): coming this much closer to the target (along its path) than ever is
    /// progress (algorithms §5.3, "give up").
    #[setting(above = 0.0)]
    pub approach: f64,
    /// A target with neither approach nor new area for this long (s) is given up (§5.3).
    #[setting(above = 0.0)]
    pub give_up_s: f64,
    /// Frontier cells within this distance (m) of a target given up are no frontier any more.
    #[setting(min = 0.0)]
    pub give_up_radius: f64,
}

impl Default for FrontierConfig {
    fn default() -> Self {
        Self {
            min_cluster: 4,
            gain_radius: 1.0,
            alpha: 1.0,
            beta: 1.0,
            reselect_every: 200,
            reached_distance: 0.35,
            lookahead: 0.6,
            inflation_margin: 0.12,
            done_after: 3,
            approach: 0.25,
            give_up_s: 12.0,
            give_up_radius: 0.6,
        }
    }
}

/// A scored frontier candidate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Frontier {
    /// Representative cell (row-major index).
    pub cell: usize,
    /// Its centre (world, m).
    pub x: f64,
    pub y: f64,
    /// Cells in the cluster.
    pub size: usize,
    /// I(f): unexplored cells in N(f).
    pub gain: f64,
    /// L(f) (m).
    pub length: f64,
    /// C(f).
    pub cost: f64,
}

/// Algorithms §5.3: C(f) = −α·I/I_max + β·L/L_max.
pub fn frontier_cost(gain: f64, length: f64, i_max: f64, l_max: f64, alpha: f64, beta: f64) -> f64 {
    let i = if i_max > 0.0 { gain / i_max } else { 0.0 };
    let l = if l_max > 0.0 { length / l_max } else { 0.0 };
    -alpha * i + beta * l
}

/// Algorithms §5.2: whether cell `i` of a `w`-wide 0/1/2 grid is a frontier cell (free, with an
/// unexplored 4-neighbour).
#[inline]
pub fn is_frontier_cell(cells: &[u8], w: usize, h: usize, i: usize) -> bool {
    if cells.get(i) != Some(&CELL_FREE) {
        return false;
    }
    let (c, r) = (i % w, i / w);
    (c > 0 && cells[i - 1] == CELL_UNEXPLORED)
        || (c + 1 < w && cells[i + 1] == CELL_UNEXPLORED)
        || (r > 0 && cells[i - w] == CELL_UNEXPLORED)
        || (r + 1 < h && cells[i + w] == CELL_UNEXPLORED)
}

/// The old detection pass, kept as the oracle: every cell of a `w × h` grid tested with
/// [`is_frontier_cell`]; writes the frontier cells, in increasing index, into `out`.
pub fn frontier_cells_full(cells: &[u8], w: usize, h: usize, out: &mut Vec<u32>) {
    out.clear();
    out.extend(
        (0..(w * h).min(cells.len()))
            .filter_map(|i| is_frontier_cell(cells, w, h, i).then_some(i as u32)),
    );
}

/// The label of a cell in no cluster.
const NOT_FRONTIER: u32 = u32::MAX - 1;

/// Cells compared at once when looking for the cells a grid changed.
const DIFF_BLOCK: usize = 64;

/// The frontier set F kept from grid to grid by re-testing only the cells a grid changed and
/// their 4-neighbours (Keidar & Kaminka 2014, fast frontier detection).
///
/// The changed cells are found by comparing the grid with a copy of the previous one, 64 cells
/// at a time. A grid of another shape gets a full pass. Every buffer is reserved for the
/// largest grid at construction, so no update allocates.
#[derive(Debug, Clone, Default)]
pub struct FrontierCells {
    w: usize,
    h: usize,
    /// One bit per cell: whether it is a frontier cell.
    bits: Vec<u64>,
    /// Frontier cells in `bits`.
    count: usize,
    /// The cells of the grid `bits` was computed from.
    prev_cells: Vec<u8>,
    /// Cells the last update found changed (Keidar & Kaminka 2014, fast frontier detection).
    changed_cells: Vec<u32>,
    /// Full passes made (the first grid and every change of shape).
    full_passes: u64,
}

impl FrontierCells {
    /// An empty set with buffers for grids of up to `cells` cells.
    pub fn with_capacity(cells: usize) -> Self {
        Self {
            bits: Vec::with_capacity(cells.div_ceil(64)),
            prev_cells: Vec::with_capacity(cells),
            changed_cells: Vec::with_capacity(cells),
            ..Self::default()
        }
    }

    /// Brings the set up to date with the `w × h` grid `cells` (row-major, 0/1/2): a full pass
    /// on the first grid or one of another shape, otherwise only the changed cells and their
    /// 4-neighbours are re-tested (Keidar & Kaminka 2014, fast frontier detection). Returns
    /// whether it made a full pass.
    pub fn update(&mut self, cells: &[u8], w: usize, h: usize) -> bool {
        let n = w * h;
        let cells = &cells[..n.min(cells.len())];
        if (w, h) != (self.w, self.h) || self.prev_cells.len() != n || cells.len() != n {
            self.full_pass(cells, w, h);
            return true;
        }
        self.changed_cells.clear();
        let blocks = self
            .prev_cells
            .chunks_mut(DIFF_BLOCK)
            .zip(cells.chunks(DIFF_BLOCK));
        for (b, (prev, now)) in blocks.enumerate() {
            if prev != now {
                let base = b * DIFF_BLOCK;
                let diff = prev
                    .iter()
                    .zip(now)
                    .enumerate()
                    .filter(|(_, (p, q))| p != q);
                self.changed_cells
                    .extend(diff.map(|(k, _)| (base + k) as u32));
                prev.copy_from_slice(now);
            }
        }
        for k in 0..self.changed_cells.len() {
            let i = self.changed_cells[k] as usize;
            let (c, r) = (i % w, i / w);
            self.retest(cells, i);
            if c > 0 {
                self.retest(cells, i - 1);
            }
            if c + 1 < w {
                self.retest(cells, i + 1);
            }
            if r > 0 {
                self.retest(cells, i - w);
            }
            if r + 1 < h {
                self.retest(cells, i + w);
            }
        }
        false
    }

    /// Every cell tested (the first grid, a change of shape).
    pub fn full_pass(&mut self, cells: &[u8], w: usize, h: usize) {
        let n = if cells.len() == w * h { w * h } else { 0 };
        (self.w, self.h) = if n > 0 { (w, h) } else { (0, 0) };
        self.bits.clear();
        self.bits.resize(n.div_ceil(64), 0);
        self.count = 0;
        for (k, word) in self.bits.iter_mut().enumerate() {
            for j in 0..64.min(n - 64 * k) {
                if is_frontier_cell(cells, w, h, 64 * k + j) {
                    *word |= 1 << j;
                    self.count += 1;
                }
            }
        }
        self.prev_cells.clear();
        self.prev_cells.extend_from_slice(&cells[..n]);
        self.changed_cells.clear();
        self.full_passes += 1;
    }

    /// Re-tests cell `i` against [`is_frontier_cell`].
    #[inline]
    fn retest(&mut self, cells: &[u8], i: usize) {
        let (word, bit) = (&mut self.bits[i / 64], 1u64 << (i % 64));
        let was = *word & bit != 0;
        let is = is_frontier_cell(cells, self.w, self.h, i);
        if was != is {
            *word ^= bit;
            if is {
                self.count += 1;
            } else {
                self.count -= 1;
            }
        }
    }

    /// Whether cell `i` is a frontier cell.
    pub fn contains(&self, i: usize) -> bool {
        self.bits
            .get(i / 64)
            .is_some_and(|w| w & (1 << (i % 64)) != 0)
    }

    /// The frontier cells, in increasing index.
    pub fn iter(&self) -> impl Iterator<Item = usize> + '_ {
        self.bits.iter().enumerate().flat_map(|(k, &word)| {
            let mut rest = word;
            core::iter::from_fn(move || {
                (rest != 0).then(|| {
                    let j = rest.trailing_zeros() as usize;
                    rest &= rest - 1;
                    64 * k + j
                })
            })
        })
    }

    /// How many frontier cells there are.
    pub fn len(&self) -> usize {
        self.count
    }

    /// Whether there is no frontier cell.
    pub fn is_empty(&self) -> bool {
        self.count == 0
    }

    /// The cells the last update found changed (empty after a full pass).
    pub fn changed_cells(&self) -> &[u32] {
        &self.changed_cells
    }

    /// Full passes made so far.
    pub fn full_passes(&self) -> u64 {
        self.full_passes
    }
}

/// The detection, clustering, scoring and path machinery, with every buffer preallocated.
#[derive(Debug, Clone)]
pub struct FrontierSelector {
    config: FrontierConfig,
    radius: f64,
    w: usize,
    h: usize,
    res: f64,
    origin: [f64; 2],
    field: DistanceField,
    search: GridSearch,
    passable: Vec<bool>,
    /// The frontier set, updated from the cells each grid changed (Keidar & Kaminka 2014,
    /// fast frontier detection).
    frontier_cells: FrontierCells,
    /// Whether every selection re-tests every cell (the old full pass; benches and tests).
    full_pass: bool,
    /// Per cell: its cluster at the last selection, or `NOT_FRONTIER`.
    label: Vec<u32>,
    /// Cells labelled with a cluster at the last selection, in increasing index.
    labelled: Vec<u32>,
    stack: Vec<u32>,
    integral: Vec<u32>,
    candidates: Vec<Frontier>,
    path_cells: Vec<u32>,
    path: Vec<[f64; 2]>,
    /// Frontier cells the robot went to and could not explore (see [`Self::exhaust`]); they
    /// are no frontier any more. Cleared when the grid's shape changes.
    exhausted: Vec<bool>,
    /// How many times each cell was given up (see [`Self::exhaust_around`]); cleared with
    /// `exhausted`.
    given_up: Vec<u8>,
    /// Whether cells given up once are frontier again ([`Self::retry_given_up`]).
    retrying: bool,
    /// Whether the robot stood inside the inflation at the last selection (`None`: the grid
    /// was unusable or the robot off it).
    inside_inflation: Option<bool>,
}

impl FrontierSelector {
    /// A selector for a robot of `radius` m, with buffers for the largest grid.
    pub fn new(config: FrontierConfig, radius: f64) -> Self {
        let n = MAX_GRID_CELLS;
        Self {
            config,
            radius: if radius.is_finite() && radius > 0.0 {
                radius
            } else {
                0.0
            },
            w: 0,
            h: 0,
            res: 1.0,
            origin: [0.0; 2],
            field: DistanceField::with_capacity(n),
            search: GridSearch::with_capacity(n),
            passable: Vec::with_capacity(n),
            frontier_cells: FrontierCells::with_capacity(n),
            full_pass: false,
            label: Vec::with_capacity(n),
            labelled: Vec::with_capacity(n),
            stack: Vec::with_capacity(n),
            integral: Vec::with_capacity(n + 1024),
            candidates: Vec::with_capacity(n / 4),
            path_cells: Vec::with_capacity(n),
            path: Vec::with_capacity(MAX_PATH),
            exhausted: Vec::with_capacity(n),
            given_up: Vec::with_capacity(n),
            retrying: false,
            inside_inflation: None,
        }
    }

    /// The cluster of frontier cell `cell` in the last selection was reached and is still
    /// there: the sensors cannot explore it from where the robot can go, so it is no frontier
    /// from now on (algorithms §5, "complete").
    pub fn exhaust(&mut self, cell: usize) {
        let Some(&cluster) = self.label.get(cell) else {
            return;
        };
        if self.exhausted.len() != self.label.len() {
            return;
        }
        for (e, &l) in self.exhausted.iter_mut().zip(&self.label) {
            *e |= l == cluster;
        }
    }

    /// Frontier cells within `radius` m of cell `cell` are given up (algorithms §5.3, "give
    /// up"): no frontier until [`Self::retry_given_up`], and for good once given up twice.
    pub fn exhaust_around(&mut self, cell: usize, radius: f64) {
        if self.w == 0 || self.given_up.len() != self.w * self.h || cell >= self.given_up.len() {
            return;
        }
        let (w, h) = (self.w as i64, self.h as i64);
        let k = (radius / self.res).ceil().max(0.0) as i64;
        let (cx, cy) = ((cell % self.w) as i64, (cell / self.w) as i64);
        for y in (cy - k).max(0)..=(cy + k).min(h - 1) {
            for x in (cx - k).max(0)..=(cx + k).min(w - 1) {
                if ((x - cx) * (x - cx) + (y - cy) * (y - cy)) as f64 * self.res * self.res
                    <= radius * radius
                {
                    let n = &mut self.given_up[(y * w + x) as usize];
                    *n = n.saturating_add(1);
                }
            }
        }
    }

    /// With no other frontier reachable: the cells given up once are frontier again, once per
    /// run, and their second give-up holds for good. A give-up may have been a passing failure
    /// (the robot circled at a corner it passes from another side), and held for good it ended
    /// an exploration at 85% coverage with the only way into a corridor given up. Returns
    /// whether that changed anything.
    pub fn retry_given_up(&mut self) -> bool {
        if self.retrying || !self.given_up.contains(&1) {
            return false;
        }
        self.retrying = true;
        true
    }

    /// Whether the cells given up once are frontier again.
    pub fn retrying(&self) -> bool {
        self.retrying
    }

    /// Unexplored cells of the grid at the last selection.
    pub fn unexplored(&self) -> u32 {
        self.integral.last().copied().unwrap_or(0)
    }

    /// The frontier set of the last grid selected on.
    pub fn frontier_cells(&self) -> &FrontierCells {
        &self.frontier_cells
    }

    /// With `yes`, every selection tests and labels every cell, the full pass before Keidar &
    /// Kaminka 2014, fast frontier detection (benches and tests compare the two); the frontier
    /// set is then not kept.
    pub fn set_full_pass(&mut self, yes: bool) {
        self.full_pass = yes;
    }

    /// The candidates of the last selection.
    pub fn candidates(&self) -> &[Frontier] {
        &self.candidates
    }

    /// The chosen frontier's path (world, m; robot first), at most `MAX_PATH` points.
    pub fn path(&self) -> &[[f64; 2]] {
        &self.path
    }

    fn centre(&self, i: usize) -> [f64; 2] {
        [
            self.origin[0] + ((i % self.w) as f64 + 0.5) * self.res,
            self.origin[1] + ((i / self.w) as f64 + 0.5) * self.res,
        ]
    }

    /// Detects, clusters and scores the frontiers of `grid` seen from `robot` and returns the
    /// cheapest reachable one (and fills its path); `None` if none is reachable or the grid is
    /// unusable. Allocation-free once the buffers have the grid's size.
    pub fn select(&mut self, grid: &Grid, robot: [f64; 2]) -> Option<Frontier> {
        let keep = self.radius + self.config.inflation_margin;
        let best = self.select_with(grid, robot, keep);
        if best.is_some() || self.inside_inflation.is_none() {
            return best;
        }
        // Nothing reachable with the inflation: the robot's radius alone (§5.3). Wedged where
        // the inflation leaves no way out, or where it closes a way the robot fits through (a
        // speckle of the map in a corridor: a maze was reported explored at 9% covered).
        self.select_with(grid, robot, self.radius)
    }

    fn select_with(&mut self, grid: &Grid, robot: [f64; 2], keep: f64) -> Option<Frontier> {
        self.inside_inflation = None;
        self.candidates.clear();
        self.path.clear();
        let res = grid.resolution;
        if !(res.is_finite() && res > 0.0 && grid.origin_x.is_finite() && grid.origin_y.is_finite())
        {
            return None;
        }
        let cells = grid.cells();
        let (w, h) = (grid.width as usize, grid.height as usize);
        if w == 0 || h == 0 || cells.len() != w * h {
            return None;
        }
        if !self.full_pass {
            self.frontier_cells.update(cells, w, h);
        }
        if (self.w, self.h) != (w, h) || self.exhausted.len() != w * h {
            self.exhausted.clear();
            self.exhausted.resize(w * h, false);
            self.given_up.clear();
            self.given_up.resize(w * h, 0);
        }
        (self.w, self.h, self.res, self.origin) = (w, h, res, [grid.origin_x, grid.origin_y]);
        let col = ((robot[0] - grid.origin_x) / res).floor();
        let row = ((robot[1] - grid.origin_y) / res).floor();
        if !(col >= 0.0 && row >= 0.0 && col < w as f64 && row < h as f64) {
            return None;
        }
        let source = row as usize * w + col as usize;
        self.field.update(grid);
        // Free cells outside the inflation (and around the robot if it sits inside it).
        self.field.clear_of(keep, &mut self.passable);
        if self.passable.len() != cells.len() {
            return None;
        }
        for (p, c) in self.passable.iter_mut().zip(cells) {
            *p &= *c == CELL_FREE;
        }
        self.inside_inflation = Some(!self.passable[source]);
        if !self.passable[source] {
            // The robot inside the inflation: free cells near it that its radius alone fits
            // (and its own and the next ones no nearer the wall) let it step out (§5.3);
            // everything else keeps the inflation the path is driven with, so a frontier behind
            // a gap too narrow stays unreachable.
            let k = (keep / res).ceil() as i64 + 1;
            let (sc, sr) = (col as i64, row as i64);
            let here = self.field.cell_clearance(source);
            self.passable[source] = cells[source] == CELL_FREE;
            for r in (sr - k).max(0)..=(sr + k).min(h as i64 - 1) {
                for c in (sc - k).max(0)..=(sc + k).min(w as i64 - 1) {
                    let i = r as usize * w + c as usize;
                    let d2 = ((r - sr) * (r - sr) + (c - sc) * (c - sc)) as f64;
                    let clearance = self.field.cell_clearance(i);
                    // Its radius fits, or one cell from where it stands, no nearer the wall.
                    let fits = clearance > self.radius
                        || ((r - sr).abs() <= 1 && (c - sc).abs() <= 1 && clearance >= here);
                    if d2 <= (k * k) as f64 && cells[i] == CELL_FREE && fits {
                        self.passable[i] = true;
                    }
                }
            }
        }
        let passable = &self.passable;
        self.search.dijkstra(w, h, &|i| passable[i], source);
        // Summed-area table of the unexplored cells, (w+1) × (h+1).
        self.integral.clear();
        self.integral.resize((w + 1) * (h + 1), 0);
        for r in 0..h {
            let mut run = 0u32;
            for c in 0..w {
                run += (cells[r * w + c] == CELL_UNEXPLORED) as u32;
                self.integral[(r + 1) * (w + 1) + c + 1] = self.integral[r * (w + 1) + c + 1] + run;
            }
        }
        // Clusters: 8-connected flood fill over the frontier cells, seeded in increasing index
        // from the frontier set (Keidar & Kaminka 2014, fast frontier detection): only the
        // cells labelled last time are reset, not the whole grid.
        const UNSEEN: u32 = u32::MAX;
        if self.label.len() != w * h {
            self.label.clear();
            self.label.resize(w * h, NOT_FRONTIER);
            self.labelled.clear();
        }
        for &i in &self.labelled {
            self.label[i as usize] = NOT_FRONTIER;
        }
        self.labelled.clear();
        let (exhausted, given_up, retrying) = (&self.exhausted, &self.given_up, self.retrying);
        let open = |i: usize| !exhausted[i] && (given_up[i] == 0 || (retrying && given_up[i] == 1));
        if self.full_pass {
            // The old pass: every cell tested, every label written.
            for (i, l) in self.label.iter_mut().enumerate() {
                *l = if is_frontier_cell(cells, w, h, i) && open(i) {
                    UNSEEN
                } else {
                    NOT_FRONTIER
                };
            }
            let label = &self.label;
            self.labelled
                .extend((0..w * h).filter(|&i| label[i] == UNSEEN).map(|i| i as u32));
        } else {
            for i in self.frontier_cells.iter() {
                if open(i) {
                    self.label[i] = UNSEEN;
                    self.labelled.push(i as u32);
                }
            }
        }
        let gain_cells = (self.config.gain_radius / res).round().max(0.0) as usize;
        let mut n_clusters = 0u32;
        for k in 0..self.labelled.len() {
            let seed = self.labelled[k] as usize;
            if self.label[seed] != UNSEEN {
                continue;
            }
            // Pass 1: label the cluster and its centroid.
            self.stack.clear();
            self.stack.push(seed as u32);
            self.label[seed] = n_clusters;
            let (mut sx, mut sy, mut size) = (0.0, 0.0, 0usize);
            let first = self.path_cells.len();
            debug_assert_eq!(first, 0);
            while let Some(c) = self.stack.pop() {
                let c = c as usize;
                size += 1;
                sx += (c % w) as f64;
                sy += (c / w) as f64;
                self.path_cells.push(c as u32); // members, reused as scratch
                let (cx, cy) = ((c % w) as i64, (c / w) as i64);
                for dy in -1..=1i64 {
                    for dx in -1..=1i64 {
                        let (nx, ny) = (cx + dx, cy + dy);
                        if nx < 0 || ny < 0 || nx >= w as i64 || ny >= h as i64 {
                            continue;
                        }
                        let n = ny as usize * w + nx as usize;
                        if self.label[n] == UNSEEN {
                            self.label[n] = n_clusters;
                            self.stack.push(n as u32);
                        }
                    }
                }
            }
            n_clusters += 1;
            let members = &self.path_cells;
            if size >= self.config.min_cluster {
                let (mx, my) = (sx / size as f64, sy / size as f64);
                // The reachable member nearest the centroid.
                let mut best: Option<(f64, usize, f64)> = None;
                for &m in members {
                    let m = m as usize;
                    if let Some(l) = self.search.distance(m) {
                        let d = ((m % w) as f64 - mx).hypot((m / w) as f64 - my);
                        if best.is_none_or(|b| d < b.0) {
                            best = Some((d, m, l));
                        }
                    }
                }
                if let Some((_, m, l)) = best {
                    let (c, r) = (m % w, m / w);
                    let (c0, c1) = (c.saturating_sub(gain_cells), (c + gain_cells + 1).min(w));
                    let (r0, r1) = (r.saturating_sub(gain_cells), (r + gain_cells + 1).min(h));
                    let s = |r: usize, c: usize| self.integral[r * (w + 1) + c] as i64;
                    let gain = (s(r1, c1) - s(r0, c1) - s(r1, c0) + s(r0, c0)) as f64;
                    let [x, y] = self.centre(m);
                    if self.candidates.len() < self.candidates.capacity() {
                        self.candidates.push(Frontier {
                            cell: m,
                            x,
                            y,
                            size,
                            gain,
                            length: l * res,
                            cost: 0.0,
                        });
                    }
                }
            }
            self.path_cells.clear();
        }
        // C(f) with I_max, L_max over the candidates.
        let i_max = self.candidates.iter().map(|f| f.gain).fold(0.0, f64::max);
        let l_max = self.candidates.iter().map(|f| f.length).fold(0.0, f64::max);
        let (alpha, beta) = (self.config.alpha, self.config.beta);
        let mut best: Option<Frontier> = None;
        for f in self.candidates.iter_mut() {
            f.cost = frontier_cost(f.gain, f.length, i_max, l_max, alpha, beta);
            if best.is_none_or(|b| f.cost < b.cost) {
                best = Some(*f);
            }
        }
        let best = best?;
        self.extract_path(best.cell, robot);
        Some(best)
    }

    /// Whether the straight segment between cells a and b crosses only passable cells.
    fn line_of_sight(&self, a: usize, b: usize) -> bool {
        let w = self.w;
        let (ax, ay) = ((a % w) as f64 + 0.5, (a / w) as f64 + 0.5);
        let (bx, by) = ((b % w) as f64 + 0.5, (b / w) as f64 + 0.5);
        let n = ((bx - ax).abs().max((by - ay).abs()) * 2.0).ceil() as usize;
        (0..=n).all(|k| {
            let t = if n == 0 { 0.0 } else { k as f64 / n as f64 };
            let (x, y) = (ax + t * (bx - ax), ay + t * (by - ay));
            let i = y as usize * w + x as usize;
            self.passable.get(i).copied().unwrap_or(false) || i == a
        })
    }

    fn extract_path(&mut self, target: usize, robot: [f64; 2]) {
        let mut cells = core::mem::take(&mut self.path_cells);
        self.search.path_to(target, &mut cells);
        self.path.clear();
        self.path.push(robot);
        // Greedy line-of-sight shortening (bounded look-ahead keeps it linear-ish).
        let mut anchor = 0usize;
        while anchor + 1 < cells.len() {
            let mut next = anchor + 1;
            let mut j = anchor + 2;
            while j < cells.len() && j - anchor <= 200 {
                if self.line_of_sight(cells[anchor] as usize, cells[j] as usize) {
                    next = j;
                }
                j += 1;
            }
            let p = self.centre(cells[next] as usize);
            if self.path.len() < MAX_PATH {
                self.path.push(p);
            } else if let Some(last) = self.path.last_mut() {
                *last = p;
            }
            anchor = next;
        }
        cells.clear();
        self.path_cells = cells;
    }
}

/// The frontier planner (algorithms §5) with a local planner following the path.
#[derive(Debug)]
pub struct FrontierExplorer {
    config: FrontierConfig,
    /// The goal seeker that follows the path (`--local-planner`, [`Planner::track`]).
    local: Box<dyn Planner>,
    selector: FrontierSelector,
    chosen: Option<Frontier>,
    /// The chosen frontier's path, followed with a carrot (shared with the `dwa` planner).
    follow: GlobalPath,
    last_select: Option<u64>,
    misses: u32,
    done: bool,
    carrot: Option<[f64; 2]>,
    selections: u64,
    /// Progress toward the target (algorithms §5.3, "give up").
    track: Track,
    /// Targets given up so far: not approached in time (§5.3).
    give_ups: u32,
}

/// A target's progress (algorithms §5.3, "give up"): the shortest path length left to it so
/// far, the fewest unexplored cells seen, and the step of the last progress.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Track {
    target: Option<[f64; 2]>,
    best: f64,
    unexplored: u32,
    since: u64,
}

/// A target that moved this far (m) is a new one: its approach is measured afresh, but the
/// switch itself is no progress (as the monitor's livelock detector judges it).
const NEW_TARGET_M: f64 = 0.5;
/// Fewer unexplored cells than ever by this many is new area, progress (§5.3).
const NEW_AREA_CELLS: u32 = 10;

impl FrontierExplorer {
    /// A frontier explorer with `local` following the path.
    pub fn new(limits: RobotLimits, config: FrontierConfig, local: Box<dyn Planner>) -> Self {
        let limits = limits.sanitized();
        Self {
            config,
            local,
            selector: FrontierSelector::new(config, limits.radius),
            chosen: None,
            follow: GlobalPath::new(),
            last_select: None,
            misses: 0,
            done: false,
            carrot: None,
            selections: 0,
            track: Track {
                target: None,
                best: f64::INFINITY,
                unexplored: u32::MAX,
                since: 0,
            },
            give_ups: 0,
        }
    }

    /// Frontier targets given up so far: not approached in time (algorithms §5.3).
    pub fn give_ups(&self) -> u32 {
        self.give_ups
    }

    /// Path length (m) left from `p` along the followed path to its end.
    fn path_left(&self, p: [f64; 2]) -> f64 {
        let rest = self.follow.remaining();
        let Some(&first) = rest.get(1) else {
            return self
                .chosen
                .map_or(f64::INFINITY, |f| (p[0] - f.x).hypot(p[1] - f.y));
        };
        let along: f64 = rest[1..]
            .windows(2)
            .map(|s| (s[1][0] - s[0][0]).hypot(s[1][1] - s[0][1]))
            .sum();
        (p[0] - first[0]).hypot(p[1] - first[1]) + along
    }

    /// Algorithms §5.3, "give up": progress is APPROACH closer to the target along its path
    /// than ever, or new area; a target with neither for `give_up_s` is given up, its frontier
    /// cells within `give_up_radius` exhausted and counted. Returns whether it was given up.
    fn watch_progress(&mut self, tick: u64, dt: f64, p: [f64; 2]) -> bool {
        let Some(f) = self.chosen else {
            return false;
        };
        let t = &mut self.track;
        if t.target
            .is_none_or(|o| (o[0] - f.x).hypot(o[1] - f.y) >= NEW_TARGET_M)
        {
            (t.target, t.best) = (Some([f.x, f.y]), f64::INFINITY);
        }
        let left = self.path_left(p);
        let t = &mut self.track;
        if !t.best.is_finite() {
            t.best = left;
        } else if left < t.best - self.config.approach {
            (t.best, t.since) = (left, tick);
        }
        let window = (self.config.give_up_s / dt).ceil() as u64;
        if tick.saturating_sub(t.since) < window.max(1) {
            return false;
        }
        self.selector
            .exhaust_around(f.cell, self.config.give_up_radius);
        self.give_ups = self.give_ups.saturating_add(1);
        (t.since, t.target) = (tick, None);
        self.chosen = None;
        true
    }

    /// The chosen frontier.
    pub fn chosen(&self) -> Option<Frontier> {
        self.chosen
    }

    /// Whether no reachable frontier is left.
    pub fn done(&self) -> bool {
        self.done
    }

    /// Selections made so far.
    pub fn selections(&self) -> u64 {
        self.selections
    }

    /// The selector (candidates, path).
    pub fn selector(&self) -> &FrontierSelector {
        &self.selector
    }

    fn needs_selection(&self, grid: &Grid, tick: u64, p: [f64; 2]) -> bool {
        let Some(f) = self.chosen else { return true };
        let Some(last) = self.last_select else {
            return true;
        };
        let (w, h) = (grid.width as usize, grid.height as usize);
        tick.saturating_sub(last) >= self.config.reselect_every
            || (p[0] - f.x).hypot(p[1] - f.y) < self.config.reached_distance
            || !is_frontier_cell(grid.cells(), w, h, f.cell)
    }

    fn carrot(&mut self, p: [f64; 2]) -> [f64; 2] {
        self.follow.carrot(p, self.config.lookahead).unwrap_or(p)
    }
}

impl crate::Registered for FrontierExplorer {
    fn build(
        settings: &crate::Settings,
        limits: RobotLimits,
        _goal: Option<[f64; 2]>,
        local: Option<Box<dyn Planner>>,
        _seed: u64,
    ) -> Result<Self, crate::PlanningError> {
        let local = local.ok_or(crate::PlanningError::NotAFollower {
            kind: PlannerKind::Frontier,
        })?;
        Ok(FrontierExplorer::new(limits, settings.frontier, local))
    }

    /// The DWA follows its paths by default: the reactive layer is set as under the DWA.
    fn bounce_back(settings: &crate::Settings) -> crate::BounceBackConfig {
        settings.bounce_back.under_dwa(&settings.dwa)
    }
}

impl Planner for FrontierExplorer {
    fn kind(&self) -> PlannerKind {
        PlannerKind::Frontier
    }

    fn set_settings(&mut self, settings: &crate::Settings) -> Result<(), String> {
        self.local.set_settings(settings)?;
        (self.config, self.selector.config) = (settings.frontier, settings.frontier);
        Ok(())
    }

    fn step(&mut self, input: &PlannerInput) -> Command {
        if !usable(input) {
            return Command::STOP;
        }
        let p = [input.pose.x, input.pose.y];
        let Some(grid) = input.grid else {
            // No map yet: look around in place.
            return Command {
                v: 0.0,
                omega: 0.5,
                mode: MODE_EXPLORE,
            };
        };
        let gave_up = self.watch_progress(input.tick, input.dt, p);
        if gave_up || self.needs_selection(grid, input.tick, p) {
            // Reached, yet still a frontier: nothing to gain there (algorithms §5, "complete").
            let (w, h) = (grid.width as usize, grid.height as usize);
            if let Some(f) = self.chosen
                && (p[0] - f.x).hypot(p[1] - f.y) < self.config.reached_distance
                && is_frontier_cell(grid.cells(), w, h, f.cell)
            {
                self.selector.exhaust(f.cell);
            }
            self.last_select = Some(input.tick);
            self.selections += 1;
            self.chosen = self.selector.select(grid, p);
            let unexplored = self.selector.unexplored();
            if unexplored.saturating_add(NEW_AREA_CELLS) <= self.track.unexplored
                || self.track.unexplored == u32::MAX
            {
                (self.track.unexplored, self.track.since) = (unexplored, input.tick);
            }
            self.follow.set_path(self.selector.path());
            if self.chosen.is_some() {
                self.misses = 0;
                self.done = false;
            } else if crate::obstacles::grid_cell(grid, p[0], p[1]) == Some(CELL_FREE) {
                // The robot is on the map and no frontier is reachable: before calling it done,
                // the frontier given up once is tried again.
                self.misses += 1;
                if self.misses >= self.config.done_after && self.selector.retry_given_up() {
                    self.misses = 0;
                }
                self.done = self.misses >= self.config.done_after;
                // Look again soon.
                self.last_select = Some(
                    input
                        .tick
                        .saturating_sub(self.config.reselect_every.saturating_sub(20)),
                );
            }
        }
        if self.done {
            self.carrot = None;
            Command {
                v: 0.0,
                omega: 0.0,
                mode: MODE_DONE,
            }
        } else if self.chosen.is_some() {
            let carrot = self.carrot(p);
            self.carrot = Some(carrot);
            let c = self.local.track(input, carrot, self.follow.remaining());
            Command {
                mode: if c.mode == mole_types::MODE_STALLED || c.mode == mole_types::MODE_ESCAPE {
                    c.mode
                } else {
                    MODE_EXPLORE
                },
                ..c
            }
        } else {
            // Nothing reachable yet (map still empty around the robot): turn in place to see.
            let e = wrap_angle(0.5);
            Command {
                v: 0.0,
                omega: e,
                mode: MODE_EXPLORE,
            }
        }
    }

    fn replan(&mut self) {
        self.chosen = None;
        self.local.replan();
    }

    fn target(&self) -> Option<[f64; 2]> {
        self.chosen.map(|f| [f.x, f.y])
    }

    fn write_status(&self, status: &mut PlanStatus) {
        status.flags = 0;
        (status.goal_x, status.goal_y) = (0.0, 0.0);
        (status.frontier_x, status.frontier_y) = (0.0, 0.0);
        status.n_path = 0;
        status.bounces = 0;
        status.give_ups = self.give_ups;
        if self.done {
            status.flags |= STATUS_EXPLORATION_COMPLETE;
            return;
        }
        if let Some(f) = self.chosen {
            status.flags |= STATUS_HAS_FRONTIER;
            (status.frontier_x, status.frontier_y) = (f.x, f.y);
            if let Some(c) = self.carrot {
                status.flags |= STATUS_HAS_GOAL;
                (status.goal_x, status.goal_y) = (c[0], c[1]);
            }
            let path = self.selector.path();
            crate::write_path(status, path);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::obstacles::test_support::grid_free;
    use mole_types::CELL_OCCUPIED;

    fn limits() -> RobotLimits {
        RobotLimits::default()
    }

    /// The DWA with default settings, as frontier's follower.
    fn dwa_follower() -> Box<dyn Planner> {
        Box::new(crate::Dwa::new(
            limits(),
            crate::DwaConfig::default(),
            [0.0, 0.0],
        ))
    }

    #[test]
    fn frontier_cells_are_free_with_an_unexplored_4_neighbour() {
        let cells = [1, 1, 0, 1, 2, 1, 1, 1, 1];
        let f: Vec<bool> = (0..9).map(|i| is_frontier_cell(&cells, 3, 3, i)).collect();
        assert_eq!(
            f,
            [false, true, false, false, false, true, false, false, false]
        );
    }

    #[test]
    fn cost_trades_gain_against_length() {
        assert_eq!(frontier_cost(10.0, 5.0, 10.0, 10.0, 1.0, 1.0), -0.5);
        assert_eq!(frontier_cost(0.0, 0.0, 0.0, 0.0, 1.0, 1.0), 0.0);
    }

    /// A 4 m × 2 m free strip (0.1 m cells) with unexplored space left and right; a wall with a
    /// gap splits it.
    fn corridor() -> Box<Grid> {
        let mut g = grid_free(60, 20, 0.1);
        for r in 0..20 {
            for c in 0..10 {
                g.cells[r * 60 + c] = CELL_UNEXPLORED;
            }
            for c in 50..60 {
                g.cells[r * 60 + c] = CELL_UNEXPLORED;
            }
        }
        g
    }

    #[test]
    fn nearer_frontier_wins_at_equal_gain_and_walls_lengthen_paths() {
        let g = corridor();
        // A thin inflation (0.03 m): the 0.5 m gap below is passable only for a thin one.
        let thin = FrontierConfig {
            inflation_margin: 0.03,
            ..FrontierConfig::default()
        };
        let mut s = FrontierSelector::new(thin, 0.2);
        let f = s.select(&g, [2.0, 1.0]);
        assert_eq!(s.candidates().len(), 2);
        let f = f.unwrap_or_else(|| panic!("no frontier"));
        // Robot at x = 2.0: the left frontier (x = 1.05) is nearer than the right one (4.95).
        assert!((f.x - 1.05).abs() < 1e-9, "{f:?}");
        assert!((f.length - 0.95).abs() < 0.15, "{f:?}");
        // Path from the robot to the frontier, straight (line of sight).
        assert_eq!(s.path().len(), 2, "{:?}", s.path());
        // From x = 2.6 the left frontier is still the nearer (1.6 m against 2.4 m); a wall at
        // x = 1.5 with a gap of 0.5 m at the top (against the arena's wall): the left
        // frontier's path goes around it and the right one becomes the cheaper.
        let mut g = corridor();
        for r in 0..15 {
            g.cells[r * 60 + 15] = CELL_OCCUPIED;
        }
        let f = s
            .select(&g, [2.6, 0.5])
            .unwrap_or_else(|| panic!("no frontier"));
        let left = s.candidates().iter().find(|c| c.x < 2.0).map(|c| c.length);
        assert!(left.is_some_and(|l| l > 2.5), "{:?}", s.candidates());
        assert!(f.x > 4.0, "{f:?}");
        assert!(s.path().len() >= 2);
    }

    #[test]
    fn unreachable_frontier_is_excluded_and_inflation_falls_back() {
        let mut g = corridor();
        // Seal the left part off completely.
        for r in 0..20 {
            g.cells[r * 60 + 15] = CELL_OCCUPIED;
        }
        let mut s = FrontierSelector::new(FrontierConfig::default(), 0.2);
        let f = s.select(&g, [3.0, 1.0]).unwrap_or_else(|| panic!("none"));
        assert!(f.x > 4.0 && s.candidates().len() == 1);
        // Robot pressed against the wall (inside the inflation): still plans.
        let f = s.select(&g, [1.65, 1.0]);
        assert!(f.is_some());
    }

    /// A 4 m × 4 m room at 0.1 m: the left half explored and free, the right half unexplored.
    fn half_explored_room() -> Box<Grid> {
        let mut g = grid_free(40, 40, 0.1);
        for r in 0..40 {
            g.cells[r * 40 + 20..r * 40 + 40].fill(CELL_UNEXPLORED);
        }
        g
    }

    /// Steps `e` `steps` times at `pose` on `g` (the robot held there), each after the command
    /// before; returns the modes.
    fn hold(e: &mut FrontierExplorer, g: &Grid, pose: mole_types::Pose2, steps: u64) -> Vec<u32> {
        let mut c = Command::STOP;
        (0..steps)
            .map(|tick| {
                c = e.step(&PlannerInput {
                    tick,
                    dt: 0.01,
                    pose,
                    scan: None,
                    tactile: None,
                    grid: Some(g),
                    last_command: c,
                });
                c.mode
            })
            .collect()
    }

    fn explorer() -> FrontierExplorer {
        FrontierExplorer::new(limits(), FrontierConfig::default(), dwa_follower())
    }

    /// Half a room unexplored, its frontier 1.5 m away and reachable: never done while the
    /// robot takes its time (five re-selections) within the give-up window.
    #[test]
    fn a_reachable_frontier_with_gain_is_never_done() {
        let g = half_explored_room();
        let mut e = explorer();
        let modes = hold(&mut e, &g, mole_types::Pose2::new(0.5, 2.0, 0.0), 1100);
        assert!(
            !modes.contains(&MODE_DONE),
            "done with half the room unexplored"
        );
        assert!(e.chosen().is_some_and(|f| f.x > 1.9 && f.x < 2.1));
        assert!(e.selections() >= 5 && !e.done() && e.give_ups() == 0);
    }

    /// Steps an explorer held at one pose in [`half_explored_room`] at 100 Hz, calling `each`
    /// after every step, until it is done or `ticks` steps went by; returns it and its last
    /// command.
    fn held_in_the_room(
        ticks: u64,
        mut each: impl FnMut(u64, &FrontierExplorer),
    ) -> (FrontierExplorer, Command) {
        let g = half_explored_room();
        let mut e = explorer();
        let pose = mole_types::Pose2::new(0.5, 2.0, 0.0);
        let mut c = Command::STOP;
        for tick in 0..ticks {
            c = e.step(&PlannerInput {
                tick,
                dt: 0.01,
                pose,
                scan: None,
                tactile: None,
                grid: Some(&g),
                last_command: c,
            });
            each(tick, &e);
            if c.mode == MODE_DONE {
                break;
            }
        }
        (e, c)
    }

    /// Algorithms §5.3, "give up": the robot held where it is never approaches the target;
    /// after `give_up_s` without approach or new area the target is given up and counted, the
    /// next one likewise, and once the whole frontier is given up exploration is complete.
    #[test]
    fn a_target_not_approached_in_time_is_given_up_and_counted_then_done() {
        let window = (FrontierConfig::default().give_up_s / 0.01) as usize;
        let mut first = None;
        let (e, c) = held_in_the_room(10_000, |tick, e| {
            if first.is_none() && e.give_ups() > 0 {
                first = Some(tick as usize);
            }
        });
        let first = first.unwrap_or_else(|| panic!("never given up"));
        assert!(
            (window..window + 10).contains(&first),
            "first give-up at step {first}, window {window}"
        );
        assert_eq!(
            c.mode,
            MODE_DONE,
            "not done after {} give-ups",
            e.give_ups()
        );
        assert!(e.give_ups() >= 2, "{}", e.give_ups());
        let mut st: Box<PlanStatus> = bytemuck::zeroed_box();
        e.write_status(&mut st);
        assert_eq!(st.give_ups, e.give_ups());
        assert_ne!(st.flags & STATUS_EXPLORATION_COMPLETE, 0);
    }

    /// Algorithms §5.3, "give up": with nothing else reachable, the frontier given up once is
    /// tried again before exploration is complete, and given up again for good: the robot held
    /// in place gives up every target twice. (Held for good after one give-up, exploration
    /// ended at 85% coverage on a maze whose only way into a corridor was given up.)
    #[test]
    fn a_frontier_given_up_is_tried_again_before_exploration_is_complete() {
        let mut before_retry = None;
        let (e, c) = held_in_the_room(40_000, |_, e| {
            if before_retry.is_none() && e.selector().retrying() {
                before_retry = Some(e.give_ups());
            }
        });
        assert_eq!(
            c.mode,
            MODE_DONE,
            "not done after {} give-ups",
            e.give_ups()
        );
        let first = before_retry.expect("the given-up frontier was tried again");
        assert!(first >= 1, "{first}");
        assert!(
            e.give_ups() >= 2 * first,
            "{} give-ups in all, {first} before the retry",
            e.give_ups()
        );
    }

    /// Algorithms §5.3: the only frontier lies behind a 0.3 m gap, narrower than the inflated
    /// robot (and than the robot itself); the robot stands inside the inflation beside the wall.
    /// The frontier is never chosen and exploration is complete.
    #[test]
    fn a_frontier_behind_a_gap_too_narrow_is_never_chosen_and_then_done() {
        let mut g = corridor();
        for r in 0..20 {
            g.cells[r * 60 + 50..r * 60 + 60].fill(CELL_FREE);
            if !(9..12).contains(&r) {
                g.cells[r * 60 + 15] = CELL_OCCUPIED;
            }
        }
        let mut e = explorer();
        let pose = mole_types::Pose2::new(1.75, 1.0, 0.0);
        let mut c = Command::STOP;
        for tick in 0..400 {
            c = e.step(&PlannerInput {
                tick,
                dt: 0.01,
                pose,
                scan: None,
                tactile: None,
                grid: Some(&g),
                last_command: c,
            });
            assert!(e.chosen().is_none(), "step {tick}: chose {:?}", e.chosen());
        }
        assert!(e.done() && c.mode == MODE_DONE);
    }

    /// Standing at the frontier while it stays (the sensors cannot explore it): it is
    /// exhausted, and with nothing else left, exploration is complete.
    #[test]
    fn a_frontier_reached_that_stays_is_exhausted_and_then_done() {
        let g = half_explored_room();
        let mut e = explorer();
        let at = mole_types::Pose2::new(1.95, 2.0, 0.0);
        let modes = hold(&mut e, &g, at, 400);
        assert_eq!(modes.last(), Some(&MODE_DONE));
        assert!(e.done() && e.chosen().is_none());
        // Elsewhere in the room the exhausted cells stay no frontier.
        assert!(e.selector.select(&g, [0.5, 2.0]).is_none());
    }

    #[test]
    fn explored_map_means_done_with_a_zero_command_and_the_flag() {
        let g = grid_free(40, 40, 0.1);
        let mut e = FrontierExplorer::new(limits(), FrontierConfig::default(), dwa_follower());
        let mut c = Command::STOP;
        for tick in 0..400 {
            let input = PlannerInput {
                tick,
                dt: 0.01,
                pose: mole_types::Pose2::new(2.0, 2.0, 0.0),
                scan: None,
                tactile: None,
                grid: Some(&g),
                last_command: c,
            };
            c = e.step(&input);
        }
        assert!(e.done());
        assert_eq!((c.v, c.omega, c.mode), (0.0, 0.0, MODE_DONE));
        let mut st: Box<PlanStatus> = bytemuck::zeroed_box();
        e.write_status(&mut st);
        assert_eq!(
            st.flags & STATUS_EXPLORATION_COMPLETE,
            STATUS_EXPLORATION_COMPLETE
        );
    }
}

/// Keidar & Kaminka 2014, fast frontier detection: the frontier set kept from the cells each
/// grid changed equals the full pass after every grid, and so do the selections.
#[cfg(test)]
mod incremental {
    use super::*;
    use crate::obstacles::test_support::grid_free;
    use proptest::prelude::*;

    const SIDE: core::ops::Range<usize> = 8..40;
    const MAX_SIDE: usize = 40;

    /// A cell value: mostly free, some unexplored, fewer occupied.
    fn cell() -> impl Strategy<Value = u8> {
        (0u8..10).prop_map(|v| match v {
            0..=2 => CELL_UNEXPLORED,
            3..=8 => CELL_FREE,
            _ => mole_types::CELL_OCCUPIED,
        })
    }

    /// One new grid: `kind` 0 a new shape filled from `fill`, 1-3 changes at the borders,
    /// 4-5 a changed block (a scan), else changes anywhere.
    #[derive(Debug, Clone)]
    struct Step {
        kind: u8,
        changes: Vec<(usize, u8)>,
        dims: (usize, usize),
        fill: Vec<u8>,
        robot: (f64, f64),
    }

    fn step() -> impl Strategy<Value = Step> {
        (
            0u8..10,
            prop::collection::vec((0usize..10_000, cell()), 0..30),
            (SIDE, SIDE),
            prop::collection::vec(cell(), MAX_SIDE * MAX_SIDE),
            (0.0..1.0f64, 0.0..1.0f64),
        )
            .prop_map(|(kind, changes, dims, fill, robot)| Step {
                kind,
                changes,
                dims,
                fill,
                robot,
            })
    }

    fn grid_of(w: usize, h: usize, fill: &[u8]) -> Box<Grid> {
        let mut g = grid_free(w as u32, h as u32, 0.1);
        g.cells[..w * h].copy_from_slice(&fill[..w * h]);
        g
    }

    /// Applies `s` to `g`; returns the robot's position.
    fn apply(g: &mut Box<Grid>, s: &Step) -> [f64; 2] {
        let (w, h) = (g.width as usize, g.height as usize);
        match s.kind {
            0 => *g = grid_of(s.dims.0, s.dims.1, &s.fill),
            1..=3 => {
                // The border ring, cell by cell.
                let ring = 2 * (w + h) - 4;
                for &(k, v) in &s.changes {
                    let k = k % ring;
                    let i = if k < w {
                        k
                    } else if k < 2 * w {
                        (h - 1) * w + k - w
                    } else {
                        let k = k - 2 * w;
                        (k / 2 + 1) * w + if k % 2 == 0 { 0 } else { w - 1 }
                    };
                    g.cells[i] = v;
                }
            }
            4 | 5 => {
                // A block around the first change, filled from `fill` (a scan's footprint).
                if let Some(&(k, _)) = s.changes.first() {
                    let (c0, r0) = ((k % w).saturating_sub(3), (k / w % h).saturating_sub(3));
                    for r in r0..(r0 + 7).min(h) {
                        for c in c0..(c0 + 7).min(w) {
                            g.cells[r * w + c] = s.fill[r * w + c];
                        }
                    }
                }
            }
            _ => {
                for &(k, v) in &s.changes {
                    g.cells[k % (w * h)] = v;
                }
            }
        }
        let (w, h) = (g.width as f64, g.height as f64);
        [s.robot.0 * w * 0.1, s.robot.1 * h * 0.1]
    }

    fn oracle(g: &Grid) -> Vec<u32> {
        let mut out = Vec::new();
        frontier_cells_full(g.cells(), g.width as usize, g.height as usize, &mut out);
        out
    }

    fn config(min_cluster: usize) -> FrontierConfig {
        FrontierConfig {
            min_cluster,
            gain_radius: 0.3,
            inflation_margin: 0.0,
            ..FrontierConfig::default()
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(256))]

        /// The frontier set after every grid equals the full pass over it.
        #[test]
        fn frontier_cells_equal_the_full_pass(
            dims in (SIDE, SIDE),
            fill in prop::collection::vec(cell(), MAX_SIDE * MAX_SIDE),
            steps in prop::collection::vec(step(), 1..16),
        ) {
            let mut g = grid_of(dims.0, dims.1, &fill);
            let mut f = FrontierCells::with_capacity(MAX_GRID_CELLS);
            for (k, s) in std::iter::once(None).chain(steps.iter().map(Some)).enumerate() {
                if let Some(s) = s {
                    apply(&mut g, s);
                }
                f.update(g.cells(), g.width as usize, g.height as usize);
                let full = oracle(&g);
                let kept: Vec<u32> = f.iter().map(|i| i as u32).collect();
                prop_assert_eq!(&kept, &full, "grid {} ({}x{})", k, g.width, g.height);
                prop_assert_eq!(f.len(), full.len());
            }
        }

        /// `select` with the frontier set kept from grid to grid gives the same candidates,
        /// frontier and path as one making the old full pass, and, until a frontier is
        /// exhausted or given up, as a fresh selector.
        #[test]
        fn selection_equals_the_full_pass(
            dims in (SIDE, SIDE),
            fill in prop::collection::vec(cell(), MAX_SIDE * MAX_SIDE),
            steps in prop::collection::vec(step(), 1..12),
            min_cluster in 1usize..5,
            radius in prop::sample::select(vec![0.05, 0.12]),
        ) {
            let mut g = grid_of(dims.0, dims.1, &fill);
            let mut kept = FrontierSelector::new(config(min_cluster), radius);
            let mut full = FrontierSelector::new(config(min_cluster), radius);
            full.set_full_pass(true);
            let mut exhausted = false;
            let mut robot = [0.5 * dims.0 as f64 * 0.1, 0.5 * dims.1 as f64 * 0.1];
            for (k, s) in std::iter::once(None).chain(steps.iter().map(Some)).enumerate() {
                if let Some(s) = s {
                    robot = apply(&mut g, s);
                }
                let mut fresh = FrontierSelector::new(config(min_cluster), radius);
                let a = kept.select(&g, robot);
                let b = full.select(&g, robot);
                let c = fresh.select(&g, robot);
                let kept_cells: Vec<u32> =
                    kept.frontier_cells().iter().map(|i| i as u32).collect();
                prop_assert_eq!(kept_cells, oracle(&g), "grid {}", k);
                prop_assert_eq!(a, b, "grid {}", k);
                if !exhausted {
                    prop_assert_eq!(a, c, "grid {}", k);
                    prop_assert_eq!(kept.candidates(), fresh.candidates(), "grid {}", k);
                    prop_assert_eq!(kept.path(), fresh.path(), "grid {}", k);
                }
                prop_assert_eq!(kept.candidates(), full.candidates(), "grid {}", k);
                prop_assert_eq!(kept.path(), full.path(), "grid {}", k);
                prop_assert_eq!(&kept.label, &full.label, "grid {}", k);
                // Now and then the chosen frontier is exhausted or given up, in both.
                if let (Some(f), Some(s)) = (a, s) {
                    if s.kind == 7 {
                        kept.exhaust(f.cell);
                        full.exhaust(f.cell);
                        exhausted = true;
                    } else if s.kind == 8 {
                        kept.exhaust_around(f.cell, 0.3);
                        full.exhaust_around(f.cell, 0.3);
                        exhausted = true;
                    }
                }
            }
        }
    }
}
