//! The particle filter (algorithms §6.7): J particles x^[j] = (x, y, θ) with weights w^[j]; proposal
//! π = the unicycle motion model with sampled odometry noise, importance weights from the beacon
//! and fix likelihoods, low-variance resampling when the effective sample size drops.
//!
//! Errata handled here (docs/errata.md): the source's "draw i with probability ∝ w^[i]" is done on
//! weights normalised first (in log space, log-sum-exp, so 10⁴ tight likelihoods never underflow)
//! and with Thrun's low-variance sampler (*Probabilistic Robotics*, Table 4.4) rather than J
//! independent draws, which lose diversity faster; bearing innovations and particle headings are
//! wrapped to (−π, π].

use crate::models::{BeaconTable, MIN_RANGE, sinc, sliding_is_plausible, wrap_near};
use crate::noise::NoiseModel;
use crate::{Estimator, ReadingError, Readings};
use mole_types::Setting;
use mole_types::{
    BeaconReading, BeaconSite, EstimatorKind, Fix, MAX_PARTICLES, Odom, Particle, Particles, Pose2,
    WorldMap, wrap_angle,
};
use nalgebra::Vector2;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use serde::{Deserialize, Serialize};

/// Default particle count J.
pub const DEFAULT_PARTICLES: usize = 10_000;
/// The most particles a filter runs (`localization.pf.n_particles`); more than the message holds
/// ([`MAX_PARTICLES`]): what is published is then a subset ([`ParticleFilter::len`] vs the
/// message's `n_particles`).
pub const MAX_FILTER_PARTICLES: usize = 1_000_000;
/// Default resampling threshold: resample when N_eff < threshold · J.
pub const DEFAULT_RESAMPLE_THRESHOLD: f64 = 0.5;
/// Initial position σ (m) around the start pose, as for the EKF.
pub const INITIAL_STD_XY: f64 = 0.05;
/// Initial heading σ (rad) around the start pose.
pub const INITIAL_STD_THETA: f64 = 0.05;
/// Mixed into the map's seed so the PF's stream differs from other processes' streams.
const PF_SEED_SALT: u64 = 0x9F_F11E_5EED_0007;

/// Normalises log weights in place by log-sum-exp (algorithms §6.7), writes the linear weights
/// into `w` and returns N_eff = 1/Σw². When no log weight is finite the set is reset to uniform
/// weights; a NaN log weight (impossible with checked inputs) weighs nothing.
pub fn normalise_log_weights(log_w: &mut [f64], w: &mut [f64]) -> f64 {
    let n = log_w.len();
    let max = log_w
        .iter()
        .copied()
        .filter(|l| l.is_finite())
        .fold(f64::NEG_INFINITY, f64::max);
    if !max.is_finite() {
        log_w.fill(-(n as f64).ln());
        w.fill(1.0 / n as f64);
        return n as f64;
    }
    let mut sum = 0.0;
    for (w, &l) in w.iter_mut().zip(log_w.iter()) {
        *w = if l.is_nan() { 0.0 } else { (l - max).exp() };
        sum += *w;
    }
    // sum ≥ 1: the maximum contributes exp(0).
    let log_norm = max + sum.ln();
    let mut sum_sq = 0.0;
    for (w, l) in w.iter_mut().zip(log_w.iter_mut()) {
        *w /= sum;
        *l = if *w > 0.0 {
            *l - log_norm
        } else {
            f64::NEG_INFINITY
        };
        sum_sq += *w * *w;
    }
    1.0 / sum_sq
}

