//! The planning process: turns the estimated pose, the scan, touch and the map into a velocity
//! command, with bounce-back as the reactive layer under every planner.
//!
//! world/map once, then localization/pose, sensing/scan, sensing/tactile and mapping/grid every
//! step → planning/cmd and planning/status.

use clap::Parser;
use mole_planning::{PlannerInput, RobotLimits, planner_by_name};
use mole_runtime::{ClockMode, CommonArgs, Context, StepGate, Wake};
use mole_types::{Pose2, topics};
use std::process::ExitCode;

#[derive(Debug, Parser)]
#[command(name = "mole-planning", about = "mole's planners (seed §1, §3-§5)")]
struct Args {
    #[command(flatten)]
    common: CommonArgs,
    /// Planner: random-walk.
    #[arg(long, env = "MOLE_PLANNER", default_value = "random-walk")]
    planner: String,
}

fn main() -> ExitCode {
    let args = Args::parse();
    match run(&args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            tracing::error!("{e}");
            ExitCode::FAILURE
        }
    }
}

fn run(args: &Args) -> Result<(), Box<dyn std::error::Error>> {
    let mut ctx = Context::new("planning", &args.common)?;
    let mut map_sub = ctx.subscriber(topics::WORLD_MAP)?;
    let mut pose_sub = ctx.subscriber(topics::LOCALIZATION_POSE)?;
    let mut scan_sub = ctx.subscriber(topics::SENSING_SCAN)?;
    let mut tactile_sub = ctx.subscriber(topics::SENSING_TACTILE)?;
    let mut grid_sub = ctx.subscriber(topics::MAPPING_GRID)?;
    let mut cmd_pub = ctx.publisher(topics::PLANNING_CMD)?;
    let mut status_pub = ctx.publisher(topics::PLANNING_STATUS)?;
    let waitset = ctx.waitset()?;
    let wakers = [map_sub.waker(), pose_sub.waker(), grid_sub.waker()];
    let _attached = wakers
        .iter()
        .map(|w| waitset.attach(w))
        .collect::<Result<Vec<_>, _>>()?;
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
            let limits = RobotLimits {
                radius: map.robot.radius,
                max_speed: map.robot.max_speed,
                max_omega: map.robot.max_omega,
                max_accel: map.robot.max_accel,
                max_alpha: map.robot.max_alpha,
            };
            dt = map.dt;
            let seed = ctx.seed().unwrap_or(map.seed);
            planner = Some(planner_by_name(&args.planner, limits, seed)?);
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
        status_pub.publish(tick, origin, |status| {
            status.mode = command.mode;
            status.flags = 0;
            let [tx, ty] = planner.target().unwrap_or([input.pose.x, input.pose.y]);
            (status.goal_x, status.goal_y) = (tx, ty);
            (status.frontier_x, status.frontier_y) = (0.0, 0.0);
            status.bounces = planner.bounces();
            status.n_path = 0;
        })?;
        ctx.count_step();
    }
}
