//! Dijkstra and A* on an 8-connected grid: octile moves (1 orthogonal, √2 diagonal, in cells),
//! no corner cutting (a diagonal move needs both orthogonal neighbours passable).
//!
//! Our own rather than the `pathfinding` crate: the frontier planner runs one Dijkstra over the
//! whole grid every few steps, and `pathfinding`'s `dijkstra_all` returns a fresh `HashMap` each
//! call; this one keeps its distance, predecessor and indexed-heap buffers between searches, so
//! a search allocates nothing once the buffers have the grid's size.

use core::f64::consts::SQRT_2;

const NOT_IN_HEAP: u32 = u32::MAX;
/// "No predecessor" (the source, or a cell not reached).
pub const NO_PRED: u32 = u32::MAX;

/// The 8 moves (dx, dy, cost in cells).
const MOVES: [(i32, i32, f64); 8] = [
    (1, 0, 1.0),
    (-1, 0, 1.0),
    (0, 1, 1.0),
    (0, -1, 1.0),
    (1, 1, SQRT_2),
    (-1, 1, SQRT_2),
    (1, -1, SQRT_2),
    (-1, -1, SQRT_2),
];

/// Octile distance between two cells (cells): the exact shortest path length without obstacles,
/// A*'s admissible, consistent heuristic.
#[inline]
pub fn octile(a: (usize, usize), b: (usize, usize)) -> f64 {
    let dx = a.0.abs_diff(b.0) as f64;
    let dy = a.1.abs_diff(b.1) as f64;
    dx.max(dy) + (SQRT_2 - 1.0) * dx.min(dy)
}

/// Reusable Dijkstra / A* state over a `width × height` grid.
#[derive(Debug, Clone, Default)]
pub struct GridSearch {
    width: usize,
    height: usize,
    /// g: path length from the source (cells); +∞ when not reached.
    dist: Vec<f64>,
    /// Predecessor on the shortest path, or `NO_PRED`.
    pred: Vec<u32>,
    /// Heap key per cell (g for Dijkstra, g + h for A*).
    key: Vec<f64>,
    heap: Vec<u32>,
    pos: Vec<u32>,
    closed: Vec<bool>,
    /// Dijkstra's two FIFO queues (key, cell): orthogonal and diagonal moves.
    q_orth: Vec<(f64, u32)>,
    q_diag: Vec<(f64, u32)>,
    /// Cells settled in the last search.
    settled: usize,
}

impl GridSearch {
    /// Empty state; buffers grow on the first search.
    pub fn new() -> Self {
        Self::default()
    }

    /// State with buffers for grids of up to `cells` cells.
    pub fn with_capacity(cells: usize) -> Self {
        let mut s = Self::new();
        s.dist.reserve(cells);
        s.pred.reserve(cells);
        s.key.reserve(cells);
        s.heap.reserve(cells);
        s.pos.reserve(cells);
        s.closed.reserve(cells);
        s.q_orth.reserve(cells);
        s.q_diag.reserve(cells);
        s
    }

    fn reset(&mut self, width: usize, height: usize) {
        let n = width * height;
        self.width = width;
        self.height = height;
        for v in [&mut self.dist, &mut self.key] {
            v.clear();
            v.resize(n, f64::INFINITY);
        }
        for v in [&mut self.pred, &mut self.pos] {
            v.clear();
            v.resize(n, NO_PRED);
        }
        self.closed.clear();
        self.closed.resize(n, false);
        self.heap.clear();
        self.settled = 0;
    }

    // --- indexed binary min-heap on `key` ---

    fn sift_up(&mut self, mut i: usize) {
        while i > 0 {
            let parent = (i - 1) / 2;
            if self.key[self.heap[i] as usize] < self.key[self.heap[parent] as usize] {
                self.swap(i, parent);
                i = parent;
            } else {
                break;
            }
        }
    }

    fn sift_down(&mut self, mut i: usize) {
        let n = self.heap.len();
        loop {
            let (l, r) = (2 * i + 1, 2 * i + 2);
            let mut m = i;
            if l < n && self.key[self.heap[l] as usize] < self.key[self.heap[m] as usize] {
                m = l;
            }
            if r < n && self.key[self.heap[r] as usize] < self.key[self.heap[m] as usize] {
                m = r;
            }
            if m == i {
                break;
            }
            self.swap(i, m);
            i = m;
        }
    }

    fn swap(&mut self, a: usize, b: usize) {
        self.heap.swap(a, b);
        self.pos[self.heap[a] as usize] = a as u32;
        self.pos[self.heap[b] as usize] = b as u32;
    }

    fn push_or_decrease(&mut self, cell: usize, key: f64) {
        self.key[cell] = key;
        if self.pos[cell] == NOT_IN_HEAP {
            self.heap.push(cell as u32);
            let i = self.heap.len() - 1;
            self.pos[cell] = i as u32;
            self.sift_up(i);
        } else {
            self.sift_up(self.pos[cell] as usize);
        }
    }

