//! Dynamic window approach (algorithms §4.2; Fox, Burgard & Thrun, "The dynamic window approach to
//! collision avoidance", IEEE RAM 1997) with Nav2-DWB-style critics.
//!
//! The window: speeds reachable within `window_dt` from the current (v, ω) under the
//! acceleration limits, intersected with the speed limits. Each sampled (v, ω) is rolled out over
//! T_H in steps of `sim_dt` (not the source's single chord of length T_H, which can tunnel through
//! an obstacle), checked against the distance field of the grid's occupied cells (O(1) per
//! point) and the latest scan's hits that the grid does not have yet, and scored by named critics
//! with weights ([`Critics`]). Rollouts step by `sim_dt` for the first second, 2·`sim_dt` after,
//! and longer (≤ 5·`sim_dt`) where the clearance allows (sphere tracing), and stop at the first
//! collision. With a grid, the `dwa` planner follows an A* path over the inflated grid
//! ([`GlobalPath`], optimistic through unexplored cells) with a carrot `lookahead` m ahead as
//! the goal and heading critics' target; a robot that stands still short of its aim near an
//! obstacle turns away from it and creeps clear (`MODE_ESCAPE`).
//! [`DwaCost::Source`] keeps the source's cost (J_goal = −d_goal after one step of T_H, which makes
//! the robot flee the goal); [`DwaCost::PythonRobotics`] is PythonRobotics'
//! dynamic_window_approach.py cost, for the parity test.

use crate::distance_field::DistanceField;
use crate::global_path::{GlobalPath, path_distance};
use crate::{Command, Planner, PlannerInput, RobotLimits, usable};
use mole_types::Setting;
use mole_types::{
    Grid, MODE_ARRIVED, MODE_ESCAPE, MODE_GOAL, PlanStatus, PlannerKind, STATUS_HAS_GOAL,
    wrap_angle,
};
use serde::{Deserialize, Serialize};

/// Rollouts step by `sim_dt` up to this time (s), by 2 × `sim_dt` beyond.
const FINE_HORIZON: f64 = 1.0;

/// How far (m) below the hard limit a rollout from outside it may still reach (so that the
/// robot can pass where the measured clearance sits on the limit); a rollout from inside it may
/// not approach at all, so the robot never creeps in step by step.
const SLACK: f64 = 0.01;

/// Standing still this long (s) near an obstacle while the aim is not reached starts a recovery.
const STUCK_TIME: f64 = 0.5;
/// The recovery lasts at most this long (s)...
const UNSTICK_TIME: f64 = 2.0;
/// ...or until the clearance exceeds the hard limit by this much (m).
const UNSTICK_CLEARANCE: f64 = 0.04;

/// Longest rollout step, in `sim_dt`s, where the clearance allows it.
const MAX_K: usize = 5;

/// sin/cos of ω·k·dt for k = 0..=MAX_K (the rollouts' heading increments).
fn rotations(w: f64, dt: f64) -> [(f64, f64); MAX_K + 1] {
    let mut out = [(0.0, 1.0); MAX_K + 1];
    for (k, o) in out.iter_mut().enumerate() {
        *o = (w * k as f64 * dt).sin_cos();
    }
    out
}

/// Path points the path critic looks at (the next few segments of the path).
const PATH_CRITIC_POINTS: usize = 6;

/// The cost a [`Dwa`] minimises.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize, Setting)]
#[serde(rename_all = "kebab-case")]
pub enum DwaCost {
    /// Weighted critics over a multi-step rollout (the default).
    #[default]
    Critics,
    /// Algorithms §4.2 as written: one step of T_H, J = −d_goal + Σ(1/d_i)² + |Δv| + |Δω|.
    Source,
    /// PythonRobotics: 0.15·|heading error to the goal| + 1.0·(v_max − v) + 1.0/min clearance,
    /// infinite on contact (gains from [`Critics`]: `heading`, `velocity`, `obstacle`).
    PythonRobotics,
}

/// Critic weights (Nav2 DWB style): the total cost is Σ weight·critic.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, Setting)]
#[serde(default, deny_unknown_fields)]
pub struct Critics {
    /// Goal distance: distance (m) from the rollout's end to the goal.
    #[setting(min = 0.0)]
    pub goal: f64,
    /// Goal heading: |angle| (rad) between the end heading and the direction to the goal.
    #[setting(min = 0.0)]
    pub heading: f64,
    /// Obstacle clearance: (cap − min(clearance, cap))/cap ∈ [0, 1] over the rollout.
    #[setting(min = 0.0)]
    pub obstacle: f64,
    /// Velocity: (v_max − v)/v_max, prefer going fast.
    #[setting(min = 0.0)]
    pub velocity: f64,
    /// Path following: distance (m) from the rollout's end to the path (its next segments).
    #[setting(min = 0.0)]
    pub path: f64,
}

impl Default for Critics {
    fn default() -> Self {
        Self {
            goal: 1.0,
            heading: 0.2,
            obstacle: 0.6,
            velocity: 0.2,
            path: 0.3,
        }
    }
}

/// How the window is sampled: `{ count = { nv = 11, nw = 21 } }` or
/// `{ resolution = { v_res = 0.01, w_res = 0.02 } }`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", deny_unknown_fields)]
pub enum Sampling {
    /// `nv × nw` samples spread evenly over the window, endpoints included.
    Count { nv: usize, nw: usize },
    /// NumPy `arange(min, max, res)` per axis (PythonRobotics).
    Resolution { v_res: f64, w_res: f64 },
}

impl mole_types::settings::Setting for Sampling {
    fn kind() -> String {
        "`{ count = { nv = …, nw = … } }` (≥ 1 each) or `{ resolution = { v_res = …, w_res = … } }` \
         (> 0 each)"
            .to_owned()
    }

    fn check_at(&self, at: &str) -> Result<(), mole_types::settings::SettingError> {
        let ok = match *self {
            Sampling::Count { nv, nw } => nv >= 1 && nw >= 1,
            Sampling::Resolution { v_res, w_res } => {
                v_res.is_finite() && w_res.is_finite() && v_res > 0.0 && w_res > 0.0
            }
        };
        if ok {
            Ok(())
        } else {
            Err(mole_types::settings::SettingError::new(
                at,
                "counts of at least 1, or resolutions above 0",
                self,
            ))
        }
    }

    fn keys_at(
        at: &str,
        about: mole_types::settings::About,
        out: &mut Vec<mole_types::settings::Key>,
    ) {
        out.push(mole_types::settings::Key::leaf::<Self>(at, about));
    }
}

