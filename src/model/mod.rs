//! The model types every layer above shares: the IMU's deterministic
//! calibration (paper eq. 1 and 16, with the audit's effects), its noise in
//! Kalibr's form, and the full error model the simulator draws from. Nothing
//! here reads files, simulates or estimates: `io` reads and writes these
//! types, `sim` samples them, the pipelines estimate them.

use crate::error::OptionError;

pub mod calibration;
pub mod consensus;
pub mod datasheet;
pub mod geometry;
pub mod imu_model;
mod imu_samples;
pub mod noise;
pub mod numeric;
pub mod split;
pub mod tag36h11;
pub mod target;

pub use imu_samples::ImuData;

/// Standard gravity \[m/s²\] (the unit `g`).
pub const STANDARD_GRAVITY: f64 = 9.80665;

/// Gravity anywhere a person can record an IMU \[m/s²\]: normal gravity runs
/// from 9.780 (equator) to 9.832 (poles) at sea level and falls 3.1e-6 per metre up.
pub const EARTH_GRAVITY_M_S2: std::ops::Range<f64> = 9.7..9.9;

impl OptionError {
    /// Ok when `gravity` \[m/s²\] is a local gravity on Earth
    /// ([`EARTH_GRAVITY_M_S2`]); else an error on `--gravity`
    /// that ends with `why` it matters.
    pub fn earth_gravity(gravity: f64, why: &str) -> Result<(), OptionError> {
        let earth = EARTH_GRAVITY_M_S2;
        if earth.contains(&gravity) {
            return Ok(());
        }
        Err(OptionError::new(
            "--gravity",
            format!("must be the local gravity on Earth in m/s² ({}–{}), got {gravity}: {why}", earth.start, earth.end),
        ))
    }
}

/// A parameter counts as determined by the data when its σ from the data is
/// below this fraction of its prior σ (the data carry at least 3× the
/// prior's information): the IMU calibration's misalignments, the VIO's
/// online camera calibration.
pub const DETERMINED_FRACTION: f64 = 0.5;

/// A model value that cannot be used (the message names the key).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{0}")]
pub struct ModelError(pub String);

crate::error::message_error_conversions!(ModelError, ModelError);
