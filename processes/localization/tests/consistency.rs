//! Filter consistency (Bar-Shalom, Li & Kirubarajan 2001, §5.4): over 50 seeded Monte-Carlo runs
//! the average normalised estimation error squared (NEES) of a consistent filter with n states
//! lies, with 95% probability, in [χ²_{50n}(0.025), χ²_{50n}(0.975)] / 50. The bounds come from
//! statrs, not from a table.
//!
//! The EKF runs on the stack's own sensor model (mole-sensing) driving a tiny unicycle truth; the
//! linear KF runs on a linear-Gaussian simulation of exactly its model.

use mole_localization::kf::KalmanFilter;
use mole_localization::models::unicycle_g;
use mole_localization::{Ekf, Estimator, Readings};
use mole_sensing::Sensing;
use mole_types::{Beacons, Fix, Odom, Truth, WorldMap, wrap_angle};
use nalgebra::{Matrix2, Matrix2x4, Matrix4, Matrix4x2, Vector2, Vector3, Vector4};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use statrs::distribution::{ChiSquared, ContinuousCDF};

const RUNS: usize = 50;

/// The two-sided 95% interval of the average NEES over `RUNS` runs for `dof` states.
fn nees_bounds(dof: usize) -> (f64, f64) {
    let chi2 = ChiSquared::new((RUNS * dof) as f64).expect("positive dof");
    (
        chi2.inverse_cdf(0.025) / RUNS as f64,
        chi2.inverse_cdf(0.975) / RUNS as f64,
    )
}

fn gauss(rng: &mut ChaCha8Rng) -> f64 {
    StandardNormal.sample(rng)
}

/// A 10 m × 10 m arena with four beacons and the noise of a typical scenario, at 20 Hz.
fn world(seed: u64) -> Box<WorldMap> {
    let mut m: Box<WorldMap> = bytemuck::zeroed_box();
    m.arena_width = 10.0;
    m.arena_height = 10.0;
    m.dt = 0.05;
    m.seed = seed;
    m.grid_resolution = 0.05;
    m.robot.radius = 0.2;
    m.start_x = 2.5;
    m.start_y = 2.0;
    m.start_theta = 0.3;
    let s = &mut m.sensors;
    s.odom_v_std = 0.05;
    s.odom_omega_std = 0.05;
    s.beacon_range_max = 7.0;
    s.beacon_range_std = 0.05;
    s.beacon_bearing_std = 0.02;
    s.fix_std = 0.5;
    s.fix_period_ticks = 20;
    m.place_beacons(&[(1.0, 1.0), (9.0, 1.0), (9.0, 9.0), (1.0, 9.0)]);
    m
}

/// One EKF run of `steps` ticks; returns the NEES summed over the ticks.
fn ekf_run(seed: u64, steps: usize) -> f64 {
    let map = world(seed);
    let mut sensing = Sensing::new(&map, seed).expect("valid map");
    let mut ekf = Ekf::from_map(&map);
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0xE4F);
    // The truth starts at a draw from the filter's prior, as consistency requires.
    let l = ekf.sigma.cholesky().expect("SPD prior").l();
    let x0 = ekf.mu + l * Vector3::new(gauss(&mut rng), gauss(&mut rng), gauss(&mut rng));
    let mut truth: Box<Truth> = bytemuck::zeroed_box();
    (truth.x, truth.y, truth.theta) = (x0[0], x0[1], x0[2]);
    let mut odom: Odom = bytemuck::Zeroable::zeroed();
    let mut beacons: Box<Beacons> = bytemuck::zeroed_box();
    let mut fix: Fix = bytemuck::Zeroable::zeroed();
    let mut nees = 0.0;
    for k in 1..=steps {
        // A slow lap: 0.5 m/s with a gentle turn.
        (truth.v, truth.omega) = (0.5, 0.25);
        let x = unicycle_g(
            &Vector3::new(truth.x, truth.y, truth.theta),
            truth.v,
            truth.omega,
            map.dt,
        );
        (truth.x, truth.y, truth.theta) = (x[0], x[1], x[2]);
        truth.header.tick = k as u64;
        sensing.odom(&truth, &mut odom);
        sensing.beacons(&truth, &mut beacons);
        sensing.fix(&truth, &mut fix);
        ekf.step(
            &Readings::of(&odom)
                .with_beacons(Some(&beacons))
                .with_fix(Some(&fix)),
        );
        let mut e = x - ekf.mu;
        e[2] = wrap_angle(e[2]);
        let chol = ekf.sigma.cholesky().expect("Σ stays SPD");
        nees += e.dot(&chol.solve(&e));
    }
    nees
}