/// Thrun's low-variance sampler (*Probabilistic Robotics*, Table 4.4): with M = `out.len()`, the
/// m-th pointer U = r + m/M (r ∈ [0, 1/M)) picks the particle i whose cumulative weight first
/// reaches U; `out[m] = i`. Each particle i is drawn ⌊M·w_i⌋ or ⌈M·w_i⌉ times.
///
/// Deviation (robustness): weights need not be normalised (the pointers are scaled by Σw);
/// negative or non-finite weights count as 0, all-zero weights as uniform, and r is clamped
/// into [0, 1/M). With no weights `out` is left alone.
pub fn low_variance_resample(weights: &[f64], r: f64, out: &mut [usize]) {
    let n = weights.len();
    let m_total = out.len();
    if n == 0 || m_total == 0 {
        return;
    }
    let clean = |w: f64| if w.is_finite() && w > 0.0 { w } else { 0.0 };
    let total: f64 = weights.iter().map(|&w| clean(w)).sum();
    let step = 1.0 / m_total as f64;
    let r = if r.is_finite() {
        r.clamp(0.0, step * (1.0 - f64::EPSILON))
    } else {
        0.0
    };
    if !(total.is_finite() && total > 0.0) {
        // Uniform weights: pointer m lands in particle ⌊(r + m/M)·n⌋.
        for (m, o) in out.iter_mut().enumerate() {
            *o = (((r + m as f64 * step) * n as f64) as usize).min(n - 1);
        }
        return;
    }
    let mut i = 0;
    let mut c = clean(weights[0]);
    for (m, o) in out.iter_mut().enumerate() {
        let u = (r + m as f64 * step) * total;
        while u > c && i + 1 < n {
            i += 1;
            c += clean(weights[i]);
        }
        *o = i;
    }
}

/// Tuning of a [`ParticleFilter`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, Setting)]
#[serde(default, deny_unknown_fields)]
pub struct PfConfig {
    /// J, the number of particles (1..=[`MAX_FILTER_PARTICLES`]).
    #[setting(min = 1, max = MAX_FILTER_PARTICLES, fixed = "the particle set is allocated at start")]
    pub n_particles: usize,
    /// Resample when N_eff < `resample_threshold` · J.
    #[setting(min = 0.0, max = 1.0)]
    pub resample_threshold: f64,
    /// σ (m) of the initial particles around the start position.
    #[setting(min = 0.0)]
    pub initial_std_xy: f64,
    /// σ (rad) of the initial particles around the start heading.
    #[setting(min = 0.0)]
    pub initial_std_theta: f64,
}

impl Default for PfConfig {
    fn default() -> Self {
        Self {
            n_particles: DEFAULT_PARTICLES,
            resample_threshold: DEFAULT_RESAMPLE_THRESHOLD,
            initial_std_xy: INITIAL_STD_XY,
            initial_std_theta: INITIAL_STD_THETA,
        }
    }
}

/// The particle set Ψ = {⟨x^[j], w^[j]⟩} (algorithms §6.7), stored as columns, double-buffered for
/// resampling, with the summary (mean, covariance) kept current after every step.
#[derive(Debug, Clone)]
pub struct ParticleFilter {
    x: Vec<f64>,
    y: Vec<f64>,
    theta: Vec<f64>,
    /// ln w^[j], normalised (log-sum-exp = 0) after each correction.
    log_w: Vec<f64>,
    /// w^[j], normalised.
    w: Vec<f64>,
    x_next: Vec<f64>,
    y_next: Vec<f64>,
    theta_next: Vec<f64>,
    picks: Vec<usize>,
    rng: ChaCha8Rng,
    /// Motion and measurement noise.
    pub noise: NoiseModel,
    /// Resample when N_eff < `resample_threshold` · J.
    pub resample_threshold: f64,
    beacons: BeaconTable,
    mean: Pose2,
    cov: [f64; 9],
    n_eff: f64,
    resamples: u64,
    ignored: u64,
}

/// One standard normal draw.
#[inline]
fn gauss(rng: &mut ChaCha8Rng) -> f64 {
    rng.sample(StandardNormal)
}

