//! The calibration pipeline: detect static intervals (sweeping the threshold
//! multiplier), fit the accelerometer with gravity-norm factors, then the
//! gyroscope with integrated-rotation factors, both on the solver, and turn
//! the estimates and their covariances into the paper's convention.

use super::detect::{
    axis_noise, axis_ratio, find_initial_rest, intervals_below, mean3, norms, quietest, sliding_mean, sliding_variance,
    var3, InitialRest, Interval,
};
use super::fit::*;
use super::observability::names;
use super::options::{CalibOptions, MIN_INITIAL_REST_S, PAPER_INITIAL_REST_S, PAPER_MIN_HOLD_S, RECORDING_ADVICE};
use super::result::*;
use super::result::{Assessment, Verdict};
use crate::io::{ImuRecording, Stored};
use crate::model::calibration::{ImuCalibration, Units};
use crate::model::numeric::median;
use nalgebra::{Matrix3, Vector3};
use rayon::prelude::*;
use tumble_factors::imu_calib::accel_matrix;

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
    let err = |message: String, hint: Option<&str>| CalibError::new(rec, message, hint);
    opts.validate().map_err(|e| err(e.to_string(), None))?;
    check_recording(rec, opts)?;
    let mut warnings = Vec::new();
    let scores = Scores::of(rec, opts)?;
    let rest = initial_rest(rec, opts, &scores, &mut warnings)?;
    let ratio = detection_ratio(rec, opts, &scores, &rest);
    let gyro_inputs = GyroInputs {
        var_a: &rest.var_a,
        var_g: &rest.var_g,
        bias: &rest.gyro_bias,
        n_init: rest.samples,
        edge: scores.half,
    };
    let (sweep, best) = sweep_thresholds(rec, opts, &scores, &rest, &ratio, &gyro_inputs)?;
    let Kept { multiplier, intervals, accel } = best;
    // The kept detection's gyro fit again, with the accelerometer's uncertainty carried into it.
    let means = interval_means(rec, &intervals);
    let gyro = fit_gyro(rec, &intervals, &means, &accel, &gyro_inputs, opts, true, GyroStart::Search)
        .map_err(|m| err(m, None))?;
    let halves_start = GyroStart::Scale { scale: gyro.starts[0], from: Some(gyro.matrix()) };
    let ma = accel_matrix(&accel.params);
    let ba = Vector3::new(accel.params[6], accel.params[7], accel.params[8]);
    let dirs: Vec<Vector3<f64>> = means.iter().map(|m| ma * (m - ba)).collect();
    excitation_warnings(&dirs, &mut warnings).map_err(|m| err(m, Some(RECORDING_ADVICE)))?;
    let static_intervals = static_intervals(rec, &intervals, &dirs, opts.gravity);
    pose_warnings(rec, &intervals, &static_intervals, &mut warnings);
    let not_determined =
        [names("accelerometer", &accel.not_determined), names("gyroscope", &gyro.not_determined)].concat();
    let mut result = CalibrationResult {
        calibration: ImuCalibration {
            accel: accel_triad(&accel.params, &accel.cov, accel.stats.covariance_inflation),
            gyro: gyro_triad(&gyro.x, &gyro.cov),
            gravity: opts.gravity,
            units: units_of(rec),
            effects: None,
            time_offsets: None,
        },
        initial_rest: rest.report,
        multiplier,
        thresholds: DetectionThresholds {
            accel_variance: rest.noise_a.map(|v| multiplier * v),
            gyro_variance: rest.noise_g.map(|v| multiplier * v),
            window_rate: opts.detect_with_gyro.then_some(rest.window_limit),
        },
        ratio,
        intervals,
        static_intervals,
        sweep,
        accel_fit: accel.stats,
        gyro_fit: gyro.stats,
        rotations: gyro.rotations,
        score: scores.accel,
        warnings,
        assessment: Assessment { verdict: Verdict::Ok, reasons: Vec::new(), not_determined: Vec::new() },
        split: None,
    };
    super::split::check_halves(rec, &result.intervals.clone(), &gyro_inputs, opts, halves_start, &mut result);
    result.assessment = Assessment::of(&result, not_determined, gyro.ambiguity);
    if result.assessment.verdict == Verdict::Failed {
        return Err(CalibError {
            message: format!("calibration failed: {}", result.assessment.reasons.join("; ")),
            hint: Some(RECORDING_ADVICE.to_string()),
            diagnosis: Some(Box::new(result)),
            ..err(String::new(), None)
        });
    }
    Ok(result)
}

