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

/// The kind of a correlated term (IEEE Std 952 annex C).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ExtraKind {
    /// Exponentially correlated (first-order Gauss–Markov) noise of standard
    /// deviation σ_m and correlation time T_c: σ²(τ) = 2σ_m²T_c/τ ·
    /// [1 − T_c/(2τ)(3 − 4e^(−τ/T_c) + e^(−2τ/T_c))] — rises like a rate random
    /// walk for τ ≪ T_c, falls like white noise for τ ≫ T_c.
    Markov,
    /// A sinusoid of amplitude Ω₀ and period P = 1/f₀ (vibration, a fan, a
    /// thermostat): σ²(τ) = Ω₀² (sin²(πτ/P)/(πτ/P))², a hump at τ ≈ 0.37 P,
    /// averaged over frequencies within ±[`SINUSOID_BANDWIDTH`] of f₀
    /// (narrow-band rather than one pure tone).
    Sinusoid,
}

impl ExtraKind {
    /// `Markov` or `sinusoid`.
    pub fn name(self) -> &'static str {
        match self {
            ExtraKind::Markov => "Markov",
            ExtraKind::Sinusoid => "sinusoid",
        }
    }
    /// What its time is.
    pub fn time_name(self) -> &'static str {
        match self {
            ExtraKind::Markov => "correlation time",
            ExtraKind::Sinusoid => "period",
        }
    }
}

/// A correlated term: its amplitude (Markov σ_m or sinusoid Ω₀, in the
/// sensor's units) with interval, and its time (Markov T_c or sinusoid period
/// P, \[s\]; chosen on a grid of 8 per decade).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ExtraTerm {
    /// Markov or sinusoid.
    pub kind: ExtraKind,
    /// σ_m or Ω₀.
    pub amplitude: Coefficient,
    /// T_c or P \[s\].
    pub time_s: f64,
}

/// Relative half-width of the frequency band a sinusoidal term spreads over.
pub const SINUSOID_BANDWIDTH: f64 = 0.25;

/// σ² per unit amplitude² of a correlated term at τ.
pub fn extra_basis(kind: ExtraKind, time: f64, tau: f64) -> f64 {
    match kind {
        ExtraKind::Markov => {
            let x = tau / time;
            if x < 1e-3 {
                // Series of the bracket: x²/3 − x³/12 …; avoids cancellation.
                2.0 / 3.0 * x * (1.0 - x / 4.0)
            } else {
                2.0 / x * (1.0 - (3.0 - 4.0 * (-x).exp() + (-2.0 * x).exp()) / (2.0 * x))
            }
        }
        ExtraKind::Sinusoid => {
            // A pure tone's σ² averaged over ±SINUSOID_BANDWIDTH of its frequency
            // (16 points): real vibration is never one frequency, and the average
            // fills the tone's zeros at τ = P, 2P, … as the data do.
            const K: usize = 16;
            (0..K)
                .map(|j| {
                    let f = (1.0 + SINUSOID_BANDWIDTH * (2.0 * (j as f64 + 0.5) / K as f64 - 1.0)) / time;
                    let u = std::f64::consts::PI * tau * f;
                    (u.sin().powi(2) / u).powi(2)
                })
                .sum::<f64>()
                / K as f64
        }
    }
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
    /// Correlated terms the fit added (Markov or sinusoid, at most
    /// [`MAX_EXTRA_TERMS`]), when the five terms do not follow the curve and
    /// each does better by BIC.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub extra: Vec<ExtraTerm>,
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
        let extra: f64 =
            self.extra.iter().map(|e| e.amplitude.value.powi(2) * extra_basis(e.kind, e.time_s, tau)).sum();
        ((0..5).map(|k| self.get(k).map_or(0.0, |c| c.value * c.value) * b[k]).sum::<f64>() + extra).sqrt()
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
    /// Whether the fitted model follows the measured curve: within the
    /// curve's interval or within [`FOLLOW_RATIO`]× at every τ from 0.1 s to
    /// a tenth of the largest τ.
    pub follows_data: bool,
    /// Where the model is furthest from the curve: `(τ [s], model / measured)`.
    pub worst_misfit: Option<(f64, f64)>,
    /// τ \[s\] of the point each read-off was read at (Q, N, B, K, R order).
    pub readoff_tau: [Option<f64>; 5],
}

