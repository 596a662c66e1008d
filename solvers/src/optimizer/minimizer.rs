//! The minimizer's loop: at each linearization assemble the normal
//! equations, check a proposed stop, then try damped steps until one is
//! accepted or the strategy gives up. The strategy ([`TrustRegion`]) decides
//! the damping, [`super::termination`] when to stop; the evaluation of the
//! factors is [`crate::linearized`]'s.

use super::linear_step::linear_step;
use super::strategy::{DampingExhausted, TrustRegion};
use super::termination::{check_stop, predicted_decrease, remaining_decrease, scaled_gradient};
use super::{IterationLog, LmOptions, Summary, Termination};
use crate::error::SolveError;
use crate::graph::FactorEntry;
use crate::layout::{Layout, Role};
use crate::linear::{Structure, System};
use crate::linearized::{linearize_all_into, Linearized};
use crate::variable::DynVariable;
use std::time::Instant;

/// The largest share of the best decrease along its line a chord step may
/// leave undone (e² of [`Minimizer::chord_step`]): on a long, linearly
/// converging solve (torus3D, MIT) steps that lose more were taken where the
/// tolerance test allowed them and added iterations (MIT: 29 → 39 with no
/// bound, 33 with this one).
const CHORD_MAX_LOSS: f64 = 0.1;

/// One solve's state: the current point and its linearization, the trial
/// point's buffers, the assembled system and the summary being written.
pub(super) struct Minimizer<'a> {
    pub o: &'a LmOptions,
    pub layout: &'a Layout,
    pub structure: Structure,
    pub entries: &'a [FactorEntry],
    /// The current point (the layout's variables, in its key order) and its linearization and cost.
    pub vars: Vec<Box<dyn DynVariable>>,
    pub lins: Linearized,
    pub cost: f64,
    /// The trial point, overwritten by each step's retraction, and its linearization.
    trial: Vec<Box<dyn DynVariable>>,
    trial_lins: Linearized,
    pub sys: System,
    /// Whether `sys` is assembled at the current point (no step accepted since).
    pub sys_current: bool,
    pub summary: Summary,
    /// The free variables (kept, then eliminated).
    free: Vec<usize>,
    /// The previous accepted step's cost decrease.
    previous_decrease: f64,
}

/// The gradient and the damping scale at the current linearization.
struct Point {
    /// `Jᵀr`, kept then eliminated unknowns.
    g: Vec<f64>,
    /// Its largest entry's magnitude.
    g_max: f64,
    /// The damping scale D.
    diag: Vec<f64>,
    /// The current curvature diag H: the stationarity check's undamped step
    /// is damped relative to it, not to D, which keeps the largest curvature
    /// each unknown had (and a floor) and would hold back a column that has
    /// since all but vanished (a saturated exponential).
    curvature: Vec<f64>,
    /// ‖x‖ over the free variables.
    x_norm: f64,
}

/// How an iteration's damped steps ended.
enum Outcome {
    /// A step was accepted; a tolerance test it passed proposes a stop, to be
    /// checked at the next linearization.
    Accepted(Option<Termination>),
    /// A rejected step this small: λ is large; the stop is checked at this same point.
    Tiny,
    /// The solve ends.
    Stop(Termination),
}

