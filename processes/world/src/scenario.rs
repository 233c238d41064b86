//! Scenario files: the arena of algorithms §1.3 (a rectangle `[0, W] × [0, H]` with axis-aligned
//! square obstacles), the robot, its sensors and their noise, the seed and an optional goal.
//!
//! A scenario is a TOML file; every section is optional and falls back to the defaults below, so
//! an empty file is a valid, empty 10 m × 10 m arena.
//!
//! ```text
//! name = "default"                 # default: the file name without `.toml`
//! [sim]       dt = 0.01, seed = 0  # step Δt (s), seed of the run
//! [arena]     width = 10.0, height = 10.0          # m (default from the [map] when one is given)
//! [robot]     radius = 0.2, max_speed = 0.5, max_omega = 2.0, max_accel = 2.0, max_alpha = 8.0
//! [start]     x = 1.0, y = 1.0, theta = 0.0
//! [goal]      x, y (required in the section), tolerance = 0.3       # no [goal]: no goal
//! [grid]      resolution = 0.05    # cell size of the mapping grids (m)
//! obstacles = [ { x = 3.0, y = 4.0, side = 1.0 } ]   # square centre and side (m); or [[obstacles]]
//! beacons   = [ { x = 0.5, y = 9.5 } ]               # id = index in the list
//! [sensors.lidar]     beams = 180, range_max = 4.0, fov = 2π, range_std = 0.01  (beams = 0: none)
//! [sensors.tactile]   count = 8, stiffness = 2000.0, force_std = 0.05
//! [sensors.odometry]  v_std = 0.02, omega_std = 0.02
//! [sensors.beacons]   range_max = 6.0, range_std = 0.05, bearing_std = 0.02,
//!                     anonymous = false   (true: readings hide the beacon ids)
//! [sensors.fix]       std = 0.3, period_ticks = 100   (period_ticks = 0: no fix)
//! [map]       image = "maps/small.yaml"  # a ROS map_server YAML, relative to the scenario file
//! ```
//!
//! Keys after a `[table]` header belong to that table (TOML), so write the `obstacles` and
//! `beacons` arrays before the first header, or as `[[obstacles]]` tables. Every error names the
//! file, the line and column, the field and what was expected.

use crate::rosmap::{self, OccupancyMap};
use mole_types::{
    BeaconSite, MAX_BEACONS, MAX_BEAMS, MAX_GRID_CELLS, MAX_OBSTACLES, MAX_TACTILE, Pose2,
    RobotSpec, SensorSpec, Square, WorldMap,
};
use serde::Deserialize;
use std::fmt;
use std::path::{Path, PathBuf};
use toml::de::DeValue;

// ---------------------------------------------------------------------------------------------
// The file as written
// ---------------------------------------------------------------------------------------------

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct File {
    name: Option<String>,
    #[serde(default)]
    sim: SimSection,
    arena: Option<ArenaSection>,
    #[serde(default)]
    robot: RobotSection,
    #[serde(default)]
    start: StartSection,
    goal: Option<GoalSection>,
    #[serde(default)]
    grid: GridSection,
    #[serde(default)]
    obstacles: Vec<ObstacleEntry>,
    #[serde(default)]
    beacons: Vec<BeaconEntry>,
    #[serde(default)]
    sensors: SensorsSection,
    map: Option<MapSection>,
}

#[derive(Debug, Deserialize)]
#[serde(default, deny_unknown_fields)]
struct SimSection {
    dt: f64,
    seed: u64,
}

impl Default for SimSection {
    fn default() -> Self {
        Self { dt: 0.01, seed: 0 }
    }
}

#[derive(Debug, Deserialize)]
#[serde(default, deny_unknown_fields)]
struct ArenaSection {
    width: f64,
    height: f64,
}

impl Default for ArenaSection {
    fn default() -> Self {
        Self {
            width: 10.0,
            height: 10.0,
        }
    }
}

#[derive(Debug, Deserialize)]
#[serde(default, deny_unknown_fields)]
struct RobotSection {
    radius: f64,
    max_speed: f64,
    max_omega: f64,
    max_accel: f64,
    max_alpha: f64,
}

impl Default for RobotSection {
    fn default() -> Self {
        let r = mole_types::RobotSpec::SCENARIO_DEFAULT;
        Self {
            radius: r.radius,
            max_speed: r.max_speed,
            max_omega: r.max_omega,
            max_accel: r.max_accel,
            max_alpha: r.max_alpha,
        }
    }
}

#[derive(Debug, Deserialize)]
#[serde(default, deny_unknown_fields)]
struct StartSection {
    x: f64,
    y: f64,
    theta: f64,
}

