//! Several recordings of one sensor: each recording's estimate of a
//! parameter the sensor owns (a scale, a misalignment), their consensus, and
//! whether they agree.
//!
//! # The model
//!
//! Recording `r` estimates `θ_r = θ + b_r + e_r`: `e_r` the error its σ
//! describe, `b_r` what differs between recordings and its σ does not
//! describe (an effect one recording excites and another does not, a
//! temperature, a mounting), with variance `τ²`. The DerSimonian–Laird
//! moment estimate from Cochran's `Q = Σ w_r (θ_r − θ̄)²`, `w_r = 1/σ_r²`:
//! `τ̂² = max(0, (Q − (k − 1)) / (Σw − Σw²/Σw))`. The consensus is the mean
//! weighted by `1/(σ_r² + τ̂²)`, its σ `1/√Σ 1/(σ_r² + τ̂²)`: when the
//! recordings agree within their σ (`τ̂ = 0`) it is the joint estimate of the
//! recordings' information (the first-order equal of one solve over all of
//! them, since they share no other parameter), and when they do not, the σ
//! covers what they show. For two recordings the rule is that of
//! [`crate::model::split`] for two halves.
//!
//! Whether the recordings agree: `Q` against χ² with `k − 1` degrees of
//! freedom, flagged below [`FALSE_ALARM`] shared by the parameters checked
//! (Bonferroni); the pairwise normalized differences
//! `(θ_r − θ_s)/√(σ_r² + σ_s²)` say the same per pair.

use serde::Serialize;
use statrs::distribution::{ChiSquared, ContinuousCDF};

pub use super::split::FALSE_ALARM;

/// One parameter as each recording estimated it, and their consensus.
#[derive(Debug, Clone, Serialize)]
pub struct Consensus {
    /// What (e.g. `gyroscope scale y`).
    pub parameter: String,
    /// Units of the values and σ.
    pub units: String,
    /// Each recording's estimate, in the order of [`RecordingsCheck::recordings`].
    pub values: Vec<f64>,
    /// Their σ.
    pub sigmas: Vec<f64>,
    /// Which estimates the consensus leaves out (no positive finite σ, or
    /// not determined by that recording's data).
    pub left_out: Vec<bool>,
    /// The consensus (see the module's model).
    pub value: f64,
    /// Its σ.
    pub sigma: f64,
    /// `τ̂`: the spread between recordings their σ do not describe (0 when they agree).
    pub tau: f64,
    /// Cochran's `Q` (≈ k − 1 when the σ are honest).
    pub q: f64,
    /// The chance of a `Q` this large from recordings whose σ are honest.
    pub p_value: f64,
}

impl Consensus {
    /// The consensus of `estimates` `(value, σ)` of one parameter, in `units`
    /// (estimates with a σ that is not positive and finite are left out).
    pub fn new(parameter: String, units: &str, estimates: &[(f64, f64)]) -> Consensus {
        Consensus::without(parameter, units, estimates, &vec![false; estimates.len()])
    }

