//! Pose graphs: synthetic ones with known truth (the solver's demo and test
//! data), plots, and the two-stage solve of a g2o file.

use nalgebra::{Vector3, Vector6};
use rand::{Rng, SeedableRng};
use rand_distr::{Distribution, Normal};
use tumble_factors::{BetweenFactor, PriorFactor};
use tumble_solvers::sophus_lie::Isometry3F64;

use tumble_solvers::{Graph, LmOptions, NoiseModel, Optimizer, SolveError, Summary, Values, X};

/// Solve a 3-D pose graph in two stages: first with Ceres' `pose_graph_3d`
/// edge error (`quaternion`, read with
/// [`crate::io::g2o::EdgeError::CeresQuaternion`]), then with the log error
/// (`log`, the same file read with [`crate::io::g2o::EdgeError::Log`]) from
/// the first stage's solution. Both graphs must come from the same file.
/// Returns the solution (a minimum of the log cost) and each stage's summary.
///
/// From the odometry start the two costs can lead to different minima: on
/// torus3D the log error alone stops at χ² 59 900.8, the two stages reach
/// χ² 45 167.1 (in the log cost), the minimum Ceres finds.
///
/// ```no_run
/// use tumble::io::g2o::{read_g2o, EdgeError, G2oOptions};
/// let path = std::path::Path::new("torus3D.g2o");
/// let quat = read_g2o(path, &G2oOptions { edge_error: EdgeError::CeresQuaternion, ..Default::default() }).unwrap();
/// let log = read_g2o(path, &G2oOptions::default()).unwrap();
/// let (solution, first, second) =
///     tumble::posegraph::solve_two_stage(&quat.graph, &log.graph, &quat.values, &Default::default()).unwrap();
/// println!("χ² {:.3} after {} + {} iterations", 2.0 * second.final_cost, first.iterations, second.iterations);
/// ```
pub fn solve_two_stage(
    quaternion: &Graph,
    log: &Graph,
    initial: &Values,
    options: &LmOptions,
) -> Result<(Values, Summary, Summary), SolveError> {
    let optimizer = Optimizer::new(options.clone());
    let (first_solution, first) = optimizer.optimize(quaternion, initial)?;
    let (solution, second) = optimizer.optimize(log, &first_solution)?;
    Ok((solution, first, second))
}

/// A simulated SE(3) pose graph with its ground truth.
pub struct SimulatedPoseGraph {
    /// Odometry and loop-closure factors, plus a prior on pose 0.
    pub graph: Graph,
    /// Initial guess: dead-reckoned noisy odometry.
    pub initial: Values,
    /// True poses.
    pub truth: Values,
    /// Number of poses.
    pub poses: usize,
}

