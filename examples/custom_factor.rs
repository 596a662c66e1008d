//! A user-defined factor with automatic differentiation, solved by tumble.
//!
//! Fits a circle (center cx, cy and radius r, one R³ variable) to noisy points
//! of which 15 % are gross outliers, with a Huber loss. The residual is written
//! once, generically over the scalar; `AutoDiff` gives exact Jacobians.
//!
//! ```sh
//! cargo run --example custom_factor
//! ```

use nalgebra::Vector3;
use tumble::solvers::prelude::*;

/// Signed distance of one point from the circle: ‖p − c‖ − r \[m\].
struct PointOnCircle {
    keys: [Key; 1],
    p: [f64; 2],
}

impl AutoDiffResidual<3> for PointOnCircle {
    fn keys(&self) -> &[Key] {
        &self.keys
    }
    fn residual_dim(&self) -> usize {
        1
    }
    fn residual<T: Real>(&self, params: &[&[T]]) -> Vec<T> {
        let (cx, cy, r) = (params[0][0], params[0][1], params[0][2]);
        let dx = -cx + self.p[0];
        let dy = -cy + self.p[1];
        vec![(dx * dx + dy * dy).sqrt() - r]
    }
}

fn main() {
    let truth = Vector3::new(1.0, -2.0, 3.0);
    let sigma = 0.02;
    let mut graph = Graph::new();
    let noise = NoiseModel::isotropic(1, sigma).expect("positive sigma");
    // Deterministic pseudo-noise so the example prints the same numbers every run.
    let mut state = 12345u64;
    let mut uniform = move || {
        state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    for i in 0..200 {
        let a = i as f64 * 0.0314;
        let mut rho = truth.z + sigma * 1.7 * (uniform() - 0.5);
        if i % 7 == 0 {
            rho += 1.0 + uniform(); // gross outlier
        }
        let p = [truth.x + rho * a.cos(), truth.y + rho * a.sin()];
        graph.add_robust(AutoDiff::new(PointOnCircle { keys: [X(0)], p }), noise.clone(), Huber(1.345));
    }
    let start = Vector3::new(0.0, 0.0, 1.0);
    // Verify the automatic Jacobian against central differences.
    let report = check_jacobians(graph.entries()[0].factor.as_ref(), &[&start]).expect("evaluates");
    println!("Jacobian check: worst relative error {:.2e}", report.max_relative_error);

    let mut values = Values::new();
    values.insert(X(0), start);
    let (solution, summary) = Optimizer::new(LmOptions::default()).optimize(&graph, &values).expect("solves");
    let fit: &Vector3<f64> = solution.get(X(0)).expect("solution holds X(0)");
    println!("{summary}");
    println!(
        "circle: center ({:.4}, {:.4}) radius {:.4}   truth ({}, {}) {}",
        fit.x, fit.y, fit.z, truth.x, truth.y, truth.z
    );
}
