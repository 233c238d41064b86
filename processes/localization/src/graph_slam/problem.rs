//! The least-squares problem the graph stands for: the current estimate of every node, every
//! factor, and the objective they define.

use super::factors::{ObservationFactor, OdometryFactor, PositionFactor, prior_residual};
use mole_types::wrap_angle;
use nalgebra::{Matrix2, Matrix3, Vector2, Vector3};

/// Nodes (the estimate) and factors of a pose graph.
#[derive(Debug, Clone)]
pub struct Problem {
    /// Pose estimates (x, y, θ), in the order they were added.
    pub poses: Vec<Vector3<f64>>,
    /// Landmark estimates (x, y), in the order they were first seen.
    pub landmarks: Vec<Vector2<f64>>,
    /// `odometry[i]` links pose i to pose i + 1.
    pub odometry: Vec<OdometryFactor>,
    /// Every accepted range-bearing reading.
    pub observations: Vec<ObservationFactor>,
    /// Every accepted position fix.
    pub positions: Vec<PositionFactor>,
    /// Mean of the prior on the first pose.
    pub prior: Vector3<f64>,
    /// Information of the prior on the first pose.
    pub prior_information: Matrix3<f64>,
    /// Information of one range-bearing reading.
    pub observation_information: Matrix2<f64>,
}

impl Problem {
    /// χ² = Σ eᵀ Ω e over all factors: the GraphSLAM objective J_GraphSLAM of Thrun §11.2
    /// (eq. 11.3–11.5), F(x) of Grisetti et al. 2010 eq. 3.
    pub fn cost(&self) -> f64 {
        let e = prior_residual(&self.poses[0], &self.prior);
        let mut chi2 = e.dot(&(self.prior_information * e));
        for (i, odometry) in self.odometry.iter().enumerate() {
            let e = odometry.residual(&self.poses[i], &self.poses[i + 1]);
            chi2 += e.dot(&(odometry.information * e));
        }
        for o in &self.observations {
            if let Some(e) = o.residual(&self.poses[o.pose], &self.landmarks[o.landmark]) {
                chi2 += e.dot(&(self.observation_information * e));
            }
        }
        for p in &self.positions {
            let e = p.residual(&self.poses[p.pose]);
            chi2 += e.dot(&(p.information * e));
        }
        chi2
    }

    /// x ← x ⊞ Δ: vector addition with headings re-wrapped (Grisetti et al. 2010 §V, eq. 22).
    pub fn apply(&mut self, step: &[f64]) {
        let (pose_steps, landmark_steps) = step.split_at(3 * self.poses.len());
        for (pose, d) in self.poses.iter_mut().zip(pose_steps.chunks_exact(3)) {
            pose[0] += d[0];
            pose[1] += d[1];
            pose[2] = wrap_angle(pose[2] + d[2]);
        }
        for (landmark, d) in self
            .landmarks
            .iter_mut()
            .zip(landmark_steps.chunks_exact(2))
        {
            landmark[0] += d[0];
            landmark[1] += d[1];
        }
    }
}
