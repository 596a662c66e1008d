//! The `tumble` command-line tool.

use clap::{Args, Parser, Subcommand, ValueEnum};
use std::path::PathBuf;
use std::process::ExitCode;
use tumble::io::validate::Duplicates;
use tumble::io::{bal, g2o, AccelUnit, GyroUnit, ImuColumns, RecordingOptions, TimeUnit};
use tumble_solvers::{LmOptions, Method, Optimizer, Summary};

#[derive(Parser)]
#[command(
    name = "tumble",
    version,
    about = "Turntable-free IMU calibration, Allan noise identification and visual-inertial bias estimation"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Clone, Copy, ValueEnum)]
enum MethodArg {
    Lm,
    Gn,
}

/// `tumble demo --walk`.
#[derive(Clone, Copy, ValueEnum)]
enum DemoWalkArg {
    /// Hand motion in a room, within about a metre (38.5 m in 6 minutes).
    Room,
    /// Laps of a 28 m × 14 m elliptical corridor at about 1 m/s (347 m in 6 minutes).
    Corridor,
}

/// `tumble solve --edge-error`: the cost of a 3-D g2o edge.
#[derive(Clone, Copy, ValueEnum)]
enum EdgeErrorArg {
    /// Log(Z⁻¹ X₁⁻¹ X₂), GTSAM's BetweenFactor.
    Log,
    /// Ceres' pose_graph_3d error [R₁ᵀ(p₂−p₁) − p_z, 2·vec(q_z q₁₂⁻¹)].
    Ceres,
    /// Ceres' error first, then log from its solution (reaches Ceres' minimum
    /// of torus3D in the log cost).
    CeresThenLog,
}

/// `tumble vio --init`: how the first state is found.
#[derive(Clone, Copy, ValueEnum)]
enum InitArg {
    /// At rest when the recording starts at rest, else from the motion.
    Auto,
    /// The recording must start at rest.
    Static,
    /// Closed-form visual–inertial solution over a moving start.
    Motion,
}

/// How to read an IMU recording given on the command line.
#[derive(Args, Clone)]
struct RecordingArgs {
    /// Text files: column names in file order, from t, gx, gy, gz, ax, ay, az, temp and _ (skip).
    #[arg(long, default_value = "t,gx,gy,gz,ax,ay,az", value_parser = |s: &str| ImuColumns::parse(s))]
    columns: ImuColumns,
    /// Text files: unit of the time column (s, ms, us, ns).
    #[arg(long, default_value = "ns", value_parser = |s: &str| TimeUnit::parse(s).ok_or("use s, ms, us or ns"))]
    time_unit: TimeUnit,
    /// Text files: gyro unit: rad/s (default), deg/s, counts (kept raw) or counts:SCALE[:OFFSET] (SCALE in rad/s per count).
    #[arg(long, value_parser = |s: &str| GyroUnit::parse(s))]
    gyro_unit: Option<GyroUnit>,
    /// Text files: accelerometer unit: m/s2 (default), g, counts or counts:SCALE[:OFFSET] (SCALE in m/s² per count).
    #[arg(long, value_parser = |s: &str| AccelUnit::parse(s))]
    accel_unit: Option<AccelUnit>,
    /// imu_tk layout: the gyro file (`t x y z`); the recording argument is then the accelerometer file.
    #[arg(long)]
    gyro_file: Option<PathBuf>,
    /// ROS bag / MCAP: the sensor_msgs/Imu topic (needed when the file has several).
    #[arg(long)]
    topic: Option<String>,
    /// Nominal sample rate [Hz] (estimated from the timestamps when absent).
    #[arg(long)]
    rate: Option<f64>,
    /// Refuse duplicated timestamps instead of re-stamping at the nominal rate.
    #[arg(long)]
    strict_timestamps: bool,
    /// Skip the check that values at rest look like rad/s and m/s².
    #[arg(long)]
    no_unit_check: bool,
}

impl RecordingArgs {
    fn options(&self) -> RecordingOptions {
        let mut o = RecordingOptions::default();
        o.format.columns = self.columns.clone();
        o.format.time_unit = self.time_unit;
        o.format.gyro_unit = self.gyro_unit.unwrap_or(GyroUnit::RadPerS);
        o.format.accel_unit = self.accel_unit.unwrap_or(AccelUnit::MetersPerS2);
        o.format.validate.nominal_rate = self.rate;
        o.format.validate.check_units = !self.no_unit_check;
        if self.strict_timestamps {
            o.format.validate.duplicates = Duplicates::Error;
        }
        o.gyro_file = self.gyro_file.clone();
        o.topic = self.topic.clone();
        o
    }
}

/// Settings of the visual frontend (`track`, and `vio` on image folders).
#[derive(Args, Clone)]
struct FrontendArgs {
    /// Features kept per frame.
    #[arg(long, default_value_t = 150)]
    max_features: usize,
    /// Smallest distance between two features [px].
    #[arg(long, default_value_t = 30.0)]
    min_distance: f64,
    /// Largest forward–backward KLT disagreement [px].
    #[arg(long, default_value_t = 0.5)]
    fb_threshold: f64,
    /// RANSAC epipolar threshold [px of the undistorted image].
    #[arg(long, default_value_t = 1.0)]
    ransac_threshold: f64,
    /// Equalize images (CLAHE) before tracking: for dark or low-contrast sequences (costs track accuracy).
    #[arg(long)]
    equalize: bool,
    /// Also match cam0's features into cam1 (same time; epipolar check with both
    /// sensor.yaml extrinsics) and write tracks_cam1.csv with the same track ids.
    #[arg(long)]
    stereo: bool,
}

impl FrontendArgs {
    fn options(&self) -> tumble::vio::frontend::FrontendOptions {
        tumble::vio::frontend::FrontendOptions {
            max_features: self.max_features,
            min_distance: self.min_distance,
            fb_threshold: self.fb_threshold,
            ransac_threshold: self.ransac_threshold,
            equalize: self.equalize,
            stereo: self.stereo,
            ..Default::default()
        }
    }
}

/// Track an ASL folder's camera with a progress bar; writes tracks.csv, frontend.json, tracks.png into `dir`.
fn run_frontend(
    ds: &tumble::io::asl::AslDataset,
    camera: usize,
    args: &FrontendArgs,
    dir: &std::path::Path,
) -> Result<Vec<tumble::vio::frontend::Observation>, String> {
    let n = ds.cameras.get(camera).map_or(0, |c| c.frames.len());
    let bar = progress_bar(n as u64, "track [{bar:40}] {pos}/{len} images {elapsed_precise} (eta {eta})");
    let (obs, stats, files) = tumble::vio::frontend::track_asl_into(ds, camera, &args.options(), dir, &mut |d, _| {
        bar.set_position(d as u64)
    })?;
    bar.finish_and_clear();
    for w in &stats.warnings {
        eprintln!("warning: {w}");
    }
    println!("frontend: {}", stats.line());
    if let Some(s) = &stats.stereo {
        println!("frontend: {}", s.line());
    }
    println!("wrote {}", paths(&files));
    Ok(obs)
}

/// Paths for a "wrote …" line.
fn paths(files: &[PathBuf]) -> String {
    files.iter().map(|f| f.display().to_string()).collect::<Vec<_>>().join(", ")
}

fn progress_bar(len: u64, template: &str) -> indicatif::ProgressBar {
    let bar = indicatif::ProgressBar::new(len);
    bar.set_style(indicatif::ProgressStyle::with_template(template).expect("static template").progress_chars("=> "));
    bar
}

/// Input layouts of `calibrate` and `apply`.
#[derive(Clone, Copy, ValueEnum, PartialEq)]
enum InputFormat {
    /// By the path: ASL folder, .bag/.mcap, or text with --columns.
    Auto,
    /// imu_tk's two files `t x y z` (time in s; raw counts or SI, recognised from the data).
    #[value(alias = "imu_tk")]
    ImuTk,
}

