//! Outputs of a calibration from several recordings: the sensor's
//! `calibration.json` / `.yaml` and imu_tk `.calib` files (what a user
//! loads), `recordings.md` (each parameter per recording, the consensus and
//! whether they agree), `recordings.png`, and each recording's own outputs in
//! a folder of its own.

use super::options::CalibOptions;
use super::report::{calibration_table, write_loadable};
use super::result::{Assessment, Verdict};
use super::several::RecordingsResult;
use crate::error::OutputError;
use crate::io::ImuRecording;
use crate::model::calibration::CalibrationFile;
use crate::model::consensus::RecordingsCheck;
use plotters::prelude::*;
use serde::Serialize;
use std::path::{Path, PathBuf};

/// One recording in `calibration.json`.
#[derive(Serialize)]
struct RecordingEntry<'a> {
    name: &'a str,
    folder: String,
    verdict: Verdict,
    static_poses: usize,
    /// RMS normalized difference of its halves (None: too few poses to split).
    halves_rms_z: Option<f64>,
}

#[derive(Serialize)]
struct Output<'a> {
    #[serde(flatten)]
    calibration: CalibrationFile,
    assessment: &'a Assessment,
    recordings: Vec<RecordingEntry<'a>>,
    /// Scales and misalignments per recording, their consensus (the values above) and agreement.
    pooled: &'a RecordingsCheck,
    /// Biases per recording (each power-on differs; the value above is their
    /// consensus, its σ the one a new power-on's bias is known to).
    biases: &'a RecordingsCheck,
    rms_pairwise_z: f64,
    max_pairwise_z: f64,
    warnings: &'a [String],
}

/// The folder of recording `i` (from 0) named `name`: `recording_<i+1>_<name's file stem>`.
pub fn recording_folder(i: usize, name: &str) -> String {
    let stem = Path::new(name).file_stem().and_then(|s| s.to_str()).unwrap_or("");
    let clean: String = stem.chars().map(|c| if c.is_alphanumeric() || c == '-' { c } else { '_' }).collect();
    if clean.is_empty() {
        format!("recording_{}", i + 1)
    } else {
        format!("recording_{}_{clean}", i + 1)
    }
}

impl RecordingsResult {
    fn output<'a>(&'a self, names: &'a [String]) -> Output<'a> {
        Output {
            calibration: CalibrationFile {
                verdict: Some(self.assessment.verdict.to_string()),
                ..CalibrationFile::from(&self.calibration)
            },
            assessment: &self.assessment,
            recordings: self
                .each
                .iter()
                .zip(names)
                .enumerate()
                .map(|(i, (r, name))| RecordingEntry {
                    name,
                    folder: recording_folder(i, name),
                    verdict: r.assessment.verdict,
                    static_poses: r.intervals.len(),
                    halves_rms_z: r.split.as_ref().map(|s| s.rms_z()),
                })
                .collect(),
            pooled: &self.check,
            biases: &self.biases,
            rms_pairwise_z: self.check.rms_pairwise_z(),
            max_pairwise_z: self.check.max_pairwise_z(),
            warnings: &self.warnings,
        }
    }

    /// A short human-readable summary: the pooled calibration, the agreement, the verdict.
    pub fn summary_table(&self) -> String {
        let mut s = format!("{} recordings of one sensor, each calibrated alone:\n", self.each.len());
        for (name, r) in self.check.recordings.iter().zip(&self.each) {
            s.push_str(&format!(
                "  {name}: {} static poses, verdict {}{}\n",
                r.intervals.len(),
                r.assessment.verdict,
                r.split.as_ref().map_or(String::new(), |h| format!(", halves RMS z {:.2}", h.rms_z()))
            ));
        }
        s.push_str("pooled (scales and misalignments: consensus; biases: consensus, σ of a new power-on):\n");
        s.push_str(&calibration_table(&self.calibration));
        s.push_str(&format!(
            "recordings against each other: RMS normalized difference {:.2}, largest {:.2} over {} parameters \
             (≈ 1 when the σ are honest; σ widened where larger)\n",
            self.check.rms_pairwise_z(),
            self.check.max_pairwise_z(),
            self.check.parameters.len()
        ));
        s.push_str(&format!("verdict: {}\n", self.assessment.verdict));
        for r in &self.assessment.reasons {
            s.push_str(&format!("  - {r}\n"));
        }
        s
    }

    /// `recordings.md`: every parameter per recording and pooled.
    pub fn recordings_markdown(&self) -> String {
        let names = &self.check.recordings;
        let mut s = String::from("# One sensor, several recordings\n\n");
        s.push_str(&format!(
            "Verdict: **{}**. Recordings against each other: RMS normalized difference {:.2}, largest {:.2} \
             (≈ 1 when the σ are honest). Pooled: the consensus weighted by 1/(σ² + τ²), τ the spread between \
             recordings their σ do not describe (0 when they agree); p: the chance of a spread this large \
             from honest σ.\n\n",
            self.assessment.verdict,
            self.check.rms_pairwise_z(),
            self.check.max_pairwise_z()
        ));
        for r in &self.assessment.reasons {
            s.push_str(&format!("- {r}\n"));
        }
        for (title, check) in
            [("Scales and misalignments", &self.check), ("Biases (differ at every power-on)", &self.biases)]
        {
            s.push_str(&format!("\n## {title}\n\n| parameter | "));
            s.push_str(&names.iter().map(|n| format!("{n} |")).collect::<Vec<_>>().join(" "));
            s.push_str(" pooled | τ | p |\n|---|");
            s.push_str(&"---|".repeat(names.len() + 3));
            s.push('\n');
            for p in &check.parameters {
                s.push_str(&format!("| {} |", p.parameter));
                for r in 0..p.values.len() {
                    s.push_str(&format!(" {} |", p.estimate_text(r)));
                }
                s.push_str(&format!(" {:.6} ± {:.1e} | {:.1e} | {:.2} |\n", p.value, p.sigma, p.tau, p.p_value));
            }
        }
        s
    }

