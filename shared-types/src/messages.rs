//! The message types, one per topic of docs/architecture.md's process table (plus `RunStatus`, the monitor's
//! live summary). Capacities are fixed; counts say how much of an array is in use.

use crate::geometry::{BeaconSite, Contact, Square};
use crate::{Invalid, Layout, Message, all_finite, finite, within};
use bytemuck::{Pod, Zeroable};
use iceoryx2_bb_derive_macros::ZeroCopySend;
use iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend;

/// Most square obstacles a world can hold (a 20 m maze of 0.5 m blocks needs ~800).
pub const MAX_OBSTACLES: usize = 2048;
/// Most beacons a world can hold.
pub const MAX_BEACONS: usize = 32;
/// Most lidar beams in one scan.
pub const MAX_BEAMS: usize = 1024;
/// Most tactile sensors on the rim.
pub const MAX_TACTILE: usize = 32;
/// Most simultaneous contacts the world reports.
pub const MAX_CONTACTS: usize = 8;
/// Most grid cells (512 × 512).
pub const MAX_GRID_CELLS: usize = 512 * 512;
/// Most particles in a particle set.
pub const MAX_PARTICLES: usize = 16_384;
/// Landmarks a SLAM estimator can hold (`localization/landmarks`): room for every beacon and
/// for the spurious ones an estimator without beacon ids may create.
pub const MAX_LANDMARKS: usize = 64;
/// Most waypoints in a planned path.
pub const MAX_PATH: usize = 512;
/// Most topics one process reports statistics for.
pub const MAX_TOPIC_STATS: usize = 16;
/// Bytes of a fixed name field (process role, topic name).
pub const NAME_LEN: usize = 32;

/// The header every message starts with.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Pod, Zeroable, ZeroCopySend, Layout)]
#[type_name("mole.Header.v1")]
#[layout(size = 32)]
pub struct Header {
    /// Per-publisher sequence number, starting at 0.
    pub seq: u64,
    /// Simulation step this message belongs to.
    pub tick: u64,
    /// CLOCK_MONOTONIC (ns) when published.
    pub stamp_ns: u64,
    /// `stamp_ns` of the oldest ground-truth sample this message was derived from.
    pub origin_ns: u64,
}

// ---------------------------------------------------------------------------------------------
// world/map
// ---------------------------------------------------------------------------------------------

/// Robot body and motion limits.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Default, Pod, Zeroable, ZeroCopySend, Layout)]
#[type_name("mole.RobotSpec.v1")]
#[layout(size = 40)]
pub struct RobotSpec {
    /// Disk radius r (m).
    pub radius: f64,
    /// |v| limit (m/s).
    pub max_speed: f64,
    /// |ω| limit (rad/s).
    pub max_omega: f64,
    /// |dv/dt| limit (m/s²).
    pub max_accel: f64,
    /// |dω/dt| limit (rad/s²).
    pub max_alpha: f64,
}

impl RobotSpec {
    /// The robot of a scenario that sets none: a 0.2 m disk at up to 0.5 m/s and 2 rad/s.
    pub const SCENARIO_DEFAULT: RobotSpec = RobotSpec {
        radius: 0.2,
        max_speed: 0.5,
        max_omega: 2.0,
        max_accel: 2.0,
        max_alpha: 8.0,
    };
}

/// Sensor parameters and noise, as the world's scenario sets them.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Default, Pod, Zeroable, ZeroCopySend, Layout)]
#[type_name("mole.SensorSpec.v1")]
#[layout(size = 104)]
pub struct SensorSpec {
    /// Lidar beams per scan (0: no lidar, as in the dark room).
    pub lidar_beams: u32,
    /// Tactile sensors around the rim.
    pub tactile_sensors: u32,
    pub lidar_range_max: f64,
    /// Field of view (rad), centred on the heading.
    pub lidar_fov: f64,
    /// Range noise σ (m).
    pub lidar_range_std: f64,
    /// Tactile stiffness (N/m): force = stiffness × penetration.
    pub tactile_stiffness: f64,
    /// Tactile force noise σ (N).
    pub tactile_force_std: f64,
    /// Odometry noise σ on v (m/s) and ω (rad/s).
    pub odom_v_std: f64,
    pub odom_omega_std: f64,
    /// Beacon visibility range (m), range noise σ (m) and bearing noise σ (rad).
    pub beacon_range_max: f64,
    pub beacon_range_std: f64,
    pub beacon_bearing_std: f64,
    /// Position-fix noise σ (m) and period in ticks (0: no fix).
    pub fix_std: f64,
    pub fix_period_ticks: u32,
    /// 1: beacon readings hide the ids (`LANDMARK_ANONYMOUS`), so a SLAM estimator must
    /// associate them itself; 0: each reading names its beacon.
    pub beacons_anonymous: u32,
}

/// `world/map`: everything static about the world, published once with history 1.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable, ZeroCopySend, Message)]
#[type_name("mole.WorldMap.v1")]
#[layout(size = 280 + 24 * MAX_OBSTACLES + 24 * MAX_BEACONS)]
#[message(check = WorldMap::check)]
pub struct WorldMap {
    pub header: Header,
    /// Arena `[0, width] × [0, height]` (m).
    pub arena_width: f64,
    pub arena_height: f64,
    /// Simulation step Δt (s).
    pub dt: f64,
    /// Seed of the run; every process derives its own stream from it.
    pub seed: u64,
    /// Start pose.
    pub start_x: f64,
    pub start_y: f64,
    pub start_theta: f64,
    /// Goal, valid when `has_goal == 1`.
    pub goal_x: f64,
    pub goal_y: f64,
    pub goal_tolerance: f64,
    pub has_goal: u32,
    pub n_obstacles: u32,
    pub n_beacons: u32,
    pub _pad: u32,
    /// Cell size of the mapping grids (m).
    pub grid_resolution: f64,
    pub robot: RobotSpec,
    pub sensors: SensorSpec,
    pub obstacles: [Square; MAX_OBSTACLES],
    pub beacons: [BeaconSite; MAX_BEACONS],
}

impl WorldMap {
    pub fn obstacles(&self) -> &[Square] {
        &self.obstacles[..(self.n_obstacles as usize).min(MAX_OBSTACLES)]
    }
    pub fn beacons(&self) -> &[BeaconSite] {
        &self.beacons[..(self.n_beacons as usize).min(MAX_BEACONS)]
    }

