//! # tumble
//!
//! Turntable-free IMU calibration, Allan-variance noise identification,
//! camera–IMU rig calibration and visual-inertial bias estimation, all as
//! factor graphs on one sparse Levenberg–Marquardt engine ([`solvers`]) with
//! the factors of [`factors`]. Every estimate comes with its σ and a verdict.
//!
//! ## The front door
//!
//! | task | call | options → result, error |
//! |---|---|---|
//! | read an IMU recording (ASL, CSV, imu_tk, bags, MCAP, phone exports) | [`io::open_recording`] | [`io::RecordingOptions`] → [`io::ImuRecording`], [`InputError`] |
//! | calibrate an IMU from a hand tumble | [`calib::calibrate`] | [`calib::CalibOptions`] → [`calib::CalibrationResult`], [`calib::CalibError`] |
//! | apply a calibration | [`calib::apply_calibration`], [`model::calibration::Corrector`] | [`calib::ImuCalibration`] |
//! | identify noise by Allan variance | [`allan::run_allan`] | [`allan::AllanRunOptions`] → [`allan::AllanReport`], [`allan::AllanError`] |
//! | … in motion, against a ground truth | [`allan::in_motion::run_allan_in_motion`] | same |
//! | find what a calibration misses | [`audit::audit`] | [`audit::AuditOptions`] → [`audit::Audit`], [`audit::AuditError`] |
//! | calibrate a camera–IMU rig on a target | [`rig::calibrate_rig`] | [`rig::RigInput`], [`rig::RigOptions`] → [`rig::RigResult`], [`rig::RigError`] |
//! | estimate pose and biases with a camera (VIO) | [`vio::run`] | [`vio::VioInput`], [`vio::VioOptions`] → [`vio::VioResult`], [`vio::VioError`] |
//! | track features in images (feature `opencv`) | `vio::frontend` | |
//! | evaluate a trajectory | [`eval::evaluate`] | [`eval::EvalInputs`], [`eval::EvalOptions`] → [`eval::Evaluation`], [`eval::EvalError`] |
//! | simulate recordings with known truth | [`sim::simulate`], [`sim::simulate_and_write`] (images: [`sim::render`]) | [`sim::Scenario`], [`sim::SimConfig`] → [`sim::Simulation`], [`sim::SimError`] |
//! | the whole chain | [`pipeline::run_chain`] | [`pipeline::ChainInputs`], [`pipeline::ChainOptions`] |
//! | solve a g2o / BAL file | [`posegraph::solve_file`] | [`posegraph::SolveFileOptions`] → [`posegraph::SolvedFile`] |
//! | export to another estimator's config | [`export::export`] | [`export::Target`], [`export::ExportInputs`] |
//! | your own factor graph | [`solvers::prelude`] | [`solvers::Graph`], [`solvers::Values`], [`solvers::LmOptions`] |
//!
//! The model types every stage shares (IMU samples, calibrations, camera
//! geometry, targets, noise figures) are in [`model`]; files in and out in
//! [`io`]. Options are checked once, by each options type's `validate()`,
//! which the entry points call; errors name the file and line, or the option.
//!
//! Modules hidden from these docs (`calib::detect`, `rig::init`,
//! `vio::init`, `allan::identify`, `audit::fit`) are internals that the
//! project's own tests reach into; they are not part of the supported API.
//! Frames and units: SI throughout (s, m, rad, m/s², rad/s); the body frame is
//! the IMU's; each item's doc says its frames.

#![warn(missing_docs)]

pub mod allan;
pub mod audit;
pub mod calib;
pub mod demo;
pub mod error;
pub mod eval;
pub mod export;
pub mod inspect;
pub mod io;
pub mod model;
pub mod pipeline;
pub mod plot;
pub mod posegraph;
pub mod rig;
pub mod sim;
pub mod vio;

pub use error::{InputError, OptionError};
pub use tumble_factors as factors;
pub use tumble_solvers as solvers;
