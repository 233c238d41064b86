//! The mapping process: builds the frontier grid (algorithms §5.2) from scans and the contact grid
//! (algorithms §2) from touch, both placed with the estimated pose.
//!
//! world/map once, then localization/pose, sensing/scan and sensing/tactile every step →
//! mapping/grid and mapping/contact. It works beside the control loop (planning uses the
//! previous step's grid), so in lockstep it may fall a step behind and takes every pose in order.

use clap::Parser;
use mole_mapping::{Maps, Settings};
use mole_runtime::{CommonArgs, Order, Process, Rule};
use mole_types::{Pose2, Role, topics};
use std::process::ExitCode;

/// mole's maps: frontier grid from range, contact grid from touch
#[derive(Debug, Parser)]
struct Args {
    #[command(flatten)]
    common: CommonArgs,
}

fn main() -> ExitCode {
    let args = Args::parse();
    mole_runtime::run_role(Role::Mapping, &args.common, |p| run(p, &args))
}

fn run(mut p: Process, args: &Args) -> Result<(), Box<dyn std::error::Error>> {
    let tuning = p.tuning::<Settings>(&args.common)?;
    let settings = *tuning.settings();
    // A replacement goes on from the grids of the one it replaces (the frontier grid is
    // published last, so its step is the one to resume after).
    let contact_was = p.resume_from(topics::MAPPING_CONTACT)?;
    let frontier_was = p.resume_from(topics::MAPPING_GRID)?;
    let pose = p.trigger(topics::LOCALIZATION_POSE, Order::EveryTick)?;
    let scan = p.input(topics::SENSING_SCAN, Rule::SameTick)?;
    let tactile = p.input(topics::SENSING_TACTILE, Rule::SameTick)?;
    let mut grid_out = p.output(topics::MAPPING_GRID)?;
    let mut contact_out = p.output(topics::MAPPING_CONTACT)?;

    p.run_tuned(
        tuning,
        |start| {
            let mut maps = Maps::new(start.map, &settings)?;
            if contact_was.is_some() || frontier_was.is_some() {
                let both = maps.restore(frontier_was.as_deref(), contact_was.as_deref());
                tracing::info!(both, "took over the running grids");
            }
            Ok(maps)
        },
        |maps, step| {
            let pose = step.trigger(pose);
            let estimate = Pose2::new(pose.x, pose.y, pose.theta);
            maps.integrate(estimate, step.get(scan), step.get(tactile));
            let (k, origin) = (step.tick(), step.origin_ns());
            // The frontier grid last: it is what wakes planning and the monitor for this step.
            contact_out.publish(k, origin, |grid| maps.contact.write(grid))?;
            grid_out.publish(k, origin, |grid| maps.frontier.write(grid))?;
            Ok(())
        },
        |maps, new| maps.set_settings(new).map_err(|e| e.to_string()),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use mole_runtime::{Harness, same_payload};
    use mole_sensing::Sensing;
    use mole_types::{Grid, Scan, Tactile};
    use mole_world::{World, bundled_scenario};

    /// The main on a harness, with a setting from its arguments: each step waits for the scan
    /// and touch of its tick (one pose came before them), and publishes both grids as the
    /// library builds them with that setting.
    #[test]
    fn each_pose_publishes_both_grids_built_from_its_ticks_scan_and_touch() {
        let scenario = bundled_scenario("default").unwrap();
        let map = scenario.world_map();
        let (mut world, mut sensing) = (World::new(&scenario), Sensing::new(&map, 7).unwrap());
        let harness = Harness::new();
        harness.deliver(topics::WORLD_MAP, 0, |m| *m = *map);
        let (mut readings, mut touch_of_step_3) = (Vec::new(), 0);
        for k in 0..5 {
            let mut truth = bytemuck::zeroed_box();
            world.write_step(&mut truth, 0, None);
            let pose = world.pose();
            let deliver_pose = || {
                harness.deliver(topics::LOCALIZATION_POSE, k, |p| {
                    (p.x, p.y, p.theta) = (pose.x, pose.y, pose.theta);
                })
            };
            // Step 3's pose comes before its scan and touch: the step waits for them.
            if k == 3 {
                deliver_pose();
            }
            harness.deliver(topics::SENSING_SCAN, k, |s| sensing.scan(&truth, s));
            let scan = harness.delivered_last::<Scan>();
            let last = harness.deliver(topics::SENSING_TACTILE, k, |t| sensing.tactile(&truth, t));
            let tactile = harness.delivered_last::<Tactile>();
            if k != 3 {
                deliver_pose();
            } else {
                touch_of_step_3 = last;
            }
            readings.push((pose, scan, tactile));
            world.step(0.4, 0.6);
        }
        let set = r#"{"mapping": {"log_odds": {"hit": 2.0}}}"#;
        let args = Args::parse_from(["mole-mapping", "--settings", set]);
        run(harness.process(Role::Mapping, &args.common).unwrap(), &args).unwrap();

        let settings: Settings = args.common.settings(Role::Mapping).unwrap();
        assert_ne!(settings, Settings::default());
        let mut maps = Maps::new(&map, &settings).unwrap();
        let (grids, contacts) = (
            harness.published(topics::MAPPING_GRID),
            harness.published(topics::MAPPING_CONTACT),
        );
        assert_eq!((grids.len(), contacts.len()), (5, 5));
        harness
            .check_publish_order(Role::Mapping.spec().outputs)
            .unwrap();
        for topic in [topics::MAPPING_GRID, topics::MAPPING_CONTACT] {
            assert!(
                harness.published_after(topic)[3] > touch_of_step_3,
                "{}",
                topic.name
            );
        }
        for (k, (pose, scan, tactile)) in readings.iter().enumerate() {
            maps.integrate(*pose, Some(scan), Some(tactile));
            let mut expected: Box<Grid> = bytemuck::zeroed_box();
            maps.frontier.write(&mut expected);
            assert_eq!(grids[k].header.tick, k as u64);
            assert!(same_payload(&*expected, &*grids[k]), "frontier grid at {k}");
            maps.contact.write(&mut expected);
            assert!(
                same_payload(&*expected, &*contacts[k]),
                "contact grid at {k}"
            );
        }
    }
}
