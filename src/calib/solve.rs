//! The calibration pipeline: detect static intervals (sweeping the threshold
//! multiplier), fit the accelerometer with gravity-norm factors, then the
//! gyroscope with integrated-rotation factors, both on the solver, and turn
//! the estimates and their covariances into the paper's convention.

use super::detect::{intervals_below, mean3, sliding_variance_norm, var3, Interval};
use super::model::{split_unit_diagonal, ImuCalibration, Triad, Units};
use crate::io::{ImuRecording, Stored};
use nalgebra::{DMatrix, DVector, Matrix3, Vector3};
use rayon::prelude::*;
use serde::Serialize;
use std::fmt;
use tumble_factors::imu_calib::{
    accel_matrix, gyro_matrix, AccelParams, GravityNormFactor, GyroMatrix, IntegratedRotationFactor, UPPER,
};
use tumble_solvers::{covariances, Factor, Graph, Key, LmOptions, NoiseModel, Optimizer, Values, Vars};

const KEY_ACCEL: Key = Key::new('a', 0);
const KEY_GYRO: Key = Key::new('g', 0);
const KEY_GYRO_BIAS: Key = Key::new('g', 1);

/// Settings of [`calibrate`].
#[derive(Debug, Clone, PartialEq)]
pub struct CalibOptions {
    /// Local gravity magnitude \[m/s²\] (see [`super::normal_gravity`]).
    pub gravity: f64,
    /// Length of the initial static period \[s\] (its variance sets the threshold; its mean the gyro bias).
    pub init_static_s: f64,
    /// Window of the sliding accelerometer variance \[s\] (imu_tk: 101 samples).
    pub window_s: f64,
    /// Shortest usable static interval \[s\] (imu_tk: 100 samples).
    pub min_interval_s: f64,
    /// Threshold multipliers `k` to sweep (imu_tk: 2, 3, …, 10).
    pub multipliers: Vec<f64>,
    /// Estimate the gyro bias with the other gyro parameters instead of taking
    /// the mean of the initial static period.
    pub estimate_gyro_bias: bool,
    /// Fewest static intervals accepted (imu_tk: 12).
    pub min_intervals: usize,
    /// Require the gyro to be as still as the accelerometer (windowed variance
    /// below `k` × its initial variance too). imu_tk uses the accelerometer only,
    /// which counts the slow start and end of a turn as static.
    pub detect_with_gyro: bool,
}

impl Default for CalibOptions {
    fn default() -> Self {
        CalibOptions {
            gravity: crate::io::STANDARD_GRAVITY,
            init_static_s: 50.0,
            window_s: 0.5,
            min_interval_s: 0.5,
            multipliers: (2..=10).map(f64::from).collect(),
            estimate_gyro_bias: false,
            min_intervals: 12,
            detect_with_gyro: true,
        }
    }
}

