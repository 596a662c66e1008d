//! The recording checks itself: a calibration's estimate from the first
//! half of a recording against the one from the second half, and the σ of
//! the whole recording widened to cover what the halves show.
//!
//! # The model
//!
//! Each half's estimate is `θ_h = θ + b_h + e_h`: `e_h` the error its σ
//! describe (the noise model, the cluster-robust sandwich), `b_h` an error
//! the model lacks that differs between parts of the recording (a corner
//! bias that depends on the view, motion that excites a weak direction in
//! one half only, a lens model that fits one part of the image worse), with
//! variance `τ²` per half. Their difference `d = θ₁ − θ₂` then has variance
//! `σ₁² + σ₂² + 2τ²`; the method of moments on the one difference gives
//! `τ̂² = max(0, (d² − σ₁² − σ₂²) / 2)` (the two-study DerSimonian–Laird
//! estimate). The whole recording averages the halves' `b_h`, so its σ
//! becomes `√(σ² + τ̂²/2)`. When the σ are honest `d² ≈ σ₁² + σ₂²` and
//! nothing changes; the truncation at 0 makes the rule conservative, never
//! optimistic.
//!
//! One difference is one degree of freedom: `τ̂` is a rough figure, and a
//! normalized difference `|z| = |d| / √(σ₁² + σ₂²)` beyond
//! [`SplitCheck::threshold`] says more plainly that the recording does not
//! settle a parameter, which the verdicts of the pipelines then say.

use serde::Serialize;
use statrs::distribution::{ContinuousCDF, Normal};

/// The chance that a check of honest σ flags any of its parameters (the
/// family-wise false-alarm rate): a calibration compares 20–40 parameters,
/// and at |z| > 3 each one would flag a perfect sensor's recording one time
/// in ten.
pub const FALSE_ALARM: f64 = 0.01;

/// One parameter's estimate from each half of a recording.
#[derive(Debug, Clone, Serialize)]
pub struct HalfComparison {
    /// What (e.g. `cam0 cy`, `gyro scale y`).
    pub parameter: String,
    /// Units of the values and σ (e.g. `px`, `deg`).
    pub units: String,
    /// The first half's estimate and its σ.
    pub first: f64,
    /// See `first`.
    pub first_sigma: f64,
    /// The second half's estimate and its σ.
    pub second: f64,
    /// See `second`.
    pub second_sigma: f64,
    /// `(first − second) / √(σ₁² + σ₂²)`.
    pub z: f64,
    /// The whole recording's σ before the check.
    pub sigma_before: f64,
    /// Its σ after: `√(σ² + τ̂²/2)` (see the module's model).
    pub sigma_after: f64,
}

impl HalfComparison {
    /// Compare the halves' estimates `(value, σ)` of one parameter whose
    /// whole-recording σ is `sigma`; values and σ in `units`.
    pub fn new(parameter: String, units: &str, first: (f64, f64), second: (f64, f64), sigma: f64) -> HalfComparison {
        let (d, var) = (first.0 - second.0, first.1.powi(2) + second.1.powi(2));
        let z = if var > 0.0 { d / var.sqrt() } else { f64::NAN };
        let tau2 = ((d * d - var) / 2.0).max(0.0);
        let sigma_after = if tau2.is_finite() { (sigma * sigma + tau2 / 2.0).sqrt() } else { sigma };
        HalfComparison {
            parameter,
            units: units.to_string(),
            first: first.0,
            first_sigma: first.1,
            second: second.0,
            second_sigma: second.1,
            z,
            sigma_before: sigma,
            sigma_after,
        }
    }
}

/// The halves of one recording compared, parameter by parameter.
#[derive(Debug, Clone, Default, Serialize)]
pub struct SplitCheck {
    /// What each half held (e.g. `frames 0–739 (0.0–37.0 s)`).
    pub halves: [String; 2],
    /// Every parameter compared.
    pub parameters: Vec<HalfComparison>,
}

impl SplitCheck {
    /// RMS of the normalized differences (≈ 1 when the σ are honest).
    pub fn rms_z(&self) -> f64 {
        let z: Vec<f64> = self.parameters.iter().map(|p| p.z).filter(|z| z.is_finite()).collect();
        (z.iter().map(|z| z * z).sum::<f64>() / z.len().max(1) as f64).sqrt()
    }

    /// The |z| beyond which the halves disagree: the two-sided normal
    /// quantile of [`FALSE_ALARM`] shared by the parameters compared
    /// (Bonferroni; 3.45 for the 18 parameters of an IMU, 3.58 for the 29 of a stereo rig).
    pub fn threshold(&self) -> f64 {
        let tail = FALSE_ALARM / (2.0 * self.parameters.len().max(1) as f64);
        Normal::standard().inverse_cdf(1.0 - tail)
    }

