//! Noise-free 2-D ray casting against the arena walls and the axis-aligned square obstacles.
//!
//! Broad phase: a uniform grid of obstacle indices (compressed rows, built once) walked with the
//! voxel traversal of Amanatides & Woo, "A Fast Voxel Traversal Algorithm for Ray Tracing" (1987);
//! narrow phase: the slab test per square (Kay & Kajiya 1986). A cast never allocates.
//!
//! Conventions: a ray starts at `(x, y)` with heading `angle` (world frame, rad); a surface that
//! the ray merely touches (a corner, or an edge it runs along) counts as a hit; a ray that starts
//! inside a square or outside the arena reads 0 (it starts inside a solid).

use crate::SensingError;
use mole_types::{Square, WorldMap};

/// Most grid cells along one axis of the broad phase (512 × 512 cells × 4 bytes = 1 MiB of offsets).
pub const MAX_CELLS_PER_AXIS: usize = 512;

/// An axis-aligned box `[x0, x1] × [y0, y1]`.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Aabb {
    x0: f64,
    y0: f64,
    x1: f64,
    y1: f64,
}

impl Aabb {
    fn of(s: &Square) -> Self {
        let (x0, y0) = s.min();
        let (x1, y1) = s.max();
        Self { x0, y0, x1, y1 }
    }

    /// Entry distance of the ray `o + t·d`, `t ≥ 0`, into the box; +∞ when it misses, 0 when the
    /// origin is inside. `inv_dx`/`inv_dy` are `1/dx`, `1/dy` (unused when the component is 0).
    #[inline]
    fn entry(&self, x: f64, y: f64, dx: f64, dy: f64, inv_dx: f64, inv_dy: f64) -> f64 {
        // Slab test (Kay & Kajiya 1986); a zero direction component is handled explicitly so that
        // 0 × ∞ never produces NaN for an origin on a slab plane.
        let (mut t0, mut t1) = (f64::NEG_INFINITY, f64::INFINITY);
        if dx != 0.0 {
            let a = (self.x0 - x) * inv_dx;
            let b = (self.x1 - x) * inv_dx;
            t0 = a.min(b);
            t1 = a.max(b);
        } else if x < self.x0 || x > self.x1 {
            return f64::INFINITY;
        }
        if dy != 0.0 {
            let a = (self.y0 - y) * inv_dy;
            let b = (self.y1 - y) * inv_dy;
            t0 = t0.max(a.min(b));
            t1 = t1.min(a.max(b));
        } else if y < self.y0 || y > self.y1 {
            return f64::INFINITY;
        }
        if t0 > t1 || t1 < 0.0 {
            f64::INFINITY
        } else {
            t0.max(0.0)
        }
    }

    fn overlaps(&self, width: f64, height: f64) -> bool {
        self.x1 >= 0.0 && self.x0 <= width && self.y1 >= 0.0 && self.y0 <= height
    }
}

/// The noise-free ray caster over a fixed world: arena `[0, width] × [0, height]` and squares.
///
/// Built once (allocates); [`RayCaster::cast`] and friends never allocate.
#[derive(Debug, Clone)]
pub struct RayCaster {
    width: f64,
    height: f64,
    /// Every square, in map order.
    boxes: Vec<Aabb>,
    /// Grid: `nx × ny` cells of `cell_w × cell_h` tiling the arena exactly.
    nx: usize,
    ny: usize,
    cell_w: f64,
    cell_h: f64,
    /// Row offsets: cell `c` holds `cell_items[cell_start[c]..cell_start[c + 1]]`.
    cell_start: Vec<u32>,
    cell_items: Vec<u32>,
}

