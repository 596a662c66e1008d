//! Levenberg–Marquardt (trust region with Nielsen's damping update, as in
//! Ceres) and Gauss–Newton over a [`Graph`], returning a [`Summary`].

use crate::error::SolveError;
use crate::graph::Graph;
use crate::key::Key;
use crate::layout::{Layout, Role};
use crate::linear::{LinearSolver, Structure, System};
use crate::linearized::{linearize_all, linearize_all_into, Linearized};
use crate::marginal::{covariances_of_system, robust_covariances_of_system, Covariances, RobustCovariances};
use crate::values::Values;
use crate::variable::DynVariable;
use std::fmt;
use std::time::Instant;

/// Which nonlinear method to run.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Method {
    /// Levenberg–Marquardt with a trust-region damping update.
    #[default]
    LevenbergMarquardt,
    /// Undamped Gauss–Newton: every step is taken.
    GaussNewton,
}

/// Options of the optimizer. The damping starts small (λ₀ = 1e-8 relative to
/// the scale D) and may shrink 10× per good step, which on the standard pose
/// graphs needs 2–3× fewer iterations than Ceres' λ₀ = 1e-4 with a 3× floor
/// (e.g. M3500: 5 instead of 18). Steps are kept from running away on hard
/// small problems by MINPACK's two safeguards: each unknown's scale D is the
/// largest curvature it has had ([`LmOptions::keep_largest_scale`]) and a step
/// may be at most twice as long (in D) as the last good one
/// ([`LmOptions::trust_radius`]). A solve ends as converged only when the
/// decrease still to come is below `function_tolerance` and an undamped
/// solve agrees ([`LmOptions::check_stationarity`]); see `docs/solver.md`.
#[derive(Clone, Debug)]
pub struct LmOptions {
    /// Nonlinear method.
    pub method: Method,
    /// Maximum number of iterations (linearizations).
    pub max_iterations: usize,
    /// Stop when the relative cost decrease still to come is below this: the
    /// last decrease, extrapolated as a geometric series from the last two
    /// (a fast, superlinear convergence stops without one more iteration; a
    /// slow, linear one is not taken for a minimum).
    pub function_tolerance: f64,
    /// Stop when the largest gradient entry is below this.
    pub gradient_tolerance: f64,
    /// Stop when ‖δ‖ < this · (‖x‖ + this): converged where the scaled
    /// gradient agrees ([`LmOptions::check_stationarity`]), else
    /// [`Termination::Stalled`].
    pub parameter_tolerance: f64,
    /// Initial damping λ (1 / trust-region radius).
    pub initial_lambda: f64,
    /// Damping is λ · clamp(D, min_diagonal, max_diagonal), D = diag H (or
    /// its running maximum, [`LmOptions::keep_largest_scale`]).
    pub min_diagonal: f64,
    /// See `min_diagonal`.
    pub max_diagonal: f64,
    /// Give up when λ exceeds this.
    pub max_lambda: f64,
    /// Smallest factor λ is multiplied by after a successful step (Nielsen's
    /// update `max(this, 1 − (2ρ − 1)³)`; Ceres uses 1/3, tumble 1/10).
    pub min_lambda_decrease: f64,
    /// A step is accepted when it lowers the cost and its gain ratio (actual
    /// over predicted decrease) exceeds this (Ceres' `min_relative_decrease`
    /// is 1e-3).
    pub min_gain_ratio: f64,
    /// Linear solver for the (reduced) normal equations.
    pub linear_solver: LinearSolver,
    /// Key tags (e.g. `['l']`) of variables to eliminate first by the Schur
    /// complement (landmarks in bundle adjustment). Each factor may touch at
    /// most one of them.
    pub eliminate: Vec<char>,
    /// Record one [`IterationLog`] per iteration.
    pub log_iterations: bool,
    /// Before stopping on [`LmOptions::function_tolerance`] or
    /// [`LmOptions::parameter_tolerance`], check that the point is a minimum:
    /// the squared scaled gradient ([`Summary::scaled_gradient`]) is within
    /// the function tolerance, and one undamped (Gauss–Newton) solve predicts
    /// no larger relative decrease (or no longer step) either — the damped
    /// steps may have been small because the damping was large, not because
    /// the minimum is near. A small damped step needs only the scaled
    /// gradient (the undamped model can promise a decrease along columns that
    /// cancel, which no step delivers). A cost test that fails goes on; a
    /// small step that fails ends [`Termination::Stalled`]. Without the check
    /// a tolerance that fires ends the solve under its own name (as in
    /// Ceres). Off for anytime solves with a fixed budget (the VIO window,
    /// re-solved at the next frame).
    pub check_stationarity: bool,
    /// Damp each unknown by the largest curvature (diagonal of H) it has had
    /// in this solve, not only the current one (MINPACK's scaling): an
    /// unknown whose Jacobian column collapses — a saturated exponential, a
    /// decay rate run off to infinity — stays damped at its earlier scale
    /// instead of becoming free to leave the region where the data see it.
    pub keep_largest_scale: bool,
    /// Bound each step's length ‖δ‖_D = (Σ D_j δ_j²)^½ by a radius that is
    /// twice the last step after a good one (gain ratio ≥ 0.75) and halves
    /// after a poor one (< 0.25), as MINPACK does; a longer step raises λ
    /// instead. Nielsen's λ update alone is relative: where λ is far below
    /// the problem's curvature, doubling it leaves the step as long, and one
    /// lucky step can throw the parameters out of the model's reach.
    pub trust_radius: bool,
}

