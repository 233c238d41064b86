//! Sensing: lidar ray casting, tactile forces, odometry, beacons, position fix.
//!
//! [`Sensing`] turns the world's ground truth into what the robot's sensors would report, filling
//! loaned messages in place (never their `header`: the caller stamps it). Each sensor draws its
//! noise from its own ChaCha stream, so one sensor's output does not depend on whether or in
//! which order the others were called. [`RayCaster`] is the noise-free lidar, reusable by the
//! monitor and the planners.

pub mod raycast;
pub mod tactile;

pub use raycast::RayCaster;
pub use tactile::{sensor_angle, split_between_sensors};

use core::f64::consts::TAU;
use mole_types::{
    BeaconReading, BeaconSite, Beacons, Fix, Invalid, LANDMARK_ANONYMOUS, MAX_BEACONS, MAX_BEAMS,
    MAX_TACTILE, Message, Odom, Pose2, Scan, SensorSpec, Tactile, TactileReading, Truth, WorldMap,
    arc_between, unicycle_arc, wrap_angle,
};
use rand::RngExt;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

/// Why a [`Sensing`] or [`RayCaster`] could not be built.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SensingError {
    /// The map failed `WorldMap::validate()`.
    #[error("world map is invalid: {0}")]
    InvalidMap(#[from] Invalid),
    /// A parameter is outside its physical range (a negative σ, a non-positive field of view...).
    #[error("`{field}` is out of range: {value}")]
    OutOfRange {
        /// The map field, e.g. `sensors.lidar_range_std`.
        field: &'static str,
        /// The offending value (NaN when the field is not a number).
        value: f64,
    },
}

/// Mixed into the run's seed so that sensing's streams differ from other processes' streams
/// derived from the same seed.
const SENSING_SEED_SALT: u64 = 0x5E45_1A6C_0DE5_7A7E;
/// ChaCha stream ids, one per sensor.
const STREAM_LIDAR: u64 = 1;
const STREAM_TACTILE: u64 = 2;
const STREAM_ODOM: u64 = 3;
const STREAM_BEACONS: u64 = 4;
const STREAM_FIX: u64 = 5;
/// A field of view within this of 2π is a full circle (no duplicated beam at ±π).
const FULL_CIRCLE_TOL: f64 = 1e-6;

/// The independent noise stream of one sensor.
fn stream(seed: u64, id: u64) -> ChaCha8Rng {
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ SENSING_SEED_SALT);
    rng.set_stream(id);
    rng
}

/// One zero-mean Gaussian sample of standard deviation `sigma`.
#[inline]
fn gauss(rng: &mut ChaCha8Rng, sigma: f64) -> f64 {
    let z: f64 = rng.sample(StandardNormal);
    sigma * z
}

/// Lidar beam layout, fixed at start-up.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BeamLayout {
    /// Beams per scan.
    pub n_beams: usize,
    /// First beam, relative to the heading (rad).
    pub angle_min: f64,
    /// Angle between consecutive beams (rad).
    pub angle_increment: f64,
    /// Longest reading (m).
    pub range_max: f64,
}

impl BeamLayout {
    /// `n_beams` evenly over `fov` centred on the heading: a full circle spaces them `fov/n`
    /// (no beam twice at ±π), a partial fov `fov/(n-1)` so the end beams sit on its edges; a
    /// single beam of a partial fov looks straight ahead (deviation: `fov/(n-1)` is undefined).
    pub fn new(n_beams: usize, fov: f64, range_max: f64) -> Self {
        let fov = fov.min(TAU);
        let full = fov >= TAU - FULL_CIRCLE_TOL;
        let (angle_min, angle_increment) = match n_beams {
            _ if full => (-fov / 2.0, fov / n_beams.max(1) as f64),
            0 | 1 => (0.0, 0.0),
            n => (-fov / 2.0, fov / (n - 1) as f64),
        };
        Self {
            n_beams,
            angle_min,
            angle_increment,
            range_max,
        }
    }

    /// Direction of beam `i` relative to the heading (rad).
    #[inline]
    pub fn angle(&self, i: usize) -> f64 {
        self.angle_min + i as f64 * self.angle_increment
    }
}

