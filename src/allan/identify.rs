//! Noise coefficients from an Allan deviation curve, two ways side by side
//! (IEEE Std 952-1997 annex C, IEEE Std 1554):
//!
//! σ²(τ) = 3Q²/τ² + N²/τ + (2 ln 2/π)·B² + K²·τ/3 + R²·τ²/2
//!
//! * Q quantization noise (units·s: rad for a gyro), slope −1, read at τ = √3;
//! * N white noise density (units/√Hz = angle/velocity random walk), slope −½, at τ = 1;
//! * B bias instability (units; flicker floor ÷ 0.664), slope 0;
//! * K rate random walk (units·√Hz, i.e. units/√s), slope +½, at τ = 3;
//! * R rate ramp (units/s), slope +1, at τ = √2.
//!
//! **Read-offs**: each coefficient from the part of the curve whose local
//! log-log slope matches its term (within ±0.1), with the interval of the
//! point read. A term whose slope never appears is not reported.
//!
//! **Fit**: weighted least squares on σ² with non-negative coefficients
//! (every subset of terms is tried; the best feasible one wins). Weights are
//! the inverse variances of the σ² estimates, edf/(2σ⁴) from the model, shared
//! among the points of each octave (points closer than an octave are strongly
//! correlated, so one octave counts as one measurement). The covariance is
//! scaled by χ²/dof when the model fits worse than the noise allows. A term is
//! *supported* only when its σ² contribution exceeds twice its standard error;
//! unsupported terms are dropped and the rest refitted. Intervals are 95 %.
//!
//! In particular no bias instability is reported where the curve only bends
//! between the −½ and +½ slopes (the crossing of the N and K lines): there
//! the B term is not significant and both methods leave it out.

use super::{AllanCurve, DeviationKind};
use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

/// Names of the five terms, in order.
pub const TERM_NAMES: [&str; 5] = ["Q", "N", "B", "K", "R"];

/// Two-sided normal quantile of the coefficient intervals (95 %).
const Z95: f64 = 1.959_964;

/// A coefficient with its interval.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Coefficient {
    /// Estimate.
    pub value: f64,
    /// Lower end of the interval.
    pub lo: f64,
    /// Upper end of the interval.
    pub hi: f64,
}

/// The five coefficients; `None` where the data does not support the term.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[allow(non_snake_case)]
pub struct NoiseTerms {
    /// Quantization noise (units·s).
    pub Q: Option<Coefficient>,
    /// White noise density (units/√Hz).
    pub N: Option<Coefficient>,
    /// Bias instability (units).
    pub B: Option<Coefficient>,
    /// Rate random walk (units/√s).
    pub K: Option<Coefficient>,
    /// Rate ramp (units/s).
    pub R: Option<Coefficient>,
}

impl NoiseTerms {
    /// Coefficient by index in [`TERM_NAMES`] order.
    pub fn get(&self, k: usize) -> Option<Coefficient> {
        [self.Q, self.N, self.B, self.K, self.R][k]
    }

    fn set(&mut self, k: usize, c: Option<Coefficient>) {
        match k {
            0 => self.Q = c,
            1 => self.N = c,
            2 => self.B = c,
            3 => self.K = c,
            _ => self.R = c,
        }
    }

    /// The model σ(τ) of these terms (missing terms count as zero).
    pub fn model_dev(&self, tau: f64) -> f64 {
        let b = basis(tau);
        (0..5).map(|k| self.get(k).map_or(0.0, |c| c.value * c.value) * b[k]).sum::<f64>().sqrt()
    }
}

/// Both identifications of one axis.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Identification {
    /// Weighted non-negative least-squares fit.
    pub fit: NoiseTerms,
    /// IEEE read-offs.
    pub readoff: NoiseTerms,
    /// Terms the fit finds significant.
    pub supported: Vec<String>,
    /// Why each other term is left out, and other remarks.
    pub notes: Vec<String>,
    /// χ²/dof of the fit with the effective (octave-shared) weights.
    pub fit_chi2_dof: f64,
}

/// σ² per unit coefficient² of each term at τ.
pub fn basis(tau: f64) -> [f64; 5] {
    [3.0 / (tau * tau), 1.0 / tau, 2.0 * std::f64::consts::LN_2 / std::f64::consts::PI, tau / 3.0, tau * tau / 2.0]
}

/// Slope of each term in log σ vs log τ.
const SLOPES: [f64; 5] = [-1.0, -0.5, 0.0, 0.5, 1.0];

