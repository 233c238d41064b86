//! A lattice of square cells separated by walls, drawn as squares: the geometry the maze, the
//! rooms and the corridors share. Cell `(i, j)` spans `[i·p, i·p + c] × [j·p, j·p + c]` with
//! `p = c + w` (cell `c`, wall `w`), so the arena is `cols·p − w` wide, as scenarios/maze.toml
//! draws its maze; the arena walls bound the outer cells.

use super::{ChaCha8Rng, index};
use mole_types::{Pose2, Square};
use std::collections::VecDeque;

/// The wall between two neighbouring cells.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum Wall {
    /// A solid wall.
    Closed,
    /// No wall: the two cells form one corridor.
    Open,
    /// A wall with a gap from `from` to `to` (m along the wall from its lower or left end).
    Door { from: f64, to: f64 },
}

/// A lattice of cells and the walls between them; a solid cell is filled, walls and all.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct Lattice {
    pub(super) cols: usize,
    pub(super) rows: usize,
    /// Cell side c (m).
    pub(super) cell: f64,
    /// Wall thickness w (m).
    pub(super) wall: f64,
    /// The wall east of cell `(i, j)`, `i < cols − 1`, at `j·(cols − 1) + i`.
    east: Vec<Wall>,
    /// The wall north of cell `(i, j)`, `j < rows − 1`, at `j·cols + i`.
    north: Vec<Wall>,
    /// Filled cells, at `j·cols + i`.
    pub(super) solid: Vec<bool>,
}

impl Lattice {
    /// Every wall closed, no cell solid.
    pub(super) fn new(cols: usize, rows: usize, cell: f64, wall: f64) -> Lattice {
        Lattice {
            cols,
            rows,
            cell,
            wall,
            east: vec![Wall::Closed; cols.saturating_sub(1) * rows],
            north: vec![Wall::Closed; cols * rows.saturating_sub(1)],
            solid: vec![false; cols * rows],
        }
    }

    /// Cell pitch `c + w` (m).
    fn pitch(&self) -> f64 {
        self.cell + self.wall
    }

    /// Arena width and height (m).
    pub(super) fn extent(&self) -> (f64, f64) {
        extent(self.cols, self.rows, self.cell, self.wall)
    }

    /// Centre of a cell (m).
    pub(super) fn centre(&self, (i, j): (usize, usize)) -> (f64, f64) {
        let p = self.pitch();
        let half = self.cell / 2.0;
        (i as f64 * p + half, j as f64 * p + half)
    }

    /// Index of a cell in `solid` and in distance tables.
    pub(super) fn at(&self, (i, j): (usize, usize)) -> usize {
        j * self.cols + i
    }

    /// The cells next to a cell (east, west, north, south), inside the lattice.
    pub(super) fn neighbours(&self, (i, j): (usize, usize)) -> Vec<(usize, usize)> {
        let mut out = Vec::with_capacity(4);
        if i + 1 < self.cols {
            out.push((i + 1, j));
        }
        if i > 0 {
            out.push((i - 1, j));
        }
        if j + 1 < self.rows {
            out.push((i, j + 1));
        }
        if j > 0 {
            out.push((i, j - 1));
        }
        out
    }

    /// Where the wall between two neighbouring cells is kept: `(true, k)` in `east`, `(false, k)`
    /// in `north`; `None` for cells that are not neighbours.
    fn slot(&self, a: (usize, usize), b: (usize, usize)) -> Option<(bool, usize)> {
        let (lo, hi) = if (a.1, a.0) <= (b.1, b.0) {
            (a, b)
        } else {
            (b, a)
        };
        if hi.0 >= self.cols || hi.1 >= self.rows {
            None
        } else if lo.1 == hi.1 && hi.0 == lo.0 + 1 {
            Some((true, lo.1 * (self.cols - 1) + lo.0))
        } else if lo.0 == hi.0 && hi.1 == lo.1 + 1 {
            Some((false, lo.1 * self.cols + lo.0))
        } else {
            None
        }
    }

