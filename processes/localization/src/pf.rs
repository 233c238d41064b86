//! The particle filter (algorithms §6.7): J particles x^[j] = (x, y, θ) with weights w^[j]; proposal
//! π = the unicycle motion model with sampled odometry noise, importance weights from the beacon
//! and fix likelihoods, low-variance resampling when the effective sample size drops, and, as an
//! option, KLD-sampling (Fox 2003), which sizes each resampled set to the belief's spread.
//!
//! Errata handled here (docs/errata.md): the source's "draw i with probability ∝ w^[i]" is done on
//! weights normalised first (in log space, log-sum-exp, so 10⁴ tight likelihoods never underflow)
//! and with Thrun's low-variance sampler (*Probabilistic Robotics*, Table 4.4) rather than J
//! independent draws, which lose diversity faster; bearing innovations and particle headings are
//! wrapped to [−π, π].
//!
//! Layout: the particles are columns of [`f64x4`] lanes (`wide`), so every per-particle loop
//! (motion, weights, normalisation, summary) runs four particles at a time on SIMD registers
//! with `wide`'s vector sin/cos, atan2 and exp; the noise is drawn first, in one scalar pass per
//! column. Lanes past the J-th particle hold finite values of weight exactly 0 (ln w = −∞), so
//! no sum sees them.

use crate::models::{BeaconTable, MIN_RANGE, SINC_SERIES_BELOW, sliding_is_plausible};
use crate::noise::NoiseModel;
use crate::ziggurat::ZigguratLanes;
use crate::{Estimator, ReadingError, Readings};
use mole_types::{
    BeaconReading, BeaconSite, EstimatorKind, Fix, MAX_PARTICLES, Odom, Particle, Particles, Pose2,
    Setting, WorldMap, wrap_angle,
};
use nalgebra::Vector2;
use rand::rngs::Xoshiro256PlusPlus;
use rand::{RngExt, SeedableRng};
use rand_distr::StandardNormal;
use serde::{Deserialize, Serialize};
use wide::f64x4;

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
/// Default smallest set KLD-sampling shrinks to (AMCL's `min_particles`).
pub const DEFAULT_MIN_PARTICLES: usize = 2_000;
/// Default KLD-sampling error bound ε (Fox 2003; AMCL's `kld_err`).
pub const DEFAULT_KLD_EPSILON: f64 = 0.05;
/// Default upper standard-normal quantile z_{1−δ} for δ = 0.01 (AMCL's `kld_z` 0.99).
pub const DEFAULT_KLD_Z: f64 = 2.33;
/// Default KLD bin size in x and y (m).
pub const DEFAULT_KLD_BIN_XY: f64 = 0.2;
/// Default KLD bin size in θ (degrees).
pub const DEFAULT_KLD_BIN_THETA_DEG: f64 = 10.0;
/// Mixed into the map's seed so the PF's stream differs from other processes' streams.
const PF_SEED_SALT: u64 = 0x9F_F11E_5EED_0007;
/// Particles per SIMD lane group.
const LANES: usize = 4;

/// The scalars of a column of lanes.
fn scalars(v: &[f64x4]) -> &[f64] {
    wide::bytemuck::cast_slice(v)
}

/// The scalars of a column of lanes, to write.
fn scalars_mut(v: &mut [f64x4]) -> &mut [f64] {
    wide::bytemuck::cast_slice_mut(v)
}

/// Lane groups holding `n` particles.
fn groups(n: usize) -> usize {
    n.div_ceil(LANES)
}

/// Angles wrapped to [−π, π] by one rounding, for any finite angle (the lane form of
/// [`wrap_angle`]; an angle of exactly −π may stay −π, the same heading).
#[inline]
fn wrap_lanes(a: f64x4) -> f64x4 {
    use core::f64::consts::TAU;
    a - f64x4::splat(TAU) * (a * f64x4::splat(1.0 / TAU)).round()
}

/// Below this |a| (rad) [`small_sin_cos`] is used; the Taylor terms it drops are below 1e-18.
const SMALL_ANGLE: f64 = 0.1;

/// sin(a)/a and cos a by their Taylor series to a¹⁰ and a¹², for |a| < [`SMALL_ANGLE`] (the turn
/// of one step): a motion step then needs no range reduction and no division.
#[inline]
fn small_sinc_cos(a: f64x4) -> (f64x4, f64x4) {
    let a2 = a * a;
    let term = |k: f64| a2 * f64x4::splat(1.0 / k);
    let one = f64x4::ONE;
    let sinc = one
        - term(6.0)
            * (one - term(20.0) * (one - term(42.0) * (one - term(72.0) * (one - term(110.0)))));
    let cos = one
        - term(2.0)
            * (one - term(12.0) * (one - term(30.0) * (one - term(56.0) * (one - term(90.0)))));
    (sinc, cos)
}

/// sin a and cos a from [`small_sinc_cos`], for |a| < [`SMALL_ANGLE`].
#[inline]
fn small_sin_cos(a: f64x4) -> (f64x4, f64x4) {
    let (sinc, cos) = small_sinc_cos(a);
    (a * sinc, cos)
}

/// sin(a)/a given sin(a), with the limit 1 at a = 0 (the lane form of `models::sinc`).
#[inline]
fn sinc_lanes(a: f64x4, sin_a: f64x4) -> f64x4 {
    let a2 = a * a;
    let series = f64x4::ONE - a2 / f64x4::splat(6.0) + a2 * a2 / f64x4::splat(120.0);
    a.abs()
        .simd_lt(f64x4::splat(SINC_SERIES_BELOW))
        .select(series, sin_a / a)
}

