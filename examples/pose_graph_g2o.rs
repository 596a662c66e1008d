//! Solve a g2o pose graph (SE(2) or SE(3)) and print the solver summary.
//!
//! ```sh
//! cargo run --example pose_graph_g2o -- sphere2500.g2o
//! cargo run --example pose_graph_g2o            # a simulated helix when no file is given
//! ```

use tumble::io::g2o::{read_g2o, G2oOptions};
use tumble::solvers::{LmOptions, Optimizer};

fn main() {
    let (graph, values) = match std::env::args().nth(1) {
        Some(path) => match read_g2o(path.as_ref(), &G2oOptions::default()) {
            Ok(pg) => {
                println!("{path}: {:?}, {} vertices, {} edges", pg.kind, pg.vertices, pg.edges);
                (pg.graph, pg.values)
            }
            Err(e) => {
                eprintln!("error: {e}");
                std::process::exit(1);
            }
        },
        None => {
            let sim = tumble::posegraph::simulate_helix(100, 3, 5.0, 0.01, 0.05, 1);
            println!("simulated helix: {} poses, {} factors", sim.poses, sim.graph.len());
            (sim.graph, sim.initial)
        }
    };
    match Optimizer::new(LmOptions::default()).optimize(&graph, &values) {
        Ok((_, summary)) => {
            println!("{summary}");
            println!("final chi2 = {:.6}", 2.0 * summary.final_cost);
        }
        Err(e) => {
            eprintln!("error: {e}");
            std::process::exit(1);
        }
    }
}
