//! The fits' solve with an unmodelled-error floor (a variance-component
//! estimate of what the model does not explain) and the misalignments' prior.

#[cfg(doc)]
use super::observability::MISALIGNMENT_PRIOR_SIGMA;
use super::observability::{prior_sigma, OffDiagonal};
use nalgebra::{DMatrix, DVector};
use tumble_factors::PartialPriorFactor;
use tumble_solvers::{Factor, Graph, Key, LmOptions, NoiseModel, Optimizer, Termination, Values, Vars};

/// The Gaussian prior on the misalignments of a 9-vector model matrix (see
/// [`super::observability`]): zero, σ = [`MISALIGNMENT_PRIOR_SIGMA`] × the
/// row's scale at the start.
#[derive(Clone, Debug)]
pub(super) struct MisalignmentPrior {
    pub key: Key,
    /// The start with the misalignments at zero.
    pub at: nalgebra::SVector<f64, 9>,
    pub indices: Vec<usize>,
    pub sigmas: Vec<f64>,
}

impl MisalignmentPrior {
    pub(super) fn new(key: Key, start: &nalgebra::SVector<f64, 9>, offs: &[OffDiagonal]) -> MisalignmentPrior {
        let mut at = *start;
        for o in offs {
            at[o.index] = 0.0;
        }
        MisalignmentPrior {
            key,
            at,
            indices: offs.iter().map(|o| o.index).collect(),
            sigmas: offs.iter().map(|o| prior_sigma(start, o)).collect(),
        }
    }
}

/// A solve whose noise model may have been widened by an unmodelled-error floor.
pub(super) struct FloorFit {
    pub values: Values,
    pub graph: Graph,
    /// χ²/dof with the base noise.
    pub chi2_white: f64,
    /// χ²/dof with the floor (≈ 1 when a floor was added).
    pub chi2_final: f64,
    /// The floor, in residual units.
    pub floor: f64,
    pub iterations: usize,
    /// A solve stopped at the iteration cap ([`LmOptions::max_iterations`]).
    pub capped: bool,
}

/// Solve factors with per-factor noise covariances `base`; when the residuals
/// exceed that noise (χ²/dof > 1), add a common isotropic floor `s²` (C_k + s² I)
/// that makes χ²/dof = 1 — a variance-component estimate of what the model does
/// not explain, which evens out the weights of long and short intervals — and
/// re-solve (when `refine`; otherwise the floor is only estimated, enough to rank
/// detections).
pub(super) fn solve_with_floor<F: Factor + Clone + 'static>(
    factors: &[F],
    base: &[DMatrix<f64>],
    values: &Values,
    n_params: usize,
    prior: &MisalignmentPrior,
    max_iterations: usize,
    refine: bool,
) -> Result<FloorFit, String> {
    let dim = factors.first().map(|f| f.residual_dim()).unwrap_or(1);
    // The prior's residuals count as observations of the misalignments.
    let n_params = n_params.saturating_sub(prior.indices.len());
    let dof = (dim * factors.len()).saturating_sub(n_params).max(1) as f64;
    let lm = Optimizer::new(LmOptions { max_iterations, ..LmOptions::default() });
    let widen = |c: &DMatrix<f64>, s2: f64| c + DMatrix::identity(dim, dim) * s2;
    let build = |s2: f64| -> Result<Graph, String> {
        let mut g = Graph::new();
        for (f, c) in factors.iter().zip(base) {
            g.add(f.clone(), NoiseModel::from_covariance(&widen(c, s2)).map_err(|e| e.to_string())?);
        }
        add_prior(&mut g, prior)?;
        Ok(g)
    };
    let graph = build(0.0)?;
    let (mut sol, summary) = lm.optimize(&graph, values).map_err(|e| e.to_string())?;
    let chi2_white = 2.0 * summary.final_cost / dof;
    let mut iterations = summary.iterations;
    let mut capped = summary.termination == Termination::MaxIterations;
    let (mut graph, mut s2, mut chi2_final) = (graph, 0.0, chi2_white);
    for _ in 0..3 {
        if chi2_final <= 1.0 + 1e-3 {
            break;
        }
        let residual = |f: &F| -> Result<DVector<f64>, String> {
            let vars: Vec<&dyn tumble_solvers::DynVariable> =
                f.keys().iter().map(|k| sol.get_dyn(*k)).collect::<Result<_, _>>().map_err(|e| e.to_string())?;
            f.residual(Vars::new(&vars)).map_err(|e| e.to_string())
        };
        let rs: Vec<DVector<f64>> = factors.iter().map(residual).collect::<Result<_, _>>()?;
        let chi2 = |s2: f64| {
            rs.iter()
                .zip(base)
                .map(|(r, c)| widen(c, s2).cholesky().map(|ch| r.dot(&ch.solve(r))).unwrap_or(f64::MAX))
                .sum::<f64>()
                / dof
        };
        let (mut lo, mut hi) = (s2, rs.iter().map(|r| r.norm_squared()).fold(0.0, f64::max).max(1e-300));
        while chi2(hi) > 1.0 {
            hi *= 4.0;
        }
        for _ in 0..60 {
            let mid = 0.5 * (lo + hi);
            if chi2(mid) > 1.0 {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        s2 = hi;
        graph = build(s2)?;
        if !refine {
            // Ranking only: the floor from the first solution, not solved again.
            chi2_final = 1.0;
            break;
        }
        let (next, summary) = lm.optimize(&graph, &sol).map_err(|e| e.to_string())?;
        sol = next;
        iterations += summary.iterations;
        capped |= summary.termination == Termination::MaxIterations;
        chi2_final = 2.0 * summary.final_cost / dof;
    }
    Ok(FloorFit { values: sol, graph, chi2_white, chi2_final, floor: s2.sqrt(), iterations, capped })
}

/// Add the misalignment prior's [`PartialPriorFactor`] to a graph.
fn add_prior(g: &mut Graph, prior: &MisalignmentPrior) -> Result<(), String> {
    let noise = NoiseModel::diagonal(&prior.sigmas).map_err(|e| e.to_string())?;
    g.add(PartialPriorFactor::new(prior.key, prior.at, prior.indices.clone()), noise);
    Ok(())
}
