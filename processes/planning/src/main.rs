//! The planning process: turns the estimated pose, the scan, touch and the map into a velocity
//! command, with bounce-back as the reactive layer under every planner.
//!
//! world/map once, then localization/pose, sensing/scan, sensing/tactile (step k) and
//! mapping/grid (step k−1: mapping works beside the loop) → planning/cmd and planning/status.
//! An operator's goal (operator/goal, the newest, never waited for) redirects a goal-seeking
//! planner, which stops there and waits for the next one; an explorer ignores it, says so once
//! and counts what it ignored.

use clap::Parser;
use mole_planning::{Command, OperatorGoals, PlannerConfig, PlannerInput, Settings};
use mole_runtime::{BadInput, CommonArgs, Order, Process, Rule};
use mole_types::{PlannerKind, Pose2, Role, env, topics};
use std::process::ExitCode;

/// mole's planners (algorithms §1, §3-§5)
#[derive(Debug, Parser)]
struct Args {
    #[command(flatten)]
    common: CommonArgs,
    #[arg(long, env = env::PLANNER, default_value_t = PlannerKind::RandomWalk)]
    planner: PlannerKind,
    /// Goal X,Y (m) for the goal-seeking planners; the scenario's goal otherwise.
    #[arg(long, env = env::GOAL, value_parser = mole_runtime::parse_point)]
    goal: Option<(f64, f64)>,
    /// The goal seeker that follows frontier's paths (dwa, apf).
    #[arg(long, env = env::LOCAL_PLANNER, default_value_t = PlannerKind::Dwa)]
    local_planner: PlannerKind,
}

fn main() -> ExitCode {
    let args = Args::parse();
    mole_runtime::run_role(Role::Planning, &args.common, |p| run(p, &args))
}

