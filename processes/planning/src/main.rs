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

#[derive(Debug, Parser)]
#[command(
    name = "mole-planning",
    about = "mole's planners (algorithms §1, §3-§5)"
)]
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
    mole_runtime::exit_code(run(&Args::parse()))
}

fn run(args: &Args) -> Result<(), Box<dyn std::error::Error>> {
    let mut p = Process::new(Role::Planning.name(), &args.common)?;
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
