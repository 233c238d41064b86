//! The monitor process: observes everything, judges it against ground truth, and writes
//! summary.json and map.png when the run ends.
//!
//! Every topic in → monitor/status (a few times a second) and, at the end, the two files.

use clap::Parser;
use mole_monitor::{Monitor, RunMeta, write_summary};
use mole_runtime::{ClockMode, CommonArgs, Context, Wake, now_ns};
use mole_types::{EndReason, topics};
use std::collections::BTreeMap;
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::{Duration, Instant};

const STATUS_PERIOD: Duration = Duration::from_millis(200);
/// Lockstep: how long to wait for the last step's messages after the world's final step.
const LOCKSTEP_DRAIN: Duration = Duration::from_secs(2);

#[derive(Debug, Parser)]
#[command(
    name = "mole-monitor",
    about = "mole's observer: metrics, summary.json, map.png"
)]
struct Args {
    #[command(flatten)]
    common: CommonArgs,
    /// Where summary.json and map.png go.
    #[arg(long, env = "MOLE_OUT", default_value = "runs/latest")]
    out: PathBuf,
    /// The planner's name, for the summary.
    #[arg(long, env = "MOLE_PLANNER", default_value = "random-walk")]
    planner: String,
    /// The estimator's name, for the summary.
    #[arg(long, env = "MOLE_ESTIMATOR", default_value = "ekf")]
    estimator: String,
}

fn main() -> ExitCode {
    let args = Args::parse();
    mole_runtime::exit_code(run(&args))
}

fn end_reason(code: u32) -> &'static str {
    EndReason::from_code(code).map_or("interrupted", EndReason::name)
}

fn run(args: &Args) -> Result<(), Box<dyn std::error::Error>> {
    let mut ctx = Context::new("monitor", &args.common)?;
    let mut map_sub = ctx.subscriber(topics::WORLD_MAP)?;
    let mut truth_sub = ctx.subscriber(topics::WORLD_TRUTH)?;
    // The truth and the frontier grid wake the monitor; the rest is read on those wake-ups.
    let mut pose_sub = ctx.passive_subscriber(topics::LOCALIZATION_POSE)?;
    let mut grid_sub = ctx.subscriber(topics::MAPPING_GRID)?;
    let mut contact_sub = ctx.passive_subscriber(topics::MAPPING_CONTACT)?;
    let mut particles_sub = ctx.passive_subscriber(topics::LOCALIZATION_PARTICLES)?;
    let mut plan_sub = ctx.passive_subscriber(topics::PLANNING_STATUS)?;
    let mut stats_sub = ctx.passive_subscriber(topics::STACK_STATS)?;
    let mut status_pub = ctx.publisher(topics::MONITOR_STATUS)?;
    let waitset = ctx.waitset()?;
    let wakers = [map_sub.waker(), truth_sub.waker(), grid_sub.waker()];
    let _attached = wakers
        .iter()
        .map(|w| waitset.attach(w))
        .collect::<Result<Vec<_>, _>>()?;
    ctx.ready();

    let mut monitor: Option<Monitor> = None;
    let mut started: Option<Instant> = None;
    let mut next_status = Instant::now() + STATUS_PERIOD;
    let mut end: Option<u32> = None;
    let mut end_seen: Option<Instant> = None;
    loop {
        let wake = waitset.wait(&mut ctx, Some(next_status))?;
        if monitor.is_none()
            && map_sub.update()
            && let Some(map) = map_sub.latest()
        {
            monitor = Some(Monitor::new(map)?);
            tracing::info!("map received");
        }
        let Some(m) = monitor.as_mut() else {
            if wake == Wake::Shutdown {
                return Ok(());
            }
            next_status = Instant::now() + STATUS_PERIOD;
            continue;
        };
        // Truth first: every estimate, grid and status of a step was derived from a truth
        // that is already in its queue.
        truth_sub.drain(|t| {
            m.on_truth(t);
            if t.is_end() {
                end = Some(t.end_reason);
            }
        });
        started.get_or_insert_with(Instant::now);
        pose_sub.drain(|p| m.on_pose(p));
        grid_sub.drain(|g| m.on_grid(g));
        contact_sub.drain(|g| m.on_contact(g));
        particles_sub.drain(|p| m.on_particles(p));
        plan_sub.drain(|s| m.on_plan_status(s));
        stats_sub.drain(|s| m.on_stats(s));

        // Lockstep: the last step's estimate and grids were sent before the world's final
        // step, but a publisher blocked on our full queue may still be delivering them; wait
        // for them (briefly) so the summary is the same on every run.
        if let Some(last) = truth_sub.tick().filter(|_| end.is_some())
            && ctx.mode() == ClockMode::Lockstep
            && wake != Wake::Shutdown
        {
            let expected = last.saturating_sub(1);
            let behind = [pose_sub.tick(), grid_sub.tick(), contact_sub.tick()]
                .iter()
                .any(|t| t.is_some_and(|t| t < expected));
            let waited = end_seen.get_or_insert_with(Instant::now).elapsed();
            if behind && waited < LOCKSTEP_DRAIN {
                next_status = Instant::now() + Duration::from_millis(5);
                continue;
            }
        }
        let finished = end.is_some() || wake == Wake::Shutdown;
        if finished || Instant::now() >= next_status {
            next_status = Instant::now() + STATUS_PERIOD;
            let tick = truth_sub.tick().unwrap_or(0);
            if finished {
                let reason = end.map_or("interrupted", end_reason);
                let meta = RunMeta {
                    planner: args.planner.clone(),
                    estimator: args.estimator.clone(),
                    mode: ctx.mode().to_string(),
                    seed: map_sub
                        .latest()
                        .map_or(0, |map| ctx.seed().unwrap_or(map.seed)),
                    wall_time_s: started.map_or(0.0, |s| s.elapsed().as_secs_f64()),
                    exit_reason: reason.to_string(),
                    restarts: BTreeMap::new(),
                };
                std::fs::create_dir_all(&args.out)?;
                write_summary(&m.summary(&meta), &args.out.join("summary.json"))?;
                m.render_png(&args.out.join("map.png"))?;
                tracing::info!(out = %args.out.display(), exit_reason = reason, "summary written");
            }
            status_pub.publish(tick, now_ns(), |s| {
                m.write_status(s);
                s.finished = u32::from(finished);
            })?;
            if finished {
                return Ok(());
            }
        }
    }
}
