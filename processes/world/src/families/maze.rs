//! `maze`: a depth-first ("perfect") maze on a lattice, drawn as scenarios/maze.toml draws its
//! maze: corridors `corridor_width` wide between walls that are rows of `wall_thickness` squares.
//! The start is in the corner cell (0, 0), the goal in the cell farthest from it along the maze.

use super::lattice::{self, Lattice, Wall};
use super::{
    Bad, ChaCha8Rng, Layout, at_least, check_arena, check_obstacles, positive, wider_than_robot,
};
use mole_types::RobotSpec;

/// Parameters of the maze family.
#[derive(Debug, Clone, PartialEq)]
pub struct MazeParams {
    /// Lattice cells per side (at least 2).
    pub cells: usize,
    /// Corridor width (m): more than the robot's diameter.
    pub corridor_width: f64,
    /// Wall thickness (m): the side of the wall squares.
    pub wall_thickness: f64,
}

impl Default for MazeParams {
    /// 8 × 8 cells, corridors 1.0 m wide, walls 0.5 m thick (scenarios/maze.toml's maze).
    fn default() -> Self {
        MazeParams {
            cells: 8,
            corridor_width: 1.0,
            wall_thickness: 0.5,
        }
    }
}

impl MazeParams {
    /// `key = value` for the file header.
    pub(super) fn describe(&self) -> String {
        format!(
            "maze.cells = {}, maze.corridor_width = {:?}, maze.wall_thickness = {:?}",
            self.cells, self.corridor_width, self.wall_thickness
        )
    }

    /// Checks the parameters against the robot and the grid.
    pub(super) fn check(&self, robot: &RobotSpec, resolution: f64) -> Result<(), Bad> {
        at_least("maze.cells", self.cells, 2)?;
        wider_than_robot("maze.corridor_width", self.corridor_width, robot)?;
        positive("maze.wall_thickness", self.wall_thickness)?;
        let (w, h) = lattice::extent(
            self.cells,
            self.cells,
            self.corridor_width,
            self.wall_thickness,
        );
        check_arena("maze.cells", w, h, resolution)?;
        check_obstacles(
            "maze.cells",
            Lattice::max_squares(
                self.cells,
                self.cells,
                self.corridor_width,
                self.wall_thickness,
            ),
            self.cells,
        )
    }

    /// The carved maze of one draw.
    pub(super) fn lattice(&self, rng: &mut ChaCha8Rng) -> Lattice {
        let mut lattice = Lattice::new(
            self.cells,
            self.cells,
            self.corridor_width,
            self.wall_thickness,
        );
        lattice.carve_tree((0, 0), rng, |_| Wall::Open);
        lattice
    }

    /// One draw: the maze, the start in cell (0, 0), the goal in the farthest cell.
    pub(super) fn draw(&self, rng: &mut ChaCha8Rng) -> Layout {
        self.lattice(rng).layout()
    }
}

#[cfg(test)]
mod tests {
    use super::super::{Family, WorldSpec, generate};
    use super::*;
    use crate::free_space::{FREE, FreeSpace};
    use rand::SeedableRng;

    /// The lattice is a spanning tree: every cell joined to (0, 0), `cells² − 1` openings.
    #[test]
    fn the_maze_is_perfect() {
        for cells in [2, 3, 8, 13] {
            let p = MazeParams {
                cells,
                ..MazeParams::default()
            };
            for seed in 0..50 {
                let lattice = p.lattice(&mut ChaCha8Rng::seed_from_u64(seed));
                assert_eq!(
                    lattice.openings(),
                    cells * cells - 1,
                    "{cells} cells, {seed}"
                );
                let dist = lattice.distances((0, 0));
                assert!(dist.iter().all(Option::is_some), "{cells} cells, {seed}");
            }
        }
    }

    /// The drawn world is the perfect maze too: probing the middle of every inner wall finds
    /// `cells² − 1` of them open, and the robot reaches every cell centre and every free cell.
    #[test]
    fn the_drawn_maze_is_perfect() {
        let spec = WorldSpec::new(Family::Maze);
        let p = &spec.maze;
        let (n, c, w) = (p.cells, p.corridor_width, p.wall_thickness);
        let pitch = c + w;
        for seed in 0..20 {
            let s = generate(&spec, seed).unwrap();
            let blocked = |x: f64, y: f64| s.obstacles.iter().any(|o| o.contains(x, y));
            let mut open = 0;
            for j in 0..n {
                for i in 0..n {
                    let (x, y) = (i as f64 * pitch + c / 2.0, j as f64 * pitch + c / 2.0);
                    if i + 1 < n && !blocked(x + c / 2.0 + w / 2.0, y) {
                        open += 1;
                    }
                    if j + 1 < n && !blocked(x, y + c / 2.0 + w / 2.0) {
                        open += 1;
                    }
                }
            }
            assert_eq!(open, n * n - 1, "seed {seed}");
            let space = FreeSpace::new(&s);
            for j in 0..n {
                for i in 0..n {
                    let (x, y) = (i as f64 * pitch + c / 2.0, j as f64 * pitch + c / 2.0);
                    assert!(space.is_reachable(x, y), "seed {seed}: cell ({i}, {j})");
                }
            }
            assert_eq!(space.count(FREE), 0, "seed {seed}");
            assert!(s.obstacles.iter().all(|o| o.side == w));
            assert_eq!(s.start.x, c / 2.0);
        }
    }

    /// A robot of radius just below half the corridor width gets from the start to the goal; one
    /// just above fits nowhere in a corridor and does not (and the generator refuses it).
    #[test]
    fn the_corridor_width_is_honoured() {
        let spec = WorldSpec::new(Family::Maze);
        let half = spec.maze.corridor_width / 2.0;
        for seed in 0..5 {
            let s = generate(&spec, seed).unwrap();
            let goal = s.goal.unwrap();
            let mut thin = s.clone();
            thin.robot.radius = half - 0.02;
            let space = FreeSpace::with_resolution(&thin, 0.01);
            assert!(space.goal_reachable(&goal), "seed {seed}");
            assert!(
                space
                    .shortest_path((s.start.x, s.start.y), (goal.x, goal.y))
                    .is_some()
            );
            let mut fat = s.clone();
            fat.robot.radius = half + 0.02;
            let space = FreeSpace::with_resolution(&fat, 0.01);
            assert!(!fat.disk_is_free(s.start.x, s.start.y));
            assert!(!space.goal_reachable(&goal), "seed {seed}");
            assert_eq!(
                space.shortest_path((s.start.x, s.start.y), (goal.x, goal.y)),
                None,
                "seed {seed}"
            );
        }
        let mut fat = spec.clone();
        fat.robot.radius = half + 0.02;
        let e = generate(&fat, 0).unwrap_err().to_string();
        assert!(e.contains("parameter `maze.corridor_width`"), "{e}");
    }

    /// The default maze is scenarios/maze.toml's: 11.5 m square, 0.5 m squares on the lattice.
    #[test]
    fn the_default_maze_has_the_shape_of_the_maze_scenario() {
        let s = generate(&WorldSpec::new(Family::Maze), 3).unwrap();
        assert_eq!((s.arena_width, s.arena_height), (11.5, 11.5));
        // 49 closed walls of two squares and 49 posts.
        assert_eq!(s.obstacles.len(), 49 * 3);
        for o in &s.obstacles {
            let on_lattice = |v: f64| ((v - 0.25) / 0.5).fract() == 0.0;
            assert!(on_lattice(o.cx) && on_lattice(o.cy), "{o:?}");
        }
    }
}
