//! Levenberg–Marquardt (trust region with Nielsen's damping update, as in
//! Ceres) and Gauss–Newton over a [`Graph`], returning a [`Summary`].
//!
//! The parts, as Ceres keeps them apart: [`LmOptions`] (the settings), the
//! strategy (`strategy`: the damping λ, the scale D, the step bound), the
//! minimizer's loop (`minimizer`), the stopping rules (`termination`) and
//! the [`Summary`]. The factors are evaluated by the crate's linearization.

use crate::error::SolveError;
use crate::graph::Graph;
use crate::key::Key;
use crate::layout::{Layout, Role};
use crate::linear::{Structure, System, PARALLEL_MIN_FACTORS};
use crate::linearized::{linearize_all, Linearized};
use crate::marginal::{covariances_of_system, robust_covariances_of_system, Covariances, RobustCovariances};
use crate::values::Values;
use crate::variable::DynVariable;
use std::time::Instant;

mod awake;
mod linear_step;
mod minimizer;
mod options;
mod strategy;
mod summary;
mod termination;

use minimizer::Minimizer;
pub use options::{LmOptions, Method};
pub use summary::{IterationLog, Summary, Termination};

/// Covariances requested from [`Optimizer::optimize_with_covariances`], or why they failed.
type CovarianceResult = Result<Covariances, SolveError>;

/// What is computed at the solution from the optimizer's last linearization
/// (covariances of some kind), by [`Optimizer::optimize_impl`].
type AtSolution<'a, R> = &'a (dyn Fn(&Layout, &mut Structure, &System, &Linearized) -> Result<R, SolveError> + Sync);

/// The solution, its summary and, when asked for, what was computed at it.
type Solved<R> = (Values, Summary, Option<Result<R, SolveError>>);

/// Nonlinear least-squares optimizer over a [`Graph`].
///
/// ```
/// use tumble_solvers::{Graph, Values, NoiseModel, Optimizer, LmOptions, AutoDiff, AutoDiffResidual, Real, Key, X};
/// use nalgebra::Vector2;
/// struct Rosenbrock(Vec<Key>);
/// impl AutoDiffResidual<2> for Rosenbrock {
///     fn keys(&self) -> &[Key] { &self.0 }
///     fn residual_dim(&self) -> usize { 2 }
///     fn residual<T: Real>(&self, p: &[&[T]]) -> Vec<T> {
///         vec![T::from(1.0) - p[0][0], (p[0][1] - p[0][0] * p[0][0]) * 10.0]
///     }
/// }
/// let mut graph = Graph::new();
/// graph.add(AutoDiff::new(Rosenbrock(vec![X(0)])), NoiseModel::Unit);
/// let mut values = Values::new();
/// values.insert(X(0), Vector2::new(-1.2, 1.0));
/// let (sol, summary) = Optimizer::new(LmOptions::default()).optimize(&graph, &values).unwrap();
/// let x: &Vector2<f64> = sol.get(X(0)).unwrap();
/// assert!((x - Vector2::new(1.0, 1.0)).norm() < 1e-6);
/// println!("{summary}");
/// ```
pub struct Optimizer {
    /// Options in force.
    pub options: LmOptions,
}

impl Optimizer {
    /// Optimizer with these options.
    pub fn new(options: LmOptions) -> Self {
        Optimizer { options }
    }

    /// Minimize the graph's cost starting from `initial`; returns the solution
    /// (all of `initial`'s values, the free ones updated) and a [`Summary`].
    pub fn optimize(&self, graph: &Graph, initial: &Values) -> Result<(Values, Summary), SolveError> {
        self.optimize_impl::<()>(graph, initial, None).map(|(v, s, _)| (v, s))
    }

