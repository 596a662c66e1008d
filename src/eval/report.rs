//! The files of an evaluation: `metrics.json` and the PNG figures.

use super::EvalError;
use super::Evaluation;
use crate::plot::{write_panels, Band, ScatterChart, Series, AXIS_COLORS};
use plotters::style::RGBColor;
use std::path::{Path, PathBuf};

const TRUTH: RGBColor = RGBColor(40, 40, 40);
const ESTIMATE: RGBColor = RGBColor(31, 119, 180);

fn line(label: &str, color: RGBColor, points: Vec<(f64, f64)>) -> Series {
    Series { label: label.into(), color, points, line: true }
}

/// Top view (x–y) of the ground truth and the aligned estimate, equal scales.
fn top_view(e: &Evaluation, path: &Path) -> Result<(), crate::plot::PlotError> {
    // The ground truth over the estimate's span only.
    let (t0, t1) = (e.pairs[0].t, e.pairs[e.pairs.len() - 1].t);
    let gt = (0..e.groundtruth.len())
        .filter(|&i| (t0..=t1).contains(&(e.groundtruth.t_ns[i] as f64 * 1e-9)))
        .map(|i| (e.groundtruth.p[i][0], e.groundtruth.p[i][1]))
        .collect();
    // One line per piece of the estimate, each aligned by itself.
    let pieces = e.pairs.chunk_by(|a, b| a.piece == b.piece).enumerate().map(|(k, piece)| {
        let est = piece
            .iter()
            .map(|p| {
                let q = e.similarities[p.piece].apply(&p.est.translation.vector);
                (q.x, q.y)
            })
            .collect();
        line(if k == 0 { "estimate" } else { "" }, ESTIMATE, est)
    });
    let first = e.pairs[0].gt.translation.vector;
    let n = e.similarities.len();
    ScatterChart {
        title: format!(
            "Top view, {} aligned{}: ATE RMSE {:.3} m",
            e.metrics.alignment.name(),
            if n > 1 { format!(" ({n} pieces, each by itself)") } else { String::new() },
            e.metrics.ate_rmse_m
        ),
        x_label: "x [m]".into(),
        y_label: "y [m]".into(),
        series: std::iter::once(line("ground truth", TRUTH, gt))
            .chain(pieces)
            .chain([Series {
                label: "start".into(),
                color: AXIS_COLORS[1],
                points: vec![(first.x, first.y)],
                line: false,
            }])
            .collect(),
        equal_aspect: true,
        ..Default::default()
    }
    .write_png(path, 900, 800)
}

/// Position and rotation error over time.
fn errors_over_time(e: &Evaluation, path: &Path) -> Result<(), crate::plot::PlotError> {
    let pos = e.pairs.iter().zip(&e.position_errors).map(|(p, &d)| (p.t, d)).collect();
    let rot = e.pairs.iter().zip(&e.rotation_errors).map(|(p, &d)| (p.t, d)).collect();
    let panel = |title: String, y: &str, pts| ScatterChart {
        title,
        x_label: "time since the first estimate [s]".into(),
        y_label: y.into(),
        series: vec![line("", ESTIMATE, pts)],
        ..Default::default()
    };
    write_panels(
        path,
        &[
            panel(format!("Position error after {} alignment", e.metrics.alignment.name()), "error [m]", pos),
            panel("Rotation error".into(), "error [deg]", rot),
        ],
        1000,
        800,
    )
}

/// One figure per sensor: a panel per axis with the estimate, its ±σ band and the ground truth.
fn bias_tracks(e: &Evaluation, gyro: bool, path: &Path) -> Result<(), crate::plot::PlotError> {
    let (name, unit) = if gyro { ("Gyro bias", "rad/s") } else { ("Accelerometer bias", "m/s²") };
    let panels: Vec<ScatterChart> = (0..3)
        .map(|a| {
            let pick = |r: &super::BiasRow| if gyro { r.gyro } else { r.accel };
            let est = e.bias_rows.iter().map(|r| (r.t, pick(r).0[a])).collect();
            let band: Vec<(f64, f64, f64)> = e
                .bias_rows
                .iter()
                .filter(|r| pick(r).1[a].is_finite())
                .map(|r| (r.t, pick(r).0[a] - pick(r).1[a], pick(r).0[a] + pick(r).1[a]))
                .collect();
            let truth: Vec<(f64, f64)> = e
                .bias_rows
                .iter()
                .filter_map(|r| r.truth.map(|(g, acc)| (r.t, if gyro { g[a] } else { acc[a] })))
                .collect();
            let mut series = vec![line("estimate", AXIS_COLORS[a], est)];
            if !truth.is_empty() {
                series.push(line("ground truth", TRUTH, truth));
            }
            ScatterChart {
                title: format!("{name} {} (band: ±1σ)", ["x", "y", "z"][a]),
                x_label: "time since the first estimate [s]".into(),
                y_label: format!("[{unit}]"),
                series,
                bands: if band.is_empty() { Vec::new() } else { vec![Band { color: AXIS_COLORS[a], points: band }] },
                ..Default::default()
            }
        })
        .collect();
    write_panels(path, &panels, 1000, 1050)
}

/// Relative translation error against the travelled distance.
fn rpe_chart(e: &Evaluation, path: &Path) -> Result<(), crate::plot::PlotError> {
    let pts = |f: fn(&super::RpeEntry) -> f64| e.metrics.rpe.iter().map(|r| (r.distance_m, f(r))).collect::<Vec<_>>();
    ScatterChart {
        title: "Relative translation error over travelled distance".into(),
        x_label: "distance [m]".into(),
        y_label: "error [m]".into(),
        series: vec![
            line("", ESTIMATE, pts(|r| r.trans_rmse_m)),
            Series { label: "RMSE".into(), color: ESTIMATE, points: pts(|r| r.trans_rmse_m), line: false },
            Series { label: "median".into(), color: AXIS_COLORS[0], points: pts(|r| r.trans_median_m), line: false },
        ],
        ..Default::default()
    }
    .write_png(path, 900, 500)
}

/// Write `metrics.json`, `trajectory_top.png`, `errors.png`, `rpe.png` and,
/// with a bias track, `bias_gyro.png` and `bias_accel.png` into `dir`;
/// returns the paths written.
pub fn write_report(dir: &Path, e: &Evaluation) -> Result<Vec<PathBuf>, EvalError> {
    crate::io::staging::write_staged(dir, |stage| write_unstaged(stage, e))
}

fn write_unstaged(dir: &Path, e: &Evaluation) -> Result<Vec<PathBuf>, EvalError> {
    let mut out = Vec::new();
    let metrics = dir.join("metrics.json");
    let text = serde_json::to_string_pretty(&e.metrics).map_err(|err| err.to_string())?;
    std::fs::write(&metrics, text).map_err(|err| format!("{}: {err}", metrics.display()))?;
    out.push(metrics);
    let mut figure =
        |name: &str, draw: &dyn Fn(&Path) -> Result<(), crate::plot::PlotError>| -> Result<(), EvalError> {
            let p = dir.join(name);
            draw(&p)?;
            out.push(p);
            Ok(())
        };
    figure("trajectory_top.png", &|p| top_view(e, p))?;
    figure("errors.png", &|p| errors_over_time(e, p))?;
    if !e.metrics.rpe.is_empty() {
        figure("rpe.png", &|p| rpe_chart(e, p))?;
    }
    if !e.bias_rows.is_empty() {
        figure("bias_gyro.png", &|p| bias_tracks(e, true, p))?;
        figure("bias_accel.png", &|p| bias_tracks(e, false, p))?;
    }
    Ok(out)
}
