//! `tumble run`: the stages chained — calibrate a hand tumble, identify the
//! noise from a static log (Allan), audit the calibration for a missing effect,
//! and estimate biases online with a camera (VIO) — each stage writing into its
//! own folder of the output directory and the next one reading what it found.
//! Ends with `report.md`, every stage's tables and figures in one page.
//!
//! Stages can be skipped. A skipped stage's result comes from what the caller
//! gives ([`ChainInputs::calibration`], [`ChainInputs::noise`]) or else from the
//! files an earlier run left in the output folder (`calibrate/calibration.json`,
//! `allan/imu.yaml`, `audit/calibration.json`) — but never from a folder whose
//! upstream stage has just been re-run, which would mix two runs.
//!
//! ```no_run
//! use tumble::pipeline::{run_chain, ChainInputs, ChainOptions};
//! use tumble::io::{open_recording, RecordingOptions};
//! let o = RecordingOptions::default();
//! let inputs = ChainInputs {
//!     tumble: Some(open_recording("tumble_session/".as_ref(), &o)?),
//!     still: Some(open_recording("static_2h.csv".as_ref(), &o)?),
//!     ..Default::default()
//! };
//! let report = run_chain(inputs, &ChainOptions::default(), "out".as_ref(), &mut |_| {})?;
//! print!("{}", report.summary());
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

use crate::allan::{run_allan_with_progress, AllanError, AllanReport, AllanRunOptions};
use crate::audit::{audit, Audit, AuditOptions};
use crate::calib::{calibrate, CalibOptions, CalibrationResult};
use crate::io::{ImuNoise, ImuRecording};
use crate::model::calibration::ImuCalibration;
use crate::vio::{summarize, write_outputs, NoiseSource, Summary, VioInput, VioOptions, VioResult};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// One stage of the chain, in chain order.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum Stage {
    /// Turntable-free calibration of the tumble recording (`calibrate/`).
    Calibrate,
    /// Noise identification from the static recording (`allan/`).
    Allan,
    /// Model-discrepancy audit of the calibration (`audit/`).
    Audit,
    /// Visual-inertial bias estimation (`vio/`).
    Vio,
}

impl Stage {
    /// Every stage in chain order.
    pub const ALL: [Stage; 4] = [Stage::Calibrate, Stage::Allan, Stage::Audit, Stage::Vio];

    /// Its name on the command line and its folder in the output directory.
    pub fn id(self) -> &'static str {
        match self {
            Stage::Calibrate => "calibrate",
            Stage::Allan => "allan",
            Stage::Audit => "audit",
            Stage::Vio => "vio",
        }
    }
}

impl std::str::FromStr for Stage {
    type Err = crate::OptionError;
    /// The stage named `s` (as [`Stage::id`]).
    fn from_str(s: &str) -> Result<Stage, crate::OptionError> {
        Stage::ALL.into_iter().find(|st| st.id() == s.trim()).ok_or_else(|| {
            crate::OptionError::new(
                "--skip",
                format!("names an unknown stage `{s}` (stages: {})", Stage::ALL.map(|s| s.id()).join(", ")),
            )
        })
    }
}

/// Makes the VIO's input once the chain knows the calibration to correct the
/// IMU with (None: no calibration available, samples used as read).
pub type VioInputMaker = Box<dyn FnOnce(Option<&ImuCalibration>) -> Result<VioInput, Box<dyn std::error::Error>>>;

/// What the chain works on; every part optional.
#[derive(Default)]
pub struct ChainInputs {
    /// The hand-tumbled calibration recording (for `calibrate` and `audit`).
    pub tumble: Option<ImuRecording>,
    /// The static recording (for `allan`), hours long for the bias random walk.
    pub still: Option<ImuRecording>,
    /// The VIO data (for `vio`).
    pub vio: Option<VioInputMaker>,
    /// A calibration to use when `calibrate` does not run (e.g. `--calibration FILE`).
    pub calibration: Option<ImuCalibration>,
    /// Noise to use when `allan` does not run (e.g. `--noise imu.yaml`).
    pub noise: Option<ImuNoise>,
}

