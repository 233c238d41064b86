//! The sensing process: turns the ground truth into what the robot's sensors would read.
//!
//! world/map once, then world/truth every step → sensing/{scan, tactile, odom, beacons, fix}.

use clap::Parser;
use mole_runtime::{CommonArgs, Order, Process};
use mole_sensing::Sensing;
use mole_types::{Role, topics};
use std::process::ExitCode;

/// mole's sensors: lidar, tactile, odometry, beacons, position fix
#[derive(Debug, Parser)]
struct Args {
    #[command(flatten)]
    common: CommonArgs,
}

fn main() -> ExitCode {
    let args = Args::parse();
    mole_runtime::run_role(Role::Sensing, &args.common, run)
}

fn run(mut p: Process) -> Result<(), Box<dyn std::error::Error>> {
    // A replacement (a restart, a swap) goes on in the odom frame of the one before it.
    let odom_was = p.resume_from(topics::SENSING_ODOM)?;
    let truth = p.trigger(topics::WORLD_TRUTH, Order::Newest)?;
    let mut scan_out = p.output(topics::SENSING_SCAN)?;
    let mut tactile_out = p.output(topics::SENSING_TACTILE)?;
    let mut odom_out = p.output(topics::SENSING_ODOM)?;
    let mut beacons_out = p.output(topics::SENSING_BEACONS)?;
    let mut fix_out = p.output(topics::SENSING_FIX)?;

    p.run(
        |start| {
            let mut sensing = Sensing::new(start.map, start.seed)?;
            if let Some(odom) = odom_was.as_deref() {
                sensing.resume_odometry(odom);
            }
            Ok(sensing)
        },
        |sensing, step| {
            let truth = step.trigger(truth);
            // The world's final state ends the run: no step follows it, so nothing is sensed.
            if truth.is_end() {
                return Ok(());
            }
            let (k, origin) = (step.tick(), step.origin_ns());
            // Odometry goes last: it triggers localization, whose pose triggers mapping and
            // planning, so every other reading of this step is already delivered when they run.
            fix_out.publish(k, origin, |m| sensing.fix(truth, m))?;
            beacons_out.publish(k, origin, |m| sensing.beacons(truth, m))?;
            tactile_out.publish(k, origin, |m| sensing.tactile(truth, m))?;
            scan_out.publish(k, origin, |m| sensing.scan(truth, m))?;
            odom_out.publish(k, origin, |m| sensing.odom(truth, m))?;
            Ok(())
        },
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use mole_runtime::{Harness, same_payload};
    use mole_types::{Message, Topic, Truth, WorldMap};
    use mole_world::{World, bundled_scenario};

    /// The main on a harness: each truth gives one reading of every sensor at its tick, the
    /// ones the library senses from the same truths in the same order; an invalid truth is
    /// dropped, counted, and senses nothing.
    #[test]
    fn each_truth_gives_one_reading_of_every_sensor_and_an_invalid_one_none() {
        let scenario = bundled_scenario("default").unwrap();
        let (mut world, harness) = (World::new(&scenario), Harness::new());
        harness.deliver(topics::WORLD_MAP, 0, |m| scenario.write_world_map(m));
        let mut truths = Vec::new();
        for k in 0..4 {
            harness.deliver(topics::WORLD_TRUTH, k, |t| world.write_step(t, 0, None));
            truths.push(harness.delivered_last::<Truth>());
            world.step(0.3, 0.5);
        }
        harness.deliver(topics::WORLD_TRUTH, 4, |t| t.x = f64::NAN);
        run(harness
            .process(Role::Sensing, &Args::parse_from(["mole-sensing"]).common)
            .unwrap())
        .unwrap();

        assert_eq!(harness.invalid(topics::WORLD_TRUTH.name), 1);
        harness
            .check_publish_order(Role::Sensing.spec().outputs)
            .unwrap();
        let mut map: Box<WorldMap> = bytemuck::zeroed_box();
        scenario.write_world_map(&mut map);
        let mut sensing = Sensing::new(&map, scenario.seed).unwrap();
        fn expect<M: Message>(h: &Harness, topic: Topic<M>, k: usize, make: impl FnOnce(&mut M)) {
            let published = h.published(topic);
            assert_eq!(published.len(), 4, "{}", topic.name);
            assert_eq!(published[k].header().tick, k as u64, "{}", topic.name);
            let mut expected: Box<M> = bytemuck::zeroed_box();
            make(&mut expected);
            assert!(
                same_payload(&*expected, &*published[k]),
                "{} at {k}",
                topic.name
            );
        }
        for (k, truth) in truths.iter().enumerate() {
            expect(&harness, topics::SENSING_FIX, k, |m| sensing.fix(truth, m));
            expect(&harness, topics::SENSING_BEACONS, k, |m| {
                sensing.beacons(truth, m)
            });
            expect(&harness, topics::SENSING_TACTILE, k, |m| {
                sensing.tactile(truth, m)
            });
            expect(&harness, topics::SENSING_SCAN, k, |m| {
                sensing.scan(truth, m)
            });
            expect(&harness, topics::SENSING_ODOM, k, |m| {
                sensing.odom(truth, m)
            });
        }
    }
}
