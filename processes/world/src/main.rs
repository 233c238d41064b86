//! The world process: steps the simulation and publishes the ground truth; it keeps the
//! stack's time.
//!
//! world/map once (history 1, for late joiners) → every step: planning/cmd in, world/truth and
//! stack/tick out. The run ends at the tick limit, when the planner reports done (at its goal,
//! or nothing left to explore), or on a shutdown.

use clap::Parser;
use mole_runtime::{ClockEvent, CommonArgs, Flow, Order, Process, now_ns};
use mole_types::{EndReason, Role, TICK_END, env, topics};
use mole_world::{World, load_scenario};
use std::path::PathBuf;
use std::process::ExitCode;

/// How often late subscribers (a restarted process) are handed the map from history.
const MAP_REFRESH_TICKS: u64 = 25;

/// mole's world simulation: unicycle dynamics, contacts, ground truth
#[derive(Debug, Parser)]
struct Args {
    #[command(flatten)]
    common: CommonArgs,
    /// Scenario file (TOML).
    #[arg(long, env = env::SCENARIO, default_value = "scenarios/default.toml")]
    scenario: PathBuf,
    /// Steps to run before the run ends.
    #[arg(long, env = env::TICKS, default_value_t = 3000)]
    ticks: u64,
    /// Lockstep: hold after step 0 until an operator paces the run.
    #[arg(long, env = env::PAUSED)]
    paused: bool,
}

fn main() -> ExitCode {
    let args = Args::parse();
    mole_runtime::run_role(Role::World, &args.common, |p| run(p, &args))
}

fn run(mut p: Process, args: &Args) -> Result<(), Box<dyn std::error::Error>> {
    let mut scenario =
        load_scenario(&args.scenario).map_err(|e| mole_runtime::BadInput(e.to_string()))?;
    scenario.seed = args.common.seed.unwrap_or(scenario.seed);
    if args.paused {
        p.start_held();
    }
    // Restarted after a crash: the run goes on from the last truth. In lockstep the step after
    // it takes the command the planner sent to the dead world (from history), so the run is the
    // one an unkilled world makes; in realtime it is taken with the robot stopped.
    let truth_was = p.resume_from(topics::WORLD_TRUTH)?;
    let cmd = p.trigger(topics::PLANNING_CMD, Order::Newest)?;
    let mut map_out = p.output(topics::WORLD_MAP)?;
    let mut truth_out = p.output(topics::WORLD_TRUTH)?;
    let mut tick_out = p.output(topics::STACK_TICK)?;
    let mode = p.context().mode();
    let mut world = match truth_was {
        Some(truth) => World::resume(&scenario, &truth),
        None => World::new(&scenario),
    };
    map_out.publish(0, now_ns(), |map| scenario.write_world_map(map))?;

    p.run_clock(cmd, |event| {
        let (tick, latency_ns, end) = match event {
            ClockEvent::Publish { tick } => (tick, 0, None),
            ClockEvent::Stop { tick } => (tick, 0, Some(EndReason::Stopped)),
            ClockEvent::Advance {
                tick,
                reply,
                latency_ns,
            } => {
                world.step(reply.map_or(0.0, |c| c.v), reply.map_or(0.0, |c| c.omega));
                let planner_done = reply.and_then(|c| EndReason::asked_by_planner(c.mode));
                let end = (tick >= args.ticks)
                    .then_some(EndReason::Ticks)
                    .or(planner_done);
                if tick.is_multiple_of(MAP_REFRESH_TICKS) {
                    map_out.update_connections();
                }
                (tick, latency_ns, end)
            }
        };
        let origin = now_ns();
        truth_out.publish(tick, origin, |t| world.write_step(t, latency_ns, end))?;
        tick_out.publish(tick, origin, |c| {
            (c.dt, c.mode) = (scenario.dt, mode.code());
            c.flags = if end.is_some() { TICK_END } else { 0 };
        })?;
        Ok(if end.is_some() {
            Flow::End
        } else {
            Flow::Continue
        })
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use mole_runtime::{Harness, same_payload};
    use mole_types::{TRUTH_END, Truth};

    /// The main on a harness, as the clock: it publishes the map and step 0, takes a step on
    /// each reply to the step it published (an answer to an older step does not count), steps
    /// the robot by it, and ends at the tick limit with the end on the last truth.
    #[test]
    fn each_reply_to_the_published_step_advances_the_world_to_the_tick_limit() {
        let path = mole_world::bundled_scenarios().join("default.toml");
        let path = path.to_str().unwrap();
        let args = Args::parse_from(["mole-world", "--scenario", path, "--ticks", "3"]);
        let harness = Harness::new();
        let command =
            |k: u64| move |c: &mut mole_types::Cmd| (c.v, c.omega) = (0.2 * k as f64, 0.5);
        for k in 0..5 {
            harness.deliver(topics::PLANNING_CMD, k, command(k));
            if k == 1 {
                // A late resend of step 0's answer, after step 1's.
                harness.deliver(topics::PLANNING_CMD, 0, command(9));
            }
        }
        run(harness.process(Role::World, &args.common).unwrap(), &args).unwrap();

        let scenario = load_scenario(path.as_ref()).unwrap();
        let expected_map = scenario.world_map();
        let maps = harness.published(topics::WORLD_MAP);
        harness
            .check_publish_order(Role::World.spec().outputs)
            .unwrap();
        assert_eq!(maps.len(), 1);
        assert!(same_payload(&*expected_map, &*maps[0]));
        let (truths, ticks) = (
            harness.published(topics::WORLD_TRUTH),
            harness.published(topics::STACK_TICK),
        );
        assert_eq!((truths.len(), ticks.len()), (4, 4));
        assert_eq!(
            harness.undelivered(),
            2,
            "nothing is read after the last step"
        );
        let mut world = World::new(&scenario);
        for (k, truth) in truths.iter().enumerate() {
            let end = (k == 3).then_some(EndReason::Ticks);
            let mut expected: Box<Truth> = bytemuck::zeroed_box();
            world.write_step(&mut expected, 0, end);
            let mut published = truth.clone();
            published.cmd_latency_ns = 0;
            assert_eq!(truth.header.tick, k as u64);
            assert!(same_payload(&*expected, &*published), "truth at {k}");
            assert_eq!(ticks[k].flags == TICK_END, k == 3);
            assert_eq!(truth.flags & TRUTH_END != 0, k == 3);
            world.step(0.2 * k as f64, 0.5);
        }
    }
}
