//! Reading users' files. Every parser reports errors with file and line.

pub mod asl;
pub mod bal;
pub mod biases;
pub mod calibration;
pub mod convert;
pub mod datasets;
pub mod g2o;
#[cfg(feature = "opencv")]
pub mod image;
pub mod imu;
pub mod imu_text;
pub(crate) mod imu_write;
pub(crate) mod kalibr;
pub(crate) mod mem;
pub mod noise;
pub mod phone;
pub mod recording;
pub mod recordings;
pub mod ros;
pub mod split;
pub(crate) mod staging;
pub mod table;
pub mod target;
pub(crate) mod tokens;
pub mod trajectory;
pub mod validate;
pub mod yaml;

pub use imu::{AxisStats, ImuRecording, RecordingStats, Stored};
pub use imu_text::{
    read_imu_text, read_imu_tk, recording_from_samples, AccelUnit, GyroUnit, ImuColumns, ImuTextFormat,
    STANDARD_GRAVITY,
};
pub use imu_write::write_asl_imu;
pub use noise::{ImuNoise, ImuNoiseAxes};
pub use recording::{open_recording, recognise_imu_tk_units, RecordingOptions};
pub use table::TimeUnit;