/// Settings of every stage.
#[derive(Clone, Debug)]
pub struct ChainOptions {
    /// Stages not to run (their results are taken from the inputs or earlier files).
    pub skip: Vec<Stage>,
    /// Calibration settings.
    pub calib: CalibOptions,
    /// Allan settings.
    pub allan: AllanRunOptions,
    /// Audit settings (its `noise` is replaced by the chain's when the chain has one).
    pub audit: AuditOptions,
    /// VIO settings (its IMU noise is replaced by the chain's when the chain has one).
    pub vio: VioOptions,
    /// VIO bias errors are averaged from this many seconds after initialization.
    pub bias_after_s: f64,
    /// Record the VIO stage into this rerun file (cargo feature `rerun`; an
    /// error before any stage runs without it).
    pub rerun: Option<PathBuf>,
}

impl ChainOptions {
    /// Use `calib` for the calibrate stage and its static-interval detection
    /// for the audit stage (the audit re-detects the intervals the calibration used).
    pub fn set_calibration(&mut self, calib: CalibOptions) {
        self.audit.detection = calib.clone();
        self.calib = calib;
    }

    /// Check every stage's options once, before any work ([`run_chain`] calls it).
    pub fn validate(&self) -> Result<(), crate::OptionError> {
        self.calib.validate()?;
        self.allan.validate().map_err(|e| crate::OptionError::new("allan stage:", e.to_string()))?;
        self.audit.validate()?;
        self.vio.validate()?;
        if !self.bias_after_s.is_finite() {
            return Err(crate::OptionError::new("--bias-after", "must be a finite number of seconds"));
        }
        Ok(())
    }
}

impl Default for ChainOptions {
    fn default() -> Self {
        ChainOptions {
            skip: Vec::new(),
            calib: CalibOptions::default(),
            allan: AllanRunOptions::default(),
            audit: AuditOptions::default(),
            vio: VioOptions::default(),
            bias_after_s: 10.0,
            rerun: None,
        }
    }
}

/// What the chain reports while it works.
#[derive(Clone, Copy, Debug)]
pub enum Progress<'a> {
    /// A stage starts, with a line saying what it does.
    Stage(Stage, &'a str),
    /// VIO frames done out of total.
    Frames(usize, usize),
    /// Allan stage: τ values done out of total (six axes).
    Taus(usize, usize),
}

/// How a stage ended.
#[derive(Clone, Debug, PartialEq)]
pub enum Status {
    /// It ran, taking this many seconds.
    Ran(f64),
    /// It did not run; its result was taken from here (a file, or "given").
    Reused(String),
    /// It did not run and nothing stands in for it, because of this.
    Skipped(String),
}

/// One stage's line of the report.
#[derive(Clone, Debug)]
pub struct StageReport {
    /// Which stage.
    pub stage: Stage,
    /// Ran, reused or skipped.
    pub status: Status,
    /// Its main figures in one line (empty when skipped).
    pub headline: String,
    /// Its section of `report.md` (markdown, links relative to the output folder).
    pub markdown: String,
}

/// Everything the chain did and found.
pub struct ChainReport {
    /// One entry per stage, in chain order.
    pub stages: Vec<StageReport>,
    /// The calibration stage's result, when it ran.
    pub calibration: Option<CalibrationResult>,
    /// The Allan stage's result, when it ran.
    pub allan: Option<AllanReport>,
    /// The audit's result, when it ran.
    pub audit: Option<Audit>,
    /// The VIO's input, result and figures, when it ran.
    pub vio: Option<(VioInput, VioResult, Summary)>,
    /// The calibration the VIO used (the audited one when there is one).
    pub final_calibration: Option<ImuCalibration>,
    /// The noise the audit and the VIO used.
    pub noise: Option<ImuNoise>,
    /// Problems met on the way that did not stop the chain.
    pub warnings: Vec<String>,
    /// `report.md`.
    pub report_path: PathBuf,
}

/// Markdown image links for the files of `files` that are PNGs, relative to `root`.
fn figures(root: &Path, files: &[PathBuf]) -> String {
    let mut s = String::new();
    for f in files.iter().filter(|f| f.extension().is_some_and(|e| e == "png")) {
        let rel = f.strip_prefix(root).unwrap_or(f).display().to_string();
        let _ = writeln!(s, "![{rel}]({rel})\n");
    }
    s
}

fn code(text: &str) -> String {
    format!("```text\n{}\n```\n\n", text.trim_end())
}

/// An earlier run's file, if there is one.
fn earlier(path: PathBuf) -> Option<PathBuf> {
    path.is_file().then_some(path)
}

