//! Flags several commands share, and the terminal's progress bars.

use clap::Args;
use std::path::PathBuf;
use tumble::io::recording::RecordingSource;
use tumble::io::validate::Duplicates;
use tumble::io::{AccelUnit, GyroUnit, ImuColumns, RecordingOptions, TimeUnit};

/// How to read an IMU recording given on the command line.
#[derive(Args, Clone)]
pub struct RecordingArgs {
    /// Text files: column names in file order, from t, gx, gy, gz, ax, ay, az, temp and _ (skip).
    #[arg(long, default_value = "t,gx,gy,gz,ax,ay,az", value_parser = |s: &str| ImuColumns::parse(s))]
    pub columns: ImuColumns,
    /// Text files: unit of the time column (s, ms, us, ns; default ns, imu_tk files s).
    #[arg(long, value_parser = |s: &str| TimeUnit::parse(s).ok_or("use s, ms, us or ns"))]
    pub time_unit: Option<TimeUnit>,
    /// Text files: gyro unit: rad/s (default), deg/s, counts (kept raw) or counts:SCALE[:OFFSET] (SCALE in rad/s per count).
    #[arg(long, value_parser = |s: &str| GyroUnit::parse(s))]
    pub gyro_unit: Option<GyroUnit>,
    /// Text files: accelerometer unit: m/s2 (default), g, counts or counts:SCALE[:OFFSET] (SCALE in m/s² per count).
    #[arg(long, value_parser = |s: &str| AccelUnit::parse(s))]
    pub accel_unit: Option<AccelUnit>,
    /// imu_tk layout: the gyro file (`t x y z`); the recording argument is then the accelerometer file.
    #[arg(long)]
    pub gyro_file: Option<PathBuf>,
    #[command(flatten)]
    pub topics: TopicArgs,
    /// Nominal sample rate [Hz] (estimated from the timestamps when absent).
    #[arg(long)]
    pub rate: Option<f64>,
    /// Refuse duplicated timestamps instead of re-stamping at the nominal rate.
    #[arg(long)]
    pub strict_timestamps: bool,
    /// Skip the check that values at rest look like rad/s and m/s².
    #[arg(long)]
    pub no_unit_check: bool,
}

impl RecordingArgs {
    /// The reader's options: what the flags say, the readers' defaults elsewhere.
    pub fn options(&self) -> RecordingOptions {
        let mut o = RecordingOptions::default();
        o.format.columns = self.columns.clone();
        o.format.time_unit = self.time_unit.unwrap_or(TimeUnit::Ns);
        o.format.gyro_unit = self.gyro_unit.unwrap_or(GyroUnit::RadPerS);
        o.format.accel_unit = self.accel_unit.unwrap_or(AccelUnit::MetersPerS2);
        o.format.validate.nominal_rate = self.rate;
        o.format.validate.check_units = !self.no_unit_check;
        if self.strict_timestamps {
            o.format.validate.duplicates = Duplicates::Error;
        }
        o.gyro_file = self.gyro_file.clone();
        o.topics = self.topics.topics();
        o
    }

    /// Which of the layout's settings the user gave (imu_tk pairs default the rest).
    fn declared(&self) -> tumble::io::recording::Declared {
        tumble::io::recording::Declared {
            time_unit: self.time_unit.is_some(),
            units: self.accel_unit.is_some() || self.gyro_unit.is_some(),
        }
    }
}

/// Which topics of a ROS recording make the IMU.
#[derive(Args, Clone)]
pub struct TopicArgs {
    /// ROS recordings (.bag, .mcap, .db3, rosbag2 folder): the sensor_msgs/Imu topic (needed when there are several).
    #[arg(long)]
    pub topic: Option<String>,
    /// ROS recordings with split streams: the accelerometer's sensor_msgs/Imu topic (with --gyro-topic).
    #[arg(long)]
    pub accel_topic: Option<String>,
    /// ROS recordings with split streams: the gyro's sensor_msgs/Imu topic (with --accel-topic).
    #[arg(long)]
    pub gyro_topic: Option<String>,
    /// ROS recordings: a sensor_msgs/Temperature topic joined by time (default: the only one, if one).
    #[arg(long)]
    pub temperature_topic: Option<String>,
}

impl TopicArgs {
    /// The library's topic choice.
    pub fn topics(&self) -> tumble::io::ros::ImuTopics {
        tumble::io::ros::ImuTopics {
            imu: self.topic.clone(),
            accel: self.accel_topic.clone(),
            gyro: self.gyro_topic.clone(),
            temperature: self.temperature_topic.clone(),
        }
    }
}

/// Settings of the visual frontend (`track`, and `vio` on image folders).
#[derive(Args, Clone)]
pub struct FrontendArgs {
    /// Features kept per frame.
    #[arg(long, default_value_t = 150)]
    pub max_features: usize,
    /// Smallest distance between two features [px].
    #[arg(long, default_value_t = 30.0)]
    pub min_distance: f64,
    /// Largest forward–backward KLT disagreement [px].
    #[arg(long, default_value_t = 0.5)]
    pub fb_threshold: f64,
    /// RANSAC epipolar threshold [px of the undistorted image].
    #[arg(long, default_value_t = 1.0)]
    pub ransac_threshold: f64,
    /// Equalize images (CLAHE) before tracking: for dark or low-contrast sequences (costs track accuracy).
    #[arg(long)]
    pub equalize: bool,
    /// Also match cam0's features into cam1 (same time; epipolar check with both
    /// sensor.yaml extrinsics) and write tracks_cam1.csv with the same track ids.
    #[arg(long)]
    pub stereo: bool,
    /// Start KLT at each feature's old place instead of where the gyro's
    /// rotation since the last frame moves it (imu0's samples and the camera's T_BS).
    #[arg(long)]
    pub no_gyro_prediction: bool,
    /// Plain frame-to-frame KLT: do not hold each track to the patch where it
    /// began (the default aligns that patch to every new image by an affine
    /// warp, so that KLT's small errors do not add up along a track).
    #[arg(long)]
    pub no_anchors: bool,
}

