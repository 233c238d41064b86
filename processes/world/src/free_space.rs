//! The robot's free configuration space on a raster: a cell is free when the robot disk centred
//! on it lies in the arena and overlaps no obstacle (the obstacles dilated by the radius), and
//! reachable when a 4-connected path of free cells leads to it from the start.
//!
//! Scenario tests use it to prove every scenario is connected; the monitor can use it as the
//! ground truth for "the reachable free area".

use crate::scenario::{Goal, Scenario, distance_to_square};
use std::collections::VecDeque;

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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scenario::{load_scenario, parse_scenario};
    use std::path::{Path, PathBuf};

    fn scenarios_dir() -> PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenarios")
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
