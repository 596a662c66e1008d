//! One entry point for every IMU recording a command accepts: an ASL dataset
//! folder (or its `mav0/`), a ROS recording (ROS 1 `.bag`, MCAP `.mcap`,
//! rosbag2 `.db3` or a rosbag2 folder with `metadata.yaml`),
//! a text file with a declared format, or imu_tk's pair of accelerometer and
//! gyro files.

use super::asl::read_asl;
use super::imu::ImuRecording;
use super::imu_text::{read_imu_text, read_imu_tk, ImuTextFormat};
use crate::error::InputError;
use std::path::{Path, PathBuf};

/// Where the samples are and how to read them.
#[derive(Debug, Clone, Default)]
pub struct RecordingOptions {
    /// Format of text files (ignored for ASL folders except its checks).
    pub format: ImuTextFormat,
    /// With imu_tk's two-file layout: the gyro file (the main path is then the accelerometer file).
    pub gyro_file: Option<PathBuf>,
    /// ROS recordings: which topics make the IMU (see [`super::ros`]).
    pub topics: super::ros::ImuTopics,
}

/// Open a recording: a ROS recording (rosbag2 folder, `.bag`, `.mcap`,
/// `.db3`) by its topics, a phone logger's export folder (see
/// [`super::phone`]), another folder as ASL, any other file as text
/// (`.gz` allowed).
pub fn open_recording(path: &Path, opts: &RecordingOptions) -> Result<ImuRecording, InputError> {
    // A bad option is the command line's fault, reported with the file it was meant for.
    opts.format.validate.check().map_err(|e| InputError::file(path, e))?;
    if !path.exists() {
        return Err(InputError::file(path, "does not exist"));
    }
    if let Some(storage) = super::ros::Storage::of(path)? {
        return super::ros::read_ros_imu(&storage, &opts.topics, &opts.format.validate);
    }
    if path.is_dir() && super::phone::PhoneLogger::of(path).is_some() {
        return super::phone::read_phone_folder(path, &opts.format.validate);
    }
    if path.is_dir() {
        let fmt = ImuTextFormat { validate: opts.format.validate.clone(), ..ImuTextFormat::default() };
        return Ok(read_asl(path, &fmt)?.imu);
    }
    match &opts.gyro_file {
        Some(g) => read_imu_tk(
            path,
            g,
            opts.format.time_unit,
            opts.format.accel_unit,
            opts.format.gyro_unit,
            &opts.format.validate,
        ),
        None => read_imu_text(path, &opts.format),
    }
}

/// Which text-layout settings the user declared (the rest take the layout's
/// defaults: imu_tk pairs are stamped in seconds and recognised as SI or raw
/// counts from the data).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Declared {
    /// The time unit was given.
    pub time_unit: bool,
    /// The accelerometer or gyro unit was given.
    pub units: bool,
}

/// Why a recording's paths and layout do not fit together.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SourceError {
    /// Both a recording and an imu_tk pair were named.
    #[error("give either a recording or --accel/--gyro, not both")]
    Both,
    /// Nothing was named.
    #[error("no input: give a recording (ASL folder, bag, text) or --accel and --gyro")]
    Nothing,
    /// imu_tk's layout without its gyro file.
    #[error("--format imu_tk needs --accel FILE --gyro FILE (or --gyro-file)")]
    NoGyroFile,
    /// A reading option cannot work (a recordings file's key, or its flag).
    #[error(transparent)]
    Options(#[from] crate::OptionError),
}

/// A recording named on a command line: one path (ASL folder, bag, MCAP,
/// text) or imu_tk's pair of accelerometer and gyro files, with the options
/// to read it.
#[derive(Debug, Clone)]
pub struct RecordingSource {
    /// The recording, or imu_tk's accelerometer file.
    pub path: PathBuf,
    /// How to read it (imu_tk's gyro file in [`RecordingOptions::gyro_file`]).
    pub options: RecordingOptions,
    /// imu_tk units to be recognised from the data (see [`RecordingSource::open`]).
    auto_units: bool,
}

impl RecordingSource {
    /// The recording `recording`, or the imu_tk pair `(accel, gyro)`; `imu_tk`
    /// says the path is imu_tk's accelerometer file (its gyro file then in
    /// `options.gyro_file`). An imu_tk pair is stamped in seconds unless the
    /// time unit was `declared`, and its units are recognised from the data
    /// unless declared.
    pub fn new(
        recording: Option<PathBuf>,
        pair: Option<(PathBuf, PathBuf)>,
        imu_tk: bool,
        mut options: RecordingOptions,
        declared: Declared,
    ) -> Result<RecordingSource, SourceError> {
        let imu_tk = imu_tk || pair.is_some();
        let path = match (recording, pair) {
            (Some(_), Some(_)) => return Err(SourceError::Both),
            (Some(p), None) => p,
            (None, Some((a, g))) => {
                options.gyro_file = Some(g);
                a
            }
            (None, None) => return Err(SourceError::Nothing),
        };
        if imu_tk {
            if options.gyro_file.is_none() {
                return Err(SourceError::NoGyroFile);
            }
            if !declared.time_unit {
                options.format.time_unit = super::TimeUnit::S;
            }
            if !declared.units {
                options.format.accel_unit = super::AccelUnit::Counts { scale: None, offset: 0.0 };
                options.format.gyro_unit = super::GyroUnit::Counts { scale: None, offset: 0.0 };
            }
        }
        Ok(RecordingSource { path, options, auto_units: imu_tk && !declared.units })
    }

    /// Read the recording. imu_tk files without declared units are SI when
    /// the accelerometer reads between 7 and 13 m/s² over its first 5 s (at
    /// rest, ≈ 1 g), raw counts otherwise.
    pub fn open(&self) -> Result<ImuRecording, InputError> {
        let mut rec = open_recording(&self.path, &self.options)?;
        if self.auto_units {
            recognise_imu_tk_units(&mut rec);
        }
        Ok(rec)
    }
}

/// imu_tk's units, recognised from the data: a recording read as raw counts
/// whose accelerometer reads between 7 and 13 over its first 5 s (at rest,
/// ≈ 1 g in m/s²) is in SI units (gyro in rad/s), else it stays in counts.
pub fn recognise_imu_tk_units(rec: &mut ImuRecording) {
    if rec.is_empty() {
        return;
    }
    let n = rec.len().min(((rec.mean_rate() * 5.0) as usize).max(10));
    let g = super::validate::norm(super::validate::mean3(&rec.accel[..n]));
    if (7.0..13.0).contains(&g) {
        rec.accel_units = super::Stored::Si;
        rec.gyro_units = super::Stored::Si;
    }
}
