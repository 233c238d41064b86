//! EKF-SLAM (Thrun et al. 2005 §10.2): one Gaussian over y = (x, y, θ, m₁ₓ, m₁ᵧ, …, mₙₓ, mₙᵧ),
//! preallocated for a maximum landmark count; only the active block (3 + 2n) is touched.

use super::{
    Association, AssociationStats, Correspondence, Gates, Landmark, SlamConfig, SlamError,
    SlotTable, Tally, checked_reading, inverse_range_bearing, observe,
};
use crate::kalman::symmetrize;
use crate::models::{
    add_slide, sliding_is_plausible, unicycle_g, unicycle_jacobian_g, unicycle_jacobian_v,
};
use crate::noise::NoiseModel;
use crate::slam::ci::argmin_on_unit_interval;
use mole_types::{BeaconReading, LANDMARK_ANONYMOUS, Pose2, wrap_angle};
use nalgebra::{
    Cholesky, DMatrix, DVector, Matrix2, Matrix2x3, Matrix3, SMatrix, Vector2, Vector3,
};

/// The robot's motion model as EKF-SLAM needs it: the mean g, its Jacobian G_t and the process
/// noise R_t in pose space (Thrun §10.2, Table 10.1 lines 3–5).
pub trait MotionModel {
    /// g(x, u): the pose after moving by (v, ω) for dt.
    fn g(&self, pose: &Vector3<f64>, v: f64, omega: f64, dt: f64) -> Vector3<f64>;
    /// G_t = ∂g/∂x at (x, u).
    fn jacobian_g(&self, pose: &Vector3<f64>, v: f64, omega: f64, dt: f64) -> Matrix3<f64>;
    /// R_t, the process noise added to the pose block.
    fn process_noise(&self, pose: &Vector3<f64>, v: f64, omega: f64, dt: f64) -> Matrix3<f64>;
    /// G_t at the first estimates (Huang, Mourikis & Roumeliotis 2008): ∂g/∂x of a planar rigid
    /// motion (a displacement fixed in the robot frame) whose displacement is `to` − `from`, the
    /// pose's predicted estimates at this step and the last. The default is that of every model
    /// of the form p' = p + R(θ) d(u), θ' = θ + Δθ(u), the unicycle's included.
    fn jacobian_g_first_estimates(&self, from: &Vector3<f64>, to: &Vector3<f64>) -> Matrix3<f64> {
        let mut g_t = Matrix3::identity();
        g_t[(0, 2)] = -(to[1] - from[1]);
        g_t[(1, 2)] = to[0] - from[0];
        g_t
    }
}

/// The crate's unicycle ([`crate::models`]) with R_t = V_t M_t V_tᵀ + floor (Thrun §7.4, Table
/// 7.2), the model the EKF localiser uses.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct UnicycleMotion {
    /// Odometry noise M_t and the additive floor.
    pub noise: NoiseModel,
}

impl MotionModel for UnicycleMotion {
    fn g(&self, pose: &Vector3<f64>, v: f64, omega: f64, dt: f64) -> Vector3<f64> {
        unicycle_g(pose, v, omega, dt)
    }

    fn jacobian_g(&self, pose: &Vector3<f64>, v: f64, omega: f64, dt: f64) -> Matrix3<f64> {
        unicycle_jacobian_g(pose, v, omega, dt)
    }

    fn process_noise(&self, pose: &Vector3<f64>, v: f64, omega: f64, dt: f64) -> Matrix3<f64> {
        let v_t = unicycle_jacobian_v(pose, v, omega, dt);
        v_t * self.noise.m_t() * v_t.transpose() + self.noise.r_floor(dt)
    }
}

/// How a landmark seen for the first time enters the state.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum LandmarkInit {
    /// Mean from the inverse observation model h⁻¹(x, z), covariance from its Jacobians with the
    /// pose and landmark cross-covariances (Σₘₘ = Jₓ Σₓₓ Jₓᵀ + J_z Q J_zᵀ, Σₘ. = Jₓ Σₓ.); the
    /// founding reading is then spent and not applied again.
    InverseModel,
    /// Thrun's Table 10.2 (lines 15–16): mean from h⁻¹(x, z), an uncorrelated prior σ²·I (Thrun
    /// takes σ² → ∞), then the ordinary update with the founding reading.
    Prior {
        /// σ² of the prior on each coordinate (m²).
        variance: f64,
    },
}

/// Where EKF-SLAM evaluates the Jacobians of the motion and of the readings.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Linearisation {
    /// At the current estimate, as Thrun's Table 10.1: G_t at μ_{t−1}, H at μ̄_t. The Jacobians
    /// of successive steps are then evaluated at estimates that the corrections in between have
    /// moved, and the filter gains information along the directions no reading observes (the
    /// map frame's translation and rotation): over-confident after a loop or so (Huang &
    /// Dissanayake 2007; Bailey et al. 2006).
    Estimate,
    /// First-estimates Jacobians (FEJ-EKF, Huang, Mourikis & Roumeliotis 2008): G_t from the
    /// pose's predicted estimates at this step and the last, H at the pose predicted for this
    /// step and the landmark's first estimate. The innovation still uses the current estimate;
    /// only the linearisation points are frozen, so the linearised system keeps the
    /// unobservable directions of the true one and the filter gains no spurious information.
    FirstEstimates,
}

