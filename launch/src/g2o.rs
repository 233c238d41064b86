//! `mole g2o IN.g2o [--out OUT.g2o] [--iterations N]`: a 2-D g2o graph optimised by GraphSLAM's
//! Levenberg–Marquardt (`mole_localization::graph_slam::g2o`, algorithms §6.9.4 "g2o graphs
//! and GTSAM").

use crate::Failure;
use clap::Args;
use mole_localization::graph_slam::g2o::{DEFAULT_ITERATIONS, G2oGraph, solver_config};
use std::path::PathBuf;
use std::time::Instant;

#[derive(Debug, Clone, Args)]
pub struct G2oArgs {
    /// A 2-D g2o file (VERTEX_SE2, VERTEX_XY, EDGE_SE2, EDGE_SE2_XY, FIX).
    pub file: PathBuf,
    /// Write the optimised graph here (same records and ids, vertices at the optimum).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Largest number of Levenberg–Marquardt iterations.
    #[arg(long, default_value_t = DEFAULT_ITERATIONS)]
    pub iterations: usize,
}

/// Reads, optimises, reports and writes; a bad file is a [`Failure::input`] (exit 2).
pub fn g2o(args: &G2oArgs) -> Result<(), Failure> {
    let mut graph = G2oGraph::read(&args.file).map_err(|e| Failure::input(e.to_string()))?;
    println!(
        "{}: {} poses, {} points, {} edges, gauge on {} pose(s)",
        args.file.display(),
        graph.pose_count(),
        graph.point_count(),
        graph.edges.len(),
        graph.anchors().len()
    );
    let start = Instant::now();
    let report = graph
        .optimize(&solver_config(), args.iterations)
        .map_err(|e| Failure::run(format!("{}: {e}", args.file.display())))?;
    println!(
        "error (½ Σ eᵀΩe): initial {:.9}, final {:.9}; {} iterations ({:?}) in {:.3} s",
        report.initial_error,
        report.final_error,
        report.iterations,
        report.termination,
        start.elapsed().as_secs_f64()
    );
    if let Some(out) = &args.out {
        graph
            .write(out)
            .map_err(|e| Failure::run(format!("cannot write {}: {e}", out.display())))?;
        println!("wrote {}", out.display());
    }
    Ok(())
}
