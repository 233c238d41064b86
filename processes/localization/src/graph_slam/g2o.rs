//! 2-D g2o graphs: read, optimise with GraphSLAM's Levenberg–Marquardt, write back
//! (algorithms §6.9.4, "g2o graphs and GTSAM").
//!
//! # Format
//!
//! One record per line, fields separated by white space; blank lines and lines starting with
//! `#` are skipped. Ids are non-negative integers, unique over all vertices.
//!
//! - `VERTEX_SE2 id x y θ`: a pose.
//! - `VERTEX_XY id x y`: a point (landmark).
//! - `EDGE_SE2 i j dx dy dθ I11 I12 I13 I22 I23 I33`: the pose of `j` in the frame of `i`, with
//!   the upper triangle of its 3×3 information matrix (row by row).
//! - `EDGE_SE2_XY i j dx dy I11 I12 I22`: the point `j` in the frame of pose `i` (not a
//!   bearing and range), with its 2×2 information matrix.
//! - `FIX id…`: poses held at their initial value (the gauge).
//!
//! Any other tag is an error, as is every malformed line: [`G2oError`] names the file, the line,
//! the field and what was expected there. Nothing panics on bad input.
//!
//! # Objective
//!
//! The error is GTSAM's, ½ Σ eᵀ Ω e (half the χ² of [`super::PoseGraph::cost`]), with GTSAM's
//! residuals:
//! - `EDGE_SE2`: e = Log(z⁻¹ · (xᵢ⁻¹ · xⱼ)), the SE(2) logarithm (GTSAM's `BetweenFactor<Pose2>`
//!   with `Pose2::Logmap`, as the PyPI wheel is built): for D = (t, φ), φ wrapped to (−π, π],
//!   Log D = (V(φ)⁻¹ t, φ) with V(φ)⁻¹ = (φ/2)·[[cot(φ/2), 1], [−1, cot(φ/2)]]. For small φ this
//!   is g2o's own (t, φ); at φ = π/2 the translation part differs by 21%.
//! - `EDGE_SE2_XY`: e = R(θᵢ)ᵀ(m − tᵢ) − z, the point in the pose frame (GTSAM's
//!   `Pose2::transformTo`).
//! - The gauge: each `FIX`ed pose, or without `FIX` the first `VERTEX_SE2`, gets a prior
//!   e = Log(x₀⁻¹ · x) at its initial value x₀ with σ = [`super::DEFAULT_PRIOR_STD`] per axis, as
//!   [`super::PoseGraph`] anchors its first pose. With one anchor its residual is 0 at the optimum.
//!
//! The unknowns are updated additively in (x, y, θ) (θ re-wrapped), as [`super::PoseGraph`]
//! does; the optimum does not depend on that choice. The normal equations are GraphSLAM's
//! (H = Σ JᵀΩJ, Marquardt damping λ·diag H, faer's supernodal LLᵀ) but for an arbitrary graph:
//! [`super::PoseGraph`]'s are laid out for a chain of odometry with range-bearing readings in
//! trajectory order, and a g2o graph has loop closures between any two poses, so here the block
//! pattern comes from the edges and faer orders it by approximate minimum degree.

use super::{DEFAULT_PRIOR_STD, GraphError, SolverConfig, Termination};
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::llt::factor::LltRegularization;
use faer::sparse::linalg::cholesky::{
    CholeskySymbolicParams, SymbolicCholesky, SymmetricOrdering, factorize_symbolic_cholesky,
};
use faer::sparse::{SparseColMatRef, SymbolicSparseColMatRef};
use faer::{Conj, MatMut, Par, Side};
use mole_types::wrap_angle;
use nalgebra::{Matrix2, Matrix2x3, Matrix3, SMatrix, SVector, Vector2, Vector3};
use std::collections::HashMap;
use std::fmt::Write as _;
use std::path::Path;
use thiserror::Error;

/// The tags this reader knows.
pub const TAGS: &str = "VERTEX_SE2, VERTEX_XY, EDGE_SE2, EDGE_SE2_XY or FIX";

/// A refused g2o file: where and what.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
#[error("{file}{}: {field}: expected {expected}, found {found}",
        line.map(|l| format!(" line {l}")).unwrap_or_default())]
pub struct G2oError {
    /// The file as it was named.
    pub file: String,
    /// 1-based line number; `None` for the file as a whole.
    pub line: Option<usize>,
    /// The record and field, e.g. `EDGE_SE2 I22 (field 9)`.
    pub field: String,
    /// What the field must hold.
    pub expected: String,
    /// What it held.
    pub found: String,
}

/// A vertex's estimate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum VertexValue {
    /// `VERTEX_SE2`: (x, y, θ).
    Se2(Vector3<f64>),
    /// `VERTEX_XY`: (x, y).
    Xy(Vector2<f64>),
}

/// One vertex: its file id and estimate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Vertex {
    /// The id in the file.
    pub id: u64,
    /// The estimate.
    pub value: VertexValue,
}

