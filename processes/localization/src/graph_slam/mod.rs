//! GraphSLAM: full-trajectory SLAM as sparse nonlinear least squares over a pose graph
//! (Thrun et al., *Probabilistic Robotics* 2005, ch. 11; Grisetti et al. 2010, "A tutorial on
//! graph-based SLAM").
//!
//! Nodes are the robot poses (x, y, θ) and the beacons seen so far (x, y). Factors are a prior
//! on the first pose, one odometry constraint between consecutive poses (the unicycle model of
//! [`crate::models`] with the control noise of [`NoiseModel`]) and one range-bearing
//! observation per accepted [`BeaconReading`] (known correspondence: the reading's id). The
//! solver is Levenberg–Marquardt on the sparse normal equations, factorised by faer's sparse
//! Cholesky; the symbolic analysis is redone only when the graph's structure changed.
//!
//! # Threading
//!
//! [`PoseGraph`] is `Send` and not meant to be shared: one thread owns it. In the process,
//! [`GraphSlamEstimator`] (module `smoother`) runs an EKF-SLAM front-end on the step path and
//! hands each step's odometry and associated readings through a bounded queue to a smoother
//! thread that owns the graph, appends with [`PoseGraph::add_pose`] and
//! [`PoseGraph::add_observation`] (which do not allocate within the reserved capacity) and
//! solves with [`PoseGraph::optimize`] from the previous optimum, so every solve starts from a
//! good initial guess.

pub mod factors;
pub mod g2o;
mod normal_equations;
mod problem;
mod smoother;

pub use smoother::{
    GraphSlamEstimator, QUEUE_STEPS, SMOOTHER_POSES, SOLVE_EVERY, SOLVE_ITERATIONS,
};

use crate::models::MIN_RANGE;
use crate::models::{MAX_ODOM_DT, MAX_ODOM_SPEED, MAX_ODOM_TURN_RATE};
use crate::noise::NoiseModel;
use factors::{ObservationFactor, OdometryFactor, PositionFactor, observation_information};
use mole_types::Setting;
use mole_types::{BeaconReading, Odom, Pose2, WorldMap, wrap_angle};
use nalgebra::{Matrix2, Matrix3, Vector2, Vector3};
use normal_equations::{NormalEquations, SolveError};
use problem::Problem;
use serde::{Deserialize, Serialize};
use thiserror::Error;

/// Default σ of the prior on the first pose (m, m, rad): the start is known.
pub const DEFAULT_PRIOR_STD: [f64; 3] = [1e-3, 1e-3, 1e-3];
/// Default bound on a reading's range (m) beyond which it is refused as absurd.
pub const DEFAULT_MAX_RANGE: f64 = 1000.0;
/// Position fixes reserved: one per this many poses (a fix a second at 100 Hz); more grow the
/// storage.
const POSES_PER_RESERVED_FIX: usize = 100;

/// Levenberg–Marquardt settings (Grisetti et al. 2010 §IV; Marquardt's diagonal scaling).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, Setting)]
#[serde(default, deny_unknown_fields)]
pub struct SolverConfig {
    /// λ of the first iteration of every [`PoseGraph::optimize`] call.
    #[setting(above = 0.0)]
    pub initial_lambda: f64,
    /// λ is divided by this after an accepted step and multiplied by it after a rejected one.
    #[setting(above = 1.0)]
    pub lambda_factor: f64,
    /// λ never drops below this.
    #[setting(above = 0.0)]
    pub min_lambda: f64,
    /// Past this λ the solve stops: no step along the gradient reduces the cost.
    #[setting(above = 0.0)]
    pub max_lambda: f64,
    /// Converged when the largest component of a step (m or rad) is at most this.
    #[setting(above = 0.0)]
    pub step_tolerance: f64,
    /// Converged when an accepted step lowers χ² by at most this fraction of it (1e-6 is far
    /// below χ²'s own statistical spread, √(2/dof) of it, for any graph worth solving).
    #[setting(above = 0.0)]
    pub cost_tolerance: f64,
}

impl Default for SolverConfig {
    fn default() -> Self {
        Self {
            initial_lambda: 1e-6,
            lambda_factor: 10.0,
            min_lambda: 1e-12,
            max_lambda: 1e8,
            step_tolerance: 1e-10,
            cost_tolerance: 1e-6,
        }
    }
}

