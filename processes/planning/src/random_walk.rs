//! Random walk (algorithms §3): the 1-D walk and its moments (§3.2), the 8-direction grid walk with
//! its coverage (§3.3), and [`RandomWalk`], the robot-level planner built on it.

use crate::obstacles::{corridor_clear, segment_free};
use crate::{Command, Planner, PlannerInput, PlanningError, RobotLimits, usable};
use core::f64::consts::{FRAC_PI_4, SQRT_2};
use mole_types::Setting;
use mole_types::{MODE_EXPLORE, PlannerKind, Pose2, wrap_angle};
use rand::{Rng, RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

fn check_probability(p: f64) -> Result<(), PlanningError> {
    if (0.0..=1.0).contains(&p) {
        Ok(())
    } else {
        Err(PlanningError::InvalidParameter {
            name: "p",
            value: p,
            expected: "a probability in [0, 1]",
        })
    }
}

/// Algorithms §3.2: x_k = x_0 + Σ_{t=1..k} ξ_t with ξ_t = +1 with probability p, −1 with q = 1 − p.
pub fn walk_1d<R: Rng + ?Sized>(
    rng: &mut R,
    x0: i64,
    k: u64,
    p: f64,
) -> Result<i64, PlanningError> {
    check_probability(p)?;
    let mut x = x0;
    for _ in 0..k {
        x = if rng.random_bool(p) {
            x.saturating_add(1)
        } else {
            x.saturating_sub(1)
        };
    }
    Ok(x)
}

/// Algorithms §3.2: E(x_k − x_0) = k(p − q).
pub fn mean_1d(k: u64, p: f64) -> f64 {
    k as f64 * (p - (1.0 - p))
}

/// Algorithms §3.2: Var(x_k) = 4kpq.
pub fn variance_1d(k: u64, p: f64) -> f64 {
    4.0 * k as f64 * p * (1.0 - p)
}

/// The diagonal stride of the 2-D walk for an orthogonal stride of r cells (algorithms §3.3).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum DiagonalStride {
    /// The source's ⌊r/√2⌋ cells per axis: 0 for r = 1, so every diagonal move stands still
    /// (docs/errata.md).
    Source,
    /// max(1, round(r/√2)) cells per axis: the nearest stride of Euclidean length ≈ r that moves.
    #[default]
    Rounded,
}

impl DiagonalStride {
    /// Cells per axis of a diagonal move for orthogonal stride `r`.
    pub fn cells(self, r: u32) -> u32 {
        let d = r as f64 / SQRT_2;
        match self {
            DiagonalStride::Source => d.floor() as u32,
            DiagonalStride::Rounded => (d.round() as u32).max(1),
        }
    }
}

/// The eight unit directions, counter-clockwise from +x: E, NE, N, NW, W, SW, S, SE.
const DIRECTIONS: [(i64, i64); 8] = [
    (1, 0),
    (1, 1),
    (0, 1),
    (-1, 1),
    (-1, 0),
    (-1, -1),
    (0, -1),
    (1, -1),
];

/// Parameters of a grid-level 2-D walk (algorithms §3.3).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Walk2d {
    /// Grid width m (cells).
    pub m: usize,
    /// Grid height n (cells).
    pub n: usize,
    /// Orthogonal stride r (cells).
    pub r: u32,
    /// Moves to make.
    pub steps: u64,
    /// How a diagonal stride is derived from r.
    pub diagonal: DiagonalStride,
    /// Start cell (column, row).
    pub start: (usize, usize),
}

/// What a 2-D walk did.
#[derive(Debug, Clone, PartialEq)]
pub struct WalkReport {
    /// Moves made.
    pub steps: u64,
    /// Moves along a diagonal.
    pub diagonal_moves: u64,
    /// Moves that left the walker where it was.
    pub stood_still: u64,
    /// Distinct cells the walker has been on (start, every cell it passed, every end point).
    pub covered_cells: usize,
    /// `covered_cells` as a percentage of m × n (algorithms §3.3's "total area covered").
    pub coverage_percent: f64,
    /// Where the walk ended (column, row).
    pub final_cell: (usize, usize),
}

