//! Per-step cost of the estimators: EKF predict + update (target ≤ 1 µs), PF with 10,000
//! particles predict + weight + resample (target ≤ 0.5 ms), histogram filter on a 200 × 200 × 16 belief
//! predict + correct (≤ 5 ms).

use criterion::{Criterion, criterion_group, criterion_main};
use mole_localization::pf::{ParticleFilter, PfConfig};
use mole_localization::{BayesConfig, Ekf, Estimator, HistogramFilter, Readings};
use mole_types::{BeaconReading, Beacons, Fix, Odom, WorldMap};
use std::hint::black_box;

fn map(width: f64) -> Box<WorldMap> {
    let mut m: Box<WorldMap> = bytemuck::zeroed_box();
    m.arena_width = width;
    m.arena_height = width;
    m.dt = 0.01;
    m.seed = 1;
    m.start_x = 0.5 * width;
    m.start_y = 0.5 * width;
    m.sensors.odom_v_std = 0.05;
    m.sensors.odom_omega_std = 0.05;
    m.sensors.beacon_range_std = 0.05;
    m.sensors.beacon_bearing_std = 0.02;
    m.sensors.fix_std = 0.5;
    let w = width;
    m.place_beacons(&[
        (0.1 * w, 0.1 * w),
        (0.9 * w, 0.1 * w),
        (0.9 * w, 0.9 * w),
        (0.1 * w, 0.9 * w),
    ]);
    m
}

/// Inputs of step k of a straight drive east from the start at 0.5 m/s.
struct Inputs {
    odom: Odom,
    beacons: Box<Beacons>,
    fix: Fix,
}

impl Inputs {
    /// The step's readings, every sensor present.
    fn readings(&self) -> Readings<'_> {
        Readings::of(&self.odom)
            .with_beacons(Some(&self.beacons))
            .with_fix(Some(&self.fix))
    }
}

fn inputs(map: &WorldMap, k: usize) -> Inputs {
    let (x, y) = (map.start_x + 0.005 * (k % 400) as f64, map.start_y);
    let mut odom: Odom = bytemuck::Zeroable::zeroed();
    (odom.v, odom.omega, odom.dt) = (0.5, 0.0, map.dt);
    let mut beacons: Box<Beacons> = bytemuck::zeroed_box();
    for (i, b) in map.beacons().iter().enumerate() {
        let (dx, dy) = (b.x - x, b.y - y);
        beacons.readings[i] = BeaconReading {
            id: b.id,
            _pad: 0,
            range: dx.hypot(dy),
            bearing: dy.atan2(dx),
        };
    }
    beacons.n_readings = map.beacons().len() as u32;
    let mut fix: Fix = bytemuck::Zeroable::zeroed();
    (fix.x, fix.y, fix.std, fix.valid) = (x, y, 0.5, 1);
    Inputs { odom, beacons, fix }
}

fn bench_step(c: &mut Criterion, name: &str, est: &mut dyn Estimator, map: &WorldMap) {
    let steps: Vec<Inputs> = (0..64).map(|k| inputs(map, k)).collect();
    // Steady state first.
    for s in &steps {
        est.step(&s.readings());
    }
    let mut k = 0;
    c.bench_function(name, |b| {
        b.iter(|| {
            let s = &steps[k % steps.len()];
            k += 1;
            est.step(black_box(&s.readings()));
            black_box(est.pose())
        })
    });
}

fn estimators(c: &mut Criterion) {
    let small = map(10.0);
    let mut ekf = Ekf::from_map(&small);
    bench_step(c, "ekf predict+update (4 beacons + fix)", &mut ekf, &small);

    let mut pf = ParticleFilter::from_map_with(&small, PfConfig::default());
    // Resample every step, the worst case: threshold 1 means N_eff < J always.
    pf.resample_threshold = 1.0;
    bench_step(c, "pf 10000 predict+weight+resample", &mut pf, &small);

    // 20 m arena at 0.1 m: 200 × 200 × 16.
    let big = map(20.0);
    let mut bayes = HistogramFilter::from_map_with(&big, BayesConfig::default());
    assert_eq!(bayes.dims(), (200, 200, 16));
    bench_step(c, "histogram 200x200x16 predict+correct", &mut bayes, &big);
}

criterion_group!(benches, estimators);
criterion_main!(benches);
