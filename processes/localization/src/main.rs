//! The localization process: estimates the pose from odometry, beacons and position fixes; the
//! SLAM estimators estimate the beacon map too.
//!
//! world/map once, then sensing/{odom, beacons, fix, tactile} every step → localization/pose,
//! /particles (PF), /landmarks (SLAM) and /trajectory after each smoother solve (GraphSLAM).
//! With `--peer` (EKF-SLAM) the landmarks are offered to another robot and its offer fused in.

use clap::Parser;
use mole_localization::slam::{PeerArgs, PeerLink};
use mole_localization::{
    EstimatorKind, NoiseModel, Odometer, PARTICLES_EVERY, Readings, Settings, start_estimator,
};
use mole_runtime::{CommonArgs, Order, Process, Rule, timed_ns};
use mole_types::{Role, env, topics};
use std::process::ExitCode;

/// mole's pose estimators (algorithms §6)
#[derive(Debug, Parser)]
struct Args {
    #[command(flatten)]
    common: CommonArgs,
    #[arg(long, env = env::ESTIMATOR, default_value_t = EstimatorKind::Ekf)]
    estimator: EstimatorKind,
    #[command(flatten)]
    peers: PeerArgs,
}

fn main() -> ExitCode {
    let args = Args::parse();
    mole_runtime::run_role(Role::Localization, &args.common, |p| run(p, &args))
}

