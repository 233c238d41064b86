//! `clutter`: a rectangular field of random squares, sides drawn in `[min_size, max_size]`, placed
//! by rejection (random sequential adsorption, Feder 1980) so that any two squares, and any square and the arena walls, are at least
//! `min_gap` apart (more than the robot's diameter, so the robot fits between any two), until
//! they cover `density` of the field. The start is at the left side, the goal at the right,
//! each kept `min_gap` clear of every square.

use super::{Bad, ChaCha8Rng, Layout, check_arena, positive, uniform, wider_than_robot};
use mole_types::{MAX_OBSTACLES, Pose2, RobotSpec, Square};

/// Squares drawn at most per world before the field counts as full.
const PLACEMENT_TRIES: usize = 20_000;

/// Parameters of the clutter family.
#[derive(Debug, Clone, PartialEq)]
pub struct ClutterParams {
    /// Field (arena) width (m).
    pub width: f64,
    /// Field (arena) height (m).
    pub height: f64,
    /// Smallest square side (m).
    pub min_size: f64,
    /// Largest square side (m).
    pub max_size: f64,
    /// Least distance between squares, walls, start and goal disks (m); above the robot diameter.
    pub min_gap: f64,
    /// Fraction of the field to cover, in [0, 1]; placement jams at 0.09–0.12 with the defaults.
    pub density: f64,
}

impl Default for ClutterParams {
    /// A 10 m × 10 m field of squares of 0.3 to 0.8 m, 0.6 m apart, covering 7% of it.
    fn default() -> Self {
        ClutterParams {
            width: 10.0,
            height: 10.0,
            min_size: 0.3,
            max_size: 0.8,
            min_gap: 0.6,
            density: 0.07,
        }
    }
}

impl ClutterParams {
    /// `key = value` for the file header.
    pub(super) fn describe(&self) -> String {
        format!(
            "clutter.width = {:?}, clutter.height = {:?}, clutter.min_size = {:?}, \
             clutter.max_size = {:?}, clutter.min_gap = {:?}, clutter.density = {:?}",
            self.width, self.height, self.min_size, self.max_size, self.min_gap, self.density
        )
    }

    /// Checks the parameters against the robot and the grid.
    pub(super) fn check(&self, robot: &RobotSpec, resolution: f64) -> Result<(), Bad> {
        positive("clutter.width", self.width)?;
        positive("clutter.height", self.height)?;
        positive("clutter.min_size", self.min_size)?;
        positive("clutter.max_size", self.max_size)?;
        if self.max_size < self.min_size {
            return Err(Bad::new(
                "clutter.max_size",
                format!("at least min_size = {:?} m", self.min_size),
                self.max_size,
            ));
        }
        wider_than_robot("clutter.min_gap", self.min_gap, robot)?;
        if !(0.0..=1.0).contains(&self.density) {
            return Err(Bad::new(
                "clutter.density",
                "a fraction of the field in [0, 1]",
                self.density,
            ));
        }
        let least = 2.0 * self.min_gap + self.max_size;
        for (name, v) in [
            ("clutter.width", self.width),
            ("clutter.height", self.height),
        ] {
            if v < least {
                return Err(Bad::new(
                    name,
                    format!("at least 2 × min_gap + max_size = {least:?} m"),
                    v,
                ));
            }
        }
        check_arena("clutter.width", self.width, self.height, resolution)
    }

