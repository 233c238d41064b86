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

/// mole's observer: metrics, summary.json, map.png
#[derive(Debug, Parser)]
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
    let args = Args::parse();
    mole_runtime::run_role(Role::Monitor, &args.common, |p| run(p, &args))
}

fn run(mut p: Process, args: &Args) -> Result<(), Box<dyn std::error::Error>> {
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

#[cfg(test)]
mod tests {
    use super::*;
    use mole_monitor::Summary;
    use mole_runtime::Harness;
    use mole_types::EndReason;
    use mole_world::{World, bundled_scenario};

    /// The main on a harness, as the observer: it judges every pose against the truth of its
    /// tick, ends with the final truth (not waiting for the pose of the last step, one behind)
    /// and writes summary.json with the run's names, and a last status saying it finished.
    #[test]
    fn the_final_truth_ends_the_run_with_every_pose_judged_against_its_truth() {
        let scenario = bundled_scenario("default").unwrap();
        let mut world = World::new(&scenario);
        let harness = Harness::new();
        harness.deliver(topics::WORLD_MAP, 0, |m| scenario.write_world_map(m));
        for k in 0..=10 {
            let end = (k == 10).then_some(EndReason::Ticks);
            harness.deliver(topics::WORLD_TRUTH, k, |t| world.write_step(t, 0, end));
            let at = world.pose();
            // An estimate 0.1 m off the truth, in x, every step.
            harness.deliver(topics::LOCALIZATION_POSE, k, |p| {
                (p.x, p.y, p.theta) = (at.x + 0.1, at.y, at.theta);
                p.covariance = [1e-2, 0.0, 0.0, 0.0, 1e-2, 0.0, 0.0, 0.0, 1e-2];
            });
            world.step(0.3, 0.2);
        }
        let out = std::env::temp_dir().join(format!("mole-monitor-harness-{}", std::process::id()));
        let out_arg = out.to_str().unwrap();
        let args = Args::parse_from(["mole-monitor", "--out", out_arg, "--planner", "dwa"]);
        let ran = run(harness.process(Role::Monitor, &args.common).unwrap(), &args);
        let summary = std::fs::read_to_string(out.join("summary.json"));
        std::fs::remove_dir_all(&out).unwrap();
        ran.unwrap();

        let summary: Summary = serde_json::from_str(&summary.unwrap()).unwrap();
        assert_eq!(
            (summary.ticks, summary.end_reason.as_deref()),
            (10, Some("ticks"))
        );
        assert_eq!(
            (summary.planner.as_str(), summary.mode.as_str()),
            ("dwa", "lockstep")
        );
        assert_eq!(summary.pose_samples, 10);
        assert!((summary.localization_rmse_m.unwrap() - 0.1).abs() < 1e-9);
        let statuses = harness.published(topics::MONITOR_STATUS);
        harness
            .check_publish_order(Role::Monitor.spec().outputs)
            .unwrap();
        assert_eq!(
            statuses.last().map(|s| (s.header.tick, s.finished)),
            Some((10, 1))
        );
        assert_eq!(harness.undelivered(), 1, "the last pose is not waited for");
    }
}
