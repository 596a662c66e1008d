//! `tumble run`: the whole chain on the user's recordings.

use super::common::{open_input, progress_bar, CalibInput, FrontendArgs, InputFormat, RecordingArgs};
use super::vio::EstimatorArgs;
use super::CliResult;
use clap::Args;
use std::path::PathBuf;
use tumble::calib::{local_gravity, CalibOptions};
use tumble::pipeline::{run_chain, ChainInputs, ChainOptions, Progress, Stage};

/// Flags of `tumble run`.
#[derive(Args)]
pub struct RunArgs {
    /// Hand-tumbled calibration recording (ASL folder, bag/MCAP, text; with
    /// --gyro-file for imu_tk's two files): the calibrate and audit stages.
    #[arg(long)]
    tumble: Option<PathBuf>,
    /// Static recording (hours, for the bias random walk): the allan stage.
    #[arg(long = "static")]
    still: Option<PathBuf>,
    /// A YAML file describing each recording with its own reading options
    /// (`tumble:` and `static:` entries with path, columns, units, topic…; see
    /// docs/formats.md): for recordings in different layouts.
    #[arg(long, conflicts_with_all = ["tumble", "still"])]
    inputs: Option<PathBuf>,
    /// VIO data (ASL folder with tracks or images, or an EqVIO .csv): the vio stage.
    #[arg(long)]
    vio: Option<PathBuf>,
    /// Output folder (gets calibrate/, allan/, audit/, vio/ and report.md).
    #[arg(long, required_unless_present = "print_config")]
    out: Option<PathBuf>,
    /// Stages not to run, comma separated (calibrate, allan, audit, vio): their
    /// results come from --calibration/--noise or from an earlier run's files in --out.
    #[arg(long, value_delimiter = ',', value_parser = |s: &str| s.parse::<Stage>())]
    skip: Vec<Stage>,
    /// Calibration to use instead of the calibrate stage.
    #[arg(long)]
    calibration: Option<PathBuf>,
    /// Kalibr imu.yaml to use instead of the allan stage.
    #[arg(long)]
    noise: Option<PathBuf>,
    /// Output folder of `tumble calibrate-rig`: its cameras and time offset
    /// replace the VIO recording's camN/sensor.yaml.
    #[arg(long)]
    rig: Option<PathBuf>,
    /// Local gravity [m/s²] (default: WGS-84 at --latitude, else 9.80665).
    #[arg(long, conflicts_with = "latitude")]
    gravity: Option<f64>,
    /// Geodetic latitude [deg] for WGS-84 normal gravity (at sea level).
    #[arg(long)]
    latitude: Option<f64>,
    /// Length of the tumble's initial static period [s] (default: found in the data).
    #[arg(long)]
    init_static: Option<f64>,
    /// Ground truth (ASL CSV) for the vio stage; an ASL folder's own is used when present.
    #[arg(long)]
    groundtruth: Option<PathBuf>,
    /// vio stage without camera data: a simulated camera flies the ground truth.
    #[arg(long)]
    simulate_camera: bool,
    /// Also record the vio stage for the rerun viewer into this .rrd file: images with
    /// features, poses, window, landmarks, ground truth, biases (cargo feature
    /// `rerun`; view with `pip install rerun-sdk==0.36.3 && rerun FILE.rrd`).
    #[arg(long, value_name = "FILE.rrd")]
    rerun: Option<PathBuf>,
    /// How to read text recordings (both --tumble and --static).
    #[command(flatten)]
    read: RecordingArgs,
    /// The vio stage's estimator.
    #[command(flatten)]
    estimator: EstimatorArgs,
    /// The visual frontend, used when the vio folder has images but no tracks.
    #[command(flatten)]
    frontend: FrontendArgs,
}

