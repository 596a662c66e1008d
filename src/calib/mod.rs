//! Turntable-free calibration of a MEMS IMU from one hand-tumbled recording
//! (paper §2; the method of imu_tk, Tedaldi et al. 2014), on the solver.
//!
//! 1. [`detect`]: the initial rest (found in the data unless given), then static
//!    intervals where the sliding accelerometer and gyro variances are below
//!    `k · σ²(initial rest)`, for a sweep of `k`;
//! 2. accelerometer: one [`GravityNormFactor`](tumble_factors::GravityNormFactor)
//!    per interval (9 parameters; misalignments with a prior, see `observability`);
//! 3. gyroscope: bias from the initial rest (or estimated), then one
//!    [`IntegratedRotationFactor`](tumble_factors::IntegratedRotationFactor) per
//!    pair of consecutive intervals (9 parameters, from several starts); for each
//!    `k` both fits, the most certain calibration kept;
//! 4. [`model`](crate::model): the paper's `T`, `K`, `b` with standard deviations from the
//!    solver's covariance (inflated by χ²/dof when the residuals exceed the noise),
//!    imu_tk's convention, correction of raw samples;
//! 5. `verdict`: `ok`, `weak` (with reasons) or `failed` (an error carrying the
//!    diagnosis; nothing loadable is written);
//! 6. `report`: `calibration.json` / `.yaml`, imu_tk `.calib` files, a PNG of the detection.
//!
//! ```
//! use tumble::calib::{calibrate, CalibOptions};
//! use tumble::sim::{simulate, Scenario, SimConfig};
//! let sim = simulate(Scenario::Tumble, &SimConfig::default(), 1).unwrap();
//! let rec = sim.imu.to_recording();
//! let result = calibrate(&rec, &CalibOptions { gravity: 9.81, ..Default::default() }).unwrap();
//! let k_a = result.calibration.accel.k;
//! assert!((k_a.x - sim.config.imu.accel.scale[0]).abs() < 5.0 * result.calibration.accel.k_std.x);
//! ```

pub(crate) mod apply;
#[doc(hidden)]
pub mod detect;
mod fit;
mod floor;
pub(crate) mod gravity;
pub(crate) mod observability;
mod options;
pub(crate) mod report;
mod result;
mod several;
mod several_report;
pub(crate) mod solve;
mod split;
pub(crate) mod verdict;

pub use crate::io::calibration::read_imu_tk_calib;
pub use crate::model::calibration::{Corrector, EffectTerm, ImuCalibration, ModelEffects, TimeOffsets, Triad, Units};
pub use apply::{apply_calibration, write_like_input, Applied, ApplyError};
pub(crate) use fit::{accel_triad, gyro_triad};
pub use gravity::{local_gravity, normal_gravity, LocalGravity};
pub use options::{parse_multipliers, CalibOptions, MIN_STATIC_INTERVALS, RECORDING_ADVICE};
pub use result::{
    Assessment, CalibError, CalibrationResult, DetectionThresholds, FitStats, InitialRestReport, RotationResidual,
    StaticInterval, SweepEntry, Verdict,
};
pub use several::{calibrate_recordings, RecordingsResult};
pub use several_report::recording_folder;
pub use solve::calibrate;