/// The fitted model may differ from the measured deviation by this factor
/// (either way) where it lies outside the curve's interval.
pub const FOLLOW_RATIO: f64 = 1.3;

/// A correlated term's hump must lie this factor (half a decade) inside the
/// curve's τ range.
const HUMP_MARGIN: f64 = 3.16;

/// Correlated terms one fit may add.
pub const MAX_EXTRA_TERMS: usize = 2;

/// σ² per unit coefficient² of each term at τ.
pub fn basis(tau: f64) -> [f64; 5] {
    [3.0 / (tau * tau), 1.0 / tau, 2.0 * std::f64::consts::LN_2 / std::f64::consts::PI, tau / 3.0, tau * tau / 2.0]
}

/// Slope of each term in log σ vs log τ.
const SLOPES: [f64; 5] = [-1.0, -0.5, 0.0, 0.5, 1.0];

/// Identify the noise terms of an Allan (overlapping or not) deviation curve.
pub fn identify(curve: &AllanCurve) -> Result<Identification, super::AllanError> {
    if !matches!(curve.kind, DeviationKind::Oadev | DeviationKind::Adev) {
        return Err(super::AllanError::Invalid(format!(
            "noise identification needs an Allan deviation curve, not the {}",
            curve.kind.name()
        )));
    }
    let pts: Vec<usize> = (0..curve.tau.len()).filter(|&i| curve.edf[i] >= 1.0 && curve.dev[i] > 0.0).collect();
    if pts.len() < 3 {
        return Err(super::AllanError::Invalid(format!("only {} usable τ points; the record is too short", pts.len())));
    }
    let mut notes = Vec::new();
    let best = fit_best(curve, &pts, &mut notes);
    let (readoff, readoff_tau) = read_off(curve, &pts, &best.terms, &mut notes);
    let (follows_data, worst_misfit) = follows(curve, &pts, &best.terms);
    if let (false, Some((tau, ratio))) = (follows_data, worst_misfit) {
        notes.push(format!(
            "fit: the model does not follow the measured curve: {ratio:.2}× the data at τ = {tau:.3} s, outside \
             its interval"
        ));
    }
    Ok(Identification {
        fit: best.terms,
        readoff,
        supported: best.supported,
        notes,
        fit_chi2_dof: best.chi2_dof,
        follows_data,
        worst_misfit,
        readoff_tau,
    })
}

/// A weighted NNLS solution: θ (σ² per term, zeros for inactive terms), the
/// covariance of the active terms (in `cols` order), and χ².
type NnlsSolution = (Vec<f64>, DMatrix<f64>, Vec<usize>, f64);

