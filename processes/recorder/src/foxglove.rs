//! A recording exported for Foxglove and Lichtblick: the same run on channels that carry
//! Foxglove's well-known schemas (`foxglove.PoseInFrame`, `foxglove.LaserScan`, `foxglove.Grid`,
//! `foxglove.SceneUpdate`, `foxglove.FrameTransform`) as JSON, so either tool shows the robot,
//! its scans, its maps and its beliefs without a plug-in.
//!
//! The conversions ([`Converter`]) take a sample's fixed-layout bytes and its log time and give
//! the JSON messages it becomes; [`export`] streams a recording through them, one message at a
//! time, into a new MCAP file. Every exported message keeps its source's log time.

use crate::export::{Exporting, Format};
use mole_types::{
    Grid, Header, Landmarks, Particles, PlanStatus, Pose, Scan, Truth, WorldMap, topics,
};
use serde_json::{Value, json};
use std::collections::BTreeMap;

/// The schema encoding of every exported channel.
pub const JSON_SCHEMA_ENCODING: &str = "jsonschema";
/// The message encoding of every exported channel.
pub const JSON_MESSAGE_ENCODING: &str = "json";
/// The fixed frame every position is given in.
pub const MAP_FRAME: &str = "map";
/// The robot's frame (`/tf` places it in [`MAP_FRAME`]); the scan is taken from its centre.
pub const ROBOT_FRAME: &str = "base_link";
/// χ²(2 degrees of freedom) at 95 %: a 2D Gaussian's 95 % ellipse is where the Mahalanobis
/// distance squared equals it.
const CHI2_2D_95: f64 = 5.991_464_547_107_979;
/// Points on a drawn ellipse.
const ELLIPSE_POINTS: usize = 36;
/// Length of a particle's heading tick (m).
const PARTICLE_TICK: f64 = 0.1;

/// Foxglove's well-known schemas, as JSON Schema: the published ones (`@foxglove/schemas` 2.1.0,
/// see `foxglove-schemas/README.md`), embedded as Foxglove writes them.
pub mod schemas {
    pub const POSE_IN_FRAME: &str = "foxglove.PoseInFrame";
    pub const FRAME_TRANSFORM: &str = "foxglove.FrameTransform";
    pub const LASER_SCAN: &str = "foxglove.LaserScan";
    pub const GRID: &str = "foxglove.Grid";
    pub const SCENE_UPDATE: &str = "foxglove.SceneUpdate";

    /// Every schema an export writes, with its JSON Schema text.
    pub const ALL: [(&str, &str); 5] = [
        (
            POSE_IN_FRAME,
            include_str!("../foxglove-schemas/PoseInFrame.json"),
        ),
        (
            FRAME_TRANSFORM,
            include_str!("../foxglove-schemas/FrameTransform.json"),
        ),
        (
            LASER_SCAN,
            include_str!("../foxglove-schemas/LaserScan.json"),
        ),
        (GRID, include_str!("../foxglove-schemas/Grid.json")),
        (
            SCENE_UPDATE,
            include_str!("../foxglove-schemas/SceneUpdate.json"),
        ),
    ];

    /// The JSON Schema text of the well-known schema `name` (`None` for one this export does
    /// not write).
    pub fn json_schema(name: &str) -> Option<&'static str> {
        ALL.iter().find(|(n, _)| *n == name).map(|(_, text)| *text)
    }
}

/// Every channel of the mapping, with the mole topic it comes from and its schema: what
/// `mole export --foxglove` writes and what `mole-foxglove` serves live. The converter makes
/// nothing else (a test checks each topic's output against this table).
pub const CHANNELS: [Channel; 11] = {
    use schemas::*;
    const fn c(source: &'static str, channel: &'static str, schema: &'static str) -> Channel {
        Channel {
            source,
            channel,
            schema,
        }
    }
    [
        c(topics::WORLD_TRUTH.name, "/truth", POSE_IN_FRAME),
        c(topics::WORLD_TRUTH.name, "/tf", FRAME_TRANSFORM),
        c(topics::LOCALIZATION_POSE.name, "/pose", POSE_IN_FRAME),
        c(
            topics::LOCALIZATION_POSE.name,
            "/pose/ellipse",
            SCENE_UPDATE,
        ),
        c(topics::SENSING_SCAN.name, "/scan", LASER_SCAN),
        c(topics::MAPPING_GRID.name, "/grid", GRID),
        c(topics::MAPPING_CONTACT.name, "/contact", GRID),
        c(topics::WORLD_MAP.name, "/map", SCENE_UPDATE),
        c(topics::PLANNING_STATUS.name, "/path", SCENE_UPDATE),
        c(
            topics::LOCALIZATION_PARTICLES.name,
            "/particles",
            SCENE_UPDATE,
        ),
        c(
            topics::LOCALIZATION_LANDMARKS.name,
            "/landmarks",
            SCENE_UPDATE,
        ),
    ]
};

/// One channel of the mapping.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Channel {
    /// The mole topic its messages are made from.
    pub source: &'static str,
    /// Its name in Foxglove.
    pub channel: &'static str,
    /// Its well-known schema.
    pub schema: &'static str,
}

