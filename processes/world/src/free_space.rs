//! The robot's free configuration space on a raster: a cell is free when the robot disk centred
//! on it lies in the arena and overlaps no obstacle (the obstacles dilated by the radius), and
//! reachable when a 4-connected path of free cells leads to it from the start.
//!
//! Scenario tests use it to prove every scenario is connected; the monitor can use it as the
//! ground truth for "the reachable free area"; [`FreeSpace::shortest_path`] gives the optimal path
//! length that BARN's optimal time `T_opt = length / max_speed` is made of (Perille et al. 2020).

use crate::scenario::{Goal, Scenario, distance_to_square};
use std::cmp::{Ordering, Reverse};
use std::collections::{BinaryHeap, VecDeque};

/// The disk centred on this cell overlaps a wall or an obstacle.
pub const BLOCKED: u8 = 0;
/// Free, but no free path leads here from the start.
pub const FREE: u8 = 1;
/// Free and reachable from the start.
pub const REACHABLE: u8 = 2;

/// Free and reachable cells over the arena, row-major from the lower-left corner.
#[derive(Debug, Clone, PartialEq)]
pub struct FreeSpace {
    pub width: usize,
    pub height: usize,
    /// Cell size (m).
    pub resolution: f64,
    /// [`BLOCKED`], [`FREE`] or [`REACHABLE`] per cell; cell `(i, j)` is centred at
    /// `((i + ½)·res, (j + ½)·res)`.
    pub cells: Vec<u8>,
}

impl FreeSpace {
    /// The free space of a scenario at its grid resolution.
    pub fn new(scenario: &Scenario) -> FreeSpace {
        FreeSpace::with_resolution(scenario, scenario.grid_resolution)
    }

    /// The free space at a given cell size (clamped so the raster stays below 4096 × 4096).
    pub fn with_resolution(scenario: &Scenario, resolution: f64) -> FreeSpace {
        let (w, h) = (
            scenario.arena_width.max(0.0),
            scenario.arena_height.max(0.0),
        );
        let mut res = if resolution.is_finite() && resolution > 0.0 {
            resolution
        } else {
            0.05
        };
        res = res.max(w.max(h) / 4096.0);
        let width = (w / res).ceil() as usize;
        let height = (h / res).ceil() as usize;
        let r = scenario.robot.radius;
        let eps = 1e-9;
        let centre = |i: usize| (i as f64 + 0.5) * res;
        let mut cells = vec![FREE; width * height];
        for j in 0..height {
            for i in 0..width {
                let (x, y) = (centre(i), centre(j));
                if x < r - eps || y < r - eps || x > w - r + eps || y > h - r + eps {
                    cells[j * width + i] = BLOCKED;
                }
            }
        }
        // Dilate each obstacle by the radius, visiting only the cells its dilated box covers.
        for o in &scenario.obstacles {
            let reach = o.side / 2.0 + r;
            let lo = |c: f64| (((c - reach) / res).floor().max(0.0)) as usize;
            let hi = |c: f64, n: usize| ((((c + reach) / res).ceil().max(0.0)) as usize).min(n);
            for j in lo(o.cy)..hi(o.cy, height) {
                for i in lo(o.cx)..hi(o.cx, width) {
                    if distance_to_square(o, centre(i), centre(j)) < r - eps {
                        cells[j * width + i] = BLOCKED;
                    }
                }
            }
        }
        let mut space = FreeSpace {
            width,
            height,
            resolution: res,
            cells,
        };
        space.flood_from(scenario.start.x, scenario.start.y);
        space
    }

    /// The cell holding a point, if inside the raster.
    pub fn cell(&self, x: f64, y: f64) -> Option<(usize, usize)> {
        if !(x >= 0.0 && y >= 0.0) {
            return None;
        }
        let (i, j) = (
            (x / self.resolution) as usize,
            (y / self.resolution) as usize,
        );
        (i < self.width && j < self.height).then_some((i, j))
    }

    /// Whether the point's cell is reachable from the start.
    pub fn is_reachable(&self, x: f64, y: f64) -> bool {
        self.cell(x, y)
            .is_some_and(|(i, j)| self.cells[j * self.width + i] == REACHABLE)
    }

    /// Cells in a given state.
    pub fn count(&self, state: u8) -> usize {
        self.cells.iter().filter(|&&c| c == state).count()
    }

    /// Area the robot centre can reach (m²).
    pub fn reachable_area(&self) -> f64 {
        self.count(REACHABLE) as f64 * self.resolution * self.resolution
    }

