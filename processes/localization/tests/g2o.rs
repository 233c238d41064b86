//! g2o graphs (algorithms §6.9.4, "g2o graphs and GTSAM"): the reader and writer, its refusals,
//! and GraphSLAM's optimum on GTSAM's example graphs against GTSAM's own, computed by
//! `scripts/gtsam-reference.py` in this run (skipped without the gtsam package, a failure under
//! CI).

use mole_localization::graph_slam::Termination;
use mole_localization::graph_slam::g2o::{
    DEFAULT_ITERATIONS, G2oGraph, VertexValue, solver_config,
};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

/// Relative tolerance on the final error.
const ERROR_TOLERANCE: f64 = 1e-6;
/// Largest difference of any pose or point coordinate and heading from GTSAM's, in units of that
/// coordinate's marginal standard deviation at GTSAM's optimum: a weakly constrained graph
/// (w20000's edges have σ ≈ 1.8 m) has a nearly flat valley where two optimisers stop
/// centimetres apart at the same error, a difference that means nothing against a σ of metres.
const POSE_TOLERANCE_SIGMAS: f64 = 1e-4;

fn data(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/g2o")
        .join(name)
}

const DATASETS: &[&str] = &[
    "noisyToyGraph.g2o",
    "w100.g2o",
    "w20000-3500.g2o",
    "victoria_park-1000.g2o",
];

/// Every dataset parses, and its written form parses back to the same graph, before and after
/// optimisation.
#[test]
fn a_written_graph_reads_back_the_same() {
    for name in DATASETS {
        let mut graph = G2oGraph::read(&data(name)).expect("dataset parses");
        assert!(graph.pose_count() > 0);
        let again = G2oGraph::parse(&graph.to_g2o(), name).expect("written graph parses");
        assert_eq!(again, graph, "{name}");
        if *name == "w100.g2o" {
            graph
                .optimize(&solver_config(), DEFAULT_ITERATIONS)
                .expect("solves");
            let again = G2oGraph::parse(&graph.to_g2o(), name).expect("written graph parses");
            assert_eq!(again, graph, "{name} optimised");
        }
    }
    let with_fix = "VERTEX_SE2 3 0 0 0\nVERTEX_SE2 5 1 0 0.5\nVERTEX_XY 9 2 2\n\
                    EDGE_SE2 3 5 1 0 0.5 1 0 0 1 0 1\nEDGE_SE2_XY 5 9 1 1 2 0.5 2\nFIX 5\n";
    let graph = G2oGraph::parse(with_fix, "fix").expect("parses");
    assert_eq!(graph.fixed, vec![1]);
    assert_eq!(graph.anchors(), vec![1]);
    assert_eq!(
        G2oGraph::parse(&graph.to_g2o(), "fix").expect("parses"),
        graph
    );
}