impl RayCaster {
    /// Builds the caster for an arena of `width × height` (m) and its square obstacles.
    ///
    /// The grid cell is about the mean side of the squares in the arena (so a square covers a
    /// handful of cells), with at most [`MAX_CELLS_PER_AXIS`] cells per axis.
    pub fn new(width: f64, height: f64, squares: &[Square]) -> Result<Self, SensingError> {
        for (field, v) in [("arena_width", width), ("arena_height", height)] {
            if !(v.is_finite() && v > 0.0) {
                return Err(SensingError::OutOfRange { field, value: v });
            }
        }
        if squares.len() > u32::MAX as usize {
            return Err(SensingError::OutOfRange {
                field: "obstacles",
                value: squares.len() as f64,
            });
        }
        let mut boxes = Vec::with_capacity(squares.len());
        for s in squares {
            if !(s.cx.is_finite() && s.cy.is_finite() && s.side.is_finite()) {
                return Err(SensingError::OutOfRange {
                    field: "obstacles",
                    value: f64::NAN,
                });
            }
            if s.side <= 0.0 {
                return Err(SensingError::OutOfRange {
                    field: "obstacles.side",
                    value: s.side,
                });
            }
            boxes.push(Aabb::of(s));
        }

        let (mut side_sum, mut n_in) = (0.0, 0usize);
        for b in boxes.iter().filter(|b| b.overlaps(width, height)) {
            side_sum += b.x1 - b.x0;
            n_in += 1;
        }
        let min_cell = width.max(height) / MAX_CELLS_PER_AXIS as f64;
        let cell = if n_in == 0 {
            width.max(height)
        } else {
            (side_sum / n_in as f64).max(min_cell)
        };
        let nx = ((width / cell).ceil() as usize).clamp(1, MAX_CELLS_PER_AXIS);
        let ny = ((height / cell).ceil() as usize).clamp(1, MAX_CELLS_PER_AXIS);
        let cell_w = width / nx as f64;
        let cell_h = height / ny as f64;

        let mut caster = Self {
            width,
            height,
            boxes,
            nx,
            ny,
            cell_w,
            cell_h,
            cell_start: vec![0; nx * ny + 1],
            cell_items: Vec::new(),
        };
        caster.fill_grid();
        Ok(caster)
    }

    /// Builds the caster from a world map's arena and obstacles (after `map.validate()`).
    pub fn from_map(map: &WorldMap) -> Result<Self, SensingError> {
        Self::new(map.arena_width, map.arena_height, map.obstacles())
    }

    /// The cell range a box covers, padded so that a hit exactly on a cell boundary is found
    /// from either side.
    fn cell_range(&self, b: &Aabb) -> (usize, usize, usize, usize) {
        let pad = 1e-9 * (1.0 + self.width.max(self.height));
        let ix = |x: f64| ((x / self.cell_w).floor().max(0.0) as usize).min(self.nx - 1);
        let iy = |y: f64| ((y / self.cell_h).floor().max(0.0) as usize).min(self.ny - 1);
        (
            ix(b.x0 - pad),
            ix(b.x1 + pad),
            iy(b.y0 - pad),
            iy(b.y1 + pad),
        )
    }

    /// Counting sort of the in-arena squares into the cells (two passes, compressed rows).
    fn fill_grid(&mut self) {
        let mut counts = vec![0u32; self.nx * self.ny];
        for b in self
            .boxes
            .iter()
            .filter(|b| b.overlaps(self.width, self.height))
        {
            let (x0, x1, y0, y1) = self.cell_range(b);
            for iy in y0..=y1 {
                for c in &mut counts[iy * self.nx + x0..=iy * self.nx + x1] {
                    *c += 1;
                }
            }
        }
        let mut total = 0u32;
        for (c, n) in counts.iter().enumerate() {
            self.cell_start[c] = total;
            total = total.saturating_add(*n);
        }
        self.cell_start[self.nx * self.ny] = total;
        self.cell_items = vec![0; total as usize];
        let mut cursor: Vec<u32> = self.cell_start[..self.nx * self.ny].to_vec();
        for (i, b) in self.boxes.iter().enumerate() {
            if !b.overlaps(self.width, self.height) {
                continue;
            }
            let (x0, x1, y0, y1) = self.cell_range(b);
            for iy in y0..=y1 {
                for ix in x0..=x1 {
                    let c = iy * self.nx + ix;
                    self.cell_items[cursor[c] as usize] = i as u32;
                    cursor[c] += 1;
                }
            }
        }
    }

    /// Arena width (m).
    pub fn width(&self) -> f64 {
        self.width
    }

    /// Arena height (m).
    pub fn height(&self) -> f64 {
        self.height
    }