/// Largest grid [`walk_2d`] accepts (cells), to bound its one allocation.
pub const MAX_WALK_CELLS: usize = 1 << 26;

/// Algorithms §3.3: a walk on an m × n grid choosing one of the 8 directions uniformly at random each
/// step, r cells orthogonally and [`DiagonalStride::cells`] diagonally, reporting the area
/// covered. Only moves that stay on the grid are drawn (the source leaves the border open).
pub fn walk_2d<R: Rng + ?Sized>(rng: &mut R, walk: &Walk2d) -> Result<WalkReport, PlanningError> {
    let Walk2d {
        m,
        n,
        r,
        steps,
        diagonal,
        start,
    } = *walk;
    if m == 0 || n == 0 || m.saturating_mul(n) > MAX_WALK_CELLS {
        return Err(PlanningError::InvalidParameter {
            name: "m×n",
            value: m as f64 * n as f64,
            expected: "between 1 and MAX_WALK_CELLS cells",
        });
    }
    if r == 0 {
        return Err(PlanningError::InvalidParameter {
            name: "r",
            value: 0.0,
            expected: "at least 1 cell",
        });
    }
    if start.0 >= m || start.1 >= n {
        return Err(PlanningError::InvalidParameter {
            name: "start",
            value: start.0.max(start.1) as f64,
            expected: "a cell inside the grid",
        });
    }
    let mut covered = vec![false; m * n];
    let (mut x, mut y) = (start.0 as i64, start.1 as i64);
    covered[start.1 * m + start.0] = true;
    let mut report = WalkReport {
        steps,
        diagonal_moves: 0,
        stood_still: 0,
        covered_cells: 1,
        coverage_percent: 0.0,
        final_cell: start,
    };
    let d = diagonal.cells(r) as i64;
    let mut valid = [0usize; 8];
    for _ in 0..steps {
        let mut n_valid = 0;
        for (k, &(dx, dy)) in DIRECTIONS.iter().enumerate() {
            let len = if dx != 0 && dy != 0 { d } else { r as i64 };
            let (tx, ty) = (x + dx * len, y + dy * len);
            if tx >= 0 && ty >= 0 && tx < m as i64 && ty < n as i64 {
                valid[n_valid] = k;
                n_valid += 1;
            }
        }
        if n_valid == 0 {
            report.stood_still += 1;
            continue;
        }
        let (dx, dy) = DIRECTIONS[valid[rng.random_range(0..n_valid)]];
        let diagonal_move = dx != 0 && dy != 0;
        let len = if diagonal_move { d } else { r as i64 };
        report.diagonal_moves += diagonal_move as u64;
        if len == 0 {
            report.stood_still += 1;
        }
        for _ in 0..len {
            x += dx;
            y += dy;
            let cell = &mut covered[y as usize * m + x as usize];
            report.covered_cells += !*cell as usize;
            *cell = true;
        }
    }
    report.final_cell = (x as usize, y as usize);
    report.coverage_percent = 100.0 * report.covered_cells as f64 / (m * n) as f64;
    Ok(report)
}

/// Settings of the robot-level [`RandomWalk`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, Setting)]
#[serde(default, deny_unknown_fields)]
pub struct RandomWalkConfig {
    /// Distance to each waypoint (m), in all 8 directions: in metres the algorithms §3.3 diagonal
    /// stride needs no rounding (r/√2 per axis).
    #[setting(above = 0.0)]
    pub stride: f64,
    /// A waypoint closer than this counts as reached (m).
    #[setting(above = 0.0)]
    pub reach_tolerance: f64,
    /// Give up on a waypoint after this long (s) and draw the next.
    #[setting(above = 0.0)]
    pub timeout: f64,
    /// Cruise speed as a fraction of the speed limit.
    #[setting(above = 0.0, max = 1.0)]
    pub cruise_fraction: f64,
    /// Proportional heading gain k: ω = k·(heading error) (1/s).
    #[setting(above = 0.0)]
    pub k_heading: f64,
    /// Turn in place while the heading error exceeds this (rad)...
    #[setting(min = 0.0)]
    pub turn_enter: f64,
    /// ...until it falls below this (rad); then drive.
    #[setting(min = 0.0)]
    pub turn_exit: f64,
    /// Algorithms §3.1's adaptive walk: with a grid, draw only directions whose segment (extended by
    /// the robot radius) is free or unexplored, never occupied.
    pub adaptive: bool,
    /// With a scan, also skip directions whose corridor (robot width) holds a scan hit.
    pub scan_aware: bool,
    /// Skip directions within this angle (rad) of an obstacle the reactive layer reported
    /// ([`Planner::obstacle_hint`])...
    #[setting(min = 0.0)]
    pub hint_half_angle: f64,
    /// ...while the robot is within this distance (m) of where it was met...
    #[setting(min = 0.0)]
    pub hint_radius: f64,
    /// ...for this many draws.
    pub hint_draws: u32,
}

