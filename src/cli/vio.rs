//! `tumble vio`: visual-inertial bias estimation over a recording.

use super::common::{open_input, paths, progress_bar, FrontendArgs};
use super::CliResult;
use clap::{Args, ValueEnum};
use std::path::PathBuf;
use tumble::vio::{Estimate, ImuNoise, Init, NoiseSource, VioOptions};

/// `tumble vio --init`: how the first state is found.
#[derive(Clone, Copy, ValueEnum)]
pub enum InitArg {
    /// At rest when the recording starts at rest, else from the motion.
    Auto,
    /// The recording must start at rest.
    Static,
    /// Closed-form visual–inertial solution over a moving start.
    Motion,
}

impl From<InitArg> for Init {
    fn from(a: InitArg) -> Init {
        match a {
            InitArg::Auto => Init::Auto,
            InitArg::Static => Init::Static,
            InitArg::Motion => Init::Motion,
        }
    }
}

/// `tumble vio --estimate-extrinsics` / `--estimate-time-offset`: how.
#[derive(Clone, Copy, ValueEnum)]
pub enum EstimateArg {
    /// Held at the given value.
    Off,
    /// Estimated in the window (held for its first window's length).
    On,
    /// Estimated once the motion determines it (σ below half its prior's);
    /// held at the given value until then, and said so if never.
    Auto,
}

impl From<EstimateArg> for Estimate {
    fn from(a: EstimateArg) -> Estimate {
        match a {
            EstimateArg::Off => Estimate::Off,
            EstimateArg::On => Estimate::On,
            EstimateArg::Auto => Estimate::Auto,
        }
    }
}

/// The estimator's flags shared by `vio` and `run`: each overrides the
/// `--config` file's value (or the default) only when given.
#[derive(Args, Clone)]
pub struct EstimatorArgs {
    /// Estimator options as YAML (`--print-config` prints every key with its
    /// default); the flags below override it.
    #[arg(long, value_name = "FILE.yaml")]
    pub config: Option<PathBuf>,
    /// Print the estimator options (the defaults, --config and the flags) as YAML and exit.
    #[arg(long)]
    pub print_config: bool,
    /// How the first state is found without ground truth: `static` needs the
    /// recording to start at rest; `motion` solves velocity, roll, pitch and
    /// scale in closed form from the IMU and the tracks of a moving start
    /// (with cam1's matches too, when the folder has them: see --mono);
    /// `auto` (default) uses the first when the start is at rest, else the second.
    #[arg(long, value_enum)]
    pub init: Option<InitArg>,
    /// Keyframes in the window [default: 10].
    #[arg(long)]
    pub window: Option<usize>,
    /// Median feature parallax to the last keyframe (rotation taken out) that
    /// makes a frame a keyframe [px]; larger values stretch the window over
    /// more time [default: 15].
    #[arg(long)]
    pub keyframe_parallax: Option<f64>,
    /// Longest time between keyframes [s] [default: 1].
    #[arg(long)]
    pub keyframe_interval: Option<f64>,
    /// Shortest time between keyframes made by parallax [s]: fast motion
    /// otherwise makes nearly every frame a keyframe (a frame that lost half
    /// of the last keyframe's features is one regardless) [default: 0.15].
    #[arg(long)]
    pub keyframe_min_interval: Option<f64>,
    /// Feature observation noise [px] [default: 1].
    #[arg(long)]
    pub pixel_sigma: Option<f64>,
    /// A new observation of a landmark farther than this from where the
    /// IMU-predicted pose projects it stays out of the solve [px] [default: 30].
    #[arg(long)]
    pub prediction_gate: Option<f64>,
    /// A track is triangulated only when its observations agree with the
    /// triangulated point within this; the worst one leaves the track
    /// otherwise [px] [default: 12].
    #[arg(long)]
    pub triangulation_gate: Option<f64>,
    /// Solve the whole window at every frame (VINS-Mono's way; several
    /// times slower) instead of at keyframes only, with the frames in
    /// between tracked against the fixed window.
    #[arg(long)]
    pub solve_every_frame: bool,
    /// Integrate with GTSAM's zero-order hold instead of the midpoint rule
    /// (the default: the hold lags the IMU by half a sample).
    #[arg(long)]
    pub zoh: bool,
    /// Raise the IMU noise to what the static start measured (vibration).
    #[arg(long)]
    pub noise_from_static: bool,
    /// Keep the given IMU noise throughout instead of measuring it in motion
    /// from the window's IMU residuals (and raising it where they show more).
    #[arg(long)]
    pub fixed_noise: bool,
    /// Use cam1's matches for the initialization only, not in the sliding
    /// window (by default they enter it: the baseline fixes far landmarks'
    /// depths; about 1.5× faster without, and less accurate — docs/vio.md).
    #[arg(long)]
    pub stereo_init_only: bool,
    /// VINS-Mono's landmarks: the bearing fixed at the anchor pixel and the
    /// inverse depth alone estimated, instead of both (OpenVINS' and Basalt's
    /// three parameters, the default). About 1.4× faster, but the anchor
    /// pixel's noise is counted nowhere: the σ come out too small and the
    /// path short (window.landmark_bearings: false).
    #[arg(long)]
    pub inverse_depth_only: bool,
    /// Estimate cam0's pose in the IMU frame (T_BC) in the window, starting
    /// from the given one under a prior of camera.rotation_sigma_deg (5°) and
    /// camera.translation_sigma_m (5 cm); needs rotation about several axes.
    /// Held until a window's length of keyframes has left the window; with
    /// `auto`, until the motion determines it (see docs/vio.md). The flag
    /// alone means `on`.
    #[arg(long, value_enum, num_args = 0..=1, default_missing_value = "on", value_name = "on|auto|off")]
    pub estimate_extrinsics: Option<EstimateArg>,
    /// Estimate the camera–IMU time offset (t_imu = t_cam + td) in the
    /// window, from 0 under a prior of camera.time_offset_sigma_s (20 ms);
    /// `auto` as for `--estimate-extrinsics`. The flag alone means `on`.
    #[arg(long, value_enum, num_args = 0..=1, default_missing_value = "on", value_name = "on|auto|off")]
    pub estimate_time_offset: Option<EstimateArg>,
}