impl Default for StartSection {
    fn default() -> Self {
        Self {
            x: 1.0,
            y: 1.0,
            theta: 0.0,
        }
    }
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct GoalSection {
    x: f64,
    y: f64,
    #[serde(default = "default_goal_tolerance")]
    tolerance: f64,
}

fn default_goal_tolerance() -> f64 {
    0.3
}

#[derive(Debug, Deserialize)]
#[serde(default, deny_unknown_fields)]
struct GridSection {
    resolution: f64,
}

impl Default for GridSection {
    fn default() -> Self {
        Self { resolution: 0.05 }
    }
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct ObstacleEntry {
    x: f64,
    y: f64,
    side: f64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct BeaconEntry {
    x: f64,
    y: f64,
}

#[derive(Debug, Default, Deserialize)]
#[serde(default, deny_unknown_fields)]
struct SensorsSection {
    lidar: LidarSection,
    tactile: TactileSection,
    odometry: OdometrySection,
    beacons: BeaconSensorSection,
    fix: FixSection,
}

#[derive(Debug, Deserialize)]
#[serde(default, deny_unknown_fields)]
struct LidarSection {
    beams: u32,
    range_max: f64,
    fov: f64,
    range_std: f64,
}

impl Default for LidarSection {
    fn default() -> Self {
        Self {
            beams: 180,
            range_max: 4.0,
            fov: std::f64::consts::TAU,
            range_std: 0.01,
        }
    }
}

#[derive(Debug, Deserialize)]
#[serde(default, deny_unknown_fields)]
struct TactileSection {
    count: u32,
    stiffness: f64,
    force_std: f64,
}

impl Default for TactileSection {
    fn default() -> Self {
        Self {
            count: 8,
            stiffness: 2000.0,
            force_std: 0.05,
        }
    }
}

#[derive(Debug, Deserialize)]
#[serde(default, deny_unknown_fields)]
struct OdometrySection {
    v_std: f64,
    omega_std: f64,
}

impl Default for OdometrySection {
    fn default() -> Self {
        Self {
            v_std: 0.02,
            omega_std: 0.02,
        }
    }
}

#[derive(Debug, Deserialize)]
#[serde(default, deny_unknown_fields)]
struct BeaconSensorSection {
    range_max: f64,
    range_std: f64,
    bearing_std: f64,
    anonymous: bool,
}

impl Default for BeaconSensorSection {
    fn default() -> Self {
        Self {
            range_max: 6.0,
            range_std: 0.05,
            bearing_std: 0.02,
            anonymous: false,
        }
    }
}

#[derive(Debug, Deserialize)]
#[serde(default, deny_unknown_fields)]
struct FixSection {
    std: f64,
    period_ticks: u32,
}

impl Default for FixSection {
    fn default() -> Self {
        Self {
            std: 0.3,
            period_ticks: 100,
        }
    }
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct MapSection {
    image: String,
}

// ---------------------------------------------------------------------------------------------
// The scenario as the simulation uses it
// ---------------------------------------------------------------------------------------------

/// A goal position and the distance within which it counts as reached.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Goal {
    pub x: f64,
    pub y: f64,
    /// Reached when the robot centre is within this distance (m).
    pub tolerance: f64,
}

/// A loaded, validated scenario. Fields are public so a launcher can override them (`--seed`).
#[derive(Debug, Clone, PartialEq)]
pub struct Scenario {
    /// Scenario name (default: the file stem).
    pub name: String,
    /// The file it was read from.
    pub path: PathBuf,
    /// Simulation step Δt (s).
    pub dt: f64,
    /// Seed of the run; every process derives its own stream from it.
    pub seed: u64,
    /// Arena `[0, arena_width] × [0, arena_height]` (m).
    pub arena_width: f64,
    pub arena_height: f64,
    /// Robot body and motion limits.
    pub robot: RobotSpec,
    /// Start pose.
    pub start: Pose2,
    /// Optional goal.
    pub goal: Option<Goal>,
    /// Cell size of the mapping grids (m).
    pub grid_resolution: f64,
    /// Square obstacles: those listed in the file, then those of the ROS map (if any).
    pub obstacles: Vec<Square>,
    /// Beacons; `id` is the index.
    pub beacons: Vec<BeaconSite>,
    /// Sensor parameters and noise.
    pub sensors: SensorSpec,
}

impl Default for Scenario {
    /// The scenario of an empty file: an empty 10 m × 10 m arena with every default.
    fn default() -> Self {
        Scenario::from_file(File::default(), None, Path::new("default.toml"))
    }
}

impl Scenario {
    fn from_file(file: File, map: Option<&OccupancyMap>, path: &Path) -> Scenario {
        let name = file.name.unwrap_or_else(|| {
            path.file_stem()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_default()
        });
        let arena = match (&file.arena, map) {
            (Some(a), _) => (a.width, a.height),
            (None, Some(m)) => m.extent(),
            (None, None) => {
                let a = ArenaSection::default();
                (a.width, a.height)
            }
        };
        let mut obstacles: Vec<Square> = file
            .obstacles
            .iter()
            .map(|o| Square::new(o.x, o.y, o.side))
            .collect();
        if let Some(m) = map {
            // Pixels whose centre falls outside the arena are dropped: the arena walls bound the
            // world anyway.
            obstacles
                .extend(m.obstacles().filter(|s| {
                    (0.0..=arena.0).contains(&s.cx) && (0.0..=arena.1).contains(&s.cy)
                }));
        }
        let beacons = file
            .beacons
            .iter()
            .enumerate()
            .map(|(i, b)| BeaconSite {
                x: b.x,
                y: b.y,
                id: i as u32,
                _pad: 0,
            })
            .collect();
        let s = &file.sensors;
        Scenario {
            name,
            path: path.to_path_buf(),
            dt: file.sim.dt,
            seed: file.sim.seed,
            arena_width: arena.0,
            arena_height: arena.1,
            robot: RobotSpec {
                radius: file.robot.radius,
                max_speed: file.robot.max_speed,
                max_omega: file.robot.max_omega,
                max_accel: file.robot.max_accel,
                max_alpha: file.robot.max_alpha,
            },
            start: Pose2::new(file.start.x, file.start.y, file.start.theta),
            goal: file.goal.as_ref().map(|g| Goal {
                x: g.x,
                y: g.y,
                tolerance: g.tolerance,
            }),
            grid_resolution: file.grid.resolution,
            obstacles,
            beacons,
            sensors: SensorSpec {
                lidar_beams: s.lidar.beams,
                tactile_sensors: s.tactile.count,
                lidar_range_max: s.lidar.range_max,
                lidar_fov: s.lidar.fov,
                lidar_range_std: s.lidar.range_std,
                tactile_stiffness: s.tactile.stiffness,
                tactile_force_std: s.tactile.force_std,
                odom_v_std: s.odometry.v_std,
                odom_omega_std: s.odometry.omega_std,
                beacon_range_max: s.beacons.range_max,
                beacon_range_std: s.beacons.range_std,
                beacon_bearing_std: s.beacons.bearing_std,
                fix_std: s.fix.std,
                fix_period_ticks: s.fix.period_ticks,
                beacons_anonymous: u32::from(s.beacons.anonymous),
            },
        }
    }

    /// Grid cells of a mapping grid over the arena: `(⌈W/res⌉, ⌈H/res⌉)`.
    pub fn grid_size(&self) -> (usize, usize) {
        let cells = |len: f64| (len / self.grid_resolution).ceil().max(0.0) as usize;
        (cells(self.arena_width), cells(self.arena_height))
    }

    /// Whether the robot disk centred at `(x, y)` lies inside the arena and overlaps no obstacle
    /// (touching is allowed).
    pub fn disk_is_free(&self, x: f64, y: f64) -> bool {
        self.disk_conflict(x, y).is_none()
    }

    /// What the robot disk at `(x, y)` conflicts with: `Some(None)` the arena walls,
    /// `Some(Some(i))` obstacle i, `None` nothing.
    fn disk_conflict(&self, x: f64, y: f64) -> Option<Option<usize>> {
        let r = self.robot.radius;
        let eps = 1e-9;
        if x < r - eps || y < r - eps || x > self.arena_width - r + eps {
            return Some(None);
        }
        if y > self.arena_height - r + eps {
            return Some(None);
        }
        self.obstacles
            .iter()
            .position(|o| distance_to_square(o, x, y) < r - eps)
            .map(Some)
    }

    /// The `world/map` message of this scenario (header zero), boxed: it is too large for the
    /// stack.
    pub fn world_map(&self) -> Box<WorldMap> {
        let mut map: Box<WorldMap> = bytemuck::zeroed_box();
        self.write_world_map(&mut map);
        map
    }

    /// Fills every field of the `world/map` message except `header`, in place.
    pub fn write_world_map(&self, map: &mut WorldMap) {
        map.arena_width = self.arena_width;
        map.arena_height = self.arena_height;
        map.dt = self.dt;
        map.seed = self.seed;
        map.start_x = self.start.x;
        map.start_y = self.start.y;
        map.start_theta = self.start.theta;
        match self.goal {
            Some(g) => {
                map.goal_x = g.x;
                map.goal_y = g.y;
                map.goal_tolerance = g.tolerance;
                map.has_goal = 1;
            }
            None => {
                map.goal_x = 0.0;
                map.goal_y = 0.0;
                map.goal_tolerance = 0.0;
                map.has_goal = 0;
            }
        }
        map._pad = 0;
        map.grid_resolution = self.grid_resolution;
        map.robot = self.robot;
        map.sensors = self.sensors;
        let n_obstacles = self.obstacles.len().min(MAX_OBSTACLES);
        map.obstacles[..n_obstacles].copy_from_slice(&self.obstacles[..n_obstacles]);
        map.obstacles[n_obstacles..].fill(Square::default());
        map.n_obstacles = n_obstacles as u32;
        let n_beacons = self.beacons.len().min(MAX_BEACONS);
        for (i, (dst, src)) in map.beacons.iter_mut().zip(&self.beacons).enumerate() {
            *dst = BeaconSite {
                x: src.x,
                y: src.y,
                id: i as u32,
                _pad: 0,
            };
        }
        map.beacons[n_beacons..].fill(BeaconSite::default());
        map.n_beacons = n_beacons as u32;
    }

    /// Checks every value; the error names the field (a path into the file) and what was wrong.
    fn check(&self, from_map: bool) -> Result<(), Invalid> {
        finite_positive("sim.dt", self.dt, "a positive number of seconds")?;
        let arena_unit = "a positive number of metres";
        let arena_field = |f: &'static str| if from_map { "map.image" } else { f };
        finite_positive(arena_field("arena.width"), self.arena_width, arena_unit)?;
        finite_positive(arena_field("arena.height"), self.arena_height, arena_unit)?;

        let r = &self.robot;
        finite_positive("robot.radius", r.radius, "a positive number of metres")?;
        finite_positive("robot.max_speed", r.max_speed, "a positive speed in m/s")?;
        finite_positive(
            "robot.max_omega",
            r.max_omega,
            "a positive turn rate in rad/s",
        )?;
        finite_positive(
            "robot.max_accel",
            r.max_accel,
            "a positive acceleration in m/s²",
        )?;
        finite_positive(
            "robot.max_alpha",
            r.max_alpha,
            "a positive angular acceleration in rad/s²",
        )?;
        if 2.0 * r.radius > self.arena_width.min(self.arena_height) {
            return Err(Invalid::new(
                "robot.radius",
                format!(
                    "expected a robot that fits in the {} m × {} m arena, found radius {}",
                    self.arena_width, self.arena_height, r.radius
                ),
            ));
        }

        finite_positive(
            "grid.resolution",
            self.grid_resolution,
            "a positive cell size in metres",
        )?;
        let (gw, gh) = self.grid_size();
        if gw.saturating_mul(gh) > MAX_GRID_CELLS {
            return Err(Invalid::new(
                "grid.resolution",
                format!(
                    "expected at most {MAX_GRID_CELLS} grid cells over the arena, found {gw} × {gh} \
                     = {} at {} m",
                    gw.saturating_mul(gh),
                    self.grid_resolution
                ),
            ));
        }

        if self.obstacles.len() > MAX_OBSTACLES {
            let field = if from_map { "map.image" } else { "obstacles" };
            return Err(Invalid::new(
                field,
                format!(
                    "expected at most {MAX_OBSTACLES} obstacles, found {}",
                    self.obstacles.len()
                ),
            ));
        }
        for (i, o) in self.obstacles.iter().enumerate() {
            // Map obstacles come after the listed ones and were built from validated map values.
            let field = |f: &str| format!("obstacles[{i}].{f}");
            finite(&field("x"), o.cx)?;
            finite(&field("y"), o.cy)?;
            if !(o.side.is_finite() && o.side > 0.0) {
                return Err(Invalid::new(
                    field("side"),
                    format!("expected a positive number of metres, found {}", o.side),
                ));
            }
            if !self.inside_arena(o.cx, o.cy) {
                return Err(Invalid::new(
                    format!("obstacles[{i}]"),
                    format!(
                        "expected a centre inside the arena [0, {}] × [0, {}], found ({}, {})",
                        self.arena_width, self.arena_height, o.cx, o.cy
                    ),
                ));
            }
        }

        if self.beacons.len() > MAX_BEACONS {
            return Err(Invalid::new(
                "beacons",
                format!(
                    "expected at most {MAX_BEACONS} beacons, found {}",
                    self.beacons.len()
                ),
            ));
        }
        for (i, b) in self.beacons.iter().enumerate() {
            finite(&format!("beacons[{i}].x"), b.x)?;
            finite(&format!("beacons[{i}].y"), b.y)?;
            if !self.inside_arena(b.x, b.y) {
                return Err(Invalid::new(
                    format!("beacons[{i}]"),
                    format!(
                        "expected a position inside the arena [0, {}] × [0, {}], found ({}, {})",
                        self.arena_width, self.arena_height, b.x, b.y
                    ),
                ));
            }
        }

        finite("start.x", self.start.x)?;
        finite("start.y", self.start.y)?;
        finite("start.theta", self.start.theta)?;
        self.check_placement("start", self.start.x, self.start.y)?;
        if let Some(g) = self.goal {
            finite("goal.x", g.x)?;
            finite("goal.y", g.y)?;
            finite_positive("goal.tolerance", g.tolerance, "a positive number of metres")?;
            self.check_placement("goal", g.x, g.y)?;
        }

        let s = &self.sensors;
        if s.lidar_beams as usize > MAX_BEAMS {
            return Err(Invalid::new(
                "sensors.lidar.beams",
                format!(
                    "expected at most {MAX_BEAMS} beams, found {}",
                    s.lidar_beams
                ),
            ));
        }
        if s.lidar_beams > 0 {
            finite_positive(
                "sensors.lidar.range_max",
                s.lidar_range_max,
                "a positive range in metres",
            )?;
            let fov = s.lidar_fov;
            if !(fov.is_finite() && fov > 0.0 && fov <= std::f64::consts::TAU + 1e-9) {
                return Err(Invalid::new(
                    "sensors.lidar.fov",
                    format!("expected a field of view in (0, 2π] radians, found {fov}"),
                ));
            }
        }
        non_negative("sensors.lidar.range_std", s.lidar_range_std)?;
        if s.tactile_sensors as usize > MAX_TACTILE {
            return Err(Invalid::new(
                "sensors.tactile.count",
                format!(
                    "expected at most {MAX_TACTILE} sensors, found {}",
                    s.tactile_sensors
                ),
            ));
        }
        finite_positive(
            "sensors.tactile.stiffness",
            s.tactile_stiffness,
            "a positive stiffness in N/m",
        )?;
        non_negative("sensors.tactile.force_std", s.tactile_force_std)?;
        non_negative("sensors.odometry.v_std", s.odom_v_std)?;
        non_negative("sensors.odometry.omega_std", s.odom_omega_std)?;
        non_negative("sensors.beacons.range_max", s.beacon_range_max)?;
        non_negative("sensors.beacons.range_std", s.beacon_range_std)?;
        non_negative("sensors.beacons.bearing_std", s.beacon_bearing_std)?;
        non_negative("sensors.fix.std", s.fix_std)?;
        Ok(())
    }

    fn inside_arena(&self, x: f64, y: f64) -> bool {
        (0.0..=self.arena_width).contains(&x) && (0.0..=self.arena_height).contains(&y)
    }

    fn check_placement(&self, what: &str, x: f64, y: f64) -> Result<(), Invalid> {
        let r = self.robot.radius;
        match self.disk_conflict(x, y) {
            None => Ok(()),
            Some(None) => Err(Invalid::new(
                what,
                format!(
                    "expected the robot disk (radius {r} m) inside the arena, i.e. x in [{r}, {}] \
                     and y in [{r}, {}], found ({x}, {y})",
                    self.arena_width - r,
                    self.arena_height - r
                ),
            )),
            Some(Some(i)) => {
                let o = self.obstacles[i];
                let mut invalid = Invalid::new(
                    what,
                    format!(
                        "expected a free position, found ({x}, {y}), where the robot disk (radius \
                         {r} m) overlaps obstacle {i} (centre ({}, {}), side {})",
                        o.cx, o.cy, o.side
                    ),
                );
                invalid.related = Some(format!("obstacles[{i}]"));
                Err(invalid)
            }
        }
    }
}

/// Distance from a point to an axis-aligned square (0 inside).
pub(crate) fn distance_to_square(o: &Square, x: f64, y: f64) -> f64 {
    let h = o.side / 2.0;
    let dx = ((x - o.cx).abs() - h).max(0.0);
    let dy = ((y - o.cy).abs() - h).max(0.0);
    dx.hypot(dy)
}

// ---------------------------------------------------------------------------------------------
// Errors
// ---------------------------------------------------------------------------------------------

/// A place in a file: 1-based line and column (0 when unknown).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Location {
    pub file: PathBuf,
    pub line: usize,
    pub column: usize,
}

impl Location {
    fn at(file: &Path, text: &str, offset: Option<usize>) -> Location {
        let (line, column) = offset.map_or((0, 0), |o| line_column(text, o));
        Location {
            file: file.to_path_buf(),
            line,
            column,
        }
    }
}

impl fmt::Display for Location {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.file.display())?;
        if self.line > 0 {
            write!(f, ":{}:{}", self.line, self.column)?;
        }
        Ok(())
    }
}

