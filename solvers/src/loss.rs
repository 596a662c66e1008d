//! Robust losses ρ(s) of the squared whitened residual norm s = ‖r‖², and the
//! Triggs correction that folds them into a Gauss–Newton step (as Ceres does).

use nalgebra::{DMatrix, DVector};
use std::fmt::Debug;

/// A robust loss: returns `[ρ(s), ρ'(s), ρ''(s)]` for `s ≥ 0`, with ρ(0) = 0
/// and ρ'(0) = 1 so that small residuals are treated as by least squares.
pub trait RobustLoss: Debug + Send + Sync {
    /// `[ρ(s), ρ'(s), ρ''(s)]`.
    fn evaluate(&self, s: f64) -> [f64; 3];
}

/// Huber loss with threshold δ (in whitened units):
/// ρ(s) = s for s ≤ δ², 2δ√s − δ² otherwise.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Huber(pub f64);

/// Cauchy loss with scale c: ρ(s) = c² ln(1 + s/c²).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Cauchy(pub f64);

/// Tukey biweight with scale c: ρ(s) = c²/3 (1 − (1 − s/c²)³) for s ≤ c², c²/3 beyond.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Tukey(pub f64);

impl RobustLoss for Huber {
    fn evaluate(&self, s: f64) -> [f64; 3] {
        let d = self.0;
        if s <= d * d {
            [s, 1.0, 0.0]
        } else {
            let r = s.sqrt();
            [2.0 * d * r - d * d, d / r, -d / (2.0 * s * r)]
        }
    }
}

impl RobustLoss for Cauchy {
    fn evaluate(&self, s: f64) -> [f64; 3] {
        let c2 = self.0 * self.0;
        let sum = 1.0 + s / c2;
        let inv = 1.0 / sum;
        [c2 * sum.ln(), inv, -inv * inv / c2]
    }
}

impl RobustLoss for Tukey {
    fn evaluate(&self, s: f64) -> [f64; 3] {
        let c2 = self.0 * self.0;
        if s <= c2 {
            let v = 1.0 - s / c2;
            [c2 / 3.0 * (1.0 - v * v * v), v * v, -2.0 / c2 * v]
        } else {
            [c2 / 3.0, 0.0, 0.0]
        }
    }
}

/// Apply the Triggs correction (Ceres' `Corrector`) to a whitened residual and
/// its Jacobian blocks so that ½‖r'‖² linearizes ½ρ(‖r‖²). Returns ρ(s).
pub fn apply_robust(loss: &dyn RobustLoss, r: &mut DVector<f64>, jacobians: &mut [DMatrix<f64>]) -> f64 {
    let s = r.norm_squared();
    let [rho, rho1, rho2] = loss.evaluate(s);
    if rho1 <= 0.0 {
        // Fully down-weighted (e.g. Tukey beyond c): contributes nothing to the step.
        r.fill(0.0);
        for j in jacobians.iter_mut() {
            j.fill(0.0);
        }
        return rho;
    }
    let sqrt_rho1 = rho1.sqrt();
    let (scaling, alpha_sq_norm) = if s == 0.0 || rho2 <= 0.0 {
        (sqrt_rho1, 0.0)
    } else {
        let d = 1.0 + 2.0 * s * rho2 / rho1;
        let alpha = 1.0 - d.sqrt();
        (sqrt_rho1 / (1.0 - alpha), alpha / s)
    };
    for j in jacobians.iter_mut() {
        if alpha_sq_norm != 0.0 {
            let rt_j = r.transpose() * &*j;
            *j -= (&*r * rt_j) * alpha_sq_norm;
        }
        *j *= sqrt_rho1;
    }
    *r *= scaling;
    rho
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn derivatives_match_numeric() {
        let losses: [&dyn RobustLoss; 3] = [&Huber(1.3), &Cauchy(0.7), &Tukey(2.0)];
        for l in losses {
            for s in [0.1, 0.9, 1.5, 3.0, 10.0] {
                let h = 1e-6;
                let [_, d1, d2] = l.evaluate(s);
                let num1 = (l.evaluate(s + h)[0] - l.evaluate(s - h)[0]) / (2.0 * h);
                let num2 = (l.evaluate(s + h)[1] - l.evaluate(s - h)[1]) / (2.0 * h);
                assert_relative_eq!(d1, num1, epsilon = 1e-6);
                assert_relative_eq!(d2, num2, epsilon = 1e-5);
            }
            assert_relative_eq!(l.evaluate(0.0)[1], 1.0);
        }
    }

    #[test]
    fn huber_matches_issue_definition() {
        let h = Huber(2.0);
        assert_relative_eq!(h.evaluate(3.0)[0], 3.0);
        assert_relative_eq!(h.evaluate(9.0)[0], 2.0 * 2.0 * 3.0 - 4.0);
    }
}
