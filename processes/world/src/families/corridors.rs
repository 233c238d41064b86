//! `corridors`: a long main corridor across a lattice from its left column to its right one
//! (stepping east, with random jogs up or down), and side branches off it that end blind; every
//! lattice cell off the corridors is filled. Branches only ever enter unused cells, so the
//! corridors form a tree: the dead ends are real. The start is at the main corridor's west end,
//! the goal at its east end.

use super::lattice::{self, Lattice, Wall};
use super::{
    Bad, ChaCha8Rng, Layout, at_least, check_arena, check_obstacles, index, positive,
    wider_than_robot,
};
use mole_types::{Pose2, RobotSpec};
use rand::RngExt;

/// Chance that the main corridor jogs up or down in a column before it steps east.
const JOG: f64 = 0.35;
/// Cells a jog spans at most.
const MAX_JOG: usize = 2;
/// Chance that a branch goes straight on where it can.
const STRAIGHT: f64 = 0.6;
/// Cells of the main corridor tried for each branch before it is given up.
const BRANCH_TRIES: usize = 32;

/// Parameters of the corridors family.
#[derive(Debug, Clone, PartialEq)]
pub struct CorridorsParams {
    /// Lattice columns: the main corridor's length in cells (at least 2).
    pub cols: usize,
    /// Lattice rows.
    pub rows: usize,
    /// Corridor width (m): more than the robot's diameter.
    pub corridor_width: f64,
    /// Wall thickness (m): the side of the wall squares.
    pub wall_thickness: f64,
    /// Side branches to grow off the main corridor.
    pub branches: usize,
    /// Cells a branch spans at most (at least 1).
    pub branch_length: usize,
}

impl Default for CorridorsParams {
    /// 14 × 7 cells (20.5 m × 10 m), corridors 1.0 m wide, walls 0.5 m, 8 branches of up to 4
    /// cells.
    fn default() -> Self {
        CorridorsParams {
            cols: 14,
            rows: 7,
            corridor_width: 1.0,
            wall_thickness: 0.5,
            branches: 8,
            branch_length: 4,
        }
    }
}

impl CorridorsParams {
    /// `key = value` for the file header.
    pub(super) fn describe(&self) -> String {
        format!(
            "corridors.cols = {}, corridors.rows = {}, corridors.corridor_width = {:?}, \
             corridors.wall_thickness = {:?}, corridors.branches = {}, \
             corridors.branch_length = {}",
            self.cols,
            self.rows,
            self.corridor_width,
            self.wall_thickness,
            self.branches,
            self.branch_length
        )
    }

    /// Checks the parameters against the robot and the grid.
    pub(super) fn check(&self, robot: &RobotSpec, resolution: f64) -> Result<(), Bad> {
        at_least("corridors.cols", self.cols, 2)?;
        at_least("corridors.rows", self.rows, 1)?;
        wider_than_robot("corridors.corridor_width", self.corridor_width, robot)?;
        positive("corridors.wall_thickness", self.wall_thickness)?;
        at_least("corridors.branch_length", self.branch_length, 1)?;
        let (w, h) = lattice::extent(
            self.cols,
            self.rows,
            self.corridor_width,
            self.wall_thickness,
        );
        check_arena("corridors.cols", w, h, resolution)?;
        check_obstacles(
            "corridors.cols",
            Lattice::max_squares(
                self.cols,
                self.rows,
                self.corridor_width,
                self.wall_thickness,
            ),
            self.cols,
        )
    }

