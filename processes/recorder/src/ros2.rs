//! A recording exported as a ROS 2 bag: rosbag2's MCAP profile (`ros2`), each message in CDR
//! with its `ros2msg` definition as the channel's schema, stamped with the simulated time of its
//! step (tick · Δt): the format `ros2 bag` writes and reads. (Checked with mcap-ros2-support's
//! decoder; ROS 2 itself is not installed where the tests run.)
//!
//! | mole topic | channel | ROS 2 type |
//! | --- | --- | --- |
//! | `world/truth` | `/truth` | `geometry_msgs/msg/PoseStamped` |
//! | `localization/pose` | `/pose`, `/tf` (map → odom) | `geometry_msgs/msg/PoseWithCovarianceStamped`, `tf2_msgs/msg/TFMessage` |
//! | `sensing/odom` | `/odom`, `/tf` (odom → base_link) | `nav_msgs/msg/Odometry`, `tf2_msgs/msg/TFMessage` |
//! | `sensing/scan` | `/scan` | `sensor_msgs/msg/LaserScan` |
//! | `mapping/grid`, `mapping/contact` | `/map`, `/contact_map` | `nav_msgs/msg/OccupancyGrid` |
//! | `planning/cmd` | `/cmd_vel` | `geometry_msgs/msg/Twist` |
//! | `localization/particles` | `/particles` | `geometry_msgs/msg/PoseArray` |
//! | `localization/landmarks` | `/landmarks` | `visualization_msgs/msg/MarkerArray` |
//!
//! The CDR is written by the `cdr` crate from structs laid out as the `.msg` files are (field
//! order and types); the definitions below are those files without their comments.

use crate::export::{Exporting, Format};
use mole_types::{
    CELL_FREE, CELL_OCCUPIED, CELL_UNEXPLORED, Cmd, GRID_FRONTIER, Grid, Header, Landmarks, Odom,
    Particles, Pose, Scan, Truth, WorldMap, topics,
};
use std::collections::BTreeMap;

/// rosbag2's MCAP profile.
pub const PROFILE: &str = "ros2";
/// The schema encoding of every channel: a `.msg` definition with its dependencies.
pub const SCHEMA_ENCODING: &str = "ros2msg";
/// The message encoding of every channel.
pub const MESSAGE_ENCODING: &str = "cdr";
/// The fixed frame.
pub const MAP_FRAME: &str = "map";
/// The odometry frame: where the robot is by its wheels alone.
pub const ODOM_FRAME: &str = "odom";
/// The robot's frame.
pub const ROBOT_FRAME: &str = "base_link";
/// χ²(2 degrees of freedom) at 95 %: a landmark's marker is its 95 % ellipse.
const CHI2_2D_95: f64 = 5.991_464_547_107_979;
/// The QoS rosbag2 records a reliable, volatile publisher with; `ros2 bag play` offers it again.
const OFFERED_QOS: &str = "- history: 3\n  depth: 0\n  reliability: 1\n  durability: 2\n  \
deadline:\n    sec: 2147483647\n    nsec: 4294967295\n  lifespan:\n    sec: 2147483647\n    \
nsec: 4294967295\n  liveliness: 1\n  liveliness_lease_duration:\n    sec: 2147483647\n    \
nsec: 4294967295\n  avoid_ros_namespace_conventions: false\n";

/// The ROS 2 messages, laid out as their `.msg` files are: serialised field by field in order,
/// that is their CDR.
pub mod msg {
    use serde::Serialize;
    use serde::ser::SerializeTuple;

    #[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
    pub struct Time {
        pub sec: i32,
        pub nanosec: u32,
    }

    #[derive(Debug, Clone, Default, PartialEq, Serialize)]
    pub struct Header {
        pub stamp: Time,
        pub frame_id: String,
    }

    #[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
    pub struct Vector3 {
        pub x: f64,
        pub y: f64,
        pub z: f64,
    }

    /// `geometry_msgs/Point` has the fields of a `Vector3`.
    pub type Point = Vector3;

    #[derive(Debug, Clone, Copy, PartialEq, Serialize)]
    pub struct Quaternion {
        pub x: f64,
        pub y: f64,
        pub z: f64,
        pub w: f64,
    }

