//! Outputs of a calibration: `calibration.json` and `calibration.yaml` (the
//! paper's convention plus diagnostics), imu_tk's `imu_tk_acc.calib` and
//! `imu_tk_gyro.calib`, and `static_detection.png`.

use super::options::CalibOptions;
use super::result::{Assessment, Verdict};
use super::result::{
    CalibrationResult, DetectionThresholds, FitStats, InitialRestReport, RotationResidual, StaticInterval, SweepEntry,
};
use crate::error::OutputError;
use crate::io::ImuRecording;
use crate::model::calibration::{imu_tk_calib_text, CalibrationFile, ImuCalibration, Triad};
use crate::plot::{ensure_font, AXIS_COLORS};
use plotters::prelude::*;
use serde::Serialize;
use std::path::{Path, PathBuf};

#[derive(Serialize)]
struct Residuals<'a> {
    accel: &'a FitStats,
    gyro: &'a FitStats,
    rotations: &'a [RotationResidual],
}

#[derive(Serialize)]
struct Detection<'a> {
    multiplier: f64,
    thresholds: &'a DetectionThresholds,
    initial_rest: &'a InitialRestReport,
    window_s: f64,
    min_interval_s: f64,
    with_gyro: bool,
    sweep: &'a [SweepEntry],
}

#[derive(Serialize)]
struct ImuTkTriad {
    #[serde(rename = "T")]
    t: [[f64; 3]; 3],
    #[serde(rename = "K")]
    k: [f64; 3],
    b: [f64; 3],
}

#[derive(Serialize)]
struct ImuTkOut {
    acc: Option<ImuTkTriad>,
    gyro: Option<ImuTkTriad>,
}

#[derive(Serialize)]
struct Output<'a> {
    #[serde(flatten)]
    calibration: CalibrationFile,
    static_intervals: &'a [StaticInterval],
    residuals: Residuals<'a>,
    detection: Detection<'a>,
    /// The same calibration in imu_tk's convention `calibrated = T·K·(raw − b)`.
    imu_tk: ImuTkOut,
    /// The verdict (`ok` / `weak` / `failed`) with its reasons.
    assessment: &'a Assessment,
    /// The halves of the recording compared (the σ above are widened to cover them).
    #[serde(skip_serializing_if = "Option::is_none")]
    split: Option<&'a crate::model::split::SplitCheck>,
    warnings: &'a [String],
}

fn imu_tk_triad(t: &Triad) -> Option<ImuTkTriad> {
    let (tt, k, b) = t.to_imu_tk()?;
    Some(ImuTkTriad { t: [0, 1, 2].map(|r| [0, 1, 2].map(|c| tt[(r, c)])), k: [k.x, k.y, k.z], b: [b.x, b.y, b.z] })
}