impl EstimatorArgs {
    /// The options: `--config` (or the defaults), then the flags given, with
    /// `gravity` when the command has its own flag for it.
    pub fn options(&self, gravity: Option<f64>) -> Result<VioOptions, Box<dyn std::error::Error>> {
        let mut o = match &self.config {
            Some(p) => VioOptions::read(p)?,
            None => VioOptions::default(),
        };
        if let Some(i) = self.init {
            o.init.mode = i.into();
        }
        set(&mut o.window.size, self.window);
        set(&mut o.window.keyframe_parallax_px, self.keyframe_parallax);
        set(&mut o.window.keyframe_max_interval_s, self.keyframe_interval);
        set(&mut o.window.keyframe_min_interval_s, self.keyframe_min_interval);
        set(&mut o.noise.pixel_sigma, self.pixel_sigma);
        set(&mut o.gates.prediction_px, self.prediction_gate);
        set(&mut o.gates.triangulation_px, self.triangulation_gate);
        set(&mut o.noise.gravity, gravity);
        o.window.solve_every_frame |= self.solve_every_frame;
        o.window.stereo &= !self.stereo_init_only;
        o.window.landmark_bearings &= !self.inverse_depth_only;
        o.noise.from_static |= self.noise_from_static;
        o.noise.measure_in_motion &= !self.fixed_noise;
        if let Some(e) = self.estimate_extrinsics {
            o.camera.extrinsics = e.into();
        }
        if let Some(e) = self.estimate_time_offset {
            o.camera.time_offset = e.into();
        }
        if self.zoh {
            o.noise.imu.scheme = tumble::factors::imu_preint::Scheme::ZeroOrderHold;
        }
        o.validate()?;
        Ok(o)
    }
}

fn set<T>(field: &mut T, value: Option<T>) {
    if let Some(v) = value {
        *field = v;
    }
}

