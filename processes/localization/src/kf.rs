//! The linear Kalman filter (algorithms §6.5): a generic [`KalmanFilter`] over N states, M measurement
//! components and U controls, and the [`Kf`] estimator that runs it on the robot.
//!
//! Noise naming follows algorithms.md and Thrun: R is the PROCESS noise covariance, Q the
//! MEASUREMENT noise covariance. filterpy (and many other libraries) use the opposite letters:
//! filterpy's `Q` is our R and filterpy's `R` is our Q.
//!
//! The [`Kf`] state is (x, y, vx, vy). The model must be linear, so the heading is not part of
//! the state: it is integrated from the odometry ω on the side (dead reckoning) and only used to
//! rotate the odometry speed into a world-frame velocity control. Beacon range-bearing readings
//! are nonlinear in (x, y) and are therefore ignored by the KF (the EKF and PF use them); the
//! position fix is its one measurement, C = [I 0].

use crate::kalman::{KalmanError, kalman_correct, symmetrize};
use crate::models::odometry_is_plausible;
use crate::noise::NoiseModel;
use crate::{Estimator, ReadingError, Readings};
use mole_types::{EstimatorKind, Fix, Odom, Pose2, WorldMap, wrap_angle};
use nalgebra::{Matrix2, Matrix2x4, Matrix4, Matrix4x2, SMatrix, SVector, Vector2, Vector4};

/// Initial position σ (m) of [`Kf::from_map`], as for the EKF.
pub const INITIAL_STD_XY: f64 = 0.05;
/// Initial velocity σ (m/s) of [`Kf::from_map`]: the robot starts at rest.
pub const INITIAL_STD_V: f64 = 0.01;
/// Initial heading σ (rad) of [`Kf::from_map`].
pub const INITIAL_STD_THETA: f64 = 0.05;
/// Cap on the heading variance (rad²): π²/3 is the variance of a heading uniform on the circle.
pub const MAX_HEADING_VAR: f64 = core::f64::consts::PI * core::f64::consts::PI / 3.0;

/// The linear-Gaussian belief N(μ, Σ) and its model x_t = A x_{t−1} + B u_t + ε (ε ~ N(0, R)),
/// z_t = C x_t + δ (δ ~ N(0, Q)), algorithms §6.5. Every matrix is a stack-allocated nalgebra
/// `SMatrix`: predict and correct never allocate.
#[derive(Debug, Clone, PartialEq)]
pub struct KalmanFilter<const N: usize, const M: usize, const U: usize> {
    /// μ, the mean.
    pub mu: SVector<f64, N>,
    /// Σ, the covariance.
    pub sigma: SMatrix<f64, N, N>,
    /// A_t, the state transition.
    pub a: SMatrix<f64, N, N>,
    /// B_t, the control matrix.
    pub b: SMatrix<f64, N, U>,
    /// C_t, the measurement matrix.
    pub c: SMatrix<f64, M, N>,
    /// R_t, the PROCESS noise covariance (filterpy's `Q`).
    pub r: SMatrix<f64, N, N>,
    /// Q_t, the MEASUREMENT noise covariance (filterpy's `R`).
    pub q: SMatrix<f64, M, M>,
}

impl<const N: usize, const M: usize, const U: usize> KalmanFilter<N, M, U> {
    /// A filter with belief N(μ, Σ) and model (A, B, C, R, Q), algorithms §6.5.
    pub fn new(
        mu: SVector<f64, N>,
        sigma: SMatrix<f64, N, N>,
        a: SMatrix<f64, N, N>,
        b: SMatrix<f64, N, U>,
        c: SMatrix<f64, M, N>,
        r: SMatrix<f64, N, N>,
        q: SMatrix<f64, M, M>,
    ) -> Self {
        Self {
            mu,
            sigma,
            a,
            b,
            c,
            r,
            q,
        }
    }

    /// Prediction (algorithms §6.5, Algorithm 1): μ̄ = A μ + B u, Σ̄ = A Σ Aᵀ + R. A non-finite
    /// control leaves the belief alone.
    pub fn predict(&mut self, u: &SVector<f64, U>) -> Result<(), KalmanError> {
        if !u.iter().all(|v| v.is_finite()) {
            return Err(KalmanError::NotFinite);
        }
        self.mu = self.a * self.mu + self.b * u;
        self.sigma = self.a * self.sigma * self.a.transpose() + self.r;
        symmetrize(&mut self.sigma);
        Ok(())
    }