impl Default for LmOptions {
    fn default() -> Self {
        LmOptions {
            method: Method::LevenbergMarquardt,
            max_iterations: 1000,
            function_tolerance: 1e-10,
            gradient_tolerance: 1e-10,
            parameter_tolerance: 1e-8,
            initial_lambda: 1e-8,
            min_diagonal: 1e-6,
            max_diagonal: 1e32,
            max_lambda: 1e16,
            min_lambda_decrease: 0.1,
            min_gain_ratio: 0.0,
            linear_solver: LinearSolver::Auto,
            eliminate: Vec::new(),
            log_iterations: true,
            check_stationarity: true,
            keep_largest_scale: true,
            trust_radius: true,
        }
    }
}

impl LmOptions {
    /// Refuse options no solve can honour: tolerances and damping bounds
    /// that are negative or not finite, `min_diagonal > max_diagonal`, an
    /// initial damping outside `(0, max_lambda]`, or a `min_lambda_decrease`
    /// outside `(0, 1)`. [`Optimizer::optimize`] calls it first.
    pub fn validate(&self) -> Result<(), SolveError> {
        let bad = |name: &str, v: f64, what: &str| Err(SolveError::Config(format!("{name} = {v}: {what}")));
        for (name, v) in [
            ("function_tolerance", self.function_tolerance),
            ("gradient_tolerance", self.gradient_tolerance),
            ("parameter_tolerance", self.parameter_tolerance),
            ("min_gain_ratio", self.min_gain_ratio),
            ("min_diagonal", self.min_diagonal),
        ] {
            if !v.is_finite() || v < 0.0 {
                return bad(name, v, "must be a finite number ≥ 0");
            }
        }
        if self.max_diagonal.is_nan() || self.max_diagonal < self.min_diagonal {
            return bad("max_diagonal", self.max_diagonal, "must be ≥ min_diagonal");
        }
        if !self.max_lambda.is_finite() || self.max_lambda <= 0.0 {
            return bad("max_lambda", self.max_lambda, "must be a finite number > 0");
        }
        if self.initial_lambda.is_nan() || self.initial_lambda <= 0.0 || self.initial_lambda > self.max_lambda {
            return bad("initial_lambda", self.initial_lambda, "must be > 0 and ≤ max_lambda");
        }
        if self.min_lambda_decrease.is_nan() || self.min_lambda_decrease <= 0.0 || self.min_lambda_decrease >= 1.0 {
            return bad("min_lambda_decrease", self.min_lambda_decrease, "must lie in (0, 1)");
        }
        Ok(())
    }
}