    /// Places beacons at `sites`, ids 0, 1, … in order (at most [`MAX_BEACONS`]); the others
    /// are gone.
    pub fn place_beacons(&mut self, sites: &[(f64, f64)]) {
        let n = sites.len().min(MAX_BEACONS);
        for (id, (slot, &(x, y))) in self.beacons.iter_mut().zip(&sites[..n]).enumerate() {
            *slot = BeaconSite {
                x,
                y,
                id: id as u32,
                _pad: 0,
            };
        }
        self.n_beacons = n as u32;
    }
}

impl WorldMap {
    /// Whether the values make sense (`Message::validate`).
    fn check(&self) -> Result<(), Invalid> {
        within("n_obstacles", self.n_obstacles, MAX_OBSTACLES)?;
        within("n_beacons", self.n_beacons, MAX_BEACONS)?;
        within("sensors.lidar_beams", self.sensors.lidar_beams, MAX_BEAMS)?;
        within(
            "sensors.tactile_sensors",
            self.sensors.tactile_sensors,
            MAX_TACTILE,
        )?;
        if self.has_goal > 1 {
            return Err(Invalid::UnknownCode("has_goal"));
        }
        if self.sensors.beacons_anonymous > 1 {
            return Err(Invalid::UnknownCode("sensors.beacons_anonymous"));
        }
        for (field, v) in [
            ("arena_width", self.arena_width),
            ("arena_height", self.arena_height),
            ("dt", self.dt),
            ("grid_resolution", self.grid_resolution),
            ("robot.radius", self.robot.radius),
        ] {
            finite(field, v)?;
            if v <= 0.0 {
                return Err(Invalid::OutOfRange(field));
            }
        }
        let s = &self.sensors;
        all_finite(
            "start/goal/robot/sensors",
            &[
                self.start_x,
                self.start_y,
                self.start_theta,
                self.goal_x,
                self.goal_y,
                self.goal_tolerance,
                self.robot.max_speed,
                self.robot.max_omega,
                self.robot.max_accel,
                self.robot.max_alpha,
                s.lidar_range_max,
                s.lidar_fov,
                s.lidar_range_std,
                s.tactile_stiffness,
                s.tactile_force_std,
                s.odom_v_std,
                s.odom_omega_std,
                s.beacon_range_max,
                s.beacon_range_std,
                s.beacon_bearing_std,
                s.fix_std,
            ],
        )?;
        for o in self.obstacles() {
            all_finite("obstacles", &[o.cx, o.cy, o.side])?;
            if o.side <= 0.0 {
                return Err(Invalid::OutOfRange("obstacles.side"));
            }
        }
        for b in self.beacons() {
            all_finite("beacons", &[b.x, b.y])?;
        }
        Ok(())
    }
}

// ---------------------------------------------------------------------------------------------
// world/truth
// ---------------------------------------------------------------------------------------------

/// `Truth::flags`: this is the last step of the run.
pub const TRUTH_END: u32 = 1;
/// `Truth::flags`: the robot is within the goal tolerance.
pub const TRUTH_GOAL_REACHED: u32 = 2;
/// `Truth::flags`: the robot touches something.
pub const TRUTH_IN_CONTACT: u32 = 4;
const TRUTH_FLAGS: u32 = TRUTH_END | TRUTH_GOAL_REACHED | TRUTH_IN_CONTACT;

/// `Truth::end_reason` while the run goes on; the codes of its end are [`crate::EndReason`]'s.
pub const END_NONE: u32 = 0;

/// `world/truth`: the true state after step `tick`.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable, ZeroCopySend, Message)]
#[type_name("mole.Truth.v1")]
#[layout(size = 104 + 40 * MAX_CONTACTS)]
#[message(check = Truth::check)]
pub struct Truth {
    pub header: Header,
    pub x: f64,
    pub y: f64,
    pub theta: f64,
    /// Velocities actually applied this step (after limits).
    pub v: f64,
    pub omega: f64,
    /// Deepest overlap of robot and obstacles left after contact resolution (m).
    pub penetration: f64,
    /// Loop latency of the command applied this step: its `origin_ns` to its receipt (ns; 0: none).
    pub cmd_latency_ns: u64,
    pub flags: u32,
    pub end_reason: u32,
    pub n_contacts: u32,
    pub _pad: u32,
    pub contacts: [Contact; MAX_CONTACTS],
}

impl Truth {
    pub fn contacts(&self) -> &[Contact] {
        &self.contacts[..(self.n_contacts as usize).min(MAX_CONTACTS)]
    }
    pub fn is_end(&self) -> bool {
        self.flags & TRUTH_END != 0
    }
}

impl Truth {
    /// Whether the values make sense (`Message::validate`).
    fn check(&self) -> Result<(), Invalid> {
        within("n_contacts", self.n_contacts, MAX_CONTACTS)?;
        if self.flags & !TRUTH_FLAGS != 0 {
            return Err(Invalid::UnknownCode("flags"));
        }
        if self.end_reason != END_NONE && crate::EndReason::from_code(self.end_reason).is_none() {
            return Err(Invalid::UnknownCode("end_reason"));
        }
        all_finite(
            "pose/velocity",
            &[
                self.x,
                self.y,
                self.theta,
                self.v,
                self.omega,
                self.penetration,
            ],
        )?;
        for c in self.contacts() {
            all_finite("contacts", &[c.px, c.py, c.nx, c.ny, c.depth])?;
        }
        Ok(())
    }
}

// ---------------------------------------------------------------------------------------------
// sensing/*
// ---------------------------------------------------------------------------------------------

/// `sensing/scan`: a lidar scan in the robot frame; beam i points at
/// `angle_min + i·angle_increment` relative to the heading. A beam that hits nothing reads
/// `range_max`.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable, ZeroCopySend, Message)]
#[type_name("mole.Scan.v1")]
#[layout(size = 48 + 4 * MAX_BEAMS)]
#[message(check = Scan::check)]
pub struct Scan {
    pub header: Header,
    pub angle_min: f32,
    pub angle_increment: f32,
    pub range_max: f32,
    pub n_beams: u32,
    pub ranges: [f32; MAX_BEAMS],
}

impl Scan {
    pub fn ranges(&self) -> &[f32] {
        &self.ranges[..(self.n_beams as usize).min(MAX_BEAMS)]
    }
}