    /// [`Consensus::new`] with the estimates marked in `leave_out` left out too.
    pub fn without(parameter: String, units: &str, estimates: &[(f64, f64)], leave_out: &[bool]) -> Consensus {
        let left_out: Vec<bool> = estimates
            .iter()
            .zip(leave_out.iter().chain(std::iter::repeat(&false)))
            .map(|((v, s), out)| *out || !(v.is_finite() && s.is_finite() && *s > 0.0))
            .collect();
        let kept: Vec<(f64, f64)> =
            estimates.iter().zip(&left_out).filter(|(_, out)| !**out).map(|(e, _)| *e).collect();
        let weighted_mean = |w: &[f64]| {
            let sw: f64 = w.iter().sum();
            (kept.iter().zip(w).map(|((v, _), w)| w * v).sum::<f64>() / sw, 1.0 / sw.sqrt())
        };
        let w: Vec<f64> = kept.iter().map(|(_, s)| 1.0 / (s * s)).collect();
        let (fixed, _) = weighted_mean(&w);
        let q: f64 = kept.iter().zip(&w).map(|((v, _), w)| w * (v - fixed).powi(2)).sum();
        let dof = kept.len().saturating_sub(1) as f64;
        let (sw, sw2) = (w.iter().sum::<f64>(), w.iter().map(|w| w * w).sum::<f64>());
        let tau2 = if dof > 0.0 { ((q - dof) / (sw - sw2 / sw)).max(0.0) } else { 0.0 };
        let w_re: Vec<f64> = kept.iter().map(|(_, s)| 1.0 / (s * s + tau2)).collect();
        let (value, sigma) = if kept.is_empty() { (f64::NAN, f64::NAN) } else { weighted_mean(&w_re) };
        let p_value = ChiSquared::new(dof).map_or(1.0, |c| 1.0 - c.cdf(q));
        Consensus {
            parameter,
            units: units.to_string(),
            values: estimates.iter().map(|e| e.0).collect(),
            sigmas: estimates.iter().map(|e| e.1).collect(),
            left_out,
            value,
            sigma,
            tau: tau2.sqrt(),
            q,
            p_value,
        }
    }

    /// The σ of the parameter in a recording not yet made: the consensus's σ
    /// and the spread between recordings, `√(σ² + τ̂²)` (for a bias that
    /// changes at every power-on, what a new power-on's is known to).
    pub fn new_recording_sigma(&self) -> f64 {
        self.sigma.hypot(self.tau)
    }

    /// Recording `r`'s estimate as text: `"1.002100 ± 3.0e-4"`, marked when left out.
    pub fn estimate_text(&self, r: usize) -> String {
        let text = format!("{:.6} ± {:.1e}", self.values[r], self.sigmas[r]);
        if self.left_out[r] {
            format!("({text}, left out)")
        } else {
            text
        }
    }

    /// The normalized difference of every pair of recordings (those left out skipped).
    pub fn pairwise_z(&self) -> Vec<f64> {
        let n = self.values.len();
        let mut z = Vec::new();
        for r in (0..n).filter(|&r| !self.left_out[r]) {
            for s in (r + 1..n).filter(|&s| !self.left_out[s]) {
                let var = self.sigmas[r].powi(2) + self.sigmas[s].powi(2);
                if var > 0.0 && var.is_finite() {
                    z.push((self.values[r] - self.values[s]) / var.sqrt());
                }
            }
        }
        z
    }
}

/// The recordings of one sensor compared, parameter by parameter.
#[derive(Debug, Clone, Default, Serialize)]
pub struct RecordingsCheck {
    /// The recordings (names), in order.
    pub recordings: Vec<String>,
    /// Every parameter compared.
    pub parameters: Vec<Consensus>,
}

impl RecordingsCheck {
    /// The pairwise normalized differences of every parameter.
    fn all_pairwise_z(&self) -> Vec<f64> {
        self.parameters.iter().flat_map(Consensus::pairwise_z).collect()
    }

    /// RMS of the pairwise normalized differences (≈ 1 when the σ are honest).
    pub fn rms_pairwise_z(&self) -> f64 {
        let z = self.all_pairwise_z();
        (z.iter().map(|z| z * z).sum::<f64>() / z.len().max(1) as f64).sqrt()
    }

    /// The largest |pairwise normalized difference|.
    pub fn max_pairwise_z(&self) -> f64 {
        self.all_pairwise_z().iter().fold(0.0, |m, z| m.max(z.abs()))
    }

    /// The p-value below which the recordings disagree on a parameter:
    /// [`FALSE_ALARM`] shared by the parameters compared (Bonferroni).
    pub fn threshold(&self) -> f64 {
        FALSE_ALARM / self.parameters.len().max(1) as f64
    }

    /// The parameters the recordings disagree on, the worst first.
    pub fn disagreements(&self) -> Vec<&Consensus> {
        let mut out: Vec<&Consensus> = self.parameters.iter().filter(|p| p.p_value < self.threshold()).collect();
        out.sort_by(|a, b| a.p_value.total_cmp(&b.p_value));
        out
    }

