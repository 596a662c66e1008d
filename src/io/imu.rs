//! An IMU recording in memory: timestamps, gyro and accelerometer triads, an
//! optional temperature trace, and what the reader noticed on the way.

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
    /// Samples with `t` in `[t_start, t_end)` \[s\] as a new recording (warnings dropped).
    pub fn slice_time(&self, t_start: f64, t_end: f64) -> ImuRecording {
        let a = self.t.partition_point(|&x| x < t_start);
        let b = self.t.partition_point(|&x| x < t_end);
        let shift = self.t.get(a).copied().unwrap_or(0.0);
        ImuRecording {
            sources: self.sources.clone(),
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