/// All the robot's sensors over one world, with their noise streams and buffers.
#[derive(Debug, Clone)]
pub struct Sensing {
    caster: RayCaster,
    spec: SensorSpec,
    dt: f64,
    radius: f64,
    beams: BeamLayout,
    n_tactile: usize,
    beacons: Vec<BeaconSite>,
    rng_lidar: ChaCha8Rng,
    rng_tactile: ChaCha8Rng,
    rng_odom: ChaCha8Rng,
    rng_beacons: ChaCha8Rng,
    rng_fix: ChaCha8Rng,
    /// Per-sensor force accumulator (robot frame, N) and whether the sensor carries a contact.
    force: [[f64; 2]; MAX_TACTILE],
    loaded: [bool; MAX_TACTILE],
    /// The odometry pose (odom frame), and the tick and true pose of the last step odometry saw.
    odom_pose: Pose2,
    odom_seen: Option<(u64, Pose2)>,
    /// The tick of the odometry resumed (a restart), until the first step.
    odom_resumed: Option<u64>,
}

impl Sensing {
    /// Copies what it needs from the map (obstacles into the ray caster's broad phase, beacons,
    /// sensor parameters); `seed` is the run's seed, from which each sensor gets its own ChaCha
    /// stream. Errors if the map fails `validate()` or a sensor parameter is out of range
    /// (negative σ, range or stiffness; a non-positive field of view with beams).
    pub fn new(map: &WorldMap, seed: u64) -> Result<Sensing, SensingError> {
        map.validate()?;
        let s = map.sensors;
        for (field, value) in [
            ("sensors.lidar_range_max", s.lidar_range_max),
            ("sensors.lidar_range_std", s.lidar_range_std),
            ("sensors.tactile_stiffness", s.tactile_stiffness),
            ("sensors.tactile_force_std", s.tactile_force_std),
            ("sensors.odom_v_std", s.odom_v_std),
            ("sensors.odom_omega_std", s.odom_omega_std),
            ("sensors.beacon_range_max", s.beacon_range_max),
            ("sensors.beacon_range_std", s.beacon_range_std),
            ("sensors.beacon_bearing_std", s.beacon_bearing_std),
            ("sensors.fix_std", s.fix_std),
        ] {
            if value < 0.0 {
                return Err(SensingError::OutOfRange { field, value });
            }
        }
        if s.lidar_beams > 0 && s.lidar_fov <= 0.0 {
            return Err(SensingError::OutOfRange {
                field: "sensors.lidar_fov",
                value: s.lidar_fov,
            });
        }
        let n_beams = (s.lidar_beams as usize).min(MAX_BEAMS);
        Ok(Sensing {
            caster: RayCaster::from_map(map)?,
            spec: s,
            dt: map.dt,
            radius: map.robot.radius,
            beams: BeamLayout::new(n_beams, s.lidar_fov, s.lidar_range_max),
            n_tactile: (s.tactile_sensors as usize).min(MAX_TACTILE),
            beacons: map.beacons().to_vec(),
            rng_lidar: stream(seed, STREAM_LIDAR),
            rng_tactile: stream(seed, STREAM_TACTILE),
            rng_odom: stream(seed, STREAM_ODOM),
            rng_beacons: stream(seed, STREAM_BEACONS),
            rng_fix: stream(seed, STREAM_FIX),
            force: [[0.0; 2]; MAX_TACTILE],
            loaded: [false; MAX_TACTILE],
            odom_pose: Pose2::default(),
            odom_seen: None,
            odom_resumed: None,
        })
    }

    /// The noise-free ray caster over this world.
    pub fn ray_caster(&self) -> &RayCaster {
        &self.caster
    }

    /// The sensor parameters copied from the map.
    pub fn spec(&self) -> &SensorSpec {
        &self.spec
    }

    /// The lidar beam layout.
    pub fn beam_layout(&self) -> &BeamLayout {
        &self.beams
    }

    /// Lidar: `lidar_beams` beams over `lidar_fov` centred on the heading ([`BeamLayout`]); each
    /// range is the distance from the robot CENTRE to the first wall or square, plus Gaussian
    /// noise σ = `lidar_range_std`, clamped to `[0, range_max]`; a beam that hits nothing within
    /// `range_max` reads exactly `range_max`. Ranges past `n_beams` are zeroed.
    pub fn scan(&mut self, truth: &Truth, out: &mut Scan) {
        let b = self.beams;
        out.angle_min = b.angle_min as f32;
        out.angle_increment = b.angle_increment as f32;
        out.range_max = b.range_max as f32;
        out.n_beams = b.n_beams as u32;
        let sigma = self.spec.lidar_range_std;
        for (i, r) in out.ranges[..b.n_beams].iter_mut().enumerate() {
            let true_range =
                self.caster
                    .cast(truth.x, truth.y, truth.theta + b.angle(i), b.range_max);
            // One draw per beam, hit or not, so the stream advances the same every scan.
            let noise = gauss(&mut self.rng_lidar, sigma);
            let range = if true_range < b.range_max {
                (true_range + noise).clamp(0.0, b.range_max)
            } else {
                b.range_max
            };
            *r = range as f32;
        }
        out.ranges[b.n_beams..].fill(0.0);
    }