fn run(mut p: Process, args: &Args) -> Result<(), Box<dyn std::error::Error>> {
    let kind = args.estimator;
    let tuning = p.tuning::<Settings>(&args.common)?;
    let settings = *tuning.settings();
    // A replacement (a swap, a restart) goes on from the estimate and SLAM map before it.
    let landmarks_were = match kind.is_slam() {
        true => p.resume_from(topics::LOCALIZATION_LANDMARKS)?,
        false => None,
    };
    let pose_was = p.resume_from(topics::LOCALIZATION_POSE)?;
    // Sensing publishes odometry last: the fix and the beacons of a step are in when it wakes us.
    let odom = p.trigger(topics::SENSING_ODOM, Order::Newest)?;
    let beacons = p.input(topics::SENSING_BEACONS, Rule::SameTick)?;
    let fix = p.input(topics::SENSING_FIX, Rule::SameTick)?;
    let tactile = p.input(topics::SENSING_TACTILE, Rule::SameTick)?;
    let mut pose_out = p.output(topics::LOCALIZATION_POSE)?;
    let mut particles_out = p.output(topics::LOCALIZATION_PARTICLES)?;
    let mut landmarks_out = p.output(topics::LOCALIZATION_LANDMARKS)?;
    let mut trajectory_out = p.output(topics::LOCALIZATION_TRAJECTORY)?;
    // Two robots: read the map the peer offers (never waited for) and offer ours.
    let mut peer = PeerLink::open(&mut p, &args.peers, kind, &args.common.namespace)?;
    let mut solves = 0;

    p.run_tuned(
        tuning,
        |start| {
            let (map, pose, landmarks) =
                (start.map, pose_was.as_deref(), landmarks_were.as_deref());
            let estimator = start_estimator(kind, map, &settings, pose, landmarks)?;
            // The odometry pose of the step handled last (a replacement: its predecessor's).
            let odometer = Odometer::new(pose.map(|pose| pose.odom), map.dt);
            Ok((estimator, Box::new(*map), odometer))
        },
        |(estimator, map, odometer), step| {
            let odom = odometer.step(step.trigger(odom), step.ticks_since_last());
            let readings = Readings::of(&odom)
                .with_beacons(step.get(beacons))
                .with_fix(step.get(fix))
                .with_contacts(step.get(tactile), map.sensors.tactile_force_std);
            let update_ns = timed_ns(|| estimator.step(&readings));
            peer.fuse(step, estimator.as_mut());
            let (k, origin) = (step.tick(), step.origin_ns());
            pose_out.publish(k, origin, |pose| {
                estimator.write_pose(pose);
                pose.update_ns = update_ns;
                pose.odom = odometer.pose();
            })?;
            if kind == EstimatorKind::Pf && k % PARTICLES_EVERY == 0 {
                particles_out.publish(k, origin, |out| _ = estimator.write_particles(out))?;
            }
            // Every step, so that a swap or a restart takes over the landmarks with the pose.
            if kind.is_slam() {
                landmarks_out.publish(k, origin, |out| _ = estimator.write_landmarks(out))?;
            }
            peer.offer(k, origin, estimator.as_ref())?;
            // After each solve a smoother (GraphSLAM) finished: the whole smoothed trajectory.
            if estimator.smoother_solves() != solves {
                solves = estimator.smoother_solves();
                trajectory_out.publish(k, origin, |out| _ = estimator.write_trajectory(out))?;
            }
            Ok(())
        },
        // Only the noise changes while the estimator runs (the rest is fixed, docs/settings.md).
        |(e, map, _), new| e.set_noise(&NoiseModel::from_map(&new.noise.assumed(map))),
    )?;
    peer.log_totals();
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use mole_runtime::{Harness, same_payload};
    use mole_sensing::Sensing;
    use mole_types::{Beacons, Fix, Landmarks, Odom, Pose, Tactile};
    use mole_world::{World, bundled_scenario};

    /// The main on a harness: each odometry reading gives the estimator's own pose (and a SLAM
    /// estimator's landmarks) for the same readings, a step that never came (5) is bridged by
    /// the odometry of the gap, and the pose carries the odometry pose it is for.
    #[test]
    fn each_odometry_reading_gives_the_estimators_pose_and_map_across_a_missed_step() {
        // The default room has a position fix; the SLAM loop has none, and more beacons.
        for (kind, scenario) in [
            (EstimatorKind::Ekf, "default"),
            (EstimatorKind::EkfSlam, "slam_loop"),
        ] {
            estimates_across_a_missed_step(kind, scenario);
        }
    }

    fn estimates_across_a_missed_step(kind: EstimatorKind, scenario: &str) {
        let scenario = bundled_scenario(scenario).unwrap();
        let map = scenario.world_map();
        let (mut world, mut sensing) = (World::new(&scenario), Sensing::new(&map, 7).unwrap());
        let harness = Harness::new();
        harness.deliver(topics::WORLD_MAP, 0, |m| *m = *map);
        let mut steps = Vec::new();
        // Past the first position fix (one a second).
        for k in 0..120u64 {
            let mut truth = bytemuck::zeroed_box();
            world.write_step(&mut truth, 0, None);
            fn sensed<M: mole_types::Message>(read: impl FnOnce(&mut M)) -> Box<M> {
                let mut m = bytemuck::zeroed_box();
                read(&mut m);
                m
            }
            // In the order sensing publishes them, odometry last.
            let fix: Box<Fix> = sensed(|m| sensing.fix(&truth, m));
            let beacons: Box<Beacons> = sensed(|m| sensing.beacons(&truth, m));
            let tactile: Box<Tactile> = sensed(|m| sensing.tactile(&truth, m));
            let odom: Box<Odom> = sensed(|m| sensing.odom(&truth, m));
            // Step 5 is sensed but never delivered: localization misses it.
            if k != 5 {
                harness.deliver(topics::SENSING_FIX, k, |m| *m = *fix);
                harness.deliver(topics::SENSING_BEACONS, k, |m| *m = *beacons);
                harness.deliver(topics::SENSING_TACTILE, k, |m| *m = *tactile);
                harness.deliver(topics::SENSING_ODOM, k, |m| *m = *odom);
                steps.push((k, (fix, beacons, tactile, odom)));
            }
            world.step(0.3, 0.4);
        }
        let args = Args::parse_from(["mole-localization", "--estimator", kind.name()]);
        run(
            harness.process(Role::Localization, &args.common).unwrap(),
            &args,
        )
        .unwrap();

        let (poses, landmarks) = (
            harness.published(topics::LOCALIZATION_POSE),
            harness.published(topics::LOCALIZATION_LANDMARKS),
        );
        let slam = kind.is_slam();
        harness
            .check_publish_order(Role::Localization.spec().outputs)
            .unwrap();
        assert_eq!(
            (poses.len(), landmarks.len()),
            (119, if slam { 119 } else { 0 })
        );
        let mut estimator = start_estimator(kind, &map, &Settings::default(), None, None).unwrap();
        let (mut odometer, mut last) = (Odometer::new(None, map.dt), None::<u64>);
        for (i, (k, (fix, beacons, tactile, odom))) in steps.iter().enumerate() {
            let odom = odometer.step(odom, last.map(|l| k - l));
            last = Some(*k);
            estimator.step(
                &Readings::of(&odom)
                    .with_beacons(Some(beacons))
                    .with_fix(Some(fix))
                    .with_contacts(Some(tactile), map.sensors.tactile_force_std),
            );
            let mut pose: Box<Pose> = bytemuck::zeroed_box();
            estimator.write_pose(&mut pose);
            pose.odom = odometer.pose();
            let mut published = poses[i].clone();
            published.update_ns = 0;
            assert_eq!(poses[i].header.tick, *k);
            assert!(same_payload(&*pose, &*published), "{kind}: pose at {k}");
            if !slam {
                continue;
            }
            let mut map_out: Box<Landmarks> = bytemuck::zeroed_box();
            estimator.write_landmarks(&mut map_out);
            assert!(same_payload(&*map_out, &*landmarks[i]), "landmarks at {k}");
        }
    }
}
