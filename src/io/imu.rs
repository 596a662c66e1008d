//! An IMU recording in memory: timestamps, gyro and accelerometer triads, an
//! optional temperature trace, and what the reader noticed on the way.

use crate::model::calibration::{Corrector, ImuCalibration};
use crate::model::ImuData;
use nalgebra::Vector3;
use std::path::PathBuf;

/// What the stored numbers of one sensor are.
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Stored {
    /// SI units: rad/s for the gyro, m/s² for the accelerometer.
    #[default]
    Si,
    /// Raw sensor counts, kept as read because no scale was given (imu_tk's
    /// calibration works on these; its biases come out in counts).
    RawCounts,
}

/// An IMU recording: sample `i` was taken at `t0_ns + t[i]·1e9` ns.
#[derive(Debug, Clone, Default)]
pub struct ImuRecording {
    /// The file(s) the samples came from (for messages).
    pub sources: Vec<PathBuf>,
    /// The ROS topic(s) the samples came from (`/imu0`, or `ACCEL + GYRO` for
    /// split streams); None for files without topics.
    pub topic: Option<String>,
    /// Absolute time of the first sample \[ns\] (epoch or sensor clock, as in the file).
    pub t0_ns: i64,
    /// Sample times relative to `t0_ns` \[s\], strictly increasing after validation.
    pub t: Vec<f64>,
    /// Angular rate in the sensor frame, per sample (\[rad/s\] when `gyro_units` is `Si`).
    pub gyro: Vec<[f64; 3]>,
    /// Specific force in the sensor frame, per sample (\[m/s²\] when `accel_units` is `Si`).
    pub accel: Vec<[f64; 3]>,
    /// Temperature per sample \[°C\], when the file has a temperature column.
    pub temperature: Option<Vec<f64>>,
    /// Units of `gyro`.
    pub gyro_units: Stored,
    /// Units of `accel`.
    pub accel_units: Stored,
    /// Line of each sample in the first source (for messages).
    pub lines: super::table::LineMap,
    /// Problems found that did not stop reading (duplicates, gaps, units, saturation).
    pub warnings: Vec<String>,
}

impl ImuRecording {
    /// Number of samples.
    pub fn len(&self) -> usize {
        self.t.len()
    }
    /// True when there are no samples.
    pub fn is_empty(&self) -> bool {
        self.t.is_empty()
    }
    /// Duration from first to last sample \[s\].
    pub fn duration(&self) -> f64 {
        self.t.last().copied().unwrap_or(0.0)
    }
    /// Mean sample rate \[Hz\] over the whole recording ((n−1)/duration).
    pub fn mean_rate(&self) -> f64 {
        if self.len() < 2 || self.duration() <= 0.0 {
            return 0.0;
        }
        (self.len() - 1) as f64 / self.duration()
    }
    /// Absolute time of sample `i` \[ns\].
    pub fn t_ns(&self, i: usize) -> i64 {
        self.t0_ns + (self.t[i] * 1e9).round() as i64
    }
    /// Name of the first source, for messages.
    pub fn source_name(&self) -> String {
        self.sources.first().map(|p| p.display().to_string()).unwrap_or_else(|| "<memory>".into())
    }
    /// An error at sample `i`: the first source file and the sample's line.
    pub fn error_at(&self, i: usize, message: impl std::fmt::Display) -> crate::InputError {
        let file = self.sources.first().cloned().unwrap_or_else(|| "<memory>".into());
        crate::InputError::at(&file, self.lines.line(i), message)
    }
    /// Mean and standard deviation per axis of the accelerometer and the
    /// gyro (in the stored units), and the temperature range \[°C\].
    pub fn stats(&self) -> RecordingStats {
        let axes = |v: &[[f64; 3]]| -> Option<AxisStats> {
            if v.is_empty() {
                return None;
            }
            let n = v.len() as f64;
            let mean = [0, 1, 2].map(|k| v.iter().map(|s| s[k]).sum::<f64>() / n);
            let std = [0, 1, 2].map(|k| (v.iter().map(|s| (s[k] - mean[k]).powi(2)).sum::<f64>() / n).sqrt());
            Some(AxisStats { mean, std })
        };
        let temperature = self
            .temperature
            .as_ref()
            .map(|t| t.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| (a.min(x), b.max(x))));
        RecordingStats { accel: axes(&self.accel), gyro: axes(&self.gyro), temperature }
    }
    /// Samples with `t` in `[t_start, t_end)` \[s\] as a new recording (warnings dropped).
    pub fn slice_time(&self, t_start: f64, t_end: f64) -> ImuRecording {
        let a = self.t.partition_point(|&x| x < t_start);
        let b = self.t.partition_point(|&x| x < t_end);
        let shift = self.t.get(a).copied().unwrap_or(0.0);
        ImuRecording {
            sources: self.sources.clone(),
            topic: self.topic.clone(),
            t0_ns: self.t0_ns + (shift * 1e9).round() as i64,
            t: self.t[a..b].iter().map(|x| x - shift).collect(),
            gyro: self.gyro[a..b].to_vec(),
            accel: self.accel[a..b].to_vec(),
            temperature: self.temperature.as_ref().map(|v| v[a..b].to_vec()),
            gyro_units: self.gyro_units,
            accel_units: self.accel_units,
            lines: self.lines.slice(a),
            warnings: Vec::new(),
        }
    }
}

