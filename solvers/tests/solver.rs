//! Correctness of the solver on problems with known answers.

use approx::assert_relative_eq;
use nalgebra::{DMatrix, DVector, SVector, Vector1, Vector2, Vector3, Vector6};
use rand::{Rng, SeedableRng};
use tumble_factors::{BetweenFactor, PriorFactor, SnavelyReprojection};
use tumble_solvers::sophus_lie::Isometry3F64;
use tumble_solvers::testing::LinearFactor;
use tumble_solvers::*;

fn lm() -> LmOptions {
    LmOptions { function_tolerance: 1e-12, parameter_tolerance: 1e-12, ..LmOptions::default() }
}

/// Random overdetermined linear problem: the solution equals the normal-equation closed form.
#[test]
fn linear_least_squares_equals_closed_form() {
    let mut rng = rand::rngs::StdRng::seed_from_u64(1);
    let (m, n) = (20, 4);
    let a = DMatrix::from_fn(m, n, |_, _| rng.random::<f64>() - 0.5);
    let b = DVector::from_fn(m, |_, _| rng.random::<f64>() - 0.5);
    let mut g = Graph::new();
    // Split the 4 unknowns into two 2-vectors, the rows into 4 factors.
    for f in 0..4 {
        let rows = a.rows(5 * f, 5);
        g.add(
            LinearFactor::new(
                vec![X(0), X(1)],
                vec![rows.columns(0, 2).into_owned(), rows.columns(2, 2).into_owned()],
                -b.rows(5 * f, 5).into_owned(),
            ),
            NoiseModel::Unit,
        );
    }
    let mut v = Values::new();
    v.insert(X(0), Vector2::new(3.0, -1.0));
    v.insert(X(1), Vector2::new(0.0, 10.0));
    let closed = (a.transpose() * &a).cholesky().unwrap().solve(&(a.transpose() * &b));
    for method in [Method::LevenbergMarquardt, Method::GaussNewton] {
        let (sol, s) = Optimizer::new(LmOptions { method, ..lm() }).optimize(&g, &v).unwrap();
        let x0: &Vector2<f64> = sol.get(X(0)).unwrap();
        let x1: &Vector2<f64> = sol.get(X(1)).unwrap();
        assert_relative_eq!(DVector::from_column_slice(&[x0[0], x0[1], x1[0], x1[1]]), closed, epsilon = 1e-9);
        assert_relative_eq!(2.0 * s.final_cost, (&a * &closed - &b).norm_squared(), epsilon = 1e-12);
    }
}

struct Rosenbrock(Vec<Key>);
impl AutoDiffResidual<2> for Rosenbrock {
    fn keys(&self) -> &[Key] {
        &self.0
    }
    fn residual_dim(&self) -> usize {
        2
    }
    fn residual<T: Real>(&self, p: &[&[T]]) -> Vec<T> {
        vec![T::from(1.0) - p[0][0], (p[0][1] - p[0][0] * p[0][0]) * 10.0]
    }
}

/// Beale's function: minimum 0 at (3, 0.5).
struct Beale(Vec<Key>);
impl AutoDiffResidual<2> for Beale {
    fn keys(&self) -> &[Key] {
        &self.0
    }
    fn residual_dim(&self) -> usize {
        3
    }
    fn residual<T: Real>(&self, p: &[&[T]]) -> Vec<T> {
        let (x, y) = (p[0][0], p[0][1]);
        let one = T::from(1.0);
        vec![-(x * (one - y)) + 1.5, -(x * (one - y * y)) + 2.25, -(x * (one - y * y * y)) + 2.625]
    }
}