/// Normalises log weights in place by log-sum-exp (algorithms §6.7), writes the linear weights
/// into `w` and returns N_eff = 1/Σw². When no log weight is finite the set is reset to uniform
/// weights; a NaN log weight (impossible with checked inputs) weighs nothing.
pub fn normalise_log_weights(log_w: &mut [f64], w: &mut [f64]) -> f64 {
    let n = log_w.len();
    let mut max = f64x4::splat(f64::NEG_INFINITY);
    for_lanes(log_w, w, |l, _| {
        max = l.is_finite().select(l.max(max), max);
        None
    });
    let max = max.to_array().into_iter().fold(f64::NEG_INFINITY, f64::max);
    if !max.is_finite() {
        log_w.fill(-(n as f64).ln());
        w.fill(1.0 / n as f64);
        return n as f64;
    }
    let mut sum = f64x4::ZERO;
    for_lanes(log_w, w, |l, _| {
        let e = l
            .is_finite()
            .select((l - f64x4::splat(max)).exp(), f64x4::ZERO);
        sum += e;
        Some((l, e))
    });
    // sum ≥ 1: the maximum contributes exp(0).
    let sum = sum.reduce_add();
    let (log_norm, inv_sum) = (f64x4::splat(max + sum.ln()), f64x4::splat(1.0 / sum));
    let mut sum_sq = f64x4::ZERO;
    for_lanes(log_w, w, |l, e| {
        let w = e * inv_sum;
        sum_sq = w.mul_add(w, sum_sq);
        let l = w
            .simd_gt(f64x4::ZERO)
            .select(l - log_norm, f64x4::splat(f64::NEG_INFINITY));
        Some((l, w))
    });
    1.0 / sum_sq.reduce_add()
}

/// Runs `f` over `a` and `b` four at a time (the last group padded with −∞ in `a` and 0 in
/// `b`, which weigh nothing) and writes back what it returns.
#[inline]
fn for_lanes(
    a: &mut [f64],
    b: &mut [f64],
    mut f: impl FnMut(f64x4, f64x4) -> Option<(f64x4, f64x4)>,
) {
    let (mut whole_a, mut whole_b) = (a.chunks_exact_mut(LANES), b.chunks_exact_mut(LANES));
    for (a, b) in (&mut whole_a).zip(&mut whole_b) {
        let (la, lb): ([f64; LANES], [f64; LANES]) = (
            (&*a).try_into().unwrap_or_default(),
            (&*b).try_into().unwrap_or_default(),
        );
        if let Some((na, nb)) = f(f64x4::from(la), f64x4::from(lb)) {
            a.copy_from_slice(&na.to_array());
            b.copy_from_slice(&nb.to_array());
        }
    }
    let (a, b) = (whole_a.into_remainder(), whole_b.into_remainder());
    if a.is_empty() {
        return;
    }
    let (mut la, mut lb) = ([f64::NEG_INFINITY; LANES], [0.0; LANES]);
    la[..a.len()].copy_from_slice(a);
    lb[..b.len()].copy_from_slice(b);
    if let Some((na, nb)) = f(f64x4::from(la), f64x4::from(lb)) {
        a.copy_from_slice(&na.to_array()[..a.len()]);
        b.copy_from_slice(&nb.to_array()[..b.len()]);
    }
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
    /// J, the number of particles; with `kld`, the most.
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
    /// KLD-sampling (Fox 2003, as AMCL): each resampling keeps as many particles as bound the
    /// K-L divergence to the belief by `kld_epsilon` with probability 1 − δ, given the bins they
    /// occupy; between `min_particles` and `n_particles`.
    pub kld: bool,
    /// KLD-sampling: ε, the bound on the K-L divergence.
    #[setting(above = 0.0, max = 1.0)]
    pub kld_epsilon: f64,
    /// KLD-sampling: z_{1−δ}, the upper standard-normal quantile of the confidence 1 − δ (2.33:
    /// δ = 0.01).
    #[setting(min = 0.0, max = 10.0)]
    pub kld_z: f64,
    /// KLD-sampling: bin size in x and y (m).
    #[setting(above = 0.0)]
    pub kld_bin_xy: f64,
    /// KLD-sampling: bin size in θ (degrees).
    #[setting(above = 0.0, max = 360.0)]
    pub kld_bin_theta_deg: f64,
    /// KLD-sampling: the fewest particles a resampling keeps (`n_particles` when it is more).
    #[setting(min = 1, max = MAX_FILTER_PARTICLES)]
    pub min_particles: usize,
}

impl Default for PfConfig {
    fn default() -> Self {
        Self {
            n_particles: DEFAULT_PARTICLES,
            resample_threshold: DEFAULT_RESAMPLE_THRESHOLD,
            initial_std_xy: INITIAL_STD_XY,
            initial_std_theta: INITIAL_STD_THETA,
            kld: false,
            kld_epsilon: DEFAULT_KLD_EPSILON,
            kld_z: DEFAULT_KLD_Z,
            kld_bin_xy: DEFAULT_KLD_BIN_XY,
            kld_bin_theta_deg: DEFAULT_KLD_BIN_THETA_DEG,
            min_particles: DEFAULT_MIN_PARTICLES,
        }
    }
}

/// Fox's KLD bound (Fox 2003, eq. 12; AMCL's `pf_resample_limit`): the number of samples n such
/// that, with probability 1 − δ, the K-L divergence between the sample-based maximum-likelihood
/// estimate and the true posterior over `k` occupied bins is below `epsilon`, by the
/// Wilson–Hilferty approximation of the χ²(k − 1) quantile:
/// n = (k − 1)/(2ε) · {1 − 2/(9(k − 1)) + √(2/(9(k − 1)))·z_{1−δ}}³, rounded up.
///
/// Deviation from AMCL: k ≤ 1 gives 0 (the formula's limit, as in Fox's paper), so a belief in
/// one bin shrinks to the caller's minimum; AMCL returns its maximum for k = 1.
pub fn kld_sample_bound(k: usize, epsilon: f64, z: f64) -> usize {
    if k <= 1 {
        return 0;
    }
    let km1 = (k - 1) as f64;
    let b = 2.0 / (9.0 * km1);
    let x = 1.0 - b + b.sqrt() * z;
    let n = km1 / (2.0 * epsilon) * x * x * x;
    if n > 0.0 {
        // Saturating: a bound past usize::MAX (or ε = 0) is "every particle".
        n.ceil().min(usize::MAX as f64) as usize
    } else {
        0
    }
}

/// The occupied KLD bins of one resampling: an open-addressed set of (x, y, θ) bin indices with
/// room for every particle at load ≤ ½, allocated once; a new resampling bumps `stamp` instead
/// of clearing the table.
#[derive(Debug, Clone)]
struct KldBins {
    epsilon: f64,
    z: f64,
    inv_xy: f64,
    inv_theta: f64,
    min: usize,
    keys: Vec<[i32; 3]>,
    stamps: Vec<u32>,
    stamp: u32,
    shift: u32,
}

