//! What the page's controls publish: its goals on `operator/goal`, its paces (run, pause, step)
//! on `operator/pace`.

use crate::PageInput;
use mole_runtime::{Context, Publisher, RuntimeError, now_ns};
use mole_types::{Goal, PACE_PAUSE, PACE_RUN, PACE_STEP, Pace, topics};

/// The operator topics the page's controls publish on.
pub struct Controls {
    goal: Publisher<Goal>,
    pace: Publisher<Pace>,
}

impl Controls {
    /// Opens the publishers on `operator/goal` and `operator/pace`.
    pub fn open(ctx: &Context) -> Result<Controls, RuntimeError> {
        Ok(Controls {
            goal: ctx.publisher(topics::OPERATOR_GOAL)?,
            pace: ctx.publisher(topics::OPERATOR_PACE)?,
        })
    }

    /// Publishes `command` at `tick`; of several goals at once only the newest counts.
    pub fn publish(&mut self, commands: Vec<PageInput>, tick: u64) -> Result<(), RuntimeError> {
        let newest_goal = commands
            .iter()
            .rposition(|c| matches!(c, PageInput::Goal { .. }));
        for (i, command) in commands.into_iter().enumerate() {
            tracing::info!(?command, tick, "from the page");
            let (op, steps) = match command {
                PageInput::Goal { x, y } if Some(i) == newest_goal => {
                    self.goal
                        .publish(tick, now_ns(), |g| (g.x, g.y, g.tolerance) = (x, y, 0.0))?;
                    continue;
                }
                PageInput::Goal { .. } => continue,
                PageInput::Run => (PACE_RUN, 0),
                PageInput::Pause => (PACE_PAUSE, 0),
                PageInput::Step { steps } => (PACE_STEP, steps),
                // The server refuses timeline ops in a live view.
                PageInput::Timeline(_) => continue,
            };
            self.pace
                .publish(tick, now_ns(), |p| (p.op, p.steps) = (op, steps))?;
        }
        Ok(())
    }
}
