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
#[command(name = "mole-planning", about = "mole's planners (seed §1, §3-§5)")]
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
    // Realtime steps on each new pose; lockstep also needs the step's grid, which mapping
    // publishes after the pose, so there the grid alone wakes us. Scan and tactile readings
    // come before the pose and never need to.
    let lockstep = ctx.mode() == mole_runtime::ClockMode::Lockstep;
    let mut pose_sub = if lockstep {
        ctx.passive_subscriber(topics::LOCALIZATION_POSE)?
    } else {
        ctx.subscriber(topics::LOCALIZATION_POSE)?
    };
    let mut scan_sub = ctx.passive_subscriber(topics::SENSING_SCAN)?;
    let mut tactile_sub = ctx.passive_subscriber(topics::SENSING_TACTILE)?;
    let mut grid_sub = ctx.subscriber(topics::MAPPING_GRID)?;
    let mut cmd_pub = ctx.publisher(topics::PLANNING_CMD)?;
    let mut status_pub = ctx.publisher(topics::PLANNING_STATUS)?;
    let waitset = ctx.waitset()?;
    let mut wakers = vec![map_sub.waker(), grid_sub.waker()];
    if !lockstep {
        wakers.push(pose_sub.waker());
    }
    let _attached = wakers
        .iter()
        .map(|w| waitset.attach(w))
        .collect::<Result<Vec<_>, _>>()?;
    if !lockstep {
        ctx.anticipate(&waitset, &pose_sub.waker());
    }
    ctx.ready();

    let mut planner = None;
    let mut dt = 0.01;
    let mut gate = StepGate::new(ctx.mode());
    // Realtime reacts to the pose at once with the newest grid; lockstep also waits for this
    // step's grid, so that the same seed gives the same run.
    let lockstep = ctx.mode() == ClockMode::Lockstep;
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
        grid_sub.update();
        let grid_tick = if lockstep {
            grid_sub.tick()
        } else {
            pose_sub.tick()
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
            grid: grid_sub.latest(),
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
