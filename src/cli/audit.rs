//! `tumble audit`: the model-discrepancy audit of a calibration, or (`--vio`)
//! of a VIO run's time offsets.

use super::common::{open_input, progress_bar, CalibInput, FrontendArgs};
use super::CliResult;
use clap::Args;
use std::path::PathBuf;
use tumble::audit::{AuditOptions, Effect};
use tumble::calib::ImuCalibration;
use tumble::vio::ImuNoise;

/// Flags of `tumble audit`.
#[derive(Args)]
pub struct AuditArgs {
    #[command(flatten)]
    input: CalibInput,
    /// Several tumbles of one sensor (the file `tumble calibrate --inputs`
    /// read; give its calibration.json as --calibration): each audited with
    /// its own calibration (the folder per recording beside it), then every
    /// effect found compared across them; those that repeat are added to the
    /// sensor's calibration (docs/audit.md).
    #[arg(long, conflicts_with_all = ["recording", "accel", "gyro", "vio"], requires = "calibration")]
    inputs: Option<PathBuf>,
    /// calibration.json or .yaml from `tumble calibrate` (or imu_tk's, converted by it);
    /// optional with --vio (then calibration.json with the offsets is written only when given).
    #[arg(long)]
    calibration: Option<PathBuf>,
    /// Audit a VIO run on this input instead (as `tumble vio` takes it: ASL folder with
    /// tracks or images, or an EqVIO .csv): fits the time offsets by re-running the estimator.
    #[arg(long, conflicts_with_all = ["recording", "accel", "gyro"])]
    vio: Option<PathBuf>,
    /// With --vio: feature observation noise [px].
    #[arg(long, default_value_t = 1.0)]
    pixel_sigma: f64,
    /// With --vio: gravity magnitude [m/s²].
    #[arg(long, default_value_t = 9.81)]
    gravity: f64,
    /// With --vio: spacing of the offsets tried [ms].
    #[arg(long, default_value_t = 4.0)]
    offset_step_ms: f64,
    #[command(flatten)]
    frontend: FrontendArgs,
    /// Kalibr imu.yaml with the noise (from `tumble allan`): its bias random walks (per axis
    /// when it has tumble's `axes` block) set how far biases may wander (default: estimated
    /// from the recording, per axis, and stated in the report; a hand tumble rarely determines
    /// them, and the verdict then says so).
    #[arg(long)]
    noise: Option<PathBuf>,
    /// Output folder.
    #[arg(long)]
    out: PathBuf,
    /// Family-wise significance level (each candidate is tested at alpha / candidates).
    #[arg(long, default_value_t = 1e-3)]
    alpha: f64,
    /// Most effects to add.
    #[arg(long, default_value_t = 4)]
    max_effects: usize,
    /// Candidates to test, comma separated (default: all the sensor model holds).
    #[arg(long, value_delimiter = ',', value_parser = |s: &str| s.parse::<Effect>())]
    candidates: Vec<Effect>,
    /// Length of the initial static period [s] (for the static-interval detection) (default: found in the data).
    #[arg(long)]
    init_static: Option<f64>,
}

impl AuditArgs {
    pub fn run(self) -> CliResult {
        let noise = self.noise.as_deref().map(ImuNoise::read).transpose()?;
        if let Some(path) = &self.vio {
            let cal = self.calibration.as_deref().map(ImuCalibration::read).transpose()?;
            return self.run_vio(path, cal.as_ref(), noise);
        }
        let calibration =
            self.calibration.as_ref().ok_or("--calibration is required to audit a calibration recording")?;
        let cal = ImuCalibration::read(calibration)?;
        let mut opts = AuditOptions { alpha: self.alpha, max_effects: self.max_effects, noise, ..Default::default() };
        opts.detection.init_static_s = self.init_static;
        if !self.candidates.is_empty() {
            opts.candidates = self.candidates;
        }
        opts.validate()?;
        if let Some(inputs) = &self.inputs {
            return audit_several(inputs, calibration, &cal, &opts, &self.out);
        }
        let rec = self.input.source()?.open()?;
        for w in &rec.warnings {
            eprintln!("warning: {w}");
        }
        let t = std::time::Instant::now();
        let result = tumble::audit::audit_with_progress(&rec, &cal, &opts, &mut |m| eprintln!("{m}"))?;
        print!("{}", tumble::audit::summary_table(&result));
        for n in &result.notes {
            eprintln!("note: {n}");
        }
        let files = tumble::audit::write_report(&result, &self.out)?;
        println!("{}", result.verdict());
        println!("audited in {:.2} s; wrote {} in {}", t.elapsed().as_secs_f64(), files.join(", "), self.out.display());
        Ok(())
    }

