//! The localization process: estimates the pose from odometry, beacons and position fixes; the
//! SLAM estimators estimate the beacon map too.
//!
//! world/map once, then sensing/{odom, beacons, fix} every step → localization/pose, and
//! localization/particles (PF) or localization/landmarks (SLAM).

use clap::Parser;
use mole_localization::{Estimator, EstimatorKind, Readings, build_estimator, resume};
use mole_runtime::{CommonArgs, Order, Process, Rule, now_ns};
use mole_types::{env, topics};
use std::process::ExitCode;

/// Publish the particle set every this many steps: plenty for a picture or a viewer, and it
/// keeps 256 KiB per step off the bus.
const PARTICLES_EVERY: u64 = 10;

#[derive(Debug, Parser)]
#[command(
    name = "mole-localization",
    about = "mole's pose estimators (algorithms §6)"
)]
struct Args {
    #[command(flatten)]
    common: CommonArgs,
    #[arg(long, env = env::ESTIMATOR, default_value_t = EstimatorKind::Ekf)]
    estimator: EstimatorKind,
}

fn main() -> ExitCode {
    mole_runtime::exit_code(run(&Args::parse()))
}

fn run(args: &Args) -> Result<(), Box<dyn std::error::Error>> {
    let kind = args.estimator;
    let mut p = Process::new("localization", &args.common)?;
    // A replacement goes on from the estimate (and a SLAM estimator's map) of the one it replaces.
    let landmarks_were = match kind.is_slam() {
        true => p.resume_from(topics::LOCALIZATION_LANDMARKS)?,
        false => None,
    };
    let pose_was = p.resume_from(topics::LOCALIZATION_POSE)?;
    // Sensing publishes odometry last: the fix and the beacons of a step are in when it wakes us.
    let odom = p.trigger(topics::SENSING_ODOM, Order::Newest)?;
    let beacons = p.input(topics::SENSING_BEACONS, Rule::SameTick)?;
    let fix = p.input(topics::SENSING_FIX, Rule::SameTick)?;
    let mut pose_out = p.output(topics::LOCALIZATION_POSE)?;
    let mut particles_out = p.output(topics::LOCALIZATION_PARTICLES)?;
    let mut landmarks_out = p.output(topics::LOCALIZATION_LANDMARKS)?;

    p.run(
        |start| {
            let estimator: Box<dyn Estimator> = match pose_was.as_deref() {
                Some(pose) => resume(kind, start.map, pose, landmarks_were.as_deref())?,
                None => build_estimator(kind, start.map)?,
            };
            Ok(estimator)
        },
        |estimator, step| {
            let readings = Readings {
                odom: step.trigger(odom),
                beacons: step.get(beacons),
                fix: step.get(fix),
            };
            let started = now_ns();
            estimator.step(&readings);
            let update_ns = now_ns().saturating_sub(started);
            let (k, origin) = (step.tick(), step.origin_ns());
            pose_out.publish(k, origin, |pose| {
                estimator.write_pose(pose);
                pose.update_ns = update_ns;
            })?;
            if kind == EstimatorKind::Pf && k % PARTICLES_EVERY == 0 {
                particles_out.publish(k, origin, |out| _ = estimator.write_particles(out))?;
            }
            // Every step, so that a swap takes over the landmarks with the pose.
            if kind.is_slam() {
                landmarks_out.publish(k, origin, |out| _ = estimator.write_landmarks(out))?;
            }
            Ok(())
        },
    )
}
