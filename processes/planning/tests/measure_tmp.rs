mod sim;
use mole_planning::{PlannerConfig, RobotLimits, build_planner};

#[test]
#[ignore]
fn measure() {
    for (name, planner, ticks, goal) in [
        ("default.toml", "random-walk", 3000usize, false),
        ("cluttered.toml", "dwa", 12000, true),
        ("maze.toml", "frontier", 80000, false),
    ] {
        for seed in [1u64, 7] {
            let sc = sim::scenario(name, seed);
            let mut cfg = PlannerConfig::new(planner);
            cfg.seed = seed;
            if goal {
                cfg.goal = sc.goal.map(|g| (g.x, g.y));
            }
            let mut p = build_planner(&cfg, RobotLimits::from(&sc.robot)).unwrap();
            let o = sim::run(&sc, p.as_mut(), ticks, |c| c.mode == mole_types::MODE_DONE);
            eprintln!("MEASURE {name} {planner} seed {seed}: {o:?}");
        }
    }
}
