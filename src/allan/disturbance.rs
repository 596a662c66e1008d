//! Disturbances in a static log: knocks (short bursts far out of the noise)
//! and steps (the level jumps and stays), found by robust statistics so that
//! the noise itself — white noise, bias instability, random walk — never
//! counts as one.
//!
//! * **Knock**: a sample further than [`KNOCK_SIGMAS`] robust standard
//!   deviations from the 1 s running mean of its axis. The standard deviation
//!   is the MAD of the first differences (÷√2), which a few knocks do not move.
//!   Flagged samples less than a second apart are one knock.
//! * **Step**: the difference between the means of the 10 s before and after a
//!   time, further than [`STEP_SIGMAS`] robust spreads (MAD) of that same
//!   difference over the whole log from zero: the slow wander of the bias moves
//!   it continuously and sets the spread; a step stands out of it.
//!
//! The Allan stage analyses the longest span free of both (a margin of one
//! window around each), saying which; `tumble inspect` lists them.

use crate::error::InputError;
use crate::io::ImuRecording;
use serde::Serialize;

/// Distance from the running mean, in robust standard deviations, that makes a knock.
pub const KNOCK_SIGMAS: f64 = 10.0;

/// Distance of the before/after mean difference from zero, in robust spreads, that makes a step.
pub const STEP_SIGMAS: f64 = 8.0;

/// Window of the step test on each side \[s\].
pub const STEP_WINDOW_S: f64 = 10.0;

/// What kind of disturbance.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum DisturbanceKind {
    /// A short burst.
    Knock,
    /// A jump of the level that stays.
    Step,
}

/// One disturbance.
#[derive(Debug, Clone, Serialize)]
pub struct Disturbance {
    /// Knock or step.
    pub kind: DisturbanceKind,
    /// `gyro x` … `accel z`.
    pub axis: String,
    /// Start \[s from the first sample\] and the first sample.
    pub t_s: f64,
    /// See `t_s`.
    pub sample: usize,
    /// Knock: its duration \[s\]; step: 0.
    pub duration_s: f64,
    /// Knock: the largest excursion; step: the jump (sensor units).
    pub size: f64,
    /// `size` in the robust standard deviations or spreads of the test.
    pub sigmas: f64,
}

impl std::fmt::Display for Disturbance {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.kind {
            DisturbanceKind::Knock => write!(
                f,
                "knock on {} at t = {:.2} s ({:.2} s long, {:+.3e} from its running mean, {:.0}σ)",
                self.axis, self.t_s, self.duration_s, self.size, self.sigmas
            ),
            DisturbanceKind::Step => write!(
                f,
                "step on {} at t = {:.1} s ({:+.3e}, {:.0}× the spread of 10 s means)",
                self.axis, self.t_s, self.size, self.sigmas
            ),
        }
    }
}

/// Median of `v` (0 when empty).
fn median(mut v: Vec<f64>) -> f64 {
    crate::model::numeric::median(&mut v).unwrap_or(0.0)
}

/// Largest turn of a static log's gravity direction (its mean over 10 s)
/// within [`MOTION_SPAN_S`] \[deg\]: more means the IMU moved, and motion
/// would be read as noise.
pub const MAX_STATIC_TILT_DEG: f64 = 2.0;

/// The span within which a turn of the gravity direction is taken for motion
/// \[s\]. Over it an accelerometer's bias cannot move the mean by degrees (a
/// datasheet bias walk of 3·10⁻³ m/s³/√Hz moves it by 0.13° in 60 s), over
/// hours it can (1.8° in 3 h): that slow drift is part of what an Allan
/// analysis measures, so it is reported, not refused.
pub const MOTION_SPAN_S: f64 = 60.0;

/// A log whose gravity direction turned, between two 10 s means less than
/// [`MOTION_SPAN_S`] apart, by more than [`MAX_STATIC_TILT_DEG`] (or its
/// means' own noise) is not a static log: the error names the time and line.
/// A slower drift of the direction by more than that over the whole log is
/// accepted, and described in the returned warning. Accelerometer in m/s²
/// only: raw counts have unknown offsets.
pub fn check_static(rec: &ImuRecording) -> Result<Option<String>, InputError> {
    if rec.accel_units != crate::io::Stored::Si || rec.len() < 20 {
        return Ok(None);
    }
    let per = ((10.0 / rec.duration().max(1e-9)) * rec.len() as f64).clamp(10.0, rec.len() as f64 / 2.0) as usize;
    let means: Vec<nalgebra::Vector3<f64>> =
        rec.accel.chunks_exact(per).map(|c| nalgebra::Vector3::from(crate::io::validate::mean3(c))).collect();
    if means[0].norm() < 1.0 {
        return Ok(None);
    }
    // A tilt must stand out of the chunk means' own noise (5σ of the angle
    // between two means of `per` samples).
    let sd = crate::io::validate::var3(&rec.accel[..per]).iter().sum::<f64>().sqrt();
    let noise_deg = (5.0 * sd * (2.0 / per as f64).sqrt() / means[0].norm()).to_degrees();
    let limit = MAX_STATIC_TILT_DEG.max(noise_deg);
    let chunk_s = rec.duration() * per as f64 / rec.len() as f64;
    let lookback = ((MOTION_SPAN_S / chunk_s).floor() as usize).max(1);
    for k in 1..means.len() {
        for j in k.saturating_sub(lookback)..k {
            let tilt = means[k].angle(&means[j]).to_degrees();
            if tilt > limit {
                let i = k * per;
                return Err(rec
                    .error_at(
                        i,
                        format!(
                            "not a static log: gravity has turned {tilt:.1}° within {:.0} s by t = {:.1} s; an Allan \
                         analysis reads motion as noise",
                            (k - j) as f64 * chunk_s,
                            rec.t[i]
                        ),
                    )
                    .with_hint("record the IMU lying still"));
            }
        }
    }
    let (k, drift) = (1..means.len())
        .map(|k| (k, means[k].angle(&means[0]).to_degrees()))
        .max_by(|a, b| a.1.total_cmp(&b.1))
        .unwrap_or((0, 0.0));
    Ok((drift > limit).then(|| {
        format!(
            "the gravity direction drifted {drift:.1}° from its start by t = {:.0} s, slowly (under {limit:.1}° \
             within any {MOTION_SPAN_S:.0} s): read as the accelerometer's bias drifting, which the Allan curves \
             include, not as motion",
            rec.t[k * per]
        )
    }))
}