    impl Quaternion {
        /// A rotation by `yaw` about z.
        pub fn yaw(yaw: f64) -> Quaternion {
            let half = 0.5 * yaw;
            Quaternion {
                x: 0.0,
                y: 0.0,
                z: half.sin(),
                w: half.cos(),
            }
        }
    }

    #[derive(Debug, Clone, Copy, PartialEq, Serialize)]
    pub struct Pose {
        pub position: Point,
        pub orientation: Quaternion,
    }

    impl Pose {
        /// The planar pose (x, y, yaw).
        pub fn planar(x: f64, y: f64, yaw: f64) -> Pose {
            Pose {
                position: Point { x, y, z: 0.0 },
                orientation: Quaternion::yaw(yaw),
            }
        }
    }

    /// A 6×6 row-major covariance over (x, y, z, rotation about x, y, z): `float64[36]`, a fixed
    /// array (serde's arrays stop at 32).
    #[derive(Debug, Clone, Copy, PartialEq)]
    pub struct Covariance(pub [f64; 36]);

    impl Covariance {
        /// The 3×3 planar covariance over (x, y, θ) in its place in the 6×6: rows and columns
        /// 0, 1 and 5; the rest zero.
        pub fn planar(sigma: &[f64; 9]) -> Covariance {
            let mut c = [0.0; 36];
            let at = [0, 1, 5];
            for (i, &r) in at.iter().enumerate() {
                for (j, &k) in at.iter().enumerate() {
                    c[r * 6 + k] = sigma[i * 3 + j];
                }
            }
            Covariance(c)
        }
    }

    impl Serialize for Covariance {
        fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
            let mut tuple = serializer.serialize_tuple(36)?;
            for value in &self.0 {
                tuple.serialize_element(value)?;
            }
            tuple.end()
        }
    }

    #[derive(Debug, Clone, PartialEq, Serialize)]
    pub struct PoseStamped {
        pub header: Header,
        pub pose: Pose,
    }

    #[derive(Debug, Clone, Copy, PartialEq, Serialize)]
    pub struct PoseWithCovariance {
        pub pose: Pose,
        pub covariance: Covariance,
    }

    #[derive(Debug, Clone, PartialEq, Serialize)]
    pub struct PoseWithCovarianceStamped {
        pub header: Header,
        pub pose: PoseWithCovariance,
    }

    #[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
    pub struct Twist {
        pub linear: Vector3,
        pub angular: Vector3,
    }

    #[derive(Debug, Clone, Copy, PartialEq, Serialize)]
    pub struct TwistWithCovariance {
        pub twist: Twist,
        pub covariance: Covariance,
    }

    #[derive(Debug, Clone, PartialEq, Serialize)]
    pub struct Odometry {
        pub header: Header,
        pub child_frame_id: String,
        pub pose: PoseWithCovariance,
        pub twist: TwistWithCovariance,
    }

    #[derive(Debug, Clone, Copy, PartialEq, Serialize)]
    pub struct Transform {
        pub translation: Vector3,
        pub rotation: Quaternion,
    }

    #[derive(Debug, Clone, PartialEq, Serialize)]
    pub struct TransformStamped {
        pub header: Header,
        pub child_frame_id: String,
        pub transform: Transform,
    }

    #[derive(Debug, Clone, PartialEq, Serialize)]
    pub struct TfMessage {
        pub transforms: Vec<TransformStamped>,
    }

    #[derive(Debug, Clone, PartialEq, Serialize)]
    pub struct LaserScan {
        pub header: Header,
        pub angle_min: f32,
        pub angle_max: f32,
        pub angle_increment: f32,
        pub time_increment: f32,
        pub scan_time: f32,
        pub range_min: f32,
        pub range_max: f32,
        pub ranges: Vec<f32>,
        pub intensities: Vec<f32>,
    }

    #[derive(Debug, Clone, Copy, PartialEq, Serialize)]
    pub struct MapMetaData {
        pub map_load_time: Time,
        pub resolution: f32,
        pub width: u32,
        pub height: u32,
        pub origin: Pose,
    }

    #[derive(Debug, Clone, PartialEq, Serialize)]
    pub struct OccupancyGrid {
        pub header: Header,
        pub info: MapMetaData,
        pub data: Vec<i8>,
    }

    #[derive(Debug, Clone, PartialEq, Serialize)]
    pub struct PoseArray {
        pub header: Header,
        pub poses: Vec<Pose>,
    }

    #[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
    pub struct ColorRgba {
        pub r: f32,
        pub g: f32,
        pub b: f32,
        pub a: f32,
    }

    #[derive(Debug, Clone, Default, PartialEq, Serialize)]
    pub struct CompressedImage {
        pub header: Header,
        pub format: String,
        pub data: Vec<u8>,
    }

    #[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
    pub struct UvCoordinate {
        pub u: f32,
        pub v: f32,
    }

    #[derive(Debug, Clone, Default, PartialEq, Serialize)]
    pub struct MeshFile {
        pub filename: String,
        pub data: Vec<u8>,
    }

    /// `visualization_msgs/Marker` as ROS 2 Jazzy defines it (with its texture and mesh
    /// fields).
    #[derive(Debug, Clone, PartialEq, Serialize)]
    pub struct Marker {
        pub header: Header,
        pub ns: String,
        pub id: i32,
        pub r#type: i32,
        pub action: i32,
        pub pose: Pose,
        pub scale: Vector3,
        pub color: ColorRgba,
        pub lifetime: Time,
        pub frame_locked: bool,
        pub points: Vec<Point>,
        pub colors: Vec<ColorRgba>,
        pub texture_resource: String,
        pub texture: CompressedImage,
        pub uv_coordinates: Vec<UvCoordinate>,
        pub text: String,
        pub mesh_resource: String,
        pub mesh_file: MeshFile,
        pub mesh_use_embedded_materials: bool,
    }

    /// `Marker::type`: a cylinder.
    pub const MARKER_CYLINDER: i32 = 3;
    /// `Marker::action`: add or modify.
    pub const MARKER_ADD: i32 = 0;
    /// `Marker::action`: delete every marker of the namespace.
    pub const MARKER_DELETEALL: i32 = 3;

    #[derive(Debug, Clone, PartialEq, Serialize)]
    pub struct MarkerArray {
        pub markers: Vec<Marker>,
    }
}

