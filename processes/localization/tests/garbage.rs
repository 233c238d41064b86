//! Garbage in never panics: every estimator takes arbitrary odometry, beacon readings (NaN,
//! infinities, unknown ids, counts above capacity) and fixes (bad flags, NaN) in any order.

use mole_localization::{BayesConfig, Estimator, EstimatorKind, HistogramFilter};
use mole_types::{BeaconReading, BeaconSite, Beacons, Fix, Odom, Particles, Pose, WorldMap};
use proptest::prelude::*;

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
    m.beacons[0] = BeaconSite {
        x: 0.5,
        y: 2.5,
        id: 0,
        _pad: 0,
    };
    m.beacons[1] = BeaconSite {
        x: 3.5,
        y: 0.5,
        id: 1,
        _pad: 0,
    };
    m.n_beacons = 2;
    m
}

fn any_f64() -> impl Strategy<Value = f64> {
    prop_oneof![
        -10.0..10.0f64,
        Just(f64::NAN),
        Just(f64::INFINITY),
        Just(f64::NEG_INFINITY),
        Just(0.0),
        Just(-0.0),
        Just(1e300),
        Just(-1e300),
        Just(f64::MIN_POSITIVE),
    ]
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

fn run(est: &mut dyn Estimator, ops: &[Op]) {
    let mut beacons: Box<Beacons> = bytemuck::zeroed_box();
    let mut fix: Fix = bytemuck::Zeroable::zeroed();
    let mut odom: Odom = bytemuck::Zeroable::zeroed();
    let mut pose: Pose = bytemuck::Zeroable::zeroed();
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
                est.correct(&beacons, &fix);
            }
        }
        est.write_pose(&mut pose);
        est.write_particles(&mut particles);
        let _ = (est.rejected(), est.ignored());
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]
    #[test]
    fn no_estimator_panics_on_garbage(ops in prop::collection::vec(op(), 1..25)) {
        let map = map();
        for kind in [EstimatorKind::Kf, EstimatorKind::Ekf] {
            let mut est = kind.from_map(&map).map_err(|e| TestCaseError::fail(e.to_string()))?;
            run(est.as_mut(), &ops);
        }
        // The PF with fewer particles and a coarse histogram keep the debug run fast; the code
        // paths are those of the defaults.
        let mut pf = mole_localization::ParticleFilter::from_map_with(
            &map,
            mole_localization::PfConfig { n_particles: 500, ..Default::default() },
        );
        run(&mut pf, &ops);
        let mut bayes = HistogramFilter::from_map_with(
            &map,
            BayesConfig { cell_size: 0.25, heading_bins: 8, ..Default::default() },
        );
        run(&mut bayes, &ops);
        let s: f64 = bayes.belief().iter().sum();
        prop_assert!((s - 1.0).abs() < 1e-9 || s.is_nan(), "Σ Bel = {}", s);
    }
}
