//! Reactive bounce-back (algorithms §4.1) with docs/errata.md, as a layer around any [`Planner`].
//!
//! Trigger: d_obs < d_th, d_obs being the nearest scan range minus the robot radius in the
//! direction of travel, or any tactile sensor above its force threshold. Then reverse,
//! v ← −α·v (at least a minimum speed) for a fixed time, turn toward the freest direction (away
//! from the obstacle), and hand control back to the wrapped planner with [`Planner::replan`].
//! Hysteresis: the range trigger re-arms only once d_obs rises above d_release > d_th, or after
//! a cooldown, so the robot does not chatter at the threshold. The robot's velocity is the
//! command sent last ([`PlannerInput::last_command`]); like the planners, this layer returns a
//! wish, limited once by [`crate::Limited`] around it.

use crate::obstacles::{contact_force, free_travel, freest_direction, nearest_obstacle};
use crate::{Command, DwaConfig, Planner, PlannerInput, RobotLimits, usable};
use core::f64::consts::{FRAC_PI_2, FRAC_PI_3, PI};
use mole_types::Setting;
use mole_types::{MODE_BOUNCE_BACK, PlannerKind, wrap_angle};
use serde::{Deserialize, Serialize};

/// Algorithms §4.1: the bounced velocity (v_x, v_y)(t+1) = −α·(v_x, v_y)(t), α ∈ (0, 1].
pub fn bounce_back_velocity(v: [f64; 2], alpha: f64) -> [f64; 2] {
    [-alpha * v[0], -alpha * v[1]]
}

/// Which position update [`bounce_back_position`] uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum PositionUpdate {
    /// The source's (x, y)(t+1) = −α·(v_x, v_y)(t)·Δt, which drops x(t) (docs/errata.md).
    Source,
    /// (x, y)(t+1) = (x, y)(t) − α·(v_x, v_y)(t)·Δt.
    #[default]
    Corrected,
}

/// Algorithms §4.1's position update after a bounce-back, in the source's form or the corrected one.
pub fn bounce_back_position(
    x: [f64; 2],
    v: [f64; 2],
    alpha: f64,
    dt: f64,
    form: PositionUpdate,
) -> [f64; 2] {
    let [vx, vy] = bounce_back_velocity(v, alpha);
    match form {
        PositionUpdate::Source => [vx * dt, vy * dt],
        PositionUpdate::Corrected => [x[0] + vx * dt, x[1] + vy * dt],
    }
}

/// What the range trigger under the DWA allows for lidar noise (m): d_obs is the shortest raw
/// range in its sector, which reads up to about 3 σ short of the true gap at the default
/// σ = 0.01 m (`sensors.lidar.range_std`).
pub const TRIGGER_NOISE: f64 = 0.03;

/// d_th when the settings leave it to the layer, not under the DWA (m).
const DEFAULT_D_TH: f64 = 0.15;
/// d_release − d_th when the settings leave d_release to the layer, not under the DWA (m).
const DEFAULT_HYSTERESIS: f64 = 0.2;
/// d_release − d_th under the DWA (m).
const HYSTERESIS_UNDER_DWA: f64 = 0.09;

/// Settings of the bounce-back layer (`[planning.bounce-back]`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, Setting)]
#[serde(default, deny_unknown_fields)]
pub struct BounceBackConfig {
    /// Trigger threshold d_th on d_obs (m). Unset: 0.15 m, and under the DWA (`dwa`,
    /// `frontier`) 0.03 m below the closest gap the DWA drives to.
    #[setting(min = 0.0)]
    #[serde(skip_serializing_if = "Option::is_none")]
    pub d_th: Option<f64>,
    /// Re-arm threshold d_release > d_th (m): the hysteresis band is [d_th, d_release]. Unset:
    /// d_th + 0.2 m, under the DWA d_th + 0.09 m.
    #[setting(min = 0.0)]
    #[serde(skip_serializing_if = "Option::is_none")]
    pub d_release: Option<f64>,
    /// The trigger re-arms anyway this long (s) after a bounce-back ended.
    #[setting(min = 0.0)]
    pub cooldown: f64,
    /// α ∈ (0, 1]: reverse at α·|v|.
    #[setting(above = 0.0, max = 1.0)]
    pub alpha: f64,
    /// Reverse at least this fast (m/s), so a bounce from standstill still backs off.
    #[setting(min = 0.0)]
    pub min_reverse_speed: f64,
    /// How long to reverse (s).
    #[setting(min = 0.0)]
    pub reverse_time: f64,
    /// Turn until the heading is within this of the freest direction (rad)...
    #[setting(above = 0.0)]
    pub turn_tolerance: f64,
    /// ...or for at most this long (s).
    #[setting(min = 0.0)]
    pub turn_timeout: f64,
    /// Proportional heading gain of the turn (1/s).
    #[setting(above = 0.0)]
    pub k_heading: f64,
    /// A tactile sensor touches when its |f| exceeds this (N).
    #[setting(min = 0.0)]
    pub force_threshold: f64,
    /// d_obs looks at the beams within this angle (rad) of the direction of travel; π takes
    /// every beam (the source's form), which lets walls beside the robot trigger it.
    #[setting(above = 0.0, max = PI)]
    pub sector_half_angle: f64,
    /// Half-width (rad) of the neighbourhood whose shortest beam scores a direction as free.
    #[setting(min = 0.0)]
    pub free_window: f64,
    /// Between bounces, cap the wrapped planner's speed so it can brake to a stop d_stop (m)
    /// short of the first obstacle in its path: the source flips v at once, a robot with an acceleration
    /// limit cannot, so without the cap it would hit before the reversal takes hold.
    #[setting(min = 0.0)]
    pub d_stop: f64,
}

