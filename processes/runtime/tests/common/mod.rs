//! What the IPC tests of the runtime publish by hand in place of the world and sensing.

use mole_runtime::Publisher;
use mole_types::{Odom, WorldMap};
use std::time::Duration;

/// A small world's map, once the process under test listens (it subscribes as it starts its
/// loop).
pub fn publish_map(map: &mut Publisher<WorldMap>) {
    std::thread::sleep(Duration::from_millis(200));
    map.publish(0, 1, |m| {
        (m.arena_width, m.arena_height, m.dt) = (1.0, 1.0, 0.01);
        (m.grid_resolution, m.robot.radius) = (0.1, 0.1);
    })
    .unwrap();
}

/// Odometry of step `k`: standing still.
pub fn publish_odom(odom: &mut Publisher<Odom>, k: u64) {
    odom.publish(k, 1, |m| (m.v, m.omega, m.dt) = (0.0, 0.0, 0.01))
        .unwrap();
}