/// The disturbances of a static log, or `None` when `rec` is not one
/// ([`check_static`]): in a moving recording everything would be one.
pub fn static_disturbances(rec: &ImuRecording) -> Option<Vec<Disturbance>> {
    check_static(rec).ok()?;
    (rec.accel_units == crate::io::Stored::Si).then(|| find_disturbances(rec))
}

/// Knocks and steps on the six axes of `rec`, in time order.
pub fn find_disturbances(rec: &ImuRecording) -> Vec<Disturbance> {
    let n = rec.len();
    if n < 10 || rec.duration() <= 0.0 {
        return Vec::new();
    }
    let rate = (n - 1) as f64 / rec.duration();
    let second = (rate.round() as usize).max(1);
    let w = ((STEP_WINDOW_S * rate).round() as usize).max(2);
    let mut out = Vec::new();
    for (sensor, data) in [("gyro", &rec.gyro), ("accel", &rec.accel)] {
        if data.len() != n {
            continue;
        }
        for (k, axis) in ["x", "y", "z"].into_iter().enumerate() {
            let x: Vec<f64> = data.iter().map(|s| s[k]).collect();
            let name = format!("{sensor} {axis}");
            let mut prefix = Vec::with_capacity(n + 1);
            prefix.push(0.0);
            for (i, v) in x.iter().enumerate() {
                prefix.push(prefix[i] + (v - x[0]));
            }
            let mean = |a: usize, b: usize| x[0] + (prefix[b] - prefix[a]) / (b - a) as f64;
            // Knocks.
            let sd = 1.4826 * median(x.windows(2).map(|p| (p[1] - p[0]).abs()).collect()) / 2f64.sqrt();
            if sd > 0.0 {
                let mut i = 0;
                while i < n {
                    let (a, b) = (i.saturating_sub(second / 2), (i + second / 2 + 1).min(n));
                    let dev = x[i] - mean(a, b);
                    if dev.abs() > KNOCK_SIGMAS * sd {
                        // Extend over flagged samples less than a second apart.
                        let (start, mut last, mut peak) = (i, i, dev);
                        let mut j = i + 1;
                        while j < n && j <= last + second {
                            let (a, b) = (j.saturating_sub(second / 2), (j + second / 2 + 1).min(n));
                            let d = x[j] - mean(a, b);
                            if d.abs() > KNOCK_SIGMAS * sd {
                                last = j;
                                if d.abs() > peak.abs() {
                                    peak = d;
                                }
                            }
                            j += 1;
                        }
                        out.push(Disturbance {
                            kind: DisturbanceKind::Knock,
                            axis: name.clone(),
                            t_s: rec.t[start],
                            sample: start,
                            duration_s: rec.t[last] - rec.t[start],
                            size: peak,
                            sigmas: peak.abs() / sd,
                        });
                        i = last + second;
                        continue;
                    }
                    i += 1;
                }
            }
            // Steps: before/after differences every quarter window.
            if n < 4 * w {
                continue;
            }
            let at: Vec<usize> = (w..=n - w).step_by((w / 4).max(1)).collect();
            let d: Vec<f64> = at.iter().map(|&c| mean(c, c + w) - mean(c - w, c)).collect();
            let spread = 1.4826 * median(d.iter().map(|v| v.abs()).collect());
            if spread <= 0.0 {
                continue;
            }
            let mut j = 0;
            while j < d.len() {
                if d[j].abs() > STEP_SIGMAS * spread {
                    // The largest difference of this excursion marks the step.
                    let mut best = j;
                    while j < d.len() && d[j].abs() > STEP_SIGMAS * spread {
                        if d[j].abs() > d[best].abs() {
                            best = j;
                        }
                        j += 1;
                    }
                    // Knocks also move 10 s means: a step must hold on both sides of its knock.
                    let c = at[best];
                    out.push(Disturbance {
                        kind: DisturbanceKind::Step,
                        axis: name.clone(),
                        t_s: rec.t[c],
                        sample: c,
                        duration_s: 0.0,
                        size: d[best],
                        sigmas: d[best].abs() / spread,
                    });
                }
                j += 1;
            }
        }
    }
    // A knock's burst shifts the 10 s means around it: a "step" within a window
    // of a knock on the same axis, whose level returns, is that knock.
    let knocks: Vec<(String, usize)> =
        out.iter().filter(|d| d.kind == DisturbanceKind::Knock).map(|d| (d.axis.clone(), d.sample)).collect();
    out.retain(|d| {
        d.kind == DisturbanceKind::Knock || !knocks.iter().any(|(a, s)| *a == d.axis && s.abs_diff(d.sample) < w)
    });
    out.sort_by(|a, b| a.t_s.total_cmp(&b.t_s));
    out
}