/// The recording a calibration command reads.
#[derive(Args, Clone)]
struct CalibInput {
    /// ASL folder, ROS bag/MCAP or text file (or give --accel and --gyro).
    recording: Option<PathBuf>,
    /// imu_tk layout: the accelerometer file.
    #[arg(long, requires = "gyro")]
    accel: Option<PathBuf>,
    /// imu_tk layout: the gyro file.
    #[arg(long, requires = "accel")]
    gyro: Option<PathBuf>,
    /// Input layout.
    #[arg(long, value_enum, default_value = "auto")]
    format: InputFormat,
    #[command(flatten)]
    read: RecordingArgs,
}

impl CalibInput {
    /// The main path and the reader options, imu_tk pairs resolved.
    fn resolve(&self) -> Result<(PathBuf, RecordingOptions, bool), String> {
        let mut o = self.read.options();
        let imu_tk = self.format == InputFormat::ImuTk || self.accel.is_some();
        let path = match (&self.recording, &self.accel) {
            (Some(_), Some(_)) => return Err("give either a recording or --accel/--gyro, not both".into()),
            (Some(p), None) => p.clone(),
            (None, Some(a)) => {
                o.gyro_file = self.gyro.clone();
                a.clone()
            }
            (None, None) => {
                return Err("no input: give a recording (ASL folder, bag, text) or --accel and --gyro".into())
            }
        };
        if imu_tk {
            if o.gyro_file.is_none() {
                return Err("--format imu_tk needs --accel FILE --gyro FILE (or --gyro-file)".into());
            }
            if self.read.time_unit == TimeUnit::Ns {
                o.format.time_unit = TimeUnit::S;
            }
            // Units recognised from the data unless declared.
            if self.read.accel_unit.is_none() && self.read.gyro_unit.is_none() {
                o.format.accel_unit = AccelUnit::Counts { scale: None, offset: 0.0 };
                o.format.gyro_unit = GyroUnit::Counts { scale: None, offset: 0.0 };
            }
        }
        let auto_units = imu_tk && self.read.accel_unit.is_none() && self.read.gyro_unit.is_none();
        Ok((path, o, auto_units))
    }

    /// Read the recording; imu_tk files without declared units are SI when the
    /// accelerometer reads ≈ 1 g at rest, raw counts otherwise.
    fn open(&self) -> Result<(tumble::io::ImuRecording, PathBuf, RecordingOptions), Box<dyn std::error::Error>> {
        let (path, o, auto_units) = self.resolve()?;
        let mut rec = tumble::io::open_recording(&path, &o)?;
        if auto_units {
            let n = rec.len().min(((rec.mean_rate() * 5.0) as usize).max(10));
            let m = tumble::calib::detect::mean3(&rec.accel[..n]);
            let g = (m[0] * m[0] + m[1] * m[1] + m[2] * m[2]).sqrt();
            if (7.0..13.0).contains(&g) {
                rec.accel_units = tumble::io::Stored::Si;
                rec.gyro_units = tumble::io::Stored::Si;
            }
        }
        Ok((rec, path, o))
    }
}