    /// Number of square obstacles.
    pub fn n_obstacles(&self) -> usize {
        self.boxes.len()
    }

    /// Broad-phase grid size (cells along x, cells along y).
    pub fn grid_dims(&self) -> (usize, usize) {
        (self.nx, self.ny)
    }

    /// Whether `(x, y)` lies inside the closed arena.
    #[inline]
    fn in_arena(&self, x: f64, y: f64) -> bool {
        (0.0..=self.width).contains(&x) && (0.0..=self.height).contains(&y)
    }

    /// Whether `(x, y)` is free: inside the closed arena and not strictly inside any square (a
    /// square's rim counts as free).
    pub fn is_free(&self, x: f64, y: f64) -> bool {
        if !self.in_arena(x, y) {
            return false;
        }
        let (ix, iy) = self.cell_of(x, y);
        let c = iy * self.nx + ix;
        self.cell_items[self.cell_start[c] as usize..self.cell_start[c + 1] as usize]
            .iter()
            .all(|&i| {
                let b = &self.boxes[i as usize];
                !(x > b.x0 && x < b.x1 && y > b.y0 && y < b.y1)
            })
    }

    #[inline]
    fn cell_of(&self, x: f64, y: f64) -> (usize, usize) {
        let ix = ((x / self.cell_w).floor().max(0.0) as usize).min(self.nx - 1);
        let iy = ((y / self.cell_h).floor().max(0.0) as usize).min(self.ny - 1);
        (ix, iy)
    }

    /// Distance from `(x, y)` to the first wall or square along heading `angle`, at most
    /// `max_range` (a ray that hits nothing within `max_range` reads `max_range`).
    ///
    /// Non-finite inputs, an origin outside the arena or inside a square read 0; a negative or
    /// NaN `max_range` is taken as 0.
    #[inline]
    pub fn cast(&self, x: f64, y: f64, angle: f64, max_range: f64) -> f64 {
        let (dy, dx) = angle.sin_cos();
        self.cast_dir(x, y, dx, dy, max_range)
    }

    /// [`RayCaster::cast`] along a direction `(dx, dy)` (need not be unit: the distance is in units
    /// of its length; pass a unit vector for metres). A zero direction reads 0.
    pub fn cast_dir(&self, x: f64, y: f64, dx: f64, dy: f64, max_range: f64) -> f64 {
        let max_range = if max_range > 0.0 { max_range } else { 0.0 };
        if !(x.is_finite() && y.is_finite() && dx.is_finite() && dy.is_finite())
            || (dx == 0.0 && dy == 0.0)
            || !self.in_arena(x, y)
        {
            return 0.0;
        }
        let t_wall = self.wall_exit(x, y, dx, dy);
        let limit = t_wall.min(max_range);
        let t_obstacle = self.grid_hit(x, y, dx, dy, limit);
        t_obstacle.min(t_wall).min(max_range)
    }

    /// Distance along `(dx, dy)` from `(x, y)` to the first SQUARE (walls ignored) if one is hit
    /// within `max_range`; an origin inside a square gives `Some(0.0)`. Used for line of sight.
    pub fn first_obstacle_hit(
        &self,
        x: f64,
        y: f64,
        dx: f64,
        dy: f64,
        max_range: f64,
    ) -> Option<f64> {
        if !(x.is_finite() && y.is_finite() && dx.is_finite() && dy.is_finite())
            || (dx == 0.0 && dy == 0.0)
        {
            return None;
        }
        let max_range = if max_range > 0.0 { max_range } else { 0.0 };
        // The grid covers the arena only: a segment that starts or ends outside it (a beacon
        // beyond the walls) may meet squares, or parts of squares, outside the arena.
        let t = if self.in_arena(x, y) && max_range < self.wall_exit(x, y, dx, dy) {
            self.grid_hit(x, y, dx, dy, max_range)
        } else {
            self.brute_obstacles(x, y, dx, dy)
        };
        (t <= max_range).then_some(t)
    }