    /// Whether a reachable cell centre lies within the goal's tolerance.
    pub fn goal_reachable(&self, goal: &Goal) -> bool {
        let res = self.resolution;
        (0..self.height).any(|j| {
            (0..self.width).any(|i| {
                self.cells[j * self.width + i] == REACHABLE
                    && ((i as f64 + 0.5) * res - goal.x).hypot((j as f64 + 0.5) * res - goal.y)
                        <= goal.tolerance
            })
        })
    }

    /// Length (m) of the shortest 8-connected free-cell path between two points (A*), or `None`.
    pub fn shortest_path(&self, from: (f64, f64), to: (f64, f64)) -> Option<f64> {
        // A* (Hart, Nilsson and Raphael 1968) with the octile distance; a diagonal step only
        // when both orthogonal neighbours are free (no corner cutting). The length runs from
        // cell centre to cell centre. A point whose own cell is blocked although its disk may be
        // free (the raster is coarser than the geometry) starts from its nearest free
        // 8-neighbour, as the flood fill does. BARN's optimal time is this length over the
        // robot's top speed (Perille et al. 2020).
        let start = self.free_cell_near(from.0, from.1)?;
        let goal = self.free_cell_near(to.0, to.1)?;
        let (w, h) = (self.width, self.height);
        let res = self.resolution;
        let diagonal = res * std::f64::consts::SQRT_2;
        let (gi, gj) = ((goal % w) as f64, (goal / w) as f64);
        // The octile distance: admissible and consistent on this 8-connected grid.
        let heuristic = |k: usize| {
            let dx = ((k % w) as f64 - gi).abs();
            let dy = ((k / w) as f64 - gj).abs();
            let (lo, hi) = if dx < dy { (dx, dy) } else { (dy, dx) };
            (hi - lo) * res + lo * diagonal
        };
        let free = |i: i64, j: i64| {
            i >= 0
                && j >= 0
                && (i as usize) < w
                && (j as usize) < h
                && self.cells[j as usize * w + i as usize] != BLOCKED
        };
        let mut best = vec![f64::INFINITY; w * h];
        let mut done = vec![false; w * h];
        let mut open = BinaryHeap::new();
        best[start] = 0.0;
        open.push(Reverse(Entry(heuristic(start), start)));
        while let Some(Reverse(Entry(_, k))) = open.pop() {
            if done[k] {
                continue;
            }
            if k == goal {
                return Some(best[k]);
            }
            done[k] = true;
            let (i, j) = ((k % w) as i64, (k / w) as i64);
            for (di, dj) in [
                (1, 0),
                (-1, 0),
                (0, 1),
                (0, -1),
                (1, 1),
                (1, -1),
                (-1, 1),
                (-1, -1),
            ] {
                let (ni, nj) = (i + di, j + dj);
                if !free(ni, nj) {
                    continue;
                }
                let step = if di != 0 && dj != 0 {
                    // No corner cutting: both orthogonal neighbours must be free.
                    if !free(i + di, j) || !free(i, j + dj) {
                        continue;
                    }
                    diagonal
                } else {
                    res
                };
                let n = nj as usize * w + ni as usize;
                let g = best[k] + step;
                if !done[n] && g < best[n] {
                    best[n] = g;
                    open.push(Reverse(Entry(g + heuristic(n), n)));
                }
            }
        }
        None
    }

    /// The point's cell if it is not blocked, else its free 8-neighbour nearest to the point.
    fn free_cell_near(&self, x: f64, y: f64) -> Option<usize> {
        let (ci, cj) = self.cell(x, y)?;
        let k = cj * self.width + ci;
        if self.cells[k] != BLOCKED {
            return Some(k);
        }
        let res = self.resolution;
        let mut nearest: Option<(f64, usize)> = None;
        for dj in -1..=1_i64 {
            for di in -1..=1_i64 {
                let (i, j) = (ci as i64 + di, cj as i64 + dj);
                if i < 0 || j < 0 || i as usize >= self.width || j as usize >= self.height {
                    continue;
                }
                let n = j as usize * self.width + i as usize;
                if self.cells[n] == BLOCKED {
                    continue;
                }
                let (cx, cy) = ((i as f64 + 0.5) * res - x, (j as f64 + 0.5) * res - y);
                let d = cx * cx + cy * cy;
                if nearest.is_none_or(|(best, _)| d < best) {
                    nearest = Some((d, n));
                }
            }
        }
        nearest.map(|(_, n)| n)
    }

