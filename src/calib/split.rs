//! The recording checks itself: both fits again on the first and on the
//! second half of the static poses (in time), every estimated parameter
//! compared, and the whole recording's σ widened to cover what the halves
//! show ([`crate::model::split`]).

use super::detect::Interval;
use super::fit::{fit_accel, fit_gyro, interval_means, GyroInputs, GyroStart};
use super::options::{CalibOptions, MIN_STATIC_INTERVALS};
use super::result::CalibrationResult;
use crate::calib::{accel_triad, gyro_triad};
use crate::io::ImuRecording;
use crate::model::calibration::Triad;
use crate::model::split::{HalfComparison, SplitCheck};
use rayon::prelude::*;

/// The triads `(accelerometer, gyroscope)` of a half's fits, or why it could not be fitted.
fn fit_half(
    rec: &ImuRecording,
    intervals: &[Interval],
    inputs: &GyroInputs,
    opts: &CalibOptions,
    start: GyroStart,
) -> Result<(Triad, Triad), String> {
    let accel = fit_accel(rec, intervals, opts.gravity, inputs.var_a).ok_or("the accelerometer fit failed")?;
    let means = interval_means(rec, intervals);
    let gyro = fit_gyro(rec, intervals, &means, &accel, inputs, opts, true, start)?;
    Ok((accel_triad(&accel.params, &accel.cov, accel.stats.covariance_inflation), gyro_triad(&gyro.x, &gyro.cov)))
}

/// Compare the halves of the kept detection's `intervals` and widen the σ
/// of `result.calibration`; `result.split` holds the comparison (None, with a
/// warning, when a half has fewer than [`MIN_STATIC_INTERVALS`] poses or
/// cannot be fitted). Each half's gyro fit starts from `gyro_start`: the
/// isotropic scale the whole recording's fit kept, solved from its solution
/// (the halves turn the same gyro: its scale need not be searched for again).
pub(super) fn check_halves(
    rec: &ImuRecording,
    intervals: &[Interval],
    inputs: &GyroInputs,
    opts: &CalibOptions,
    gyro_start: GyroStart,
    result: &mut CalibrationResult,
) {
    let m = intervals.len();
    if m < 2 * MIN_STATIC_INTERVALS {
        result.warnings.push(format!(
            "{m} static poses: too few to check the calibration on each half of the recording (≥ {} needed; σ not checked)",
            2 * MIN_STATIC_INTERVALS
        ));
        return;
    }
    let halves = [&intervals[..m / 2], &intervals[m / 2..]];
    let fits: Result<Vec<_>, String> = halves.par_iter().map(|h| fit_half(rec, h, inputs, opts, gyro_start)).collect();
    let fits = match fits {
        Ok(f) => f,
        Err(why) => {
            result
                .warnings
                .push(format!("a half of the recording could not be calibrated alone ({why}): σ not checked"));
            return;
        }
    };
    let label = |h: &[Interval], first: usize| {
        let (a, b) = (h[0].start, h[h.len() - 1].end.saturating_sub(1));
        let seconds = |i: usize| rec.t[i.min(rec.t.len() - 1)] - rec.t[0];
        format!("static poses {}–{} ({:.1}–{:.1} s)", first, first + h.len() - 1, seconds(a), seconds(b))
    };
    let mut parameters = Vec::new();
    let whole = &result.calibration;
    for (name, w, a, b) in
        [("accelerometer", &whole.accel, &fits[0].0, &fits[1].0), ("gyroscope", &whole.gyro, &fits[0].1, &fits[1].1)]
    {
        let with_bias = name == "accelerometer" || opts.estimate_gyro_bias;
        parameters.extend(compare_triads(name, w, a, b, with_bias));
    }
    let check = SplitCheck { halves: [label(halves[0], 0), label(halves[1], m / 2)], parameters };
    widen(&mut result.calibration.accel, "accelerometer", &check);
    widen(&mut result.calibration.gyro, "gyroscope", &check);
    result.split = Some(check);
}

/// The estimated entries of a triad: `(name, value, σ)` — scales, the
/// misalignments with a σ (those the model estimates) and, with
/// `with_bias`, the biases.
pub(super) fn entries(name: &str, t: &Triad, with_bias: bool) -> Vec<(String, f64, f64)> {
    let axes = ["x", "y", "z"];
    let mut out: Vec<(String, f64, f64)> =
        (0..3).map(|i| (format!("{name} scale {}", axes[i]), t.k[i], t.k_std[i])).collect();
    for r in 0..3 {
        for c in 0..3 {
            if r != c && t.t_std[(r, c)] > 0.0 {
                out.push((format!("{name} misalignment T[{r}][{c}]"), t.t[(r, c)], t.t_std[(r, c)]));
            }
        }
    }
    if with_bias {
        out.extend((0..3).map(|i| (format!("{name} bias {}", axes[i]), t.b[i], t.b_std[i])));
    }
    out
}

/// One triad's halves compared against the whole recording's σ.
fn compare_triads(name: &str, whole: &Triad, a: &Triad, b: &Triad, with_bias: bool) -> Vec<HalfComparison> {
    let (w, a, b) = (entries(name, whole, with_bias), entries(name, a, with_bias), entries(name, b, with_bias));
    w.into_iter()
        .filter_map(|(p, _, sigma)| {
            let find = |e: &[(String, f64, f64)]| e.iter().find(|x| x.0 == p).map(|x| (x.1, x.2));
            let (fa, fb) = (find(&a)?, find(&b)?);
            Some(HalfComparison::new(p, "", fa, fb, sigma))
        })
        .collect()
}

/// Widen a triad's σ to the check's.
fn widen(t: &mut Triad, name: &str, check: &SplitCheck) {
    for (i, axis) in ["x", "y", "z"].iter().enumerate() {
        t.k_std[i] = check.sigma_after(&format!("{name} scale {axis}"), t.k_std[i]);
        t.b_std[i] = check.sigma_after(&format!("{name} bias {axis}"), t.b_std[i]);
        for c in 0..3 {
            t.t_std[(i, c)] = check.sigma_after(&format!("{name} misalignment T[{i}][{c}]"), t.t_std[(i, c)]);
        }
    }
}
