//! Covariance intersection (Julier & Uhlmann 1997): fusing two estimates of the same quantity
//! whose cross-correlation is unknown, e.g. two robots' maps built from shared odometry or
//! shared readings, without ever becoming over-confident.

use nalgebra::{Cholesky, SMatrix, SVector};

/// Golden-section iterations: the bracket shrinks by 0.618 each, to ~1e-13 after 60.
const GOLDEN_ITERATIONS: usize = 60;

/// A fused estimate N(mean, cov) and the weight ω ∈ [0, 1] given to the first input.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Fused<const N: usize> {
    /// Fused mean.
    pub mean: SVector<f64, N>,
    /// Fused covariance.
    pub cov: SMatrix<f64, N, N>,
    /// ω: the weight of the first estimate's information.
    pub omega: f64,
}

/// CI of (a, P_a) and (b, P_b) for one ω (Julier & Uhlmann 1997, eq. 5–6):
/// P⁻¹ = ω P_a⁻¹ + (1 − ω) P_b⁻¹, P⁻¹ c = ω P_a⁻¹ a + (1 − ω) P_b⁻¹ b.
fn fuse_at<const N: usize>(
    omega: f64,
    a: &SVector<f64, N>,
    ia: &SMatrix<f64, N, N>,
    b: &SVector<f64, N>,
    ib: &SMatrix<f64, N, N>,
) -> Option<(SVector<f64, N>, SMatrix<f64, N, N>)> {
    let info = ia * omega + ib * (1.0 - omega);
    let chol = Cholesky::new(info)?;
    let mean = chol.solve(&(ia * a * omega + ib * b * (1.0 - omega)));
    let mut cov = chol.inverse();
    cov = (cov + cov.transpose()) * 0.5;
    Some((mean, cov))
}

/// Covariance intersection of two estimates of the same quantity with unknown correlation
/// (Julier & Uhlmann 1997): ω ∈ [0, 1] minimises tr P(ω), a convex function of ω (Reinhardt,
/// Noack & Hanebeck 2012), found by golden-section search and compared with both ends. The
/// result is consistent for every cross-correlation of the inputs. `None` when an input is not
/// finite or a covariance is not positive definite.
pub fn covariance_intersection<const N: usize>(
    a: &SVector<f64, N>,
    pa: &SMatrix<f64, N, N>,
    b: &SVector<f64, N>,
    pb: &SMatrix<f64, N, N>,
) -> Option<Fused<N>> {
    let finite = a.iter().chain(pa.iter()).chain(b.iter()).chain(pb.iter());
    if !finite.into_iter().all(|v| v.is_finite()) {
        return None;
    }
    let ia = Cholesky::new(*pa)?.inverse();
    let ib = Cholesky::new(*pb)?.inverse();
    let omega = argmin_on_unit_interval(|omega: f64| {
        fuse_at(omega, a, &ia, b, &ib).map_or(f64::INFINITY, |f| f.1.trace())
    });
    let (mean, cov) = fuse_at(omega, a, &ia, b, &ib)?;
    Some(Fused { mean, cov, omega })
}

/// The ω ∈ [0, 1] that minimises `f`, a convex function (∞ where undefined): golden-section
/// search inside, compared with both ends (the optimum is often an end: one estimate alone).
pub(crate) fn argmin_on_unit_interval(f: impl Fn(f64) -> f64) -> f64 {
    let inv_phi = (5f64.sqrt() - 1.0) / 2.0;
    let (mut lo, mut hi) = (0.0, 1.0);
    let (mut x1, mut x2) = (hi - inv_phi * (hi - lo), lo + inv_phi * (hi - lo));
    let (mut f1, mut f2) = (f(x1), f(x2));
    for _ in 0..GOLDEN_ITERATIONS {
        if f1 <= f2 {
            hi = x2;
            (x2, f2) = (x1, f1);
            x1 = hi - inv_phi * (hi - lo);
            f1 = f(x1);
        } else {
            lo = x1;
            (x1, f1) = (x2, f2);
            x2 = lo + inv_phi * (hi - lo);
            f2 = f(x2);
        }
    }
    let inner = 0.5 * (lo + hi);
    [0.0, inner, 1.0]
        .into_iter()
        .min_by(|&p, &q| f(p).total_cmp(&f(q)))
        .unwrap_or(inner)
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;
    use nalgebra::{Matrix2, Vector2};

    #[test]
    fn equal_isotropic_estimates_share_the_weight_and_keep_the_covariance() {
        let p = Matrix2::identity() * 0.5;
        let f = covariance_intersection(&Vector2::new(0.0, 0.0), &p, &Vector2::new(2.0, 0.0), &p)
            .unwrap();
        // Any ω gives P; the mean is the ω-weighted average. CI never claims more than P here.
        assert_relative_eq!(f.cov, p, epsilon = 1e-9);
        assert_relative_eq!(f.mean[0], 2.0 * (1.0 - f.omega), epsilon = 1e-9);
    }

    #[test]
    fn a_much_better_estimate_takes_all_the_weight() {
        let f = covariance_intersection(
            &Vector2::new(1.0, 1.0),
            &(Matrix2::identity() * 0.01),
            &Vector2::new(0.0, 0.0),
            &(Matrix2::identity() * 4.0),
        )
        .unwrap();
        assert_eq!(f.omega, 1.0);
        assert_relative_eq!(f.mean, Vector2::new(1.0, 1.0), epsilon = 1e-12);
    }

    #[test]
    fn crossed_ellipses_fuse_tighter_than_either_and_omega_is_the_trace_minimum() {
        let pa = Matrix2::new(4.0, 0.0, 0.0, 0.1);
        let pb = Matrix2::new(0.1, 0.0, 0.0, 4.0);
        let (a, b) = (Vector2::new(0.0, 0.0), Vector2::new(1.0, 1.0));
        let f = covariance_intersection(&a, &pa, &b, &pb).unwrap();
        assert_relative_eq!(f.omega, 0.5, epsilon = 1e-6);
        assert!(f.cov.trace() < pa.trace().min(pb.trace()));
        let ia = pa.try_inverse().unwrap();
        let ib = pb.try_inverse().unwrap();
        for omega in [0.3, 0.45, 0.55, 0.7] {
            let other = fuse_at(omega, &a, &ia, &b, &ib).unwrap().1.trace();
            assert!(f.cov.trace() <= other + 1e-12);
        }
        assert!(covariance_intersection(&a, &(-pa), &b, &pb).is_none());
        assert!(covariance_intersection(&Vector2::new(f64::NAN, 0.0), &pa, &b, &pb).is_none());
    }
}