#[test]
fn classic_nonlinear_problems_reach_known_optimum() {
    let solve = |f: Box<dyn Fn(&mut Graph)>, x0: Vector2<f64>| {
        let mut g = Graph::new();
        f(&mut g);
        let mut v = Values::new();
        v.insert(X(0), x0);
        let (sol, s) = Optimizer::new(lm()).optimize(&g, &v).unwrap();
        (*sol.get::<Vector2<f64>>(X(0)).unwrap(), s)
    };
    let (x, s) = solve(
        Box::new(|g| {
            g.add(AutoDiff::new(Rosenbrock(vec![X(0)])), NoiseModel::Unit);
        }),
        Vector2::new(-1.2, 1.0),
    );
    assert_relative_eq!(x, Vector2::new(1.0, 1.0), epsilon = 1e-8);
    assert!(s.final_cost < 1e-20);
    let (x, s) = solve(
        Box::new(|g| {
            g.add(AutoDiff::new(Beale(vec![X(0)])), NoiseModel::Unit);
        }),
        Vector2::new(1.0, 1.0),
    );
    assert_relative_eq!(x, Vector2::new(3.0, 0.5), epsilon = 1e-7);
    assert!(s.final_cost < 1e-18);
    // Numeric Jacobians (default Factor::linearize) reach the same optimum.
    struct NumericRosenbrock(Vec<Key>);
    impl Factor for NumericRosenbrock {
        fn keys(&self) -> &[Key] {
            &self.0
        }
        fn residual_dim(&self) -> usize {
            2
        }
        fn residual(&self, v: Vars<'_>) -> Result<DVector<f64>, FactorError> {
            let x: &Vector2<f64> = v.get(0)?;
            Ok(DVector::from_vec(vec![1.0 - x[0], 10.0 * (x[1] - x[0] * x[0])]))
        }
    }
    let (x, _) = solve(
        Box::new(|g| {
            g.add(NumericRosenbrock(vec![X(0)]), NoiseModel::Unit);
        }),
        Vector2::new(-1.2, 1.0),
    );
    assert_relative_eq!(x, Vector2::new(1.0, 1.0), epsilon = 1e-6);
}

fn pose(w: [f64; 3], t: [f64; 3]) -> Isometry3F64 {
    Isometry3F64::exp(Vector6::new(w[0], w[1], w[2], 0.0, 0.0, 0.0))
        .group_mul(Isometry3F64::from_translation(Vector3::from(t)))
}

/// A square SE(3) loop with exact measurements: optimum is the truth, cost 0.
#[test]
fn se3_pose_graph_loop_reaches_known_optimum() {
    let truth: Vec<Isometry3F64> = (0..8)
        .map(|i| {
            let a = i as f64 * std::f64::consts::FRAC_PI_4;
            Isometry3F64::from_translation(Vector3::new(3.0 * a.cos(), 3.0 * a.sin(), 0.2 * i as f64))
                .group_mul(Isometry3F64::exp(Vector6::new(0.1, -0.05, a, 0.0, 0.0, 0.0)))
        })
        .collect();
    let noise = NoiseModel::diagonal(&[0.01, 0.01, 0.01, 0.1, 0.1, 0.1]).unwrap();
    let mut g = Graph::new();
    g.add(PriorFactor::new(X(0), truth[0]), NoiseModel::isotropic(6, 1e-3).unwrap());
    for i in 0..8 {
        let j = (i + 1) % 8;
        g.add(BetweenFactor::new(X(i as u64), X(j as u64), truth[i].inverse().group_mul(truth[j])), noise.clone());
    }
    let mut v = Values::new();
    for (i, t) in truth.iter().enumerate() {
        v.insert(X(i as u64), t.group_mul(pose([0.2, -0.1, 0.3], [0.5, -0.4, 0.3])));
    }
    let (sol, s) = Optimizer::new(lm()).optimize(&g, &v).unwrap();
    assert!(s.final_cost < 1e-16, "{s}");
    for (i, t) in truth.iter().enumerate() {
        let x: &Isometry3F64 = sol.get(X(i as u64)).unwrap();
        assert!(t.inverse().group_mul(*x).log().norm() < 1e-7);
    }
}