/// The `.msg` definitions of every type the export writes and of the types they refer to,
/// without comments, by their names without `/msg/`.
const DEFINITIONS: &[(&str, &str)] = &[
    ("builtin_interfaces/Time", "int32 sec\nuint32 nanosec\n"),
    ("builtin_interfaces/Duration", "int32 sec\nuint32 nanosec\n"),
    (
        "std_msgs/Header",
        "builtin_interfaces/Time stamp\nstring frame_id\n",
    ),
    (
        "std_msgs/ColorRGBA",
        "float32 r\nfloat32 g\nfloat32 b\nfloat32 a\n",
    ),
    ("geometry_msgs/Point", "float64 x\nfloat64 y\nfloat64 z\n"),
    ("geometry_msgs/Vector3", "float64 x\nfloat64 y\nfloat64 z\n"),
    (
        "geometry_msgs/Quaternion",
        "float64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n",
    ),
    (
        "geometry_msgs/Pose",
        "Point position\nQuaternion orientation\n",
    ),
    (
        "geometry_msgs/PoseStamped",
        "std_msgs/Header header\nPose pose\n",
    ),
    (
        "geometry_msgs/PoseWithCovariance",
        "Pose pose\nfloat64[36] covariance\n",
    ),
    (
        "geometry_msgs/PoseWithCovarianceStamped",
        "std_msgs/Header header\nPoseWithCovariance pose\n",
    ),
    (
        "geometry_msgs/PoseArray",
        "std_msgs/Header header\nPose[] poses\n",
    ),
    ("geometry_msgs/Twist", "Vector3 linear\nVector3 angular\n"),
    (
        "geometry_msgs/TwistWithCovariance",
        "Twist twist\nfloat64[36] covariance\n",
    ),
    (
        "geometry_msgs/Transform",
        "Vector3 translation\nQuaternion rotation\n",
    ),
    (
        "geometry_msgs/TransformStamped",
        "std_msgs/Header header\nstring child_frame_id\nTransform transform\n",
    ),
    (
        "tf2_msgs/TFMessage",
        "geometry_msgs/TransformStamped[] transforms\n",
    ),
    (
        "nav_msgs/Odometry",
        "std_msgs/Header header\nstring child_frame_id\ngeometry_msgs/PoseWithCovariance pose\n\
         geometry_msgs/TwistWithCovariance twist\n",
    ),
    (
        "nav_msgs/MapMetaData",
        "builtin_interfaces/Time map_load_time\nfloat32 resolution\nuint32 width\nuint32 height\n\
         geometry_msgs/Pose origin\n",
    ),
    (
        "nav_msgs/OccupancyGrid",
        "std_msgs/Header header\nMapMetaData info\nint8[] data\n",
    ),
    (
        "sensor_msgs/LaserScan",
        "std_msgs/Header header\nfloat32 angle_min\nfloat32 angle_max\nfloat32 angle_increment\n\
         float32 time_increment\nfloat32 scan_time\nfloat32 range_min\nfloat32 range_max\n\
         float32[] ranges\nfloat32[] intensities\n",
    ),
    (
        "sensor_msgs/CompressedImage",
        "std_msgs/Header header\nstring format\nuint8[] data\n",
    ),
    ("visualization_msgs/UVCoordinate", "float32 u\nfloat32 v\n"),
    (
        "visualization_msgs/MeshFile",
        "string filename\nuint8[] data\n",
    ),
    (
        "visualization_msgs/Marker",
        "int32 ARROW=0\nint32 CUBE=1\nint32 SPHERE=2\nint32 CYLINDER=3\nint32 LINE_STRIP=4\n\
         int32 LINE_LIST=5\nint32 CUBE_LIST=6\nint32 SPHERE_LIST=7\nint32 POINTS=8\n\
         int32 TEXT_VIEW_FACING=9\nint32 MESH_RESOURCE=10\nint32 TRIANGLE_LIST=11\n\
         int32 ARROW_STRIP=12\nint32 ADD=0\nint32 MODIFY=0\nint32 DELETE=2\nint32 DELETEALL=3\n\
         std_msgs/Header header\nstring ns\nint32 id\nint32 type\nint32 action\n\
         geometry_msgs/Pose pose\ngeometry_msgs/Vector3 scale\nstd_msgs/ColorRGBA color\n\
         builtin_interfaces/Duration lifetime\nbool frame_locked\ngeometry_msgs/Point[] points\n\
         std_msgs/ColorRGBA[] colors\nstring texture_resource\n\
         sensor_msgs/CompressedImage texture\nUVCoordinate[] uv_coordinates\nstring text\n\
         string mesh_resource\nMeshFile mesh_file\nbool mesh_use_embedded_materials\n",
    ),
    ("visualization_msgs/MarkerArray", "Marker[] markers\n"),
];