    /// Whether the halves disagree on `p` beyond [`SplitCheck::threshold`].
    pub fn disagrees(&self, p: &HalfComparison) -> bool {
        p.z.abs() > self.threshold()
    }

    /// The parameters the halves disagree on, the worst first.
    pub fn disagreements(&self) -> Vec<&HalfComparison> {
        let mut out: Vec<&HalfComparison> = self.parameters.iter().filter(|p| self.disagrees(p)).collect();
        out.sort_by(|a, b| b.z.abs().total_cmp(&a.z.abs()));
        out
    }

    /// The widened σ of `parameter` (its σ unchanged when it was not compared).
    pub fn sigma_after(&self, parameter: &str, sigma: f64) -> f64 {
        self.parameters.iter().find(|p| p.parameter == parameter).map_or(sigma, |p| p.sigma_after)
    }

    /// One line per disagreement: `"cy: the halves disagree at 4.9σ (248.1 ± 0.5 vs 252.0 ± 0.6 px)"`.
    pub fn describe_disagreements(&self) -> Vec<String> {
        self.disagreements()
            .iter()
            .map(|p| {
                format!(
                    "{}: the halves disagree at {:.1}σ ({} ± {} vs {} ± {} {})",
                    p.parameter,
                    p.z.abs(),
                    short(p.first),
                    short(p.first_sigma),
                    short(p.second),
                    short(p.second_sigma),
                    p.units
                )
            })
            .collect()
    }

    /// A Markdown table of every parameter compared.
    pub fn markdown(&self) -> String {
        let mut s = format!(
            "First half: {}; second half: {}. RMS normalized difference {:.2} (≈ 1 when the σ are honest); \
             ⚠ marks |z| > {:.2} (a chance of {} that honest σ flag any).\n\n\
             | parameter | first half | second half | z | σ before → after |\n|---|---|---|---|---|\n",
            self.halves[0],
            self.halves[1],
            self.rms_z(),
            self.threshold(),
            FALSE_ALARM
        );
        for p in &self.parameters {
            s += &format!(
                "| {} | {} ± {} | {} ± {} | {:+.2}{} | {} → {} {} |\n",
                p.parameter,
                short(p.first),
                short(p.first_sigma),
                short(p.second),
                short(p.second_sigma),
                p.z,
                if self.disagrees(p) { " ⚠" } else { "" },
                short(p.sigma_before),
                short(p.sigma_after),
                p.units
            );
        }
        s
    }
}

/// A number with 4 significant digits, plainly or in e-notation.
fn short(x: f64) -> String {
    if x != 0.0 && (x.abs() < 1e-3 || x.abs() >= 1e5) {
        format!("{x:.3e}")
    } else {
        format!("{}", (x * 1e4).round() / 1e4)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn agreeing_halves_leave_the_sigma() {
        let p = HalfComparison::new("fx".into(), "px", (458.0, 0.5), (458.3, 0.5), 0.35);
        assert!((p.z + 0.3 / 0.5f64.hypot(0.5)).abs() < 1e-12);
        assert_eq!(p.sigma_after, 0.35);
        let check = SplitCheck { halves: ["a".into(), "b".into()], parameters: vec![p] };
        assert!(check.disagreements().is_empty());
        // One parameter: the two-sided 1 % quantile.
        assert!((check.threshold() - 2.5758).abs() < 1e-3);
    }

    #[test]
    fn disagreeing_halves_widen_the_sigma_to_cover_their_difference() {
        // d = 4, σ₁ = σ₂ = 0.5: τ̂² = (16 − 0.5)/2 = 7.75, σ² + τ̂²/2 = 0.1225 + 3.875.
        let p = HalfComparison::new("cy".into(), "px", (250.0, 0.5), (246.0, 0.5), 0.35);
        assert!((p.sigma_after - (0.1225f64 + 3.875).sqrt()).abs() < 1e-12);
        // Halves with the widened σ (×√2 of the whole's) differ by ≈ 1 of their σ.
        let half = p.sigma_after * 2f64.sqrt();
        assert!((4.0 / half.hypot(half) - 1.0).abs() < 0.01);
        let check = SplitCheck { halves: ["a".into(), "b".into()], parameters: vec![p] };
        assert_eq!(check.disagreements().len(), 1);
        assert!(check.describe_disagreements()[0].starts_with("cy: the halves disagree at 5.7σ"));
        assert!(check.markdown().contains("⚠"));
    }
}