#[derive(Subcommand)]
enum Command {
    /// Simulate a recording with known truth and write it as an ASL dataset folder.
    Sim {
        /// What to simulate.
        #[arg(value_enum)]
        scenario: tumble::sim::Scenario,
        /// Output folder (gets mav0/ and truth.json).
        #[arg(long)]
        out: PathBuf,
        /// YAML config: IMU model, effects, durations, camera (every key optional).
        #[arg(long)]
        config: Option<PathBuf>,
        /// Random seed; the same seed and config give the same bytes.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Length of static, walk, flight and corridor scenarios [s] (overrides the config).
        #[arg(long)]
        duration: Option<f64>,
        /// Add a second camera this far right of cam0 [m] (EuRoC: 0.11): writes
        /// cam1/sensor.yaml and its matches in cam0/tracks_cam1.csv, which
        /// `tumble vio` uses to initialize (overrides the config's
        /// camera.stereo_baseline_m).
        #[arg(long, value_name = "METRES")]
        stereo_baseline: Option<f64>,
        /// Stop a walk, flight or corridor walk on the way: slow down over 1 s from START
        /// seconds, stand still for LENGTH seconds, speed up over 1 s
        /// (repeatable; each makes the recording LENGTH + 1 s longer; overrides
        /// the config's pauses_s).
        #[arg(long, value_name = "START,LENGTH")]
        pause: Vec<String>,
        /// Print the default config as YAML and exit (a starting point for --config).
        #[arg(long)]
        print_config: bool,
        /// Hide an effect the calibration model lacks (for `tumble audit`): EFFECT or
        /// EFFECT:STRENGTH with EFFECT one of g_sensitivity, temperature_bias,
        /// temperature_scale, gyro_nonlinearity, accel_nonlinearity, bias_drift
        /// (repeatable; STRENGTH multiplies the model's coefficients, default 1).
        #[arg(long)]
        hide: Vec<String>,
    },
    /// Read an IMU recording, check it, and print what it holds and what looks wrong.
    Inspect {
        /// ASL dataset folder (or its mav0/), a ROS .bag or .mcap, a text/CSV file (.gz allowed), or imu_tk's accelerometer file.
        recording: PathBuf,
        #[command(flatten)]
        read: RecordingArgs,
        /// Also write a PNG of the accelerometer and gyro (and temperature) against time.
        #[arg(long, value_name = "FILE.png")]
        plot: Option<PathBuf>,
    },
    /// Identify IMU noise from a static recording by Allan variance: writes
    /// allan.json, Kalibr's imu.yaml and allan_gyro.png / allan_accel.png.
    Allan {
        /// Static recording: ASL folder, ROS bag/MCAP, or text/CSV (.gz allowed).
        recording: PathBuf,
        #[command(flatten)]
        read: RecordingArgs,
        /// Output folder.
        #[arg(long)]
        out: PathBuf,
        /// Estimator (noise coefficients are identified from oadev or adev curves).
        #[arg(long, value_enum, default_value = "oadev")]
        kind: tumble::allan::DeviationKind,
        /// τ values: a number of log-spaced values per decade, `octave`, or `all`.
        #[arg(long, default_value = "20")]
        taus: String,
        /// Largest τ as a fraction of the record length.
        #[arg(long, default_value_t = 0.1)]
        max_tau_fraction: f64,
        /// Confidence level of the deviation intervals (0.683 = 1 σ).
        #[arg(long, default_value_t = 0.683)]
        confidence: f64,
        /// How the three axes become Kalibr's single number.
        #[arg(long, value_enum, default_value = "max")]
        axis_stat: tumble::allan::AxisStat,
        /// Analyse only this time span of the recording [s from its start], e.g. 0:3600.
        #[arg(long)]
        span: Option<String>,
    },
    /// Calibrate accelerometer and gyroscope from one hand-tumbled recording
    /// (≥ 50 s still, then many poses held still): writes calibration.json/.yaml,
    /// imu_tk_acc.calib, imu_tk_gyro.calib and static_detection.png.
    Calibrate {
        #[command(flatten)]
        input: CalibInput,
        /// Output folder.
        #[arg(long)]
        out: PathBuf,
        /// Local gravity [m/s²] (default: WGS-84 at --latitude/--height, else 9.80665).
        #[arg(long, conflicts_with = "latitude")]
        gravity: Option<f64>,
        /// Geodetic latitude [deg] for WGS-84 normal gravity.
        #[arg(long)]
        latitude: Option<f64>,
        /// Ellipsoidal height [m] for WGS-84 normal gravity (with --latitude).
        #[arg(long, default_value_t = 0.0, requires = "latitude")]
        height: f64,
        /// Length of the initial static period [s].
        #[arg(long, default_value_t = 50.0)]
        init_static: f64,
        /// Window of the sliding accelerometer variance [s] (imu_tk: 101 samples).
        #[arg(long, default_value_t = 0.5)]
        window: f64,
        /// Shortest usable static interval [s] (imu_tk: 100 samples).
        #[arg(long, default_value_t = 0.5)]
        min_interval: f64,
        /// Threshold multipliers to sweep: FIRST:LAST (integers) or a comma list.
        #[arg(long, default_value = "2:10")]
        multipliers: String,
        /// Estimate the gyro bias with the other gyro parameters (default: mean of the initial static period).
        #[arg(long)]
        estimate_gyro_bias: bool,
        /// Fewest static intervals accepted.
        #[arg(long, default_value_t = 12)]
        min_intervals: usize,
        /// Detect static intervals from the accelerometer alone, as imu_tk does
        /// (default: the gyro must be still too).
        #[arg(long)]
        accel_only_detection: bool,
    },
    /// Correct a recording with a calibration (paper eq. 16) and write it in the format it was read.
    Apply {
        #[command(flatten)]
        input: CalibInput,
        /// calibration.json or .yaml from `tumble calibrate`.
        #[arg(long)]
        calibration: PathBuf,
        /// Output folder.
        #[arg(long)]
        out: PathBuf,
    },
    /// Model-discrepancy audit of a calibration recording: find the effect the
    /// calibration lacks, add it, show the gap shrink. Writes audit.json,
    /// audit.md, calibration.json (with the effects) and figures. With --vio,
    /// the audit of a VIO run instead: camera–IMU and accelerometer–gyro time offsets.
    Audit {
        #[command(flatten)]
        input: CalibInput,
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
        /// Kalibr imu.yaml with the noise (from `tumble allan`): its bias random walks set how
        /// far biases may wander (default: generous consumer-MEMS values).
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
        #[arg(long, value_delimiter = ',')]
        candidates: Vec<String>,
        /// Length of the initial static period [s] (for the static-interval detection).
        #[arg(long, default_value_t = 50.0)]
        init_static: f64,
    },
    /// Visual-inertial bias estimation (sliding window, paper §4): writes
    /// trajectory.txt (TUM), biases.csv and summary.json.
    Vio {
        /// ASL folder with imu0/ and cam0/sensor.yaml plus either cam0/tracks.csv
        /// (e.g. from `tumble sim walk` or `tumble track`) or the images (tracked
        /// by the visual frontend, feature `opencv`), or an EqVIO processed .csv.
        input: PathBuf,
        /// calibration.json from `tumble calibrate` (eq. 16 applied to every sample).
        #[arg(long)]
        calibration: Option<PathBuf>,
        /// Kalibr imu.yaml with the noise (from `tumble allan`); default: imu0/sensor.yaml's figures.
        #[arg(long)]
        noise: Option<PathBuf>,
        /// Ground truth (ASL CSV) for evaluation; an ASL folder's own is used when present.
        #[arg(long)]
        groundtruth: Option<PathBuf>,
        /// Output folder.
        #[arg(long)]
        out: PathBuf,
        /// Start from the ground-truth state at the first frame (evaluation aid only).
        #[arg(long)]
        init_from_groundtruth: bool,
        /// How the first state is found without ground truth: `static` needs the
        /// recording to start at rest; `motion` solves velocity, roll, pitch and
        /// scale in closed form from the IMU and the tracks of a moving start
        /// (with cam1's matches too, when the folder has them: see --mono);
        /// `auto` uses the first when the start is at rest, else the second.
        #[arg(long, value_enum, default_value_t = InitArg::Auto)]
        init: InitArg,
        /// Keyframes in the window.
        #[arg(long, default_value_t = 10)]
        window: usize,
        /// Median feature parallax to the last keyframe (rotation taken out) that
        /// makes a frame a keyframe [px]; larger values stretch the window over
        /// more time.
        #[arg(long, default_value_t = 15.0)]
        keyframe_parallax: f64,
        /// Longest time between keyframes [s].
        #[arg(long, default_value_t = 1.0)]
        keyframe_interval: f64,
        /// Feature observation noise [px].
        #[arg(long, default_value_t = 1.0)]
        pixel_sigma: f64,
        /// A new observation of a landmark farther than this from where the
        /// IMU-predicted pose projects it stays out of the solve [px].
        #[arg(long, default_value_t = 30.0)]
        prediction_gate: f64,
        /// A track is triangulated only when its observations agree with the
        /// triangulated point within this; the worst one leaves the track
        /// otherwise [px].
        #[arg(long, default_value_t = 12.0)]
        triangulation_gate: f64,
        /// Solve the whole window at every frame (VINS-Mono's way; several
        /// times slower) instead of at keyframes only, with the frames in
        /// between tracked against the fixed window.
        #[arg(long)]
        solve_every_frame: bool,
        /// Integrate with VINS-Mono's midpoint rule instead of GTSAM's zero-order hold.
        #[arg(long)]
        midpoint: bool,
        /// Gravity magnitude [m/s²].
        #[arg(long, default_value_t = 9.81)]
        gravity: f64,
        /// Raise the IMU noise to what the static start measured (vibration).
        #[arg(long)]
        noise_from_static: bool,
        /// Bias errors are averaged from this many seconds after initialization.
        #[arg(long, default_value_t = 10.0)]
        bias_after: f64,
        /// No camera data: simulate a camera flying the ground-truth path (real IMU,
        /// simulated vision; an evaluation aid for IMU + ground-truth recordings).
        #[arg(long)]
        simulate_camera: bool,
        /// Seed of the simulated camera's landmarks and noise.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Ignore cam0/tracks_cam1.csv (cam0's features matched into cam1, as
        /// `tumble track --stereo` or `tumble sim --stereo-baseline` write them):
        /// initialize from cam0 alone.
        #[arg(long)]
        mono: bool,
        /// Also put cam1's matches into the sliding window (not only into the
        /// initialization): more landmarks and constraints, about half the speed;
        /// on four simulated walks it was not consistently more accurate.
        #[arg(long)]
        stereo_window: bool,
        /// Also record the run for the rerun viewer into this .rrd file: images with
        /// features, poses, window, landmarks, ground truth, biases (cargo feature
        /// `rerun`; view with `pip install rerun-sdk==0.36.3 && rerun FILE.rrd`).
        #[arg(long, value_name = "FILE.rrd")]
        rerun: Option<PathBuf>,
        /// The visual frontend, used when cam0 has images but no tracks.csv.
        #[command(flatten)]
        frontend: FrontendArgs,
    },
    /// Track features in an ASL folder's camera images (visual frontend, cargo
    /// feature `opencv`): writes tracks.csv, frontend.json and tracks.png.
    Track {
        /// ASL folder (mav0/ or its parent) with camN/data.csv and the images.
        input: PathBuf,
        /// Camera folder to track.
        #[arg(long, default_value = "cam0")]
        camera: String,
        /// Output folder.
        #[arg(long)]
        out: PathBuf,
        #[command(flatten)]
        frontend: FrontendArgs,
    },
    /// Evaluate a trajectory against ground truth: ATE after alignment, RPE over
    /// distances, bias errors; writes metrics.json and plots.
    Eval {
        /// Estimated trajectory: TUM (`t[s] x y z qx qy qz qw`) or ASL CSV.
        #[arg(long)]
        estimate: PathBuf,
        /// Ground truth: EuRoC/ASL CSV (with bias columns for bias errors) or TUM.
        #[arg(long)]
        groundtruth: PathBuf,
        /// Alignment before the absolute errors: se3, sim3, posyaw (VIO's gauge) or none.
        #[arg(long, default_value = "posyaw", value_parser = |s: &str| tumble::eval::Alignment::parse(s))]
        align: tumble::eval::Alignment,
        /// Bias track (`tumble vio`'s biases.csv); default: biases.csv beside the estimate, if there.
        #[arg(long)]
        biases: Option<PathBuf>,
        /// Relative-error distances [m], comma separated; default 10–50 % of the path.
        #[arg(long, value_delimiter = ',')]
        rpe_distances: Vec<f64>,
        /// Bias errors count from this many seconds after the first estimate.
        #[arg(long, default_value_t = 10.0)]
        bias_after: f64,
        /// Largest ground-truth gap to interpolate across [s].
        #[arg(long, default_value_t = 0.1)]
        max_gap: f64,
        /// Output folder (default: `eval/` beside the estimate).
        #[arg(long)]
        out: Option<PathBuf>,
    },
    /// The whole chain on your recordings: calibrate → allan → audit → vio, each
    /// stage in its own folder of --out, then report.md with every table and figure.
    Run {
        /// Hand-tumbled calibration recording (ASL folder, bag/MCAP, text; with
        /// --gyro-file for imu_tk's two files): the calibrate and audit stages.
        #[arg(long)]
        tumble: Option<PathBuf>,
        /// Static recording (hours, for the bias random walk): the allan stage.
        #[arg(long = "static")]
        still: Option<PathBuf>,
        /// VIO data (ASL folder with tracks or images, or an EqVIO .csv): the vio stage.
        #[arg(long)]
        vio: Option<PathBuf>,
        /// Output folder (gets calibrate/, allan/, audit/, vio/ and report.md).
        #[arg(long)]
        out: PathBuf,
        /// Stages not to run, comma separated (calibrate, allan, audit, vio): their
        /// results come from --calibration/--noise or from an earlier run's files in --out.
        #[arg(long, value_delimiter = ',')]
        skip: Vec<String>,
        /// Calibration to use instead of the calibrate stage.
        #[arg(long)]
        calibration: Option<PathBuf>,
        /// Kalibr imu.yaml to use instead of the allan stage.
        #[arg(long)]
        noise: Option<PathBuf>,
        /// Local gravity [m/s²] (default: WGS-84 at --latitude, else 9.80665).
        #[arg(long, conflicts_with = "latitude")]
        gravity: Option<f64>,
        /// Geodetic latitude [deg] for WGS-84 normal gravity (at sea level).
        #[arg(long)]
        latitude: Option<f64>,
        /// Length of the tumble's initial static period [s].
        #[arg(long, default_value_t = 50.0)]
        init_static: f64,
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
        /// The visual frontend, used when the vio folder has images but no tracks.
        #[command(flatten)]
        frontend: FrontendArgs,
    },
    /// The whole chain on simulated recordings with known truth: calibrate a hand
    /// tumble with a hidden effect, identify the noise (Allan), audit, and run the
    /// VIO on the 6-minute walk; prints every estimate next to the truth.
    Demo {
        /// Folder for the chain's files and report.md.
        #[arg(long, default_value = "tumble-demo")]
        out: PathBuf,
        /// The 6-minute walk: laps of a corridor at walking speed, or hand motion in a room.
        #[arg(long, value_enum, default_value = "corridor")]
        walk: DemoWalkArg,
        /// Seed of every simulation.
        #[arg(long, default_value_t = 1)]
        seed: u64,
    },
    /// Solve a g2o pose graph (.g2o) or a Bundle Adjustment in the Large file (other extensions).
    Solve {
        /// Input file.
        file: PathBuf,
        /// Nonlinear method.
        #[arg(long, value_enum, default_value = "lm")]
        method: MethodArg,
        /// Maximum iterations.
        #[arg(long, default_value_t = 100)]
        max_iterations: usize,
        /// Initial Levenberg–Marquardt damping λ (relative to diag(H)).
        #[arg(long)]
        initial_lambda: Option<f64>,
        /// Smallest factor λ shrinks by after a good step.
        #[arg(long)]
        min_lambda_decrease: Option<f64>,
        /// Relative cost-decrease tolerance.
        #[arg(long, default_value_t = 1e-6)]
        function_tolerance: f64,
        /// g2o: replace non-positive-definite information matrices by the nearest
        /// positive-definite ones (with a warning each) instead of refusing the file.
        #[arg(long)]
        repair_information: bool,
        /// g2o: the cost of each 3-D edge.
        #[arg(long, value_enum, default_value = "log")]
        edge_error: EdgeErrorArg,
        /// Print the per-iteration log.
        #[arg(long)]
        verbose: bool,
        /// g2o only: write a PNG of the initial guess and the solution seen from above.
        #[arg(long, value_name = "FILE.png")]
        plot: Option<PathBuf>,
    },
}