    /// The reference caster: the same result as [`RayCaster::cast`], testing every square (no
    /// broad phase). For tests and cross-checks.
    pub fn cast_brute_force(&self, x: f64, y: f64, angle: f64, max_range: f64) -> f64 {
        let (dy, dx) = angle.sin_cos();
        let max_range = if max_range > 0.0 { max_range } else { 0.0 };
        if !(x.is_finite() && y.is_finite() && dx.is_finite() && dy.is_finite())
            || (dx == 0.0 && dy == 0.0)
            || !self.in_arena(x, y)
        {
            return 0.0;
        }
        let t_wall = self.wall_exit(x, y, dx, dy);
        self.brute_obstacles(x, y, dx, dy)
            .min(t_wall)
            .min(max_range)
    }

    /// Nearest square entry over every square.
    fn brute_obstacles(&self, x: f64, y: f64, dx: f64, dy: f64) -> f64 {
        let (inv_dx, inv_dy) = (1.0 / dx, 1.0 / dy);
        self.boxes
            .iter()
            .map(|b| b.entry(x, y, dx, dy, inv_dx, inv_dy))
            .fold(f64::INFINITY, f64::min)
    }

    /// Distance from an origin inside the arena to where the ray leaves it.
    #[inline]
    fn wall_exit(&self, x: f64, y: f64, dx: f64, dy: f64) -> f64 {
        let tx = if dx > 0.0 {
            (self.width - x) / dx
        } else if dx < 0.0 {
            -x / dx
        } else {
            f64::INFINITY
        };
        let ty = if dy > 0.0 {
            (self.height - y) / dy
        } else if dy < 0.0 {
            -y / dy
        } else {
            f64::INFINITY
        };
        tx.min(ty).max(0.0)
    }