impl RunArgs {
    pub fn run(self) -> CliResult {
        let mut opts = ChainOptions { skip: self.skip.clone(), rerun: self.rerun.clone(), ..Default::default() };
        opts.vio = self.estimator.options(None)?;
        if self.estimator.print_config {
            print!("{}", opts.vio.to_yaml()?);
            return Ok(());
        }
        let out = self.out.clone().ok_or("give --out (or --print-config)")?;
        let described = self.inputs.as_deref().map(tumble::io::recordings::RunRecordings::read).transpose()?;
        if self.tumble.is_none()
            && self.still.is_none()
            && described.is_none()
            && self.vio.is_none()
            && self.calibration.is_none()
        {
            return Err("nothing to do: give --tumble, --static and/or --vio (see `tumble run --help`)".into());
        }
        let mut calib = CalibOptions { init_static_s: self.init_static, ..Default::default() };
        let described_tumble = described.as_ref().map(|d| d.single_tumble()).transpose()?.flatten();
        let has_tumble = self.tumble.is_some() || described_tumble.is_some();
        if has_tumble && !opts.skip.contains(&Stage::Calibrate) {
            let gravity = local_gravity(self.gravity, self.latitude, 0.0)?;
            if let Some(note) = gravity.note {
                eprintln!("note: {note}");
            }
            calib.gravity = gravity.value;
        }
        opts.set_calibration(calib);
        opts.validate()?;
        let mut inputs = ChainInputs::default();
        if let Some(p) = &self.tumble {
            let input = CalibInput {
                recording: Some(p.clone()),
                accel: None,
                gyro: None,
                format: if self.read.gyro_file.is_some() { InputFormat::ImuTk } else { InputFormat::Auto },
                read: self.read.clone(),
            };
            let rec = input.source()?.open()?;
            for w in &rec.warnings {
                eprintln!("warning: {}: {w}", p.display());
            }
            inputs.tumble = Some(rec);
        }
        if let Some(p) = &self.still {
            let mut o = self.read.options();
            o.gyro_file = None;
            let rec = tumble::io::open_recording(p, &o)?;
            for w in &rec.warnings {
                eprintln!("warning: {}: {w}", p.display());
            }
            inputs.still = Some(rec);
        }
        if let Some(d) = &described {
            for (spec, slot, what) in
                [(&described_tumble, &mut inputs.tumble, "tumble"), (&d.still.as_ref(), &mut inputs.still, "static")]
            {
                if let Some(spec) = spec {
                    println!("{what}: {}", spec.describe());
                    let rec = spec.source()?.open()?;
                    for w in &rec.warnings {
                        eprintln!("warning: {}: {w}", spec.path.display());
                    }
                    *slot = Some(rec);
                }
            }
        }
        inputs.calibration = self.calibration.as_deref().map(tumble::calib::ImuCalibration::read).transpose()?;
        inputs.noise = self.noise.as_deref().map(tumble::io::ImuNoise::read).transpose()?;
        if let Some(p) = self.vio.clone() {
            let mut source = tumble::vio::VioSource {
                groundtruth: self.groundtruth.clone(),
                simulate_camera: self.simulate_camera.then_some(1),
                frontend: self.frontend.options(),
                frontend_dir: out.join(Stage::Vio.id()),
                rig: self.rig.as_deref().map(tumble::io::target::RigCalibration::read).transpose()?,
                ..Default::default()
            };
            inputs.vio = Some(Box::new(move |cal| {
                source.calibration = cal.cloned();
                Ok(open_input(&p, &source)?)
            }));
        }
        let bar = progress_bar(0, "{prefix} [{bar:40}] {pos}/{len} {msg} {elapsed_precise} (eta {eta})");
        bar.set_draw_target(indicatif::ProgressDrawTarget::hidden());
        let show = |prefix: &'static str, unit: &'static str, done: usize, total: usize| {
            if bar.is_hidden() || bar.prefix() != prefix {
                bar.set_draw_target(indicatif::ProgressDrawTarget::stderr());
                bar.set_prefix(prefix);
                bar.set_message(unit);
                bar.reset();
            }
            bar.set_length(total as u64);
            bar.set_position(done as u64);
        };
        let report = run_chain(inputs, &opts, &out, &mut |p| match p {
            Progress::Stage(stage, line) => {
                bar.set_draw_target(indicatif::ProgressDrawTarget::hidden());
                eprintln!("{}: {line}", stage.id())
            }
            Progress::Frames(done, total) => show("vio", "frames", done, total),
            Progress::Taus(done, total) => show("allan", "τ", done, total),
        })?;
        bar.finish_and_clear();
        for w in &report.warnings {
            eprintln!("warning: {w}");
        }
        print!("\n{}", report.summary());
        Ok(())
    }
}