impl Default for BounceBackConfig {
    fn default() -> Self {
        Self {
            d_th: None,
            d_release: None,
            cooldown: 3.0,
            alpha: 0.5,
            min_reverse_speed: 0.1,
            reverse_time: 0.8,
            turn_tolerance: 0.15,
            turn_timeout: 3.0,
            k_heading: 3.0,
            force_threshold: 0.5,
            sector_half_angle: FRAC_PI_3,
            free_window: 0.26,
            d_stop: 0.05,
        }
    }
}

impl BounceBackConfig {
    /// The reactive layer under the DWA `dwa`, its last resort only (algorithms §4): unless the
    /// settings say otherwise, the range trigger d_th sits [`TRIGGER_NOISE`] below the closest
    /// gap the DWA drives to ([`DwaConfig::closest_approach`]), so the DWA alone never drives
    /// where it fires (a DWA margin under the noise leaves the touch alone); it re-arms 0.09 m
    /// further out (0.12 m at the default margin).
    #[must_use]
    pub fn under_dwa(self, dwa: &DwaConfig) -> Self {
        let d_th = self
            .d_th
            .unwrap_or((dwa.closest_approach() - TRIGGER_NOISE).max(0.0));
        Self {
            d_th: Some(d_th),
            d_release: Some(self.d_release.unwrap_or(d_th + HYSTERESIS_UNDER_DWA)),
            ..self
        }
    }

    /// d_th (m), as set or by default.
    pub fn d_th(&self) -> f64 {
        self.d_th.unwrap_or(DEFAULT_D_TH)
    }

    /// d_release (m), as set or by default.
    pub fn d_release(&self) -> f64 {
        self.d_release.unwrap_or(self.d_th() + DEFAULT_HYSTERESIS)
    }

    /// The config with every non-finite or out-of-range field replaced by its default
    /// (α clamped into (0, 1], d_release kept above d_th).
    pub fn sanitized(self) -> Self {
        let d = Self::default();
        let pos = |x: f64, def: f64| if x.is_finite() && x > 0.0 { x } else { def };
        let non_neg = |x: f64, def: f64| if x.is_finite() && x >= 0.0 { x } else { def };
        let d_th = non_neg(self.d_th(), DEFAULT_D_TH);
        let d_release = non_neg(self.d_release(), d_th + DEFAULT_HYSTERESIS);
        let d_release = if d_release > d_th {
            d_release
        } else {
            d_th + DEFAULT_HYSTERESIS
        };
        Self {
            d_th: Some(d_th),
            d_release: Some(d_release),
            cooldown: pos(self.cooldown, d.cooldown),
            alpha: pos(self.alpha, d.alpha).min(1.0),
            min_reverse_speed: non_neg(self.min_reverse_speed, d.min_reverse_speed),
            reverse_time: non_neg(self.reverse_time, d.reverse_time),
            turn_tolerance: pos(self.turn_tolerance, d.turn_tolerance),
            turn_timeout: non_neg(self.turn_timeout, d.turn_timeout),
            k_heading: pos(self.k_heading, d.k_heading),
            force_threshold: non_neg(self.force_threshold, d.force_threshold),
            sector_half_angle: pos(self.sector_half_angle, d.sector_half_angle).min(PI),
            free_window: non_neg(self.free_window, d.free_window),
            d_stop: non_neg(self.d_stop, d.d_stop),
        }
    }
}

/// Where the bounce-back layer is in its cycle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Phase {
    /// Passing the wrapped planner's commands through; the trigger is armed.
    Armed,
    /// Backing away at `v_rev` since tick `start`; then turn to heading `target` (world, rad).
    /// `obstacle` is the world heading of the obstacle from `at`, where the bounce started.
    Reversing {
        start: u64,
        v_rev: f64,
        target: f64,
        obstacle: f64,
        at: [f64; 2],
    },
    /// Turning in place toward heading `target` (world, rad) since tick `start`.
    Turning {
        start: u64,
        target: f64,
        obstacle: f64,
        at: [f64; 2],
    },
    /// Passing through again since tick `since`; the range trigger waits for d_obs > d_release
    /// or the cooldown.
    Disarmed { since: u64 },
}