impl KldBins {
    fn new(config: &PfConfig, max: usize) -> Self {
        let pos = |v: f64, d: f64| if v.is_finite() && v > 0.0 { v } else { d };
        let capacity = (2 * max).next_power_of_two().max(2);
        Self {
            epsilon: pos(config.kld_epsilon, DEFAULT_KLD_EPSILON),
            z: if config.kld_z.is_finite() {
                config.kld_z.max(0.0)
            } else {
                DEFAULT_KLD_Z
            },
            inv_xy: 1.0 / pos(config.kld_bin_xy, DEFAULT_KLD_BIN_XY),
            inv_theta: 1.0 / pos(config.kld_bin_theta_deg, DEFAULT_KLD_BIN_THETA_DEG).to_radians(),
            min: config.min_particles.clamp(1, max),
            keys: vec![[0; 3]; capacity],
            stamps: vec![0; capacity],
            stamp: 1,
            shift: 64 - capacity.trailing_zeros(),
        }
    }

    /// Empties the set.
    fn clear(&mut self) {
        self.stamp = self.stamp.wrapping_add(1);
        if self.stamp == 0 {
            self.stamps.fill(0);
            self.stamp = 1;
        }
    }

    /// Adds the bin of (x, y, θ); whether it was not in the set yet.
    fn insert(&mut self, x: f64, y: f64, theta: f64) -> bool {
        // Saturating casts: a non-finite coordinate lands in a bin of its own kind.
        let key = [
            (x * self.inv_xy).floor() as i32,
            (y * self.inv_xy).floor() as i32,
            (theta * self.inv_theta).floor() as i32,
        ];
        // Fibonacci hashing of the three indices mixed together.
        let h = (key[0] as u32 as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
            ^ (key[1] as u32 as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F)
            ^ (key[2] as u32 as u64).wrapping_mul(0x1656_67B1_9E37_79F9);
        let mask = self.keys.len() - 1;
        let mut i = ((h ^ (h >> 29)).wrapping_mul(0x9E37_79B9_7F4A_7C15) >> self.shift) as usize;
        loop {
            if self.stamps[i] != self.stamp {
                self.stamps[i] = self.stamp;
                self.keys[i] = key;
                return true;
            }
            if self.keys[i] == key {
                return false;
            }
            i = (i + 1) & mask;
        }
    }

    /// The set size for `k` occupied bins: the KLD bound within [`min`, `max`].
    fn target(&self, k: usize, max: usize) -> usize {
        kld_sample_bound(k, self.epsilon, self.z).clamp(self.min, max)
    }
}

/// The particle set Ψ = {⟨x^[j], w^[j]⟩} (algorithms §6.7), stored as columns of lanes,
/// double-buffered for resampling, with the summary (mean, covariance) kept current after every
/// step.
#[derive(Debug, Clone)]
pub struct ParticleFilter {
    /// J, the particles in use (≤ the columns' room; KLD-sampling changes it).
    n: usize,
    x: Vec<f64x4>,
    y: Vec<f64x4>,
    theta: Vec<f64x4>,
    /// sin θ^[j] and cos θ^[j], kept with θ: the motion, the bearing likelihood and the circular
    /// mean use them, so each step takes one vector sin/cos per particle.
    sin_t: Vec<f64x4>,
    cos_t: Vec<f64x4>,
    /// ln w^[j], normalised (log-sum-exp = 0) after each correction; −∞ past J.
    log_w: Vec<f64x4>,
    /// w^[j], normalised; 0 past J.
    w: Vec<f64x4>,
    x_next: Vec<f64x4>,
    y_next: Vec<f64x4>,
    theta_next: Vec<f64x4>,
    sin_next: Vec<f64x4>,
    cos_next: Vec<f64x4>,
    /// The standard normal draws of one motion step: v, ω, then x, y, θ of the state noise.
    draws: [Vec<f64x4>; 5],
    picks: Vec<usize>,
    rng: Xoshiro256PlusPlus,
    /// The motion step's normal draws, four lanes at a time.
    normals: ZigguratLanes,
    kld: Option<KldBins>,
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

impl ParticleFilter {
    /// J = `config.n_particles` (clamped to 1..=[`MAX_FILTER_PARTICLES`]) particles drawn around
    /// `initial`, from the Xoshiro256++ stream of `seed`. Non-finite pose values become 0.
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
        let column = || vec![f64x4::ZERO; groups(n)];
        let threshold = fin(config.resample_threshold, DEFAULT_RESAMPLE_THRESHOLD).clamp(0.0, 1.0);
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed ^ PF_SEED_SALT);
        let normals = ZigguratLanes::from_rng(&mut rng);
        let mut pf = Self {
            n,
            x: column(),
            y: column(),
            theta: column(),
            sin_t: column(),
            cos_t: column(),
            log_w: column(),
            w: column(),
            x_next: column(),
            y_next: column(),
            theta_next: column(),
            sin_next: column(),
            cos_next: column(),
            draws: [column(), column(), column(), column(), column()],
            picks: vec![0; n],
            rng,
            normals,
            kld: config.kld.then(|| KldBins::new(&config, n)),
            noise,
            resample_threshold: threshold,
            beacons: BeaconTable::new(beacons),
            mean: Pose2::default(),
            cov: [0.0; 9],
            n_eff: n as f64,
            resamples: 0,
            ignored: 0,
        };
        let rng = &mut pf.rng;
        for (x, y, t) in scalars_mut(&mut pf.x)[..n]
            .iter_mut()
            .zip(&mut scalars_mut(&mut pf.y)[..n])
            .zip(&mut scalars_mut(&mut pf.theta)[..n])
            .map(|((x, y), t)| (x, y, t))
        {
            *x = x0 + sxy * rng.sample::<f64, _>(StandardNormal);
            *y = y0 + sxy * rng.sample::<f64, _>(StandardNormal);
            *t = wrap_angle(th0 + sth * rng.sample::<f64, _>(StandardNormal));
        }
        for k in 0..groups(n) {
            (pf.sin_t[k], pf.cos_t[k]) = pf.theta[k].sin_cos();
        }
        pf.reset_weights();
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

