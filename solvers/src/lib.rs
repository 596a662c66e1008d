//! # tumble-solvers
//!
//! The engine of tumble: a sparse Levenberg–Marquardt solver over manifold
//! variables. Every stage of tumble (calibration, Allan fitting, VIO) is a
//! factor graph handed to this crate; it knows nothing of IMUs or files.
//!
//! - [`Variable`]: R^n (`nalgebra::SVector`), SO(3), SE(3), SE(2) (sophus-rs
//!   types), or your own; any variable can be held constant ([`Values::set_constant`]).
//! - [`Values`]: the value store keyed by [`Key`]s like GTSAM's `X(3)`, `L(17)`.
//! - [`Factor`]: residual + Jacobians, analytic, automatic ([`AutoDiff`], dual
//!   numbers from `num-dual`) or numeric ([`numeric_linearize`]); verify with
//!   [`check_jacobians`].
//! - [`NoiseModel`] and robust losses ([`Huber`], [`Cauchy`], [`Tukey`], Triggs-corrected).
//! - [`Optimizer`]: Levenberg–Marquardt or Gauss–Newton on block-sparse normal
//!   equations assembled directly, faer sparse Cholesky (symbolic analysis once),
//!   a dense path for small problems, Schur elimination of landmarks
//!   ([`LmOptions::eliminate`]); returns a [`Summary`].
//! - [`marginalize`] → [`MarginalPrior`]; [`covariances`] for marginal covariance blocks.
//!
//! ## Why sophus-rs only for the group operations
//! The Lie groups ([`sophus_lie::Rotation3F64`], [`sophus_lie::Isometry3F64`],
//! [`sophus_lie::Isometry2F64`]) are sophus-rs types and their `exp`, `log`,
//! products and inverses are sophus'. The closed-form right Jacobians of SO(3)
//! and SE(3) that analytic factors need are in [`lie`]: sophus exposes left
//! Jacobians through its generic batch/dual scalar machinery, and tumble's
//! automatic differentiation uses `num-dual` over ambient parameters instead of
//! sophus' own dual types, so one scalar system serves user factors of any variable type.

#![warn(missing_docs)]

pub mod autodiff;
pub mod error;
pub mod factor;
pub mod graph;
mod group;
pub mod key;
mod layout;
pub mod lie;
pub mod linear;
mod linearized;
pub mod loss;
pub mod marginal;
pub mod noise;
pub mod optimizer;
pub mod testing;
pub mod values;
pub mod variable;

pub use autodiff::{AutoDiff, AutoDiffResidual, Real};
pub use error::{FactorError, NoiseError, SolveError, ValueError};
pub use factor::{check_jacobians, numeric_linearize, Factor, JacobianCheck, Linearization, Vars};
pub use graph::{FactorEntry, Graph};
pub use group::LieGroup;
pub use key::{Key, B, C, L, P, V, X};
pub use linear::LinearSolver;
pub use loss::{Cauchy, Huber, RobustLoss, Tukey};
pub use marginal::{
    cluster_robust_covariances, covariances, covariances_eliminating, information_log_det, marginalize, Covariances,
    MarginalPrior, Marginalization, RobustCovariances,
};
pub use noise::NoiseModel;
pub use optimizer::{IterationLog, LmOptions, Method, Optimizer, Summary, Termination};
pub use values::Values;
pub use variable::{se2, se3_from_quaternion, DynVariable, DynVector, Variable};

pub use nalgebra;
pub use sophus_lie;

/// What a custom factor and its solve need, in one import:
/// `use tumble_solvers::prelude::*;`.
///
/// A factor is [`AutoDiffResidual`] (keys, residual dimension, the residual
/// written generically over [`Real`]) wrapped in [`AutoDiff`], or [`Factor`]
/// (the residual on [`Vars`]; Jacobians by central differences unless you
/// write them); [`check_jacobians`] compares yours with numeric ones.
pub mod prelude {
    pub use crate::{
        check_jacobians, AutoDiff, AutoDiffResidual, Factor, FactorError, Graph, Huber, Key, LmOptions, NoiseModel,
        Optimizer, Real, Values, Variable, Vars, X,
    };
}
