//! Checks every IMU reader runs: time order, duplicated stamps, gaps, units
//! and saturation. Fatal problems are errors naming file and line; the rest
//! become warnings on the recording (and are printed by the CLI).

use super::imu::{ImuRecording, Stored};
use crate::error::InputError;
use rayon::prelude::*;
use std::path::{Path, PathBuf};

/// What to do with duplicated timestamps.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Duplicates {
    /// Re-stamp every sample at the nominal rate (when the stamps are merely
    /// coarse and there are no real gaps), with a warning. The default.
    #[default]
    Restamp,
    /// Refuse the file.
    Error,
}

/// Options of [`validate`].
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ValidateOptions {
    /// Nominal sample rate \[Hz\]; estimated from the stamps when None.
    pub nominal_rate: Option<f64>,
    /// Policy for duplicated timestamps.
    pub duplicates: Duplicates,
    /// A step longer than this many nominal periods is a gap.
    pub gap_factor: f64,
    /// Check that values at rest look like rad/s and m/s².
    pub check_units: bool,
    /// Shortest run of identical extreme values reported as saturation.
    pub saturation_run: usize,
}

impl Default for ValidateOptions {
    fn default() -> Self {
        ValidateOptions {
            nominal_rate: None,
            duplicates: Duplicates::Restamp,
            gap_factor: 2.0,
            check_units: true,
            saturation_run: 5,
        }
    }
}

impl ValidateOptions {
    /// Check the options themselves: a nominal rate, when given, is a
    /// positive number of Hz; the gap factor is above 1.
    pub fn check(&self) -> Result<(), crate::OptionError> {
        if let Some(r) = self.nominal_rate {
            crate::OptionError::positive("--rate", r, "Hz")?;
        }
        if !(self.gap_factor.is_finite() && self.gap_factor > 1.0) {
            return Err(crate::OptionError::new("gap_factor", format!("must be above 1, got {}", self.gap_factor)));
        }
        Ok(())
    }
}

fn source(rec: &ImuRecording) -> PathBuf {
    rec.sources.first().cloned().unwrap_or_else(|| PathBuf::from("<memory>"))
}

fn line_of(rec: &ImuRecording, i: usize) -> usize {
    rec.lines.line(i)
}

/// Validate (and where documented, repair) a freshly read recording.
pub fn validate(rec: &mut ImuRecording, opts: &ValidateOptions) -> Result<(), InputError> {
    let file = source(rec);
    let n = rec.len();
    if n < 2 {
        return Err(InputError::file(&file, format!("only {n} sample(s): too few to be a recording")));
    }
    for (v, what) in [(&rec.gyro, "gyro"), (&rec.accel, "accelerometer")] {
        if !v.is_empty() && v.len() != n {
            return Err(InputError::file(&file, format!("{} {what} samples for {n} timestamps", v.len())));
        }
    }
    if let Some(i) = (1..n).find(|&i| rec.t[i] < rec.t[i - 1]) {
        return Err(InputError::at(
            &file,
            line_of(rec, i),
            format!(
                "timestamp goes backwards: {:.9} s after {:.9} s on line {}",
                rec.t[i],
                rec.t[i - 1],
                line_of(rec, i - 1)
            ),
        )
        .with_hint("sort the file by time, or check that the time column and its unit are right"));
    }
    check_duplicates(rec, opts, &file)?;
    check_gaps(rec, opts);
    if opts.check_units {
        check_units(rec, &file)?;
    }
    check_saturation(rec, opts);
    Ok(())
}

fn check_duplicates(rec: &mut ImuRecording, opts: &ValidateOptions, file: &Path) -> Result<(), InputError> {
    let n = rec.len();
    let dups: Vec<usize> = (1..n).filter(|&i| rec.t[i] == rec.t[i - 1]).collect();
    let Some(&first) = dups.first() else { return Ok(()) };
    let duration = rec.duration();
    if duration <= 0.0 {
        return Err(InputError::file(file, "all timestamps are equal"));
    }
    let period = opts.nominal_rate.map(|r| 1.0 / r).unwrap_or(duration / (n - 1) as f64);
    let resolution = (1..n).map(|i| rec.t[i] - rec.t[i - 1]).filter(|&d| d > 0.0).fold(f64::INFINITY, f64::min);
    let what = format!(
        "{} duplicated timestamps (first on line {}); the stamps step by at least {:.3} ms while samples come every {:.3} ms on average",
        dups.len(),
        line_of(rec, first),
        resolution * 1e3,
        period * 1e3
    );
    if opts.duplicates == Duplicates::Error {
        return Err(InputError::at(file, line_of(rec, first), what)
            .with_hint("the timestamps are printed too coarsely; allow re-stamping at the nominal rate"));
    }
    // Re-stamping is only honest if the stamps never stray from the uniform grid
    // by more than their own resolution plus a period (no real gaps).
    let worst = (0..n).map(|i| (rec.t[i] - i as f64 * period).abs()).fold(0.0, f64::max);
    if worst > resolution + 2.0 * period {
        return Err(InputError::at(file, line_of(rec, first), what).with_hint(format!(
            "re-stamping at {:.3} Hz would move a sample by {:.3} s: the recording also has gaps; give the true rate or fix the stamps",
            1.0 / period,
            worst
        )));
    }
    for (i, t) in rec.t.iter_mut().enumerate() {
        *t = i as f64 * period;
    }
    rec.warnings.push(format!(
        "{}: {what}: re-stamped all samples at the nominal rate {:.4} Hz (largest shift {:.3} ms)",
        file.display(),
        1.0 / period,
        worst * 1e3
    ));
    Ok(())
}

