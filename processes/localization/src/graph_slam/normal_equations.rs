//! The sparse normal equations H Δ = −b of the pose graph, their block sparsity pattern and the
//! sparse Cholesky factorisation (faer's supernodal LLᵀ).
//!
//! Unknowns are ordered poses first, in trajectory order (3 per pose), then landmarks (2 per
//! landmark). Only the lower triangle of H is stored, column by column (CSC, rows ≥ column):
//! a pose column holds its own diagonal block, the next pose's block (their odometry factor)
//! and one 2-row block per distinct landmark the pose observes; a landmark column holds only
//! its diagonal block.
//!
//! The elimination order is another one, fixed by the same structure: the chain of poses in
//! segments of [`SEGMENT_POSES`]. The poses inside each segment go first, segment by segment,
//! then the poses that separate the segments (every [`SEGMENT_POSES`]-th), then the landmarks,
//! in the order they have in H. A pose's column in the factor then holds only the landmarks
//! its own segment observed, where the chain's own order (every pose before any landmark)
//! fills each landmark row from the landmark's first sighting to the end of the trajectory.
//! On the `graph_slam` bench's ten laps among 30 beacons the factor has 1.13 million entries
//! instead of the chain order's 2.29 million (faer's AMD order leaves as many). It is a
//! one-level nested dissection of the chain, with the landmarks as the last separator (George
//! 1973). H is stored in the elimination order too, so that faer neither permutes nor
//! transposes it on each factorisation. The symbolic factorisation depends on the pattern
//! only, so it is computed once per graph structure and reused by every LM iteration and
//! every later call on the same structure.

use super::factors::PositionFactor;
use super::problem::Problem;
use faer::dyn_stack::{MemBuffer, MemStack, StackReq};
use faer::linalg::cholesky::llt::factor::LltRegularization;
use faer::sparse::linalg::SupernodalThreshold;
use faer::sparse::linalg::cholesky::{
    CholeskySymbolicParams, LltRef, SymbolicCholesky, SymmetricOrdering,
    factorize_symbolic_cholesky,
};
use faer::sparse::{SparseColMatRef, SymbolicSparseColMat, SymbolicSparseColMatRef};
use faer::{Conj, MatMut, Par, Side};
use nalgebra::{Matrix2, Matrix3, SMatrix, SVector};

