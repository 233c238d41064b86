//! The sparse normal equations H Δ = −b of the pose graph, their block sparsity pattern and the
//! sparse Cholesky factorisation (faer's supernodal LLᵀ).
//!
//! Unknowns are ordered poses first, in trajectory order (3 per pose), then landmarks (2 per
//! landmark). Only the lower triangle of H is stored, column by column (CSC, rows ≥ column):
//! a pose column holds its own diagonal block, the next pose's block (their odometry factor)
//! and one 2-row block per distinct landmark the pose observes; a landmark column holds only
//! its diagonal block.
//!
//! That order is also the elimination order, kept as is (no fill-reducing permutation): for a
//! map of a few dozen beacons it is already a good one. Eliminating the chain of poses fills in
//! only the landmark rows (each dense from the landmark's first sighting on), and faer then
//! neither permutes nor transposes H on each factorisation. (For maps of hundreds of
//! landmarks an AMD ordering would be the better choice.) The symbolic factorisation depends
//! on the pattern only, so it is computed once per graph structure and reused by every LM
//! iteration and every later call on the same structure.

use super::factors::{ObservationFactor, PositionFactor};
use super::problem::Problem;
use faer::dyn_stack::{MemBuffer, MemStack, StackReq};
use faer::linalg::cholesky::llt::factor::LltRegularization;
use faer::sparse::linalg::SupernodalThreshold;
use faer::sparse::linalg::cholesky::{
    CholeskySymbolicParams, LltRef, SymbolicCholesky, SymmetricOrdering,
    factorize_symbolic_cholesky,
};
use faer::sparse::{SparseColMatRef, SymbolicSparseColMatRef};
use faer::{Conj, MatMut, Par, Side};
use nalgebra::{Matrix2, Matrix3, SMatrix, SVector};

/// Landmark columns solved at once for the marginal covariances (bounds the RHS buffer).
const COVARIANCE_LANDMARKS_PER_SOLVE: usize = 8;

/// Why the normal equations could not be solved.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SolveError {
    /// The (damped) H was not numerically positive definite.
    NotPositiveDefinite,
    /// faer could not allocate the symbolic factorisation.
    OutOfMemory,
}

/// The pattern, values and factorisation workspace of H Δ = −b.
pub struct NormalEquations {
    n_poses: usize,
    col_ptr: Vec<usize>,
    row_idx: Vec<usize>,
    /// H, lower triangle, in the order of `row_idx`; each column starts with its diagonal.
    hessian: Vec<f64>,
    /// H + λ·diag(H), what is factorised.
    damped: Vec<f64>,
    /// b = Σ Jᵀ Ω e, then overwritten by Δ.
    rhs: Vec<f64>,
    /// The last step Δ.
    step: Vec<f64>,
    /// (pose, landmark) pairs, sorted and unique: the landmark blocks of the pose columns.
    pairs: Vec<(usize, usize)>,
    /// Per pose, the start of its run in `pairs` (one more entry than poses).
    pose_pairs: Vec<usize>,
    /// Per observation factor, its landmark's block position in its pose's column.
    slots: Vec<usize>,
    symbolic: Option<SymbolicCholesky<usize>>,
    factor_values: Vec<f64>,
    scratch: MemBuffer,
    covariance_rhs: Vec<f64>,
    /// The landmark block of H⁻¹ from the last [`Self::landmark_covariances`], column-major,
    /// (2·landmarks)², for the map's NEES degrees of freedom.
    landmark_block: Vec<f64>,
}

impl NormalEquations {
    /// Empty workspace with room for a graph of `poses`, `landmarks` and `observations`.
    pub fn with_capacity(poses: usize, landmarks: usize, observations: usize) -> Self {
        let n = 3 * poses + 2 * landmarks;
        let nnz = 15 * poses + 6 * observations + 3 * landmarks;
        Self {
            n_poses: 0,
            col_ptr: Vec::with_capacity(n + 1),
            row_idx: Vec::with_capacity(nnz),
            hessian: Vec::with_capacity(nnz),
            damped: Vec::with_capacity(nnz),
            rhs: Vec::with_capacity(n),
            step: Vec::with_capacity(n),
            pairs: Vec::with_capacity(observations),
            pose_pairs: Vec::with_capacity(poses + 1),
            slots: Vec::with_capacity(observations),
            symbolic: None,
            factor_values: Vec::new(),
            scratch: MemBuffer::new(StackReq::EMPTY),
            covariance_rhs: Vec::new(),
            landmark_block: Vec::new(),
        }
    }