const PRIMITIVES: &[&str] = &[
    "bool", "byte", "char", "int8", "uint8", "int16", "uint16", "int32", "uint32", "int64",
    "uint64", "float32", "float64", "string", "wstring",
];

/// The definition of `name` (`sensor_msgs/LaserScan`) as rosbag2 stores it: its own `.msg`,
/// then every type it refers to, directly or not, once each, after a line of 80 `=` and
/// `MSG: package/Type`.
pub fn full_definition(name: &str) -> String {
    let text = |name: &str| {
        DEFINITIONS
            .iter()
            .find(|(n, _)| *n == name)
            .map(|(_, text)| *text)
            .unwrap_or_else(|| panic!("no definition of {name}"))
    };
    let mut out = text(name).to_string();
    let (mut seen, mut queue) = (vec![name.to_string()], vec![name.to_string()]);
    while let Some(current) = queue.pop() {
        let package = current.split('/').next().unwrap_or_default();
        for line in text(&current).lines() {
            let Some(field_type) = line.split_whitespace().next() else {
                continue;
            };
            let base = field_type.split('[').next().unwrap_or(field_type);
            if PRIMITIVES.contains(&base) || line.contains('=') {
                continue;
            }
            let full = match base.contains('/') {
                true => base.to_string(),
                false => format!("{package}/{base}"),
            };
            if !seen.contains(&full) {
                out.push_str(&format!("{}\nMSG: {full}\n{}", "=".repeat(80), text(&full)));
                seen.push(full.clone());
                queue.insert(0, full);
            }
        }
    }
    out
}

/// The channel type name of a definition: `sensor_msgs/LaserScan` is `sensor_msgs/msg/LaserScan`.
fn type_name(definition: &str) -> String {
    definition.replacen('/', "/msg/", 1)
}

