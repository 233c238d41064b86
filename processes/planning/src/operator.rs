//! The operator's goals (`operator/goal`) as the planning process hands them to its planner: a
//! goal seeker heads for each new one and stands there waiting for the next; an explorer
//! ignores them, says so once and counts them.

use crate::{Command, Planner};
use mole_types::{Goal, Header, MODE_ARRIVED};

/// The operator's goals (operator/goal) as the planner has taken them.
#[derive(Debug, Default)]
pub struct OperatorGoals {
    /// The header of the goal handled last: a goal is new when its header differs (a new
    /// `seq`, or a new publisher's first goal, which has a new stamp).
    last: Option<Header>,
    /// Whether the planner is heading for an operator's goal (not the scenario's).
    following: bool,
    /// Goals an explorer ignored.
    ignored: u64,
}

impl OperatorGoals {
    /// Hands `goal` to `planner` if it is new; a planner that seeks no goals ignores it, which
    /// is said once and counted.
    pub fn follow(&mut self, goal: &Goal, planner: &mut dyn Planner) {
        if self.last == Some(goal.header) {
            return;
        }
        self.last = Some(goal.header);
        let tolerance = (goal.tolerance > 0.0).then_some(goal.tolerance);
        if planner.set_goal([goal.x, goal.y], tolerance) {
            self.following = true;
            tracing::info!(
                x = goal.x,
                y = goal.y,
                tolerance = goal.tolerance,
                "heading for the operator's goal"
            );
            return;
        }
        self.ignored += 1;
        if self.ignored == 1 {
            tracing::info!(
                planner = %planner.kind(),
                "this planner seeks no goals: it ignores the operator's goals (counted)"
            );
        } else {
            tracing::debug!(ignored = self.ignored, "operator goal ignored");
        }
    }
}

impl OperatorGoals {
    /// At an operator's goal the robot stands and waits for the next one (`MODE_IDLE`): only
    /// the scenario's goal ends the run (`MODE_ARRIVED` is the world's cue to end it).
    pub fn hold_at_operator_goal(&self, command: Command) -> Command {
        if self.following && command.mode == MODE_ARRIVED {
            return Command::STOP;
        }
        command
    }
}

impl Drop for OperatorGoals {
    /// At the end of the run, how many goals an explorer ignored.
    fn drop(&mut self) {
        if self.ignored > 0 {
            tracing::info!(
                ignored = self.ignored,
                "operator goals ignored by this planner"
            );
        }
    }
}