    fn pop(&mut self) -> Option<usize> {
        let top = *self.heap.first()?;
        let last = self.heap.len() - 1;
        self.swap(0, last);
        self.heap.pop();
        self.pos[top as usize] = NOT_IN_HEAP;
        if !self.heap.is_empty() {
            self.sift_down(0);
        }
        Some(top as usize)
    }

    /// The search core: from `source` through cells where `passable` holds (the source itself
    /// need not), stopping when `target` is settled; `heuristic` 0 gives Dijkstra.
    fn search<P: Fn(usize) -> bool>(
        &mut self,
        width: usize,
        height: usize,
        passable: &P,
        source: usize,
        target: Option<usize>,
    ) {
        self.reset(width, height);
        if source >= width * height {
            return;
        }
        let h = |s: &Self, c: usize| match target {
            Some(t) => octile((c % s.width, c / s.width), (t % s.width, t / s.width)),
            None => 0.0,
        };
        self.dist[source] = 0.0;
        let k = h(self, source);
        self.push_or_decrease(source, k);
        while let Some(c) = self.pop() {
            self.closed[c] = true;
            self.settled += 1;
            if Some(c) == target {
                return;
            }
            let (cx, cy) = ((c % width) as i32, (c / width) as i32);
            for (dx, dy, cost) in MOVES {
                let (nx, ny) = (cx + dx, cy + dy);
                if nx < 0 || ny < 0 || nx >= width as i32 || ny >= height as i32 {
                    continue;
                }
                let n = ny as usize * width + nx as usize;
                if self.closed[n] || !passable(n) {
                    continue;
                }
                if dx != 0 && dy != 0 {
                    let side_a = cy as usize * width + nx as usize;
                    let side_b = ny as usize * width + cx as usize;
                    if !(passable(side_a) && passable(side_b)) {
                        continue;
                    }
                }
                let g = self.dist[c] + cost;
                if g < self.dist[n] {
                    self.dist[n] = g;
                    self.pred[n] = c as u32;
                    let k = g + h(self, n);
                    self.push_or_decrease(n, k);
                }
            }
        }
    }

    /// Dijkstra from `source` over every cell reachable through passable cells: afterwards
    /// [`GridSearch::distance`] and [`GridSearch::path_to`] answer for every cell.
    ///
    /// With only two edge weights (1 and √2) a FIFO queue per weight replaces the heap: cells
    /// are settled in nondecreasing distance, so each queue receives nondecreasing keys, and the
    /// smaller of the two heads is the global minimum (exact Dijkstra in O(cells), with lazy
    /// deletion of superseded entries).
    pub fn dijkstra<P: Fn(usize) -> bool>(
        &mut self,
        width: usize,
        height: usize,
        passable: &P,
        source: usize,
    ) {
        let n = width * height;
        self.width = width;
        self.height = height;
        self.dist.clear();
        self.dist.resize(n, f64::INFINITY);
        self.pred.clear();
        self.pred.resize(n, NO_PRED);
        self.closed.clear();
        self.closed.resize(n, false);
        self.q_orth.clear();
        self.q_diag.clear();
        self.settled = 0;
        if source >= n {
            return;
        }
        self.dist[source] = 0.0;
        self.q_orth.push((0.0, source as u32));
        let (mut ho, mut hd) = (0usize, 0usize);
        let (w, h) = (width as i64, height as i64);
        loop {
            let take_orth = match (self.q_orth.get(ho), self.q_diag.get(hd)) {
                (Some(a), Some(b)) => a.0 <= b.0,
                (Some(_), None) => true,
                (None, Some(_)) => false,
                (None, None) => break,
            };
            let (k, c) = if take_orth {
                ho += 1;
                self.q_orth[ho - 1]
            } else {
                hd += 1;
                self.q_diag[hd - 1]
            };
            let c = c as usize;
            if self.closed[c] || k > self.dist[c] {
                continue;
            }
            self.closed[c] = true;
            self.settled += 1;
            let (cx, cy) = ((c % width) as i64, (c / width) as i64);
            for (dx, dy, cost) in MOVES {
                let (nx, ny) = (cx + dx as i64, cy + dy as i64);
                if nx < 0 || ny < 0 || nx >= w || ny >= h {
                    continue;
                }
                let nb = (ny * w + nx) as usize;
                if self.closed[nb] || !passable(nb) {
                    continue;
                }
                let diagonal = dx != 0 && dy != 0;
                if diagonal
                    && !(passable((cy * w + nx) as usize) && passable((ny * w + cx) as usize))
                {
                    continue;
                }
                let g = k + cost;
                if g < self.dist[nb] {
                    self.dist[nb] = g;
                    self.pred[nb] = c as u32;
                    if diagonal {
                        self.q_diag.push((g, nb as u32));
                    } else {
                        self.q_orth.push((g, nb as u32));
                    }
                }
            }
        }
    }

    /// A* from `source` to `target` with the octile heuristic; the path length (cells), or
    /// `None` when the target cannot be reached.
    pub fn astar<P: Fn(usize) -> bool>(
        &mut self,
        width: usize,
        height: usize,
        passable: &P,
        source: usize,
        target: usize,
    ) -> Option<f64> {
        self.search(width, height, passable, source, Some(target));
        self.distance(target)
    }