/// At most this many values enter a median (evenly spread over the recording).
const MEDIAN_SAMPLES: usize = 1 << 16;

/// Median of `f(i)` over at most [`MEDIAN_SAMPLES`] indices evenly spread over `0..n`.
fn sampled_median(n: usize, f: impl Fn(usize) -> f64) -> f64 {
    if n == 0 {
        return 0.0;
    }
    let stride = n.div_ceil(MEDIAN_SAMPLES);
    let mut v: Vec<f64> = (0..n).step_by(stride).map(f).collect();
    crate::model::numeric::median(&mut v).unwrap_or(0.0)
}

/// Median step between samples \[s\] (from at most 65 536 steps spread over the recording).
pub fn median_period(t: &[f64]) -> f64 {
    sampled_median(t.len().saturating_sub(1), |i| t[i + 1] - t[i])
}

fn check_gaps(rec: &mut ImuRecording, opts: &ValidateOptions) {
    let period = opts.nominal_rate.map(|r| 1.0 / r).unwrap_or_else(|| median_period(&rec.t));
    let limit = opts.gap_factor * period;
    let gaps: Vec<usize> = (1..rec.len()).filter(|&i| rec.t[i] - rec.t[i - 1] > limit).collect();
    if gaps.is_empty() {
        return;
    }
    let missing: f64 = gaps.iter().map(|&i| (rec.t[i] - rec.t[i - 1]) / period - 1.0).sum();
    let largest = *gaps
        .iter()
        .max_by(|&&a, &&b| (rec.t[a] - rec.t[a - 1]).total_cmp(&(rec.t[b] - rec.t[b - 1])))
        .unwrap_or(&gaps[0]);
    let listed: Vec<String> = gaps
        .iter()
        .take(5)
        .map(|&i| {
            format!("line {} (t = {:.3} s, {:.1} ms)", line_of(rec, i), rec.t[i], (rec.t[i] - rec.t[i - 1]) * 1e3)
        })
        .collect();
    rec.warnings.push(format!(
        "{}: {} gaps longer than {} nominal periods ({:.3} ms), about {:.0} samples missing; largest {:.3} s before line {}; first: {}",
        rec.source_name(),
        gaps.len(),
        opts.gap_factor,
        period * 1e3,
        missing,
        rec.t[largest] - rec.t[largest - 1],
        line_of(rec, largest),
        listed.join(", ")
    ));
}

/// Index range of the quietest window of `w` samples (lowest accelerometer
/// variance), among windows starting every `w/4` samples. O(n): per-block
/// sums (in parallel), then four blocks per window.
pub fn quietest_window(accel: &[[f64; 3]], w: usize) -> Option<std::ops::Range<usize>> {
    let n = accel.len();
    if n < w || w < 4 {
        return None;
    }
    let b = w / 4;
    let blocks: Vec<([f64; 3], [f64; 3])> = accel
        .par_chunks_exact(b)
        .map(|c| {
            let mut s = [0.0; 3];
            let mut s2 = [0.0; 3];
            for a in c {
                for k in 0..3 {
                    s[k] += a[k];
                    s2[k] += a[k] * a[k];
                }
            }
            (s, s2)
        })
        .collect();
    let m = (4 * b) as f64;
    (0..blocks.len().saturating_sub(3))
        .map(|j| {
            let mut v = 0.0;
            for k in 0..3 {
                let s: f64 = blocks[j..j + 4].iter().map(|x| x.0[k]).sum();
                let s2: f64 = blocks[j..j + 4].iter().map(|x| x.1[k]).sum();
                v += (s2 - s * s / m).max(0.0);
            }
            (v, j)
        })
        .min_by(|x, y| x.0.total_cmp(&y.0))
        .map(|(_, j)| j * b..j * b + 4 * b)
}

/// Per-axis mean of `v` (zeros when empty).
pub fn mean3(v: &[[f64; 3]]) -> [f64; 3] {
    let mut m = [0.0; 3];
    for x in v {
        for k in 0..3 {
            m[k] += x[k];
        }
    }
    m.map(|s| s / v.len().max(1) as f64)
}