/// Poses per segment of the elimination order. 16 to 128 all halve the factor on the bench's
/// graph (1.12 to 1.19 million entries); 64 solved it fastest.
const SEGMENT_POSES: usize = 64;

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
    /// H + λ·diag(H), what is factorised: the lower triangle of P H Pᵀ, P the elimination
    /// order, in the order of `factor_pattern`.
    damped: Vec<f64>,
    /// The pattern of `damped`, column by column (CSC), rows sorted (checked once, here).
    factor_pattern: Option<SymbolicSparseColMat<usize>>,
    /// Per entry of `damped`, the entry of `hessian` it is.
    factor_source: Vec<usize>,
    /// Per unknown, its position in the elimination order.
    position: Vec<usize>,
    /// b = Σ Jᵀ Ω e.
    rhs: Vec<f64>,
    /// −b in the elimination order, then overwritten by the permuted Δ.
    permuted_step: Vec<f64>,
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
            factor_pattern: None,
            factor_source: Vec::with_capacity(nnz),
            position: Vec::with_capacity(n),
            rhs: Vec::with_capacity(n),
            permuted_step: Vec::with_capacity(n),
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
        self.permuted_step.clear();
        self.permuted_step.resize(n, 0.0);
        let pattern = self.permute_pattern(n_poses);
        let symbolic = symbolic_cholesky(pattern.as_ref())?;
        self.factor_values.clear();
        self.factor_values.resize(symbolic.len_val(), 0.0);
        let need = symbolic
            .factorize_numeric_llt_scratch::<f64>(Par::Seq, Default::default())
            .or(symbolic
                .solve_in_place_scratch::<f64>(2 * COVARIANCE_LANDMARKS_PER_SOLVE, Par::Seq));
        self.scratch = MemBuffer::try_new(need).map_err(|_| SolveError::OutOfMemory)?;
        self.symbolic = Some(symbolic);
        self.factor_pattern = Some(pattern);
        Ok(())
    }

    /// The elimination order (module doc), and H's lower triangle in that order: its pattern,
    /// returned, and which entry of H each of its entries is (`factor_source`).
    fn permute_pattern(&mut self, n_poses: usize) -> SymbolicSparseColMat<usize> {
        let n = self.dim();
        let nnz = self.row_idx.len();
        self.position.clear();
        self.position.resize(n, 0);
        let mut next = 0;
        let mut place = |unknowns: std::ops::Range<usize>| {
            for u in unknowns {
                self.position[u] = next;
                next += 1;
            }
        };
        for start in (0..n_poses).step_by(SEGMENT_POSES) {
            place(3 * (start + 1)..3 * (start + SEGMENT_POSES).min(n_poses));
        }
        for separator in (0..n_poses).step_by(SEGMENT_POSES) {
            place(3 * separator..3 * separator + 3);
        }
        place(3 * n_poses..n);

        // Each entry (r, c), r ≥ c, lands at (max, min) of their positions: count, then fill.
        let lower = |r: usize, c: usize| {
            let (r, c) = (self.position[r], self.position[c]);
            (r.max(c), r.min(c))
        };
        let mut col_ptr = vec![0; n + 1];
        for c in 0..n {
            for &r in &self.row_idx[self.col_ptr[c]..self.col_ptr[c + 1]] {
                col_ptr[lower(r, c).1 + 1] += 1;
            }
        }
        for c in 0..n {
            col_ptr[c + 1] += col_ptr[c];
        }
        let mut fill = col_ptr.clone();
        let mut entries = vec![(0usize, 0usize); nnz];
        for c in 0..n {
            for k in self.col_ptr[c]..self.col_ptr[c + 1] {
                let (row, column) = lower(self.row_idx[k], c);
                entries[fill[column]] = (row, k);
                fill[column] += 1;
            }
        }
        for c in 0..n {
            entries[col_ptr[c]..col_ptr[c + 1]].sort_unstable();
        }
        self.factor_source.clear();
        self.factor_source.extend(entries.iter().map(|&(_, k)| k));
        let row_idx = entries.into_iter().map(|(row, _)| row).collect();
        SymbolicSparseColMat::new_checked(n, n, col_ptr, None, row_idx)
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
            let Some((e, j_pose)) = o.linearise(pose, landmark) else {
                continue;
            };
            let omega = &problem.observation_information;
            chi2 += e.dot(&(omega * e));
            // The landmark's Jacobian is minus the pose's first two columns, so its blocks
            // are parts of the pose's, exactly (a negation is exact in floating point).
            let jt_omega = j_pose.transpose() * omega;
            let block = jt_omega * j_pose;
            let gradient = jt_omega * e;
            self.add_block(3 * o.pose, &block, &gradient);
            self.add_block(
                first_landmark + 2 * o.landmark,
                &block.fixed_view::<2, 2>(0, 0).into_owned(),
                &-gradient.fixed_rows::<2>(0),
            );
            let next_pose = if o.pose + 1 < problem.poses.len() {
                3
            } else {
                0
            };
            let cross = -block.fixed_rows::<2>(0);
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
        self.add_block(column, &(jt_omega * j), &(jt_omega * e));
    }

    /// Adds `block` (lower triangle) and `gradient` to the diagonal block of the variable
    /// whose first scalar column is `column`.
    fn add_block<const C: usize>(
        &mut self,
        column: usize,
        block: &SMatrix<f64, C, C>,
        gradient: &SVector<f64, C>,
    ) {
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
        let pattern = self
            .factor_pattern
            .as_ref()
            .expect("analyse runs before solve");
        for (d, &k) in self.damped.iter_mut().zip(&self.factor_source) {
            *d = self.hessian[k];
        }
        // Each column's first entry is its diagonal (rows sorted, lower triangle).
        for &d in &pattern.col_ptr()[..pattern.ncols()] {
            self.damped[d] += lambda * self.damped[d];
        }
        for (&at, b) in self.position.iter().zip(&self.rhs) {
            self.permuted_step[at] = -b;
        }
        let n = self.dim();
        let symbolic = self.symbolic.as_ref().expect("analyse runs before solve");
        let stack = MemStack::new(&mut self.scratch);
        let llt = symbolic
            .factorize_numeric_llt(
                &mut self.factor_values,
                SparseColMatRef::new(pattern.as_ref(), &self.damped),
                Side::Lower,
                LltRegularization::default(),
                Par::Seq,
                stack,
                Default::default(),
            )
            .map_err(|_| SolveError::NotPositiveDefinite)?;
        let rhs = MatMut::from_column_major_slice_mut(&mut self.permuted_step, n, 1);
        llt.solve_in_place_with_conj(Conj::No, rhs, Par::Seq, MemStack::new(&mut self.scratch));
        for (s, &at) in self.step.iter_mut().zip(&self.position) {
            *s = self.permuted_step[at];
        }
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
        // The landmarks come last in the elimination order too, so their unknowns have the
        // same index in the factor's space as in H's.
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

/// The symbolic supernodal Cholesky factorisation of a lower-triangle pattern, in its own order.
fn symbolic_cholesky(
    lower: SymbolicSparseColMatRef<'_, usize>,
) -> Result<SymbolicCholesky<usize>, SolveError> {
    // The symbolic analysis reads the upper triangle when it does not permute (whatever side
    // it is told), so it gets the transposed pattern; the numeric factorisation then takes the
    // lower triangle as stored, without a copy.
    let n = lower.ncols();
    let mut upper_ptr = vec![0usize; n + 1];
    for &r in lower.row_idx() {
        upper_ptr[r + 1] += 1;
    }
    for c in 0..n {
        upper_ptr[c + 1] += upper_ptr[c];
    }
    let mut next = upper_ptr.clone();
    let mut upper_idx = vec![0usize; lower.row_idx().len()];
    for c in 0..n {
        for &r in lower.row_idx_of_col_raw(c) {
            upper_idx[next[r]] = c;
            next[r] += 1;
        }
    }
    let upper = SymbolicSparseColMatRef::new_checked(n, n, &upper_ptr, None, &upper_idx);
    factorize_symbolic_cholesky(
        upper,
        Side::Upper,
        SymmetricOrdering::Identity,
        CholeskySymbolicParams {
            supernodal_flop_ratio_threshold: SupernodalThreshold::FORCE_SUPERNODAL,
            ..Default::default()
        },
    )
    .map_err(|_| SolveError::OutOfMemory)
}

#[cfg(test)]
mod tests {
    use super::super::{GraphCapacity, GraphSlamConfig, PoseGraph};
    use crate::noise::NoiseModel;
    use faer::sparse::SymbolicSparseColMatRef;
    use mole_types::{BeaconReading, Odom, Pose2};

    /// A graph of `n_poses`, `per_lap` to a lap of a 4 m circle among `beacons`, with
    /// odometry and readings that disagree with each other (so that H and b are those of a
    /// graph off its optimum).
    fn graph(n_poses: usize, per_lap: usize, beacons: usize) -> PoseGraph {
        let noise = NoiseModel::new(0.02, 0.02, 0.05, 0.02, 0.3);
        let capacity = GraphCapacity {
            poses: n_poses,
            landmarks: beacons,
            observations: beacons * n_poses,
        };
        let start = Pose2::new(0.0, -4.0, 0.0);
        let mut graph = PoseGraph::new(start, GraphSlamConfig::new(noise), capacity);
        let (dt, omega) = (0.1, std::f64::consts::TAU / per_lap as f64 / 0.1);
        let beacons: Vec<(f64, f64)> = (0..beacons)
            .map(|i| {
                let a = i as f64 * std::f64::consts::TAU / beacons as f64;
                let r = if i % 2 == 0 { 2.5 } else { 6.0 };
                (r * a.cos(), r * a.sin())
            })
            .collect();
        let (mut x, mut y, mut theta) = (start.x, start.y, start.theta);
        for k in 0..n_poses {
            if k > 0 {
                let mut odometry: Odom = bytemuck::Zeroable::zeroed();
                (odometry.v, odometry.omega, odometry.dt) = (4.0 * omega, omega, dt);
                graph.add_pose(&odometry).unwrap();
                theta += omega * dt * (1.0 + 0.01 * (k as f64).sin());
                x += 4.0 * omega * dt * theta.cos();
                y += 4.0 * omega * dt * theta.sin();
            }
            for (id, &(bx, by)) in beacons.iter().enumerate() {
                let (dx, dy) = (bx - x, by - y);
                let range = dx.hypot(dy);
                if range < 4.0 {
                    let wobble = 0.01 * ((k * 7 + id) as f64).cos();
                    let reading = BeaconReading {
                        id: id as u32,
                        _pad: 0,
                        range: range + wobble,
                        bearing: mole_types::wrap_angle(dy.atan2(dx) - theta + wobble),
                    };
                    graph.add_observation(k, &reading).unwrap();
                }
            }
        }
        graph
    }

    /// The step solved in the segmented elimination order is the dense Cholesky solve of the
    /// same damped H in H's own order, to 1e-9, on graphs shorter than, equal to and longer
    /// than a segment; and the landmarks keep their indices (the covariances rely on it).
    #[test]
    fn the_segmented_order_solves_what_the_dense_solve_does() {
        for n_poses in [1, 2, super::SEGMENT_POSES, super::SEGMENT_POSES + 1, 300] {
            let mut graph = graph(n_poses, 100, 12);
            let normal = &mut graph.normal;
            normal.analyse(&graph.problem).unwrap();
            normal.assemble(&graph.problem);
            let lambda = 1e-3;
            normal.solve(lambda).unwrap();

            let n = normal.dim();
            let mut dense = nalgebra::DMatrix::<f64>::zeros(n, n);
            for c in 0..n {
                for k in normal.col_ptr[c]..normal.col_ptr[c + 1] {
                    let r = normal.row_idx[k];
                    let damping = if r == c { lambda } else { 0.0 };
                    dense[(r, c)] = normal.hessian[k] * (1.0 + damping);
                    dense[(c, r)] = dense[(r, c)];
                }
            }
            let b = nalgebra::DVector::from_column_slice(&normal.rhs);
            let expected = dense.cholesky().expect("positive definite").solve(&(-b));
            assert!(
                n_poses < 3 || graph.problem.landmarks.len() > 3,
                "{n_poses}"
            );
            for (i, (s, d)) in normal.step().iter().zip(expected.iter()).enumerate() {
                assert!(
                    (s - d).abs() < 1e-9 * (1.0 + d.abs()),
                    "{n_poses} poses, unknown {i}: {s} vs {d}"
                );
            }
            for u in 3 * n_poses..n {
                assert_eq!(
                    normal.position[u], u,
                    "{n_poses} poses, landmark unknown {u}"
                );
            }
        }
    }

    /// The segmented order keeps the factor small: on three laps among 30 beacons, at the
    /// bench's 0.05 m a pose, it has far fewer entries than the chain's own order (every pose,
    /// then every landmark) gives.
    #[test]
    fn the_segmented_order_fills_in_less_than_the_chain() {
        let mut graph = graph(1500, 500, 30);
        let normal = &mut graph.normal;
        normal.analyse(&graph.problem).unwrap();
        let segmented = normal.symbolic.as_ref().unwrap().len_val();
        let n = normal.dim();
        let natural =
            SymbolicSparseColMatRef::new_checked(n, n, &normal.col_ptr, None, &normal.row_idx);
        let chain = super::symbolic_cholesky(natural).unwrap().len_val();
        println!("factor entries: segmented {segmented}, chain {chain}");
        assert!(10 * segmented < 7 * chain, "{segmented} vs {chain}");
    }
}