/// One edge; `from`, `to`, `pose` and `point` index [`G2oGraph::vertices`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Edge {
    /// `EDGE_SE2`: pose `to` measured in the frame of pose `from`.
    Se2 {
        /// Vertex index of i.
        from: usize,
        /// Vertex index of j.
        to: usize,
        /// (dx, dy, dθ).
        measurement: Vector3<f64>,
        /// Ω (symmetric, positive definite).
        information: Matrix3<f64>,
    },
    /// `EDGE_SE2_XY`: point `point` measured in the frame of pose `pose`.
    Se2Xy {
        /// Vertex index of the pose.
        pose: usize,
        /// Vertex index of the point.
        point: usize,
        /// (dx, dy).
        measurement: Vector2<f64>,
        /// Ω (symmetric, positive definite).
        information: Matrix2<f64>,
    },
}

/// A 2-D g2o graph: vertices and edges in file order, and the fixed poses.
#[derive(Debug, Clone, PartialEq)]
pub struct G2oGraph {
    /// Every vertex, in file order.
    pub vertices: Vec<Vertex>,
    /// Every edge, in file order.
    pub edges: Vec<Edge>,
    /// Vertex indices of the `FIX`ed poses, in file order.
    pub fixed: Vec<usize>,
}

/// What [`G2oGraph::optimize`] did; errors are GTSAM's ½ Σ eᵀΩe.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct G2oReport {
    /// Linear solves (accepted or rejected LM steps).
    pub iterations: usize,
    /// Error at the initial estimate.
    pub initial_error: f64,
    /// Error at the result.
    pub final_error: f64,
    /// Why it stopped.
    pub termination: Termination,
}

/// The Levenberg–Marquardt settings for g2o graphs: [`SolverConfig::default`] run to
/// convergence (relative decrease 1e-12, step 1e-10) rather than to the online smoother's
/// budget, so that two solvers' optima can be compared to 1e-6.
pub fn solver_config() -> SolverConfig {
    SolverConfig {
        cost_tolerance: 1e-12,
        step_tolerance: 1e-10,
        ..SolverConfig::default()
    }
}

/// Iterations [`G2oGraph::optimize`] is given by the `mole g2o` command and the tests.
pub const DEFAULT_ITERATIONS: usize = 100;

struct LineCursor<'a> {
    file: &'a str,
    line: usize,
    tag: &'a str,
    names: &'static [&'static str],
    fields: Vec<&'a str>,
}

impl<'a> LineCursor<'a> {
    fn error(&self, k: usize, expected: &str, found: String) -> G2oError {
        let name = self.names.get(k).copied().unwrap_or("id");
        G2oError {
            file: self.file.to_string(),
            line: Some(self.line),
            field: format!("{} {name} (field {})", self.tag, k + 1),
            expected: expected.to_string(),
            found,
        }
    }

    fn check_count(&self) -> Result<(), G2oError> {
        let n = self.names.len();
        if self.fields.len() < n {
            return Err(self.error(
                self.fields.len(),
                &format!("{n} fields after the tag"),
                format!("{} (the line ends)", self.fields.len()),
            ));
        }
        if self.fields.len() > n {
            return Err(G2oError {
                file: self.file.to_string(),
                line: Some(self.line),
                field: format!("{} (field {})", self.tag, n + 1),
                expected: format!("the end of the line after {n} fields"),
                found: format!("{:?}", self.fields[n]),
            });
        }
        Ok(())
    }

    fn id(&self, k: usize) -> Result<u64, G2oError> {
        self.fields[k].parse::<u64>().map_err(|_| {
            self.error(
                k,
                "a vertex id (an integer ≥ 0)",
                format!("{:?}", self.fields[k]),
            )
        })
    }

    /// The `N` numbers from field `first` on.
    fn numbers<const N: usize>(&self, first: usize) -> Result<[f64; N], G2oError> {
        let mut v = [0.0; N];
        for (k, x) in v.iter_mut().enumerate() {
            *x = self.number(first + k)?;
        }
        Ok(v)
    }

    fn number(&self, k: usize) -> Result<f64, G2oError> {
        match self.fields[k].parse::<f64>() {
            Ok(x) if x.is_finite() => Ok(x),
            _ => Err(self.error(k, "a finite number", format!("{:?}", self.fields[k]))),
        }
    }
}

/// An edge as read, before its ids are resolved (vertices may come after edges).
struct PendingEdge {
    line: usize,
    tag: &'static str,
    i: u64,
    j: u64,
    edge: Edge,
}

const VERTEX_SE2: &[&str] = &["id", "x", "y", "theta"];
const VERTEX_XY: &[&str] = &["id", "x", "y"];
const EDGE_SE2: &[&str] = &[
    "i", "j", "dx", "dy", "dtheta", "I11", "I12", "I13", "I22", "I23", "I33",
];
const EDGE_SE2_XY: &[&str] = &["i", "j", "dx", "dy", "I11", "I12", "I22"];

