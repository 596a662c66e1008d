//! The `tumble allan` stage ([`run_allan`]): a static recording in, the
//! noise coefficients of all six axes out, as an [`AllanReport`].

use super::disturbance::Disturbance;
use super::report::{AllanReport, AllanRunOptions, AxisResult, AxisStat, KalibrNoise, SensorResult};
use super::{identify, AllanCurve, AllanError};
use crate::io::{ImuRecording, Stored};
use std::ops::Range;

/// A step that skips more than this many samples splits the record: Allan
/// deviations need evenly spaced samples, and a few lost samples shift the
/// time base by less than the τ resolution, a long gap does not.
pub const MAX_BRIDGED_GAP_SAMPLES: f64 = 10.0;

/// The longest gap-free stretch is analysed alone when it holds at least this
/// share of the samples; otherwise the record is refused.
pub const MIN_SEGMENT_SHARE: f64 = 0.5;

/// The stretches free of disturbances must hold this share of the record to
/// be analysed instead of the whole.
pub const MIN_CLEAN_SHARE: f64 = 0.25;

/// The samples `[start, end)` to analyse and the sample period τ0 (its mean step).
fn gap_free_segment(
    rec: &ImuRecording,
    warnings: &mut Vec<String>,
) -> Result<(std::ops::Range<usize>, f64), AllanError> {
    let tau0 = crate::io::validate::median_period(&rec.t);
    if !(tau0.is_finite() && tau0 > 0.0) {
        return Err(AllanError::Invalid(format!(
            "{}: cannot tell the sample rate from the timestamps",
            rec.source_name()
        )));
    }
    let splits: Vec<usize> =
        (1..rec.len()).filter(|&i| rec.t[i] - rec.t[i - 1] > (MAX_BRIDGED_GAP_SAMPLES + 1.0) * tau0).collect();
    // τ0 of the analysed stretch: its mean step (bridged gaps of a few samples
    // shift it by less than their share of the samples).
    let mean_step = |r: &std::ops::Range<usize>| (rec.t[r.end - 1] - rec.t[r.start]) / (r.len() - 1).max(1) as f64;
    if splits.is_empty() {
        return Ok((0..rec.len(), mean_step(&(0..rec.len()))));
    }
    let bounds: Vec<usize> = std::iter::once(0).chain(splits.iter().copied()).chain([rec.len()]).collect();
    let longest = bounds.windows(2).map(|w| w[0]..w[1]).max_by_key(|r| r.len()).unwrap_or(0..rec.len());
    let (gap_at, gap) =
        splits.iter().map(|&i| (i, rec.t[i] - rec.t[i - 1])).max_by(|a, b| a.1.total_cmp(&b.1)).unwrap_or((0, 0.0));
    let describe = format!(
        "{} gap(s) in the timestamps, the longest {gap:.3} s before line {} (t = {:.1} s)",
        splits.len(),
        rec.lines.line(gap_at),
        rec.t[gap_at]
    );
    if (longest.len() as f64) < MIN_SEGMENT_SHARE * rec.len() as f64 {
        return Err(AllanError::Invalid(format!(
            "{}: {describe}; no gap-free stretch holds half the samples (longest: {} of {}). Allan deviations need \
             evenly spaced samples: analyse the stretches separately",
            rec.source_name(),
            longest.len(),
            rec.len()
        )));
    }
    warnings.push(format!(
        "{describe}: analysing the longest gap-free stretch, t = {:.1}–{:.1} s ({} of {} samples)",
        rec.t[longest.start],
        rec.t[longest.end - 1],
        longest.len(),
        rec.len()
    ));
    let tau0 = mean_step(&longest);
    Ok((longest, tau0))
}

/// Compute curves and coefficients of all six axes of a static recording.
pub fn run_allan(rec: &ImuRecording, opts: &AllanRunOptions) -> Result<AllanReport, AllanError> {
    run_allan_with_progress(rec, opts, &|_, _| {})
}