fn print_log(s: &Summary) {
    println!("{:>5} {:>16} {:>10} {:>12} {:>9} {:>8}", "iter", "cost", "lambda", "|step|", "gain", "accepted");
    for l in &s.log {
        println!(
            "{:>5} {:>16.8e} {:>10.2e} {:>12.4e} {:>9.3} {:>8}",
            l.iteration, l.cost, l.lambda, l.step_norm, l.gain_ratio, l.accepted
        );
    }
}

fn run(cli: Cli) -> Result<(), Box<dyn std::error::Error>> {
    match cli.command {
        Command::Sim { scenario, out, config, seed, duration, stereo_baseline, pause, print_config, hide } => {
            let mut cfg = match &config {
                Some(p) => tumble::sim::SimConfig::read(p)?,
                None => tumble::sim::SimConfig::default(),
            };
            for h in &hide {
                let (name, strength) = match h.split_once(':') {
                    Some((n, s)) => (
                        n,
                        s.parse::<f64>().map_err(|e| format!("--hide {h}: strength `{s}` is not a number ({e})"))?,
                    ),
                    None => (h.as_str(), 1.0),
                };
                tumble::sim::hide_effect(&mut cfg, name, strength).map_err(|e| format!("--hide {h}: {e}"))?;
            }
            if print_config {
                print!("{}", serde_saphyr::to_string(&cfg)?);
                return Ok(());
            }
            if duration.is_some() {
                cfg.duration_s = duration;
            }
            if !pause.is_empty() {
                cfg.pauses_s = pause.iter().map(|p| parse_pause(p)).collect::<Result<_, _>>()?;
            }
            if let Some(b) = stereo_baseline {
                cfg.camera.stereo_baseline_m = b;
                cfg.camera.check().map_err(|e| format!("--stereo-baseline: {e}"))?;
            }
            let start = std::time::Instant::now();
            let sim = tumble::sim::simulate_and_write(scenario, &cfg, seed, &out)?;
            println!(
                "simulated {:?}: {} IMU samples over {:.1} s{}, written to {} in {:.2} s",
                scenario,
                sim.imu.t.len(),
                sim.motion.duration(),
                sim.tracks
                    .as_ref()
                    .map(|t| format!(", {} frames, {} feature observations", t.frames.len(), t.observations.len()))
                    .unwrap_or_default(),
                out.display(),
                start.elapsed().as_secs_f64()
            );
        }
        Command::Inspect { recording, read, plot } => {
            let start = std::time::Instant::now();
            let r = tumble::io::open_recording(&recording, &read.options())?;
            println!("{}: {} samples in {:.2} s", r.source_name(), r.len(), start.elapsed().as_secs_f64());
            println!("  duration {:.3} s, mean rate {:.3} Hz", r.duration(), r.mean_rate());
            let stat = |v: &[[f64; 3]], name: &str, unit: &str| {
                if v.is_empty() {
                    return;
                }
                let n = v.len() as f64;
                let m: Vec<f64> = (0..3).map(|k| v.iter().map(|s| s[k]).sum::<f64>() / n).collect();
                let sd: Vec<f64> =
                    (0..3).map(|k| (v.iter().map(|s| (s[k] - m[k]).powi(2)).sum::<f64>() / n).sqrt()).collect();
                println!(
                    "  {name:<6} mean [{:+.5}, {:+.5}, {:+.5}] std [{:.5}, {:.5}, {:.5}] {unit}",
                    m[0], m[1], m[2], sd[0], sd[1], sd[2]
                );
            };
            let unit = |u: tumble::io::Stored, si: &'static str| match u {
                tumble::io::Stored::Si => si,
                tumble::io::Stored::RawCounts => "counts",
            };
            stat(&r.gyro, "gyro", unit(r.gyro_units, "rad/s"));
            stat(&r.accel, "accel", unit(r.accel_units, "m/s²"));
            if let Some(t) = &r.temperature {
                let (lo, hi) = t.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| (a.min(x), b.max(x)));
                println!("  temperature {lo:.2} … {hi:.2} °C");
            }
            if r.warnings.is_empty() {
                println!("  no problems found");
            }
            for w in &r.warnings {
                println!("warning: {w}");
            }
            if let Some(png) = plot {
                r.write_overview_png(&png)?;
                println!("wrote {}", png.display());
            }
        }
        Command::Allan { recording, read, out, kind, taus, max_tau_fraction, confidence, axis_stat, span } => {
            let grid = match taus.as_str() {
                "octave" => tumble::allan::TauGrid::Octave,
                "all" => tumble::allan::TauGrid::All,
                v => tumble::allan::TauGrid::LogSpaced(
                    v.parse()
                        .ok()
                        .filter(|&p: &usize| p > 0)
                        .ok_or_else(|| format!("--taus: expected a count per decade, `octave` or `all`, got `{v}`"))?,
                ),
            };
            if !(confidence > 0.0 && confidence < 1.0) {
                return Err(format!("--confidence must lie strictly between 0 and 1, got {confidence}").into());
            }
            if max_tau_fraction.is_nan() || max_tau_fraction <= 0.0 {
                return Err(format!("--max-tau-fraction must be positive, got {max_tau_fraction}").into());
            }
            let start = std::time::Instant::now();
            let mut rec = tumble::io::open_recording(&recording, &read.options())?;
            if let Some(span) = span {
                let (a, b) = parse_span(&span)?;
                rec = rec.slice_time(a, b);
            }
            eprintln!("read {} samples ({:.1} s) in {:.2} s", rec.len(), rec.duration(), start.elapsed().as_secs_f64());
            let opts = tumble::allan::AllanRunOptions {
                allan: tumble::allan::AllanOptions { kind, taus: grid, max_tau_fraction, confidence },
                axis_stat,
                progress: std::io::IsTerminal::is_terminal(&std::io::stderr()),
            };
            let t = std::time::Instant::now();
            let report = tumble::allan::run_allan(&rec, &opts)?;
            let elapsed = t.elapsed().as_secs_f64();
            print!("{}", report.summary_table());
            let files = report.write_all(&out)?;
            println!("\ncomputed in {elapsed:.2} s; wrote {}", paths(&files));
        }
        Command::Calibrate {
            input,
            out,
            gravity,
            latitude,
            height,
            init_static,
            window,
            min_interval,
            multipliers,
            estimate_gyro_bias,
            min_intervals,
            accel_only_detection,
        } => {
            let start = std::time::Instant::now();
            let (rec, _, _) = input.open()?;
            for w in &rec.warnings {
                eprintln!("warning: {w}");
            }
            let gravity = gravity_arg(gravity, latitude, height)?;
            for (v, name) in [(init_static, "--init-static"), (window, "--window"), (min_interval, "--min-interval")] {
                if !(v.is_finite() && v > 0.0) {
                    return Err(format!("{name} must be positive, got {v}").into());
                }
            }
            let opts = tumble::calib::CalibOptions {
                gravity,
                init_static_s: init_static,
                window_s: window,
                min_interval_s: min_interval,
                multipliers: parse_multipliers(&multipliers)?,
                estimate_gyro_bias,
                min_intervals: min_intervals.max(10),
                detect_with_gyro: !accel_only_detection,
            };
            eprintln!("read {} samples ({:.1} s) in {:.2} s", rec.len(), rec.duration(), start.elapsed().as_secs_f64());
            let t = std::time::Instant::now();
            let result = tumble::calib::calibrate(&rec, &opts)?;
            let elapsed = t.elapsed().as_secs_f64();
            print!("{}", result.summary_table());
            for w in &result.warnings {
                eprintln!("warning: {w}");
            }
            let files = result.write_all(&rec, &opts, &out)?;
            println!("calibrated in {elapsed:.3} s; wrote {}", paths(&files));
        }
        Command::Audit {
            input,
            calibration,
            vio,
            pixel_sigma,
            gravity,
            offset_step_ms,
            frontend,
            noise,
            out,
            alpha,
            max_effects,
            candidates,
            init_static,
        } => {
            use tumble::audit::{audit, AuditOptions, Effect};
            let candidates = candidates
                .iter()
                .map(|c| {
                    Effect::from_id(c.trim()).ok_or_else(|| {
                        let ids: Vec<&str> = Effect::ALL.iter().map(|e| e.id()).collect();
                        format!("--candidates: unknown effect `{c}` (known: {})", ids.join(", "))
                    })
                })
                .collect::<Result<Vec<_>, _>>()?;
            if !(alpha > 0.0 && alpha < 1.0) {
                return Err(format!("--alpha must be in (0, 1), got {alpha}").into());
            }
            if let Some(path) = vio {
                let cal = calibration.as_deref().map(tumble::calib::ImuCalibration::read).transpose()?;
                let noise = noise.as_deref().map(tumble::vio::ImuNoise::read).transpose()?;
                let args = VioAuditArgs { pixel_sigma, gravity, offset_step_ms, alpha, max_effects, candidates, noise };
                return audit_vio_command(&path, cal.as_ref(), &args, &frontend, &out);
            }
            let calibration = calibration.ok_or("--calibration is required to audit a calibration recording")?;
            let cal = tumble::calib::ImuCalibration::read(&calibration)?;
            let (rec, _, _) = input.open()?;
            for w in &rec.warnings {
                eprintln!("warning: {w}");
            }
            if !(init_static.is_finite() && init_static > 0.0) {
                return Err(format!("--init-static must be positive, got {init_static}").into());
            }
            let mut opts = AuditOptions { alpha, max_effects, ..AuditOptions::default() };
            opts.detection.init_static_s = init_static;
            if !candidates.is_empty() {
                opts.candidates = candidates;
            }
            if let Some(p) = &noise {
                opts.noise = Some(tumble::vio::ImuNoise::read(p)?);
            }
            let t = std::time::Instant::now();
            let result = audit(&rec, &cal, &opts)?;
            print!("{}", tumble::audit::report::summary_table(&result));
            for n in &result.notes {
                eprintln!("note: {n}");
            }
            let files = tumble::audit::report::write(&result, &out)?;
            println!("{}", result.verdict());
            println!("audited in {:.2} s; wrote {} in {}", t.elapsed().as_secs_f64(), files.join(", "), out.display());
        }
        Command::Apply { input, calibration, out } => {
            let cal = tumble::calib::ImuCalibration::read(&calibration)?;
            let (mut rec, path, o) = input.open()?;
            let check = |what: &str, stored: tumble::io::Stored, expected: &str| -> Result<(), String> {
                let got = if stored == tumble::io::Stored::RawCounts { "counts" } else { "SI" };
                let exp = if expected == "counts" { "counts" } else { "SI" };
                if got != exp {
                    return Err(format!(
                        "{}: the {what} was calibrated on {exp} input but this recording's {what} is read as {got}",
                        calibration.display()
                    ));
                }
                Ok(())
            };
            check("accelerometer", rec.accel_units, &cal.units.accel_input)?;
            check("gyro", rec.gyro_units, &cal.units.gyro_input)?;
            let corr = cal.corrector().ok_or("calibration matrices are singular")?;
            for w in corr.warnings_for(&rec) {
                eprintln!("warning: {w}");
            }
            (rec.accel, rec.gyro) = corr.correct_recording(&rec);
            if let Some(o) = cal.time_offsets.filter(|o| o.accel_gyro_s != 0.0) {
                rec.accel = tumble::io::imu::resample_delayed(&rec.t, &rec.accel, o.accel_gyro_s);
                println!(
                    "accelerometer resampled onto the gyro's stamps (accel–gyro offset {:+.3} ms)",
                    1e3 * o.accel_gyro_s
                );
            }
            rec.accel_units = tumble::io::Stored::Si;
            rec.gyro_units = tumble::io::Stored::Si;
            let written = tumble::calib::write_like_input(&rec, &path, &o, &out)?;
            println!(
                "corrected {} samples (eq. 16{}) into {}",
                rec.len(),
                if corr.has_effects() { format!(" + {}", cal.effect_ids().join(", ")) } else { String::new() },
                paths(&written)
            );
        }
        Command::Vio {
            input,
            calibration,
            noise,
            groundtruth,
            out,
            init_from_groundtruth,
            init,
            window,
            keyframe_parallax,
            keyframe_interval,
            pixel_sigma,
            prediction_gate,
            triangulation_gate,
            solve_every_frame,
            midpoint,
            gravity,
            noise_from_static,
            bias_after,
            simulate_camera,
            seed,
            mono,
            stereo_window,
            rerun,
            frontend,
        } => {
            use tumble::vio::{ImuNoise, VioOptions};
            if let Some(r) = &rerun {
                tumble::vio::rerun_available(r)?;
            }
            for (v, name, unit) in [
                (keyframe_parallax, "--keyframe-parallax", "pixels"),
                (keyframe_interval, "--keyframe-interval", "seconds"),
                (prediction_gate, "--prediction-gate", "pixels"),
                (triangulation_gate, "--triangulation-gate", "pixels"),
            ] {
                if !(v.is_finite() && v > 0.0) {
                    return Err(format!("{name} must be a positive number of {unit}, got {v}").into());
                }
            }
            let cal = calibration.as_deref().map(tumble::calib::ImuCalibration::read).transpose()?;
            let mut opts = VioOptions {
                window,
                keyframe_parallax_px: keyframe_parallax,
                keyframe_max_interval_s: keyframe_interval,
                pixel_sigma,
                prediction_gate_px: prediction_gate,
                triangulation_gate_px: triangulation_gate,
                gravity,
                noise_from_static,
                solve_window_every_frame: solve_every_frame,
                stereo_window,
                init: match init {
                    InitArg::Auto => tumble::vio::Init::Auto,
                    InitArg::Static => tumble::vio::Init::Static,
                    InitArg::Motion => tumble::vio::Init::Motion,
                },
                ..VioOptions::default()
            };
            if midpoint {
                opts.imu.scheme = tumble::factors::imu_preint::Scheme::Midpoint;
            }
            let vin = vio_input(
                &input,
                cal.as_ref(),
                groundtruth.as_deref(),
                (simulate_camera, seed),
                mono,
                &frontend,
                &out,
            )?;
            if let (Some(st), Some(baseline)) = (&vin.stereo, vin.stereo_baseline_m()) {
                let matches: usize = st.features.iter().map(Vec::len).sum();
                println!(
                    "stereo: {matches} matches in cam1 ({baseline:.3} m from cam0) for the initialization (--mono to ignore)"
                );
            }
            let given = noise.as_deref().map(ImuNoise::read).transpose()?;
            match vin.apply_noise(given, &mut opts.imu) {
                tumble::vio::NoiseSource::Given => {}
                tumble::vio::NoiseSource::Input => println!("noise: the figures of the dataset's imu0/sensor.yaml"),
                tumble::vio::NoiseSource::Default => {
                    println!("noise: EuRoC's ADIS16448 figures (give --noise imu.yaml for yours)")
                }
            }
            if init_from_groundtruth {
                opts.init = ground_truth_init(&vin)?;
            }
            let bar = progress_bar(
                vin.frames.len() as u64,
                "vio [{bar:40}] {pos}/{len} frames {elapsed_precise} (eta {eta})",
            );
            let mut tick = |done: usize, _: usize| bar.set_position(done as u64);
            let (result, recorded) = tumble::vio::run_recorded(&vin, &opts, Some(&mut tick), rerun.as_deref())?;
            bar.finish_and_clear();
            let summary = tumble::vio::summarize(&vin, &opts, &result, bias_after);
            for w in &summary.warnings {
                eprintln!("warning: {w}");
            }
            println!("{}", summary.table());
            let mut files = tumble::vio::write_outputs(&out, &vin, &result, &summary)?;
            files.extend(recorded);
            println!("wrote {}", paths(&files));
        }
        Command::Eval { estimate, groundtruth, align, biases, rpe_distances, bias_after, max_gap, out } => {
            use tumble::io::{biases::read_biases, trajectory::read_trajectory};
            if let Some(d) = rpe_distances.iter().find(|d| !(d.is_finite() && **d > 0.0)) {
                return Err(format!("--rpe-distances: {d} is not a positive distance in metres").into());
            }
            if !(max_gap.is_finite() && max_gap > 0.0) {
                return Err(format!("--max-gap: {max_gap} is not a positive time in seconds").into());
            }
            let est = read_trajectory(&estimate)?;
            let gt = read_trajectory(&groundtruth)?;
            let beside = estimate.with_file_name("biases.csv");
            let biases = match biases {
                Some(b) => Some(read_biases(&b)?),
                None if beside.is_file() => {
                    println!("biases: {}", beside.display());
                    Some(read_biases(&beside)?)
                }
                None => None,
            };
            let opts = tumble::eval::EvalOptions {
                alignment: align,
                rpe_distances,
                bias_after_s: bias_after,
                max_gap_s: max_gap,
            };
            let ev = tumble::eval::evaluate(&est, biases.as_ref(), &gt, &opts)?;
            for w in &ev.metrics.warnings {
                eprintln!("warning: {w}");
            }
            print!("{}", ev.metrics.table());
            let dir = out.unwrap_or_else(|| estimate.with_file_name("eval"));
            let files = tumble::eval::write_report(&dir, &ev)?;
            println!("wrote {}", paths(&files));
        }
        Command::Track { input, camera, out, frontend } => {
            let ds = tumble::io::asl::read_asl(&input, &Default::default())?;
            let k = ds.cameras.iter().position(|c| c.name == camera).ok_or_else(|| {
                let names: Vec<&str> = ds.cameras.iter().map(|c| c.name.as_str()).collect();
                format!("{}: no camera '{camera}' (found: {})", ds.root.display(), names.join(", "))
            })?;
            run_frontend(&ds, k, &frontend, &out)?;
        }
        Command::Run {
            tumble: tumble_rec,
            still,
            vio,
            out,
            skip,
            calibration,
            noise,
            gravity,
            latitude,
            init_static,
            groundtruth,
            simulate_camera,
            read,
            rerun,
            frontend,
        } => {
            use tumble::pipeline::{run_chain, ChainInputs, ChainOptions, Progress, Stage};
            let skip = skip
                .iter()
                .map(|s| Stage::parse(s))
                .collect::<Result<Vec<_>, _>>()
                .map_err(|e| format!("--skip: {e}"))?;
            if tumble_rec.is_none() && still.is_none() && vio.is_none() && calibration.is_none() {
                return Err("nothing to do: give --tumble, --static and/or --vio (see `tumble run --help`)".into());
            }
            if !(init_static.is_finite() && init_static > 0.0) {
                return Err(format!("--init-static must be positive, got {init_static}").into());
            }
            let mut opts = ChainOptions { skip, rerun, ..Default::default() };
            opts.calib.init_static_s = init_static;
            opts.allan.progress = std::io::IsTerminal::is_terminal(&std::io::stderr());
            if tumble_rec.is_some() && !opts.skip.contains(&Stage::Calibrate) {
                opts.calib.gravity = gravity_arg(gravity, latitude, 0.0)?;
            }
            opts.audit.detection = opts.calib.clone();
            let mut inputs = ChainInputs::default();
            if let Some(p) = &tumble_rec {
                let input = CalibInput {
                    recording: Some(p.clone()),
                    accel: None,
                    gyro: None,
                    format: if read.gyro_file.is_some() { InputFormat::ImuTk } else { InputFormat::Auto },
                    read: read.clone(),
                };
                let (rec, _, _) = input.open()?;
                for w in &rec.warnings {
                    eprintln!("warning: {}: {w}", p.display());
                }
                inputs.tumble = Some(rec);
            }
            if let Some(p) = &still {
                let mut o = read.options();
                o.gyro_file = None;
                let rec = tumble::io::open_recording(p, &o)?;
                for w in &rec.warnings {
                    eprintln!("warning: {}: {w}", p.display());
                }
                inputs.still = Some(rec);
            }
            inputs.calibration = calibration.as_deref().map(tumble::calib::ImuCalibration::read).transpose()?;
            inputs.noise = noise.as_deref().map(tumble::io::ImuNoise::read).transpose()?;
            if let Some(p) = vio {
                let vio_dir = out.join(Stage::Vio.id());
                inputs.vio = Some(Box::new(move |cal| {
                    vio_input(&p, cal, groundtruth.as_deref(), (simulate_camera, 1), false, &frontend, &vio_dir)
                        .map_err(|e| e.to_string())
                }));
            }
            let bar = progress_bar(0, "vio [{bar:40}] {pos}/{len} frames {elapsed_precise} (eta {eta})");
            bar.set_draw_target(indicatif::ProgressDrawTarget::hidden());
            let report = run_chain(inputs, &opts, &out, &mut |p| match p {
                Progress::Stage(stage, line) => eprintln!("{}: {line}", stage.id()),
                Progress::Frames(done, total) => {
                    if bar.is_hidden() {
                        bar.set_draw_target(indicatif::ProgressDrawTarget::stderr());
                        bar.set_length(total as u64);
                    }
                    bar.set_position(done as u64);
                }
            })?;
            bar.finish_and_clear();
            for w in &report.warnings {
                eprintln!("warning: {w}");
            }
            print!("\n{}", report.summary());
        }
        Command::Demo { out, walk, seed } => {
            println!("tumble demo: the whole chain on simulated recordings with known truth (BMI055-like IMU)");
            let opts = tumble::demo::DemoOptions {
                walk: match walk {
                    DemoWalkArg::Room => tumble::sim::Scenario::Walk,
                    DemoWalkArg::Corridor => tumble::sim::Scenario::Corridor,
                },
                seed,
                ..Default::default()
            };
            let report = tumble::demo::run(&opts, &out, &mut |stage| eprintln!("{stage}"))?;
            print!("{}", report.table());
        }
        Command::Solve {
            file,
            method,
            max_iterations,
            initial_lambda,
            min_lambda_decrease,
            function_tolerance,
            repair_information,
            edge_error,
            verbose,
            plot,
        } => {
            let defaults = LmOptions::default();
            let options = LmOptions {
                method: match method {
                    MethodArg::Lm => Method::LevenbergMarquardt,
                    MethodArg::Gn => Method::GaussNewton,
                },
                max_iterations,
                function_tolerance,
                initial_lambda: initial_lambda.unwrap_or(defaults.initial_lambda),
                min_lambda_decrease: min_lambda_decrease.unwrap_or(defaults.min_lambda_decrease),
                ..LmOptions::default()
            };
            let is_g2o = file.extension().is_some_and(|e| e.eq_ignore_ascii_case("g2o"));
            if plot.is_some() && !is_g2o {
                return Err(format!("--plot draws pose graphs (.g2o); {} is a BAL problem", file.display()).into());
            }
            // The file's poses (for the plot), the cost there (in the error solved
            // last), the solution and its summary.
            let (values, initial_cost, solved, summary) = if is_g2o {
                let opts = |edge_error| g2o::G2oOptions {
                    bad_information: if repair_information {
                        g2o::BadInformation::Repair
                    } else {
                        g2o::BadInformation::Refuse
                    },
                    edge_error,
                };
                let pg = g2o::read_g2o(
                    &file,
                    &opts(match edge_error {
                        EdgeErrorArg::Log => g2o::EdgeError::Log,
                        EdgeErrorArg::Ceres | EdgeErrorArg::CeresThenLog => g2o::EdgeError::CeresQuaternion,
                    }),
                )?;
                for w in &pg.warnings {
                    eprintln!("warning: {w}");
                }
                println!("{}: {:?} pose graph, {} vertices, {} edges", file.display(), pg.kind, pg.vertices, pg.edges);
                if matches!(edge_error, EdgeErrorArg::CeresThenLog) {
                    let log = g2o::read_g2o(&file, &opts(g2o::EdgeError::Log))?;
                    let (solved, first, second) =
                        tumble::posegraph::solve_two_stage(&pg.graph, &log.graph, &pg.values, &options)?;
                    println!("first stage, Ceres' quaternion edge error:");
                    if verbose {
                        print_log(&first);
                    }
                    println!("{first}");
                    println!(
                        "both stages: {} iterations, {:.3} s; second stage, the log edge error from the first's solution:",
                        first.iterations + second.iterations,
                        first.time_total + second.time_total
                    );
                    let start_cost = log.graph.cost(&pg.values)?;
                    (pg.values, start_cost, solved, second)
                } else {
                    let (solved, summary) = Optimizer::new(options).optimize(&pg.graph, &pg.values)?;
                    (pg.values, summary.initial_cost, solved, summary)
                }
            } else {
                let p = bal::read_bal(&file)?;
                println!(
                    "{}: BAL problem, {} cameras, {} points, {} observations",
                    file.display(),
                    p.cameras,
                    p.points,
                    p.observations
                );
                let options = LmOptions { eliminate: vec!['l'], ..options };
                let (solved, summary) = Optimizer::new(options).optimize(&p.graph, &p.values)?;
                (p.values, summary.initial_cost, solved, summary)
            };
            if verbose {
                print_log(&summary);
            }
            println!("{summary}");
            println!("final chi2 {:.6}", 2.0 * summary.final_cost);
            if let Some(png) = plot {
                let name = file.file_stem().map_or_else(String::new, |s| s.to_string_lossy().into_owned());
                let title = format!("{name}: χ² {:.1} → {:.1}", 2.0 * initial_cost, 2.0 * summary.final_cost);
                tumble::posegraph::plot_top_view(&values, &solved, &title, &png)?;
                println!("wrote {}", png.display());
            }
        }
    }
    Ok(())
}

