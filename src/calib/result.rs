//! What a calibration returns: the calibration with its σ, the detection
//! that produced it and the fits' statistics ([`CalibrationResult`]), or why
//! it failed ([`CalibError`]).

use super::detect::Interval;
use crate::model::calibration::ImuCalibration;
use serde::{Deserialize, Serialize};
use std::fmt;

/// The initial static period used.
#[derive(Debug, Clone, Serialize)]
pub struct InitialRestReport {
    /// First and last sample, seconds from the first sample of the recording.
    pub start_s: f64,
    /// See `start_s`.
    pub end_s: f64,
    /// Samples averaged (knocks cut out).
    pub samples: usize,
    /// Found from the data (false: `--init-static` given).
    pub detected: bool,
}

/// Why a recording cannot be calibrated.
#[derive(Debug, Clone)]
pub struct CalibError {
    /// The recording (file name).
    pub source: String,
    /// What is wrong.
    pub message: String,
    /// What to do about it.
    pub hint: Option<String>,
    /// The calibration that was computed but failed its verdict
    /// ([`Verdict::Failed`]), for diagnosis only: its figures and residuals
    /// show what went wrong; its parameters must not be used.
    pub diagnosis: Option<Box<CalibrationResult>>,
}

impl fmt::Display for CalibError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}: {}", self.source, self.message)?;
        if let Some(h) = &self.hint {
            write!(f, "\n  hint: {h}")?;
        }
        Ok(())
    }
}

impl std::error::Error for CalibError {}

impl CalibError {
    /// An error on recording `rec` with an optional hint (no diagnosis).
    pub(crate) fn new(rec: &crate::io::ImuRecording, message: String, hint: Option<&str>) -> CalibError {
        CalibError { source: rec.source_name(), message, hint: hint.map(str::to_string), diagnosis: None }
    }
}

/// One detected static interval in the output.
#[derive(Debug, Clone, Serialize)]
pub struct StaticInterval {
    /// Start and end, seconds from the first sample.
    pub start_s: f64,
    /// See `start_s`.
    pub end_s: f64,
    /// Start and end timestamps as in the input \[ns\].
    pub start_ns: i64,
    /// See `start_ns`.
    pub end_ns: i64,
    /// Samples averaged.
    pub samples: usize,
    /// Calibrated mean specific force of the interval \[m/s²\].
    pub accel: [f64; 3],
    /// `|a| − g` \[m/s²\] after calibration.
    pub norm_error: f64,
}

/// One entry of the threshold sweep.
#[derive(Debug, Clone, Serialize)]
pub struct SweepEntry {
    /// Multiplier `k`.
    pub multiplier: f64,
    /// Static intervals found.
    pub intervals: usize,
    /// Whitened χ²/dof of the accelerometer fit (`None`: too few intervals or no convergence).
    pub chi2_per_dof: Option<f64>,
    /// RMS of `|a| − g` \[m/s²\].
    pub rms_norm_error: Option<f64>,
    /// ln det of the inflated accelerometer and gyro covariances (the sweep keeps the smallest).
    pub uncertainty: Option<f64>,
}

/// Fit statistics of one stage.
#[derive(Debug, Clone, Serialize)]
pub struct FitStats {
    /// Residuals (factors × dimension).
    pub residuals: usize,
    /// Parameters estimated.
    pub parameters: usize,
    /// Whitened χ²/dof with the noise predicted from the initial static period
    /// (1 when that noise explains the residuals); the threshold sweep keeps the lowest.
    pub chi2_per_dof: f64,
    /// Unmodelled error added in quadrature to every residual's noise so that
    /// χ²/dof = 1 (0 when the noise explains the residuals); accel: \[m/s²\] on |a|, gyro: \[rad\].
    pub unmodelled_sigma: f64,
    /// Factor applied to the covariance: max(1, χ²/dof) after the unmodelled error is added.
    pub covariance_inflation: f64,
    /// RMS residual in physical units (accel: `|a| − g` \[m/s²\]; gyro: direction error \[rad\]).
    pub rms: f64,
    /// The cost imu_tk prints for the same parameters and intervals (½Σr², its residuals:
    /// accel `g² − |a|²` on the first 100 samples of each interval, gyro `Rᵀg₀ − g₁`).
    pub imu_tk_cost: f64,
    /// Solver iterations.
    pub iterations: usize,
    /// False when a solve stopped at the iteration cap instead of converging.
    pub converged: bool,
}