impl Default for RandomWalkConfig {
    fn default() -> Self {
        Self {
            stride: 1.0,
            reach_tolerance: 0.05,
            timeout: 10.0,
            cruise_fraction: 0.8,
            k_heading: 2.5,
            turn_enter: 0.6,
            turn_exit: 0.1,
            adaptive: true,
            scan_aware: true,
            hint_half_angle: 1.2,
            hint_radius: 1.0,
            hint_draws: 6,
        }
    }
}

impl RandomWalkConfig {
    /// The config with every non-finite or out-of-range field replaced by its default.
    pub fn sanitized(self) -> Self {
        let d = Self::default();
        let pos = |x: f64, def: f64| if x.is_finite() && x > 0.0 { x } else { def };
        let turn_enter = pos(self.turn_enter, d.turn_enter);
        let turn_exit = pos(self.turn_exit, d.turn_exit).min(turn_enter);
        Self {
            stride: pos(self.stride, d.stride),
            reach_tolerance: pos(self.reach_tolerance, d.reach_tolerance),
            timeout: pos(self.timeout, d.timeout),
            cruise_fraction: pos(self.cruise_fraction, d.cruise_fraction).min(1.0),
            k_heading: pos(self.k_heading, d.k_heading),
            turn_enter,
            turn_exit,
            adaptive: self.adaptive,
            scan_aware: self.scan_aware,
            hint_half_angle: if self.hint_half_angle.is_finite() {
                self.hint_half_angle.clamp(0.0, core::f64::consts::PI)
            } else {
                d.hint_half_angle
            },
            hint_radius: if self.hint_radius.is_finite() {
                self.hint_radius.max(0.0)
            } else {
                d.hint_radius
            },
            hint_draws: self.hint_draws,
        }
    }
}

/// The robot-level random walk (algorithms §3.3 on the robot): draw one of 8 world directions (seeded
/// ChaCha8), drive to the waypoint one stride away — turn in place toward it, then drive with a
/// proportional heading controller — and draw the next when it is reached or after a timeout.
#[derive(Debug, Clone)]
pub struct RandomWalk {
    limits: RobotLimits,
    config: RandomWalkConfig,
    rng: ChaCha8Rng,
    waypoint: Option<[f64; 2]>,
    /// Index into the 8 directions of the current waypoint.
    direction: usize,
    started_tick: u64,
    turning: bool,
    picks: u64,
    fallbacks: u64,
    /// Obstacles the reactive layer met lately: (where, world heading, draws left).
    hints: [([f64; 2], f64, u32); HINTS],
    next_hint: usize,
}

/// How many obstacle hints the walk remembers.
const HINTS: usize = 4;

impl RandomWalk {
    /// A walk for a robot with `limits`, drawing directions from a ChaCha8 stream seeded `seed`.
    pub fn new(limits: RobotLimits, config: RandomWalkConfig, seed: u64) -> Self {
        Self {
            limits: limits.sanitized(),
            config: config.sanitized(),
            rng: ChaCha8Rng::seed_from_u64(seed),
            waypoint: None,
            direction: 0,
            started_tick: 0,
            turning: true,
            picks: 0,
            fallbacks: 0,
            hints: [([0.0; 2], 0.0, 0); HINTS],
            next_hint: 0,
        }
    }

