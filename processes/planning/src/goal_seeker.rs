//! Goal seeking with a configurable re-planner after a bounce-back (algorithms §4: "path
//! re-planning" after the reactive layer's bounce, by APF or DWA).
//!
//! [`GoalSeeker`] drives toward the goal with its primary local planner; when the bounce-back
//! layer asks for a re-plan ([`Planner::replan`]), the configured re-planner takes over for
//! `replan_time` seconds, then hands back to the primary (which re-plans too). Both planners are
//! built up front, so switching allocates nothing; both read the robot's velocity from the
//! command sent last, whichever planner made it.

use crate::{Command, Planner, PlannerInput};
use mole_types::{PlanStatus, PlannerKind};

/// A goal-seeking planner whose re-planning after a bounce is another goal seeker's (APF or
/// DWA). See the module docs.
#[derive(Debug)]
pub struct GoalSeeker {
    primary: Box<dyn Planner>,
    replanner: Box<dyn Planner>,
    replan_time: f64,
    /// Whether the re-planner drives now.
    replanning: bool,
    /// Seconds the re-planner still drives.
    remaining: f64,
    pending: bool,
    /// Whether the re-planner has seen a step (its buffers sized to the grid).
    warmed: bool,
}

impl GoalSeeker {
    /// `primary` toward its goal; after a bounce `replanner` (toward the same goal) drives for
    /// `replan_time` s (non-finite or negative: 0, i.e. the primary re-plans at once).
    pub fn new(primary: Box<dyn Planner>, replanner: Box<dyn Planner>, replan_time: f64) -> Self {
        Self {
            primary,
            replanner,
            replan_time: if replan_time.is_finite() && replan_time > 0.0 {
                replan_time
            } else {
                0.0
            },
            replanning: false,
            remaining: 0.0,
            pending: false,
            warmed: false,
        }
    }

    /// The planner driving now.
    pub fn active(&self) -> PlannerKind {
        self.driving().kind()
    }

    fn driving(&self) -> &dyn Planner {
        if self.replanning {
            &*self.replanner
        } else {
            &*self.primary
        }
    }
}

impl Planner for GoalSeeker {
    fn kind(&self) -> PlannerKind {
        self.primary.kind()
    }

    fn set_settings(&mut self, settings: &crate::Settings) -> Result<(), String> {
        self.primary.set_settings(settings)?;
        self.replanner.set_settings(settings)?;
        self.replan_time = settings.replan_time;
        Ok(())
    }

    fn step(&mut self, input: &PlannerInput) -> Command {
        if !self.warmed && input.grid.is_some() {
            // Size the re-planner's buffers now, not on its first turn in steady state.
            self.warmed = true;
            self.replanner.step(input);
            self.replanner.replan();
        }
        if self.pending {
            self.pending = false;
            self.replanning = true;
            self.remaining = self.replan_time;
            self.replanner.replan();
        }
        if self.replanning {
            if self.remaining <= 0.0 {
                self.replanning = false;
                self.primary.replan();
            } else if input.dt.is_finite() && input.dt > 0.0 {
                self.remaining -= input.dt;
            }
        }
        if self.replanning {
            self.replanner.step(input)
        } else {
            self.primary.step(input)
        }
    }

    fn replan(&mut self) {
        if self.replan_time <= 0.0 {
            self.primary.replan();
        } else {
            self.pending = true;
        }
    }

    fn obstacle_hint(&mut self, at: [f64; 2], heading: f64) {
        self.primary.obstacle_hint(at, heading);
        self.replanner.obstacle_hint(at, heading);
    }

    fn target(&self) -> Option<[f64; 2]> {
        self.primary.target()
    }

    /// Both planners head for the new goal, whichever drives now.
    fn set_goal(&mut self, goal: [f64; 2], tolerance: Option<f64>) -> bool {
        self.primary.set_goal(goal, tolerance) & self.replanner.set_goal(goal, tolerance)
    }

    fn write_status(&self, status: &mut PlanStatus) {
        self.driving().write_status(status);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::obstacles::test_support::grid_free;
    use crate::{Limited, RobotLimits};

    #[test]
    fn the_replanner_drives_after_a_bounce_then_hands_back() {
        let limits = RobotLimits::default();
        let g = grid_free(60, 60, 0.05);
        let seeker = GoalSeeker::new(
            Box::new(crate::Dwa::new(
                limits,
                crate::DwaConfig::default(),
                [2.5, 2.5],
            )),
            Box::new(crate::Apf::new(
                limits,
                crate::ApfConfig::default(),
                [2.5, 2.5],
                3,
            )),
            1.0,
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
        assert!(active[..10].iter().all(|a| *a == PlannerKind::Dwa));
        // APF for 1 s = 20 steps (+1 for the hand-back step), then DWA again.
        let apf = active.iter().filter(|a| **a == PlannerKind::Apf).count();
        assert!((20..=22).contains(&apf), "{apf}");
        assert_eq!(active.last(), Some(&PlannerKind::Dwa));
    }
}