impl ParticleFilter {
    /// J = `config.n_particles` (clamped to 1..=[`MAX_FILTER_PARTICLES`]) particles drawn around
    /// `initial`, from the ChaCha stream of `seed`. Non-finite pose values become 0.
    pub fn new(
        initial: Pose2,
        config: PfConfig,
        noise: NoiseModel,
        beacons: &[BeaconSite],
        seed: u64,
    ) -> Self {
        let n = config.n_particles.clamp(1, MAX_FILTER_PARTICLES);
        let fin = |v: f64, d: f64| if v.is_finite() { v } else { d };
        let sxy = fin(config.initial_std_xy, INITIAL_STD_XY).abs();
        let sth = fin(config.initial_std_theta, INITIAL_STD_THETA).abs();
        let (x0, y0, th0) = (
            fin(initial.x, 0.0),
            fin(initial.y, 0.0),
            fin(initial.theta, 0.0),
        );
        let mut rng = ChaCha8Rng::seed_from_u64(seed ^ PF_SEED_SALT);
        let mut x = vec![0.0; n];
        let mut y = vec![0.0; n];
        let mut theta = vec![0.0; n];
        for j in 0..n {
            x[j] = x0 + sxy * gauss(&mut rng);
            y[j] = y0 + sxy * gauss(&mut rng);
            theta[j] = wrap_angle(th0 + sth * gauss(&mut rng));
        }
        let threshold = fin(config.resample_threshold, DEFAULT_RESAMPLE_THRESHOLD).clamp(0.0, 1.0);
        let mut pf = Self {
            x,
            y,
            theta,
            log_w: vec![-(n as f64).ln(); n],
            w: vec![1.0 / n as f64; n],
            x_next: vec![0.0; n],
            y_next: vec![0.0; n],
            theta_next: vec![0.0; n],
            picks: vec![0; n],
            rng,
            noise,
            resample_threshold: threshold,
            beacons: BeaconTable::new(beacons),
            mean: Pose2::default(),
            cov: [0.0; 9],
            n_eff: n as f64,
            resamples: 0,
            ignored: 0,
        };
        pf.summarise();
        pf
    }

    /// The PF for the world in `map` with `config`: start pose, sensor noise, beacons, and the
    /// map's seed.
    pub fn from_map_with(map: &WorldMap, config: PfConfig) -> Self {
        Self::new(
            Pose2::new(map.start_x, map.start_y, map.start_theta),
            config,
            NoiseModel::from_map(map),
            map.beacons(),
            map.seed,
        )
    }

    /// The PF for the world in `map` with the default [`PfConfig`].
    pub fn from_map(map: &WorldMap) -> Self {
        Self::from_map_with(map, PfConfig::default())
    }

    /// J, the number of particles.
    pub fn len(&self) -> usize {
        self.x.len()
    }

    /// Whether the set is empty (never: J ≥ 1).
    pub fn is_empty(&self) -> bool {
        self.x.is_empty()
    }

    /// Normalised weights w^[j].
    pub fn weights(&self) -> &[f64] {
        &self.w
    }

    /// Particle j as (x, y, θ), if it exists.
    pub fn particle(&self, j: usize) -> Option<Pose2> {
        Some(Pose2::new(
            *self.x.get(j)?,
            *self.y.get(j)?,
            *self.theta.get(j)?,
        ))
    }

    /// The effective sample size N_eff = 1 / Σ w² after the last correction (before any
    /// resampling it triggered).
    pub fn n_eff(&self) -> f64 {
        self.n_eff
    }

    /// How many times the set was resampled.
    pub fn resamples(&self) -> u64 {
        self.resamples
    }

    /// Sampling from the proposal π (algorithms §6.7, step 1): each particle moves along the unicycle
    /// arc with its own draw of the odometry noise, v^[j] = v + σ_v·n, ω^[j] = ω + σ_ω·n.
    ///
    /// The additive state noise of `noise.state_noise_rate` (the EKF's floor of R_t) is added to
    /// x, y and θ as well, so the particles diffuse in every direction, as the EKF's Σ does.
    ///
    /// Odometry that is not plausible ([`crate::models::odometry_is_plausible`]) is ignored and
    /// counted.
    pub fn predict_with(&mut self, v: f64, omega: f64, dt: f64) -> Result<(), ReadingError> {
        self.predict_sliding_with(v, omega, dt, &Vector2::zeros())
    }

