//! One linear solve of the minimizer, by whichever route is cheapest —
//! the last factorization where it still serves, else a new one — with the
//! summary's accounting of both.

use super::Summary;
use crate::error::SolveError;
use crate::linear::{Structure, System};
use std::time::Instant;

/// Solve `(H + diag(damping)) δ = −g` at the assembled system `sys`: from
/// the last factorization where `reuse` is `Some(enough)` and conjugate
/// gradients preconditioned with it converge (to within `enough` of the
/// exact step's model decrease, or to their relative tolerance), else by a
/// new one; the summary counts the solve and its time.
pub(super) fn linear_step(
    structure: &mut Structure,
    sys: &System,
    damping: Option<&[f64]>,
    reuse: Option<f64>,
    summary: &mut Summary,
) -> Result<Vec<f64>, SolveError> {
    summary.linear_solves += 1;
    if let Some(enough) = reuse {
        let t = Instant::now();
        let reused = structure.solve_with_last_factor(sys, damping, enough);
        summary.time_solve += t.elapsed().as_secs_f64();
        if let Some((delta, _)) = reused {
            return Ok(delta);
        }
    }
    let (delta, fs, ss, bs) = structure.solve(sys, damping)?;
    summary.factorizations += 1;
    summary.time_factorize += fs;
    summary.time_solve += ss;
    summary.time_build += bs;
    Ok(delta)
}
