//! The localization process: estimates the pose from odometry, beacons and position fixes; the
//! SLAM estimators estimate the beacon map too.
//!
//! world/map once, then sensing/{odom, beacons, fix, tactile} every step → localization/pose,
//! /particles (PF), /landmarks (SLAM) and /trajectory after each smoother solve (GraphSLAM).
//! With `--peer` (EKF-SLAM) the landmarks are offered to another robot and its offer fused in.

use clap::Parser;
use mole_localization::slam::{PEER_LANDMARKS, PeerArgs, PeerFusion};
use mole_localization::{
    EstimatorKind, NoiseModel, Odometer, PARTICLES_EVERY, Readings, Settings, start_estimator,
};
use mole_runtime::{BadInput, CommonArgs, Order, Process, Rule, now_ns};
use mole_types::{Role, env, topics};
use std::process::ExitCode;

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
                pose.odom = odometer.pose();
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
        |(e, map, _), new| e.set_noise(&NoiseModel::from_map(&new.noise.assumed(map))),
    )?;
    peer.inspect(|peer| fusion.log_totals(peer));
    Ok(())
}