/// Settings of the DWA.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, Setting)]
#[serde(default, deny_unknown_fields)]
pub struct DwaConfig {
    /// The cost.
    pub cost: DwaCost,
    /// Critic weights.
    pub critics: Critics,
    /// Sampling of the window.
    pub sampling: Sampling,
    /// Horizon T_H (s).
    #[setting(above = 0.0)]
    pub predict_time: f64,
    /// Rollout step (s).
    #[setting(above = 0.0)]
    pub sim_dt: f64,
    /// Time over which the acceleration limits bound the window (s).
    #[setting(above = 0.0)]
    pub window_dt: f64,
    /// Lowest linear speed (m/s); 0 = no reversing (bounce-back reverses).
    pub min_speed: f64,
    /// Clearances above this (m) cost nothing in the obstacle critic.
    #[setting(above = 0.0)]
    pub clearance_cap: f64,
    /// Extra margin (m) over the robot radius that a rollout must keep. The grid's squares
    /// contain the surface, so a gap reads up to a cell (0.05 m) narrower than it is: 0.05 m
    /// leaves passable what the world families guarantee (0.1 m to spare each side), where
    /// 0.07 m had the DWA circle in front of some of those gaps.
    #[setting(min = 0.0)]
    pub safety_margin: f64,
    /// The goal counts as reached within this distance (m).
    #[setting(above = 0.0)]
    pub goal_tolerance: f64,
    /// Follow an A* path over the inflated grid toward the goal ([`GlobalPath`]) instead of
    /// heading straight for it (the `dwa` planner; ignored without a grid).
    pub global_path: bool,
    /// Carrot distance (m) along the global path: the goal and heading critics aim at it.
    #[setting(above = 0.0)]
    pub lookahead: f64,
    /// Re-plan the global path at least every this many steps.
    #[setting(min = 1)]
    pub replan_every: u64,
    /// Re-plan when the robot is farther than this (m) from the path.
    #[setting(above = 0.0)]
    pub stray_distance: f64,
    /// Inflation (m) of the global path over the robot radius + `safety_margin`.
    #[setting(min = 0.0)]
    pub inflation_margin: f64,
    /// A robot whose path left to the goal has not shrunk by `progress_epsilon` in this long
    /// (s) closes the tightest spot just ahead on its path and re-plans around it.
    #[setting(above = 0.0)]
    pub no_progress_time: f64,
    /// Progress (m) along the global path that counts (see `no_progress_time`).
    #[setting(min = 0.0)]
    pub progress_epsilon: f64,
}

impl DwaConfig {
    /// The smallest gap (m) between the rim and an obstacle, as the DWA measures it, that its
    /// rollouts may reach: `safety_margin` less the slack below the hard limit. The reactive
    /// layer under the DWA fires only below this ([`crate::BounceBackConfig::under_dwa`]).
    pub fn closest_approach(&self) -> f64 {
        self.safety_margin - SLACK
    }
}

impl Default for DwaConfig {
    fn default() -> Self {
        Self {
            cost: DwaCost::Critics,
            critics: Critics::default(),
            sampling: Sampling::Count { nv: 11, nw: 21 },
            predict_time: 2.0,
            sim_dt: 0.1,
            window_dt: 0.25,
            min_speed: 0.0,
            clearance_cap: 0.6,
            safety_margin: 0.05,
            goal_tolerance: 0.25,
            global_path: true,
            lookahead: 1.2,
            replan_every: 100,
            stray_distance: 0.5,
            inflation_margin: 0.05,
            no_progress_time: 6.0,
            progress_epsilon: 0.25,
        }
    }
}

/// The robot state a DWA plans from: pose and current velocities.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct DwaState {
    pub x: f64,
    pub y: f64,
    pub theta: f64,
    pub v: f64,
    pub omega: f64,
}

/// Algorithms §4.2 / Fox et al.: the dynamic window [v_lo, v_hi, ω_lo, ω_hi] = the speed limits
/// ∩ the speeds reachable within `dt` under the acceleration limits.
pub fn dynamic_window(state: &DwaState, limits: &RobotLimits, min_speed: f64, dt: f64) -> [f64; 4] {
    [
        min_speed.max(state.v - limits.max_accel * dt),
        limits.max_speed.min(state.v + limits.max_accel * dt),
        (-limits.max_omega).max(state.omega - limits.max_alpha * dt),
        limits.max_omega.min(state.omega + limits.max_alpha * dt),
    ]
}

/// NumPy's `arange(start, stop, step)` length: ⌈(stop − start)/step⌉, at least 0.
fn arange_len(start: f64, stop: f64, step: f64) -> usize {
    if step.is_nan() || step <= 0.0 || stop.is_nan() || start.is_nan() || stop <= start {
        return 0;
    }
    ((stop - start) / step).ceil().min(1e6) as usize
}

/// Scan points (world frame) in a uniform bucket grid, rebuilt each step without allocating.
#[derive(Debug, Clone)]
pub struct PointIndex {
    points: Vec<[f64; 2]>,
    sorted: Vec<[f64; 2]>,
    start: Vec<u32>,
    base_bucket: f64,
    bucket: f64,
    origin: [f64; 2],
    dims: (usize, usize),
}

const MAX_BUCKETS: usize = 64;

impl PointIndex {
    /// An index for up to `capacity` points with buckets of `bucket` m.
    pub fn new(capacity: usize, bucket: f64) -> Self {
        Self {
            points: Vec::with_capacity(capacity),
            sorted: Vec::with_capacity(capacity),
            start: Vec::with_capacity(MAX_BUCKETS * MAX_BUCKETS + 1),
            base_bucket: if bucket > 0.0 { bucket } else { 0.25 },
            bucket: if bucket > 0.0 { bucket } else { 0.25 },
            origin: [0.0; 2],
            dims: (0, 0),
        }
    }

    /// Removes every point.
    pub fn clear(&mut self) {
        self.points.clear();
        self.sorted.clear();
        self.dims = (0, 0);
    }

    /// Adds a point (ignored when full or not finite); call [`PointIndex::build`] after.
    pub fn push(&mut self, p: [f64; 2]) {
        if self.points.len() < self.points.capacity() && p[0].is_finite() && p[1].is_finite() {
            self.points.push(p);
        }
    }

    /// Whether the index holds no point.
    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }

    /// The points.
    pub fn points(&self) -> &[[f64; 2]] {
        &self.points
    }

    /// Sorts the points into buckets (counting sort).
    pub fn build(&mut self) {
        self.sorted.clear();
        if self.points.is_empty() {
            self.dims = (0, 0);
            return;
        }
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for p in &self.points {
            lo = [lo[0].min(p[0]), lo[1].min(p[1])];
            hi = [hi[0].max(p[0]), hi[1].max(p[1])];
        }
        let b = self
            .base_bucket
            .max((hi[0] - lo[0]).max(hi[1] - lo[1]) / (MAX_BUCKETS as f64 - 1.0));
        self.bucket = b;
        self.origin = lo;
        let nx = (((hi[0] - lo[0]) / b) as usize + 1).min(MAX_BUCKETS);
        let ny = (((hi[1] - lo[1]) / b) as usize + 1).min(MAX_BUCKETS);
        self.dims = (nx, ny);
        self.start.clear();
        self.start.resize(nx * ny + 1, 0);
        let key = |p: &[f64; 2]| {
            let cx = (((p[0] - lo[0]) / b) as usize).min(nx - 1);
            let cy = (((p[1] - lo[1]) / b) as usize).min(ny - 1);
            cy * nx + cx
        };
        for p in &self.points {
            self.start[key(p) + 1] += 1;
        }
        for i in 0..nx * ny {
            self.start[i + 1] += self.start[i];
        }
        self.sorted.resize(self.points.len(), [0.0; 2]);
        // Fill from the back of each bucket, using `start[k+1]` as a moving cursor.
        for p in &self.points {
            let k = key(p);
            self.start[k + 1] -= 1;
            let at = self.start[k + 1] as usize;
            self.sorted[at] = *p;
        }
        // Cursors now hold each bucket's start; shift back into place.
        for k in 0..nx * ny {
            self.start[k] = self.start[k + 1];
        }
        self.start[nx * ny] = self.points.len() as u32;
    }

    /// The distance from (x, y) to the nearest point, looking only `cap` m around (returns
    /// `cap` when none is nearer; +∞ cap searches every point).
    pub fn nearest(&self, x: f64, y: f64, cap: f64) -> f64 {
        let (nx, ny) = self.dims;
        if nx == 0 {
            return cap;
        }
        let b = self.bucket;
        let mut best2 = cap * cap;
        let reach = if cap.is_finite() {
            (cap / b).ceil() as i64
        } else {
            nx.max(ny) as i64
        };
        let cx = ((x - self.origin[0]) / b).floor() as i64;
        let cy = ((y - self.origin[1]) / b).floor() as i64;
        let (x0, x1) = ((cx - reach).max(0), (cx + reach).min(nx as i64 - 1));
        let (y0, y1) = ((cy - reach).max(0), (cy + reach).min(ny as i64 - 1));
        for by in y0..=y1 {
            for bx in x0..=x1 {
                let k = by as usize * nx + bx as usize;
                for p in &self.sorted[self.start[k] as usize..self.start[k + 1] as usize] {
                    let d2 = (p[0] - x) * (p[0] - x) + (p[1] - y) * (p[1] - y);
                    if d2 < best2 {
                        best2 = d2;
                    }
                }
            }
        }
        best2.sqrt()
    }
}