/// [`run_allan`], calling `progress(done, total)` as the τ of the six axes
/// are computed (from several threads at once).
///
/// The steps: the longest gap-free stretch, checked to be static → its
/// disturbances (knocks, steps) and, per sensor, the stretches free of them
/// → one Allan curve per stretch and axis, joined → each axis's noise
/// identified → Kalibr's figures.
pub fn run_allan_with_progress(
    rec: &ImuRecording,
    opts: &AllanRunOptions,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<AllanReport, AllanError> {
    opts.validate()?;
    if rec.len() < 10 {
        return Err(AllanError::Invalid(format!(
            "{}: {} samples are too few for an Allan analysis",
            rec.source_name(),
            rec.len()
        )));
    }
    let mut warnings = rec.warnings.clone();
    let (segment, tau0) = gap_free_segment(rec, &mut warnings)?;
    let whole = rec;
    let rec = &whole.slice_time(whole.t[segment.start], whole.t[segment.end - 1] + 0.5 * tau0);
    if let Some(drift) = super::disturbance::check_static(rec)? {
        warnings.push(drift);
    }
    let disturbances = super::disturbance::find_disturbances(rec);
    for d in &disturbances {
        warnings.push(format!("disturbance: {d}"));
    }
    let sensor_spans = sensor_spans(rec, &disturbances, opts.cut_disturbances, tau0, &mut warnings);
    let rate = 1.0 / tau0;
    let tau0 = 1.0 / rate;
    if rec.duration() < 3600.0 {
        warnings.push(format!(
            "the record is {:.0} s long; rate random walk (K) and bias instability (B) are usually resolved only by hours of static data",
            rec.duration()
        ));
    }
    let curves = curves(rec, &sensor_spans, tau0, opts, progress)?;
    let sensors = identify_sensors(rec, curves);
    let si = rec.gyro_units == Stored::Si && rec.accel_units == Stored::Si;
    let kalibr = if si && sensors.iter().all(|s| s.axes.iter().all(|a| a.id.is_some())) {
        Some(kalibr_noise(&sensors, rate, opts.axis_stat))
    } else {
        if !si {
            warnings.push(
                "data in raw counts: no Kalibr imu.yaml (it needs SI units; give --gyro-unit/--accel-unit scales)"
                    .into(),
            );
        }
        None
    };
    Ok(AllanReport {
        source: rec.source_name(),
        topic: rec.topic.clone(),
        samples: rec.len(),
        rate_hz: rate,
        duration_s: rec.duration(),
        sensors,
        kalibr,
        axis_stat: opts.axis_stat,
        warnings,
        disturbances,
    })
}

/// Per sensor (gyro, accel), the stretches to analyse: all of it, or (with
/// `cut`) the stretches free of that sensor's `disturbances` (10 s margins,
/// each at least four windows long), joined — when they hold enough of the record.
fn sensor_spans(
    rec: &ImuRecording,
    disturbances: &[Disturbance],
    cut: bool,
    tau0: f64,
    warnings: &mut Vec<String>,
) -> Vec<Vec<Range<usize>>> {
    let margin = (super::disturbance::STEP_WINDOW_S / tau0).round() as usize;
    let mut sensor_spans: Vec<Vec<Range<usize>>> = Vec::new();
    for sensor in ["gyro", "accel"] {
        let own: Vec<Disturbance> = disturbances.iter().filter(|d| d.axis.starts_with(sensor)).cloned().collect();
        let mut spans: Vec<Range<usize>> = std::iter::once(0..rec.len()).collect();
        if cut && !own.is_empty() {
            let clean = super::disturbance::clean_spans(rec.len(), &own, margin, 4 * margin);
            let kept: usize = clean.iter().map(|r| r.len()).sum();
            if kept as f64 >= MIN_CLEAN_SHARE * rec.len() as f64 {
                let list: Vec<String> =
                    clean.iter().map(|r| format!("{:.0}–{:.0} s", rec.t[r.start], rec.t[r.end - 1])).collect();
                warnings.push(format!(
                    "{sensor}: analysing the {} stretch(es) free of its disturbances, joined so that no difference \
                     crosses one (10 s margins; {:.0} % of the record): t = {} (--span analyses a span as it is)",
                    clean.len(),
                    100.0 * kept as f64 / rec.len() as f64,
                    list.join(", ")
                ));
                spans = clean;
            } else {
                warnings.push(format!(
                    "{sensor}: the stretches free of its disturbances hold less than {:.0} % of the record: analysing \
                     all of it; its random walks and bias instability may be too large",
                    100.0 * MIN_CLEAN_SHARE
                ));
            }
        }
        sensor_spans.push(spans);
    }
    sensor_spans
}

/// The six axes' Allan curves (gyro x y z, accel x y z): one per stretch of
/// `sensor_spans`, joined per axis; refused for an axis without noise.
fn curves(
    rec: &ImuRecording,
    sensor_spans: &[Vec<Range<usize>>],
    tau0: f64,
    opts: &AllanRunOptions,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<Vec<AllanCurve>, AllanError> {
    let n_tau: usize = sensor_spans
        .iter()
        .flatten()
        .map(|r| {
            super::cluster_sizes(&opts.allan.taus, r.len(), tau0, opts.allan.kind, opts.allan.max_tau_fraction).len()
        })
        .sum();
    let total = 3 * n_tau;
    let done = std::sync::atomic::AtomicUsize::new(0);
    let tick = || progress(done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1, total);
    let columns: Vec<Vec<f64>> =
        (0..6).map(|k| if k < 3 { &rec.gyro } else { &rec.accel }.iter().map(|s| s[k % 3]).collect()).collect();
    for (k, c) in columns.iter().enumerate() {
        let (lo, hi) = c.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| (a.min(x), b.max(x)));
        if lo == hi {
            return Err(AllanError::Invalid(format!(
                "{}: the {} {} axis reads {lo} in every sample: there is no noise to analyse \
                 (a stuck sensor, a quantization coarser than the noise, or a column of constants)",
                rec.source_name(),
                if k < 3 { "gyro" } else { "accelerometer" },
                ["x", "y", "z"][k % 3]
            )));
        }
    }
    let mut curves: Vec<AllanCurve> = Vec::new();
    for (sensor, spans) in sensor_spans.iter().enumerate() {
        let mut per_span: Vec<Vec<AllanCurve>> = Vec::new();
        for r in spans {
            let refs: Vec<&[f64]> = columns[3 * sensor..3 * sensor + 3].iter().map(|c| &c[r.clone()]).collect();
            per_span.push(
                super::allan_deviation_axes(&refs, tau0, &opts.allan, &tick)
                    .map_err(|e| AllanError::Invalid(format!("{}: {e}", rec.source_name())))?,
            );
        }
        for k in 0..3 {
            let parts: Vec<AllanCurve> = per_span.iter().map(|c| c[k].clone()).collect();
            curves.push(AllanCurve::joined(&parts).expect("at least one stretch"));
        }
    }
    Ok(curves)
}

/// The two sensors' results: each axis's curve with its noise identified.
fn identify_sensors(rec: &ImuRecording, curves: Vec<AllanCurve>) -> Vec<SensorResult> {
    let mut curves = curves.into_iter();
    let mut sensors = Vec::new();
    for (name, stored) in [("gyro", rec.gyro_units), ("accel", rec.accel_units)] {
        let unit = match (stored, name) {
            (Stored::RawCounts, _) => "counts",
            (_, "gyro") => "rad/s",
            _ => "m/s^2",
        };
        let axes = curves
            .by_ref()
            .take(3)
            .map(|curve| {
                let id = identify(&curve).ok();
                AxisResult { curve, id }
            })
            .collect();
        sensors.push(SensorResult { name, unit, axes });
    }
    sensors
}

/// The white-noise density and random walk of one axis for Kalibr, with a
/// note when the random walk is only an upper bound, and its bias
/// instability (0 when not resolved).
fn axis_n_k_b(axis: &AxisResult, label: &str, notes: &mut Vec<String>) -> (f64, f64, f64) {
    let id = axis.id.as_ref().expect("checked by the caller");
    let c = &axis.curve;
    let n = id.fit.N.or(id.readoff.N).map(|c| c.value).unwrap_or_else(|| {
        // σ² ≥ N²/τ everywhere, so every point bounds N from above.
        let b = (0..c.tau.len()).map(|i| c.dev_hi[i] * c.tau[i].sqrt()).fold(f64::INFINITY, f64::min);
        notes.push(format!("{label}: white noise not resolved; using its upper bound {b:.3e}"));
        b
    });
    let k = id.fit.K.or(id.readoff.K).map(|c| c.value).unwrap_or_else(|| {
        // σ² ≥ K²τ/3 everywhere, so every point bounds K from above.
        let b = (0..c.tau.len()).map(|i| c.dev_hi[i] * (3.0 / c.tau[i]).sqrt()).fold(f64::INFINITY, f64::min);
        notes.push(format!(
            "{label}: random walk not resolved by this record (too short); using its upper bound {b:.3e} — record longer for a real estimate"
        ));
        b
    });
    for e in &id.fit.extra {
        notes.push(match e.kind {
            super::identify::ExtraKind::Markov => format!(
                "{label}: a Markov (correlated) term, σ_m {:.3e} with correlation time {:.3} s, is not a random walk \
                 and is left out of it; an estimator without a state for it may add its low-frequency level \
                 √(2σ_m²T_c) = {:.3e} to the noise density",
                e.amplitude.value,
                e.time_s,
                (2.0 * e.amplitude.value.powi(2) * e.time_s).sqrt()
            ),
            super::identify::ExtraKind::Sinusoid => format!(
                "{label}: a sinusoid of amplitude {:.3e} at {:.3} Hz (vibration?) is neither white noise nor a random \
                 walk and is left out of both",
                e.amplitude.value,
                1.0 / e.time_s
            ),
        });
    }
    if let (false, Some((tau, ratio))) = (id.follows_data, id.worst_misfit) {
        notes.push(format!(
            "{label}: the fitted model does not follow the measured curve ({ratio:.2}× at τ = {tau:.3} s): its \
             random walk is uncertain"
        ));
    }
    (n, k, id.fit.B.or(id.readoff.B).map_or(0.0, |c| c.value))
}

fn kalibr_noise(sensors: &[SensorResult], rate: f64, stat: AxisStat) -> KalibrNoise {
    let mut notes = Vec::new();
    // (N, K) combined over the axes, and per axis (N, K with the bias instability).
    let mut combine = |s: &SensorResult| -> ((f64, f64), [f64; 3], [f64; 3]) {
        let v: Vec<(f64, f64, f64)> = s
            .axes
            .iter()
            .zip(["x", "y", "z"])
            .map(|(a, ax)| axis_n_k_b(a, &format!("{} {ax}", s.name), &mut notes))
            .collect();
        let combined = match stat {
            AxisStat::Max => (v.iter().map(|p| p.0).fold(0.0, f64::max), v.iter().map(|p| p.1).fold(0.0, f64::max)),
            AxisStat::Mean => (v.iter().map(|p| p.0).sum::<f64>() / 3.0, v.iter().map(|p| p.1).sum::<f64>() / 3.0),
        };
        let walk = [0, 1, 2].map(|i| crate::io::noise::estimator_random_walk(v[i].1, v[i].2));
        (combined, [v[0].0, v[1].0, v[2].0], walk)
    };
    let ((gn, gk), gn_axes, gk_axes) = combine(&sensors[0]);
    let ((an, ak), an_axes, ak_axes) = combine(&sensors[1]);
    KalibrNoise {
        axes: crate::io::ImuNoiseAxes {
            accelerometer_noise_density: an_axes,
            accelerometer_random_walk: ak_axes,
            gyroscope_noise_density: gn_axes,
            gyroscope_random_walk: gk_axes,
        },
        accelerometer_noise_density: an,
        accelerometer_random_walk: ak,
        gyroscope_noise_density: gn,
        gyroscope_random_walk: gk,
        update_rate: rate,
        notes,
    }
}
