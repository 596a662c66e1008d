//! The model types every layer above shares: the IMU's deterministic
//! calibration (paper eq. 1 and 16, with the audit's effects), its noise in
//! Kalibr's form, and the full error model the simulator draws from. Nothing
//! here reads files, simulates or estimates: `io` reads and writes these
//! types, `sim` samples them, the pipelines estimate them.

pub mod calibration;
pub mod datasheet;
pub mod imu_model;
pub mod noise;

/// Standard gravity \[m/s²\] (the unit `g`).
pub const STANDARD_GRAVITY: f64 = 9.80665;

/// Gravity anywhere a person can record an IMU \[m/s²\]: normal gravity runs
/// from 9.780 (equator) to 9.832 (poles) at sea level and falls 3.1e-6 per metre up.
pub const EARTH_GRAVITY_M_S2: std::ops::Range<f64> = 9.7..9.9;

/// A model value that cannot be used (the message names the key).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{0}")]
pub struct ModelError(pub String);

crate::error::message_error_conversions!(ModelError, ModelError);