/// Bad input is refused with the line, the field and what was expected, never a panic.
#[test]
fn bad_input_names_the_line_and_field() {
    let good = "VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0\nVERTEX_XY 2 1 1\n";
    let cases: &[(&str, &str)] = &[
        (
            "VERTEX2 0 0 0 0\n",
            "line 1: tag (field 0): expected VERTEX_SE2, VERTEX_XY, EDGE_SE2, EDGE_SE2_XY or FIX, found \"VERTEX2\"",
        ),
        (
            "VERTEX_SE2 0 0 0\n",
            "line 1: VERTEX_SE2 theta (field 4): expected 4 fields after the tag, found 3 (the line ends)",
        ),
        (
            "VERTEX_SE2 0 0 0 0 7\n",
            "line 1: VERTEX_SE2 (field 5): expected the end of the line after 4 fields, found \"7\"",
        ),
        (
            "VERTEX_SE2 -1 0 0 0\n",
            "line 1: VERTEX_SE2 id (field 1): expected a vertex id (an integer ≥ 0), found \"-1\"",
        ),
        (
            "VERTEX_SE2 0 0 nan 0\n",
            "line 1: VERTEX_SE2 y (field 3): expected a finite number, found \"nan\"",
        ),
        (
            "VERTEX_SE2 0 0 0 0\n\nVERTEX_XY 0 1 1\n",
            "line 3: VERTEX_XY id (field 1): expected an id no other vertex has, found 0, already the id of the vertex on line 1",
        ),
        (
            "EDGE_SE2 0 1 1 0 0 1 0 0 1 0 x\n",
            "line 4: EDGE_SE2 I33 (field 11): expected a finite number, found \"x\"",
        ),
        (
            "EDGE_SE2 0 1 1 0 0 1 0 0 0 0 1\n",
            "line 4: EDGE_SE2 I11 (field 6): expected an information matrix (I11 … I33) that is positive definite, found [1 0 0; 0 0 0; 0 0 1]",
        ),
        (
            "EDGE_SE2 0 7 1 0 0 1 0 0 1 0 1\n",
            "line 4: EDGE_SE2 j (field 2): expected the id of a VERTEX_SE2, found 7, which no vertex has",
        ),
        (
            "EDGE_SE2 0 2 1 0 0 1 0 0 1 0 1\n",
            "line 4: EDGE_SE2 j (field 2): expected the id of a VERTEX_SE2, found 2, a VERTEX_XY",
        ),
        (
            "EDGE_SE2 1 1 1 0 0 1 0 0 1 0 1\n",
            "line 4: EDGE_SE2 j (field 2): expected an id other than i's, found 1",
        ),
        (
            "EDGE_SE2_XY 2 0 1 1 1 0 1\n",
            "line 4: EDGE_SE2_XY i (field 1): expected the id of a VERTEX_SE2, found 2, a VERTEX_XY",
        ),
        (
            "EDGE_SE2_XY 0 2 1 1 1 2 1\n",
            "line 4: EDGE_SE2_XY I11 (field 5): expected an information matrix (I11 I12 I22) that is positive definite, found [1 2; 2 1]",
        ),
        (
            "FIX\n",
            "line 4: FIX id (field 1): expected at least one vertex id, found the end of the line",
        ),
        (
            "FIX 0 2\n",
            "line 4: FIX id (field 2): expected the id of a VERTEX_SE2, found 2, a VERTEX_XY",
        ),
    ];
    for (tail, message) in cases {
        let text = if tail.starts_with("VERTEX") {
            tail.to_string()
        } else {
            format!("{good}{tail}")
        };
        let error = G2oGraph::parse(&text, "bad.g2o").expect_err(tail);
        assert_eq!(error.to_string(), format!("bad.g2o {message}"), "{tail}");
    }
    // A vertex no edge reaches has no defined optimum: refused, named by its line.
    let error = G2oGraph::parse(
        "VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0\nVERTEX_XY 2 1 1\nEDGE_SE2_XY 0 2 1 1 1 0 1\n",
        "apart.g2o",
    )
    .expect_err("pose 1 apart");
    assert_eq!(
        error.to_string(),
        "apart.g2o line 2: VERTEX_SE2 id (field 1): expected a vertex that edges join to the \
         anchored pose (the FIXed ones, else the first VERTEX_SE2), so that the optimum is \
         defined, found 1, which no chain of edges reaches"
    );
    let error = G2oGraph::parse("VERTEX_XY 0 1 1\n", "points.g2o").expect_err("no pose");
    assert_eq!(
        error.to_string(),
        "points.g2o: VERTEX_SE2: expected at least one VERTEX_SE2 (2-D g2o), found 1 vertices, none a pose"
    );
    let error = G2oGraph::read(Path::new("/nonexistent/x.g2o")).expect_err("no file");
    assert!(
        error
            .to_string()
            .starts_with("/nonexistent/x.g2o: file: expected a readable")
    );
    // Comments and blank lines are skipped.
    assert!(G2oGraph::parse("# a comment\n\nVERTEX_SE2 0 0 0 0\n", "c").is_ok());
}

/// The python that scripts/python-env.sh sets up, if it has gtsam.
fn gtsam_python() -> Result<PathBuf, String> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let python = root.join("target/python-env/bin/python3");
    if !python.exists() {
        return Err(format!("no {}", python.display()));
    }
    let ok = Command::new(&python)
        .args(["-c", "import gtsam"])
        .output()
        .map(|o| o.status.success())
        .unwrap_or(false);
    if ok {
        Ok(python)
    } else {
        Err(format!("{} has no gtsam", python.display()))
    }
}