impl G2oGraph {
    /// Reads the g2o file at `path`.
    pub fn read(path: &Path) -> Result<Self, G2oError> {
        let name = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|e| G2oError {
            file: name.clone(),
            line: None,
            field: "file".into(),
            expected: "a readable UTF-8 text file".into(),
            found: e.to_string(),
        })?;
        Self::parse(&text, &name)
    }

    /// Parses g2o text; `file` names it in errors.
    pub fn parse(text: &str, file: &str) -> Result<Self, G2oError> {
        let mut vertices = Vec::new();
        let mut index: HashMap<u64, (usize, usize)> = HashMap::new();
        let mut pending = Vec::new();
        let mut fixes = Vec::new();
        for (n, raw) in text.lines().enumerate() {
            let mut tokens = raw.split_whitespace();
            let Some(tag) = tokens.next() else { continue };
            if tag.starts_with('#') {
                continue;
            }
            let names: &'static [&'static str] = match tag {
                "VERTEX_SE2" => VERTEX_SE2,
                "VERTEX_XY" => VERTEX_XY,
                "EDGE_SE2" => EDGE_SE2,
                "EDGE_SE2_XY" => EDGE_SE2_XY,
                "FIX" => &[],
                _ => {
                    return Err(G2oError {
                        file: file.to_string(),
                        line: Some(n + 1),
                        field: "tag (field 0)".into(),
                        expected: TAGS.into(),
                        found: format!("{tag:?}"),
                    });
                }
            };
            let c = LineCursor {
                file,
                line: n + 1,
                tag,
                names,
                fields: tokens.collect(),
            };
            match tag {
                "VERTEX_SE2" | "VERTEX_XY" => {
                    c.check_count()?;
                    let id = c.id(0)?;
                    let value = if tag == "VERTEX_SE2" {
                        VertexValue::Se2(Vector3::new(c.number(1)?, c.number(2)?, c.number(3)?))
                    } else {
                        VertexValue::Xy(Vector2::new(c.number(1)?, c.number(2)?))
                    };
                    if let Some(&(_, first)) = index.get(&id) {
                        return Err(c.error(
                            0,
                            "an id no other vertex has",
                            format!("{id}, already the id of the vertex on line {first}"),
                        ));
                    }
                    index.insert(id, (vertices.len(), n + 1));
                    vertices.push(Vertex { id, value });
                }
                "EDGE_SE2" => {
                    c.check_count()?;
                    let (i, j) = (c.id(0)?, c.id(1)?);
                    let [dx, dy, dt, i11, i12, i13, i22, i23, i33] = c.numbers(2)?;
                    let information = Matrix3::new(i11, i12, i13, i12, i22, i23, i13, i23, i33);
                    if information.cholesky().is_none() {
                        return Err(c.error(
                            5,
                            "an information matrix (I11 … I33) that is positive definite",
                            format!("[{i11} {i12} {i13}; {i12} {i22} {i23}; {i13} {i23} {i33}]"),
                        ));
                    }
                    let edge = Edge::Se2 {
                        from: 0,
                        to: 0,
                        measurement: Vector3::new(dx, dy, dt),
                        information,
                    };
                    pending.push(PendingEdge {
                        line: n + 1,
                        tag: "EDGE_SE2",
                        i,
                        j,
                        edge,
                    });
                }
                "EDGE_SE2_XY" => {
                    c.check_count()?;
                    let (i, j) = (c.id(0)?, c.id(1)?);
                    let [dx, dy, i11, i12, i22] = c.numbers(2)?;
                    let information = Matrix2::new(i11, i12, i12, i22);
                    if information.cholesky().is_none() {
                        return Err(c.error(
                            4,
                            "an information matrix (I11 I12 I22) that is positive definite",
                            format!("[{i11} {i12}; {i12} {i22}]"),
                        ));
                    }
                    let edge = Edge::Se2Xy {
                        pose: 0,
                        point: 0,
                        measurement: Vector2::new(dx, dy),
                        information,
                    };
                    pending.push(PendingEdge {
                        line: n + 1,
                        tag: "EDGE_SE2_XY",
                        i,
                        j,
                        edge,
                    });
                }
                _ => {
                    // FIX id…
                    if c.fields.is_empty() {
                        return Err(c.error(
                            0,
                            "at least one vertex id",
                            "the end of the line".into(),
                        ));
                    }
                    for k in 0..c.fields.len() {
                        fixes.push((n + 1, k, c.id(k)?));
                    }
                }
            }
        }

        let is_pose = |v: usize| matches!(vertices[v].value, VertexValue::Se2(_));
        let error = |line: usize, field: String, expected: &str, found: String| G2oError {
            file: file.to_string(),
            line: Some(line),
            field,
            expected: expected.to_string(),
            found,
        };
        let resolve = |line: usize, field: String, id: u64, pose: bool| {
            let expected = if pose {
                "the id of a VERTEX_SE2"
            } else {
                "the id of a VERTEX_XY"
            };
            match index.get(&id) {
                None => Err(error(
                    line,
                    field,
                    expected,
                    format!("{id}, which no vertex has"),
                )),
                Some(&(v, _)) if is_pose(v) != pose => {
                    let kind = if pose { "VERTEX_XY" } else { "VERTEX_SE2" };
                    Err(error(line, field, expected, format!("{id}, a {kind}")))
                }
                Some(&(v, _)) => Ok(v),
            }
        };
        let mut edges = Vec::with_capacity(pending.len());
        for p in pending {
            let field = |k: usize| format!("{} {} (field {})", p.tag, ["i", "j"][k], k + 1);
            let a = resolve(p.line, field(0), p.i, true)?;
            let b = resolve(p.line, field(1), p.j, matches!(p.edge, Edge::Se2 { .. }))?;
            if a == b {
                return Err(error(
                    p.line,
                    field(1),
                    "an id other than i's",
                    format!("{}", p.j),
                ));
            }
            edges.push(match p.edge {
                Edge::Se2 {
                    measurement,
                    information,
                    ..
                } => Edge::Se2 {
                    from: a,
                    to: b,
                    measurement,
                    information,
                },
                Edge::Se2Xy {
                    measurement,
                    information,
                    ..
                } => Edge::Se2Xy {
                    pose: a,
                    point: b,
                    measurement,
                    information,
                },
            });
        }
        let mut fixed = Vec::with_capacity(fixes.len());
        for (line, k, id) in fixes {
            let v = resolve(line, format!("FIX id (field {})", k + 1), id, true)?;
            if !fixed.contains(&v) {
                fixed.push(v);
            }
        }
        if !vertices
            .iter()
            .any(|v| matches!(v.value, VertexValue::Se2(_)))
        {
            return Err(G2oError {
                file: file.to_string(),
                line: None,
                field: "VERTEX_SE2".into(),
                expected: "at least one VERTEX_SE2 (2-D g2o)".into(),
                found: format!("{} vertices, none a pose", vertices.len()),
            });
        }
        let graph = Self {
            vertices,
            edges,
            fixed,
        };
        if let Some(v) = graph.first_unanchored() {
            let vertex = &graph.vertices[v];
            let tag = match vertex.value {
                VertexValue::Se2(_) => "VERTEX_SE2",
                VertexValue::Xy(_) => "VERTEX_XY",
            };
            return Err(error(
                index[&vertex.id].1,
                format!("{tag} id (field 1)"),
                "a vertex that edges join to the anchored pose (the FIXed ones, else the first \
                 VERTEX_SE2), so that the optimum is defined",
                format!("{}, which no chain of edges reaches", vertex.id),
            ));
        }
        Ok(graph)
    }

    /// The first vertex no chain of edges joins to an anchor: its position is not defined by
    /// the graph, and the normal equations are singular there.
    fn first_unanchored(&self) -> Option<usize> {
        let mut neighbours = vec![Vec::new(); self.vertices.len()];
        for edge in &self.edges {
            let (a, b) = match *edge {
                Edge::Se2 { from, to, .. } => (from, to),
                Edge::Se2Xy { pose, point, .. } => (pose, point),
            };
            neighbours[a].push(b);
            neighbours[b].push(a);
        }
        let mut reached = vec![false; self.vertices.len()];
        let mut stack = self.anchors();
        for &a in &stack {
            reached[a] = true;
        }
        while let Some(v) = stack.pop() {
            for &n in &neighbours[v] {
                if !reached[n] {
                    reached[n] = true;
                    stack.push(n);
                }
            }
        }
        reached.iter().position(|&r| !r)
    }

    /// The graph as g2o text: the vertices at their current estimate, then the edges as read,
    /// then the `FIX` line; numbers in the shortest form that reads back to the same f64, so
    /// [`Self::parse`] of the text gives this graph again.
    pub fn to_g2o(&self) -> String {
        let mut out = String::with_capacity(64 * (self.vertices.len() + self.edges.len()));
        for v in &self.vertices {
            let _ = match v.value {
                VertexValue::Se2(p) => {
                    writeln!(out, "VERTEX_SE2 {} {} {} {}", v.id, p[0], p[1], p[2])
                }
                VertexValue::Xy(p) => writeln!(out, "VERTEX_XY {} {} {}", v.id, p[0], p[1]),
            };
        }
        for e in &self.edges {
            let _ = match *e {
                Edge::Se2 {
                    from,
                    to,
                    measurement: z,
                    information: m,
                } => writeln!(
                    out,
                    "EDGE_SE2 {} {} {} {} {} {} {} {} {} {} {}",
                    self.vertices[from].id,
                    self.vertices[to].id,
                    z[0],
                    z[1],
                    z[2],
                    m[(0, 0)],
                    m[(0, 1)],
                    m[(0, 2)],
                    m[(1, 1)],
                    m[(1, 2)],
                    m[(2, 2)]
                ),
                Edge::Se2Xy {
                    pose,
                    point,
                    measurement: z,
                    information: m,
                } => writeln!(
                    out,
                    "EDGE_SE2_XY {} {} {} {} {} {} {}",
                    self.vertices[pose].id,
                    self.vertices[point].id,
                    z[0],
                    z[1],
                    m[(0, 0)],
                    m[(0, 1)],
                    m[(1, 1)]
                ),
            };
        }
        if !self.fixed.is_empty() {
            out.push_str("FIX");
            for &v in &self.fixed {
                let _ = write!(out, " {}", self.vertices[v].id);
            }
            out.push('\n');
        }
        out
    }

    /// Writes [`Self::to_g2o`] to `path`.
    pub fn write(&self, path: &Path) -> std::io::Result<()> {
        std::fs::write(path, self.to_g2o())
    }

    /// Number of `VERTEX_SE2`.
    pub fn pose_count(&self) -> usize {
        self.vertices
            .iter()
            .filter(|v| matches!(v.value, VertexValue::Se2(_)))
            .count()
    }

    /// Number of `VERTEX_XY`.
    pub fn point_count(&self) -> usize {
        self.vertices.len() - self.pose_count()
    }

    /// The vertex indices the gauge priors sit on: the `FIX`ed poses, else the first pose.
    pub fn anchors(&self) -> Vec<usize> {
        if self.fixed.is_empty() {
            self.vertices
                .iter()
                .position(|v| matches!(v.value, VertexValue::Se2(_)))
                .into_iter()
                .collect()
        } else {
            self.fixed.clone()
        }
    }

    /// GTSAM's error ½ Σ eᵀΩe of the current estimate, the gauge priors at the current
    /// estimate of their poses (so 0 there).
    pub fn error(&self) -> f64 {
        let priors = Priors::new(self);
        0.5 * chi2(self, &priors)
    }

    /// Levenberg–Marquardt from the current estimate, at most `max_iterations` linear solves,
    /// with `config` (see [`solver_config`]); the vertices are left at the result.
    pub fn optimize(
        &mut self,
        config: &SolverConfig,
        max_iterations: usize,
    ) -> Result<G2oReport, GraphError> {
        let priors = Priors::new(self);
        let mut normal = Normal::analyse(self, &priors)?;
        let mut cost = normal.assemble(self, &priors);
        let mut report = G2oReport {
            iterations: 0,
            initial_error: 0.5 * cost,
            final_error: 0.5 * cost,
            termination: Termination::MaxIterations,
        };
        let mut lambda = config.initial_lambda;
        let mut saved = self.vertices.clone();
        let mut linearised = true;
        while report.iterations < max_iterations {
            if !linearised {
                normal.assemble(self, &priors);
                linearised = true;
            }
            report.iterations += 1;
            if normal.solve(lambda).is_ok() {
                let largest = normal.step.iter().fold(0.0f64, |m, s| m.max(s.abs()));
                if largest <= config.step_tolerance {
                    report.termination = Termination::Converged;
                    break;
                }
                saved.copy_from_slice(&self.vertices);
                normal.apply(&mut self.vertices);
                let new_cost = normal.assemble(self, &priors);
                if new_cost < cost {
                    let previous = cost;
                    cost = new_cost;
                    lambda = (lambda / config.lambda_factor).max(config.min_lambda);
                    if previous - new_cost <= config.cost_tolerance * previous {
                        report.termination = Termination::Converged;
                        break;
                    }
                    continue;
                }
                self.vertices.copy_from_slice(&saved);
                linearised = false;
            }
            lambda *= config.lambda_factor;
            if lambda > config.max_lambda {
                report.termination = Termination::LambdaExhausted;
                break;
            }
        }
        report.final_error = 0.5 * cost;
        Ok(report)
    }
}

