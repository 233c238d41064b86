//! Garbage in never poisons an estimator: every estimator takes arbitrary odometry, beacon
//! readings (NaN, infinities, absurd but finite values, unknown ids, counts above capacity) and
//! fixes (bad flags, NaN) in any order, and after every step still publishes a finite pose and a
//! finite covariance; the histogram's belief stays a distribution, the PF's weights stay
//! normalised and the SLAM estimators' landmarks pass the message's own validation. Odometry no robot could produce is ignored and counted, and leaves the pose alone.

use mole_localization::models::{MAX_ODOM_DT, MAX_ODOM_SPEED, MAX_ODOM_TURN_RATE};
use mole_localization::{
    BayesConfig, Ekf, EkfSlamEstimator, Estimator, FastSlamEstimator, GraphSlamEstimator,
    HistogramFilter, Kf, ParticleFilter, PfConfig, Readings,
};
use mole_types::{
    BeaconReading, Beacons, Fix, Landmarks, Message, Odom, Particles, Pose, WorldMap,
};
use proptest::prelude::*;

#[path = "common/garbage.rs"]
mod garbage_values;
use garbage_values::any_f64;

fn map() -> Box<WorldMap> {
    let mut m: Box<WorldMap> = bytemuck::zeroed_box();
    m.arena_width = 4.0;
    m.arena_height = 3.0;
    m.dt = 0.01;
    m.seed = 9;
    m.start_x = 1.0;
    m.start_y = 1.0;
    m.sensors.odom_v_std = 0.05;
    m.sensors.beacon_range_std = 0.05;
    m.sensors.beacon_bearing_std = 0.02;
    m.sensors.fix_std = 0.3;
    m.place_beacons(&[(0.5, 2.5), (3.5, 0.5)]);
    m
}

/// The PF with fewer particles and a coarse histogram keep the debug run fast; the code paths
/// are those of the defaults.
fn small_pf(map: &WorldMap) -> ParticleFilter {
    ParticleFilter::from_map_with(
        map,
        PfConfig {
            n_particles: 500,
            ..Default::default()
        },
    )
}

fn coarse_histogram(map: &WorldMap) -> HistogramFilter {
    HistogramFilter::from_map_with(
        map,
        BayesConfig {
            cell_size: 0.25,
            heading_bins: 8,
            ..Default::default()
        },
    )
}

#[derive(Debug, Clone)]
enum Op {
    Predict(f64, f64, f64),
    Correct(Vec<(u32, f64, f64)>, u32, (f64, f64, f64, u32)),
}

fn op() -> impl Strategy<Value = Op> {
    prop_oneof![
        (any_f64(), any_f64(), any_f64()).prop_map(|(v, w, dt)| Op::Predict(v, w, dt)),
        (
            prop::collection::vec((0u32..40, any_f64(), any_f64()), 0..6),
            prop_oneof![Just(u32::MAX), 0u32..40],
            (any_f64(), any_f64(), any_f64(), 0u32..4),
        )
            .prop_map(|(r, n, f)| Op::Correct(r, n, f)),
    ]
}

/// The published summary is usable: a finite pose and a finite covariance.
fn check_summary(name: &str, est: &dyn Estimator) -> Result<(), TestCaseError> {
    let p = est.pose();
    prop_assert!(
        p.x.is_finite() && p.y.is_finite() && p.theta.is_finite(),
        "{name}: pose {p:?}"
    );
    let c = est.covariance();
    prop_assert!(c.iter().all(|v| v.is_finite()), "{name}: covariance {c:?}");
    let mut out: Pose = bytemuck::Zeroable::zeroed();
    est.write_pose(&mut out);
    prop_assert!(
        out.x.is_finite() && out.y.is_finite() && out.theta.is_finite(),
        "{name}: published pose {out:?}"
    );
    Ok(())
}

/// A SLAM estimator's summary is usable and its landmarks message passes validation.
fn check_slam(name: &str, est: &dyn Estimator) -> Result<(), TestCaseError> {
    check_summary(name, est)?;
    let mut out: Box<Landmarks> = bytemuck::zeroed_box();
    prop_assert!(
        est.write_landmarks(&mut out),
        "{name}: no landmarks written"
    );
    prop_assert!(out.validate().is_ok(), "{name}: {:?}", out.validate());
    Ok(())
}