impl Scan {
    /// Whether the values make sense (`Message::validate`).
    fn check(&self) -> Result<(), Invalid> {
        within("n_beams", self.n_beams, MAX_BEAMS)?;
        all_finite(
            "angle_min/angle_increment/range_max",
            &[self.angle_min, self.angle_increment, self.range_max],
        )?;
        if self.range_max < 0.0 {
            return Err(Invalid::OutOfRange("range_max"));
        }
        if self.ranges().iter().any(|r| !r.is_finite() || *r < 0.0) {
            return Err(Invalid::OutOfRange("ranges"));
        }
        Ok(())
    }
}

/// One tactile sensor's reading.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Default, Pod, Zeroable, ZeroCopySend, Layout)]
#[type_name("mole.TactileReading.v1")]
#[layout(size = 16)]
pub struct TactileReading {
    /// Where the sensor sits on the rim, robot frame (rad from the heading).
    pub angle: f32,
    /// Force the obstacle exerts on the robot at this sensor, robot frame (N).
    pub fx: f32,
    pub fy: f32,
    pub _pad: f32,
}

/// `sensing/tactile`: k force vectors around the rim (algorithms §2.2's f_net).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable, ZeroCopySend, Message)]
#[type_name("mole.Tactile.v1")]
#[layout(size = 40 + 16 * MAX_TACTILE)]
#[message(check = Tactile::check)]
pub struct Tactile {
    pub header: Header,
    pub n_sensors: u32,
    /// Robot radius (m): the sensors sit at `radius·(cos angle, sin angle)`.
    pub radius: f32,
    pub sensors: [TactileReading; MAX_TACTILE],
}

impl Tactile {
    pub fn sensors(&self) -> &[TactileReading] {
        &self.sensors[..(self.n_sensors as usize).min(MAX_TACTILE)]
    }
}

impl Tactile {
    /// Whether the values make sense (`Message::validate`).
    fn check(&self) -> Result<(), Invalid> {
        within("n_sensors", self.n_sensors, MAX_TACTILE)?;
        finite("radius", self.radius as f64)?;
        for s in self.sensors() {
            all_finite("sensors", &[s.angle, s.fx, s.fy])?;
        }
        Ok(())
    }
}

/// `sensing/odom`: wheel odometry. `x, y, theta`: the pose integrated from the wheels since
/// sensing first started, in the odom frame (REP 105: continuous, drifting, its origin where the
/// robot started); `v, omega`: the velocities measured over the last `dt`. A reader that missed
/// steps takes the motion between two odometry poses, which nothing lost.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable, ZeroCopySend, Message)]
#[type_name("mole.Odom.v2")]
#[layout(size = 80)]
#[message(check = Odom::check)]
pub struct Odom {
    pub header: Header,
    pub x: f64,
    pub y: f64,
    pub theta: f64,
    pub v: f64,
    pub omega: f64,
    pub dt: f64,
}

impl Odom {
    /// Whether the values make sense (`Message::validate`).
    fn check(&self) -> Result<(), Invalid> {
        all_finite("x/y/theta", &[self.x, self.y, self.theta])?;
        all_finite("v/omega/dt", &[self.v, self.omega, self.dt])?;
        if self.dt < 0.0 {
            return Err(Invalid::OutOfRange("dt"));
        }
        Ok(())
    }
}

/// One beacon sighting, robot frame.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Default, Pod, Zeroable, ZeroCopySend, Layout)]
#[type_name("mole.BeaconReading.v1")]
#[layout(size = 24)]
pub struct BeaconReading {
    /// The beacon's id in `WorldMap::beacons`.
    pub id: u32,
    pub _pad: u32,
    pub range: f64,
    /// Bearing from the heading (rad).
    pub bearing: f64,
}

/// `sensing/beacons`: range and bearing to every beacon within range.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable, ZeroCopySend, Message)]
#[type_name("mole.Beacons.v1")]
#[layout(size = 40 + 24 * MAX_BEACONS)]
#[message(check = Beacons::check)]
pub struct Beacons {
    pub header: Header,
    pub n_readings: u32,
    pub _pad: u32,
    pub readings: [BeaconReading; MAX_BEACONS],
}

impl Beacons {
    pub fn readings(&self) -> &[BeaconReading] {
        &self.readings[..(self.n_readings as usize).min(MAX_BEACONS)]
    }
}

impl Beacons {
    /// Whether the values make sense (`Message::validate`).
    fn check(&self) -> Result<(), Invalid> {
        within("n_readings", self.n_readings, MAX_BEACONS)?;
        for r in self.readings() {
            all_finite("readings", &[r.range, r.bearing])?;
            if r.range < 0.0 {
                return Err(Invalid::OutOfRange("readings.range"));
            }
            // A beacon's index in the map, or LANDMARK_ANONYMOUS when the scenario hides ids.
            if r.id as usize >= MAX_BEACONS && r.id != LANDMARK_ANONYMOUS {
                return Err(Invalid::OutOfRange("readings.id"));
            }
        }
        Ok(())
    }
}

/// `sensing/fix`: a noisy absolute position (GPS-like), valid when `valid == 1`.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable, ZeroCopySend, Message)]
#[type_name("mole.Fix.v1")]
#[layout(size = 64)]
#[message(check = Fix::check)]
pub struct Fix {
    pub header: Header,
    pub x: f64,
    pub y: f64,
    /// Standard deviation of each coordinate (m).
    pub std: f64,
    pub valid: u32,
    pub _pad: u32,
}

impl Fix {
    /// Whether the values make sense (`Message::validate`).
    fn check(&self) -> Result<(), Invalid> {
        if self.valid > 1 {
            return Err(Invalid::UnknownCode("valid"));
        }
        all_finite("x/y/std", &[self.x, self.y, self.std])?;
        if self.std < 0.0 {
            return Err(Invalid::OutOfRange("std"));
        }
        Ok(())
    }
}

// ---------------------------------------------------------------------------------------------
// localization/*
// ---------------------------------------------------------------------------------------------