/// Algorithms §4 reactive bounce-back around a wrapped planner `P`.
#[derive(Debug, Clone)]
pub struct BounceBack<P: Planner> {
    inner: P,
    limits: RobotLimits,
    config: BounceBackConfig,
    phase: Phase,
    bounces: u32,
    /// The direction (robot frame) the wrapped planner wanted to drive in on the last step but
    /// could not: the speed cap held it d_stop short of an obstacle.
    blocked: Option<f64>,
}

/// Below this speed (m/s) the robot counts as standing: a disk turning in place cannot run into
/// anything, and −α·v has nothing to reverse, so the range trigger waits.
const MOVING: f64 = 0.01;

impl<P: Planner> BounceBack<P> {
    /// Wraps `inner` for a robot with `limits`.
    pub fn new(inner: P, limits: RobotLimits, config: BounceBackConfig) -> Self {
        Self {
            inner,
            limits: limits.sanitized(),
            config: config.sanitized(),
            phase: Phase::Armed,
            bounces: 0,
            blocked: None,
        }
    }

    /// Bounce-backs triggered so far.
    pub fn bounces(&self) -> u32 {
        self.bounces
    }

    /// Where the layer is in its cycle.
    pub fn phase(&self) -> Phase {
        self.phase
    }

    /// The wrapped planner.
    pub fn inner(&self) -> &P {
        &self.inner
    }

    /// The settings in use.
    pub fn config(&self) -> &BounceBackConfig {
        &self.config
    }

    /// Seconds from tick `since` to `tick` at step `dt` (0 if the clock went back).
    fn elapsed(tick: u64, since: u64, dt: f64) -> f64 {
        tick.saturating_sub(since) as f64 * dt
    }

    /// d_obs in the sector around robot-frame direction `dir`, with the nearest beam's angle.
    fn d_obs(&self, input: &PlannerInput, dir: f64) -> (f64, f64) {
        input
            .scan
            .and_then(|s| {
                nearest_obstacle(s, self.limits.radius, dir, self.config.sector_half_angle)
            })
            .map_or((f64::INFINITY, dir), |n| (n.d_obs, n.angle))
    }

    /// Starts a bounce-back: reverse away from the obstacle at robot-frame angle
    /// `obstacle`, at α·|v| (at least the minimum speed), then turn to the freest direction.
    fn trigger(&mut self, input: &PlannerInput, obstacle: f64, touch: Option<[f64; 2]>) {
        self.bounces = self.bounces.saturating_add(1);
        let c = obstacle.cos();
        let sent = input.last_command.v;
        let sign = if c > 0.2 {
            -1.0
        } else if c < -0.2 {
            1.0
        } else if sent > 0.0 {
            -1.0
        } else {
            1.0
        };
        let speed = (self.config.alpha * sent.abs())
            .max(self.config.min_reverse_speed)
            .min(self.limits.max_speed);
        let free = input
            .scan
            .and_then(|s| freest_direction(s, self.config.free_window, obstacle))
            .or_else(|| touch.map(|f| f[1].atan2(f[0])))
            .unwrap_or(obstacle + PI);
        self.phase = Phase::Reversing {
            start: input.tick,
            v_rev: sign * speed,
            target: wrap_angle(input.pose.theta + free),
            obstacle: wrap_angle(input.pose.theta + obstacle),
            at: [input.pose.x, input.pose.y],
        };
    }

    /// The wrapped planner's command with its speed capped so that it can still stop d_stop
    /// short of the first obstacle in its path: v ≤ √(2·(a/2)·(free travel − d_stop)).
    fn pass_through(&mut self, input: &PlannerInput) -> Command {
        let cmd = self.inner.step(input);
        let Some(scan) = input.scan else { return cmd };
        if !(self.limits.max_accel.is_finite() && cmd.v.is_finite()) {
            return cmd;
        }
        let dir = if cmd.v < 0.0 { PI } else { 0.0 };
        let free = free_travel(scan, dir, self.limits.radius);
        // Half the deceleration limit: the cap then binds before the limiter does, so the robot
        // tracks it despite the one-step lag between the scan and the motion.
        let cap = (self.limits.max_accel * (free - self.config.d_stop).max(0.0)).sqrt();
        if cmd.v.abs() > MOVING && cap < MOVING {
            self.blocked = Some(dir);
        }
        Command {
            v: cmd.v.clamp(-cap, cap),
            ..cmd
        }
    }
}