/// Identify the noise terms of an Allan (overlapping or not) deviation curve.
pub fn identify(curve: &AllanCurve) -> Result<Identification, super::AllanError> {
    if !matches!(curve.kind, DeviationKind::Oadev | DeviationKind::Adev) {
        return Err(super::AllanError(format!(
            "noise identification needs an Allan deviation curve, not the {}",
            curve.kind.name()
        )));
    }
    let pts: Vec<usize> = (0..curve.tau.len()).filter(|&i| curve.edf[i] >= 1.0 && curve.dev[i] > 0.0).collect();
    if pts.len() < 3 {
        return Err(super::AllanError(format!("only {} usable τ points; the record is too short", pts.len())));
    }
    let mut notes = Vec::new();
    let (fit, supported, chi2) = fit_terms(curve, &pts, &mut notes);
    let readoff = read_off(curve, &pts, &fit, &mut notes);
    Ok(Identification { fit, readoff, supported, notes, fit_chi2_dof: chi2 })
}

/// A weighted NNLS solution: θ (σ² per term, zeros for inactive terms), the
/// covariance of the active terms (in `cols` order), and χ².
type NnlsSolution = (Vec<f64>, DMatrix<f64>, Vec<usize>, f64);

/// Solve the weighted NNLS problem over the allowed terms.
fn nnls(a: &DMatrix<f64>, b: &DVector<f64>, w: &DVector<f64>, allowed: &[bool; 5]) -> Option<NnlsSolution> {
    let mut best: Option<NnlsSolution> = None;
    for mask in 1u32..32 {
        let cols: Vec<usize> = (0..5).filter(|&k| mask & (1 << k) != 0).collect();
        if cols.iter().any(|&k| !allowed[k]) || cols.len() > b.len() {
            continue;
        }
        // Column scaling for conditioning (the basis spans many decades).
        let scale: Vec<f64> = cols
            .iter()
            .map(|&k| (0..b.len()).map(|i| w[i] * a[(i, k)] * a[(i, k)]).sum::<f64>().sqrt().max(1e-300))
            .collect();
        let p = cols.len();
        let mut ata = DMatrix::zeros(p, p);
        let mut atb = DVector::zeros(p);
        for i in 0..b.len() {
            for (r, &kr) in cols.iter().enumerate() {
                let ar = a[(i, kr)] / scale[r];
                atb[r] += w[i] * ar * b[i];
                for (c, &kc) in cols.iter().enumerate() {
                    ata[(r, c)] += w[i] * ar * a[(i, kc)] / scale[c];
                }
            }
        }
        let Some(inv) = ata.clone().try_inverse() else { continue };
        let sol: DVector<f64> = &inv * &atb;
        if sol.iter().any(|&v| v < 0.0 || !v.is_finite()) {
            continue;
        }
        let mut theta = vec![0.0; 5];
        for (r, &k) in cols.iter().enumerate() {
            theta[k] = sol[r] / scale[r];
        }
        let chi2: f64 = (0..b.len())
            .map(|i| {
                let pred: f64 = (0..5).map(|k| a[(i, k)] * theta[k]).sum();
                w[i] * (b[i] - pred).powi(2)
            })
            .sum();
        let mut cov = DMatrix::zeros(p, p);
        for r in 0..p {
            for c in 0..p {
                cov[(r, c)] = inv[(r, c)] / (scale[r] * scale[c]);
            }
        }
        if best.as_ref().is_none_or(|bst| chi2 < bst.3) {
            best = Some((theta, cov, cols, chi2));
        }
    }
    best
}

