//! Covariance intersection: fusing two correlated estimates of a landmark is never worse than
//! either alone and stays consistent, where naive information fusion becomes over-confident.

use mole_localization::NoiseModel;
use mole_localization::slam::{EkfSlam, Landmark, SlamConfig, covariance_intersection};
use mole_types::{BeaconReading, Pose2};
use nalgebra::{Cholesky, Matrix2, Matrix3, Vector2};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use statrs::distribution::{ChiSquared, ContinuousCDF};

/// Seeded trials.
const TRIALS: usize = 2000;

/// A draw from N(0, p).
fn draw(rng: &mut ChaCha8Rng, p: &Matrix2<f64>) -> Vector2<f64> {
    let l = Cholesky::new(*p).expect("positive definite").l();
    l * Vector2::new(rng.sample(StandardNormal), rng.sample(StandardNormal))
}

/// The landmark's true position.
fn truth() -> Vector2<f64> {
    Vector2::new(3.0, -2.0)
}

/// Mean squared error and mean NEES of an estimator over the trials.
#[derive(Debug, Default, Clone, Copy)]
struct Tally {
    sq_error: f64,
    nees: f64,
}

impl Tally {
    fn add(&mut self, est: &Vector2<f64>, cov: &Matrix2<f64>) {
        let e = est - truth();
        self.sq_error += e.norm_squared() / TRIALS as f64;
        let inv = cov.try_inverse().expect("invertible");
        self.nees += e.dot(&(inv * e)) / TRIALS as f64;
    }
}

/// Two estimates of a landmark share an error c ~ N(0, P_c) (e.g. the same
/// odometry) plus independent errors crossed in direction: a = c + e_a, b = c + e_b, each
/// reported with its own (consistent) P_c + P_e. CI's squared error is no worse than either
/// input's, its average NEES is below the χ² 95% upper bound; the naive information sum
/// P = (P_a⁻¹ + P_b⁻¹)⁻¹, which assumes independence, is over the bound.
#[test]
fn ci_is_consistent_on_correlated_estimates_where_naive_fusion_is_not() {
    let p_c = Matrix2::new(0.3, 0.1, 0.1, 0.3);
    let (p_ea, p_eb) = (
        Matrix2::new(1.0, 0.0, 0.0, 0.05),
        Matrix2::new(0.05, 0.0, 0.0, 1.0),
    );
    let (pa, pb) = (p_c + p_ea, p_c + p_eb);
    let mut rng = ChaCha8Rng::seed_from_u64(42);
    let (mut ta, mut tb, mut tci, mut tnaive) = [Tally::default(); 4].into();
    for _ in 0..TRIALS {
        let c = draw(&mut rng, &p_c);
        let a = truth() + c + draw(&mut rng, &p_ea);
        let b = truth() + c + draw(&mut rng, &p_eb);
        ta.add(&a, &pa);
        tb.add(&b, &pb);
        let f = covariance_intersection(&a, &pa, &b, &pb).expect("valid inputs");
        tci.add(&f.mean, &f.cov);
        let (ia, ib) = (pa.try_inverse().unwrap(), pb.try_inverse().unwrap());
        let p_naive = (ia + ib).try_inverse().unwrap();
        tnaive.add(&(p_naive * (ia * a + ib * b)), &p_naive);
    }
    let hi = ChiSquared::new(2.0 * TRIALS as f64)
        .unwrap()
        .inverse_cdf(0.975)
        / TRIALS as f64;
    println!("a {ta:?}\nb {tb:?}\nCI {tci:?}\nnaive {tnaive:?}\nNEES upper bound {hi:.3}");
    assert!(
        tci.sq_error <= ta.sq_error.min(tb.sq_error),
        "CI {tci:?}, a {ta:?}, b {tb:?}"
    );
    assert!(tci.nees <= hi, "CI over-confident: {tci:?}");
    assert!(
        tnaive.nees > hi,
        "naive fusion consistent after all: {tnaive:?}"
    );
}

/// `EkfSlam::fuse_landmarks` fuses shared ids by CI (the landmark block becomes the CI of the
/// two estimates: tighter than the own one, pulled toward the other), adds ids it lacks, refuses garbage, and leaves a
/// finite symmetric state.
#[test]
fn fuse_landmarks_merges_by_id_adds_new_ones_and_refuses_garbage() {
    let mut slam = EkfSlam::new(
        Pose2::default(),
        Matrix3::identity() * 1e-4,
        NoiseModel::new(0.1, 0.05, 0.3, 0.05, 0.5),
        4,
        SlamConfig::default(),
    );
    let reading = |id, range, bearing| BeaconReading {
        id,
        _pad: 0,
        range,
        bearing,
    };
    slam.correct(&[reading(1, 5.0, 0.0), reading(2, 5.0, 1.5)]);
    let own = slam.landmark(0).expect("landmark 1");
    let other = [
        // A tight estimate of landmark 1 across its range direction.
        Landmark {
            id: 1,
            mean: Vector2::new(5.2, 0.1),
            cov: Matrix2::new(0.01, 0.0, 0.0, 0.5),
        },
        Landmark {
            id: 7,
            mean: Vector2::new(-3.0, 2.0),
            cov: Matrix2::identity() * 0.2,
        },
        Landmark {
            id: 2,
            mean: Vector2::new(f64::NAN, 0.0),
            cov: Matrix2::identity(),
        },
        Landmark {
            id: 3,
            mean: Vector2::zeros(),
            cov: -Matrix2::identity(),
        },
    ];
    let report = slam.fuse_landmarks(&other);
    assert_eq!((report.fused, report.added, report.refused), (1, 1, 2));
    let fused = slam.landmark(0).unwrap();
    // The landmark block is exactly the CI of the two estimates.
    let ci = covariance_intersection(&own.mean, &own.cov, &other[0].mean, &other[0].cov).unwrap();
    assert!((fused.mean - ci.mean).norm() < 1e-9, "{fused:?} vs {ci:?}");
    assert!((fused.cov - ci.cov).norm() < 1e-9, "{fused:?} vs {ci:?}");
    assert!(fused.cov.trace() < own.cov.trace(), "{fused:?} vs {own:?}");
    assert!(fused.mean[0] > own.mean[0] + 0.05, "{fused:?}");
    let added = slam.landmark(2).unwrap();
    assert_eq!(
        (added.id, added.mean, added.cov),
        (7, other[1].mean, other[1].cov)
    );
    let cov = slam.covariance();
    assert!(cov.iter().all(|v| v.is_finite()));
    assert_eq!(cov.into_owned(), cov.transpose());
}