/// Why the optimizer stopped.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Termination {
    /// Relative cost decrease below `function_tolerance`.
    FunctionTolerance,
    /// Gradient below `gradient_tolerance`.
    GradientTolerance,
    /// Step below `parameter_tolerance`.
    ParameterTolerance,
    /// `max_iterations` reached.
    MaxIterations,
    /// Damping grew past `max_lambda` without finding a decrease.
    NoProgress,
    /// The damped steps became too small ([`LmOptions::parameter_tolerance`])
    /// while the residual was still aligned with a Jacobian column (squared
    /// [`Summary::scaled_gradient`] above [`LmOptions::function_tolerance`]):
    /// not a minimum, the solver stalled — e.g. a parameter ran to where the
    /// data no longer see it.
    Stalled,
    /// The graph has no free variable.
    NothingToOptimize,
}

/// One row of the iteration log.
#[derive(Clone, Debug)]
pub struct IterationLog {
    /// Iteration number (from 1).
    pub iteration: usize,
    /// Cost after the iteration.
    pub cost: f64,
    /// Damping used for the accepted (or last tried) step.
    pub lambda: f64,
    /// Norm of the step.
    pub step_norm: f64,
    /// Gain ratio actual / predicted decrease.
    pub gain_ratio: f64,
    /// Whether the step was accepted.
    pub accepted: bool,
}

/// What a user reads after a solve (cf. Ceres' `Solver::Summary`).
#[derive(Clone, Debug)]
pub struct Summary {
    /// Cost ½ Σ ρ(‖W r‖²) at the start.
    pub initial_cost: f64,
    /// Cost at the end.
    pub final_cost: f64,
    /// Number of linearizations after the first.
    pub iterations: usize,
    /// Number of linear solves (accepted and rejected steps).
    pub linear_solves: usize,
    /// Why it stopped.
    pub termination: Termination,
    /// Free variables.
    pub variables: usize,
    /// Factors.
    pub factors: usize,
    /// Unknowns of the reduced system.
    pub reduced_dim: usize,
    /// Unknowns eliminated by the Schur complement.
    pub eliminated_dim: usize,
    /// Stored nonzeros of the lower triangle of the reduced system.
    pub reduced_nnz: usize,
    /// Seconds evaluating factors (residuals and Jacobians).
    pub time_linearize: f64,
    /// Seconds assembling normal equations, damping and Schur complement.
    pub time_build: f64,
    /// Seconds in numeric (and the first symbolic) factorization.
    pub time_factorize: f64,
    /// Seconds in triangular solves and back-substitution.
    pub time_solve: f64,
    /// Total seconds.
    pub time_total: f64,
    /// Per-iteration log (when enabled).
    pub log: Vec<IterationLog>,
    /// The scaled gradient at the last assembled linearization (the final
    /// point's, or the one before it when a step ends the solve): the largest cosine of
    /// the angle between the (whitened) residual and a Jacobian column,
    /// `max_j |(Jᵀr)_j| / (‖J_j‖ ‖r‖)` — 0 at a minimum whatever the problem's
    /// scale, and its square estimates the relative decrease still to come.
    pub scaled_gradient: f64,
    /// Largest gradient entry |(Jᵀr)_j| at the last assembled linearization
    /// (the test of [`LmOptions::gradient_tolerance`]).
    pub max_gradient: f64,
    /// Relative decrease still to come, as estimated after the last
    /// accepted step (the test of [`LmOptions::function_tolerance`]).
    pub remaining_decrease: f64,
    /// Relative decrease the undamped (Gauss–Newton) model predicted at the
    /// last stationarity check ([`LmOptions::check_stationarity`]); NaN when
    /// none ran.
    pub gauss_newton_decrease: f64,
}

impl Summary {
    /// Whether the solve ended at a minimum (a tolerance test passed with a
    /// small scaled gradient), not at a limit or a stall.
    pub fn converged(&self) -> bool {
        matches!(
            self.termination,
            Termination::FunctionTolerance | Termination::GradientTolerance | Termination::ParameterTolerance
        )
    }
}