/// The DWA planner toward a goal (or a carrot point set each step by the frontier planner).
#[derive(Debug, Clone)]
pub struct Dwa {
    limits: RobotLimits,
    config: DwaConfig,
    goal: [f64; 2],
    /// Where the goal and heading critics aim: the goal, or the carrot on the global path.
    aim: [f64; 2],
    global: GlobalPath,
    last_plan: Option<u64>,
    replan_requested: bool,
    /// The shortest path left to the goal (m) so far, and the tick it was reached.
    progress: (f64, u64),
    /// Re-plans around a spot the robot did not get through.
    detours: u64,
    /// Steps the DWA has chosen to stand still short of its aim.
    stuck: u32,
    /// Recovery steps left.
    unstick: u32,
    field: DistanceField,
    scan_points: PointIndex,
    /// Path to follow (world points), for the path critic.
    path: Vec<[f64; 2]>,
    n_steps: usize,
    last_cost: f64,
    use_grid: bool,
}

/// What [`Dwa::choose`] picked.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DwaChoice {
    pub v: f64,
    pub omega: f64,
    /// Its cost (+∞ when every candidate collides).
    pub cost: f64,
    /// The window it was chosen from.
    pub window: [f64; 4],
}

/// Rollout steps as PythonRobotics counts them: `while t <= T_H: t += dt`.
fn rollout_steps(config: &DwaConfig) -> usize {
    let mut n = 0usize;
    let mut t = 0.0;
    let dt = if config.sim_dt > 0.0 {
        config.sim_dt
    } else {
        0.1
    };
    while t <= config.predict_time && n < 10_000 {
        n += 1;
        t += dt;
    }
    n
}

impl Dwa {
    /// A DWA planner toward `goal`.
    pub fn new(limits: RobotLimits, config: DwaConfig, goal: [f64; 2]) -> Self {
        let n = rollout_steps(&config);
        Self {
            limits: limits.sanitized(),
            config,
            goal,
            aim: goal,
            global: GlobalPath::new(),
            last_plan: None,
            replan_requested: true,
            progress: (f64::INFINITY, 0),
            detours: 0,
            stuck: 0,
            unstick: 0,
            field: DistanceField::with_capacity(mole_types::MAX_GRID_CELLS),
            scan_points: PointIndex::new(mole_types::MAX_BEAMS + 64, 0.25),
            path: Vec::with_capacity(mole_types::MAX_PATH),
            n_steps: n,
            last_cost: 0.0,
            use_grid: true,
        }
    }

    /// The goal.
    pub fn goal(&self) -> [f64; 2] {
        self.goal
    }

    /// Where the goal and heading critics aim (the goal, or the carrot on the global path).
    pub fn aim(&self) -> [f64; 2] {
        self.aim
    }

    /// The global path toward the goal (empty without one).
    pub fn global_path(&self) -> &GlobalPath {
        &self.global
    }

    /// Sets the path for the path critic (at most `MAX_PATH` points kept); empty = none.
    pub fn set_path(&mut self, path: &[[f64; 2]]) {
        self.path.clear();
        self.path
            .extend(path.iter().take(mole_types::MAX_PATH).copied());
    }

    /// One step toward `carrot` with `path` (its next few segments) for the path critic:
    /// the path follower of the frontier planner and of the goal-seeking `dwa`.
    pub fn track_path(
        &mut self,
        input: &PlannerInput,
        carrot: [f64; 2],
        path: &[[f64; 2]],
    ) -> Command {
        self.aim = carrot;
        self.path.clear();
        self.path
            .extend(path.iter().take(PATH_CRITIC_POINTS).copied());
        self.follow(input)
    }

    /// Re-plans around spots the robot did not get through so far (algorithms §4.2).
    pub fn detours(&self) -> u64 {
        self.detours
    }

    /// Re-plans the global path when due (none yet, every `replan_every` steps, asked for, the
    /// robot strayed, the grid changed and blocks a segment ahead, or the robot made no
    /// progress along it) and returns the carrot (algorithms §4.2, "Aim point").
    fn update_global(&mut self, input: &PlannerInput, grid: &Grid) -> Option<[f64; 2]> {
        let p = [input.pose.x, input.pose.y];
        let changed = self.field.update(grid);
        let cfg = self.config;
        let keep = self.limits.radius + cfg.safety_margin + cfg.inflation_margin;
        let stuck = !self.global.is_empty()
            && input.tick.saturating_sub(self.progress.1) as f64 * input.dt >= cfg.no_progress_time;
        if stuck {
            // Circling short of a spot it cannot pass: close the tightest spot just ahead and go
            // another way round; with no other way left, open every closed spot again.
            match self
                .global
                .tightest_ahead(&self.field, cfg.lookahead + keep)
            {
                Some(q) => self.global.avoid(q, keep),
                None => self.global.forget_avoided(),
            }
            self.detours += 1;
        }
        let due = stuck
            || self.replan_requested
            || self.global.is_empty()
            || self
                .last_plan
                .is_none_or(|t| input.tick.saturating_sub(t) >= cfg.replan_every)
            || self.global.distance_to(p) > cfg.stray_distance
            || (changed && !self.global.still_clear(grid, &self.field));
        if due {
            self.replan_requested = false;
            self.last_plan = Some(input.tick);
            let before = self.progress.0;
            if !self.plan_global(grid, p, keep) && !self.global.avoided().is_empty() {
                self.global.forget_avoided();
                self.plan_global(grid, p, keep);
            }
            let left = self.global.remaining_length(p);
            // A new way (round a closed spot), or one longer than the best so far (the grid
            // showed more): progress is measured afresh.
            if stuck || left.is_nan() || left >= before + cfg.progress_epsilon {
                self.progress = (left, input.tick);
            }
        }
        let carrot = self.global.carrot(p, cfg.lookahead);
        let left = self.global.remaining_length(p);
        if left < self.progress.0 - cfg.progress_epsilon || self.global.is_empty() {
            self.progress = (left, input.tick);
        }
        carrot
    }