/// Noise, input bounds and solver settings of a [`PoseGraph`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GraphSlamConfig {
    /// Odometry and beacon noise: M_t, R_floor and Q_t.
    pub noise: NoiseModel,
    /// σ of the prior on the first pose (m, m, rad).
    pub prior_std: [f64; 3],
    /// Readings with a range above this (m) are refused.
    pub max_range: f64,
    /// Levenberg–Marquardt settings.
    pub solver: SolverConfig,
}

impl GraphSlamConfig {
    /// The default bounds and solver with the given noise.
    pub fn new(noise: NoiseModel) -> Self {
        Self {
            noise,
            prior_std: DEFAULT_PRIOR_STD,
            max_range: DEFAULT_MAX_RANGE,
            solver: SolverConfig::default(),
        }
    }

    /// The defaults with the noise the world's sensors are configured with.
    pub fn from_map(map: &WorldMap) -> Self {
        Self::new(NoiseModel::from_map(map))
    }
}

/// Room reserved up front; appends within it do not allocate.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct GraphCapacity {
    /// Poses, the first included.
    pub poses: usize,
    /// Distinct landmarks.
    pub landmarks: usize,
    /// Range-bearing readings.
    pub observations: usize,
}

/// Why an input was refused. Every refusal is also counted (see [`PoseGraph::refused`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Error)]
pub enum GraphError {
    /// A value is NaN or infinite.
    #[error("{0} is not finite")]
    NotFinite(&'static str),
    /// A value is outside its plausible range (negative or absurdly large).
    #[error("{0} is out of range")]
    OutOfRange(&'static str),
    /// The reading names a pose the graph does not have.
    #[error("no pose {0} in the graph")]
    UnknownPose(usize),
    /// The odometry's covariance could not be inverted.
    #[error("odometry covariance is degenerate")]
    DegenerateOdometry,
    /// H was not positive definite at the current estimate.
    #[error("information matrix is not positive definite")]
    NotPositiveDefinite,
    /// The sparse factorisation could not allocate.
    #[error("out of memory in the sparse factorisation")]
    OutOfMemory,
}

impl From<SolveError> for GraphError {
    fn from(e: SolveError) -> Self {
        match e {
            SolveError::NotPositiveDefinite => GraphError::NotPositiveDefinite,
            SolveError::OutOfMemory => GraphError::OutOfMemory,
        }
    }
}

/// Inputs refused so far.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct RefusedCounts {
    /// Odometry steps refused by [`PoseGraph::add_pose`].
    pub odometry: u64,
    /// Readings refused by [`PoseGraph::add_observation`].
    pub readings: u64,
}

/// Why [`PoseGraph::optimize`] stopped.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Termination {
    /// The step or the relative cost decrease fell below its tolerance.
    Converged,
    /// The iteration budget ran out first.
    MaxIterations,
    /// λ grew past its bound without finding a step that lowers the cost.
    LambdaExhausted,
}

/// What one [`PoseGraph::optimize`] call did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OptimizeReport {
    /// Linear solves (accepted or rejected LM steps).
    pub iterations: usize,
    /// χ² before.
    pub initial_cost: f64,
    /// χ² after.
    pub final_cost: f64,
    /// λ at the end (the next call starts again from the configured one).
    pub lambda: f64,
    /// Why it stopped.
    pub termination: Termination,
    /// Whether the symbolic factorisation had to be redone (the graph grew since the last call).
    pub reanalysed: bool,
}

/// The optimised trajectory and map, borrowed from the graph.
#[derive(Debug, Clone, Copy)]
pub struct Solution<'a> {
    /// Smoothed poses (x, y, θ), θ in (−π, π], in the order they were added.
    pub poses: &'a [Vector3<f64>],
    /// Landmark positions, in the order first seen.
    pub landmarks: &'a [Vector2<f64>],
    /// The beacon id of each landmark.
    pub landmark_ids: &'a [u32],
    /// What the solve did.
    pub report: OptimizeReport,
}

/// A pose graph with its preallocated solver workspace (Thrun §11.2; Grisetti et al. 2010 §III).
pub struct PoseGraph {
    config: GraphSlamConfig,
    problem: Problem,
    landmark_ids: Vec<u32>,
    saved_poses: Vec<Vector3<f64>>,
    saved_landmarks: Vec<Vector2<f64>>,
    normal: NormalEquations,
    structure_changed: bool,
    refused: RefusedCounts,
}

