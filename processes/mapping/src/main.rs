//! The mapping process: builds the frontier grid (algorithms §5.2) from scans and the contact grid
//! (algorithms §2) from touch, both placed with the estimated pose.
//!
//! world/map once, then localization/pose, sensing/scan and sensing/tactile every step →
//! mapping/grid and mapping/contact. It works beside the control loop (planning uses the
//! previous step's grid), so in lockstep it may fall a step behind and takes every pose in order.

use clap::Parser;
use mole_mapping::{Maps, Settings};
use mole_runtime::{CommonArgs, Order, Process, Rule};
use mole_types::{Pose2, Role, topics};
use std::process::ExitCode;

#[derive(Debug, Parser)]
#[command(
    name = "mole-mapping",
    about = "mole's maps: frontier grid from range, contact grid from touch"
)]
struct Args {
    #[command(flatten)]
    common: CommonArgs,
}

fn main() -> ExitCode {
    mole_runtime::exit_code(run(&Args::parse()))
}

fn run(args: &Args) -> Result<(), Box<dyn std::error::Error>> {
    let mut p = Process::new(Role::Mapping.name(), &args.common)?;
    let tuning = p.tuning::<Settings>(&args.common)?;
    let settings = *tuning.settings();
    // A replacement goes on from the grids of the one it replaces (the frontier grid is
    // published last, so its step is the one to resume after).
    let contact_was = p.resume_from(topics::MAPPING_CONTACT)?;
    let frontier_was = p.resume_from(topics::MAPPING_GRID)?;
    let pose = p.trigger(topics::LOCALIZATION_POSE, Order::EveryTick)?;
    let scan = p.input(topics::SENSING_SCAN, Rule::SameTick)?;
    let tactile = p.input(topics::SENSING_TACTILE, Rule::SameTick)?;
    let mut grid_out = p.output(topics::MAPPING_GRID)?;
    let mut contact_out = p.output(topics::MAPPING_CONTACT)?;

    p.run_tuned(
        tuning,
        |start| {
            let mut maps = Maps::new(start.map, &settings)?;
            if contact_was.is_some() || frontier_was.is_some() {
                let both = maps.restore(frontier_was.as_deref(), contact_was.as_deref());
                tracing::info!(both, "took over the running grids");
            }
            Ok(maps)
        },
        |maps, step| {
            let pose = step.trigger(pose);
            let estimate = Pose2::new(pose.x, pose.y, pose.theta);
            maps.integrate(estimate, step.get(scan), step.get(tactile));
            let (k, origin) = (step.tick(), step.origin_ns());
            // The frontier grid last: it is what wakes planning and the monitor for this step.
            contact_out.publish(k, origin, |grid| maps.contact.write(grid))?;
            grid_out.publish(k, origin, |grid| maps.frontier.write(grid))?;
            Ok(())
        },
        |maps, new| maps.set_settings(new).map_err(|e| e.to_string()),
    )
}
