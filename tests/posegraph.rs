//! Pose-graph helpers of the top crate: the top view and its figure.

use tumble_solvers::{LmOptions, Optimizer, Values};

fn lm() -> LmOptions {
    LmOptions { function_tolerance: 1e-12, parameter_tolerance: 1e-12, ..LmOptions::default() }
}

#[test]
fn pose_graph_top_view_png() {
    let sim = tumble::posegraph::simulate_helix(20, 2, 3.0, 0.01, 0.05, 2);
    let (solved, _) = Optimizer::new(lm()).optimize(&sim.graph, &sim.initial).unwrap();
    let top = tumble::posegraph::top_view(&solved);
    assert_eq!(top.len(), 40);
    let truth = tumble::posegraph::top_view(&sim.truth);
    assert!(top.iter().zip(&truth).all(|(a, b)| (a.0 - b.0).hypot(a.1 - b.1) < 0.5));
    let png = std::env::temp_dir().join("tumble_test_top_view.png");
    tumble::posegraph::plot_top_view(&sim.initial, &solved, "helix", &png).unwrap();
    assert!(std::fs::metadata(&png).unwrap().len() > 1000);
    assert!(tumble::posegraph::plot_top_view(&Values::new(), &Values::new(), "none", &png).is_err());
}