impl<'a> Minimizer<'a> {
    pub fn new(
        o: &'a LmOptions,
        layout: &'a Layout,
        structure: Structure,
        entries: &'a [FactorEntry],
        vars: Vec<Box<dyn DynVariable>>,
        (lins, cost): (Linearized, f64),
        summary: Summary,
    ) -> Minimizer<'a> {
        let free = layout.kept_vars.iter().chain(&layout.elim_vars).copied().collect();
        let trial = vars.clone();
        Minimizer {
            o,
            layout,
            structure,
            entries,
            vars,
            lins,
            cost,
            trial,
            trial_lins: Linearized::default(),
            sys: System::default(),
            sys_current: false,
            summary,
            free,
            previous_decrease: f64::NAN,
        }
    }

    /// Iterate until a termination; the summary's `termination` says which.
    pub fn run(&mut self) -> Result<(), SolveError> {
        let mut strategy = TrustRegion::new(self.o);
        // A tolerance test passed after the last accepted step: the stop it
        // proposes is checked at the next linearization.
        let mut proposed: Option<Termination> = None;
        while self.summary.termination != Termination::NothingToOptimize {
            if self.summary.iterations >= self.o.max_iterations {
                self.summary.termination = Termination::MaxIterations;
                break;
            }
            let point = self.assemble(&mut strategy);
            // A small gradient proposes a stop as a small decrease does: where
            // the cost is small too (a zero-residual fit still converging, an
            // ill-conditioned fit whose columns nearly cancel) the undamped
            // model still promises a decrease, and the solve goes on.
            let small_gradient = point.g_max <= self.o.gradient_tolerance;
            if small_gradient && !self.o.check_stationarity {
                self.summary.termination = Termination::GradientTolerance;
                break;
            }
            let mut tests = small_gradient.then_some(Termination::GradientTolerance).into_iter().chain(proposed.take());
            if let Some(t) = tests.find_map(|test| self.check(test, &point)) {
                self.summary.termination = t;
                break;
            }
            self.summary.iterations += 1;
            match self.iterate(&point, &mut strategy)? {
                Outcome::Accepted(test) => proposed = test,
                Outcome::Tiny => proposed = Some(Termination::ParameterTolerance),
                Outcome::Stop(t) => {
                    self.summary.termination = t;
                    break;
                }
            }
        }
        self.summary.final_cost = self.cost;
        Ok(())
    }

    /// The stationarity check of the stop `test` proposes at `point`
    /// ([`check_stop`]): the termination, or None to go on.
    fn check(&mut self, test: Termination, point: &Point) -> Option<Termination> {
        let at = (self.cost, point.x_norm);
        let (o, sys) = (self.o, &self.sys);
        check_stop(test, &mut self.structure, sys, &point.curvature, &point.g, at, o, &mut self.summary)
    }

    /// Assemble the normal equations at the current point: its gradient,
    /// scaled gradient and damping scale.
    fn assemble(&mut self, strategy: &mut TrustRegion) -> Point {
        let t = Instant::now();
        self.structure.assemble_into(&self.lins, &mut self.sys);
        self.sys_current = true;
        self.summary.time_build += t.elapsed().as_secs_f64();
        let g: Vec<f64> = self.sys.g.iter().copied().chain(self.sys.gl.iter().copied()).collect();
        let gmax = g.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let raw_diag = self.structure.diagonal(&self.sys);
        self.summary.scaled_gradient = scaled_gradient(&g, &raw_diag, self.cost);
        self.summary.max_gradient = gmax;
        let diag = strategy.scale(&raw_diag, self.o);
        let x_norm =
            self.free.iter().map(|&v| self.vars[v].params_dyn().iter().map(|p| p * p).sum::<f64>()).sum::<f64>().sqrt();
        Point { g, g_max: gmax, diag, curvature: raw_diag, x_norm }
    }

    /// One iteration: damped steps until one is accepted, or the strategy gives up.
    fn iterate(&mut self, p: &Point, strategy: &mut TrustRegion) -> Result<Outcome, SolveError> {
        let o = self.o;
        let defer = o.check_stationarity && !strategy.undamped();
        let mut chord_allowed = o.reuse_factorization;
        loop {
            let damping = strategy.damping(&p.diag);
            let chord = if chord_allowed { self.chord_step(p, damping.as_deref()) } else { None };
            // A chord step rejected or bounded is retried with a new factorization.
            chord_allowed &= chord.is_none();
            let (delta, hd) = match chord {
                Some(step) => step,
                None => {
                    match linear_step(&mut self.structure, &self.sys, damping.as_deref(), None, &mut self.summary) {
                        Ok(d) => {
                            let hd = self.structure.h_times(&self.sys, &d);
                            (d, hd)
                        }
                        Err(e) if strategy.undamped() => return Err(e),
                        Err(_) => match strategy.grow(o) {
                            Ok(()) => continue,
                            Err(DampingExhausted) => return Ok(Outcome::Stop(Termination::NoProgress)),
                        },
                    }
                }
            };
            let scaled_len = delta.iter().zip(&p.diag).map(|(v, d)| v * v * d).sum::<f64>().sqrt();
            let mu = delta.iter().zip(&hd).map(|(a, b)| a * b).sum::<f64>() / (scaled_len * scaled_len);
            match strategy.bound(scaled_len, mu, o) {
                Ok(true) => continue,
                Ok(false) => {}
                Err(DampingExhausted) => return Ok(Outcome::Stop(Termination::NoProgress)),
            }
            let predicted = predicted_decrease(&delta, &p.g, &hd);
            if self.model_says_stop(predicted, strategy) {
                return Ok(Outcome::Stop(Termination::FunctionTolerance));
            }
            let step_norm = delta.iter().map(|v| v * v).sum::<f64>().sqrt();
            let small_step = step_norm <= o.parameter_tolerance * (p.x_norm + o.parameter_tolerance);
            let trial_cost = self.try_step(&delta);
            let linearized = trial_cost.is_some();
            let (new_cost, accepted, rho) = match trial_cost {
                Some(c) => {
                    let rho = if predicted > 0.0 { (self.cost - c) / predicted } else { -1.0 };
                    (c, strategy.undamped() || (c < self.cost && rho > o.min_gain_ratio), rho)
                }
                None => (f64::INFINITY, false, -1.0),
            };
            if o.log_iterations {
                self.summary.log.push(IterationLog {
                    iteration: self.summary.iterations,
                    cost: if accepted { new_cost } else { self.cost },
                    lambda: strategy.lambda,
                    step_norm,
                    gain_ratio: rho,
                    accepted,
                });
            }
            strategy.update_radius(accepted, rho, scaled_len, o);
            if accepted && linearized {
                strategy.accept(rho, o);
                return Ok(self.accept(new_cost, small_step, defer));
            }
            if small_step {
                return Ok(if defer { Outcome::Tiny } else { Outcome::Stop(Termination::ParameterTolerance) });
            }
            if strategy.grow(o).is_err() {
                return Ok(Outcome::Stop(Termination::NoProgress));
            }
        }
    }

    /// The chord step from the last factorization ([`Structure::chord_step`])
    /// and its `Hδ`, where it serves as well as a new factorization's step:
    /// along its line it gains `1 − e²` of the best decrease, `e = μ − 1`
    /// the difference between the current system and the factored one along
    /// it, and what it leaves, `e²/(1 − e²)` × its model decrease, must be
    /// within `function_tolerance` × the cost (so the steps that end a
    /// solve end it as the exact ones would) and e² at most
    /// [`CHORD_MAX_LOSS`]. None to factorize.
    fn chord_step(&mut self, p: &Point, damping: Option<&[f64]>) -> Option<(Vec<f64>, Vec<f64>)> {
        let t = Instant::now();
        let mu_max = 1.0 + CHORD_MAX_LOSS.sqrt();
        let step = self.structure.chord_step(&self.sys, damping, (self.lins.model_value(), mu_max));
        self.summary.time_solve += t.elapsed().as_secs_f64();
        let (delta, hd, mu) = step?;
        let predicted = predicted_decrease(&delta, &p.g, &hd);
        let e2 = (mu - 1.0).powi(2);
        let undone = e2 / (1.0 - e2) * predicted;
        (predicted > 0.0 && e2 <= CHORD_MAX_LOSS && undone <= self.o.function_tolerance * self.cost).then(|| {
            self.summary.linear_solves += 1;
            (delta, hd)
        })
    }

    /// [`LmOptions::stop_on_predicted_decrease`]: whether a step of model
    /// decrease `predicted`, no more damped than the first, gains too little
    /// to be tried.
    fn model_says_stop(&self, predicted: f64, strategy: &TrustRegion) -> bool {
        let o = self.o;
        o.stop_on_predicted_decrease
            && (strategy.undamped() || strategy.lambda <= o.initial_lambda)
            && (0.0..=o.function_tolerance * self.cost).contains(&predicted)
    }

    /// Retract the current point by `delta` into the trial buffers and
    /// linearize there right away (with small damping nearly every step is
    /// accepted, and this is then the next iteration's linearization): its
    /// cost, None when a factor cannot be evaluated there.
    fn try_step(&mut self, delta: &[f64]) -> Option<f64> {
        let t = Instant::now();
        retract_all(self.layout, &self.structure, &self.vars, delta, &mut self.trial);
        let cost = linearize_all_into(self.entries, self.layout, &self.trial, &mut self.trial_lins).ok();
        self.summary.time_linearize += t.elapsed().as_secs_f64();
        cost
    }

    /// Move to the trial point (cost `new_cost`) and say which stop, if any,
    /// its decrease proposes (`defer`: checked at the next linearization).
    fn accept(&mut self, new_cost: f64, small_step: bool, defer: bool) -> Outcome {
        let decrease = self.cost - new_cost;
        std::mem::swap(&mut self.vars, &mut self.trial);
        std::mem::swap(&mut self.lins, &mut self.trial_lins);
        self.sys_current = false;
        self.cost = new_cost;
        let remaining = remaining_decrease(decrease, self.previous_decrease);
        self.previous_decrease = decrease;
        self.summary.remaining_decrease = remaining / self.cost.max(f64::MIN_POSITIVE);
        let test = if self.cost == 0.0 {
            return Outcome::Stop(Termination::FunctionTolerance);
        } else if small_step {
            Some(Termination::ParameterTolerance)
        } else if remaining.abs() <= self.o.function_tolerance * self.cost {
            Some(Termination::FunctionTolerance)
        } else {
            None
        };
        match test {
            Some(t) if !defer => Outcome::Stop(t),
            t => Outcome::Accepted(t),
        }
    }
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