/// Why a scenario could not be loaded. The message names the file, line, column and field.
#[derive(Debug, thiserror::Error)]
pub enum ScenarioError {
    /// The file could not be read.
    #[error("{}: cannot read the scenario: {source}", path.display())]
    Read {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// The text is not valid TOML.
    #[error("{location}: {message}")]
    Syntax { location: Location, message: String },
    /// A field has the wrong type, an unknown name, or a value out of range.
    #[error("{location}: field `{field}`: {message}")]
    Field {
        location: Location,
        field: String,
        message: String,
    },
    /// A key the format does not know, or a field that is missing.
    #[error("{location}: {message}")]
    Structure { location: Location, message: String },
    /// The ROS map named in `[map]` could not be loaded.
    #[error("{location}: field `map.image`: {source}")]
    Map {
        location: Location,
        #[source]
        source: rosmap::MapError,
    },
}

/// A validation failure before it is located in the text.
#[derive(Debug)]
struct Invalid {
    field: String,
    message: String,
    /// Where to point when `field` is not written in the file (it took its default).
    related: Option<String>,
}

impl Invalid {
    fn new(field: impl Into<String>, message: impl Into<String>) -> Self {
        Self {
            field: field.into(),
            message: message.into(),
            related: None,
        }
    }
}

fn finite(field: &str, v: f64) -> Result<(), Invalid> {
    if v.is_finite() {
        Ok(())
    } else {
        Err(Invalid::new(
            field,
            format!("expected a finite number, found {v}"),
        ))
    }
}

fn finite_positive(field: &str, v: f64, expected: &str) -> Result<(), Invalid> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err(Invalid::new(
            field,
            format!("expected {expected}, found {v}"),
        ))
    }
}