/// One exported message: the channel it goes on, its schema and its JSON.
#[derive(Debug, Clone, PartialEq)]
pub struct Converted {
    pub topic: &'static str,
    pub schema: &'static str,
    pub message: Value,
}

impl Converted {
    fn new(topic: &'static str, schema: &'static str, message: Value) -> Converted {
        Converted {
            topic,
            schema,
            message,
        }
    }
}

/// Turns recorded samples into Foxglove messages; remembers each grid's last content, so a grid
/// is exported only when it changed.
#[derive(Debug, Default)]
pub struct Converter {
    /// Each grid channel's last exported content.
    last_grid: BTreeMap<&'static str, Vec<u8>>,
}

impl Converter {
    /// The messages the sample `data` of `topic`, recorded at `log_time` (ns), becomes; none for
    /// a topic without a Foxglove counterpart or a grid that did not change. `data` must be the
    /// topic's whole message (the caller checks its size).
    pub fn convert(&mut self, topic: &str, log_time: u64, data: &[u8]) -> Vec<Converted> {
        use schemas::*;
        let t = log_time;
        match topic {
            name if name == topics::WORLD_TRUTH.name => {
                let truth: Box<Truth> = boxed(data);
                vec![
                    Converted::new("/truth", POSE_IN_FRAME, truth_pose(&truth, t)),
                    Converted::new("/tf", FRAME_TRANSFORM, robot_transform(&truth, t)),
                ]
            }
            name if name == topics::LOCALIZATION_POSE.name => {
                let pose: Box<Pose> = boxed(data);
                vec![
                    Converted::new("/pose", POSE_IN_FRAME, estimated_pose(&pose, t)),
                    Converted::new("/pose/ellipse", SCENE_UPDATE, pose_ellipse(&pose, t)),
                ]
            }
            name if name == topics::SENSING_SCAN.name => {
                let scan: Box<Scan> = boxed(data);
                vec![Converted::new("/scan", LASER_SCAN, laser_scan(&scan, t))]
            }
            name if name == topics::MAPPING_GRID.name => self.grid("/grid", t, data),
            name if name == topics::MAPPING_CONTACT.name => self.grid("/contact", t, data),
            name if name == topics::WORLD_MAP.name => {
                let map: Box<WorldMap> = boxed(data);
                vec![Converted::new("/map", SCENE_UPDATE, world_map(&map, t))]
            }
            name if name == topics::PLANNING_STATUS.name => {
                let status: Box<PlanStatus> = boxed(data);
                vec![Converted::new(
                    "/path",
                    SCENE_UPDATE,
                    planned_path(&status, t),
                )]
            }
            name if name == topics::LOCALIZATION_PARTICLES.name => {
                let particles: Box<Particles> = boxed(data);
                vec![Converted::new(
                    "/particles",
                    SCENE_UPDATE,
                    particle_set(&particles, t),
                )]
            }
            name if name == topics::LOCALIZATION_LANDMARKS.name => {
                let landmarks: Box<Landmarks> = boxed(data);
                vec![Converted::new(
                    "/landmarks",
                    SCENE_UPDATE,
                    landmark_map(&landmarks, t),
                )]
            }
            _ => Vec::new(),
        }
    }

    /// Forgets the grids exported, so the next of each is exported even if unchanged (for a
    /// client that subscribed since).
    pub fn forget_grids(&mut self) {
        self.last_grid.clear();
    }

    /// The grid on `channel` if its content (all but the header) differs from the last one.
    fn grid(&mut self, channel: &'static str, log_time: u64, data: &[u8]) -> Vec<Converted> {
        let content = &data[size_of::<Header>()..];
        if self
            .last_grid
            .get(channel)
            .is_some_and(|last| last == content)
        {
            return Vec::new();
        }
        self.last_grid.insert(channel, content.to_vec());
        let grid: Box<Grid> = boxed(data);
        vec![Converted::new(
            channel,
            schemas::GRID,
            occupancy_grid(&grid, log_time),
        )]
    }
}

/// A recorded message's bytes as the message, on the heap: grids and particle sets are
/// hundreds of KiB. The bytes are the message's size (the tape's layout check saw to that).
fn boxed<M: bytemuck::Pod>(data: &[u8]) -> Box<M> {
    let mut message: Box<M> = bytemuck::zeroed_box();
    bytemuck::bytes_of_mut(&mut *message).copy_from_slice(data);
    message
}

/// A log time (ns) as Foxglove's `{sec, nsec}`.
pub fn timestamp(log_time: u64) -> Value {
    json!({ "sec": log_time / 1_000_000_000, "nsec": log_time % 1_000_000_000 })
}

/// A planar pose: position on the ground, heading `yaw` as a rotation about z.
pub fn planar_pose(x: f64, y: f64, yaw: f64) -> Value {
    json!({ "position": { "x": x, "y": y, "z": 0.0 }, "orientation": yaw_quaternion(yaw) })
}

/// The unit quaternion of a rotation by `yaw` about z.
fn yaw_quaternion(yaw: f64) -> Value {
    let half = yaw / 2.0;
    json!({ "x": 0.0, "y": 0.0, "z": half.sin(), "w": half.cos() })
}

/// `foxglove.PoseInFrame` of the true pose, in the map frame.
pub fn truth_pose(truth: &Truth, log_time: u64) -> Value {
    pose_in_map(truth.x, truth.y, truth.theta, log_time)
}

