//! Marginalization and covariance recovery against dense references.

use approx::assert_relative_eq;
use nalgebra::{DMatrix, DVector, SVector, Vector1, Vector2, Vector3};
use rand::{Rng, SeedableRng};
use tumble_solvers::testing::LinearFactor;
use tumble_solvers::*;

fn lm() -> LmOptions {
    LmOptions { function_tolerance: 1e-12, parameter_tolerance: 1e-12, ..LmOptions::default() }
}

/// The dense normal equations `(JᵀJ, Jᵀr)` of `factors` of `g` at `v`, each
/// key's columns placed by `col` among `n`.
fn dense_normal_equations(
    g: &Graph,
    v: &Values,
    factors: &[usize],
    col: impl Fn(Key) -> usize,
    n: usize,
) -> (DMatrix<f64>, DVector<f64>) {
    let (mut h, mut grad) = (DMatrix::zeros(n, n), DVector::zeros(n));
    for &fi in factors {
        let e = &g.entries()[fi];
        let vars: Vec<&dyn DynVariable> = e.factor.keys().iter().map(|k| v.get_dyn(*k).unwrap()).collect();
        let lin = e.factor.linearize(Vars::new(&vars)).unwrap();
        let mut j = DMatrix::zeros(lin.residual.len(), n);
        for (k, jk) in e.factor.keys().iter().zip(&lin.jacobians) {
            j.view_mut((0, col(*k)), (jk.nrows(), jk.ncols())).copy_from(jk);
        }
        h += j.transpose() * &j;
        grad += j.transpose() * &lin.residual;
    }
    (h, grad)
}

/// A linear-Gaussian chain: marginalizing x0 then solving equals solving the
/// full problem, in solution and in information of the kept variables.
#[test]
fn marginalization_is_equivalent_to_full_problem() {
    // A linear chain and, in the second graph, three scalar "landmarks" that
    // only the marginalized variable and one kept variable see, marginalized
    // with it (as the VIO does with the oldest keyframe's landmarks).
    for landmarks in [false, true] {
        let build = || {
            let mut rng = rand::rngs::StdRng::seed_from_u64(9);
            let mut rand_mat = |r: usize, c: usize| DMatrix::from_fn(r, c, |_, _| rng.random::<f64>() - 0.5);
            let b = |v: f64| DVector::from_element(2, v);
            let i2 = DMatrix::identity(2, 2);
            let mut g = Graph::new();
            g.add(LinearFactor::new(vec![X(0)], vec![i2.clone()], b(0.3)), NoiseModel::isotropic(2, 0.5).unwrap());
            g.add(LinearFactor::new(vec![X(0), X(1)], vec![rand_mat(2, 2), i2.clone()], b(-0.2)), NoiseModel::Unit);
            g.add(
                LinearFactor::new(vec![X(0), X(2)], vec![rand_mat(2, 2), rand_mat(2, 2) + &i2], b(0.7)),
                NoiseModel::Unit,
            );
            if landmarks {
                for l in 0..3 {
                    let kept = X(1 + l % 2);
                    g.add(
                        LinearFactor::new(
                            vec![X(0), L(l), kept],
                            vec![rand_mat(2, 2), rand_mat(2, 1), rand_mat(2, 2)],
                            b(0.1),
                        ),
                        NoiseModel::Unit,
                    );
                    g.add(
                        LinearFactor::new(vec![L(l), kept], vec![rand_mat(2, 1), rand_mat(2, 2)], b(-0.3)),
                        NoiseModel::Unit,
                    );
                }
            }
            g.add(LinearFactor::new(vec![X(1), X(2)], vec![rand_mat(2, 2), i2.clone()], b(0.1)), NoiseModel::Unit);
            g.add(LinearFactor::new(vec![X(2)], vec![i2], b(-1.0)), NoiseModel::Unit);
            g
        };
        let g = build();
        let mut v = Values::new();
        for i in 0..3 {
            v.insert(X(i), Vector2::new(0.5 * i as f64, -0.25));
        }
        let mut gone = vec![X(0)];
        if landmarks {
            for l in 0..3 {
                v.insert(L(l), Vector1::new(0.1 * l as f64));
                gone.push(L(l));
            }
        }
        let (full, _) = Optimizer::new(lm()).optimize(&g, &v).unwrap();
        let full_cov = covariances(&g, &full, &[X(1), X(2)]).unwrap();

        let m = marginalize(&g, &v, &gone).unwrap();
        if !landmarks {
            assert_eq!(m.removed_factors, vec![0, 1, 2]);
        }
        let mut g2 = build();
        g2.remove(&m.removed_factors);
        g2.add(m.prior, NoiseModel::Unit);
        let mut v2 = v.clone();
        for k in &gone {
            v2.remove(*k);
        }
        let (marg, _) = Optimizer::new(lm()).optimize(&g2, &v2).unwrap();
        for k in [X(1), X(2)] {
            assert_relative_eq!(
                marg.get::<Vector2<f64>>(k).unwrap(),
                full.get::<Vector2<f64>>(k).unwrap(),
                epsilon = 1e-9
            );
        }
        let marg_cov = covariances(&g2, &marg, &[X(1), X(2)]).unwrap();
        for (a, b) in [(X(1), X(1)), (X(1), X(2)), (X(2), X(2))] {
            assert_relative_eq!(marg_cov.block(a, b).unwrap(), full_cov.block(a, b).unwrap(), epsilon = 1e-9);
        }
    }
}

