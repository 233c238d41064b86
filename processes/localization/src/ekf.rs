//! The extended Kalman filter (algorithms §6.6) on the state x = (x, y, θ), with unicycle motion from
//! odometry and range-bearing corrections to known beacons plus an optional position fix.
//!
//! The seed (after Thrun) calls the PROCESS noise covariance R_t and the MEASUREMENT noise
//! covariance Q_t; here R_t = V_t M_t V_tᵀ (+ a small floor) from the odometry σ (Thrun §7.4)
//! and Q_t = diag(σ_r², σ_b²) per beacon reading, σ_fix²·I per fix.

use crate::kalman::{CHI2_999_2DOF, KalmanError, kalman_correct, symmetrize};
use crate::models::{
    BeaconTable, MIN_RANGE, add_slide, range_bearing_h, range_bearing_jacobian_h,
    sliding_is_plausible, unicycle_g, unicycle_jacobian_g, unicycle_jacobian_v,
};
use crate::noise::NoiseModel;
use crate::{Estimator, ReadingError, Readings};
use mole_types::{
    BeaconReading, BeaconSite, EstimatorKind, Fix, Odom, Pose2, WorldMap, wrap_angle,
};
use nalgebra::{Cholesky, Matrix2, Matrix2x3, Matrix3, Matrix3x2, Vector2, Vector3};

/// Initial position σ (m) of [`Ekf::from_map`]: the world places the robot exactly at the start.
pub const INITIAL_STD_XY: f64 = 0.05;
/// Initial heading σ (rad) of [`Ekf::from_map`].
pub const INITIAL_STD_THETA: f64 = 0.05;
/// Default window (in readings) of the running outlier rate that decides re-acquisition.
pub const DEFAULT_REACQUIRE_WINDOW: u32 = 25;
/// Running outlier rate above which a gated reading means the filter, not the reading, is wrong.
pub const REACQUIRE_OUTLIER_RATE: f64 = 0.5;
/// Largest factor one re-acquisition inflates Σ by.
const MAX_INFLATION: f64 = 1e6;

/// The EKF belief N(μ, Σ) over (x, y, θ) and what it needs to update it (algorithms §6.6).
#[derive(Debug, Clone)]
pub struct Ekf {
    /// μ = (x, y, θ), θ wrapped to (−π, π].
    pub mu: Vector3<f64>,
    /// Σ, symmetric positive definite.
    pub sigma: Matrix3<f64>,
    /// Motion (R_t) and measurement (Q_t) noise.
    pub noise: NoiseModel,
    /// χ² gate on νᵀ S⁻¹ ν for a 2-D reading (default 99.9%).
    pub gate_chi2: f64,
    /// Window (readings) of the running outlier rate: when more than
    /// [`REACQUIRE_OUTLIER_RATE`] of recent readings were gated the filter assumes it is lost,
    /// not the readings, inflates Σ and takes the gated reading after all (0 disables this).
    pub reacquire_window: u32,
    beacons: BeaconTable,
    rejected: u64,
    ignored: u64,
    reacquisitions: u64,
    outlier_rate: f64,
}

impl Ekf {
    /// A filter starting at N(initial, initial_sigma). Non-finite pose components become 0, and
    /// an initial Σ that is not finite and positive definite becomes the default of `from_map`.
    pub fn new(
        initial: Pose2,
        initial_sigma: Matrix3<f64>,
        noise: NoiseModel,
        beacons: &[BeaconSite],
    ) -> Ekf {
        let finite_or_zero = |v: f64| if v.is_finite() { v } else { 0.0 };
        let mut sigma = initial_sigma;
        symmetrize(&mut sigma);
        if !(sigma.iter().all(|v| v.is_finite()) && Cholesky::new(sigma).is_some()) {
            sigma = default_initial_sigma();
        }
        Ekf {
            mu: Vector3::new(
                finite_or_zero(initial.x),
                finite_or_zero(initial.y),
                wrap_angle(finite_or_zero(initial.theta)),
            ),
            sigma,
            noise,
            gate_chi2: CHI2_999_2DOF,
            reacquire_window: DEFAULT_REACQUIRE_WINDOW,
            beacons: BeaconTable::new(beacons),
            rejected: 0,
            ignored: 0,
            reacquisitions: 0,
            outlier_rate: 0.0,
        }
    }

