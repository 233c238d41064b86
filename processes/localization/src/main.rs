//! The localization process: estimates the pose from odometry, beacons and position fixes; the
//! SLAM estimators estimate the beacon map too.
//!
//! world/map once, then sensing/{odom, beacons, fix, tactile} every step (the tactile ring for
//! the wheels' slide along a wall) → localization/pose, and
//! localization/particles (PF) or localization/landmarks (SLAM), and localization/trajectory
//! after each smoother solve (GraphSLAM). With `--peer` (EKF-SLAM) the landmarks are offered to
//! another robot on peers/localization/landmarks too, and its offer is fused into them.

use clap::Parser;
use mole_localization::slam::{PEER_LANDMARKS, PeerArgs, PeerFusion};
use mole_localization::{
    EstimatorKind, NoiseModel, Readings, Settings, odometry_since, start_estimator,
};
use mole_runtime::{BadInput, CommonArgs, Order, Process, Rule, now_ns};
use mole_types::{Role, env, topics};
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
    #[command(flatten)]
    peers: PeerArgs,
}

fn main() -> ExitCode {
    mole_runtime::exit_code(run(&Args::parse()))
}

fn run(args: &Args) -> Result<(), Box<dyn std::error::Error>> {
    let kind = args.estimator;
    let peer = args
        .peers
        .checked(kind, &args.common.namespace)
        .map_err(|e| BadInput(e.to_string()))?;
    let mut p = Process::new(Role::Localization.name(), &args.common)?;
    let tuning = p.tuning::<Settings>(&args.common)?;
    let settings = *tuning.settings();
    // A replacement (a swap, a restart) goes on from the estimate and SLAM map before it.
    let landmarks_were = kind
        .is_slam()
        .then(|| p.resume_from(topics::LOCALIZATION_LANDMARKS));
    let landmarks_were = landmarks_were.transpose()?.flatten();
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
    let peer_map = peer
        .map(|ns| p.peer_input(ns, PEER_LANDMARKS))
        .transpose()?;
    let mut offer_out = peer.map(|_| p.peer_output(PEER_LANDMARKS)).transpose()?;
    let (mut fusion, mut solves) = (PeerFusion::new(args.peers.fuse_every), 0);
    // The odometry pose of the step handled last (a replacement: of its predecessor's last).
    let mut odom_before = pose_was.as_deref().map(|pose| pose.odom);
    let tick_dt = std::cell::Cell::new(0.0);
    let force_std = std::cell::Cell::new(0.0);

    p.run_tuned(
        tuning,
        |start| {
            tick_dt.set(start.map.dt);
            force_std.set(start.map.sensors.tactile_force_std);
            let (map, pose, landmarks) =
                (start.map, pose_was.as_deref(), landmarks_were.as_deref());
            let estimator = start_estimator(kind, map, &settings, pose, landmarks)?;
            Ok((estimator, Box::new(*map)))
        },
        |(estimator, _), step| {
            let measured = step.trigger(odom);
            let gap = step.ticks_since_last();
            let odom = odometry_since(measured, odom_before, gap, tick_dt.get());
            odom_before = Some([measured.x, measured.y, measured.theta]);
            let readings = Readings::of(&odom)
                .with_beacons(step.get(beacons))
                .with_fix(step.get(fix))
                .with_contacts(step.get(tactile), force_std.get());
            let started = now_ns();
            estimator.step(&readings);
            let update_ns = now_ns().saturating_sub(started);
            if let Some(peer_map) = peer_map {
                fusion.step(step.tick(), step.get(peer_map), estimator.as_mut());
            }
            let (k, origin) = (step.tick(), step.origin_ns());
            pose_out.publish(k, origin, |pose| {
                estimator.write_pose(pose);
                pose.update_ns = update_ns;
                pose.odom = odom_before.unwrap_or_default();
            })?;
            if kind == EstimatorKind::Pf && k % PARTICLES_EVERY == 0 {
                particles_out.publish(k, origin, |out| _ = estimator.write_particles(out))?;
            }
            // Every step, so that a swap or a restart takes over the landmarks with the pose.
            if kind.is_slam() {
                landmarks_out.publish(k, origin, |out| _ = estimator.write_landmarks(out))?;
            }
            if let Some(offer_out) = offer_out.as_mut() {
                offer_out.publish(k, origin, |out| _ = estimator.write_landmarks(out))?;
            }
            // After each solve a smoother (GraphSLAM) finished: the whole smoothed trajectory.
            if estimator.smoother_solves() != solves {
                solves = estimator.smoother_solves();
                trajectory_out.publish(k, origin, |out| _ = estimator.write_trajectory(out))?;
            }
            Ok(())
        },
        // Only the noise changes while the estimator runs (the rest is fixed, docs/settings.md).
        |(estimator, map), new| estimator.set_noise(&NoiseModel::from_map(&new.noise.assumed(map))),
    )?;
    peer.inspect(|peer| fusion.log_totals(peer));
    Ok(())
}
