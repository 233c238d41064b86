//! Planning: APF, DWA, random walk, bounce-back, frontier selection (algorithms §1, §3-§5).
//!
//! Every planner implements [`Planner`]: the process main fills a [`PlannerInput`] from the
//! newest pose, scan, tactile forces and frontier grid, calls [`Planner::step`] once per
//! simulation step and writes the returned [`Command`] into the loaned `planning/cmd` sample.
//! The reactive layer [`bounce_back::BounceBack`] wraps any planner (algorithms §4: react at once, then
//! hand back and re-plan). [`build_planner`] builds the configured stack.
//!
//! The planners and the reactive layer say what they wish to drive; the outermost layer,
//! [`Limited`], makes the one command that is sent: finite, within the speed limits and within
//! the acceleration limits relative to the command sent last ([`PlannerInput::last_command`],
//! [`RobotLimits::limit`]). It is the only place the limits are applied.

pub mod apf;
pub mod bounce_back;
pub mod distance_field;
pub mod dwa;
pub mod frontier;
pub mod global_path;
pub mod goal_seeker;
pub mod grid_search;
pub mod obstacles;
pub mod operator;
pub mod random_walk;
pub mod settings;

pub use apf::{Apf, ApfConfig, ApfForm};
pub use distance_field::DistanceField;
pub use dwa::{Critics, Dwa, DwaConfig, DwaCost};
pub use frontier::{FrontierConfig, FrontierExplorer};
pub use global_path::{GlobalPath, PathKind};
pub use goal_seeker::GoalSeeker;
pub use grid_search::GridSearch;
pub use operator::OperatorGoals;

pub use bounce_back::{BounceBack, BounceBackConfig, PositionUpdate, bounce_back_position};
pub use random_walk::{DiagonalStride, RandomWalk, RandomWalkConfig, WalkReport};
pub use settings::Settings;

/// docs/extending.md: its worked planner is compiled and run as a doctest of this crate.
#[cfg(doctest)]
#[doc = include_str!("../../../docs/extending.md")]
pub struct ExtendingGuide;

use mole_types::{
    Grid, MODE_IDLE, PlanStatus, PlannerKind, Pose2, RobotSpec, STATUS_HAS_GOAL, Scan, Tactile,
};
use thiserror::Error;

/// Why a planner could not be built or a pure function could not run.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum PlanningError {
    /// A parameter is NaN, infinite or outside its range.
    #[error("parameter `{name}` = {value} is out of range: {expected}")]
    InvalidParameter {
        /// The parameter.
        name: &'static str,
        /// Its value.
        value: f64,
        /// What it must be.
        expected: &'static str,
    },
    /// A planner that drives to no goal cannot follow a path.
    #[error("planner `{kind}` drives to no goal, so it cannot follow a path: expected one of {}", settings::goal_seekers().join(", "))]
    NotAFollower {
        /// The planner asked for.
        kind: PlannerKind,
    },
    /// A goal-seeking planner was asked for without a goal.
    #[error("planner `{kind}` needs a goal: pass `--goal X,Y` (or give the scenario a [goal])")]
    MissingGoal {
        /// The planner asked for.
        kind: PlannerKind,
    },
}

/// Robot body and motion limits, as `mole_types::RobotSpec` carries them.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RobotLimits {
    /// Disk radius r (m).
    pub radius: f64,
    /// |v| limit (m/s).
    pub max_speed: f64,
    /// |ω| limit (rad/s).
    pub max_omega: f64,
    /// |dv/dt| limit (m/s²); non-positive or non-finite means no limit.
    pub max_accel: f64,
    /// |dω/dt| limit (rad/s²); non-positive or non-finite means no limit.
    pub max_alpha: f64,
}

impl Default for RobotLimits {
    /// The robot of a scenario that sets none ([`RobotSpec::SCENARIO_DEFAULT`]).
    fn default() -> Self {
        Self::from(&RobotSpec::SCENARIO_DEFAULT)
    }
}

impl From<&RobotSpec> for RobotLimits {
    fn from(s: &RobotSpec) -> Self {
        Self {
            radius: s.radius,
            max_speed: s.max_speed,
            max_omega: s.max_omega,
            max_accel: s.max_accel,
            max_alpha: s.max_alpha,
        }
    }
}