/// Refuse a recording no calibration can use: one triad missing, a sample
/// not finite, too short (or shorter than the initial rest given).
fn check_recording(rec: &ImuRecording, opts: &CalibOptions) -> Result<(), CalibError> {
    let err = |message: String, hint: Option<&str>| CalibError::new(rec, message, hint);
    if rec.accel.len() != rec.len() || rec.gyro.len() != rec.len() {
        return Err(err("calibration needs both accelerometer and gyro samples".into(), None));
    }
    if let Some(i) = (0..rec.len())
        .find(|&i| !rec.t[i].is_finite() || rec.accel[i].iter().chain(&rec.gyro[i]).any(|x| !x.is_finite()))
    {
        return Err(err(format!("sample {} (line {}) is not finite", i, rec.lines.line(i)), None));
    }
    let n = rec.len();
    if n < 100 || opts.init_static_s.is_some_and(|t| rec.duration() <= t) {
        return Err(err(
            match opts.init_static_s {
                Some(t) => format!("{:.1} s of data: less than the {t} s initial static period", rec.duration()),
                None => format!("{:.1} s of data ({n} samples): too short for a calibration", rec.duration()),
            },
            Some(RECORDING_ADVICE),
        ));
    }
    Ok(())
}

/// The detector's windows and scores over the whole recording.
struct Scores {
    /// Median sample period \[s\].
    period: f64,
    /// Half the sliding window, the window \[samples\], and the shortest interval.
    half: usize,
    w: usize,
    min_len: usize,
    /// Sliding per-axis variances of accelerometer and gyro.
    accel_var: Vec<[f64; 3]>,
    gyro_var: Vec<[f64; 3]>,
    /// Their norms (the accelerometer's is the report's detection score).
    accel: Vec<f64>,
    gyro: Vec<f64>,
}

impl Scores {
    fn of(rec: &ImuRecording, opts: &CalibOptions) -> Result<Scores, CalibError> {
        let mut dts: Vec<f64> = rec.t.windows(2).map(|w| w[1] - w[0]).collect();
        let period = median(&mut dts).unwrap_or(f64::NAN);
        if period.is_nan() || period <= 0.0 {
            return Err(CalibError::new(rec, "timestamps do not increase".into(), None));
        }
        let half = ((opts.window_s / period / 2.0).round() as usize).max(2);
        let w = 2 * half + 1;
        let min_len = ((opts.min_interval_s / period).round() as usize).max(3);
        let (accel_var, gyro_var) = (sliding_variance(&rec.accel, w), sliding_variance(&rec.gyro, w));
        let (accel, gyro) = (norms(&accel_var), norms(&gyro_var));
        Ok(Scores { period, half, w, min_len, accel_var, gyro_var, accel, gyro })
    }
}

/// The initial rest and what is taken from it: the noise per axis, the gyro
/// bias and the limits that tell a steady turn from a pose.
struct Rest {
    report: InitialRestReport,
    samples: usize,
    var_a: [f64; 3],
    var_g: [f64; 3],
    /// Each axis's noise variance at rest (the detection's unit).
    noise_a: [f64; 3],
    noise_g: [f64; 3],
    /// Mean gyro reading at rest (the bias).
    gyro_bias: Vector3<f64>,
    /// Largest offset of an interval's mean rate from the bias (a turn beyond).
    turn_limit: Vector3<f64>,
    /// Largest offset of a window's mean rate ([`window_rate_limit`]).
    window_limit: [f64; 3],
}