    /// One A* plan: with room to spare first, then the bare inflation `keep`.
    fn plan_global(&mut self, grid: &Grid, p: [f64; 2], keep: f64) -> bool {
        let roomy = keep + self.config.safety_margin + 0.1;
        if self.global.plan(grid, &self.field, p, self.goal, roomy)
            && self.global.kind() != crate::global_path::PathKind::Optimistic
        {
            return true;
        }
        self.global.plan(grid, &self.field, p, self.goal, keep)
    }

    /// The point obstacles (scan points, or PythonRobotics' obstacle list), world frame.
    pub fn points_mut(&mut self) -> &mut PointIndex {
        &mut self.scan_points
    }

    /// Whether the grid's distance field is used (default yes).
    pub fn set_use_grid(&mut self, on: bool) {
        self.use_grid = on;
    }

    /// Cost of the last chosen command.
    pub fn last_cost(&self) -> f64 {
        self.last_cost
    }

    /// The arena walls as the grid's extent (+∞ box without a grid or when it is not used).
    fn walls(&self) -> [f64; 4] {
        match self.field.extent() {
            Some(e) if self.use_grid => e,
            _ => [
                f64::NEG_INFINITY,
                f64::NEG_INFINITY,
                f64::INFINITY,
                f64::INFINITY,
            ],
        }
    }

    /// [`Dwa::clearance`] for the rollouts: `walls` from [`Dwa::walls`] once per rollout, plain
    /// comparisons (no NaN-aware min), and the point index only when it holds points.
    #[inline(always)]
    fn rollout_clearance(&self, x: f64, y: f64, cap: f64, walls: &[f64; 4]) -> f64 {
        let mut c = if self.scan_points.is_empty() {
            cap
        } else {
            self.scan_points.nearest(x, y, cap)
        };
        if self.use_grid {
            let d = self.field.distance(x, y);
            if d < c {
                c = d;
            }
        }
        for d in [x - walls[0], walls[2] - x, y - walls[1], walls[3] - y] {
            if d < c {
                c = d;
            }
        }
        c
    }

    /// Clearance (m) from the robot centre at (x, y) to the nearest obstacle, looking `cap` m.
    #[inline]
    fn clearance(&self, x: f64, y: f64, cap: f64) -> f64 {
        let mut c = if self.scan_points.is_empty() {
            cap
        } else {
            self.scan_points.nearest(x, y, cap)
        };
        if self.use_grid {
            c = c.min(self.field.distance(x, y));
        }
        // The arena walls as the grid's extent.
        if self.use_grid
            && let Some(e) = self.field.extent()
        {
            c = c.min(x - e[0]).min(e[2] - x).min(y - e[1]).min(e[3] - y);
        }
        c
    }

    /// Evaluates the window around `state` and returns the cheapest (v, ω). Allocation-free.
    pub fn choose(&self, state: &DwaState) -> DwaChoice {
        let cfg = &self.config;
        let window = dynamic_window(state, &self.limits, cfg.min_speed, cfg.window_dt);
        let mut best = DwaChoice {
            v: 0.0,
            omega: 0.0,
            cost: f64::INFINITY,
            window,
        };
        let (nv, nw) = match cfg.sampling {
            Sampling::Count { nv, nw } => (nv.max(1), nw.max(1)),
            Sampling::Resolution { v_res, w_res } => (
                arange_len(window[0], window[1], v_res),
                arange_len(window[2], window[3], w_res),
            ),
        };
        let sample = |lo: f64, hi: f64, n: usize, i: usize, res: f64| match cfg.sampling {
            Sampling::Count { .. } => {
                if n == 1 {
                    0.5 * (lo + hi)
                } else {
                    lo + (hi - lo) * i as f64 / (n - 1) as f64
                }
            }
            Sampling::Resolution { .. } => lo + i as f64 * res,
        };
        let (v_res, w_res) = match cfg.sampling {
            Sampling::Resolution { v_res, w_res } => (v_res, w_res),
            Sampling::Count { .. } => (0.0, 0.0),
        };
        // The critics' rollouts share the start heading's sin/cos, and per ω the rotations of
        // 1..=MAX_K steps: ω in the outer loop (ties may then resolve differently from the
        // v-outer order PythonRobotics uses, which the other costs keep).
        let critics = cfg.cost == DwaCost::Critics;
        let head = state.theta.sin_cos();
        let (outer, inner) = if critics { (nw, nv) } else { (nv, nw) };
        for a in 0..outer {
            let w_outer = sample(window[2], window[3], nw, a, w_res);
            let rot = rotations(w_outer, cfg.sim_dt);
            for b in 0..inner {
                let (i, j) = if critics { (b, a) } else { (a, b) };
                let v = sample(window[0], window[1], nv, i, v_res);
                let w = sample(window[2], window[3], nw, j, w_res);
                let cost = if critics {
                    self.critics_cost(state, v, w, head, &rot)
                } else {
                    self.score(state, v, w)
                };
                // `>=` as PythonRobotics: among equal costs the last one wins.
                if best.cost >= cost {
                    best = DwaChoice {
                        v,
                        omega: w,
                        cost,
                        window,
                    };
                }
            }
        }
        best
    }

    /// The cost of holding (v, ω) from `state`.
    pub fn score(&self, s: &DwaState, v: f64, w: f64) -> f64 {
        let cfg = &self.config;
        let r = self.limits.radius;
        match cfg.cost {
            DwaCost::Source => {
                // One step of T_H along the current heading, as written.
                let th = cfg.predict_time;
                let x = s.x + th * v * s.theta.cos();
                let y = s.y + th * v * s.theta.sin();
                let j_goal = -(x - self.aim[0]).hypot(y - self.aim[1]);
                let j_obs: f64 = self
                    .scan_points
                    .points()
                    .iter()
                    .map(|p| {
                        let d = (p[0] - x).hypot(p[1] - y).max(1e-6);
                        1.0 / (d * d)
                    })
                    .sum();
                let j_vel = (v - s.v).abs() + (w - s.omega).abs();
                j_goal + j_obs + j_vel
            }
            DwaCost::PythonRobotics => {
                let (mut x, mut y, mut th) = (s.x, s.y, s.theta);
                let mut min_r = self.clearance(x, y, f64::INFINITY);
                if min_r <= r {
                    return f64::INFINITY;
                }
                for _ in 0..self.n_steps {
                    th += w * cfg.sim_dt;
                    x += v * th.cos() * cfg.sim_dt;
                    y += v * th.sin() * cfg.sim_dt;
                    let c = self.clearance(x, y, f64::INFINITY);
                    if c <= r {
                        return f64::INFINITY;
                    }
                    min_r = min_r.min(c);
                }
                let e = (self.aim[1] - y).atan2(self.aim[0] - x) - th;
                let heading = e.sin().atan2(e.cos()).abs();
                cfg.critics.heading * heading
                    + cfg.critics.velocity * (self.limits.max_speed - v)
                    + cfg.critics.obstacle / min_r
            }
            DwaCost::Critics => {
                let rot = rotations(w, cfg.sim_dt);
                self.critics_cost(s, v, w, s.theta.sin_cos(), &rot)
            }
        }
    }