/// Line fit y = a x + b with 20 % gross outliers.
fn line_fit(loss: Option<&str>, outliers: bool) -> Vector2<f64> {
    struct Point(Vec<Key>, f64, f64);
    impl AutoDiffResidual<2> for Point {
        fn keys(&self) -> &[Key] {
            &self.0
        }
        fn residual_dim(&self) -> usize {
            1
        }
        fn residual<T: Real>(&self, p: &[&[T]]) -> Vec<T> {
            vec![p[0][0] * self.1 + p[0][1] - self.2]
        }
    }
    let mut rng = rand::rngs::StdRng::seed_from_u64(5);
    let mut g = Graph::new();
    let sigma = 0.1;
    let noise = NoiseModel::isotropic(1, sigma).unwrap();
    for i in 0..100 {
        let x = i as f64 / 10.0;
        let mut y = 2.0 * x - 1.0 + sigma * (rng.random::<f64>() - 0.5) * 3.4;
        if outliers && i % 5 == 0 {
            y += 20.0 + 10.0 * rng.random::<f64>();
        }
        let f = AutoDiff::new(Point(vec![X(0)], x, y));
        match loss {
            Some("huber") => g.add_robust(f, noise.clone(), Huber(1.345)),
            Some("cauchy") => g.add_robust(f, noise.clone(), Cauchy(1.0)),
            Some("tukey") => g.add_robust(f, noise.clone(), Tukey(4.685)),
            _ => g.add(f, noise.clone()),
        };
    }
    let mut v = Values::new();
    v.insert(X(0), Vector2::new(0.0, 0.0));
    if loss == Some("tukey") {
        // Tukey is non-convex: start from the Huber solution, as one does in practice.
        v.insert(X(0), line_fit(Some("huber"), outliers));
    }
    let (sol, _) = Optimizer::new(lm()).optimize(&g, &v).unwrap();
    *sol.get::<Vector2<f64>>(X(0)).unwrap()
}

#[test]
fn robust_losses_resist_gross_outliers() {
    let clean = line_fit(None, false);
    let plain = line_fit(None, true);
    assert!((plain - clean).norm() > 1.0, "plain least squares should be pulled away: {plain:?} vs {clean:?}");
    // Huber keeps a bounded pull from each outlier (about δσ), the redescending
    // losses almost none.
    for (l, tol) in [("huber", 0.1), ("cauchy", 0.03), ("tukey", 0.03)] {
        let robust = line_fit(Some(l), true);
        assert!((robust - clean).norm() < tol, "{l}: {robust:?} vs {clean:?}");
        assert!((robust - clean).norm() < 0.1 * (plain - clean).norm());
    }
}

/// A small bundle-adjustment problem: `n_cams` Snavely cameras looking at
/// `n_points` points, every point seen by every camera, the cameras' x moved
/// by 1 cm and the points by (1, −1, 2) cm; camera 0 held constant.
fn bundle_adjustment(n_cams: usize, n_points: usize, seed: u64) -> (Graph, Values, Vec<SVector<f64, 9>>) {
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    let cams: Vec<SVector<f64, 9>> = (0..n_cams)
        .map(|i| {
            SVector::<f64, 9>::from_column_slice(&[
                0.01 * i as f64,
                -0.02,
                0.01,
                0.1 * i as f64,
                0.0,
                -5.0,
                500.0,
                0.0,
                0.0,
            ])
        })
        .collect();
    let pts: Vec<Vector3<f64>> = (0..n_points)
        .map(|_| Vector3::new(rng.random::<f64>() - 0.5, rng.random::<f64>() - 0.5, rng.random::<f64>() - 0.5))
        .collect();
    let mut g = Graph::new();
    let mut v = Values::new();
    for (ci, c) in cams.iter().enumerate() {
        for (pi, p) in pts.iter().enumerate() {
            let proj = SnavelyReprojection::new(C(ci as u64), L(pi as u64), [0.0, 0.0]);
            let f = AutoDiff::new(proj);
            let r = f.residual(Vars::new(&[c, p])).unwrap();
            let obs = [r[0] + 0.5 * (rng.random::<f64>() - 0.5), r[1] + 0.5 * (rng.random::<f64>() - 0.5)];
            g.add(AutoDiff::new(SnavelyReprojection::new(C(ci as u64), L(pi as u64), obs)), NoiseModel::Unit);
        }
        let mut perturbed = *c;
        perturbed[3] += 0.01;
        v.insert(C(ci as u64), perturbed);
    }
    for (pi, p) in pts.iter().enumerate() {
        v.insert(L(pi as u64), p + Vector3::new(0.01, -0.01, 0.02));
    }
    v.set_constant(C(0), true);
    (g, v, cams)
}