/// The initial rest: given (`--init-static`, then checked) or found in the data.
fn initial_rest(
    rec: &ImuRecording,
    opts: &CalibOptions,
    sc: &Scores,
    warnings: &mut Vec<String>,
) -> Result<Rest, CalibError> {
    let err = |message: String, hint: Option<&str>| CalibError::new(rec, message, hint);
    let min_rest = ((MIN_INITIAL_REST_S / sc.period).round() as usize).max(2 * sc.w);
    let rest = match opts.init_static_s {
        Some(t) => InitialRest::given(rec.t.partition_point(|&x| x < t)),
        None => find_initial_rest(&rec.accel, &rec.gyro, &sc.accel, &sc.gyro, sc.w, min_rest).ok_or_else(|| {
            err(
                format!(
                    "no rest of ≥ {:.1} s in the first {:.0} % of the recording to take the noise and gyro bias from",
                    min_rest as f64 * sc.period,
                    100.0 * super::detect::EARLY_FRACTION
                ),
                Some(
                    "start the recording with the IMU lying still for a few seconds (better 50 s), or give its \
                      length with --init-static",
                ),
            )
        })?,
    };
    let n_init = rest.samples();
    if n_init < 2 * sc.w {
        return Err(err(format!("initial static period has only {n_init} samples; need ≥ {}", 2 * sc.w), None));
    }
    let (init_accel, init_gyro) = (rest.collect(&rec.accel), rest.collect(&rec.gyro));
    let (var_a, var_g) = (var3(&init_accel), var3(&init_gyro));
    let var_init = var_a.iter().map(|x| x * x).sum::<f64>().sqrt();
    if !rest.detected {
        check_initial_static(rec, &sc.accel, &sc.gyro, n_init, sc.half, var_init, warnings)
            .map_err(|(m, h)| err(m, Some(h)))?;
    }
    let span = rest.span();
    let report = InitialRestReport {
        start_s: rec.t[span.start],
        end_s: rec.t[span.end - 1],
        samples: n_init,
        detected: rest.detected,
    };
    if report.end_s - report.start_s < PAPER_INITIAL_REST_S {
        warnings.push(format!(
            "the initial rest lasts {:.1} s (the paper asks ≥ {PAPER_INITIAL_REST_S} s): the gyro bias taken from it \
             is less certain (its σ says how much)",
            report.end_s - report.start_s
        ));
    }
    let (noise_a, noise_g) = (axis_noise(&init_accel), axis_noise(&init_gyro));
    let raw_counts = rec.gyro_units == Stored::RawCounts;
    let floor = if raw_counts { 0.0 } else { MIN_TURN_RATE };
    Ok(Rest {
        report,
        samples: n_init,
        var_a,
        var_g,
        noise_a,
        noise_g,
        gyro_bias: Vector3::from(mean3(&init_gyro)),
        turn_limit: Vector3::from(var_g.map(|v| (TURN_SIGMAS * v.sqrt()).max(floor))),
        window_limit: window_rate_limit(&noise_g, sc.w, raw_counts),
    })
}

/// Detection score per sample: each axis's windowed variance over its own
/// variance in the initial rest, averaged over the triad's axes; the larger
/// of accelerometer and gyro (the gyro catches slow turns the accelerometer
/// hardly sees). A steady turn keeps the windowed variances low: a window
/// whose mean rate is far above the rest's noise is a turn, not a pose.
fn detection_ratio(rec: &ImuRecording, opts: &CalibOptions, sc: &Scores, rest: &Rest) -> Vec<f64> {
    let mut ratio = axis_ratio(&sc.accel_var, &rest.noise_a);
    if opts.detect_with_gyro {
        let rate = sliding_mean(&rec.gyro, sc.w);
        for ((r, g), m) in ratio.iter_mut().zip(axis_ratio(&sc.gyro_var, &rest.noise_g)).zip(&rate) {
            *r = r.max(g);
            if (0..3).any(|k| (m[k] - rest.gyro_bias[k]).abs() > rest.window_limit[k]) {
                *r = f64::INFINITY;
            }
        }
    }
    ratio
}

/// The detection the threshold sweep kept, with its accelerometer fit.
struct Kept {
    multiplier: f64,
    intervals: Vec<Interval>,
    accel: AccelFit,
}

type Fits = (Option<AccelFit>, Option<Result<GyroFit, String>>);

