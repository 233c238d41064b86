//! The three factor types of the pose graph: their residuals (errors), Jacobians and
//! information matrices, built from the shared motion and measurement models in
//! [`crate::models`].
//!
//! Each factor contributes eᵀ Ω e to the GraphSLAM objective (Thrun et al., *Probabilistic
//! Robotics* 2005, §11.2, eq. 11.3–11.5; Grisetti et al. 2010, "A tutorial on graph-based SLAM",
//! eq. 3). The residuals are "estimate minus measurement" with angles wrapped to (−π, π].

use crate::models::{MIN_RANGE, unicycle_jacobian_v};
use crate::models::{range_bearing_jacobian_at, unicycle_g, unicycle_jacobian_g};
use crate::noise::NoiseModel;
use mole_types::wrap_angle;
use nalgebra::{Matrix2, Matrix2x3, Matrix3, Vector2, Vector3};

/// Variance floor (m², rad²) added to the odometry covariance so its inverse always exists,
/// even for a zero-length step on a noise model whose additive process noise is zero.
pub const MIN_ODOMETRY_VARIANCE: f64 = 1e-12;

/// One odometry constraint between consecutive poses: the control u = (v, ω) applied for dt.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OdometryFactor {
    /// Forward speed v (m/s).
    pub v: f64,
    /// Turn rate ω (rad/s).
    pub omega: f64,
    /// Duration (s).
    pub dt: f64,
    /// Ω = R⁻¹ in the frame of the earlier pose (see [`OdometryFactor::residual`]).
    pub information: Matrix3<f64>,
    /// The slide along a wall the wheels did not see ([`crate::contact`]), in the frame of the
    /// earlier pose (m); zero for a step without contact.
    pub slide: Vector2<f64>,
}

impl OdometryFactor {
    /// The factor for control (v, ω) over dt; None when its covariance cannot be inverted.
    ///
    /// R = V M Vᵀ + R_floor(dt) (Thrun §7.4, Table 7.2 line 4–6, as the motion term of §11.2),
    /// evaluated at heading 0: the residual is expressed in the earlier pose's frame, where
    /// the covariance of the relative motion no longer depends on the heading.
    pub fn new(noise: &NoiseModel, v: f64, omega: f64, dt: f64) -> Option<Self> {
        let v_t = unicycle_jacobian_v(&Vector3::zeros(), v, omega, dt);
        let r_t = v_t * noise.m_t() * v_t.transpose()
            + noise.r_floor(dt)
            + Matrix3::identity() * MIN_ODOMETRY_VARIANCE;
        let information = r_t.cholesky()?.inverse();
        information.iter().all(|x| x.is_finite()).then_some(Self {
            v,
            omega,
            dt,
            information,
            slide: Vector2::zeros(),
        })
    }

    /// The factor with the slide `sideways` after the arc (robot frame at the arc's end, as
    /// [`crate::Estimator::predict_sliding`] takes it), kept in the earlier pose's frame,
    /// R(ω·dt)·b. In that frame the slide does not depend on either pose, so it shifts the
    /// residual and leaves the Jacobians as they are.
    pub fn with_slide(self, sideways: &Vector2<f64>) -> Self {
        let (s, c) = (self.omega * self.dt).sin_cos();
        Self {
            slide: Vector2::new(
                c * sideways[0] - s * sideways[1],
                s * sideways[0] + c * sideways[1],
            ),
            ..self
        }
    }

    /// e = Λ(θ_a)·(x_b ⊖ g(x_a, u)), Λ(θ) = diag(R(θ)ᵀ, 1): the pose difference of Thrun §11.2
    /// (eq. 11.4) rotated into the frame of x_a, as the pose-pose errors of Grisetti et al.
    /// 2010 §III are; θ wrapped.
    pub fn residual(&self, x_a: &Vector3<f64>, x_b: &Vector3<f64>) -> Vector3<f64> {
        let predicted = unicycle_g(x_a, self.v, self.omega, self.dt);
        let (s, c) = x_a[2].sin_cos();
        let dx = x_b[0] - predicted[0];
        let dy = x_b[1] - predicted[1];
        Vector3::new(
            c * dx + s * dy - self.slide[0],
            -s * dx + c * dy - self.slide[1],
            wrap_angle(x_b[2] - predicted[2]),
        )
    }

    /// (∂e/∂x_a, ∂e/∂x_b) = (−Λ G_t + ∂Λ/∂θ_a·d, Λ), with G_t the motion Jacobian of Thrun
    /// §7.4 and d the world-frame difference (Grisetti et al. 2010 §IV, eq. 27 analogue).
    pub fn jacobians(
        &self,
        x_a: &Vector3<f64>,
        x_b: &Vector3<f64>,
    ) -> (Matrix3<f64>, Matrix3<f64>) {
        let predicted = unicycle_g(x_a, self.v, self.omega, self.dt);
        let (s, c) = x_a[2].sin_cos();
        let dx = x_b[0] - predicted[0];
        let dy = x_b[1] - predicted[1];
        let lambda = Matrix3::new(c, s, 0.0, -s, c, 0.0, 0.0, 0.0, 1.0);
        let mut j_a = -lambda * unicycle_jacobian_g(x_a, self.v, self.omega, self.dt);
        j_a[(0, 2)] += -s * dx + c * dy;
        j_a[(1, 2)] += -c * dx - s * dy;
        (j_a, lambda)
    }
}