    /// Nearest in-arena square hit within `limit` (+∞ if none), walking the grid cells the ray
    /// crosses (Amanatides & Woo 1987). The origin must be inside the arena, `(dx, dy)` non-zero.
    fn grid_hit(&self, x: f64, y: f64, dx: f64, dy: f64, limit: f64) -> f64 {
        if self.cell_items.is_empty() {
            return f64::INFINITY;
        }
        let (inv_dx, inv_dy) = (1.0 / dx, 1.0 / dy);
        let (ix, iy) = self.cell_of(x, y);
        let (mut ix, mut iy) = (ix as isize, iy as isize);
        let (step_x, mut t_max_x, t_delta_x) = if dx > 0.0 {
            (
                1,
                ((ix + 1) as f64 * self.cell_w - x) * inv_dx,
                self.cell_w * inv_dx,
            )
        } else if dx < 0.0 {
            (
                -1,
                (ix as f64 * self.cell_w - x) * inv_dx,
                -self.cell_w * inv_dx,
            )
        } else {
            (0, f64::INFINITY, f64::INFINITY)
        };
        let (step_y, mut t_max_y, t_delta_y) = if dy > 0.0 {
            (
                1,
                ((iy + 1) as f64 * self.cell_h - y) * inv_dy,
                self.cell_h * inv_dy,
            )
        } else if dy < 0.0 {
            (
                -1,
                (iy as f64 * self.cell_h - y) * inv_dy,
                -self.cell_h * inv_dy,
            )
        } else {
            (0, f64::INFINITY, f64::INFINITY)
        };
        let (nx, ny) = (self.nx as isize, self.ny as isize);
        let mut best = f64::INFINITY;
        loop {
            let c = iy as usize * self.nx + ix as usize;
            let items =
                &self.cell_items[self.cell_start[c] as usize..self.cell_start[c + 1] as usize];
            for &i in items {
                best = best.min(self.boxes[i as usize].entry(x, y, dx, dy, inv_dx, inv_dy));
            }
            let t_exit = t_max_x.min(t_max_y);
            // A hit before this cell's exit cannot be beaten by a square met further on.
            if best <= t_exit || t_exit > limit {
                break;
            }
            if t_max_x < t_max_y {
                ix += step_x;
                if ix < 0 || ix >= nx {
                    break;
                }
                t_max_x += t_delta_x;
            } else {
                iy += step_y;
                if iy < 0 || iy >= ny {
                    break;
                }
                t_max_y += t_delta_y;
            }
        }
        best
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;
    use core::f64::consts::{FRAC_1_SQRT_2, FRAC_PI_2, FRAC_PI_4, PI};
    use proptest::prelude::*;

    fn empty(w: f64, h: f64) -> RayCaster {
        RayCaster::new(w, h, &[]).expect("valid arena")
    }

    #[test]
    fn empty_arena_reads_the_walls() {
        let rc = empty(10.0, 8.0);
        let (x, y) = (2.0, 3.0);
        assert_relative_eq!(rc.cast(x, y, 0.0, 100.0), 8.0, epsilon = 1e-12);
        assert_relative_eq!(rc.cast(x, y, FRAC_PI_2, 100.0), 5.0, epsilon = 1e-12);
        assert_relative_eq!(rc.cast(x, y, PI, 100.0), 2.0, epsilon = 1e-12);
        assert_relative_eq!(rc.cast(x, y, -FRAC_PI_2, 100.0), 3.0, epsilon = 1e-12);
        // Towards the far corner (10, 8).
        let a = (5.0f64).atan2(8.0);
        assert_relative_eq!(rc.cast(x, y, a, 100.0), 89f64.sqrt(), epsilon = 1e-9);
        // Beyond max range reads max range.
        assert_eq!(rc.cast(x, y, 0.0, 3.5), 3.5);
        assert_eq!(rc.cast(x, y, 0.0, 0.0), 0.0);
        assert_eq!(rc.cast(x, y, 0.0, -1.0), 0.0);
    }

    #[test]
    fn square_in_front() {
        // Square [5, 7] × [2, 4]; robot at (2, 3) facing +x: the face x = 5 is 3 m away.
        let rc = RayCaster::new(10.0, 10.0, &[Square::new(6.0, 3.0, 2.0)]).expect("valid");
        assert_relative_eq!(rc.cast(2.0, 3.0, 0.0, 100.0), 3.0, epsilon = 1e-12);
        // Slightly upward: hits the face at y = 3.5.
        let a = (0.5f64).atan2(3.0);
        assert_relative_eq!(
            rc.cast(2.0, 3.0, a, 100.0),
            (9.25f64).sqrt(),
            epsilon = 1e-9
        );
        // Backwards: wall at x = 0.
        assert_relative_eq!(rc.cast(2.0, 3.0, PI, 100.0), 2.0, epsilon = 1e-12);
        // From the right, facing -x: the face x = 7 is 2 m from x = 9.
        assert_relative_eq!(rc.cast(9.0, 3.0, PI, 100.0), 2.0, epsilon = 1e-12);
        // Above the square going +x: misses it and reads the wall.
        assert_relative_eq!(rc.cast(2.0, 4.5, 0.0, 100.0), 8.0, epsilon = 1e-12);
        // Max range shorter than the square.
        assert_eq!(rc.cast(2.0, 3.0, 0.0, 2.0), 2.0);
    }

    #[test]
    fn beam_grazing_a_corner_and_an_edge_counts_as_a_hit() {
        // Square [5, 7] × [2, 4]; the line y = x - 1 touches only its corner (5, 4).
        let rc = RayCaster::new(10.0, 10.0, &[Square::new(6.0, 3.0, 2.0)]).expect("valid");
        let (d, t) = (FRAC_1_SQRT_2, 3.0 / FRAC_1_SQRT_2);
        assert_eq!(rc.cast_dir(2.0, 1.0, d, d, 100.0), t);
        assert_relative_eq!(t, 18f64.sqrt(), epsilon = 1e-12);
        // A hair above the corner the beam misses and reads the wall x = 10 (8 m along x).
        assert_relative_eq!(
            rc.cast_dir(2.0, 1.0 + 1e-9, d, d, 100.0),
            8.0 / d,
            epsilon = 1e-6
        );
        // Running along the top edge y = 4 counts as touching at x = 5.
        assert_relative_eq!(rc.cast(1.0, 4.0, 0.0, 100.0), 4.0, epsilon = 1e-12);
        assert_eq!(
            rc.cast_brute_force(2.0, 1.0, FRAC_PI_4, 100.0),
            rc.cast(2.0, 1.0, FRAC_PI_4, 100.0)
        );
    }

    #[test]
    fn origins_inside_solids_read_zero() {
        let rc = RayCaster::new(10.0, 10.0, &[Square::new(6.0, 3.0, 2.0)]).expect("valid");
        assert_eq!(rc.cast(6.0, 3.0, 0.3, 100.0), 0.0);
        assert_eq!(rc.cast(-1.0, 3.0, 0.0, 100.0), 0.0);
        assert_eq!(rc.cast(11.0, 3.0, PI, 100.0), 0.0);
        assert_eq!(rc.cast(f64::NAN, 3.0, 0.0, 100.0), 0.0);
        assert_eq!(rc.cast(1.0, 3.0, f64::INFINITY, 100.0), 0.0);
        assert_eq!(rc.cast_dir(1.0, 3.0, 0.0, 0.0, 100.0), 0.0);
        assert!(!rc.is_free(6.0, 3.0));
        assert!(rc.is_free(1.0, 1.0));
        assert!(!rc.is_free(-0.5, 1.0));
        // On the wall facing outward: 0.
        assert_eq!(rc.cast(0.0, 5.0, PI, 100.0), 0.0);
    }

    #[test]
    fn line_of_sight_ignores_walls_and_sees_squares() {
        let rc = RayCaster::new(10.0, 10.0, &[Square::new(6.0, 3.0, 2.0)]).expect("valid");
        assert_eq!(rc.first_obstacle_hit(2.0, 3.0, 1.0, 0.0, 100.0), Some(3.0));
        assert_eq!(rc.first_obstacle_hit(2.0, 3.0, 1.0, 0.0, 2.9), None);
        assert_eq!(rc.first_obstacle_hit(2.0, 3.0, -1.0, 0.0, 100.0), None);
        assert_eq!(rc.first_obstacle_hit(6.0, 3.0, -1.0, 0.0, 100.0), Some(0.0));
        // A square outside the arena is seen by a segment that leaves the arena.
        let rc = RayCaster::new(10.0, 10.0, &[Square::new(12.0, 3.0, 2.0)]).expect("valid");
        assert_eq!(rc.first_obstacle_hit(2.0, 3.0, 1.0, 0.0, 100.0), Some(9.0));
        assert_eq!(rc.cast(2.0, 3.0, 0.0, 100.0), 8.0);
    }

    #[test]
    fn bad_worlds_are_refused() {
        assert!(RayCaster::new(0.0, 10.0, &[]).is_err());
        assert!(RayCaster::new(10.0, f64::NAN, &[]).is_err());
        assert!(RayCaster::new(10.0, 10.0, &[Square::new(1.0, 1.0, 0.0)]).is_err());
        assert!(RayCaster::new(10.0, 10.0, &[Square::new(f64::INFINITY, 1.0, 1.0)]).is_err());
    }

    #[test]
    fn grid_stays_bounded_for_tiny_squares_in_a_huge_arena() {
        let rc = RayCaster::new(1e5, 1e5, &[Square::new(1.0, 1.0, 1e-3)]).expect("valid");
        let (nx, ny) = rc.grid_dims();
        assert!(nx <= MAX_CELLS_PER_AXIS && ny <= MAX_CELLS_PER_AXIS);
        assert_relative_eq!(rc.cast(0.5, 1.0, 0.0, 1e6), 0.5 - 5e-4, epsilon = 1e-9);
    }

    /// A maze-like world: a regular block pattern of `n × n` blocks of side `side` on a pitch.
    fn maze(n: usize, side: f64, pitch: f64) -> RayCaster {
        let mut squares = Vec::new();
        for i in 0..n {
            for j in 0..n {
                if (i * 7 + j * 3) % 4 != 0 {
                    squares.push(Square::new(
                        pitch * (i as f64 + 0.5),
                        pitch * (j as f64 + 0.5),
                        side,
                    ));
                }
            }
        }
        let extent = pitch * n as f64;
        RayCaster::new(extent, extent, &squares).expect("valid maze")
    }

    #[test]
    fn maze_of_a_thousand_squares_matches_brute_force() {
        // 36 × 36 pattern, ~970 squares of 0.4 m on a 0.55 m pitch: narrow corridors.
        let rc = maze(36, 0.4, 0.55);
        assert!(rc.n_obstacles() > 900);
        let mut origins = 0;
        for k in 0..40 {
            let x = 0.55 * (k as f64 % 36.0) + 0.02;
            let y = 0.55 * ((k * 13) as f64 % 36.0) + 0.02;
            if !rc.is_free(x, y) {
                continue;
            }
            origins += 1;
            for b in 0..360 {
                let a = -PI + b as f64 * PI / 180.0;
                let fast = rc.cast(x, y, a, 30.0);
                let slow = rc.cast_brute_force(x, y, a, 30.0);
                assert_eq!(fast, slow, "origin ({x}, {y}) angle {a}");
            }
        }
        assert!(origins > 20);
    }

    /// Release-mode timing of a 360-beam scan in a ~1000-square maze:
    /// `cargo test -p mole-sensing --release -- --ignored --nocapture scan_timing`.
    #[test]
    #[ignore]
    fn scan_timing() {
        let rc = maze(36, 0.4, 0.55);
        let start = std::time::Instant::now();
        let mut sum = 0.0;
        let n_scans = 2000;
        for s in 0..n_scans {
            let (x, y) = (
                0.02 + 0.55 * (s % 36) as f64,
                0.02 + 0.55 * ((s / 36) % 36) as f64,
            );
            for b in 0..360 {
                sum += rc.cast(x, y, b as f64 * PI / 180.0, 30.0);
            }
        }
        let per_scan = start.elapsed() / n_scans as u32;
        eprintln!(
            "360-beam scan in a {}-square maze: {per_scan:?} (checksum {sum})",
            rc.n_obstacles()
        );
    }

    fn world() -> impl Strategy<Value = (f64, f64, Vec<Square>)> {
        (2.0f64..30.0, 2.0f64..30.0).prop_flat_map(|(w, h)| {
            let free = (-1.0..w + 1.0, -1.0..h + 1.0, 0.05f64..3.0)
                .prop_map(|(cx, cy, side)| Square::new(cx, cy, side));
            // Grid-aligned squares stress rays along cell and square boundaries.
            let aligned = (0u32..=(w as u32), 0u32..=(h as u32), 1u32..=2)
                .prop_map(|(cx, cy, s)| Square::new(cx as f64 + 0.5, cy as f64, s as f64 * 0.5));
            (
                Just(w),
                Just(h),
                prop::collection::vec(prop_oneof![free, aligned], 0..80),
            )
        })
    }

    fn angle() -> impl Strategy<Value = f64> {
        prop_oneof![-4.0f64..4.0, (-8i32..8).prop_map(|k| k as f64 * FRAC_PI_4)]
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(200))]

