//! The optimizer's settings.

use crate::error::SolveError;
use crate::linear::LinearSolver;

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
///
/// # Stopping rules
///
/// With cost `C = ½‖r‖²` (whitened), gradient `g = Jᵀr`, `H = JᵀJ`, the
/// last two accepted decreases `d_k`, `d_{k−1}` and `q = d_k / d_{k−1}`, each
/// tolerance means one thing:
///
/// - `function_tolerance` `f` bounds the **relative decrease still to come**,
///   measured three ways, all of which must agree for `FunctionTolerance`:
///   extrapolated `d_k q/(1−q) ≤ f C` (or `d_k ≤ f C` when `q ∉ (0, 1)`);
///   along the best single column `max_j g_j² / (H_jj · 2C) ≤ f` (the squared
///   scaled gradient, [`Summary::scaled_gradient`](super::Summary::scaled_gradient)); and by one undamped step
///   `δ`: `(−gᵀδ − ½ δᵀHδ) / C ≤ f`.
/// - `gradient_tolerance` `γ` is absolute: `max_j |g_j| ≤ γ` ends the solve as
///   `GradientTolerance` where the undamped step agrees, as for a cost test
///   (a gradient can be that small far from a minimum: a zero-residual fit
///   whose cost is still falling, columns that nearly cancel).
/// - `parameter_tolerance` `p` bounds the step: `‖δ‖ ≤ p (‖x‖ + p)` ends it
///   as `ParameterTolerance` where the scaled gradient agrees, else
///   `Stalled`.
/// - `max_iterations` ends it as `MaxIterations` (not converged).
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
    /// Stop when the largest gradient entry is below this (and, with
    /// [`LmOptions::check_stationarity`], one undamped step predicts no
    /// larger relative decrease than `function_tolerance`).
    pub gradient_tolerance: f64,
    /// Stop when ‖δ‖ < this · (‖x‖ + this): converged where the scaled
    /// gradient agrees ([`LmOptions::check_stationarity`]), else
    /// [`Termination::Stalled`](super::Termination::Stalled).
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
    /// Record one [`IterationLog`](super::IterationLog) per iteration.
    pub log_iterations: bool,
    /// Before stopping on [`LmOptions::function_tolerance`] or
    /// [`LmOptions::parameter_tolerance`], check that the point is a minimum:
    /// the squared scaled gradient ([`Summary::scaled_gradient`](super::Summary::scaled_gradient)) is within
    /// the function tolerance, and one undamped (Gauss–Newton) solve predicts
    /// no larger relative decrease (or no longer step) either — the damped
    /// steps may have been small because the damping was large, not because
    /// the minimum is near. A small damped step needs only the scaled
    /// gradient (the undamped model can promise a decrease along columns that
    /// cancel, which no step delivers). A cost test that fails goes on; a
    /// small step that fails ends [`Termination::Stalled`](super::Termination::Stalled). Without the check
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
    /// End the solve as [`Termination::FunctionTolerance`](super::Termination::FunctionTolerance) before trying a
    /// step whose model decrease −gᵀδ − ½δᵀHδ is at most
    /// `function_tolerance` × the cost, when that step is no more damped than
    /// the first (λ ≤ `initial_lambda`, or Gauss–Newton): the quadratic model
    /// of the current linearization says that no step gains what the
    /// tolerance asks for, so the step's evaluation (a linearization) and, with
    /// covariances, a second assembly at its point are saved. A damped step's
    /// model decrease understates the undamped one, hence the condition on λ.
    /// For anytime solves (the VIO window, re-solved at the next frame); not
    /// with [`LmOptions::check_stationarity`], which checks the stops it
    /// proposes at the next linearization.
    pub stop_on_predicted_decrease: bool,
    /// Reuse the last sparse factorization where the normal equations have
    /// barely changed since (near a minimum): a step is first tried as the
    /// chord step `δ = −P⁻¹g` with the old factor P, taken where it gains
    /// as much as the exact step would to within the tolerances (else the
    /// system is factorized), and the stationarity check solves by
    /// conjugate gradients preconditioned with P, to the accuracy its
    /// decision needs, factorizing only where they do not get there within a
    /// few iterations. Either costs a few triangular solves instead of a
    /// factorization. Sparse systems without eliminated variables use it:
    /// the check with any factor, the chord steps only with a supernodal
    /// one (costly to recompute, where a failed try is cheap beside it).
    /// The stops are decided as without it, the decrease to come known to
    /// 10⁻³ of the tolerance it is compared with.
    pub reuse_factorization: bool,
    /// On graphs of 4096 factors or more, whose linearization and assembly
    /// run in parallel passes of milliseconds between serial
    /// factorizations, keep rayon's other threads polling for the solve's
    /// work instead of sleeping between passes: waking them took 1–3 ms on
    /// two-vCPU virtual machines, as long as a pass (parking-garage and
    /// city10000 solve 10–20 % faster there, sphere2500 3–12 %). Between
    /// polls they nap 50 µs, leaving their cores to any other thread, until
    /// the solve ends. Only where the solve is called from outside rayon's
    /// pool, the pool has more than one thread and no other solve keeps it
    /// awake. Turn it off to leave the cores idle between passes.
    pub keep_threads_awake: bool,
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
            stop_on_predicted_decrease: false,
            reuse_factorization: true,
            keep_threads_awake: true,
        }
    }
}

impl LmOptions {
    /// Refuse options no solve can honour: tolerances and damping bounds
    /// that are negative or not finite, `min_diagonal > max_diagonal`, an
    /// initial damping outside `(0, max_lambda]`, or a `min_lambda_decrease`
    /// outside `(0, 1)`, `stop_on_predicted_decrease` with
    /// `check_stationarity`. [`Optimizer::optimize`](super::Optimizer::optimize) calls it first.
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
        if self.stop_on_predicted_decrease && self.check_stationarity && self.method != Method::GaussNewton {
            return Err(SolveError::Config(
                "stop_on_predicted_decrease with check_stationarity: the first ends a solve at once where the second \
                 checks every stop at the next linearization; choose one"
                    .into(),
            ));
        }
        Ok(())
    }
}
