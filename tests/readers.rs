//! g2o and BAL readers: every malformed input is an error naming file and line;
//! real benchmark files reach the costs the peers print.

use std::path::Path;
use tumble::io::bal::parse_bal;
use tumble::io::g2o::{parse_g2o, read_g2o, BadInformation, EdgeError, G2oOptions, PoseKind};
use tumble_solvers::{LmOptions, Optimizer};

const SE2_OK: &str = "VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0\nEDGE_SE2 0 1 1 0 0 1 0 0 1 0 1\n";

fn g2o_err(text: &str) -> String {
    match parse_g2o(Path::new("bad.g2o"), text, &G2oOptions::default()) {
        Ok(_) => panic!("accepted bad input:\n{text}"),
        Err(e) => e.to_string(),
    }
}

#[test]
fn g2o_errors_name_file_and_line() {
    assert!(parse_g2o(Path::new("ok.g2o"), SE2_OK, &G2oOptions::default()).is_ok());
    let cases = [
        ("VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0\n", "bad.g2o:2:", "missing theta"),
        ("VERTEX_SE2 0 0 0 0\nVERTEX_XY 1 1 0\n", "bad.g2o:2:", "unknown tag 'VERTEX_XY'"),
        ("VERTEX_SE2 0 0 NaN 0\n", "bad.g2o:1:", "not finite"),
        (
            "VERTEX_SE2 0 0 0 0\nEDGE_SE2 0 1 1 0 0 1 0 0 1 0 1\nEDGE_SE2 5 7 1 0 0 1 0 0 1 0 1\n",
            "bad.g2o:3:",
            "vertex 5 has no VERTEX line, and no chain of edges links it",
        ),
        (
            "VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0\nEDGE_SE2 0 1 1 0 0 1 0 0 -1 0 1\n",
            "bad.g2o:3:",
            "not positive definite",
        ),
        ("VERTEX_SE2 0 0 0 0\nVERTEX_SE2 0 1 0 0\n", "bad.g2o:2:", "defined twice"),
        ("VERTEX_SE2 0 0 0 0\nVERTEX_SE3:QUAT 1 0 0 0 0 0 0 1\n", "bad.g2o:2:", "mixes"),
        ("VERTEX_SE3:QUAT 1 0 0 0 0 0 0 2\n", "bad.g2o:1:", "quaternion norm"),
        ("VERTEX_SE2 0 0 0 0 5\n", "bad.g2o:1:", "extra field"),
        ("VERTEX_SE2 0 0 abc 0\n", "bad.g2o:1:", "'abc' is not a number"),
        ("# only a comment\n", "bad.g2o:", "no vertex or edge"),
        ("VERTEX_SE2 0 0 0 0\nFIX 3\n", "bad.g2o:2:", "FIX names vertex 3"),
    ];
    for (text, loc, what) in cases {
        let e = g2o_err(text);
        assert!(e.starts_with(loc) && e.contains(what), "for {text:?} got: {e}");
    }
}

/// Files of edges alone (Carlone's CSAIL, manhattan, KITTI graphs): the
/// poses are chained along the edges from the first vertex at the origin, an
/// edge read backwards inverted; the gauge is that vertex.
#[test]
fn g2o_edges_alone_chain_the_initial_poses() {
    use tumble::solvers::sophus_lie::{IsAffineGroup, Isometry2F64, Isometry3F64};
    use tumble::solvers::X;
    let text = "EDGE_SE2 0 1 1 0 1.5707963267948966 1 0 0 1 0 1\nEDGE_SE2 2 1 1 0 0 1 0 0 1 0 1\n";
    let pg = parse_g2o(Path::new("edges.g2o"), text, &G2oOptions::default()).unwrap();
    assert_eq!((pg.vertices, pg.edges), (3, 2));
    assert!(pg.warnings.iter().any(|w| w.contains("2 vertices without a VERTEX line")), "{:?}", pg.warnings);
    // Vertex 1 at (1, 0) facing +y; vertex 2 one metre behind it along its heading: (1, −1).
    let p2 = pg.values.get::<Isometry2F64>(X(2)).unwrap().translation();
    assert!((p2[0] - 1.0).abs() < 1e-12 && (p2[1] + 1.0).abs() < 1e-12, "{p2:?}");
    assert!(pg.values.is_constant(X(0)));
    let info: String = (0..6).flat_map(|r| (r..6).map(move |c| if r == c { "1 " } else { "0 " })).collect();
    let text = format!("VERTEX_SE3:QUAT 4 0 0 2 0 0 0 1\nEDGE_SE3:QUAT 4 9 0 3 0 0 0 0 1 {info}\n");
    let pg = parse_g2o(Path::new("edges3.g2o"), &text, &G2oOptions::default()).unwrap();
    let p9 = pg.values.get::<Isometry3F64>(X(9)).unwrap().translation();
    assert!((p9 - nalgebra::Vector3::new(0.0, 3.0, 2.0)).norm() < 1e-12, "{p9:?}");
}