/// Small bundle adjustment: Schur elimination of the points gives the same
/// solution as the full sparse and dense solves.
#[test]
fn schur_complement_matches_full_solve() {
    let (g, v, cams) = bundle_adjustment(4, 30, 11);
    let run = |eliminate: Vec<char>, linear_solver| {
        Optimizer::new(LmOptions { eliminate, linear_solver, ..lm() }).optimize(&g, &v).unwrap()
    };
    let (a, sa) = run(vec!['l'], LinearSolver::SparseCholesky);
    let (b, sb) = run(vec![], LinearSolver::SparseCholesky);
    let (c, _) = run(vec!['l'], LinearSolver::DenseCholesky);
    assert_eq!(sa.eliminated_dim, 90);
    assert_eq!(sb.eliminated_dim, 0);
    assert_relative_eq!(sa.final_cost, sb.final_cost, epsilon = 1e-9, max_relative = 1e-9);
    for k in 1..4 {
        let ka: &SVector<f64, 9> = a.get(C(k)).unwrap();
        assert_relative_eq!(ka, b.get::<SVector<f64, 9>>(C(k)).unwrap(), epsilon = 1e-6);
        assert_relative_eq!(ka, c.get::<SVector<f64, 9>>(C(k)).unwrap(), epsilon = 1e-6);
    }
    // The constant camera did not move.
    assert_eq!(a.get::<SVector<f64, 9>>(C(0)).unwrap()[3], cams[0][3] + 0.01);
    // Camera covariances from the Schur-reduced system equal those of the full
    // system (a second constant camera fixes the scale).
    let mut a = a;
    a.set_constant(C(1), true);
    let keys = [C(2), C(3)];
    let full = tumble_solvers::covariances(&g, &a, &keys).unwrap();
    let reduced = tumble_solvers::covariances_eliminating(&g, &a, &keys, &['l']).unwrap();
    for x in keys {
        for y in keys {
            let (f, r) = (full.block(x, y).unwrap(), reduced.block(x, y).unwrap());
            assert_relative_eq!(f, r, epsilon = 1e-12 * f.amax().max(1.0), max_relative = 1e-7);
        }
    }
    assert!(tumble_solvers::covariances_eliminating(&g, &a, &[L(0)], &['l']).is_err());
    // The optimizer's own covariances (from its last linearization, at its
    // solution) equal a separate recovery at that solution, dense and sparse.
    let mut v2 = v.clone();
    v2.set_constant(C(1), true);
    for linear_solver in [LinearSolver::SparseCholesky, LinearSolver::DenseCholesky] {
        let opt = Optimizer::new(LmOptions { eliminate: vec!['l'], linear_solver, ..lm() });
        let (sol, _, cov) = opt.optimize_with_covariances(&g, &v2, &keys).unwrap();
        let (cov, separate) = (cov.unwrap(), tumble_solvers::covariances(&g, &sol, &keys).unwrap());
        for x in keys {
            for y in keys {
                let (f, r) = (separate.block(x, y).unwrap(), cov.block(x, y).unwrap());
                assert_relative_eq!(f, r, epsilon = 1e-12 * f.amax().max(1.0), max_relative = 1e-7);
            }
        }
        // An eliminated key has no kept covariance: an error, the solution stays.
        let (sol2, _, bad) = opt.optimize_with_covariances(&g, &v2, &[L(0)]).unwrap();
        assert!(bad.is_err());
        assert_eq!(sol2.get::<SVector<f64, 9>>(C(2)).unwrap(), sol.get::<SVector<f64, 9>>(C(2)).unwrap());
    }
}

/// The pose-graph picture: initial guess and solution seen from above.
/// Results are bit-identical whatever the number of threads: small graphs,
/// and graphs big enough (over 4096 factors) for the linearization and the
/// assembly of the normal equations — kept and Schur-eliminated parts — to be
/// spread over the threads.
#[test]
fn parallel_solves_are_deterministic() {
    fn solve_with(threads: usize, g: &Graph, v: &Values, eliminate: &[char]) -> (Values, tumble_solvers::Summary) {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        let opt = Optimizer::new(LmOptions { eliminate: eliminate.to_vec(), ..LmOptions::default() });
        pool.install(|| opt.optimize(g, v).unwrap())
    }
    for (per_lap, laps) in [(50, 2), (400, 8)] {
        let sim = tumble_factors::testing::simulate_helix(per_lap, laps, 5.0, 0.02, 0.1, 3);
        assert!(laps == 2 || sim.graph.len() > 4096, "{} factors", sim.graph.len());
        let (a, sa) = solve_with(1, &sim.graph, &sim.initial, &[]);
        let (b, sb) = solve_with(3, &sim.graph, &sim.initial, &[]);
        assert_eq!(sa.final_cost.to_bits(), sb.final_cost.to_bits());
        for i in 0..sim.poses as u64 {
            assert_eq!(
                a.get::<Isometry3F64>(X(i)).unwrap().params_dyn(),
                b.get::<Isometry3F64>(X(i)).unwrap().params_dyn()
            );
        }
    }
    let (g, v, _) = bundle_adjustment(8, 600, 5);
    let (a, sa) = solve_with(1, &g, &v, &['l']);
    let (b, sb) = solve_with(3, &g, &v, &['l']);
    assert!(sa.iterations > 1);
    assert_eq!(sa.final_cost.to_bits(), sb.final_cost.to_bits());
    for k in 0..8 {
        assert_eq!(a.get::<SVector<f64, 9>>(C(k)).unwrap(), b.get::<SVector<f64, 9>>(C(k)).unwrap());
    }
    for k in 0..600 {
        assert_eq!(a.get::<Vector3<f64>>(L(k)).unwrap(), b.get::<Vector3<f64>>(L(k)).unwrap());
    }
}