/// The gauge priors: (vertex, mean) with Ω = diag(σ⁻²), σ = [`DEFAULT_PRIOR_STD`].
struct Priors {
    at: Vec<(usize, Vector3<f64>)>,
    information: Matrix3<f64>,
}

impl Priors {
    fn new(graph: &G2oGraph) -> Self {
        let at = graph
            .anchors()
            .into_iter()
            .filter_map(|v| match graph.vertices[v].value {
                VertexValue::Se2(p) => Some((v, p)),
                VertexValue::Xy(_) => None,
            })
            .collect();
        Self {
            at,
            information: Matrix3::from_diagonal(&Vector3::from(
                DEFAULT_PRIOR_STD.map(|s| 1.0 / (s * s)),
            )),
        }
    }
}

fn pose(graph: &G2oGraph, v: usize) -> Vector3<f64> {
    match graph.vertices[v].value {
        VertexValue::Se2(p) => p,
        VertexValue::Xy(p) => Vector3::new(p[0], p[1], 0.0),
    }
}

fn point(graph: &G2oGraph, v: usize) -> Vector2<f64> {
    match graph.vertices[v].value {
        VertexValue::Xy(p) => p,
        VertexValue::Se2(p) => Vector2::new(p[0], p[1]),
    }
}

/// Σ eᵀΩe over the edges and the priors.
fn chi2(graph: &G2oGraph, priors: &Priors) -> f64 {
    let mut total = 0.0;
    for e in &graph.edges {
        total += match *e {
            Edge::Se2 {
                from,
                to,
                measurement,
                information,
            } => {
                let (r, _, _) = se2_between(&pose(graph, from), &pose(graph, to), &measurement);
                r.dot(&(information * r))
            }
            Edge::Se2Xy {
                pose: p,
                point: m,
                measurement,
                information,
            } => {
                let (r, _, _) = se2_point(&pose(graph, p), &point(graph, m), &measurement);
                r.dot(&(information * r))
            }
        };
    }
    for &(v, mean) in &priors.at {
        let (r, _, _) = se2_between(&mean, &pose(graph, v), &Vector3::zeros());
        total += r.dot(&(priors.information * r));
    }
    total
}