impl RobotLimits {
    /// The limits with every bad value made safe: a non-finite or negative radius or speed
    /// limit becomes 0 (the robot does not move), a bad acceleration limit becomes "none".
    pub fn sanitized(self) -> Self {
        let non_negative = |x: f64| if x.is_finite() && x > 0.0 { x } else { 0.0 };
        let limit_or_none = |x: f64| {
            if x.is_finite() && x > 0.0 {
                x
            } else {
                f64::INFINITY
            }
        };
        Self {
            radius: non_negative(self.radius),
            max_speed: non_negative(self.max_speed),
            max_omega: non_negative(self.max_omega),
            max_accel: limit_or_none(self.max_accel),
            max_alpha: limit_or_none(self.max_alpha),
        }
    }

    /// The command closest to the desired (v, ω) that respects the speed limits and, relative to
    /// `prev`, the acceleration limits over `dt`. Non-finite wishes count as 0; a non-finite or
    /// non-positive `dt` gives no time base, so the command stays at `prev` (clamped to the speed
    /// limits).
    pub fn limit(&self, prev: &Command, v: f64, omega: f64, dt: f64) -> (f64, f64) {
        let dt = if dt.is_finite() && dt > 0.0 { dt } else { 0.0 };
        let finite_or_zero = |x: f64| if x.is_finite() { x } else { 0.0 };
        let (pv, pw) = (
            finite_or_zero(prev.v).clamp(-self.max_speed, self.max_speed),
            finite_or_zero(prev.omega).clamp(-self.max_omega, self.max_omega),
        );
        let dv = self.max_accel * dt;
        let dw = self.max_alpha * dt;
        // No limit (∞) times no time base (0) is NaN: then no change is allowed.
        let dv = if dv.is_nan() { 0.0 } else { dv };
        let dw = if dw.is_nan() { 0.0 } else { dw };
        let v = finite_or_zero(v)
            .clamp(-self.max_speed, self.max_speed)
            .clamp(pv - dv, pv + dv);
        let omega = finite_or_zero(omega)
            .clamp(-self.max_omega, self.max_omega)
            .clamp(pw - dw, pw + dw);
        (v, omega)
    }
}

/// What a planner sees each step. Every reference points into a loaned sample the caller owns.
#[derive(Debug, Clone, Copy)]
pub struct PlannerInput<'a> {
    /// Simulation step.
    pub tick: u64,
    /// Step length Δt (s).
    pub dt: f64,
    /// Estimated pose (localization/pose).
    pub pose: Pose2,
    /// Newest scan, robot frame; `None` (or 0 beams) without a lidar.
    pub scan: Option<&'a Scan>,
    /// Newest tactile forces, robot frame.
    pub tactile: Option<&'a Tactile>,
    /// Newest frontier grid (0 unexplored, 1 free, 2 occupied).
    pub grid: Option<&'a Grid>,
    /// The command the process sent last step ([`Command::STOP`] before the first): the
    /// robot's current velocity as far as planning knows, and what [`Limited`] limits against.
    pub last_command: Command,
}

/// A velocity command and the mode that produced it.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Command {
    /// Linear velocity v (m/s).
    pub v: f64,
    /// Angular velocity ω (rad/s).
    pub omega: f64,
    /// `mole_types::MODE_*` code.
    pub mode: u32,
}

impl Command {
    /// Standing still, idle.
    pub const STOP: Command = Command {
        v: 0.0,
        omega: 0.0,
        mode: MODE_IDLE,
    };
}