impl fmt::Display for Summary {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(f, "tumble solver summary")?;
        writeln!(f, "  variables {:>10}   factors {:>10}", self.variables, self.factors)?;
        writeln!(
            f,
            "  reduced system {} unknowns, {} nonzeros; {} eliminated",
            self.reduced_dim, self.reduced_nnz, self.eliminated_dim
        )?;
        writeln!(f, "  initial cost {:.6e}", self.initial_cost)?;
        writeln!(f, "  final cost   {:.6e}", self.final_cost)?;
        writeln!(
            f,
            "  iterations {} ({} linear solves), termination: {:?} (scaled gradient {:.1e})",
            self.iterations, self.linear_solves, self.termination, self.scaled_gradient
        )?;
        let checked = if self.gauss_newton_decrease.is_nan() {
            "not checked".to_string()
        } else {
            format!("undamped model {:.1e}", self.gauss_newton_decrease)
        };
        writeln!(
            f,
            "  relative decrease to come {:.1e} ({checked}), largest gradient {:.1e}",
            self.remaining_decrease, self.max_gradient
        )?;
        writeln!(
            f,
            "  time [s]: linearize {:.4}  build {:.4}  factorize {:.4}  solve {:.4}  total {:.4}",
            self.time_linearize, self.time_build, self.time_factorize, self.time_solve, self.time_total
        )
    }
}

/// Damping (relative to diag H) of the Gauss–Newton step that checks a
/// small decrease: small enough to leave the step undamped, large enough to
/// keep a semi-definite H factorizable.
const GAUSS_NEWTON_CHECK_DAMPING: f64 = 1e-12;

/// The largest cosine of the angle between the whitened residual (cost
/// `cost` = ½‖r‖²) and a Jacobian column: `|g_j| / sqrt(H_jj · 2 cost)`, with
/// `g = Jᵀr` and `H_jj = ‖J_j‖²` (0 where a column or the residual vanishes).
fn scaled_gradient(g: &[f64], diag: &[f64], cost: f64) -> f64 {
    let r2 = 2.0 * cost;
    g.iter()
        .zip(diag)
        .map(|(gj, hj)| if *hj > 0.0 && r2 > 0.0 { gj.abs() / (hj * r2).sqrt() } else { 0.0 })
        .fold(0.0, f64::max)
}

/// The decrease still to come after an accepted step that lowered the cost
/// by `decrease` (the one before by `previous`, NaN for the first): the
/// geometric series of the two when they shrink, else the decrease itself.
fn remaining_decrease(decrease: f64, previous: f64) -> f64 {
    let q = decrease / previous;
    if q > 0.0 && q < 1.0 {
        decrease * q / (1.0 - q)
    } else {
        decrease
    }
}

/// Predicted decrease −gᵀδ − ½ δᵀHδ of step `delta`, given `hd` = Hδ.
fn predicted_decrease(delta: &[f64], g: &[f64], hd: &[f64]) -> f64 {
    -delta.iter().zip(g).map(|(a, b)| a * b).sum::<f64>() - 0.5 * delta.iter().zip(hd).map(|(a, b)| a * b).sum::<f64>()
}