    /// The critics' cost of (v, ω) from `s`, with sin/cos of the start heading and the
    /// rotations by ω over 1..=MAX_K steps precomputed ([`rotations`]).
    fn critics_cost(
        &self,
        s: &DwaState,
        v: f64,
        w: f64,
        head: (f64, f64),
        rot: &[(f64, f64); MAX_K + 1],
    ) -> f64 {
        let cfg = &self.config;
        let r = self.limits.radius;
        {
            let cap = cfg.clearance_cap + r;
            let (mut x, mut y, mut th) = (s.x, s.y, s.theta);
            let c0 = self.clearance(x, y, cap);
            let mut min_c = c0;
            // Hard limit: radius + margin, less `SLACK` (see `DwaConfig::closest_approach`).
            let hard = r + cfg.safety_margin;
            let walls = self.walls();
            let braking = v * v / (2.0 * self.limits.max_accel.min(1e6));
            let far = FINE_HORIZON.max(2.0 * cfg.sim_dt);
            // In-place turns: the heading critic takes the best heading along the turn.
            let mut best_e = f64::INFINITY;
            let tol2 = 0.25 * cfg.goal_tolerance * cfg.goal_tolerance;
            if v == 0.0 {
                // The clearance stays c0; the best heading along the turn in closed form.
                let e0 = wrap_angle((self.aim[1] - y).atan2(self.aim[0] - x) - th);
                let turn = w * cfg.predict_time;
                best_e = if e0 * turn > 0.0 && turn.abs() >= e0.abs() {
                    0.0
                } else {
                    e0.abs().min(wrap_angle(e0 - turn).abs())
                };
                th += turn;
            } else {
                let speed = v.abs();
                let mut t = 0.0;
                let mut travelled = 0.0;
                let mut c = c0;
                // cos/sin of the heading, advanced by rotations (sin/cos per step only for
                // the long steps).
                let (mut sn, mut cs) = head;
                while t < cfg.predict_time - 1e-9 {
                    // Fine steps near the robot, coarse ones (2 × sim_dt) beyond `far` s,
                    // and long ones where the clearance allows (sphere tracing: within
                    // c − hard of travel nothing can be hit).
                    // Steps are whole multiples k of sim_dt, k ≤ MAX_K.
                    let base = if t < far { 1 } else { 2 };
                    let free = (c - hard) / (speed * cfg.sim_dt);
                    let k = if free >= MAX_K as f64 {
                        MAX_K
                    } else if free > base as f64 {
                        free as usize
                    } else {
                        base
                    };
                    let mut dt = k as f64 * cfg.sim_dt;
                    let (mut rs, mut rc) = rot[k];
                    if dt > cfg.predict_time - t {
                        dt = cfg.predict_time - t;
                        (rs, rc) = (w * dt).sin_cos();
                    }
                    t += dt;
                    let (px, py, pth) = (x, y, th);
                    th += w * dt;
                    // Exact arc for constant (v, ω) would differ by O(ω·dt²); the heading is
                    // advanced first, as in the source's and PythonRobotics' motion model.
                    (sn, cs) = (sn * rc + cs * rs, cs * rc - sn * rs);
                    x += v * cs * dt;
                    y += v * sn * dt;
                    c = self.rollout_clearance(x, y, cap, &walls);
                    // Collides: closer than the hard limit less `SLACK`, or, from a start
                    // already that close, any closer than the start (the robot may turn away or
                    // run parallel, never creep in: the limit is not re-measured from where the
                    // last step left it).
                    if (c < r + 0.01 && c < c0 - 1e-9) || c < c0.min(hard - SLACK) {
                        // Fox et al.'s admissible velocities: fine if the robot can still
                        // brake before that point; the arc then ends there.
                        if braking + 1e-9 > travelled {
                            return f64::INFINITY;
                        }
                        (x, y, th) = (px, py, pth);
                        min_c = min_c.min(r);
                        break;
                    }
                    travelled += speed * dt;
                    if c < min_c {
                        min_c = c;
                    }
                    let (gx, gy) = (x - self.aim[0], y - self.aim[1]);
                    if gx * gx + gy * gy < tol2 {
                        break;
                    }
                }
            }
            let k = &cfg.critics;
            let d_goal = (x - self.aim[0]).hypot(y - self.aim[1]);
            let e = wrap_angle((self.aim[1] - y).atan2(self.aim[0] - x) - th);
            let heading = if d_goal > cfg.goal_tolerance {
                e.abs().min(best_e)
            } else {
                0.0
            };
            let clear = (cfg.clearance_cap - (min_c - r).clamp(0.0, cfg.clearance_cap))
                / cfg.clearance_cap.max(1e-9);
            let vel = if self.limits.max_speed > 0.0 {
                (self.limits.max_speed - v) / self.limits.max_speed
            } else {
                0.0
            };
            let path = if self.path.is_empty() {
                0.0
            } else {
                path_distance(&self.path, [x, y])
            };
            k.goal * d_goal
                + k.heading * heading
                + k.obstacle * clear
                + k.velocity * vel
                + k.path * path
        }
    }

    /// Loads the scan's hits (world frame) into the point index: with the grid's field in use,
    /// only the hits the grid does not already have (no occupied cell within a cell diagonal),
    /// so that rollouts usually query the O(1) field alone (the mapping folds every scan into
    /// the grid, so the index holds only what changed since the grid was published).
    pub fn load_scan(&mut self, input: &PlannerInput) {
        self.scan_points.clear();
        let (w, _) = self.field.dims();
        let filter = self.use_grid && w > 0;
        let known = self.field.resolution() * core::f64::consts::SQRT_2;
        if let Some(scan) = input.scan {
            let range_max = scan.range_max as f64;
            let reach = self.limits.max_speed * self.config.predict_time
                + self.limits.radius
                + self.config.clearance_cap
                + 0.5;
            for (i, &r) in scan.ranges().iter().enumerate() {
                let r = r as f64;
                if !(r.is_finite() && r >= 0.0 && r < range_max && r < reach) {
                    continue;
                }
                let a = input.pose.theta + crate::obstacles::beam_angle(scan, i);
                let p = [input.pose.x + r * a.cos(), input.pose.y + r * a.sin()];
                if filter && self.field.distance(p[0], p[1]) <= known {
                    continue;
                }
                self.scan_points.push(p);
            }
        }
        self.scan_points.build();
    }

