//! What the audit compares: the static intervals and the motions between them
//! of a calibration recording, with the temperature and time of every sample.

use super::AuditError;
use crate::calib::detect::{axis_noise, mean3, var3, Interval};
use crate::io::ImuRecording;
use nalgebra::Vector3;
use tumble_factors::imu_effects::{Context, MotionSamples};

/// One static interval, summarized.
#[derive(Clone, Debug)]
pub struct StaticData {
    /// Samples averaged.
    pub samples: usize,
    /// Mean raw accelerometer reading \[raw units\].
    pub raw_accel: Vector3<f64>,
    /// Mean raw gyro reading \[raw units\].
    pub raw_gyro: Vector3<f64>,
    /// Mean temperature and time relative to the references.
    pub context: Context,
}

/// A calibration recording cut into static intervals and motions.
#[derive(Clone, Debug)]
pub struct AuditData {
    /// Local gravity \[m/s²\].
    pub gravity: f64,
    /// Static intervals in time order (the first is the initial static period).
    pub statics: Vec<StaticData>,
    /// Motion `k` goes from static interval `k` to `k + 1`.
    pub motions: Vec<MotionSamples>,
    /// Per-sample white-noise variance of the raw readings, per axis (median over
    /// the static intervals) \[raw units²\].
    pub var_accel: Vector3<f64>,
    /// See `var_accel`.
    pub var_gyro: Vector3<f64>,
    /// Whether the readings stay put inside the static intervals, against
    /// their white noise: the gyro's axes, the accelerometer's axes and its norm.
    pub within: Vec<WithinInterval>,
    /// Whether the recording has a temperature column.
    pub has_temperature: bool,
    /// Reference temperature: mean over the first static interval \[°C\] (0 without a column).
    pub reference_temperature: f64,
    /// Reference instant: middle of the first static interval \[s, recording time\].
    pub reference_time: f64,
}

impl AuditData {
    /// Summarize `rec` over the static `intervals` (sample ranges, sorted, ≥ 2)
    /// under local gravity `gravity` \[m/s²\].
    pub fn new(rec: &ImuRecording, intervals: &[Interval], gravity: f64) -> Result<AuditData, AuditError> {
        if intervals.len() < 2 {
            return Err(format!("{} static intervals: the audit needs at least 2", intervals.len()).into());
        }
        let temps = rec.temperature.as_deref();
        if let Some(t) = temps {
            if let Some(i) = t.iter().position(|x| !x.is_finite()) {
                return Err(format!("temperature of sample {i} (line {}) is not finite", rec.lines.line(i)).into());
            }
        }
        let first = intervals[0];
        let reference_temperature =
            temps.map(|t| t[first.start..first.end].iter().sum::<f64>() / first.len() as f64).unwrap_or(0.0);
        let reference_time = 0.5 * (rec.t[first.start] + rec.t[first.end - 1]);
        let ctx = |i: usize| Context {
            dtemp: temps.map(|t| t[i] - reference_temperature).unwrap_or(0.0),
            time: rec.t[i] - reference_time,
        };
        let statics = intervals
            .iter()
            .map(|iv| {
                let n = iv.len() as f64;
                let (dtemp, time) = (iv.start..iv.end).fold((0.0, 0.0), |(a, b), i| {
                    let c = ctx(i);
                    (a + c.dtemp, b + c.time)
                });
                StaticData {
                    samples: iv.len(),
                    raw_accel: Vector3::from(mean3(&rec.accel[iv.start..iv.end])),
                    raw_gyro: Vector3::from(mean3(&rec.gyro[iv.start..iv.end])),
                    context: Context { dtemp: dtemp / n, time: time / n },
                }
            })
            .collect();
        let motions = intervals
            .windows(2)
            .map(|w| {
                let (a, b) = (w[0].end - 1, w[1].start);
                MotionSamples {
                    raw_gyro: rec.gyro[a..=b].iter().map(|x| Vector3::from(*x)).collect(),
                    raw_accel: rec.accel[a..=b].iter().map(|x| Vector3::from(*x)).collect(),
                    context: (a..=b).map(ctx).collect(),
                    dt: rec.t[a..=b].windows(2).map(|t| t[1] - t[0]).collect(),
                }
            })
            .collect();
        let median_var = |x: &[[f64; 3]]| -> Vector3<f64> {
            let vars: Vec<[f64; 3]> = intervals.iter().map(|iv| var3(&x[iv.start..iv.end])).collect();
            Vector3::from_fn(|k, _| {
                let mut v: Vec<f64> = vars.iter().map(|a| a[k]).collect();
                v.sort_by(f64::total_cmp);
                v[v.len() / 2]
            })
        };
        let norm: Vec<[f64; 3]> = rec.accel.iter().map(|a| [Vector3::from(*a).norm(), 0.0, 0.0]).collect::<Vec<_>>();
        let mut within = Vec::new();
        for (triad, x) in [("gyro", &rec.gyro), ("accel", &rec.accel)] {
            for (k, axis) in ["x", "y", "z"].into_iter().enumerate() {
                within.extend(WithinInterval::measure(format!("{triad} {axis}"), x, k, intervals));
            }
        }
        within.extend(WithinInterval::measure("|accel|".into(), &norm, 0, intervals));
        Ok(AuditData {
            gravity,
            statics,
            motions,
            var_accel: median_var(&rec.accel),
            var_gyro: median_var(&rec.gyro),
            within,
            has_temperature: temps.is_some(),
            reference_temperature,
            reference_time,
        })
    }
}