/// A motion planner: one command per step.
pub trait Planner: core::fmt::Debug {
    /// The kind `--planner` selects it by.
    fn kind(&self) -> PlannerKind;
    /// The (v, ω) this planner wishes to drive this step and its mode. Only the outermost layer,
    /// [`Limited`], limits it; a planner reads the robot's current velocity from
    /// [`PlannerInput::last_command`], never from its own previous wish.
    fn step(&mut self, input: &PlannerInput) -> Command;
    /// Drop the current plan and choose a new one at the next step (algorithms §4 "path re-planning",
    /// asked for by the reactive layer after a bounce-back).
    fn replan(&mut self) {}
    /// An obstacle was met at world heading `heading` (rad) from world point `at`: the reactive
    /// layer says so before it asks for a re-plan, so the planner can avoid that side for a while.
    fn obstacle_hint(&mut self, _at: [f64; 2], _heading: f64) {}
    /// Bounce-backs triggered so far (0 for a planner without a reactive layer).
    fn bounces(&self) -> u32 {
        0
    }
    /// The point the planner is heading for (world frame, m), for `planning/status`.
    fn target(&self) -> Option<[f64; 2]> {
        None
    }
    /// A new goal (world frame, m) from an operator (`operator/goal`), reached within
    /// `tolerance` (m; `None` keeps the current one). Returns whether this planner seeks goals
    /// (apf, dwa) and took it; an explorer ignores goals and returns false.
    fn set_goal(&mut self, _goal: [f64; 2], _tolerance: Option<f64>) -> bool {
        false
    }
    /// One step toward `carrot` (world, m) along `path` (the next points of a path it follows):
    /// how a goal seeker follows another planner's path (frontier's `--local-planner`). By
    /// default the carrot is its goal for this step.
    fn track(&mut self, input: &PlannerInput, carrot: [f64; 2], _path: &[[f64; 2]]) -> Command {
        self.set_goal(carrot, None);
        self.step(input)
    }
    /// Takes new settings while it runs (`mole param set`), keeping what it has (its goal,
    /// path, phase); `Err` says why it cannot. By default a planner takes none.
    fn set_settings(&mut self, _settings: &Settings) -> Result<(), String> {
        Err(format!("{} takes no settings while it runs", self.kind()))
    }
    /// Fills `planning/status` (everything but the header) after a step: `mode` is left as the
    /// caller set it ([`Limited`] writes the mode of the command it sent); by default
    /// goal = [`Planner::target`] with `STATUS_HAS_GOAL`, bounces, no frontier, no path.
    fn write_status(&self, status: &mut PlanStatus) {
        status.flags = 0;
        if let Some([x, y]) = self.target() {
            (status.goal_x, status.goal_y) = (x, y);
            status.flags |= STATUS_HAS_GOAL;
        } else {
            (status.goal_x, status.goal_y) = (0.0, 0.0);
        }
        (status.frontier_x, status.frontier_y) = (0.0, 0.0);
        status.bounces = self.bounces();
        status.n_path = 0;
    }
}

impl<P: Planner + ?Sized> Planner for Box<P> {
    fn kind(&self) -> PlannerKind {
        (**self).kind()
    }
    fn step(&mut self, input: &PlannerInput) -> Command {
        (**self).step(input)
    }
    fn replan(&mut self) {
        (**self).replan()
    }
    fn obstacle_hint(&mut self, at: [f64; 2], heading: f64) {
        (**self).obstacle_hint(at, heading)
    }
    fn bounces(&self) -> u32 {
        (**self).bounces()
    }
    fn target(&self) -> Option<[f64; 2]> {
        (**self).target()
    }
    fn set_goal(&mut self, goal: [f64; 2], tolerance: Option<f64>) -> bool {
        (**self).set_goal(goal, tolerance)
    }
    fn track(&mut self, input: &PlannerInput, carrot: [f64; 2], path: &[[f64; 2]]) -> Command {
        (**self).track(input, carrot, path)
    }
    fn set_settings(&mut self, settings: &Settings) -> Result<(), String> {
        (**self).set_settings(settings)
    }
    fn write_status(&self, status: &mut PlanStatus) {
        (**self).write_status(status)
    }
}

/// How much closer (m) than the goal tolerance a goal seeker's estimate must come before it
/// reports `MODE_ARRIVED` (at most half the tolerance): the world judges the true pose, and an
/// estimate a few millimetres off on the tolerance's edge ended runs the world did not count as
/// reached.
pub const ARRIVAL_MARGIN: f64 = 0.05;

/// Whether a goal seeker `distance` m from its goal (by its pose estimate) has arrived, for the
/// world's `tolerance` (see [`ARRIVAL_MARGIN`]).
pub(crate) fn arrived(distance: f64, tolerance: f64) -> bool {
    distance <= tolerance - ARRIVAL_MARGIN.min(0.5 * tolerance)
}