/// `localization/pose`: the estimate (μ, Σ) after step `tick`.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable, ZeroCopySend, Message)]
#[type_name("mole.Pose.v2")]
#[layout(size = 168)]
#[message(check = Pose::check)]
pub struct Pose {
    pub header: Header,
    pub x: f64,
    pub y: f64,
    pub theta: f64,
    /// Σ over (x, y, θ), row-major.
    pub covariance: [f64; 9],
    /// The odometry pose (`sensing/odom`'s x, y, θ) of the step this estimate is for: with the
    /// estimate it gives map → odom, and a restarted estimator takes the motion since from it.
    pub odom: [f64; 3],
    /// How long predict + correct took for this step (ns).
    pub update_ns: u64,
    /// Which estimator: an [`crate::EstimatorKind`] code.
    pub estimator: u32,
    pub _pad: u32,
}

impl Pose {
    /// Whether the values make sense (`Message::validate`).
    fn check(&self) -> Result<(), Invalid> {
        if crate::EstimatorKind::from_code(self.estimator).is_none() {
            return Err(Invalid::UnknownCode("estimator"));
        }
        all_finite("x/y/theta", &[self.x, self.y, self.theta])?;
        all_finite("covariance", &self.covariance)?;
        all_finite("odom", &self.odom)?;
        Ok(())
    }
}

/// One weighted particle.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Default, Pod, Zeroable, ZeroCopySend, Layout)]
#[type_name("mole.Particle.v1")]
#[layout(size = 16)]
pub struct Particle {
    pub x: f32,
    pub y: f32,
    pub theta: f32,
    /// Normalised weight w^[j].
    pub w: f32,
}

/// `localization/particles`: the particle set Ψ (algorithms §6.7), when the PF runs.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable, ZeroCopySend, Message)]
#[type_name("mole.Particles.v2")]
#[layout(size = 40 + 16 * MAX_PARTICLES)]
#[message(check = Particles::check)]
pub struct Particles {
    pub header: Header,
    /// Particles in this message.
    pub n_particles: u32,
    /// Particles the filter holds: more than `n_particles` when the message carries an evenly
    /// strided subset of a larger set; it changes over a run with KLD-sampling.
    pub n_filter: u32,
    pub particles: [Particle; MAX_PARTICLES],
}

impl Particles {
    pub fn particles(&self) -> &[Particle] {
        &self.particles[..(self.n_particles as usize).min(MAX_PARTICLES)]
    }
}

impl Particles {
    /// Whether the values make sense (`Message::validate`).
    fn check(&self) -> Result<(), Invalid> {
        within("n_particles", self.n_particles, MAX_PARTICLES)?;
        if self.n_filter < self.n_particles {
            return Err(Invalid::OutOfRange("n_filter"));
        }
        for p in self.particles() {
            all_finite("particles", &[p.x, p.y, p.theta, p.w])?;
        }
        Ok(())
    }
}

/// `Landmark::id` of a landmark created from readings without beacon ids.
pub const LANDMARK_ANONYMOUS: u32 = u32::MAX;

/// One estimated landmark: its mean and 2×2 covariance in the world frame.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Default, Pod, Zeroable, ZeroCopySend, Layout)]
#[type_name("mole.Landmark.v1")]
#[layout(size = 56)]
pub struct Landmark {
    /// The beacon id it was created from, or `LANDMARK_ANONYMOUS`.
    pub id: u32,
    pub _pad: u32,
    pub x: f64,
    pub y: f64,
    /// Σ over (x, y), row-major.
    pub covariance: [f64; 4],
}

/// `localization/landmarks`: a SLAM estimator's map of the beacons (algorithms §6.9) after step
/// `tick`.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable, ZeroCopySend, Message)]
#[type_name("mole.Landmarks.v2")]
#[layout(size = 48 + 56 * MAX_LANDMARKS)]
#[message(check = Landmarks::check)]
pub struct Landmarks {
    pub header: Header,
    pub n_landmarks: u32,
    /// Which estimator: an [`crate::EstimatorKind`] code.
    pub estimator: u32,
    /// The degrees of freedom of the map's mean landmark NEES under the estimator's own joint
    /// covariance (Satterthwaite's, between 2 and 2·n: 2·n when the landmarks' errors are
    /// independent, 2 when they are one error shared); 0 when the estimator does not say.
    pub nees_dof: f64,
    pub landmarks: [Landmark; MAX_LANDMARKS],
}

impl Landmarks {
    pub fn landmarks(&self) -> &[Landmark] {
        &self.landmarks[..(self.n_landmarks as usize).min(MAX_LANDMARKS)]
    }
}

impl Landmarks {
    /// Whether the values make sense (`Message::validate`).
    fn check(&self) -> Result<(), Invalid> {
        within("n_landmarks", self.n_landmarks, MAX_LANDMARKS)?;
        if crate::EstimatorKind::from_code(self.estimator).is_none() {
            return Err(Invalid::UnknownCode("estimator"));
        }
        all_finite("nees_dof", &[self.nees_dof])?;
        if self.nees_dof < 0.0 {
            return Err(Invalid::OutOfRange("nees_dof"));
        }
        for l in self.landmarks() {
            all_finite("landmarks", &[l.x, l.y])?;
            all_finite("landmarks.covariance", &l.covariance)?;
            if l.covariance[0] < 0.0 || l.covariance[3] < 0.0 {
                return Err(Invalid::OutOfRange("landmarks.covariance"));
            }
        }
        Ok(())
    }
}

/// Most poses of a smoothed trajectory (`localization/trajectory`): 200 s at 100 Hz, as many as
/// GraphSLAM's pose graph holds.
pub const MAX_TRAJECTORY_POSES: usize = 20_000;

/// One pose of a smoothed trajectory, in single precision (a few µm over any arena a grid
/// message holds), which halves the message.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Default, Pod, Zeroable, ZeroCopySend, Layout)]
#[type_name("mole.TrajectoryPose.v1")]
#[layout(size = 16)]
pub struct TrajectoryPose {
    /// Steps after `Trajectory::first_tick`: the pose is the state after that step.
    pub tick_offset: u32,
    pub x: f32,
    pub y: f32,
    pub theta: f32,
}

/// `localization/trajectory`: a smoother's optimised trajectory (GraphSLAM, algorithms §6.9.4),
/// published after each finished solve. Pose i estimates the state after step
/// `first_tick + poses[i].tick_offset`; the offsets increase strictly.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable, ZeroCopySend, Message)]
#[type_name("mole.Trajectory.v1")]
#[layout(size = 48 + 16 * MAX_TRAJECTORY_POSES)]
#[message(check = Trajectory::check)]
pub struct Trajectory {
    pub header: Header,
    /// The step the offsets count from.
    pub first_tick: u64,
    pub n_poses: u32,
    /// Which estimator: an [`crate::EstimatorKind`] code.
    pub estimator: u32,
    pub poses: [TrajectoryPose; MAX_TRAJECTORY_POSES],
}

