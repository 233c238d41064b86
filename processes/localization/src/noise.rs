//! Motion and measurement noise, from the map's `SensorSpec`.
//!
//! Names follow algorithms.md (§6.5, after Thrun): R_t is the PROCESS (motion) noise covariance and
//! Q_t the MEASUREMENT noise covariance; M_t is the noise of the control u = (v, ω) that R_t is
//! built from.

use mole_types::WorldMap;
use nalgebra::{Matrix2, Matrix3};

/// Floor on the odometry speed σ (m/s), so Σ never collapses on a noiseless spec.
pub const MIN_ODOM_V_STD: f64 = 1e-3;
/// Floor on the odometry turn-rate σ (rad/s).
pub const MIN_ODOM_OMEGA_STD: f64 = 1e-3;
/// Floor on the beacon range σ (m).
pub const MIN_BEACON_RANGE_STD: f64 = 1e-3;
/// Floor on the beacon bearing σ (rad).
pub const MIN_BEACON_BEARING_STD: f64 = 1e-4;
/// Floor on the position-fix σ (m).
pub const MIN_FIX_STD: f64 = 1e-3;
/// Default additive process noise on (x, y, θ), variance per second of motion: unmodelled
/// effects (wheel slip, contact pushes) and a floor that keeps R_t full rank when v = ω = 0.
pub const DEFAULT_STATE_NOISE_RATE: [f64; 3] = [1e-6, 1e-6, 1e-7];

/// `value` if it is finite and at least `floor`, else `floor`.
#[inline]
fn floored(value: f64, floor: f64) -> f64 {
    if value.is_finite() && value >= floor {
        value
    } else {
        floor
    }
}

/// Motion and measurement noise σ, every one at least its floor.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NoiseModel {
    /// Odometry σ on v (m/s).
    pub odom_v_std: f64,
    /// Odometry σ on ω (rad/s).
    pub odom_omega_std: f64,
    /// Beacon range σ (m).
    pub beacon_range_std: f64,
    /// Beacon bearing σ (rad).
    pub beacon_bearing_std: f64,
    /// Position-fix σ per coordinate (m), used when a fix does not carry a usable σ of its own.
    pub fix_std: f64,
    /// Additive process noise on (x, y, θ), variance per second (m²/s, m²/s, rad²/s).
    pub state_noise_rate: [f64; 3],
}

impl NoiseModel {
    /// A model from explicit σ, each raised to its floor (non-finite values become the floor).
    pub fn new(
        odom_v_std: f64,
        odom_omega_std: f64,
        beacon_range_std: f64,
        beacon_bearing_std: f64,
        fix_std: f64,
    ) -> Self {
        Self {
            odom_v_std: floored(odom_v_std, MIN_ODOM_V_STD),
            odom_omega_std: floored(odom_omega_std, MIN_ODOM_OMEGA_STD),
            beacon_range_std: floored(beacon_range_std, MIN_BEACON_RANGE_STD),
            beacon_bearing_std: floored(beacon_bearing_std, MIN_BEACON_BEARING_STD),
            fix_std: floored(fix_std, MIN_FIX_STD),
            state_noise_rate: DEFAULT_STATE_NOISE_RATE,
        }
    }

    /// The model the world's sensors are configured with (`WorldMap::sensors`), floored.
    pub fn from_map(map: &WorldMap) -> Self {
        let s = &map.sensors;
        Self::new(
            s.odom_v_std,
            s.odom_omega_std,
            s.beacon_range_std,
            s.beacon_bearing_std,
            s.fix_std,
        )
    }

    /// M_t = diag(σ_v², σ_ω²): covariance of the measured control u = (v, ω) (Thrun §7.4).
    pub fn m_t(&self) -> Matrix2<f64> {
        Matrix2::new(
            self.odom_v_std * self.odom_v_std,
            0.0,
            0.0,
            self.odom_omega_std * self.odom_omega_std,
        )
    }

    /// The additive part of the process noise R_t over a step of `dt` seconds.
    pub fn r_floor(&self, dt: f64) -> Matrix3<f64> {
        let [a, b, c] = self.state_noise_rate;
        let f = |rate: f64| {
            if rate.is_finite() && rate > 0.0 {
                rate * dt
            } else {
                0.0
            }
        };
        Matrix3::new(f(a), 0.0, 0.0, 0.0, f(b), 0.0, 0.0, 0.0, f(c))
    }

    /// Q_t = diag(σ_r², σ_b²): measurement noise of one range-bearing reading.
    pub fn q_beacon(&self) -> Matrix2<f64> {
        Matrix2::new(
            self.beacon_range_std * self.beacon_range_std,
            0.0,
            0.0,
            self.beacon_bearing_std * self.beacon_bearing_std,
        )
    }

    /// Q_t = σ²·I for a position fix; `fix_std` is the σ the fix message carries, used when it
    /// is finite and positive (then floored), else the model's own σ.
    pub fn q_fix(&self, fix_std: f64) -> Matrix2<f64> {
        let std = if fix_std.is_finite() && fix_std > 0.0 {
            floored(fix_std, MIN_FIX_STD)
        } else {
            self.fix_std
        };
        Matrix2::identity() * (std * std)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn zero_and_non_finite_sigmas_are_floored() {
        let n = NoiseModel::new(0.0, f64::NAN, -1.0, f64::INFINITY, 0.5);
        assert_eq!(n.odom_v_std, MIN_ODOM_V_STD);
        assert_eq!(n.odom_omega_std, MIN_ODOM_OMEGA_STD);
        assert_eq!(n.beacon_range_std, MIN_BEACON_RANGE_STD);
        assert_eq!(n.beacon_bearing_std, MIN_BEACON_BEARING_STD);
        assert_eq!(n.fix_std, 0.5);
        assert_eq!(n.q_fix(0.0)[(0, 0)], 0.25);
        assert_eq!(n.q_fix(f64::NAN)[(1, 1)], 0.25);
        assert_eq!(n.q_fix(0.1)[(1, 1)], 0.1 * 0.1);
        assert_eq!(n.q_fix(1e-9)[(0, 0)], MIN_FIX_STD * MIN_FIX_STD);
        assert_eq!(n.m_t()[(0, 0)], MIN_ODOM_V_STD * MIN_ODOM_V_STD);
    }

    #[test]
    fn from_map_reads_the_sensor_spec() {
        let mut map = crate::test_support::zeroed_map();
        map.sensors.odom_v_std = 0.05;
        map.sensors.odom_omega_std = 0.02;
        map.sensors.beacon_range_std = 0.1;
        map.sensors.beacon_bearing_std = 0.03;
        map.sensors.fix_std = 0.5;
        let n = NoiseModel::from_map(&map);
        assert_eq!(n, NoiseModel::new(0.05, 0.02, 0.1, 0.03, 0.5));
        assert_eq!(n.q_beacon(), Matrix2::new(0.1 * 0.1, 0.0, 0.0, 0.03 * 0.03));
        assert_eq!(n.r_floor(2.0)[(0, 0)], 2.0 * DEFAULT_STATE_NOISE_RATE[0]);
    }
}