/// a(φ) = (φ/2)·cot(φ/2) and its derivative, by series near 0.
fn half_cot(phi: f64) -> (f64, f64) {
    if phi.abs() < 1e-3 {
        let p2 = phi * phi;
        (
            1.0 - p2 / 12.0 - p2 * p2 / 720.0,
            -phi / 6.0 - phi * p2 / 180.0,
        )
    } else {
        let h = 0.5 * phi;
        let (s, c) = h.sin_cos();
        (h * c / s, 0.5 * c / s - 0.5 * h / (s * s))
    }
}

/// e = Log(z⁻¹ · (a⁻¹ · b)) and (∂e/∂a, ∂e/∂b) for additive (x, y, θ) updates of a and b.
pub fn se2_between(
    a: &Vector3<f64>,
    b: &Vector3<f64>,
    z: &Vector3<f64>,
) -> (Vector3<f64>, Matrix3<f64>, Matrix3<f64>) {
    let (sa, ca) = a[2].sin_cos();
    let (sz, cz) = z[2].sin_cos();
    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
    // d = R(θa)ᵀ (tb − ta), then D = z⁻¹ · (d, θb − θa): t = R(θz)ᵀ (d − tz).
    let d = Vector2::new(ca * dx + sa * dy, -sa * dx + ca * dy);
    let u = d - Vector2::new(z[0], z[1]);
    let t = Vector2::new(cz * u[0] + sz * u[1], -sz * u[0] + cz * u[1]);
    let phi = wrap_angle(b[2] - a[2] - z[2]);
    // ∂(t, φ)/∂a and ∂(t, φ)/∂b.
    let (s, c) = (a[2] + z[2]).sin_cos();
    let rt = Matrix2::new(c, s, -s, c);
    let mut g_a = Matrix3::zeros();
    let mut g_b = Matrix3::zeros();
    g_a.fixed_view_mut::<2, 2>(0, 0).copy_from(&(-rt));
    g_b.fixed_view_mut::<2, 2>(0, 0).copy_from(&rt);
    let dtheta = Vector2::new(cz * d[1] - sz * d[0], -sz * d[1] - cz * d[0]);
    g_a[(0, 2)] = dtheta[0];
    g_a[(1, 2)] = dtheta[1];
    g_a[(2, 2)] = -1.0;
    g_b[(2, 2)] = 1.0;
    // Log(t, φ) = (A(φ) t, φ), A = [[a, φ/2], [−φ/2, a]].
    let (ah, dah) = half_cot(phi);
    let e = Vector3::new(
        ah * t[0] + 0.5 * phi * t[1],
        -0.5 * phi * t[0] + ah * t[1],
        phi,
    );
    let m = Matrix3::new(
        ah,
        0.5 * phi,
        dah * t[0] + 0.5 * t[1],
        -0.5 * phi,
        ah,
        -0.5 * t[0] + dah * t[1],
        0.0,
        0.0,
        1.0,
    );
    (e, m * g_a, m * g_b)
}