/// What [`EkfSlam::fuse_landmarks`] did with another robot's list.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct FuseReport {
    /// Landmarks both maps had, fused by covariance intersection (ω < 1).
    pub fused: usize,
    /// Landmarks both maps had whose CI optimum was this map's own estimate (ω = 1): the other
    /// one brought less than fusing would have cost the rest of the state; left as they were.
    pub kept: usize,
    /// Landmarks only the other map had, left for this robot to map itself (see
    /// [`EkfSlam::fuse_landmarks`] for why they are not added).
    pub unmapped: usize,
    /// Entries not finite, not positive definite, or beyond the capacity.
    pub refused: usize,
}

/// EKF-SLAM over the pose and up to `capacity` landmarks (Thrun §10.2).
#[derive(Debug, Clone)]
pub struct EkfSlam<M: MotionModel = UnicycleMotion> {
    /// The motion model (g, G_t, R_t).
    pub motion: M,
    /// Q_t, the measurement noise of one range-bearing reading.
    pub q_t: Matrix2<f64>,
    /// How first sightings enter the state.
    pub landmark_init: LandmarkInit,
    /// Where the Jacobians are evaluated.
    pub linearisation: Linearisation,
    config: SlamConfig,
    gates: Gates,
    /// μ, 3 + 2·capacity long; entries past 3 + 2n are unused.
    mu: DVector<f64>,
    /// Σ, (3 + 2·capacity)²; only the active (3 + 2n)² block is meaningful.
    sigma: DMatrix<f64>,
    /// Σ Hᵀ of the update in progress (a scratch column pair).
    sigma_h: DMatrix<f64>,
    /// K of the update in progress.
    gain: DMatrix<f64>,
    n: usize,
    ids: Vec<u32>,
    slots: SlotTable,
    tally: Tally,
    /// The pose's predicted estimate μ̄_t of this step, the linearisation point of the pose
    /// ([`Linearisation::FirstEstimates`]).
    first_pose: Vector3<f64>,
    /// Each landmark's first estimate, in slot order: its linearisation point.
    first_landmarks: Vec<Vector2<f64>>,
}

/// Offset of landmark `slot` in the state vector.
#[inline]
fn offset(slot: usize) -> usize {
    3 + 2 * slot
}

impl EkfSlam<UnicycleMotion> {
    /// EKF-SLAM with the crate's unicycle and the noise model's Q_t, starting at N(pose, Σ₀)
    /// with room for `capacity` landmarks.
    pub fn new(
        pose: Pose2,
        pose_sigma: Matrix3<f64>,
        noise: NoiseModel,
        capacity: usize,
        config: SlamConfig,
    ) -> Self {
        Self::with_motion(
            UnicycleMotion { noise },
            noise.q_beacon(),
            pose,
            pose_sigma,
            capacity,
            config,
        )
    }
}

impl<M: MotionModel> EkfSlam<M> {
    /// EKF-SLAM with any motion model and measurement noise Q_t; all memory is allocated here.
    /// A non-finite start pose becomes 0; a start Σ that is not finite and symmetric positive
    /// semi-definite becomes 0 (the map frame is the start pose).
    pub fn with_motion(
        motion: M,
        q_t: Matrix2<f64>,
        pose: Pose2,
        pose_sigma: Matrix3<f64>,
        capacity: usize,
        config: SlamConfig,
    ) -> Self {
        let dim = offset(capacity);
        let fin = |v: f64| if v.is_finite() { v } else { 0.0 };
        let mut mu = DVector::zeros(dim);
        mu[0] = fin(pose.x);
        mu[1] = fin(pose.y);
        mu[2] = wrap_angle(fin(pose.theta));
        let mut sigma = DMatrix::zeros(dim, dim);
        let mut s0 = pose_sigma;
        symmetrize(&mut s0);
        let usable = s0.iter().all(|v| v.is_finite())
            && Cholesky::new(s0 + Matrix3::identity() * 1e-12).is_some();
        if usable {
            sigma.fixed_view_mut::<3, 3>(0, 0).copy_from(&s0);
        }
        let first_pose = Vector3::new(mu[0], mu[1], mu[2]);
        Self {
            motion,
            q_t,
            landmark_init: LandmarkInit::InverseModel,
            linearisation: Linearisation::FirstEstimates,
            gates: Gates::new(&config),
            config,
            mu,
            sigma,
            sigma_h: DMatrix::zeros(dim, 2),
            gain: DMatrix::zeros(dim, 2),
            n: 0,
            ids: Vec::with_capacity(capacity),
            slots: SlotTable::with_capacity(capacity),
            tally: Tally::default(),
            first_pose,
            first_landmarks: Vec::with_capacity(capacity),
        }
    }