    /// J, the number of particles in use.
    pub fn len(&self) -> usize {
        self.n
    }

    /// The most particles the set holds (`n_particles`); [`ParticleFilter::len`] is less only
    /// with KLD-sampling.
    pub fn capacity(&self) -> usize {
        self.picks.len()
    }

    /// Whether the set is empty (never: J ≥ 1).
    pub fn is_empty(&self) -> bool {
        self.n == 0
    }

    /// Normalised weights w^[j] of the J particles.
    pub fn weights(&self) -> &[f64] {
        &scalars(&self.w)[..self.n]
    }

    /// Particle j as (x, y, θ), if it exists.
    pub fn particle(&self, j: usize) -> Option<Pose2> {
        (j < self.n).then(|| {
            Pose2::new(
                scalars(&self.x)[j],
                scalars(&self.y)[j],
                scalars(&self.theta)[j],
            )
        })
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
        self.move_particles(v, omega, dt, sideways)?;
        self.summarise();
        Ok(())
    }

    /// The motion of [`ParticleFilter::predict_sliding_with`], without the summary.
    fn move_particles(
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
        let floor = self.noise.r_floor(dt);
        let sigmas = [
            self.noise.odom_v_std,
            self.noise.odom_omega_std,
            floor[(0, 0)].sqrt(),
            floor[(1, 1)].sqrt(),
            floor[(2, 2)].sqrt(),
        ];
        // The draws, one column at a time; a column of σ = 0 is not drawn (its lanes are
        // multiplied by 0).
        for (column, &sigma) in self.draws.iter_mut().zip(&sigmas) {
            if sigma > 0.0 {
                self.normals.fill(&mut column[..groups(self.n)]);
            }
        }
        let [sv, sw, fx, fy, ft] = sigmas.map(f64x4::splat);
        let (v, omega, dt) = (f64x4::splat(v), f64x4::splat(omega), f64x4::splat(dt));
        let (bx, by) = (f64x4::splat(sideways[0]), f64x4::splat(sideways[1]));
        let slides = sideways[0] != 0.0 || sideways[1] != 0.0;
        let [nv, nw, nx, ny, nt] = &self.draws;
        for k in 0..groups(self.n) {
            let vj = sv.mul_add(nv[k], v);
            let wj = sw.mul_add(nw[k], omega);
            // The chord form of g (models::unicycle_g): length v·dt·sinc(ω·dt/2) along
            // φ = θ + ω·dt/2, whose sin and cos are θ's turned by ω·dt/2.
            let half = f64x4::HALF * wj * dt;
            let (sinc_h, sin_h, cos_h) = if half.abs().simd_lt(f64x4::splat(SMALL_ANGLE)).all() {
                let (sinc_h, cos_h) = small_sinc_cos(half);
                (sinc_h, half * sinc_h, cos_h)
            } else {
                let (sin_h, cos_h) = half.sin_cos();
                (sinc_lanes(half, sin_h), sin_h, cos_h)
            };
            let s = vj * dt * sinc_h;
            let (sin_t, cos_t) = (self.sin_t[k], self.cos_t[k]);
            let sin_phi = sin_t * cos_h + cos_t * sin_h;
            let cos_phi = cos_t * cos_h - sin_t * sin_h;
            let mut x = self.x[k] + s * cos_phi + fx * nx[k];
            let mut y = self.y[k] + s * sin_phi + fy * ny[k];
            // θ' = φ + ω·dt/2 + noise: sin θ' and cos θ' are φ's turned by that small angle,
            // rescaled to unit length by one Newton step, so no lane needs a range reduction.
            let heading_noise = ft * nt[k];
            let rest = half + heading_noise;
            let theta = wrap_lanes(self.theta[k] + wj * dt + heading_noise);
            let (sin_t, cos_t) = if rest.abs().simd_lt(f64x4::splat(SMALL_ANGLE)).all() {
                let (sin_r, cos_r) = small_sin_cos(rest);
                let sin_t = sin_phi * cos_r + cos_phi * sin_r;
                let cos_t = cos_phi * cos_r - sin_phi * sin_r;
                let unit = f64x4::HALF * (f64x4::splat(3.0) - sin_t.mul_add(sin_t, cos_t * cos_t));
                (sin_t * unit, cos_t * unit)
            } else {
                theta.sin_cos()
            };
            if slides {
                x += cos_t * bx - sin_t * by;
                y += sin_t * bx + cos_t * by;
            }
            (self.x[k], self.y[k], self.theta[k]) = (x, y, theta);
            (self.sin_t[k], self.cos_t[k]) = (sin_t, cos_t);
        }
        Ok(())
    }

    /// Importance weights (algorithms §6.7, step 2) for one range-bearing reading: with the motion
    /// model as proposal, w^[j] ∝ p(z | x^[j]), here added as ln p in log space: a Gaussian in
    /// the range and a von Mises density in the bearing error e, κ·(cos e − 1) with
    /// κ = 1/σ_β², the circular form of the Gaussian (equal to −e²/2σ_β² to fourth order in
    /// e). Deviation: cos e is a dot product of unit vectors, where e itself needs an atan2, the
    /// most expensive step of the filter.
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
        let (ir, kappa) = (
            f64x4::splat(-0.5 / q[(0, 0)]),
            f64x4::splat(1.0 / q[(1, 1)]),
        );
        let (bx, by) = (f64x4::splat(bx), f64x4::splat(by));
        let range = f64x4::splat(reading.range);
        let (sin_b, cos_b) = reading.bearing.sin_cos();
        let (sin_b, cos_b) = (f64x4::splat(sin_b), f64x4::splat(cos_b));
        for k in 0..groups(self.n) {
            let dx = bx - self.x[k];
            let dy = by - self.y[k];
            let d = dx.mul_add(dx, dy * dy).sqrt();
            let er = range - d;
            // The measured direction in the world, θ + β, against the direction to the beacon.
            let (sin_t, cos_t) = (self.sin_t[k], self.cos_t[k]);
            let cos_m = cos_t * cos_b - sin_t * sin_b;
            let sin_m = sin_t * cos_b + cos_t * sin_b;
            let cos_e = (cos_m * dx + sin_m * dy) / d;
            // At the beacon itself the bearing is undefined: only the range counts.
            let bearing = d
                .simd_lt(f64x4::splat(MIN_RANGE))
                .select(f64x4::ZERO, kappa * (cos_e - f64x4::ONE));
            self.log_w[k] += ir * er * er + bearing;
        }
        Ok(())
    }