/// e = R(θ)ᵀ(m − t) − z and (∂e/∂pose, ∂e/∂m).
pub fn se2_point(
    pose: &Vector3<f64>,
    m: &Vector2<f64>,
    z: &Vector2<f64>,
) -> (Vector2<f64>, Matrix2x3<f64>, Matrix2<f64>) {
    let (s, c) = pose[2].sin_cos();
    let (dx, dy) = (m[0] - pose[0], m[1] - pose[1]);
    let q = Vector2::new(c * dx + s * dy, -s * dx + c * dy);
    let j_pose = Matrix2x3::new(-c, -s, q[1], s, -c, -q[0]);
    (q - z, j_pose, Matrix2::new(c, s, -s, c))
}

/// The sparse normal equations of a g2o graph: upper triangle of H in CSC, each column's rows
/// ascending, its diagonal entry last.
struct Normal {
    offset: Vec<usize>,
    col_ptr: Vec<usize>,
    row_idx: Vec<usize>,
    /// Per vertex, the position of its own block in its columns (rows above it first).
    diagonal: Vec<usize>,
    /// Per edge, the position of the lower-indexed vertex's rows in the other's columns.
    slots: Vec<usize>,
    hessian: Vec<f64>,
    damped: Vec<f64>,
    rhs: Vec<f64>,
    step: Vec<f64>,
    symbolic: SymbolicCholesky<usize>,
    factor_values: Vec<f64>,
    scratch: MemBuffer,
}

fn dim(v: &Vertex) -> usize {
    match v.value {
        VertexValue::Se2(_) => 3,
        VertexValue::Xy(_) => 2,
    }
}

fn edge_vertices(e: &Edge) -> (usize, usize) {
    match *e {
        Edge::Se2 { from, to, .. } => (from, to),
        Edge::Se2Xy { pose, point, .. } => (pose, point),
    }
}

impl Normal {
    fn analyse(graph: &G2oGraph, _priors: &Priors) -> Result<Self, GraphError> {
        let nv = graph.vertices.len();
        let mut offset = Vec::with_capacity(nv + 1);
        let mut n = 0;
        for v in &graph.vertices {
            offset.push(n);
            n += dim(v);
        }
        offset.push(n);
        // Per vertex, the lower-indexed vertices it shares an edge with.
        let mut above: Vec<Vec<usize>> = vec![Vec::new(); nv];
        for e in &graph.edges {
            let (a, b) = edge_vertices(e);
            above[a.max(b)].push(a.min(b));
        }
        for list in &mut above {
            list.sort_unstable();
            list.dedup();
        }
        let mut col_ptr = Vec::with_capacity(n + 1);
        let mut row_idx = Vec::new();
        let mut diagonal = Vec::with_capacity(nv);
        col_ptr.push(0);
        for (v, list) in above.iter().enumerate() {
            let rows_above: usize = list.iter().map(|&u| dim(&graph.vertices[u])).sum();
            diagonal.push(rows_above);
            for k in 0..dim(&graph.vertices[v]) {
                for &u in list {
                    row_idx.extend(offset[u]..offset[u + 1]);
                }
                row_idx.extend(offset[v]..=offset[v] + k);
                col_ptr.push(row_idx.len());
            }
        }
        let slots = graph
            .edges
            .iter()
            .map(|e| {
                let (a, b) = edge_vertices(e);
                let (lo, hi) = (a.min(b), a.max(b));
                above[hi]
                    .iter()
                    .take_while(|&&u| u < lo)
                    .map(|&u| dim(&graph.vertices[u]))
                    .sum()
            })
            .collect();
        let nnz = row_idx.len();
        let pattern = SymbolicSparseColMatRef::new_checked(n, n, &col_ptr, None, &row_idx);
        let symbolic = factorize_symbolic_cholesky(
            pattern,
            Side::Upper,
            SymmetricOrdering::Amd,
            CholeskySymbolicParams::default(),
        )
        .map_err(|_| GraphError::OutOfMemory)?;
        let need = symbolic
            .factorize_numeric_llt_scratch::<f64>(Par::Seq, Default::default())
            .or(symbolic.solve_in_place_scratch::<f64>(1, Par::Seq));
        let scratch = MemBuffer::try_new(need).map_err(|_| GraphError::OutOfMemory)?;
        let factor_values = vec![0.0; symbolic.len_val()];
        Ok(Self {
            offset,
            col_ptr,
            row_idx,
            diagonal,
            slots,
            hessian: vec![0.0; nnz],
            damped: vec![0.0; nnz],
            rhs: vec![0.0; n],
            step: vec![0.0; n],
            symbolic,
            factor_values,
            scratch,
        })
    }