/// Residual of one integrated-rotation factor.
#[derive(Debug, Clone, Serialize)]
pub struct RotationResidual {
    /// Index of the static interval before and after the motion.
    pub from: usize,
    /// See `from`.
    pub to: usize,
    /// Angle turned between them \[deg\].
    pub rotation_deg: f64,
    /// Angle between predicted and measured gravity direction \[rad\].
    pub error_rad: f64,
}

/// What the kept multiplier `k` makes of the detector's rules, per axis x y z.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct DetectionThresholds {
    /// `k` × each accelerometer axis's variance in the initial rest \[raw units²\].
    pub accel_variance: [f64; 3],
    /// `k` × each gyro axis's variance in the initial rest \[raw units²\].
    pub gyro_variance: [f64; 3],
    /// Largest offset of a window's mean rate from the initial rest's \[raw units\]
    /// (`None` without the gyro in the detection).
    pub window_rate: Option<[f64; 3]>,
}

/// Everything [`calibrate`](crate::calib::calibrate) found.
#[derive(Debug, Clone)]
pub struct CalibrationResult {
    /// The calibration with 1-σ uncertainties.
    pub calibration: ImuCalibration,
    /// The initial static period used.
    pub initial_rest: InitialRestReport,
    /// The multiplier `k` kept.
    pub multiplier: f64,
    /// The thresholds it gives.
    pub thresholds: DetectionThresholds,
    /// The static intervals used (sample indices).
    pub intervals: Vec<Interval>,
    /// The same intervals with times and residuals.
    pub static_intervals: Vec<StaticInterval>,
    /// The threshold sweep.
    pub sweep: Vec<SweepEntry>,
    /// Accelerometer fit.
    pub accel_fit: FitStats,
    /// Gyroscope fit.
    pub gyro_fit: FitStats,
    /// Per motion between intervals.
    pub rotations: Vec<RotationResidual>,
    /// Sliding accelerometer variance norm per sample \[raw units²\] (∞ where the window does not fit).
    pub score: Vec<f64>,
    /// Detection score per sample: each axis's windowed variance over its variance
    /// in the initial rest, averaged over a triad's axes ([`super::detect::axis_ratio`]),
    /// the larger of accelerometer and gyro (accelerometer only without
    /// `detect_with_gyro`), ∞ where the window's mean rate is beyond
    /// [`DetectionThresholds::window_rate`]; static where below the multiplier.
    pub ratio: Vec<f64>,
    /// Problems that did not stop the calibration.
    pub warnings: Vec<String>,
    /// The verdict: `ok`, `weak` (with reasons) or `failed` (only in [`CalibError::diagnosis`]).
    pub assessment: Assessment,
    /// The halves of the recording compared (None when too few poses).
    pub split: Option<crate::model::split::SplitCheck>,
}

/// The verdict.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Verdict {
    /// Every parameter determined, the fits explain the data.
    Ok,
    /// Usable, but some parameters are not determined or uncertain (see the reasons).
    Weak,
    /// The fit does not explain the data: do not use it.
    Failed,
}

impl fmt::Display for Verdict {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Verdict::Ok => "ok",
            Verdict::Weak => "weak",
            Verdict::Failed => "failed",
        })
    }
}

/// The verdict with its reasons.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Assessment {
    /// `ok`, `weak` or `failed`.
    pub verdict: Verdict,
    /// Why the verdict is not `ok` (empty when it is).
    pub reasons: Vec<String>,
    /// Parameters the poses do not determine (estimate near the prior of no
    /// misalignment, σ about the prior's), e.g. `accelerometer T[0][1]`.
    pub not_determined: Vec<String>,
}
