//! Goal seeking with a configurable re-planner after a bounce-back (algorithms §4: "path
//! re-planning" after the reactive layer's bounce, by APF or DWA).
//!
//! [`GoalSeeker`] drives toward the goal with its primary local planner; when the bounce-back
//! layer asks for a re-plan ([`Planner::replan`]), the configured re-planner takes over for
//! `replan_time` seconds, then hands back to the primary (which re-plans too). Both planners are
//! built up front, so switching allocates nothing; both read the robot's velocity from the
//! command sent last, whichever planner made it.

use crate::apf::{Apf, ApfConfig};
use crate::dwa::{Dwa, DwaConfig};
use crate::{Command, LocalPlanner, Planner, PlannerInput, RobotLimits};
use mole_types::{PlanStatus, PlannerKind};

/// A goal-seeking planner whose re-planning after a bounce is APF or DWA. See the module docs.
#[derive(Debug, Clone)]
pub struct GoalSeeker {
    primary: LocalPlanner,
    replanner: LocalPlanner,
    replan_time: f64,
    dwa: Dwa,
    apf: Apf,
    active: LocalPlanner,
    /// Seconds the re-planner still drives.
    remaining: f64,
    pending: bool,
    /// Whether the re-planner has seen a step (its buffers sized to the grid).
    warmed: bool,
}

impl GoalSeeker {
    /// `primary` toward `goal`; after a bounce `replanner` drives for `replan_time` s
    /// (non-finite or negative: 0, i.e. the primary re-plans at once).
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        limits: RobotLimits,
        goal: [f64; 2],
        primary: LocalPlanner,
        replanner: LocalPlanner,
        replan_time: f64,
        dwa: DwaConfig,
        apf: ApfConfig,
        seed: u64,
    ) -> Self {
        let limits = limits.sanitized();
        Self {
            primary,
            replanner,
            replan_time: if replan_time.is_finite() && replan_time > 0.0 {
                replan_time
            } else {
                0.0
            },
            dwa: Dwa::new(limits, dwa, goal),
            apf: Apf::new(limits, apf, goal, seed),
            active: primary,
            remaining: 0.0,
            pending: false,
            warmed: false,
        }
    }

    /// The local planner driving now.
    pub fn active(&self) -> LocalPlanner {
        self.active
    }

    fn planner(&mut self, which: LocalPlanner) -> &mut dyn Planner {
        match which {
            LocalPlanner::Dwa => &mut self.dwa,
            LocalPlanner::Apf => &mut self.apf,
        }
    }
}

impl Planner for GoalSeeker {
    fn kind(&self) -> PlannerKind {
        match self.primary {
            LocalPlanner::Dwa => PlannerKind::Dwa,
            LocalPlanner::Apf => PlannerKind::Apf,
        }
    }

    fn step(&mut self, input: &PlannerInput) -> Command {
        if !self.warmed && input.grid.is_some() {
            // Size the re-planner's buffers now, not on its first turn in steady state.
            self.warmed = true;
            let r = self.replanner;
            if r != self.primary {
                self.planner(r).step(input);
                self.planner(r).replan();
            }
        }
        if self.pending {
            self.pending = false;
            self.active = self.replanner;
            self.remaining = self.replan_time;
            let r = self.replanner;
            self.planner(r).replan();
        }
        if self.active != self.primary {
            if self.remaining <= 0.0 {
                self.active = self.primary;
                let p = self.primary;
                self.planner(p).replan();
            } else if input.dt.is_finite() && input.dt > 0.0 {
                self.remaining -= input.dt;
            }
        }
        let a = self.active;
        self.planner(a).step(input)
    }

    fn replan(&mut self) {
        if self.replanner == self.primary || self.replan_time <= 0.0 {
            let p = self.primary;
            self.planner(p).replan();
        } else {
            self.pending = true;
        }
    }

    fn obstacle_hint(&mut self, at: [f64; 2], heading: f64) {
        self.dwa.obstacle_hint(at, heading);
        self.apf.obstacle_hint(at, heading);
    }

    fn target(&self) -> Option<[f64; 2]> {
        Some(self.dwa.goal())
    }

    /// Both local planners head for the new goal, whichever drives now.
    fn set_goal(&mut self, goal: [f64; 2], tolerance: Option<f64>) -> bool {
        self.dwa.set_goal(goal, tolerance) & self.apf.set_goal(goal, tolerance)
    }

    fn write_status(&self, status: &mut PlanStatus) {
        match self.active {
            LocalPlanner::Dwa => self.dwa.write_status(status),
            LocalPlanner::Apf => self.apf.write_status(status),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Limited;
    use crate::obstacles::test_support::grid_free;

    #[test]
    fn the_replanner_drives_after_a_bounce_then_hands_back() {
        let limits = RobotLimits {
            radius: 0.2,
            max_speed: 0.5,
            max_omega: 2.0,
            max_accel: 2.0,
            max_alpha: 8.0,
        };
        let g = grid_free(60, 60, 0.05);
        let seeker = GoalSeeker::new(
            limits,
            [2.5, 2.5],
            LocalPlanner::Dwa,
            LocalPlanner::Apf,
            1.0,
            DwaConfig::default(),
            ApfConfig::default(),
            3,
        );
        // Whichever planner drives, the command sent stays within the acceleration limit of
        // the one sent before.
        let mut s = Limited::new(seeker, limits);
        let input = |tick, last_command| PlannerInput {
            tick,
            dt: 0.05,
            pose: mole_types::Pose2::new(0.5, 0.5, 0.0),
            scan: None,
            tactile: None,
            grid: Some(&g),
            last_command,
        };
        let mut prev = Command::STOP;
        let mut active = Vec::new();
        for tick in 0..60 {
            if tick == 10 {
                s.replan();
            }
            let c = s.step(&input(tick, prev));
            assert!(
                (c.v - prev.v).abs() <= 2.0 * 0.05 + 1e-9,
                "{c:?} after {prev:?}"
            );
            prev = c;
            active.push(s.inner().active());
        }
        assert_eq!(s.kind(), PlannerKind::Dwa);
        assert!(active[..10].iter().all(|a| *a == LocalPlanner::Dwa));
        // APF for 1 s = 20 steps (+1 for the hand-back step), then DWA again.
        let apf = active.iter().filter(|a| **a == LocalPlanner::Apf).count();
        assert!((20..=22).contains(&apf), "{apf}");
        assert_eq!(active.last(), Some(&LocalPlanner::Dwa));
    }
}