    /// The settings in use.
    pub fn config(&self) -> &RandomWalkConfig {
        &self.config
    }

    /// Index (0 = +x, counter-clockwise in 45° steps) of the current direction, if any.
    pub fn direction(&self) -> Option<usize> {
        self.waypoint.map(|_| self.direction)
    }

    /// Directions drawn so far, and how many of them had to fall back to an unchecked one.
    pub fn picks(&self) -> (u64, u64) {
        (self.picks, self.fallbacks)
    }

    /// Which of the 8 directions pass the grid check (`grid_ok`) and the scan and hint checks
    /// (`scan_ok`).
    fn candidates(&self, input: &PlannerInput) -> ([bool; 8], [bool; 8]) {
        let p = input.pose;
        let s = self.config.stride;
        let mut grid_ok = [true; 8];
        let mut scan_ok = [true; 8];
        for k in 0..8 {
            let phi = k as f64 * FRAC_PI_4;
            scan_ok[k] = self.hints.iter().all(|&(at, heading, left)| {
                left == 0
                    || (at[0] - p.x).hypot(at[1] - p.y) > self.config.hint_radius
                    || wrap_angle(phi - heading).abs() > self.config.hint_half_angle
            });
            let (sin, cos) = phi.sin_cos();
            if self.config.adaptive
                && let Some(grid) = input.grid
            {
                let reach = s + self.limits.radius;
                grid_ok[k] = segment_free(grid, [p.x, p.y], [p.x + reach * cos, p.y + reach * sin]);
            }
            if self.config.scan_aware
                && let Some(scan) = input.scan
            {
                let r = self.limits.radius;
                scan_ok[k] &= corridor_clear(scan, wrap_angle(phi - p.theta), s + r, r);
            }
        }
        (grid_ok, scan_ok)
    }

    /// Draws the next direction: among those all checks pass, else those the grid check
    /// passes, else any (the adaptive walk never dead-ends).
    fn pick(&mut self, input: &PlannerInput) {
        let (grid_ok, scan_ok) = self.candidates(input);
        for h in self.hints.iter_mut() {
            h.2 = h.2.saturating_sub(1);
        }
        let mut pool = [0usize; 8];
        let mut n = 0;
        for pass in 0..3 {
            for k in 0..8 {
                let ok = match pass {
                    0 => grid_ok[k] && scan_ok[k],
                    1 => grid_ok[k],
                    _ => true,
                };
                if ok {
                    pool[n] = k;
                    n += 1;
                }
            }
            if n > 0 {
                self.fallbacks += (pass > 0) as u64;
                break;
            }
        }
        let k = pool[self.rng.random_range(0..n.max(1))];
        let phi = k as f64 * FRAC_PI_4;
        let p = input.pose;
        self.direction = k;
        self.waypoint = Some([
            p.x + self.config.stride * phi.cos(),
            p.y + self.config.stride * phi.sin(),
        ]);
        self.started_tick = input.tick;
        self.turning = true;
        self.picks += 1;
    }

    /// Heading controller toward the waypoint: turn in place while the error is large, else
    /// drive at cruise speed, slowing so the robot can stop at the waypoint.
    fn control(&mut self, pose: Pose2, wp: [f64; 2]) -> (f64, f64) {
        let (dx, dy) = (wp[0] - pose.x, wp[1] - pose.y);
        let dist = dx.hypot(dy);
        let e = wrap_angle(dy.atan2(dx) - pose.theta);
        if self.turning && e.abs() < self.config.turn_exit {
            self.turning = false;
        } else if !self.turning && e.abs() > self.config.turn_enter {
            self.turning = true;
        }
        let omega =
            (self.config.k_heading * e).clamp(-self.limits.max_omega, self.limits.max_omega);
        if self.turning {
            return (0.0, omega);
        }
        let cruise = self.config.cruise_fraction * self.limits.max_speed;
        // v ≤ √(2·a·d): stop at the waypoint within the acceleration limit.
        let brake = (2.0 * 0.8 * self.limits.max_accel * dist).sqrt();
        (cruise.min(brake) * e.cos().max(0.0), omega)
    }
}

