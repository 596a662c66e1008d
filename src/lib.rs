//! # tumble
//!
//! Turntable-free IMU calibration, Allan-variance noise identification and
//! visual-inertial bias estimation, all as factor graphs on one sparse
//! Levenberg–Marquardt engine ([`tumble_solvers`]) with the factors of
//! [`tumble_factors`]. This crate holds the pipelines, data I/O and the CLI.

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