    /// The wall between two neighbouring cells (`Closed` for cells that are not neighbours).
    pub(super) fn wall_between(&self, a: (usize, usize), b: (usize, usize)) -> Wall {
        match self.slot(a, b) {
            Some((true, k)) => self.east[k],
            Some((false, k)) => self.north[k],
            None => Wall::Closed,
        }
    }

    /// Sets the wall between two neighbouring cells (nothing for cells that are not).
    pub(super) fn set_wall(&mut self, a: (usize, usize), b: (usize, usize), wall: Wall) {
        match self.slot(a, b) {
            Some((true, k)) => self.east[k] = wall,
            Some((false, k)) => self.north[k] = wall,
            None => {}
        }
    }

    /// The neighbours a cell is joined to (an open wall or a door).
    pub(super) fn links(&self, c: (usize, usize)) -> Vec<(usize, usize)> {
        self.neighbours(c)
            .into_iter()
            .filter(|&n| self.joined(c, n))
            .collect()
    }

    /// Whether two neighbouring cells are joined (an open wall or a door).
    fn joined(&self, a: (usize, usize), b: (usize, usize)) -> bool {
        self.wall_between(a, b) != Wall::Closed
    }

    /// Walls that are not closed.
    #[cfg(test)]
    pub(super) fn openings(&self) -> usize {
        self.east
            .iter()
            .chain(&self.north)
            .filter(|w| **w != Wall::Closed)
            .count()
    }

    /// Steps from `from` to every cell through the joined walls (`None`: not joined).
    pub(super) fn distances(&self, from: (usize, usize)) -> Vec<Option<usize>> {
        let mut dist = vec![None; self.cols * self.rows];
        let mut queue = VecDeque::new();
        dist[self.at(from)] = Some(0);
        queue.push_back(from);
        while let Some(c) = queue.pop_front() {
            let d = dist[self.at(c)].unwrap_or(0);
            for n in self.links(c) {
                let k = self.at(n);
                if dist[k].is_none() {
                    dist[k] = Some(d + 1);
                    queue.push_back(n);
                }
            }
        }
        dist
    }

    /// The cell farthest from `from` through the joined walls (the first in row-major order on
    /// ties).
    pub(super) fn farthest(&self, from: (usize, usize)) -> (usize, usize) {
        let dist = self.distances(from);
        let mut best = (from, 0);
        for j in 0..self.rows {
            for i in 0..self.cols {
                if let Some(d) = dist[self.at((i, j))]
                    && d > best.1
                {
                    best = ((i, j), d);
                }
            }
        }
        best.0
    }

    /// Carves a spanning tree of the cells not solid, depth first from `from` (the recursive
    /// backtracker): each step opens the wall to a random unvisited neighbour with `wall(rng)`,
    /// and backs up when there is none. Every carved cell is then joined to every other by
    /// exactly one path ("perfect").
    pub(super) fn carve_tree(
        &mut self,
        from: (usize, usize),
        rng: &mut ChaCha8Rng,
        mut wall: impl FnMut(&mut ChaCha8Rng) -> Wall,
    ) {
        let mut visited: Vec<bool> = self.solid.clone();
        let mut stack = vec![from];
        visited[self.at(from)] = true;
        while let Some(&c) = stack.last() {
            let fresh: Vec<(usize, usize)> = self
                .neighbours(c)
                .into_iter()
                .filter(|&n| !visited[self.at(n)])
                .collect();
            if fresh.is_empty() {
                stack.pop();
                continue;
            }
            let n = fresh[index(rng, fresh.len())];
            let kind = wall(rng);
            self.set_wall(c, n, kind);
            visited[self.at(n)] = true;
            stack.push(n);
        }
    }