/// The histogram's belief is a distribution: every cell finite and ≥ 0, Σ Bel = 1 within 1e-9.
fn check_belief(f: &HistogramFilter) -> Result<(), TestCaseError> {
    let bel = f.belief();
    prop_assert!(
        bel.iter().all(|p| p.is_finite() && *p >= 0.0),
        "bayes: a cell is negative or not finite"
    );
    let s: f64 = bel.iter().sum();
    prop_assert!((s - 1.0).abs() < 1e-9, "bayes: Σ Bel = {}", s);
    Ok(())
}

/// The PF's weights are normalised: every w finite and ≥ 0, Σ w = 1 within 1e-9.
fn check_weights(pf: &ParticleFilter) -> Result<(), TestCaseError> {
    let w = pf.weights();
    prop_assert!(
        w.iter().all(|w| w.is_finite() && *w >= 0.0),
        "pf: a weight is negative or not finite"
    );
    let s: f64 = w.iter().sum();
    prop_assert!((s - 1.0).abs() < 1e-9, "pf: Σ w = {}", s);
    Ok(())
}

/// Feeds `ops` to `est` and runs `check` after every one of them.
fn run<E: Estimator>(
    est: &mut E,
    ops: &[Op],
    check: impl Fn(&E) -> Result<(), TestCaseError>,
) -> Result<(), TestCaseError> {
    let mut beacons: Box<Beacons> = bytemuck::zeroed_box();
    let mut fix: Fix = bytemuck::Zeroable::zeroed();
    let mut odom: Odom = bytemuck::Zeroable::zeroed();
    let mut particles: Box<Particles> = bytemuck::zeroed_box();
    for op in ops {
        match op {
            Op::Predict(v, w, dt) => {
                (odom.v, odom.omega, odom.dt) = (*v, *w, *dt);
                est.predict(&odom);
            }
            Op::Correct(readings, n, (x, y, std, valid)) => {
                for (i, &(id, range, bearing)) in readings.iter().enumerate() {
                    beacons.readings[i] = BeaconReading {
                        id,
                        _pad: 0,
                        range,
                        bearing,
                    };
                }
                beacons.n_readings = if *n == u32::MAX {
                    readings.len() as u32
                } else {
                    *n
                };
                (fix.x, fix.y, fix.std, fix.valid) = (*x, *y, *std, *valid);
                est.correct(
                    &Readings::of(&odom)
                        .with_beacons(Some(&beacons))
                        .with_fix(Some(&fix)),
                );
            }
        }
        est.write_particles(&mut particles);
        check(est)?;
    }
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]
    /// Whatever arrives, every estimator's output stays finite and its belief normalised.
    #[test]
    fn garbage_never_poisons_an_estimator(ops in prop::collection::vec(op(), 1..25)) {
        let map = map();
        run(&mut Kf::from_map(&map), &ops, |e| check_summary("kf", e))?;
        run(&mut Ekf::from_map(&map), &ops, |e| check_summary("ekf", e))?;
        run(&mut small_pf(&map), &ops, |pf| {
            check_summary("pf", pf)?;
            check_weights(pf)
        })?;
        run(&mut coarse_histogram(&map), &ops, |f| {
            check_summary("bayes", f)?;
            check_belief(f)
        })?;
        run(&mut EkfSlamEstimator::from_map(&map), &ops, |e| check_slam("ekf-slam", e))?;
        run(&mut FastSlamEstimator::from_map(&map), &ops, |e| check_slam("fastslam", e))?;
        let mut graph = GraphSlamEstimator::from_map(&map).expect("smoother thread starts");
        run(&mut graph, &ops, |e| check_slam("graph-slam", e))?;
        graph.settle();
        check_slam("graph-slam settled", &graph)?;
    }
}