/// Turns recorded samples into ROS 2 messages; remembers Δt (from `world/map`) for the stamps
/// and each grid's last content, so a grid is exported only when it changed.
#[derive(Debug, Default)]
pub struct Ros2 {
    /// The world's step (ns); `None` until `world/map` is read: nothing is stamped before.
    dt_ns: Option<u64>,
    last_grid: BTreeMap<&'static str, Vec<u8>>,
}

/// A step's simulated time.
pub fn stamp(tick: u64, dt_ns: u64) -> msg::Time {
    let ns = tick.saturating_mul(dt_ns);
    msg::Time {
        sec: i32::try_from(ns / 1_000_000_000).unwrap_or(i32::MAX),
        nanosec: (ns % 1_000_000_000) as u32,
    }
}

fn header(stamp: msg::Time, frame: &str) -> msg::Header {
    msg::Header {
        stamp,
        frame_id: frame.to_string(),
    }
}

/// `message` in CDR, little-endian, with its encapsulation header.
pub fn cdr<T: serde::Serialize>(message: &T) -> Vec<u8> {
    cdr::serialize::<_, _, cdr::CdrLe>(message, cdr::Infinite)
        .expect("every exported message serialises (no size limit)")
}

fn out<T: serde::Serialize>(topic: &'static str, definition: &'static str, m: &T) -> Exporting {
    Exporting {
        topic,
        schema: definition,
        data: cdr(m),
    }
}

/// The transform from `parent` to `child` at (x, y, yaw).
fn transform(
    stamp: msg::Time,
    parent: &str,
    child: &str,
    x: f64,
    y: f64,
    yaw: f64,
) -> msg::TfMessage {
    msg::TfMessage {
        transforms: vec![msg::TransformStamped {
            header: header(stamp, parent),
            child_frame_id: child.to_string(),
            transform: msg::Transform {
                translation: msg::Vector3 { x, y, z: 0.0 },
                rotation: msg::Quaternion::yaw(yaw),
            },
        }],
    }
}

/// map → odom, from the estimate (map → base_link) and the odometry pose of its step
/// (odom → base_link): the estimate composed with the inverse of the odometry pose.
pub fn map_to_odom(estimate: [f64; 3], odom: [f64; 3]) -> [f64; 3] {
    let yaw = estimate[2] - odom[2];
    let (s, c) = yaw.sin_cos();
    [
        estimate[0] - (c * odom[0] - s * odom[1]),
        estimate[1] - (s * odom[0] + c * odom[1]),
        yaw,
    ]
}

/// A grid cell as `nav_msgs/OccupancyGrid` has it: -1 unknown, 0 free, 100 occupied. The
/// contact grid knows only touched cells: the others are unknown.
pub fn occupancy(kind: u32, cell: u8) -> i8 {
    match (kind, cell) {
        (GRID_FRONTIER, CELL_UNEXPLORED) => -1,
        (GRID_FRONTIER, CELL_FREE) => 0,
        (GRID_FRONTIER, CELL_OCCUPIED) => 100,
        (GRID_FRONTIER, _) => -1,
        (_, 0) => -1,
        _ => 100,
    }
}

impl Ros2 {
    fn grid(&mut self, channel: &'static str, data: &[u8], dt_ns: u64) -> Vec<Exporting> {
        let content = &data[size_of::<Header>()..];
        if self.last_grid.get(channel).is_some_and(|l| l == content) {
            return Vec::new();
        }
        self.last_grid.insert(channel, content.to_vec());
        let grid: Box<Grid> = boxed(data);
        let t = stamp(grid.header.tick, dt_ns);
        let m = msg::OccupancyGrid {
            header: header(t, MAP_FRAME),
            info: msg::MapMetaData {
                map_load_time: t,
                resolution: grid.resolution as f32,
                width: grid.width,
                height: grid.height,
                origin: msg::Pose::planar(grid.origin_x, grid.origin_y, 0.0),
            },
            data: grid
                .cells()
                .iter()
                .map(|&c| occupancy(grid.kind, c))
                .collect(),
        };
        vec![out(channel, "nav_msgs/OccupancyGrid", &m)]
    }
}

/// The 95 % ellipse of a 2×2 covariance: its axes (m, full lengths) and the first one's yaw.
fn ellipse(c: &[f64; 4]) -> (f64, f64, f64) {
    let (a, b, d) = (c[0], 0.5 * (c[1] + c[2]), c[3]);
    let mean = 0.5 * (a + d);
    let spread = (0.25 * (a - d) * (a - d) + b * b).sqrt();
    let axis = |lambda: f64| 2.0 * (CHI2_2D_95 * lambda.max(0.0)).sqrt();
    (
        axis(mean + spread),
        axis(mean - spread),
        0.5 * (2.0 * b).atan2(a - d),
    )
}