/// Threshold sweep: one calibration per multiplier; the most certain one is
/// kept (smallest ln det of the inflated accelerometer and gyro
/// covariances): a strict threshold drops poses and widens σ, a loose one
/// lets the slow start and end of turns into the poses, which the fits'
/// χ²/dof and so the inflated σ show. Multipliers that detect the same
/// intervals share one calibration.
fn sweep_thresholds(
    rec: &ImuRecording,
    opts: &CalibOptions,
    sc: &Scores,
    rest: &Rest,
    ratio: &[f64],
    gyro_inputs: &GyroInputs,
) -> Result<(Vec<SweepEntry>, Kept), CalibError> {
    let detections: Vec<(f64, Vec<Interval>)> = opts
        .multipliers
        .iter()
        .map(|&k| (k, not_turning(rec, intervals_below(ratio, k, sc.min_len), &rest.gyro_bias, rest.turn_limit)))
        .collect();
    let firsts: Vec<usize> =
        (0..detections.len()).map(|i| (0..=i).find(|&j| detections[j].1 == detections[i].1).unwrap_or(i)).collect();
    let unique: Vec<usize> = (0..detections.len()).filter(|&i| firsts[i] == i).collect();
    let accel_fits: Vec<(usize, Option<AccelFit>)> = unique
        .par_iter()
        .map(|&i| {
            let iv = &detections[i].1;
            (i, (iv.len() >= opts.min_intervals).then(|| fit_accel(rec, iv, opts.gravity, &rest.var_a)).flatten())
        })
        .collect();
    // One isotropic start for every ranking fit, searched on the first
    // detection fitted: the scale is the gyro's, not the detection's, and the
    // search (some 30 integrations of every turn) cost 80 % of each ranking.
    // That detection is fitted first, and the others are solved from its
    // solution (their own problems, nearby: fewer iterations). The kept
    // detection's final fit searches its own starts.
    let shared = accel_fits.iter().enumerate().find_map(|(k, (i, a))| {
        ranking_start(rec, &detections[*i].1, a.as_ref()?, gyro_inputs).ok().map(|scale| (k, scale))
    });
    let rank = |(i, fit): (usize, Option<AccelFit>), start: GyroStart| {
        let iv = &detections[i].1;
        let gyro =
            fit.as_ref().map(|a| fit_gyro(rec, iv, &interval_means(rec, iv), a, gyro_inputs, opts, false, start));
        (i, (fit, gyro))
    };
    let mut fitted: Vec<(usize, Fits)> = Vec::with_capacity(accel_fits.len());
    let mut start = GyroStart::Search;
    if let Some((first, scale)) = shared {
        let done = rank(accel_fits[first].clone(), GyroStart::Scale { scale, from: None });
        let from = done.1 .1.as_ref().and_then(|g| g.as_ref().ok()).map(GyroFit::matrix);
        start = GyroStart::Scale { scale, from };
        fitted.push(done);
    }
    let rest: Vec<(usize, Option<AccelFit>)> =
        accel_fits.into_iter().enumerate().filter(|(k, _)| Some(*k) != shared.map(|s| s.0)).map(|(_, f)| f).collect();
    fitted.extend(rest.into_par_iter().map(|f| rank(f, start)).collect::<Vec<_>>());
    let fits_of = |i: usize| &fitted.iter().find(|f| f.0 == firsts[i]).expect("every first detection is fitted").1;
    let sweep: Vec<SweepEntry> = detections
        .iter()
        .enumerate()
        .map(|(i, (k, iv))| {
            let (fit, gyro) = fits_of(i);
            SweepEntry {
                multiplier: *k,
                intervals: iv.len(),
                chi2_per_dof: fit.as_ref().map(|f| f.stats.chi2_per_dof),
                rms_norm_error: fit.as_ref().map(|f| f.stats.rms),
                uncertainty: match (fit, gyro) {
                    (Some(a), Some(Ok(g))) => Some(a.uncertainty() + g.uncertainty()),
                    _ => None,
                },
            }
        })
        .collect();
    let mut gyro_error = None;
    let mut best: Option<(f64, Kept)> = None;
    for (i, (k, iv)) in detections.into_iter().enumerate() {
        let (Some(a), Some(g)) = fits_of(i) else { continue };
        match g {
            Err(e) => gyro_error = Some(e.clone()),
            Ok(g) => {
                let u = a.uncertainty() + g.uncertainty();
                if best.as_ref().is_none_or(|b| u < b.0) {
                    best = Some((u, Kept { multiplier: k, intervals: iv, accel: a.clone() }));
                }
            }
        }
    }
    match (best, gyro_error) {
        (Some((_, kept)), _) => Ok((sweep, kept)),
        (None, Some(e)) => Err(CalibError::new(rec, e, None)),
        (None, None) => {
            let most = sweep.iter().map(|s| s.intervals).max().unwrap_or(0);
            Err(CalibError::new(
                rec,
                format!(
                    "found at most {most} usable static intervals (≥ {:.2} s each) over threshold multipliers {:?}; \
                     calibration needs ≥ {}",
                    sc.min_len as f64 * sc.period,
                    opts.multipliers,
                    opts.min_intervals
                ),
                Some(RECORDING_ADVICE),
            ))
        }
    }
}

