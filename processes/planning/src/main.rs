//! The planning process: turns the estimated pose, the scan, touch and the map into a velocity
//! command, with bounce-back as the reactive layer under every planner.
//!
//! world/map once, then localization/pose, sensing/scan, sensing/tactile and mapping/grid every
//! step → planning/cmd and planning/status.

use clap::Parser;
use mole_planning::{
    KNOWN_PLANNERS, LocalPlanner, PlannerConfig, PlannerInput, RobotLimits, build_planner,
};
use mole_runtime::{ClockMode, CommonArgs, Context, StepGate, Wake};
use mole_types::{Pose2, topics};
use std::process::ExitCode;

#[derive(Debug, Parser)]
#[command(
    name = "mole-planning",
    about = "mole's planners (algorithms §1, §3-§5)"
)]
struct Args {
    #[command(flatten)]
    common: CommonArgs,
    /// Planner: random-walk, apf, dwa or frontier.
    #[arg(long, env = "MOLE_PLANNER", default_value = "random-walk")]
    planner: String,
    /// Goal X,Y (m) for apf and dwa; the scenario's goal otherwise.
    #[arg(long, env = "MOLE_GOAL", value_parser = mole_runtime::parse_point)]
    goal: Option<(f64, f64)>,
    /// Local planner that follows the frontier path: dwa or apf.
    #[arg(long, env = "MOLE_LOCAL_PLANNER", default_value = "dwa", value_parser = parse_local)]
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
    let args = Args::parse();
    if !KNOWN_PLANNERS.contains(&args.planner.as_str()) {
        eprintln!(
            "error: --planner: unknown planner `{}`, expected one of {}",
            args.planner,
            KNOWN_PLANNERS.join(", ")
        );
        return ExitCode::from(2);
    }
    mole_runtime::exit_code(run(&args))
}

fn run(args: &Args) -> Result<(), Box<dyn std::error::Error>> {
    let mut ctx = Context::new("planning", &args.common)?;
    let mut map_sub = ctx.subscriber(topics::WORLD_MAP)?;
    // Each new pose starts a step; lockstep also waits for the previous step's grid, which a
    // late mapping may still be writing, so the grid wakes us too. Scan and tactile readings
    // come before the pose and never need to.
    let lockstep = ctx.mode() == ClockMode::Lockstep;
    let mut pose_sub = ctx.subscriber(topics::LOCALIZATION_POSE)?;
    let mut scan_sub = ctx.passive_subscriber(topics::SENSING_SCAN)?;
    let mut tactile_sub = ctx.passive_subscriber(topics::SENSING_TACTILE)?;
    let mut grid_sub = ctx.subscriber(topics::MAPPING_GRID)?;
    let mut cmd_pub = ctx.publisher(topics::PLANNING_CMD)?;
    let mut status_pub = ctx.publisher(topics::PLANNING_STATUS)?;
    let waitset = ctx.waitset()?;
    let wakers = [map_sub.waker(), grid_sub.waker(), pose_sub.waker()];
    let _attached = wakers
        .iter()
        .map(|w| waitset.attach(w))
        .collect::<Result<Vec<_>, _>>()?;
    ctx.anticipate(&waitset, &wakers[2]);
    ctx.ready();

    let mut planner = None;
    let mut dt = 0.01;
    let mut gate = StepGate::new(ctx.mode());
    loop {
        if waitset.wait(&mut ctx, None)? == Wake::Shutdown {
            return Ok(());
        }
        if planner.is_none()
            && map_sub.update()
            && let Some(map) = map_sub.latest()
        {
            let limits = RobotLimits::from(&map.robot);
            dt = map.dt;
            let mut config = PlannerConfig::new(&args.planner);
            config.seed = ctx.seed().unwrap_or(map.seed);
            config.local = args.local;
            config.goal = args
                .goal
                .or((map.has_goal == 1).then_some((map.goal_x, map.goal_y)));
            // A planner that cannot be built is bad input (exit 2), not a crash to retry.
            planner = Some(
                build_planner(&config, limits)
                    .map_err(|e| mole_runtime::BadInput(e.to_string()))?,
            );
            tracing::info!(planner = %args.planner, "map received");
        }
        let Some(planner) = planner.as_mut() else {
            continue;
        };
        pose_sub.update();
        scan_sub.update();
        tactile_sub.update();
        // Lockstep plans step k on the grid of step k−1, as realtime does in practice: mapping
        // then works beside the control loop instead of inside it. Step 0 has no grid yet.
        let grid_through = if lockstep {
            pose_sub.tick().and_then(|k| k.checked_sub(1))
        } else {
            None
        };
        let grid_tick = match (lockstep, grid_through) {
            (false, _) => {
                grid_sub.update();
                pose_sub.tick()
            }
            (true, Some(previous)) => {
                grid_sub.update_through(previous);
                grid_sub.tick().map(|g| g + 1)
            }
            (true, None) => pose_sub.tick(),
        };
        let ticks = [
            pose_sub.tick(),
            scan_sub.tick(),
            tactile_sub.tick(),
            grid_tick,
        ];
        let Some(tick) = gate.ready(&ticks) else {
            continue;
        };
        let Some(pose) = pose_sub.latest() else {
            continue;
        };
        let input = PlannerInput {
            tick,
            dt,
            pose: Pose2::new(pose.x, pose.y, pose.theta),
            scan: scan_sub.latest().filter(|s| s.header.tick == tick),
            tactile: tactile_sub.latest().filter(|t| t.header.tick == tick),
            grid: grid_sub
                .latest()
                .filter(|_| !lockstep || grid_through.is_some()),
        };
        let command = planner.step(&input);
        let origin = pose.header.origin_ns;
        cmd_pub.publish(tick, origin, |cmd| {
            cmd.v = command.v;
            cmd.omega = command.omega;
            cmd.mode = command.mode;
            cmd._pad = 0;
        })?;
        status_pub.publish(tick, origin, |status| planner.write_status(status))?;
        ctx.count_step();
    }
}