/// Why the chain stopped (the message names the stage and the cause).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{0}")]
pub struct ChainError(pub String);

crate::error::message_error_conversions!(ChainError, ChainError);

impl From<crate::vio::VioError> for ChainError {
    fn from(e: crate::vio::VioError) -> ChainError {
        ChainError(e.to_string())
    }
}

impl From<crate::sim::SimError> for ChainError {
    fn from(e: crate::sim::SimError) -> ChainError {
        ChainError(e.to_string())
    }
}

/// Run the chain into `out` (created) and write `out/report.md`.
///
/// Errors of a stage that runs stop the chain (a stage's output is the next
/// one's input); a stage without input is skipped with the reason in the report.
pub fn run_chain(
    inputs: ChainInputs,
    opts: &ChainOptions,
    out: &Path,
    progress: &mut dyn FnMut(Progress),
) -> Result<ChainReport, ChainError> {
    opts.validate().map_err(|e| e.to_string())?;
    if let Some(r) = &opts.rerun {
        crate::vio::rerun_available(r)?;
    }
    std::fs::create_dir_all(out).map_err(|e| format!("{}: cannot create: {e}", out.display()))?;
    let ChainInputs { tumble, still, vio, calibration: given_cal, noise: given_noise } = inputs;
    let mut run = Run { out, opts, stages: Vec::new(), warnings: Vec::new() };
    let (calibration, cal) = run.calibrate(tumble.as_ref(), given_cal, progress)?;
    let (allan, noise) = run.allan(still.as_ref(), given_noise, progress)?;
    let (audited, final_cal) = run.audit(tumble.as_ref(), calibration.is_some(), cal, noise, progress)?;
    let vio_out = run.vio(vio, final_cal.as_ref(), noise, progress)?;
    let report_path = out.join("report.md");
    let report = ChainReport {
        stages: run.stages,
        calibration,
        allan,
        audit: audited,
        vio: vio_out,
        final_calibration: final_cal.map(|(c, _)| c),
        noise,
        warnings: run.warnings,
        report_path: report_path.clone(),
    };
    std::fs::write(&report_path, report.markdown()).map_err(|e| format!("{}: {e}", report_path.display()))?;
    Ok(report)
}

/// A calibration in use and where it came from (`calibrate`, `given`, a file).
type SourcedCalibration = (ImuCalibration, String);

/// The chain's run: its folder, options, and the stages' reports and warnings so far.
struct Run<'a> {
    out: &'a Path,
    opts: &'a ChainOptions,
    stages: Vec<StageReport>,
    warnings: Vec<String>,
}