        #[test]
        fn accelerated_caster_equals_brute_force(
            (w, h, squares) in world(),
            rays in prop::collection::vec((0.0f64..1.0, 0.0f64..1.0, angle(), 0.0f64..40.0), 1..24),
        ) {
            let rc = RayCaster::new(w, h, &squares).expect("valid world");
            for (fx, fy, a, max_range) in rays {
                let (x, y) = (fx * w, fy * h);
                let fast = rc.cast(x, y, a, max_range);
                let slow = rc.cast_brute_force(x, y, a, max_range);
                prop_assert_eq!(fast, slow, "origin ({}, {}) angle {}", x, y, a);
                prop_assert!((0.0..=max_range).contains(&fast));
                // Line of sight agrees with a brute-force scan of every square.
                let (dy, dx) = a.sin_cos();
                let los = rc.first_obstacle_hit(x, y, dx, dy, max_range);
                let brute = rc.brute_obstacles(x, y, dx, dy);
                prop_assert_eq!(los, (brute <= max_range).then_some(brute));
            }
        }

        #[test]
        fn origins_on_integer_coordinates_match_brute_force(
            (w, h, squares) in world(),
            rays in prop::collection::vec((0u32..30, 0u32..30, angle()), 1..24),
        ) {
            let rc = RayCaster::new(w, h, &squares).expect("valid world");
            for (ix, iy, a) in rays {
                let (x, y) = ((ix as f64).min(w), (iy as f64).min(h));
                prop_assert_eq!(rc.cast(x, y, a, 50.0), rc.cast_brute_force(x, y, a, 50.0));
            }
        }
    }
}