/// One range-bearing reading of a landmark from a pose, with known correspondence.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ObservationFactor {
    /// Index of the observing pose.
    pub pose: usize,
    /// Index of the landmark in the graph (not the beacon id).
    pub landmark: usize,
    /// Measured range (m).
    pub range: f64,
    /// Measured bearing from the heading (rad).
    pub bearing: f64,
}

impl ObservationFactor {
    /// e = (h(x, m) − z) with the bearing wrapped (Thrun §11.2, eq. 11.5, h from §6.6); None when
    /// the landmark estimate sits on the pose (range < [`MIN_RANGE`]), where the bearing and
    /// the Jacobian are undefined and the factor is left out of that linearisation.
    pub fn residual(&self, pose: &Vector3<f64>, landmark: &Vector2<f64>) -> Option<Vector2<f64>> {
        let (dx, dy, q) = Self::offset(pose, landmark)?;
        Some(self.error(pose, dx, dy, q.sqrt()))
    }

    /// The residual and ∂e/∂x (H_t of Thrun §7.4) at once; ∂e/∂m is minus the first two
    /// columns of ∂e/∂x (Thrun §11.2, Table 11.2 line 17). None where [`Self::residual`] is.
    pub fn linearise(
        &self,
        pose: &Vector3<f64>,
        landmark: &Vector2<f64>,
    ) -> Option<(Vector2<f64>, Matrix2x3<f64>)> {
        let (dx, dy, q) = Self::offset(pose, landmark)?;
        let r = q.sqrt();
        Some((
            self.error(pose, dx, dy, r),
            range_bearing_jacobian_at(dx, dy, q, r),
        ))
    }

    /// The landmark's offset (dx, dy) from the pose and q = dx² + dy², None within
    /// [`MIN_RANGE`].
    fn offset(pose: &Vector3<f64>, landmark: &Vector2<f64>) -> Option<(f64, f64, f64)> {
        let (dx, dy) = (landmark[0] - pose[0], landmark[1] - pose[1]);
        let q = dx * dx + dy * dy;
        (q >= MIN_RANGE * MIN_RANGE).then_some((dx, dy, q))
    }

    /// h(x, m) − z (algorithms §6.6) from the offset and its length r = √q, not `hypot`: the
    /// ranges are metres, far from where √ over- or underflows, and hypot took a quarter of
    /// the linearisation's time.
    fn error(&self, pose: &Vector3<f64>, dx: f64, dy: f64, r: f64) -> Vector2<f64> {
        Vector2::new(
            r - self.range,
            wrap_angle(dy.atan2(dx) - pose[2] - self.bearing),
        )
    }
}

/// A position fix of one pose: z = (x, y) + δ, δ ~ N(0, σ²·I) (the linear reading of
/// algorithms §6.5 as a unary factor).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PositionFactor {
    /// Index of the pose.
    pub pose: usize,
    /// Measured position (m).
    pub position: Vector2<f64>,
    /// Ω = σ⁻²·I.
    pub information: Matrix2<f64>,
}

impl PositionFactor {
    /// ∂e/∂x = [I₂ 0]: the fix reads x and y, not θ.
    pub const JACOBIAN: Matrix2x3<f64> = Matrix2x3::new(1.0, 0.0, 0.0, 0.0, 1.0, 0.0);

    /// e = (x, y) of the pose − the fix.
    pub fn residual(&self, pose: &Vector3<f64>) -> Vector2<f64> {
        Vector2::new(pose[0] - self.position[0], pose[1] - self.position[1])
    }
}

/// Ω = Q⁻¹ of one range-bearing reading (Thrun §11.2, Table 11.2 line 13).
pub fn observation_information(noise: &NoiseModel) -> Matrix2<f64> {
    let q = noise.q_beacon();
    Matrix2::new(1.0 / q[(0, 0)], 0.0, 0.0, 1.0 / q[(1, 1)])
}

/// e = x₀ ⊖ prior (θ wrapped): the anchoring term of Thrun §11.2 (Table 11.2 line 2,
/// Ω₀ = diag(∞) there, a finite σ here) that fixes the gauge freedom (Grisetti et al. 2010 §IV-B).
pub fn prior_residual(pose: &Vector3<f64>, prior: &Vector3<f64>) -> Vector3<f64> {
    Vector3::new(
        pose[0] - prior[0],
        pose[1] - prior[1],
        wrap_angle(pose[2] - prior[2]),
    )
}