impl PoseGraph {
    /// A graph holding only the first pose, `start`, anchored by the prior, with room for
    /// `capacity` reserved.
    pub fn new(start: Pose2, config: GraphSlamConfig, capacity: GraphCapacity) -> Self {
        let poses = capacity.poses.max(1);
        let mut problem = Problem {
            poses: Vec::with_capacity(poses),
            landmarks: Vec::with_capacity(capacity.landmarks),
            odometry: Vec::with_capacity(poses - 1),
            observations: Vec::with_capacity(capacity.observations),
            positions: Vec::with_capacity(poses / POSES_PER_RESERVED_FIX + 1),
            prior: Vector3::new(start.x, start.y, wrap_angle(start.theta)),
            prior_information: Matrix3::from_diagonal(&Vector3::from(
                config.prior_std.map(|s| 1.0 / (s * s)),
            )),
            observation_information: observation_information(&config.noise),
        };
        problem.poses.push(problem.prior);
        Self {
            config,
            problem,
            landmark_ids: Vec::with_capacity(capacity.landmarks),
            saved_poses: Vec::with_capacity(poses),
            saved_landmarks: Vec::with_capacity(capacity.landmarks),
            normal: NormalEquations::with_capacity(
                poses,
                capacity.landmarks,
                capacity.observations,
            ),
            structure_changed: true,
            refused: RefusedCounts::default(),
        }
    }

    /// Appends a pose reached from the newest one by the odometry (v, ω) over dt, with its
    /// odometry factor, and returns its index; its initial estimate is g(newest estimate, u)
    /// (Thrun §11.2, Table 11.1 GraphSLAM_initialize).
    pub fn add_pose(&mut self, odometry: &Odom) -> Result<usize, GraphError> {
        self.add_sliding_pose(odometry, &Vector2::zeros())
    }

    /// [`PoseGraph::add_pose`] for a step whose wheels turned against a wall: the arc of
    /// `odometry`, then the slide `sideways` (robot frame at the arc's end, [`crate::contact`]).
    pub fn add_sliding_pose(
        &mut self,
        odometry: &Odom,
        sideways: &Vector2<f64>,
    ) -> Result<usize, GraphError> {
        let result = self.try_add_pose(odometry, sideways);
        if result.is_err() {
            self.refused.odometry += 1;
        }
        result
    }

    fn try_add_pose(
        &mut self,
        odometry: &Odom,
        sideways: &Vector2<f64>,
    ) -> Result<usize, GraphError> {
        let (v, omega, dt) = (odometry.v, odometry.omega, odometry.dt);
        if !(v.is_finite() && omega.is_finite() && dt.is_finite()) {
            return Err(GraphError::NotFinite("odometry"));
        }
        if !sideways.iter().all(|d| d.is_finite()) {
            return Err(GraphError::NotFinite("slide"));
        }
        // The bounds every estimator applies (models::odometry_is_plausible), named one by one.
        if v.abs() > MAX_ODOM_SPEED {
            return Err(GraphError::OutOfRange("speed"));
        }
        if omega.abs() > MAX_ODOM_TURN_RATE {
            return Err(GraphError::OutOfRange("turn rate"));
        }
        if !(0.0..=MAX_ODOM_DT).contains(&dt) {
            return Err(GraphError::OutOfRange("dt"));
        }
        let factor = OdometryFactor::new(&self.config.noise, v, omega, dt)
            .ok_or(GraphError::DegenerateOdometry)?
            .with_slide(sideways);
        let newest = self.problem.poses[self.problem.poses.len() - 1];
        let mut reached = crate::models::unicycle_g(&newest, v, omega, dt);
        crate::models::add_slide(&mut reached, None, sideways);
        self.problem.poses.push(reached);
        self.problem.odometry.push(factor);
        self.structure_changed = true;
        Ok(self.problem.poses.len() - 1)
    }

    /// Adds the range-bearing reading taken at pose `pose_index` and returns the index of the
    /// landmark it observes; a beacon id seen for the first time becomes a new landmark,
    /// initialised by inverting h at the pose's current estimate (Thrun §11.2, Table 11.1).
    pub fn add_observation(
        &mut self,
        pose_index: usize,
        reading: &BeaconReading,
    ) -> Result<usize, GraphError> {
        let result = self.try_add_observation(pose_index, reading);
        if result.is_err() {
            self.refused.readings += 1;
        }
        result
    }