impl Trajectory {
    pub fn poses(&self) -> &[TrajectoryPose] {
        &self.poses[..(self.n_poses as usize).min(MAX_TRAJECTORY_POSES)]
    }
}

impl Trajectory {
    /// Whether the values make sense (`Message::validate`).
    fn check(&self) -> Result<(), Invalid> {
        within("n_poses", self.n_poses, MAX_TRAJECTORY_POSES)?;
        if crate::EstimatorKind::from_code(self.estimator).is_none() {
            return Err(Invalid::UnknownCode("estimator"));
        }
        let mut previous = None;
        for p in self.poses() {
            all_finite("poses", &[p.x, p.y, p.theta])?;
            if previous.is_some_and(|offset| p.tick_offset <= offset) {
                return Err(Invalid::OutOfRange("poses.tick_offset"));
            }
            previous = Some(p.tick_offset);
        }
        if let Some(last) = previous
            && self.first_tick.checked_add(u64::from(last)).is_none()
        {
            return Err(Invalid::OutOfRange("first_tick"));
        }
        Ok(())
    }
}

// ---------------------------------------------------------------------------------------------
// mapping/*
// ---------------------------------------------------------------------------------------------

/// `Grid::kind`: the frontier grid, cells 0 unexplored, 1 free, 2 occupied (algorithms §5.2).
pub const GRID_FRONTIER: u32 = 0;
/// `Grid::kind`: the contact grid, cells 0 free/unknown, 1 occupied (algorithms §2.2).
pub const GRID_CONTACT: u32 = 1;

/// Frontier-grid cell values (algorithms §5.2).
pub const CELL_UNEXPLORED: u8 = 0;
pub const CELL_FREE: u8 = 1;
pub const CELL_OCCUPIED: u8 = 2;

/// `mapping/grid` and `mapping/contact`: a row-major grid; cell (col, row) covers
/// `[origin_x + col·res, origin_x + (col+1)·res) × [origin_y + row·res, …)`.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable, ZeroCopySend, Message)]
#[type_name("mole.Grid.v1")]
#[layout(size = 72 + MAX_GRID_CELLS)]
#[message(check = Grid::check)]
pub struct Grid {
    pub header: Header,
    pub width: u32,
    pub height: u32,
    pub resolution: f64,
    pub origin_x: f64,
    pub origin_y: f64,
    pub kind: u32,
    pub _pad: u32,
    pub cells: [u8; MAX_GRID_CELLS],
}

impl Grid {
    /// The cells in use, `width × height`, row-major.
    pub fn cells(&self) -> &[u8] {
        &self.cells[..((self.width as usize) * (self.height as usize)).min(MAX_GRID_CELLS)]
    }
}

impl Grid {
    /// Whether the values make sense (`Message::validate`).
    fn check(&self) -> Result<(), Invalid> {
        if (self.width as u64) * (self.height as u64) > MAX_GRID_CELLS as u64 {
            return Err(Invalid::CountAboveCapacity("width×height"));
        }
        let max_cell = match self.kind {
            GRID_FRONTIER => CELL_OCCUPIED,
            GRID_CONTACT => 1,
            _ => return Err(Invalid::UnknownCode("kind")),
        };
        all_finite(
            "resolution/origin",
            &[self.resolution, self.origin_x, self.origin_y],
        )?;
        if self.resolution <= 0.0 {
            return Err(Invalid::OutOfRange("resolution"));
        }
        // A max over every cell (no early exit) vectorises; grids are checked every step.
        if self.cells().iter().fold(0u8, |m, &c| m.max(c)) > max_cell {
            return Err(Invalid::UnknownCode("cells"));
        }
        Ok(())
    }
}

// ---------------------------------------------------------------------------------------------
// planning/*
// ---------------------------------------------------------------------------------------------

/// Planner mode codes (`Cmd::mode`, `PlanStatus::mode`).
pub const MODE_IDLE: u32 = 0;
pub const MODE_EXPLORE: u32 = 1;
pub const MODE_BOUNCE_BACK: u32 = 2;
pub const MODE_GOAL: u32 = 3;
pub const MODE_STALLED: u32 = 4;
pub const MODE_ESCAPE: u32 = 5;
/// Exploration is complete: no reachable frontier is worth its cost (algorithms §5).
pub const MODE_DONE: u32 = 6;
/// A goal-seeking planner (apf, dwa) has its estimated pose within the goal tolerance.
pub const MODE_ARRIVED: u32 = 7;
const MODE_LAST: u32 = MODE_ARRIVED;

/// `planning/cmd`: the velocity command (v, ω) for the next step.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable, ZeroCopySend, Message)]
#[type_name("mole.Cmd.v1")]
#[layout(size = 56)]
#[message(check = Cmd::check)]
pub struct Cmd {
    pub header: Header,
    pub v: f64,
    pub omega: f64,
    pub mode: u32,
    pub _pad: u32,
}

impl Cmd {
    /// Whether the values make sense (`Message::validate`).
    fn check(&self) -> Result<(), Invalid> {
        if self.mode > MODE_LAST {
            return Err(Invalid::UnknownCode("mode"));
        }
        all_finite("v/omega", &[self.v, self.omega])
    }
}

/// `PlanStatus::flags`: a goal is set.
pub const STATUS_HAS_GOAL: u32 = 1;
/// `PlanStatus::flags`: a frontier is chosen.
pub const STATUS_HAS_FRONTIER: u32 = 2;
/// `PlanStatus::flags`: no reachable frontier is left.
pub const STATUS_EXPLORATION_COMPLETE: u32 = 4;
const STATUS_FLAGS: u32 = STATUS_HAS_GOAL | STATUS_HAS_FRONTIER | STATUS_EXPLORATION_COMPLETE;

/// `planning/status`: what the planner is doing and why.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable, ZeroCopySend, Message)]
#[type_name("mole.PlanStatus.v2")]
#[layout(size = 88 + 8 * MAX_PATH)]
#[message(check = PlanStatus::check)]
pub struct PlanStatus {
    pub header: Header,
    pub mode: u32,
    pub flags: u32,
    pub goal_x: f64,
    pub goal_y: f64,
    pub frontier_x: f64,
    pub frontier_y: f64,
    /// Bounce-backs triggered so far.
    pub bounces: u32,
    /// Frontier targets given up so far: not approached in time or unreachable.
    pub give_ups: u32,
    pub n_path: u32,
    pub _pad: u32,
    /// Waypoints (m), world frame.
    pub path: [[f32; 2]; MAX_PATH],
}

