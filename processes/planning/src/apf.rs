//! Artificial potential field (algorithms §1), in the source's form and corrected (docs/errata.md).
//!
//! Source form ([`ApfForm::Source`]): φ_goal = c·|p − p_goal| (§1.2), the boundary potential
//! φ_b = 1/(δ + Σ(g_i + |g_i|)) (§1.3), the square-obstacle potential φ_k = φ_max/(1 + h) with
//! the '+1' of h as written, φ_obs = max_k φ_k, F_net = F_goal − (∇φ_b + ∇φ_obs) (§1.4) and the
//! heading θ = atan(F_y/F_x).
//!
//! Corrected form ([`ApfForm::Corrected`], the default): the conic attraction guarded at the goal,
//! Khatib's FIRAS barrier ("Real-time obstacle avoidance for manipulators and mobile robots",
//! 1986) per arena wall and for the nearest obstacle (occupied grid cell, a square of side
//! = resolution, via a [`DistanceField`], or the nearest scan hit) within the influence distance
//! ρ0, and θ = atan2(F_y, F_x). Local minima: a stall (progress toward the goal below ε over a
//! window) or an oscillation (heading-rate sign flips) is reported as `MODE_STALLED`, then a
//! random-walk burst (`MODE_ESCAPE`) leaves it, and the minimum gets a repulsive mark so the
//! field does not pull the robot back into it.

use crate::distance_field::DistanceField;
use crate::random_walk::{RandomWalk, RandomWalkConfig};
use crate::{Command, Planner, PlannerInput, RobotLimits, usable};
use mole_types::Setting;
use mole_types::{
    MODE_ARRIVED, MODE_ESCAPE, MODE_GOAL, MODE_STALLED, PlanStatus, PlannerKind, STATUS_HAS_GOAL,
    Square, wrap_angle,
};
use serde::{Deserialize, Serialize};

/// Which APF formulas to use.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, Setting)]
#[serde(rename_all = "kebab-case")]
pub enum ApfForm {
    /// Algorithms §1 as written (atan, '+1' in h, 1/(δ+Σ(g+|g|)) boundary).
    Source,
    /// docs/errata.md: atan2, guarded attraction, FIRAS barriers per wall and obstacle.
    #[default]
    Corrected,
}

/// Algorithms §1.2: φ_goal(x, y) = c·√((x − x_goal)² + (y − y_goal)²).
pub fn phi_goal(p: [f64; 2], goal: [f64; 2], c: f64) -> f64 {
    c * (p[0] - goal[0]).hypot(p[1] - goal[1])
}

/// Algorithms §1.2: F_goal = −c/|p − p_goal| · (p − p_goal), as written: NaN at the goal.
pub fn f_goal_seed(p: [f64; 2], goal: [f64; 2], c: f64) -> [f64; 2] {
    let (dx, dy) = (p[0] - goal[0], p[1] - goal[1]);
    let d = dx.hypot(dy);
    [-c / d * dx, -c / d * dy]
}

/// Algorithms §1.2's F_goal guarded at the goal: 0 within `eps` of it (the conic force is undefined
/// there, docs/errata.md).
pub fn f_goal(p: [f64; 2], goal: [f64; 2], c: f64, eps: f64) -> [f64; 2] {
    let (dx, dy) = (p[0] - goal[0], p[1] - goal[1]);
    let d = dx.hypot(dy);
    if d.is_nan() || d <= eps.max(1e-12) {
        return [0.0, 0.0];
    }
    [-c / d * dx, -c / d * dy]
}

/// Algorithms §1.3: the boundary lines g_i of the arena `[x0, x1] × [y0, y1]`, each ≤ 0 inside
/// (the source leaves the sign open; this one makes g + |g| vanish inside).
pub fn boundary_g(p: [f64; 2], arena: [f64; 4]) -> [f64; 4] {
    [
        arena[0] - p[0],
        p[0] - arena[2],
        arena[1] - p[1],
        p[1] - arena[3],
    ]
}

/// Algorithms §1.3: φ_b = 1/(δ + Σ_i (g_i + |g_i|)): the constant 1/δ everywhere inside the arena.
pub fn phi_b_seed(p: [f64; 2], arena: [f64; 4], delta: f64) -> f64 {
    let s: f64 = boundary_g(p, arena).iter().map(|g| g + g.abs()).sum();
    1.0 / (delta + s)
}