impl CalibrationResult {
    fn output<'a>(&'a self, opts: &CalibOptions) -> Output<'a> {
        Output {
            calibration: CalibrationFile {
                verdict: Some(self.assessment.verdict.to_string()),
                ..CalibrationFile::from(&self.calibration)
            },
            static_intervals: &self.static_intervals,
            residuals: Residuals { accel: &self.accel_fit, gyro: &self.gyro_fit, rotations: &self.rotations },
            detection: Detection {
                multiplier: self.multiplier,
                thresholds: &self.thresholds,
                initial_rest: &self.initial_rest,
                window_s: opts.window_s,
                min_interval_s: opts.min_interval_s,
                with_gyro: opts.detect_with_gyro,
                sweep: &self.sweep,
            },
            imu_tk: ImuTkOut { acc: imu_tk_triad(&self.calibration.accel), gyro: imu_tk_triad(&self.calibration.gyro) },
            assessment: &self.assessment,
            split: self.split.as_ref(),
            warnings: &self.warnings,
        }
    }

    /// `calibration.json` text.
    pub fn to_json(&self, opts: &CalibOptions) -> String {
        serde_json::to_string_pretty(&self.output(opts)).unwrap_or_default()
    }

    /// `calibration.yaml` text (same content as the JSON).
    pub fn to_yaml(&self, opts: &CalibOptions) -> Result<String, OutputError> {
        serde_saphyr::to_string(&self.output(opts)).map_err(|e| OutputError::Failed(e.to_string()))
    }

    /// A short human-readable summary (parameters ± 1σ, fit quality).
    pub fn summary_table(&self) -> String {
        let c = &self.calibration;
        let mut s = String::new();
        let r = &self.initial_rest;
        s.push_str(&format!(
            "initial rest: {:.2}–{:.2} s ({} samples, {})\n",
            r.start_s,
            r.end_s,
            r.samples,
            if r.detected { "found in the data" } else { "--init-static" }
        ));
        s.push_str(&format!(
            "static intervals: {} (threshold multiplier {}), gravity {} m/s²\n",
            self.intervals.len(),
            self.multiplier,
            c.gravity
        ));
        s.push_str(&calibration_table(c));
        s.push_str(&format!(
            "fit: accel rms |a|−g {:.2e} m/s² (χ²/dof {:.2}), gyro rms direction error {:.2e} rad (χ²/dof {:.2})\n",
            self.accel_fit.rms, self.accel_fit.chi2_per_dof, self.gyro_fit.rms, self.gyro_fit.chi2_per_dof
        ));
        s.push_str(&format!(
            "imu_tk-style costs: accel {:.6}, gyro {:.6}\n",
            self.accel_fit.imu_tk_cost, self.gyro_fit.imu_tk_cost
        ));
        if let Some(split) = &self.split {
            s.push_str(&format!(
                "halves ({} / {}): RMS normalized difference {:.2} over {} parameters (≈ 1 when the σ are honest; σ widened where larger)\n",
                split.halves[0],
                split.halves[1],
                split.rms_z(),
                split.parameters.len()
            ));
        }
        s.push_str(&format!("verdict: {}\n", self.assessment.verdict));
        for r in &self.assessment.reasons {
            s.push_str(&format!("  - {r}\n"));
        }
        s
    }

    /// Write every output into `dir` (created); returns the files written.
    /// A [`Verdict::Failed`] result gets [`Self::write_diagnosis`]'s files only.
    pub fn write_all(&self, rec: &ImuRecording, opts: &CalibOptions, dir: &Path) -> Result<Vec<PathBuf>, OutputError> {
        if self.assessment.verdict == Verdict::Failed {
            return self.write_diagnosis(rec, opts, dir);
        }
        crate::io::staging::write_staged(dir, |stage| self.write_unstaged(rec, opts, stage))
    }

    /// For a failed calibration: `diagnosis.json` (what `calibration.json`
    /// would hold, marked `verdict: failed`, which readers refuse) and the
    /// detection figure; no `calibration.json`/`.yaml` or `.calib` a user
    /// could load by mistake.
    pub fn write_diagnosis(
        &self,
        rec: &ImuRecording,
        opts: &CalibOptions,
        dir: &Path,
    ) -> Result<Vec<PathBuf>, OutputError> {
        crate::io::staging::write_staged(dir, |stage| {
            let p = stage.join("diagnosis.json");
            std::fs::write(&p, self.to_json(opts)).map_err(|e| format!("{}: {e}", p.display()))?;
            let png = stage.join("static_detection.png");
            self.plot_detection(rec, &png)?;
            Ok(vec![p, png])
        })
    }

    pub(super) fn write_unstaged(
        &self,
        rec: &ImuRecording,
        opts: &CalibOptions,
        dir: &Path,
    ) -> Result<Vec<PathBuf>, OutputError> {
        let mut files = write_loadable(dir, self.to_json(opts), self.to_yaml(opts)?, &self.calibration)?;
        let png = dir.join("static_detection.png");
        self.plot_detection(rec, &png)?;
        files.push(png);
        Ok(files)
    }

    /// The recording's accelerometer with the static intervals shaded (top)
    /// and the sliding variance against the threshold (bottom).
    pub fn plot_detection(&self, rec: &ImuRecording, path: &Path) -> Result<(), OutputError> {
        ensure_font();
        let e = |e: &dyn std::fmt::Display| format!("{}: {e}", path.display());
        let root = BitMapBackend::new(path, (1400, 800)).into_drawing_area();
        root.fill(&WHITE).map_err(|x| e(&x))?;
        let (top, bottom) = root.split_vertically(480);
        let corr = self.calibration.corrector().ok_or_else(|| e(&"singular calibration"))?;
        let stride = (rec.len() / 20_000).max(1);
        let idx: Vec<usize> = (0..rec.len()).step_by(stride).collect();
        let (t0, t1) = (rec.t[0], rec.duration());
        let g = self.calibration.gravity * 1.3;
        let mut chart = ChartBuilder::on(&top)
            .caption("Calibrated accelerometer and detected static intervals", ("sans-serif", 22))
            .margin(12)
            .x_label_area_size(36)
            .y_label_area_size(70)
            .build_cartesian_2d(t0..t1, -g..g)
            .map_err(|x| e(&x))?;
        chart.configure_mesh().y_desc("specific force [m/s²]").draw().map_err(|x| e(&x))?;
        let shade = RGBColor(200, 235, 200);
        chart
            .draw_series(
                self.intervals
                    .iter()
                    .map(|iv| Rectangle::new([(rec.t[iv.start], -g), (rec.t[iv.end - 1], g)], shade.filled())),
            )
            .map_err(|x| e(&x))?;
        for (k, axis) in ["x", "y", "z"].iter().enumerate() {
            let color = AXIS_COLORS[k];
            chart
                .draw_series(LineSeries::new(idx.iter().map(|&i| (rec.t[i], corr.accel(rec.accel[i])[k])), color))
                .map_err(|x| e(&x))?
                .label(format!("a_{axis}"))
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], color));
        }
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .draw()
            .map_err(|x| e(&x))?;

        let pts: Vec<(f64, f64)> = idx
            .iter()
            .filter(|&&i| self.ratio[i].is_finite() && self.ratio[i] > 0.0)
            .map(|&i| (rec.t[i], self.ratio[i].log10()))
            .collect();
        let th = self.multiplier.log10();
        let lo = pts.iter().map(|p| p.1).fold(f64::MAX, f64::min).min(th) - 0.2;
        let hi = pts.iter().map(|p| p.1).fold(f64::MIN, f64::max).max(th) + 0.2;
        let mut chart = ChartBuilder::on(&bottom)
            .caption(
                format!("Windowed variance / rest variance, mean over axes; static below k = {}", self.multiplier),
                ("sans-serif", 20),
            )
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(70)
            .build_cartesian_2d(t0..t1, lo..hi)
            .map_err(|x| e(&x))?;
        chart.configure_mesh().x_desc("time [s]").y_desc("log10 ratio").draw().map_err(|x| e(&x))?;
        chart.draw_series(LineSeries::new(pts, BLACK)).map_err(|x| e(&x))?;
        chart.draw_series(LineSeries::new([(t0, th), (t1, th)], RED.stroke_width(2))).map_err(|x| e(&x))?;
        root.present().map_err(|x| e(&x))?;
        Ok(())
    }
}