fn non_negative(field: &str, v: f64) -> Result<(), Invalid> {
    if v.is_finite() && v >= 0.0 {
        Ok(())
    } else {
        Err(Invalid::new(
            field,
            format!("expected a finite number >= 0, found {v}"),
        ))
    }
}

/// 1-based line and column (in characters) of a byte offset.
fn line_column(text: &str, offset: usize) -> (usize, usize) {
    let mut offset = offset.min(text.len());
    while !text.is_char_boundary(offset) {
        offset -= 1;
    }
    let before = &text[..offset];
    let line = before.matches('\n').count() + 1;
    let line_start = before.rfind('\n').map_or(0, |i| i + 1);
    (line, before[line_start..].chars().count() + 1)
}

/// Segments of a field path such as `obstacles[3].side` or `sensors.lidar.beams`.
enum Segment<'a> {
    Key(&'a str),
    Index(usize),
}

fn segments(path: &str) -> impl Iterator<Item = Segment<'_>> {
    path.split('.').flat_map(|part| {
        let (key, rest) = match part.find('[') {
            Some(i) => (&part[..i], &part[i..]),
            None => (part, ""),
        };
        let key = (!key.is_empty()).then_some(Segment::Key(key));
        let indices = rest
            .split(['[', ']'])
            .filter(|s| !s.is_empty())
            .filter_map(|s| s.parse().ok())
            .map(Segment::Index);
        key.into_iter().chain(indices)
    })
}