#[test]
fn ekf_average_nees_lies_in_the_chi2_interval() {
    let steps = 200;
    let total: f64 = (0..RUNS as u64).map(|s| ekf_run(s + 1, steps)).sum();
    let nees = total / (RUNS * steps) as f64;
    let (lo, hi) = nees_bounds(3);
    eprintln!("EKF average NEES {nees:.3}, 95% interval [{lo:.3}, {hi:.3}]");
    assert!(
        (lo..=hi).contains(&nees),
        "EKF NEES {nees} outside [{lo}, {hi}]"
    );
}

/// One KF run on x_t = A x + B u + ε, z = C x + δ, exactly the filter's model: constant velocity
/// (x, y, vx, vy) driven by an acceleration control, noisy position readings.
fn kf_run(seed: u64, steps: usize) -> f64 {
    let dt = 0.1;
    let a = Matrix4::new(
        1.0, 0.0, dt, 0.0, 0.0, 1.0, 0.0, dt, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0,
    );
    let b = Matrix4x2::new(0.5 * dt * dt, 0.0, 0.0, 0.5 * dt * dt, dt, 0.0, 0.0, dt);
    // Process noise: white acceleration σ_a = 0.3 m/s² (R = σ_a² B Bᵀ) plus a small full-rank part.
    let r = b * b.transpose() * 0.09 + Matrix4::identity() * 1e-5;
    let q = Matrix2::new(0.04, 0.01, 0.01, 0.09);
    let c = Matrix2x4::new(1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0);
    let sigma0 = Matrix4::from_diagonal(&Vector4::new(0.25, 0.25, 0.04, 0.04));
    let mut kf =
        KalmanFilter::<4, 2, 2>::new(Vector4::new(1.0, 2.0, 0.5, 0.0), sigma0, a, b, c, r, q);
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let g4 = |rng: &mut ChaCha8Rng| Vector4::new(gauss(rng), gauss(rng), gauss(rng), gauss(rng));
    let l_r = r.cholesky().expect("SPD").l();
    let l_q = q.cholesky().expect("SPD").l();
    let mut x = kf.mu + sigma0.cholesky().expect("SPD").l() * g4(&mut rng);
    let mut nees = 0.0;
    for k in 0..steps {
        let t = k as f64 * dt;
        let u = Vector2::new((0.5 * t).sin(), (0.3 * t).cos());
        x = a * x + b * u + l_r * g4(&mut rng);
        let z = c * x + l_q * Vector2::new(gauss(&mut rng), gauss(&mut rng));
        kf.predict(&u).expect("finite control");
        kf.correct(&z, None).expect("finite reading");
        nees += kf.nees(&x).expect("SPD Σ");
    }
    nees
}

#[test]
fn kf_average_nees_lies_in_the_chi2_interval() {
    let steps = 200;
    let total: f64 = (0..RUNS as u64).map(|s| kf_run(s + 100, steps)).sum();
    let nees = total / (RUNS * steps) as f64;
    let (lo, hi) = nees_bounds(4);
    eprintln!("KF average NEES {nees:.3}, 95% interval [{lo:.3}, {hi:.3}]");
    assert!(
        (lo..=hi).contains(&nees),
        "KF NEES {nees} outside [{lo}, {hi}]"
    );
}