/// The VIO's input from the command line: an EqVIO .csv, or an ASL folder with
/// tracks, with images (run through the frontend into `out`), or with only a
/// ground truth (`simulate_camera`).
/// Options of `tumble audit --vio`.
struct VioAuditArgs {
    pixel_sigma: f64,
    gravity: f64,
    offset_step_ms: f64,
    alpha: f64,
    max_effects: usize,
    candidates: Vec<tumble::audit::Effect>,
    noise: Option<tumble::vio::ImuNoise>,
}

/// `tumble audit --vio`: fit the time offsets of a VIO input and write the audit.
fn audit_vio_command(
    path: &std::path::Path,
    cal: Option<&tumble::calib::ImuCalibration>,
    args: &VioAuditArgs,
    frontend: &FrontendArgs,
    out: &std::path::Path,
) -> Result<(), Box<dyn std::error::Error>> {
    use tumble::audit::vio::{audit_vio, VioAuditOptions};
    if !(args.pixel_sigma.is_finite() && args.pixel_sigma > 0.0) {
        return Err(format!("--pixel-sigma must be positive, got {}", args.pixel_sigma).into());
    }
    if !(args.offset_step_ms.is_finite() && args.offset_step_ms > 0.0 && args.offset_step_ms <= 20.0) {
        return Err(format!("--offset-step-ms must be in (0, 20], got {}", args.offset_step_ms).into());
    }
    let vin = vio_input(path, cal, None, (false, 0), false, frontend, out)?;
    let mut vopts =
        tumble::vio::VioOptions { pixel_sigma: args.pixel_sigma, gravity: args.gravity, ..Default::default() };
    vin.apply_noise(args.noise, &mut vopts.imu);
    let mut opts = VioAuditOptions::new(vopts);
    opts.alpha = args.alpha;
    opts.max_effects = args.max_effects;
    opts.step_s = 1e-3 * args.offset_step_ms;
    if !args.candidates.is_empty() {
        opts.candidates = args.candidates.clone();
    }
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
    let files = tumble::audit::vio::write(&result, cal, out)?;
    println!("{}", result.verdict());
    println!("audited in {:.1} s; wrote {} in {}", t.elapsed().as_secs_f64(), files.join(", "), out.display());
    Ok(())
}