    /// One draw: the start and goal heights, then squares until the density is reached.
    pub(super) fn draw(&self, robot: &RobotSpec, rng: &mut ChaCha8Rng) -> Layout {
        let (w, h) = (self.width, self.height);
        let r = robot.radius;
        // The start and goal centres stand a radius off the side walls.
        let edge = 2.0 * r;
        let start = (edge, uniform(rng, edge, h - edge));
        let goal = (w - edge, uniform(rng, edge, h - edge));
        let clear = r + self.min_gap;
        let target = self.density * w * h;
        let gap = self.min_gap;
        let mut covered = 0.0;
        let mut squares: Vec<Square> = Vec::new();
        for _ in 0..PLACEMENT_TRIES {
            if covered >= target || squares.len() >= MAX_OBSTACLES {
                break;
            }
            let side = uniform(rng, self.min_size, self.max_size);
            let half = side / 2.0;
            let cx = uniform(rng, gap + half, w - gap - half);
            let cy = uniform(rng, gap + half, h - gap - half);
            let s = Square::new(cx, cy, side);
            if point_distance(&s, start) < clear
                || point_distance(&s, goal) < clear
                || squares.iter().any(|o| gap_between(o, &s) < gap)
            {
                continue;
            }
            covered += side * side;
            squares.push(s);
        }
        Layout {
            width: w,
            height: h,
            start: Pose2::new(start.0, start.1, 0.0),
            goal,
            obstacles: squares,
        }
    }
}

/// Distance from a point to a square (0 inside).
fn point_distance(s: &Square, (x, y): (f64, f64)) -> f64 {
    let half = s.side / 2.0;
    let dx = ((x - s.cx).abs() - half).max(0.0);
    let dy = ((y - s.cy).abs() - half).max(0.0);
    (dx * dx + dy * dy).sqrt()
}

/// Distance between two squares (0 when they overlap).
pub(super) fn gap_between(a: &Square, b: &Square) -> f64 {
    let reach = (a.side + b.side) / 2.0;
    let dx = ((a.cx - b.cx).abs() - reach).max(0.0);
    let dy = ((a.cy - b.cy).abs() - reach).max(0.0);
    (dx * dx + dy * dy).sqrt()
}

#[cfg(test)]
mod tests {
    use super::super::{Family, WorldSpec, generate};
    use super::*;

    /// Any two squares, and any square and the walls, the start and the goal, keep the gap.
    #[test]
    fn the_minimum_gap_holds_between_every_pair() {
        for gap in [0.6, 0.9] {
            let mut spec = WorldSpec::new(Family::Clutter);
            spec.clutter.min_gap = gap;
            let (w, h) = (spec.clutter.width, spec.clutter.height);
            for seed in 0..50 {
                let s = generate(&spec, seed).unwrap();
                let o = &s.obstacles;
                assert!(o.len() >= 10, "seed {seed}: only {} squares", o.len());
                for (i, a) in o.iter().enumerate() {
                    for b in &o[i + 1..] {
                        assert!(gap_between(a, b) >= gap, "seed {seed}: {a:?} {b:?}");
                    }
                    let half = a.side / 2.0;
                    assert!(a.cx - half >= gap && a.cy - half >= gap, "{a:?}");
                    assert!(a.cx + half <= w - gap && a.cy + half <= h - gap, "{a:?}");
                    assert!((0.3..=0.8).contains(&a.side), "{a:?}");
                    let goal = s.goal.unwrap();
                    for (x, y) in [(s.start.x, s.start.y), (goal.x, goal.y)] {
                        assert!(point_distance(a, (x, y)) >= s.robot.radius + gap);
                    }
                }
                assert!(s.start.x < 1.0 && s.goal.unwrap().x > w - 1.0);
            }
        }
    }

    /// The squares cover the density asked for, when there is room for it.
    #[test]
    fn the_density_is_reached() {
        let mut spec = WorldSpec::new(Family::Clutter);
        for density in [0.0, 0.035, 0.07] {
            spec.clutter.density = density;
            for seed in 0..50 {
                let s = generate(&spec, seed).unwrap();
                let covered: f64 = s.obstacles.iter().map(|o| o.side * o.side).sum();
                let target = density * 100.0;
                assert!(
                    covered >= target && covered < target + 0.8 * 0.8,
                    "density {density}, seed {seed}: {covered}"
                );
            }
        }
    }
}
