//! How well each window knew its own length — the scale it carries — and,
//! against a ground truth, whether it was right to (`summary.json`'s
//! `window_length`).
//!
//! A monocular window gets its scale from the accelerometer alone; where the
//! motion is gentle or the window short, the scale rests on the
//! marginalization prior. Each keyframe solve reports the distance from the
//! window's oldest state to its newest and that distance's σ
//! ([`super::WindowLength`]); their ratio bounds the scale's relative σ in
//! that window. With a ground truth, the same distance between the true
//! positions gives each window's length error, normalized by its σ: an RMS
//! near 1 means the σ can be believed, far above 1 that the windows are more
//! sure of their scale than they should be.

use super::{VioInput, VioResult};
use crate::eval::pose_at;
use crate::model::numeric::percentile;
use serde::Serialize;

/// Windows shorter than this \[m\] are left out of the relative figures: a
/// hovering window's σ/length says nothing about its scale.
pub const MIN_LENGTH_M: f64 = 0.1;

/// Largest gap \[s\] of the ground truth across which a position is interpolated.
const MAX_GT_GAP_S: f64 = 0.1;

/// Seconds between the points of [`WindowScale::series`].
pub const SERIES_STEP_S: f64 = 1.0;

/// The windows' lengths and their σ over a run.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct WindowScale {
    /// Keyframe windows at least `MIN_LENGTH_M` (0.1 m) long.
    pub windows: usize,
    /// Median over those windows of σ/length (the scale's relative σ bound).
    pub relative_sigma_median: f64,
    /// Its 95th percentile.
    pub relative_sigma_p95: f64,
    /// With a ground truth: Σ(length − true length) / Σ true length over the
    /// windows, the mean scale error they carried (−0.05: 5 % short).
    pub length_error: Option<f64>,
    /// With a ground truth: RMS of (length − true length)/σ over the windows
    /// (1 when the σ are honest).
    pub normalized_error_rms: Option<f64>,
    /// `[t s, length m, σ m]` of the first window in each second (`SERIES_STEP_S`).
    pub series: Vec<[f64; 3]>,
}

impl WindowScale {
    /// One line for a terminal.
    pub fn line(&self) -> String {
        let mut s = format!(
            "window length (the scale it carries): σ {:.2} % of it (median; 95th percentile {:.2} %) over {} windows",
            100.0 * self.relative_sigma_median,
            100.0 * self.relative_sigma_p95,
            self.windows
        );
        if let (Some(e), Some(z)) = (self.length_error, self.normalized_error_rms) {
            s += &format!("; against the ground truth {:+.2} %, normalized error RMS {z:.2}", 100.0 * e);
        }
        s
    }
}

/// The windows of `result` summed up (None when no keyframe had a length with σ).
pub fn window_scale(input: &VioInput, result: &VioResult) -> Option<WindowScale> {
    let windows: Vec<(f64, super::WindowLength)> = result
        .estimates
        .iter()
        .filter_map(|e| e.window_length.map(|w| (e.t, w)))
        .filter(|(_, w)| w.length_m >= MIN_LENGTH_M && w.sigma_m > 0.0)
        .collect();
    if windows.is_empty() {
        return None;
    }
    let mut relative: Vec<f64> = windows.iter().map(|(_, w)| w.sigma_m / w.length_m).collect();
    let mut series: Vec<[f64; 3]> = Vec::new();
    for (t, w) in &windows {
        if series.last().is_none_or(|s| *t >= s[0] + SERIES_STEP_S) {
            series.push([*t, w.length_m, w.sigma_m]);
        }
    }
    let truth = input.groundtruth.as_ref().and_then(|gt| {
        let position = |t: f64| {
            let t_ns = input.t0_ns + (t * 1e9).round() as i64;
            pose_at(gt, t_ns, MAX_GT_GAP_S * 1e9).map(|p| p.translation.vector)
        };
        let (mut error, mut true_total, mut z2, mut n) = (0.0, 0.0, 0.0, 0usize);
        for (t, w) in &windows {
            if let (Some(a), Some(b)) = (position(w.from_t), position(*t)) {
                let true_length = (b - a).norm();
                error += w.length_m - true_length;
                true_total += true_length;
                z2 += ((w.length_m - true_length) / w.sigma_m).powi(2);
                n += 1;
            }
        }
        (n > 0).then(|| (error / true_total, (z2 / n as f64).sqrt()))
    });
    Some(WindowScale {
        windows: windows.len(),
        relative_sigma_median: percentile(&mut relative, 0.5),
        relative_sigma_p95: percentile(&mut relative, 0.95),
        length_error: truth.map(|t| t.0),
        normalized_error_rms: truth.map(|t| t.1),
        series,
    })
}