    /// The consensus of `parameter`, if it was compared.
    pub fn get(&self, parameter: &str) -> Option<&Consensus> {
        self.parameters.iter().find(|p| p.parameter == parameter)
    }

    /// One line per disagreement: `"gyroscope scale y: the recordings disagree
    /// (p 2e-5; 1.0021 ± 0.0003, 1.0043 ± 0.0004; spread τ 0.0015)"`.
    pub fn disagreement_lines(&self) -> Vec<String> {
        self.disagreements()
            .into_iter()
            .map(|p| {
                let each: Vec<String> = (0..p.values.len()).map(|r| p.estimate_text(r)).collect();
                format!(
                    "{}: the recordings disagree (p {:.1e}; {}{}; spread between recordings τ {:.1e}, σ widened to {:.1e})",
                    p.parameter,
                    p.p_value,
                    each.join(", "),
                    if p.units.is_empty() { String::new() } else { format!(" {}", p.units) },
                    p.tau,
                    p.sigma
                )
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recordings_that_agree_pool_their_information() {
        let c = Consensus::new("s".into(), "", &[(1.0, 0.1), (1.05, 0.1), (0.98, 0.2)]);
        assert_eq!(c.tau, 0.0);
        let w = [100.0, 100.0, 25.0];
        let mean = (w[0] * 1.0 + w[1] * 1.05 + w[2] * 0.98) / 225.0;
        assert!((c.value - mean).abs() < 1e-12 && (c.sigma - 1.0 / 15.0).abs() < 1e-12);
        assert!(c.p_value > 0.5);
    }

    #[test]
    fn two_recordings_widen_as_two_halves_do() {
        let (a, b) = ((1.0, 0.1), (1.6, 0.2));
        let c = Consensus::new("s".into(), "", &[a, b]);
        let tau2 = ((0.6f64.powi(2) - 0.01 - 0.04) / 2.0).max(0.0);
        assert!((c.tau - tau2.sqrt()).abs() < 1e-12);
        let sigma = (1.0 / (1.0 / (0.01 + tau2) + 1.0 / (0.04 + tau2))).sqrt();
        assert!((c.sigma - sigma).abs() < 1e-12);
        // The widened σ covers the pair: each recording within ~1σ of its own spread.
        assert!((a.0 - c.value).abs() / (c.sigma.powi(2) + tau2).sqrt() < 1.5);
        let z = c.pairwise_z();
        assert!((z[0] + 0.6 / 0.05f64.sqrt()).abs() < 1e-12);
    }

    #[test]
    fn a_recording_far_off_is_flagged() {
        let mut check = RecordingsCheck { recordings: vec!["a".into(), "b".into(), "c".into()], parameters: vec![] };
        check.parameters.push(Consensus::new("same".into(), "", &[(1.0, 0.01), (1.01, 0.01), (0.995, 0.01)]));
        check.parameters.push(Consensus::new("off".into(), "", &[(1.0, 0.01), (1.08, 0.01), (0.99, 0.01)]));
        let d = check.disagreements();
        assert_eq!(d.len(), 1);
        assert_eq!(d[0].parameter, "off");
        assert!(check.max_pairwise_z() > 6.0);
        assert!(check.disagreement_lines()[0].starts_with("off: the recordings disagree"));
    }

    #[test]
    fn estimates_without_a_sigma_are_left_out() {
        let c = Consensus::new("s".into(), "", &[(1.0, 0.1), (f64::NAN, 0.1), (2.0, 0.0)]);
        assert_eq!(c.value, 1.0);
        assert_eq!(c.values.len(), 3);
        assert_eq!(c.left_out, [false, true, true]);
        let c = Consensus::without("s".into(), "", &[(1.0, 0.1), (3.0, 0.1), (1.1, 0.1)], &[false, true]);
        assert!((c.value - 1.05).abs() < 1e-12 && c.pairwise_z().len() == 1);
        assert!(c.estimate_text(1).ends_with("left out)"));
    }
}
