//! A closed loop without IPC: the world library steps the robot, the sensing library reads its
//! lidar and tactile rim from the truth, the mapping library folds the scans into the frontier
//! grid, and the planner answers on the true pose with the grid of the step before (as in
//! lockstep). What the stack does, minus the processes and the estimator.

use mole_mapping::FrontierGrid;
use mole_planning::{Command, Planner, PlannerInput};
use mole_sensing::Sensing;
use mole_types::{Grid, Scan, Tactile, Truth, WorldMap};
use mole_world::{Scenario, World, load_scenario};
use std::hash::{DefaultHasher, Hash, Hasher};

/// Scenario `name` from scenarios/, at its own Δt, with `seed`.
pub fn scenario(name: &str, seed: u64) -> Scenario {
    let path = mole_world::bundled_scenarios().join(name);
    let mut s = load_scenario(&path).unwrap_or_else(|e| panic!("{e}"));
    s.seed = seed;
    s
}

/// What one closed-loop run did.
#[derive(Debug, Clone, PartialEq)]
pub struct Outcome {
    /// Steps run.
    pub steps: usize,
    /// The last command's mode.
    pub last_mode: u32,
    /// The first step after which the world saw the robot within the goal tolerance.
    pub goal_at: Option<usize>,
    /// Share of the free cells reachable from the start that the frontier grid marks explored.
    pub coverage: f64,
    /// Bounce-backs the planner triggered.
    pub bounces: u32,
    /// Steps that ended with the robot touching something.
    pub contact_steps: usize,
    /// Hash of every command (v, ω, mode bits), the run's fingerprint.
    pub commands: u64,
}

/// Runs `planner` on the world of `sc` for up to `max_steps`, stopping after the first step
/// whose command satisfies `stop`.
pub fn run(
    sc: &Scenario,
    planner: &mut dyn Planner,
    max_steps: usize,
    stop: impl Fn(&Command) -> bool,
) -> Outcome {
    let mut map: Box<WorldMap> = bytemuck::zeroed_box();
    sc.write_world_map(&mut map);
    let mut world = World::new(sc);
    let mut sensing = Sensing::new(&map, sc.seed).unwrap_or_else(|e| panic!("{e}"));
    let mut fg = FrontierGrid::new(sc.arena_width, sc.arena_height, sc.grid_resolution)
        .unwrap_or_else(|e| panic!("{e}"));
    let mut truth: Box<Truth> = bytemuck::zeroed_box();
    let mut scan: Box<Scan> = bytemuck::zeroed_box();
    let mut tactile: Box<Tactile> = bytemuck::zeroed_box();
    let mut grid: Box<Grid> = bytemuck::zeroed_box();
    let mut hasher = DefaultHasher::new();
    let mut last_command = Command::STOP;
    let mut out = Outcome {
        steps: 0,
        last_mode: 0,
        goal_at: None,
        coverage: 0.0,
        bounces: 0,
        contact_steps: 0,
        commands: 0,
    };
    for step in 0..max_steps {
        world.write_truth(&mut truth);
        sensing.scan(&truth, &mut scan);
        sensing.tactile(&truth, &mut tactile);
        let pose = world.pose();
        let input = PlannerInput {
            tick: step as u64,
            dt: sc.dt,
            pose,
            scan: Some(&scan),
            tactile: Some(&tactile),
            grid: (step > 0).then_some(&*grid),
            last_command,
        };
        let c = planner.step(&input);
        last_command = c;
        (c.v.to_bits(), c.omega.to_bits(), c.mode).hash(&mut hasher);
        fg.integrate_footprint(pose, sc.robot.radius);
        fg.integrate_scan(pose, &scan);
        fg.write(&mut grid);
        world.step(c.v, c.omega);
        out.steps = step + 1;
        out.last_mode = c.mode;
        out.contact_steps += usize::from(!world.contacts().is_empty());
        if world.goal_reached() && out.goal_at.is_none() {
            out.goal_at = Some(step);
        }
        if stop(&c) {
            break;
        }
    }
    out.bounces = planner.bounces();
    out.commands = hasher.finish();
    out.coverage = coverage(sc, grid.cells(), grid.width as usize, grid.height as usize);
    out
}

/// The `dwa` stack on scenario `name` (its goal, `seed`) until it reports arriving, for up to
/// 12,000 steps.
pub fn dwa_to_the_goal(name: &str, seed: u64) -> Outcome {
    use mole_planning::{PlannerConfig, RobotLimits, build_planner};
    let sc = scenario(name, seed);
    let goal = sc.goal.unwrap_or_else(|| panic!("{name} has a goal"));
    let config = PlannerConfig {
        seed,
        goal: Some((goal.x, goal.y)),
        goal_tolerance: Some(goal.tolerance),
        ..PlannerConfig::new(mole_types::PlannerKind::Dwa)
    };
    let mut p =
        build_planner(&config, RobotLimits::from(&sc.robot)).unwrap_or_else(|e| panic!("{e}"));
    run(&sc, p.as_mut(), 12_000, |c| {
        c.mode == mole_types::MODE_ARRIVED
    })
}

/// Share of the free cells reachable from the start (8-connected over cell centres outside
/// every square) that `cells` marks explored.
pub fn coverage(sc: &Scenario, cells: &[u8], w: usize, h: usize) -> f64 {
    let res = sc.grid_resolution;
    let free: Vec<bool> = (0..w * h)
        .map(|i| {
            let (x, y) = (((i % w) as f64 + 0.5) * res, ((i / w) as f64 + 0.5) * res);
            !sc.obstacles.iter().any(|o| o.contains(x, y))
        })
        .collect();
    let start = (sc.start.y / res) as usize * w + (sc.start.x / res) as usize;
    let mut seen = vec![false; w * h];
    let mut stack = vec![start];
    seen[start] = true;
    let (mut total, mut explored) = (0usize, 0usize);
    while let Some(c) = stack.pop() {
        total += 1;
        explored += usize::from(cells[c] != 0);
        let (cx, cy) = ((c % w) as i64, (c / w) as i64);
        for dy in -1..=1 {
            for dx in -1..=1 {
                let (nx, ny) = (cx + dx, cy + dy);
                if nx < 0 || ny < 0 || nx >= w as i64 || ny >= h as i64 {
                    continue;
                }
                let n = ny as usize * w + nx as usize;
                if free[n] && !seen[n] {
                    seen[n] = true;
                    stack.push(n);
                }
            }
        }
    }
    explored as f64 / total as f64
}