/// The calibration's parameters ± 1σ, one block per triad (K, b, T rows).
pub(super) fn calibration_table(c: &ImuCalibration) -> String {
    let mut s = String::new();
    let u = &c.units;
    for (name, t, unit_b, unit_k) in [
        ("accelerometer", &c.accel, &u.accel_input, format!("{} per m/s²", u.accel_input)),
        ("gyroscope", &c.gyro, &u.gyro_input, format!("{} per rad/s", u.gyro_input)),
    ] {
        s.push_str(&format!("{name}:\n"));
        s.push_str(&format!("  {:<4} {:>16} {:>16} {:>16}\n", "", "x", "y", "z"));
        let row = |s: &mut String, label: &str, v: [f64; 3], sd: [f64; 3]| {
            s.push_str(&format!("  {label:<4}"));
            for k in 0..3 {
                s.push_str(&format!(" {:>16}", format!("{:.6} ±{:.1e}", v[k], sd[k])));
            }
            s.push('\n');
        };
        row(&mut s, "K", [t.k.x, t.k.y, t.k.z], [t.k_std.x, t.k_std.y, t.k_std.z]);
        row(&mut s, "b", [t.b.x, t.b.y, t.b.z], [t.b_std.x, t.b_std.y, t.b_std.z]);
        for r in 0..3 {
            let label = format!("T{r}");
            row(
                &mut s,
                &label,
                [t.t[(r, 0)], t.t[(r, 1)], t.t[(r, 2)]],
                [t.t_std[(r, 0)], t.t_std[(r, 1)], t.t_std[(r, 2)]],
            );
        }
        s.push_str(&format!("  (K in {unit_k}, b in {unit_b})\n"));
    }
    s
}

/// Write what a user loads into `dir`: `calibration.json` and `.yaml` (the
/// texts given) and imu_tk's `.calib` files of `c`; returns the files written.
pub(super) fn write_loadable(
    dir: &Path,
    json: String,
    yaml: String,
    c: &ImuCalibration,
) -> Result<Vec<PathBuf>, String> {
    let mut files = Vec::new();
    let mut write = |name: &str, text: String| -> Result<(), String> {
        let p = dir.join(name);
        std::fs::write(&p, text).map_err(|e| format!("{}: {e}", p.display()))?;
        files.push(p);
        Ok(())
    };
    write("calibration.json", json)?;
    write("calibration.yaml", yaml)?;
    for (name, triad) in [("imu_tk_acc.calib", &c.accel), ("imu_tk_gyro.calib", &c.gyro)] {
        if let Some((t, k, b)) = triad.to_imu_tk() {
            write(name, imu_tk_calib_text(&t, &k, &b))?;
        }
    }
    Ok(files)
}