fn run(mut p: Process, args: &Args) -> Result<(), Box<dyn std::error::Error>> {
    let pose = p.trigger(topics::LOCALIZATION_POSE, Order::Newest)?;
    let scan = p.input(topics::SENSING_SCAN, Rule::SameTick)?;
    let tactile = p.input(topics::SENSING_TACTILE, Rule::SameTick)?;
    let grid = p.input(topics::MAPPING_GRID, Rule::PreviousTick)?;
    let goal = p.input(topics::OPERATOR_GOAL, Rule::Newest)?;
    let mut cmd_out = p.output(topics::PLANNING_CMD)?;
    let mut status_out = p.output(topics::PLANNING_STATUS)?;
    let tuning = p.tuning::<Settings>(&args.common)?;
    let settings = *tuning.settings();

    p.run_tuned(
        tuning,
        |start| {
            let config = PlannerConfig {
                seed: start.seed,
                local: args.local_planner,
                settings,
                ..PlannerConfig::new(args.planner)
            }
            .with_world_goal(start.map, args.goal);
            let planner = mole_planning::build_planner_for(&config, start.map).map_err(BadInput)?;
            let (dt, last_command) = (start.map.dt, Command::STOP);
            Ok((planner, config, dt, last_command, OperatorGoals::default()))
        },
        |(planner, _, dt, last_command, goals), step| {
            if let Some(goal) = step.get(goal) {
                goals.follow(goal, planner);
            }
            let pose = step.trigger(pose);
            let command = goals.hold_at_operator_goal(planner.step(&PlannerInput {
                tick: step.tick(),
                dt: *dt,
                pose: Pose2::new(pose.x, pose.y, pose.theta),
                scan: step.get(scan),
                tactile: step.get(tactile),
                grid: step.get(grid),
                last_command: *last_command,
            }));
            let (k, origin) = (step.tick(), step.origin_ns());
            cmd_out.publish(k, origin, |cmd| {
                (cmd.v, cmd.omega, cmd.mode, cmd._pad) =
                    (command.v, command.omega, command.mode, 0);
            })?;
            *last_command = command;
            status_out.publish(k, origin, |status| planner.write_status(status))?;
            Ok(())
        },
        |(planner, config, ..), new| {
            let next = PlannerConfig {
                settings: *new,
                ..config.clone()
            };
            planner.set_settings(&next.tuned()).map(|()| *config = next)
        },
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use mole_mapping::Maps;
    use mole_runtime::{Harness, same_payload};
    use mole_sensing::Sensing;
    use mole_types::{Grid, PlanStatus, Scan, Tactile};
    use mole_world::{World, bundled_scenario};

    /// The main on a harness, exploring with frontier: each step waits for the previous
    /// step's grid (one came after its pose), and its command and status are the planner's own
    /// for the same pose, readings and grid.
    #[test]
    fn each_pose_gives_the_planners_command_for_it_with_the_previous_steps_grid() {
        let scenario = bundled_scenario("default").unwrap();
        let map = scenario.world_map();
        let mut world = World::new(&scenario);
        let mut sensing = Sensing::new(&map, 7).unwrap();
        let mut maps = Maps::new(&map, &Default::default()).unwrap();
        let harness = Harness::new();
        harness.deliver(topics::WORLD_MAP, 0, |m| *m = *map);
        let (mut inputs, mut grid) = (Vec::new(), None::<Box<Grid>>);
        let mut grid_of_step_3 = 0;
        for k in 0..6u64 {
            let mut truth = bytemuck::zeroed_box();
            world.write_step(&mut truth, 0, None);
            let pose = world.pose();
            harness.deliver(topics::SENSING_SCAN, k, |s| sensing.scan(&truth, s));
            let scan = harness.delivered_last::<Scan>();
            harness.deliver(topics::SENSING_TACTILE, k, |t| sensing.tactile(&truth, t));
            let tactile = harness.delivered_last::<Tactile>();
            let deliver_grid = || {
                let grid = grid.as_ref()?;
                Some(harness.deliver(topics::MAPPING_GRID, k - 1, |g| *g = **grid))
            };
            // Step 4's pose comes before step 3's grid: the step waits for it.
            if k != 4 {
                deliver_grid();
            }
            harness.deliver(topics::LOCALIZATION_POSE, k, |p| {
                (p.x, p.y, p.theta) = (pose.x, pose.y, pose.theta);
            });
            if k == 4 {
                grid_of_step_3 = deliver_grid().unwrap();
            }
            inputs.push((pose, scan.clone(), tactile.clone(), grid.take()));
            maps.integrate(pose, Some(&scan), Some(&tactile));
            let mut next: Box<Grid> = bytemuck::zeroed_box();
            maps.frontier.write(&mut next);
            grid = Some(next);
            world.step(0.3, 0.2);
        }
        let args = Args::parse_from(["mole-planning", "--planner", "frontier"]);
        run(
            harness.process(Role::Planning, &args.common).unwrap(),
            &args,
        )
        .unwrap();

        let config = PlannerConfig {
            seed: map.seed,
            ..PlannerConfig::new(PlannerKind::Frontier)
        }
        .with_world_goal(&map, None);
        let mut planner = mole_planning::build_planner_for(&config, &map).unwrap();
        let mut last_command = Command::STOP;
        let (cmds, statuses) = (
            harness.published(topics::PLANNING_CMD),
            harness.published(topics::PLANNING_STATUS),
        );
        assert_eq!((cmds.len(), statuses.len()), (6, 6));
        harness
            .check_publish_order(Role::Planning.spec().outputs)
            .unwrap();
        assert!(harness.published_after(topics::PLANNING_CMD)[4] > grid_of_step_3);
        assert!(
            cmds.iter().any(|c| c.v != 0.0 || c.omega != 0.0),
            "it never moved"
        );
        for (k, (pose, scan, tactile, grid)) in inputs.iter().enumerate() {
            let command = planner.step(&PlannerInput {
                tick: k as u64,
                dt: map.dt,
                pose: *pose,
                scan: Some(scan),
                tactile: Some(tactile),
                grid: grid.as_deref(),
                last_command,
            });
            last_command = command;
            let cmd = &cmds[k];
            assert_eq!(cmd.header.tick, k as u64);
            assert_eq!(
                (cmd.v, cmd.omega, cmd.mode),
                (command.v, command.omega, command.mode)
            );
            let mut status: Box<PlanStatus> = bytemuck::zeroed_box();
            planner.write_status(&mut status);
            assert!(same_payload(&*status, &*statuses[k]), "status at {k}");
        }
    }
}