    /// The filter for the world in `map`: the start pose, a small initial Σ
    /// (σ = [`INITIAL_STD_XY`], [`INITIAL_STD_THETA`]), the sensors' noise and the beacons.
    pub fn from_map(map: &WorldMap) -> Ekf {
        Ekf::new(
            Pose2::new(map.start_x, map.start_y, map.start_theta),
            default_initial_sigma(),
            NoiseModel::from_map(map),
            map.beacons(),
        )
    }

    /// The filter for the world in `map` going on from another estimator's `pose` (a swap, a
    /// restart): N(pose, its covariance), so a killed EKF's restart steps as the EKF it replaces
    /// (its running outlier rate starts at 0 again); a covariance that is not positive definite
    /// becomes the default initial Σ.
    pub fn resume(map: &WorldMap, pose: &mole_types::Pose) -> Ekf {
        Ekf::new(
            Pose2::new(pose.x, pose.y, pose.theta),
            Matrix3::from_row_slice(&pose.covariance),
            NoiseModel::from_map(map),
            map.beacons(),
        )
    }

    /// g(μ, u): unicycle motion (exact arc; straight-line limit when |ω| small), algorithms §6.6.
    pub fn g(mu: &Vector3<f64>, v: f64, omega: f64, dt: f64) -> Vector3<f64> {
        unicycle_g(mu, v, omega, dt)
    }

    /// G_t = ∂g/∂x, analytic (algorithms §6.6); with V_t ([`Ekf::jacobian_v`]) it gives the process
    /// noise R_t = V_t M_t V_tᵀ. The seed (after Thrun) calls process noise R, measurement noise Q.
    pub fn jacobian_g(mu: &Vector3<f64>, v: f64, omega: f64, dt: f64) -> Matrix3<f64> {
        unicycle_jacobian_g(mu, v, omega, dt)
    }

    /// V_t = ∂g/∂u, analytic; the process noise is R_t = V_t M_t V_tᵀ (Thrun §5.3/§7.4). The
    /// seed (after Thrun) calls process noise R and measurement noise Q.
    pub fn jacobian_v(mu: &Vector3<f64>, v: f64, omega: f64, dt: f64) -> Matrix3x2<f64> {
        unicycle_jacobian_v(mu, v, omega, dt)
    }

    /// h(x) = (range, bearing) to a beacon at (x, y), bearing relative to the heading, wrapped.
    pub fn h(x: &Vector3<f64>, beacon: (f64, f64)) -> Vector2<f64> {
        range_bearing_h(x, beacon)
    }

    /// Readings refused as outliers by the χ² gate so far.
    pub fn rejected(&self) -> u64 {
        self.rejected
    }

    /// Inputs ignored so far: unknown beacon ids, non-finite or out-of-range values, bad flags.
    pub fn ignored(&self) -> u64 {
        self.ignored
    }

    /// Times the filter declared itself lost and re-acquired (see `reacquire_window`).
    pub fn reacquisitions(&self) -> u64 {
        self.reacquisitions
    }

    /// Prediction (algorithms §6.6): μ̄ = g(μ, u), Σ̄ = G_t Σ G_tᵀ + R_t with R_t = V_t M_t V_tᵀ + floor.
    /// Odometry that is not plausible ([`crate::models::odometry_is_plausible`]: non-finite,
    /// negative dt, or beyond the bounds of [`crate::models`]) is ignored (and counted); dt = 0
    /// changes nothing.
    pub fn predict_with(&mut self, v: f64, omega: f64, dt: f64) -> Result<(), ReadingError> {
        self.predict_sliding_with(v, omega, dt, &Vector2::zeros())
    }