#[test]
fn g2o_repair_is_explicit() {
    let text = "VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0\nEDGE_SE2 0 1 1 0 0 1 0 0 -1 0 1\n";
    let pg = parse_g2o(
        Path::new("x.g2o"),
        text,
        &G2oOptions { bad_information: BadInformation::Repair, ..Default::default() },
    )
    .unwrap();
    assert_eq!(pg.warnings.len(), 1);
    assert!(pg.warnings[0].contains("x.g2o:3"));
}

/// Ceres' edge error takes g2o's information matrix in the file's order
/// (position, then rotation): a pure position error of 0.1 m weighed 100 and
/// a pure rotation error weighed 400 cost what they should under both errors.
#[test]
fn ceres_edge_error_weighs_position_and_rotation_as_the_file_says() {
    let info = "100 0 0 0 0 0 100 0 0 0 0 100 0 0 0 400 0 0 400 0 400";
    let edge = format!("EDGE_SE3:QUAT 0 1 1 0 0 0 0 0 1 {info}\n");
    // Vertex 1 off the measurement by 0.1 m along z, or by 0.02 rad about x.
    let (s, c) = (0.01f64.sin(), 0.01f64.cos());
    for (v1, expect) in [
        ("VERTEX_SE3:QUAT 1 1 0 0.1 0 0 0 1", 0.5 * 100.0 * 0.01),
        (&*format!("VERTEX_SE3:QUAT 1 1 0 0 {s} 0 0 {c}"), 0.5 * 400.0 * 0.02 * 0.02),
    ] {
        let text = format!("VERTEX_SE3:QUAT 0 0 0 0 0 0 0 1\n{v1}\n{edge}");
        for edge_error in [EdgeError::Log, EdgeError::CeresQuaternion] {
            let pg = parse_g2o(Path::new("e.g2o"), &text, &G2oOptions { edge_error, ..Default::default() }).unwrap();
            let cost = pg.graph.cost(&pg.values).unwrap();
            assert!((cost - expect).abs() < 1e-3 * expect, "{edge_error:?} {v1}: {cost} vs {expect}");
        }
    }
    let planar = G2oOptions { edge_error: EdgeError::CeresQuaternion, ..Default::default() };
    let e = parse_g2o(Path::new("p.g2o"), SE2_OK, &planar).err().expect("refused").to_string();
    assert!(e.starts_with("p.g2o") && e.contains("planar"), "{e}");
}

#[test]
fn bal_errors_name_file_and_line() {
    let ok = "1 1 1\n0 0 1.0 2.0\n0\n0\n0\n0\n0\n-5\n500\n0\n0\n0.1 0.2 0.3\n";
    let p = parse_bal(Path::new("ok.txt"), ok).unwrap();
    assert_eq!((p.cameras, p.points, p.observations), (1, 1, 1));
    let cases = [
        ("1 1 1\n0 0 1.0 2.0\n0\n0\n0\n", "b.txt:5:", "file ends early"),
        ("1 1 1\n3 0 1.0 2.0\n", "b.txt:2:", "camera index 3 out of range"),
        ("1 1 1\n0 4 1.0 2.0\n", "b.txt:2:", "point index 4 out of range"),
        ("1 1 1\n0 0 nan 2.0\n", "b.txt:2:", "not finite"),
        ("0 1 1\n", "b.txt:1:", "nothing to solve"),
        ("x 1 1\n", "b.txt:1:", "not a non-negative integer"),
        // The point at the camera's centre (−Rᵀt = (0, 0, 5)): no projection.
        (
            "1 1 2\n0 0 1.0 2.0\n0 0 3.0 4.0\n0\n0\n0\n0\n0\n-5\n500\n0\n0\n0 0 5\n",
            "b.txt:2:",
            "observation 0: point 0 cannot be projected by camera 0",
        ),
    ];
    for (text, loc, what) in cases {
        let e = parse_bal(Path::new("b.txt"), text).err().map(|e| e.to_string()).unwrap_or_default();
        assert!(e.starts_with(loc) && e.contains(what), "for {text:?} got: {e}");
    }
    let extra = format!("{ok}7\n");
    let e = parse_bal(Path::new("b.txt"), &extra).err().unwrap().to_string();
    assert!(e.starts_with("b.txt:13:") && e.contains("extra data"), "{e}");
}

