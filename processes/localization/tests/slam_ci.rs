//! Covariance intersection: fusing two correlated estimates of a landmark is never worse than
//! either alone and stays consistent, where naive information fusion becomes over-confident.

use mole_localization::NoiseModel;
use mole_localization::slam::{EkfSlam, Landmark, SlamConfig, covariance_intersection};
use mole_types::{BeaconReading, Pose2};
use nalgebra::{Cholesky, DMatrix, Matrix2, Matrix3, Vector2};
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

/// `EkfSlam::fuse_landmarks` fuses shared ids by CI, leaves out ids it lacks, refuses garbage, and
/// leaves a finite symmetric state. The landmark block is the CI of the two estimates at some
/// ω < 1 (P_f⁻¹ = ω P_a⁻¹ + (1 − ω) P_b⁻¹, P_f⁻¹ m_f = ω P_a⁻¹ a + (1 − ω) P_b⁻¹ b): tighter
/// than the own one, pulled toward the other. That ω minimises the trace of the WHOLE state's
/// fused covariance, as the dense textbook CI update computes it on a grid of ω.
#[test]
fn fuse_landmarks_merges_by_id_leaves_unmapped_ones_and_refuses_garbage() {
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
    let sigma = slam.covariance().into_owned();
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
    assert_eq!(
        (report.fused, report.kept, report.unmapped, report.refused),
        (1, 0, 1, 2)
    );
    let fused = slam.landmark(0).unwrap();
    // The landmark block is a CI of the two estimates: recover its ω from the information.
    let inv = |p: &Matrix2<f64>| p.try_inverse().expect("invertible");
    let (ia, ib, i_f) = (inv(&own.cov), inv(&other[0].cov), inv(&fused.cov));
    let omega = (i_f - ib).dot(&(ia - ib)) / (ia - ib).norm_squared();
    assert!(omega > 0.0 && omega < 1.0, "ω = {omega}");
    let ci_info = ia * omega + ib * (1.0 - omega);
    assert!(
        (i_f - ci_info).norm() < 1e-6 * i_f.norm(),
        "{i_f} vs {ci_info}"
    );
    let ci_mean = ci_info.try_inverse().unwrap()
        * (ia * own.mean * omega + ib * other[0].mean * (1.0 - omega));
    assert!(
        (fused.mean - ci_mean).norm() < 1e-9,
        "{fused:?} vs {ci_mean}"
    );
    assert!(fused.cov.trace() < own.cov.trace(), "{fused:?} vs {own:?}");
    assert!(fused.mean[0] > own.mean[0] + 0.05, "{fused:?}");
    // And it is the ω of least whole-state trace: none on a grid does better.
    let best = whole_state_ci_trace(&sigma, 3, &other[0].cov, omega);
    assert!(best < sigma.trace(), "{best} vs {}", sigma.trace());
    for k in 1..100 {
        let w = f64::from(k) / 100.0;
        let t = whole_state_ci_trace(&sigma, 3, &other[0].cov, w);
        assert!(best <= t + 1e-9, "ω = {omega}: {best}; ω = {w}: {t}");
    }
    assert!(slam.landmark(2).is_none(), "landmark 7 was added");
    let cov = slam.covariance();
    assert!(cov.iter().all(|v| v.is_finite()));
    assert_eq!(cov.into_owned(), cov.transpose());
}

/// The trace of the dense textbook CI of a whole state (Σ) with an estimate (covariance `p_b`)
/// of the two components at `o`, at weight ω: Σ_f = Σ/ω − (Σ/ω)Hᵀ S⁻¹ H(Σ/ω),
/// S = HΣHᵀ/ω + P_b/(1 − ω).
fn whole_state_ci_trace(sigma: &DMatrix<f64>, o: usize, p_b: &Matrix2<f64>, omega: f64) -> f64 {
    let d = sigma.nrows();
    let mut h = DMatrix::zeros(2, d);
    h[(0, o)] = 1.0;
    h[(1, o + 1)] = 1.0;
    let inflated = sigma / omega;
    let p_b = DMatrix::from_column_slice(2, 2, p_b.as_slice());
    let s = &h * &inflated * h.transpose() + p_b / (1.0 - omega);
    let gain = &inflated * h.transpose() * s.try_inverse().expect("S invertible");
    (&inflated - gain * &h * &inflated).trace()
}

/// Fusing a peer's map of many shared landmarks, round after round (as two robots do every
/// second), never grows the trace of the state's covariance and keeps every landmark's
/// covariance positive definite. Weighting each landmark's CI by that landmark alone inflated
/// the whole state by 1/ω once per landmark: ten shared landmarks ran Σ away to ~1e13.
#[test]
fn repeated_fusion_of_a_many_landmark_map_never_grows_the_state_covariance() {
    let mut slam = EkfSlam::new(
        Pose2::default(),
        Matrix3::identity() * 1e-4,
        NoiseModel::new(0.1, 0.05, 0.05, 0.02, 0.5),
        16,
        SlamConfig::default(),
    );
    let readings: Vec<BeaconReading> = (0..10)
        .map(|i| BeaconReading {
            id: i,
            _pad: 0,
            range: 1.0 + 0.2 * f64::from(i),
            bearing: -2.5 + 0.5 * f64::from(i),
        })
        .collect();
    slam.correct(&readings);
    // The peer's estimates: twice as confident as ours, a few centimetres off.
    let peer: Vec<Landmark> = slam
        .landmarks()
        .map(|l| Landmark {
            mean: l.mean + Vector2::new(0.02, -0.01),
            cov: l.cov * 0.5,
            ..l
        })
        .collect();
    let mut trace = slam.covariance().trace();
    for round in 0..20 {
        let report = slam.fuse_landmarks(&peer);
        assert_eq!(report.fused + report.kept, 10, "round {round}: {report:?}");
        let now = slam.covariance().trace();
        assert!(
            now <= trace * (1.0 + 1e-9),
            "round {round}: tr Σ {trace} → {now}"
        );
        for l in slam.landmarks() {
            assert!(Cholesky::new(l.cov).is_some(), "round {round}: {l:?}");
        }
        trace = now;
    }
}