fn landmark_markers(landmarks: &Landmarks, t: msg::Time) -> msg::MarkerArray {
    let marker = |id: i32, action: i32, pose: msg::Pose, scale: msg::Vector3| msg::Marker {
        header: header(t, MAP_FRAME),
        ns: "landmarks".to_string(),
        id,
        r#type: msg::MARKER_CYLINDER,
        action,
        pose,
        scale,
        color: msg::ColorRgba {
            r: 0.2,
            g: 0.4,
            b: 1.0,
            a: 0.6,
        },
        lifetime: msg::Time::default(),
        frame_locked: false,
        points: Vec::new(),
        colors: Vec::new(),
        texture_resource: String::new(),
        texture: msg::CompressedImage::default(),
        uv_coordinates: Vec::new(),
        text: String::new(),
        mesh_resource: String::new(),
        mesh_file: msg::MeshFile::default(),
        mesh_use_embedded_materials: false,
    };
    // A landmark gone from the map (a FastSLAM particle's) goes from the display too.
    let mut markers = vec![marker(
        0,
        msg::MARKER_DELETEALL,
        msg::Pose::planar(0.0, 0.0, 0.0),
        msg::Vector3::default(),
    )];
    for l in landmarks.landmarks() {
        let (major, minor, yaw) = ellipse(&l.covariance);
        let scale = msg::Vector3 {
            x: major,
            y: minor,
            z: 0.05,
        };
        markers.push(marker(
            l.id as i32,
            msg::MARKER_ADD,
            msg::Pose::planar(l.x, l.y, yaw),
            scale,
        ));
    }
    msg::MarkerArray { markers }
}

/// A recorded message's bytes as the message, on the heap (grids are hundreds of KiB).
fn boxed<M: bytemuck::Pod>(data: &[u8]) -> Box<M> {
    let mut message: Box<M> = bytemuck::zeroed_box();
    bytemuck::bytes_of_mut(&mut *message).copy_from_slice(data);
    message
}