    /// One step toward the goal from `input`, without the goal-reached test (the frontier
    /// planner's local planner).
    pub fn follow(&mut self, input: &PlannerInput) -> Command {
        if let Some(grid) = input.grid {
            self.field.update(grid);
        }
        self.load_scan(input);
        let state = DwaState {
            x: input.pose.x,
            y: input.pose.y,
            theta: input.pose.theta,
            v: input.last_command.v,
            omega: input.last_command.omega,
        };
        let choice = self.choose(&state);
        self.last_cost = choice.cost;
        let hard = self.limits.radius + self.config.safety_margin;
        let c0 = self.clearance(state.x, state.y, hard + 1.0);
        let mut mode = MODE_GOAL;
        let (v, w) = if self.unstick > 0 {
            // Recovery: turn to face away from the nearest obstacle, then creep away from it.
            self.unstick -= 1;
            if c0 >= hard + UNSTICK_CLEARANCE {
                self.unstick = 0;
            }
            mode = MODE_ESCAPE;
            let away = self.field.clearance_in_arena(state.x, state.y).away;
            let e = if away == [0.0, 0.0] {
                wrap_angle((self.aim[1] - state.y).atan2(self.aim[0] - state.x) - state.theta)
            } else {
                wrap_angle(away[1].atan2(away[0]) - state.theta)
            };
            if e.abs() > 0.3 {
                (0.0, 3.0 * e)
            } else {
                (0.15, 2.0 * e)
            }
        } else if choice.cost.is_finite() {
            // Stuck: the cheapest arc stands still although the aim is not reached.
            let far =
                (self.aim[0] - state.x).hypot(self.aim[1] - state.y) > self.config.goal_tolerance;
            if choice.v.abs() < 0.02 && far && c0 < hard + UNSTICK_CLEARANCE {
                self.stuck += 1;
            } else {
                self.stuck = 0;
            }
            if self.stuck as f64 * input.dt >= STUCK_TIME {
                self.stuck = 0;
                self.unstick = (UNSTICK_TIME / input.dt).ceil() as u32;
            }
            (choice.v, choice.omega)
        } else {
            // Every arc collides: brake and turn toward the goal in place.
            let e = wrap_angle(
                (self.aim[1] - input.pose.y).atan2(self.aim[0] - input.pose.x) - input.pose.theta,
            );
            (0.0, 2.0 * e)
        };
        Command { v, omega: w, mode }
    }
}

impl crate::Registered for Dwa {
    fn build(
        settings: &crate::Settings,
        limits: RobotLimits,
        goal: Option<[f64; 2]>,
        _local: Option<Box<dyn Planner>>,
        _seed: u64,
    ) -> Result<Self, crate::PlanningError> {
        let goal = goal.ok_or(crate::PlanningError::MissingGoal {
            kind: PlannerKind::Dwa,
        })?;
        Ok(Dwa::new(limits, settings.dwa, goal))
    }

    /// The last resort under the DWA: it fires only closer than the DWA ever drives.
    fn bounce_back(settings: &crate::Settings) -> crate::BounceBackConfig {
        settings.bounce_back.under_dwa(&settings.dwa)
    }
}

impl Planner for Dwa {
    fn kind(&self) -> PlannerKind {
        PlannerKind::Dwa
    }

    fn set_settings(&mut self, settings: &crate::Settings) -> Result<(), String> {
        self.config = settings.dwa;
        self.n_steps = rollout_steps(&self.config);
        Ok(())
    }

    fn track(&mut self, input: &PlannerInput, carrot: [f64; 2], path: &[[f64; 2]]) -> Command {
        self.track_path(input, carrot, path)
    }

    fn step(&mut self, input: &PlannerInput) -> Command {
        if !usable(input) {
            return Command::STOP;
        }
        let d = (input.pose.x - self.goal[0]).hypot(input.pose.y - self.goal[1]);
        if crate::arrived(d, self.config.goal_tolerance) {
            return Command {
                v: 0.0,
                omega: 0.0,
                mode: MODE_ARRIVED,
            };
        }
        if self.config.global_path
            && self.config.cost == DwaCost::Critics
            && let Some(grid) = input.grid
        {
            match self.update_global(input, grid) {
                Some(carrot) => {
                    self.aim = carrot;
                    self.path.clear();
                    let rest = self.global.remaining();
                    self.path
                        .extend(rest.iter().take(PATH_CRITIC_POINTS).copied());
                }
                None => {
                    // No path even through the unknown: head for the goal itself.
                    self.aim = self.goal;
                    self.path.clear();
                }
            }
        }
        self.follow(input)
    }

    fn replan(&mut self) {
        self.replan_requested = true;
    }

    fn target(&self) -> Option<[f64; 2]> {
        Some(self.goal)
    }

    /// Sets the goal (and the aim point of the critics, and the tolerance if given); drops the
    /// global path.
    fn set_goal(&mut self, goal: [f64; 2], tolerance: Option<f64>) -> bool {
        if let Some(t) = tolerance.filter(|t| t.is_finite() && *t > 0.0) {
            self.config.goal_tolerance = t;
        }
        self.goal = goal;
        self.aim = goal;
        self.global.clear();
        self.global.forget_avoided();
        self.progress = (f64::INFINITY, 0);
        self.replan_requested = true;
        true
    }

