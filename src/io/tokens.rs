//! Whitespace-separated numeric tokens with file:line errors.

use crate::error::InputError;
use std::path::Path;

/// Tokens of one line, with its location for errors.
pub(crate) struct LineTokens<'a> {
    pub file: &'a Path,
    pub line: usize,
    toks: std::str::SplitWhitespace<'a>,
    pub consumed: usize,
}

impl<'a> LineTokens<'a> {
    pub fn new(file: &'a Path, line: usize, text: &'a str) -> Self {
        LineTokens { file, line, toks: text.split_whitespace(), consumed: 0 }
    }
    fn next_str(&mut self, what: &str) -> Result<&'a str, InputError> {
        self.consumed += 1;
        self.toks.next().ok_or_else(|| {
            InputError::at(self.file, self.line, format!("line ends early: missing {what} (field {})", self.consumed))
        })
    }
    /// Next token as a finite f64.
    pub fn f64(&mut self, what: &str) -> Result<f64, InputError> {
        let s = self.next_str(what)?;
        let v: f64 =
            s.parse().map_err(|_| InputError::at(self.file, self.line, format!("{what}: '{s}' is not a number")))?;
        if !v.is_finite() {
            return Err(InputError::at(self.file, self.line, format!("{what} is not finite ({s})")));
        }
        Ok(v)
    }
    /// Next token as a non-negative integer.
    pub fn usize(&mut self, what: &str) -> Result<usize, InputError> {
        let s = self.next_str(what)?;
        s.parse()
            .map_err(|_| InputError::at(self.file, self.line, format!("{what}: '{s}' is not a non-negative integer")))
    }
    /// Error if tokens remain.
    pub fn finish(mut self) -> Result<(), InputError> {
        match self.toks.next() {
            None => Ok(()),
            Some(t) => Err(InputError::at(self.file, self.line, format!("unexpected extra field '{t}'"))),
        }
    }
}

/// Read a whole file, naming it in the error.
pub(crate) fn read_text(path: &Path) -> Result<String, InputError> {
    std::fs::read_to_string(path).map_err(|e| InputError::file(path, format!("cannot read: {e}")))
}