/// Flags of `tumble vio`.
#[derive(Args)]
pub struct VioArgs {
    /// ASL folder with imu0/ and cam0/sensor.yaml plus either cam0/tracks.csv
    /// (e.g. from `tumble sim walk` or `tumble track`) or the images (tracked
    /// by the visual frontend, feature `opencv`), or an EqVIO processed .csv.
    #[arg(required_unless_present = "print_config")]
    input: Option<PathBuf>,
    /// calibration.json from `tumble calibrate` (eq. 16 applied to every sample).
    #[arg(long)]
    calibration: Option<PathBuf>,
    /// Kalibr imu.yaml with the noise (from `tumble allan`); default: imu0/sensor.yaml's figures.
    #[arg(long)]
    noise: Option<PathBuf>,
    /// Output folder of `tumble calibrate-rig`: its cameras (intrinsics, T_BC)
    /// and time offset replace the dataset's camN/sensor.yaml.
    #[arg(long)]
    rig: Option<PathBuf>,
    /// Ground truth (ASL CSV) for evaluation; an ASL folder's own is used when present.
    #[arg(long)]
    groundtruth: Option<PathBuf>,
    /// Output folder.
    #[arg(long, required_unless_present = "print_config")]
    out: Option<PathBuf>,
    /// Start from the ground-truth state at the first frame (evaluation aid only).
    #[arg(long)]
    init_from_groundtruth: bool,
    #[command(flatten)]
    estimator: EstimatorArgs,
    /// Gravity magnitude [m/s²] [default: 9.81].
    #[arg(long)]
    gravity: Option<f64>,
    /// Bias errors are averaged from this many seconds after initialization.
    #[arg(long, default_value_t = 10.0)]
    bias_after: f64,
    /// No camera data: simulate a camera flying the ground-truth path (real IMU,
    /// simulated vision; an evaluation aid for IMU + ground-truth recordings).
    #[arg(long)]
    simulate_camera: bool,
    /// The simulated camera's second camera, this far to the right of the
    /// first [m] (0: one camera). By default as the dataset has them: the
    /// distance between cam0 and cam1 when both have a sensor.yaml (EuRoC:
    /// 0.11), else one camera.
    #[arg(long, value_name = "METRES", requires = "simulate_camera")]
    simulate_stereo: Option<f64>,
    /// Seed of the simulated camera's landmarks and noise.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// One camera: ignore cam0/tracks_cam1.csv (cam0's features matched into
    /// cam1, as `tumble track --stereo` or `tumble sim --stereo-baseline`
    /// write them) and, when the frontend tracks the images, do not match
    /// them into cam1 (it does when cam1/ has images and both cameras their
    /// extrinsics).
    #[arg(long)]
    mono: bool,
    /// Also record the run for the rerun viewer into this .rrd file: images with
    /// features, poses, window, landmarks, ground truth, biases (cargo feature
    /// `rerun`; view with `pip install rerun-sdk==0.36.3 && rerun FILE.rrd`).
    #[arg(long, value_name = "FILE.rrd")]
    rerun: Option<PathBuf>,
    /// The visual frontend, used when cam0 has images but no tracks.csv.
    #[command(flatten)]
    frontend: FrontendArgs,
}

impl VioArgs {
    pub fn run(self) -> CliResult {
        let mut opts = self.estimator.options(self.gravity)?;
        if self.estimator.print_config {
            print!("{}", opts.to_yaml()?);
            return Ok(());
        }
        let input = self.input.ok_or("give the input to run on (or --print-config)")?;
        let out = self.out.ok_or("give --out (or --print-config)")?;
        if let Some(r) = &self.rerun {
            tumble::vio::rerun_available(r)?;
        }
        let cal = self.calibration.as_deref().map(tumble::calib::ImuCalibration::read).transpose()?;
        let source = tumble::vio::VioSource {
            calibration: cal,
            groundtruth: self.groundtruth.clone(),
            simulate_camera: self.simulate_camera.then_some(self.seed),
            simulated_stereo_baseline_m: self.simulate_stereo,
            mono: self.mono,
            frontend: self.frontend.options(),
            frontend_dir: out.clone(),
            rig: self.rig.as_deref().map(tumble::io::target::RigCalibration::read).transpose()?,
        };
        let vin = open_input(&input, &source)?;
        if let (Some(st), Some(baseline)) = (&vin.stereo, vin.stereo_baseline_m()) {
            let matches: usize = st.features.iter().map(Vec::len).sum();
            let used = if opts.window.stereo {
                "the initialization and the window (--stereo-init-only: the initialization only"
            } else {
                "the initialization (without --stereo-init-only: the window too"
            };
            println!(
                "stereo: {matches} matches in cam1 ({baseline:.3} m from cam0) for {used}; --mono to ignore them)"
            );
        }
        let given = self.noise.as_deref().map(ImuNoise::read).transpose()?;
        // --noise, else a --config file's noise.imu, else the dataset's, else the defaults.
        if given.is_none() && self.estimator.config.is_some() {
            println!("noise: the --config file's noise.imu");
        } else {
            match vin.apply_noise(given, &mut opts.noise.imu) {
                NoiseSource::Given => {}
                NoiseSource::Input => println!("noise: the figures of the dataset's imu0/sensor.yaml"),
                NoiseSource::Default => println!("noise: EuRoC's ADIS16448 figures (give --noise imu.yaml for yours)"),
            }
        }
        if self.init_from_groundtruth {
            opts.init.mode = Init::from_groundtruth(&vin)?;
        }
        let bar =
            progress_bar(vin.frames.len() as u64, "vio [{bar:40}] {pos}/{len} frames {elapsed_precise} (eta {eta})");
        let mut tick = |done: usize, _: usize| bar.set_position(done as u64);
        let (result, recorded) = tumble::vio::run_recorded(&vin, &opts, Some(&mut tick), self.rerun.as_deref())?;
        bar.finish_and_clear();
        let summary = tumble::vio::summarize(&vin, &opts, &result, self.bias_after);
        for w in &summary.warnings {
            eprintln!("warning: {w}");
        }
        println!("{}", summary.table());
        let mut files = tumble::vio::write_outputs(&out, &vin, &result, &summary)?;
        files.extend(recorded);
        println!("wrote {}", paths(&files));
        Ok(())
    }
}