fn fit_terms(curve: &AllanCurve, pts: &[usize], notes: &mut Vec<String>) -> (NoiseTerms, Vec<String>, f64) {
    let n = pts.len();
    let a = DMatrix::from_fn(n, 5, |i, k| basis(curve.tau[pts[i]])[k]);
    let b = DVector::from_fn(n, |i, _| curve.dev[pts[i]].powi(2));
    // Share of each point in its octave.
    let share: Vec<f64> = pts
        .iter()
        .map(|&i| {
            let c = pts.iter().filter(|&&j| (curve.tau[j] / curve.tau[i]).log2().abs() < 0.5).count();
            1.0 / c as f64
        })
        .collect();
    let effective_points: f64 = share.iter().sum();
    let mut allowed = [true; 5];
    let mut model: Vec<f64> = b.iter().copied().collect();
    let mut result = None;
    for _round in 0..5 {
        // Reweight from the model a few times (weights from the data would bias the fit low).
        // Points far off the model by their own uncertainty (a vibration
        // hump, a temperature transient) are down-weighted (Cauchy, scale 3σ)
        // so they cannot hide the terms the rest of the curve shows.
        let mut sol = None;
        let mut robust = vec![1.0; n];
        let mut w = DVector::zeros(n);
        for _ in 0..6 {
            w = DVector::from_fn(n, |i, _| {
                curve.edf[pts[i]] / (2.0 * model[i].max(1e-300).powi(2)) * share[i] * robust[i]
            });
            let Some(s) = nnls(&a, &b, &w, &allowed) else { break };
            for (i, m) in model.iter_mut().enumerate() {
                let pred: f64 = (0..5).map(|k| a[(i, k)] * s.0[k]).sum();
                *m = if pred > 0.0 { pred } else { b[i] };
                let r = (b[i] - *m) / (*m * (2.0 / curve.edf[pts[i]]).sqrt());
                robust[i] = 1.0 / (1.0 + (r / 3.0).powi(2));
            }
            sol = Some(s);
        }
        let Some((theta, bread, cols, chi2)) = sol else { break };
        let cov = sandwich(&a, &bread, &cols, &model, curve, pts, w.as_slice());
        let dof = (effective_points - cols.len() as f64).max(1.0);
        let inflate = (chi2 / dof).max(1.0);
        // Drop the least significant unsupported term, if any, and refit.
        let mut worst: Option<(usize, f64)> = None;
        for (r, &k) in cols.iter().enumerate() {
            let sd = (cov[(r, r)] * inflate).max(0.0).sqrt();
            let z = theta[k] / sd.max(1e-300);
            if z < 2.0 && worst.is_none_or(|(_, wz)| z < wz) {
                worst = Some((k, z));
            }
        }
        let n_cols = cols.len();
        result = Some((theta, cov, cols, chi2 / dof, inflate));
        match worst {
            Some((k, z)) if n_cols > 1 => {
                let (theta, _, _, _, _) = result.as_ref().unwrap();
                notes.push(format!(
                    "fit: {} not supported (its σ² term {:.3e} is only {:.1} standard errors from zero)",
                    TERM_NAMES[k], theta[k], z
                ));
                allowed[k] = false;
            }
            _ => break,
        }
    }
    let mut terms = NoiseTerms::default();
    let mut supported = Vec::new();
    let mut chi2_dof = f64::NAN;
    if let Some((theta, cov, cols, c2, inflate)) = result {
        chi2_dof = c2;
        for (r, &k) in cols.iter().enumerate() {
            let sd = (cov[(r, r)] * inflate).max(0.0).sqrt();
            let v = theta[k];
            terms.set(
                k,
                Some(Coefficient { value: v.sqrt(), lo: (v - Z95 * sd).max(0.0).sqrt(), hi: (v + Z95 * sd).sqrt() }),
            );
            supported.push(TERM_NAMES[k].to_string());
        }
        for (k, name) in TERM_NAMES.iter().enumerate() {
            if allowed[k] && !cols.contains(&k) {
                notes.push(format!("fit: {name} not supported (its best non-negative value is zero)"));
            }
        }
        if c2 > 3.0 {
            notes.push(format!(
                "fit: χ²/dof = {c2:.1}: the five-term model does not describe this curve fully (intervals are widened by √{c2:.1})"
            ));
        }
    }
    (terms, supported, chi2_dof)
}

/// Exponent γ of the assumed correlation (τ_small/τ_large)^γ between Allan
/// variance estimates at two τ (γ = ½: 0.71 between neighbouring octaves).
/// Overlapping estimates at nearby τ share most of their data; the value is
/// on the conservative side of what random-walk and white noise give.
const CORRELATION_EXPONENT: f64 = 0.5;

/// Covariance of the weighted fit when the σ² estimates are correlated:
/// (AᵀWA)⁻¹ AᵀW Σ W A (AᵀWA)⁻¹ with W the weights the fit used and Σ from
/// conservative EDFs and the correlation model.
fn sandwich(
    a: &DMatrix<f64>,
    bread: &DMatrix<f64>,
    cols: &[usize],
    model: &[f64],
    curve: &AllanCurve,
    pts: &[usize],
    w: &[f64],
) -> DMatrix<f64> {
    let n = pts.len();
    let p = cols.len();
    // The σ² estimates' spread from the smallest EDF any single noise type
    // would give at that τ: the identified type is only the dominant one,
    // and a mixture (quantization under white noise, say) has fewer
    // degrees of freedom than the dominant type alone.
    let sd: Vec<f64> = (0..n).map(|i| model[i] * (2.0 / conservative_edf(curve, pts[i])).sqrt()).collect();
    // G = W A (n × p)
    let g = DMatrix::from_fn(n, p, |i, c| w[i] * a[(i, cols[c])]);
    let mut meat = DMatrix::zeros(p, p);
    for i in 0..n {
        for j in 0..n {
            let (ti, tj) = (curve.tau[pts[i]], curve.tau[pts[j]]);
            let rho = (ti.min(tj) / ti.max(tj)).powf(CORRELATION_EXPONENT);
            let sij = rho * sd[i] * sd[j];
            for r in 0..p {
                for c in 0..p {
                    meat[(r, c)] += g[(i, r)] * sij * g[(j, c)];
                }
            }
        }
    }
    bread * meat * bread
}

