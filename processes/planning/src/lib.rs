//! Planning: APF, DWA, random walk, bounce-back, frontier selection (seed §1, §3-§5).
//!
//! Every planner implements [`Planner`]: the process main fills a [`PlannerInput`] from the
//! newest pose, scan, tactile forces and frontier grid, calls [`Planner::step`] once per
//! simulation step and writes the returned [`Command`] into the loaned `planning/cmd` sample.
//! The reactive layer [`bounce_back::BounceBack`] wraps any planner (seed §4: react at once, then
//! hand back and re-plan). [`planner_by_name`] builds the configured stack.
//!
//! Every command a planner returns is finite, within the speed limits and within the
//! acceleration limits relative to the previous command ([`RobotLimits::limit`]).

pub mod bounce_back;
pub mod obstacles;
pub mod random_walk;

pub use bounce_back::{BounceBack, BounceBackConfig, PositionUpdate, bounce_back_position};
pub use random_walk::{DiagonalStride, RandomWalk, RandomWalkConfig, WalkReport};

use mole_types::{Grid, MODE_IDLE, Pose2, RobotSpec, Scan, Tactile};
use thiserror::Error;

/// The planners [`planner_by_name`] knows.
pub const KNOWN_PLANNERS: &[&str] = &["random-walk"];

/// Why a planner could not be built or a pure function could not run.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum PlanningError {
    /// `--planner NAME` names no planner this crate has.
    #[error("unknown planner `{name}`; known planners: {}", KNOWN_PLANNERS.join(", "))]
    UnknownPlanner {
        /// The name asked for.
        name: String,
    },
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
pub trait Planner {
    /// The name `--planner` selects it by.
    fn name(&self) -> &'static str;
    /// The command for this step; finite, within the speed limits, and within the acceleration
    /// limits relative to the previous command.
    fn step(&mut self, input: &PlannerInput) -> Command;
    /// Drop the current plan and choose a new one at the next step (seed §4 "path re-planning",
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
}

impl<P: Planner + ?Sized> Planner for Box<P> {
    fn name(&self) -> &'static str {
        (**self).name()
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
}

/// Whether a step can be planned at all: a finite pose and a positive, finite Δt.
pub(crate) fn usable(input: &PlannerInput) -> bool {
    input.pose.x.is_finite()
        && input.pose.y.is_finite()
        && input.pose.theta.is_finite()
        && input.dt.is_finite()
        && input.dt > 0.0
}

/// The stop command for an unusable input: brake toward (0, 0) as fast as the limits allow
/// (at once without a valid Δt, which gives no time base to ramp on).
pub(crate) fn stop_command(limits: &RobotLimits, prev: &Command, dt: f64) -> Command {
    if !(dt.is_finite() && dt > 0.0) {
        return Command::STOP;
    }
    let (v, omega) = limits.limit(prev, 0.0, 0.0, dt);
    Command {
        v,
        omega,
        mode: MODE_IDLE,
    }
}

/// Build the configured planner by name (`random-walk`: the seed §3 random walk inside the seed §4
/// bounce-back layer); an unknown name is an error listing the known ones.
pub fn planner_by_name(
    name: &str,
    limits: RobotLimits,
    seed: u64,
) -> Result<Box<dyn Planner>, PlanningError> {
    match name {
        "random-walk" => Ok(Box::new(BounceBack::new(
            RandomWalk::new(limits, RandomWalkConfig::default(), seed),
            limits,
            BounceBackConfig::default(),
        ))),
        _ => Err(PlanningError::UnknownPlanner {
            name: name.to_owned(),
        }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn limits() -> RobotLimits {
        RobotLimits {
            radius: 0.2,
            max_speed: 0.5,
            max_omega: 2.0,
            max_accel: 2.0,
            max_alpha: 8.0,
        }
    }

    #[test]
    fn unknown_planner_lists_the_known_ones() {
        let err = planner_by_name("teleport", limits(), 1).err();
        let text = err.map(|e| e.to_string()).unwrap_or_default();
        assert!(
            text.contains("teleport") && text.contains("random-walk"),
            "{text}"
        );
        let p = planner_by_name("random-walk", limits(), 1);
        assert_eq!(p.map(|p| p.name()).ok(), Some("random-walk"));
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