    /// Path length (cells) from the last search's source to `cell`; `None` if not reached.
    pub fn distance(&self, cell: usize) -> Option<f64> {
        self.dist.get(cell).copied().filter(|d| d.is_finite())
    }

    /// Cells settled by the last search.
    pub fn settled(&self) -> usize {
        self.settled
    }

    /// Predecessor of `cell` on its shortest path (`NO_PRED` for the source or unreached).
    pub fn pred(&self, cell: usize) -> u32 {
        self.pred.get(cell).copied().unwrap_or(NO_PRED)
    }

    /// Writes the path source → `cell` into `out` (cleared first); false if `cell` was not
    /// reached. Allocation-free when `out` has capacity for the path.
    pub fn path_to(&self, cell: usize, out: &mut Vec<u32>) -> bool {
        out.clear();
        if self.distance(cell).is_none() {
            return false;
        }
        let mut c = cell as u32;
        loop {
            out.push(c);
            let p = self.pred(c as usize);
            if p == NO_PRED || out.len() > self.width * self.height {
                break;
            }
            c = p;
        }
        out.reverse();
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// Bellman-Ford with the same moves: the reference the searches must match.
    fn bellman_ford(w: usize, h: usize, free: &[bool], source: usize) -> Vec<f64> {
        let mut d = vec![f64::INFINITY; w * h];
        d[source] = 0.0;
        for _ in 0..w * h {
            let mut changed = false;
            for c in 0..w * h {
                if !d[c].is_finite() {
                    continue;
                }
                let (cx, cy) = ((c % w) as i32, (c / w) as i32);
                for (dx, dy, cost) in MOVES {
                    let (nx, ny) = (cx + dx, cy + dy);
                    if nx < 0 || ny < 0 || nx >= w as i32 || ny >= h as i32 {
                        continue;
                    }
                    let n = ny as usize * w + nx as usize;
                    let corner_ok = dx == 0
                        || dy == 0
                        || (free[cy as usize * w + nx as usize]
                            && free[ny as usize * w + cx as usize]);
                    if free[n] && corner_ok && d[c] + cost < d[n] - 1e-12 {
                        d[n] = d[c] + cost;
                        changed = true;
                    }
                }
            }
            if !changed {
                break;
            }
        }
        d
    }

    #[test]
    fn open_grid_distances_are_octile_and_corners_are_not_cut() {
        let mut s = GridSearch::new();
        let free = [true; 100];
        s.dijkstra(10, 10, &|i| free[i], 0);
        assert!((s.distance(99).unwrap_or(0.0) - 9.0 * SQRT_2).abs() < 1e-12);
        assert_eq!(s.distance(9), Some(9.0));
        // Two blocked cells touching at a corner: the diagonal between them is closed.
        let mut free = [true; 9];
        free[1] = false; // (1, 0)
        free[3] = false; // (0, 1)
        s.dijkstra(3, 3, &|i| free[i], 0);
        assert_eq!(s.distance(4), None, "(1,1) only via the cut corner");
        let mut path = Vec::new();
        s.dijkstra(10, 10, &|_| true, 0);
        assert!(s.path_to(22, &mut path));
        assert_eq!(path.first(), Some(&0));
        assert_eq!(path.last(), Some(&22));
        assert_eq!(path.len(), 3);
    }

    proptest! {
        #[test]
        fn dijkstra_and_astar_match_bellman_ford(
            w in 1usize..14, h in 1usize..14,
            cells in proptest::collection::vec(0u8..10, 14 * 14),
            src in 0usize..196, dst in 0usize..196,
        ) {
            let n = w * h;
            let free: Vec<bool> = cells[..n].iter().map(|c| *c >= 3).collect();
            let (src, dst) = (src % n, dst % n);
            let reference = bellman_ford(w, h, &free, src);
            let mut s = GridSearch::new();
            s.dijkstra(w, h, &|i| free[i], src);
            let mut path = Vec::new();
            #[allow(clippy::needless_range_loop)]
            for c in 0..n {
                let got = s.distance(c).unwrap_or(f64::INFINITY);
                prop_assert!((got.is_infinite() && reference[c].is_infinite())
                    || (got - reference[c]).abs() < 1e-9, "cell {} {} vs {}", c, got, reference[c]);
                if got.is_finite() {
                    // The path's own length equals the distance.
                    prop_assert!(s.path_to(c, &mut path));
                    let len: f64 = path.windows(2).map(|p| {
                        let (a, b) = (p[0] as usize, p[1] as usize);
                        if a % w != b % w && a / w != b / w { SQRT_2 } else { 1.0 }
                    }).sum();
                    prop_assert!((len - got).abs() < 1e-9);
                }
            }
            let a = s.astar(w, h, &|i| free[i], src, dst).unwrap_or(f64::INFINITY);
            prop_assert!((a.is_infinite() && reference[dst].is_infinite())
                || (a - reference[dst]).abs() < 1e-9, "A* {} vs {}", a, reference[dst]);
        }
    }
}