    /// As [`Optimizer::optimize`], and the marginal covariance blocks of `keys`
    /// at the solution — the same blocks as [`crate::covariances_eliminating`]
    /// with [`LmOptions::eliminate`], from the optimizer's own last
    /// linearization (taken at the solution) instead of a second one. The
    /// covariances' own error (e.g. a key held constant or eliminated, or a
    /// singular information matrix) does not discard the solution.
    ///
    /// ```
    /// use tumble_solvers::{Graph, Values, NoiseModel, Optimizer, LmOptions, X};
    /// use tumble_solvers::testing::LinearFactor;
    /// use nalgebra::{DMatrix, DVector, Vector1};
    /// let mut g = Graph::new();
    /// let i = DMatrix::identity(1, 1);
    /// g.add(LinearFactor::new(vec![X(0)], vec![i.clone()], DVector::from_element(1, -1.0)), NoiseModel::isotropic(1, 0.5).unwrap());
    /// let mut v = Values::new();
    /// v.insert(X(0), Vector1::new(0.0));
    /// let (sol, _, cov) = Optimizer::new(LmOptions::default()).optimize_with_covariances(&g, &v, &[X(0)]).unwrap();
    /// assert!((sol.get::<Vector1<f64>>(X(0)).unwrap()[0] - 1.0).abs() < 1e-9);
    /// assert!((cov.unwrap().get(X(0)).unwrap()[(0, 0)] - 0.25).abs() < 1e-12);
    /// ```
    pub fn optimize_with_covariances(
        &self,
        graph: &Graph,
        initial: &Values,
        keys: &[Key],
    ) -> Result<(Values, Summary, CovarianceResult), SolveError> {
        let at = |l: &Layout, st: &mut Structure, sys: &System, _: &Linearized| covariances_of_system(l, st, sys, keys);
        self.optimize_impl(graph, initial, Some(&at))
            .map(|(v, s, c)| (v, s, c.unwrap_or_else(|| Err(SolveError::Config("no covariance requested".into())))))
    }

    /// [`Optimizer::optimize`], then the covariances of `keys` at the
    /// solution both from the noise models and cluster-robust
    /// ([`crate::cluster_robust_covariances`]; `clusters[fi]` is factor
    /// `fi`'s cluster), from the last linearization. Not with
    /// [`LmOptions::eliminate`].
    pub fn optimize_with_robust_covariances(
        &self,
        graph: &Graph,
        initial: &Values,
        keys: &[Key],
        clusters: &[Option<usize>],
    ) -> Result<(Values, Summary, Result<RobustCovariances, SolveError>), SolveError> {
        let at = |l: &Layout, st: &mut Structure, sys: &System, lins: &Linearized| {
            robust_covariances_of_system(l, st, sys, lins, keys, clusters)
        };
        self.optimize_impl(graph, initial, Some(&at))
            .map(|(v, s, c)| (v, s, c.unwrap_or_else(|| Err(SolveError::Config("no covariance requested".into())))))
    }

    /// The solve, on a pool kept awake where [`LmOptions::keep_threads_awake`]
    /// applies.
    fn optimize_impl<R: Send>(
        &self,
        graph: &Graph,
        initial: &Values,
        at_solution: Option<AtSolution<R>>,
    ) -> Result<Solved<R>, SolveError> {
        self.options.validate()?;
        let large = graph.entries().len() >= PARALLEL_MIN_FACTORS;
        if self.options.keep_threads_awake && large {
            awake::run_keeping_pool_awake(|| self.solve(graph, initial, at_solution))
        } else {
            self.solve(graph, initial, at_solution)
        }
    }

    /// Minimize from `initial` (the options validated), then compute
    /// `at_solution` from the last linearization.
    fn solve<R>(
        &self,
        graph: &Graph,
        initial: &Values,
        at_solution: Option<AtSolution<R>>,
    ) -> Result<Solved<R>, SolveError> {
        let o = &self.options;
        let t0 = Instant::now();
        let layout = Layout::new(graph, initial, &o.eliminate)?;
        let vars: Vec<Box<dyn DynVariable>> =
            layout.keys.iter().map(|&k| initial.get_dyn(k).map(|v| v.clone_box())).collect::<Result<_, _>>()?;
        let structure = layout.structure(&vars, o.linear_solver)?;
        let entries = graph.entries();
        let mut summary = Summary::empty(&layout, &structure, entries.len());
        let t = Instant::now();
        let (lins, cost) = linearize_all(entries, &layout, &vars)?;
        summary.time_linearize += t.elapsed().as_secs_f64();
        summary.initial_cost = cost;
        if summary.variables == 0 {
            summary.termination = Termination::NothingToOptimize;
        }
        let mut m = Minimizer::new(o, &layout, structure, entries, vars, (lins, cost), summary);
        m.run()?;
        // `lins` is the linearization at the final values (trial points are
        // linearized when tried), so the covariance needs no second pass;
        // nor a second assembly when the stop was decided at that point.
        let covariances = at_solution.map(|f| {
            if !m.sys_current {
                m.structure.assemble_into(&m.lins, &mut m.sys);
            }
            f(&layout, &mut m.structure, &m.sys, &m.lins)
        });
        let mut out = initial.clone();
        for (i, k) in layout.keys.iter().enumerate() {
            if layout.roles[i] != Role::Const {
                out.insert_dyn(*k, m.vars[i].clone_box());
            }
        }
        let mut summary = m.summary;
        summary.time_total = t0.elapsed().as_secs_f64();
        Ok((out, summary, covariances))
    }
}