    /// Importance weights for a position fix, ln p(z | x^[j]) with z ~ N((x, y), σ²·I), when
    /// `fix.valid == 1`. Returns whether it was used.
    pub fn weigh_fix(&mut self, fix: &Fix) -> Result<bool, ReadingError> {
        match fix.valid {
            0 => Ok(false),
            1 if fix.x.is_finite() && fix.y.is_finite() => {
                let k = f64x4::splat(-0.5 / self.noise.q_fix(fix.std)[(0, 0)]);
                let (fx, fy) = (f64x4::splat(fix.x), f64x4::splat(fix.y));
                for g in 0..groups(self.n) {
                    let (ex, ey) = (fx - self.x[g], fy - self.y[g]);
                    self.log_w[g] += k * ex.mul_add(ex, ey * ey);
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
        let n = self.n;
        self.n_eff = normalise_log_weights(
            &mut scalars_mut(&mut self.log_w)[..n],
            &mut scalars_mut(&mut self.w)[..n],
        );
        self.n_eff
    }

    /// Uniform weights over the J particles; weight 0 (ln w = −∞) in the lanes past them.
    fn reset_weights(&mut self) {
        let n = self.n;
        let (log_w, w) = (scalars_mut(&mut self.log_w), scalars_mut(&mut self.w));
        log_w[..n].fill(-(n as f64).ln());
        w[..n].fill(1.0 / n as f64);
        log_w[n..].fill(f64::NEG_INFINITY);
        w[n..].fill(0.0);
    }

    /// Resampling (algorithms §6.7, step 3) with the low-variance sampler into the second buffer,
    /// then the buffers swap and the weights become uniform.
    ///
    /// With KLD-sampling (Fox 2003): the low-variance sample is of the most particles, and its
    /// particles are taken in random order (a partial Fisher–Yates shuffle: each one is, on its
    /// own, drawn ∝ w) until their number reaches the KLD bound of the bins they occupy
    /// ([`kld_sample_bound`]), at least `min_particles`.
    pub fn resample(&mut self) {
        let max = self.capacity();
        let m_total = if self.kld.is_some() { max } else { self.n };
        let r = self.rng.random::<f64>() / m_total as f64;
        low_variance_resample(&scalars(&self.w)[..self.n], r, &mut self.picks[..m_total]);
        let (xs, ys, ts) = (scalars(&self.x), scalars(&self.y), scalars(&self.theta));
        let (ss, cs) = (scalars(&self.sin_t), scalars(&self.cos_t));
        let (xn, yn, tn) = (
            scalars_mut(&mut self.x_next),
            scalars_mut(&mut self.y_next),
            scalars_mut(&mut self.theta_next),
        );
        let (sn, cn) = (
            scalars_mut(&mut self.sin_next),
            scalars_mut(&mut self.cos_next),
        );
        let new_n = match &mut self.kld {
            None => {
                for (m, &i) in self.picks[..m_total].iter().enumerate() {
                    (xn[m], yn[m], tn[m]) = (xs[i], ys[i], ts[i]);
                    (sn[m], cn[m]) = (ss[i], cs[i]);
                }
                m_total
            }
            Some(bins) => {
                bins.clear();
                let (mut k, mut target, mut m) = (0, max, 0);
                while m < target {
                    let pick = self.rng.random_range(m..max);
                    self.picks.swap(m, pick);
                    let i = self.picks[m];
                    (xn[m], yn[m], tn[m]) = (xs[i], ys[i], ts[i]);
                    (sn[m], cn[m]) = (ss[i], cs[i]);
                    m += 1;
                    if bins.insert(xs[i], ys[i], ts[i]) {
                        k += 1;
                        target = bins.target(k, max);
                    }
                }
                m
            }
        };
        core::mem::swap(&mut self.x, &mut self.x_next);
        core::mem::swap(&mut self.y, &mut self.y_next);
        core::mem::swap(&mut self.theta, &mut self.theta_next);
        core::mem::swap(&mut self.sin_t, &mut self.sin_next);
        core::mem::swap(&mut self.cos_t, &mut self.cos_next);
        self.n = new_n;
        self.reset_weights();
        self.resamples += 1;
    }

    /// Weighted mean (circular mean for θ) and covariance (θ deviations wrapped) of the set.
    fn summarise(&mut self) {
        let (mut sx, mut sy, mut sc, mut ss) = (f64x4::ZERO, f64x4::ZERO, f64x4::ZERO, f64x4::ZERO);
        let groups = groups(self.n);
        for k in 0..groups {
            let w = self.w[k];
            sx = w.mul_add(self.x[k], sx);
            sy = w.mul_add(self.y[k], sy);
            sc = w.mul_add(self.cos_t[k], sc);
            ss = w.mul_add(self.sin_t[k], ss);
        }
        let (mx, my, sc, ss) = (
            sx.reduce_add(),
            sy.reduce_add(),
            sc.reduce_add(),
            ss.reduce_add(),
        );
        let mt = if sc == 0.0 && ss == 0.0 {
            0.0
        } else {
            ss.atan2(sc)
        };
        let mut c = [f64x4::ZERO; 6]; // xx, xy, xt, yy, yt, tt
        let (mx4, my4, mt4) = (f64x4::splat(mx), f64x4::splat(my), f64x4::splat(mt));
        for k in 0..groups {
            let w = self.w[k];
            let (ex, ey, et) = (
                self.x[k] - mx4,
                self.y[k] - my4,
                wrap_lanes(self.theta[k] - mt4),
            );
            let (wx, wy, wt) = (w * ex, w * ey, w * et);
            c[0] = wx.mul_add(ex, c[0]);
            c[1] = wx.mul_add(ey, c[1]);
            c[2] = wx.mul_add(et, c[2]);
            c[3] = wy.mul_add(ey, c[3]);
            c[4] = wy.mul_add(et, c[4]);
            c[5] = wt.mul_add(et, c[5]);
        }
        let c = c.map(f64x4::reduce_add);
        self.mean = Pose2::new(mx, my, wrap_angle(mt));
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

    /// As the trait's, with the summary taken once: after the correction, or after the motion
    /// when there is nothing to correct with.
    fn step(&mut self, readings: &Readings<'_>) {
        let (odom, sideways) = match &readings.slide {
            Some(slide) => (&slide.odom, slide.sideways),
            None => (readings.odom, Vector2::zeros()),
        };
        // Refusals are counted inside.
        let _ = self.move_particles(odom.v, odom.omega, odom.dt, &sideways);
        if readings.beacons.is_none() && readings.fix.is_none() {
            self.summarise();
        } else {
            self.correct(readings);
        }
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
        if n_eff < self.resample_threshold * self.n as f64 {
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

    /// Fills the particles (f32, normalised weights), `n_particles` and `n_filter`, never the
    /// header. A filter of more than [`MAX_PARTICLES`] writes every (J / `MAX_PARTICLES`)-th
    /// particle, an evenly strided subset of `MAX_PARTICLES` whose weights are normalised again:
    /// the message is a picture of the cloud for a viewer, not the filter's state, which nothing
    /// restores from it (a restart draws a fresh set around the last pose).
    fn write_particles(&self, out: &mut Particles) -> bool {
        let total = self.n;
        let n = total.min(MAX_PARTICLES);
        let (xs, ys, ts, ws) = (
            scalars(&self.x),
            scalars(&self.y),
            scalars(&self.theta),
            scalars(&self.w),
        );
        // Particle i of the message is particle ⌊i·J/n⌋ of the filter: every one when J ≤ n.
        let pick = |i: usize| i * total / n;
        let picked_weight: f64 = (0..n).map(|i| ws[pick(i)]).sum();
        let scale = if picked_weight > 0.0 {
            1.0 / picked_weight
        } else {
            0.0
        };
        for (i, p) in out.particles[..n].iter_mut().enumerate() {
            let j = pick(i);
            *p = Particle {
                x: xs[j] as f32,
                y: ys[j] as f32,
                theta: ts[j] as f32,
                w: if scale > 0.0 {
                    (ws[j] * scale) as f32
                } else {
                    1.0 / n as f32
                },
            };
        }
        out.n_particles = n as u32;
        out.n_filter = total as u32;
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

    /// A filter among [`beacon_sites`] with the tests' noise.
    fn filter(initial: Pose2, config: PfConfig, seed: u64) -> ParticleFilter {
        let noise = NoiseModel::new(0.05, 0.05, 0.05, 0.02, 0.5);
        ParticleFilter::new(initial, config, noise, &beacon_sites(), seed)
    }

    fn pf(n: usize) -> ParticleFilter {
        let config = PfConfig {
            n_particles: n,
            initial_std_xy: 0.3,
            initial_std_theta: 0.2,
            ..PfConfig::default()
        };
        filter(Pose2::new(5.0, 5.0, 0.0), config, 7)
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
        for (w, r) in scalars_mut(&mut pf.w).iter_mut().zip(&raw) {
            *w = r / sum;
        }
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

    /// sin θ and cos θ are carried from step to step by small rotations: over a long run they
    /// must stay those of θ, and of unit length, to rounding.
    #[test]
    fn the_carried_sin_and_cos_stay_those_of_theta() {
        let mut p = spread_pf(64);
        for k in 0..20_000 {
            let omega = if k % 2000 < 1000 { 0.9 } else { -0.4 };
            p.predict_with(0.3, omega, 0.01).unwrap();
        }
        let n = p.len();
        for j in 0..n {
            let (st, ct) = scalars(&p.theta)[j].sin_cos();
            let (s, c) = (scalars(&p.sin_t)[j], scalars(&p.cos_t)[j]);
            assert!(
                (s - st).abs() < 1e-13 && (c - ct).abs() < 1e-13,
                "{j}: {s} {c} vs {st} {ct}"
            );
            assert!(
                (s.mul_add(s, c * c) - 1.0).abs() < 1e-15,
                "{j}: |(sin, cos)| drifted"
            );
        }
    }

    /// A set of `n` particles spread around (5, 5) with headings all round, so the kernels see
    /// every octant of atan2 and the wrap of θ.
    fn spread_pf(n: usize) -> ParticleFilter {
        let config = PfConfig {
            n_particles: n,
            initial_std_xy: 4.0,
            initial_std_theta: 3.0,
            ..PfConfig::default()
        };
        filter(Pose2::new(5.0, 5.0, 3.0), config, 5)
    }

    /// The lane kernels against the scalar formulas with std's libm (hypot, atan2, sin_cos,
    /// wrap_angle), on a set whose size is not a multiple of the lanes.
    #[test]
    fn lane_kernels_match_the_scalar_formulas() {
        let mut pf = spread_pf(1003);
        let before: Vec<Pose2> = (0..pf.len()).map(|j| pf.particle(j).unwrap()).collect();
        let (v, omega, dt) = (0.7, -1.9, 0.1);
        let sideways = Vector2::new(0.01, -0.02);
        pf.predict_sliding_with(v, omega, dt, &sideways).unwrap();
        let floor = pf.noise.r_floor(dt);
        let (sv, sw) = (pf.noise.odom_v_std, pf.noise.odom_omega_std);
        let d = |c: usize, j: usize| scalars(&pf.draws[c])[j];
        for (j, p) in before.iter().enumerate() {
            let vj = v + sv * d(0, j);
            let wj = omega + sw * d(1, j);
            let half = 0.5 * wj * dt;
            let s = vj * dt * crate::models::sinc(half);
            let (sp, cp) = (p.theta + half).sin_cos();
            let theta = wrap_angle(p.theta + wj * dt + floor[(2, 2)].sqrt() * d(4, j));
            let (st, ct) = theta.sin_cos();
            let x =
                p.x + s * cp + floor[(0, 0)].sqrt() * d(2, j) + ct * sideways[0] - st * sideways[1];
            let y =
                p.y + s * sp + floor[(1, 1)].sqrt() * d(3, j) + st * sideways[0] + ct * sideways[1];
            let q = pf.particle(j).unwrap();
            assert_relative_eq!(q.x, x, epsilon = 1e-12);
            assert_relative_eq!(q.y, y, epsilon = 1e-12);
            assert!(
                wrap_angle(q.theta - theta).abs() < 1e-12,
                "{j}: {} {theta}",
                q.theta
            );
            assert!(q.theta.abs() <= core::f64::consts::PI);
            // sin θ and cos θ are kept with θ.
            let (st, ct) = q.theta.sin_cos();
            assert_relative_eq!(scalars(&pf.sin_t)[j], st, epsilon = 1e-15);
            assert_relative_eq!(scalars(&pf.cos_t)[j], ct, epsilon = 1e-15);
        }
        // The series of a step's turn against std, up to where it is used.
        for i in -100..=100 {
            let a = i as f64 * SMALL_ANGLE / 100.0;
            let (s, c) = small_sin_cos(f64x4::splat(a));
            assert!((s.to_array()[0] - a.sin()).abs() < 2e-17, "{a}");
            assert!((c.to_array()[0] - a.cos()).abs() < 2e-16, "{a}");
            let sinc = small_sinc_cos(f64x4::splat(a)).0.to_array()[0];
            assert!((sinc - crate::models::sinc(a)).abs() < 2e-16, "{a}");
        }

        // Weights: ln p of a range-bearing reading, the bearing wrapped, summed in log space.
        let start = scalars(&pf.log_w)[..pf.len()].to_vec();
        let reading = BeaconReading {
            id: 2,
            _pad: 0,
            range: 6.0,
            bearing: -2.5,
        };
        pf.weigh_beacon(&reading).unwrap();
        let q = pf.noise.q_beacon();
        for (j, &l0) in start.iter().enumerate() {
            let p = pf.particle(j).unwrap();
            let (dx, dy) = (10.0 - p.x, 10.0 - p.y);
            let er = reading.range - dx.hypot(dy);
            let eb = wrap_angle(reading.bearing - (dy.atan2(dx) - p.theta));
            let expected = l0 - 0.5 * er * er / q[(0, 0)] + (eb.cos() - 1.0) / q[(1, 1)];
            assert_relative_eq!(scalars(&pf.log_w)[j], expected, max_relative = 1e-12);
        }
        // The lanes past J weigh nothing, whatever the readings.
        assert!(
            scalars(&pf.log_w)[pf.len()..]
                .iter()
                .all(|&l| l == f64::NEG_INFINITY)
        );

        // Normalisation and the summary against the scalar sums.
        pf.normalise();
        pf.summarise();
        let w = pf.weights();
        let (mut mx, mut my, mut c, mut s) = (0.0, 0.0, 0.0, 0.0);
        for (j, &wj) in w.iter().enumerate() {
            let p = pf.particle(j).unwrap();
            mx += wj * p.x;
            my += wj * p.y;
            c += wj * p.theta.cos();
            s += wj * p.theta.sin();
        }
        let mt = s.atan2(c);
        let mut tt = 0.0;
        for (j, &wj) in w.iter().enumerate() {
            let et = wrap_angle(pf.particle(j).unwrap().theta - mt);
            tt += wj * et * et;
        }
        let mean = pf.pose();
        assert_relative_eq!(mean.x, mx, epsilon = 1e-12);
        assert_relative_eq!(mean.y, my, epsilon = 1e-12);
        assert_relative_eq!(mean.theta, mt, epsilon = 1e-12);
        assert_relative_eq!(pf.covariance()[8], tt, max_relative = 1e-9);
    }

    /// docs/algorithms.md §6.7: the von Mises bearing term κ(cos e − 1) is within 0.2 % of the
    /// Gaussian −e²/2σ² inside 3σ for σ ≤ 0.05 rad, and within 0.06 % at σ = 0.02.
    #[test]
    fn von_mises_bearing_term_is_the_gaussian_within_three_sigma() {
        let worst = |sigma: f64| {
            (1..=300)
                .map(|i| {
                    let e = 3.0 * sigma * i as f64 / 300.0;
                    let gauss = -0.5 * e * e / (sigma * sigma);
                    let von_mises = (e.cos() - 1.0) / (sigma * sigma);
                    (von_mises - gauss).abs() / gauss.abs()
                })
                .fold(0.0, f64::max)
        };
        assert!(worst(0.05) < 2e-3, "{}", worst(0.05));
        assert!(worst(0.02) < 6e-4, "{}", worst(0.02));
        assert!(worst(0.01) < worst(0.05));
    }

    /// The lane exp of the normalisation against the scalar one, on lengths that leave a tail,
    /// with −∞ and NaN log weights (weight 0).
    #[test]
    fn normalisation_matches_the_scalar_exp_on_any_length() {
        for n in [1usize, 2, 3, 4, 5, 7, 8, 9, 31] {
            let mut log_w: Vec<f64> = (0..n).map(|j| -0.37 * (j * j) as f64).collect();
            if n > 2 {
                log_w[1] = f64::NEG_INFINITY;
                log_w[n - 1] = f64::NAN;
            }
            let raw: Vec<f64> = log_w
                .iter()
                .map(|&l| if l.is_finite() { l.exp() } else { 0.0 })
                .collect();
            let total: f64 = raw.iter().sum();
            let mut w = vec![9.0; n];
            let n_eff = normalise_log_weights(&mut log_w, &mut w);
            for j in 0..n {
                assert_relative_eq!(w[j], raw[j] / total, max_relative = 1e-14);
            }
            let sum_sq: f64 = w.iter().map(|w| w * w).sum();
            assert_relative_eq!(n_eff, 1.0 / sum_sq, max_relative = 1e-14);
        }
    }

    /// Fox's bound by hand: n = (k−1)/(2ε)·(1 − b + √b·z)³, b = 2/(9(k−1)), ε = 0.05, z = 2.33.
    /// k = 2: b = 2/9, 1 − 0.2222 + 0.4714·2.33 = 1.87615, ³ = 6.6039, ·10 = 66.04 → 67;
    /// k = 10: b = 2/81, 1 − 0.02469 + 0.15713·2.33 = 1.34143, ³ = 2.41383, ·90 = 217.24 → 218.
    #[test]
    fn kld_bound_matches_hand_computed_values() {
        for (k, n) in [(0, 0), (1, 0), (2, 67), (10, 218)] {
            assert_eq!(kld_sample_bound(k, 0.05, 2.33), n, "k = {k}");
        }
        // Half the error bound, twice the particles (to the rounding up).
        assert_eq!(kld_sample_bound(10, 0.025, 2.33), 435);
        // Wilson–Hilferty: the bound is the χ²(k − 1) quantile at 1 − δ = 0.99 over 2ε.
        use statrs::distribution::{ChiSquared, ContinuousCDF};
        for k in [50usize, 500, 5000] {
            let q = ChiSquared::new((k - 1) as f64).unwrap().inverse_cdf(0.99);
            let n = kld_sample_bound(k, 0.05, 2.326_347_874);
            assert_relative_eq!(n as f64, q / 0.1, max_relative = 5e-3);
        }
        // The set size: the bound within [min, max].
        let cfg = PfConfig {
            kld: true,
            min_particles: 150,
            n_particles: 1000,
            ..PfConfig::default()
        };
        let bins = KldBins::new(&cfg, 1000);
        let sizes = [1, 10, 100].map(|k| bins.target(k, 1000));
        assert_eq!(sizes, [150, 218, 1000]);
    }

    fn kld_pf(n: usize, min: usize, std_xy: f64, std_theta: f64, seed: u64) -> ParticleFilter {
        let config = PfConfig {
            n_particles: n,
            min_particles: min,
            kld: true,
            initial_std_xy: std_xy,
            initial_std_theta: std_theta,
            ..PfConfig::default()
        };
        // Mid-bin: bins of 0.2 m and 10° start at 0.
        filter(Pose2::new(5.1, 5.1, 5f64.to_radians()), config, seed)
    }

    /// All particles in one bin: k = 1, the bound is 0, the set shrinks to `min_particles`; a
    /// belief over more bins than the bound needs keeps the most; between, the set is the bound
    /// of the bins its particles occupy; a tight set that spreads again grows back.
    #[test]
    fn kld_shrinks_a_tight_belief_to_the_minimum_and_keeps_a_spread_one() {
        let mut tight = kld_pf(5000, 121, 1e-3, 1e-3, 3);
        assert_eq!((tight.len(), tight.capacity()), (5000, 5000));
        tight.resample();
        assert_eq!(tight.len(), 121);
        assert_eq!(tight.weights().len(), 121);
        assert_relative_eq!(tight.weights().iter().sum::<f64>(), 1.0, epsilon = 1e-12);
        assert!(tight.particle(120).is_some() && tight.particle(121).is_none());
        // The lanes past J weigh nothing, so the summary is of the 121.
        assert!(scalars(&tight.w)[121..].iter().all(|&w| w == 0.0));
        let mut out: Box<Particles> = bytemuck::zeroed_box();
        assert!(tight.write_particles(&mut out));
        assert_eq!((out.n_particles, out.n_filter), (121, 121));
        assert_eq!(mole_types::Message::validate(&*out), Ok(()));

        // 3 m × 3 m × 2π: thousands of bins, a bound far above 5000.
        let mut spread = kld_pf(5000, 121, 3.0, 3.0, 3);
        spread.resample();
        assert_eq!(spread.len(), 5000);

        let mut mid = kld_pf(5000, 10, 0.15, 0.1, 3);
        mid.resample();
        let mut bins = KldBins::new(&PfConfig::default(), 5000);
        bins.clear();
        let k = (0..mid.len())
            .filter(|&j| {
                let p = mid.particle(j).unwrap();
                bins.insert(p.x, p.y, p.theta)
            })
            .count();
        assert!(
            k > 1 && mid.len() < 5000,
            "k = {k}, {} particles",
            mid.len()
        );
        assert_eq!(mid.len(), kld_sample_bound(k, 0.05, 2.33), "k = {k}");

        for _ in 0..3 {
            tight.noise.odom_omega_std = 2.0;
            tight.noise.odom_v_std = 2.0;
            tight.predict_with(1.0, 0.0, 1.0).unwrap();
        }
        tight.resample();
        assert!(tight.len() > 1000, "{}", tight.len());
    }

    /// The same seed gives the same run, KLD-sampling and all; another seed another run; the
    /// set shrinks as the beacons tighten the belief.
    #[test]
    fn kld_runs_reproduce_from_the_seed() {
        let run = |seed: u64| {
            let mut pf = kld_pf(3000, 50, 0.3, 0.2, seed);
            let mut beacons: Box<Beacons> = bytemuck::zeroed_box();
            for (i, b) in beacon_sites().iter().enumerate() {
                let (dx, dy) = (b.x - 5.2, b.y - 5.0);
                beacons.readings[i] = BeaconReading {
                    id: b.id,
                    _pad: 0,
                    range: dx.hypot(dy),
                    bearing: dy.atan2(dx),
                };
            }
            beacons.n_readings = 3;
            let mut odom: Odom = bytemuck::Zeroable::zeroed();
            (odom.v, odom.omega, odom.dt) = (0.5, 0.2, 0.1);
            let mut sizes = Vec::new();
            for _ in 0..20 {
                pf.step(&Readings::of(&odom).with_beacons(Some(&beacons)));
                sizes.push(pf.len());
            }
            let cloud: Vec<_> = (0..pf.len()).map(|j| pf.particle(j).unwrap()).collect();
            (sizes, cloud, pf.pose(), pf.covariance())
        };
        let a = run(11);
        assert!(
            a.0.iter().any(|&n| n < 3000),
            "KLD never shrank the set: {:?}",
            a.0
        );
        assert_eq!(a, run(11));
        assert_ne!(a.1, run(12).1);
    }

    /// A minimum above the most is the most: `n_particles` = 1,000 with the default minimum of
    /// 2,000 runs, and a tight belief keeps all 1,000.
    #[test]
    fn min_particles_above_the_count_keeps_the_count() {
        use mole_types::settings::Setting as _;
        let cfg = PfConfig {
            n_particles: 1000,
            kld: true,
            ..PfConfig::default()
        };
        assert!(cfg.check_at("pf").is_ok());
        let mut pf = kld_pf(1000, DEFAULT_MIN_PARTICLES, 1e-3, 1e-3, 3);
        pf.resample();
        assert_eq!(pf.len(), 1000);
    }
}