/// Reusing the last factorization (chord steps, the stationarity check by
/// preconditioned conjugate gradients) ends at the same minimum as
/// factorizing every solve, with fewer factorizations, on sparse pose graphs
/// of several noise levels.
#[test]
fn reusing_the_factorization_reaches_the_same_minimum() {
    let mut fewer = 0;
    for (seed, sigma_rot) in [(3, 0.02), (11, 0.05), (17, 0.1)] {
        let sim = tumble_factors::testing::simulate_helix(60, 5, 5.0, sigma_rot, 0.1, seed);
        let solve = |reuse_factorization| {
            let o =
                LmOptions { reuse_factorization, linear_solver: LinearSolver::SparseCholesky, ..LmOptions::default() };
            Optimizer::new(o).optimize(&sim.graph, &sim.initial).unwrap()
        };
        let ((a, sa), (b, sb)) = (solve(false), solve(true));
        assert!(sa.converged() && sb.converged(), "{sa}\n{sb}");
        assert_eq!(sa.factorizations, sa.linear_solves, "every solve factorizes without reuse");
        assert!(sb.factorizations <= sa.factorizations);
        fewer += usize::from(sb.factorizations < sa.factorizations);
        assert_relative_eq!(sa.final_cost, sb.final_cost, max_relative = 1e-9);
        for i in 0..sim.poses as u64 {
            let (pa, pb) =
                (a.get::<Isometry3F64>(X(i)).unwrap().params_dyn(), b.get::<Isometry3F64>(X(i)).unwrap().params_dyn());
            let d = pa.iter().zip(&pb).map(|(x, y)| (x - y).powi(2)).sum::<f64>().sqrt();
            // 10⁻⁴ of the edges' translation σ (0.1): what a cost 10⁻¹⁰ from the minimum allows.
            assert!(d < 1e-5, "pose {i}: {pa:?} vs {pb:?}");
        }
    }
    assert!(fewer > 0, "no solve reused a factorization");
}

/// A factor that hides its constant Jacobians from the optimizer.
struct Varying(LinearFactor);

impl Factor for Varying {
    fn keys(&self) -> &[Key] {
        self.0.keys()
    }
    fn residual_dim(&self) -> usize {
        self.0.residual_dim()
    }
    fn residual(&self, vars: Vars<'_>) -> Result<DVector<f64>, FactorError> {
        self.0.residual(vars)
    }
    fn linearize(&self, vars: Vars<'_>) -> Result<Linearization, FactorError> {
        self.0.linearize(vars)
    }
}