/// Whether a step can be planned at all: a finite pose and a positive, finite Δt.
pub(crate) fn usable(input: &PlannerInput) -> bool {
    input.pose.x.is_finite()
        && input.pose.y.is_finite()
        && input.pose.theta.is_finite()
        && input.dt.is_finite()
        && input.dt > 0.0
}

/// The outermost layer of every planner stack: the one place where a wish becomes the command
/// that is sent, limited ([`RobotLimits::limit`]) relative to [`PlannerInput::last_command`].
/// Without a valid Δt there is no time base to ramp on, so it stops at once.
#[derive(Debug, Clone)]
pub struct Limited<P: Planner> {
    inner: P,
    limits: RobotLimits,
    /// The mode of the command returned last, for `planning/status`.
    mode: u32,
}

impl<P: Planner> Limited<P> {
    /// Limits `inner`'s wishes to a robot with `limits`.
    pub fn new(inner: P, limits: RobotLimits) -> Self {
        Self {
            inner,
            limits: limits.sanitized(),
            mode: MODE_IDLE,
        }
    }

    /// The wrapped planner.
    pub fn inner(&self) -> &P {
        &self.inner
    }

    /// The wrapped planner, to adjust.
    pub fn inner_mut(&mut self) -> &mut P {
        &mut self.inner
    }
}

impl<P: Planner> Planner for Limited<P> {
    fn kind(&self) -> PlannerKind {
        self.inner.kind()
    }

    fn step(&mut self, input: &PlannerInput) -> Command {
        let wish = self.inner.step(input);
        let command = if input.dt.is_finite() && input.dt > 0.0 {
            let (v, omega) = self
                .limits
                .limit(&input.last_command, wish.v, wish.omega, input.dt);
            Command {
                v,
                omega,
                mode: wish.mode,
            }
        } else {
            Command::STOP
        };
        self.mode = command.mode;
        command
    }

    fn replan(&mut self) {
        self.inner.replan();
    }

    fn obstacle_hint(&mut self, at: [f64; 2], heading: f64) {
        self.inner.obstacle_hint(at, heading);
    }

    fn bounces(&self) -> u32 {
        self.inner.bounces()
    }

    fn target(&self) -> Option<[f64; 2]> {
        self.inner.target()
    }

    fn set_goal(&mut self, goal: [f64; 2], tolerance: Option<f64>) -> bool {
        self.inner.set_goal(goal, tolerance)
    }

    fn set_settings(&mut self, settings: &Settings) -> Result<(), String> {
        self.inner.set_settings(settings)
    }

    /// The wrapped planner's status with the mode of the command sent.
    fn write_status(&self, status: &mut PlanStatus) {
        self.inner.write_status(status);
        status.mode = self.mode;
    }
}

/// What a run asks of the planning process (`--planner`, `--goal`, `--local-planner`, the
/// seed); how each planner is tuned is its [`Settings`]. See [`build_planner`].
#[derive(Debug, Clone, PartialEq)]
pub struct PlannerConfig {
    /// Which planner.
    pub kind: PlannerKind,
    /// Goal (world, m): required by the planners that drive to one (apf, dwa).
    pub goal: Option<(f64, f64)>,
    /// The goal counts as reached within this distance (m): the world's own tolerance
    /// (`WorldMap::goal_tolerance`), so that planner and world agree (the planner reports
    /// `MODE_ARRIVED` [`ARRIVAL_MARGIN`] inside it). `None` keeps the settings' tolerance.
    pub goal_tolerance: Option<f64>,
    /// The goal seeker that follows frontier's paths.
    pub local: PlannerKind,
    /// Seed of every random stream.
    pub seed: u64,
    /// Every planner's tuning.
    pub settings: Settings,
}

impl PlannerConfig {
    /// Planner `kind` with the default settings, DWA following frontier's paths.
    pub fn new(kind: PlannerKind) -> Self {
        Self {
            kind,
            goal: None,
            goal_tolerance: None,
            local: PlannerKind::Dwa,
            seed: 0,
            settings: Settings::default(),
        }
    }

    /// With the run's goal (`goal`, else the world's) and the world's goal tolerance.
    pub fn with_world_goal(mut self, map: &mole_types::WorldMap, goal: Option<(f64, f64)>) -> Self {
        let has_goal = map.has_goal == 1;
        self.goal = goal.or(has_goal.then_some((map.goal_x, map.goal_y)));
        self.goal_tolerance = has_goal.then_some(map.goal_tolerance);
        self
    }