/// Poses on `laps` loops of a helix of radius `radius` \[m\]; odometry between
/// consecutive poses and a loop closure to the pose one lap earlier, all with
/// noise `sigma_rot` \[rad\] and `sigma_trans` \[m\]. Deterministic for a seed.
pub fn simulate_helix(
    poses_per_lap: usize,
    laps: usize,
    radius: f64,
    sigma_rot: f64,
    sigma_trans: f64,
    seed: u64,
) -> SimulatedPoseGraph {
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    let n = poses_per_lap * laps;
    let truth_poses: Vec<Isometry3F64> = (0..n)
        .map(|i| {
            let a = 2.0 * std::f64::consts::PI * i as f64 / poses_per_lap as f64;
            let rot = Isometry3F64::exp(Vector6::new(0.0, 0.0, a + std::f64::consts::FRAC_PI_2, 0.0, 0.0, 0.0));
            let t = Vector3::new(radius * a.cos(), radius * a.sin(), 0.3 * i as f64 / poses_per_lap as f64);
            Isometry3F64::from_translation(t).group_mul(rot)
        })
        .collect();
    let nr = Normal::new(0.0, sigma_rot).expect("finite sigma");
    let nt = Normal::new(0.0, sigma_trans).expect("finite sigma");
    let noisy = |z: Isometry3F64, rng: &mut rand::rngs::StdRng| {
        let d = Vector6::new(
            nr.sample(rng),
            nr.sample(rng),
            nr.sample(rng),
            nt.sample(rng),
            nt.sample(rng),
            nt.sample(rng),
        );
        z.group_mul(Isometry3F64::exp(d))
    };
    let noise = NoiseModel::diagonal(&[sigma_rot, sigma_rot, sigma_rot, sigma_trans, sigma_trans, sigma_trans])
        .expect("positive sigmas");
    let mut graph = Graph::new();
    let mut truth = Values::new();
    let mut initial = Values::new();
    graph.add(PriorFactor::new(X(0), truth_poses[0]), NoiseModel::isotropic(6, 1e-3).expect("positive"));
    let mut dead = truth_poses[0];
    initial.insert(X(0), dead);
    for i in 0..n {
        truth.insert(X(i as u64), truth_poses[i]);
        if i + 1 < n {
            let z = noisy(truth_poses[i].inverse().group_mul(truth_poses[i + 1]), &mut rng);
            graph.add(BetweenFactor::new(X(i as u64), X(i as u64 + 1), z), noise.clone());
            dead = dead.group_mul(z);
            initial.insert(X(i as u64 + 1), dead);
        }
        if i >= poses_per_lap && rng.random::<f64>() < 0.5 {
            let j = i - poses_per_lap;
            let z = noisy(truth_poses[j].inverse().group_mul(truth_poses[i]), &mut rng);
            graph.add(BetweenFactor::new(X(j as u64), X(i as u64), z), noise.clone());
        }
    }
    SimulatedPoseGraph { graph, initial, truth, poses: n }
}

/// Positions seen from above, `(x, y)` \[m\], of every SE(2) or SE(3) pose in
/// `values`, in key order (other variable types are skipped).
pub fn top_view(values: &Values) -> Vec<(f64, f64)> {
    use tumble_solvers::sophus_lie::prelude::*;
    use tumble_solvers::sophus_lie::Isometry2F64;
    values
        .keys()
        .filter_map(|k| {
            if let Ok(p) = values.get::<Isometry3F64>(k) {
                let t = p.translation();
                Some((t[0], t[1]))
            } else {
                values.get::<Isometry2F64>(k).ok().map(|p| {
                    let t = p.translation();
                    (t[0], t[1])
                })
            }
        })
        .collect()
}

/// Write a PNG (1000×800) of a pose graph seen from above: the initial guess
/// and the solution, each as the path through the poses in key order.
///
/// ```no_run
/// use tumble::io::g2o::{read_g2o, G2oOptions};
/// use tumble::solvers::{LmOptions, Optimizer};
/// let pg = read_g2o("M3500.g2o".as_ref(), &G2oOptions::default()).unwrap();
/// let (solved, _) = Optimizer::new(LmOptions::default()).optimize(&pg.graph, &pg.values).unwrap();
/// tumble::posegraph::plot_top_view(&pg.values, &solved, "M3500", "m3500.png".as_ref()).unwrap();
/// ```
pub fn plot_top_view(initial: &Values, solved: &Values, title: &str, path: &std::path::Path) -> Result<(), String> {
    use crate::plot::{ScatterChart, Series};
    use plotters::style::RGBColor;
    let (a, b) = (top_view(initial), top_view(solved));
    if b.is_empty() {
        return Err(format!("{}: no SE(2) or SE(3) poses to draw", path.display()));
    }
    let chart = ScatterChart {
        title: title.to_string(),
        x_label: "x [m]".into(),
        y_label: "y [m]".into(),
        series: vec![
            Series { label: "initial guess".into(), color: RGBColor(200, 200, 200), points: a, line: true },
            Series { label: "solution".into(), color: RGBColor(31, 119, 180), points: b, line: true },
        ],
        equal_aspect: true,
        ..Default::default()
    };
    chart.write_png(path, 1000, 800)
}
