//! One entry point for every IMU recording a command accepts: an ASL dataset
//! folder (or its `mav0/`), a ROS 1 bag (`.bag`), a ROS 2 MCAP file (`.mcap`),
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
    /// Bags and MCAP files: the `sensor_msgs/Imu` topic (needed when there are several).
    pub topic: Option<String>,
}

/// Open a recording: a folder is read as ASL, `.bag` / `.mcap` as ROS, any
/// other file as text (`.gz` allowed).
pub fn open_recording(path: &Path, opts: &RecordingOptions) -> Result<ImuRecording, InputError> {
    if path.is_dir() {
        let fmt = ImuTextFormat { validate: opts.format.validate.clone(), ..ImuTextFormat::default() };
        return Ok(read_asl(path, &fmt)?.imu);
    }
    if !path.exists() {
        return Err(InputError::file(path, "does not exist"));
    }
    let ext = path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
    match ext.as_deref() {
        Some("bag") => return super::rosbag::read_ros1_bag_imu(path, opts.topic.as_deref(), &opts.format.validate),
        Some("mcap") => return super::rosbag::read_mcap_imu(path, opts.topic.as_deref(), &opts.format.validate),
        _ => {}
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