    /// [`Ekf::predict_with`] followed by the slide `sideways` the wheels did not see (robot
    /// frame at the arc's end, [`crate::contact`]): μ̄ moves by R(θ̄)·b and G_t turns it with θ.
    pub fn predict_sliding_with(
        &mut self,
        v: f64,
        omega: f64,
        dt: f64,
        sideways: &Vector2<f64>,
    ) -> Result<(), ReadingError> {
        if !sliding_is_plausible(v, omega, dt, sideways) {
            self.ignored += 1;
            return Err(ReadingError::Invalid);
        }
        if dt == 0.0 {
            return Ok(());
        }
        let mut g_t = unicycle_jacobian_g(&self.mu, v, omega, dt);
        let v_t = unicycle_jacobian_v(&self.mu, v, omega, dt);
        let r_t = v_t * self.noise.m_t() * v_t.transpose() + self.noise.r_floor(dt);
        self.mu = unicycle_g(&self.mu, v, omega, dt);
        add_slide(&mut self.mu, Some(&mut g_t), sideways);
        self.sigma = g_t * self.sigma * g_t.transpose() + r_t;
        symmetrize(&mut self.sigma);
        Ok(())
    }

    /// Correction with one range-bearing reading (algorithms §6.6): ν = z − h(μ̄) with the bearing
    /// wrapped, gated, Joseph-form update. Returns νᵀ S⁻¹ ν; refusals are counted.
    pub fn correct_beacon(&mut self, reading: &BeaconReading) -> Result<f64, ReadingError> {
        let result = self.try_correct_beacon(reading);
        self.count(result)
    }

    fn try_correct_beacon(&mut self, reading: &BeaconReading) -> Result<f64, ReadingError> {
        if !(reading.range.is_finite() && reading.bearing.is_finite() && reading.range >= 0.0) {
            return Err(ReadingError::Invalid);
        }
        let beacon = self
            .beacons
            .get(reading.id)
            .ok_or(ReadingError::UnknownBeacon(reading.id))?;
        let z_hat = range_bearing_h(&self.mu, beacon);
        if z_hat[0] < MIN_RANGE {
            return Err(ReadingError::TooClose);
        }
        let nu = Vector2::new(
            reading.range - z_hat[0],
            wrap_angle(reading.bearing - z_hat[1]),
        );
        let h_t = range_bearing_jacobian_h(&self.mu, beacon);
        let q_t = self.noise.q_beacon();
        self.update(&nu, &h_t, &q_t)
    }

    /// Correction with a position fix as the linear measurement z = (x, y) + δ, when
    /// `fix.valid == 1`; `valid == 0` does nothing. Returns νᵀ S⁻¹ ν; refusals are counted.
    pub fn correct_fix(&mut self, fix: &Fix) -> Result<Option<f64>, ReadingError> {
        match fix.valid {
            0 => Ok(None),
            1 if fix.x.is_finite() && fix.y.is_finite() => {
                let nu = Vector2::new(fix.x - self.mu[0], fix.y - self.mu[1]);
                let h_t = Matrix2x3::new(1.0, 0.0, 0.0, 0.0, 1.0, 0.0);
                let q_t: Matrix2<f64> = self.noise.q_fix(fix.std);
                let result = self.update(&nu, &h_t, &q_t);
                self.count(result).map(Some)
            }
            _ => self.count(Err(ReadingError::Invalid)),
        }
    }