fn vio_input(
    input: &std::path::Path,
    cal: Option<&tumble::calib::ImuCalibration>,
    groundtruth: Option<&std::path::Path>,
    (simulate_camera, seed): (bool, u64),
    mono: bool,
    frontend: &FrontendArgs,
    out: &std::path::Path,
) -> Result<tumble::vio::VioInput, Box<dyn std::error::Error>> {
    use tumble::vio::VioInput;
    let is_csv = input.extension().is_some_and(|e| e.eq_ignore_ascii_case("csv"));
    let mut vin = if is_csv {
        if cal.is_some() {
            eprintln!("warning: EqVIO files hold corrected samples already; the calibration is not applied");
        }
        tumble::vio::read_eqvio(input, groundtruth)?
    } else {
        let ds = tumble::io::asl::read_asl(input, &Default::default())?;
        if simulate_camera {
            let cam = tumble::sim::CameraSettings::default();
            println!("camera: simulated (EuRoC cam0 model) along the ground truth, seed {seed}");
            VioInput::from_dataset_with_simulated_camera(ds, cal, &cam, seed)?
        } else {
            let needs_frontend = ds
                .cameras
                .first()
                .is_some_and(|c| !ds.root.join(&c.name).join("tracks.csv").is_file() && !c.frames.is_empty());
            let tracks = match needs_frontend {
                true => Some(run_frontend(&ds, 0, frontend, out)?),
                false => None,
            };
            // Stereo matches next to cam0's tracks.csv (not with the tracks
            // the frontend just made).
            let stereo = !mono && tracks.is_none();
            VioInput::from_dataset(ds, cal, tracks, stereo)?
        }
    };
    if let (Some(g), false) = (groundtruth, is_csv) {
        vin.groundtruth = Some(tumble::io::trajectory::read_asl_groundtruth(g)?);
    }
    vin.name = input.display().to_string();
    Ok(vin)
}