/// Algorithms §1.3's h(x, y) for the square `k`, with the '+1' as written (an integer-cell
/// convention that shrinks the square by one unit); 0 anywhere inside the square.
pub fn h_seed(p: [f64; 2], k: &Square) -> f64 {
    let (x, y) = (p[0], p[1]);
    let l2 = k.side / 2.0;
    let t = |v: f64| v + v.abs();
    t(k.cx - l2 - x) + t(k.cy - l2 - y) + t(x + 1.0 - k.cx - l2) + t(y + 1.0 - k.cy - l2)
}

/// Algorithms §1.3: φ_k = φ_max/(1 + h(x, y)).
pub fn phi_k_seed(p: [f64; 2], k: &Square, phi_max: f64) -> f64 {
    phi_max / (1.0 + h_seed(p, k))
}

/// Algorithms §1.3: φ_obs = max_k φ_k (0 without obstacles).
pub fn phi_obs_seed(p: [f64; 2], squares: &[Square], phi_max: f64) -> f64 {
    squares
        .iter()
        .map(|k| phi_k_seed(p, k, phi_max))
        .fold(0.0, f64::max)
}

/// Central-difference gradient of `f` at `p` with step `h`.
pub fn numerical_gradient(f: impl Fn([f64; 2]) -> f64, p: [f64; 2], h: f64) -> [f64; 2] {
    [
        (f([p[0] + h, p[1]]) - f([p[0] - h, p[1]])) / (2.0 * h),
        (f([p[0], p[1] + h]) - f([p[0], p[1] - h])) / (2.0 * h),
    ]
}

/// Algorithms §1.4: θ = tan⁻¹(F_y/F_x) as written: only (−π/2, π/2], the quadrant is lost.
pub fn heading_seed(f: [f64; 2]) -> f64 {
    (f[1] / f[0]).atan()
}

/// Algorithms §1.4's heading with atan2 (docs/errata.md).
pub fn heading(f: [f64; 2]) -> f64 {
    f[1].atan2(f[0])
}

/// Khatib's FIRAS magnitude at clearance ρ: η(1/ρ − 1/ρ0)/ρ² for ρ < ρ0, else 0 (ρ floored at
/// 1 mm so touching gives a large finite push).
pub fn firas(rho: f64, rho0: f64, eta: f64) -> f64 {
    if rho.is_nan() || rho >= rho0 {
        return 0.0;
    }
    let r = rho.max(1e-3);
    eta * (1.0 / r - 1.0 / rho0) / (r * r)
}

/// Corrected boundary force: a FIRAS barrier per wall of the arena, on the clearance between
/// the robot disk (radius `radius`) and the wall.
pub fn f_walls(p: [f64; 2], arena: [f64; 4], radius: f64, rho0: f64, eta: f64) -> [f64; 2] {
    let left = firas(p[0] - arena[0] - radius, rho0, eta);
    let right = firas(arena[2] - p[0] - radius, rho0, eta);
    let bottom = firas(p[1] - arena[1] - radius, rho0, eta);
    let top = firas(arena[3] - p[1] - radius, rho0, eta);
    [left - right, bottom - top]
}

/// Settings of the APF planner.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, Setting)]
#[serde(default, deny_unknown_fields)]
pub struct ApfConfig {
    /// Formulas.
    pub form: ApfForm,
    /// Attraction gain c.
    #[setting(min = 0.0)]
    pub c: f64,
    /// Repulsion gain η (FIRAS).
    #[setting(min = 0.0)]
    pub eta: f64,
    /// Influence distance ρ0 (m) of the barriers.
    #[setting(above = 0.0)]
    pub rho0: f64,
    /// φ_max of the source's obstacle potential.
    #[setting(above = 0.0)]
    pub phi_max: f64,
    /// δ of the source's boundary potential.
    #[setting(above = 0.0)]
    pub delta: f64,
    /// The goal counts as reached within this distance (m).
    #[setting(above = 0.0)]
    pub goal_tolerance: f64,
    /// Heading gain (1/s): ω = k·(θ_F − θ).
    #[setting(above = 0.0)]
    pub k_heading: f64,
    /// Stall: the best distance to the goal improved by less than this (m)...
    #[setting(min = 0.0)]
    pub stall_epsilon: f64,
    /// ...over this long (s).
    #[setting(above = 0.0)]
    pub stall_window: f64,
    /// Oscillation: this many sign flips of the heading error within `stall_window`.
    pub oscillation_flips: u32,
    /// Length of the random-walk escape burst (s).
    #[setting(min = 0.0)]
    pub escape_time: f64,
    /// Height of the repulsive mark left at a stall point (FIRAS gain of the mark).
    #[setting(min = 0.0)]
    pub mark_eta: f64,
    /// Influence radius (m) of a stall mark.
    #[setting(min = 0.0)]
    pub mark_radius: f64,
}