    /// Dimension of the unknown vector.
    pub fn dim(&self) -> usize {
        self.col_ptr.len().saturating_sub(1)
    }

    /// The last solved step Δ (poses then landmarks).
    pub fn step(&self) -> &[f64] {
        &self.step
    }

    /// Builds the block pattern of H for the graph's structure and its symbolic Cholesky
    /// factorisation in that order (Grisetti et al. 2010 §IV-A on the sparsity of H).
    pub fn analyse(&mut self, problem: &Problem) -> Result<(), SolveError> {
        let n_poses = problem.poses.len();
        let n_landmarks = problem.landmarks.len();
        self.n_poses = n_poses;
        self.pairs.clear();
        self.pairs
            .extend(problem.observations.iter().map(|o| (o.pose, o.landmark)));
        self.pairs.sort_unstable();
        self.pairs.dedup();
        self.pose_pairs.clear();
        let mut at = 0;
        for i in 0..n_poses {
            self.pose_pairs.push(at);
            while at < self.pairs.len() && self.pairs[at].0 == i {
                at += 1;
            }
        }
        self.pose_pairs.push(at);
        self.slots.clear();
        for o in &problem.observations {
            let run = &self.pairs[self.pose_pairs[o.pose]..self.pose_pairs[o.pose + 1]];
            let slot = run
                .binary_search(&(o.pose, o.landmark))
                .expect("every observation's pair is in the pattern");
            self.slots.push(slot);
        }

        let first_landmark = 3 * n_poses;
        self.col_ptr.clear();
        self.row_idx.clear();
        self.col_ptr.push(0);
        for i in 0..n_poses {
            for k in 0..3 {
                self.row_idx.extend(3 * i + k..3 * i + 3);
                if i + 1 < n_poses {
                    self.row_idx.extend(3 * (i + 1)..3 * (i + 2));
                }
                for &(_, landmark) in &self.pairs[self.pose_pairs[i]..self.pose_pairs[i + 1]] {
                    let row = first_landmark + 2 * landmark;
                    self.row_idx.extend(row..row + 2);
                }
                self.col_ptr.push(self.row_idx.len());
            }
        }
        for j in 0..n_landmarks {
            let column = first_landmark + 2 * j;
            for k in 0..2 {
                self.row_idx.extend(column + k..column + 2);
                self.col_ptr.push(self.row_idx.len());
            }
        }
        let nnz = self.row_idx.len();
        let n = self.dim();
        self.hessian.clear();
        self.hessian.resize(nnz, 0.0);
        self.damped.clear();
        self.damped.resize(nnz, 0.0);
        self.rhs.clear();
        self.rhs.resize(n, 0.0);
        self.step.clear();
        self.step.resize(n, 0.0);

        // The symbolic analysis reads the upper triangle when it does not permute (whatever
        // side it is told), so it gets the transposed pattern; the numeric factorisation then
        // takes the lower triangle as stored, without a copy.
        let mut upper_ptr = vec![0usize; n + 1];
        for &r in &self.row_idx {
            upper_ptr[r + 1] += 1;
        }
        for c in 0..n {
            upper_ptr[c + 1] += upper_ptr[c];
        }
        let mut next = upper_ptr.clone();
        let mut upper_idx = vec![0usize; nnz];
        for c in 0..n {
            for &r in &self.row_idx[self.col_ptr[c]..self.col_ptr[c + 1]] {
                upper_idx[next[r]] = c;
                next[r] += 1;
            }
        }
        let upper = SymbolicSparseColMatRef::new_checked(n, n, &upper_ptr, None, &upper_idx);
        let symbolic = factorize_symbolic_cholesky(
            upper,
            Side::Upper,
            SymmetricOrdering::Identity,
            CholeskySymbolicParams {
                supernodal_flop_ratio_threshold: SupernodalThreshold::FORCE_SUPERNODAL,
                ..Default::default()
            },
        )
        .map_err(|_| SolveError::OutOfMemory)?;
        self.factor_values.clear();
        self.factor_values.resize(symbolic.len_val(), 0.0);
        let need = symbolic
            .factorize_numeric_llt_scratch::<f64>(Par::Seq, Default::default())
            .or(symbolic
                .solve_in_place_scratch::<f64>(2 * COVARIANCE_LANDMARKS_PER_SOLVE, Par::Seq));
        self.scratch = MemBuffer::try_new(need).map_err(|_| SolveError::OutOfMemory)?;
        self.symbolic = Some(symbolic);
        Ok(())
    }

