//! # tumble-factors
//!
//! Concrete factors for tumble's graphs. Factors compute residuals and
//! Jacobians from variables; they know nothing of files or pipelines.
//!
//! - [`PriorFactor`]: `r = prior ⊟ x` on any [`LieGroup`] variable.
//! - [`BetweenFactor`]: `r = Log(Z⁻¹ · X₁⁻¹ X₂)`, relative measurement (odometry, loop closures).
//! - [`camera::CameraModel`]: pinhole with radial–tangential or equidistant distortion.
//! - [`imu_calib`]: gravity-norm and integrated-rotation factors of turntable-free IMU calibration.
//! - [`SnavelyReprojection`]: the Bundle-Adjustment-in-the-Large camera model (autodiff).
//!
//! Every factor's Jacobians are verified against central differences in tests.

pub mod bal;
pub mod between;
pub mod camera;
pub mod imu_calib;
pub mod prior;

pub use bal::SnavelyReprojection;
pub use between::BetweenFactor;
pub use imu_calib::{GravityNormFactor, IntegratedRotationFactor};
pub use prior::PriorFactor;
pub use tumble_solvers::LieGroup;