fn number(v: &serde_json::Value, key: &str) -> f64 {
    v[key].as_f64().unwrap_or_else(|| panic!("{key} in {v}"))
}

/// On every dataset, GraphSLAM's final error is GTSAM's to 1e-6 relative and every vertex is
/// GTSAM's to 1e-4 of its marginal standard deviation. Prints the table of algorithms §6.9.4.
#[test]
fn the_optimum_is_gtsams() {
    let python = match gtsam_python() {
        Ok(p) => p,
        Err(reason) => {
            mole_integration_tests::skip(
                "the_optimum_is_gtsams",
                &format!("{reason} (scripts/python-env.sh installs it)"),
            );
            return;
        }
    };
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scripts/gtsam-reference.py");
    println!(
        "| dataset | poses | landmarks | edges | initial error | mole final | GTSAM final | max vertex difference | in σ | mole s | GTSAM s |"
    );
    for name in DATASETS {
        let path = data(name);
        let mut graph = G2oGraph::read(&path).expect("dataset parses");
        let start = Instant::now();
        let report = graph
            .optimize(&solver_config(), DEFAULT_ITERATIONS)
            .expect("solves");
        let mole_seconds = start.elapsed().as_secs_f64();
        assert_eq!(
            report.termination,
            Termination::Converged,
            "{name}: {report:?}"
        );

        let output = Command::new(&python)
            .arg(&script)
            .arg(&path)
            .output()
            .expect("run gtsam-reference.py");
        assert!(
            output.status.success(),
            "gtsam-reference.py {name}: {}",
            String::from_utf8_lossy(&output.stderr)
        );
        let reference: serde_json::Value =
            serde_json::from_slice(&output.stdout).expect("gtsam-reference.py prints JSON");
        let gtsam_initial = number(&reference, "initial_error");
        let gtsam_final = number(&reference, "final_error");
        assert!(
            (report.initial_error - gtsam_initial).abs() <= 1e-9 * gtsam_initial.max(1.0),
            "{name}: initial error {} against GTSAM's {gtsam_initial}",
            report.initial_error
        );

        let mut largest: f64 = 0.0;
        let mut largest_sigmas: f64 = 0.0;
        for v in &graph.vertices {
            let id = v.id.to_string();
            let (ours, kind) = match v.value {
                VertexValue::Se2(p) => (p.iter().copied().collect::<Vec<f64>>(), "poses"),
                VertexValue::Xy(p) => (p.iter().copied().collect(), "points"),
            };
            let sigma_kind = if kind == "poses" {
                "sigmas"
            } else {
                "point_sigmas"
            };
            let numbers = |key: &str| -> Vec<f64> {
                reference[key][&id]
                    .as_array()
                    .unwrap_or_else(|| panic!("{name}: GTSAM has no {key} of vertex {id}"))
                    .iter()
                    .map(|x| x.as_f64().expect("a number"))
                    .collect()
            };
            let (theirs, sigmas) = (numbers(kind), numbers(sigma_kind));
            for (k, ((a, b), sigma)) in ours.iter().zip(&theirs).zip(&sigmas).enumerate() {
                let d = if k == 2 {
                    mole_types::wrap_angle(a - b).abs()
                } else {
                    (a - b).abs()
                };
                largest = largest.max(d);
                largest_sigmas = largest_sigmas.max(d / sigma);
            }
        }
        println!(
            "| {name} | {} | {} | {} | {:.6} | {:.9} | {:.9} | {:.1e} | {:.1e} | {:.3} | {:.3} |",
            graph.pose_count(),
            graph.point_count(),
            graph.edges.len(),
            report.initial_error,
            report.final_error,
            gtsam_final,
            largest,
            largest_sigmas,
            mole_seconds,
            number(&reference, "seconds"),
        );
        assert!(
            (report.final_error - gtsam_final).abs() <= ERROR_TOLERANCE * gtsam_final,
            "{name}: final error {} against GTSAM's {gtsam_final}",
            report.final_error
        );
        assert!(
            largest_sigmas <= POSE_TOLERANCE_SIGMAS,
            "{name}: a vertex differs from GTSAM's by {largest_sigmas:e} of its σ ({largest:e})"
        );
    }
}