    /// Every wall that is closed, as pairs of neighbouring cells not solid (row-major order).
    pub(super) fn closed_walls(&self) -> Vec<((usize, usize), (usize, usize))> {
        let mut out = Vec::new();
        for j in 0..self.rows {
            for i in 0..self.cols {
                for n in [(i + 1, j), (i, j + 1)] {
                    if n.0 < self.cols
                        && n.1 < self.rows
                        && !self.solid[self.at((i, j))]
                        && !self.solid[self.at(n)]
                        && !self.joined((i, j), n)
                    {
                        out.push(((i, j), n));
                    }
                }
            }
        }
        out
    }

    /// The layout it draws: the start in cell (0, 0), the goal in the cell farthest from it.
    pub(super) fn layout(&self) -> super::Layout {
        let (width, height) = self.extent();
        let (sx, sy) = self.centre((0, 0));
        super::Layout {
            width,
            height,
            start: Pose2::new(sx, sy, 0.0),
            goal: self.centre(self.farthest((0, 0))),
            obstacles: self.squares(),
        }
    }

    /// The squares of the lattice: each solid cell one square of side `c + 2w` (the cell and
    /// its walls), each wall not next to a solid cell a row of wall-thickness squares (two rows
    /// for a door, one each side of the gap), and a wall-thickness post at every inner corner
    /// no solid cell covers.
    pub(super) fn squares(&self) -> Vec<Square> {
        let (c, w, p) = (self.cell, self.wall, self.pitch());
        let solid = |i: usize, j: usize| self.solid[j * self.cols + i];
        let mut out = Vec::new();
        for j in 0..self.rows {
            for i in 0..self.cols {
                if solid(i, j) {
                    let (x, y) = self.centre((i, j));
                    out.push(Square::new(x, y, c + 2.0 * w));
                }
            }
        }
        let segments = |wall: Wall| -> Vec<(f64, f64)> {
            match wall {
                Wall::Closed => vec![(0.0, c)],
                Wall::Open => Vec::new(),
                Wall::Door { from, to } => [(0.0, from), (to, c)]
                    .into_iter()
                    .filter(|(a, b)| b > a)
                    .collect(),
            }
        };
        for j in 0..self.rows {
            for i in 0..self.cols.saturating_sub(1) {
                if solid(i, j) || solid(i + 1, j) {
                    continue;
                }
                let x0 = i as f64 * p + c;
                for (a, b) in segments(self.east[j * (self.cols - 1) + i]) {
                    let y0 = j as f64 * p;
                    wall_row(&mut out, (x0, y0 + a), Axis::Y, b - a, w);
                }
            }
        }
        for j in 0..self.rows.saturating_sub(1) {
            for i in 0..self.cols {
                if solid(i, j) || solid(i, j + 1) {
                    continue;
                }
                let y0 = j as f64 * p + c;
                for (a, b) in segments(self.north[j * self.cols + i]) {
                    let x0 = i as f64 * p;
                    wall_row(&mut out, (x0 + a, y0), Axis::X, b - a, w);
                }
            }
        }
        for j in 0..self.rows.saturating_sub(1) {
            for i in 0..self.cols.saturating_sub(1) {
                if solid(i, j) || solid(i + 1, j) || solid(i, j + 1) || solid(i + 1, j + 1) {
                    continue;
                }
                let (x, y) = (i as f64 * p + c + w / 2.0, j as f64 * p + c + w / 2.0);
                out.push(Square::new(x, y, w));
            }
        }
        out
    }

    /// An upper bound on the squares [`Lattice::squares`] draws for this lattice's size, for the
    /// parameter checks: every wall closed and split once, every post drawn.
    pub(super) fn max_squares(cols: usize, rows: usize, cell: f64, wall: f64) -> f64 {
        let (cols, rows) = (cols as f64, rows as f64);
        let walls = (cols - 1.0).max(0.0) * rows + cols * (rows - 1.0).max(0.0);
        let per_wall = (cell.max(wall) / cell.min(wall)).ceil() + 1.0;
        let posts = (cols - 1.0).max(0.0) * (rows - 1.0).max(0.0);
        (walls * per_wall + posts).max(cols * rows)
    }
}

