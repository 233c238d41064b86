//! The planners in the whole stack, lockstep: DWA reaches a goal through clutter, frontier
//! exploration covers the maze, APF reports the U-trap's local minimum and keeps moving, each
//! without touching anything. (The world keeps any command within 1 mm of penetration, so only
//! `contact_events`, the rising edges of the world's contact flag, shows what a planner avoided.)

use mole_integration_tests::*;
use mole_types::{EndReason, PlannerKind};
use std::time::Duration;

fn run(test: &str, args: &[&str]) -> Summary {
    let _serial = serial();
    Stack::start(test, args).succeeded(Duration::from_secs(600))
}

/// DWA drives through the cluttered field to its goal and never touches an obstacle.
#[test]
fn dwa_reaches_the_goal_in_the_cluttered_field_without_touching_anything() {
    let s = run(
        "dwa",
        &[
            "--mode",
            "lockstep",
            "--seed",
            "1",
            "--planner",
            PlannerKind::Dwa.name(),
            "--scenario",
            "scenarios/cluttered.toml",
            "--ticks",
            "9000",
        ],
    );
    assert!(s.goal_reached, "{s:#?}");
    assert_eq!(s.exit_reason, EndReason::GoalReached.name());
    // The world keeps any command within 1 mm of penetration; not touching at all is what
    // DWA's clearance is for (contact_events: rising edges of the world's contact flag).
    assert_eq!(s.contact_events, 0, "{s:#?}");
}

/// Frontier exploration covers 95 % of the maze's reachable area without touching a wall.
#[test]
fn frontier_exploration_covers_the_maze() {
    let s = run(
        "frontier",
        &[
            "--mode",
            "lockstep",
            "--seed",
            "1",
            "--planner",
            PlannerKind::Frontier.name(),
            "--scenario",
            "scenarios/maze.toml",
            "--ticks",
            "25000",
        ],
    );
    assert!(s.coverage >= 0.95, "coverage {}: {s:#?}", s.coverage);
    assert!(
        s.coverage_steps.get("0.95").is_some_and(Option::is_some),
        "{s:#?}"
    );
    // Corridors 1 m wide, explored without touching a wall.
    assert_eq!(s.contact_events, 0, "{s:#?}");
}

/// APF in the U-trap reports its local minimum, travels on, and never touches the trap.
#[test]
fn apf_in_the_u_trap_reports_a_stall_and_does_not_spin_forever() {
    let s = run(
        "apf",
        &[
            "--mode",
            "lockstep",
            "--seed",
            "1",
            "--planner",
            PlannerKind::Apf.name(),
            "--scenario",
            "scenarios/u_trap.toml",
            "--ticks",
            "3000",
        ],
    );
    assert!(s.stalls >= 1, "the local minimum is reported: {s:#?}");
    // Escaping means moving on: metres of travel, not a robot turning on the spot.
    assert!(s.path_length_m > 3.0, "{s:#?}");
    // The obstacles' repulsion, escape bursts included, keeps the robot off the trap's walls.
    assert_eq!(s.contact_events, 0, "{s:#?}");
}