/// The stationarity check ([`LmOptions::check_stationarity`]) of a stop that
/// `test` proposes at the assembled system `sys` (cost `cost`, parameter
/// norm `x_norm`, damping scale `diag`): the termination to end the solve
/// with, or `None` to go on with damped steps.
///
/// - The squared scaled gradient must be within `function_tolerance`: it
///   bounds the relative decrease to come from below whatever a solve's
///   accuracy, and a column that has all but vanished (a saturated
///   parameter, below the damping floor) still shows. Else a small step has
///   stalled and a cost test goes on.
/// - A small damped step needs no more: at a first-order stationary point the
///   undamped model can still promise a decrease along directions where the
///   columns cancel (identical columns at a symmetric minimum), which no step
///   delivers.
/// - A cost test also needs one undamped solve whose predicted decrease (or
///   step) is within the tolerances.
/// - A cost at the rounding level of the start is a zero-residual fit, where
///   the residual stays aligned with the columns: converged.
#[allow(clippy::too_many_arguments)]
fn check_stop(
    test: Termination,
    structure: &mut Structure,
    sys: &System,
    diag: &[f64],
    g: &[f64],
    (cost, x_norm): (f64, f64),
    o: &LmOptions,
    summary: &mut Summary,
) -> Option<Termination> {
    if cost <= f64::EPSILON * summary.initial_cost {
        return Some(test);
    }
    let aligned = summary.scaled_gradient.powi(2) <= o.function_tolerance;
    if test != Termination::FunctionTolerance {
        return Some(if aligned { test } else { Termination::Stalled });
    }
    if !aligned {
        return None;
    }
    let tiny: Vec<f64> = diag.iter().map(|d| d * GAUSS_NEWTON_CHECK_DAMPING).collect();
    summary.linear_solves += 1;
    let solved = structure.solve(sys, Some(&tiny)).ok().and_then(|(delta, fs, ss, bs)| {
        summary.time_factorize += fs;
        summary.time_solve += ss;
        summary.time_build += bs;
        let d = predicted_decrease(&delta, g, &structure.h_times(sys, &delta));
        // ½ gᵀH⁻¹g is not negative: anything else is a numerically failed solve.
        (d.is_finite() && d >= 0.0).then(|| (d, delta.iter().map(|v| v * v).sum::<f64>().sqrt()))
    });
    let small = match solved {
        Some((d, step)) => {
            summary.gauss_newton_decrease = d / cost.max(f64::MIN_POSITIVE);
            d <= o.function_tolerance * cost || step <= o.parameter_tolerance * (x_norm + o.parameter_tolerance)
        }
        // No undamped step (H singular there): the scaled gradient decided.
        None => true,
    };
    small.then_some(test)
}

/// Retract the free variables of `vars` by `delta` (kept then eliminated
/// unknowns) into `trial`; constants stay as they are there.
fn retract_all(
    layout: &Layout,
    structure: &Structure,
    vars: &[Box<dyn DynVariable>],
    delta: &[f64],
    trial: &mut [Box<dyn DynVariable>],
) {
    for (i, (v, out)) in vars.iter().zip(trial.iter_mut()).enumerate() {
        match layout.roles[i] {
            Role::Const => {}
            Role::Kept(b) => {
                let o = structure.kept_offset(b);
                v.retract_into(&delta[o..o + structure.kept_dim(b)], out);
            }
            Role::Elim(e) => {
                let o = structure.elim_offsets[e];
                v.retract_into(&delta[o..o + v.dim()], out);
            }
        }
    }
}

/// Covariances requested from [`Optimizer::optimize_with_covariances`], or why they failed.
type CovarianceResult = Result<Covariances, SolveError>;