mod common;
use common::shared;

/// Real benchmark graphs reach the final cost GTSAM/Ceres/factrs print (0.5·χ²).
#[test]
fn real_pose_graphs_reach_peer_costs() {
    for (name, kind, peer_cost, tol) in [
        ("M3500.g2o", PoseKind::Se2, 68.958, 1e-4),
        ("intel.g2o", PoseKind::Se2, 22.502, 1e-4),
        ("sphere2500.g2o", PoseKind::Se3, 675.701, 1e-5),
    ] {
        let Some(path) = shared(&format!("pose_graphs/{name}")) else {
            return;
        };
        let pg = read_g2o(&path, &G2oOptions::default()).unwrap();
        assert_eq!(pg.kind, kind);
        let opts = LmOptions { function_tolerance: 1e-8, ..LmOptions::default() };
        let (_, s) = Optimizer::new(opts).optimize(&pg.graph, &pg.values).unwrap();
        assert!(((s.final_cost - peer_cost) / peer_cost).abs() < tol, "{name}: {} vs {peer_cost}", s.final_cost);
    }
}

/// torus3D from the file's start: the log error alone stops in a folded
/// minimum (0.5·χ² ≈ 29 950, where GTSAM and the Rust peers stop too); Ceres'
/// quaternion error first, then the log error, reach the minimum Ceres finds
/// (its solution has 0.5·χ² = 22 583.7 in the log cost) or lower.
#[test]
#[ignore = "long trial: CI runs it (cargo test -- --ignored)"]
fn torus_two_stage_reaches_the_ceres_minimum() {
    let Some(path) = shared("pose_graphs/torus3D.g2o") else {
        return;
    };
    let quat = read_g2o(&path, &G2oOptions { edge_error: EdgeError::CeresQuaternion, ..Default::default() }).unwrap();
    let log = read_g2o(&path, &G2oOptions::default()).unwrap();
    let opts = LmOptions { log_iterations: false, ..LmOptions::default() };
    let (_, first, second) = tumble::posegraph::solve_two_stage(&quat.graph, &log.graph, &quat.values, &opts).unwrap();
    assert!(first.final_cost < 22_600.0, "Ceres' cost {}", first.final_cost);
    assert!(second.final_cost <= 22_583.7, "log cost {}", second.final_cost);
}

/// cubicle.g2o carries non-positive-definite information matrices: refused by
/// default, repaired only on request and then every one is reported.
#[test]
fn cubicle_is_refused_not_reinterpreted() {
    let Some(path) = shared("pose_graphs/cubicle.g2o") else {
        return;
    };
    let e = read_g2o(&path, &G2oOptions::default()).err().expect("must be refused").to_string();
    assert!(e.contains("cubicle.g2o:") && e.contains("not positive definite"), "{e}");
    let pg = read_g2o(&path, &G2oOptions { bad_information: BadInformation::Repair, ..Default::default() }).unwrap();
    assert!(pg.warnings.len() > 1000, "{} warnings", pg.warnings.len());
}

/// BAL with Schur elimination reaches the cost Ceres prints.
#[test]
fn real_bal_reaches_ceres_cost() {
    let Some(path) = shared("bal/synthetic-bal-49-7776.txt") else {
        return;
    };
    let p = tumble::io::bal::read_bal(&path).unwrap();
    let opts = LmOptions { eliminate: vec!['l'], function_tolerance: 1e-8, ..LmOptions::default() };
    let (_, s) = Optimizer::new(opts).optimize(&p.graph, &p.values).unwrap();
    assert!(((s.final_cost - 19236.73) / 19236.73).abs() < 1e-5, "{}", s.final_cost);
}