    /// Marks every free cell 4-connected to the start's cell (or, when the raster blocks that
    /// cell although the start pose is free, to a free neighbour) as reachable.
    fn flood_from(&mut self, x: f64, y: f64) {
        let Some((si, sj)) = self.cell(x, y) else {
            return;
        };
        let mut queue = VecDeque::new();
        for (di, dj) in [
            (0, 0),
            (-1, 0),
            (1, 0),
            (0, -1),
            (0, 1),
            (-1, -1),
            (1, -1),
            (-1, 1),
            (1, 1),
        ] {
            let (i, j) = (si as i64 + di, sj as i64 + dj);
            if i >= 0 && j >= 0 && (i as usize) < self.width && (j as usize) < self.height {
                let k = j as usize * self.width + i as usize;
                if self.cells[k] == FREE {
                    self.cells[k] = REACHABLE;
                    queue.push_back(k);
                    if (di, dj) == (0, 0) {
                        break;
                    }
                }
            }
        }
        while let Some(k) = queue.pop_front() {
            let (i, j) = (k % self.width, k / self.width);
            let mut visit = |n: usize| {
                if self.cells[n] == FREE {
                    self.cells[n] = REACHABLE;
                    queue.push_back(n);
                }
            };
            if i > 0 {
                visit(k - 1);
            }
            if i + 1 < self.width {
                visit(k + 1);
            }
            if j > 0 {
                visit(k - self.width);
            }
            if j + 1 < self.height {
                visit(k + self.width);
            }
        }
    }
}

/// A* queue entry: the estimated total length, then the cell (ordered by `f64::total_cmp`).
#[derive(Debug, Clone, Copy)]
struct Entry(f64, usize);

impl PartialEq for Entry {
    fn eq(&self, other: &Self) -> bool {
        self.cmp(other) == Ordering::Equal
    }
}

impl Eq for Entry {}

impl PartialOrd for Entry {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}