impl<P: Planner> Planner for BounceBack<P> {
    fn kind(&self) -> PlannerKind {
        self.inner.kind()
    }

    /// The layer's own settings as its planner takes it, then the planner's.
    fn set_settings(&mut self, settings: &crate::Settings) -> Result<(), String> {
        self.inner.set_settings(settings)?;
        self.config = crate::bounce_back_of(self.inner.kind(), settings);
        Ok(())
    }

    fn step(&mut self, input: &PlannerInput) -> Command {
        if !usable(input) {
            return Command::STOP;
        }
        let (tick, dt) = (input.tick, input.dt);
        let sent = input.last_command.v;
        let blocked = self.blocked.take();
        let moving = sent.abs() > MOVING || blocked.is_some();
        let travel = blocked.unwrap_or(if sent < 0.0 { PI } else { 0.0 });
        let (d_ahead, obstacle_angle) = self.d_obs(input, travel);
        let touch = input
            .tactile
            .and_then(|t| contact_force(t, self.config.force_threshold));
        // The obstacle lies against the force it exerts on the robot.
        let touch_angle = touch.map(|f| (-f[1]).atan2(-f[0]));
        let touch_ahead = touch_angle.is_some_and(|a| wrap_angle(a - travel).abs() < FRAC_PI_2);

        // Hysteresis: re-arm above d_release, or after the cooldown.
        if let Phase::Disarmed { since } = self.phase
            && (d_ahead > self.config.d_release()
                || Self::elapsed(tick, since, dt) >= self.config.cooldown)
        {
            self.phase = Phase::Armed;
        }
        // Trigger: when armed, d_obs < d_th while moving, or any touch; when not, a touch
        // against the travel, or the wrapped planner pressing on toward an obstacle it is held
        // short of (else it would wait there for the cooldown).
        match self.phase {
            Phase::Armed if touch_angle.is_some() => {
                self.trigger(input, touch_angle.unwrap_or(travel), touch);
            }
            Phase::Armed if moving && d_ahead < self.config.d_th() => {
                self.trigger(input, obstacle_angle, touch)
            }
            Phase::Disarmed { .. } if touch_ahead => {
                self.trigger(input, touch_angle.unwrap_or(travel), touch);
            }
            Phase::Disarmed { .. } if blocked.is_some() => self.trigger(input, travel, touch),
            _ => {}
        }
        // Reverse for the set time, or until something is in the way behind.
        if let Phase::Reversing {
            start,
            v_rev,
            target,
            obstacle,
            at,
        } = self.phase
        {
            let back = if v_rev < 0.0 { PI } else { 0.0 };
            let (d_back, _) = self.d_obs(input, back);
            let touch_back = touch_angle.is_some_and(|a| wrap_angle(a - back).abs() < FRAC_PI_2);
            if Self::elapsed(tick, start, dt) >= self.config.reverse_time
                || d_back < self.config.d_stop
                || touch_back
            {
                self.phase = Phase::Turning {
                    start: tick,
                    target,
                    obstacle,
                    at,
                };
            }
        }
        // Turn toward the freest direction, then hand back and ask for a new plan.
        if let Phase::Turning {
            start,
            target,
            obstacle,
            at,
        } = self.phase
            && (wrap_angle(target - input.pose.theta).abs() < self.config.turn_tolerance
                || Self::elapsed(tick, start, dt) >= self.config.turn_timeout)
        {
            self.inner.obstacle_hint(at, obstacle);
            self.inner.replan();
            self.phase = Phase::Disarmed { since: tick };
        }

        match self.phase {
            Phase::Reversing { v_rev, .. } => Command {
                v: v_rev,
                omega: 0.0,
                mode: MODE_BOUNCE_BACK,
            },
            Phase::Turning { target, .. } => {
                let e = wrap_angle(target - input.pose.theta);
                Command {
                    v: 0.0,
                    omega: self.config.k_heading * e,
                    mode: MODE_BOUNCE_BACK,
                }
            }
            Phase::Armed | Phase::Disarmed { .. } => self.pass_through(input),
        }
    }

    fn replan(&mut self) {
        self.inner.replan();
    }

    fn obstacle_hint(&mut self, at: [f64; 2], heading: f64) {
        self.inner.obstacle_hint(at, heading);
    }

    fn bounces(&self) -> u32 {
        self.bounces
    }

    fn target(&self) -> Option<[f64; 2]> {
        self.inner.target()
    }

    fn set_goal(&mut self, goal: [f64; 2], tolerance: Option<f64>) -> bool {
        self.inner.set_goal(goal, tolerance)
    }

    /// The wrapped planner's status with this layer's bounce count.
    fn write_status(&self, status: &mut mole_types::PlanStatus) {
        self.inner.write_status(status);
        status.bounces = self.bounces;
    }
}

#[cfg(test)]
mod tests;