/// Marginalization with what a sliding window meets: a variable no factor
/// constrains (a landmark left with its anchor observation only) and
/// information spanning fourteen orders of magnitude (a tight gyro-bias random
/// walk next to a barely seen landmark). The prior must equal the dense Schur
/// complement; before the Jacobi scaling such a matrix could give the
/// eigen-decomposition NaN and an empty prior without an error.
#[test]
fn marginalization_survives_unconstrained_and_badly_scaled_variables() {
    let mut rng = rand::rngs::StdRng::seed_from_u64(21);
    let mut rand_mat = |r: usize, c: usize| DMatrix::from_fn(r, c, |_, _| rng.random::<f64>() - 0.5);
    let i3 = DMatrix::identity(3, 3);
    let mut g = Graph::new();
    let mut add = |keys: Vec<Key>, a: Vec<DMatrix<f64>>, b: DVector<f64>| {
        g.add(LinearFactor::new(keys, a, b), NoiseModel::Unit);
    };
    add(vec![X(0)], vec![&i3 * 1e5], DVector::from_element(3, 0.2));
    add(vec![X(0), X(1)], vec![rand_mat(3, 3) * 1e5, &i3 * 1e5], DVector::from_element(3, -0.1));
    add(
        vec![X(0), L(1), X(2)],
        vec![rand_mat(2, 3), rand_mat(2, 1) * 0.03, rand_mat(2, 3)],
        DVector::from_element(2, 0.3),
    );
    add(vec![L(1), X(1)], vec![rand_mat(1, 1) * 1e-2, rand_mat(1, 3)], DVector::from_element(1, 0.05));
    add(vec![X(1), X(2)], vec![rand_mat(3, 3), i3.clone()], DVector::from_element(3, 0.4));
    let mut v = Values::new();
    for i in 0..3 {
        v.insert(X(i), Vector3::new(0.1 * i as f64, -0.2, 0.3));
    }
    v.insert(L(0), Vector1::new(0.5));
    v.insert(L(1), Vector1::new(0.7));
    let gone = [X(0), L(0), L(1)];
    let m = marginalize(&g, &v, &gone).unwrap();
    assert_eq!(m.removed_factors, vec![0, 1, 2, 3]);
    // Dense: stack the removed factors' Jacobians over [X0, L0, L1 | X1, X2].
    let cols = |k: Key| match k {
        k if k == X(0) => 0,
        k if k == L(0) => 3,
        k if k == L(1) => 4,
        k if k == X(1) => 5,
        _ => 8,
    };
    let (h, grad) = dense_normal_equations(&g, &v, &m.removed_factors, cols, 11);
    // L0 has no information: the Schur complement over [X0, L1] alone.
    let idx = [0, 1, 2, 4];
    let hmm = DMatrix::from_fn(4, 4, |r, c| h[(idx[r], idx[c])]);
    let hms = DMatrix::from_fn(4, 6, |r, c| h[(idx[r], 5 + c)]);
    let hss = h.view((5, 5), (6, 6)).into_owned();
    let inv = hmm.clone().try_inverse().unwrap();
    let hstar = &hss - hms.transpose() * &inv * &hms;
    let gm = DVector::from_fn(4, |r, _| grad[idx[r]]);
    let gstar = grad.rows(5, 6) - hms.transpose() * &inv * gm;
    let info = m.prior.information();
    assert!(info.iter().all(|x| x.is_finite()));
    // Nine rows of the removed factors less the four eliminated unknowns.
    assert_eq!(m.prior.sqrt_information.nrows(), 5, "the prior keeps the Schur complement's full rank");
    assert_relative_eq!(info, hstar, max_relative = 1e-6, epsilon = 1e-6);
    let rte = m.prior.sqrt_information.transpose() * &m.prior.offset;
    assert_relative_eq!(rte, gstar, max_relative = 1e-6, epsilon = 1e-6);
    // Information that overflows is an error, not an empty prior.
    let mut bad = Graph::new();
    bad.add(LinearFactor::new(vec![X(0), X(1)], vec![i3.clone(), &i3 * 1e200], DVector::zeros(3)), NoiseModel::Unit);
    let r = marginalize(&bad, &v, &[X(0)]);
    assert!(matches!(r, Err(SolveError::Singular(_))), "{:?}", r.map(|m| m.prior));
}