/// Byte offset of the value at `path` in the document, or of its deepest ancestor written there.
fn locate(root: &DeValue<'_>, path: &str) -> Option<usize> {
    let mut node = root;
    let mut found = None;
    for seg in segments(path) {
        let next = match seg {
            Segment::Key(k) => node.get(k),
            Segment::Index(i) => node.get(i),
        };
        match next {
            Some(v) => {
                found = Some(v.span().start);
                node = v.get_ref();
            }
            None => break,
        }
    }
    found
}

// ---------------------------------------------------------------------------------------------
// Loading
// ---------------------------------------------------------------------------------------------

/// The folder of the scenarios that ship with mole (`scenarios/` at the repository's root).
pub fn bundled_scenarios() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenarios")
}

/// A scenario that ships with mole, by its file's stem (`default`, `slam_loop`…): for tests and
/// benchmarks.
pub fn bundled_scenario(name: &str) -> Result<Scenario, ScenarioError> {
    load_scenario(&bundled_scenarios().join(format!("{name}.toml")))
}

/// Reads and validates a scenario file.
pub fn load_scenario(path: &Path) -> Result<Scenario, ScenarioError> {
    let text = std::fs::read_to_string(path).map_err(|source| ScenarioError::Read {
        path: path.to_path_buf(),
        source,
    })?;
    parse_scenario(&text, path)
}

