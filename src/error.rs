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
    pub fn at(file: &Path, line: usize, message: impl Into<String>) -> Self {
        InputError { file: file.to_path_buf(), line: Some(line), message: message.into(), hint: None }
    }
    /// Error about a whole file.
    pub fn file(file: &Path, message: impl Into<String>) -> Self {
        InputError { file: file.to_path_buf(), line: None, message: message.into(), hint: None }
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