/// Factors with constant Jacobians have their JᵀJ formed once per solve: the
/// result is bit-identical to forming it every iteration.
#[test]
fn constant_jacobians_are_formed_once_with_the_same_result() {
    let build = |varying: bool| {
        let mut rng = rand::rngs::StdRng::seed_from_u64(4);
        let mut sim = tumble_factors::testing::simulate_helix(12, 1, 2.0, 0.02, 0.1, 9);
        // A dense linear factor over three more variables, solved in the same
        // nonlinear problem (so assembled several times).
        let a: Vec<DMatrix<f64>> = (0..3).map(|_| DMatrix::from_fn(24, 6, |_, _| rng.random::<f64>() - 0.5)).collect();
        let b = DVector::from_fn(24, |_, _| rng.random::<f64>() - 0.5);
        let f = LinearFactor::new(vec![P(0), P(1), P(2)], a, b);
        for k in 0..3 {
            sim.initial.insert(P(k), Vector6::zeros());
        }
        if varying {
            sim.graph.add(Varying(f), NoiseModel::Unit);
        } else {
            sim.graph.add(f, NoiseModel::Unit);
        }
        (sim.graph, sim.initial)
    };
    let (g1, v) = build(false);
    let (g2, _) = build(true);
    let (a, sa) = Optimizer::new(lm()).optimize(&g1, &v).unwrap();
    let (b, sb) = Optimizer::new(lm()).optimize(&g2, &v).unwrap();
    assert!(sa.iterations > 1);
    assert_eq!(sa.final_cost.to_bits(), sb.final_cost.to_bits());
    for i in 0..12 {
        assert_eq!(
            a.get::<Isometry3F64>(X(i)).unwrap().params_dyn(),
            b.get::<Isometry3F64>(X(i)).unwrap().params_dyn()
        );
    }
    for k in 0..3 {
        assert_eq!(a.get::<Vector6<f64>>(P(k)).unwrap(), b.get::<Vector6<f64>>(P(k)).unwrap());
    }
}

/// A factor with no residual rows (a marginalization prior of rank 0) adds nothing.
#[test]
fn empty_factor_is_harmless() {
    let mut g = Graph::new();
    g.add(PriorFactor::new(X(0), Vector1::new(2.0)), NoiseModel::Unit);
    g.add(
        LinearFactor::new(vec![X(0), X(1)], vec![DMatrix::zeros(0, 1), DMatrix::zeros(0, 1)], DVector::zeros(0)),
        NoiseModel::Unit,
    );
    g.add(PriorFactor::new(X(1), Vector1::new(-1.0)), NoiseModel::Unit);
    let mut v = Values::new();
    v.insert(X(0), Vector1::new(0.0));
    v.insert(X(1), Vector1::new(0.0));
    let (sol, _, cov) = Optimizer::new(lm()).optimize_with_covariances(&g, &v, &[X(0), X(1)]).unwrap();
    assert_relative_eq!(sol.get::<Vector1<f64>>(X(0)).unwrap()[0], 2.0, epsilon = 1e-9);
    assert_relative_eq!(sol.get::<Vector1<f64>>(X(1)).unwrap()[0], -1.0, epsilon = 1e-9);
    assert_relative_eq!(cov.unwrap().block(X(0), X(1)).unwrap()[(0, 0)], 0.0, epsilon = 1e-12);
}

#[test]
fn errors_not_panics() {
    let mut v = Values::new();
    v.insert(X(0), Vector1::new(1.0));
    assert_eq!(v.get::<Vector1<f64>>(X(1)).unwrap_err(), ValueError::Missing(X(1)));
    assert!(matches!(v.get::<Vector2<f64>>(X(0)), Err(ValueError::WrongType { .. })));
    // Factor on a missing key.
    let mut g = Graph::new();
    g.add(PriorFactor::new(X(5), Vector1::new(0.0)), NoiseModel::Unit);
    assert!(matches!(Optimizer::new(lm()).optimize(&g, &v), Err(SolveError::MissingVariable { factor: 0, .. })));
    // Factor whose variable has the wrong type.
    let mut g = Graph::new();
    g.add(PriorFactor::new(X(0), Vector2::new(0.0, 0.0)), NoiseModel::Unit);
    assert!(matches!(Optimizer::new(lm()).optimize(&g, &v), Err(SolveError::Factor { factor: 0, .. })));
    // Noise model of the wrong dimension.
    let mut g = Graph::new();
    g.add(PriorFactor::new(X(0), Vector1::new(0.0)), NoiseModel::isotropic(3, 1.0).unwrap());
    assert!(matches!(Optimizer::new(lm()).optimize(&g, &v), Err(SolveError::BadFactor { .. })));
    // Gauss–Newton on a singular system reports it.
    let mut g = Graph::new();
    g.add(
        LinearFactor::new(vec![X(0), X(1)], vec![DMatrix::identity(1, 1), -DMatrix::identity(1, 1)], DVector::zeros(1)),
        NoiseModel::Unit,
    );
    v.insert(X(1), Vector1::new(0.0));
    let r = Optimizer::new(LmOptions { method: Method::GaussNewton, ..lm() }).optimize(&g, &v);
    assert!(matches!(r, Err(SolveError::Singular(_))), "{:?}", r.err());
    // Two landmarks in one factor cannot be Schur-eliminated.
    let mut g = Graph::new();
    g.add(BetweenFactor::new(L(0), L(1), Vector1::new(1.0)), NoiseModel::Unit);
    let mut v = Values::new();
    v.insert(L(0), Vector1::new(0.0));
    v.insert(L(1), Vector1::new(0.0));
    assert!(matches!(
        Optimizer::new(LmOptions { eliminate: vec!['l'], ..lm() }).optimize(&g, &v),
        Err(SolveError::Config(_))
    ));
}