    /// [`ParticleFilter::predict_with`] followed by the slide `sideways` the wheels did not see
    /// (robot frame at the arc's end, [`crate::contact`]): each particle moves by R(θ_j)·b.
    pub fn predict_sliding_with(
        &mut self,
        v: f64,
        omega: f64,
        dt: f64,
        sideways: &Vector2<f64>,
    ) -> Result<(), ReadingError> {
        if !sliding_is_plausible(v, omega, dt, sideways) {
            self.ignored += 1;
            return Err(ReadingError::Invalid);
        }
        if dt == 0.0 {
            return Ok(());
        }
        let (sv, sw) = (self.noise.odom_v_std, self.noise.odom_omega_std);
        let floor = self.noise.r_floor(dt);
        let (fx, fy, ft) = (
            floor[(0, 0)].sqrt(),
            floor[(1, 1)].sqrt(),
            floor[(2, 2)].sqrt(),
        );
        let slides = sideways[0] != 0.0 || sideways[1] != 0.0;
        for j in 0..self.x.len() {
            let vj = v + sv * gauss(&mut self.rng);
            let wj = omega + sw * gauss(&mut self.rng);
            // The chord form of g (models::unicycle_g): length v·dt·sinc(ω·dt/2) along θ + ω·dt/2.
            let half = 0.5 * wj * dt;
            let s = vj * dt * sinc(half);
            let (sin_phi, cos_phi) = (self.theta[j] + half).sin_cos();
            self.x[j] += s * cos_phi;
            self.y[j] += s * sin_phi;
            self.theta[j] += wj * dt;
            if fx > 0.0 {
                self.x[j] += fx * gauss(&mut self.rng);
            }
            if fy > 0.0 {
                self.y[j] += fy * gauss(&mut self.rng);
            }
            if ft > 0.0 {
                self.theta[j] += ft * gauss(&mut self.rng);
            }
            self.theta[j] = wrap_near(self.theta[j]);
            if slides {
                let (sin_t, cos_t) = self.theta[j].sin_cos();
                self.x[j] += cos_t * sideways[0] - sin_t * sideways[1];
                self.y[j] += sin_t * sideways[0] + cos_t * sideways[1];
            }
        }
        self.summarise();
        Ok(())
    }

    /// Importance weights (algorithms §6.7, step 2) for one range-bearing reading: with the motion
    /// model as proposal, w^[j] ∝ p(z | x^[j]), here added as ln p in log space, bearing wrapped.
    pub fn weigh_beacon(&mut self, reading: &BeaconReading) -> Result<(), ReadingError> {
        if !(reading.range.is_finite() && reading.bearing.is_finite() && reading.range >= 0.0) {
            self.ignored += 1;
            return Err(ReadingError::Invalid);
        }
        let Some((bx, by)) = self.beacons.get(reading.id) else {
            self.ignored += 1;
            return Err(ReadingError::UnknownBeacon(reading.id));
        };
        let q = self.noise.q_beacon();
        let (ir, ib) = (-0.5 / q[(0, 0)], -0.5 / q[(1, 1)]);
        for j in 0..self.x.len() {
            let dx = bx - self.x[j];
            let dy = by - self.y[j];
            let d = dx.hypot(dy);
            let er = reading.range - d;
            // At the beacon itself the bearing is undefined: only the range counts.
            let eb = if d < MIN_RANGE {
                0.0
            } else {
                wrap_near(reading.bearing - (dy.atan2(dx) - self.theta[j]))
            };
            self.log_w[j] += ir * er * er + ib * eb * eb;
        }
        Ok(())
    }