    /// Correction (algorithms §6.5, Algorithm 1): K = Σ̄ Cᵀ (C Σ̄ Cᵀ + Q)⁻¹, μ = μ̄ + K (z − C μ̄), and
    /// Σ in Joseph form (see [`kalman_correct`]). Returns νᵀ S⁻¹ ν; an optional χ² gate refuses
    /// outliers.
    pub fn correct(&mut self, z: &SVector<f64, M>, gate: Option<f64>) -> Result<f64, KalmanError> {
        let nu = z - self.c * self.mu;
        kalman_correct(&mut self.mu, &mut self.sigma, &nu, &self.c, &self.q, gate)
    }

    /// The normalised estimation error squared (x − μ)ᵀ Σ⁻¹ (x − μ) of a true state x, the
    /// consistency statistic of Bar-Shalom et al. (2001, §5.4); `None` if Σ is not invertible.
    pub fn nees(&self, truth: &SVector<f64, N>) -> Option<f64> {
        let e = truth - self.mu;
        let chol = self.sigma.cholesky()?;
        Some(e.dot(&chol.solve(&e)))
    }
}

/// The linear KF estimator (algorithms §6.5) on the state (x, y, vx, vy), with the heading integrated
/// from ω on the side and the position fix as the measurement (beacons are ignored: nonlinear).
#[derive(Debug, Clone)]
pub struct Kf {
    /// The linear filter: μ = (x, y, vx, vy).
    pub filter: KalmanFilter<4, 2, 2>,
    /// Heading θ̂ (rad), dead-reckoned from the odometry ω, wrapped to (−π, π].
    pub heading: f64,
    /// Variance of θ̂ (rad²), grown by σ_ω²·dt² per step, capped at [`MAX_HEADING_VAR`].
    pub heading_var: f64,
    /// Motion (R) and measurement (Q) noise.
    pub noise: NoiseModel,
    /// Optional χ² gate on the fix; `None` by default, because the fix is the KF's only
    /// correction and refusing it could leave the filter lost for good.
    pub gate_chi2: Option<f64>,
    rejected: u64,
    ignored: u64,
}

impl Kf {
    /// A KF at `initial` (velocity 0) with position σ `std_xy`, velocity σ [`INITIAL_STD_V`] and
    /// heading σ `std_theta`. Non-finite values become 0 (pose) or the defaults (σ).
    pub fn new(initial: Pose2, std_xy: f64, std_theta: f64, noise: NoiseModel) -> Kf {
        let fin = |v: f64, d: f64| if v.is_finite() { v } else { d };
        let pos_var = fin(std_xy, INITIAL_STD_XY).powi(2).max(1e-12);
        let vel_var = INITIAL_STD_V * INITIAL_STD_V;
        let sigma = Matrix4::from_diagonal(&Vector4::new(pos_var, pos_var, vel_var, vel_var));
        let c = Matrix2x4::new(1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0);
        Kf {
            filter: KalmanFilter::new(
                Vector4::new(fin(initial.x, 0.0), fin(initial.y, 0.0), 0.0, 0.0),
                sigma,
                Matrix4::identity(),
                Matrix4x2::zeros(),
                c,
                Matrix4::zeros(),
                noise.q_fix(noise.fix_std),
            ),
            heading: wrap_angle(fin(initial.theta, 0.0)),
            heading_var: fin(std_theta, INITIAL_STD_THETA)
                .powi(2)
                .min(MAX_HEADING_VAR),
            noise,
            gate_chi2: None,
            rejected: 0,
            ignored: 0,
        }
    }

    /// The KF for the world in `map`: start pose, the σ of the EKF's prior, the sensors' noise.
    pub fn from_map(map: &WorldMap) -> Kf {
        Kf::new(
            Pose2::new(map.start_x, map.start_y, map.start_theta),
            INITIAL_STD_XY,
            INITIAL_STD_THETA,
            NoiseModel::from_map(map),
        )
    }