    fn try_add_observation(
        &mut self,
        pose_index: usize,
        reading: &BeaconReading,
    ) -> Result<usize, GraphError> {
        let (range, bearing) = (reading.range, reading.bearing);
        if !(range.is_finite() && bearing.is_finite()) {
            return Err(GraphError::NotFinite("reading"));
        }
        if !(MIN_RANGE..=self.config.max_range).contains(&range) {
            return Err(GraphError::OutOfRange("range"));
        }
        let pose = *self
            .problem
            .poses
            .get(pose_index)
            .ok_or(GraphError::UnknownPose(pose_index))?;
        let landmark = match self.landmark_ids.iter().position(|&id| id == reading.id) {
            Some(j) => j,
            None => {
                let heading = pose[2] + bearing;
                self.problem.landmarks.push(Vector2::new(
                    pose[0] + range * heading.cos(),
                    pose[1] + range * heading.sin(),
                ));
                self.landmark_ids.push(reading.id);
                self.landmark_ids.len() - 1
            }
        };
        self.problem.observations.push(ObservationFactor {
            pose: pose_index,
            landmark,
            range,
            bearing: wrap_angle(bearing),
        });
        self.structure_changed = true;
        Ok(landmark)
    }

    /// Adds a position fix (x, y) of pose `pose_index` with σ `std` per coordinate (m; floored
    /// as [`NoiseModel::q_fix`] does, the model's own σ when not positive): a unary factor that
    /// ties the graph to the world frame, as the fix does the filters.
    pub fn add_position(
        &mut self,
        pose_index: usize,
        x: f64,
        y: f64,
        std: f64,
    ) -> Result<(), GraphError> {
        let result = self.try_add_position(pose_index, x, y, std);
        if result.is_err() {
            self.refused.readings += 1;
        }
        result
    }

    fn try_add_position(
        &mut self,
        pose_index: usize,
        x: f64,
        y: f64,
        std: f64,
    ) -> Result<(), GraphError> {
        if !(x.is_finite() && y.is_finite()) {
            return Err(GraphError::NotFinite("position"));
        }
        if pose_index >= self.problem.poses.len() {
            return Err(GraphError::UnknownPose(pose_index));
        }
        let q = self.config.noise.q_fix(std);
        self.problem.positions.push(PositionFactor {
            pose: pose_index,
            position: Vector2::new(x, y),
            information: Matrix2::new(1.0 / q[(0, 0)], 0.0, 0.0, 1.0 / q[(1, 1)]),
        });
        // The pose's diagonal block is always in H: the structure did not change.
        Ok(())
    }