    fn write_status(&self, status: &mut PlanStatus) {
        status.flags = STATUS_HAS_GOAL;
        (status.goal_x, status.goal_y) = (self.goal[0], self.goal[1]);
        (status.frontier_x, status.frontier_y) = (0.0, 0.0);
        status.bounces = 0;
        let path = self.global.points();
        crate::write_path(status, path);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use core::f64::consts::PI;

    fn limits() -> RobotLimits {
        RobotLimits::default()
    }

    /// PythonRobotics' default Config and obstacle list.
    fn python_robotics() -> Dwa {
        let deg = PI / 180.0;
        let limits = RobotLimits {
            radius: 1.0,
            max_speed: 1.0,
            max_omega: 40.0 * deg,
            max_accel: 0.2,
            max_alpha: 40.0 * deg,
        };
        let config = DwaConfig {
            cost: DwaCost::PythonRobotics,
            critics: Critics {
                goal: 0.0,
                heading: 0.15,
                obstacle: 1.0,
                velocity: 1.0,
                path: 0.0,
            },
            sampling: Sampling::Resolution {
                v_res: 0.01,
                w_res: 0.1 * deg,
            },
            predict_time: 3.0,
            sim_dt: 0.1,
            window_dt: 0.1,
            min_speed: -0.5,
            clearance_cap: f64::INFINITY,
            safety_margin: 0.0,
            goal_tolerance: 1.0,
            global_path: false,
            ..DwaConfig::default()
        };
        let mut dwa = Dwa::new(limits, config, [10.0, 10.0]);
        dwa.set_use_grid(false);
        let ob = [
            [-1.0, -1.0],
            [0.0, 2.0],
            [4.0, 2.0],
            [5.0, 4.0],
            [5.0, 5.0],
            [5.0, 6.0],
            [5.0, 9.0],
            [8.0, 9.0],
            [7.0, 9.0],
            [8.0, 10.0],
            [9.0, 11.0],
            [12.0, 13.0],
            [12.0, 12.0],
            [15.0, 15.0],
            [13.0, 13.0],
        ];
        for p in ob {
            dwa.points_mut().push(p);
        }
        dwa.points_mut().build();
        dwa
    }

    #[test]
    fn parity_with_python_robotics_first_command() {
        let dwa = python_robotics();
        let s = DwaState {
            x: 0.0,
            y: 0.0,
            theta: PI / 8.0,
            v: 0.0,
            omega: 0.0,
        };
        let c = dwa.choose(&s);
        let expected_window = [-0.02, 0.02, -0.0698132, 0.0698132];
        for (a, b) in c.window.iter().zip(expected_window) {
            assert!((a - b).abs() < 1e-6, "{:?}", c.window);
        }
        assert!((c.v - 0.02).abs() < 1e-6, "{c:?}");
        assert!((c.omega - 0.06806784082777904).abs() < 1e-6, "{c:?}");
        assert_eq!(
            dwa.n_steps, 30,
            "`while t <= 3.0: t += 0.1` runs 30 times (t ends at 3.0000000000000013)"
        );
    }

    #[test]
    fn dynamic_window_is_the_reachable_speeds_within_the_limits() {
        let s = DwaState {
            v: 0.45,
            omega: -1.9,
            ..Default::default()
        };
        let w = dynamic_window(&s, &limits(), 0.0, 0.1);
        assert!(
            (w[0] - 0.25).abs() < 1e-12 && (w[1] - 0.5).abs() < 1e-12,
            "{w:?}"
        );
        assert!(
            (w[2] + 2.0).abs() < 1e-12 && (w[3] + 1.1).abs() < 1e-12,
            "{w:?}"
        );
    }

    fn facing_goal(cost: DwaCost) -> Dwa {
        let config = DwaConfig {
            cost,
            min_speed: -0.5,
            ..Default::default()
        };
        Dwa::new(limits(), config, [5.0, 0.0])
    }

    #[test]
    fn source_cost_flees_the_goal_critics_approach_it() {
        let s = DwaState {
            v: 0.0,
            ..Default::default()
        };
        let seed = facing_goal(DwaCost::Source).choose(&s);
        assert!(
            seed.v < 0.0,
            "J_goal = −d_goal: least cost backs away, {seed:?}"
        );
        let fixed = facing_goal(DwaCost::Critics).choose(&s);
        assert!(fixed.v > 0.0, "{fixed:?}");
    }

    #[test]
    fn each_critic_alone_prefers_what_it_names() {
        let s = DwaState::default();
        let only = |critics: Critics| {
            let mut d = Dwa::new(
                limits(),
                DwaConfig {
                    critics,
                    ..Default::default()
                },
                [0.0, 5.0],
            );
            d.points_mut().push([1.0, 0.6]);
            d.points_mut().build();
            d
        };
        let zero = Critics {
            goal: 0.0,
            heading: 0.0,
            obstacle: 0.0,
            velocity: 0.0,
            path: 0.0,
        };
        // Goal at +y: the goal critic turns left.
        let g = only(Critics { goal: 1.0, ..zero });
        assert!(g.score(&s, 0.5, 1.0) < g.score(&s, 0.5, -1.0));
        let h = only(Critics {
            heading: 1.0,
            ..zero
        });
        assert!(h.score(&s, 0.3, 1.0) < h.score(&s, 0.3, 0.0));
        // Velocity: faster is cheaper.
        let v = only(Critics {
            velocity: 1.0,
            ..zero
        });
        assert!(v.score(&s, 0.5, 0.0) < v.score(&s, 0.1, 0.0));
        // Obstacle at (1, 0.6): turning right keeps more clearance than turning left.
        let o = only(Critics {
            obstacle: 1.0,
            ..zero
        });
        assert!(o.score(&s, 0.3, -0.5) < o.score(&s, 0.3, 0.3));
        // Path along y = −1: the arc that bends right ends nearer to it.
        let mut p = only(Critics { path: 1.0, ..zero });
        let line: Vec<[f64; 2]> = (0..20).map(|i| [i as f64 * 0.25, -1.0]).collect();
        p.set_path(&line);
        assert!(p.score(&s, 0.5, -0.6) < p.score(&s, 0.5, 0.6));
    }

    #[test]
    fn rollout_catches_an_obstacle_the_chord_would_skip() {
        // A point obstacle on the arc of (v, ω) = (0.5, 1.0) at 1.5 s, off the straight chord.
        let config = DwaConfig::default();
        let mut d = Dwa::new(limits(), config, [0.0, 3.0]);
        let clean = d.score(&DwaState::default(), 0.5, 1.0);
        let (r, t) = (0.5f64, 1.5f64);
        d.points_mut().push([r * t.sin(), r * (1.0 - t.cos())]);
        d.points_mut().build();
        // Far enough to brake before it (Fox et al.'s admissible velocities): the arc is cut
        // at the obstacle and costs more than without the obstacle.
        let hit = d.score(&DwaState::default(), 0.5, 1.0);
        assert!(hit.is_finite() && hit > clean, "{hit} {clean}");
        // An obstacle right ahead on the arc, too near to brake: inadmissible.
        d.points_mut().clear();
        d.points_mut().push([0.3, 0.06]);
        d.points_mut().build();
        assert_eq!(d.score(&DwaState::default(), 0.5, 0.3), f64::INFINITY);
    }

    /// The dynamic window is centred on the command sent last: turning left at full rate, the
    /// DWA cannot wish a right turn toward a goal on its right within `window_dt`; standing, it
    /// can.
    #[test]
    fn the_window_starts_from_the_command_sent() {
        let mut d = Dwa::new(limits(), DwaConfig::default(), [0.0, -5.0]);
        let input = |last_command| PlannerInput {
            tick: 0,
            dt: 0.05,
            pose: mole_types::Pose2::new(0.0, 0.0, 0.0),
            scan: None,
            tactile: None,
            grid: None,
            last_command,
        };
        let standing = d.step(&input(Command::STOP));
        assert!(standing.omega < 0.0, "{standing:?}");
        let turning_left = Command {
            v: 0.2,
            omega: 2.0,
            mode: MODE_GOAL,
        };
        let c = d.step(&input(turning_left));
        // ω ∈ [2 − 8·0.25, 2] = [0, 2].
        assert!(c.omega >= 0.0, "{c:?}");
    }

    #[test]
    fn goal_seeking_dwa_follows_a_path_around_a_wall() {
        // 4 m × 4 m at 0.05 m, a wall at x = 2 m from y = 0 to 3 m; goal behind it.
        let mut g = crate::obstacles::test_support::grid_free(80, 80, 0.05);
        for r in 0..60 {
            g.cells[r * 80 + 40] = mole_types::CELL_OCCUPIED;
        }
        let mut d = crate::Limited::new(
            Dwa::new(limits(), DwaConfig::default(), [3.0, 1.0]),
            limits(),
        );
        let mut pose = mole_types::Pose2::new(1.0, 1.0, 0.0);
        let mut reached = false;
        let mut min_clear = f64::INFINITY;
        let mut last_command = Command::STOP;
        for tick in 0..1500 {
            let input = PlannerInput {
                tick,
                dt: 0.05,
                pose,
                scan: None,
                tactile: None,
                grid: Some(&g),
                last_command,
            };
            let c = d.step(&input);
            last_command = c;
            if tick == 0 {
                let path = d.inner().global_path();
                assert_eq!(path.kind(), crate::global_path::PathKind::Known);
                // The path goes over the wall's end (y > 3 m).
                assert!(path.points().iter().any(|p| p[1] > 3.0));
            }
            pose.theta += c.omega * 0.05;
            pose.x += c.v * pose.theta.cos() * 0.05;
            pose.y += c.v * pose.theta.sin() * 0.05;
            min_clear = min_clear.min(d.inner().field.distance(pose.x, pose.y));
            if c.mode == MODE_ARRIVED {
                reached = true;
                break;
            }
        }
        // Reached, and the robot never touched the wall.
        assert!(reached, "stopped at {pose:?}");
        assert!(min_clear > limits().radius, "{min_clear}");
        let mut st: Box<PlanStatus> = bytemuck::zeroed_box();
        d.write_status(&mut st);
        assert!(st.n_path >= 2 && st.flags & STATUS_HAS_GOAL != 0);
        assert_eq!(st.mode, MODE_ARRIVED);
    }

    /// A robot already inside its margin beside a wall, its aim inside the margin too, never
    /// creeps closer than where it starts: the limit is not re-measured step by step.
    /// 4 m × 4 m at 0.05 m, a wall at x = 2 m with two gaps of 0.8 m, at y ∈ [1, 1.8) and
    /// y ∈ [2.6, 3.4): room for the path's bare inflation, not for its roomy one.
    fn two_gaps() -> Box<Grid> {
        let mut g = crate::obstacles::test_support::grid_free(80, 80, 0.05);
        for r in (0..80).filter(|r| !(20..36).contains(r) && !(52..68).contains(r)) {
            g.cells[r * 80 + 40] = mole_types::CELL_OCCUPIED;
        }
        g
    }

    /// Whether the path crosses x = 2 m within 0.3 m of `y`.
    fn crosses_at(path: &GlobalPath, y: f64) -> bool {
        path.points().windows(2).any(|s| {
            let t = (2.025 - s[0][0]) / (s[1][0] - s[0][0]);
            (0.0..=1.0).contains(&t) && (s[0][1] + t * (s[1][1] - s[0][1]) - y).abs() < 0.3
        })
    }

    fn held_at(tick: u64, pose: mole_types::Pose2, g: &Grid) -> PlannerInput<'_> {
        PlannerInput {
            tick,
            dt: 0.05,
            pose,
            scan: None,
            tactile: None,
            grid: Some(g),
            last_command: Command::STOP,
        }
    }