    /// The settings with the world's goal tolerance in the goal seekers' when the planner is
    /// one (what [`build_planner`] and [`Planner::set_settings`] take). An explorer's follower
    /// keeps its own: it arrives at carrots, not at the world's goal.
    pub fn tuned(&self) -> Settings {
        let mut s = self.settings;
        let world = self.goal_tolerance.filter(|t| t.is_finite() && *t > 0.0);
        if let Some(t) = world.filter(|_| self.kind.needs_goal()) {
            s.apf.goal_tolerance = t;
            s.dwa.goal_tolerance = t;
        }
        s
    }
}

/// The planner `config` names, for the robot and sensors of `map`: refused, with the reason, when
/// the world lacks a sensor it needs or the configuration cannot build it (a missing goal). Bad
/// input for a process: running it again cannot help.
pub fn build_planner_for(
    config: &PlannerConfig,
    map: &mole_types::WorldMap,
) -> Result<Box<dyn Planner>, String> {
    if let Some(why) = config.kind.refuses_sensors(&map.sensors, "this world") {
        return Err(why);
    }
    build_planner(config, RobotLimits::from(&map.robot)).map_err(|e| e.to_string())
}

/// A planner the registry builds: one row of [`mole_types::planners!`] names its type.
pub trait Registered: Planner + Sized + 'static {
    /// Built with `settings` for a robot with `limits`; `goal` is given to a planner that needs
    /// one (`PlannerKind::needs_goal`), `seed` seeds its random streams, and `local` is the goal
    /// seeker that follows a path it plans.
    fn build(
        settings: &Settings,
        limits: RobotLimits,
        goal: Option<[f64; 2]>,
        local: Option<Box<dyn Planner>>,
        seed: u64,
    ) -> Result<Self, PlanningError>;

    /// The reactive layer under it: `[planning.bounce-back]` as set.
    fn bounce_back(settings: &Settings) -> BounceBackConfig {
        settings.bounce_back
    }
}

