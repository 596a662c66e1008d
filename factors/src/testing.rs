//! Synthetic factor graphs with known truth, for tests, benchmarks and
//! examples of the solver and of the factors.

use crate::{BetweenFactor, PriorFactor};
use nalgebra::{Vector3, Vector6};
use rand::{Rng, SeedableRng};
use rand_distr::{Distribution, Normal};
use tumble_solvers::sophus_lie::Isometry3F64;
use tumble_solvers::{Graph, NoiseModel, Values, X};

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
