//! # tumble-factors
//!
//! Concrete factors for tumble's graphs. Factors compute residuals and
//! Jacobians from variables; they know nothing of files or pipelines.
//!
//! - [`PriorFactor`]: `r = prior ⊟ x` on any [`LieGroup`] variable.
//! - [`BetweenFactor`]: `r = Log(Z⁻¹ · X₁⁻¹ X₂)`, relative measurement (odometry, loop closures).
//! - [`pose_graph_3d::QuaternionPoseError`]: Ceres' `pose_graph_3d` edge error `[R₁ᵀ(p₂−p₁) − p_z, 2·vec(q_z q₁₂⁻¹)]` (autodiff), to compare minima with Ceres.
//! - [`camera::CameraModel`]: pinhole with radial–tangential or equidistant distortion.
//! - [`imu_calib`]: gravity-norm and integrated-rotation factors of turntable-free IMU calibration.
//! - [`imu_preint`]: IMU preintegration (GTSAM's zero-order hold or VINS-Mono's midpoint), [`ImuFactor`], [`bias_random_walk`].
//! - [`InverseDepthReprojection`]: the reprojection of an anchored inverse-depth landmark (VINS-Mono's
//!   one parameter, or three with the bearing: [`reprojection::Landmark`]) through any [`camera::CameraModel`].
//! - [`rig`]: a target corner seen by a camera with unknown intrinsics, pose in the IMU frame and time offset ([`rig::TargetCorner`]), the camera-only corner ([`rig::CameraCorner`]) and the target's gauge.
//! - [`SnavelyReprojection`]: the Bundle-Adjustment-in-the-Large camera model (analytic Jacobians; its residual is generic too, for autodiff).
//!
//! Every factor's Jacobians are verified against central differences in tests.

#![warn(missing_docs)]

pub mod bal;
pub mod between;
pub mod camera;
pub mod imu_calib;
pub mod imu_effects;
pub mod imu_factor;
pub mod imu_preint;
mod pixel;
pub mod pose_graph_3d;
pub mod prior;
pub mod reprojection;
pub mod rig;
pub mod testing;

pub use bal::SnavelyReprojection;
pub use between::BetweenFactor;
pub use imu_calib::{GravityNormFactor, IntegratedRotationFactor};
pub use imu_factor::{bias_random_walk, bias_random_walk_axes, ImuFactor};
pub use prior::{PartialPriorFactor, PriorFactor};
pub use reprojection::InverseDepthReprojection;
pub use tumble_solvers::LieGroup;