    /// Linearises every factor at the current estimate, accumulates H = Σ JᵀΩJ and
    /// b = Σ JᵀΩe (Thrun §11.2, Table 11.2 lines 2–18; Grisetti et al. 2010 eq. 9–13) and
    /// returns χ² = Σ eᵀΩe there (Thrun eq. 11.3–11.5), as [`Problem::cost`] would.
    pub fn assemble(&mut self, problem: &Problem) -> f64 {
        self.hessian.fill(0.0);
        self.rhs.fill(0.0);
        let x0 = &problem.poses[0];
        let e = super::factors::prior_residual(x0, &problem.prior);
        let mut chi2 = e.dot(&(problem.prior_information * e));
        self.add_diagonal(0, &Matrix3::identity(), &problem.prior_information, &e);
        for (i, odometry) in problem.odometry.iter().enumerate() {
            let (a, b) = (&problem.poses[i], &problem.poses[i + 1]);
            let e = odometry.residual(a, b);
            let (j_a, j_b) = odometry.jacobians(a, b);
            let omega = &odometry.information;
            chi2 += e.dot(&(omega * e));
            self.add_diagonal(3 * i, &j_a, omega, &e);
            self.add_diagonal(3 * (i + 1), &j_b, omega, &e);
            let cross = j_b.transpose() * omega * j_a;
            self.add_below(3 * i, 0, &cross);
        }
        let first_landmark = 3 * problem.poses.len();
        for (k, o) in problem.observations.iter().enumerate() {
            let slot = self.slots[k];
            let pose = &problem.poses[o.pose];
            let landmark = &problem.landmarks[o.landmark];
            let Some(e) = o.residual(pose, landmark) else {
                continue;
            };
            let (j_pose, j_landmark) = ObservationFactor::jacobians(pose, landmark);
            let omega = &problem.observation_information;
            chi2 += e.dot(&(omega * e));
            self.add_diagonal(3 * o.pose, &j_pose, omega, &e);
            self.add_diagonal(first_landmark + 2 * o.landmark, &j_landmark, omega, &e);
            let next_pose = if o.pose + 1 < problem.poses.len() {
                3
            } else {
                0
            };
            let cross = j_landmark.transpose() * omega * j_pose;
            self.add_below(3 * o.pose, next_pose + 2 * slot, &cross);
        }
        for p in &problem.positions {
            let e = p.residual(&problem.poses[p.pose]);
            chi2 += e.dot(&(p.information * e));
            self.add_diagonal(3 * p.pose, &PositionFactor::JACOBIAN, &p.information, &e);
        }
        chi2
    }

    /// Adds JᵀΩJ (lower triangle) and JᵀΩe to the diagonal block of the variable whose first
    /// scalar column is `column`.
    fn add_diagonal<const R: usize, const C: usize>(
        &mut self,
        column: usize,
        j: &SMatrix<f64, R, C>,
        omega: &SMatrix<f64, R, R>,
        e: &SVector<f64, R>,
    ) {
        let jt_omega = j.transpose() * omega;
        let block = jt_omega * j;
        let gradient = jt_omega * e;
        for k in 0..C {
            let start = self.col_ptr[column + k];
            for r in k..C {
                self.hessian[start + r - k] += block[(r, k)];
            }
            self.rhs[column + k] += gradient[k];
        }
    }

    /// Adds a block below the diagonal block of the pose whose first scalar column is `column`,
    /// `offset` rows below that pose's own block.
    fn add_below<const R: usize>(
        &mut self,
        column: usize,
        offset: usize,
        block: &SMatrix<f64, R, 3>,
    ) {
        for k in 0..3 {
            let start = self.col_ptr[column + k] + 3 - k + offset;
            for r in 0..R {
                self.hessian[start + r] += block[(r, k)];
            }
        }
    }

