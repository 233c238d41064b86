use super::*;
use mole_types::Header;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

fn noise() -> NoiseModel {
    NoiseModel::new(0.05, 0.05, 0.05, 0.02, 0.5)
}

fn site(x: f64, y: f64, id: u32) -> BeaconSite {
    BeaconSite { x, y, id, _pad: 0 }
}

fn sum(f: &HistogramFilter) -> f64 {
    f.belief().iter().sum()
}

fn no_fix() -> Fix {
    bytemuck::Zeroable::zeroed()
}

#[test]
fn grid_is_capped_and_the_belief_starts_normalised_at_the_start() {
    let f = HistogramFilter::new(
        50.0,
        10.0,
        Pose2::new(3.0, 4.0, 1.0),
        BayesConfig::default(),
        noise(),
        &[],
    );
    // 50 m / 200 cells: the cell grows to 0.25 m.
    assert_eq!(f.dims(), (200, 40, 16));
    assert!((f.cell_size() - 0.25).abs() < 1e-12);
    assert!((sum(&f) - 1.0).abs() < 1e-9);
    let p = f.pose();
    assert!(
        (p.x - 3.0).abs() < 1e-9 && (p.y - 4.0).abs() < 1e-9,
        "{p:?}"
    );
    assert!((p.theta - 1.0).abs() < 1e-9, "{p:?}");
    // A garbage arena and start give a 1 m uniform grid, still normalised.
    let g = HistogramFilter::new(
        f64::NAN,
        -1.0,
        Pose2::new(f64::NAN, 0.0, 0.0),
        BayesConfig::default(),
        noise(),
        &[],
    );
    assert_eq!(g.dims(), (10, 10, 16));
    assert!((sum(&g) - 1.0).abs() < 1e-9);
}

#[test]
fn prediction_moves_the_mean_along_each_heading_and_turns() {
    let mut f = HistogramFilter::new(
        10.0,
        10.0,
        Pose2::new(2.0, 2.0, 0.0),
        BayesConfig::default(),
        noise(),
        &[],
    );
    // 2 m along +x at 1 m/s, 100 Hz.
    for _ in 0..200 {
        f.predict_with(1.0, 0.0, 0.01).unwrap();
        assert!((sum(&f) - 1.0).abs() < 1e-9);
    }
    let p = f.pose();
    assert!((p.x - 4.0).abs() < 0.02, "{p:?}");
    assert!((p.y - 2.0).abs() < 0.02, "{p:?}");
    // A quarter turn on the spot, then 1 m along +y.
    for _ in 0..100 {
        f.predict_with(0.0, core::f64::consts::FRAC_PI_2, 0.01)
            .unwrap();
    }
    assert!((f.pose().theta - core::f64::consts::FRAC_PI_2).abs() < 0.02);
    for _ in 0..100 {
        f.predict_with(1.0, 0.0, 0.01).unwrap();
    }
    let p = f.pose();
    assert!((p.x - 4.0).abs() < 0.05, "{p:?}");
    assert!((p.y - 3.0).abs() < 0.05, "{p:?}");
    // The motion noise widened the belief.
    assert!(f.covariance()[0] > 0.1 * 0.1 / 12.0);
}

/// A 20 m × 1 m corridor with one beacon at its west end; the robot starts at an unknown place
/// (uniform belief) and drives east with noisy odometry, seeing the beacon every step.
#[test]
fn corridor_belief_concentrates_on_the_true_cell() {
    let beacon = (0.0, 0.5);
    let mut f = HistogramFilter::new(
        20.0,
        1.0,
        Pose2::new(0.0, 0.0, 0.0),
        BayesConfig {
            uniform_prior: true,
            ..BayesConfig::default()
        },
        noise(),
        &[site(beacon.0, beacon.1, 0)],
    );
    assert!((sum(&f) - 1.0).abs() < 1e-9);
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let mut g = || -> f64 { StandardNormal.sample(&mut rng) };
    let (mut x, y, theta) = (5.03, 0.52, 0.0);
    let mut beacons: Box<Beacons> = bytemuck::zeroed_box();
    beacons.n_readings = 1;
    let dt = 0.01;
    for _ in 0..300 {
        x += 1.0 * dt;
        let odom = Odom {
            header: Header::default(),
            x: 0.0,
            y: 0.0,
            theta: 0.0,
            v: 1.0 + 0.05 * g(),
            omega: 0.05 * g(),
            dt,
        };
        let (dx, dy) = (beacon.0 - x, beacon.1 - y);
        beacons.readings[0] = BeaconReading {
            id: 0,
            _pad: 0,
            range: dx.hypot(dy) + 0.05 * g(),
            bearing: wrap_angle(dy.atan2(dx) - theta + 0.02 * g()),
        };
        f.step(
            &Readings::of(&odom)
                .with_beacons(Some(&beacons))
                .with_fix(Some(&no_fix())),
        );
        assert!((sum(&f) - 1.0).abs() < 1e-9, "Σ Bel = {}", sum(&f));
    }
    let (ix, iy, k) = f.argmax();
    let (tx, ty) = f.cell_of(x, y).unwrap();
    assert!(
        ix.abs_diff(tx) <= 1 && iy.abs_diff(ty) <= 1,
        "max at ({ix}, {iy}), truth in ({tx}, {ty})"
    );
    assert!(k == 0 || k == 15, "heading bin {k}");
    let p = f.pose();
    assert!((p.x - x).abs() < 0.1, "{p:?} vs x = {x}");
    assert!(wrap_angle(p.theta - theta).abs() < 0.1, "{p:?}");
}

#[test]
fn a_fix_pulls_the_belief_and_garbage_is_ignored() {
    let mut f = HistogramFilter::new(
        10.0,
        10.0,
        Pose2::new(5.0, 5.0, 0.0),
        BayesConfig {
            uniform_prior: true,
            ..BayesConfig::default()
        },
        noise(),
        &[site(1.0, 1.0, 4)],
    );
    let mut fix = no_fix();
    fix.valid = 1;
    fix.x = 7.0;
    fix.y = 2.0;
    fix.std = 0.1;
    let mut beacons: Box<Beacons> = bytemuck::zeroed_box();
    assert_eq!(f.apply_correction(Some(&beacons), Some(&fix)), 1);
    let p = f.pose();
    assert!(
        (p.x - 7.0).abs() < 0.02 && (p.y - 2.0).abs() < 0.02,
        "{p:?}"
    );
    let before = f.belief().to_vec();
    // Unknown id, NaN range, bad flag, NaN fix, count above capacity: nothing used.
    beacons.n_readings = 2;
    beacons.readings[0] = BeaconReading {
        id: 9,
        _pad: 0,
        range: 1.0,
        bearing: 0.0,
    };
    beacons.readings[1] = BeaconReading {
        id: 4,
        _pad: 0,
        range: f64::NAN,
        bearing: 0.0,
    };
    fix.valid = 3;
    assert_eq!(f.apply_correction(Some(&beacons), Some(&fix)), 0);
    fix.valid = 1;
    fix.x = f64::INFINITY;
    assert_eq!(f.apply_correction(Some(&beacons), Some(&fix)), 0);
    assert!(f.predict_with(f64::NAN, 0.0, 0.01).is_err());
    assert!(f.predict_with(0.0, 0.0, -1.0).is_err());
    assert_eq!(f.belief(), &before[..]);
    assert_eq!(f.ignored(), 2 + 1 + 2 + 1 + 2);
}