impl Format for Ros2 {
    fn profile(&self) -> &'static str {
        PROFILE
    }

    fn name(&self) -> &'static str {
        "ros2"
    }

    fn schema(&self, definition: &str) -> (String, &'static str, Vec<u8>) {
        (
            type_name(definition),
            SCHEMA_ENCODING,
            full_definition(definition).into_bytes(),
        )
    }

    fn message_encoding(&self) -> &'static str {
        MESSAGE_ENCODING
    }

    fn channel_metadata(&self) -> BTreeMap<String, String> {
        BTreeMap::from([("offered_qos_profiles".to_string(), OFFERED_QOS.to_string())])
    }

    fn convert(&mut self, topic: &str, _log_time: u64, data: &[u8]) -> Vec<Exporting> {
        if topic == topics::WORLD_MAP.name {
            let map: Box<WorldMap> = boxed(data);
            self.dt_ns = Some((map.dt * 1e9).round() as u64);
            return Vec::new();
        }
        let Some(dt_ns) = self.dt_ns else {
            return Vec::new();
        };
        let tick_of = |data: &[u8]| -> u64 {
            bytemuck::pod_read_unaligned::<Header>(&data[..size_of::<Header>()]).tick
        };
        let t = stamp(tick_of(data), dt_ns);
        match topic {
            name if name == topics::WORLD_TRUTH.name => {
                let truth: Box<Truth> = boxed(data);
                let m = msg::PoseStamped {
                    header: header(t, MAP_FRAME),
                    pose: msg::Pose::planar(truth.x, truth.y, truth.theta),
                };
                vec![out("/truth", "geometry_msgs/PoseStamped", &m)]
            }
            name if name == topics::LOCALIZATION_POSE.name => {
                let pose: Box<Pose> = boxed(data);
                let m = msg::PoseWithCovarianceStamped {
                    header: header(t, MAP_FRAME),
                    pose: msg::PoseWithCovariance {
                        pose: msg::Pose::planar(pose.x, pose.y, pose.theta),
                        covariance: msg::Covariance::planar(&pose.covariance),
                    },
                };
                let [x, y, yaw] = map_to_odom([pose.x, pose.y, pose.theta], pose.odom);
                let tf = transform(t, MAP_FRAME, ODOM_FRAME, x, y, yaw);
                vec![
                    out("/pose", "geometry_msgs/PoseWithCovarianceStamped", &m),
                    out("/tf", "tf2_msgs/TFMessage", &tf),
                ]
            }
            name if name == topics::SENSING_ODOM.name => {
                let odom: Box<Odom> = boxed(data);
                let m = msg::Odometry {
                    header: header(t, ODOM_FRAME),
                    child_frame_id: ROBOT_FRAME.to_string(),
                    pose: msg::PoseWithCovariance {
                        pose: msg::Pose::planar(odom.x, odom.y, odom.theta),
                        covariance: msg::Covariance([0.0; 36]),
                    },
                    twist: msg::TwistWithCovariance {
                        twist: planar_twist(odom.v, odom.omega),
                        covariance: msg::Covariance([0.0; 36]),
                    },
                };
                let tf = transform(t, ODOM_FRAME, ROBOT_FRAME, odom.x, odom.y, odom.theta);
                vec![
                    out("/odom", "nav_msgs/Odometry", &m),
                    out("/tf", "tf2_msgs/TFMessage", &tf),
                ]
            }
            name if name == topics::SENSING_SCAN.name => {
                let scan: Box<Scan> = boxed(data);
                let ranges = scan.ranges().to_vec();
                let last = ranges.len().saturating_sub(1) as f32;
                let m = msg::LaserScan {
                    header: header(t, ROBOT_FRAME),
                    angle_min: scan.angle_min,
                    angle_max: scan.angle_min + last * scan.angle_increment,
                    angle_increment: scan.angle_increment,
                    time_increment: 0.0,
                    scan_time: dt_ns as f32 * 1e-9,
                    range_min: 0.0,
                    range_max: scan.range_max,
                    ranges,
                    intensities: Vec::new(),
                };
                vec![out("/scan", "sensor_msgs/LaserScan", &m)]
            }
            name if name == topics::MAPPING_GRID.name => self.grid("/map", data, dt_ns),
            name if name == topics::MAPPING_CONTACT.name => self.grid("/contact_map", data, dt_ns),
            name if name == topics::PLANNING_CMD.name => {
                let cmd: Box<Cmd> = boxed(data);
                vec![out(
                    "/cmd_vel",
                    "geometry_msgs/Twist",
                    &planar_twist(cmd.v, cmd.omega),
                )]
            }
            name if name == topics::LOCALIZATION_PARTICLES.name => {
                let particles: Box<Particles> = boxed(data);
                let poses = particles.particles().iter();
                let m = msg::PoseArray {
                    header: header(t, MAP_FRAME),
                    poses: poses
                        .map(|p| msg::Pose::planar(p.x.into(), p.y.into(), p.theta.into()))
                        .collect(),
                };
                vec![out("/particles", "geometry_msgs/PoseArray", &m)]
            }
            name if name == topics::LOCALIZATION_LANDMARKS.name => {
                let landmarks: Box<Landmarks> = boxed(data);
                let m = landmark_markers(&landmarks, t);
                vec![out("/landmarks", "visualization_msgs/MarkerArray", &m)]
            }
            _ => Vec::new(),
        }
    }
}

