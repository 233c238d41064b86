//! Closed loop on the real world (mole-world dynamics and contacts), a noise-free lidar
//! (mole-sensing's ray caster) and the real frontier grid (mole-mapping): the DWA alone reaches
//! every scenario's goal without ever touching an obstacle, and so does the configured `dwa`
//! stack (the world's contact resolution bounds penetration for any command; avoiding contact is
//! the planner's own work), frontier exploration covers the maze without touching a wall, APF in
//! the U-trap reports a stall instead of spinning forever.

#[allow(dead_code)] // tests/sim serves several tests; this one uses `coverage` alone.
mod sim;

use mole_mapping::FrontierGrid;
use mole_planning::{
    Command, Dwa, DwaConfig, Limited, Planner, PlannerConfig, PlannerInput, RobotLimits,
    build_planner,
};
use mole_sensing::RayCaster;
use mole_types::{Grid, MODE_DONE, MODE_ESCAPE, MODE_STALLED, PlannerKind, Scan, Tactile};
use mole_world::{Scenario, World, load_scenario};

const DT: f64 = 0.05;
const BEAMS: usize = 180;
const RANGE_MAX: f64 = 4.0;

/// Scenario `name` from scenarios/, stepped at [`DT`].
fn scenario(name: &str) -> Scenario {
    let path = mole_world::bundled_scenarios().join(name);
    let mut s = load_scenario(&path).unwrap_or_else(|e| panic!("{e}"));
    s.dt = DT;
    s
}

/// What one closed-loop run achieved.
struct Run {
    steps: usize,
    reached: bool,
    /// Steps that ended with the robot touching a wall or square (rim within the world's skin).
    contact_steps: usize,
    coverage: f64,
    modes: Vec<u32>,
    path_length: f64,
}

/// Runs `planner` on the world of `sc` with a noise-free lidar and the frontier grid for up to
/// `max_steps`, stopping at the goal (`stop_at_goal`) or when the planner reports it is done.
fn run(sc: &Scenario, planner: &mut dyn Planner, max_steps: usize, stop_at_goal: bool) -> Run {
    let mut world = World::new(sc);
    let caster = RayCaster::new(sc.arena_width, sc.arena_height, &sc.obstacles)
        .unwrap_or_else(|e| panic!("{e}"));
    let mut fg = FrontierGrid::new(sc.arena_width, sc.arena_height, sc.grid_resolution)
        .unwrap_or_else(|e| panic!("{e}"));
    let mut scan: Box<Scan> = bytemuck::zeroed_box();
    let tactile: Box<Tactile> = bytemuck::zeroed_box();
    let mut grid: Box<Grid> = bytemuck::zeroed_box();
    let r = sc.robot.radius;
    let mut out = Run {
        steps: 0,
        reached: false,
        contact_steps: 0,
        coverage: 0.0,
        modes: Vec::new(),
        path_length: 0.0,
    };
    let mut last_command = Command::STOP;
    for step in 0..max_steps {
        let pose = world.pose();
        scan.n_beams = BEAMS as u32;
        scan.angle_min = -std::f32::consts::PI;
        scan.angle_increment = std::f32::consts::TAU / BEAMS as f32;
        scan.range_max = RANGE_MAX as f32;
        for i in 0..BEAMS {
            let a = pose.theta + scan.angle_min as f64 + i as f64 * scan.angle_increment as f64;
            scan.ranges[i] = caster.cast(pose.x, pose.y, a, RANGE_MAX) as f32;
        }
        fg.integrate_footprint(pose, r);
        fg.integrate_scan(pose, &scan);
        fg.write(&mut grid);
        let input = PlannerInput {
            tick: step as u64,
            dt: DT,
            pose,
            scan: Some(&scan),
            tactile: Some(&tactile),
            grid: Some(&grid),
            last_command,
        };
        let c = planner.step(&input);
        last_command = c;
        if std::env::var("DEBUG_LOOP").is_ok() && step % 100 == 0 {
            eprintln!(
                "{step} pose {:.2} {:.2} {:.2} cmd {:.3} {:.3} mode {}",
                pose.x, pose.y, pose.theta, c.v, c.omega, c.mode
            );
        }
        out.modes.push(c.mode);
        world.step(c.v, c.omega);
        let p = world.pose();
        out.path_length += (p.x - pose.x).hypot(p.y - pose.y);
        out.contact_steps += usize::from(!world.contacts().is_empty());
        out.steps = step + 1;
        if world.goal_reached() {
            out.reached = true;
            if stop_at_goal {
                break;
            }
        }
        if c.mode == MODE_DONE && !stop_at_goal {
            break;
        }
    }
    out.coverage = sim::coverage(sc, grid.cells(), grid.width as usize, grid.height as usize);
    out
}