    /// Write every output into `dir` (created); `recs` and `names` in the
    /// order calibrated. Returns the files written (each recording's folder
    /// counted as its files).
    pub fn write_all(
        &self,
        recs: &[ImuRecording],
        names: &[String],
        opts: &CalibOptions,
        dir: &Path,
    ) -> Result<Vec<PathBuf>, OutputError> {
        crate::io::staging::write_staged(dir, |stage| {
            let out = self.output(names);
            let json = serde_json::to_string_pretty(&out).unwrap_or_default();
            let yaml = serde_saphyr::to_string(&out).map_err(|e| e.to_string())?;
            let mut files = write_loadable(stage, json, yaml, &self.calibration)?;
            let md = stage.join("recordings.md");
            std::fs::write(&md, self.recordings_markdown()).map_err(|e| format!("{}: {e}", md.display()))?;
            files.push(md);
            let png = stage.join("recordings.png");
            plot_pooled(&self.check, &png)?;
            files.push(png);
            for (i, ((r, rec), name)) in self.each.iter().zip(recs).zip(names).enumerate() {
                let sub = stage.join(recording_folder(i, name));
                std::fs::create_dir_all(&sub).map_err(|e| format!("{}: {e}", sub.display()))?;
                files.extend(r.write_unstaged(rec, opts, &sub)?);
            }
            Ok(files)
        })
    }
}

/// Each recording's estimate of each pooled parameter against the
/// consensus, in units of the consensus's σ widened by the recording's own
/// (`(θ_r − θ̄)/√(σ_r² + σ̄²)`), one row per parameter: points beyond ±3
/// are recordings that disagree.
fn plot_pooled(check: &RecordingsCheck, path: &Path) -> Result<(), OutputError> {
    crate::plot::ensure_font();
    let e = |x: &dyn std::fmt::Display| OutputError::Failed(format!("{}: {x}", path.display()));
    let n = check.parameters.len().max(1);
    let root = BitMapBackend::new(path, (900, 120 + 22 * n as u32)).into_drawing_area();
    root.fill(&WHITE).map_err(|x| e(&x))?;
    let z = |p: &crate::model::consensus::Consensus, r: usize| {
        (p.values[r] - p.value) / (p.sigmas[r].powi(2) + p.sigma.powi(2)).sqrt()
    };
    let zmax = check
        .parameters
        .iter()
        .flat_map(|p| (0..p.values.len()).map(move |r| z(p, r)))
        .filter(|v| v.is_finite())
        .fold(4.0f64, |m, v| m.max(v.abs() * 1.1));
    let mut chart = ChartBuilder::on(&root)
        .caption("each recording against the pooled value [σ]", ("sans-serif", 18))
        .margin(12)
        .x_label_area_size(36)
        .y_label_area_size(260)
        .build_cartesian_2d(-zmax..zmax, (0..n).into_segmented())
        .map_err(|x| e(&x))?;
    let label = |v: &SegmentValue<usize>| match v {
        SegmentValue::CenterOf(i) | SegmentValue::Exact(i) => {
            check.parameters.get(*i).map_or(String::new(), |p| p.parameter.clone())
        }
        SegmentValue::Last => String::new(),
    };
    chart
        .configure_mesh()
        .x_desc("(recording − pooled) / σ")
        .y_labels(n)
        .y_label_formatter(&label)
        .draw()
        .map_err(|x| e(&x))?;
    for bound in [-3.0, 3.0] {
        chart
            .draw_series(LineSeries::new(
                [(bound, SegmentValue::Exact(0)), (bound, SegmentValue::Last)],
                RED.stroke_width(1),
            ))
            .map_err(|x| e(&x))?;
    }
    for r in 0..check.recordings.len() {
        let color = Palette99::pick(r).to_rgba();
        chart
            .draw_series(check.parameters.iter().enumerate().filter_map(|(i, p)| {
                let v = z(p, r);
                (v.is_finite() && !p.left_out[r])
                    .then(|| Circle::new((v, SegmentValue::CenterOf(i)), 4, color.filled()))
            }))
            .map_err(|x| e(&x))?
            .label(check.recordings[r].clone())
            .legend(move |(x, y)| Circle::new((x, y), 4, color.filled()));
    }
    chart.configure_series_labels().background_style(WHITE.mix(0.8)).border_style(BLACK).draw().map_err(|x| e(&x))?;
    root.present().map_err(|x| e(&x))?;
    Ok(())
}