/// Per-axis (population) variance of `x`.
pub fn var3(x: &[[f64; 3]]) -> [f64; 3] {
    let m = mean3(x);
    let n = x.len().max(1) as f64;
    let mut v = [0.0; 3];
    for s in x {
        for k in 0..3 {
            v[k] += (s[k] - m[k]).powi(2);
        }
    }
    v.map(|s| s / n)
}

/// Euclidean norm of a triad.
pub(crate) fn norm(v: [f64; 3]) -> f64 {
    (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()
}

fn check_units(rec: &mut ImuRecording, file: &Path) -> Result<(), InputError> {
    let period = median_period(&rec.t).max(1e-6);
    // A second of samples, at least 10, at most the recording (a shorter one is checked whole).
    let w = ((1.0 / period).round() as usize).max(10).min(rec.len());
    let Some(win) = (if rec.accel.is_empty() { Some(0..w) } else { quietest_window(&rec.accel, w) }) else {
        return Ok(());
    };
    let at = format!("at rest (the quietest second, from line {})", line_of(rec, win.start));
    if !rec.accel.is_empty() && rec.accel_units == Stored::Si {
        let g = norm(mean3(&rec.accel[win.clone()]));
        if (0.8..1.25).contains(&g) {
            return Err(InputError::at(
                file,
                line_of(rec, win.start),
                format!("accelerometer reads |a| = {g:.3} {at}: that is 1 g, but the file was read as m/s²"),
            )
            .with_hint("declare the accelerometer unit as g"));
        }
        if g > 50.0 {
            return Err(InputError::at(
                file,
                line_of(rec, win.start),
                format!("accelerometer reads |a| = {g:.1} {at}: far above 9.8 m/s²"),
            )
            .with_hint("the values look like raw counts or mg; declare the unit (counts with a scale, or g)"));
        }
        if !(7.0..13.0).contains(&g) {
            rec.warnings.push(format!(
                "{}: accelerometer reads |a| = {g:.3} m/s² {at}, not ≈ 9.8: check the unit and scale",
                file.display()
            ));
        }
    }
    if !rec.gyro.is_empty() && rec.gyro_units == Stored::Si {
        let wmean = norm(mean3(&rec.gyro[win.clone()]));
        if wmean > 1.0 {
            return Err(InputError::at(
                file,
                line_of(rec, win.start),
                format!("gyro reads |ω| = {wmean:.3} rad/s {at}: no gyro at rest turns that fast"),
            )
            .with_hint("the values look like deg/s (or counts) read as rad/s; declare the gyro unit"));
        }
        let peak = rec.gyro.iter().map(|w| norm(*w)).fold(0.0, f64::max);
        if peak > 40.0 {
            rec.warnings.push(format!(
                "{}: gyro peaks at {peak:.1} rad/s ({:.0} deg/s): implausible for rad/s, are these deg/s?",
                file.display(),
                peak.to_degrees()
            ));
        }
    }
    Ok(())
}

fn check_saturation(rec: &mut ImuRecording, opts: &ValidateOptions) {
    let name = rec.source_name();
    let sensors: Vec<(&Vec<[f64; 3]>, &str)> =
        [(&rec.gyro, "gyro"), (&rec.accel, "accelerometer")].into_iter().filter(|(v, _)| !v.is_empty()).collect();
    let found: Vec<Vec<String>> = sensors
        .par_iter()
        .map(|&(v, sensor)| {
            // One pass for the extremes of all three axes.
            let mut lo = [f64::INFINITY; 3];
            let mut hi = [f64::NEG_INFINITY; 3];
            for x in v.iter() {
                for k in 0..3 {
                    lo[k] = lo[k].min(x[k]);
                    hi[k] = hi[k].max(x[k]);
                }
            }
            let mut found = Vec::new();
            for (k, axis) in ["x", "y", "z"].into_iter().enumerate() {
                let col = |i: usize| v[i][k];
                let median = sampled_median(v.len(), col);
                let mad = sampled_median(v.len(), |i| (col(i) - median).abs());
                for extreme in [hi[k], lo[k]] {
                    // Only an extreme far out in the tail can be a clipping level.
                    if (extreme - median).abs() <= 10.0 * mad.max(1e-12) {
                        continue;
                    }
                    let mut runs = 0;
                    let mut longest = (0, 0);
                    let mut i = 0;
                    while i < v.len() {
                        if col(i) == extreme {
                            let j = (i..v.len()).find(|&j| col(j) != extreme).unwrap_or(v.len());
                            if j - i >= opts.saturation_run {
                                runs += 1;
                                if j - i > longest.0 {
                                    longest = (j - i, i);
                                }
                            }
                            i = j;
                        } else {
                            i += 1;
                        }
                    }
                    if runs > 0 {
                        found.push(format!(
                            "{name}: {sensor} {axis} is flat at {extreme} in {runs} run(s) (longest {} samples from line {}): the sensor saturates there and those samples are clipped",
                            longest.0,
                            line_of(rec, longest.1)
                        ));
                    }
                }
            }
            found
        })
        .collect();
    rec.warnings.extend(found.into_iter().flatten());
}