/// Marginal covariance equals the block of the dense inverse of JᵀJ, with
/// 3- and 6-dimensional variables (the assembly forms square blocks of
/// those sizes as fixed-size products) and a 4-dimensional one (dot products).
#[test]
fn covariance_equals_dense_inverse() {
    covariance_equals_dense_inverse_of::<3>();
    covariance_equals_dense_inverse_of::<4>();
    covariance_equals_dense_inverse_of::<6>();
}

fn covariance_equals_dense_inverse_of<const D: usize>() {
    let mut rng = rand::rngs::StdRng::seed_from_u64(3);
    let n = 4;
    let mut g = Graph::new();
    let mut j_rows: Vec<DMatrix<f64>> = Vec::new();
    for i in 0..n {
        for k in i..n.min(i + 2) {
            let a = DMatrix::from_fn(D, D, |_, _| rng.random::<f64>() - 0.5) + DMatrix::identity(D, D);
            let c = DMatrix::from_fn(D, D, |_, _| rng.random::<f64>() - 0.5);
            let mut row = DMatrix::zeros(D, D * n);
            if k == i {
                g.add(LinearFactor::new(vec![X(i as u64)], vec![a.clone()], DVector::zeros(D)), NoiseModel::Unit);
                row.view_mut((0, D * i), (D, D)).copy_from(&a);
            } else {
                g.add(
                    LinearFactor::new(vec![X(i as u64), X(k as u64)], vec![a.clone(), c.clone()], DVector::zeros(D)),
                    NoiseModel::Unit,
                );
                row.view_mut((0, D * i), (D, D)).copy_from(&a);
                row.view_mut((0, D * k), (D, D)).copy_from(&c);
            }
            j_rows.push(row);
        }
    }
    let mut j = DMatrix::zeros(D * j_rows.len(), D * n);
    for (r, row) in j_rows.iter().enumerate() {
        j.view_mut((D * r, 0), (D, D * n)).copy_from(row);
    }
    let dense = (j.transpose() * &j).try_inverse().unwrap();
    let mut v = Values::new();
    for i in 0..n {
        v.insert(X(i as u64), SVector::<f64, D>::zeros());
    }
    let keys: Vec<Key> = (0..n as u64).map(X).collect();
    let cov = covariances(&g, &v, &keys).unwrap();
    for a in 0..n {
        for b in 0..n {
            assert_relative_eq!(
                cov.block(X(a as u64), X(b as u64)).unwrap(),
                dense.view((D * a, D * b), (D, D)).into_owned(),
                epsilon = 1e-10
            );
        }
    }
    // A joint selection in another order is the dense inverse's rows and columns.
    let joint = cov.joint(&[X(2), X(0)]).unwrap();
    let idx: Vec<usize> = (2 * D..3 * D).chain(0..D).collect();
    assert_relative_eq!(joint, DMatrix::from_fn(2 * D, 2 * D, |r, c| dense[(idx[r], idx[c])]), epsilon = 1e-10);
    assert!(cov.joint(&[X(n as u64)]).is_none());
}

fn add_line_point(g: &mut Graph, x: f64, y: f64) {
    g.add(
        LinearFactor::new(vec![X(0)], vec![DMatrix::from_row_slice(1, 2, &[1.0, x])], DVector::from_element(1, -y)),
        NoiseModel::isotropic(1, 0.1).unwrap(),
    );
}

