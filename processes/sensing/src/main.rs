//! The sensing process: turns the ground truth into what the robot's sensors would read.
//!
//! world/map once, then world/truth every step → sensing/{scan, tactile, odom, beacons, fix}.

use clap::Parser;
use mole_runtime::{CommonArgs, Order, Process};
use mole_sensing::Sensing;
use mole_types::{Role, topics};
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
    mole_runtime::exit_code(run(&Args::parse()))
}

fn run(args: &Args) -> Result<(), Box<dyn std::error::Error>> {
    let mut p = Process::new(Role::Sensing.name(), &args.common)?;
    // A replacement (a restart, a swap) goes on in the odom frame of the one before it.
    let odom_was = p.resume_from(topics::SENSING_ODOM)?;
    let truth = p.trigger(topics::WORLD_TRUTH, Order::Newest)?;
    let mut scan_out = p.output(topics::SENSING_SCAN)?;
    let mut tactile_out = p.output(topics::SENSING_TACTILE)?;
    let mut odom_out = p.output(topics::SENSING_ODOM)?;
    let mut beacons_out = p.output(topics::SENSING_BEACONS)?;
    let mut fix_out = p.output(topics::SENSING_FIX)?;

    p.run(
        |start| {
            let mut sensing = Sensing::new(start.map, start.seed)?;
            if let Some(odom) = odom_was.as_deref() {
                sensing.resume_odometry(odom);
            }
            Ok(sensing)
        },
        |sensing, step| {
            let truth = step.trigger(truth);
            // The world's final state ends the run: no step follows it, so nothing is sensed.
            if truth.is_end() {
                return Ok(());
            }
            let (k, origin) = (step.tick(), step.origin_ns());
            // Odometry goes last: it triggers localization, whose pose triggers mapping and
            // planning, so every other reading of this step is already delivered when they run.
            fix_out.publish(k, origin, |m| sensing.fix(truth, m))?;
            beacons_out.publish(k, origin, |m| sensing.beacons(truth, m))?;
            tactile_out.publish(k, origin, |m| sensing.tactile(truth, m))?;
            scan_out.publish(k, origin, |m| sensing.scan(truth, m))?;
            odom_out.publish(k, origin, |m| sensing.odom(truth, m))?;
            Ok(())
        },
    )
}
