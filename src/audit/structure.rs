//! Structure left in the audit's residuals: the whitened residuals of the
//! final model, binned against each quantity an effect could depend on
//! (temperature, time, orientation, rate), and tested against "flat".
//!
//! With `n` residual vectors of dimension `d` sorted by the regressor into `B`
//! bins of equal count, `T = Σ_b n_b ‖z̄_b‖² / s²` is χ²(B·d) when the
//! residuals are zero-mean noise (`s²` = the group's χ² per row when above 1,
//! so more scatter alone is not structure). A significant `T` (Bonferroni
//! over the tests) is structure no effect of the model explains; its excess
//! `T − B·d` over the final model's χ² excess is its share of the gap.

use super::data::AuditData;
use super::fit::{self, Fit, Noise};
use super::AuditError;
use statrs::distribution::{ChiSquared, ContinuousCDF};

/// Family-wise significance level of the structure tests.
pub const ALPHA: f64 = 1e-3;

/// Residual vectors per bin, about (bins: between 2 and [`MAX_BINS`]).
pub const PER_BIN: usize = 8;

/// Most bins.
pub const MAX_BINS: usize = 8;

/// One structure test.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Structure {
    /// Which residual: `gyro at rest`, `|a| - g at rest` or `motion direction`.
    pub residual: String,
    /// Against what: `time [s]`, `temperature [°C]`, `accel x [raw]`, `mean rate [rad/s]`, …
    pub regressor: String,
    /// Bins.
    pub bins: usize,
    /// `T` (see the module docs) and its degrees of freedom.
    pub statistic: f64,
    /// See `statistic`.
    pub dof: usize,
    /// Its p-value.
    pub p_value: f64,
    /// `(T − dof)` over the final model's χ² − dof, in \[0, 1\].
    pub share_of_gap: f64,
    /// Below the Bonferroni threshold.
    pub significant: bool,
}

/// Test the whitened residuals of `fit` against every regressor.
pub fn test(data: &AuditData, noise: &Noise, fit: &Fit) -> Result<Vec<Structure>, AuditError> {
    let (statics, motions) = fit::whitened(data, noise, fit)?;
    let excess = (fit.chi2() - fit.dof() as f64).max(0.0);
    let mut regress_static: Vec<(String, Vec<f64>)> =
        vec![("time [s]".into(), data.statics.iter().map(|s| s.context.time + data.reference_time).collect())];
    if data.has_temperature {
        regress_static.push((
            "temperature [°C]".into(),
            data.statics.iter().map(|s| s.context.dtemp + data.reference_temperature).collect(),
        ));
    }
    for (k, axis) in ["x", "y", "z"].iter().enumerate() {
        regress_static.push((format!("accel {axis} [raw]"), data.statics.iter().map(|s| s.raw_accel[k]).collect()));
    }
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len().max(1) as f64;
    let mut regress_motion: Vec<(String, Vec<f64>)> = vec![
        (
            "mean rate [raw]".into(),
            data.motions.iter().map(|m| mean(&m.raw_gyro.iter().map(|w| w.norm()).collect::<Vec<_>>())).collect(),
        ),
        (
            "peak rate [raw]".into(),
            data.motions.iter().map(|m| m.raw_gyro.iter().map(|w| w.norm()).fold(0.0, f64::max)).collect(),
        ),
        (
            "time [s]".into(),
            data.motions
                .iter()
                .map(|m| mean(&m.context.iter().map(|c| c.time).collect::<Vec<_>>()) + data.reference_time)
                .collect(),
        ),
    ];
    if data.has_temperature {
        regress_motion.push((
            "temperature [°C]".into(),
            data.motions
                .iter()
                .map(|m| mean(&m.context.iter().map(|c| c.dtemp).collect::<Vec<_>>()) + data.reference_temperature)
                .collect(),
        ));
    }
    let gyro: Vec<Vec<f64>> = statics.iter().map(|r| r[1..].to_vec()).collect();
    let norm: Vec<Vec<f64>> = statics.iter().map(|r| vec![r[0]]).collect();
    let dirs: Vec<Vec<f64>> = motions.iter().map(|r| r.to_vec()).collect();
    let mut out = Vec::new();
    for (name, z, regressors) in [
        ("gyro at rest", &gyro, &regress_static),
        ("|a| - g at rest", &norm, &regress_static),
        ("motion direction", &dirs, &regress_motion),
    ] {
        for (reg, x) in regressors {
            if let Some(s) = binned(z, x, excess) {
                out.push(Structure { residual: name.into(), regressor: reg.clone(), ..s });
            }
        }
    }
    let threshold = ALPHA / out.len().max(1) as f64;
    for s in out.iter_mut() {
        s.significant = s.p_value < threshold;
    }
    Ok(out)
}

/// The binned test of residual vectors `z` against `x` (see the module docs);
/// `None` with fewer than two bins' worth of residuals.
fn binned(z: &[Vec<f64>], x: &[f64], excess: f64) -> Option<Structure> {
    let n = z.len().min(x.len());
    let bins = (n / PER_BIN).clamp(2, MAX_BINS);
    if n < 2 * bins || z.is_empty() {
        return None;
    }
    let d = z[0].len();
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by(|&a, &b| x[a].total_cmp(&x[b]));
    let scatter =
        (z.iter().take(n).map(|v| v.iter().map(|e| e * e).sum::<f64>()).sum::<f64>() / (n * d) as f64).max(1.0);
    let mut t = 0.0;
    for b in 0..bins {
        let idx = &order[b * n / bins..(b + 1) * n / bins];
        let m = idx.len() as f64;
        let mut sum = vec![0.0; d];
        for &i in idx {
            sum.iter_mut().zip(&z[i]).for_each(|(s, v)| *s += v);
        }
        t += sum.iter().map(|s| s * s / m).sum::<f64>();
    }
    t /= scatter;
    let dof = bins * d;
    let p_value = ChiSquared::new(dof as f64).map(|c| c.sf(t)).unwrap_or(1.0);
    let share = if excess > 0.0 { ((t - dof as f64) / excess).clamp(0.0, 1.0) } else { 0.0 };
    Some(Structure {
        residual: String::new(),
        regressor: String::new(),
        bins,
        statistic: t,
        dof,
        p_value,
        share_of_gap: share,
        significant: false,
    })
}

/// One clause for the verdict naming the significant structure, largest share
/// first (empty when there is none).
pub fn summary(structure: &[Structure]) -> String {
    let mut sig: Vec<&Structure> = structure.iter().filter(|s| s.significant).collect();
    sig.sort_by(|a, b| b.share_of_gap.total_cmp(&a.share_of_gap));
    let parts: Vec<String> = sig
        .iter()
        .map(|s| {
            format!(
                "the {} residual against {} (p {:.1e}, about {:.0} % of the gap left)",
                s.residual,
                s.regressor,
                s.p_value,
                100.0 * s.share_of_gap
            )
        })
        .collect();
    if parts.is_empty() {
        String::new()
    } else {
        format!("unexplained structure: {}", parts.join("; "))
    }
}