    /// `tumble audit --vio`: fit the time offsets of a VIO input and write the audit.
    fn run_vio(&self, path: &std::path::Path, cal: Option<&ImuCalibration>, noise: Option<ImuNoise>) -> CliResult {
        use tumble::audit::vio::{audit_vio, VioAuditOptions};
        let mut vopts = tumble::vio::VioOptions::default();
        vopts.noise.pixel_sigma = self.pixel_sigma;
        vopts.noise.gravity = self.gravity;
        // The audit's options around the estimator's, once the noise is known.
        let audit_options = |vio| {
            let mut opts = VioAuditOptions::new(vio);
            opts.alpha = self.alpha;
            opts.max_effects = self.max_effects;
            opts.step_s = 1e-3 * self.offset_step_ms;
            if !self.candidates.is_empty() {
                opts.candidates = self.candidates.clone();
            }
            opts
        };
        audit_options(vopts.clone()).validate()?;
        let source = tumble::vio::VioSource {
            calibration: cal.cloned(),
            frontend: self.frontend.options(),
            frontend_dir: self.out.clone(),
            ..Default::default()
        };
        let vin = open_input(path, &source)?;
        vin.apply_noise(noise, &mut vopts.noise.imu);
        let opts = audit_options(vopts);
        if let Some(o) = cal.and_then(|c| c.time_offsets) {
            println!(
                "the calibration's time offsets are applied: camera–IMU {:+.3} ms, accel–gyro {:+.3} ms",
                1e3 * o.camera_imu_s,
                1e3 * o.accel_gyro_s
            );
        }
        let bar = progress_bar(0, "audit [{elapsed_precise}] {pos} VIO runs {msg}");
        let mut tick = |done: usize| bar.set_position(done as u64);
        let t = std::time::Instant::now();
        let result = audit_vio(&vin, &opts, Some(&mut tick))?;
        bar.finish_and_clear();
        for n in &result.notes {
            eprintln!("note: {n}");
        }
        let files = tumble::audit::vio::write(&result, cal, &self.out)?;
        println!("{}", result.verdict());
        println!("audited in {:.1} s; wrote {} in {}", t.elapsed().as_secs_f64(), files.join(", "), self.out.display());
        Ok(())
    }
}

/// `--inputs`: each recording audited with the calibration in its folder
/// beside the pooled `calibration`, then the effects compared across them.
fn audit_several(
    inputs: &std::path::Path,
    calibration: &std::path::Path,
    pooled: &ImuCalibration,
    opts: &AuditOptions,
    out: &std::path::Path,
) -> CliResult {
    let (recs, names) = super::common::read_tumbles(inputs)?;
    let dir = calibration.parent().unwrap_or(std::path::Path::new("."));
    let folders: Vec<String> = names.iter().enumerate().map(|(i, n)| tumble::calib::recording_folder(i, n)).collect();
    let cals = folders
        .iter()
        .map(|f| ImuCalibration::read(&dir.join(f).join("calibration.json")))
        .collect::<Result<Vec<_>, _>>()
        .map_err(|e| {
            format!(
                "{e} (give --calibration the calibration.json `tumble calibrate --inputs` wrote from the same file)"
            )
        })?;
    let t = std::time::Instant::now();
    let result = tumble::audit::audit_recordings(&recs, &cals, &names, pooled, opts, &mut |m| eprintln!("{m}"))?;
    for (name, a) in names.iter().zip(&result.each) {
        println!("{name}: {}", a.verdict());
    }
    for line in result.verdict_lines() {
        println!("{line}");
    }
    let files = result.write(&folders, out)?;
    println!(
        "audited {} recordings in {:.1} s; wrote {} files into {}",
        recs.len(),
        t.elapsed().as_secs_f64(),
        files.len(),
        out.display()
    );
    Ok(())
}
