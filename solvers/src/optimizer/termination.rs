//! When a solve may stop: the scaled gradient, the decrease still to come,
//! and the check that a proposed stop is at a minimum.

use super::linear_step::linear_step;
use super::{LmOptions, Summary, Termination};
use crate::linear::{Structure, System};

/// Damping (relative to diag H) of the Gauss–Newton step that checks a
/// small decrease: small enough to leave the step undamped, large enough to
/// keep a semi-definite H factorizable.
const GAUSS_NEWTON_CHECK_DAMPING: f64 = 1e-12;

/// How closely the check of a cost test needs the decrease to come, as a
/// fraction of the tolerance (`function_tolerance` × cost) it is compared
/// with: a solve from the last factorization may stop once what it has not
/// yet found is below this share. The relative accuracy of a converged solve
/// (10⁻⁸ of the decrease) is far more than that decision needs when the
/// decrease is already well below the tolerance, and each further iteration
/// costs a pair of triangular solves.
const DECREASE_ACCURACY: f64 = 1e-3;

/// The largest cosine of the angle between the whitened residual (cost
/// `cost` = ½‖r‖²) and a Jacobian column: `|g_j| / sqrt(H_jj · 2 cost)`, with
/// `g = Jᵀr` and `H_jj = ‖J_j‖²` (0 where a column or the residual vanishes).
pub(super) fn scaled_gradient(g: &[f64], diag: &[f64], cost: f64) -> f64 {
    let r2 = 2.0 * cost;
    g.iter()
        .zip(diag)
        .map(|(gj, hj)| if *hj > 0.0 && r2 > 0.0 { gj.abs() / (hj * r2).sqrt() } else { 0.0 })
        .fold(0.0, f64::max)
}

/// The decrease still to come after an accepted step that lowered the cost
/// by `decrease` (the one before by `previous`, NaN for the first): the
/// geometric series of the two when they shrink, else the decrease itself.
pub(super) fn remaining_decrease(decrease: f64, previous: f64) -> f64 {
    let q = decrease / previous;
    if q > 0.0 && q < 1.0 {
        decrease * q / (1.0 - q)
    } else {
        decrease
    }
}

/// Predicted decrease −gᵀδ − ½ δᵀHδ of step `delta`, given `hd` = Hδ.
pub(super) fn predicted_decrease(delta: &[f64], g: &[f64], hd: &[f64]) -> f64 {
    -delta.iter().zip(g).map(|(a, b)| a * b).sum::<f64>() - 0.5 * delta.iter().zip(hd).map(|(a, b)| a * b).sum::<f64>()
}

/// The stationarity check ([`LmOptions::check_stationarity`]) of a stop that
/// `test` proposes at the assembled system `sys` (cost `cost`, parameter
/// norm `x_norm`, current curvature `diag`, diag H): the termination to end the solve
/// with, or `None` to go on with damped steps.
///
/// - A cost at the rounding level of the start's residuals (`ε²` times the
///   start's cost: each residual `ε` times the start's) is a zero-residual
///   fit: converged. (A singular one, whose solution is `x = 0`, would
///   otherwise creep on with steps that never get small against `x`.)
/// - The squared scaled gradient within `function_tolerance` bounds the
///   relative decrease to come from below whatever a solve's accuracy, and a
///   column that has all but vanished (a saturated parameter, below the
///   damping floor) still shows. A small damped step needs no more: at a
///   first-order stationary point the undamped model can still promise a
///   decrease along directions where the columns cancel (identical columns
///   at a symmetric minimum), which no step delivers. Where it fails, a cost
///   test or a small gradient goes on.
/// - Otherwise one undamped solve decides: a cost test or a small gradient
///   stops where its predicted decrease (or its step) is within the
///   tolerances; a small damped step stops where the undamped step is small
///   too (a zero-residual fit converging, whose residual stays aligned with
///   the columns) and is a [`Termination::Stalled`] where it is not (the
///   damping, not the minimum, made the step small).
#[allow(clippy::too_many_arguments)]
pub(super) fn check_stop(
    test: Termination,
    structure: &mut Structure,
    sys: &System,
    diag: &[f64],
    g: &[f64],
    (cost, x_norm): (f64, f64),
    o: &LmOptions,
    summary: &mut Summary,
) -> Option<Termination> {
    if cost <= f64::EPSILON * f64::EPSILON * summary.initial_cost {
        return Some(test);
    }
    let from_small_step = test == Termination::ParameterTolerance;
    let aligned = summary.scaled_gradient.powi(2) <= o.function_tolerance;
    match (from_small_step, aligned) {
        (true, true) => return Some(test),
        (false, false) => return None,
        _ => {}
    }
    let tiny: Vec<f64> = diag.iter().map(|d| d * GAUSS_NEWTON_CHECK_DAMPING).collect();
    // A small step's check compares the step itself: it needs the solve's full accuracy.
    let enough = if from_small_step { 0.0 } else { DECREASE_ACCURACY * o.function_tolerance * cost };
    let reuse = o.reuse_factorization.then_some(enough);
    let solved = linear_step(structure, sys, Some(&tiny), reuse, summary).ok().and_then(|delta| {
        let d = predicted_decrease(&delta, g, &structure.h_times(sys, &delta));
        // ½ gᵀH⁻¹g is not negative: anything else is a numerically failed solve.
        (d.is_finite() && d >= 0.0).then(|| (d, delta.iter().map(|v| v * v).sum::<f64>().sqrt()))
    });
    let Some((d, step)) = solved else {
        // No undamped step (H singular there): the scaled gradient decided.
        return Some(if from_small_step { Termination::Stalled } else { test });
    };
    summary.gauss_newton_decrease = d / cost.max(f64::MIN_POSITIVE);
    let undamped_step_small = step <= o.parameter_tolerance * (x_norm + o.parameter_tolerance);
    if from_small_step {
        return Some(if undamped_step_small { test } else { Termination::Stalled });
    }
    (d <= o.function_tolerance * cost || undamped_step_small).then_some(test)
}
