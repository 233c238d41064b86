//! The Kalman correction step, generic over the state size N and the measurement size M, on
//! nalgebra's stack-allocated `SMatrix` (no allocation). The EKF (algorithms §6.6) calls it with its
//! linearised H_t; a linear KF (algorithms §6.5) calls it with C_t.

use nalgebra::{Cholesky, SMatrix, SVector};
use thiserror::Error;

/// χ² quantile at 99.9% for 1 degree of freedom.
pub const CHI2_999_1DOF: f64 = 10.827_566_170_662_733;
/// χ² quantile at 99.9% for 2 degrees of freedom, −2·ln(0.001).
pub const CHI2_999_2DOF: f64 = 13.815_510_557_964_274;
/// χ² quantile at 99.9% for 3 degrees of freedom.
pub const CHI2_999_3DOF: f64 = 16.266_236_196_238_13;

/// Why a correction was not applied; μ and Σ are then left as they were.
#[derive(Debug, Clone, Copy, PartialEq, Error)]
pub enum KalmanError {
    /// The innovation's squared Mahalanobis distance exceeds the χ² gate: an outlier.
    #[error("innovation gated: squared Mahalanobis distance {mahalanobis2} > {gate}")]
    Gated {
        /// νᵀ S⁻¹ ν.
        mahalanobis2: f64,
        /// The gate it was compared with.
        gate: f64,
    },
    /// The innovation covariance S = H Σ Hᵀ + Q is not positive definite.
    #[error("innovation covariance is not positive definite")]
    NotPositiveDefinite,
    /// The innovation, H or Q holds NaN or infinity.
    #[error("innovation, H or Q is not finite")]
    NotFinite,
}

/// Replaces `m` by (m + mᵀ)/2, so rounding never leaves Σ asymmetric.
#[inline]
pub fn symmetrize<const N: usize>(m: &mut SMatrix<f64, N, N>) {
    for r in 0..N {
        for c in (r + 1)..N {
            let a = 0.5 * (m[(r, c)] + m[(c, r)]);
            m[(r, c)] = a;
            m[(c, r)] = a;
        }
    }
}

