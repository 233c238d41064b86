//! The monitor process: observes everything, judges it against ground truth, and writes
//! summary.json and map.png when the run ends.
//!
//! Every topic in → monitor/status (a few times a second) and, at the end, the two files.

use clap::Parser;
use mole_monitor::{Ending, Monitor, RunEnding, RunMeta};
use mole_runtime::{CommonArgs, Flow, Process, now_ns};
use mole_types::{EstimatorKind, PlannerKind, Role, env, topics};
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Duration;

const STATUS_PERIOD: Duration = Duration::from_millis(200);

#[derive(Debug, Parser)]
#[command(
    name = "mole-monitor",
    about = "mole's observer: metrics, summary.json, map.png"
)]
struct Args {
    #[command(flatten)]
    common: CommonArgs,
    /// Where summary.json and map.png go.
    #[arg(long, env = env::OUT, default_value = "runs/latest")]
    out: PathBuf,
    #[arg(long, env = env::PLANNER, default_value_t = PlannerKind::RandomWalk)]
    planner: PlannerKind,
    #[arg(long, env = env::ESTIMATOR, default_value_t = EstimatorKind::Ekf)]
    estimator: EstimatorKind,
}

fn main() -> ExitCode {
    mole_runtime::exit_code(run(&Args::parse()))
}

fn run(args: &Args) -> Result<(), Box<dyn std::error::Error>> {
    let mut p = Process::new(Role::Monitor.name(), &args.common)?;
    // The truth and the frontier grid wake the monitor; the rest is read on those wake-ups.
    let truth = p.observed(topics::WORLD_TRUTH, true)?;
    let pose = p.observed(topics::LOCALIZATION_POSE, false)?;
    let grid = p.observed(topics::MAPPING_GRID, true)?;
    let contact = p.observed(topics::MAPPING_CONTACT, false)?;
    let particles = p.observed(topics::LOCALIZATION_PARTICLES, false)?;
    let landmarks = p.observed(topics::LOCALIZATION_LANDMARKS, false)?;
    let trajectory = p.observed(topics::LOCALIZATION_TRAJECTORY, false)?;
    let plan = p.observed(topics::PLANNING_STATUS, false)?;
    let stats = p.observed(topics::STACK_STATS, false)?;
    let mut status_out = p.output(topics::MONITOR_STATUS)?;
    let mode = p.context().mode();
    let mut ending = RunEnding::new(mode);

    p.observe(
        STATUS_PERIOD,
        |start| Ok((Monitor::new(start.map)?, start.seed)),
        |(m, seed), seen| {
            // Truth first: every estimate, grid and status of a step derives from a truth in.
            seen.drain(truth, |t| {
                m.on_truth(t);
                ending.on_truth(t);
            });
            seen.drain(pose, |x| m.on_pose(x));
            seen.drain(grid, |x| m.on_grid(x));
            seen.drain(contact, |x| m.on_contact(x));
            seen.drain(particles, |x| m.on_particles(x));
            seen.drain(landmarks, |x| m.on_landmarks(x));
            seen.drain(trajectory, |x| m.on_trajectory(x));
            seen.drain(plan, |x| m.on_plan_status(x));
            seen.drain(stats, |x| m.on_stats(x));
            let last = seen.latest_tick(truth).unwrap_or(0);
            let (p, g, c) = (pose, grid, contact);
            let outputs = [
                seen.latest_tick(p),
                seen.latest_tick(g),
                seen.latest_tick(c),
            ];
            let finished = match ending.decide(last, &outputs, seen.shutdown()) {
                Ending::Running => false,
                Ending::Draining => {
                    seen.again_in(Duration::from_millis(5));
                    return Ok(Flow::Continue);
                }
                Ending::Finished(reason) => {
                    let wall = ending.wall_time();
                    let meta =
                        RunMeta::new(args.planner, args.estimator, mode, *seed, wall, reason);
                    m.write_files(&meta, &args.out)?;
                    true
                }
            };
            if finished || seen.periodic() {
                status_out.publish(last, now_ns(), |s| {
                    m.write_status(s);
                    s.finished = u32::from(finished);
                })?;
            }
            Ok(if finished { Flow::End } else { Flow::Continue })
        },
    )
}