impl crate::Registered for RandomWalk {
    fn build(
        settings: &crate::Settings,
        limits: RobotLimits,
        _goal: Option<[f64; 2]>,
        _local: Option<Box<dyn Planner>>,
        seed: u64,
    ) -> Result<Self, PlanningError> {
        Ok(RandomWalk::new(limits, settings.random_walk, seed))
    }
}

impl Planner for RandomWalk {
    fn kind(&self) -> PlannerKind {
        PlannerKind::RandomWalk
    }

    fn set_settings(&mut self, settings: &crate::Settings) -> Result<(), String> {
        self.config = settings.random_walk;
        Ok(())
    }

    fn step(&mut self, input: &PlannerInput) -> Command {
        if !usable(input) {
            self.waypoint = None;
            return Command::STOP;
        }
        let p = input.pose;
        if input.tick < self.started_tick {
            self.started_tick = input.tick; // the clock went back (a restarted world): restart the timer
        }
        let elapsed = (input.tick - self.started_tick) as f64 * input.dt;
        let due = match self.waypoint {
            None => true,
            Some(wp) => {
                (wp[0] - p.x).hypot(wp[1] - p.y) < self.config.reach_tolerance
                    || elapsed >= self.config.timeout
            }
        };
        if due {
            self.pick(input);
        }
        let (v, omega) = match self.waypoint {
            Some(wp) => self.control(p, wp),
            None => (0.0, 0.0),
        };
        Command {
            v,
            omega,
            mode: MODE_EXPLORE,
        }
    }

    fn replan(&mut self) {
        self.waypoint = None;
    }

    fn obstacle_hint(&mut self, at: [f64; 2], heading: f64) {
        if at[0].is_finite() && at[1].is_finite() && heading.is_finite() {
            self.hints[self.next_hint] = (at, heading, self.config.hint_draws);
            self.next_hint = (self.next_hint + 1) % HINTS;
        }
    }

    fn target(&self) -> Option<[f64; 2]> {
        self.waypoint
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Limited;
    use crate::obstacles::test_support::{grid_free, scan_wall_ahead};
    use mole_types::CELL_OCCUPIED;
    use proptest::prelude::*;

    fn limits() -> RobotLimits {
        RobotLimits::default()
    }

    /// Step `tick` at `pose`, the robot standing (nothing sent yet).
    fn input(tick: u64, pose: Pose2) -> PlannerInput<'static> {
        sent(tick, pose, Command::STOP)
    }