/// One Kalman correction with innovation ν = z − h(μ̄) (algorithms §6.5/§6.6, correction step):
/// S = H Σ Hᵀ + Q, K = Σ Hᵀ S⁻¹, μ ← μ + K ν, and the covariance in Joseph form
/// Σ ← (I − K H) Σ (I − K H)ᵀ + K Q Kᵀ, symmetrised.
///
/// Deviation from the source's Σ ← (I − K H) Σ: the Joseph form is algebraically equal for the
/// optimal K but stays symmetric positive definite under rounding (Bucy & Joseph, 1968).
/// With `gate = Some(g)` a reading whose νᵀ S⁻¹ ν exceeds g is refused. Returns νᵀ S⁻¹ ν.
/// The caller wraps angle components of ν (and of μ afterwards); this function knows no angles.
pub fn kalman_correct<const N: usize, const M: usize>(
    mu: &mut SVector<f64, N>,
    sigma: &mut SMatrix<f64, N, N>,
    innovation: &SVector<f64, M>,
    h_t: &SMatrix<f64, M, N>,
    q_t: &SMatrix<f64, M, M>,
    gate: Option<f64>,
) -> Result<f64, KalmanError> {
    if !(innovation.iter().all(|v| v.is_finite())
        && h_t.iter().all(|v| v.is_finite())
        && q_t.iter().all(|v| v.is_finite()))
    {
        return Err(KalmanError::NotFinite);
    }
    let sigma_h_t = *sigma * h_t.transpose();
    let mut s_t = h_t * sigma_h_t + q_t;
    symmetrize(&mut s_t);
    let chol = Cholesky::new(s_t).ok_or(KalmanError::NotPositiveDefinite)?;
    let mahalanobis2 = innovation.dot(&chol.solve(innovation));
    if !mahalanobis2.is_finite() {
        return Err(KalmanError::NotPositiveDefinite);
    }
    if let Some(gate) = gate
        && mahalanobis2 > gate
    {
        return Err(KalmanError::Gated { mahalanobis2, gate });
    }
    // K = Σ Hᵀ S⁻¹ = (S⁻¹ H Σ)ᵀ, as S and Σ are symmetric.
    let k_gain: SMatrix<f64, N, M> = chol.solve(&sigma_h_t.transpose()).transpose();
    *mu += k_gain * innovation;
    let i_kh = SMatrix::<f64, N, N>::identity() - k_gain * h_t;
    *sigma = i_kh * *sigma * i_kh.transpose() + k_gain * q_t * k_gain.transpose();
    symmetrize(sigma);
    Ok(mahalanobis2)
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;
    use nalgebra::{Matrix1, Matrix2, Matrix2x3, Matrix3, Vector1, Vector2, Vector3};

    #[test]
    fn chi2_quantiles_match_the_closed_form_for_two_dof() {
        assert_relative_eq!(CHI2_999_2DOF, -2.0 * 0.001f64.ln(), epsilon = 1e-12);
    }

    #[test]
    fn scalar_update_matches_the_textbook_formula() {
        // Prior N(1, 4), reading 3 with variance 1: K = 4/5, μ = 1 + 0.8·2 = 2.6, σ² = 0.8.
        let mut mu = Vector1::new(1.0);
        let mut sigma = Matrix1::new(4.0);
        let d2 = kalman_correct(
            &mut mu,
            &mut sigma,
            &Vector1::new(2.0),
            &Matrix1::new(1.0),
            &Matrix1::new(1.0),
            None,
        )
        .unwrap();
        assert_relative_eq!(mu[0], 2.6, epsilon = 1e-12);
        assert_relative_eq!(sigma[(0, 0)], 0.8, epsilon = 1e-12);
        assert_relative_eq!(d2, 4.0 / 5.0, epsilon = 1e-12);
    }

    #[test]
    fn joseph_form_equals_the_source_form_for_the_optimal_gain() {
        let mut mu = Vector3::new(1.0, 2.0, 0.1);
        let mut sigma = Matrix3::new(0.5, 0.1, 0.02, 0.1, 0.4, -0.03, 0.02, -0.03, 0.2);
        let h_t = Matrix2x3::new(0.6, -0.8, 0.0, 0.16, 0.12, -1.0);
        let q_t = Matrix2::new(0.01, 0.0, 0.0, 0.004);
        let nu = Vector2::new(0.3, -0.05);
        // The source's form, computed directly.
        let s = h_t * sigma * h_t.transpose() + q_t;
        let k = sigma * h_t.transpose() * s.try_inverse().unwrap();
        let mu_seed = mu + k * nu;
        let sigma_seed = (Matrix3::identity() - k * h_t) * sigma;
        kalman_correct(&mut mu, &mut sigma, &nu, &h_t, &q_t, None).unwrap();
        assert_relative_eq!(mu, mu_seed, epsilon = 1e-12);
        assert_relative_eq!(sigma, sigma_seed, epsilon = 1e-12);
        assert_eq!(sigma, sigma.transpose());
    }

    #[test]
    fn gated_and_degenerate_readings_leave_the_state_alone() {
        let mu0 = Vector2::new(0.0, 0.0);
        let sigma0 = Matrix2::identity() * 0.01;
        let (mut mu, mut sigma) = (mu0, sigma0);
        let h_t = Matrix2::identity();
        let q_t = Matrix2::identity() * 0.01;
        // ν = (1, 0): νᵀ S⁻¹ ν = 1/0.02 = 50 > 13.8.
        let r = kalman_correct(
            &mut mu,
            &mut sigma,
            &Vector2::new(1.0, 0.0),
            &h_t,
            &q_t,
            Some(CHI2_999_2DOF),
        );
        assert!(
            matches!(r, Err(KalmanError::Gated { mahalanobis2, .. }) if (mahalanobis2 - 50.0).abs() < 1e-9)
        );
        assert_eq!((mu, sigma), (mu0, sigma0));
        let r = kalman_correct(
            &mut mu,
            &mut sigma,
            &Vector2::new(f64::NAN, 0.0),
            &h_t,
            &q_t,
            None,
        );
        assert_eq!(r, Err(KalmanError::NotFinite));
        let r = kalman_correct(
            &mut mu,
            &mut sigma,
            &Vector2::new(0.1, 0.0),
            &h_t,
            &(-q_t * 10.0),
            None,
        );
        assert_eq!(r, Err(KalmanError::NotPositiveDefinite));
        assert_eq!((mu, sigma), (mu0, sigma0));
    }
}