impl Default for ApfConfig {
    fn default() -> Self {
        Self {
            form: ApfForm::Corrected,
            c: 1.0,
            eta: 0.02,
            rho0: 0.5,
            phi_max: 1.0,
            delta: 1e-3,
            goal_tolerance: 0.25,
            k_heading: 3.0,
            stall_epsilon: 0.15,
            stall_window: 4.0,
            oscillation_flips: 12,
            escape_time: 6.0,
            mark_eta: 0.5,
            mark_radius: 1.5,
        }
    }
}

/// Stall marks kept (oldest replaced).
const MARKS: usize = 16;
/// Heading flips remembered for the oscillation test.
const FLIPS: usize = 32;

/// What the APF planner is doing.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ApfPhase {
    /// Following the field.
    Seeking,
    /// A local minimum was detected at tick `since`; braking for one report period.
    Stalled { since: u64 },
    /// Random-walk escape burst until tick `until`.
    Escape { until: u64 },
    /// The goal is reached.
    Reached,
}

/// The APF planner (algorithms §1) with stall/oscillation detection and random-walk escape.
#[derive(Debug, Clone)]
pub struct Apf {
    limits: RobotLimits,
    config: ApfConfig,
    goal: [f64; 2],
    field: DistanceField,
    walk: RandomWalk,
    phase: ApfPhase,
    best: f64,
    best_tick: u64,
    last_error_sign: f64,
    flips: [u64; FLIPS],
    n_flips: usize,
    marks: [[f64; 2]; MARKS],
    n_marks: usize,
    stalls: u32,
    oscillations: u32,
    replan_asked: bool,
}

impl Apf {
    /// An APF planner toward `goal` (world, m).
    pub fn new(limits: RobotLimits, config: ApfConfig, goal: [f64; 2], seed: u64) -> Self {
        Self {
            limits: limits.sanitized(),
            config,
            goal,
            field: DistanceField::with_capacity(mole_types::MAX_GRID_CELLS),
            walk: RandomWalk::new(limits, RandomWalkConfig::default(), seed ^ 0xa9f),
            phase: ApfPhase::Seeking,
            best: f64::INFINITY,
            best_tick: 0,
            last_error_sign: 0.0,
            flips: [0; FLIPS],
            n_flips: 0,
            marks: [[0.0; 2]; MARKS],
            n_marks: 0,
            stalls: 0,
            oscillations: 0,
            replan_asked: false,
        }
    }

    /// The phase.
    pub fn phase(&self) -> ApfPhase {
        self.phase
    }

    /// Stalls (progress below ε over the window) detected so far.
    pub fn stalls(&self) -> u32 {
        self.stalls
    }

    /// Oscillations (heading sign flips) detected so far.
    pub fn oscillations(&self) -> u32 {
        self.oscillations
    }

    /// The distance field the planner keeps of the grid's occupied cells.
    pub fn field(&self) -> &DistanceField {
        &self.field
    }