impl Ord for Entry {
    fn cmp(&self, other: &Self) -> Ordering {
        self.0.total_cmp(&other.0).then(self.1.cmp(&other.1))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scenario::{load_scenario, parse_scenario};
    use std::path::{Path, PathBuf};

    fn scenarios_dir() -> PathBuf {
        crate::scenario::bundled_scenarios()
    }

    #[test]
    fn a_walled_off_room_is_unreachable() {
        // A wall of touching squares across the arena at x = 5 cuts it in two.
        let mut text = String::from("[start]\nx = 1.0\ny = 1.0\n[goal]\nx = 8.0\ny = 5.0\n");
        for k in 0..10 {
            text.push_str(&format!(
                "[[obstacles]]\nx = 5.0\ny = {}\nside = 1.0\n",
                0.5 + k as f64
            ));
        }
        let s = parse_scenario(&text, Path::new("t.toml")).unwrap();
        let space = FreeSpace::new(&s);
        assert!(space.is_reachable(1.0, 1.0));
        assert!(!space.is_reachable(8.0, 5.0));
        assert!(!space.goal_reachable(&s.goal.unwrap()));
        // Left part: x in [0.2, 4.3], right part: x in [5.7, 9.8]; both 9.6 m tall.
        let left = 4.1 * 9.6;
        assert!(
            (space.reachable_area() - left).abs() < 0.05 * left,
            "{}",
            space.reachable_area()
        );
        assert!(space.count(FREE) > 0);
        // Open one block: now everything is connected.
        let opened = text.replacen("y = 4.5\nside = 1.0", "y = 4.5\nside = 0.01", 1);
        let s = parse_scenario(&opened, Path::new("t.toml")).unwrap();
        let space = FreeSpace::new(&s);
        assert_eq!(space.count(FREE), 0);
        assert!(space.goal_reachable(&s.goal.unwrap()));
    }

    /// A wall of 1 m squares at x = 5 from y = 0 up to `top`.
    fn walled(top: usize) -> Scenario {
        let mut text = String::from("[start]\nx = 2.0\ny = 2.0\n");
        for k in 0..top {
            text.push_str(&format!(
                "[[obstacles]]\nx = 5.0\ny = {}\nside = 1.0\n",
                0.5 + k as f64
            ));
        }
        parse_scenario(&text, Path::new("t.toml")).unwrap()
    }

    #[test]
    fn shortest_path_in_the_open_is_the_straight_line() {
        let s = parse_scenario("[sim]\n", Path::new("t.toml")).unwrap();
        let space = FreeSpace::new(&s);
        // 140 cells to the right: 7 m exactly (up to rounding).
        let d = space.shortest_path((1.0, 5.0), (8.0, 5.0)).unwrap();
        assert!((d - 7.0).abs() < 1e-9, "{d}");
        // 100 diagonal steps: 5·√2 m.
        let d = space.shortest_path((1.0, 1.0), (6.0, 6.0)).unwrap();
        assert!((d - 5.0 * 2f64.sqrt()).abs() < 1e-9, "{d}");
        assert_eq!(space.shortest_path((3.0, 3.0), (3.01, 3.01)), Some(0.0));
        // Symmetric.
        let there = space.shortest_path((1.3, 2.7), (8.1, 6.4)).unwrap();
        let back = space.shortest_path((8.1, 6.4), (1.3, 2.7)).unwrap();
        assert!((there - back).abs() < 1e-9, "{there} {back}");
    }

    #[test]
    fn shortest_path_goes_around_a_wall() {
        let s = walled(8);
        let space = FreeSpace::new(&s);
        let d = space.shortest_path((2.0, 2.0), (8.0, 2.0)).unwrap();
        // The true shortest path runs over the corners of the wall dilated by the radius 0.2,
        // (4.3, 8.2) and (5.7, 8.2); the 8-connected one is at most 8.3% longer than a line.
        let leg = (2.3f64 * 2.3 + 6.2 * 6.2).sqrt();
        let euclid = 2.0 * leg + 1.4;
        assert!(
            d > euclid - 0.1 && d < euclid * 1.083 + 0.1,
            "{d} against {euclid}"
        );
        // A lower wall: a shorter detour.
        let lower = FreeSpace::new(&walled(4))
            .shortest_path((2.0, 2.0), (8.0, 2.0))
            .unwrap();
        assert!(lower < d - 3.0, "{lower} {d}");
    }

    #[test]
    fn shortest_path_is_none_when_nothing_joins_the_points() {
        let s = walled(10);
        let space = FreeSpace::new(&s);
        assert_eq!(space.shortest_path((2.0, 2.0), (8.0, 2.0)), None);
        // Outside the raster, or inside an obstacle with no free neighbour.
        assert_eq!(space.shortest_path((2.0, 2.0), (12.0, 2.0)), None);
        assert_eq!(space.shortest_path((2.0, 2.0), (-1.0, 2.0)), None);
        assert_eq!(space.shortest_path((5.0, 3.0), (2.0, 2.0)), None);
        assert_eq!(space.shortest_path((2.0, 2.0), (f64::NAN, 2.0)), None);
        // The same side is still joined.
        assert!(space.shortest_path((2.0, 2.0), (2.0, 9.0)).is_some());
    }

    /// A hand-made raster: `#` blocked, `.` free, top row first.
    fn raster(rows: &[&str]) -> FreeSpace {
        let height = rows.len();
        let width = rows[0].len();
        let mut cells = vec![FREE; width * height];
        for (r, row) in rows.iter().enumerate() {
            for (i, c) in row.bytes().enumerate() {
                if c == b'#' {
                    cells[(height - 1 - r) * width + i] = BLOCKED;
                }
            }
        }
        FreeSpace {
            width,
            height,
            resolution: 1.0,
            cells,
        }
    }

    #[test]
    fn shortest_path_cuts_no_corner() {
        // From the lower-left cell to the one diagonal to it: the two cells between are blocked.
        let space = raster(&[".#.", "#.#", ".#."]);
        assert_eq!(space.shortest_path((0.5, 0.5), (1.5, 1.5)), None);
        // One blocked side forbids the diagonal too: two straight steps instead.
        let space = raster(&["...", "#..", "..."]);
        let d = space.shortest_path((0.5, 0.5), (1.5, 1.5)).unwrap();
        assert!((d - 2.0).abs() < 1e-12, "{d}");
        let space = raster(&["...", "...", "..."]);
        let d = space.shortest_path((0.5, 0.5), (1.5, 1.5)).unwrap();
        assert!((d - 2f64.sqrt()).abs() < 1e-12, "{d}");
        // Squeezed between two blocked cells: the long way round, six straight steps.
        let space = raster(&["...", ".#.", "..#"]);
        let d = space.shortest_path((1.5, 0.5), (2.5, 1.5)).unwrap();
        assert!((d - 6.0).abs() < 1e-12, "{d}");
    }

    /// The plain Bellman–Ford relaxation over the same moves, as the reference for A*.
    fn reference(space: &FreeSpace, from: usize, to: usize) -> Option<f64> {
        let (w, h) = (space.width as i64, space.height as i64);
        let free = |i: i64, j: i64| {
            i >= 0 && j >= 0 && i < w && j < h && space.cells[(j * w + i) as usize] != BLOCKED
        };
        let mut dist = vec![f64::INFINITY; space.cells.len()];
        dist[from] = 0.0;
        loop {
            let mut changed = false;
            for k in 0..space.cells.len() {
                let (i, j) = (k as i64 % w, k as i64 / w);
                if !free(i, j) || dist[k].is_infinite() {
                    continue;
                }
                for di in -1..=1 {
                    for dj in -1..=1 {
                        let diagonal = di != 0 && dj != 0;
                        if (di, dj) == (0, 0)
                            || !free(i + di, j + dj)
                            || (diagonal && (!free(i + di, j) || !free(i, j + dj)))
                        {
                            continue;
                        }
                        let step = if diagonal { 2f64.sqrt() } else { 1.0 } * space.resolution;
                        let n = ((j + dj) * w + i + di) as usize;
                        if dist[k] + step < dist[n] - 1e-12 {
                            dist[n] = dist[k] + step;
                            changed = true;
                        }
                    }
                }
            }
            if !changed {
                break;
            }
        }
        dist[to].is_finite().then_some(dist[to])
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(200))]