/// Solve the weighted NNLS problem over the allowed terms (columns of `a`).
fn nnls(a: &DMatrix<f64>, b: &DVector<f64>, w: &DVector<f64>, allowed: &[bool]) -> Option<NnlsSolution> {
    let nt = a.ncols();
    let mut best: Option<NnlsSolution> = None;
    for mask in 1u32..(1 << nt) {
        let cols: Vec<usize> = (0..nt).filter(|&k| mask & (1 << k) != 0).collect();
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
        let mut theta = vec![0.0; nt];
        for (r, &k) in cols.iter().enumerate() {
            theta[k] = sol[r] / scale[r];
        }
        let chi2: f64 = (0..b.len())
            .map(|i| {
                let pred: f64 = (0..nt).map(|k| a[(i, k)] * theta[k]).sum();
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

/// Relative error of σ² a model of a real sensor's curve is allowed at every
/// τ (5 % in σ), added to the estimate's own, once the five terms have failed
/// to follow the curve: the curve then holds structure no term describes
/// exactly, and without the floor the shortest τ, whose estimates carry a
/// million degrees of freedom, would decide the fit by the sensor's
/// anti-alias filter alone. The intervals stay honest for any weights (the
/// sandwich covariance).
const MODEL_FLOOR: f64 = 0.1;

/// Weight of a σ² estimate with `edf` degrees of freedom around the model
/// value `m` (with [`MODEL_FLOOR`] when `floor`).
fn weight(edf: f64, m: f64, floor: bool) -> f64 {
    let rel = 2.0 / edf + if floor { MODEL_FLOOR * MODEL_FLOOR } else { 0.0 };
    1.0 / (m.max(1e-300).powi(2) * rel)
}

/// What one fit of the terms (the five, and possibly a correlated one) found.
struct FitOutcome {
    terms: NoiseTerms,
    supported: Vec<String>,
    notes: Vec<String>,
    /// χ²/dof with the fit's own (robust, octave-shared) weights.
    chi2_dof: f64,
    /// χ² without the robust down-weighting, for comparing models (BIC).
    chi2_plain: f64,
    /// Effective number of points (octave-shared).
    n_eff: f64,
    /// Free parameters: active coefficients, plus the correlated term's time.
    params: usize,
}

impl FitOutcome {
    /// Bayesian information criterion (smaller is better).
    fn bic(&self) -> f64 {
        self.chi2_plain + self.params as f64 * self.n_eff.max(1.0).ln()
    }
}

fn fit_terms(curve: &AllanCurve, pts: &[usize], extra: &[(ExtraKind, f64)], floor: bool) -> FitOutcome {
    let mut notes = Vec::new();
    let n = pts.len();
    let nt = 5 + extra.len();
    let a = DMatrix::from_fn(n, nt, |i, k| {
        let tau = curve.tau[pts[i]];
        match extra.get(k.wrapping_sub(5)) {
            Some(&(kind, time)) if k >= 5 => extra_basis(kind, time, tau),
            _ => basis(tau)[k],
        }
    });
    let name = |k: usize| if k < 5 { TERM_NAMES[k] } else { "a correlated term" };
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
    let mut allowed = vec![true; nt];
    let mut model: Vec<f64> = b.iter().copied().collect();
    let mut result = None;
    for _round in 0..nt {
        // Reweight from the model a few times (weights from the data would bias the fit low).
        // Points far off the model by their own uncertainty (a vibration
        // hump, a temperature transient) are down-weighted (Cauchy, scale 3σ)
        // so they cannot hide the terms the rest of the curve shows.
        let mut sol = None;
        let mut robust = vec![1.0; n];
        let mut w = DVector::zeros(n);
        for _ in 0..6 {
            w = DVector::from_fn(n, |i, _| weight(curve.edf[pts[i]], model[i], floor) * share[i] * robust[i]);
            let Some(s) = nnls(&a, &b, &w, &allowed) else { break };
            for (i, m) in model.iter_mut().enumerate() {
                let pred: f64 = (0..nt).map(|k| a[(i, k)] * s.0[k]).sum();
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
                    name(k),
                    theta[k],
                    z
                ));
                allowed[k] = false;
            }
            _ => break,
        }
    }
    let mut terms = NoiseTerms::default();
    let mut supported = Vec::new();
    let mut chi2_dof = f64::NAN;
    let mut chi2_plain = f64::INFINITY;
    let mut params = 0;
    if let Some((theta, cov, cols, c2, inflate)) = result {
        chi2_dof = c2;
        params = cols.len() + cols.iter().filter(|&&k| k >= 5).count();
        chi2_plain = (0..n)
            .map(|i| {
                let pred: f64 = (0..nt).map(|k| a[(i, k)] * theta[k]).sum::<f64>().max(1e-300);
                weight(curve.edf[pts[i]], pred, floor) * share[i] * (b[i] - pred).powi(2)
            })
            .sum();
        for (r, &k) in cols.iter().enumerate() {
            let sd = (cov[(r, r)] * inflate).max(0.0).sqrt();
            let v = theta[k];
            let c = Coefficient { value: v.sqrt(), lo: (v - Z95 * sd).max(0.0).sqrt(), hi: (v + Z95 * sd).sqrt() };
            match extra.get(k.wrapping_sub(5)) {
                Some(&(kind, time)) if k >= 5 => {
                    terms.extra.push(ExtraTerm { kind, amplitude: c, time_s: time });
                    supported.push(kind.name().to_string());
                }
                _ => {
                    terms.set(k, Some(c));
                    supported.push(TERM_NAMES[k].to_string());
                }
            }
        }
        for (k, name) in TERM_NAMES.iter().enumerate() {
            if allowed[k] && !cols.contains(&k) {
                notes.push(format!("fit: {name} not supported (its best non-negative value is zero)"));
            }
        }
        if c2 > 3.0 {
            notes.push(format!(
                "fit: χ²/dof = {c2:.1}: the model does not describe this curve fully (intervals are widened by √{c2:.1})"
            ));
        }
    }
    FitOutcome { terms, supported, notes, chi2_dof, chi2_plain, n_eff: effective_points, params }
}

/// The five-term fit, or — when it does not follow the curve ([`follows`]) —
/// a fit with [`MODEL_FLOOR`] of the five terms plus up to [`MAX_EXTRA_TERMS`]
/// Markov or sinusoidal terms, added one at a time (forward selection): each
/// the kind and time (hump on a grid of 8 per decade, half a decade inside the curve's τ range)
/// with the smallest BIC, kept only if it lowers the BIC and the fit supports it.
fn fit_best(curve: &AllanCurve, pts: &[usize], notes: &mut Vec<String>) -> FitOutcome {
    use rayon::prelude::*;
    let five = fit_terms(curve, pts, &[], false);
    if follows(curve, pts, &five.terms).0 {
        notes.extend(five.notes.iter().cloned());
        return five;
    }
    let mut current = fit_terms(curve, pts, &[], true);
    // Humps identifiable on this curve: half a decade of data on each side (a
    // Markov term whose hump lies below that is white noise by another name).
    let (t0, t1) = (curve.tau[pts[0]] * HUMP_MARGIN, curve.tau[pts[pts.len() - 1]] / HUMP_MARGIN);
    if t1 <= t0 {
        notes.extend(current.notes.iter().cloned());
        return current;
    }
    let steps = (8.0 * (t1 / t0).log10()).ceil().max(1.0) as usize;
    let times: Vec<f64> = (0..=steps).map(|i| t0 * (t1 / t0).powf(i as f64 / steps as f64)).collect();
    let mut chosen: Vec<(ExtraKind, f64)> = Vec::new();
    while chosen.len() < MAX_EXTRA_TERMS && !follows(curve, pts, &current.terms).0 {
        let candidates: Vec<(ExtraKind, f64)> = [ExtraKind::Markov, ExtraKind::Sinusoid]
            .iter()
            .flat_map(|&kind| {
                // Times whose hump falls at `t`: a sinusoid's sits at ≈ 0.37 P, a
                // Markov term's at ≈ 1.9 T_c.
                let scale = if kind == ExtraKind::Sinusoid { 1.0 / 0.37 } else { 1.0 / 1.9 };
                times.iter().map(move |&t| (kind, t * scale))
            })
            .collect();
        let best = candidates
            .par_iter()
            .map(|&c| {
                let mut with = chosen.clone();
                with.push(c);
                (c, fit_terms(curve, pts, &with, true))
            })
            .filter(|(_, f)| f.terms.extra.len() == chosen.len() + 1)
            .min_by(|a, b| a.1.bic().total_cmp(&b.1.bic()));
        match best {
            Some((c, f)) if f.bic() < current.bic() => {
                let e = f.terms.extra.iter().find(|e| e.kind == c.0 && e.time_s == c.1).copied().expect("kept");
                notes.push(format!(
                    "fit: the terms so far do not follow the curve; a {} term (amplitude {:.3e}, {} {:.3} s) \
                     describes it better (BIC {:.1} against {:.1})",
                    e.kind.name(),
                    e.amplitude.value,
                    e.kind.time_name(),
                    e.time_s,
                    f.bic(),
                    current.bic()
                ));
                chosen.push(c);
                current = f;
            }
            _ => break,
        }
    }
    notes.extend(current.notes.iter().cloned());
    current
}

/// Whether `fit` follows the curve from 0.1 s to a tenth of the largest τ:
/// within the curve's interval or within [`FOLLOW_RATIO`]×; and the worst point.
fn follows(curve: &AllanCurve, pts: &[usize], fit: &NoiseTerms) -> (bool, Option<(f64, f64)>) {
    let t_max = curve.tau[pts[pts.len() - 1]];
    let mut ok = true;
    let mut worst: Option<(f64, f64)> = None;
    for &i in pts.iter().filter(|&&i| curve.tau[i] >= 0.1 && curve.tau[i] <= t_max / 10.0) {
        let m = fit.model_dev(curve.tau[i]);
        let ratio = m / curve.dev[i];
        let inside = m >= curve.dev_lo[i] && m <= curve.dev_hi[i];
        let off = ratio.max(1.0 / ratio);
        if !inside && off > FOLLOW_RATIO {
            ok = false;
        }
        if worst.is_none_or(|(_, r)| off > r.max(1.0 / r)) {
            worst = Some((curve.tau[i], ratio));
        }
    }
    (ok, worst)
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

/// Half-width of the τ span \[decades\] over which a read-off's slope must hold:
/// a term that dominates the curve does so for more than a wiggle.
const READOFF_SPAN_DECADES: f64 = 0.2;

fn read_off(
    curve: &AllanCurve,
    pts: &[usize],
    fit: &NoiseTerms,
    notes: &mut Vec<String>,
) -> (NoiseTerms, [Option<f64>; 5]) {
    let slopes = local_slopes(curve, pts);
    let mut terms = NoiseTerms::default();
    let mut at = [None; 5];
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
    // Points whose neighbourhood (±READOFF_SPAN_DECADES) all has a slope within ±0.1 of `slope`.
    let on_slope = |slope: f64| -> Vec<usize> {
        (0..pts.len())
            .filter(|&a| {
                let near: Vec<Option<f64>> = (0..pts.len())
                    .filter(|&b| (curve.tau[pts[b]] / curve.tau[pts[a]]).log10().abs() <= READOFF_SPAN_DECADES)
                    .map(|b| slopes[b])
                    .collect();
                near.len() >= 2 && near.iter().all(|s| s.is_some_and(|s| (s - slope).abs() <= 0.1))
            })
            .map(|a| pts[a])
            .collect()
    };
    for k in 0..5 {
        let pick = if k == 2 {
            // The floor, only when the fit finds a flicker term (otherwise
            // the minimum is just where N meets K).
            if fit.B.is_none() {
                notes.push("read-off: no bias-instability floor (the minimum is only where the white-noise and random-walk lines cross)".into());
                continue;
            }
            // The lowest point where the curve is flat.
            on_slope(0.0).into_iter().min_by(|&i, &j| curve.dev[i].total_cmp(&curve.dev[j]))
        } else {
            // Among the points on this term's slope, the one with most degrees of freedom.
            on_slope(SLOPES[k]).into_iter().max_by(|&i, &j| curve.edf[i].total_cmp(&curve.edf[j]))
        };
        match pick {
            Some(i) => {
                terms.set(
                    k,
                    Some(Coefficient {
                        value: through(k, curve.dev[i], curve.tau[i]),
                        lo: through(k, curve.dev_lo[i], curve.tau[i]),
                        hi: through(k, curve.dev_hi[i], curve.tau[i]),
                    }),
                );
                at[k] = Some(curve.tau[i]);
            }
            None => notes.push(format!(
                "read-off: no part of the curve keeps the slope {:+} of {} over ±{READOFF_SPAN_DECADES} decade",
                SLOPES[k], TERM_NAMES[k]
            )),
        }
    }
    (terms, at)
}