/// Gravity from `--gravity`, or WGS-84 normal gravity at `--latitude`/`--height`,
/// or standard gravity with a note.
fn gravity_arg(gravity: Option<f64>, latitude: Option<f64>, height: f64) -> Result<f64, String> {
    Ok(match (gravity, latitude) {
        (Some(g), _) => g,
        (None, Some(lat)) => {
            if !(-90.0..=90.0).contains(&lat) || !height.is_finite() {
                return Err(format!("--latitude must be within ±90° and --height finite, got {lat}, {height}"));
            }
            tumble::calib::normal_gravity(lat, height)
        }
        (None, None) => {
            eprintln!("note: no --gravity or --latitude given; using standard gravity 9.80665 m/s²");
            tumble::io::STANDARD_GRAVITY
        }
    })
}

/// `FIRST:LAST` (integer steps) or a comma-separated list of positive multipliers.
fn parse_multipliers(s: &str) -> Result<Vec<f64>, String> {
    let bad = || format!("--multipliers: expected FIRST:LAST or a comma list of positive numbers, got `{s}`");
    let v: Vec<f64> = if let Some((a, b)) = s.split_once(':') {
        let (a, b): (u32, u32) = (a.trim().parse().map_err(|_| bad())?, b.trim().parse().map_err(|_| bad())?);
        (a..=b).map(f64::from).collect()
    } else {
        s.split(',').map(|x| x.trim().parse::<f64>().map_err(|_| bad())).collect::<Result<_, _>>()?
    };
    if v.is_empty() || v.iter().any(|x| !(x.is_finite() && *x > 0.0)) {
        return Err(bad());
    }
    Ok(v)
}

