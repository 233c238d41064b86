//! FastSLAM 1.0 (Thrun et al. 2005 §13.3, Montemerlo et al. 2002): particles that each carry a
//! pose and a small EKF (2-D mean, 2×2 covariance) per landmark, in arrays preallocated for
//! `capacity` landmarks per particle and double-buffered for resampling.
//!
//! The particles are split into islands, independent filters that weigh and resample only their
//! own particles, and the estimate is the islands' equal mixture (docs/algorithms.md §6.9.3).
//! One filter's map is over-confident on long runs: resampling leaves its particles one ancestor
//! (path degeneracy, Bailey, Nieto & Nebot, "Consistency of the FastSLAM algorithm", ICRA 2006),
//! so the spread term of the mixture, the only place the path's uncertainty enters the map,
//! vanishes and each landmark's Σ is one path's. Islands never share ancestors, so their spread
//! stays (the island particle model of Vergé, Dubarry, Del Moral & Moulines, Statistics and
//! Computing 2015, without the exchange between islands). On the ring of
//! scenarios/slam_loop.toml (tests/slam_fastslam.rs) one filter of 256 particles has a mean
//! landmark NEES of 1,119 where 2 is consistent; 32 islands of 8 particles have 2.06.

use super::{
    Association, AssociationStats, Correspondence, Gates, Landmark, SlamConfig, SlamError,
    SlotTable, Tally, checked_reading, inverse_range_bearing, observe,
};
use crate::kalman::kalman_correct;
use crate::models::{add_slide, sliding_is_plausible, unicycle_g, wrap_near};
use crate::noise::NoiseModel;
use crate::pf::{low_variance_resample, normalise_log_weights};
use mole_types::Setting;
use mole_types::{BeaconReading, LANDMARK_ANONYMOUS, MAX_LANDMARKS, Pose2, wrap_angle};
use nalgebra::{Cholesky, Matrix2, Matrix3, Vector2, Vector3};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use serde::{Deserialize, Serialize};

/// Mixed into the seed so FastSLAM's stream differs from the localiser PF's.
const FASTSLAM_SEED_SALT: u64 = 0xFA57_51A3_0000_0013;

/// Islands of the default configuration: the mixture's spread is estimated from this many
/// independent maps, and NEES against a covariance estimated from K samples is inflated by about
/// (K + 1)/(K − 4) (the mean of an inverse Wishart): 1.2 at 32.
pub const DEFAULT_ISLANDS: usize = 32;
/// Particles of the default configuration, 8 per island (on the ring, 2 per island track the
/// pose at twice the error of 8, and 20 per island no better than 8).
pub const DEFAULT_PARTICLES: usize = 256;

/// Tuning of a [`FastSlam`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, Setting)]
#[serde(default, deny_unknown_fields)]
pub struct FastSlamConfig {
    /// M, the number of particles (≥ 1), rounded up to a multiple of `islands`.
    #[setting(min = 1, fixed = "the particle sets are allocated at start")]
    pub n_particles: usize,
    /// K, the independent filters the particles are split into: each island weighs and
    /// resamples its own particles only, and the estimate is their equal mixture.
    #[setting(min = 1, fixed = "the islands are allocated at start")]
    pub islands: usize,
    /// Resample when N_eff < `resample_threshold` · M.
    #[setting(min = 0.0, max = 1.0)]
    pub resample_threshold: f64,
    /// Seed of the ChaCha stream that draws the motion noise and the resampling offsets: the
    /// run's, not a setting.
    #[serde(skip)]
    pub seed: u64,
}

impl Default for FastSlamConfig {
    fn default() -> Self {
        Self {
            n_particles: DEFAULT_PARTICLES,
            islands: DEFAULT_ISLANDS,
            resample_threshold: 0.5,
            seed: 0,
        }
    }
}

/// The particle set, struct-of-arrays; landmark k of particle j sits at j·capacity + k.
#[derive(Debug, Clone)]
struct Particles {
    pose: Vec<Vector3<f64>>,
    /// Landmarks each particle has (equal across particles with known correspondences).
    count: Vec<usize>,
    lm_mean: Vec<Vector2<f64>>,
    lm_cov: Vec<Matrix2<f64>>,
    lm_id: Vec<u32>,
}

