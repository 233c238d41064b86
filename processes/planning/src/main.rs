//! The planning process: turns the estimated pose, the scan, touch and the map into a velocity
//! command, with bounce-back as the reactive layer under every planner.
//!
//! world/map once, then localization/pose, sensing/scan, sensing/tactile (step k) and
//! mapping/grid (step k−1: mapping works beside the loop) → planning/cmd and planning/status.
//! An operator's goal (operator/goal, the newest, never waited for) redirects a goal-seeking
//! planner, which stops there and waits for the next one; an explorer ignores it, says so once
//! and counts what it ignored.

use clap::Parser;
use mole_planning::{Command, LocalPlanner, Planner, PlannerConfig, PlannerInput, RobotLimits};
use mole_runtime::{BadInput, CommonArgs, Order, Process, Rule};
use mole_types::{Goal, Header, MODE_ARRIVED, PlannerKind, Pose2, env, topics};
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
    /// Local planner that follows the frontier path: dwa or apf.
    #[arg(long, env = env::LOCAL_PLANNER, default_value = "dwa", value_parser = parse_local)]
    local: LocalPlanner,
}

fn parse_local(text: &str) -> Result<LocalPlanner, String> {
    match text {
        "dwa" => Ok(LocalPlanner::Dwa),
        "apf" => Ok(LocalPlanner::Apf),
        other => Err(format!("expected dwa or apf, found `{other}`")),
    }
}

fn main() -> ExitCode {
    mole_runtime::exit_code(run(&Args::parse()))
}

fn run(args: &Args) -> Result<(), Box<dyn std::error::Error>> {
    let mut p = Process::new("planning", &args.common)?;
    let pose = p.trigger(topics::LOCALIZATION_POSE, Order::Newest)?;
    let scan = p.input(topics::SENSING_SCAN, Rule::SameTick)?;
    let tactile = p.input(topics::SENSING_TACTILE, Rule::SameTick)?;
    let grid = p.input(topics::MAPPING_GRID, Rule::PreviousTick)?;
    let goal = p.input(topics::OPERATOR_GOAL, Rule::Newest)?;
    let mut cmd_out = p.output(topics::PLANNING_CMD)?;
    let mut status_out = p.output(topics::PLANNING_STATUS)?;

    p.run(
        |start| {
            let map = start.map;
            let mut config = PlannerConfig::new(args.planner);
            (config.seed, config.local) = (start.seed, args.local);
            config.goal = args
                .goal
                .or((map.has_goal == 1).then_some((map.goal_x, map.goal_y)));
            config.goal_tolerance = (map.has_goal == 1).then_some(map.goal_tolerance);
            if let Some(why) = config.kind.refuses_sensors(&map.sensors, "this world") {
                return Err(BadInput(why).into());
            }
            // A planner that cannot be built is bad input (exit 2), not a crash to retry.
            let planner = mole_planning::build_planner(&config, RobotLimits::from(&map.robot))
                .map_err(|e| BadInput(e.to_string()))?;
            Ok((planner, map.dt, Command::STOP, OperatorGoals::default()))
        },
        |(planner, dt, last_command, goals), step| {
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
    )
}

/// The operator's goals (operator/goal) as the planner has taken them.
#[derive(Default)]
struct OperatorGoals {
    /// The header of the goal handled last: a goal is new when its header differs (a new
    /// `seq`, or a new publisher's first goal, which has a new stamp).
    last: Option<Header>,
    /// Whether the planner is heading for an operator's goal (not the scenario's).
    following: bool,
    /// Goals an explorer ignored.
    ignored: u64,
}

impl OperatorGoals {
    /// Hands `goal` to `planner` if it is new; a planner that seeks no goals ignores it, which
    /// is said once and counted.
    fn follow(&mut self, goal: &Goal, planner: &mut dyn Planner) {
        if self.last == Some(goal.header) {
            return;
        }
        self.last = Some(goal.header);
        let tolerance = (goal.tolerance > 0.0).then_some(goal.tolerance);
        if planner.set_goal([goal.x, goal.y], tolerance) {
            self.following = true;
            tracing::info!(
                x = goal.x,
                y = goal.y,
                tolerance = goal.tolerance,
                "heading for the operator's goal"
            );
            return;
        }
        self.ignored += 1;
        if self.ignored == 1 {
            tracing::info!(
                planner = %planner.kind(),
                "this planner seeks no goals: it ignores the operator's goals (counted)"
            );
        } else {
            tracing::debug!(ignored = self.ignored, "operator goal ignored");
        }
    }
}

impl OperatorGoals {
    /// At an operator's goal the robot stands and waits for the next one (`MODE_IDLE`): only
    /// the scenario's goal ends the run (`MODE_ARRIVED` is the world's cue to end it).
    fn hold_at_operator_goal(&self, command: Command) -> Command {
        if self.following && command.mode == MODE_ARRIVED {
            return Command::STOP;
        }
        command
    }
}

impl Drop for OperatorGoals {
    /// At the end of the run, how many goals an explorer ignored.
    fn drop(&mut self) {
        if self.ignored > 0 {
            tracing::info!(
                ignored = self.ignored,
                "operator goals ignored by this planner"
            );
        }
    }
}