    /// The corridors of one draw, and the two ends of the main one (west, east).
    pub(super) fn lattice(
        &self,
        rng: &mut ChaCha8Rng,
    ) -> (Lattice, (usize, usize), (usize, usize)) {
        let (cols, rows) = (self.cols, self.rows);
        let mut lat = Lattice::new(cols, rows, self.corridor_width, self.wall_thickness);
        let mut used = vec![false; cols * rows];
        let mut j = index(rng, rows);
        let west = (0, j);
        used[lat.at(west)] = true;
        let mut main = vec![west];
        for i in 0..cols - 1 {
            if rows > 1 && rng.random_bool(JOG) {
                let up = rng.random_bool(0.5);
                for _ in 0..=index(rng, MAX_JOG) {
                    let next = if up { j + 1 } else { j.wrapping_sub(1) };
                    if next >= rows {
                        break;
                    }
                    lat.set_wall((i, j), (i, next), Wall::Open);
                    j = next;
                    used[lat.at((i, j))] = true;
                    main.push((i, j));
                }
            }
            lat.set_wall((i, j), (i + 1, j), Wall::Open);
            used[lat.at((i + 1, j))] = true;
            main.push((i + 1, j));
        }
        let east = (cols - 1, j);
        for _ in 0..self.branches {
            for _ in 0..BRANCH_TRIES {
                let from = main[index(rng, main.len())];
                let fresh = |lat: &Lattice, used: &[bool], c: (usize, usize)| {
                    lat.neighbours(c)
                        .into_iter()
                        .filter(|&n| !used[lat.at(n)])
                        .collect::<Vec<_>>()
                };
                let first = fresh(&lat, &used, from);
                if first.is_empty() {
                    continue;
                }
                let mut at = from;
                let mut next = first[index(rng, first.len())];
                for _ in 0..=index(rng, self.branch_length) {
                    lat.set_wall(at, next, Wall::Open);
                    used[lat.at(next)] = true;
                    let ahead = (
                        (2 * next.0).wrapping_sub(at.0),
                        (2 * next.1).wrapping_sub(at.1),
                    );
                    at = next;
                    let around = fresh(&lat, &used, at);
                    if around.is_empty() {
                        break;
                    }
                    next = if around.contains(&ahead) && rng.random_bool(STRAIGHT) {
                        ahead
                    } else {
                        around[index(rng, around.len())]
                    };
                }
                break;
            }
        }
        for (k, u) in used.iter().enumerate() {
            lat.solid[k] = !u;
        }
        (lat, west, east)
    }

    /// One draw: the corridors, the start at the main corridor's west end, the goal at its
    /// east end.
    pub(super) fn draw(&self, rng: &mut ChaCha8Rng) -> Layout {
        let (lattice, west, east) = self.lattice(rng);
        let (width, height) = lattice.extent();
        let (sx, sy) = lattice.centre(west);
        Layout {
            width,
            height,
            start: Pose2::new(sx, sy, 0.0),
            goal: lattice.centre(east),
            obstacles: lattice.squares(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    /// The corridors form a tree from the west end to the east end with dead ends off it: one
    /// path less than corridor cells, at least one blind end besides the two ends, and every
    /// corridor cell reachable.
    #[test]
    fn the_corridors_are_a_tree_with_dead_ends() {
        let p = CorridorsParams::default();
        for seed in 0..50 {
            let (lat, west, east) = p.lattice(&mut ChaCha8Rng::seed_from_u64(seed));
            assert_eq!((west.0, east.0), (0, p.cols - 1));
            let used: Vec<(usize, usize)> = (0..p.rows)
                .flat_map(|j| (0..p.cols).map(move |i| (i, j)))
                .filter(|&c| !lat.solid[lat.at(c)])
                .collect();
            assert_eq!(lat.openings(), used.len() - 1, "seed {seed}: a tree");
            let dist = lat.distances(west);
            assert!(used.iter().all(|&c| dist[lat.at(c)].is_some()));
            let blind = used
                .iter()
                .filter(|&&c| c != west && c != east && lat.links(c).len() == 1)
                .count();
            assert!(blind >= 2, "seed {seed}: {blind} dead ends");
            assert!(used.len() >= p.cols + 4, "seed {seed}: branches");
        }
    }

    /// The drawn world is the lattice: the robot reaches every corridor cell's centre and no
    /// filled cell's, and every free cell is reachable (no void behind the walls).
    #[test]
    fn the_drawn_corridors_are_the_lattice() {
        use super::super::{Family, WorldSpec, generate};
        use crate::free_space::{FREE, FreeSpace};
        let spec = WorldSpec::new(Family::Corridors);
        let p = &spec.corridors;
        for seed in 0..20 {
            let (lat, west, east) = p.lattice(&mut ChaCha8Rng::seed_from_u64(seed));
            let s = generate(&spec, seed).unwrap();
            assert_eq!(s.obstacles, lat.squares(), "seed {seed}: the first draw");
            assert_eq!((s.start.x, s.start.y), lat.centre(west));
            assert_eq!(s.goal.map(|g| (g.x, g.y)), Some(lat.centre(east)));
            let space = FreeSpace::new(&s);
            for j in 0..p.rows {
                for i in 0..p.cols {
                    let (x, y) = lat.centre((i, j));
                    let solid = lat.solid[lat.at((i, j))];
                    assert_eq!(space.is_reachable(x, y), !solid, "seed {seed}: ({i}, {j})");
                }
            }
            assert_eq!(space.count(FREE), 0, "seed {seed}");
        }
    }
}