    /// Prediction with odometry (v, ω) over dt (algorithms §6.5): the control is the odometry velocity
    /// rotated into the world by the heading at mid-step, u = v·(cos θ̂, sin θ̂), and
    /// A = [[I, 0], [0, 0]], B = [[dt·I], [I]]: the velocity is held constant over the step at the
    /// control's value and the position integrates it.
    ///
    /// Deviation: a free-running constant-velocity A = [[I, dt·I], [0, I]] would ignore the
    /// odometry, the one measurement of the velocity we have, so the control sets it instead.
    /// R = B M_xy Bᵀ + floor, with M_xy the odometry noise rotated into the world: σ_v² along the
    /// heading and v²·σ_θ̂² across it (the heading's own uncertainty, treated as white).
    ///
    /// Odometry that is not plausible ([`odometry_is_plausible`]) is ignored and counted.
    pub fn predict_with(&mut self, v: f64, omega: f64, dt: f64) -> Result<(), ReadingError> {
        if !odometry_is_plausible(v, omega, dt) {
            self.ignored += 1;
            return Err(ReadingError::Invalid);
        }
        if dt == 0.0 {
            return Ok(());
        }
        let theta_mid = self.heading + 0.5 * omega * dt;
        let (s, c) = theta_mid.sin_cos();
        let u = Vector2::new(v * c, v * s);
        let mut a = Matrix4::identity();
        a[(2, 2)] = 0.0;
        a[(3, 3)] = 0.0;
        let b = Matrix4x2::new(dt, 0.0, 0.0, dt, 1.0, 0.0, 0.0, 1.0);
        // Odometry noise in the world frame: along-track σ_v², cross-track v²·σ_θ̂².
        let along = self.noise.odom_v_std * self.noise.odom_v_std;
        let across = v * v * self.heading_var;
        let rot = Matrix2::new(c, -s, s, c);
        let m_xy = rot * Matrix2::new(along, 0.0, 0.0, across) * rot.transpose();
        let mut r = b * m_xy * b.transpose();
        let floor = self.noise.r_floor(dt);
        r[(0, 0)] += floor[(0, 0)];
        r[(1, 1)] += floor[(1, 1)];
        self.filter.a = a;
        self.filter.b = b;
        self.filter.r = r;
        self.filter.predict(&u).map_err(ReadingError::from)?;
        self.heading = wrap_angle(self.heading + omega * dt);
        let s_w = self.noise.odom_omega_std * dt;
        self.heading_var = (self.heading_var + s_w * s_w + floor[(2, 2)]).min(MAX_HEADING_VAR);
        Ok(())
    }

    /// Correction with a position fix, z = C x + δ with C = [I 0] and Q = σ_fix²·I (algorithms §6.5),
    /// when `fix.valid == 1`. Returns νᵀ S⁻¹ ν.
    pub fn correct_fix(&mut self, fix: &Fix) -> Result<Option<f64>, ReadingError> {
        match fix.valid {
            0 => Ok(None),
            1 if fix.x.is_finite() && fix.y.is_finite() => {
                self.filter.q = self.noise.q_fix(fix.std);
                match self
                    .filter
                    .correct(&Vector2::new(fix.x, fix.y), self.gate_chi2)
                {
                    Ok(d2) => Ok(Some(d2)),
                    Err(e) => {
                        let e = ReadingError::from(e);
                        if e.is_rejection() {
                            self.rejected += 1;
                        } else {
                            self.ignored += 1;
                        }
                        Err(e)
                    }
                }
            }
            _ => {
                self.ignored += 1;
                Err(ReadingError::Invalid)
            }
        }
    }
}

impl Estimator for Kf {
    fn set_noise(&mut self, noise: &NoiseModel) -> Result<(), String> {
        self.noise = *noise;
        Ok(())
    }

    fn id(&self) -> u32 {
        EstimatorKind::Kf.code()
    }

    fn predict(&mut self, odom: &Odom) {
        // Refusals are counted inside.
        let _ = self.predict_with(odom.v, odom.omega, odom.dt);
    }

    /// Only the fix: the beacons' range-bearing model is nonlinear, outside the KF's reach.
    fn correct(&mut self, readings: &Readings<'_>) {
        if let Some(fix) = readings.fix {
            let _ = self.correct_fix(fix);
        }
    }

