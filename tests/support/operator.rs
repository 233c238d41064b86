//! An operator in a running stack, as the view is: goals and paces published by the test.

use crate::{Stack, join_stack};
use mole_runtime::{ClockMode, Context, Publisher, Subscriber};
use mole_types::{Goal, Pace, PlanStatus, Role, Truth, topics};
use std::time::{Duration, Instant};

/// An operator in the stack: it publishes goals and paces, and keeps reading the truth and the
/// planner's status (in lockstep a subscriber's full queue holds its publisher back, so every
/// wait of the test reads them).
pub struct Operator {
    pub goal: Publisher<Goal>,
    pub pace: Publisher<Pace>,
    pub truth: Subscriber<Truth>,
    pub status: Subscriber<PlanStatus>,
    /// Declared last: the ports above go before the node they live on.
    _ctx: Context,
}

impl Operator {
    /// Joins the stack of `stack`, of clock `mode`, once its world is ready.
    pub fn join(stack: &Stack, mode: ClockMode) -> Operator {
        stack.wait_for_log(Role::World.name(), "ready", Duration::from_secs(60));
        let ctx = join_stack(&stack.namespace, "operator", mode);
        Operator {
            goal: ctx.publisher(topics::OPERATOR_GOAL).unwrap(),
            pace: ctx.publisher(topics::OPERATOR_PACE).unwrap(),
            truth: ctx.subscriber(topics::WORLD_TRUTH).unwrap(),
            status: ctx.subscriber(topics::PLANNING_STATUS).unwrap(),
            _ctx: ctx,
        }
    }

    /// Reads whatever came on the truth and the status.
    pub fn read(&mut self) {
        self.truth.drain(|_| {});
        self.status.drain(|_| {});
    }

    /// Keeps reading for `how_long`.
    pub fn follow(&mut self, how_long: Duration) {
        let until = Instant::now() + how_long;
        while Instant::now() < until {
            self.read();
            std::thread::sleep(Duration::from_millis(5));
        }
    }

    /// Keeps reading until `done` holds; `timeout` only guards against waiting forever.
    pub fn follow_until(
        &mut self,
        what: &str,
        timeout: Duration,
        done: impl Fn(&Operator) -> bool,
    ) {
        let until = Instant::now() + timeout;
        loop {
            self.read();
            if done(self) {
                return;
            }
            assert!(
                Instant::now() < until,
                "{what}: not within {timeout:?}; truth {:?}",
                self.truth.latest()
            );
            std::thread::sleep(Duration::from_millis(5));
        }
    }

    /// The newest true state.
    pub fn truth(&self) -> &Truth {
        self.truth.latest().expect("a truth has come")
    }

    /// The newest truth's step.
    pub fn tick(&self) -> u64 {
        self.truth.tick().unwrap_or(0)
    }

    /// Publishes a goal, stamped with the newest step seen.
    pub fn send_goal(&mut self, x: f64, y: f64, tolerance: f64) {
        let tick = self.tick();
        self.goal
            .publish(tick, 0, |g| (g.x, g.y, g.tolerance) = (x, y, tolerance))
            .unwrap();
    }

    /// Publishes a pace, stamped with the newest step seen.
    pub fn send_pace(&mut self, op: u32, steps: u32) {
        let tick = self.tick();
        self.pace
            .publish(tick, 0, |p| (p.op, p.steps) = (op, steps))
            .unwrap();
    }
}