impl PlanStatus {
    pub fn path(&self) -> &[[f32; 2]] {
        &self.path[..(self.n_path as usize).min(MAX_PATH)]
    }
}

impl PlanStatus {
    /// Whether the values make sense (`Message::validate`).
    fn check(&self) -> Result<(), Invalid> {
        if self.mode > MODE_LAST {
            return Err(Invalid::UnknownCode("mode"));
        }
        if self.flags & !STATUS_FLAGS != 0 {
            return Err(Invalid::UnknownCode("flags"));
        }
        within("n_path", self.n_path, MAX_PATH)?;
        all_finite(
            "goal/frontier",
            &[self.goal_x, self.goal_y, self.frontier_x, self.frontier_y],
        )?;
        for p in self.path() {
            all_finite("path", p)?;
        }
        Ok(())
    }
}

// ---------------------------------------------------------------------------------------------
// operator/*
// ---------------------------------------------------------------------------------------------

/// `operator/goal`: where an operator (the view) wants a goal-seeking planner to go.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable, ZeroCopySend, Message)]
#[type_name("mole.Goal.v1")]
#[layout(size = 56)]
#[message(check = Goal::check)]
pub struct Goal {
    pub header: Header,
    /// Goal position (m), world frame.
    pub x: f64,
    pub y: f64,
    /// How close counts as reached (m); 0 keeps the planner's current tolerance.
    pub tolerance: f64,
}

impl Goal {
    /// Whether the values make sense (`Message::validate`).
    fn check(&self) -> Result<(), Invalid> {
        all_finite("x/y/tolerance", &[self.x, self.y, self.tolerance])?;
        if self.tolerance < 0.0 {
            return Err(Invalid::OutOfRange("tolerance"));
        }
        Ok(())
    }
}

/// `Pace::op`: run freely.
pub const PACE_RUN: u32 = 1;
/// `Pace::op`: hold the world before its next step.
pub const PACE_PAUSE: u32 = 2;
/// `Pace::op`: take `steps` more steps, then hold.
pub const PACE_STEP: u32 = 3;
/// Most steps one `PACE_STEP` may ask for.
pub const PACE_MAX_STEPS: u32 = 100_000;

/// `operator/pace`: pause, resume or single-step a lockstep run.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable, ZeroCopySend, Message)]
#[type_name("mole.Pace.v1")]
#[layout(size = 40)]
#[message(check = Pace::check)]
pub struct Pace {
    pub header: Header,
    /// PACE_RUN, PACE_PAUSE or PACE_STEP.
    pub op: u32,
    /// With PACE_STEP: how many steps (1..=PACE_MAX_STEPS); otherwise 0.
    pub steps: u32,
}

impl Pace {
    /// Whether the values make sense (`Message::validate`).
    fn check(&self) -> Result<(), Invalid> {
        match self.op {
            PACE_RUN | PACE_PAUSE if self.steps == 0 => Ok(()),
            PACE_RUN | PACE_PAUSE => Err(Invalid::OutOfRange("steps")),
            PACE_STEP if (1..=PACE_MAX_STEPS).contains(&self.steps) => Ok(()),
            PACE_STEP => Err(Invalid::OutOfRange("steps")),
            _ => Err(Invalid::UnknownCode("op")),
        }
    }
}

// ---------------------------------------------------------------------------------------------
// stack/*
// ---------------------------------------------------------------------------------------------

/// `Tick::flags`: the run ends after this step.
pub const TICK_END: u32 = 1;

/// `stack/tick`: the world's clock; step `header.tick` starts now.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable, ZeroCopySend, Message)]
#[type_name("mole.Tick.v1")]
#[layout(size = 48)]
#[message(check = Tick::check)]
pub struct Tick {
    pub header: Header,
    pub dt: f64,
    pub flags: u32,
    /// The clock mode: a [`crate::ClockMode`] code.
    pub mode: u32,
}

impl Tick {
    /// Whether the values make sense (`Message::validate`).
    fn check(&self) -> Result<(), Invalid> {
        if self.flags & !TICK_END != 0 {
            return Err(Invalid::UnknownCode("flags"));
        }
        if crate::ClockMode::from_code(self.mode).is_none() {
            return Err(Invalid::UnknownCode("mode"));
        }
        finite("dt", self.dt)
    }
}

/// `TopicStats::direction`.
pub const DIRECTION_SUBSCRIBE: u32 = 0;
pub const DIRECTION_PUBLISH: u32 = 1;

/// One port's counters over the process's lifetime, and its rate and latency over the last window.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Default, Pod, Zeroable, ZeroCopySend, Layout)]
#[type_name("mole.TopicStats.v1")]
#[layout(size = 80)]
pub struct TopicStats {
    /// Topic name without the namespace, NUL-padded, e.g. `sensing/scan`.
    pub topic: [u8; NAME_LEN],
    pub direction: u32,
    pub _pad: u32,
    /// Messages sent or received (valid ones) so far.
    pub count: u64,
    /// Messages lost: sequence gaps seen by a subscriber, failed sends for a publisher.
    pub dropped: u64,
    /// Messages refused by `validate()`.
    pub invalid: u64,
    /// Messages per second over the last window.
    pub rate_hz: f32,
    /// Latency from `origin_ns` to receipt over the last window (µs; subscribers only).
    pub latency_p50_us: f32,
    pub latency_p99_us: f32,
    pub latency_max_us: f32,
}

/// `stack/stats`: one process's statistics, once a second.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable, ZeroCopySend, Message)]
#[type_name("mole.Stats.v2")]
#[layout(size = 112 + 80 * MAX_TOPIC_STATS)]
#[message(check = Stats::check)]
pub struct Stats {
    pub header: Header,
    /// Role name, NUL-padded, e.g. `sensing`.
    pub process: [u8; NAME_LEN],
    pub pid: u32,
    pub n_topics: u32,
    /// User + system CPU time of the process so far (ns).
    pub cpu_ns: u64,
    /// Peak resident set size (bytes).
    pub max_rss_bytes: u64,
    /// Steps the process has handled.
    pub steps: u64,
    /// CPU time (user + system) of this process's own step function so far: its algorithm and
    /// the publishes it makes (ns); `cpu_ns` less this is the runtime around the steps.
    pub step_cpu_ns: u64,
    /// System (kernel) CPU time of the process so far, part of `cpu_ns` (ns).
    pub system_ns: u64,
    pub topics: [TopicStats; MAX_TOPIC_STATS],
}