    /// A grid that closes the gap the path runs through re-plans at once, through the other.
    #[test]
    fn a_path_the_grid_blocks_is_planned_again_at_once() {
        let mut g = two_gaps();
        let pose = mole_types::Pose2::new(1.0, 1.4, 0.0);
        let mut d = Dwa::new(limits(), DwaConfig::default(), [3.0, 1.4]);
        d.step(&held_at(0, pose, &g));
        assert!(
            crosses_at(d.global_path(), 1.4),
            "{:?}",
            d.global_path().points()
        );
        for r in 20..36 {
            g.cells[r * 80 + 40] = mole_types::CELL_OCCUPIED;
        }
        d.step(&held_at(1, pose, &g));
        assert!(
            crosses_at(d.global_path(), 3.0),
            "not re-planned through the other gap: {:?}",
            d.global_path().points()
        );
    }

    /// A robot that makes no progress along its path (held in front of the gap) closes the
    /// tightest spot ahead and re-plans the other way round instead of circling there.
    #[test]
    fn a_robot_without_progress_plans_round_the_spot_it_cannot_pass() {
        let g = two_gaps();
        let pose = mole_types::Pose2::new(1.0, 1.4, 0.0);
        let mut d = Dwa::new(limits(), DwaConfig::default(), [3.0, 1.4]);
        let no_progress = (DwaConfig::default().no_progress_time / 0.05) as u64;
        for tick in 0..no_progress {
            d.step(&held_at(tick, pose, &g));
        }
        assert!(
            crosses_at(d.global_path(), 1.4),
            "{:?}",
            d.global_path().points()
        );
        assert_eq!(d.detours(), 0, "too early");
        for tick in no_progress..no_progress + 5 {
            d.step(&held_at(tick, pose, &g));
        }
        assert_eq!(d.detours(), 1);
        assert!(
            crosses_at(d.global_path(), 3.0) && !crosses_at(d.global_path(), 1.4),
            "still through the gap it did not pass: {:?}",
            d.global_path().points()
        );
    }

    #[test]
    fn a_robot_inside_the_margin_does_not_creep_closer() {
        // 4 m × 4 m at 0.05 m, a wall whose face is at x = 2 m, the full height.
        let mut g = crate::obstacles::test_support::grid_free(80, 80, 0.05);
        for r in 0..80 {
            g.cells[r * 80 + 40] = mole_types::CELL_OCCUPIED;
        }
        let config = DwaConfig {
            global_path: false,
            ..DwaConfig::default()
        };
        // The aim hugs the face: the straight way there runs into the margin.
        let mut d = crate::Limited::new(Dwa::new(limits(), config, [1.9, 3.5]), limits());
        // The rim 0.01 m inside the closest approach, heading a little toward the face.
        let rim = DwaConfig::default().closest_approach() - 0.01;
        let mut pose = mole_types::Pose2::new(2.0 - limits().radius - rim, 1.0, 1.4);
        let gap = |d: &crate::Limited<Dwa>, p: &mole_types::Pose2| {
            d.inner().field.distance(p.x, p.y) - limits().radius
        };
        let mut last_command = Command::STOP;
        let (mut start, mut closest, mut travelled) = (f64::NAN, f64::INFINITY, 0.0);
        for tick in 0..400 {
            let input = PlannerInput {
                tick,
                dt: 0.05,
                pose,
                scan: None,
                tactile: None,
                grid: Some(&g),
                last_command,
            };
            let c = d.step(&input);
            last_command = c;
            if tick == 0 {
                start = gap(&d, &pose);
            }
            pose.theta += c.omega * 0.05;
            pose.x += c.v * pose.theta.cos() * 0.05;
            pose.y += c.v * pose.theta.sin() * 0.05;
            travelled += c.v.abs() * 0.05;
            closest = closest.min(gap(&d, &pose));
        }
        assert!((start - rim).abs() < 1e-9, "{start}");
        // It does move (along the wall, toward the aim)...
        assert!(travelled > 1.0, "{travelled}");
        // ...but never into the margin deeper than it started (within the arc's sag).
        assert!(
            closest > start - 0.005,
            "closest gap {closest}, start {start}"
        );
    }

    #[test]
    fn point_index_nearest_matches_brute_force() {
        let mut idx = PointIndex::new(200, 0.2);
        let pts: Vec<[f64; 2]> = (0..150)
            .map(|i| {
                let a = i as f64 * 0.7;
                [3.0 * a.cos() + 0.01 * i as f64, 2.0 * a.sin()]
            })
            .collect();
        for p in &pts {
            idx.push(*p);
        }
        idx.build();
        for q in [[0.0, 0.0], [2.9, 0.1], [-1.0, 1.9], [5.0, 5.0]] {
            let brute = pts
                .iter()
                .map(|p| (p[0] - q[0]).hypot(p[1] - q[1]))
                .fold(f64::INFINITY, f64::min);
            assert!((idx.nearest(q[0], q[1], f64::INFINITY) - brute).abs() < 1e-12);
            let capped = idx.nearest(q[0], q[1], 0.5);
            assert!(
                (capped - brute.min(0.5)).abs() < 1e-12,
                "{q:?} {capped} {brute}"
            );
        }
    }
}
