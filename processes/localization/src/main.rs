//! The localization process: estimates the pose from odometry, beacons and position fixes.
//!
//! world/map once, then sensing/{odom, beacons, fix} every step → localization/pose.

use clap::Parser;
use mole_localization::{Estimator, EstimatorKind, build_estimator};
use mole_runtime::{CommonArgs, Context, StepGate, Wake, now_ns};
use mole_types::{Pose, WorldMap, topics};
use std::process::ExitCode;
use std::time::Duration;

/// Publish the particle set every this many steps.
const PARTICLES_EVERY: u64 = 10;
/// A replacement (`mole swap` sets `MOLE_TAKEOVER`) waits this long for the estimate of the
/// process it replaces, then starts at the scenario's start pose.
const TAKEOVER_GRACE: Duration = Duration::from_secs(1);

#[derive(Debug, Parser)]
#[command(
    name = "mole-localization",
    about = "mole's pose estimators (algorithms §6)"
)]
struct Args {
    #[command(flatten)]
    common: CommonArgs,
    /// Estimator: bayes, kf, ekf or pf.
    #[arg(long, env = "MOLE_ESTIMATOR", default_value = "ekf")]
    estimator: String,
    /// Replace a running estimator: start from its latest pose (set by `mole swap`).
    #[arg(long, env = "MOLE_TAKEOVER", default_value_t = false)]
    takeover: bool,
}

fn main() -> ExitCode {
    let args = Args::parse();
    let kind = match args.estimator.parse::<EstimatorKind>() {
        Ok(kind) => kind,
        Err(e) => {
            eprintln!("error: --estimator: {e}");
            return ExitCode::from(2);
        }
    };
    mole_runtime::exit_code(run(&args, kind))
}

fn run(args: &Args, kind: EstimatorKind) -> Result<(), Box<dyn std::error::Error>> {
    let mut ctx = Context::new("localization", &args.common)?;
    // A replacement goes on from the estimate of the process it replaces. First, before any
    // input port exists: a lockstep publisher waits for a full queue, so an input we did not
    // read while waiting here would stop the stack.
    let mut predecessor: Option<Pose> = None;
    let resume_after = if args.takeover {
        ctx.take_over(topics::LOCALIZATION_POSE, TAKEOVER_GRACE, |pose| {
            predecessor = Some(*pose);
        })?
    } else {
        None
    };
    let mut map_sub = ctx.subscriber(topics::WORLD_MAP)?;
    let mut odom_sub = ctx.subscriber(topics::SENSING_ODOM)?;
    // Sensing publishes odom last: the fix and the beacons of a step are in when odom wakes us.
    let mut beacons_sub = ctx.passive_subscriber(topics::SENSING_BEACONS)?;
    let mut fix_sub = ctx.passive_subscriber(topics::SENSING_FIX)?;
    let mut pose_pub = ctx.publisher(topics::LOCALIZATION_POSE)?;
    let mut particles_pub = ctx.publisher(topics::LOCALIZATION_PARTICLES)?;
    let waitset = ctx.waitset()?;
    let wakers = [map_sub.waker(), odom_sub.waker()];
    let _attached = wakers
        .iter()
        .map(|w| waitset.attach(w))
        .collect::<Result<Vec<_>, _>>()?;
    ctx.anticipate(&waitset, &wakers[1]);
    ctx.ready();

    let mut estimator: Option<Box<dyn Estimator>> = None;
    let mut gate = StepGate::new(ctx.mode());
    if let Some(tick) = resume_after {
        gate.resume_after(tick);
    }
    loop {
        if waitset.wait(&mut ctx, None)? == Wake::Shutdown {
            return Ok(());
        }
        if estimator.is_none()
            && map_sub.update()
            && let Some(map) = map_sub.latest()
        {
            estimator = Some(match &predecessor {
                Some(pose) => {
                    tracing::info!(
                        from_tick = pose.header.tick,
                        x = pose.x,
                        y = pose.y,
                        "took over the running estimate"
                    );
                    build_estimator(kind, &starting_at(map, pose))?
                }
                None if args.takeover => {
                    tracing::warn!(
                        "no estimate to take over within {TAKEOVER_GRACE:?}: starting at the \
                         scenario's start pose"
                    );
                    build_estimator(kind, map)?
                }
                None => build_estimator(kind, map)?,
            });
            tracing::info!(estimator = kind.name(), "map received");
        }
        let Some(estimator) = estimator.as_mut() else {
            continue;
        };
        odom_sub.update();
        beacons_sub.update();
        fix_sub.update();
        let ticks = [odom_sub.tick(), beacons_sub.tick(), fix_sub.tick()];
        let Some(tick) = gate.ready(&ticks) else {
            continue;
        };
        let (Some(odom), Some(beacons), Some(fix)) =
            (odom_sub.latest(), beacons_sub.latest(), fix_sub.latest())
        else {
            continue;
        };
        let started = now_ns();
        estimator.predict(odom);
        // Realtime may miss a step's readings: never correct twice with the same ones.
        if beacons.header.tick == tick && fix.header.tick == tick {
            estimator.correct(beacons, fix);
        }
        let update_ns = now_ns().saturating_sub(started);
        pose_pub.publish(tick, odom.header.origin_ns, |pose| {
            estimator.write_pose(pose);
            pose.update_ns = update_ns;
        })?;
        // The particle set (PF only), written straight into shared memory; every 10th step is
        // plenty for a picture or a viewer, and keeps 256 KiB per step off the bus.
        if kind == EstimatorKind::Pf && tick % PARTICLES_EVERY == 0 {
            particles_pub.publish(tick, odom.header.origin_ns, |p| {
                if !estimator.write_particles(p) {
                    p.n_particles = 0;
                }
            })?;
        }
        ctx.count_step();
    }
}

/// The map with its start pose moved to `pose`: every estimator starts there, with its usual
/// initial uncertainty.
fn starting_at(map: &WorldMap, pose: &Pose) -> Box<WorldMap> {
    let mut moved = Box::new(*map);
    moved.start_x = pose.x;
    moved.start_y = pose.y;
    moved.start_theta = pose.theta;
    moved
}
