//! The DWA and the reactive layer under it agree (algorithms §4): the DWA keeps out of the
//! bounce-back trigger distance on its own, so in the cluttered room the `dwa` stack reaches the
//! goal with a handful of bounces at most, not one every few seconds along a box face. Closed
//! loop without IPC: tests/sim.

mod sim;

use mole_planning::{PlannerConfig, RobotLimits, build_planner};
use mole_types::{MODE_ARRIVED, PlannerKind};

/// Bounces the `dwa` stack may need in the cluttered room: the reactive layer is the last resort.
const MAX_BOUNCES: u32 = 5;

/// cluttered.toml at seed 1: the `dwa` stack arrives at the goal, never touches a box, and the
/// bounce-back layer fires at most [`MAX_BOUNCES`] times on the way.
#[test]
fn dwa_in_the_clutter_rarely_needs_the_reactive_layer() {
    let sc = sim::scenario("cluttered.toml", 1);
    let goal = sc
        .goal
        .unwrap_or_else(|| panic!("cluttered.toml has a goal"));
    let config = PlannerConfig {
        seed: 1,
        goal: Some((goal.x, goal.y)),
        goal_tolerance: Some(goal.tolerance),
        ..PlannerConfig::new(PlannerKind::Dwa)
    };
    let mut p =
        build_planner(&config, RobotLimits::from(&sc.robot)).unwrap_or_else(|e| panic!("{e}"));
    let o = sim::run(&sc, p.as_mut(), 12_000, |c| c.mode == MODE_ARRIVED);
    eprintln!("cluttered.toml dwa seed 1: {o:?}");
    assert_eq!(
        o.last_mode, MODE_ARRIVED,
        "not arrived in {} steps",
        o.steps
    );
    assert_eq!(o.contact_steps, 0, "touched a box");
    assert!(
        o.bounces <= MAX_BOUNCES,
        "{} bounces: the DWA drives where the reactive layer fires",
        o.bounces
    );
}