    /// Step `tick` at `pose` after `last_command` was sent.
    fn sent(tick: u64, pose: Pose2, last_command: Command) -> PlannerInput<'static> {
        PlannerInput {
            tick,
            dt: 0.01,
            pose,
            scan: None,
            tactile: None,
            grid: None,
            last_command,
        }
    }

    #[test]
    fn moments_of_the_1d_walk() {
        assert_eq!(mean_1d(100, 0.5), 0.0);
        assert!((mean_1d(100, 0.7) - 40.0).abs() < 1e-12);
        assert!((variance_1d(100, 0.7) - 84.0).abs() < 1e-9);
        assert_eq!(variance_1d(10, 1.0), 0.0);
    }

    #[test]
    fn sample_moments_match_the_theory_within_confidence_bounds() {
        let mut rng = ChaCha8Rng::seed_from_u64(42);
        let walks = 4000usize;
        for (k, p) in [(50u64, 0.5), (100, 0.7), (40, 0.2)] {
            let (mut sum, mut sum2, mut sum4) = (0.0, 0.0, 0.0);
            let mu = mean_1d(k, p);
            let var = variance_1d(k, p);
            let mut xs = [0.0f64; 4000];
            for x in xs.iter_mut() {
                *x = walk_1d(&mut rng, 0, k, p)
                    .map(|x| x as f64)
                    .unwrap_or(f64::NAN);
                sum += *x;
            }
            let n = walks as f64;
            let mean = sum / n;
            for x in xs {
                let c = x - mean;
                sum2 += c * c;
                sum4 += c * c * c * c;
            }
            let s2 = sum2 / (n - 1.0);
            // Mean: standard error σ/√n; accept within 4 standard errors.
            assert!(
                (mean - mu).abs() < 4.0 * (var / n).sqrt(),
                "k={k} p={p}: mean {mean} vs {mu}"
            );
            // Variance: standard error of s² ≈ √((μ₄ − σ⁴)/n) with the sample fourth moment.
            let m4 = sum4 / n;
            let se = ((m4 - s2 * s2) / n).sqrt();
            assert!(
                (s2 - var).abs() < 4.0 * se,
                "k={k} p={p}: var {s2} vs {var} (se {se})"
            );
        }
        assert!(walk_1d(&mut rng, 0, 10, 1.5).is_err());
        assert!(walk_1d(&mut rng, 0, 10, f64::NAN).is_err());
        assert_eq!(walk_1d(&mut rng, 3, 10, 1.0), Ok(13));
    }

    #[test]
    fn diagonal_strides() {
        assert_eq!(DiagonalStride::Source.cells(1), 0);
        assert_eq!(DiagonalStride::Rounded.cells(1), 1);
        assert_eq!(DiagonalStride::Source.cells(3), 2);
        assert_eq!(DiagonalStride::Rounded.cells(3), 2);
        assert_eq!(DiagonalStride::Source.cells(10), 7);
        assert_eq!(DiagonalStride::Rounded.cells(10), 7);
        assert_eq!(DiagonalStride::Source.cells(5), 3);
        assert_eq!(DiagonalStride::Rounded.cells(5), 4);
    }

    #[test]
    fn source_diagonal_stride_stands_still_the_rounded_one_never_does() {
        let walk = Walk2d {
            m: 50,
            n: 40,
            r: 1,
            steps: 4000,
            diagonal: DiagonalStride::Source,
            start: (25, 20),
        };
        let seed = walk_2d(&mut ChaCha8Rng::seed_from_u64(1), &walk);
        let seed = seed.unwrap_or_else(|e| panic!("{e}"));
        assert!(seed.diagonal_moves > 1500, "{seed:?}");
        assert_eq!(
            seed.stood_still, seed.diagonal_moves,
            "every diagonal move stands still"
        );
        let rounded = Walk2d {
            diagonal: DiagonalStride::Rounded,
            ..walk
        };
        let rounded =
            walk_2d(&mut ChaCha8Rng::seed_from_u64(1), &rounded).unwrap_or_else(|e| panic!("{e}"));
        assert!(rounded.diagonal_moves > 1500);
        assert_eq!(rounded.stood_still, 0);
        assert!(
            rounded.coverage_percent > seed.coverage_percent,
            "{rounded:?} vs {seed:?}"
        );
    }

    #[test]
    fn coverage_rises_with_steps() {
        let mut last = 0.0;
        for steps in [0u64, 100, 1000, 5000, 20000] {
            let walk = Walk2d {
                m: 60,
                n: 60,
                r: 3,
                steps,
                diagonal: DiagonalStride::Rounded,
                start: (0, 0),
            };
            let rep =
                walk_2d(&mut ChaCha8Rng::seed_from_u64(9), &walk).unwrap_or_else(|e| panic!("{e}"));
            assert!(
                rep.coverage_percent >= last,
                "{steps}: {} < {last}",
                rep.coverage_percent
            );
            assert!(rep.coverage_percent <= 100.0);
            if steps > 0 {
                assert!(
                    rep.coverage_percent > last,
                    "{steps}: coverage did not rise"
                );
            }
            last = rep.coverage_percent;
        }
        assert!(last > 50.0, "{last}");
    }

    #[test]
    fn walk_2d_refuses_bad_parameters() {
        let ok = Walk2d {
            m: 5,
            n: 5,
            r: 1,
            steps: 10,
            diagonal: DiagonalStride::Source,
            start: (0, 0),
        };
        let mut rng = ChaCha8Rng::seed_from_u64(0);
        assert!(walk_2d(&mut rng, &Walk2d { m: 0, ..ok }).is_err());
        assert!(walk_2d(&mut rng, &Walk2d { r: 0, ..ok }).is_err());
        assert!(
            walk_2d(
                &mut rng,
                &Walk2d {
                    start: (5, 0),
                    ..ok
                }
            )
            .is_err()
        );
        assert!(
            walk_2d(
                &mut rng,
                &Walk2d {
                    m: usize::MAX,
                    n: 2,
                    ..ok
                }
            )
            .is_err()
        );
        // A 1×1 grid: nowhere to go.
        let one = walk_2d(&mut rng, &Walk2d { m: 1, n: 1, ..ok }).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!((one.stood_still, one.coverage_percent), (10, 100.0));
    }

    #[test]
    fn planner_turns_then_drives_to_the_waypoint_and_draws_the_next() {
        let mut rw = Limited::new(
            RandomWalk::new(limits(), RandomWalkConfig::default(), 3),
            limits(),
        );
        let mut pose = Pose2::new(2.0, 2.0, 0.0);
        let dt = 0.01;
        let mut reached = 0;
        let mut last_dir = None;
        let mut cmd = Command::STOP;
        for tick in 0..6000 {
            cmd = rw.step(&sent(tick, pose, cmd));
            assert_eq!(cmd.mode, MODE_EXPLORE);
            if let (Some(wp), Some(d)) = (rw.target(), rw.inner().direction()) {
                if last_dir.is_some_and(|(_, w): (usize, [f64; 2])| w != wp) {
                    reached += 1;
                }
                last_dir = Some((d, wp));
            }
            pose.x += cmd.v * pose.theta.cos() * dt;
            pose.y += cmd.v * pose.theta.sin() * dt;
            pose.theta = wrap_angle(pose.theta + cmd.omega * dt);
        }
        // 60 s at ≤ 0.4 m/s with 0.5 m strides and turns: several waypoints, none by timeout.
        let (picks, fallbacks) = rw.inner().picks();
        assert!(reached >= 10, "reached {reached}");
        assert_eq!(picks, reached as u64 + 1);
        assert_eq!(fallbacks, 0);
    }

    #[test]
    fn timeout_draws_a_new_waypoint() {
        let cfg = RandomWalkConfig {
            timeout: 1.0,
            ..Default::default()
        };
        let mut rw = RandomWalk::new(limits(), cfg, 3);
        let pose = Pose2::new(2.0, 2.0, 0.0);
        // The robot never moves (pinned): a new draw every 100 steps of 10 ms.
        for tick in 0..1001 {
            rw.step(&input(tick, pose));
        }
        assert_eq!(rw.picks().0, 11);
    }

    #[test]
    fn adaptive_walk_never_picks_a_direction_into_occupied_cells() {
        // 4 m × 4 m at 0.1 m; a wall of occupied cells at x ∈ [2.5, 2.6) and one at y ∈ [1.5, 1.6).
        let mut g = grid_free(40, 40, 0.1);
        for i in 0..40 {
            g.cells[i * 40 + 25] = CELL_OCCUPIED;
            g.cells[15 * 40 + i] = CELL_OCCUPIED;
        }
        let pose = Pose2::new(2.2, 1.8, 0.3);
        let mut rw = RandomWalk::new(limits(), RandomWalkConfig::default(), 11);
        let mut seen = [false; 8];
        for round in 0..400u64 {
            rw.replan();
            let inp = PlannerInput {
                grid: Some(&g),
                ..input(round, pose)
            };
            rw.step(&inp);
            let d = rw.direction().unwrap_or(usize::MAX);
            seen[d.min(7)] = true;
            let wp = rw.target().unwrap_or([f64::NAN; 2]);
            assert!(
                segment_free(&g, [pose.x, pose.y], wp),
                "direction {d} into an occupied cell"
            );
            // E (0), NE (1), SE (7) cross x = 2.5; S (6), SW (5) cross y = 1.6 within a stride.
            assert!(![0, 1, 5, 6, 7].contains(&d), "direction {d}");
        }
        // The free ones (N, NW, W) are all drawn.
        assert!(seen[2] && seen[3] && seen[4], "{seen:?}");
        assert_eq!(rw.picks().1, 0);
    }

    #[test]
    fn scan_aware_walk_avoids_the_wall_ahead_and_falls_back_when_boxed_in() {
        let scan = scan_wall_ahead(180, 0.5, 4.0);
        let pose = Pose2::new(1.0, 1.0, 0.0);
        let mut rw = RandomWalk::new(limits(), RandomWalkConfig::default(), 5);
        for round in 0..200u64 {
            rw.replan();
            rw.step(&PlannerInput {
                scan: Some(&scan),
                ..input(round, pose)
            });
            let d = rw.direction().unwrap_or(0);
            assert!(![0, 1, 7].contains(&d), "drove into the wall: {d}");
        }
        // Every direction blocked in the grid: the walk still draws one.
        let mut g = grid_free(40, 40, 0.1);
        g.cells[..1600].fill(CELL_OCCUPIED);
        rw.replan();
        let cmd = rw.step(&PlannerInput {
            grid: Some(&g),
            ..input(500, pose)
        });
        assert!(rw.target().is_some() && cmd.v.is_finite());
        assert_eq!(rw.picks().1, 1);
    }

    #[test]
    fn same_seed_same_walk() {
        let run = |seed| {
            let mut rw = RandomWalk::new(limits(), RandomWalkConfig::default(), seed);
            (0..50u64)
                .map(|t| {
                    rw.replan();
                    rw.step(&input(t, Pose2::new(1.0, 1.0, 0.0)));
                    rw.direction().unwrap_or(9)
                })
                .collect::<Vec<_>>()
        };
        assert_eq!(run(7), run(7));
        assert_ne!(run(7), run(8));
    }

    #[test]
    fn non_finite_pose_brakes_to_a_stop() {
        let mut rw = Limited::new(
            RandomWalk::new(limits(), RandomWalkConfig::default(), 1),
            limits(),
        );
        let mut pose = Pose2::new(1.0, 1.0, 0.0);
        let mut cmd = Command::STOP;
        for tick in 0..300 {
            cmd = rw.step(&sent(tick, pose, cmd));
            pose.theta = wrap_angle(pose.theta + cmd.omega * 0.01);
            pose.x += cmd.v * pose.theta.cos() * 0.01;
        }
        assert!(cmd.v > 0.1, "{cmd:?}");
        let bad = Pose2::new(f64::NAN, 1.0, 0.0);
        let mut prev = cmd;
        for tick in 300..400 {
            let c = rw.step(&sent(tick, bad, prev));
            assert!(c.v.is_finite() && c.omega.is_finite() && c.mode == mole_types::MODE_IDLE);
            assert!(c.v.abs() <= prev.v.abs() + 1e-12 && (c.v - prev.v).abs() <= 0.02 + 1e-12);
            prev = c;
        }
        assert_eq!((prev.v, prev.omega), (0.0, 0.0));
        // No time base: stop at once.
        let c = rw.step(&PlannerInput {
            dt: f64::NAN,
            ..sent(400, pose, cmd)
        });
        assert_eq!(c, Command::STOP);
    }

    proptest! {
        #[test]
        fn commands_respect_the_limits(
            poses in proptest::collection::vec((-1.0e3f64..1.0e3, -1.0e3f64..1.0e3, -10.0f64..10.0, 0u8..20), 1..60),
            seed in 0u64..1000,
        ) {
            let l = limits();
            let mut rw = Limited::new(RandomWalk::new(l, RandomWalkConfig::default(), seed), l);
            let mut prev = Command::STOP;
            for (t, (x, y, th, flag)) in poses.into_iter().enumerate() {
                let x = if flag == 0 { f64::NAN } else if flag == 1 { f64::INFINITY } else { x };
                let c = rw.step(&sent(t as u64, Pose2::new(x, y, th), prev));
                prop_assert!(c.v.is_finite() && c.omega.is_finite());
                prop_assert!(c.v.abs() <= l.max_speed && c.omega.abs() <= l.max_omega);
                prop_assert!((c.v - prev.v).abs() <= l.max_accel * 0.01 + 1e-12);
                prop_assert!((c.omega - prev.omega).abs() <= l.max_alpha * 0.01 + 1e-12);
                prev = c;
            }
        }
    }
}