    /// Solves (H + λ·diag(H)) Δ = −b (Marquardt's scaling; Grisetti et al. 2010 §IV, eq. 14
    /// with LM damping) into [`Self::step`], reusing the symbolic factorisation.
    pub fn solve(&mut self, lambda: f64) -> Result<(), SolveError> {
        self.damped.copy_from_slice(&self.hessian);
        for &d in &self.col_ptr[..self.col_ptr.len() - 1] {
            self.damped[d] += lambda * self.hessian[d];
        }
        for (s, b) in self.step.iter_mut().zip(&self.rhs) {
            *s = -b;
        }
        let n = self.dim();
        let symbolic = self.symbolic.as_ref().expect("analyse runs before solve");
        let pattern =
            SymbolicSparseColMatRef::new_checked(n, n, &self.col_ptr, None, &self.row_idx);
        let stack = MemStack::new(&mut self.scratch);
        let llt = symbolic
            .factorize_numeric_llt(
                &mut self.factor_values,
                SparseColMatRef::new(pattern, &self.damped),
                Side::Lower,
                LltRegularization::default(),
                Par::Seq,
                stack,
                Default::default(),
            )
            .map_err(|_| SolveError::NotPositiveDefinite)?;
        let rhs = MatMut::from_column_major_slice_mut(&mut self.step, n, 1);
        llt.solve_in_place_with_conj(Conj::No, rhs, Par::Seq, MemStack::new(&mut self.scratch));
        if self.step.iter().all(|s| s.is_finite()) {
            Ok(())
        } else {
            Err(SolveError::NotPositiveDefinite)
        }
    }

    /// Marginal covariances of the landmarks: the 2×2 diagonal blocks of H⁻¹ at the current
    /// linearisation (Thrun §11.4, eq. 11.50; Grisetti et al. 2010 §IV), by solving H X = E
    /// for each landmark's two unit columns. Costs one factorisation plus 2·(landmarks)
    /// triangular solve pairs; allocates its right-hand-side buffer on first use.
    pub fn landmark_covariances(
        &mut self,
        n_landmarks: usize,
        out: &mut Vec<Matrix2<f64>>,
    ) -> Result<(), SolveError> {
        self.solve(0.0)?;
        let n = self.dim();
        let symbolic = self.symbolic.as_ref().expect("analyse runs before solve");
        let llt = LltRef::new(symbolic, &self.factor_values);
        out.clear();
        let m = 2 * n_landmarks;
        self.landmark_block.clear();
        self.landmark_block.resize(m * m, 0.0);
        let landmarks_from = 3 * self.n_poses;
        let mut first = 0;
        while first < n_landmarks {
            let count = COVARIANCE_LANDMARKS_PER_SOLVE.min(n_landmarks - first);
            self.covariance_rhs.clear();
            self.covariance_rhs.resize(n * 2 * count, 0.0);
            let base = 3 * self.n_poses + 2 * first;
            for c in 0..2 * count {
                self.covariance_rhs[c * n + base + c] = 1.0;
            }
            let rhs = MatMut::from_column_major_slice_mut(&mut self.covariance_rhs, n, 2 * count);
            llt.solve_in_place_with_conj(Conj::No, rhs, Par::Seq, MemStack::new(&mut self.scratch));
            for c in 0..2 * count {
                let column = &self.covariance_rhs[c * n + landmarks_from..][..m];
                self.landmark_block[(2 * first + c) * m..][..m].copy_from_slice(column);
            }
            for l in 0..count {
                let (c0, r0) = (2 * l, base + 2 * l);
                let at = |r: usize, c: usize| self.covariance_rhs[(c0 + c) * n + r0 + r];
                // Symmetrised: the two solves agree to rounding.
                let off = 0.5 * (at(0, 1) + at(1, 0));
                out.push(Matrix2::new(at(0, 0), off, off, at(1, 1)));
            }
            first += count;
        }
        Ok(())
    }

    /// The degrees of freedom of the mean landmark NEES ([`crate::slam::mean_nees_dof`]) under
    /// the landmark block of H⁻¹ that the last [`Self::landmark_covariances`] solved for.
    pub fn landmark_nees_dof(&self) -> f64 {
        let m = (self.landmark_block.len() as f64).sqrt() as usize;
        let at = |r: usize, c: usize| self.landmark_block[c * m + r];
        crate::slam::mean_nees_dof(m / 2, |i, j| {
            let (r, c) = (2 * i, 2 * j);
            Matrix2::new(at(r, c), at(r, c + 1), at(r + 1, c), at(r + 1, c + 1))
        })
    }
}
