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
    /// Write a PNG overview (1200 × 900, or × 1150 with a temperature column):
    /// the accelerometer and the gyro, per axis, against time \[s\] (and the
    /// temperature). Long recordings keep each axis' envelope: every pixel
    /// column holds the minimum and maximum of its samples, so spikes and
    /// saturation stay visible.
    ///
    /// ```no_run
    /// use tumble::io::{open_recording, RecordingOptions};
    /// let rec = open_recording("mav0/".as_ref(), &RecordingOptions::default()).unwrap();
    /// rec.write_overview_png("imu.png".as_ref()).unwrap();
    /// ```
    pub fn write_overview_png(&self, path: &std::path::Path) -> Result<(), String> {
        use crate::plot::{write_panels, ScatterChart, Series};
        use plotters::style::RGBColor;
        const COLUMNS: usize = 1000;
        const COLORS: [RGBColor; 3] = [RGBColor(214, 39, 40), RGBColor(44, 160, 44), RGBColor(31, 119, 180)];
        if self.is_empty() {
            return Err(format!("{}: no samples to plot", path.display()));
        }
        let per = self.len().div_ceil(COLUMNS);
        let envelope = |value: &dyn Fn(usize) -> f64| -> Vec<(f64, f64)> {
            let mut pts = Vec::with_capacity(2 * COLUMNS);
            for start in (0..self.len()).step_by(per) {
                let end = (start + per).min(self.len());
                let (lo, hi) =
                    (start..end).map(value).fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| (a.min(v), b.max(v)));
                let t = self.t[start];
                pts.push((t, lo));
                if hi > lo {
                    pts.push((t, hi));
                }
            }
            pts
        };
        // imu_tk layouts hold the gyro in a second file.
        let gyro_source = self.sources.last().map_or_else(|| self.source_name(), |p| p.display().to_string());
        let axes = |data: &[[f64; 3]], what: &str, unit: &str, source: &str| ScatterChart {
            title: format!("{what} — {source}"),
            x_label: "time [s]".into(),
            y_label: unit.into(),
            series: (0..3)
                .map(|k| Series {
                    label: ["x", "y", "z"][k].into(),
                    color: COLORS[k],
                    points: envelope(&|i| data[i][k]),
                    line: true,
                })
                .collect(),
            ..Default::default()
        };
        let unit = |u: Stored, si: &str| if u == Stored::Si { si.to_string() } else { "raw counts".into() };
        let mut charts = vec![
            axes(&self.accel, "accelerometer", &unit(self.accel_units, "m/s²"), &self.source_name()),
            axes(&self.gyro, "gyroscope", &unit(self.gyro_units, "rad/s"), &gyro_source),
        ];
        if let Some(temp) = &self.temperature {
            charts.push(ScatterChart {
                title: "temperature".into(),
                x_label: "time [s]".into(),
                y_label: "°C".into(),
                series: vec![Series {
                    color: RGBColor(120, 120, 120),
                    points: envelope(&|i| temp[i]),
                    line: true,
                    ..Default::default()
                }],
                ..Default::default()
            });
        }
        let height = if charts.len() == 3 { 1150 } else { 900 };
        write_panels(path, &charts, 1200, height)
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