/// `A:B` seconds from the start of the recording (either end may be empty).
fn parse_span(s: &str) -> Result<(f64, f64), String> {
    let (a, b) = s.split_once(':').ok_or_else(|| format!("--span: expected START:END in seconds, got `{s}`"))?;
    let num = |v: &str, default: f64| -> Result<f64, String> {
        if v.trim().is_empty() {
            return Ok(default);
        }
        v.trim()
            .parse::<f64>()
            .ok()
            .filter(|x| x.is_finite())
            .ok_or_else(|| format!("--span: `{v}` is not a number of seconds"))
    };
    let (a, b) = (num(a, 0.0)?, num(b, f64::INFINITY)?);
    if b <= a {
        return Err(format!("--span: end {b} is not after start {a}"));
    }
    Ok((a, b))
}

/// `START,LENGTH` seconds of one `--pause` (the simulator checks the values).
fn parse_pause(s: &str) -> Result<[f64; 2], String> {
    let bad = || format!("--pause: expected START,LENGTH in seconds, got `{s}`");
    let (a, b) = s.split_once(',').ok_or_else(bad)?;
    let num = |v: &str| v.trim().parse::<f64>().ok().filter(|x| x.is_finite()).ok_or_else(bad);
    Ok([num(a)?, num(b)?])
}

fn main() -> ExitCode {
    // Die quietly on a closed pipe (`tumble inspect … | head`) instead of panicking in println!.
    #[cfg(unix)]
    // SAFETY: restoring the default disposition of SIGPIPE before any thread starts.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
    // Large buffers always mmap'd, so what one stage frees goes back to the
    // system (glibc otherwise raises its mmap threshold after the first free
    // and keeps the memory in its heap: the Allan stage's axes would add up).
    #[cfg(target_os = "linux")]
    // SAFETY: called before any other thread starts; only tunes the allocator.
    unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, 1 << 20);
    }
    match run(Cli::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}

/// The ground-truth state at the first frame, as an initialization (evaluation aid).
fn ground_truth_init(v: &tumble::vio::VioInput) -> Result<tumble::vio::Init, String> {
    let gt = v.groundtruth.as_ref().ok_or("--init-from-groundtruth needs ground truth (--groundtruth FILE)")?;
    let t_first = v.frames.first().ok_or("no frames")?.t;
    let want = v.t0_ns + (t_first * 1e9).round() as i64;
    let k = gt.t_ns.partition_point(|&s| s < want);
    if k >= gt.len() {
        return Err("the ground truth ends before the first frame".into());
    }
    let t = (gt.t_ns[k] - v.t0_ns) as f64 * 1e-9;
    let vel = gt.v.as_ref().map_or([0.0; 3], |x| x[k]);
    let ba = gt.bias_accel.as_ref().map_or([0.0; 3], |x| x[k]);
    let bg = gt.bias_gyro.as_ref().map_or([0.0; 3], |x| x[k]);
    Ok(tumble::vio::Init::Given { q: gt.q[k], p: gt.p[k], v: vel, bias_accel: ba, bias_gyro: bg, t })
}