/// `foxglove.PoseInFrame` of the estimated pose, in the map frame.
pub fn estimated_pose(pose: &Pose, log_time: u64) -> Value {
    pose_in_map(pose.x, pose.y, pose.theta, log_time)
}

fn pose_in_map(x: f64, y: f64, yaw: f64, log_time: u64) -> Value {
    json!({ "timestamp": timestamp(log_time), "frame_id": MAP_FRAME,
            "pose": planar_pose(x, y, yaw) })
}

/// `foxglove.FrameTransform` placing the robot's frame at its true pose in the map.
pub fn robot_transform(truth: &Truth, log_time: u64) -> Value {
    json!({ "timestamp": timestamp(log_time), "parent_frame_id": MAP_FRAME,
            "child_frame_id": ROBOT_FRAME,
            "translation": { "x": truth.x, "y": truth.y, "z": 0.0 },
            "rotation": yaw_quaternion(truth.theta) })
}

/// `foxglove.LaserScan` in the robot's frame, its beams from `angle_min` on.
pub fn laser_scan(scan: &Scan, log_time: u64) -> Value {
    let ranges = scan.ranges();
    let end = f64::from(scan.angle_min)
        + f64::from(scan.angle_increment) * ranges.len().saturating_sub(1) as f64;
    json!({ "timestamp": timestamp(log_time), "frame_id": ROBOT_FRAME,
            "pose": planar_pose(0.0, 0.0, 0.0),
            "start_angle": scan.angle_min, "end_angle": end,
            "ranges": ranges, "intensities": [] })
}

/// `foxglove.Grid` of the cells in use: one `uint8` per cell, rows along +y from the origin.
pub fn occupancy_grid(grid: &Grid, log_time: u64) -> Value {
    /// Foxglove's `NumericType` of an unsigned byte.
    const UINT8: u32 = 1;
    json!({ "timestamp": timestamp(log_time), "frame_id": MAP_FRAME,
            "pose": planar_pose(grid.origin_x, grid.origin_y, 0.0),
            "column_count": grid.width,
            "cell_size": { "x": grid.resolution, "y": grid.resolution },
            "row_stride": grid.width, "cell_stride": 1,
            "fields": [{ "name": "cell", "offset": 0, "type": UINT8 }],
            "data": base64(grid.cells()) })
}

/// The 95 % ellipse of a 2×2 covariance `[xx, xy, yx, yy]`: semi-axes (major, minor) and the
/// major axis's angle from x.
pub fn ellipse_95(covariance: [f64; 4]) -> (f64, f64, f64) {
    let [a, b, _, c] = covariance;
    let mean = (a + c) / 2.0;
    let spread = (((a - c) / 2.0).powi(2) + b * b).sqrt();
    let axis = |eigenvalue: f64| (CHI2_2D_95 * eigenvalue.max(0.0)).sqrt();
    (
        axis(mean + spread),
        axis(mean - spread),
        0.5 * (2.0 * b).atan2(a - c),
    )
}

/// The points of the 95 % ellipse of `covariance` around (x, y).
fn ellipse_points(x: f64, y: f64, covariance: [f64; 4]) -> Vec<Value> {
    let (major, minor, angle) = ellipse_95(covariance);
    let (sin, cos) = angle.sin_cos();
    (0..ELLIPSE_POINTS)
        .map(|k| {
            let phi = std::f64::consts::TAU * k as f64 / ELLIPSE_POINTS as f64;
            let (u, v) = (major * phi.cos(), minor * phi.sin());
            json!({ "x": x + cos * u - sin * v, "y": y + sin * u + cos * v, "z": 0.0 })
        })
        .collect()
}

fn color(r: f64, g: f64, b: f64, a: f64) -> Value {
    json!({ "r": r, "g": g, "b": b, "a": a })
}

/// Foxglove's `LinePrimitive` types.
const LINE_STRIP: u32 = 0;
const LINE_LOOP: u32 = 1;
const LINE_LIST: u32 = 2;

/// A line of one colour (no per-point `colors`) through `points` in order (no `indices`).
fn line(kind: u32, points: Vec<Value>, thickness: f64, rgba: Value) -> Value {
    json!({ "type": kind, "pose": planar_pose(0.0, 0.0, 0.0), "thickness": thickness,
            "scale_invariant": false, "points": points, "color": rgba,
            "colors": [], "indices": [] })
}

/// The primitives a `foxglove.SceneEntity` holds, each a list its schema requires (empty when
/// unused).
const PRIMITIVES: [&str; 8] = [
    "arrows",
    "cubes",
    "spheres",
    "cylinders",
    "lines",
    "triangles",
    "texts",
    "models",
];

/// A scene entity `id` in the map frame, with the primitives in `shapes` (the others empty):
/// replaced by the next one of its id, shown until then.
fn entity(id: &str, log_time: u64, shapes: Value) -> Value {
    let mut entity = json!({ "timestamp": timestamp(log_time), "frame_id": MAP_FRAME, "id": id,
                             "lifetime": { "sec": 0, "nsec": 0 }, "frame_locked": false,
                             "metadata": [] });
    debug_assert!(
        shapes
            .as_object()
            .is_some_and(|s| s.keys().all(|k| PRIMITIVES.contains(&k.as_str()))),
        "not a primitive of an entity: {shapes}"
    );
    for primitive in PRIMITIVES {
        entity[primitive] = shapes.get(primitive).cloned().unwrap_or_else(|| json!([]));
    }
    entity
}