/// A planar velocity (v forward, ω about z).
fn planar_twist(v: f64, omega: f64) -> msg::Twist {
    msg::Twist {
        linear: msg::Vector3 {
            x: v,
            y: 0.0,
            z: 0.0,
        },
        angular: msg::Vector3 {
            x: 0.0,
            y: 0.0,
            z: omega,
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// CDR as ROS 2 writes it: the little-endian encapsulation header, then each field aligned
    /// to its size from just after the header; a string is its length with the NUL, its bytes
    /// and the NUL.
    #[test]
    fn a_header_is_its_stamp_then_its_frame_with_the_terminating_nul() {
        let h = header(msg::Time { sec: 2, nanosec: 5 }, "map");
        let expected = [
            0, 1, 0, 0, // CDR_LE
            2, 0, 0, 0, 5, 0, 0, 0, // stamp
            4, 0, 0, 0, b'm', b'a', b'p', 0, // frame_id
        ];
        assert_eq!(cdr(&h), expected);
        // A float64 after a 4-byte field is aligned to 8 from the payload's start.
        let t = msg::TransformStamped {
            header: header(msg::Time::default(), ""),
            child_frame_id: String::new(),
            transform: msg::Transform {
                translation: msg::Vector3 {
                    x: 1.0,
                    y: 0.0,
                    z: 0.0,
                },
                rotation: msg::Quaternion::yaw(0.0),
            },
        };
        let bytes = cdr(&t);
        // stamp 8, "" 4 + 1 (NUL), "" at 16: 4 + 1 → 21, padded to 24 for x.
        assert_eq!(&bytes[4 + 24..4 + 32], &1.0f64.to_le_bytes());
    }

    #[test]
    fn a_definition_carries_every_type_it_refers_to_once() {
        let d = full_definition("geometry_msgs/PoseWithCovarianceStamped");
        assert!(d.starts_with("std_msgs/Header header\nPoseWithCovariance pose\n"));
        for dep in [
            "std_msgs/Header",
            "builtin_interfaces/Time",
            "geometry_msgs/PoseWithCovariance",
            "geometry_msgs/Pose",
            "geometry_msgs/Point",
            "geometry_msgs/Quaternion",
        ] {
            assert_eq!(
                d.matches(&format!("MSG: {dep}\n")).count(),
                1,
                "{dep} in\n{d}"
            );
        }
        let separator = format!("\n{}\nMSG: ", "=".repeat(80));
        assert_eq!(d.matches(&separator).count(), 6);
        // Every type the export writes has a complete definition.
        let marker = full_definition("visualization_msgs/MarkerArray");
        for dep in [
            "visualization_msgs/Marker",
            "sensor_msgs/CompressedImage",
            "visualization_msgs/MeshFile",
        ] {
            assert!(marker.contains(&format!("MSG: {dep}\n")), "{dep}");
        }
        assert_eq!(
            type_name("sensor_msgs/LaserScan"),
            "sensor_msgs/msg/LaserScan"
        );
    }

    #[test]
    fn map_to_odom_composes_with_odometry_into_the_estimate() {
        let (estimate, odom) = ([2.0, 1.0, 0.9], [0.5, -0.3, 0.4]);
        let [x, y, yaw] = map_to_odom(estimate, odom);
        // map → odom ∘ odom → base_link = map → base_link.
        let (s, c) = yaw.sin_cos();
        let composed = [
            x + c * odom[0] - s * odom[1],
            y + s * odom[0] + c * odom[1],
            yaw + odom[2],
        ];
        for (a, b) in composed.iter().zip(estimate) {
            assert!((a - b).abs() < 1e-12, "{composed:?} vs {estimate:?}");
        }
    }

    #[test]
    fn grid_cells_become_unknown_free_and_occupied() {
        let f = GRID_FRONTIER;
        let got = [CELL_UNEXPLORED, CELL_FREE, CELL_OCCUPIED].map(|c| occupancy(f, c));
        assert_eq!(got, [-1, 0, 100]);
        assert_eq!(
            [0, 1].map(|c| occupancy(mole_types::GRID_CONTACT, c)),
            [-1, 100]
        );
    }

    #[test]
    fn a_landmark_marker_is_its_95_percent_ellipse() {
        // Σ = diag(4, 1): axes 2·√(5.99·4) and 2·√(5.99·1), along x.
        let (major, minor, yaw) = ellipse(&[4.0, 0.0, 0.0, 1.0]);
        assert!((major - 2.0 * (CHI2_2D_95 * 4.0).sqrt()).abs() < 1e-12);
        assert!((minor - 2.0 * CHI2_2D_95.sqrt()).abs() < 1e-12);
        assert!(yaw.abs() < 1e-12);
        // Rotated by 90°: the major axis along y.
        let (_, _, yaw) = ellipse(&[1.0, 0.0, 0.0, 4.0]);
        assert!((yaw.abs() - core::f64::consts::FRAC_PI_2).abs() < 1e-12);
    }

    #[test]
    fn a_step_is_stamped_with_its_simulated_time() {
        assert_eq!(
            stamp(150, 10_000_000),
            msg::Time {
                sec: 1,
                nanosec: 500_000_000
            }
        );
        assert_eq!(stamp(0, 10_000_000), msg::Time::default());
    }
}