/// Odometry that is finite but no robot produces: (v m/s, ω rad/s, dt s).
const ABSURD_ODOMETRY: [(f64, f64, f64); 9] = [
    (1e300, 0.0, 0.01),
    (-1e300, 0.0, 0.01),
    (0.0, 1e300, 0.01),
    (0.3, 0.2, 1e300),
    (1e300, 1e300, 1e300),
    (1e6, 0.0, 0.01),
    (0.0, -1e6, 0.01),
    (0.3, 0.2, 1e6),
    (
        MAX_ODOM_SPEED * 1.01,
        MAX_ODOM_TURN_RATE * 1.01,
        MAX_ODOM_DT * 1.01,
    ),
];

/// Each absurd odometry reading is ignored and counted, leaves the pose where it was, and the
/// estimator still follows plausible odometry afterwards.
fn absurd_odometry_is_ignored(name: &str, est: &mut dyn Estimator) {
    let mut odom: Odom = bytemuck::Zeroable::zeroed();
    for (i, &(v, omega, dt)) in ABSURD_ODOMETRY.iter().enumerate() {
        let (before, ignored) = (est.pose(), est.ignored());
        (odom.v, odom.omega, odom.dt) = (v, omega, dt);
        est.predict(&odom);
        assert_eq!(
            est.ignored(),
            ignored + 1,
            "{name}: odometry #{i} ({v:e}, {omega:e}, {dt:e}) was not ignored"
        );
        assert_eq!(
            est.pose(),
            before,
            "{name}: odometry #{i} ({v:e}, {omega:e}, {dt:e}) moved the pose"
        );
        check_summary(name, est).unwrap_or_else(|e| panic!("{e}"));
    }
    // The robot at (1, 1) facing +x drives 0.5 m: the estimate follows.
    let ignored = est.ignored();
    (odom.v, odom.omega, odom.dt) = (0.5, 0.0, 0.01);
    for _ in 0..100 {
        est.predict(&odom);
    }
    assert_eq!(est.ignored(), ignored, "{name}: plausible odometry ignored");
    let p = est.pose();
    assert!(
        (p.x - 1.5).abs() < 0.1 && (p.y - 1.0).abs() < 0.1,
        "{name}: {p:?} after 0.5 m along +x from (1, 1)"
    );
}

#[test]
fn absurd_odometry_is_ignored_by_every_estimator() {
    let map = map();
    absurd_odometry_is_ignored("kf", &mut Kf::from_map(&map));
    absurd_odometry_is_ignored("ekf", &mut Ekf::from_map(&map));
    let mut pf = small_pf(&map);
    absurd_odometry_is_ignored("pf", &mut pf);
    check_weights(&pf).unwrap_or_else(|e| panic!("{e}"));
    let mut bayes = coarse_histogram(&map);
    absurd_odometry_is_ignored("bayes", &mut bayes);
    check_belief(&bayes).unwrap_or_else(|e| panic!("{e}"));
    absurd_odometry_is_ignored("ekf-slam", &mut EkfSlamEstimator::from_map(&map));
    absurd_odometry_is_ignored("fastslam", &mut FastSlamEstimator::from_map(&map));
    let mut graph = GraphSlamEstimator::from_map(&map).expect("smoother thread starts");
    absurd_odometry_is_ignored("graph-slam", &mut graph);
}

#[test]
fn odometry_at_the_bounds_is_used() {
    let map = map();
    let mut odom: Odom = bytemuck::Zeroable::zeroed();
    (odom.v, odom.omega, odom.dt) = (-MAX_ODOM_SPEED, MAX_ODOM_TURN_RATE, MAX_ODOM_DT);
    let mut kf = Kf::from_map(&map);
    let mut ekf = Ekf::from_map(&map);
    let mut pf = small_pf(&map);
    let mut bayes = coarse_histogram(&map);
    for (name, est) in [
        ("kf", &mut kf as &mut dyn Estimator),
        ("ekf", &mut ekf),
        ("pf", &mut pf),
        ("bayes", &mut bayes),
    ] {
        est.predict(&odom);
        assert_eq!(est.ignored(), 0, "{name}: odometry at the bounds ignored");
        check_summary(name, est).unwrap_or_else(|e| panic!("{e}"));
    }
    check_weights(&pf).unwrap_or_else(|e| panic!("{e}"));
    check_belief(&bayes).unwrap_or_else(|e| panic!("{e}"));
}