/// The units the calibration's raw inputs were read in.
fn units_of(rec: &ImuRecording) -> Units {
    Units {
        accel_input: if rec.accel_units == Stored::RawCounts { "counts" } else { "m/s^2" }.into(),
        gyro_input: if rec.gyro_units == Stored::RawCounts { "counts" } else { "rad/s" }.into(),
        ..Units::default()
    }
}

/// The kept intervals for the report, each with its calibrated specific force.
fn static_intervals(rec: &ImuRecording, intervals: &[Interval], dirs: &[Vector3<f64>], g: f64) -> Vec<StaticInterval> {
    intervals
        .iter()
        .zip(dirs)
        .map(|(iv, a)| StaticInterval {
            start_s: rec.t[iv.start],
            end_s: rec.t[iv.end - 1],
            start_ns: rec.t_ns(iv.start),
            end_ns: rec.t_ns(iv.end - 1),
            samples: iv.len(),
            accel: [a.x, a.y, a.z],
            norm_error: a.norm() - g,
        })
        .collect()
}

/// Warnings about the poses: held shorter than the paper asks, or moving inside.
fn pose_warnings(rec: &ImuRecording, intervals: &[Interval], poses: &[StaticInterval], warnings: &mut Vec<String>) {
    let mut holds: Vec<f64> = poses.iter().map(|s| s.end_s - s.start_s).collect();
    holds.sort_by(f64::total_cmp);
    if holds[holds.len() / 2] < PAPER_MIN_HOLD_S {
        warnings.push(format!(
            "the poses were held {:.2} s (median; the paper asks ≥ {PAPER_MIN_HOLD_S} s): short holds leave less \
             still data per pose and blur poses into turns",
            holds[holds.len() / 2]
        ));
    }
    let stillness = super::detect::WithinInterval::measure_all(&rec.accel, &rec.gyro, intervals);
    let moving = super::detect::unsettled(&stillness, super::detect::STILLNESS_ALPHA);
    if !moving.is_empty() {
        warnings.push(format!(
            "inside the static poses {} (the halves' means differ by that many times the variance the white noise \
             gives): {}; the fits' χ²/dof, and so the σ, carry it",
            super::detect::describe(&moving),
            super::detect::UNSETTLED_CAUSES
        ));
    }
}

/// An interval whose mean gyro reading differs from the initial period's on some
/// axis by more than this many per-sample standard deviations of that axis in
/// that period is a steady turn.
const TURN_SIGMAS: f64 = 30.0;
/// Smallest such difference per axis \[rad/s\] for gyros read in SI units (3 °/s).
const MIN_TURN_RATE: f64 = 0.05;

/// Largest offset of a window's mean rate from the initial rest's per axis,
/// from each axis's noise variance at rest (raw units²) and the window's
/// length: [`TURN_SIGMAS`] standard errors of the window's mean, at least
/// [`MIN_TURN_RATE`] for a gyro read in rad/s (the bias may move that much
/// with temperature over a recording). A raw-count gyro, whose units are not
/// known yet, keeps the interval's rule (`TURN_SIGMAS` per-sample σ).
fn window_rate_limit(noise: &[f64; 3], w: usize, raw_counts: bool) -> [f64; 3] {
    noise.map(|v| {
        if raw_counts {
            TURN_SIGMAS * v.sqrt()
        } else {
            (TURN_SIGMAS * (v / w as f64).sqrt()).max(MIN_TURN_RATE)
        }
    })
}

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
    let worst = init.iter().copied().fold(f64::MIN, f64::max);
    let (Some(med), Some(quiet)) = (median(&mut init), quietest(score)) else {
        return Ok(());
    };
    let advice = "start the recording with the IMU lying perfectly still for the whole initial period \
                  (--init-static sets its length)";
    // A rotation shows in the gyro (compared with its quietest windows anywhere in the
    // recording); a knock or vibration only in the accelerometer.
    let g_quiet = quietest(gyro_score).unwrap_or(0.0).max(1e-300);
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