#[test]
fn constant_variables_stay_put() {
    let mut g = Graph::new();
    g.add(BetweenFactor::new(X(0), X(1), Vector2::new(1.0, 1.0)), NoiseModel::Unit);
    let mut v = Values::new();
    v.insert(X(0), Vector2::new(5.0, 5.0));
    v.insert(X(1), Vector2::new(0.0, 0.0));
    v.set_constant(X(0), true);
    let (sol, _) = Optimizer::new(lm()).optimize(&g, &v).unwrap();
    assert_eq!(*sol.get::<Vector2<f64>>(X(0)).unwrap(), Vector2::new(5.0, 5.0));
    assert_relative_eq!(*sol.get::<Vector2<f64>>(X(1)).unwrap(), Vector2::new(6.0, 6.0), epsilon = 1e-9);
}

/// A user-defined variable type: a direction on the unit sphere S² with a
/// 2-dof retraction, used by an autodiff factor and an analytic-free numeric one.
#[derive(Clone, Debug)]
struct Direction(Vector3<f64>);

impl Direction {
    /// Orthonormal basis of the tangent plane at the direction.
    fn basis(&self) -> (Vector3<f64>, Vector3<f64>) {
        let d = self.0;
        let a = if d.x.abs() < 0.9 { Vector3::x() } else { Vector3::y() };
        let b1 = d.cross(&a).normalize();
        (b1, d.cross(&b1))
    }
}

impl Variable for Direction {
    const DIM: usize = 2;
    fn retract(&self, delta: &[f64]) -> Self {
        let (b1, b2) = self.basis();
        Direction((self.0 + b1 * delta[0] + b2 * delta[1]).normalize())
    }
    fn local(&self, other: &Self) -> Vec<f64> {
        let (b1, b2) = self.basis();
        // Inverse of the retraction: project onto the tangent plane and rescale.
        let v = other.0 / self.0.dot(&other.0);
        vec![b1.dot(&v), b2.dot(&v)]
    }
    fn params(&self) -> Vec<f64> {
        self.0.as_slice().to_vec()
    }
}

/// Angle-free residual between a direction and a measured unit vector.
struct DirectionPrior(Vec<Key>, Vector3<f64>);
impl AutoDiffResidual<2> for DirectionPrior {
    fn keys(&self) -> &[Key] {
        &self.0
    }
    fn residual_dim(&self) -> usize {
        3
    }
    fn residual<T: Real>(&self, p: &[&[T]]) -> Vec<T> {
        (0..3).map(|i| p[0][i] - self.1[i]).collect()
    }
}

#[test]
fn user_defined_variable_type() {
    let x = Direction(Vector3::new(1.0, 2.0, 2.0).normalize());
    // Retraction and local coordinates are inverse of each other.
    let y = x.retract(&[0.1, -0.2]);
    let back = x.local(&y);
    assert_relative_eq!(back[0], 0.1, epsilon = 1e-12);
    assert_relative_eq!(back[1], -0.2, epsilon = 1e-12);
    // Autodiff through the default (numeric) params Jacobian matches central differences.
    let target = Vector3::new(0.0, 0.6, 0.8);
    let f = AutoDiff::new(DirectionPrior(vec![P(0)], target));
    assert!(check_jacobians(&f, &[&x]).unwrap().passes(1e-6));
    let mut g = Graph::new();
    g.add(f, NoiseModel::isotropic(3, 0.1).unwrap());
    let mut v = Values::new();
    v.insert(P(0), x);
    let (sol, s) = Optimizer::new(lm()).optimize(&g, &v).unwrap();
    assert_relative_eq!(sol.get::<Direction>(P(0)).unwrap().0, target, epsilon = 1e-6);
    assert!(s.final_cost < 1e-12);
}
