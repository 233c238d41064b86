//! The world process: steps the simulation and publishes the ground truth.
//!
//! world/map once (history 1, for late joiners) → every step: planning/cmd in, world/truth and
//! stack/tick out. Realtime: one step per period with the newest command. Lockstep: step k+1
//! only once the command for step k arrived.

use clap::Parser;
use mole_runtime::{ClockMode, CommonArgs, Context, Wake, now_ns};
use mole_types::{EndReason, MODE_DONE, TICK_END, TRUTH_END, topics};
use mole_world::{World, load_scenario};
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::{Duration, Instant};

/// A command older than this stops the robot (realtime): a planner that died must not leave
/// it driving.
const COMMAND_TIMEOUT: Duration = Duration::from_millis(500);
/// Lockstep: with no command for this long, publish the step again (a consumer restarted).
const LOCKSTEP_RESEND: Duration = Duration::from_secs(1);
/// How often late subscribers (a restarted process) are handed the map from history.
const MAP_REFRESH_TICKS: u64 = 25;

#[derive(Debug, Parser)]
#[command(
    name = "mole-world",
    about = "mole's world simulation: unicycle dynamics, contacts, ground truth"
)]
struct Args {
    #[command(flatten)]
    common: CommonArgs,
    /// Scenario file (TOML).
    #[arg(long, env = "MOLE_SCENARIO", default_value = "scenarios/default.toml")]
    scenario: PathBuf,
    /// Steps to run before the run ends.
    #[arg(long, env = "MOLE_TICKS", default_value_t = 3000)]
    ticks: u64,
    /// Keep running after the goal is reached.
    #[arg(long, env = "MOLE_NO_STOP_AT_GOAL")]
    no_stop_at_goal: bool,
}

fn main() -> ExitCode {
    let args = Args::parse();
    let mut scenario = match load_scenario(&args.scenario) {
        Ok(s) => s,
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::from(2);
        }
    };
    if let Some(seed) = args.common.seed {
        scenario.seed = seed;
    }
    mole_runtime::exit_code(run(&args, &scenario))
}

fn run(args: &Args, scenario: &mole_world::Scenario) -> Result<(), Box<dyn std::error::Error>> {
    let mut ctx = Context::new("world", &args.common)?;
    let mut map_pub = ctx.publisher(topics::WORLD_MAP)?;
    let mut truth_pub = ctx.publisher(topics::WORLD_TRUTH)?;
    let mut tick_pub = ctx.publisher(topics::STACK_TICK)?;
    let mut cmd_sub = ctx.subscriber(topics::PLANNING_CMD)?;
    let waitset = ctx.waitset()?;
    let cmd_wake = cmd_sub.waker();
    let _cmd_attached = waitset.attach(&cmd_wake)?;
    // The command closes the control loop: be awake for it (realtime).
    ctx.anticipate(&waitset, &cmd_wake);

    let mut world = World::new(scenario);
    let dt = scenario.dt;
    map_pub.publish(0, now_ns(), |map| scenario.write_world_map(map))?;
    ctx.ready();

    let mode = ctx.mode();
    let period = Duration::from_secs_f64(1.0 / ctx.rate_hz().max(1e-3));
    let stop_at_goal = !args.no_stop_at_goal;
    let mut tick: u64 = 0;
    // The command to apply next, and its loop latency (origin → receipt).
    let mut command = (0.0_f64, 0.0_f64);
    let mut command_latency_ns = 0_u64;
    let mut command_received = Instant::now();
    let mut last_applied_tick: Option<u64> = None;
    let mut exploration_complete = false;

    let mut publish_step = |tick: u64, world: &World, latency_ns: u64, end: u32| {
        let origin = now_ns();
        let truth = truth_pub.publish(tick, origin, |t| {
            world.write_truth(t);
            t.cmd_latency_ns = latency_ns;
            t.end_reason = end;
            if end != 0 {
                t.flags |= TRUTH_END;
            } else {
                t.flags &= !TRUTH_END;
            }
        });
        let clock = tick_pub.publish(tick, origin, |c| {
            c.dt = dt;
            c.flags = if end != 0 { TICK_END } else { 0 };
            c.mode = mode.code();
        });
        truth.and(clock)
    };

    publish_step(tick, &world, 0, 0)?;
    let mut next_step = Instant::now() + period;
    let mut last_publish = Instant::now();
    loop {
        let deadline = match mode {
            ClockMode::Realtime => next_step,
            ClockMode::Lockstep => last_publish + LOCKSTEP_RESEND,
        };
        let wake = waitset.wait(&mut ctx, Some(deadline))?;
        if wake == Wake::Shutdown {
            publish_step(tick, &world, 0, EndReason::Stopped.code())?;
            tracing::info!(tick, "stopped");
            return Ok(());
        }
        // Newest by tick (Subscriber::update): a late answer to an older step never wins.
        let fresh = if cmd_sub.update() {
            cmd_sub.latest().map(|cmd| {
                exploration_complete = cmd.mode == MODE_DONE;
                (cmd.header.tick, cmd.v, cmd.omega, cmd.header.origin_ns)
            })
        } else {
            None
        };
        if let Some((cmd_tick, v, omega, origin)) = fresh {
            command = (v, omega);
            command_latency_ns = now_ns().saturating_sub(origin);
            command_received = Instant::now();
            if mode == ClockMode::Lockstep && cmd_tick != tick {
                // A command for an older step (a resend answered twice): not this step's.
                continue;
            }
        }
        let due = match mode {
            ClockMode::Realtime => Instant::now() >= next_step,
            ClockMode::Lockstep => {
                fresh.is_some_and(|f| f.0 == tick && last_applied_tick != Some(tick))
            }
        };
        if !due {
            if mode == ClockMode::Lockstep && wake == Wake::Timeout {
                tracing::warn!(
                    tick,
                    "no command for {LOCKSTEP_RESEND:?}: publishing the step again"
                );
                publish_step(tick, &world, 0, 0)?;
                last_publish = Instant::now();
            }
            continue;
        }
        if mode == ClockMode::Realtime && command_received.elapsed() > COMMAND_TIMEOUT {
            command = (0.0, 0.0);
        }
        last_applied_tick = Some(tick);
        world.step(command.0, command.1);
        ctx.count_step();
        tick += 1;
        let latency = std::mem::take(&mut command_latency_ns);
        let end = if tick >= args.ticks {
            EndReason::Ticks.code()
        } else if stop_at_goal && world.goal_reached() {
            EndReason::GoalReached.code()
        } else if exploration_complete {
            // The planner found no reachable frontier left (algorithms §5): the run is done.
            EndReason::ExplorationComplete.code()
        } else {
            0
        };
        publish_step(tick, &world, latency, end)?;
        last_publish = Instant::now();
        if tick.is_multiple_of(MAP_REFRESH_TICKS) {
            map_pub.update_connections();
        }
        if end != 0 {
            tracing::info!(tick, end_reason = end, "run complete");
            return Ok(());
        }
        next_step += period;
        if mode == ClockMode::Realtime && Instant::now() > next_step + period * 10 {
            // Far behind (the machine stalled): do not fire a burst of catch-up steps.
            next_step = Instant::now() + period;
        }
    }
}