    fn pose(&self) -> Pose2 {
        Pose2::new(self.filter.mu[0], self.filter.mu[1], self.heading)
    }

    /// The (x, y) block of Σ, the heading variance, no x–θ correlation (θ̂ lives outside Σ).
    fn covariance(&self) -> [f64; 9] {
        let s = &self.filter.sigma;
        [
            s[(0, 0)],
            s[(0, 1)],
            0.0,
            s[(1, 0)],
            s[(1, 1)],
            0.0,
            0.0,
            0.0,
            self.heading_var,
        ]
    }

    fn rejected(&self) -> u64 {
        self.rejected
    }

    fn ignored(&self) -> u64 {
        self.ignored
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;
    use nalgebra::{Matrix1, Matrix1x2, Matrix2x1, Vector1};

    #[test]
    fn matches_filterpy_on_the_constant_velocity_example() {
        // filterpy 1.4.5: KalmanFilter(dim_x=2, dim_z=1); F=[[1,1],[0,1]], H=[[1,0]], x=[0,0],
        // P=10·I, R=[[1]] (filterpy's R = measurement = our Q), Q=0.01·I (filterpy's Q =
        // process = our R); for z in [1, 2.1, 2.9, 4.2, 5.0]: kf.predict(); kf.update(z).
        let mut kf = KalmanFilter::<2, 1, 1>::new(
            Vector2::zeros(),
            Matrix2::identity() * 10.0,
            Matrix2::new(1.0, 1.0, 0.0, 1.0),
            Matrix2x1::zeros(),
            Matrix1x2::new(1.0, 0.0),
            Matrix2::identity() * 0.01,
            Matrix1::new(1.0),
        );
        for z in [1.0, 2.1, 2.9, 4.2, 5.0] {
            kf.predict(&Vector1::zeros()).unwrap();
            kf.correct(&Vector1::new(z), None).unwrap();
        }
        assert_relative_eq!(kf.mu[0], 5.041582870065, epsilon = 1e-9);
        assert_relative_eq!(kf.mu[1], 1.001020655344, epsilon = 1e-9);
        assert_relative_eq!(kf.sigma[(0, 0)], 0.588807216267, epsilon = 1e-9);
        assert_relative_eq!(kf.sigma[(0, 1)], 0.19381468581, epsilon = 1e-9);
        assert_relative_eq!(kf.sigma[(1, 0)], 0.19381468581, epsilon = 1e-9);
        assert_relative_eq!(kf.sigma[(1, 1)], 0.113342282997, epsilon = 1e-9);
    }

    #[test]
    fn matches_filterpy_with_control_and_correlated_noise() {
        // filterpy 1.4.5, dt = 0.5: KalmanFilter(dim_x=4, dim_z=2, dim_u=2);
        // F=[[1,0,dt,0],[0,1,0,dt],[0,0,1,0],[0,0,0,1]], B=[[dt²/2,0],[0,dt²/2],[dt,0],[0,dt]],
        // H=[[1,0,0,0],[0,1,0,0]], x=[0,0,1,0], P=diag(1,1,0.5,0.5),
        // Q=[[.01,0,.005,0],[0,.01,0,.005],[.005,0,.02,0],[0,.005,0,.02]] (our R),
        // R=[[.25,.05],[.05,.16]] (our Q); for u, z in zip([(.2,0),(0,.4),(-.1,.1),(0,0)],
        // [(.6,.1),(1.1,.35),(1.4,.9),(1.95,1.2)]): kf.predict(u=u); kf.update(z).
        let dt = 0.5;
        let a = Matrix4::new(
            1.0, 0.0, dt, 0.0, 0.0, 1.0, 0.0, dt, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0,
        );
        let b = Matrix4x2::new(0.5 * dt * dt, 0.0, 0.0, 0.5 * dt * dt, dt, 0.0, 0.0, dt);
        let r = Matrix4::new(
            0.01, 0.0, 0.005, 0.0, 0.0, 0.01, 0.0, 0.005, 0.005, 0.0, 0.02, 0.0, 0.0, 0.005, 0.0,
            0.02,
        );
        let mut kf = KalmanFilter::<4, 2, 2>::new(
            Vector4::new(0.0, 0.0, 1.0, 0.0),
            Matrix4::from_diagonal(&Vector4::new(1.0, 1.0, 0.5, 0.5)),
            a,
            b,
            Matrix2x4::new(1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0),
            r,
            Matrix2::new(0.25, 0.05, 0.05, 0.16),
        );
        let us = [(0.2, 0.0), (0.0, 0.4), (-0.1, 0.1), (0.0, 0.0)];
        let zs = [(0.6, 0.1), (1.1, 0.35), (1.4, 0.9), (1.95, 1.2)];
        for (u, z) in us.iter().zip(zs.iter()) {
            kf.predict(&Vector2::new(u.0, u.1)).unwrap();
            kf.correct(&Vector2::new(z.0, z.1), None).unwrap();
        }
        let mu = [
            1.937657662531481,
            1.156857451994529,
            0.893732360342414,
            0.719732861686531,
        ];
        let p = [
            [
                0.14327098881532,
                0.025335697070457,
                0.102911649275053,
                0.015810127265383,
            ],
            [
                0.025335697070457,
                0.097666734088498,
                0.015810127265383,
                0.074453420197364,
            ],
            [
                0.102911649275053,
                0.015810127265383,
                0.152466953880743,
                0.017691600810488,
            ],
            [
                0.015810127265383,
                0.074453420197364,
                0.017691600810488,
                0.120622072421864,
            ],
        ];
        for (i, row) in p.iter().enumerate() {
            assert_relative_eq!(kf.mu[i], mu[i], epsilon = 1e-12);
            for (j, &pij) in row.iter().enumerate() {
                assert_relative_eq!(kf.sigma[(i, j)], pij, epsilon = 1e-12);
            }
        }
    }

    #[test]
    fn kf_estimator_follows_odometry_and_takes_the_fix() {
        let noise = NoiseModel::new(0.05, 0.05, 0.05, 0.02, 0.5);
        let mut kf = Kf::new(Pose2::new(1.0, 2.0, 0.0), 0.05, 0.05, noise);
        // 1 s straight along +x at 1 m/s in 100 steps, then a quarter turn on the spot.
        for _ in 0..100 {
            kf.predict_with(1.0, 0.0, 0.01).unwrap();
        }
        assert_relative_eq!(kf.pose().x, 2.0, epsilon = 1e-12);
        assert_relative_eq!(kf.pose().y, 2.0, epsilon = 1e-12);
        assert_relative_eq!(kf.filter.mu[2], 1.0, epsilon = 1e-12);
        for _ in 0..100 {
            kf.predict_with(0.0, core::f64::consts::FRAC_PI_2, 0.01)
                .unwrap();
        }
        assert_relative_eq!(kf.heading, core::f64::consts::FRAC_PI_2, epsilon = 1e-12);
        kf.predict_with(1.0, 0.0, 0.5).unwrap();
        assert_relative_eq!(kf.pose().y, 2.5, epsilon = 1e-12);
        // A fix with σ equal to the position σ pulls about half way (Σxy ≈ 8e-6 ≠ 0: the
        // along-track noise of the turn on the spot was rotated).
        let sxx = kf.filter.sigma[(0, 0)];
        let mut fix: Fix = bytemuck::Zeroable::zeroed();
        fix.valid = 1;
        fix.x = kf.pose().x + 1.0;
        fix.y = kf.pose().y;
        fix.std = sxx.sqrt();
        let x0 = kf.pose().x;
        kf.correct_fix(&fix).unwrap();
        assert_relative_eq!(kf.pose().x, x0 + 0.5, epsilon = 1e-5);
        // Garbage is ignored and counted.
        fix.x = f64::NAN;
        assert!(kf.correct_fix(&fix).is_err());
        fix.valid = 9;
        assert!(kf.correct_fix(&fix).is_err());
        assert!(kf.predict_with(f64::NAN, 0.0, 0.1).is_err());
        assert_eq!(kf.ignored(), 3);
        let c = kf.covariance();
        assert_eq!(c[1], c[3]);
        assert!(c[0] > 0.0 && c[4] > 0.0 && c[8] > 0.0);
    }
}