impl FrontendArgs {
    /// The frontend's options.
    pub fn options(&self) -> tumble::vio::frontend::FrontendOptions {
        tumble::vio::frontend::FrontendOptions {
            max_features: self.max_features,
            min_distance: self.min_distance,
            fb_threshold: self.fb_threshold,
            ransac_threshold: self.ransac_threshold,
            equalize: self.equalize,
            stereo: self.stereo,
            gyro_prediction: !self.no_gyro_prediction,
            anchored: !self.no_anchors,
            ..Default::default()
        }
    }
}

/// Input layouts of `calibrate`, `apply` and `audit`.
#[derive(Clone, Copy, clap::ValueEnum, PartialEq)]
pub enum InputFormat {
    /// By the path: ASL folder, .bag/.mcap, or text with --columns.
    Auto,
    /// imu_tk's two files `t x y z` (time in s; raw counts or SI, recognised from the data).
    #[value(alias = "imu_tk")]
    ImuTk,
}

/// The recording a calibration command reads.
#[derive(Args, Clone)]
pub struct CalibInput {
    /// ASL folder, ROS bag/MCAP or text file (or give --accel and --gyro).
    pub recording: Option<PathBuf>,
    /// imu_tk layout: the accelerometer file.
    #[arg(long, requires = "gyro")]
    pub accel: Option<PathBuf>,
    /// imu_tk layout: the gyro file.
    #[arg(long, requires = "accel")]
    pub gyro: Option<PathBuf>,
    /// Input layout.
    #[arg(long, value_enum, default_value = "auto")]
    pub format: InputFormat,
    #[command(flatten)]
    pub read: RecordingArgs,
}

impl CalibInput {
    /// The recording these flags name (the library resolves imu_tk pairs).
    pub fn source(&self) -> Result<RecordingSource, tumble::io::recording::SourceError> {
        RecordingSource::new(
            self.recording.clone(),
            self.accel.clone().zip(self.gyro.clone()),
            self.format == InputFormat::ImuTk,
            self.read.options(),
            self.read.declared(),
        )
    }
}

/// Paths for a "wrote …" line.
pub fn paths(files: &[PathBuf]) -> String {
    files.iter().map(|f| f.display().to_string()).collect::<Vec<_>>().join(", ")
}

/// A progress bar on standard error (hidden when it is not a terminal).
pub fn progress_bar(len: u64, template: &str) -> indicatif::ProgressBar {
    let bar = indicatif::ProgressBar::new(len);
    bar.set_style(indicatif::ProgressStyle::with_template(template).expect("static template").progress_chars("=> "));
    bar
}

/// The bar of a frontend run over `n` images.
pub fn track_bar(n: usize) -> indicatif::ProgressBar {
    progress_bar(n as u64, "track [{bar:40}] {pos}/{len} images {elapsed_precise} (eta {eta})")
}

/// Print what a frontend run reports.
pub fn print_frontend(report: &tumble::vio::frontend::FrontendReport) {
    for w in &report.stats.warnings {
        eprintln!("warning: {w}");
    }
    println!("frontend: {}", report.stats.line());
    if let Some(s) = &report.stats.stereo {
        println!("frontend: {}", s.line());
    }
    println!("wrote {}", paths(&report.files));
}

/// Open a VIO input with a bar for the frontend, printing what opening it did.
pub fn open_input(
    path: &std::path::Path,
    source: &tumble::vio::VioSource,
) -> Result<tumble::vio::VioInput, tumble::vio::OpenError> {
    let bar = track_bar(0);
    let opened = tumble::vio::VioInput::open(path, source, &mut |done, total| {
        bar.set_length(total as u64);
        bar.set_position(done as u64)
    })?;
    bar.finish_and_clear();
    for n in &opened.notes {
        println!("{n}");
    }
    for w in &opened.warnings {
        eprintln!("warning: {w}");
    }
    if let Some(f) = &opened.frontend {
        print_frontend(f);
    }
    Ok(opened.input)
}

/// `--inputs`: every tumble the file describes (`tumble:` then `tumbles:`),
/// opened, with its name (its file name, numbered when two are alike).
pub fn read_tumbles(
    inputs: &std::path::Path,
) -> Result<(Vec<tumble::io::ImuRecording>, Vec<String>), Box<dyn std::error::Error>> {
    let described = tumble::io::recordings::RunRecordings::read(inputs)?;
    if described.still.is_some() {
        eprintln!("note: {}: `static:` is not used here (give it to `tumble allan`)", inputs.display());
    }
    let mut recs = Vec::new();
    let mut names: Vec<String> = Vec::new();
    for (i, spec) in described.all_tumbles().into_iter().enumerate() {
        println!("tumble {}: {}", i + 1, spec.describe());
        let rec = spec.source()?.open()?;
        for w in &rec.warnings {
            eprintln!("warning: {}: {w}", spec.path.display());
        }
        let name = spec.name();
        names.push(if names.contains(&name) { format!("{name} ({})", i + 1) } else { name });
        recs.push(rec);
    }
    Ok((recs, names))
}