    /// F_net at `p` (algorithms §1.4) in the configured form, with the nearest scan hit `scan_hit`
    /// (world point) as an extra obstacle. Allocation-free; O(1) with the distance field.
    pub fn force(&self, p: [f64; 2], scan_hit: Option<[f64; 2]>) -> [f64; 2] {
        let cfg = &self.config;
        let r = self.limits.radius;
        match cfg.form {
            ApfForm::Source => {
                let fg = f_goal_seed(p, self.goal, cfg.c);
                let mut grad = [0.0, 0.0];
                if let Some(arena) = self.field.extent() {
                    let gb = numerical_gradient(|q| phi_b_seed(q, arena, cfg.delta), p, 1e-4);
                    grad = [grad[0] + gb[0], grad[1] + gb[1]];
                }
                // φ_obs = max_k φ_k: the nearest cell's square dominates.
                let c = self.field.clearance(p[0], p[1]);
                if c.distance.is_finite() {
                    let res = self.field.resolution();
                    let centre = [
                        p[0] - c.away[0] * (c.distance + res / 2.0),
                        p[1] - c.away[1] * (c.distance + res / 2.0),
                    ];
                    let k = Square::new(centre[0], centre[1], res);
                    let go = numerical_gradient(|q| phi_k_seed(q, &k, cfg.phi_max), p, 1e-4);
                    grad = [grad[0] + go[0], grad[1] + go[1]];
                }
                [fg[0] - grad[0], fg[1] - grad[1]]
            }
            ApfForm::Corrected => {
                let mut f = f_goal(p, self.goal, cfg.c, 1e-9);
                if let Some(arena) = self.field.extent() {
                    let fw = f_walls(p, arena, r, cfg.rho0, cfg.eta);
                    f = [f[0] + fw[0], f[1] + fw[1]];
                }
                let c = self.field.clearance(p[0], p[1]);
                let (mut rho, mut away) = (c.distance - r, c.away);
                if let Some(h) = scan_hit {
                    let (dx, dy) = (p[0] - h[0], p[1] - h[1]);
                    let d = dx.hypot(dy);
                    if d > 1e-9 && d - r < rho {
                        rho = d - r;
                        away = [dx / d, dy / d];
                    }
                }
                let m = firas(rho, cfg.rho0, cfg.eta);
                f = [f[0] + m * away[0], f[1] + m * away[1]];
                for mark in &self.marks[..self.n_marks] {
                    let (dx, dy) = (p[0] - mark[0], p[1] - mark[1]);
                    let d = dx.hypot(dy);
                    if d > 1e-6 && d < cfg.mark_radius {
                        let k = cfg.mark_eta * (1.0 - d / cfg.mark_radius);
                        f = [f[0] + k * dx / d, f[1] + k * dy / d];
                    }
                }
                f
            }
        }
    }

    /// The heading of F_net in the configured form (algorithms §1.4).
    pub fn heading_of(&self, f: [f64; 2]) -> f64 {
        match self.config.form {
            ApfForm::Source => heading_seed(f),
            ApfForm::Corrected => heading(f),
        }
    }

    fn nearest_scan_hit(input: &PlannerInput) -> Option<[f64; 2]> {
        let scan = input.scan?;
        let range_max = scan.range_max as f64;
        let mut best: Option<(f64, f64)> = None;
        for (i, &r) in scan.ranges().iter().enumerate() {
            let r = r as f64;
            if r.is_finite() && r >= 0.0 && r < range_max && best.is_none_or(|b| r < b.0) {
                best = Some((r, crate::obstacles::beam_angle(scan, i)));
            }
        }
        let (r, a) = best?;
        let a = input.pose.theta + a;
        a.is_finite()
            .then(|| [input.pose.x + r * a.cos(), input.pose.y + r * a.sin()])
    }

    fn steps(&self, seconds: f64, dt: f64) -> u64 {
        (seconds / dt).ceil().max(1.0) as u64
    }

    fn reset_progress(&mut self, tick: u64) {
        self.best = f64::INFINITY;
        self.best_tick = tick;
        self.n_flips = 0;
    }
}

impl crate::Registered for Apf {
    fn build(
        settings: &crate::Settings,
        limits: RobotLimits,
        goal: Option<[f64; 2]>,
        _local: Option<Box<dyn Planner>>,
        seed: u64,
    ) -> Result<Self, crate::PlanningError> {
        let goal = goal.ok_or(crate::PlanningError::MissingGoal {
            kind: PlannerKind::Apf,
        })?;
        Ok(Apf::new(limits, settings.apf, goal, seed))
    }
}

impl Planner for Apf {
    fn kind(&self) -> PlannerKind {
        PlannerKind::Apf
    }

    fn set_settings(&mut self, settings: &crate::Settings) -> Result<(), String> {
        self.config = settings.apf;
        Ok(())
    }