    /// Importance weights for a position fix, ln p(z | x^[j]) with z ~ N((x, y), σ²·I), when
    /// `fix.valid == 1`. Returns whether it was used.
    pub fn weigh_fix(&mut self, fix: &Fix) -> Result<bool, ReadingError> {
        match fix.valid {
            0 => Ok(false),
            1 if fix.x.is_finite() && fix.y.is_finite() => {
                let k = -0.5 / self.noise.q_fix(fix.std)[(0, 0)];
                for j in 0..self.x.len() {
                    let (ex, ey) = (fix.x - self.x[j], fix.y - self.y[j]);
                    self.log_w[j] += k * (ex * ex + ey * ey);
                }
                Ok(true)
            }
            _ => {
                self.ignored += 1;
                Err(ReadingError::Invalid)
            }
        }
    }

    /// Normalises the weights by log-sum-exp, η = 1/Σ exp(ln w), and computes N_eff = 1/Σw².
    /// A set whose log weights are all non-finite is reset to uniform weights.
    pub fn normalise(&mut self) -> f64 {
        self.n_eff = normalise_log_weights(&mut self.log_w, &mut self.w);
        self.n_eff
    }

    /// Resampling (algorithms §6.7, step 3) with the low-variance sampler into the second buffer,
    /// then the buffers swap and the weights become uniform.
    pub fn resample(&mut self) {
        let n = self.x.len();
        let r = self.rng.random::<f64>() / n as f64;
        low_variance_resample(&self.w, r, &mut self.picks);
        for (m, &i) in self.picks.iter().enumerate() {
            self.x_next[m] = self.x[i];
            self.y_next[m] = self.y[i];
            self.theta_next[m] = self.theta[i];
        }
        core::mem::swap(&mut self.x, &mut self.x_next);
        core::mem::swap(&mut self.y, &mut self.y_next);
        core::mem::swap(&mut self.theta, &mut self.theta_next);
        self.log_w.fill(-(n as f64).ln());
        self.w.fill(1.0 / n as f64);
        self.resamples += 1;
    }

    /// Weighted mean (circular mean for θ) and covariance (θ deviations wrapped) of the set.
    fn summarise(&mut self) {
        let (mut sx, mut sy, mut sc, mut ss) = (0.0, 0.0, 0.0, 0.0);
        for j in 0..self.x.len() {
            let w = self.w[j];
            sx += w * self.x[j];
            sy += w * self.y[j];
            let (s, c) = self.theta[j].sin_cos();
            sc += w * c;
            ss += w * s;
        }
        let mt = if sc == 0.0 && ss == 0.0 {
            0.0
        } else {
            ss.atan2(sc)
        };
        let mut c = [0.0; 6]; // xx, xy, xt, yy, yt, tt
        for j in 0..self.x.len() {
            let w = self.w[j];
            let (ex, ey, et) = (
                self.x[j] - sx,
                self.y[j] - sy,
                wrap_near(self.theta[j] - mt),
            );
            c[0] += w * ex * ex;
            c[1] += w * ex * ey;
            c[2] += w * ex * et;
            c[3] += w * ey * ey;
            c[4] += w * ey * et;
            c[5] += w * et * et;
        }
        self.mean = Pose2::new(sx, sy, wrap_angle(mt));
        self.cov = [c[0], c[1], c[2], c[1], c[3], c[4], c[2], c[4], c[5]];
    }
}

impl Estimator for ParticleFilter {
    fn set_noise(&mut self, noise: &NoiseModel) -> Result<(), String> {
        self.noise = *noise;
        Ok(())
    }

    fn id(&self) -> u32 {
        EstimatorKind::Pf.code()
    }

    fn predict(&mut self, odom: &Odom) {
        // Refusals are counted inside.
        let _ = self.predict_with(odom.v, odom.omega, odom.dt);
    }