    /// H = Σ JᵀΩJ, b = Σ JᵀΩe at the current estimate; returns χ² = Σ eᵀΩe.
    fn assemble(&mut self, graph: &G2oGraph, priors: &Priors) -> f64 {
        self.hessian.fill(0.0);
        self.rhs.fill(0.0);
        let mut total = 0.0;
        for (k, e) in graph.edges.iter().enumerate() {
            let slot = self.slots[k];
            match *e {
                Edge::Se2 {
                    from,
                    to,
                    measurement,
                    information,
                } => {
                    let (r, ja, jb) =
                        se2_between(&pose(graph, from), &pose(graph, to), &measurement);
                    total += r.dot(&(information * r));
                    self.add_binary(from, &ja, to, &jb, &information, &r, slot);
                }
                Edge::Se2Xy {
                    pose: p,
                    point: m,
                    measurement,
                    information,
                } => {
                    let (r, jp, jm) = se2_point(&pose(graph, p), &point(graph, m), &measurement);
                    total += r.dot(&(information * r));
                    self.add_binary(p, &jp, m, &jm, &information, &r, slot);
                }
            }
        }
        for &(v, mean) in &priors.at {
            let (r, _, j) = se2_between(&mean, &pose(graph, v), &Vector3::zeros());
            total += r.dot(&(priors.information * r));
            self.add_diagonal(v, &j, &priors.information, &r);
        }
        total
    }

    fn add_diagonal<const R: usize, const C: usize>(
        &mut self,
        v: usize,
        j: &SMatrix<f64, R, C>,
        omega: &SMatrix<f64, R, R>,
        e: &SVector<f64, R>,
    ) {
        let jt_omega = j.transpose() * omega;
        let block = jt_omega * j;
        let gradient = jt_omega * e;
        let column = self.offset[v];
        for k in 0..C {
            let start = self.col_ptr[column + k] + self.diagonal[v];
            for r in 0..=k {
                self.hessian[start + r] += block[(r, k)];
            }
            self.rhs[column + k] += gradient[k];
        }
    }

    #[allow(clippy::too_many_arguments)]
    fn add_binary<const R: usize, const A: usize, const B: usize>(
        &mut self,
        a: usize,
        ja: &SMatrix<f64, R, A>,
        b: usize,
        jb: &SMatrix<f64, R, B>,
        omega: &SMatrix<f64, R, R>,
        e: &SVector<f64, R>,
        slot: usize,
    ) {
        self.add_diagonal(a, ja, omega, e);
        self.add_diagonal(b, jb, omega, e);
        // The block of rows lo, columns hi: J_loᵀ Ω J_hi.
        if a < b {
            let block = ja.transpose() * omega * jb;
            self.add_off_diagonal(b, slot, &block);
        } else {
            let block = jb.transpose() * omega * ja;
            self.add_off_diagonal(a, slot, &block);
        }
    }

    fn add_off_diagonal<const RL: usize, const CH: usize>(
        &mut self,
        hi: usize,
        slot: usize,
        block: &SMatrix<f64, RL, CH>,
    ) {
        let column = self.offset[hi];
        for k in 0..CH {
            let start = self.col_ptr[column + k] + slot;
            for r in 0..RL {
                self.hessian[start + r] += block[(r, k)];
            }
        }
    }

    /// Solves (H + λ·diag H) Δ = −b into `step`.
    fn solve(&mut self, lambda: f64) -> Result<(), GraphError> {
        self.damped.copy_from_slice(&self.hessian);
        for &end in &self.col_ptr[1..] {
            self.damped[end - 1] += lambda * self.hessian[end - 1];
        }
        for (s, b) in self.step.iter_mut().zip(&self.rhs) {
            *s = -b;
        }
        let n = self.rhs.len();
        let pattern =
            SymbolicSparseColMatRef::new_checked(n, n, &self.col_ptr, None, &self.row_idx);
        let llt = self
            .symbolic
            .factorize_numeric_llt(
                &mut self.factor_values,
                SparseColMatRef::new(pattern, &self.damped),
                Side::Upper,
                LltRegularization::default(),
                Par::Seq,
                MemStack::new(&mut self.scratch),
                Default::default(),
            )
            .map_err(|_| GraphError::NotPositiveDefinite)?;
        let rhs = MatMut::from_column_major_slice_mut(&mut self.step, n, 1);
        llt.solve_in_place_with_conj(Conj::No, rhs, Par::Seq, MemStack::new(&mut self.scratch));
        if self.step.iter().all(|s| s.is_finite()) {
            Ok(())
        } else {
            Err(GraphError::NotPositiveDefinite)
        }
    }

