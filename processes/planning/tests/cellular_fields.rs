//! The `dwa` stack on generated cellular-automaton fields (BARN's worlds, `mole_world::families`)
//! where it once circled short of the goal: a global path hugging the arena's wall, which the
//! grid does not map, and, wedged inside the inflation, a path planned with none at all through
//! gaps it could not pass. Closed loop without IPC: tests/sim.

#[allow(dead_code)] // tests/sim serves several tests; this one uses `run` alone.
mod sim;

use mole_planning::{PlannerConfig, RobotLimits, build_planner};
use mole_types::{MODE_ARRIVED, PlannerKind};
use mole_world::{Family, WorldSpec, generate};

/// Seeds of `mole eval --family cellular --planner dwa` that timed out before: 2 and 29 ran
/// through gaps planned with no inflation, 8 and 30 along the arena's wall.
const SEEDS: [u64; 4] = [2, 8, 29, 30];

/// 60 s at the families' 100 Hz: more than `mole eval`'s limit on each of these worlds.
const MAX_STEPS: usize = 6_000;

#[test]
fn dwa_reaches_the_goal_on_the_cellular_fields_it_circled_in() {
    for seed in SEEDS {
        let sc =
            generate(&WorldSpec::new(Family::Cellular), seed).unwrap_or_else(|e| panic!("{e}"));
        let goal = sc
            .goal
            .unwrap_or_else(|| panic!("cellular {seed} has a goal"));
        let config = PlannerConfig {
            seed,
            goal: Some((goal.x, goal.y)),
            goal_tolerance: Some(goal.tolerance),
            ..PlannerConfig::new(PlannerKind::Dwa)
        };
        let mut p =
            build_planner(&config, RobotLimits::from(&sc.robot)).unwrap_or_else(|e| panic!("{e}"));
        let o = sim::run(&sc, p.as_mut(), MAX_STEPS, |c| c.mode == MODE_ARRIVED);
        eprintln!("cellular {seed}: {o:?}");
        assert!(
            o.goal_at.is_some(),
            "cellular {seed}: goal not reached in {} steps",
            o.steps
        );
        assert_eq!(o.contact_steps, 0, "cellular {seed}: touched an obstacle");
    }
}