/// Cluster-robust covariances against the spread of estimates over many
/// replications: a line `y = a + b·x` fitted to 20 clusters of 10 points.
/// With independent errors both covariances match the spread; with a
/// random offset per cluster that the noise model does not know of, only
/// the cluster-robust one does.
#[test]
fn cluster_robust_covariance_matches_the_spread_of_estimates() {
    let mut rng = rand::rngs::StdRng::seed_from_u64(7);
    let (clusters, per) = (20, 10);
    let normal = |rng: &mut rand::rngs::StdRng| {
        // Box–Muller.
        let (u, v): (f64, f64) = (rng.random::<f64>().max(1e-300), rng.random());
        (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
    };
    for cluster_sigma in [0.0, 0.3] {
        let reps = 400;
        let (mut estimates, mut model, mut robust) = (Vec::new(), 0.0, 0.0);
        for _ in 0..reps {
            let mut g = Graph::new();
            let mut labels = Vec::new();
            for c in 0..clusters {
                let offset = cluster_sigma * normal(&mut rng);
                for _ in 0..per {
                    let x = c as f64 / clusters as f64 + 0.05 * rng.random::<f64>();
                    let y = 1.0 + 2.0 * x + offset + 0.1 * normal(&mut rng);
                    add_line_point(&mut g, x, y);
                    labels.push(Some(c));
                }
            }
            let mut v = Values::new();
            v.insert(X(0), Vector2::new(0.0, 0.0));
            let (sol, _, cov) =
                Optimizer::new(lm()).optimize_with_robust_covariances(&g, &v, &[X(0)], &labels).unwrap();
            let cov = cov.unwrap();
            assert_eq!(cov.clusters, clusters);
            estimates.push(sol.get::<Vector2<f64>>(X(0)).unwrap()[1]);
            model += cov.model.get(X(0)).unwrap()[(1, 1)] / reps as f64;
            robust += cov.robust.get(X(0)).unwrap()[(1, 1)] / reps as f64;
        }
        let mean = estimates.iter().sum::<f64>() / reps as f64;
        let spread = estimates.iter().map(|e| (e - mean).powi(2)).sum::<f64>() / (reps - 1) as f64;
        println!(
            "cluster σ {cluster_sigma}: variance of b model/spread {:.2}, robust/spread {:.2}",
            model / spread,
            robust / spread
        );
        // 400 replications: the spread's own relative error is ≈ 7 %.
        assert!((robust / spread - 1.0).abs() < 0.25, "robust {robust:.3e} vs spread {spread:.3e}");
        if cluster_sigma == 0.0 {
            assert!((model / spread - 1.0).abs() < 0.25, "model {model:.3e} vs spread {spread:.3e}");
        } else {
            assert!(model < 0.2 * spread, "model {model:.3e} vs spread {spread:.3e}");
        }
    }
}

/// The cluster-robust covariances are the same to the last bit every time
/// they are computed: the clusters' scores are summed in the clusters' order
/// (they were summed in a hash map's order, which changes with every map, and
/// the rig calibration's σ changed in their last bits from run to run).
#[test]
fn cluster_robust_covariances_are_identical_when_repeated() {
    let mut g = Graph::new();
    let mut labels = Vec::new();
    for c in 0..30 {
        for k in 0..4 {
            let x = (c * 4 + k) as f64 / 120.0;
            let y = 1.0 + 2.0 * x + 0.01 * ((c * 7 + k * 3) % 11) as f64;
            add_line_point(&mut g, x, y);
            labels.push(Some(c));
        }
    }
    let mut v = Values::new();
    v.insert(X(0), Vector2::new(1.0, 2.0));
    let robust = || cluster_robust_covariances(&g, &v, &[X(0)], &labels).unwrap().robust.get(X(0)).unwrap();
    let first = robust();
    for _ in 0..8 {
        let again = robust();
        assert!(first.iter().zip(again.iter()).all(|(a, b)| a.to_bits() == b.to_bits()), "{first} vs {again}");
    }
}

/// Fine clusters regrouped into coarse ones give the sandwich computed with
/// the coarse labels directly (unlabelled factors stay clusters of their
/// own), with the same count of clusters.
#[test]
fn regrouped_clusters_give_the_coarse_sandwich() {
    let mut g = Graph::new();
    let (mut fine, mut coarse) = (Vec::new(), Vec::new());
    for i in 0..60 {
        let x = i as f64 / 60.0;
        add_line_point(&mut g, x, 1.0 + 2.0 * x + 0.02 * ((i * 7) % 5) as f64 - 0.03 * ((i / 10) % 3) as f64);
        fine.push(Some(i));
        coarse.push(Some(i / 10));
    }
    add_line_point(&mut g, 0.5, 2.1);
    fine.push(None);
    coarse.push(None);
    let mut v = Values::new();
    v.insert(X(0), Vector2::new(1.0, 2.0));
    let (sol, _) = Optimizer::new(lm()).optimize(&g, &v).unwrap();
    let by_fine = cluster_robust_covariances(&g, &sol, &[X(0)], &fine).unwrap();
    let direct = cluster_robust_covariances(&g, &sol, &[X(0)], &coarse).unwrap();
    let (regrouped, clusters) = by_fine.regrouped(|c| c / 10);
    assert_eq!((by_fine.clusters, clusters, direct.clusters), (61, 7, 7));
    let (a, b) = (regrouped.get(X(0)).unwrap(), direct.robust.get(X(0)).unwrap());
    assert!((&a - &b).norm() <= 1e-12 * b.norm(), "{a} vs {b}");
    // Regrouping into the same clusters changes nothing.
    let (same, _) = by_fine.regrouped(|c| c);
    assert!((same.get(X(0)).unwrap() - by_fine.robust.get(X(0)).unwrap()).norm() <= 1e-12 * b.norm());
}

/// The landmarks leaving with their anchor are eliminated block by block
/// before the anchor itself: the prior equals the dense Schur complement of
/// all of them at once, also for a landmark that two rows see along only two
/// of its three directions (its block is singular: the pseudo-inverse's case).
#[test]
fn landmarks_eliminated_one_by_one_give_the_joint_schur_complement() {
    let mut rng = rand::rngs::StdRng::seed_from_u64(17);
    let mut rand_mat = |r: usize, c: usize| DMatrix::from_fn(r, c, |_, _| rng.random::<f64>() - 0.5);
    let mut g = Graph::new();
    let i3 = DMatrix::identity(3, 3);
    g.add(LinearFactor::new(vec![X(0)], vec![&i3 * 2.0], DVector::from_element(3, 0.1)), NoiseModel::Unit);
    g.add(LinearFactor::new(vec![X(0), X(1)], vec![rand_mat(3, 3), i3.clone()], DVector::zeros(3)), NoiseModel::Unit);
    for l in 0..5 {
        // Landmark 4 has a single observation: two rows, three unknowns.
        let seen_by: &[u64] = if l == 4 { &[1] } else { &[1, 2] };
        for &k in seen_by {
            let a = vec![rand_mat(2, 3), rand_mat(2, 3), rand_mat(2, 3)];
            g.add(
                LinearFactor::new(vec![X(0), L(l), X(k)], a, DVector::from_element(2, 0.05 * l as f64)),
                NoiseModel::Unit,
            );
        }
    }
    let mut v = Values::new();
    for i in 0..3 {
        v.insert(X(i), Vector3::new(0.1 * i as f64, 0.2, -0.1));
    }
    let mut gone = vec![X(0)];
    for l in 0..5 {
        v.insert(L(l), Vector3::new(0.3, -0.1 * l as f64, 0.5));
        gone.push(L(l));
    }
    let m = marginalize(&g, &v, &gone).unwrap();
    // Dense over [X0, L0..L4 | X1, X2].
    let col = |k: Key| match k {
        k if k == X(0) => 0,
        k if k == X(1) => 18,
        k if k == X(2) => 21,
        k => 3 + 3 * (0..5).position(|l| L(l) == k).unwrap(),
    };
    let every: Vec<usize> = (0..g.len()).collect();
    let (h, grad) = dense_normal_equations(&g, &v, &every, col, 24);
    let hmm = h.view((0, 0), (18, 18)).into_owned();
    let hms = h.view((0, 18), (18, 6)).into_owned();
    let inv = hmm.pseudo_inverse(1e-9).unwrap();
    let hstar = h.view((18, 18), (6, 6)) - hms.transpose() * &inv * &hms;
    let gstar = grad.rows(18, 6) - hms.transpose() * &inv * grad.rows(0, 18);
    assert_relative_eq!(m.prior.information(), hstar, max_relative = 1e-8, epsilon = 1e-10);
    let rte = m.prior.sqrt_information.transpose() * &m.prior.offset;
    assert_relative_eq!(rte, gstar, max_relative = 1e-8, epsilon = 1e-10);
}