/// What is computed at the solution from the optimizer's last linearization
/// (covariances of some kind), by [`Optimizer::optimize_impl`].
type AtSolution<'a, R> = &'a dyn Fn(&Layout, &mut Structure, &System, &Linearized) -> Result<R, SolveError>;

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

    fn optimize_impl<R>(
        &self,
        graph: &Graph,
        initial: &Values,
        at_solution: Option<AtSolution<R>>,
    ) -> Result<Solved<R>, SolveError> {
        let o = &self.options;
        o.validate()?;
        let t0 = Instant::now();
        let layout = Layout::new(graph, initial, &o.eliminate)?;
        let mut vars: Vec<Box<dyn DynVariable>> =
            layout.keys.iter().map(|&k| initial.get_dyn(k).map(|v| v.clone_box())).collect::<Result<_, _>>()?;
        let mut structure = layout.structure(&vars, o.linear_solver)?;
        let entries = graph.entries();
        let mut summary = Summary {
            initial_cost: 0.0,
            final_cost: 0.0,
            iterations: 0,
            linear_solves: 0,
            termination: Termination::MaxIterations,
            variables: layout.kept_vars.len() + layout.elim_vars.len(),
            factors: entries.len(),
            reduced_dim: structure.n,
            eliminated_dim: structure.elim_dims.iter().sum(),
            reduced_nnz: structure.nnz(),
            time_linearize: 0.0,
            time_build: 0.0,
            time_factorize: 0.0,
            time_solve: 0.0,
            time_total: 0.0,
            log: Vec::new(),
            scaled_gradient: f64::NAN,
            max_gradient: f64::NAN,
            remaining_decrease: f64::NAN,
            gauss_newton_decrease: f64::NAN,
        };
        let t = Instant::now();
        let (mut lins, mut cost) = linearize_all(entries, &layout, &vars)?;
        // The trial point's linearization, in buffers reused from step to step.
        let mut trial_lins = Linearized::default();
        summary.time_linearize += t.elapsed().as_secs_f64();
        summary.initial_cost = cost;
        if summary.variables == 0 {
            summary.termination = Termination::NothingToOptimize;
        }
        let mut lambda = o.initial_lambda;
        let mut nu = 2.0;
        let gn = o.method == Method::GaussNewton;
        let mut sys = System::default();
        let free: Vec<usize> = layout.kept_vars.iter().chain(&layout.elim_vars).copied().collect();
        // The trial point, overwritten by each step's retraction.
        let mut trial: Vec<Box<dyn DynVariable>> = vars.clone();
        // A tolerance test passed after the last accepted step: the stop it
        // proposes is checked at the next linearization.
        let mut proposed: Option<Termination> = None;
        // Running maximum of diag H (LmOptions::keep_largest_scale).
        let mut largest: Vec<f64> = Vec::new();
        // Trust radius in the scaled norm (LmOptions::trust_radius).
        let mut radius = f64::INFINITY;
        // The previous accepted step's cost decrease.
        let mut previous_decrease = f64::NAN;

        'outer: while summary.termination != Termination::NothingToOptimize {
            if summary.iterations >= o.max_iterations {
                summary.termination = Termination::MaxIterations;
                break;
            }
            let t = Instant::now();
            structure.assemble_into(&lins, &mut sys);
            summary.time_build += t.elapsed().as_secs_f64();
            let g_all: Vec<f64> = sys.g.iter().copied().chain(sys.gl.iter().copied()).collect();
            let gmax = g_all.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            let raw_diag = structure.diagonal(&sys);
            summary.scaled_gradient = scaled_gradient(&g_all, &raw_diag, cost);
            summary.max_gradient = gmax;
            if gmax <= o.gradient_tolerance {
                summary.termination = Termination::GradientTolerance;
                break;
            }
            if o.keep_largest_scale {
                if largest.len() != raw_diag.len() {
                    largest.clone_from(&raw_diag);
                }
                for (m, d) in largest.iter_mut().zip(&raw_diag) {
                    *m = m.max(*d);
                }
            }
            let scale = if o.keep_largest_scale { &largest } else { &raw_diag };
            let diag: Vec<f64> = scale.iter().map(|d| d.clamp(o.min_diagonal, o.max_diagonal)).collect();
            let x_norm =
                free.iter().map(|&v| vars[v].params_dyn().iter().map(|p| p * p).sum::<f64>()).sum::<f64>().sqrt();
            if let Some(test) = proposed.take() {
                let point = (cost, x_norm);
                if let Some(t) = check_stop(test, &mut structure, &sys, &diag, &g_all, point, o, &mut summary) {
                    summary.termination = t;
                    break;
                }
            }
            summary.iterations += 1;
            loop {
                let damping: Option<Vec<f64>> = if gn { None } else { Some(diag.iter().map(|d| d * lambda).collect()) };
                summary.linear_solves += 1;
                let step = structure.solve(&sys, damping.as_deref());
                let (delta, fs, ss, bs) = match step {
                    Ok(s) => s,
                    Err(e) => {
                        if gn {
                            return Err(e);
                        }
                        lambda *= nu;
                        nu *= 2.0;
                        if lambda > o.max_lambda {
                            summary.termination = Termination::NoProgress;
                            break 'outer;
                        }
                        continue;
                    }
                };
                summary.time_factorize += fs;
                summary.time_solve += ss;
                summary.time_build += bs;
                let hd = structure.h_times(&sys, &delta);
                let scaled_len = delta.iter().zip(&diag).map(|(v, d)| v * v * d).sum::<f64>().sqrt();
                if o.trust_radius && !gn && scaled_len > 1.5 * radius {
                    // Longer than the radius: raise λ to about the value that brings
                    // the step to it (one dominant direction of scaled curvature μ,
                    // along which the length goes as 1 / (μ + λ)), and solve again.
                    let mu = delta.iter().zip(&hd).map(|(a, b)| a * b).sum::<f64>() / (scaled_len * scaled_len);
                    lambda = (2.0 * lambda).max((mu + lambda) * scaled_len / radius - mu);
                    if lambda > o.max_lambda {
                        summary.termination = Termination::NoProgress;
                        break 'outer;
                    }
                    continue;
                }
                let step_norm = delta.iter().map(|v| v * v).sum::<f64>().sqrt();
                let small_step = step_norm <= o.parameter_tolerance * (x_norm + o.parameter_tolerance);
                // Retract into the trial buffers (constants stay as cloned).
                let t = Instant::now();
                retract_all(&layout, &structure, &vars, &delta, &mut trial);
                // Linearize at the trial point right away: with small damping
                // nearly every step is accepted, and then this is the next
                // iteration's linearization (no second pass over the residuals).
                let new_cost = linearize_all_into(entries, &layout, &trial, &mut trial_lins);
                let linearized = new_cost.is_ok();
                summary.time_linearize += t.elapsed().as_secs_f64();
                let predicted = predicted_decrease(&delta, &g_all, &hd);
                let (new_cost, accepted, rho) = match new_cost {
                    Ok(c) => {
                        let rho = if predicted > 0.0 { (cost - c) / predicted } else { -1.0 };
                        (c, gn || (c < cost && rho > o.min_gain_ratio), rho)
                    }
                    Err(_) => (f64::INFINITY, false, -1.0),
                };
                if o.log_iterations {
                    summary.log.push(IterationLog {
                        iteration: summary.iterations,
                        cost: if accepted { new_cost } else { cost },
                        lambda,
                        step_norm,
                        gain_ratio: rho,
                        accepted,
                    });
                }
                if o.trust_radius {
                    if accepted && rho >= 0.75 {
                        radius = 2.0 * scaled_len;
                    } else if rho < 0.25 {
                        radius = 0.5 * radius.min(10.0 * scaled_len);
                    }
                }
                let defer = o.check_stationarity && !gn;
                if accepted && linearized {
                    let decrease = cost - new_cost;
                    std::mem::swap(&mut vars, &mut trial);
                    std::mem::swap(&mut lins, &mut trial_lins);
                    cost = new_cost;
                    if !gn {
                        lambda *= o.min_lambda_decrease.max(1.0 - (2.0 * rho - 1.0).powi(3));
                        lambda = lambda.max(1e-16);
                        nu = 2.0;
                    }
                    let remaining = remaining_decrease(decrease, previous_decrease);
                    previous_decrease = decrease;
                    summary.remaining_decrease = remaining / cost.max(f64::MIN_POSITIVE);
                    let test = if cost == 0.0 {
                        summary.termination = Termination::FunctionTolerance;
                        break 'outer;
                    } else if small_step {
                        Some(Termination::ParameterTolerance)
                    } else if remaining.abs() <= o.function_tolerance * cost {
                        Some(Termination::FunctionTolerance)
                    } else {
                        None
                    };
                    match test {
                        Some(t) if !defer => {
                            summary.termination = t;
                            break 'outer;
                        }
                        t => proposed = t,
                    }
                    break;
                }
                if small_step {
                    // A rejected step this small: λ is large. Checked at this same
                    // point by the next pass of the outer loop.
                    if !defer {
                        summary.termination = Termination::ParameterTolerance;
                        break 'outer;
                    }
                    proposed = Some(Termination::ParameterTolerance);
                    break;
                }
                lambda *= nu;
                nu *= 2.0;
                if lambda > o.max_lambda {
                    summary.termination = Termination::NoProgress;
                    break 'outer;
                }
            }
        }
        summary.final_cost = cost;
        // `lins` is the linearization at the final values (trial points are
        // linearized when tried), so the covariance needs no second pass.
        let covariances = at_solution.map(|f| {
            structure.assemble_into(&lins, &mut sys);
            f(&layout, &mut structure, &sys, &lins)
        });
        let mut out = initial.clone();
        for (i, k) in layout.keys.iter().enumerate() {
            if layout.roles[i] != Role::Const {
                out.insert_dyn(*k, vars[i].clone_box());
            }
        }
        summary.time_total = t0.elapsed().as_secs_f64();
        Ok((out, summary, covariances))
    }
}