impl Run<'_> {
    fn wanted(&self, s: Stage) -> bool {
        !self.opts.skip.contains(&s)
    }

    fn ran(&mut self, stage: Stage, t: Instant, headline: String, markdown: String) {
        let secs = t.elapsed().as_secs_f64();
        self.stages.push(StageReport { stage, status: Status::Ran(secs), headline, markdown });
    }

    /// Stage 1: calibrate the hand tumble, or take the calibration given, or an earlier run's.
    fn calibrate(
        &mut self,
        tumble: Option<&ImuRecording>,
        given: Option<ImuCalibration>,
        progress: &mut dyn FnMut(Progress),
    ) -> Result<(Option<CalibrationResult>, Option<SourcedCalibration>), ChainError> {
        let (out, opts) = (self.out, self.opts);
        let dir = out.join(Stage::Calibrate.id());
        if let (true, Some(rec)) = (self.wanted(Stage::Calibrate), tumble) {
            progress(Progress::Stage(Stage::Calibrate, "calibrating the hand tumble (paper eq. 1)"));
            let t = Instant::now();
            let r = match calibrate(rec, &opts.calib) {
                Ok(r) => r,
                Err(e) => {
                    // A failed calibration stops the chain; its diagnosis is kept for the user.
                    let kept = e.diagnosis.as_ref().and_then(|d| d.write_diagnosis(rec, &opts.calib, &dir).ok());
                    let note = kept.map_or(String::new(), |f| format!(" (diagnosis: {})", f[0].display()));
                    return Err(format!("calibrate: {}{note}", e.message).into());
                }
            };
            let files = r.write_all(rec, &opts.calib, &dir).map_err(|e| format!("calibrate: {e}"))?;
            self.warnings.extend(r.warnings.iter().map(|w| format!("calibrate: {w}")));
            let headline = format!(
                "{} static intervals; residual RMS accel {:.2e} m/s², gyro {:.2e} rad",
                r.static_intervals.len(),
                r.accel_fit.rms,
                r.gyro_fit.rms
            );
            self.ran(Stage::Calibrate, t, headline, format!("{}{}", code(&r.summary_table()), figures(out, &files)));
            let cal = (r.calibration.clone(), "calibrate".into());
            return Ok((Some(r), Some(cal)));
        }
        if let Some(c) = given {
            self.stages.push(reused(Stage::Calibrate, "given".into(), out));
            return Ok((None, Some((c, "given".into()))));
        }
        if let Some(p) = earlier(dir.join("calibration.json")) {
            let c = ImuCalibration::read(&p).map_err(|e| e.to_string())?;
            self.stages.push(reused(Stage::Calibrate, p.display().to_string(), out));
            return Ok((None, Some((c, p.display().to_string()))));
        }
        let why = if self.wanted(Stage::Calibrate) { "no tumble recording" } else { "skipped" };
        self.stages
            .push(skipped(Stage::Calibrate, format!("{why}; no calibration given or found in {}", dir.display())));
        Ok((None, None))
    }

    /// Stage 2: identify the noise of the static recording, or take the noise given, or an earlier run's.
    fn allan(
        &mut self,
        still: Option<&ImuRecording>,
        given: Option<ImuNoise>,
        progress: &mut dyn FnMut(Progress),
    ) -> Result<(Option<AllanReport>, Option<ImuNoise>), ChainError> {
        let (out, opts) = (self.out, self.opts);
        let dir = out.join(Stage::Allan.id());
        if let (true, Some(rec)) = (self.wanted(Stage::Allan), still) {
            progress(Progress::Stage(Stage::Allan, "identifying the noise by Allan variance"));
            let t = Instant::now();
            let r = allan_with_progress(rec, &opts.allan, progress).map_err(|e| format!("allan: {e}"))?;
            let files = r.write_all(&dir).map_err(|e| format!("allan: {e}"))?;
            self.warnings.extend(r.warnings.iter().map(|w| format!("allan: {w}")));
            let headline = match &r.kalibr {
                Some(k) => format!(
                    "gyro N {:.2e} rad/s/√Hz, K {:.2e}; accel N {:.2e} m/s²/√Hz, K {:.2e}",
                    k.gyroscope_noise_density,
                    k.gyroscope_random_walk,
                    k.accelerometer_noise_density,
                    k.accelerometer_random_walk
                ),
                None => "curves only (raw counts: no imu.yaml)".into(),
            };
            let noise = r.kalibr.as_ref().map(|k| k.imu_noise());
            self.ran(Stage::Allan, t, headline, format!("{}{}", code(&r.summary_table()), figures(out, &files)));
            return Ok((Some(r), noise));
        }
        if let Some(n) = given {
            self.stages.push(reused(Stage::Allan, "given".into(), out));
            return Ok((None, Some(n)));
        }
        if let Some(p) = earlier(dir.join("imu.yaml")) {
            let noise = ImuNoise::read(&p).map_err(|e| e.to_string())?;
            self.stages.push(reused(Stage::Allan, p.display().to_string(), out));
            return Ok((None, Some(noise)));
        }
        let why = if self.wanted(Stage::Allan) { "no static recording" } else { "skipped" };
        self.stages.push(skipped(Stage::Allan, format!("{why}; no noise given or found in {}", dir.display())));
        Ok((None, None))
    }

    /// Stage 3: audit the calibration in use on the tumble, or take an earlier
    /// run's audited calibration (when the calibration is still the one it
    /// audited: `calibrated` says this run made a new one).
    fn audit(
        &mut self,
        tumble: Option<&ImuRecording>,
        calibrated: bool,
        cal: Option<SourcedCalibration>,
        noise: Option<ImuNoise>,
        progress: &mut dyn FnMut(Progress),
    ) -> Result<(Option<Audit>, Option<SourcedCalibration>), ChainError> {
        let (out, opts) = (self.out, self.opts);
        let dir = out.join(Stage::Audit.id());
        if let (true, Some(rec), Some((c, _))) = (self.wanted(Stage::Audit), tumble, &cal) {
            progress(Progress::Stage(Stage::Audit, "auditing the calibration for a missing effect"));
            let t = Instant::now();
            let mut aopts = opts.audit.clone();
            if noise.is_some() {
                aopts.noise = noise;
            }
            let a = audit(rec, c, &aopts).map_err(|e| format!("audit: {e}"))?;
            let files = crate::audit::report::write(&a, &dir).map_err(|e| format!("audit: {e}"))?;
            let files: Vec<PathBuf> = files.iter().map(|f| dir.join(f)).collect();
            self.warnings.extend(a.notes.iter().map(|n| format!("audit: {n}")));
            let md = format!(
                "**{}**\n\n{}{}",
                a.verdict(),
                code(&crate::audit::report::summary_table(&a)),
                figures(out, &files)
            );
            self.ran(Stage::Audit, t, a.verdict(), md);
            let audited = (a.calibration.clone(), "audit".into());
            return Ok((Some(a), Some(audited)));
        }
        // An earlier audit is stale when the calibration it audited is no longer the one in use.
        let stale = calibrated || cal.as_ref().is_some_and(|(_, from)| from == "given");
        if let Some(p) = earlier(dir.join("calibration.json")).filter(|_| !stale) {
            let c = ImuCalibration::read(&p).map_err(|e| e.to_string())?;
            self.stages.push(reused(Stage::Audit, p.display().to_string(), out));
            return Ok((None, Some((c, p.display().to_string()))));
        }
        let why = match (self.wanted(Stage::Audit), tumble, &cal) {
            (false, ..) => "skipped",
            (_, None, _) => "no tumble recording",
            _ => "no calibration to audit",
        };
        self.stages.push(skipped(Stage::Audit, why.into()));
        Ok((None, cal))
    }

    /// Stage 4: run the VIO with the final calibration and the noise.
    fn vio(
        &mut self,
        source: Option<VioInputMaker>,
        final_cal: Option<&SourcedCalibration>,
        noise: Option<ImuNoise>,
        progress: &mut dyn FnMut(Progress),
    ) -> Result<Option<(VioInput, VioResult, Summary)>, ChainError> {
        let (out, opts) = (self.out, self.opts);
        let (true, Some(source)) = (self.wanted(Stage::Vio), source) else {
            let why = if self.wanted(Stage::Vio) { "no VIO data given" } else { "skipped" };
            self.stages.push(skipped(Stage::Vio, why.into()));
            return Ok(None);
        };
        let input = source(final_cal.map(|(c, _)| c)).map_err(|e| format!("vio: {e}"))?;
        let mut vopts = opts.vio.clone();
        let noise_from = match input.apply_noise(noise, &mut vopts.noise.imu) {
            NoiseSource::Given => "the Allan stage",
            NoiseSource::Input => "the dataset's sensor.yaml",
            NoiseSource::Default => "the built-in defaults",
        };
        let cal_from = final_cal.map_or("none (samples used as read)".to_string(), |(_, f)| f.clone());
        let line = format!("fusing IMU and camera ({} frames); calibration: {cal_from}", input.frames.len());
        progress(Progress::Stage(Stage::Vio, &line));
        let t = Instant::now();
        let mut tick = |done: usize, total: usize| progress(Progress::Frames(done, total));
        let (result, recorded) = crate::vio::run_recorded(&input, &vopts, Some(&mut tick), opts.rerun.as_deref())
            .map_err(|e| format!("vio: {e}"))?;
        let summary = summarize(&input, &vopts, &result, opts.bias_after_s);
        let files =
            write_outputs(&out.join(Stage::Vio.id()), &input, &result, &summary).map_err(|e| format!("vio: {e}"))?;
        let recorded = recorded.map_or(String::new(), |p| {
            format!("\n\nRecorded for the rerun viewer: `{}` (`rerun {}`).", p.display(), p.display())
        });
        self.warnings.extend(summary.warnings.iter().map(|w| format!("vio: {w}")));
        let mut headline = format!(
            "{:.1} m in {:.0} s, {} {:.3} m (IMU only {:.1} m)",
            summary.walked_m(),
            summary.duration_s,
            if summary.ends_elsewhere() { "end to start" } else { "closed loop" },
            summary.closed_loop_error_m,
            summary.imu_only_closed_loop_error_m
        );
        if let Some(ate) = summary.ate_rmse_m {
            let _ = write!(headline, ", ATE {ate:.3} m");
        }
        let md = format!(
            "Input `{}`; calibration: {cal_from}; noise from {noise_from}.\n\n{}{}{recorded}",
            input.name,
            code(&summary.table()),
            figures(out, &files)
        );
        self.ran(Stage::Vio, t, headline, md);
        Ok(Some((input, result, summary)))
    }
}