    /// The most landmarks the state has room for.
    pub fn capacity(&self) -> usize {
        self.ids.capacity()
    }

    /// Landmarks mapped so far.
    pub fn len(&self) -> usize {
        self.n
    }

    /// Whether no landmark is mapped yet.
    pub fn is_empty(&self) -> bool {
        self.n == 0
    }

    /// The pose mean (x, y, θ), θ wrapped to (−π, π].
    pub fn pose(&self) -> Pose2 {
        Pose2::new(self.mu[0], self.mu[1], self.mu[2])
    }

    /// Σₓₓ, the 3×3 pose covariance.
    pub fn pose_covariance(&self) -> Matrix3<f64> {
        self.sigma.fixed_view::<3, 3>(0, 0).into_owned()
    }

    /// The landmark in `slot`.
    pub fn landmark(&self, slot: usize) -> Option<Landmark> {
        (slot < self.n).then(|| {
            let o = offset(slot);
            Landmark {
                id: self.ids[slot],
                mean: Vector2::new(self.mu[o], self.mu[o + 1]),
                cov: self.sigma.fixed_view::<2, 2>(o, o).into_owned(),
            }
        })
    }

    /// The mapped landmarks in slot order (id, mean, 2×2 covariance).
    pub fn landmarks(&self) -> impl Iterator<Item = Landmark> + '_ {
        (0..self.n).filter_map(|s| self.landmark(s))
    }

    /// The degrees of freedom of the map's mean landmark NEES under Σ's landmark block
    /// ([`crate::slam::mean_nees_dof`]).
    pub fn mean_nees_dof(&self) -> f64 {
        crate::slam::mean_nees_dof(self.n, |i, j| {
            self.sigma
                .fixed_view::<2, 2>(offset(i), offset(j))
                .into_owned()
        })
    }

    /// The active mean, 3 + 2n long: pose then landmarks in slot order.
    pub fn state(&self) -> nalgebra::DVectorView<'_, f64> {
        self.mu.rows(0, offset(self.n))
    }

    /// The active covariance, (3 + 2n)².
    pub fn covariance(&self) -> nalgebra::DMatrixView<'_, f64> {
        let d = offset(self.n);
        self.sigma.view((0, 0), (d, d))
    }

    /// Association decisions so far.
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

    /// Prediction (Thrun §10.2, Table 10.1 lines 2–5): the pose moves by g, Σₓₓ ← G Σₓₓ Gᵀ +
    /// R_t, Σₓₘ ← G Σₓₘ; landmark blocks are untouched, so the cost is O(n). A non-finite or
    /// implausible control is ignored (and counted); dt = 0 changes nothing.
    pub fn predict(&mut self, v: f64, omega: f64, dt: f64) -> Result<(), SlamError> {
        self.predict_sliding(v, omega, dt, &Vector2::zeros())
    }

    /// [`EkfSlam::predict`] followed by the slide `sideways` the wheels did not see (robot frame
    /// at the arc's end, [`crate::contact`]): the pose moves by R(θ̄)·b, and G_t turns it with θ
    /// (the first-estimates G_t, built from the whole displacement, has it already).
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
        let pose = self.pose_vector();
        let mut moved = self.motion.g(&pose, v, omega, dt);
        let g_t = match self.linearisation {
            Linearisation::Estimate => {
                let mut g_t = self.motion.jacobian_g(&pose, v, omega, dt);
                add_slide(&mut moved, Some(&mut g_t), sideways);
                g_t
            }
            Linearisation::FirstEstimates => {
                add_slide(&mut moved, None, sideways);
                self.motion
                    .jacobian_g_first_estimates(&self.first_pose, &moved)
            }
        };
        let r_t = self.motion.process_noise(&pose, v, omega, dt);
        if !(moved.iter().all(|v| v.is_finite())
            && g_t.iter().all(|v| v.is_finite())
            && r_t.iter().all(|v| v.is_finite()))
        {
            self.tally.ignored += 1;
            return Err(SlamError::Invalid);
        }
        self.mu[0] = moved[0];
        self.mu[1] = moved[1];
        self.mu[2] = wrap_angle(moved[2]);
        self.first_pose = moved;
        let mut s_xx = g_t * self.pose_covariance() * g_t.transpose() + r_t;
        symmetrize(&mut s_xx);
        self.sigma.fixed_view_mut::<3, 3>(0, 0).copy_from(&s_xx);
        for c in 3..offset(self.n) {
            let col =
                g_t * Vector3::new(self.sigma[(0, c)], self.sigma[(1, c)], self.sigma[(2, c)]);
            for r in 0..3 {
                self.sigma[(r, c)] = col[r];
                self.sigma[(c, r)] = col[r];
            }
        }
        Ok(())
    }

    /// Correction with every reading in order ([`EkfSlam::correct_reading`]); refusals are
    /// counted.
    pub fn correct(&mut self, readings: &[BeaconReading]) {
        for reading in readings {
            // Refusals are counted inside.
            let _ = self.correct_reading(reading);
        }
    }

    /// Correction with one reading (Thrun §10.2, Table 10.1 lines 6–17; unknown
    /// correspondences Table 10.3): association, first-sight initialisation, or the update.
    pub fn correct_reading(&mut self, reading: &BeaconReading) -> Result<Association, SlamError> {
        let result = self.try_correct_reading(reading);
        self.tally.record(&result);
        result
    }

    fn try_correct_reading(&mut self, reading: &BeaconReading) -> Result<Association, SlamError> {
        let z = checked_reading(reading.range, reading.bearing, self.config.max_range)
            .ok_or(SlamError::Invalid)?;
        if reading.id == LANDMARK_ANONYMOUS {
            self.config.correspondence = Correspondence::Unknown;
        }
        match self.config.correspondence {
            Correspondence::Known => match self.slots.get(reading.id) {
                Some(slot) => {
                    self.update_landmark(slot, &z, self.gates.outlier)?;
                    Ok(Association::Matched {
                        slot,
                        id: reading.id,
                    })
                }
                None => self.add_from_reading(reading.id, &z),
            },
            Correspondence::Unknown => {
                let (best, min_d2) = self.most_likely(&z);
                match best {
                    Some(slot) => {
                        self.update_landmark(slot, &z, f64::INFINITY)?;
                        Ok(Association::Matched {
                            slot,
                            id: self.ids[slot],
                        })
                    }
                    None if min_d2 > self.gates.create => self.add_from_reading(reading.id, &z),
                    None => Ok(Association::Discarded),
                }
            }
        }
    }

    /// Maximum-likelihood association (Thrun §10.3, Table 10.3 lines 17–21): among landmarks
    /// with d² = νᵀ S⁻¹ ν inside the association gate, the one maximising N(ν; 0, S), i.e.
    /// minimising d² + ln det S. Returns it and the smallest d² over all landmarks. O(n).
    fn most_likely(&self, z: &Vector2<f64>) -> (Option<usize>, f64) {
        let pose = self.pose_vector();
        let (mut best, mut best_score, mut min_d2) = (None, f64::INFINITY, f64::INFINITY);
        for slot in 0..self.n {
            let Some((nu, s_t)) = self.innovation(&pose, slot, z) else {
                continue;
            };
            let Some(chol) = Cholesky::new(s_t) else {
                continue;
            };
            let d2 = nu.dot(&chol.solve(&nu));
            min_d2 = min_d2.min(d2);
            let score = d2 + s_t.determinant().ln();
            if d2 <= self.gates.associate && score < best_score {
                (best, best_score) = (Some(slot), score);
            }
        }
        (best, min_d2)
    }

    /// ν = z − h(μ) (bearing wrapped) and S = H Σ Hᵀ + Q_t for landmark `slot`, from the 5×5
    /// block of Σ that H touches (Thrun eq. 10.19–10.21).
    fn innovation(
        &self,
        pose: &Vector3<f64>,
        slot: usize,
        z: &Vector2<f64>,
    ) -> Option<(Vector2<f64>, Matrix2<f64>)> {
        let o = offset(slot);
        let (z_hat, h_x, h_m) = self.linearised(pose, slot)?;
        let s_xx = self.pose_covariance();
        let s_xm: SMatrix<f64, 3, 2> = self.sigma.fixed_view::<3, 2>(0, o).into_owned();
        let s_mm: Matrix2<f64> = self.sigma.fixed_view::<2, 2>(o, o).into_owned();
        let cross = h_x * s_xm * h_m.transpose();
        let mut s_t = h_x * s_xx * h_x.transpose()
            + cross
            + cross.transpose()
            + h_m * s_mm * h_m.transpose()
            + self.q_t;
        symmetrize(&mut s_t);
        let nu = Vector2::new(z[0] - z_hat[0], wrap_angle(z[1] - z_hat[1]));
        Some((nu, s_t))
    }

    /// The EKF update with a reading of landmark `slot` (Thrun §10.2, Table 10.1 lines 12–17),
    /// refused when νᵀ S⁻¹ ν > `gate`.
    fn update_landmark(
        &mut self,
        slot: usize,
        z: &Vector2<f64>,
        gate: f64,
    ) -> Result<(), SlamError> {
        let pose = self.pose_vector();
        let o = offset(slot);
        let (z_hat, h_x, h_m) = self.linearised(&pose, slot).ok_or(SlamError::TooClose)?;
        let nu = Vector2::new(z[0] - z_hat[0], wrap_angle(z[1] - z_hat[1]));
        let q_t = self.q_t;
        self.update(&nu, &h_x, o, &h_m, &q_t, gate)
    }

    /// ẑ = h(μₓ, μₘ) of landmark `slot` from the estimate `pose`, with ∂h/∂x and ∂h/∂m at the
    /// linearisation points [`EkfSlam::linearisation`] names (the estimate when the first
    /// estimates are too close for a bearing).
    fn linearised(
        &self,
        pose: &Vector3<f64>,
        slot: usize,
    ) -> Option<(Vector2<f64>, Matrix2x3<f64>, Matrix2<f64>)> {
        let o = offset(slot);
        let estimate = observe(pose, &Vector2::new(self.mu[o], self.mu[o + 1]))?;
        if self.linearisation == Linearisation::Estimate {
            return Some(estimate);
        }
        Some(
            match observe(&self.first_pose, &self.first_landmarks[slot]) {
                Some((_, h_x, h_m)) => (estimate.0, h_x, h_m),
                None => estimate,
            },
        )
    }

    /// The Kalman update for a 2-D measurement whose Jacobian H is `h_x` on the pose columns
    /// and `h_m` on the two columns at `o` (zero elsewhere), O(N) per column pair plus the O(N²)
    /// covariance update (Thrun §10.2, Table 10.1 lines 12–17):
    /// P = Σ Hᵀ, S = H P + Q, K = P S⁻¹, μ ← μ + K ν,
    /// Σ ← (I − K H) Σ (I − K H)ᵀ + K Q Kᵀ = Σ − K Pᵀ − P Kᵀ + K S Kᵀ (Joseph form, Bucy &
    /// Joseph 1968, expanded; like the product form it is first-order insensitive to errors in
    /// K), computed on the upper triangle and mirrored so Σ stays exactly symmetric.
    /// Returns Err (state untouched) when S is not positive definite or νᵀ S⁻¹ ν > `gate`.
    fn update(
        &mut self,
        nu: &Vector2<f64>,
        h_x: &Matrix2x3<f64>,
        o: usize,
        h_m: &Matrix2<f64>,
        q_t: &Matrix2<f64>,
        gate: f64,
    ) -> Result<(), SlamError> {
        if !(nu.iter().all(|v| v.is_finite())
            && h_x.iter().all(|v| v.is_finite())
            && h_m.iter().all(|v| v.is_finite())
            && q_t.iter().all(|v| v.is_finite()))
        {
            return Err(SlamError::Invalid);
        }
        let d = offset(self.n);
        // P = Σ Hᵀ, row by row over the active state.
        for r in 0..d {
            let mut p = Vector2::zeros();
            for c in 0..3 {
                p += h_x.column(c) * self.sigma[(r, c)];
            }
            p += h_m.column(0) * self.sigma[(r, o)] + h_m.column(1) * self.sigma[(r, o + 1)];
            self.sigma_h[(r, 0)] = p[0];
            self.sigma_h[(r, 1)] = p[1];
        }
        // S = H P + Q from the rows of P that H touches.
        let mut s_t = *q_t;
        for k in 0..2 {
            for c in 0..3 {
                s_t[(k, 0)] += h_x[(k, c)] * self.sigma_h[(c, 0)];
                s_t[(k, 1)] += h_x[(k, c)] * self.sigma_h[(c, 1)];
            }
            for c in 0..2 {
                s_t[(k, 0)] += h_m[(k, c)] * self.sigma_h[(o + c, 0)];
                s_t[(k, 1)] += h_m[(k, c)] * self.sigma_h[(o + c, 1)];
            }
        }
        symmetrize(&mut s_t);
        let chol = Cholesky::new(s_t).ok_or(SlamError::Singular)?;
        let d2 = nu.dot(&chol.solve(nu));
        if !d2.is_finite() {
            return Err(SlamError::Singular);
        }
        if d2 > gate {
            return Err(SlamError::Outlier {
                mahalanobis2: d2,
                gate,
            });
        }
        let s_inv = chol.inverse();
        for r in 0..d {
            let p = Vector2::new(self.sigma_h[(r, 0)], self.sigma_h[(r, 1)]);
            let k = s_inv * p;
            self.gain[(r, 0)] = k[0];
            self.gain[(r, 1)] = k[1];
            self.mu[r] += k.dot(nu);
        }
        self.mu[2] = wrap_angle(self.mu[2]);
        for c in 0..d {
            let k_c = Vector2::new(self.gain[(c, 0)], self.gain[(c, 1)]);
            let p_c = Vector2::new(self.sigma_h[(c, 0)], self.sigma_h[(c, 1)]);
            let ks_c = s_t * k_c;
            for r in 0..=c {
                let k_r = Vector2::new(self.gain[(r, 0)], self.gain[(r, 1)]);
                let p_r = Vector2::new(self.sigma_h[(r, 0)], self.sigma_h[(r, 1)]);
                let v = self.sigma[(r, c)] - k_r.dot(&p_c) - p_r.dot(&k_c) + k_r.dot(&ks_c);
                self.sigma[(r, c)] = v;
                self.sigma[(c, r)] = v;
            }
        }
        Ok(())
    }

    /// Founds landmark `id` from a first reading (Thrun §10.2.3), if there is room.
    fn add_from_reading(&mut self, id: u32, z: &Vector2<f64>) -> Result<Association, SlamError> {
        if z[0] < crate::models::MIN_RANGE {
            return Err(SlamError::TooClose);
        }
        if self.n == self.capacity() {
            return Err(SlamError::MapFull);
        }
        let pose = self.pose_vector();
        let (m, mut j_x, mut j_z) = inverse_range_bearing(&pose, z);
        // First estimates: the landmark's linearisation point is where the reading puts it
        // from the pose's linearisation point, and the Jacobians are taken there.
        let first = match self.linearisation {
            Linearisation::Estimate => m,
            Linearisation::FirstEstimates => {
                let (m_first, j_x_first, j_z_first) = inverse_range_bearing(&self.first_pose, z);
                (j_x, j_z) = (j_x_first, j_z_first);
                m_first
            }
        };
        let slot = self.n;
        let o = offset(slot);
        match self.landmark_init {
            LandmarkInit::InverseModel => {
                let s_xx = self.pose_covariance();
                let s_mm = j_x * s_xx * j_x.transpose() + j_z * self.q_t * j_z.transpose();
                // Σₘ,c = Jₓ Σₓ,c for the pose and every mapped landmark.
                for c in 0..o {
                    let col =
                        Vector3::new(self.sigma[(0, c)], self.sigma[(1, c)], self.sigma[(2, c)]);
                    let cross = j_x * col;
                    for k in 0..2 {
                        self.sigma[(o + k, c)] = cross[k];
                        self.sigma[(c, o + k)] = cross[k];
                    }
                }
                self.set_landmark_block(o, &m, &s_mm);
            }
            LandmarkInit::Prior { variance } => {
                if !(variance.is_finite() && variance > 0.0) {
                    return Err(SlamError::Invalid);
                }
                for c in 0..o {
                    for k in 0..2 {
                        self.sigma[(o + k, c)] = 0.0;
                        self.sigma[(c, o + k)] = 0.0;
                    }
                }
                self.set_landmark_block(o, &m, &(Matrix2::identity() * variance));
            }
        }
        self.activate(slot, id, first);
        if let LandmarkInit::Prior { .. } = self.landmark_init
            && let Err(e) = self.update_landmark(slot, z, f64::INFINITY)
        {
            // The prior stays; the reading is refused.
            return Err(e);
        }
        Ok(Association::New { slot, id })
    }

    /// Writes the mean and 2×2 block of the landmark at offset `o`.
    fn set_landmark_block(&mut self, o: usize, m: &Vector2<f64>, s_mm: &Matrix2<f64>) {
        self.mu[o] = m[0];
        self.mu[o + 1] = m[1];
        let mut s = *s_mm;
        symmetrize(&mut s);
        self.sigma.fixed_view_mut::<2, 2>(o, o).copy_from(&s);
    }

    /// Makes `slot` (= n) active with `id`, linearised at `first` from now on.
    fn activate(&mut self, slot: usize, id: u32, first: Vector2<f64>) {
        debug_assert_eq!(slot, self.n);
        self.ids.push(id);
        self.first_landmarks.push(first);
        if self.config.correspondence == Correspondence::Known && id != LANDMARK_ANONYMOUS {
            self.slots.insert(id, slot);
        }
        self.n += 1;
    }

    /// μₓ as a vector.
    fn pose_vector(&self) -> Vector3<f64> {
        Vector3::new(self.mu[0], self.mu[1], self.mu[2])
    }

    /// Fuses another robot's landmarks (same map frame) into this map by id: a shared landmark
    /// is fused by covariance intersection (Julier & Uhlmann 1997), one landmark at a time; the
    /// rest of the state follows through the cross-covariances. CI enters as a Kalman update on
    /// the whole state inflated by 1/ω with the other estimate as a measurement of covariance
    /// P_b/(1 − ω) (Julier & Uhlmann 1997, §4): the landmark block is the CI of the two
    /// estimates, and the joint Σ stays conservative whatever the unknown correlation. ω
    /// minimises the trace of the whole state's fused covariance (not only the landmark's), so
    /// a fusion never grows tr Σ: with ω chosen for the landmark alone, each landmark's 1/ω
    /// inflated every other one, and a map of many shared landmarks ran away to Σ ~ 1e13 and
    /// negative variances. A landmark only the other map has is left out: CI needs an estimate
    /// of ours to intersect with, and adding the other's landmarks as independent of each other
    /// (only their 2×2 blocks travel) drops the error they share through the other robot's pose,
    /// so this robot would later count that one error once per landmark it re-observes. Adding
    /// them made a robot that follows its peer around the ring over-confident (landmark NEES
    /// 6.3 against 2.2 alone over 50 runs, `tests/slam_two_robots.rs`).
    pub fn fuse_landmarks(&mut self, other: &[Landmark]) -> FuseReport {
        let mut report = FuseReport::default();
        for lm in other {
            let usable = lm.is_usable();
            let slot = (0..self.n).find(|&s| self.ids[s] == lm.id);
            match (usable, slot) {
                (false, _) => report.refused += 1,
                (true, Some(slot)) => match self.fuse_one(slot, lm) {
                    Some(true) => report.fused += 1,
                    Some(false) => report.kept += 1,
                    None => report.refused += 1,
                },
                (true, None) => report.unmapped += 1,
            }
        }
        report
    }

    /// Adds `landmark` as a new landmark with its mean and covariance, uncorrelated with the pose
    /// and every other landmark, and returns its slot; refused when it is not finite and
    /// positive definite or the map is full. Its id is not matched against the map's.
    pub fn insert_landmark(&mut self, landmark: &Landmark) -> Result<usize, SlamError> {
        if !landmark.is_usable() {
            return Err(SlamError::Invalid);
        }
        if self.n == self.capacity() {
            return Err(SlamError::MapFull);
        }
        let slot = self.n;
        let o = offset(slot);
        for c in 0..o {
            for k in 0..2 {
                self.sigma[(o + k, c)] = 0.0;
                self.sigma[(c, o + k)] = 0.0;
            }
        }
        self.set_landmark_block(o, &landmark.mean, &landmark.cov);
        self.activate(slot, landmark.id, landmark.mean);
        Ok(slot)
    }

    /// Correction with a position fix z = (x, y) of covariance `q_t` (a linear reading of the
    /// pose, H = [I₂ 0]; algorithms §6.5), refused beyond the outlier gate; refusals are
    /// counted. Through the cross-covariances it moves the landmarks too.
    pub fn correct_fix(&mut self, x: f64, y: f64, q_t: &Matrix2<f64>) -> Result<(), SlamError> {
        let nu = Vector2::new(x - self.mu[0], y - self.mu[1]);
        let h_x = Matrix2x3::new(1.0, 0.0, 0.0, 0.0, 1.0, 0.0);
        // H has no landmark columns: zero blocks at offset 0 (the pose's own columns).
        let result = self.update(&nu, &h_x, 0, &Matrix2::zeros(), q_t, self.gates.outlier);
        self.tally.record_refusal(&result);
        result
    }

    /// CI of landmark `slot` with `other` (see [`EkfSlam::fuse_landmarks`]): whether it
    /// changed the state (false: ω = 1, kept as it was); `None` if refused.
    fn fuse_one(&mut self, slot: usize, other: &Landmark) -> Option<bool> {
        let o = offset(slot);
        let omega = self.ci_weight(o, &other.cov)?;
        // ω = 1: our estimate alone is the CI optimum. ω is kept ≥ 1e-3 so 1/ω stays tame.
        if omega >= 1.0 - 1e-9 {
            return Some(false);
        }
        let omega = omega.max(1e-3);
        let d = offset(self.n);
        self.sigma.view_mut((0, 0), (d, d)).scale_mut(1.0 / omega);
        let nu = other.mean - Vector2::new(self.mu[o], self.mu[o + 1]);
        let q = other.cov / (1.0 - omega);
        self.update(
            &nu,
            &Matrix2x3::zeros(),
            o,
            &Matrix2::identity(),
            &q,
            f64::INFINITY,
        )
        .ok()
        .map(|()| true)
    }

    /// The CI weight ω ∈ [0, 1] of this state when the landmark at offset `o` is fused with an
    /// estimate of covariance `p_b`: the one that minimises the trace of the WHOLE state's
    /// fused covariance Σ_f(ω) = Σ/ω − (Σ/ω) Hᵀ S⁻¹ H (Σ/ω), S = H Σ Hᵀ/ω + P_b/(1 − ω), whose
    /// trace is tr Σ/ω − tr(S⁻¹ M)/ω² with M = Σ_{·o}ᵀ Σ_{·o} (2×2, computed once). Every ω
    /// inflates the rest of the state by 1/ω, so a fusion is taken only as far as the
    /// landmark's gain outweighs that: the trace never grows (ω = 1 leaves Σ as it is), and
    /// fusing landmark after landmark cannot run away. `None` when the trace is not finite.
    fn ci_weight(&self, o: usize, p_b: &Matrix2<f64>) -> Option<f64> {
        let d = offset(self.n);
        let trace: f64 = (0..d).map(|i| self.sigma[(i, i)]).sum();
        let a = self.sigma.fixed_view::<2, 2>(o, o).into_owned();
        let mut m = Matrix2::zeros();
        for r in 0..d {
            let p = Vector2::new(self.sigma[(r, o)], self.sigma[(r, o + 1)]);
            m += p * p.transpose();
        }
        if !(trace.is_finite() && m.iter().all(|v| v.is_finite())) {
            return None;
        }
        let fused_trace = |omega: f64| {
            if omega >= 1.0 {
                return trace;
            }
            if omega <= 0.0 {
                return f64::INFINITY;
            }
            let s = a / omega + p_b / (1.0 - omega);
            Cholesky::new(s).map_or(f64::INFINITY, |chol| {
                trace / omega - chol.solve(&m).trace() / (omega * omega)
            })
        };
        Some(argmin_on_unit_interval(fused_trace))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    fn slam(init: LandmarkInit) -> EkfSlam {
        let mut s = EkfSlam::new(
            Pose2::new(0.0, 0.0, 0.3),
            Matrix3::from_diagonal(&Vector3::new(0.01, 0.02, 0.003)),
            NoiseModel::new(0.1, 0.05, 0.1, 0.02, 0.5),
            4,
            SlamConfig::default(),
        );
        s.landmark_init = init;
        s
    }

    fn reading(id: u32, range: f64, bearing: f64) -> BeaconReading {
        BeaconReading {
            id,
            _pad: 0,
            range,
            bearing,
        }
    }

    #[test]
    fn inverse_model_initialisation_is_the_linearised_joint_covariance() {
        let mut s = slam(LandmarkInit::InverseModel);
        s.predict(1.0, 0.2, 0.5).unwrap();
        let pose = Vector3::new(s.pose().x, s.pose().y, s.pose().theta);
        let s_xx = s.pose_covariance();
        let z = Vector2::new(4.0, 0.6);
        let a = s.correct_reading(&reading(7, z[0], z[1])).unwrap();
        assert_eq!(a, Association::New { slot: 0, id: 7 });
        let (m, j_x, j_z) = inverse_range_bearing(&pose, &z);
        let lm = s.landmark(0).unwrap();
        assert_relative_eq!(lm.mean, m, epsilon = 1e-12);
        let expected = j_x * s_xx * j_x.transpose() + j_z * s.q_t * j_z.transpose();
        assert_relative_eq!(lm.cov, expected, epsilon = 1e-12);
        let cross: SMatrix<f64, 2, 3> = s.covariance().fixed_view::<2, 3>(3, 0).into_owned();
        assert_relative_eq!(cross, j_x * s_xx, epsilon = 1e-12);
        // The founding reading is spent: the pose is untouched.
        assert_relative_eq!(s.pose_covariance(), s_xx, epsilon = 0.0);
    }

    #[test]
    fn predict_moves_only_pose_rows_and_columns() {
        let mut s = slam(LandmarkInit::InverseModel);
        s.correct_reading(&reading(1, 3.0, 0.2)).unwrap();
        s.correct_reading(&reading(2, 5.0, -1.0)).unwrap();
        let before = s.covariance().into_owned();
        s.predict(0.8, -0.3, 0.2).unwrap();
        let after = s.covariance();
        assert_eq!(
            before.view((3, 3), (4, 4)).into_owned(),
            after.view((3, 3), (4, 4)).into_owned()
        );
        assert_ne!(before.view((0, 3), (3, 4)), after.view((0, 3), (3, 4)));
        assert_eq!(after.into_owned(), after.transpose());
    }

    #[test]
    fn update_equals_the_dense_textbook_update() {
        let mut s = slam(LandmarkInit::InverseModel);
        s.correct_reading(&reading(1, 3.0, 0.2)).unwrap();
        s.correct_reading(&reading(2, 5.0, -1.0)).unwrap();
        s.predict(0.8, -0.3, 0.4).unwrap();
        let mu0 = s.state().into_owned();
        let sigma0 = s.covariance().into_owned();
        let pose = Vector3::new(mu0[0], mu0[1], mu0[2]);
        let (z_hat, h_x, h_m) = observe(&pose, &Vector2::new(mu0[5], mu0[6])).unwrap();
        let z = Vector2::new(5.1, -0.95);
        let mut h = DMatrix::zeros(2, 7);
        h.view_mut((0, 0), (2, 3)).copy_from(&h_x);
        h.view_mut((0, 5), (2, 2)).copy_from(&h_m);
        let s_t = &h * &sigma0 * h.transpose() + s.q_t;
        let k = &sigma0 * h.transpose() * s_t.try_inverse().unwrap();
        let nu = DVector::from_column_slice(&[z[0] - z_hat[0], wrap_angle(z[1] - z_hat[1])]);
        let mu_ref = &mu0 + &k * nu;
        let sigma_ref = (DMatrix::identity(7, 7) - &k * &h) * &sigma0;
        assert!(matches!(
            s.correct_reading(&reading(2, z[0], z[1])),
            Ok(Association::Matched { slot: 1, id: 2 })
        ));
        assert_relative_eq!(s.state().into_owned(), mu_ref, epsilon = 1e-12);
        assert_relative_eq!(s.covariance().into_owned(), sigma_ref, epsilon = 1e-12);
    }

    #[test]
    fn a_full_map_refuses_new_landmarks_and_counts_them() {
        let mut s = slam(LandmarkInit::InverseModel);
        for id in 0..5 {
            let r = s.correct_reading(&reading(id, 2.0 + f64::from(id), 0.1 * f64::from(id)));
            assert_eq!(r.is_err(), id == 4, "{r:?}");
        }
        assert_eq!((s.len(), s.ignored()), (4, 1));
    }
}