/// Arena width and height (m) of a lattice of this size, computed without building it.
pub(super) fn extent(cols: usize, rows: usize, cell: f64, wall: f64) -> (f64, f64) {
    let p = cell + wall;
    (cols as f64 * p - wall, rows as f64 * p - wall)
}

/// The direction a wall row runs in.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum Axis {
    X,
    Y,
}

/// A wall `length` long and `thickness` thick from its lower-left corner `(x0, y0)`, running
/// along `axis`: squares of side `thickness`, evenly spaced with the last flush with the end
/// (squares of side `length` across the wall when it is shorter than it is thick).
pub(super) fn wall_row(
    out: &mut Vec<Square>,
    (x0, y0): (f64, f64),
    axis: Axis,
    length: f64,
    thickness: f64,
) {
    if !(length > 0.0 && thickness > 0.0) {
        return;
    }
    // Along the run (`along`, `span`) and across it (`across`, `depth`).
    let (side, span, depth) = if length >= thickness {
        (thickness, length, thickness)
    } else {
        (length, thickness, length)
    };
    let n = ((span / side) - 1e-9).ceil().max(1.0) as usize;
    for k in 0..n {
        let along = if n == 1 {
            span / 2.0
        } else if k + 1 == n {
            span - side / 2.0
        } else {
            side / 2.0 + k as f64 * (span - side) / (n - 1) as f64
        };
        let across = depth / 2.0;
        // A short wall stacks its squares across the run instead of along it.
        let (u, v) = if length >= thickness {
            (along, across)
        } else {
            (across, along)
        };
        out.push(match axis {
            Axis::X => Square::new(x0 + u, y0 + v, side),
            Axis::Y => Square::new(x0 + v, y0 + u, side),
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A wall row covers exactly its rectangle with squares of the wall's thickness, or of its
    /// length when it is shorter than thick.
    #[test]
    fn a_wall_row_covers_its_rectangle() {
        for (axis, length, thickness, n, side) in [
            (Axis::X, 1.0, 0.5, 2, 0.5),
            (Axis::Y, 1.0, 0.3, 4, 0.3),
            (Axis::X, 0.3, 0.3, 1, 0.3),
            (Axis::Y, 0.1, 0.5, 5, 0.1),
        ] {
            let mut out = Vec::new();
            wall_row(&mut out, (2.0, 3.0), axis, length, thickness);
            assert_eq!(out.len(), n, "{axis:?} {length} {thickness}");
            assert!(out.iter().all(|o| o.side == side));
            let (w, h) = match axis {
                Axis::X => (length, thickness),
                Axis::Y => (thickness, length),
            };
            let covered = |x: f64, y: f64| out.iter().any(|o| o.contains(x, y));
            // Up to rounding at the far edges (an ulp of a coordinate).
            let at = |len: f64, k: i32| 1e-12 + (len - 2e-12) * f64::from(k) / 20.0;
            for k in 0..=20 {
                for m in 0..=20 {
                    let (x, y) = (2.0 + at(w, k), 3.0 + at(h, m));
                    assert!(covered(x, y), "{axis:?} {length} {thickness}: ({x}, {y})");
                }
            }
            let (lo, hi) = out.iter().fold((f64::MAX, f64::MIN), |(lo, hi), o| {
                (
                    lo.min(o.min().0.min(o.min().1)),
                    hi.max(o.max().0.max(o.max().1)),
                )
            });
            assert!(
                lo >= 2.0 - 1e-12 && hi <= 3.0 + w.max(h) + 1e-12,
                "inside: {lo} {hi}"
            );
        }
        let mut out = Vec::new();
        wall_row(&mut out, (0.0, 0.0), Axis::X, 0.0, 0.5);
        wall_row(&mut out, (0.0, 0.0), Axis::X, 1.0, f64::NAN);
        assert!(out.is_empty());
    }
}