/// [`build_planner`]'s dispatch, from the table of planners (`mole_types::planners!`).
macro_rules! registry {
    ($( $(#[$meta:meta])* $variant:ident = ($name:literal, $code:literal, $ty:ident, $needs:ident) ),+ $(,)?) => {
        /// Planner `kind` alone, without the layers around it.
        fn bare(
            kind: PlannerKind,
            settings: &Settings,
            limits: RobotLimits,
            goal: Option<[f64; 2]>,
            local: Option<Box<dyn Planner>>,
            seed: u64,
        ) -> Result<Box<dyn Planner>, PlanningError> {
            Ok(match kind {
                $( PlannerKind::$variant => {
                    Box::new(<$ty as Registered>::build(settings, limits, goal, local, seed)?)
                } )+
            })
        }

        /// The reactive layer under planner `kind`.
        pub(crate) fn bounce_back_of(kind: PlannerKind, settings: &Settings) -> BounceBackConfig {
            match kind {
                $( PlannerKind::$variant => <$ty as Registered>::bounce_back(settings), )+
            }
        }
    };
}
mole_types::planners!(registry);

/// Builds the configured planner inside the bounce-back layer (algorithms §4) inside
/// [`Limited`]: a goal seeker toward `config.goal` (an error naming `--goal X,Y` without one),
/// re-planned after a bounce by `settings.replan_with` if set; an explorer with `config.local`
/// following its paths.
pub fn build_planner(
    config: &PlannerConfig,
    limits: RobotLimits,
) -> Result<Box<dyn Planner>, PlanningError> {
    let settings = config.tuned();
    let kind = config.kind;
    let goal = match config.goal.filter(|g| g.0.is_finite() && g.1.is_finite()) {
        Some(g) => Some([g.0, g.1]),
        None if kind.needs_goal() => return Err(PlanningError::MissingGoal { kind }),
        None => None,
    };
    // A path to follow is aimed at by its carrot, step by step: the follower's own goal is a
    // placeholder until the first step.
    let follower = |which: PlannerKind| {
        if !which.needs_goal() {
            return Err(PlanningError::NotAFollower { kind: which });
        }
        bare(
            which,
            &settings,
            limits,
            Some([0.0, 0.0]),
            None,
            config.seed,
        )
    };
    let local = match kind.needs_range_sensor() {
        true => Some(follower(config.local)?),
        false => None,
    };
    let primary = bare(kind, &settings, limits, goal, local, config.seed)?;
    let inner = match (goal, settings.replan_with) {
        (Some(goal), Some(with)) if with != kind => {
            let replanner = bare(with, &settings, limits, Some(goal), None, config.seed)?;
            Box::new(GoalSeeker::new(primary, replanner, settings.replan_time))
        }
        _ => primary,
    };
    Ok(Box::new(Limited::new(
        BounceBack::new(inner, limits, bounce_back_of(kind, &settings)),
        limits,
    )))
}

/// Builds planner `kind` with every default and no goal (`apf` and `dwa` then fail with
/// [`PlanningError::MissingGoal`]).
pub fn planner_by_kind(
    kind: PlannerKind,
    limits: RobotLimits,
    seed: u64,
) -> Result<Box<dyn Planner>, PlanningError> {
    build_planner(
        &PlannerConfig {
            seed,
            ..PlannerConfig::new(kind)
        },
        limits,
    )
}

/// Copies a path (world frame, m) into `PlanStatus::path`, as many waypoints as fit.
pub(crate) fn write_path(status: &mut mole_types::PlanStatus, path: &[[f64; 2]]) {
    let n = path.len().min(mole_types::MAX_PATH);
    for (out, p) in status.path.iter_mut().zip(&path[..n]) {
        *out = [p[0] as f32, p[1] as f32];
    }
    status.n_path = n as u32;
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn limits() -> RobotLimits {
        RobotLimits::default()
    }

    /// Every kind builds (the goal seekers with a goal, and say which kind lacks one without),
    /// and the stack it builds reports that kind.
    #[test]
    fn every_kind_builds_and_reports_its_kind() {
        for &kind in PlannerKind::ALL {
            let built = planner_by_kind(kind, limits(), 1);
            if kind.needs_goal() {
                let err = built.err().map(|e| e.to_string()).unwrap_or_default();
                assert!(err.contains(kind.name()) && err.contains("--goal"), "{err}");
            }
            let config = PlannerConfig {
                goal: Some((1.0, 2.0)),
                ..PlannerConfig::new(kind)
            };
            let p = build_planner(&config, limits()).unwrap_or_else(|e| panic!("{e}"));
            assert_eq!(p.kind(), kind);
        }
    }

    /// Every kind, alone or re-planned by a goal seeker, takes new settings while it runs
    /// (`mole param set`) and keeps its goal.
    #[test]
    fn every_kind_takes_new_settings_and_keeps_its_goal() {
        let mut changed = Settings::default();
        (
            changed.dwa.critics.heading,
            changed.apf.c,
            changed.random_walk.stride,
        ) = (0.4, 2.0, 0.6);
        changed.frontier.alpha = 0.5;
        for &kind in PlannerKind::ALL {
            for replan_with in [None, Some(PlannerKind::Apf)] {
                let mut config = PlannerConfig {
                    goal: Some((1.0, 2.0)),
                    ..PlannerConfig::new(kind)
                };
                config.settings.replan_with = replan_with.filter(|_| kind.needs_goal());
                let mut p = build_planner(&config, limits()).unwrap_or_else(|e| panic!("{e}"));
                let target = p.target();
                assert_eq!(p.set_settings(&changed), Ok(()), "{kind}, {replan_with:?}");
                assert_eq!(p.target(), target, "{kind}");
            }
        }
    }

    /// Under the DWA the reactive layer fires only where the DWA never drives: its range trigger
    /// lies the lidar-noise allowance below the DWA's closest approach, for `dwa` and `frontier`.
    #[test]
    fn the_trigger_under_the_dwa_is_derived_from_its_margin() {
        let settings = Settings::default();
        for kind in [PlannerKind::Dwa, PlannerKind::Frontier] {
            let d_th = bounce_back_of(kind, &settings).d_th();
            let closest = settings.dwa.closest_approach();
            assert!(d_th > 0.0, "{kind:?}: d_th {d_th}");
            assert!(
                d_th + bounce_back::TRIGGER_NOISE <= closest + 1e-12,
                "{kind:?}: d_th {d_th}, closest approach {closest}"
            );
        }
        let wide = DwaConfig {
            safety_margin: 0.2,
            ..DwaConfig::default()
        };
        let bb = BounceBackConfig::default().under_dwa(&wide);
        assert!((bb.d_th() - (wide.closest_approach() - bounce_back::TRIGGER_NOISE)).abs() < 1e-12);
        assert!(bb.d_release() > bb.d_th());
        // A trigger the settings name stays as set.
        let set = BounceBackConfig {
            d_th: Some(0.2),
            ..BounceBackConfig::default()
        }
        .under_dwa(&wide);
        assert_eq!(set.d_th(), 0.2);
        assert!((set.d_release() - 0.29).abs() < 1e-12);
        assert_eq!(bounce_back_of(PlannerKind::Apf, &settings).d_th(), 0.15);
    }

    /// Always wishes full speed ahead.
    #[derive(Debug)]
    struct FullAhead;

    impl Planner for FullAhead {
        fn kind(&self) -> PlannerKind {
            PlannerKind::RandomWalk
        }
        fn step(&mut self, _input: &PlannerInput) -> Command {
            Command {
                v: 9.0,
                omega: 0.0,
                mode: mole_types::MODE_EXPLORE,
            }
        }
    }

    /// The one limit is relative to the command sent last, not to what the stack returned
    /// before: told the robot already drives at 0.4 m/s, it may ask for 0.42 m/s at once.
    #[test]
    fn the_limit_is_relative_to_the_command_sent() {
        let mut p = Limited::new(FullAhead, limits());
        let input = |last_command| PlannerInput {
            tick: 0,
            dt: 0.01,
            pose: Pose2::new(1.0, 1.0, 0.0),
            scan: None,
            tactile: None,
            grid: None,
            last_command,
        };
        let first = p.step(&input(Command::STOP));
        assert!((first.v - 0.02).abs() < 1e-12, "{first:?}");
        let cruising = Command {
            v: 0.4,
            ..Command::STOP
        };
        let c = p.step(&input(cruising));
        assert!((c.v - 0.42).abs() < 1e-12, "{c:?}");
        let mut status: Box<PlanStatus> = bytemuck::zeroed_box();
        p.write_status(&mut status);
        assert_eq!(status.mode, mole_types::MODE_EXPLORE);
    }

    #[test]
    fn limit_clamps_speed_and_acceleration() {
        let l = limits();
        let prev = Command {
            v: 0.1,
            omega: 0.0,
            mode: 0,
        };
        // 2 m/s² × 0.01 s = 0.02 m/s per step; 8 rad/s² × 0.01 s = 0.08 rad/s per step.
        let (v, w) = l.limit(&prev, 10.0, -10.0, 0.01);
        assert!(
            (v - 0.12).abs() < 1e-12 && (w + 0.08).abs() < 1e-12,
            "{v} {w}"
        );
        let (v, w) = l.limit(&prev, f64::NAN, f64::INFINITY, 0.01);
        assert!((v - 0.08).abs() < 1e-12 && w == 0.0, "{v} {w}");
        // No time base: hold.
        assert_eq!(l.limit(&prev, 0.5, 1.0, f64::NAN), (0.1, 0.0));
        // A previous command above the speed limit is pulled back in at once.
        let fast = Command {
            v: 3.0,
            omega: -9.0,
            mode: 0,
        };
        let (v, w) = l.limit(&fast, 3.0, -9.0, 0.01);
        assert_eq!((v, w), (0.5, -2.0));
    }

    /// Drives `planner` from `pose` for `steps` steps of 0.05 s on a free 6 m × 6 m grid, moving
    /// the robot exactly as commanded (a unicycle); returns the final pose.
    fn drive(planner: &mut dyn Planner, mut pose: Pose2, steps: u64) -> Pose2 {
        let grid = crate::obstacles::test_support::grid_free(120, 120, 0.05);
        let dt = 0.05;
        let mut last_command = Command::STOP;
        for tick in 0..steps {
            let c = planner.step(&PlannerInput {
                tick,
                dt,
                pose,
                scan: None,
                tactile: None,
                grid: Some(&grid),
                last_command,
            });
            pose = Pose2::new(
                pose.x + c.v * pose.theta.cos() * dt,
                pose.y + c.v * pose.theta.sin() * dt,
                pose.theta + c.omega * dt,
            );
            last_command = c;
        }
        pose
    }

    /// A goal seeker (apf, dwa, and dwa re-planned by apf) handed an operator's goal behind it
    /// turns round and closes on it, and reports it in `planning/status`; left with its old
    /// goal it drives away from that point. The explorers take no goal.
    #[test]
    fn a_goal_seeker_heads_for_a_new_goal_and_an_explorer_ignores_it() {
        let (old, new) = ((5.0, 3.0), [1.0, 3.0]);
        let distance = |p: Pose2| (p.x - new[0]).hypot(p.y - new[1]);
        let seekers = [
            (PlannerKind::Apf, None),
            (PlannerKind::Dwa, None),
            (PlannerKind::Dwa, Some(PlannerKind::Apf)),
        ];
        for (kind, replan_with) in seekers {
            let mut config = PlannerConfig {
                goal: Some(old),
                ..PlannerConfig::new(kind)
            };
            config.settings.replan_with = replan_with;
            let build = || build_planner(&config, limits()).unwrap_or_else(|e| panic!("{e}"));
            let (mut redirected, mut left) = (build(), build());
            // Under way toward the old goal, heading +x.
            let under_way = drive(&mut redirected, Pose2::new(3.0, 3.0, 0.0), 20);
            drive(&mut left, Pose2::new(3.0, 3.0, 0.0), 20);
            assert!(
                redirected.set_goal(new, Some(0.2)),
                "{kind} {replan_with:?}"
            );
            let there = drive(&mut redirected, under_way, 300);
            let away = drive(&mut left, under_way, 300);
            let label = format!("{kind} {replan_with:?}: from {under_way:?}");
            assert!(
                distance(under_way) > 2.0 && distance(there) < 0.5,
                "{label} to {there:?}"
            );
            assert!(
                distance(away) > distance(under_way),
                "{label}, left: {away:?}"
            );
            let mut status: Box<PlanStatus> = bytemuck::zeroed_box();
            redirected.write_status(&mut status);
            assert_eq!([status.goal_x, status.goal_y], new, "{label}");
            assert_ne!(status.flags & STATUS_HAS_GOAL, 0, "{label}");
        }
        for kind in [PlannerKind::RandomWalk, PlannerKind::Frontier] {
            let mut explorer = planner_by_kind(kind, limits(), 1).unwrap();
            assert!(!explorer.set_goal(new, None), "{kind}");
            assert_eq!(explorer.target(), None, "{kind}");
        }
    }

    #[test]
    fn bad_limits_are_sanitized() {
        let l = RobotLimits {
            radius: f64::NAN,
            max_speed: -1.0,
            max_omega: f64::INFINITY,
            max_accel: 0.0,
            max_alpha: f64::NAN,
        }
        .sanitized();
        assert_eq!((l.radius, l.max_speed, l.max_omega), (0.0, 0.0, 0.0));
        assert!(l.max_accel.is_infinite() && l.max_alpha.is_infinite());
        let (v, w) = l.limit(&Command::STOP, 1.0, 1.0, 0.01);
        assert_eq!((v, w), (0.0, 0.0));
    }

    proptest! {
        #[test]
        fn limited_commands_stay_inside_the_limits(
            pv in -1.0f64..1.0, pw in -3.0f64..3.0, v in -5.0f64..5.0, w in -9.0f64..9.0,
            dt in 0.001f64..0.2,
        ) {
            let l = limits();
            let prev = Command { v: pv.clamp(-0.5, 0.5), omega: pw.clamp(-2.0, 2.0), mode: 0 };
            let (nv, nw) = l.limit(&prev, v, w, dt);
            prop_assert!(nv.abs() <= l.max_speed && nw.abs() <= l.max_omega);
            prop_assert!((nv - prev.v).abs() <= l.max_accel * dt + 1e-12);
            prop_assert!((nw - prev.omega).abs() <= l.max_alpha * dt + 1e-12);
        }
    }
}