    fn predict_sliding(&mut self, odom: &Odom, sideways: &Vector2<f64>) {
        // Refusals are counted inside.
        let _ = self.predict_sliding_with(odom.v, odom.omega, odom.dt, sideways);
    }

    /// Weights from every beacon reading and the fix, normalisation (log-sum-exp), and
    /// low-variance resampling when N_eff < threshold · J.
    /// A step without any correction reading changes nothing.
    fn correct(&mut self, readings: &Readings<'_>) {
        if readings.beacons.is_none() && readings.fix.is_none() {
            return;
        }
        if let Some(beacons) = readings.beacons {
            if beacons.n_readings as usize > beacons.readings.len() {
                self.ignored += 1;
            }
            for reading in beacons.readings() {
                // Refusals are counted inside.
                let _ = self.weigh_beacon(reading);
            }
        }
        if let Some(fix) = readings.fix {
            let _ = self.weigh_fix(fix);
        }
        let n_eff = self.normalise();
        // Summarise before resampling: the weighted set is the better estimate of the mean.
        self.summarise();
        if n_eff < self.resample_threshold * self.x.len() as f64 {
            self.resample();
        }
    }

    fn pose(&self) -> Pose2 {
        self.mean
    }

    fn covariance(&self) -> [f64; 9] {
        self.cov
    }

    fn ignored(&self) -> u64 {
        self.ignored
    }

