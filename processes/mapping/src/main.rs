//! The mapping process: builds the frontier grid (algorithms §5.2) from scans and the contact grid
//! (algorithms §2) from touch, both placed with the estimated pose.
//!
//! world/map once, then localization/pose, sensing/scan and sensing/tactile every step →
//! mapping/grid and mapping/contact.

use clap::Parser;
use mole_mapping::{ContactGrid, FrontierGrid};
use mole_runtime::{ClockMode, CommonArgs, Context, StepGate, Wake};
use mole_types::{Grid, Pose2, topics};
use std::process::ExitCode;
use std::time::{Duration, Instant};

/// Lockstep: a step held this long with its pose but not its readings is reported.
const INCOMPLETE_WARNING: Duration = Duration::from_secs(2);

/// A replacement (`mole swap` sets `MOLE_TAKEOVER`) waits this long for each grid of the
/// process it replaces, then starts with empty grids.
const TAKEOVER_GRACE: Duration = Duration::from_secs(1);

#[derive(Debug, Parser)]
#[command(
    name = "mole-mapping",
    about = "mole's maps: frontier grid from range, contact grid from touch"
)]
struct Args {
    #[command(flatten)]
    common: CommonArgs,
    /// A tactile sensor reading above this force (N) is a touch.
    #[arg(long, env = "MOLE_TOUCH_THRESHOLD", default_value_t = 0.5)]
    touch_threshold: f64,
    /// Replace a running mapping process: start from its grids (set by `mole swap`).
    #[arg(long, env = "MOLE_TAKEOVER", default_value_t = false)]
    takeover: bool,
}

struct Maps {
    frontier: FrontierGrid,
    contact: ContactGrid,
    robot_radius: f64,
}

fn main() -> ExitCode {
    let args = Args::parse();
    mole_runtime::exit_code(run(&args))
}