/// A stage that did not run; `from` names where its result came from. When
/// that is an earlier run's folder, its figures are linked again.
fn reused(stage: Stage, from: String, out: &Path) -> StageReport {
    let dir = out.join(stage.id());
    let mut md = format!("Not run: taken from {from}.\n\n");
    if Path::new(&from).starts_with(&dir) {
        let mut pngs: Vec<PathBuf> =
            std::fs::read_dir(&dir).map(|d| d.filter_map(|e| e.ok().map(|e| e.path())).collect()).unwrap_or_default();
        pngs.sort();
        md.push_str(&figures(out, &pngs));
    }
    StageReport { stage, status: Status::Reused(from), headline: String::new(), markdown: md }
}

fn skipped(stage: Stage, why: String) -> StageReport {
    let md = format!("Not run: {why}.\n\n");
    StageReport { stage, status: Status::Skipped(why), headline: String::new(), markdown: md }
}

impl ChainReport {
    /// A few lines for the terminal: per stage what happened and its main figures.
    pub fn summary(&self) -> String {
        let mut s = String::new();
        for st in &self.stages {
            let what = match &st.status {
                Status::Ran(secs) => format!("{:>6.1} s  {}", secs, st.headline),
                Status::Reused(from) => format!("  reused  {from}"),
                Status::Skipped(why) => format!(" skipped  {why}"),
            };
            let _ = writeln!(s, "{:<10}{what}", st.stage.id());
        }
        let _ = writeln!(s, "report: {}", self.report_path.display());
        s
    }