    /// Runs at most `max_iterations` Levenberg–Marquardt iterations from the current estimate
    /// (Grisetti et al. 2010 §IV, Algorithm 1 with LM damping; Thrun §11.2 Table 11.5 for the
    /// Gauss–Newton core) and returns the optimised trajectory and landmarks. Allocates only
    /// when the graph's structure changed since the last call (the symbolic factorisation),
    /// and fails only when that allocation does.
    pub fn optimize(&mut self, max_iterations: usize) -> Result<Solution<'_>, GraphError> {
        let reanalysed = self.structure_changed;
        if reanalysed {
            self.normal.analyse(&self.problem)?;
            self.structure_changed = false;
        }
        let solver = self.config.solver;
        let mut cost = self.normal.assemble(&self.problem);
        let mut report = OptimizeReport {
            iterations: 0,
            initial_cost: cost,
            final_cost: cost,
            lambda: solver.initial_lambda,
            termination: Termination::MaxIterations,
            reanalysed,
        };
        let mut linearised = true;
        while report.iterations < max_iterations {
            if !linearised {
                self.normal.assemble(&self.problem);
                linearised = true;
            }
            report.iterations += 1;
            if self.normal.solve(report.lambda).is_ok() {
                let largest = self
                    .normal
                    .step()
                    .iter()
                    .fold(0.0f64, |m, s| m.max(s.abs()));
                if largest <= solver.step_tolerance {
                    report.termination = Termination::Converged;
                    break;
                }
                self.save();
                self.problem.apply(self.normal.step());
                // Linearised at the trial point in the same pass that gives its χ²: ready for
                // the next iteration when the step is accepted, redone when it is not.
                let new_cost = self.normal.assemble(&self.problem);
                if new_cost < cost {
                    let decrease = cost - new_cost;
                    let previous = cost;
                    cost = new_cost;
                    report.lambda = (report.lambda / solver.lambda_factor).max(solver.min_lambda);
                    if decrease <= solver.cost_tolerance * previous {
                        report.termination = Termination::Converged;
                        break;
                    }
                    continue;
                }
                self.restore();
                linearised = false;
            }
            report.lambda *= solver.lambda_factor;
            if report.lambda > solver.max_lambda {
                report.termination = Termination::LambdaExhausted;
                break;
            }
        }
        report.final_cost = cost;
        Ok(Solution {
            poses: &self.problem.poses,
            landmarks: &self.problem.landmarks,
            landmark_ids: &self.landmark_ids,
            report,
        })
    }

    /// Marginal 2×2 covariance of every landmark at the current estimate, in landmark order:
    /// the diagonal blocks of H⁻¹ (Thrun §11.4; Grisetti et al. 2010 §IV). Not part of
    /// [`Self::optimize`] because it is not cheap: one more factorisation plus two triangular
    /// solves per landmark over the whole graph; `out` is cleared and filled.
    pub fn landmark_covariances(&mut self, out: &mut Vec<Matrix2<f64>>) -> Result<(), GraphError> {
        if self.structure_changed {
            self.normal.analyse(&self.problem)?;
            self.structure_changed = false;
        }
        self.normal.assemble(&self.problem);
        self.normal
            .landmark_covariances(self.problem.landmarks.len(), out)?;
        Ok(())
    }

    /// The degrees of freedom of the mean landmark NEES under the joint landmark covariance the
    /// last [`Self::landmark_covariances`] solved for (0 before one).
    pub fn landmark_nees_dof(&self) -> f64 {
        self.normal.landmark_nees_dof()
    }

    /// The current estimate of every pose.
    pub fn poses(&self) -> &[Vector3<f64>] {
        &self.problem.poses
    }

    /// The current estimate of every landmark.
    pub fn landmarks(&self) -> &[Vector2<f64>] {
        &self.problem.landmarks
    }

    /// The beacon id of every landmark.
    pub fn landmark_ids(&self) -> &[u32] {
        &self.landmark_ids
    }

    /// Number of accepted readings.
    pub fn observation_count(&self) -> usize {
        self.problem.observations.len()
    }

    /// χ² of the current estimate (Thrun §11.2, eq. 11.3–11.5).
    pub fn cost(&self) -> f64 {
        self.problem.cost()
    }

    /// Inputs refused so far.
    pub fn refused(&self) -> RefusedCounts {
        self.refused
    }

    /// Overwrites the estimate of pose `index` (e.g. a caller's own initial guess).
    pub fn set_pose(&mut self, index: usize, pose: Vector3<f64>) -> Result<(), GraphError> {
        if !pose.iter().all(|x| x.is_finite()) {
            return Err(GraphError::NotFinite("pose"));
        }
        let slot = self
            .problem
            .poses
            .get_mut(index)
            .ok_or(GraphError::UnknownPose(index))?;
        *slot = Vector3::new(pose[0], pose[1], wrap_angle(pose[2]));
        Ok(())
    }

    /// Overwrites the estimate of landmark `index`.
    pub fn set_landmark(&mut self, index: usize, position: Vector2<f64>) -> Result<(), GraphError> {
        if !position.iter().all(|x| x.is_finite()) {
            return Err(GraphError::NotFinite("landmark"));
        }
        let slot = self
            .problem
            .landmarks
            .get_mut(index)
            .ok_or(GraphError::OutOfRange("landmark index"))?;
        *slot = position;
        Ok(())
    }

    fn save(&mut self) {
        self.saved_poses.clear();
        self.saved_poses.extend_from_slice(&self.problem.poses);
        self.saved_landmarks.clear();
        self.saved_landmarks
            .extend_from_slice(&self.problem.landmarks);
    }

    fn restore(&mut self) {
        self.problem.poses.copy_from_slice(&self.saved_poses);
        self.problem
            .landmarks
            .copy_from_slice(&self.saved_landmarks);
    }
}
