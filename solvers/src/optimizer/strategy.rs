//! The trust-region strategy of Levenberg–Marquardt: the damping λ and its
//! updates (Nielsen's after a good step, doubling growth after a bad one),
//! the per-unknown scale D it multiplies, and MINPACK's step bound.

use super::{LmOptions, Method};

/// The damping state of one solve.
pub(super) struct TrustRegion {
    /// Damping λ (relative to the scale D).
    pub lambda: f64,
    /// Growth factor of λ after a rejected step (Nielsen's ν).
    nu: f64,
    /// Running maximum of diag H ([`LmOptions::keep_largest_scale`]).
    largest: Vec<f64>,
    /// Trust radius in the scaled norm ([`LmOptions::trust_radius`]).
    radius: f64,
    /// Undamped Gauss–Newton: every step is taken.
    gauss_newton: bool,
    /// The smallest λ after good steps ([`TrustRegion::scale`]).
    floor: f64,
}

/// The smallest damping relative to the current curvature: λ·D ≥ this · diag H
/// for every unknown after a run of good steps (then λ can still grow by
/// doubling from it within a few rejected steps).
const MIN_RELATIVE_DAMPING: f64 = 1e-16;

/// Why λ cannot grow any more: [`LmOptions::max_lambda`] passed.
pub(super) struct DampingExhausted;

impl TrustRegion {
    pub fn new(o: &LmOptions) -> TrustRegion {
        TrustRegion {
            lambda: o.initial_lambda,
            nu: 2.0,
            largest: Vec::new(),
            radius: f64::INFINITY,
            gauss_newton: o.method == Method::GaussNewton,
            floor: MIN_RELATIVE_DAMPING,
        }
    }

    /// Whether steps are undamped (Gauss–Newton).
    pub fn undamped(&self) -> bool {
        self.gauss_newton
    }

    /// The scale D of each unknown at this linearization, from its curvature
    /// `raw_diag` (diag H), clamped to the options' bounds.
    pub fn scale(&mut self, raw_diag: &[f64], o: &LmOptions) -> Vec<f64> {
        if o.keep_largest_scale {
            if self.largest.len() != raw_diag.len() {
                self.largest = raw_diag.to_vec();
            }
            for (m, d) in self.largest.iter_mut().zip(raw_diag) {
                *m = m.max(*d);
            }
        }
        let scale: Vec<f64> = if o.keep_largest_scale { &self.largest[..] } else { raw_diag }
            .iter()
            .map(|d| d.clamp(o.min_diagonal, o.max_diagonal))
            .collect();
        // λ's floor is relative to the current curvature, not to the largest
        // one kept: where a column has shrunk by orders of magnitude since the
        // start (a polynomial's far start), a floor relative to D would damp
        // it by far more than its own curvature and creep (Chebyquad from
        // ×100 its standard start: 1000 iterations of 1e-4 steps).
        let shrink = raw_diag.iter().zip(&scale).filter(|(r, _)| **r > 0.0).map(|(r, d)| r / d).fold(1.0, f64::min);
        self.floor = (MIN_RELATIVE_DAMPING * shrink).max(f64::MIN_POSITIVE);
        scale
    }

    /// The damping added to the diagonal (None for Gauss–Newton).
    pub fn damping(&self, diag: &[f64]) -> Option<Vec<f64>> {
        (!self.gauss_newton).then(|| diag.iter().map(|d| d * self.lambda).collect())
    }

    /// A step failed (not factorizable, or rejected): grow λ.
    pub fn grow(&mut self, o: &LmOptions) -> Result<(), DampingExhausted> {
        self.lambda *= self.nu;
        self.nu *= 2.0;
        if self.lambda > o.max_lambda {
            return Err(DampingExhausted);
        }
        Ok(())
    }

    /// A step of scaled length `scaled_len` longer than the radius allows:
    /// raise λ to about the value that brings the step to it (one dominant
    /// direction of scaled curvature `mu`, along which the length goes as
    /// 1 / (μ + λ)) and return true; false when the step may be tried.
    pub fn bound(&mut self, scaled_len: f64, mu: f64, o: &LmOptions) -> Result<bool, DampingExhausted> {
        if !(o.trust_radius && !self.gauss_newton && scaled_len > 1.5 * self.radius) {
            return Ok(false);
        }
        self.lambda = (2.0 * self.lambda).max((mu + self.lambda) * scaled_len / self.radius - mu);
        if self.lambda > o.max_lambda {
            return Err(DampingExhausted);
        }
        Ok(true)
    }

    /// The radius after a step of gain ratio `rho` (accepted or not) and
    /// scaled length `scaled_len`: doubled past a good one, halved after a poor one.
    pub fn update_radius(&mut self, accepted: bool, rho: f64, scaled_len: f64, o: &LmOptions) {
        if o.trust_radius {
            if accepted && rho >= 0.75 {
                self.radius = 2.0 * scaled_len;
            } else if rho < 0.25 {
                self.radius = 0.5 * self.radius.min(10.0 * scaled_len);
            }
        }
    }

    /// A step of gain ratio `rho` was accepted: shrink λ (Nielsen).
    pub fn accept(&mut self, rho: f64, o: &LmOptions) {
        if !self.gauss_newton {
            self.lambda *= o.min_lambda_decrease.max(1.0 - (2.0 * rho - 1.0).powi(3));
            self.lambda = self.lambda.max(self.floor);
            self.nu = 2.0;
        }
    }
}
