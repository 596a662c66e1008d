//! Error types of the solver crate.

use crate::key::Key;
use thiserror::Error;

/// Errors of the value store.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum ValueError {
    /// No value stored under the key.
    #[error("no value for key {0}")]
    Missing(Key),
    /// The stored value has another type than requested.
    #[error("key {key} holds a {stored}, not a {requested}")]
    WrongType {
        /// The key.
        key: Key,
        /// Type stored.
        stored: &'static str,
        /// Type requested.
        requested: &'static str,
    },
}

/// Errors raised while evaluating a factor.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum FactorError {
    /// A variable had an unexpected type.
    #[error("factor variable {index}: expected {expected}, got {got}")]
    WrongVariableType {
        /// Position of the variable in the factor's key list.
        index: usize,
        /// Type expected.
        expected: &'static str,
        /// Type found.
        got: &'static str,
    },
    /// The residual or a Jacobian was not finite.
    #[error("factor produced a non-finite residual or Jacobian")]
    NonFinite,
    /// Anything else the factor wants to report.
    #[error("{0}")]
    Other(String),
}

/// Errors of noise-model construction.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum NoiseError {
    /// A standard deviation was not finite and positive.
    #[error("standard deviation {0} is not finite and positive")]
    BadSigma(f64),
    /// A covariance or information matrix was not symmetric positive definite.
    #[error("matrix is not symmetric positive definite")]
    NotPositiveDefinite,
    /// Dimensions did not agree.
    #[error("dimension mismatch: {0}")]
    Dimension(String),
}

/// Errors of the optimizer and the linear algebra.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum SolveError {
    /// A factor refers to a key without a value.
    #[error("factor {factor} refers to key {key}, which has no value")]
    MissingVariable {
        /// Index of the factor in the graph.
        factor: usize,
        /// The missing key.
        key: Key,
    },
    /// A factor's declared and actual dimensions disagree.
    #[error("factor {factor}: {what}")]
    BadFactor {
        /// Index of the factor in the graph.
        factor: usize,
        /// What was wrong.
        what: String,
    },
    /// A factor evaluation failed.
    #[error("factor {factor}: {source}")]
    Factor {
        /// Index of the factor in the graph.
        factor: usize,
        /// The error.
        source: FactorError,
    },
    /// The configuration cannot be used with this graph.
    #[error("invalid configuration: {0}")]
    Config(String),
    /// The normal equations could not be factorized (singular system with
    /// Gauss–Newton, or a covariance request on an unobservable problem).
    #[error("linear system is not positive definite: {0}")]
    Singular(String),
    /// A value-store error.
    #[error(transparent)]
    Value(#[from] ValueError),
}