/// The smallest Greenhall EDF over the noise types α = +2 … −2 at point i.
fn conservative_edf(curve: &AllanCurve, i: usize) -> f64 {
    let m = curve.m[i];
    let overlapping = curve.kind == DeviationKind::Oadev;
    // Phase points from the number of terms of the estimator.
    let n_phase = if overlapping { curve.n_terms[i] + 2 * m } else { (curve.n_terms[i] + 1) * m + 1 };
    (-2..=2)
        .map(|alpha| super::edf::edf_greenhall(alpha, 2, m, n_phase, overlapping, false))
        .fold(curve.edf[i], f64::min)
}

/// Local log-log slope at each point, from the points within ±0.15 decade.
fn local_slopes(curve: &AllanCurve, pts: &[usize]) -> Vec<Option<f64>> {
    pts.iter()
        .map(|&i| {
            let near: Vec<(f64, f64)> = pts
                .iter()
                .filter(|&&j| (curve.tau[j] / curve.tau[i]).log10().abs() <= 0.15)
                .map(|&j| (curve.tau[j].log10(), curve.dev[j].log10()))
                .collect();
            if near.len() < 3 {
                return None;
            }
            let mx = near.iter().map(|p| p.0).sum::<f64>() / near.len() as f64;
            let my = near.iter().map(|p| p.1).sum::<f64>() / near.len() as f64;
            let sxx: f64 = near.iter().map(|p| (p.0 - mx).powi(2)).sum();
            let sxy: f64 = near.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
            (sxx > 0.0).then(|| sxy / sxx)
        })
        .collect()
}

fn read_off(curve: &AllanCurve, pts: &[usize], fit: &NoiseTerms, notes: &mut Vec<String>) -> NoiseTerms {
    let slopes = local_slopes(curve, pts);
    let mut terms = NoiseTerms::default();
    // The value of each term's line through a point (σ, τ).
    let through = |k: usize, sigma: f64, tau: f64| -> f64 {
        match k {
            0 => sigma * tau / 3f64.sqrt(),
            1 => sigma * tau.sqrt(),
            2 => sigma / 0.664,
            3 => sigma * (3.0 / tau).sqrt(),
            _ => sigma * 2f64.sqrt() / tau,
        }
    };
    for k in 0..5 {
        let pick = if k == 2 {
            // The floor, only when the fit finds a flicker term (otherwise
            // the minimum is just where N meets K).
            if fit.B.is_none() {
                notes.push("read-off: no bias-instability floor (the minimum is only where the white-noise and random-walk lines cross)".into());
                continue;
            }
            // The lowest point where the curve is flat (slope within ±0.1).
            pts.iter()
                .zip(&slopes)
                .filter(|(_, s)| s.is_some_and(|s| s.abs() <= 0.1))
                .map(|(&i, _)| i)
                .min_by(|&i, &j| curve.dev[i].total_cmp(&curve.dev[j]))
        } else {
            // Among the points on this term's slope, the one with most degrees of freedom.
            pts.iter()
                .zip(&slopes)
                .filter(|(_, s)| s.is_some_and(|s| (s - SLOPES[k]).abs() <= 0.1))
                .map(|(&i, _)| i)
                .max_by(|&i, &j| curve.edf[i].total_cmp(&curve.edf[j]))
        };
        match pick {
            Some(i) => terms.set(
                k,
                Some(Coefficient {
                    value: through(k, curve.dev[i], curve.tau[i]),
                    lo: through(k, curve.dev_lo[i], curve.tau[i]),
                    hi: through(k, curve.dev_hi[i], curve.tau[i]),
                }),
            ),
            None => {
                notes.push(format!("read-off: no part of the curve has the slope {:+} of {}", SLOPES[k], TERM_NAMES[k]))
            }
        }
    }
    terms
}
