//! `tumble inspect`: what a recording holds and what looks wrong, and a
//! picture of it. The statistics are the reader's
//! ([`ImuRecording::stats`](crate::io::ImuRecording::stats)); this module draws.

use crate::io::{ImuRecording, Stored};
use crate::plot::{write_panels, PlotError, ScatterChart, Series};
use plotters::style::RGBColor;
use std::path::Path;

/// Write a PNG overview (1200 × 900, or × 1150 with a temperature column):
/// the accelerometer and the gyro, per axis, against time \[s\] (and the
/// temperature). Long recordings keep each axis' envelope: every pixel
/// column holds the minimum and maximum of its samples, so spikes and
/// saturation stay visible.
///
/// ```no_run
/// use tumble::io::{open_recording, RecordingOptions};
/// let rec = open_recording("mav0/".as_ref(), &RecordingOptions::default()).unwrap();
/// tumble::inspect::write_overview_png(&rec, "imu.png".as_ref()).unwrap();
/// ```
pub fn write_overview_png(rec: &ImuRecording, path: &Path) -> Result<(), PlotError> {
    const COLUMNS: usize = 1000;
    const COLORS: [RGBColor; 3] = [RGBColor(214, 39, 40), RGBColor(44, 160, 44), RGBColor(31, 119, 180)];
    if rec.is_empty() {
        return Err(PlotError::Draw { path: path.to_path_buf(), message: "no samples to plot".into() });
    }
    let per = rec.len().div_ceil(COLUMNS);
    let envelope = |value: &dyn Fn(usize) -> f64| -> Vec<(f64, f64)> {
        let mut pts = Vec::with_capacity(2 * COLUMNS);
        for start in (0..rec.len()).step_by(per) {
            let end = (start + per).min(rec.len());
            let (lo, hi) =
                (start..end).map(value).fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| (a.min(v), b.max(v)));
            let t = rec.t[start];
            pts.push((t, lo));
            if hi > lo {
                pts.push((t, hi));
            }
        }
        pts
    };
    // imu_tk layouts hold the gyro in a second file.
    let gyro_source = rec.sources.last().map_or_else(|| rec.source_name(), |p| p.display().to_string());
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
        axes(&rec.accel, "accelerometer", &unit(rec.accel_units, "m/s²"), &rec.source_name()),
        axes(&rec.gyro, "gyroscope", &unit(rec.gyro_units, "rad/s"), &gyro_source),
    ];
    if let Some(temp) = &rec.temperature {
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