fn run(args: &Args) -> Result<(), Box<dyn std::error::Error>> {
    let mut ctx = Context::new("mapping", &args.common)?;
    // A replacement goes on with the grids of the process it replaces: the contact grid, then
    // the frontier grid (published after it), whose step it resumes after. First, before any
    // input port exists: a lockstep publisher waits for a full queue, so an input we did not
    // read while waiting here would stop the stack.
    let (mut contact_taken, mut frontier_taken) = (None, None);
    let resume_after = if args.takeover {
        ctx.take_over(topics::MAPPING_CONTACT, TAKEOVER_GRACE, |g| {
            contact_taken = Some(copy_grid(g));
        })?;
        ctx.take_over(topics::MAPPING_GRID, TAKEOVER_GRACE, |g| {
            frontier_taken = Some(copy_grid(g));
        })?
    } else {
        None
    };
    let mut map_sub = ctx.subscriber(topics::WORLD_MAP)?;
    let mut pose_sub = ctx.subscriber(topics::LOCALIZATION_POSE)?;
    // A step's pose comes after its scan and tactile readings (localization waits for sensing's
    // last topic): the pose alone wakes us.
    let mut scan_sub = ctx.passive_subscriber(topics::SENSING_SCAN)?;
    let mut tactile_sub = ctx.passive_subscriber(topics::SENSING_TACTILE)?;
    let mut grid_pub = ctx.publisher(topics::MAPPING_GRID)?;
    let mut contact_pub = ctx.publisher(topics::MAPPING_CONTACT)?;
    let waitset = ctx.waitset()?;
    let wakers = [map_sub.waker(), pose_sub.waker()];
    let _attached = wakers
        .iter()
        .map(|w| waitset.attach(w))
        .collect::<Result<Vec<_>, _>>()?;
    ctx.ready();

    let mut maps: Option<Maps> = None;
    let mut gate = StepGate::new(ctx.mode());
    if let Some(tick) = resume_after {
        gate.resume_after(tick);
    }
    let lockstep = ctx.mode() == ClockMode::Lockstep;
    let mut skipped = 0u64;
    let (mut incomplete_since, mut incomplete_warned) = (None::<(u64, Instant)>, false);
    loop {
        if waitset.wait(&mut ctx, None)? == Wake::Shutdown {
            return Ok(());
        }
        if maps.is_none()
            && map_sub.update()
            && let Some(map) = map_sub.latest()
        {
            let (w, h, res) = (map.arena_width, map.arena_height, map.grid_resolution);
            let mut frontier = FrontierGrid::new(w, h, res)?;
            let mut contact = ContactGrid::new(w, h, res)?;
            if args.takeover {
                let restored = [
                    frontier_taken.take().is_some_and(|g| frontier.restore(&g)),
                    contact_taken.take().is_some_and(|g| contact.restore(&g)),
                ];
                if restored == [true, true] {
                    tracing::info!(after_tick = resume_after, "took over the running grids");
                } else {
                    tracing::warn!(
                        "no grids of this arena to take over within {TAKEOVER_GRACE:?} \
                         (frontier, contact: {restored:?}): starting with empty grids"
                    );
                }
            }
            maps = Some(Maps {
                frontier,
                contact,
                robot_radius: map.robot.radius,
            });
            tracing::info!(width_m = w, height_m = h, resolution = res, "map received");
        }
        let Some(maps) = maps.as_mut() else { continue };
        // Mapping works beside the control loop (planning uses the previous step's grid): in
        // lockstep it may be a step or two behind, and handles every step, in order.
        loop {
            if lockstep {
                pose_sub.update_next(gate.last());
                if let Some(k) = pose_sub.tick() {
                    scan_sub.update_through(k);
                    tactile_sub.update_through(k);
                }
            } else {
                pose_sub.update();
                scan_sub.update();
                tactile_sub.update();
            }
            let ticks = [pose_sub.tick(), scan_sub.tick(), tactile_sub.tick()];
            let Some(tick) = gate.ready(&ticks) else {
                // Joined mid-run (a swap or a restart): a step whose readings were sent before
                // we listened never completes; once a later reading is in, go on without it.
                if lockstep
                    && let Some(k) = pose_sub.tick()
                    && gate.last().is_none_or(|last| last < k)
                    && [scan_sub.newest_seen(), tactile_sub.newest_seen()]
                        .iter()
                        .any(|t| t.is_some_and(|t| t > k))
                {
                    skipped += 1;
                    gate.resume_after(k);
                    continue;
                }
                // A pose held this long without its readings is a step that cannot complete:
                // say what is missing, once.
                if lockstep && let Some(k) = pose_sub.tick().filter(|&k| gate.last() < Some(k)) {
                    let since = match incomplete_since {
                        Some((held, since)) if held == k => since,
                        _ => incomplete_since.insert((k, Instant::now())).1,
                    };
                    if since.elapsed() > INCOMPLETE_WARNING && !incomplete_warned {
                        incomplete_warned = true;
                        tracing::warn!(
                            pose = k,
                            scan = ?scan_sub.newest_seen(),
                            tactile = ?tactile_sub.newest_seen(),
                            "lockstep: step {k} has its pose but not all its readings"
                        );
                    }
                }
                break;
            };
            incomplete_since = None;
            if skipped > 0 {
                tracing::info!(
                    skipped,
                    tick,
                    "joined the run: skipped the steps whose readings came before us"
                );
                skipped = 0;
            }
            let (Some(pose), Some(scan), Some(tactile)) =
                (pose_sub.latest(), scan_sub.latest(), tactile_sub.latest())
            else {
                break;
            };
            let estimate = Pose2::new(pose.x, pose.y, pose.theta);
            maps.frontier
                .integrate_footprint(estimate, maps.robot_radius);
            if scan.header.tick == tick {
                maps.frontier.integrate_scan(estimate, scan);
            }
            if tactile.header.tick == tick {
                let touched =
                    maps.contact
                        .integrate_tactile(estimate, tactile, args.touch_threshold);
                for &(x, y) in touched {
                    maps.frontier.mark_occupied(x, y);
                }
            }
            let origin = pose.header.origin_ns;
            // The frontier grid last: it is what wakes planning and the monitor for this step.
            contact_pub.publish(tick, origin, |grid| maps.contact.write(grid))?;
            grid_pub.publish(tick, origin, |grid| maps.frontier.write(grid))?;
            ctx.count_step();
        }
    }
}

/// A copy of a grid message on the heap (once, at a hand-over: never on a hot path).
fn copy_grid(grid: &Grid) -> Box<Grid> {
    let mut copy: Box<Grid> = bytemuck::zeroed_box();
    bytemuck::bytes_of_mut(&mut *copy).copy_from_slice(bytemuck::bytes_of(grid));
    copy
}