    /// Fills `n_particles` and the particles (f32, normalised weights), never the header. A
    /// filter of more than [`MAX_PARTICLES`] writes every (J / `MAX_PARTICLES`)-th particle, an
    /// evenly strided subset of `MAX_PARTICLES` whose weights are normalised again: the message
    /// is a picture of the cloud for a viewer, not the filter's state, which nothing restores
    /// from it (a restart draws a fresh set around the last pose).
    fn write_particles(&self, out: &mut Particles) -> bool {
        let total = self.x.len();
        let n = total.min(MAX_PARTICLES);
        // Particle i of the message is particle ⌊i·J/n⌋ of the filter: every one when J ≤ n.
        let pick = |i: usize| i * total / n;
        let picked_weight: f64 = (0..n).map(|i| self.w[pick(i)]).sum();
        let scale = if picked_weight > 0.0 {
            1.0 / picked_weight
        } else {
            0.0
        };
        for (i, p) in out.particles[..n].iter_mut().enumerate() {
            let j = pick(i);
            *p = Particle {
                x: self.x[j] as f32,
                y: self.y[j] as f32,
                theta: self.theta[j] as f32,
                w: if scale > 0.0 {
                    (self.w[j] * scale) as f32
                } else {
                    1.0 / n as f32
                },
            };
        }
        out.n_particles = n as u32;
        out._pad = 0;
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;
    use mole_types::Beacons;
    use proptest::prelude::*;

    #[test]
    fn low_variance_matches_thruns_table_4_4() {
        let mut out = [9; 4];
        low_variance_resample(&[0.5, 0.25, 0.125, 0.125], 0.125, &mut out);
        assert_eq!(out, [0, 0, 1, 2]);
        low_variance_resample(&[0.1, 0.2, 0.3, 0.4], 0.05, &mut out);
        assert_eq!(out, [0, 1, 2, 3]);
        // Unnormalised weights give the same draw.
        low_variance_resample(&[1.0, 2.0, 3.0, 4.0], 0.05, &mut out);
        assert_eq!(out, [0, 1, 2, 3]);
        // Degenerate weights: uniform; garbage r is clamped.
        low_variance_resample(&[0.0, f64::NAN, -1.0, 0.0], f64::NAN, &mut out);
        assert_eq!(out, [0, 1, 2, 3]);
        low_variance_resample(&[], 0.1, &mut out);
        assert_eq!(out, [0, 1, 2, 3]);
    }

    proptest! {
        #[test]
        fn low_variance_keeps_size_and_counts_within_one(
            weights in prop::collection::vec(0.0..1.0f64, 1..40),
            m in 1usize..200,
            r_frac in 0.0..1.0f64,
        ) {
            let total: f64 = weights.iter().sum();
            prop_assume!(total > 1e-9);
            let mut out = vec![usize::MAX; m];
            low_variance_resample(&weights, r_frac / m as f64, &mut out);
            prop_assert_eq!(out.len(), m);
            let mut counts = vec![0usize; weights.len()];
            for &i in &out {
                prop_assert!(i < weights.len());
                counts[i] += 1;
            }
            for (i, &c) in counts.iter().enumerate() {
                let expected = m as f64 * weights[i] / total;
                prop_assert!((c as f64 - expected).abs() <= 1.0 + 1e-9,
                    "particle {i}: {c} draws, M·w = {expected}");
            }
            // Indices come out sorted: the sampler walks the cumulative weights once.
            prop_assert!(out.windows(2).all(|p| p[0] <= p[1]));
        }
    }

    fn beacon_sites() -> Vec<BeaconSite> {
        [(0.0, 0.0), (10.0, 0.0), (10.0, 10.0)]
            .iter()
            .enumerate()
            .map(|(i, &(x, y))| BeaconSite {
                x,
                y,
                id: i as u32,
                _pad: 0,
            })
            .collect()
    }

    fn pf(n: usize) -> ParticleFilter {
        ParticleFilter::new(
            Pose2::new(5.0, 5.0, 0.0),
            PfConfig {
                n_particles: n,
                initial_std_xy: 0.3,
                initial_std_theta: 0.2,
                ..PfConfig::default()
            },
            NoiseModel::new(0.05, 0.05, 0.05, 0.02, 0.5),
            &beacon_sites(),
            7,
        )
    }

    #[test]
    fn weights_normalise_and_readings_pull_the_mean_to_the_truth() {
        let mut pf = pf(2000);
        let truth = (5.2, 4.9, 0.1);
        let mut beacons: Box<Beacons> = bytemuck::zeroed_box();
        for (i, b) in beacon_sites().iter().enumerate() {
            let (dx, dy) = (b.x - truth.0, b.y - truth.1);
            beacons.readings[i] = BeaconReading {
                id: b.id,
                _pad: 0,
                range: dx.hypot(dy),
                bearing: wrap_angle(dy.atan2(dx) - truth.2),
            };
        }
        beacons.n_readings = 3;
        let fix: Fix = bytemuck::Zeroable::zeroed();
        let still: Odom = bytemuck::Zeroable::zeroed();
        for _ in 0..10 {
            pf.predict_with(0.0, 0.0, 0.01).unwrap();
            pf.correct(
                &Readings::of(&still)
                    .with_beacons(Some(&beacons))
                    .with_fix(Some(&fix)),
            );
            let s: f64 = pf.weights().iter().sum();
            assert_relative_eq!(s, 1.0, epsilon = 1e-12);
        }
        let p = pf.pose();
        assert!((p.x - truth.0).abs() < 0.05, "{p:?}");
        assert!((p.y - truth.1).abs() < 0.05, "{p:?}");
        assert!(wrap_angle(p.theta - truth.2).abs() < 0.05, "{p:?}");
        assert!(pf.resamples() > 0);
        let c = pf.covariance();
        assert!(c[0] > 0.0 && c[4] > 0.0 && c[8] > 0.0);
        assert_eq!(c[1], c[3]);
    }

    #[test]
    fn log_space_weights_survive_hopeless_readings() {
        let mut pf = pf(500);
        // A range 1000 m away: every ln w ≈ −2·10⁸, yet the set normalises.
        let reading = BeaconReading {
            id: 0,
            _pad: 0,
            range: 1000.0,
            bearing: 0.0,
        };
        pf.weigh_beacon(&reading).unwrap();
        let n_eff = pf.normalise();
        assert!(n_eff >= 1.0 && n_eff.is_finite());
        let s: f64 = pf.weights().iter().sum();
        assert_relative_eq!(s, 1.0, epsilon = 1e-12);
        // The particle nearest the claimed range wins.
        let best = (0..pf.len())
            .max_by(|&a, &b| pf.weights()[a].total_cmp(&pf.weights()[b]))
            .unwrap_or(0);
        let far = (0..pf.len())
            .map(|j| pf.particle(j).map_or(0.0, |p| p.x.hypot(p.y)))
            .fold(0.0, f64::max);
        let pb = pf.particle(best).unwrap();
        assert_relative_eq!(pb.x.hypot(pb.y), far, epsilon = 1e-12);
    }

    #[test]
    fn write_particles_fills_the_set_but_not_the_header() {
        let pf = pf(300);
        let mut out: Box<Particles> = bytemuck::zeroed_box();
        out.header.seq = 5;
        assert!(pf.write_particles(&mut out));
        assert_eq!(out.n_particles, 300);
        assert_eq!(out.header.seq, 5);
        let s: f32 = out.particles().iter().map(|p| p.w).sum();
        assert!((s - 1.0).abs() < 1e-4);
        assert_eq!(mole_types::Message::validate(&*out), Ok(()));
    }

    /// A filter larger than the message publishes an evenly strided subset that spans the whole
    /// set, with the filter's relative weights, normalised again.
    #[test]
    fn a_filter_larger_than_the_message_writes_a_strided_subset() {
        let total = 3 * MAX_PARTICLES + 5;
        let mut pf = pf(total);
        let raw: Vec<f64> = (0..total).map(|j| (j % 7 + 1) as f64).collect();
        let sum: f64 = raw.iter().sum();
        pf.w = raw.iter().map(|w| w / sum).collect();
        let mut out: Box<Particles> = bytemuck::zeroed_box();
        assert!(pf.write_particles(&mut out));
        assert_eq!(out.n_particles as usize, MAX_PARTICLES);
        assert_eq!(mole_types::Message::validate(&*out), Ok(()));
        let written = out.particles();
        let picked_sum: f64 = (0..MAX_PARTICLES)
            .map(|i| raw[i * total / MAX_PARTICLES])
            .sum();
        // The last one comes from the end of the set, not from its first MAX_PARTICLES.
        for i in [0, 1, 2, MAX_PARTICLES / 2, MAX_PARTICLES - 1] {
            let j = i * total / MAX_PARTICLES;
            let p = pf.particle(j).unwrap();
            assert_eq!(written[i].x, p.x as f32, "particle {i} is the filter's {j}");
            assert_eq!(written[i].y, p.y as f32);
            assert_eq!(written[i].theta, p.theta as f32);
            assert_relative_eq!(
                f64::from(written[i].w),
                raw[j] / picked_sum,
                max_relative = 1e-5
            );
        }
        let weight: f64 = written.iter().map(|p| f64::from(p.w)).sum();
        assert_relative_eq!(weight, 1.0, epsilon = 1e-3);
    }

    #[test]
    fn particle_count_is_clamped_and_the_seed_reproduces() {
        let mut cfg = PfConfig {
            n_particles: 0,
            ..PfConfig::default()
        };
        let noise = NoiseModel::new(0.05, 0.05, 0.05, 0.02, 0.5);
        let p = ParticleFilter::new(Pose2::default(), cfg, noise, &[], 1);
        assert_eq!(p.len(), 1);
        cfg.n_particles = usize::MAX;
        let p = ParticleFilter::new(Pose2::default(), cfg, noise, &[], 1);
        assert_eq!(p.len(), MAX_FILTER_PARTICLES);
        let (mut a, mut b) = (pf(100), pf(100));
        a.predict_with(0.5, 0.3, 0.1).unwrap();
        b.predict_with(0.5, 0.3, 0.1).unwrap();
        assert_eq!(a.pose(), b.pose());
    }
}