    /// Tactile: k sensors around the rim, sensor i at 2πi/k (robot frame). Each contact's force,
    /// `tactile_stiffness × depth` along its normal (obstacle → robot), rotated into the robot
    /// frame, is shared between the two sensors nearest its direction
    /// ([`split_between_sensors`]); every component of a sensor that carries force gets Gaussian
    /// noise σ = `tactile_force_std`, and a sensor with no contact reads exactly 0.
    pub fn tactile(&mut self, truth: &Truth, out: &mut Tactile) {
        let k = self.n_tactile;
        self.force = [[0.0; 2]; MAX_TACTILE];
        self.loaded = [false; MAX_TACTILE];
        let (sin_t, cos_t) = truth.theta.sin_cos();
        for c in truth.contacts() {
            if k == 0 {
                break;
            }
            let depth = c.depth.max(0.0);
            let n_len = c.nx.hypot(c.ny);
            if !(n_len > 0.0 && n_len.is_finite() && depth.is_finite()) {
                continue;
            }
            let magnitude = self.spec.tactile_stiffness * depth;
            if magnitude <= 0.0 {
                continue;
            }
            let (fx, fy) = (magnitude * c.nx / n_len, magnitude * c.ny / n_len);
            // World → robot frame: rotate by −θ.
            let (fx_r, fy_r) = (cos_t * fx + sin_t * fy, -sin_t * fx + cos_t * fy);
            // Direction of the contact from the centre; on a degenerate point, the obstacle lies
            // against the normal.
            let (rx, ry) = (c.px - truth.x, c.py - truth.y);
            let world_dir = if rx.hypot(ry) > 1e-12 {
                ry.atan2(rx)
            } else {
                (-c.ny).atan2(-c.nx)
            };
            for (i, w) in split_between_sensors(world_dir - truth.theta, k) {
                if w > 0.0 {
                    self.force[i][0] += w * fx_r;
                    self.force[i][1] += w * fy_r;
                    self.loaded[i] = true;
                }
            }
        }
        out.n_sensors = k as u32;
        out.radius = self.radius as f32;
        let sigma = self.spec.tactile_force_std;
        for (i, s) in out.sensors.iter_mut().enumerate() {
            if i >= k {
                *s = TactileReading::default();
                continue;
            }
            // Two draws per sensor, loaded or not, so the stream advances the same every step.
            let (nx, ny) = (
                gauss(&mut self.rng_tactile, sigma),
                gauss(&mut self.rng_tactile, sigma),
            );
            let [fx, fy] = self.force[i];
            let (fx, fy) = if self.loaded[i] {
                (fx + nx, fy + ny)
            } else {
                (0.0, 0.0)
            };
            *s = TactileReading {
                angle: sensor_angle(i, k) as f32,
                fx: fx as f32,
                fy: fy as f32,
                _pad: 0.0,
            };
        }
    }

    /// Odometry: the velocities applied this step plus Gaussian noise (σ = `odom_v_std`,
    /// `odom_omega_std`) over `dt = map.dt`, integrated into the odometry pose. After steps this
    /// process did not see (it was stopped, or busy) the wheels turned all the same: the motion
    /// is then the truth's between the two steps, as one arc, with the noise of as many steps,
    /// and `dt` spans them. After a restart, over the steps since the odometry it resumed, the
    /// velocities measured now are held (that motion went unseen).
    pub fn odom(&mut self, truth: &Truth, out: &mut Odom) {
        let pose = Pose2::new(truth.x, truth.y, truth.theta);
        let tick = truth.header.tick;
        let since = self.odom_seen.map(|(seen, _)| seen).or(self.odom_resumed);
        let steps = since.map_or(1, |t| tick.saturating_sub(t).max(1));
        let dt = steps as f64 * self.dt;
        let (v_std, omega_std) = (self.spec.odom_v_std, self.spec.odom_omega_std);
        let (v, omega) = match self.odom_seen {
            Some((_, before)) if steps > 1 => {
                let (s, dtheta) = arc_between(before, pose);
                let spread = (steps as f64).sqrt() * self.dt;
                let s = s + spread * gauss(&mut self.rng_odom, v_std);
                let dtheta = dtheta + spread * gauss(&mut self.rng_odom, omega_std);
                (s / dt, dtheta / dt)
            }
            _ => (
                truth.v + gauss(&mut self.rng_odom, v_std),
                truth.omega + gauss(&mut self.rng_odom, omega_std),
            ),
        };
        self.odom_pose = unicycle_arc(self.odom_pose, v, omega, dt);
        self.odom_seen = Some((tick, pose));
        (out.x, out.y, out.theta) = (self.odom_pose.x, self.odom_pose.y, self.odom_pose.theta);
        (out.v, out.omega, out.dt) = (v, omega, dt);
    }