impl Particles {
    /// `n` particles at `pose` with room for `capacity` landmarks each.
    fn new(n: usize, capacity: usize, pose: Vector3<f64>) -> Self {
        Self {
            pose: vec![pose; n],
            count: vec![0; n],
            lm_mean: vec![Vector2::zeros(); n * capacity],
            lm_cov: vec![Matrix2::zeros(); n * capacity],
            lm_id: vec![0; n * capacity],
        }
    }
}

/// FastSLAM 1.0 with known or unknown correspondences (Thrun §13.3, Tables 13.1 and 13.2).
#[derive(Debug, Clone)]
pub struct FastSlam {
    /// Odometry noise (the proposal) and Q_t of the readings.
    pub noise: NoiseModel,
    config: SlamConfig,
    gates: Gates,
    resample_threshold: f64,
    /// K islands of `per_island` particles each; island k holds particles k·per_island…
    islands: usize,
    per_island: usize,
    /// N_eff of each island after the last correction.
    island_n_eff: Vec<f64>,
    capacity: usize,
    set: Particles,
    next: Particles,
    /// ln w, normalised within each island after each correction.
    log_w: Vec<f64>,
    /// The weights of the whole set: each island's normalised weights over K.
    w: Vec<f64>,
    picks: Vec<usize>,
    rng: ChaCha8Rng,
    /// Known correspondences: id → slot, shared by all particles (they all meet a landmark at
    /// the same reading).
    slots: SlotTable,
    mean: Vector3<f64>,
    cov: Matrix3<f64>,
    best: usize,
    n_eff: f64,
    tally: Tally,
    resamples: u64,
}

/// One standard normal draw.
#[inline]
fn gauss(rng: &mut ChaCha8Rng) -> f64 {
    rng.sample(StandardNormal)
}

/// ln N(ν; 0, S) from νᵀ S⁻¹ ν and det S, the importance factor of Thrun Table 13.1 line 18.
#[inline]
fn log_gaussian(d2: f64, det_s: f64) -> f64 {
    -0.5 * d2 - (core::f64::consts::TAU).ln() - 0.5 * det_s.ln()
}

impl FastSlam {
    /// M particles at `pose` (the map frame is the start pose, so all start there), each with
    /// room for `capacity` landmarks; all memory is allocated here.
    pub fn new(
        pose: Pose2,
        noise: NoiseModel,
        capacity: usize,
        config: SlamConfig,
        fast: FastSlamConfig,
    ) -> Self {
        let islands = fast.islands.max(1);
        let per_island = fast.n_particles.max(1).div_ceil(islands);
        let n = islands * per_island;
        let fin = |v: f64| if v.is_finite() { v } else { 0.0 };
        let start = Vector3::new(fin(pose.x), fin(pose.y), wrap_angle(fin(pose.theta)));
        let threshold = if fast.resample_threshold.is_finite() {
            fast.resample_threshold.clamp(0.0, 1.0)
        } else {
            0.5
        };
        Self {
            noise,
            gates: Gates::new(&config),
            config,
            resample_threshold: threshold,
            islands,
            per_island,
            island_n_eff: vec![per_island as f64; islands],
            capacity,
            set: Particles::new(n, capacity, start),
            next: Particles::new(n, capacity, start),
            log_w: vec![-(per_island as f64).ln(); n],
            w: vec![1.0 / n as f64; n],
            picks: vec![0; n],
            rng: ChaCha8Rng::seed_from_u64(fast.seed ^ FASTSLAM_SEED_SALT),
            slots: SlotTable::with_capacity(capacity),
            mean: start,
            cov: Matrix3::zeros(),
            best: 0,
            n_eff: n as f64,
            tally: Tally::default(),
            resamples: 0,
        }
    }

    /// M, the number of particles.
    pub fn len(&self) -> usize {
        self.w.len()
    }

    /// Whether the set is empty (never: M ≥ 1).
    pub fn is_empty(&self) -> bool {
        self.w.is_empty()
    }

    /// Normalised weights.
    pub fn weights(&self) -> &[f64] {
        &self.w
    }

    /// N_eff = 1/Σw² after the last correction (before the resampling it triggered).
    pub fn n_eff(&self) -> f64 {
        self.n_eff
    }

    /// How many times the set was resampled.
    pub fn resamples(&self) -> u64 {
        self.resamples
    }

