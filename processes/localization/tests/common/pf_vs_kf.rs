//! The PF against the KF on a linear-Gaussian problem: heading fixed at 0 (ω = 0, the PF's ω
//! noise at its 1e-3 floor, no θ state noise), so x moves by (v + σ_v·n)·dt + σ_a·n, y by σ_a·n
//! (the additive state noise), and a precise position fix every step: the exact posterior is the
//! KF's. Shared by the `pf_convergence` test and example.

use mole_localization::kf::KalmanFilter;
use mole_localization::pf::{ParticleFilter, PfConfig};
use mole_localization::{Estimator, NoiseModel, Readings};
use mole_types::{Beacons, Fix, Odom, Pose2};
use nalgebra::{Matrix2, Matrix2x1, Vector1, Vector2};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

/// What one PF size measured, averaged over the seeds.
pub struct Row {
    /// J.
    pub particles: usize,
    /// RMS distance of the PF mean from the truth (m).
    pub rmse: f64,
    /// RMS distance of the KF mean from the truth (m), the optimum.
    pub kf_rmse: f64,
    /// RMS distance of the PF mean from the KF mean (m).
    pub rms_to_kf: f64,
}

/// Runs the PF with `particles` and the KF on the same data for `seeds` seeds of `steps` steps.
pub fn compare(particles: usize, seeds: u64, steps: usize) -> Row {
    let (sv, sf, s0, dt, v) = (0.3, 0.03, 0.1, 0.1, 1.0);
    // Additive state noise rate a (m²/s): σ_a² = a·dt per step on x and y.
    let a = 0.09;
    let mut noise = NoiseModel::new(sv, 0.0, 0.05, 0.02, sf);
    noise.state_noise_rate = [a, a, 0.0];
    let (mut se, mut se_kf, mut se_to_kf, mut n) = (0.0, 0.0, 0.0, 0.0);
    for seed in 0..seeds {
        let start = Pose2::new(1.0, 2.0, 0.0);
        let config = PfConfig {
            n_particles: particles,
            initial_std_xy: s0,
            initial_std_theta: 0.0,
            ..PfConfig::default()
        };
        let mut pf = ParticleFilter::new(start, config, noise, &[], seed);
        let mut kf = KalmanFilter::<2, 2, 1>::new(
            Vector2::new(start.x, start.y),
            Matrix2::identity() * (s0 * s0),
            Matrix2::identity(),
            Matrix2x1::new(dt, 0.0),
            Matrix2::identity(),
            // The PF's y also drifts by v·dt·θ with θ a random walk of σ_ω = 1e-3: negligible.
            Matrix2::new(sv * sv * dt * dt + a * dt, 0.0, 0.0, a * dt),
            Matrix2::identity() * (sf * sf),
        );
        let mut rng = ChaCha8Rng::seed_from_u64(1000 + seed);
        let mut g = || -> f64 { StandardNormal.sample(&mut rng) };
        let (mut tx, mut ty) = (start.x + s0 * g(), start.y + s0 * g());
        let sa = (a * dt).sqrt();
        let beacons: Box<Beacons> = bytemuck::zeroed_box();
        let mut fix: Fix = bytemuck::Zeroable::zeroed();
        let mut odom: Odom = bytemuck::Zeroable::zeroed();
        for _ in 0..steps {
            // The measured v is the truth's plus noise: the truth moved by v_meas − σ_v·n.
            odom.v = v;
            odom.omega = 0.0;
            odom.dt = dt;
            tx += (v + sv * g()) * dt + sa * g();
            ty += sa * g();
            fix.valid = 1;
            fix.x = tx + sf * g();
            fix.y = ty + sf * g();
            fix.std = sf;
            pf.step(
                &Readings::of(&odom)
                    .with_beacons(Some(&beacons))
                    .with_fix(Some(&fix)),
            );
            kf.predict(&Vector1::new(v)).expect("finite");
            kf.correct(&Vector2::new(fix.x, fix.y), None)
                .expect("finite");
            let p = pf.pose();
            se += (p.x - tx).powi(2) + (p.y - ty).powi(2);
            se_kf += (kf.mu[0] - tx).powi(2) + (kf.mu[1] - ty).powi(2);
            se_to_kf += (p.x - kf.mu[0]).powi(2) + (p.y - kf.mu[1]).powi(2);
            n += 1.0;
        }
    }
    Row {
        particles,
        rmse: (se / n).sqrt(),
        kf_rmse: (se_kf / n).sqrt(),
        rms_to_kf: (se_to_kf / n).sqrt(),
    }
}

/// The Markdown table of `rows`.
pub fn table(rows: &[Row]) -> String {
    let mut s = String::from(
        "| particles | PF RMSE (m) | KF RMSE (m) | RMS PF mean − KF mean (m) |\n| ---: | ---: | ---: | ---: |\n",
    );
    for r in rows {
        s += &format!(
            "| {} | {:.4} | {:.4} | {:.5} |\n",
            r.particles, r.rmse, r.kf_rmse, r.rms_to_kf
        );
    }
    s
}