    /// The gated Kalman update shared by every 2-D reading, with re-acquisition when lost.
    fn update(
        &mut self,
        nu: &Vector2<f64>,
        h_t: &Matrix2x3<f64>,
        q_t: &Matrix2<f64>,
    ) -> Result<f64, ReadingError> {
        let gated = kalman_correct(
            &mut self.mu,
            &mut self.sigma,
            nu,
            h_t,
            q_t,
            Some(self.gate_chi2),
        );
        // Running outlier rate, an exponential average over about `reacquire_window` readings.
        let alpha = 1.0 / f64::from(self.reacquire_window.max(1));
        let outlier = f64::from(u8::from(matches!(gated, Err(KalmanError::Gated { .. }))));
        self.outlier_rate += alpha * (outlier - self.outlier_rate);
        let result = match gated {
            Err(KalmanError::Gated { mahalanobis2, gate })
                if self.reacquire_window > 0 && self.outlier_rate > REACQUIRE_OUTLIER_RATE =>
            {
                // Lost: covariance inflation by λ = d²/gate (fading memory, Bar-Shalom, Li &
                // Kirubarajan 2001), then the reading is taken ungated; counted as a
                // re-acquisition, not a rejection.
                let lambda = (mahalanobis2 / gate).clamp(1.0, MAX_INFLATION);
                self.sigma *= lambda;
                self.reacquisitions += 1;
                self.outlier_rate = 0.0;
                kalman_correct(&mut self.mu, &mut self.sigma, nu, h_t, q_t, None)
            }
            other => other,
        };
        self.mu[2] = wrap_angle(self.mu[2]);
        result.map_err(ReadingError::from)
    }

    /// Counts a refusal as rejected (gate) or ignored (unusable input).
    fn count<T>(&mut self, result: Result<T, ReadingError>) -> Result<T, ReadingError> {
        if let Err(e) = &result {
            if e.is_rejection() {
                self.rejected += 1;
            } else {
                self.ignored += 1;
            }
        }
        result
    }
}

/// diag(σ_xy², σ_xy², σ_θ²) from [`INITIAL_STD_XY`] and [`INITIAL_STD_THETA`].
fn default_initial_sigma() -> Matrix3<f64> {
    Matrix3::from_diagonal(&Vector3::new(
        INITIAL_STD_XY * INITIAL_STD_XY,
        INITIAL_STD_XY * INITIAL_STD_XY,
        INITIAL_STD_THETA * INITIAL_STD_THETA,
    ))
}

impl Estimator for Ekf {
    fn set_noise(&mut self, noise: &NoiseModel) -> Result<(), String> {
        self.noise = *noise;
        Ok(())
    }

    fn id(&self) -> u32 {
        EstimatorKind::Ekf.code()
    }

    fn predict(&mut self, odom: &Odom) {
        // A refused control is counted inside; nothing else to do with it here.
        let _ = self.predict_with(odom.v, odom.omega, odom.dt);
    }

    fn predict_sliding(&mut self, odom: &Odom, sideways: &Vector2<f64>) {
        // A refused control is counted inside.
        let _ = self.predict_sliding_with(odom.v, odom.omega, odom.dt, sideways);
    }

    /// Sequential updates, one per beacon reading in order, then the fix.
    fn correct(&mut self, readings: &Readings<'_>) {
        if let Some(beacons) = readings.beacons {
            if beacons.n_readings as usize > beacons.readings.len() {
                self.ignored += 1;
            }
            for reading in beacons.readings() {
                // Refusals are counted inside.
                let _ = self.correct_beacon(reading);
            }
        }
        if let Some(fix) = readings.fix {
            let _ = self.correct_fix(fix);
        }
    }

    fn pose(&self) -> Pose2 {
        Pose2::new(self.mu[0], self.mu[1], self.mu[2])
    }

    fn covariance(&self) -> [f64; 9] {
        let mut out = [0.0; 9];
        for r in 0..3 {
            for c in 0..3 {
                out[3 * r + c] = self.sigma[(r, c)];
            }
        }
        out
    }

    fn rejected(&self) -> u64 {
        self.rejected
    }

    fn ignored(&self) -> u64 {
        self.ignored
    }
}

#[cfg(test)]
mod tests;