    /// Association decisions of the most likely particle so far.
    pub fn association_stats(&self) -> AssociationStats {
        self.tally.stats
    }

    /// Known correspondences: readings refused by the outlier gate so far.
    pub fn rejected(&self) -> u64 {
        self.tally.rejected
    }

    /// Inputs ignored so far: non-finite or implausible controls and readings, a full map.
    pub fn ignored(&self) -> u64 {
        self.tally.ignored
    }

    /// The weighted mean pose, θ the circular mean (atan2 of the weighted mean sin and cos).
    pub fn pose(&self) -> Pose2 {
        Pose2::new(self.mean[0], self.mean[1], self.mean[2])
    }

    /// The weighted covariance of the particle poses (θ deviations wrapped).
    pub fn pose_covariance(&self) -> Matrix3<f64> {
        self.cov
    }

    /// The map. Known correspondences: per landmark the moments of the particles' mixture,
    /// mean Σ wⱼ μⱼ and covariance Σ wⱼ (Σⱼ + (μⱼ − μ)(μⱼ − μ)ᵀ) (Thrun §13.3 leaves the choice
    /// open; the mixture uses every particle, where one particle's map carries its path's
    /// error). Unknown correspondences: the map of the most likely particle at the last
    /// correction (Montemerlo et al. 2002), as slots need not agree across particles.
    pub fn landmarks(&self) -> impl Iterator<Item = Landmark> + '_ {
        let known = self.config.correspondence == Correspondence::Known;
        let cap = self.capacity;
        let best = self.best;
        (0..self.set.count[best]).map(move |slot| {
            let i = best * cap + slot;
            if !known {
                return Landmark {
                    id: self.set.lm_id[i],
                    mean: self.set.lm_mean[i],
                    cov: self.set.lm_cov[i],
                };
            }
            let mut mean = Vector2::zeros();
            for (j, w) in self.w.iter().enumerate() {
                mean += self.set.lm_mean[j * cap + slot] * *w;
            }
            let mut cov = Matrix2::zeros();
            for (j, w) in self.w.iter().enumerate() {
                let e = self.set.lm_mean[j * cap + slot] - mean;
                cov += (self.set.lm_cov[j * cap + slot] + e * e.transpose()) * *w;
            }
            Landmark {
                id: self.set.lm_id[i],
                mean,
                cov,
            }
        })
    }

    /// The degrees of freedom of the map's mean landmark NEES ([`crate::slam::mean_nees_dof`])
    /// under the particles' mixture, whose cross-covariances are the landmarks' spread across
    /// particles, Σ_p w_p (μ_pi − μ̄ᵢ)(μ_pj − μ̄ⱼ)ᵀ: each particle's landmarks are independent
    /// given its path, but the paths differ. With unknown correspondences the map is the best
    /// particle's alone, whose landmarks are independent: 2n.
    pub fn mean_nees_dof(&self) -> f64 {
        let n = self.set.count[self.best].min(MAX_LANDMARKS);
        if self.config.correspondence != Correspondence::Known {
            return if n > 0 { 2.0 * n as f64 } else { 0.0 };
        }
        let cap = self.capacity;
        let mut mean = [Vector2::zeros(); MAX_LANDMARKS];
        for (slot, m) in mean.iter_mut().enumerate().take(n) {
            for (j, w) in self.w.iter().enumerate() {
                *m += self.set.lm_mean[j * cap + slot] * *w;
            }
        }
        crate::slam::mean_nees_dof(n, |a, b| {
            let mut c = Matrix2::zeros();
            for (j, w) in self.w.iter().enumerate() {
                let da = self.set.lm_mean[j * cap + a] - mean[a];
                let db = self.set.lm_mean[j * cap + b] - mean[b];
                c += da * db.transpose() * *w;
                if a == b {
                    c += self.set.lm_cov[j * cap + a] * *w;
                }
            }
            c
        })
    }

    /// Sampling the proposal (Thrun §13.3, Table 13.1 line 4): every particle moves along the
    /// unicycle arc with its own draw of the odometry noise v + σ_v·n, ω + σ_ω·n, plus the
    /// additive floor of the noise model. A non-finite or implausible control is ignored (and
    /// counted); dt = 0 changes nothing.
    pub fn predict(&mut self, v: f64, omega: f64, dt: f64) -> Result<(), SlamError> {
        self.predict_sliding(v, omega, dt, &Vector2::zeros())
    }

    /// [`FastSlam::predict`] followed by the slide `sideways` the wheels did not see (robot
    /// frame at the arc's end, [`crate::contact`]): each particle moves by R(θ_j)·b.
    pub fn predict_sliding(
        &mut self,
        v: f64,
        omega: f64,
        dt: f64,
        sideways: &Vector2<f64>,
    ) -> Result<(), SlamError> {
        if !sliding_is_plausible(v, omega, dt, sideways) {
            self.tally.ignored += 1;
            return Err(SlamError::Invalid);
        }
        if dt == 0.0 {
            return Ok(());
        }
        let (sv, sw) = (self.noise.odom_v_std, self.noise.odom_omega_std);
        let floor = self.noise.r_floor(dt);
        let floor_std = Vector3::new(
            floor[(0, 0)].sqrt(),
            floor[(1, 1)].sqrt(),
            floor[(2, 2)].sqrt(),
        );
        for pose in self.set.pose.iter_mut() {
            let vj = v + sv * gauss(&mut self.rng);
            let wj = omega + sw * gauss(&mut self.rng);
            let mut moved = unicycle_g(pose, vj, wj, dt);
            for k in 0..3 {
                moved[k] += floor_std[k] * gauss(&mut self.rng);
            }
            moved[2] = wrap_near(moved[2]);
            add_slide(&mut moved, None, sideways);
            *pose = moved;
        }
        self.summarise();
        Ok(())
    }

    /// Correction with every reading (importance weights in log space), then normalisation and
    /// low-variance resampling when N_eff < threshold · M (Thrun §13.3, Table 13.1 lines 5–27).
    pub fn correct(&mut self, readings: &[BeaconReading]) {
        for reading in readings {
            // Refusals are counted inside.
            let _ = self.correct_reading(reading);
        }
        self.finish_correction();
    }

    /// Weighs every particle by a position fix z = (x, y) of covariance `q_t`,
    /// w ∝ N(z; (xⱼ, yⱼ), Q_t) (a linear reading of the pose, as the localising PF weighs it);
    /// call [`FastSlam::finish_correction`] after it. A fix that is not finite or whose `q_t` is
    /// not positive definite is ignored and counted.
    pub fn weigh_fix(&mut self, x: f64, y: f64, q_t: &Matrix2<f64>) -> Result<(), SlamError> {
        let chol = Cholesky::new(*q_t).filter(|_| x.is_finite() && y.is_finite());
        let Some(chol) = chol else {
            self.tally.ignored += 1;
            return Err(SlamError::Invalid);
        };
        for (pose, log_w) in self.set.pose.iter().zip(self.log_w.iter_mut()) {
            let e = Vector2::new(x - pose[0], y - pose[1]);
            *log_w -= 0.5 * e.dot(&chol.solve(&e));
        }
        Ok(())
    }

    /// Adds `landmark` (mean, covariance) to every particle's map and returns its slot; its id
    /// goes into the id table when correspondences are known and it is not anonymous. Refused
    /// when it is not finite and positive definite, or a particle's map is full. Meant for a
    /// filter that starts from another estimator's map (every particle has the same landmarks).
    pub fn insert_landmark(&mut self, landmark: &Landmark) -> Result<usize, SlamError> {
        if !landmark.is_usable() {
            return Err(SlamError::Invalid);
        }
        let slot = self.set.count[0];
        if self.set.count.iter().any(|&c| c != slot) || slot == self.capacity {
            return Err(SlamError::MapFull);
        }
        if self.config.correspondence == Correspondence::Known
            && landmark.id != LANDMARK_ANONYMOUS
            && !self.slots.insert(landmark.id, slot)
        {
            return Err(SlamError::MapFull);
        }
        for j in 0..self.len() {
            let i = j * self.capacity + slot;
            self.set.lm_mean[i] = landmark.mean;
            self.set.lm_cov[i] = landmark.cov;
            self.set.lm_id[i] = landmark.id;
            self.set.count[j] += 1;
        }
        Ok(slot)
    }

    /// Scatters the particles around their (common) start pose by N(0, Σ) with the filter's own
    /// random stream, for a filter that starts from another estimator's uncertain pose; a Σ
    /// that is not finite and positive semi-definite leaves them where they are.
    pub fn scatter(&mut self, sigma: &Matrix3<f64>) {
        let jittered = sigma + Matrix3::identity() * 1e-12;
        let Some(chol) = Cholesky::new(jittered).filter(|_| sigma.iter().all(|v| v.is_finite()))
        else {
            return;
        };
        let l = chol.l();
        for pose in self.set.pose.iter_mut() {
            let n = Vector3::new(
                gauss(&mut self.rng),
                gauss(&mut self.rng),
                gauss(&mut self.rng),
            );
            let d = l * n;
            *pose = Vector3::new(pose[0] + d[0], pose[1] + d[1], wrap_angle(pose[2] + d[2]));
        }
        self.summarise();
    }

    /// Ends a correction made reading by reading with [`FastSlam::correct_reading`]: normalises
    /// the weights, updates the estimate, and resamples when N_eff < threshold · M.
    pub fn finish_correction(&mut self) {
        self.normalise();
        self.summarise();
        let low = self.resample_threshold * self.per_island as f64;
        if self.island_n_eff.iter().any(|&n| n < low) {
            self.resample(low);
        }
    }

    /// One reading into every particle: the landmark EKF update and the importance factor
    /// w ∝ N(ν; 0, H Σ Hᵀ + Q_t) (Thrun Table 13.1 lines 12–18), or initialisation on first
    /// sight. Weights are not normalised here: call [`FastSlam::finish_correction`] after the
    /// step's last reading ([`FastSlam::correct`] does both). Returns the
    /// decision of the most likely particle.
    pub fn correct_reading(&mut self, reading: &BeaconReading) -> Result<Association, SlamError> {
        let result = self.try_correct_reading(reading);
        self.tally.record(&result);
        result
    }

    fn try_correct_reading(&mut self, reading: &BeaconReading) -> Result<Association, SlamError> {
        let z = checked_reading(reading.range, reading.bearing, self.config.max_range)
            .ok_or(SlamError::Invalid)?;
        if z[0] < crate::models::MIN_RANGE {
            return Err(SlamError::TooClose);
        }
        if reading.id == LANDMARK_ANONYMOUS {
            self.config.correspondence = Correspondence::Unknown;
        }
        let best = self.most_likely_particle();
        match self.config.correspondence {
            Correspondence::Known => match self.slots.get(reading.id) {
                Some(slot) => self.update_known(slot, reading.id, &z, best),
                None => {
                    let slot = self.slots_in_use();
                    if slot == self.capacity || !self.slots.insert(reading.id, slot) {
                        return Err(SlamError::MapFull);
                    }
                    // Every particle founds it; w·p₀ is the same for all, so no weight change.
                    for j in 0..self.len() {
                        self.found(j, reading.id, &z);
                    }
                    Ok(Association::New {
                        slot,
                        id: reading.id,
                    })
                }
            },
            Correspondence::Unknown => {
                let mut decision = Err(SlamError::MapFull);
                for j in 0..self.len() {
                    let a = self.associate_particle(j, reading.id, &z);
                    if j == best {
                        decision = a;
                    }
                }
                decision
            }
        }
    }

    /// Known correspondences: refused for every particle when the most likely particle finds
    /// the reading beyond the outlier gate, else every particle's landmark EKF takes it.
    fn update_known(
        &mut self,
        slot: usize,
        id: u32,
        z: &Vector2<f64>,
        best: usize,
    ) -> Result<Association, SlamError> {
        let (d2, _) = self
            .landmark_likelihood(best, slot, z)
            .ok_or(SlamError::TooClose)?;
        if d2 > self.gates.outlier {
            return Err(SlamError::Outlier {
                mahalanobis2: d2,
                gate: self.gates.outlier,
            });
        }
        for j in 0..self.len() {
            self.update_particle(j, slot, z);
        }
        Ok(Association::Matched { slot, id })
    }

    /// Unknown correspondences for particle j (Thrun §13.5, Table 13.2, with two gates): the
    /// maximum-likelihood landmark inside the association gate is updated; a reading beyond the
    /// creation gate of every landmark founds one; in between it is discarded. Both founding
    /// and discarding weigh the particle by p₀ = N at the association gate under Q_t alone.
    fn associate_particle(
        &mut self,
        j: usize,
        id: u32,
        z: &Vector2<f64>,
    ) -> Result<Association, SlamError> {
        let (mut best, mut best_score, mut min_d2) = (None, f64::INFINITY, f64::INFINITY);
        for slot in 0..self.set.count[j] {
            if let Some((d2, det_s)) = self.landmark_likelihood(j, slot, z) {
                min_d2 = min_d2.min(d2);
                let score = d2 + det_s.ln();
                if d2 <= self.gates.associate && score < best_score {
                    (best, best_score) = (Some(slot), score);
                }
            }
        }
        if let Some(slot) = best {
            self.update_particle(j, slot, z);
            return Ok(Association::Matched {
                slot,
                id: self.set.lm_id[j * self.capacity + slot],
            });
        }
        self.log_w[j] += log_gaussian(self.gates.associate, self.noise.q_beacon().determinant());
        if min_d2 <= self.gates.create {
            return Ok(Association::Discarded);
        }
        if self.set.count[j] == self.capacity {
            return Err(SlamError::MapFull);
        }
        let slot = self.found(j, id, z);
        Ok(Association::New { slot, id })
    }

    /// (νᵀ S⁻¹ ν, det S) of a reading of landmark `slot` in particle j, S = H Σ Hᵀ + Q_t.
    fn landmark_likelihood(&self, j: usize, slot: usize, z: &Vector2<f64>) -> Option<(f64, f64)> {
        let i = j * self.capacity + slot;
        let (z_hat, _, h_m) = observe(&self.set.pose[j], &self.set.lm_mean[i])?;
        let s_t = h_m * self.set.lm_cov[i] * h_m.transpose() + self.noise.q_beacon();
        let nu = Vector2::new(z[0] - z_hat[0], wrap_angle(z[1] - z_hat[1]));
        let chol = Cholesky::new(s_t)?;
        Some((nu.dot(&chol.solve(&nu)), s_t.determinant()))
    }

    /// The landmark EKF update of particle j (Thrun Table 13.1 lines 12–17, the crate's
    /// Joseph-form [`kalman_correct`]) and its importance factor ln N(ν; 0, S) (line 18). A
    /// particle whose landmark is too close or degenerate gets weight 0.
    fn update_particle(&mut self, j: usize, slot: usize, z: &Vector2<f64>) {
        let i = j * self.capacity + slot;
        let Some((z_hat, _, h_m)) = observe(&self.set.pose[j], &self.set.lm_mean[i]) else {
            self.log_w[j] = f64::NEG_INFINITY;
            return;
        };
        let q_t = self.noise.q_beacon();
        let nu = Vector2::new(z[0] - z_hat[0], wrap_angle(z[1] - z_hat[1]));
        let det_s = (h_m * self.set.lm_cov[i] * h_m.transpose() + q_t).determinant();
        match kalman_correct(
            &mut self.set.lm_mean[i],
            &mut self.set.lm_cov[i],
            &nu,
            &h_m,
            &q_t,
            None,
        ) {
            Ok(d2) => self.log_w[j] += log_gaussian(d2, det_s),
            Err(_) => self.log_w[j] = f64::NEG_INFINITY,
        }
    }

    /// Founds a landmark in particle j from reading z (Thrun Table 13.1 lines 7–10): mean from
    /// the inverse observation model, Σ = J_z Q_t J_zᵀ (= H⁻¹ Q_t H⁻ᵀ). Returns its slot.
    fn found(&mut self, j: usize, id: u32, z: &Vector2<f64>) -> usize {
        let slot = self.set.count[j];
        let i = j * self.capacity + slot;
        let (m, _, j_z) = inverse_range_bearing(&self.set.pose[j], z);
        self.set.lm_mean[i] = m;
        self.set.lm_cov[i] = j_z * self.noise.q_beacon() * j_z.transpose();
        self.set.lm_id[i] = id;
        self.set.count[j] += 1;
        slot
    }

    /// Landmark slots in use with known correspondences (the same in every particle).
    fn slots_in_use(&self) -> usize {
        self.set.count[0]
    }

    /// The particle with the largest ln w.
    fn most_likely_particle(&self) -> usize {
        let mut best = 0;
        for (j, l) in self.log_w.iter().enumerate() {
            if *l > self.log_w[best] {
                best = j;
            }
        }
        best
    }

    /// Normalises each island by log-sum-exp and computes its N_eff = 1/Σw² (all-impossible
    /// islands, every ln w −∞ or NaN, are reset to uniform); the set's weights are the
    /// islands' over K, and the set's N_eff the sum of the islands'.
    fn normalise(&mut self) {
        let (per, k) = (self.per_island, self.islands as f64);
        for (i, n_eff) in self.island_n_eff.iter_mut().enumerate() {
            let r = i * per..(i + 1) * per;
            *n_eff = normalise_log_weights(&mut self.log_w[r.clone()], &mut self.w[r.clone()]);
            self.w[r].iter_mut().for_each(|w| *w /= k);
        }
        self.n_eff = self.island_n_eff.iter().sum();
    }

    /// Low-variance resampling (Thrun Table 4.4, [`low_variance_resample`]) of every island whose
    /// N_eff is below `low`, within the island, into the second buffer (the other islands are
    /// copied as they are), each particle's pose and landmark EKFs copied; a resampled island's
    /// weights become uniform.
    fn resample(&mut self, low: f64) {
        let (per, k) = (self.per_island, self.islands);
        for i in 0..k {
            let r = i * per..(i + 1) * per;
            if self.island_n_eff[i] >= low {
                self.picks[r.clone()]
                    .iter_mut()
                    .zip(r)
                    .for_each(|(p, m)| *p = m);
                continue;
            }
            let offset = self.rng.random::<f64>() / per as f64;
            low_variance_resample(&self.w[r.clone()], offset, &mut self.picks[r.clone()]);
            self.picks[r.clone()].iter_mut().for_each(|p| *p += r.start);
            self.log_w[r.clone()].fill(-(per as f64).ln());
            self.w[r].fill(1.0 / (per * k) as f64);
        }
        let cap = self.capacity;
        for (m, &i) in self.picks.iter().enumerate() {
            let k = self.set.count[i];
            self.next.pose[m] = self.set.pose[i];
            self.next.count[m] = k;
            let (src, dst) = (i * cap..i * cap + k, m * cap..m * cap + k);
            self.next.lm_mean[dst.clone()].copy_from_slice(&self.set.lm_mean[src.clone()]);
            self.next.lm_cov[dst.clone()].copy_from_slice(&self.set.lm_cov[src.clone()]);
            self.next.lm_id[dst].copy_from_slice(&self.set.lm_id[src]);
        }
        core::mem::swap(&mut self.set, &mut self.next);
        // The best particle's first copy (it has one: its weight is the largest of its island's).
        self.best = self.picks.iter().position(|&i| i == self.best).unwrap_or(0);
        self.resamples += 1;
    }

    /// Weighted mean (circular mean for θ), covariance (θ deviations wrapped) and the most
    /// likely particle.
    fn summarise(&mut self) {
        let (mut sx, mut sy, mut sc, mut ss) = (0.0, 0.0, 0.0, 0.0);
        for (p, &w) in self.set.pose.iter().zip(self.w.iter()) {
            sx += w * p[0];
            sy += w * p[1];
            let (s, c) = p[2].sin_cos();
            sc += w * c;
            ss += w * s;
        }
        let mt = if sc == 0.0 && ss == 0.0 {
            0.0
        } else {
            ss.atan2(sc)
        };
        let mean = Vector3::new(sx, sy, wrap_angle(mt));
        let mut cov = Matrix3::zeros();
        for (p, &w) in self.set.pose.iter().zip(self.w.iter()) {
            let e = Vector3::new(p[0] - sx, p[1] - sy, wrap_near(p[2] - mt));
            cov += e * e.transpose() * w;
        }
        self.mean = mean;
        self.cov = cov;
        self.best = self.most_likely_particle();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn reading(id: u32, range: f64, bearing: f64) -> BeaconReading {
        BeaconReading {
            id,
            _pad: 0,
            range,
            bearing,
        }
    }

    fn fast(correspondence: Correspondence, seed: u64) -> FastSlam {
        FastSlam::new(
            Pose2::new(0.0, 0.0, 0.0),
            NoiseModel::new(0.1, 0.05, 0.1, 0.02, 0.5),
            3,
            SlamConfig {
                correspondence,
                ..SlamConfig::default()
            },
            FastSlamConfig {
                n_particles: 50,
                seed,
                ..FastSlamConfig::default()
            },
        )
    }

    #[test]
    fn the_same_seed_reproduces_the_run_and_another_seed_does_not() {
        let run = |seed| {
            let mut f = fast(Correspondence::Known, seed);
            for k in 0..20 {
                f.predict(1.0, 0.1, 0.1).unwrap();
                f.correct(&[reading(0, 5.0 - 0.1 * f64::from(k), 0.3)]);
            }
            (f.pose(), f.landmarks().next())
        };
        assert_eq!(run(3), run(3));
        assert_ne!(run(3).0, run(4).0);
    }

    #[test]
    fn a_landmark_ekf_starts_at_the_inverse_model_with_sensor_covariance() {
        let mut f = fast(Correspondence::Known, 1);
        f.correct(&[reading(4, 2.0, core::f64::consts::FRAC_PI_2)]);
        let lm = f.landmarks().next().unwrap();
        assert_eq!(lm.id, 4);
        approx::assert_relative_eq!(lm.mean, Vector2::new(0.0, 2.0), epsilon = 1e-12);
        // Range σ 0.1 along y, bearing σ 0.02 rad · 2 m across, along x.
        approx::assert_relative_eq!(
            lm.cov,
            Matrix2::new(0.04 * 0.04, 0.0, 0.0, 0.01),
            epsilon = 1e-12
        );
    }

    /// Resampling stays within each island: every particle's ancestor is in its own island, and
    /// an island whose weights stay uniform is left as it was.
    #[test]
    fn islands_resample_only_their_own_particles() {
        let mut f = FastSlam::new(
            Pose2::new(0.0, 0.0, 0.0),
            NoiseModel::new(0.1, 0.05, 0.1, 0.02, 0.5),
            3,
            SlamConfig::default(),
            FastSlamConfig {
                n_particles: 40,
                islands: 4,
                resample_threshold: 1.0,
                seed: 2,
            },
        );
        assert_eq!((f.len(), f.per_island), (40, 10));
        let mut resampled = 0;
        for k in 0..30 {
            f.predict(1.0, 0.1, 0.1).unwrap();
            let before = f.resamples;
            f.correct(&[reading(0, 5.0 - 0.1 * f64::from(k), 0.3)]);
            if f.resamples > before {
                resampled += 1;
                for (m, &ancestor) in f.picks.iter().enumerate() {
                    assert_eq!(
                        ancestor / 10,
                        m / 10,
                        "step {k}: particle {m} from {ancestor}"
                    );
                }
            }
        }
        assert!(resampled > 10, "resampled {resampled} times");
        // Uniform weights within an island keep it as it is, whatever the others do.
        let w = [0.1; 10];
        f.w[..10].copy_from_slice(&w.map(|w| w / 4.0));
        f.island_n_eff = vec![10.0, 1.0, 1.0, 1.0];
        let first = f.set.pose[..10].to_vec();
        f.resample(5.0);
        assert_eq!(&f.picks[..10], &(0..10).collect::<Vec<_>>()[..]);
        assert_eq!(&f.set.pose[..10], &first[..]);
        // The set's weights sum to one over the islands.
        approx::assert_relative_eq!(f.w.iter().sum::<f64>(), 1.0, epsilon = 1e-12);
    }

    #[test]
    fn unknown_correspondences_match_found_and_discard() {
        let mut f = fast(Correspondence::Unknown, 1);
        assert!(matches!(
            f.correct_reading(&reading(9, 3.0, 0.0)),
            Ok(Association::New { slot: 0, id: 9 })
        ));
        // The same place again (any id): matched.
        assert!(matches!(
            f.correct_reading(&reading(1, 3.02, 0.001)),
            Ok(Association::Matched { slot: 0, id: 9 })
        ));
        // 0.44 m beyond it, S_rr ≈ 0.015: d² ≈ 13, between the gates (9.2, 18.4): discarded.
        assert_eq!(
            f.correct_reading(&reading(2, 3.45, 0.0)),
            Ok(Association::Discarded)
        );
        // Far away: a new landmark.
        assert!(matches!(
            f.correct_reading(&reading(5, 3.0, 1.5)),
            Ok(Association::New { slot: 1, id: 5 })
        ));
        let s = f.association_stats();
        assert_eq!((s.matched, s.created, s.discarded), (1, 2, 1));
    }
}