/// The spans of samples `[start, end)` at least `margin` samples away from
/// every disturbance and at least `min_len` long, in time order.
pub fn clean_spans(
    n: usize,
    disturbances: &[Disturbance],
    margin: usize,
    min_len: usize,
) -> Vec<std::ops::Range<usize>> {
    let mut cuts: Vec<(usize, usize)> =
        disturbances.iter().map(|d| (d.sample.saturating_sub(margin), (d.sample + margin).min(n))).collect();
    cuts.sort();
    let mut spans = Vec::new();
    let mut from = 0;
    for (a, b) in cuts.into_iter().chain([(n, n)]) {
        if a > from && a - from >= min_len.max(1) {
            spans.push(from..a);
        }
        from = from.max(b);
    }
    spans
}

/// The longest span of samples `[start, end)` at least `margin` samples away
/// from every disturbance.
#[cfg(test)]
fn longest_clean_span(n: usize, disturbances: &[Disturbance], margin: usize) -> std::ops::Range<usize> {
    let mut cuts: Vec<(usize, usize)> =
        disturbances.iter().map(|d| (d.sample.saturating_sub(margin), (d.sample + margin).min(n))).collect();
    cuts.sort();
    let mut best = 0..0;
    let mut from = 0;
    for (a, b) in cuts.into_iter().chain([(n, n)]) {
        if a > from && a - from > best.len() {
            best = from..a;
        }
        from = from.max(b);
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;

    fn noise(n: usize, seed: u64) -> Vec<f64> {
        let mut s = seed;
        (0..n)
            .map(|_| {
                (0..12)
                    .map(|_| {
                        s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                        (s >> 11) as f64 / (1u64 << 53) as f64
                    })
                    .sum::<f64>()
                    - 6.0
            })
            .collect()
    }

    fn record(x: &[f64]) -> ImuRecording {
        ImuRecording {
            t: (0..x.len()).map(|i| i as f64 / 100.0).collect(),
            gyro: x.iter().map(|&v| [v * 0.01, 0.0, 0.0]).collect(),
            accel: x.iter().map(|&v| [0.0, v * 0.01, 9.81 + v * 0.01]).collect(),
            ..Default::default()
        }
    }

    #[test]
    fn white_noise_has_no_disturbance() {
        let rec = record(&noise(200_000, 3));
        let found = find_disturbances(&rec);
        assert!(found.is_empty(), "{found:?}");
        assert_eq!(longest_clean_span(rec.len(), &found, 100), 0..rec.len());
    }

    #[test]
    fn a_knock_and_a_step_are_found_where_they_are() {
        let mut x = noise(200_000, 4);
        // Knock at 500 s: 0.2 s of ±30σ.
        for (j, v) in x[50_000..50_020].iter_mut().enumerate() {
            *v += 30.0 * if j % 2 == 0 { 1.0 } else { -1.0 };
        }
        let mut rec = record(&x);
        // Step of 1σ (1e-2) on accel y at 1200 s: 10 s means carry σ/√1000.
        for a in &mut rec.accel[120_000..] {
            a[1] += 0.01;
        }
        let found = find_disturbances(&rec);
        let knock = found.iter().find(|d| d.kind == DisturbanceKind::Knock && d.axis == "gyro x").expect("knock");
        assert!((knock.t_s - 500.0).abs() < 1.0, "{knock}");
        let step = found.iter().find(|d| d.kind == DisturbanceKind::Step && d.axis == "accel y").expect("step");
        assert!((step.t_s - 1200.0).abs() < 1.0 && (step.size - 0.01).abs() < 2e-3, "{step}");
        assert!(!found.iter().any(|d| d.kind == DisturbanceKind::Step && d.axis == "gyro x"), "{found:?}");
        let span = longest_clean_span(rec.len(), &found, 1000);
        assert!((120_500..121_500).contains(&span.start) && span.end == 200_000, "{span:?}");
        let spans = clean_spans(rec.len(), &found, 1000, 10_000);
        assert_eq!(spans.len(), 3, "{spans:?}");
        assert_eq!(spans[0], 0..49_000);
    }
}