    fn step(&mut self, input: &PlannerInput) -> Command {
        if !usable(input) {
            return Command::STOP;
        }
        if let Some(grid) = input.grid {
            self.field.update(grid);
        }
        let (tick, dt) = (input.tick, input.dt);
        let p = [input.pose.x, input.pose.y];
        let d_goal = (p[0] - self.goal[0]).hypot(p[1] - self.goal[1]);
        if crate::arrived(d_goal, self.config.goal_tolerance) {
            self.phase = ApfPhase::Reached;
        }
        if self.replan_asked {
            // After a bounce-back: a fresh progress record.
            self.replan_asked = false;
            self.reset_progress(tick);
        }
        // Stall: no progress of ε over the window.
        if self.phase == ApfPhase::Seeking {
            if d_goal < self.best - self.config.stall_epsilon || !self.best.is_finite() {
                self.best = d_goal;
                self.best_tick = tick;
            }
            let window = self.steps(self.config.stall_window, dt);
            let stalled = tick.saturating_sub(self.best_tick) > window;
            let oscillating = self.n_flips >= self.config.oscillation_flips as usize
                && self.n_flips <= FLIPS
                && {
                    let first =
                        self.flips[(self.n_flips - self.config.oscillation_flips as usize) % FLIPS];
                    tick.saturating_sub(first) <= window
                };
            if stalled || oscillating {
                self.stalls += stalled as u32;
                self.oscillations += oscillating as u32;
                self.marks[self.n_marks.min(MARKS - 1)] = p;
                if self.n_marks < MARKS {
                    self.n_marks += 1;
                } else {
                    self.marks.rotate_left(1);
                }
                self.phase = ApfPhase::Stalled { since: tick };
            }
        }
        match self.phase {
            ApfPhase::Reached => Command {
                v: 0.0,
                omega: 0.0,
                mode: MODE_ARRIVED,
            },
            ApfPhase::Stalled { since } => {
                if tick.saturating_sub(since) >= self.steps(0.2, dt) {
                    self.walk.replan();
                    self.phase = ApfPhase::Escape {
                        until: tick + self.steps(self.config.escape_time, dt),
                    };
                }
                Command {
                    v: 0.0,
                    omega: 0.0,
                    mode: MODE_STALLED,
                }
            }
            ApfPhase::Escape { until } => {
                if tick >= until {
                    self.phase = ApfPhase::Seeking;
                    self.reset_progress(tick);
                }
                let c = self.walk.step(input);
                Command {
                    mode: MODE_ESCAPE,
                    ..c
                }
            }
            ApfPhase::Seeking => {
                let f = self.force(p, Self::nearest_scan_hit(input));
                let theta = self.heading_of(f);
                let theta = if theta.is_finite() {
                    theta
                } else {
                    input.pose.theta
                };
                let e = wrap_angle(theta - input.pose.theta);
                let sign = if e.abs() < 0.05 { 0.0 } else { e.signum() };
                if sign != 0.0 && self.last_error_sign != 0.0 && sign != self.last_error_sign {
                    self.flips[self.n_flips % FLIPS] = tick;
                    self.n_flips += 1;
                    if self.n_flips >= 2 * FLIPS {
                        self.n_flips -= FLIPS;
                    }
                }
                if sign != 0.0 {
                    self.last_error_sign = sign;
                }
                let slow = (d_goal / 0.5).min(1.0);
                Command {
                    v: self.limits.max_speed * e.cos().max(0.0).powi(2) * slow,
                    omega: self.config.k_heading * e,
                    mode: MODE_GOAL,
                }
            }
        }
    }

    fn replan(&mut self) {
        self.replan_asked = true;
        self.walk.replan();
    }

    fn obstacle_hint(&mut self, at: [f64; 2], heading: f64) {
        self.walk.obstacle_hint(at, heading);
    }

    fn target(&self) -> Option<[f64; 2]> {
        Some(self.goal)
    }

    /// Changes the goal (and the tolerance, if given) and forgets the progress record.
    fn set_goal(&mut self, goal: [f64; 2], tolerance: Option<f64>) -> bool {
        if let Some(t) = tolerance.filter(|t| t.is_finite() && *t > 0.0) {
            self.config.goal_tolerance = t;
        }
        if goal != self.goal {
            self.goal = goal;
            self.best = f64::INFINITY;
            self.n_flips = 0;
            if self.phase == ApfPhase::Reached {
                self.phase = ApfPhase::Seeking;
            }
        }
        true
    }