/// Parses and validates a scenario; `path` names the file in errors, and a `[map]` image is
/// looked up relative to its directory.
pub fn parse_scenario(text: &str, path: &Path) -> Result<Scenario, ScenarioError> {
    let syntax = |e: toml::de::Error| ScenarioError::Syntax {
        location: Location::at(path, text, e.span().map(|s| s.start)),
        message: e.message().trim().to_string(),
    };
    // A binary file and an empty one are wrong files, not a request for the default arena (every
    // field has a default, so either would otherwise run silently).
    if let Some((offset, c)) = text
        .char_indices()
        .find(|(_, c)| c.is_control() && !matches!(c, '\t' | '\n' | '\r'))
    {
        return Err(ScenarioError::Structure {
            location: Location::at(path, text, Some(offset)),
            message: format!(
                "not a text file (control character U+{:04X}): expected a TOML scenario",
                u32::from(c)
            ),
        });
    }
    let document = toml::de::DeTable::parse(text).map_err(syntax)?;
    let root = DeValue::Table(document.into_inner());
    if let DeValue::Table(table) = &root
        && table.is_empty()
    {
        return Err(ScenarioError::Structure {
            location: Location::at(path, text, None),
            message: "the scenario sets nothing: expected a TOML scenario with at least one \
                      field (scenarios/default.toml documents them)"
                .into(),
        });
    }
    let deserializer = toml::de::Deserializer::parse(text).map_err(syntax)?;
    let file: File = serde_path_to_error::deserialize(deserializer).map_err(|e| {
        let field = e.path().to_string();
        let inner = e.inner();
        let offset = inner
            .span()
            .map(|s| s.start)
            .or_else(|| locate(&root, &field));
        let location = Location::at(path, text, offset);
        let mut message = inner.message().trim().to_string();
        if message.starts_with("unknown field") {
            // The path ends with the unknown key; name the table it sits in.
            let table = match field.rfind('.') {
                Some(i) => format!("in `{}`", &field[..i]),
                None => "at the top level".to_string(),
            };
            message = message.replacen(", expected", &format!(" {table}, expected"), 1);
            ScenarioError::Structure { location, message }
        } else if field == "." {
            ScenarioError::Structure { location, message }
        } else {
            ScenarioError::Field {
                location,
                field,
                message,
            }
        }
    })?;

    let map = match &file.map {
        Some(m) => {
            let base = path.parent().unwrap_or_else(|| Path::new(""));
            let loaded = rosmap::load_ros_map(&base.join(&m.image)).map_err(|source| {
                ScenarioError::Map {
                    location: Location::at(path, text, locate(&root, "map.image")),
                    source,
                }
            })?;
            Some(loaded)
        }
        None => None,
    };
    let from_map = map.is_some() && file.arena.is_none();
    let scenario = Scenario::from_file(file, map.as_ref(), path);
    scenario
        .check(from_map)
        .map_err(|inv| ScenarioError::Field {
            location: Location::at(
                path,
                text,
                locate(&root, &inv.field)
                    .or_else(|| inv.related.as_deref().and_then(|r| locate(&root, r))),
            ),
            field: inv.field,
            message: inv.message,
        })?;
    Ok(scenario)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn parse(text: &str) -> Result<Scenario, ScenarioError> {
        parse_scenario(text, Path::new("scenarios/x.toml"))
    }

    fn err(text: &str) -> String {
        match parse(text) {
            Ok(_) => panic!("expected an error for:\n{text}"),
            Err(e) => e.to_string(),
        }
    }

    /// An empty file, one of comments only and a binary one are wrong files, refused naming
    /// the file (and where the first control character is), never the default arena.
    #[test]
    fn empty_and_binary_files_are_refused() {
        for empty in ["", "\n  \n", "# a scenario\n"] {
            let e = err(empty);
            assert!(
                e.starts_with("scenarios/x.toml: the scenario sets nothing"),
                "{e}"
            );
        }
        let e = err("\0\0\0\0");
        assert!(
            e.starts_with("scenarios/x.toml:1:1: not a text file (control character U+0000)"),
            "{e}"
        );
        let e = err("name = \"x\"\n\u{7f}");
        assert!(
            e.starts_with("scenarios/x.toml:2:1: not a text file (control character U+007F)"),
            "{e}"
        );
    }

    #[test]
    fn a_file_that_sets_no_value_is_the_documented_default() {
        let s = parse("[sim]\n").unwrap();
        assert_eq!(s.name, "x");
        assert_eq!(s.dt, 0.01);
        assert_eq!(s.seed, 0);
        assert_eq!((s.arena_width, s.arena_height), (10.0, 10.0));
        assert_eq!(s.robot.radius, 0.2);
        assert_eq!(s.robot.max_speed, 0.5);
        assert_eq!(s.start, Pose2::new(1.0, 1.0, 0.0));
        assert_eq!(s.goal, None);
        assert_eq!(s.grid_resolution, 0.05);
        assert_eq!(s.sensors.lidar_beams, 180);
        assert_eq!(s.sensors.tactile_sensors, 8);
        assert_eq!(s.sensors.fix_period_ticks, 100);
        assert!(s.obstacles.is_empty() && s.beacons.is_empty());
        let d = Scenario {
            name: "x".into(),
            path: "scenarios/x.toml".into(),
            ..Scenario::default()
        };
        assert_eq!(d, s);
    }

    #[test]
    fn full_file_is_read() {
        let s = parse(
            r#"
name = "t"
[sim]
dt = 0.02
seed = 99
[arena]
width = 8.0
height = 6.0
[robot]
radius = 0.25
[start]
x = 2.0
y = 3.0
theta = 1.5
[goal]
x = 7.0
y = 5.0
[[obstacles]]
x = 4.0
y = 3.0
side = 1.0
[[obstacles]]
x = 6.0
y = 1.0
side = 0.5
[[beacons]]
x = 0.5
y = 0.5
[sensors.lidar]
beams = 0
[sensors.fix]
period_ticks = 0
"#,
        )
        .unwrap();
        assert_eq!(s.name, "t");
        assert_eq!((s.dt, s.seed), (0.02, 99));
        assert_eq!((s.arena_width, s.arena_height), (8.0, 6.0));
        assert_eq!(s.robot.radius, 0.25);
        assert_eq!(s.robot.max_omega, 2.0);
        assert_eq!(
            s.goal,
            Some(Goal {
                x: 7.0,
                y: 5.0,
                tolerance: 0.3
            })
        );
        assert_eq!(
            s.obstacles,
            vec![Square::new(4.0, 3.0, 1.0), Square::new(6.0, 1.0, 0.5)]
        );
        assert_eq!(s.beacons.len(), 1);
        assert_eq!(s.sensors.lidar_beams, 0);
        assert_eq!(s.sensors.fix_period_ticks, 0);
        assert_eq!(s.sensors.tactile_sensors, 8);
    }

    #[test]
    fn negative_radius_names_file_line_column_and_field() {
        let e = err("[robot]\nmax_speed = 1.0\nradius = -0.2\n");
        assert_eq!(
            e,
            "scenarios/x.toml:3:10: field `robot.radius`: expected a positive number of metres, \
             found -0.2"
        );
    }

    #[test]
    fn unknown_field_lists_the_expected_ones() {
        let e = err("[robot]\nradiu = 0.2\n");
        assert!(e.starts_with("scenarios/x.toml:2:1: "), "{e}");
        assert!(
            e.contains("unknown field `radiu` in `robot`, expected one of"),
            "{e}"
        );
        assert!(e.contains("radius") && e.contains("max_speed"), "{e}");
        let e = err("nmae = \"x\"\n");
        assert!(
            e.contains("unknown field `nmae` at the top level") && e.contains("name"),
            "{e}"
        );
        let e = err("obstacles = [{ x = 1.0, y = 1.0, sid = 1.0 }]\n");
        assert!(
            e.contains(":1:34: unknown field `sid` in `obstacles[0]`, expected"),
            "{e}"
        );
        let e = err("[sensors.lidr]\nbeams = 3\n");
        assert!(e.contains("unknown field `lidr`"), "{e}");
    }

    #[test]
    fn wrong_type_names_the_field_path() {
        let e = err("[sim]\ndt = 0.01\nseed = \"seven\"\n");
        assert!(
            e.starts_with("scenarios/x.toml:3:8: field `sim.seed`: "),
            "{e}"
        );
        let e = err(
            "[[obstacles]]\nx = 1.0\ny = 1.0\nside = 1.0\n[[obstacles]]\nx = 5.0\ny = 5.0\nside = true\n",
        );
        assert!(
            e.starts_with("scenarios/x.toml:8:8: field `obstacles[1].side`: "),
            "{e}"
        );
        let e = err("[sensors.lidar]\nbeams = -3\n");
        assert!(
            e.contains("field `sensors.lidar.beams`") && e.contains(":2:9:"),
            "{e}"
        );
    }

    #[test]
    fn missing_required_field_is_reported() {
        let e = err("[goal]\nx = 3.0\n");
        assert!(e.contains("missing field `y`"), "{e}");
        assert!(e.starts_with("scenarios/x.toml:1:"), "{e}");
    }

    #[test]
    fn syntax_error_names_the_line() {
        let e = err("[robot]\nradius = = 0.2\n");
        assert!(e.starts_with("scenarios/x.toml:2:"), "{e}");
    }

    #[test]
    fn start_and_goal_must_be_free_and_inside() {
        let e = err("obstacles = [{ x = 3.0, y = 3.0, side = 1.0 }]\n[start]\nx = 3.0\ny = 3.6\n");
        // The start is located at its [start] header.
        assert!(
            e.starts_with("scenarios/x.toml:2:1: field `start`: "),
            "{e}"
        );
        assert!(e.contains("overlaps obstacle 0"), "{e}");
        // A default start inside an obstacle points at the obstacle.
        let e = err("obstacles = [{ x = 1.0, y = 1.0, side = 1.0 }]\n");
        assert!(
            e.starts_with("scenarios/x.toml:1:14: field `start`: "),
            "{e}"
        );
        let e = err("[start]\nx = 0.1\ny = 1.0\n");
        assert!(
            e.contains("field `start`") && e.contains("inside the arena"),
            "{e}"
        );
        let e = err("obstacles = [{ x = 3.0, y = 3.0, side = 1.0 }]\n[goal]\nx = 3.0\ny = 3.0\n");
        assert!(
            e.contains("field `goal`") && e.contains("overlaps obstacle 0"),
            "{e}"
        );
        let e = err("[goal]\nx = 11.0\ny = 3.0\n");
        assert!(e.contains("field `goal`"), "{e}");
        // Touching an obstacle is allowed.
        parse("obstacles = [{ x = 3.0, y = 3.0, side = 1.0 }]\n[start]\nx = 3.0\ny = 3.7\n")
            .unwrap();
    }

    #[test]
    fn capacities_are_checked() {
        let e = err("[sensors.lidar]\nbeams = 5000\n");
        assert!(
            e.starts_with(
                "scenarios/x.toml:2:9: field `sensors.lidar.beams`: expected at most 1024"
            ),
            "{e}"
        );
        let e = err("[sensors.tactile]\ncount = 33\n");
        assert!(
            e.contains("field `sensors.tactile.count`: expected at most 32"),
            "{e}"
        );
        let e = err("[grid]\nresolution = 0.01\n");
        assert!(
            e.contains("field `grid.resolution`: expected at most 262144 grid cells"),
            "{e}"
        );
        let mut text = String::from("beacons = [");
        for i in 0..33 {
            text.push_str(&format!("{{ x = {}.0, y = 0.5 }},", i % 10));
        }
        text.push_str("]\n");
        let e = err(&text);
        assert!(
            e.contains("field `beacons`: expected at most 32 beacons, found 33"),
            "{e}"
        );
        let mut text = String::from("[start]\nx = 0.2\ny = 0.2\n");
        for i in 0..=MAX_OBSTACLES {
            let x = 1.0 + (i % 40) as f64 * 0.2;
            let y = 1.0 + (i / 40) as f64 * 0.1;
            text.push_str(&format!("[[obstacles]]\nx = {x}\ny = {y}\nside = 0.05\n"));
        }
        let e = err(&text);
        assert!(
            e.contains("field `obstacles`: expected at most 2048 obstacles, found 2049"),
            "{e}"
        );
    }

    #[test]
    fn non_finite_and_out_of_range_values_are_refused() {
        let e = err("[sim]\ndt = nan\n");
        assert!(e.contains("field `sim.dt`") && e.contains("NaN"), "{e}");
        let e = err("[arena]\nwidth = inf\n");
        assert!(e.contains("field `arena.width`"), "{e}");
        let e = err("obstacles = [{ x = 3.0, y = 3.0, side = 0.0 }]\n");
        assert!(
            e.starts_with("scenarios/x.toml:1:41: field `obstacles[0].side`"),
            "{e}"
        );
        let e = err("obstacles = [{ x = 30.0, y = 3.0, side = 1.0 }]\n");
        assert!(
            e.contains("field `obstacles[0]`") && e.contains("inside the arena"),
            "{e}"
        );
        let e = err("[sensors.lidar]\nfov = 7.0\n");
        assert!(e.contains("field `sensors.lidar.fov`"), "{e}");
        let e = err("[sensors.odometry]\nv_std = -1.0\n");
        assert!(
            e.contains("field `sensors.odometry.v_std`: expected a finite number >= 0"),
            "{e}"
        );
        let e = err("[robot]\nradius = 6.0\n[start]\nx = 5.0\ny = 5.0\n");
        assert!(
            e.contains("field `robot.radius`") && e.contains("fits"),
            "{e}"
        );
        let e = err("[goal]\nx = 3.0\ny = 3.0\ntolerance = 0.0\n");
        assert!(e.contains("field `goal.tolerance`"), "{e}");
    }

    #[test]
    fn missing_map_file_is_reported_at_the_map_key() {
        let e = err("[map]\nimage = \"does/not/exist.yaml\"\n");
        assert!(
            e.starts_with("scenarios/x.toml:2:9: field `map.image`: "),
            "{e}"
        );
        assert!(e.contains("exist.yaml"), "{e}");
    }

    #[test]
    fn read_error_names_the_file() {
        let e = load_scenario(Path::new("/nonexistent/x.toml"))
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("/nonexistent/x.toml: cannot read"), "{e}");
    }

    /// `[sensors.beacons] anonymous` reaches the world map as 0 or 1; anything but a boolean is
    /// refused with its line, field and what was expected.
    #[test]
    fn anonymous_beacons_switch_travels_in_the_world_map() {
        let mut map: Box<WorldMap> = bytemuck::zeroed_box();
        parse("[sim]\n").unwrap().write_world_map(&mut map);
        assert_eq!(map.sensors.beacons_anonymous, 0, "ids shown by default");
        let s = parse("[sensors.beacons]\nrange_max = 2.0\nanonymous = true\n").unwrap();
        s.write_world_map(&mut map);
        assert_eq!(map.sensors.beacons_anonymous, 1);
        assert_eq!(mole_types::Message::validate(&*map), Ok(()));
        for bad in ["\"yes\"", "1", "1.0"] {
            let e = err(&format!("[sensors.beacons]\nanonymous = {bad}\n"));
            assert!(
                e.starts_with("scenarios/x.toml:2:13: field `sensors.beacons.anonymous`: ")
                    && e.contains("expected a boolean"),
                "{e}"
            );
        }
    }

    #[test]
    fn write_world_map_fills_every_field() {
        let s = parse(
            "obstacles = [{ x = 3.0, y = 4.0, side = 1.0 }, { x = 6.0, y = 6.0, side = 0.5 }]\n\
             beacons = [{ x = 0.5, y = 9.5 }, { x = 9.5, y = 0.5 }]\n\
             [sim]\nseed = 42\n[goal]\nx = 8.0\ny = 8.0\ntolerance = 0.25\n",
        )
        .unwrap();
        let mut map: Box<WorldMap> = bytemuck::zeroed_box();
        map.obstacles[5] = Square::new(1.0, 1.0, 1.0);
        map.header.seq = 77;
        s.write_world_map(&mut map);
        assert_eq!(map.header.seq, 77, "header untouched");
        assert_eq!(map.seed, 42);
        assert_eq!(map.dt, 0.01);
        assert_eq!((map.arena_width, map.arena_height), (10.0, 10.0));
        assert_eq!((map.start_x, map.start_y, map.start_theta), (1.0, 1.0, 0.0));
        assert_eq!(
            (map.has_goal, map.goal_x, map.goal_y, map.goal_tolerance),
            (1, 8.0, 8.0, 0.25)
        );
        assert_eq!(map.grid_resolution, 0.05);
        assert_eq!(map.robot, s.robot);
        assert_eq!(map.sensors, s.sensors);
        assert_eq!(map.obstacles(), &s.obstacles[..]);
        assert_eq!(map.obstacles[5], Square::default(), "stale entries cleared");
        assert_eq!(map.n_beacons, 2);
        assert_eq!(
            (map.beacons[1].x, map.beacons[1].y, map.beacons[1].id),
            (9.5, 0.5, 1)
        );
        assert_eq!(mole_types::Message::validate(&*map), Ok(()));
        let mut s2 = s.clone();
        s2.goal = None;
        s2.write_world_map(&mut map);
        assert_eq!(map.has_goal, 0);
    }

    #[test]
    fn field_paths_are_located() {
        let text = "[robot]\nradius = 0.2\n\n[[obstacles]]\nx = 1\ny = 2\nside = 3\n";
        let root = DeValue::Table(toml::de::DeTable::parse(text).unwrap().into_inner());
        let at = |p: &str| locate(&root, p).map(|o| line_column(text, o));
        assert_eq!(at("robot.radius"), Some((2, 10)));
        assert_eq!(at("obstacles[0].side"), Some((7, 8)));
        assert_eq!(
            at("robot.max_speed").map(|l| l.0),
            Some(1),
            "falls back to the section"
        );
        assert_eq!(at("goal"), None);
    }

    const VALID: &str = "name = \"p\"\nobstacles = [{ x = 3.0, y = 2.5, side = 1.0 }]\n\
        [sim]\ndt = 0.01\nseed = 3\n[arena]\nwidth = 6.0\nheight = 5.0\n\
        [robot]\nradius = 0.2\n[start]\nx = 1.0\ny = 1.0\n[goal]\nx = 5.0\ny = 4.0\n\
        [sensors.lidar]\nbeams = 90\n";

    #[test]
    fn the_mutation_base_is_valid() {
        let s = parse(VALID).unwrap();
        assert_eq!(s.obstacles.len(), 1);
        // A key after a table header belongs to that table: `obstacles` under [goal] is refused.
        let moved = VALID
            .replace("obstacles = [{ x = 3.0, y = 2.5, side = 1.0 }]\n", "")
            .replace("y = 4.0\n", "y = 4.0\nobstacles = []\n");
        assert!(err(&moved).contains("unknown field `obstacles`"));
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(200))]

        #[test]
        fn random_text_never_panics(text in "\\PC{0,200}") {
            let _ = parse(&text);
        }

        #[test]
        fn mutated_valid_files_never_panic(
            edits in proptest::collection::vec((0usize..400, any::<u8>()), 1..6)
        ) {
            let mut bytes = VALID.as_bytes().to_vec();
            for (at, b) in edits {
                let i = at % bytes.len();
                bytes[i] = b;
            }
            let text = String::from_utf8_lossy(&bytes);
            if let Err(e) = parse(&text) {
                prop_assert!(e.to_string().starts_with("scenarios/x.toml"));
            }
        }

        #[test]
        fn tokens_of_valid_files_never_panic(
            picks in proptest::collection::vec((0usize..64, 0usize..16), 1..12)
        ) {
            const KEYS: [&str; 16] = [
                "[robot]", "[sim]", "[arena]", "[goal]", "[[obstacles]]", "[sensors.lidar]",
                "radius", "x", "y", "side", "beams", "width", "seed", "dt", "[map]", "image",
            ];
            const VALUES: [&str; 8] =
                ["= 0.2", "= -1", "= nan", "= 1e308", "= \"s\"", "= 4000", "= [1, 2]", "= inf"];
            let mut text = String::new();
            for (k, v) in picks {
                text.push_str(KEYS[k % KEYS.len()]);
                if !KEYS[k % KEYS.len()].starts_with('[') {
                    text.push(' ');
                    text.push_str(VALUES[v % VALUES.len()]);
                }
                text.push('\n');
            }
            let _ = parse(&text);
        }
    }
}