/// Why a recording cannot be calibrated.
#[derive(Debug, Clone, PartialEq)]
pub struct CalibError {
    /// The recording (file name).
    pub source: String,
    /// What is wrong.
    pub message: String,
    /// What to do about it.
    pub hint: Option<String>,
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

/// How to record a usable tumble session (printed with errors).
pub const RECORDING_ADVICE: &str = "record ≥ 50 s perfectly still first, then ≥ 20 (better 50) different \
orientations, each held still for 1–4 s (rest the IMU against something), turning by hand between them so \
that every axis points up and down at least once";

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

/// Everything [`calibrate`] found.
#[derive(Debug, Clone)]
pub struct CalibrationResult {
    /// The calibration with 1-σ uncertainties.
    pub calibration: ImuCalibration,
    /// The multiplier `k` kept and the variance threshold it gives \[raw units²\].
    pub multiplier: f64,
    /// See `multiplier`.
    pub threshold: f64,
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
    /// Detection score per sample: windowed variance over the initial period's, the
    /// larger of accelerometer and gyro (accelerometer only without `detect_with_gyro`);
    /// static where below the multiplier.
    pub ratio: Vec<f64>,
    /// Problems that did not stop the calibration.
    pub warnings: Vec<String>,
}

/// The accelerometer estimate of one detection.
struct AccelFit {
    params: AccelParams,
    cov: DMatrix<f64>,
    stats: FitStats,
}

/// Calibrate accelerometer and gyroscope from one hand-tumbled recording.
///
/// ```no_run
/// use tumble::calib::{calibrate, CalibOptions};
/// use tumble::io::{open_recording, RecordingOptions};
/// let rec = open_recording("tumble_asl/".as_ref(), &RecordingOptions::default()).unwrap();
/// let result = calibrate(&rec, &CalibOptions { gravity: 9.81, ..Default::default() }).unwrap();
/// println!("K_a = {:?} ± {:?}", result.calibration.accel.k, result.calibration.accel.k_std);
/// ```
pub fn calibrate(rec: &ImuRecording, opts: &CalibOptions) -> Result<CalibrationResult, CalibError> {
    let err = |message: String, hint: Option<&str>| CalibError {
        source: rec.source_name(),
        message,
        hint: hint.map(str::to_string),
    };
    if !(opts.gravity.is_finite() && opts.gravity > 0.0) {
        return Err(err(format!("gravity must be positive, got {}", opts.gravity), None));
    }
    if rec.accel.len() != rec.len() || rec.gyro.len() != rec.len() {
        return Err(err("calibration needs both accelerometer and gyro samples".into(), None));
    }
    if let Some(i) = (0..rec.len())
        .find(|&i| !rec.t[i].is_finite() || rec.accel[i].iter().chain(&rec.gyro[i]).any(|x| !x.is_finite()))
    {
        return Err(err(format!("sample {} (line {}) is not finite", i, rec.lines.line(i)), None));
    }
    let mut warnings = Vec::new();
    if !(9.7..9.9).contains(&opts.gravity) {
        warnings.push(format!("gravity {} m/s² is outside 9.7–9.9: is it right?", opts.gravity));
    }
    let n = rec.len();
    if n < 100 || rec.duration() <= opts.init_static_s {
        return Err(err(
            format!("{:.1} s of data: less than the {} s initial static period", rec.duration(), opts.init_static_s),
            Some(RECORDING_ADVICE),
        ));
    }
    let mut dts: Vec<f64> = rec.t.windows(2).map(|w| w[1] - w[0]).collect();
    dts.sort_by(f64::total_cmp);
    let period = dts[dts.len() / 2];
    if period.is_nan() || period <= 0.0 {
        return Err(err("timestamps do not increase".into(), None));
    }
    let n_init = rec.t.partition_point(|&t| t < opts.init_static_s);
    let half = ((opts.window_s / period / 2.0).round() as usize).max(2);
    let w = 2 * half + 1;
    let min_len = ((opts.min_interval_s / period).round() as usize).max(3);
    if n_init < 2 * w {
        return Err(err(format!("initial static period has only {n_init} samples; need ≥ {}", 2 * w), None));
    }

    let score = sliding_variance_norm(&rec.accel, w);
    let gyro_score = sliding_variance_norm(&rec.gyro, w);
    let var_a = var3(&rec.accel[..n_init]);
    let var_g = var3(&rec.gyro[..n_init]);
    let norm = |v: &[f64; 3]| v.iter().map(|x| x * x).sum::<f64>().sqrt();
    let var_init = norm(&var_a);
    check_initial_static(rec, &score, &gyro_score, n_init, half, var_init, &mut warnings)
        .map_err(|(m, h)| err(m, Some(h)))?;
    let base = var_init.max(1e-300);
    // Detection score: windowed variance relative to the initial period's, the larger of
    // accelerometer and gyro (the gyro catches slow turns the accelerometer hardly sees).
    let mut ratio: Vec<f64> = score.iter().map(|s| s / base).collect();
    if opts.detect_with_gyro {
        let gyro_base = norm(&var_g).max(1e-300);
        for (r, g) in ratio.iter_mut().zip(&gyro_score) {
            *r = r.max(g / gyro_base);
        }
    }

    // A steady turn about gravity keeps both windowed variances low: an interval whose
    // mean rate is far above the initial period's noise is a turn, not a pose.
    let b_init = Vector3::from(mean3(&rec.gyro[..n_init]));
    let floor = if rec.gyro_units == Stored::RawCounts { 0.0 } else { MIN_TURN_RATE };
    let turn_limit = Vector3::from(var_g.map(|v| (TURN_SIGMAS * v.sqrt()).max(floor)));
    // Threshold sweep: one accelerometer fit per multiplier.
    let candidates: Vec<(f64, Vec<Interval>, Option<AccelFit>)> = opts
        .multipliers
        .par_iter()
        .map(|&k| {
            let iv = not_turning(rec, intervals_below(&ratio, k, min_len), &b_init, turn_limit);
            let fit = (iv.len() >= opts.min_intervals).then(|| fit_accel(rec, &iv, opts.gravity, &var_a)).flatten();
            (k, iv, fit)
        })
        .collect();
    let sweep: Vec<SweepEntry> = candidates
        .iter()
        .map(|(k, iv, fit)| SweepEntry {
            multiplier: *k,
            intervals: iv.len(),
            chi2_per_dof: fit.as_ref().map(|f| f.stats.chi2_per_dof),
            rms_norm_error: fit.as_ref().map(|f| f.stats.rms),
        })
        .collect();
    let best = candidates
        .into_iter()
        .filter_map(|(k, iv, fit)| fit.map(|f| (k, iv, f)))
        .min_by(|a, b| a.2.stats.chi2_per_dof.total_cmp(&b.2.stats.chi2_per_dof));
    let Some((multiplier, intervals, accel)) = best else {
        let most = sweep.iter().map(|s| s.intervals).max().unwrap_or(0);
        return Err(err(
            format!(
                "found at most {most} usable static intervals (≥ {:.2} s each) over threshold multipliers {:?}; \
                 calibration needs ≥ {}",
                min_len as f64 * period,
                opts.multipliers,
                opts.min_intervals
            ),
            Some(RECORDING_ADVICE),
        ));
    };

    let ma = accel_matrix(&accel.params);
    let ba = Vector3::new(accel.params[6], accel.params[7], accel.params[8]);
    let means: Vec<Vector3<f64>> =
        intervals.iter().map(|iv| Vector3::from(mean3(&rec.accel[iv.start..iv.end]))).collect();
    let dirs: Vec<Vector3<f64>> = means.iter().map(|m| ma * (m - ba)).collect();
    excitation_warnings(&dirs, &mut warnings).map_err(|m| err(m, Some(RECORDING_ADVICE)))?;

    let gyro = fit_gyro(rec, &intervals, &means, &accel, &var_a, &var_g, n_init, opts).map_err(|m| err(m, None))?;
    warnings.extend(gyro.warnings.iter().cloned());

    // Paper convention with propagated uncertainties.
    let accel_triad = accel_triad(&accel.params, &accel.cov, accel.stats.covariance_inflation);
    let gyro_triad = gyro_triad(&gyro.x, &gyro.cov);
    let units = Units {
        accel_input: if rec.accel_units == Stored::RawCounts { "counts" } else { "m/s^2" }.into(),
        gyro_input: if rec.gyro_units == Stored::RawCounts { "counts" } else { "rad/s" }.into(),
        ..Units::default()
    };
    let static_intervals = intervals
        .iter()
        .zip(&dirs)
        .map(|(iv, a)| StaticInterval {
            start_s: rec.t[iv.start],
            end_s: rec.t[iv.end - 1],
            start_ns: rec.t_ns(iv.start),
            end_ns: rec.t_ns(iv.end - 1),
            samples: iv.len(),
            accel: [a.x, a.y, a.z],
            norm_error: a.norm() - opts.gravity,
        })
        .collect();
    Ok(CalibrationResult {
        calibration: ImuCalibration {
            accel: accel_triad,
            gyro: gyro_triad,
            gravity: opts.gravity,
            units,
            effects: None,
            time_offsets: None,
        },
        multiplier,
        threshold: multiplier * base,
        ratio,
        intervals,
        static_intervals,
        sweep,
        accel_fit: accel.stats,
        gyro_fit: gyro.stats,
        rotations: gyro.rotations,
        score,
        warnings,
    })
}

/// An interval whose mean gyro reading differs from the initial period's on some
/// axis by more than this many per-sample standard deviations of that axis in
/// that period is a steady turn.
const TURN_SIGMAS: f64 = 30.0;
/// Smallest such difference per axis \[rad/s\] for gyros read in SI units (3 °/s).
const MIN_TURN_RATE: f64 = 0.05;

/// `intervals` without the steady turns (see [`TURN_SIGMAS`]).
fn not_turning(
    rec: &ImuRecording,
    intervals: Vec<Interval>,
    b_init: &Vector3<f64>,
    limit: Vector3<f64>,
) -> Vec<Interval> {
    intervals
        .into_iter()
        .filter(|iv| {
            let d = Vector3::from(mean3(&rec.gyro[iv.start..iv.end])) - b_init;
            (0..3).all(|k| d[k].abs() <= limit[k])
        })
        .collect()
}

/// The first period must be still: its windowed variance must be uniform and
/// as low as the quietest parts of the recording.
#[allow(clippy::too_many_arguments)]
fn check_initial_static(
    rec: &ImuRecording,
    score: &[f64],
    gyro_score: &[f64],
    n_init: usize,
    half: usize,
    var_init: f64,
    warnings: &mut Vec<String>,
) -> Result<(), (String, &'static str)> {
    // Windows wholly inside the initial period.
    let inside = n_init.saturating_sub(half).max(1);
    let mut init: Vec<f64> = score[..inside].iter().copied().filter(|x| x.is_finite()).collect();
    let mut all: Vec<f64> = score.iter().copied().filter(|x| x.is_finite()).collect();
    if init.is_empty() || all.is_empty() {
        return Ok(());
    }
    init.sort_by(f64::total_cmp);
    all.sort_by(f64::total_cmp);
    let med = init[init.len() / 2];
    let worst = init[init.len() - 1];
    let quiet = all[all.len() / 20];
    let advice = "start the recording with the IMU lying perfectly still for the whole initial period \
                  (--init-static sets its length)";
    // A rotation shows in the gyro (compared with its quietest windows anywhere in the
    // recording); a knock or vibration only in the accelerometer.
    let mut g: Vec<f64> = gyro_score.iter().copied().filter(|x| x.is_finite()).collect();
    g.sort_by(f64::total_cmp);
    let g_quiet = g.get(g.len() / 20).copied().unwrap_or(0.0).max(1e-300);
    if let Some(i) = gyro_score[..inside].iter().position(|&x| x.is_finite() && x > 10.0 * g_quiet) {
        return Err((
            format!(
                "the initial static period is not static: the IMU turns at t = {:.2} s (line {})",
                rec.t[i],
                rec.lines.line(i)
            ),
            advice,
        ));
    }
    let moving_at = score[..inside].iter().position(|&x| x.is_finite() && x > 20.0 * med.max(1e-300));
    if let Some(i) = moving_at.filter(|_| worst > 20.0 * med.max(1e-300)) {
        warnings.push(format!(
            "the initial static period is disturbed at t = {:.2} s (line {}): the accelerometer shakes but the gyro \
             does not turn (a knock or vibration?); it raises the detection threshold",
            rec.t[i],
            rec.lines.line(i)
        ));
    }
    if med > 20.0 * quiet.max(1e-300) || var_init > 20.0 * quiet.max(1e-300) {
        return Err((
            format!(
                "the initial period is {:.0}× noisier than the quietest 5 % of the recording: it is not static",
                (med.max(var_init) / quiet.max(1e-300))
            ),
            advice,
        ));
    }
    Ok(())
}

fn excitation_warnings(dirs: &[Vector3<f64>], warnings: &mut Vec<String>) -> Result<(), String> {
    let mut scatter = Matrix3::zeros();
    for d in dirs {
        let u = d.normalize();
        scatter += u * u.transpose();
    }
    scatter /= dirs.len() as f64;
    let eig = scatter.symmetric_eigen();
    let (imin, lmin) =
        eig.eigenvalues.iter().enumerate().fold((0, f64::MAX), |a, (i, &l)| if l < a.1 { (i, l) } else { a });
    let v = eig.eigenvectors.column(imin);
    if lmin < 0.01 {
        return Err(format!(
            "the static poses do not excite every axis: gravity never points along ({:+.2}, {:+.2}, {:+.2}) \
             (smallest eigenvalue of the direction scatter {lmin:.4}; a uniform spread gives 0.33)",
            v[0], v[1], v[2]
        ));
    }
    if lmin < 0.05 {
        warnings.push(format!(
            "poses excite the direction ({:+.2}, {:+.2}, {:+.2}) weakly (scatter eigenvalue {lmin:.3}, uniform 0.33): \
             expect larger uncertainties",
            v[0], v[1], v[2]
        ));
    }
    for (k, axis) in ["x", "y", "z"].iter().enumerate() {
        let (lo, hi) = dirs.iter().fold((f64::MAX, f64::MIN), |(lo, hi), d| {
            let u = d[k] / d.norm();
            (lo.min(u), hi.max(u))
        });
        if hi < 0.5 || lo > -0.5 {
            warnings.push(format!(
                "the {axis} axis never points within 60° of {}: its scale and bias are weakly separated",
                if hi < 0.5 { "up" } else { "down" }
            ));
        }
    }
    Ok(())
}

/// Axis-aligned ellipsoid through the interval means (linear least squares):
/// the initial bias (centre) and inverse scale (g / semi-axis).
fn ellipsoid_guess(means: &[Vector3<f64>], g: f64) -> Option<AccelParams> {
    // Centre the data for conditioning.
    let c0 = means.iter().sum::<Vector3<f64>>() / means.len() as f64;
    let spread = means.iter().map(|m| (m - c0).amax()).fold(0.0, f64::max).max(1e-300);
    let mut a = DMatrix::zeros(means.len(), 6);
    let rhs = DVector::from_element(means.len(), 1.0);
    for (i, m) in means.iter().enumerate() {
        let x = (m - c0) / spread;
        for k in 0..3 {
            a[(i, k)] = x[k] * x[k];
            a[(i, 3 + k)] = x[k];
        }
    }
    let sol = a.svd(true, true).solve(&rhs, 1e-12).ok()?;
    let mut p = AccelParams::zeros();
    let centre: Vector3<f64> = Vector3::from_fn(|k, _| -sol[3 + k] / (2.0 * sol[k]));
    let rhs = 1.0 + (0..3).map(|k| sol[k] * centre[k] * centre[k]).sum::<f64>();
    for k in 0..3 {
        let r2 = rhs / sol[k];
        if !(r2 > 0.0 && r2.is_finite()) {
            return None;
        }
        p[[0, 3, 5][k]] = g / (r2.sqrt() * spread);
        p[6 + k] = c0[k] + centre[k] * spread;
    }
    p.iter().all(|x| x.is_finite()).then_some(p)
}

/// Fallback guess: centre and half-range of each axis's interval means.
fn range_guess(means: &[Vector3<f64>], g: f64) -> AccelParams {
    let mut p = AccelParams::zeros();
    for k in 0..3 {
        let lo = means.iter().map(|m| m[k]).fold(f64::MAX, f64::min);
        let hi = means.iter().map(|m| m[k]).fold(f64::MIN, f64::max);
        p[6 + k] = 0.5 * (lo + hi);
        p[[0, 3, 5][k]] = 2.0 * g / (hi - lo).max(1e-300);
    }
    p
}

fn fit_accel(rec: &ImuRecording, intervals: &[Interval], g: f64, var_a: &[f64; 3]) -> Option<AccelFit> {
    let means: Vec<Vector3<f64>> =
        intervals.iter().map(|iv| Vector3::from(mean3(&rec.accel[iv.start..iv.end]))).collect();
    let x0 = ellipsoid_guess(&means, g).unwrap_or_else(|| range_guess(&means, g));
    let m0 = accel_matrix(&x0);
    let b0 = Vector3::new(x0[6], x0[7], x0[8]);
    let mut factors = Vec::new();
    let mut base = Vec::new();
    for (iv, m) in intervals.iter().zip(&means) {
        // Noise of g² − |a|²: 2g times the noise of |a| along gravity (white noise of the mean).
        let u = (m0 * (m - b0)).normalize();
        let var: f64 = (0..3).map(|k| (u[k] * m0[(k, k)]).powi(2) * var_a[k]).sum::<f64>() / iv.len() as f64;
        base.push(DMatrix::from_element(1, 1, (2.0 * g * var.sqrt()).max(1e-9 * g * g).powi(2)));
        factors.push(GravityNormFactor::new(KEY_ACCEL, *m, g));
    }
    let mut values = Values::new();
    values.insert(KEY_ACCEL, x0);
    let fit = solve_with_floor(&factors, &base, &values, 9).ok()?;
    let (sol, graph) = (&fit.values, &fit.graph);
    let params = *sol.get::<AccelParams>(KEY_ACCEL).ok()?;
    let cov = covariances(graph, sol, &[KEY_ACCEL]).ok()?.get(KEY_ACCEL)?;
    let chi2 = fit.chi2_white;
    let ma = accel_matrix(&params);
    let ba = Vector3::new(params[6], params[7], params[8]);
    let rms = (means.iter().map(|m| ((ma * (m - ba)).norm() - g).powi(2)).sum::<f64>() / means.len() as f64).sqrt();
    let imu_tk_cost = 0.5
        * intervals
            .iter()
            .flat_map(|iv| &rec.accel[iv.start..iv.start + iv.len().min(100)])
            .map(|a| (g * g - (ma * (Vector3::from(*a) - ba)).norm_squared()).powi(2))
            .sum::<f64>();
    if !chi2.is_finite() {
        return None;
    }
    Some(AccelFit {
        params,
        cov,
        stats: FitStats {
            residuals: intervals.len(),
            parameters: 9,
            chi2_per_dof: chi2,
            unmodelled_sigma: fit.floor / (2.0 * g),
            covariance_inflation: fit.chi2_final.max(1.0),
            rms,
            imu_tk_cost,
            iterations: fit.iterations,
        },
    })
}

/// A solve whose noise model may have been widened by an unmodelled-error floor.
struct FloorFit {
    values: Values,
    graph: Graph,
    /// χ²/dof with the base noise.
    chi2_white: f64,
    /// χ²/dof with the floor (≈ 1 when a floor was added).
    chi2_final: f64,
    /// The floor, in residual units.
    floor: f64,
    iterations: usize,
}

/// Solve factors with per-factor noise covariances `base`; when the residuals
/// exceed that noise (χ²/dof > 1), add a common isotropic floor `s²` (C_k + s² I)
/// that makes χ²/dof = 1 — a variance-component estimate of what the model does
/// not explain, which evens out the weights of long and short intervals — and re-solve.
fn solve_with_floor<F: Factor + Clone + 'static>(
    factors: &[F],
    base: &[DMatrix<f64>],
    values: &Values,
    n_params: usize,
) -> Result<FloorFit, String> {
    let dim = factors.first().map(|f| f.residual_dim()).unwrap_or(1);
    let dof = (dim * factors.len()).saturating_sub(n_params).max(1) as f64;
    let lm = Optimizer::new(LmOptions { function_tolerance: 1e-10, ..LmOptions::default() });
    let widen = |c: &DMatrix<f64>, s2: f64| c + DMatrix::identity(dim, dim) * s2;
    let build = |s2: f64| -> Result<Graph, String> {
        let mut g = Graph::new();
        for (f, c) in factors.iter().zip(base) {
            g.add(f.clone(), NoiseModel::from_covariance(&widen(c, s2)).map_err(|e| e.to_string())?);
        }
        Ok(g)
    };
    let graph = build(0.0)?;
    let (mut sol, summary) = lm.optimize(&graph, values).map_err(|e| e.to_string())?;
    let chi2_white = 2.0 * summary.final_cost / dof;
    let mut iterations = summary.iterations;
    let (mut graph, mut s2, mut chi2_final) = (graph, 0.0, chi2_white);
    for _ in 0..3 {
        if chi2_final <= 1.0 + 1e-3 {
            break;
        }
        let residual = |f: &F| -> Result<DVector<f64>, String> {
            let vars: Vec<&dyn tumble_solvers::DynVariable> =
                f.keys().iter().map(|k| sol.get_dyn(*k)).collect::<Result<_, _>>().map_err(|e| e.to_string())?;
            f.residual(Vars::new(&vars)).map_err(|e| e.to_string())
        };
        let rs: Vec<DVector<f64>> = factors.iter().map(residual).collect::<Result<_, _>>()?;
        let chi2 = |s2: f64| {
            rs.iter()
                .zip(base)
                .map(|(r, c)| widen(c, s2).cholesky().map(|ch| r.dot(&ch.solve(r))).unwrap_or(f64::MAX))
                .sum::<f64>()
                / dof
        };
        let (mut lo, mut hi) = (s2, rs.iter().map(|r| r.norm_squared()).fold(0.0, f64::max).max(1e-300));
        while chi2(hi) > 1.0 {
            hi *= 4.0;
        }
        for _ in 0..60 {
            let mid = 0.5 * (lo + hi);
            if chi2(mid) > 1.0 {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        s2 = hi;
        graph = build(s2)?;
        let (next, summary) = lm.optimize(&graph, &sol).map_err(|e| e.to_string())?;
        sol = next;
        iterations += summary.iterations;
        chi2_final = 2.0 * summary.final_cost / dof;
    }
    Ok(FloorFit { values: sol, graph, chi2_white, chi2_final, floor: s2.sqrt(), iterations })
}

struct GyroFit {
    /// `[M_g row major (9), b_g (3)]`.
    x: [f64; 12],
    /// Its covariance (12×12, inflated).
    cov: DMatrix<f64>,
    stats: FitStats,
    rotations: Vec<RotationResidual>,
    warnings: Vec<String>,
}

#[allow(clippy::too_many_arguments)]
fn fit_gyro(
    rec: &ImuRecording,
    intervals: &[Interval],
    means: &[Vector3<f64>],
    accel: &AccelFit,
    var_a: &[f64; 3],
    var_g: &[f64; 3],
    n_init: usize,
    opts: &CalibOptions,
) -> Result<GyroFit, String> {
    let directions = |pa: &AccelParams| -> Vec<Vector3<f64>> {
        let (ma, ba) = (accel_matrix(pa), Vector3::new(pa[6], pa[7], pa[8]));
        means.iter().map(|m| ma * (m - ba)).collect()
    };
    let dirs = directions(&accel.params);
    let ma = &accel_matrix(&accel.params);
    let b0 = Vector3::from(mean3(&rec.gyro[..n_init]));
    let mut factors = Vec::new();
    let mut pairs = Vec::new();
    for k in 1..intervals.len() {
        let (a, b) = (intervals[k - 1].end - 1, intervals[k].start);
        let raw = rec.gyro[a..=b].to_vec();
        let dt = rec.t[a..=b].windows(2).map(|w| w[1] - w[0]).collect();
        let f = IntegratedRotationFactor::new([KEY_GYRO, KEY_GYRO_BIAS], raw, dt, dirs[k - 1], dirs[k])
            .map_err(|e| format!("motion between static intervals {} and {k}: {e}", k - 1))?;
        factors.push(f);
        pairs.push((k - 1, k));
    }
    // Initial isotropic scale: every turn's gravity angle θ ≤ s ∫|ω̃ − b| dt gives a lower
    // bound on s; then a golden-section search of the isotropic cost above it.
    let mut s_lo = 0.0f64;
    for &(i, j) in &pairs {
        let theta = dirs[i].normalize().dot(&dirs[j].normalize()).clamp(-1.0, 1.0).acos();
        let len: f64 = integrated_raw_angle(rec, intervals[i].end - 1, intervals[j].start, &b0);
        if len > 0.0 && theta > 0.2 {
            s_lo = s_lo.max(theta / len);
        }
    }
    if !(s_lo > 0.0 && s_lo.is_finite()) {
        return Err("no turn between static intervals rotates gravity by more than 11°: nothing to calibrate the \
                    gyroscope with"
            .into());
    }
    let iso_cost = |s: f64| -> f64 {
        let m = Matrix3::identity() * s;
        factors
            .par_iter()
            .map(|f| {
                let vars: [&dyn tumble_solvers::DynVariable; 2] = [&gyro_vec(&m), &b0];
                f.residual(Vars::new(&vars)).map(|r| r.norm_squared()).unwrap_or(f64::MAX)
            })
            .sum()
    };
    let (mut lo, mut hi) = ((0.8 * s_lo).ln(), (4.0 * s_lo).ln());
    let phi = 0.5 * (5f64.sqrt() - 1.0);
    let (mut x1, mut x2) = (hi - phi * (hi - lo), lo + phi * (hi - lo));
    let (mut f1, mut f2) = (iso_cost(x1.exp()), iso_cost(x2.exp()));
    for _ in 0..20 {
        if f1 < f2 {
            hi = x2;
            x2 = x1;
            f2 = f1;
            x1 = hi - phi * (hi - lo);
            f1 = iso_cost(x1.exp());
        } else {
            lo = x1;
            x1 = x2;
            f1 = f2;
            x2 = lo + phi * (hi - lo);
            f2 = iso_cost(x2.exp());
        }
    }
    let s0 = (0.5 * (lo + hi)).exp();

    // Noise: the gyro's white noise integrated over each turn (per axis, through the
    // steps' Jacobians) plus the two gravity directions' noise.
    let m0 = Matrix3::identity() * s0;
    let var_acc: f64 = (0..3).map(|k| ma[(k, k)].powi(2) * var_a[k]).sum::<f64>() / 3.0;
    let g2 = opts.gravity * opts.gravity;
    let raw_var = Vector3::from(*var_g);
    let base: Vec<DMatrix<f64>> = factors
        .par_iter()
        .zip(&pairs)
        .map(|(f, &(i, j))| {
            let dir = var_acc / g2 * (1.0 / intervals[i].len() as f64 + 1.0 / intervals[j].len() as f64);
            let c = f.noise_covariance(&m0, &b0, &raw_var) + nalgebra::Matrix2::identity() * dir.max(1e-24);
            DMatrix::from_column_slice(2, 2, c.as_slice())
        })
        .collect();
    let mut values = Values::new();
    values.insert(KEY_GYRO, gyro_vec(&(Matrix3::identity() * s0)));
    values.insert(KEY_GYRO_BIAS, b0);
    values.set_constant(KEY_GYRO_BIAS, !opts.estimate_gyro_bias);
    let n_params = 9 + 3 * opts.estimate_gyro_bias as usize;
    let fit = solve_with_floor(&factors, &base, &values, n_params).map_err(|e| format!("gyroscope fit failed: {e}"))?;
    let (sol, graph) = (&fit.values, &fit.graph);
    let p = *sol.get::<GyroMatrix>(KEY_GYRO).map_err(|e| e.to_string())?;
    let b = *sol.get::<Vector3<f64>>(KEY_GYRO_BIAS).map_err(|e| e.to_string())?;
    let m = gyro_matrix(&p);
    let keys: Vec<Key> = if opts.estimate_gyro_bias { vec![KEY_GYRO, KEY_GYRO_BIAS] } else { vec![KEY_GYRO] };
    let cv = covariances(graph, sol, &keys).map_err(|e| format!("gyroscope covariance: {e}"))?;
    let inflation = fit.chi2_final.max(1.0);
    let mut cov = DMatrix::zeros(12, 12);
    cov.view_mut((0, 0), (9, 9)).copy_from(&(cv.get(KEY_GYRO).ok_or("no covariance")? * inflation));
    if opts.estimate_gyro_bias {
        cov.view_mut((9, 9), (3, 3)).copy_from(&(cv.get(KEY_GYRO_BIAS).ok_or("no covariance")? * inflation));
        let cross = cv.block(KEY_GYRO, KEY_GYRO_BIAS).ok_or("no covariance")? * inflation;
        cov.view_mut((0, 9), (9, 3)).copy_from(&cross);
        cov.view_mut((9, 0), (3, 9)).copy_from(&cross.transpose());
    } else {
        // Mean of the initial static period: white-noise standard error.
        for k in 0..3 {
            cov[(9 + k, 9 + k)] = var_g[k] / n_init as f64;
        }
    }
    // The gravity directions come from the accelerometer fit: carry its uncertainty
    // into the gyro parameters, ∂x_g/∂x_a by re-solving with each accelerometer
    // parameter moved by ±1σ (central differences).
    let acc_cov = &accel.cov * accel.stats.covariance_inflation;
    let resolve = |pa: &AccelParams| -> Option<[f64; 12]> {
        let d = directions(pa);
        let mut g = Graph::new();
        for ((f, &(i, j)), c) in factors.iter().zip(&pairs).zip(&base) {
            let c = c + DMatrix::identity(2, 2) * fit.floor.powi(2);
            g.add(f.with_directions(d[i], d[j]), NoiseModel::from_covariance(&c).ok()?);
        }
        let (s, _) =
            Optimizer::new(LmOptions { function_tolerance: 1e-12, ..LmOptions::default() }).optimize(&g, sol).ok()?;
        let mut x = [0.0; 12];
        x[..9].copy_from_slice(s.get::<GyroMatrix>(KEY_GYRO).ok()?.as_slice());
        x[9..].copy_from_slice(s.get::<Vector3<f64>>(KEY_GYRO_BIAS).ok()?.as_slice());
        Some(x)
    };
    let columns: Vec<Option<Vec<f64>>> = (0..9)
        .into_par_iter()
        .map(|k| {
            let h = acc_cov[(k, k)].max(0.0).sqrt();
            if h == 0.0 {
                return Some(vec![0.0; 12]);
            }
            let (mut lo, mut hi) = (accel.params, accel.params);
            lo[k] -= h;
            hi[k] += h;
            let (a, b) = (resolve(&lo)?, resolve(&hi)?);
            Some((0..12).map(|i| (b[i] - a[i]) / (2.0 * h)).collect())
        })
        .collect();
    if let Some(cols) = columns.into_iter().collect::<Option<Vec<_>>>() {
        let j = DMatrix::from_fn(12, 9, |r, c| cols[c][r]);
        cov += &j * acc_cov * j.transpose();
    } else {
        return Err("gyroscope fit does not converge when the accelerometer parameters move by 1σ".into());
    }
    let mut rotations = Vec::new();
    let (mut sq, mut tk) = (0.0, 0.0);
    for (f, &(i, j)) in factors.iter().zip(&pairs) {
        let r = f.rotation(&m, &b);
        let (g0, g1) = (dirs[i].normalize(), dirs[j].normalize());
        let pred = r.transpose() * g0;
        let e = pred.cross(&g1).norm().atan2(pred.dot(&g1));
        sq += e * e;
        tk += 0.5 * (pred - g1).norm_squared();
        let turn = nalgebra::Rotation3::from_matrix_unchecked(r).angle().to_degrees();
        rotations.push(RotationResidual { from: i, to: j, rotation_deg: turn, error_rad: e });
    }
    let mut x = [0.0; 12];
    x[..9].copy_from_slice(p.as_slice());
    x[9..].copy_from_slice(b.as_slice());
    let mut warnings = Vec::new();
    let sv = m.svd(false, false).singular_values;
    if sv.min() <= 0.0 || sv.max() / sv.min() > 1.5 {
        warnings.push(format!("gyro matrix is far from a rotation-free scale (singular values {sv:?}): check the fit"));
    }
    Ok(GyroFit {
        x,
        cov,
        stats: FitStats {
            residuals: 2 * factors.len(),
            parameters: n_params,
            chi2_per_dof: fit.chi2_white,
            unmodelled_sigma: fit.floor,
            covariance_inflation: inflation,
            rms: (sq / factors.len() as f64).sqrt(),
            imu_tk_cost: tk,
            iterations: fit.iterations,
        },
        rotations,
        warnings,
    })
}

/// `Σ |ū_i − b| Δt_i` over samples `a..=b` (raw units · s).
fn integrated_raw_angle(rec: &ImuRecording, a: usize, b: usize, bias: &Vector3<f64>) -> f64 {
    (a..b)
        .map(|i| {
            let u = (Vector3::from(rec.gyro[i]) + Vector3::from(rec.gyro[i + 1])) * 0.5 - bias;
            u.norm() * (rec.t[i + 1] - rec.t[i])
        })
        .sum()
}

fn gyro_vec(m: &Matrix3<f64>) -> GyroMatrix {
    GyroMatrix::from_row_slice(&[
        m[(0, 0)],
        m[(0, 1)],
        m[(0, 2)],
        m[(1, 0)],
        m[(1, 1)],
        m[(1, 2)],
        m[(2, 0)],
        m[(2, 1)],
        m[(2, 2)],
    ])
}

/// Standard deviations of `f(x)` from `cov(x)` by a central-difference Jacobian.
fn propagate_std(f: &dyn Fn(&[f64]) -> Vec<f64>, x: &[f64], cov: &DMatrix<f64>) -> Vec<f64> {
    let y0 = f(x);
    let mut j = DMatrix::zeros(y0.len(), x.len());
    for c in 0..x.len() {
        let h = 1e-6 * x[c].abs().max(1e-6);
        let mut xp = x.to_vec();
        let mut xm = x.to_vec();
        xp[c] += h;
        xm[c] -= h;
        let (yp, ym) = (f(&xp), f(&xm));
        for r in 0..y0.len() {
            j[(r, c)] = (yp[r] - ym[r]) / (2.0 * h);
        }
    }
    let c = &j * cov * j.transpose();
    (0..y0.len()).map(|i| c[(i, i)].max(0.0).sqrt()).collect()
}

/// `(T, K)` of the paper from the inverse model matrix `M = (T K)⁻¹`, as
/// `[T row major (9), K (3)]` (NaN when singular).
fn paper_tk(m: &Matrix3<f64>) -> Vec<f64> {
    let Some((t, k)) = m.try_inverse().and_then(|n| split_unit_diagonal(&n)) else {
        return vec![f64::NAN; 12];
    };
    let mut v: Vec<f64> = (0..9).map(|i| t[(i / 3, i % 3)]).collect();
    v.extend(k.iter());
    v
}

fn triad_from(y: &[f64], s: &[f64], b: Vector3<f64>, b_std: Vector3<f64>) -> Triad {
    Triad {
        t: Matrix3::from_row_slice(&y[..9]),
        k: Vector3::new(y[9], y[10], y[11]),
        b,
        t_std: Matrix3::from_row_slice(&s[..9]),
        k_std: Vector3::new(s[9], s[10], s[11]),
        b_std,
    }
}

pub(crate) fn accel_triad(p: &AccelParams, cov: &DMatrix<f64>, inflation: f64) -> Triad {
    let f = |x: &[f64]| {
        let mut m = Matrix3::zeros();
        for (k, &(r, c)) in UPPER.iter().enumerate() {
            m[(r, c)] = x[k];
        }
        paper_tk(&m)
    };
    let cov = cov * inflation;
    let y = f(p.as_slice());
    let s = propagate_std(&f, &p.as_slice()[..6], &cov.view((0, 0), (6, 6)).into_owned());
    let b_std = Vector3::from_fn(|k, _| (cov[(6 + k, 6 + k)]).max(0.0).sqrt());
    triad_from(&y, &s, Vector3::new(p[6], p[7], p[8]), b_std)
}

pub(crate) fn gyro_triad(x: &[f64; 12], cov: &DMatrix<f64>) -> Triad {
    let f = |x: &[f64]| paper_tk(&Matrix3::from_row_slice(&x[..9]));
    let y = f(x);
    let s = propagate_std(&f, &x[..9], &cov.view((0, 0), (9, 9)).into_owned());
    let b_std = Vector3::from_fn(|k, _| cov[(9 + k, 9 + k)].max(0.0).sqrt());
    triad_from(&y, &s, Vector3::new(x[9], x[10], x[11]), b_std)
}