fn scene_update(entities: Vec<Value>) -> Value {
    json!({ "deletions": [], "entities": entities })
}

/// `foxglove.SceneUpdate` with the 95 % ellipse of the estimate's (x, y) covariance.
pub fn pose_ellipse(pose: &Pose, log_time: u64) -> Value {
    let c = pose.covariance;
    let points = ellipse_points(pose.x, pose.y, [c[0], c[1], c[3], c[4]]);
    let shapes = json!({ "lines": [line(LINE_LOOP, points, 0.02, color(1.0, 0.6, 0.0, 1.0))] });
    scene_update(vec![entity("pose_ellipse", log_time, shapes)])
}

/// `foxglove.SceneUpdate` of the arena: obstacles as cubes, beacons as spheres, the goal as a
/// green sphere.
pub fn world_map(map: &WorldMap, log_time: u64) -> Value {
    let cubes: Vec<Value> = map
        .obstacles()
        .iter()
        .map(|o| {
            json!({ "pose": planar_pose(o.cx, o.cy, 0.0),
                    "size": { "x": o.side, "y": o.side, "z": 0.5 },
                    "color": color(0.4, 0.4, 0.45, 1.0) })
        })
        .collect();
    let sphere = |x: f64, y: f64, d: f64, rgba: Value| {
        json!({ "pose": planar_pose(x, y, 0.0), "size": { "x": d, "y": d, "z": d },
                "color": rgba })
    };
    let mut spheres: Vec<Value> = map
        .beacons()
        .iter()
        .map(|b| sphere(b.x, b.y, 0.2, color(0.2, 0.4, 1.0, 1.0)))
        .collect();
    if map.has_goal == 1 {
        let d = 2.0 * map.goal_tolerance;
        spheres.push(sphere(map.goal_x, map.goal_y, d, color(0.1, 0.8, 0.2, 0.5)));
    }
    let (w, h) = (map.arena_width, map.arena_height);
    let corners = [(0.0, 0.0), (w, 0.0), (w, h), (0.0, h)]
        .iter()
        .map(|(x, y)| json!({ "x": x, "y": y, "z": 0.0 }))
        .collect();
    let border = line(LINE_LOOP, corners, 0.05, color(0.0, 0.0, 0.0, 1.0));
    let shapes = json!({ "cubes": cubes, "spheres": spheres, "lines": [border] });
    scene_update(vec![entity("world", log_time, shapes)])
}

/// `foxglove.SceneUpdate` of the planned path as a line through its waypoints.
pub fn planned_path(status: &PlanStatus, log_time: u64) -> Value {
    let points = status
        .path()
        .iter()
        .map(|[x, y]| json!({ "x": x, "y": y, "z": 0.0 }))
        .collect();
    let shapes = json!({ "lines": [line(LINE_STRIP, points, 0.04, color(0.9, 0.1, 0.9, 1.0))] });
    scene_update(vec![entity("path", log_time, shapes)])
}

/// `foxglove.SceneUpdate` of the particle set: one short tick per particle, from its position
/// along its heading.
pub fn particle_set(particles: &Particles, log_time: u64) -> Value {
    let points = particles
        .particles()
        .iter()
        .flat_map(|p| {
            let (x, y, theta) = (f64::from(p.x), f64::from(p.y), f64::from(p.theta));
            [
                json!({ "x": x, "y": y, "z": 0.0 }),
                json!({ "x": x + PARTICLE_TICK * theta.cos(),
                        "y": y + PARTICLE_TICK * theta.sin(), "z": 0.0 }),
            ]
        })
        .collect();
    let shapes = json!({ "lines": [line(LINE_LIST, points, 0.01, color(1.0, 0.2, 0.2, 0.8))] });
    scene_update(vec![entity("particles", log_time, shapes)])
}

/// `foxglove.SceneUpdate` of the landmark map: each landmark's mean as a sphere and its 95 %
/// ellipse.
pub fn landmark_map(landmarks: &Landmarks, log_time: u64) -> Value {
    let spheres: Vec<Value> = landmarks
        .landmarks()
        .iter()
        .map(|l| {
            json!({ "pose": planar_pose(l.x, l.y, 0.0), "size": { "x": 0.1, "y": 0.1, "z": 0.1 },
                    "color": color(0.0, 0.7, 0.9, 1.0) })
        })
        .collect();
    let lines: Vec<Value> = landmarks
        .landmarks()
        .iter()
        .map(|l| {
            let points = ellipse_points(l.x, l.y, l.covariance);
            line(LINE_LOOP, points, 0.02, color(0.0, 0.7, 0.9, 1.0))
        })
        .collect();
    let shapes = json!({ "spheres": spheres, "lines": lines });
    scene_update(vec![entity("landmarks", log_time, shapes)])
}

/// Standard base64 (RFC 4648, with padding), as Foxglove's JSON encoding of `bytes` fields.
pub fn base64(bytes: &[u8]) -> String {
    use base64::Engine as _;
    base64::engine::general_purpose::STANDARD.encode(bytes)
}