/// The configured planner stack `kind` (DWA as local planner, seed 7), toward the scenario's
/// goal when `goal`.
fn build(sc: &Scenario, kind: PlannerKind, goal: bool) -> Box<dyn Planner> {
    let mut cfg = PlannerConfig::new(kind);
    cfg.seed = 7;
    cfg.local = PlannerKind::Dwa;
    if goal {
        cfg.goal = sc.goal.map(|g| (g.x, g.y));
    }
    build_planner(&cfg, RobotLimits::from(&sc.robot)).unwrap_or_else(|e| panic!("{e}"))
}

/// The DWA alone (limited, as every stack is), without the reactive layer to catch it, sees every obstacle in its lidar and
/// steers around them: it reaches the goal of every scenario without a single step in contact.
#[test]
fn dwa_alone_reaches_every_goal_without_touching_an_obstacle() {
    for name in [
        "cluttered.toml",
        "open.toml",
        "corridor.toml",
        "u_trap.toml",
        "maze.toml",
    ] {
        let sc = scenario(name);
        let goal = sc.goal.unwrap_or_else(|| panic!("{name} has no goal"));
        let limits = RobotLimits::from(&sc.robot);
        let mut dwa = Limited::new(
            Dwa::new(limits, DwaConfig::default(), [goal.x, goal.y]),
            limits,
        );
        let o = run(&sc, &mut dwa, 6000, true);
        eprintln!(
            "dwa alone {name}: reached {} in {} steps ({:.1} s), path {:.2} m, steps in contact {}",
            o.reached,
            o.steps,
            o.steps as f64 * DT,
            o.path_length,
            o.contact_steps
        );
        assert!(o.reached, "{name}: goal not reached in {} steps", o.steps);
        assert_eq!(o.contact_steps, 0, "{name}: touched an obstacle");
    }
}

/// Frontier exploration with a lidar maps 95 % of the maze it can reach, never touching a wall.
#[test]
fn frontier_exploration_covers_the_maze() {
    let sc = scenario("maze.toml");
    let mut p = build(&sc, PlannerKind::Frontier, false);
    let o = run(&sc, p.as_mut(), 12_000, false);
    eprintln!(
        "frontier maze: coverage {:.3} after {} steps ({:.0} s), path {:.1} m, done {}, steps in contact {}, bounces {}",
        o.coverage,
        o.steps,
        o.steps as f64 * DT,
        o.path_length,
        o.modes.last() == Some(&MODE_DONE),
        o.contact_steps,
        p.bounces()
    );
    assert!(o.coverage >= 0.95, "coverage {}", o.coverage);
    assert_eq!(o.contact_steps, 0, "touched a wall");
}

/// APF in the U-trap detects its local minimum (stalled), tries an escape and keeps moving.
#[test]
fn apf_in_the_u_trap_reports_a_stall_and_does_not_spin_forever() {
    let sc = scenario("u_trap.toml");
    let mut p = build(&sc, PlannerKind::Apf, true);
    let o = run(&sc, p.as_mut(), 3000, true);
    let stalled = o.modes.contains(&MODE_STALLED);
    let escaped = o.modes.contains(&MODE_ESCAPE);
    eprintln!(
        "apf u_trap: stalled {stalled}, escaped {escaped}, reached {} in {} steps, path {:.1} m",
        o.reached, o.steps, o.path_length
    );
    assert!(stalled && escaped);
    assert!(o.path_length > 3.0, "kept moving");
}

/// The configured `dwa` stack (DWA inside the bounce-back layer): the A* path (optimistic
/// through unexplored cells) gets it out of the U-trap and through the maze it has never seen,
/// as well as through the clutter, along the corridor and across the open field, without
/// touching anything.
#[test]
fn dwa_stack_reaches_every_scenario_goal_without_touching() {
    for name in [
        "cluttered.toml",
        "open.toml",
        "corridor.toml",
        "u_trap.toml",
        "maze.toml",
    ] {
        let sc = scenario(name);
        assert!(sc.goal.is_some(), "{name} has no goal");
        let mut p = build(&sc, PlannerKind::Dwa, true);
        let o = run(&sc, p.as_mut(), 6000, true);
        eprintln!(
            "dwa {name}: reached {} in {} steps ({:.1} s), path {:.1} m, steps in contact {}, bounces {}",
            o.reached,
            o.steps,
            o.steps as f64 * DT,
            o.path_length,
            o.contact_steps,
            p.bounces()
        );
        assert!(o.reached, "{name}: goal not reached in {} steps", o.steps);
        assert_eq!(o.contact_steps, 0, "{name}: touched an obstacle");
    }
}