/// The series `x` sampled at stamps `t` \[s\], read at `t[i] − delay` for every
/// `i` (linear interpolation, held at the ends): corrects a sensor whose
/// sample stamped `t` measured time `t + delay` (e.g. an accelerometer
/// `accel_gyro_s` behind the gyro). `t` must be increasing.
pub fn resample_delayed(t: &[f64], x: &[[f64; 3]], delay: f64) -> Vec<[f64; 3]> {
    let n = t.len().min(x.len());
    if n == 0 || delay == 0.0 {
        return x.to_vec();
    }
    let mut j = 0;
    (0..n)
        .map(|i| {
            let s = t[i] - delay;
            while j + 1 < n && t[j + 1] <= s {
                j += 1;
            }
            if s <= t[0] {
                x[0]
            } else if j + 1 >= n {
                x[n - 1]
            } else {
                let w = (s - t[j]) / (t[j + 1] - t[j]);
                [0, 1, 2].map(|k| x[j][k] * (1.0 - w) + x[j + 1][k] * w)
            }
        })
        .collect()
}

/// Per-axis statistics of one sensor triad (see [`ImuRecording::stats`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AxisStats {
    /// Mean per axis (x, y, z), in the stored units.
    pub mean: [f64; 3],
    /// Population standard deviation per axis, in the stored units.
    pub std: [f64; 3],
}

/// What [`ImuRecording::stats`] reports.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RecordingStats {
    /// Accelerometer statistics (None without samples).
    pub accel: Option<AxisStats>,
    /// Gyro statistics (None without samples).
    pub gyro: Option<AxisStats>,
    /// Lowest and highest temperature \[°C\], when the recording has a temperature column.
    pub temperature: Option<(f64, f64)>,
}

impl Corrector {
    /// Correct every sample of a recording with [`Corrector::sample`] (its
    /// temperature column, when present, and its time stamps): specific forces
    /// \[m/s²\] and rates \[rad/s\].
    pub fn correct_recording(&self, rec: &ImuRecording) -> (Vec<[f64; 3]>, Vec<[f64; 3]>) {
        let temps = rec.temperature.as_deref();
        (0..rec.len()).map(|i| self.sample(rec.accel[i], rec.gyro[i], temps.map(|t| t[i]), rec.t[i])).unzip()
    }

    /// Problems applying the effects to `rec` (missing temperature, a drift
    /// fitted on another recording), for the user.
    pub fn warnings_for(&self, rec: &ImuRecording) -> Vec<String> {
        self.warnings(rec.temperature.is_some())
    }
}

impl ImuRecording {
    /// The samples as the estimators take them: corrected by `calibration`
    /// when given (eq. 16 and the audit's effects, [`Corrector::correct_recording`]),
    /// else as read (already in SI units).
    pub fn calibrated(&self, calibration: Option<&ImuCalibration>) -> ImuData {
        let (acc, gyro) = match calibration.and_then(|c| c.corrector()) {
            Some(c) => c.correct_recording(self),
            None => (self.accel.clone(), self.gyro.clone()),
        };
        ImuData {
            t: self.t.clone(),
            gyro: gyro.into_iter().map(Vector3::from).collect(),
            acc: acc.into_iter().map(Vector3::from).collect(),
        }
    }
}