/// The Foxglove export's side of [`crate::export::export`]: each converted message as JSON on a
/// channel of its well-known schema.
impl Format for Converter {
    fn profile(&self) -> &'static str {
        ""
    }

    fn name(&self) -> &'static str {
        "foxglove"
    }

    fn schema(&self, name: &str) -> (String, &'static str, Vec<u8>) {
        let text = schemas::json_schema(name).expect("every converted message has a schema");
        (
            name.to_string(),
            JSON_SCHEMA_ENCODING,
            text.as_bytes().to_vec(),
        )
    }

    fn message_encoding(&self) -> &'static str {
        JSON_MESSAGE_ENCODING
    }

    fn channel_metadata(&self) -> BTreeMap<String, String> {
        BTreeMap::new()
    }

    fn convert(&mut self, topic: &str, log_time: u64, data: &[u8]) -> Vec<Exporting> {
        Converter::convert(self, topic, log_time, data)
            .into_iter()
            .map(|c| Exporting {
                topic: c.topic,
                schema: c.schema,
                data: c.message.to_string().into_bytes(),
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::schema::SCHEMA_ENCODING;
    use crate::tape::tests::{TempFile, sample, truth, write};
    use mole_types::{Landmark, Particle, Square};
    use std::fs::File;

    fn zeroed<M: bytemuck::Zeroable>() -> M {
        M::zeroed()
    }

    /// Each topic becomes exactly the channels [`CHANNELS`] gives it, with their schemas; a
    /// topic the table does not name becomes none.
    #[test]
    fn every_topic_becomes_the_channels_of_the_table() {
        let layouts = mole_types::layout::all();
        let mut converter = Converter::default();
        for (topic, type_name) in topics::all() {
            let size = layouts
                .iter()
                .find(|l| l.type_name == type_name)
                .unwrap()
                .size;
            let made: Vec<(&str, &str)> = converter
                .convert(topic, 1, &vec![0u8; size])
                .iter()
                .map(|c| (c.topic, c.schema))
                .collect();
            let table: Vec<(&str, &str)> = CHANNELS
                .iter()
                .filter(|c| c.source == topic)
                .map(|c| (c.channel, c.schema))
                .collect();
            assert_eq!(made, table, "{topic}");
        }
    }

    /// The yaw a planar quaternion encodes.
    fn yaw_of(orientation: &Value) -> f64 {
        let (z, w) = (
            orientation["z"].as_f64().unwrap(),
            orientation["w"].as_f64().unwrap(),
        );
        2.0 * z.atan2(w)
    }

    /// A truth becomes a pose in the map frame with its x, y and heading, stamped with its log
    /// time, and the robot's frame placed there.
    #[test]
    fn a_truth_becomes_a_pose_in_the_map_frame() {
        let mut t = truth(250, 1.5);
        (t.y, t.theta) = (-2.25, 2.0);
        let out = Converter::default().convert(
            topics::WORLD_TRUTH.name,
            2_500_000_001,
            bytemuck::bytes_of(&t),
        );
        assert_eq!(out[0].topic, "/truth");
        assert_eq!(out[0].schema, "foxglove.PoseInFrame");
        let m = &out[0].message;
        assert_eq!(m["frame_id"], "map");
        assert_eq!(m["timestamp"], json!({ "sec": 2, "nsec": 500_000_001 }));
        assert_eq!(
            m["pose"]["position"],
            json!({ "x": 1.5, "y": -2.25, "z": 0.0 })
        );
        assert!((yaw_of(&m["pose"]["orientation"]) - 2.0).abs() < 1e-12);
        assert_eq!(out[1].schema, "foxglove.FrameTransform");
        assert_eq!(out[1].message["child_frame_id"], ROBOT_FRAME);
        assert_eq!(out[1].message["translation"]["y"], -2.25);
    }

    /// A grid becomes a Grid of its width in columns, its cells as base64 bytes of
    /// width × height, placed at its origin; the same grid again is not exported.
    #[test]
    fn a_grid_becomes_a_grid_of_its_size_and_only_when_it_changes() {
        let mut grid: Grid = zeroed();
        (grid.width, grid.height, grid.resolution) = (30, 20, 0.05);
        (grid.origin_x, grid.origin_y) = (-1.0, 2.0);
        grid.cells[7] = 2;
        let mut converter = Converter::default();
        let out = converter.convert(topics::MAPPING_GRID.name, 10, bytemuck::bytes_of(&grid));
        assert_eq!((out[0].topic, out[0].schema), ("/grid", "foxglove.Grid"));
        let m = &out[0].message;
        assert_eq!(m["column_count"], 30);
        assert_eq!(m["row_stride"], 30);
        assert_eq!(m["cell_size"], json!({ "x": 0.05, "y": 0.05 }));
        assert_eq!(
            m["pose"]["position"],
            json!({ "x": -1.0, "y": 2.0, "z": 0.0 })
        );
        assert_eq!(m["data"], base64(grid.cells()));
        assert_eq!(
            m["data"].as_str().unwrap().len(),
            (30 * 20_usize).div_ceil(3) * 4
        );
        grid.header.tick += 1;
        let again = converter.convert(topics::MAPPING_GRID.name, 20, bytemuck::bytes_of(&grid));
        assert!(again.is_empty(), "an unchanged grid is exported again");
        grid.cells[8] = 1;
        let changed = converter.convert(topics::MAPPING_GRID.name, 30, bytemuck::bytes_of(&grid));
        assert_eq!(changed.len(), 1);
    }

    /// A scan becomes a LaserScan of its beams, from its first angle to its last.
    #[test]
    fn a_scan_becomes_a_laser_scan_of_its_beams() {
        let mut scan: Scan = zeroed();
        (scan.angle_min, scan.angle_increment, scan.n_beams) = (-1.5, 0.5, 7);
        scan.ranges[..7].copy_from_slice(&[1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0]);
        let out =
            Converter::default().convert(topics::SENSING_SCAN.name, 0, bytemuck::bytes_of(&scan));
        let m = &out[0].message;
        assert_eq!(out[0].schema, "foxglove.LaserScan");
        assert_eq!(m["ranges"].as_array().unwrap().len(), 7);
        assert_eq!(m["ranges"][6], 7.0);
        assert_eq!(
            (m["start_angle"].as_f64(), m["end_angle"].as_f64()),
            (Some(-1.5), Some(1.5))
        );
        assert_eq!(m["frame_id"], ROBOT_FRAME);
    }

    /// The 95 % ellipse of a rotated covariance has the eigenvalues' semi-axes along the
    /// eigenvectors.
    #[test]
    fn the_95_percent_ellipse_follows_the_covariance() {
        let (major, minor, angle) = ellipse_95([4.0, 0.0, 0.0, 1.0]);
        assert!((major - (CHI2_2D_95 * 4.0).sqrt()).abs() < 1e-12);
        assert!((minor - CHI2_2D_95.sqrt()).abs() < 1e-12);
        assert!(angle.abs() < 1e-12);
        // Σ = R diag(4, 1) Rᵀ with R a rotation by 30°.
        let (s, c) = 30f64.to_radians().sin_cos();
        let cov = [
            4.0 * c * c + s * s,
            3.0 * s * c,
            3.0 * s * c,
            4.0 * s * s + c * c,
        ];
        let (major, minor, angle) = ellipse_95(cov);
        assert!((major - (CHI2_2D_95 * 4.0).sqrt()).abs() < 1e-9);
        assert!((minor - CHI2_2D_95.sqrt()).abs() < 1e-9);
        assert!((angle - 30f64.to_radians()).abs() < 1e-9);
    }

    /// A pose estimate becomes a pose and its ellipse, centred on it, as wide as its x variance
    /// says.
    #[test]
    fn a_pose_estimate_brings_its_covariance_ellipse() {
        let mut pose: Pose = zeroed();
        (pose.x, pose.y, pose.theta) = (3.0, 4.0, 0.5);
        pose.covariance = [0.25, 0.0, 0.0, 0.0, 0.01, 0.0, 0.0, 0.0, 0.1];
        let out = Converter::default().convert(
            topics::LOCALIZATION_POSE.name,
            0,
            bytemuck::bytes_of(&pose),
        );
        assert_eq!(out[0].schema, "foxglove.PoseInFrame");
        assert_eq!(
            (out[1].topic, out[1].schema),
            ("/pose/ellipse", "foxglove.SceneUpdate")
        );
        let first = &out[1].message["entities"][0]["lines"][0]["points"][0];
        assert!((first["x"].as_f64().unwrap() - (3.0 + (CHI2_2D_95 * 0.25).sqrt())).abs() < 1e-12);
        assert!((first["y"].as_f64().unwrap() - 4.0).abs() < 1e-12);
    }

    /// The world's map becomes one cube per obstacle, one sphere per beacon and one for the
    /// goal; the path a line through its waypoints; particles two points each; landmarks a
    /// sphere and an ellipse each.
    #[test]
    fn scene_entities_hold_one_shape_per_item() {
        let mut map: WorldMap = zeroed();
        map.n_obstacles = 3;
        map.obstacles[2] = Square::new(1.0, 2.0, 0.5);
        (map.n_beacons, map.has_goal) = (2, 1);
        let mut c = Converter::default();
        let m = &c.convert(topics::WORLD_MAP.name, 0, bytemuck::bytes_of(&map))[0].message;
        let shapes = &m["entities"][0];
        assert_eq!(shapes["cubes"].as_array().unwrap().len(), 3);
        assert_eq!(shapes["cubes"][2]["size"]["x"], 0.5);
        assert_eq!(shapes["spheres"].as_array().unwrap().len(), 3);

        let mut status: PlanStatus = zeroed();
        status.n_path = 4;
        status.path[3] = [5.0, 6.0];
        let m = &c.convert(topics::PLANNING_STATUS.name, 0, bytemuck::bytes_of(&status))[0].message;
        let points = m["entities"][0]["lines"][0]["points"].as_array().unwrap();
        assert_eq!(points.len(), 4);
        assert_eq!(points[3], json!({ "x": 5.0, "y": 6.0, "z": 0.0 }));

        let mut particles: Particles = zeroed();
        particles.n_particles = 5;
        particles.n_filter = particles.n_particles;
        particles.particles[0] = Particle {
            x: 1.0,
            y: 1.0,
            theta: 0.0,
            w: 0.2,
        };
        let m = &c.convert(
            topics::LOCALIZATION_PARTICLES.name,
            0,
            bytemuck::bytes_of(&particles),
        )[0]
        .message;
        let points = m["entities"][0]["lines"][0]["points"].as_array().unwrap();
        assert_eq!(points.len(), 10);
        assert_eq!(points[1]["x"], 1.0 + PARTICLE_TICK);

        let mut landmarks: Landmarks = zeroed();
        landmarks.n_landmarks = 2;
        landmarks.landmarks[1] = Landmark {
            x: 2.0,
            y: 3.0,
            covariance: [0.04, 0.0, 0.0, 0.04],
            ..Default::default()
        };
        let m = &c.convert(
            topics::LOCALIZATION_LANDMARKS.name,
            0,
            bytemuck::bytes_of(&landmarks),
        )[0]
        .message;
        assert_eq!(m["entities"][0]["spheres"].as_array().unwrap().len(), 2);
        assert_eq!(m["entities"][0]["lines"].as_array().unwrap().len(), 2);
    }

    /// Every schema an export writes is JSON titled with its name, as Foxglove publishes it.
    #[test]
    fn every_written_schema_is_a_titled_json_schema() {
        for (name, text) in schemas::ALL {
            let schema: Value = serde_json::from_str(text).expect(name);
            assert_eq!(schema["title"], name);
            assert_eq!(schema["type"], "object");
            assert_eq!(schemas::json_schema(name), Some(text));
        }
        assert!(schemas::json_schema("foxglove.Nothing").is_none());
    }

    /// The fields `schema` requires that `value` lacks, as paths: `required`, followed through
    /// `properties` and array `items` (what a JSON Schema validator checks first; tests/export.rs
    /// runs a whole one over a real export).
    fn missing(schema: &Value, value: &Value, path: &str, out: &mut Vec<String>) {
        for field in schema["required"].as_array().into_iter().flatten() {
            let field = field.as_str().unwrap();
            if value.get(field).is_none() {
                out.push(format!("{path}/{field}"));
            }
        }
        for (field, inner) in schema["properties"].as_object().into_iter().flatten() {
            if let Some(v) = value.get(field) {
                missing(inner, v, &format!("{path}/{field}"), out);
            }
        }
        if let (Some(items), Some(array)) = (schema.get("items"), value.as_array()) {
            for (k, v) in array.iter().enumerate() {
                missing(items, v, &format!("{path}/{k}"), out);
            }
        }
    }

    /// Every kind of converted message holds every field its published schema requires, down
    /// to each entity's primitives.
    #[test]
    fn converted_messages_hold_every_required_field() {
        let mut map: WorldMap = zeroed();
        (map.n_obstacles, map.n_beacons, map.has_goal) = (1, 1, 1);
        let mut status: PlanStatus = zeroed();
        status.n_path = 2;
        let mut particles: Particles = zeroed();
        particles.n_particles = 2;
        particles.n_filter = particles.n_particles;
        let mut landmarks: Landmarks = zeroed();
        landmarks.n_landmarks = 1;
        let mut scan: Scan = zeroed();
        scan.n_beams = 3;
        let mut grid: Grid = zeroed();
        (grid.width, grid.height) = (2, 2);
        let samples: [(&str, Vec<u8>); 8] = [
            (
                topics::WORLD_TRUTH.name,
                bytemuck::bytes_of(&truth(1, 1.0)).to_vec(),
            ),
            (
                topics::LOCALIZATION_POSE.name,
                bytemuck::bytes_of(&zeroed::<Pose>()).to_vec(),
            ),
            (
                topics::SENSING_SCAN.name,
                bytemuck::bytes_of(&scan).to_vec(),
            ),
            (
                topics::MAPPING_GRID.name,
                bytemuck::bytes_of(&grid).to_vec(),
            ),
            (topics::WORLD_MAP.name, bytemuck::bytes_of(&map).to_vec()),
            (
                topics::PLANNING_STATUS.name,
                bytemuck::bytes_of(&status).to_vec(),
            ),
            (
                topics::LOCALIZATION_PARTICLES.name,
                bytemuck::bytes_of(&particles).to_vec(),
            ),
            (
                topics::LOCALIZATION_LANDMARKS.name,
                bytemuck::bytes_of(&landmarks).to_vec(),
            ),
        ];
        let mut converter = Converter::default();
        let mut schemas_seen = std::collections::BTreeSet::new();
        for (topic, data) in samples {
            for converted in converter.convert(topic, 1, &data) {
                let text = schemas::json_schema(converted.schema).expect(converted.schema);
                let schema: Value = serde_json::from_str(text).unwrap();
                let mut lacking = Vec::new();
                missing(&schema, &converted.message, "", &mut lacking);
                assert!(lacking.is_empty(), "{}: lacks {lacking:?}", converted.topic);
                schemas_seen.insert(converted.schema);
            }
        }
        assert_eq!(schemas_seen.len(), schemas::ALL.len());
    }

    /// A recording exports into a file of Foxglove channels whose truths are the recorded ones,
    /// each at its log time.
    #[test]
    fn a_recording_exports_into_foxglove_channels() {
        let (input, output) = (TempFile::new("fox-in"), TempFile::new("fox-out"));
        let records = (0..5)
            .map(|k| sample(topics::WORLD_TRUTH.name, &truth(k, k as f64 / 2.0)))
            .collect();
        write(&input.0, records);
        let exported =
            crate::export(&input.0, &output.0, &mut Converter::default()).expect("export");
        assert_eq!(exported.written["/truth"], 5);
        let bytes = std::fs::read(&output.0).unwrap();
        let mut xs = Vec::new();
        for m in mcap::MessageStream::new(&bytes).unwrap() {
            let m = m.unwrap();
            let schema = m.channel.schema.as_ref().unwrap();
            assert!(schema.name.starts_with("foxglove."), "{}", schema.name);
            assert_eq!(schema.encoding, "jsonschema");
            assert_eq!(m.channel.message_encoding, "json");
            if m.channel.topic == "/truth" {
                let v: Value = serde_json::from_slice(&m.data).unwrap();
                xs.push((m.log_time, v["pose"]["position"]["x"].as_f64().unwrap()));
            }
        }
        let expected: Vec<_> = (0..5).map(|k| (k * 10_000_000, k as f64 / 2.0)).collect();
        assert_eq!(xs, expected);
    }

    /// A file that is not MCAP, and an MCAP file that is not a mole recording, are refused
    /// naming the file and what was expected, and leave no output.
    #[test]
    fn what_is_not_a_recording_is_refused_naming_the_file() {
        let (input, output) = (TempFile::new("fox-garbage"), TempFile::new("fox-none"));
        std::fs::write(&input.0, b"not a recording at all").unwrap();
        let refused = crate::export(&input.0, &output.0, &mut Converter::default())
            .expect_err("garbage")
            .to_string();
        assert!(refused.contains(&*input.0.to_string_lossy()), "{refused}");
        assert!(refused.contains("not an MCAP file"), "{refused}");
        assert!(!output.0.exists());

        let mut w =
            mcap::Writer::new(std::io::BufWriter::new(File::create(&input.0).unwrap())).unwrap();
        let schema = w.add_schema("other.Thing", "jsonschema", b"{}").unwrap();
        let channel = w
            .add_channel(schema, "/thing", "json", &BTreeMap::new())
            .unwrap();
        let header = mcap::records::MessageHeader {
            channel_id: channel,
            sequence: 0,
            log_time: 0,
            publish_time: 0,
        };
        w.write_to_known_channel(&header, b"{}").unwrap();
        w.finish().unwrap();
        drop(w);
        let refused = crate::export(&input.0, &output.0, &mut Converter::default())
            .expect_err("foreign")
            .to_string();
        assert!(refused.contains("not a mole recording"), "{refused}");
        assert!(!output.0.exists());
    }

    /// A recording of other message layouts is refused naming the topic and both type names,
    /// and a recording is never exported onto itself.
    #[test]
    fn other_layouts_and_the_recording_itself_are_refused() {
        let (input, output) = (TempFile::new("fox-v0"), TempFile::new("fox-v0-out"));
        let mut w =
            mcap::Writer::new(std::io::BufWriter::new(File::create(&input.0).unwrap())).unwrap();
        let schema = w
            .add_schema("mole.Truth.v0", SCHEMA_ENCODING, b"{}")
            .unwrap();
        let channel = w
            .add_channel(
                schema,
                topics::WORLD_TRUTH.name,
                "mole-layout",
                &BTreeMap::new(),
            )
            .unwrap();
        let header = mcap::records::MessageHeader {
            channel_id: channel,
            sequence: 0,
            log_time: 0,
            publish_time: 0,
        };
        w.write_to_known_channel(&header, bytemuck::bytes_of(&truth(0, 1.0)))
            .unwrap();
        w.finish().unwrap();
        drop(w);
        let refused = crate::export(&input.0, &output.0, &mut Converter::default())
            .expect_err("v0")
            .to_string();
        assert!(refused.contains("world/truth"), "{refused}");
        assert!(
            refused.contains("mole.Truth.v0") && refused.contains("mole.Truth.v1"),
            "{refused}"
        );
        assert!(!output.0.exists());

        let before = std::fs::read(&input.0).unwrap();
        let refused = crate::export(&input.0, &input.0, &mut Converter::default())
            .expect_err("itself")
            .to_string();
        assert!(refused.contains("is the recording itself"), "{refused}");
        assert_eq!(
            std::fs::read(&input.0).unwrap(),
            before,
            "the recording was touched"
        );
    }

    /// A recording cut short is refused as truncated, naming the file.
    #[test]
    fn a_truncated_recording_is_refused() {
        let (input, output) = (TempFile::new("fox-cut"), TempFile::new("fox-cut-out"));
        let records = (0..50)
            .map(|k| sample(topics::WORLD_TRUTH.name, &truth(k, 1.0)))
            .collect();
        write(&input.0, records);
        let bytes = std::fs::read(&input.0).unwrap();
        std::fs::write(&input.0, &bytes[..bytes.len() / 2]).unwrap();
        let refused = crate::export(&input.0, &output.0, &mut Converter::default())
            .expect_err("cut")
            .to_string();
        assert!(refused.contains("truncated or corrupt"), "{refused}");
        assert!(!output.0.exists());
    }
}
