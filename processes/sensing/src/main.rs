//! The sensing process: turns the ground truth into what the robot's sensors would read.
//!
//! world/map once, then world/truth every step → sensing/{scan, tactile, odom, beacons, fix}.

use clap::Parser;
use mole_runtime::{CommonArgs, Context, StepGate, Wake};
use mole_sensing::Sensing;
use mole_types::topics;
use std::process::ExitCode;

#[derive(Debug, Parser)]
#[command(
    name = "mole-sensing",
    about = "mole's sensors: lidar, tactile, odometry, beacons, position fix"
)]
struct Args {
    #[command(flatten)]
    common: CommonArgs,
}

fn main() -> ExitCode {
    let args = Args::parse();
    mole_runtime::exit_code(run(&args))
}

fn run(args: &Args) -> Result<(), Box<dyn std::error::Error>> {
    let mut ctx = Context::new("sensing", &args.common)?;
    let mut map_sub = ctx.subscriber(topics::WORLD_MAP)?;
    let mut truth_sub = ctx.subscriber(topics::WORLD_TRUTH)?;
    let mut scan_pub = ctx.publisher(topics::SENSING_SCAN)?;
    let mut tactile_pub = ctx.publisher(topics::SENSING_TACTILE)?;
    let mut odom_pub = ctx.publisher(topics::SENSING_ODOM)?;
    let mut beacons_pub = ctx.publisher(topics::SENSING_BEACONS)?;
    let mut fix_pub = ctx.publisher(topics::SENSING_FIX)?;
    let waitset = ctx.waitset()?;
    let (map_wake, truth_wake) = (map_sub.waker(), truth_sub.waker());
    let _attached = (waitset.attach(&map_wake)?, waitset.attach(&truth_wake)?);
    ctx.anticipate(&waitset, &truth_wake);
    ctx.ready();

    let mut sensing: Option<Sensing> = None;
    let mut gate = StepGate::new(ctx.mode());
    loop {
        if waitset.wait(&mut ctx, None)? == Wake::Shutdown {
            return Ok(());
        }
        if sensing.is_none()
            && map_sub.update()
            && let Some(map) = map_sub.latest()
        {
            let seed = ctx.seed().unwrap_or(map.seed);
            sensing = Some(Sensing::new(map, seed)?);
            tracing::info!(
                obstacles = map.n_obstacles,
                beacons = map.n_beacons,
                "map received"
            );
        }
        let Some(sensing) = sensing.as_mut() else {
            continue;
        };
        truth_sub.update();
        // The world's final state ends the run: no step follows it, so nothing is sensed.
        let Some(truth) = truth_sub.latest().filter(|t| !t.is_end()) else {
            continue;
        };
        let Some(tick) = gate.ready(&[truth_sub.tick()]) else {
            continue;
        };
        let origin = truth.header.origin_ns;
        // Odometry goes last: it triggers localization, whose pose triggers mapping and
        // planning, so every other reading of this step is already delivered when they run.
        fix_pub.publish(tick, origin, |m| sensing.fix(truth, m))?;
        beacons_pub.publish(tick, origin, |m| sensing.beacons(truth, m))?;
        tactile_pub.publish(tick, origin, |m| sensing.tactile(truth, m))?;
        scan_pub.publish(tick, origin, |m| sensing.scan(truth, m))?;
        odom_pub.publish(tick, origin, |m| sensing.odom(truth, m))?;
        ctx.count_step();
    }
}