impl Stats {
    pub fn topics(&self) -> &[TopicStats] {
        &self.topics[..(self.n_topics as usize).min(MAX_TOPIC_STATS)]
    }
}

impl Stats {
    /// Whether the values make sense (`Message::validate`).
    fn check(&self) -> Result<(), Invalid> {
        within("n_topics", self.n_topics, MAX_TOPIC_STATS)?;
        for t in self.topics() {
            if t.direction > DIRECTION_PUBLISH {
                return Err(Invalid::UnknownCode("topics.direction"));
            }
            all_finite(
                "topics.rate/latency",
                &[
                    t.rate_hz,
                    t.latency_p50_us,
                    t.latency_p99_us,
                    t.latency_max_us,
                ],
            )?;
        }
        Ok(())
    }
}

/// Most processes the launcher reports on `stack/processes`.
pub const MAX_PROCESSES: usize = 16;

/// `ProcessStatus::state` codes.
pub const PROCESS_STARTING: u32 = 0;
pub const PROCESS_RUNNING: u32 = 1;
pub const PROCESS_RESTARTING: u32 = 2;
pub const PROCESS_EXITED: u32 = 3;
pub const PROCESS_FAILED: u32 = 4;

/// One supervised process, as the launcher sees it.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Default, Pod, Zeroable, ZeroCopySend, Layout)]
#[type_name("mole.ProcessStatus.v1")]
#[layout(size = 48)]
pub struct ProcessStatus {
    /// Role name, NUL-padded.
    pub role: [u8; NAME_LEN],
    pub pid: u32,
    pub state: u32,
    pub restarts: u32,
    pub _pad: u32,
}

/// `stack/processes`: the launcher's view of every process, once a second.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable, ZeroCopySend, Message)]
#[type_name("mole.Processes.v1")]
#[layout(size = 40 + 48 * MAX_PROCESSES)]
#[message(check = Processes::check)]
pub struct Processes {
    pub header: Header,
    pub n_processes: u32,
    pub _pad: u32,
    pub processes: [ProcessStatus; MAX_PROCESSES],
}

impl Processes {
    pub fn processes(&self) -> &[ProcessStatus] {
        &self.processes[..(self.n_processes as usize).min(MAX_PROCESSES)]
    }
}

impl Processes {
    /// Whether the values make sense (`Message::validate`).
    fn check(&self) -> Result<(), Invalid> {
        within("n_processes", self.n_processes, MAX_PROCESSES)?;
        if self.processes().iter().any(|p| p.state > PROCESS_FAILED) {
            return Err(Invalid::UnknownCode("processes.state"));
        }
        Ok(())
    }
}

/// `monitor/status`: the monitor's live view of the run, for progress bars and `mole top`.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable, ZeroCopySend, Message)]
#[type_name("mole.RunStatus.v1")]
#[layout(size = 56)]
#[message(check = RunStatus::check)]
pub struct RunStatus {
    pub header: Header,
    /// Coverage of the reachable free area (0..1).
    pub coverage: f32,
    /// Loop latency over the run so far (µs).
    pub loop_p50_us: f32,
    pub loop_p99_us: f32,
    pub max_penetration_m: f32,
    pub rmse_m: f32,
    /// 1 once the monitor has written summary.json and map.png.
    pub finished: u32,
}