        /// A* finds the reference's length on random rasters, and `None` exactly where it does.
        #[test]
        fn shortest_path_is_the_shortest(
            blocked in proptest::collection::vec(proptest::bool::weighted(0.3), 12 * 9),
            from in 0usize..12 * 9,
            to in 0usize..12 * 9,
        ) {
            let mut cells: Vec<u8> = blocked.iter().map(|&b| if b { BLOCKED } else { FREE }).collect();
            cells[from] = FREE;
            cells[to] = FREE;
            let space = FreeSpace { width: 12, height: 9, resolution: 0.5, cells };
            let centre = |k: usize| (((k % 12) as f64 + 0.5) * 0.5, ((k / 12) as f64 + 0.5) * 0.5);
            let found = space.shortest_path(centre(from), centre(to));
            let want = reference(&space, from, to);
            match (found, want) {
                (Some(a), Some(b)) => proptest::prop_assert!((a - b).abs() < 1e-9, "{} {}", a, b),
                (a, b) => proptest::prop_assert_eq!(a, b),
            }
        }
    }

    #[test]
    fn every_scenario_validates_and_is_connected() {
        let mut seen = 0;
        let mut entries: Vec<PathBuf> = std::fs::read_dir(scenarios_dir())
            .unwrap()
            .map(|e| e.unwrap().path())
            .filter(|p| p.extension().is_some_and(|e| e == "toml"))
            .collect();
        entries.sort();
        for path in entries {
            let s = match load_scenario(&path) {
                Ok(s) => s,
                Err(e) => panic!("{e}"),
            };
            let space = FreeSpace::new(&s);
            assert!(
                space.is_reachable(s.start.x, s.start.y),
                "{}: start",
                path.display()
            );
            assert_eq!(
                space.count(FREE),
                0,
                "{}: free cells unreachable from the start",
                path.display()
            );
            if let Some(g) = s.goal {
                assert!(
                    space.goal_reachable(&g),
                    "{}: goal unreachable",
                    path.display()
                );
            }
            seen += 1;
        }
        assert!(seen >= 8, "expected every scenario, found {seen}");
    }

    #[test]
    fn required_scenarios_have_their_shape() {
        let load = |name: &str| load_scenario(&scenarios_dir().join(name)).unwrap();
        let d = load("default.toml");
        assert_eq!((d.arena_width, d.arena_height), (10.0, 10.0));
        assert!((5..=8).contains(&d.obstacles.len()));
        assert_eq!(d.beacons.len(), 4);
        assert_eq!(
            (d.sensors.lidar_beams, d.sensors.lidar_range_max),
            (180, 4.0)
        );
        assert_eq!(d.sensors.tactile_sensors, 8);
        assert_eq!(d.sensors.fix_period_ticks, 100);
        assert!(d.goal.is_none());
        let c = load("cluttered.toml");
        assert!((20..=30).contains(&c.obstacles.len()) && c.goal.is_some());
        let m = load("maze.toml");
        assert!(m.obstacles.iter().all(|o| o.side == 0.5));
        assert!(m.arena_width >= 11.0 && m.arena_height >= 11.0);
        assert_eq!(load("dark_room.toml").sensors.lidar_beams, 0);
        assert!(load("open.toml").goal.is_some() && load("open.toml").obstacles.is_empty());
        assert!(load("u_trap.toml").goal.is_some());
        let r = load("ros_map.toml");
        assert!(!r.obstacles.is_empty());
        assert!(r.obstacles.iter().all(|o| (o.side - 0.1).abs() < 1e-12));
    }
}