/// Whether a reading stays put inside the static intervals: its two halves'
/// means against the white noise of its samples.
///
/// The audit weighs each interval's mean as `σ²/n`, white noise over `n`
/// samples, and compares the means across intervals, where every candidate
/// effect shows. Inside an interval no candidate varies, so a difference
/// between the halves beyond the noise is something else: a sensor settling
/// after the turn before, an interval not quite at rest, noise that is not
/// white over seconds (flicker, a table that shakes). Its interval means then
/// scatter more than `σ²/n`, a gap no effect in the vocabulary can explain.
/// Per interval the halves of `h` samples differ by `d`, of variance `2σ²/h`
/// under white noise; `T = Σ d²/(2σ²/h)` is χ² with one degree of freedom
/// per interval. Each interval contributes its central stretch of the median
/// interval's length (a long initial rest would otherwise measure the bias
/// walk over tens of seconds), with `σ²` from [`axis_noise`] of that stretch
/// (at least the quantization's).
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct WithinInterval {
    /// What was measured: `gyro x`, `accel z`, `|accel|`.
    pub reading: String,
    /// `T / m`: how many times the white noise's variance the halves differ by (1 for white noise).
    pub ratio: f64,
    /// Intervals measured (`m`, the degrees of freedom).
    pub intervals: usize,
    /// Probability of a `T` at least this large under white noise.
    pub p_value: f64,
}

impl WithinInterval {
    /// The test on column `k` of `x` over `intervals`; `None` with fewer than
    /// 8 intervals of 8 samples.
    pub fn measure(reading: String, x: &[[f64; 3]], k: usize, intervals: &[Interval]) -> Option<WithinInterval> {
        use statrs::distribution::{ChiSquared, ContinuousCDF};
        let mut lens: Vec<usize> = intervals.iter().map(|iv| iv.len()).collect();
        lens.sort_unstable();
        let typical = lens.get(lens.len() / 2).copied().unwrap_or(0);
        let (mut t, mut m) = (0.0, 0usize);
        for iv in intervals {
            let len = iv.len().min(typical) & !1;
            if len < 8 {
                continue;
            }
            let start = iv.start + (iv.len() - len) / 2;
            let s = &x[start..start + len];
            let h = len / 2;
            let d = mean3(&s[..h])[k] - mean3(&s[h..])[k];
            t += d * d / (2.0 * axis_noise(s)[k].max(1e-300) / h as f64);
            m += 1;
        }
        (m >= 8).then(|| WithinInterval {
            reading,
            ratio: t / m as f64,
            intervals: m,
            p_value: ChiSquared::new(m as f64).map(|c| c.sf(t)).unwrap_or(1.0),
        })
    }
}

/// The tests of `within` significant at `alpha` after Bonferroni's correction
/// over all of them.
pub fn unsettled(within: &[WithinInterval], alpha: f64) -> Vec<&WithinInterval> {
    let n = within.len().max(1) as f64;
    within.iter().filter(|w| w.p_value < alpha / n).collect()
}

/// "the accel z moves 16.2× (p 1e-40), …" for a verdict or a note.
pub fn describe(tests: &[&WithinInterval]) -> String {
    let parts: Vec<String> =
        tests.iter().map(|w| format!("the {} moves {:.1}× (p {:.1e})", w.reading, w.ratio, w.p_value)).collect();
    parts.join(", ")
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_distr::{Distribution, StandardNormal};

    /// 40 intervals of 300–700 samples of white noise (σ 2 on x), 50 samples of turn between them.
    fn recording(seed: u64, drift: f64) -> (Vec<[f64; 3]>, Vec<Interval>) {
        let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
        let (mut x, mut intervals) = (Vec::new(), Vec::new());
        for k in 0..40 {
            let n = 300 + (k * 37) % 400;
            let start = x.len();
            for i in 0..n {
                // A settling after the turn: an exponential of 2 s (200 samples) on x.
                let settle = drift * (-(i as f64) / 200.0).exp() * if k % 2 == 0 { 1.0 } else { -1.0 };
                let (e, f): (f64, f64) = (StandardNormal.sample(&mut rng), StandardNormal.sample(&mut rng));
                x.push([2.0 * e + settle, 0.5 * f, 1.0]);
            }
            intervals.push(Interval { start, end: x.len() });
            x.extend((0..50).map(|_| [100.0, 100.0, 100.0]));
        }
        (x, intervals)
    }

    #[test]
    fn white_noise_stays_put_and_a_settling_does_not() {
        let mut rejected = 0;
        for seed in 0..40 {
            let (x, iv) = recording(seed, 0.0);
            let t: Vec<WithinInterval> =
                (0..2).filter_map(|k| WithinInterval::measure(format!("axis {k}"), &x, k, &iv)).collect();
            assert_eq!(t.len(), 2);
            assert!(t.iter().all(|w| w.intervals == 40 && (0.4..2.0).contains(&w.ratio)), "{t:?}");
            rejected += unsettled(&t, 1e-2).len();
            // A constant axis (one quantization step) is not flagged either.
            let c = WithinInterval::measure("constant".into(), &x, 2, &iv).unwrap();
            assert!(c.ratio == 0.0 && c.p_value == 1.0, "{c:?}");
        }
        // 80 tests at a 0.5 % level each (1 % over two): about 0.4 expected.
        assert!(rejected <= 3, "{rejected} of 80 white-noise axes flagged");
        // A settling of 0.5 σ at the start of each interval is found on x alone.
        let (x, iv) = recording(1, 1.0);
        let t: Vec<WithinInterval> =
            (0..2).filter_map(|k| WithinInterval::measure(format!("axis {k}"), &x, k, &iv)).collect();
        let found = unsettled(&t, 1e-3);
        assert_eq!(found.len(), 1, "{t:?}");
        assert_eq!(found[0].reading, "axis 0");
        assert!(describe(&found).starts_with("the axis 0 moves"), "{}", describe(&found));
    }
}