impl RunStatus {
    /// Whether the values make sense (`Message::validate`).
    fn check(&self) -> Result<(), Invalid> {
        if self.finished > 1 {
            return Err(Invalid::UnknownCode("finished"));
        }
        all_finite(
            "coverage/latency/penetration/rmse",
            &[
                self.coverage,
                self.loop_p50_us,
                self.loop_p99_us,
                self.max_penetration_m,
                self.rmse_m,
            ],
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn zeroed_messages_are_valid() {
        let mut map: Box<WorldMap> = bytemuck::zeroed_box();
        map.arena_width = 10.0;
        map.arena_height = 10.0;
        map.dt = 0.01;
        map.grid_resolution = 0.05;
        map.robot.radius = 0.2;
        assert_eq!(map.validate(), Ok(()));
        assert_eq!(bytemuck::zeroed_box::<Truth>().validate(), Ok(()));
        assert_eq!(bytemuck::zeroed_box::<Scan>().validate(), Ok(()));
        assert_eq!(bytemuck::zeroed_box::<Tactile>().validate(), Ok(()));
        assert_eq!(bytemuck::zeroed_box::<Odom>().validate(), Ok(()));
        assert_eq!(bytemuck::zeroed_box::<Beacons>().validate(), Ok(()));
        assert_eq!(bytemuck::zeroed_box::<Fix>().validate(), Ok(()));
        assert_eq!(bytemuck::zeroed_box::<Pose>().validate(), Ok(()));
        assert_eq!(bytemuck::zeroed_box::<Particles>().validate(), Ok(()));
        assert_eq!(bytemuck::zeroed_box::<Landmarks>().validate(), Ok(()));
        assert_eq!(bytemuck::zeroed_box::<Trajectory>().validate(), Ok(()));
        assert_eq!(bytemuck::zeroed_box::<Cmd>().validate(), Ok(()));
        assert_eq!(bytemuck::zeroed_box::<PlanStatus>().validate(), Ok(()));
        assert_eq!(bytemuck::zeroed_box::<Tick>().validate(), Ok(()));
        assert_eq!(bytemuck::zeroed_box::<Stats>().validate(), Ok(()));
        assert_eq!(bytemuck::zeroed_box::<RunStatus>().validate(), Ok(()));
        assert_eq!(bytemuck::zeroed_box::<Goal>().validate(), Ok(()));
        // A zeroed pace has op 0, which is no operation.
        assert_eq!(
            bytemuck::zeroed_box::<Pace>().validate(),
            Err(Invalid::UnknownCode("op"))
        );
        // A zeroed grid has resolution 0, which is out of range.
        assert_eq!(
            bytemuck::zeroed_box::<Grid>().validate(),
            Err(Invalid::OutOfRange("resolution"))
        );
    }

    /// A trajectory's poses go forward in time, one per step, and end at a tick that exists.
    #[test]
    fn a_trajectory_moves_forward_from_its_first_tick() {
        let mut path: Box<Trajectory> = bytemuck::zeroed_box();
        path.estimator = crate::EstimatorKind::GraphSlam.code();
        path.n_poses = 3;
        for (i, offset) in [0, 1, 3].into_iter().enumerate() {
            path.poses[i].tick_offset = offset;
        }
        assert_eq!(path.validate(), Ok(()));
        path.poses[2].tick_offset = 1;
        assert_eq!(
            path.validate(),
            Err(Invalid::OutOfRange("poses.tick_offset")),
            "a step twice"
        );
        path.poses[2].tick_offset = 3;
        path.first_tick = u64::MAX - 2;
        assert_eq!(path.validate(), Err(Invalid::OutOfRange("first_tick")));
        path.first_tick = 10;
        path.poses[1].y = f32::NAN;
        assert_eq!(path.validate(), Err(Invalid::NotFinite("poses")));
        path.n_poses = MAX_TRAJECTORY_POSES as u32 + 1;
        assert_eq!(path.validate(), Err(Invalid::CountAboveCapacity("n_poses")));
    }

    #[test]
    fn a_beacon_reading_names_a_beacon_of_the_map_or_none() {
        let mut beacons: Box<Beacons> = bytemuck::zeroed_box();
        beacons.n_readings = 1;
        beacons.readings[0].id = LANDMARK_ANONYMOUS;
        assert_eq!(beacons.validate(), Ok(()), "an anonymous reading");
        beacons.readings[0].id = MAX_BEACONS as u32;
        assert_eq!(beacons.validate(), Err(Invalid::OutOfRange("readings.id")));
    }

    #[test]
    fn out_of_range_values_are_refused() {
        let mut cmd: Cmd = bytemuck::Zeroable::zeroed();
        cmd.v = f64::NAN;
        assert_eq!(cmd.validate(), Err(Invalid::NotFinite("v/omega")));
        cmd.v = 0.0;
        cmd.mode = 99;
        assert_eq!(cmd.validate(), Err(Invalid::UnknownCode("mode")));

        let mut scan: Box<Scan> = bytemuck::zeroed_box();
        scan.n_beams = MAX_BEAMS as u32 + 1;
        assert_eq!(scan.validate(), Err(Invalid::CountAboveCapacity("n_beams")));
        scan.n_beams = 2;
        scan.ranges[1] = f32::INFINITY;
        assert_eq!(scan.validate(), Err(Invalid::OutOfRange("ranges")));

        let mut grid: Box<Grid> = bytemuck::zeroed_box();
        grid.resolution = 0.1;
        grid.width = 2;
        grid.height = 2;
        grid.cells[3] = 3;
        assert_eq!(grid.validate(), Err(Invalid::UnknownCode("cells")));
        grid.cells[3] = 2;
        assert_eq!(grid.validate(), Ok(()));
        grid.kind = GRID_CONTACT;
        assert_eq!(grid.validate(), Err(Invalid::UnknownCode("cells")));
        grid.width = 1024;
        grid.height = 1024;
        assert_eq!(
            grid.validate(),
            Err(Invalid::CountAboveCapacity("width×height"))
        );

        let mut truth: Truth = bytemuck::Zeroable::zeroed();
        truth.flags = 8;
        assert_eq!(truth.validate(), Err(Invalid::UnknownCode("flags")));
    }

    /// An operator's goal is a finite point with a tolerance of zero or more; a pace names a
    /// known operation, and only a step carries a count, within its range.
    #[test]
    fn operator_messages_refuse_what_makes_no_sense() {
        let mut goal: Goal = bytemuck::Zeroable::zeroed();
        (goal.x, goal.y, goal.tolerance) = (3.0, 4.0, 0.25);
        assert_eq!(goal.validate(), Ok(()));
        goal.tolerance = -0.1;
        assert_eq!(goal.validate(), Err(Invalid::OutOfRange("tolerance")));
        goal.tolerance = 0.0;
        goal.y = f64::INFINITY;
        assert_eq!(goal.validate(), Err(Invalid::NotFinite("x/y/tolerance")));

        let pace = |op, steps| Pace {
            header: Header::default(),
            op,
            steps,
        };
        assert_eq!(pace(PACE_RUN, 0).validate(), Ok(()));
        assert_eq!(pace(PACE_PAUSE, 0).validate(), Ok(()));
        assert_eq!(pace(PACE_STEP, 1).validate(), Ok(()));
        assert_eq!(pace(PACE_STEP, PACE_MAX_STEPS).validate(), Ok(()));
        assert_eq!(
            pace(PACE_STEP, 0).validate(),
            Err(Invalid::OutOfRange("steps"))
        );
        assert_eq!(
            pace(PACE_STEP, PACE_MAX_STEPS + 1).validate(),
            Err(Invalid::OutOfRange("steps"))
        );
        assert_eq!(
            pace(PACE_PAUSE, 5).validate(),
            Err(Invalid::OutOfRange("steps"))
        );
        assert_eq!(pace(4, 0).validate(), Err(Invalid::UnknownCode("op")));
    }

    #[test]
    fn random_bytes_never_panic_validation() {
        // Every bit pattern is a valid value; validate() must answer, never panic.
        let mut state = 0x9E37_79B9_7F4A_7C15_u64;
        let mut fill = |bytes: &mut [u8]| {
            for b in bytes.iter_mut() {
                state ^= state << 13;
                state ^= state >> 7;
                state ^= state << 17;
                *b = state as u8;
            }
        };
        for _ in 0..20 {
            let mut grid: Box<Grid> = bytemuck::zeroed_box();
            fill(bytemuck::bytes_of_mut(&mut *grid));
            let _ = grid.validate();
            let mut map: Box<WorldMap> = bytemuck::zeroed_box();
            fill(bytemuck::bytes_of_mut(&mut *map));
            let _ = map.validate();
            let _ = map.obstacles().len();
            let mut scan: Box<Scan> = bytemuck::zeroed_box();
            fill(bytemuck::bytes_of_mut(&mut *scan));
            let _ = scan.validate();
            let _ = scan.ranges().len();
        }
    }
}