    /// `report.md`: a table of the stages, then each stage's tables and figures.
    pub fn markdown(&self) -> String {
        let mut s = String::from("# tumble run\n\n| stage | status | result |\n|---|---|---|\n");
        for st in &self.stages {
            let status = match &st.status {
                Status::Ran(secs) => format!("ran in {secs:.1} s"),
                Status::Reused(from) => format!("reused `{from}`"),
                Status::Skipped(why) => format!("skipped: {why}"),
            };
            let _ = writeln!(s, "| [{0}](#{0}) | {status} | {1} |", st.stage.id(), st.headline);
        }
        let titles = [
            "Calibration (hand tumble, eq. 1)",
            "Noise (Allan deviation of the static log)",
            "Model-discrepancy audit",
            "Online bias estimation (VIO)",
        ];
        for st in &self.stages {
            let title = titles[Stage::ALL.iter().position(|x| *x == st.stage).unwrap_or(0)];
            let _ = write!(s, "\n<a id=\"{}\"></a>\n## {title}\n\n{}", st.stage.id(), st.markdown);
        }
        if !self.warnings.is_empty() {
            let _ = writeln!(s, "\n## Warnings\n");
            for w in &self.warnings {
                let _ = writeln!(s, "- {w}");
            }
        }
        s
    }
}

/// The Allan stage on a worker thread, its progress ([`Progress::Taus`])
/// reported from this one every 100 ms (`progress` need not be `Sync`).
fn allan_with_progress(
    rec: &ImuRecording,
    opts: &AllanRunOptions,
    progress: &mut dyn FnMut(Progress),
) -> Result<AllanReport, AllanError> {
    use std::sync::atomic::{AtomicUsize, Ordering};
    let (done, total) = (AtomicUsize::new(0), AtomicUsize::new(0));
    std::thread::scope(|scope| {
        let worker = scope.spawn(|| {
            run_allan_with_progress(rec, opts, &|d, n| {
                total.store(n, Ordering::Relaxed);
                done.fetch_max(d, Ordering::Relaxed);
            })
        });
        while !worker.is_finished() {
            std::thread::sleep(std::time::Duration::from_millis(100));
            let n = total.load(Ordering::Relaxed);
            if n > 0 {
                progress(Progress::Taus(done.load(Ordering::Relaxed), n));
            }
        }
        worker.join().unwrap_or_else(|panic| std::panic::resume_unwind(panic))
    })
}
