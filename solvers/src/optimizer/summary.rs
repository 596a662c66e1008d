//! What a solve reports: why it stopped, its iterations and timings.

use crate::layout::Layout;
use crate::linear::Structure;
use std::fmt;

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
    /// The damped steps became too small ([`LmOptions::parameter_tolerance`](super::LmOptions::parameter_tolerance))
    /// while the residual was still aligned with a Jacobian column (squared
    /// [`Summary::scaled_gradient`] above [`LmOptions::function_tolerance`](super::LmOptions::function_tolerance)):
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
    /// Number of linear solves (accepted and rejected steps, stationarity checks).
    pub linear_solves: usize,
    /// Of those, the solves that factorized the system; the others reused
    /// the last factorization ([`LmOptions::reuse_factorization`](super::LmOptions::reuse_factorization)).
    pub factorizations: usize,
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
    /// (the test of [`LmOptions::gradient_tolerance`](super::LmOptions::gradient_tolerance)).
    pub max_gradient: f64,
    /// Relative decrease still to come, as estimated after the last
    /// accepted step (the test of [`LmOptions::function_tolerance`](super::LmOptions::function_tolerance)).
    pub remaining_decrease: f64,
    /// Relative decrease the undamped (Gauss–Newton) model predicted at the
    /// last stationarity check ([`LmOptions::check_stationarity`](super::LmOptions::check_stationarity)); NaN when
    /// none ran.
    pub gauss_newton_decrease: f64,
}

impl Summary {
    /// The summary of a solve about to start (no iteration yet, termination
    /// [`Termination::MaxIterations`] until another is found).
    pub(crate) fn empty(layout: &Layout, structure: &Structure, factors: usize) -> Summary {
        Summary {
            initial_cost: 0.0,
            final_cost: 0.0,
            iterations: 0,
            linear_solves: 0,
            factorizations: 0,
            termination: Termination::MaxIterations,
            variables: layout.kept_vars.len() + layout.elim_vars.len(),
            factors,
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
        }
    }

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
            "  iterations {} ({} linear solves, {} factorizations), termination: {:?} (scaled gradient {:.1e})",
            self.iterations, self.linear_solves, self.factorizations, self.termination, self.scaled_gradient
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
