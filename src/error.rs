//! Errors of the tumble crate: every input problem names the file and line.

use std::fmt;
use std::path::{Path, PathBuf};

/// A problem in a user's input file.
#[derive(Debug, Clone, PartialEq)]
pub struct InputError {
    /// The file.
    pub file: PathBuf,
    /// 1-based line number, when the problem is on one line.
    pub line: Option<usize>,
    /// What was wrong.
    pub message: String,
    /// How to fix it, when we know.
    pub hint: Option<String>,
}

impl InputError {
    /// Error on a line of a file.
    pub fn at(file: &Path, line: usize, message: impl fmt::Display) -> Self {
        InputError { file: file.to_path_buf(), line: Some(line), message: message.to_string(), hint: None }
    }
    /// Error about a whole file.
    pub fn file(file: &Path, message: impl fmt::Display) -> Self {
        InputError { file: file.to_path_buf(), line: None, message: message.to_string(), hint: None }
    }
    /// Attach a hint.
    pub fn with_hint(mut self, hint: impl Into<String>) -> Self {
        self.hint = Some(hint.into());
        self
    }
}

impl fmt::Display for InputError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.line {
            Some(l) => write!(f, "{}:{}: {}", self.file.display(), l, self.message)?,
            None => write!(f, "{}: {}", self.file.display(), self.message)?,
        }
        if let Some(h) = &self.hint {
            write!(f, " (hint: {h})")?;
        }
        Ok(())
    }
}

impl std::error::Error for InputError {}

/// An option (a library setting, or the command-line flag that sets it)
/// with a value that cannot work: what every `validate()` returns.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{option} {message}")]
pub struct OptionError {
    /// The option, as the command line names it (e.g. `--init-static`).
    pub option: String,
    /// What is wrong with its value, phrased to follow the option's name
    /// ("must be positive, got 0").
    pub message: String,
}

impl OptionError {
    /// `option` is wrong: `message`.
    pub fn new(option: impl Into<String>, message: impl Into<String>) -> OptionError {
        OptionError { option: option.into(), message: message.into() }
    }

    /// Ok when `value` is finite and positive; else "must be a positive number of `unit`".
    pub fn positive(option: &str, value: f64, unit: &str) -> Result<(), OptionError> {
        if value.is_finite() && value > 0.0 {
            Ok(())
        } else {
            Err(OptionError::new(option, format!("must be a positive number of {unit}, got {value}")))
        }
    }
}

/// Why an output (a report, a figure, a data file) could not be written.
#[derive(Debug, thiserror::Error)]
pub enum OutputError {
    /// Writing failed (the message names the file).
    #[error("{0}")]
    Failed(String),
    /// A file could not be written (named).
    #[error(transparent)]
    Input(#[from] InputError),
}

/// `From<String>`, `From<&str>` and `From<PlotError>` for an error type whose
/// variant (or tuple struct) `$make` holds a message.
macro_rules! message_error_conversions {
    ($ty:ty, $make:path) => {
        impl From<String> for $ty {
            fn from(s: String) -> $ty {
                $make(s)
            }
        }
        impl From<&str> for $ty {
            fn from(s: &str) -> $ty {
                $make(s.to_string())
            }
        }
        impl From<$crate::plot::PlotError> for $ty {
            fn from(e: $crate::plot::PlotError) -> $ty {
                $make(e.to_string())
            }
        }
    };
}
pub(crate) use message_error_conversions;

message_error_conversions!(OutputError, OutputError::Failed);