    /// x ← x ⊞ Δ: additive, headings re-wrapped.
    fn apply(&self, vertices: &mut [Vertex]) {
        for (v, at) in vertices.iter_mut().zip(&self.offset) {
            let d = &self.step[*at..];
            match &mut v.value {
                VertexValue::Se2(p) => {
                    p[0] += d[0];
                    p[1] += d[1];
                    p[2] = wrap_angle(p[2] + d[2]);
                }
                VertexValue::Xy(p) => {
                    p[0] += d[0];
                    p[1] += d[1];
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn numeric<const R: usize>(
        f: impl Fn(&[f64]) -> SVector<f64, R>,
        x: &[f64],
    ) -> Vec<SVector<f64, R>> {
        (0..x.len())
            .map(|k| {
                let h = 1e-6;
                let (mut p, mut m) = (x.to_vec(), x.to_vec());
                p[k] += h;
                m[k] -= h;
                (f(&p) - f(&m)) / (2.0 * h)
            })
            .collect()
    }

    /// The analytic Jacobians of both residuals agree with central differences, for small and
    /// large relative rotations.
    #[test]
    fn jacobians_match_finite_differences() {
        let z = Vector3::new(0.3, -0.2, 2.9);
        for (a, b) in [
            ([1.0, 2.0, -2.8], [-1.0, 0.5, 2.0]),
            ([0.1, 0.2, 0.3], [1.4, 0.1, 3.2]),
            ([0.1, 0.2, 0.3], [0.5, 0.3, 0.3 + 2.9 + 1e-5]),
        ] {
            let (a, b) = (Vector3::from(a), Vector3::from(b));
            let (_, ja, jb) = se2_between(&a, &b, &z);
            let x = [a[0], a[1], a[2], b[0], b[1], b[2]];
            let cols = numeric(
                |x| {
                    se2_between(
                        &Vector3::new(x[0], x[1], x[2]),
                        &Vector3::new(x[3], x[4], x[5]),
                        &z,
                    )
                    .0
                },
                &x,
            );
            for (k, col) in cols.iter().enumerate() {
                let analytic = if k < 3 {
                    ja.column(k)
                } else {
                    jb.column(k - 3)
                };
                assert!(
                    (col - analytic).norm() < 1e-6,
                    "column {k}: {col} vs {analytic}"
                );
            }
        }
        let zp = Vector2::new(1.0, -0.5);
        let (p, m) = (Vector3::new(0.5, -1.0, 2.5), Vector2::new(3.0, 1.0));
        let (_, jp, jm) = se2_point(&p, &m, &zp);
        let x = [p[0], p[1], p[2], m[0], m[1]];
        let cols = numeric(
            |x| {
                se2_point(
                    &Vector3::new(x[0], x[1], x[2]),
                    &Vector2::new(x[3], x[4]),
                    &zp,
                )
                .0
            },
            &x,
        );
        for (k, col) in cols.iter().enumerate() {
            let analytic = if k < 3 {
                jp.column(k).into_owned()
            } else {
                jm.column(k - 3).into_owned()
            };
            assert!(
                (col - analytic).norm() < 1e-6,
                "column {k}: {col} vs {analytic}"
            );
        }
    }

    /// The sparse solve (AMD-ordered, upper triangle) agrees with a dense solve of the same
    /// normal equations.
    #[test]
    fn the_sparse_step_is_the_dense_step() {
        let text = "VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1.1 0.1 0.2\nVERTEX_XY 7 2 1\n\
                    VERTEX_SE2 2 2.1 -0.1 1.6\n\
                    EDGE_SE2 0 1 1 0 0 10 1 0.5 20 0.3 30\nEDGE_SE2 1 2 1 0 1.57 10 0 0 10 0 10\n\
                    EDGE_SE2 2 0 0 2 -1.57 5 0 0 5 0 5\nEDGE_SE2_XY 0 7 2 1 4 1 3\n\
                    EDGE_SE2_XY 2 7 1 -1 4 0 4\n";
        let graph = G2oGraph::parse(text, "t").unwrap();
        let priors = Priors::new(&graph);
        let mut normal = Normal::analyse(&graph, &priors).unwrap();
        normal.assemble(&graph, &priors);
        normal.solve(0.0).unwrap();
        let n = normal.rhs.len();
        let mut dense = nalgebra::DMatrix::<f64>::zeros(n, n);
        for c in 0..n {
            for p in normal.col_ptr[c]..normal.col_ptr[c + 1] {
                let r = normal.row_idx[p];
                dense[(r, c)] = normal.hessian[p];
                dense[(c, r)] = normal.hessian[p];
            }
        }
        let b = nalgebra::DVector::from_column_slice(&normal.rhs);
        let step = dense.cholesky().unwrap().solve(&(-b));
        for (s, d) in normal.step.iter().zip(step.iter()) {
            assert!((s - d).abs() < 1e-9 * (1.0 + d.abs()), "{s} vs {d}");
        }
    }
}