    fn write_status(&self, status: &mut PlanStatus) {
        status.flags = STATUS_HAS_GOAL;
        (status.goal_x, status.goal_y) = (self.goal[0], self.goal[1]);
        (status.frontier_x, status.frontier_y) = (0.0, 0.0);
        status.bounces = 0;
        status.n_path = 0;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use core::f64::consts::PI;

    #[test]
    fn source_heading_loses_the_quadrant_atan2_does_not() {
        // Goal behind and to the left: F points into the third quadrant.
        let f = f_goal([1.0, 1.0], [0.0, 0.0], 1.0, 1e-9);
        assert!((heading(f) + 3.0 * PI / 4.0).abs() < 1e-12);
        assert!(
            (heading_seed(f) - PI / 4.0).abs() < 1e-12,
            "atan: the opposite way"
        );
    }

    #[test]
    fn attraction_is_unit_conic_and_guarded_at_the_goal() {
        let f = f_goal([3.0, 4.0], [0.0, 0.0], 2.0, 1e-9);
        assert!((f[0] + 1.2).abs() < 1e-12 && (f[1] + 1.6).abs() < 1e-12);
        assert!(f_goal_seed([1.0, 1.0], [1.0, 1.0], 1.0)[0].is_nan());
        assert_eq!(f_goal([1.0, 1.0], [1.0, 1.0], 1.0, 1e-9), [0.0, 0.0]);
        assert!((phi_goal([3.0, 4.0], [0.0, 0.0], 2.0) - 10.0).abs() < 1e-12);
    }

    #[test]
    fn source_boundary_gradient_is_zero_inside_firas_pushes_off_the_wall() {
        let arena = [0.0, 0.0, 10.0, 10.0];
        // 5 cm from the left wall: the source's potential is flat there.
        let p = [0.25, 5.0];
        let g = numerical_gradient(|q| phi_b_seed(q, arena, 1e-3), p, 1e-4);
        assert_eq!(g, [0.0, 0.0]);
        assert!((phi_b_seed(p, arena, 1e-3) - 1000.0).abs() < 1e-9);
        let f = f_walls(p, arena, 0.2, 0.5, 0.02);
        assert!(f[0] > 1.0 && f[1] == 0.0, "{f:?}");
        // Out of every wall's reach: no force.
        assert_eq!(f_walls([5.0, 5.0], arena, 0.2, 0.5, 0.02), [0.0, 0.0]);
    }

    #[test]
    fn source_h_is_zero_inside_the_square_and_its_plus_one_shrinks_it() {
        let k = Square::new(5.0, 5.0, 2.0); // [4, 6]²
        assert_eq!(h_seed([5.0, 5.0], &k), 0.0);
        assert_eq!(h_seed([4.5, 4.2], &k), 0.0);
        assert_eq!(
            phi_k_seed([5.0, 5.0], &k, 3.0),
            3.0,
            "the maximum, flat inside"
        );
        let g = numerical_gradient(|q| phi_k_seed(q, &k, 1.0), [4.5, 4.5], 1e-4);
        assert_eq!(g, [0.0, 0.0], "no gradient to leave the obstacle");
        // The '+1': h is already 0 one unit to the left of the right edge...
        assert_eq!(h_seed([4.9, 5.0], &k), 0.0);
        // ...and grows from x + 1 = x_k + l/2, i.e. from x = 5, not from x = 6 (the edge).
        assert!((h_seed([5.5, 5.0], &k) - 1.0).abs() < 1e-12);
        assert!(phi_obs_seed([5.5, 5.0], &[k], 1.0) < 1.0);
    }

    #[test]
    fn corrected_force_pushes_away_from_an_obstacle_cell_within_rho0() {
        let limits = RobotLimits::default();
        let mut apf = Apf::new(limits, ApfConfig::default(), [9.0, 5.05], 1);
        let mut mask = vec![0u8; 100 * 100];
        mask[50 * 100 + 50] = 1; // cell [5.0, 5.1] × [5.0, 5.1]
        apf.field.build_from_mask(100, 100, 0.1, [0.0, 0.0], &mask);
        // 0.4 m left of the cell, goal to the right: the obstacle pushes back (−x).
        let near = apf.force([4.6, 5.05], None);
        let far = apf.force([2.0, 5.05], None);
        assert!(near[0] < far[0], "{near:?} {far:?}");
        assert!(
            (far[0] - 1.0).abs() < 1e-9,
            "only the attraction far away: {far:?}"
        );
        // The source form flattens inside the square; the corrected one's distance stays 0 and
        // finite, never NaN.
        let inside = apf.force([5.05, 5.05], None);
        assert!(inside[0].is_finite() && inside[1].is_finite());
    }
}