    /// Goes on from the odometry of the process this one follows (a restart, a swap), so the
    /// odom frame stays continuous.
    pub fn resume_odometry(&mut self, odom: &Odom) {
        self.odom_pose = Pose2::new(odom.x, odom.y, odom.theta);
        self.odom_resumed = Some(odom.header.tick);
    }

    /// Beacons: range and bearing (from the heading, wrapped to (−π, π]) to every beacon within
    /// `beacon_range_max` whose line of sight from the robot centre no square blocks, with
    /// Gaussian noise (σ = `beacon_range_std`, `beacon_bearing_std`); the range is clamped at 0.
    /// `id` is the beacon's index in `WorldMap::beacons`, or `LANDMARK_ANONYMOUS` for every
    /// reading when the scenario hides the ids (`sensors.beacons_anonymous`).
    pub fn beacons(&mut self, truth: &Truth, out: &mut Beacons) {
        let s = self.spec;
        let anonymous = s.beacons_anonymous == 1;
        let mut n = 0;
        for (idx, b) in self.beacons.iter().enumerate().take(MAX_BEACONS) {
            // Two draws per beacon, seen or not, so the stream advances the same every step.
            let noise_r = gauss(&mut self.rng_beacons, s.beacon_range_std);
            let noise_b = gauss(&mut self.rng_beacons, s.beacon_bearing_std);
            let (dx, dy) = (b.x - truth.x, b.y - truth.y);
            let d = dx.hypot(dy);
            // NaN distances (a garbage pose) fail this test too.
            if d.is_nan() || d > s.beacon_range_max {
                continue;
            }
            if d > 0.0 {
                // A square hit before the beacon (with a tolerance for beacons on a face) occludes.
                let tol = 1e-9 * (1.0 + d);
                if let Some(t) = self
                    .caster
                    .first_obstacle_hit(truth.x, truth.y, dx / d, dy / d, d)
                    && t < d - tol
                {
                    continue;
                }
            }
            out.readings[n] = BeaconReading {
                id: if anonymous {
                    LANDMARK_ANONYMOUS
                } else {
                    idx as u32
                },
                _pad: 0,
                range: (d + noise_r).max(0.0),
                bearing: wrap_angle(dy.atan2(dx) - truth.theta + noise_b),
            };
            n += 1;
        }
        out.n_readings = n as u32;
        out._pad = 0;
        out.readings[n..].fill(BeaconReading::default());
    }

    /// Position fix: the true position plus Gaussian noise σ = `fix_std` on each coordinate,
    /// valid (1) when `fix_period_ticks > 0` and `truth.header.tick % fix_period_ticks == 0`;
    /// otherwise `valid = 0` and x = y = 0.
    pub fn fix(&mut self, truth: &Truth, out: &mut Fix) {
        let period = u64::from(self.spec.fix_period_ticks);
        let sigma = self.spec.fix_std;
        // Two draws per call, valid or not, so the stream advances the same every step.
        let (nx, ny) = (
            gauss(&mut self.rng_fix, sigma),
            gauss(&mut self.rng_fix, sigma),
        );
        let valid = period > 0 && truth.header.tick.is_multiple_of(period);
        out.std = sigma;
        out._pad = 0;
        if valid {
            out.x = truth.x + nx;
            out.y = truth.y + ny;
            out.valid = 1;
        } else {
            out.x = 0.0;
            out.y = 0.0;
            out.valid = 0;
        }
    }
}

#[cfg(test)]
mod tests;
