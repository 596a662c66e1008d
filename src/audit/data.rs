//! What the audit compares: the static intervals and the motions between them
//! of a calibration recording, with the temperature and time of every sample.

use super::AuditError;
use crate::calib::detect::{mean3, var3, Interval, WithinInterval};
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
        let within = WithinInterval::measure_all(&rec.accel, &rec.gyro, intervals);
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
