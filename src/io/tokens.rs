//! Whitespace-separated numeric tokens with file:line errors.

use crate::error::InputError;
use std::path::Path;

/// Tokens of one line, with its location for errors.
pub(crate) struct LineTokens<'a> {
    pub file: &'a Path,
    pub line: usize,
    toks: std::str::SplitWhitespace<'a>,
    consumed: usize,
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
        parse_f64(self.file, self.line, s, what)
    }
    /// Next token as a non-negative integer.
    pub fn usize(&mut self, what: &str) -> Result<usize, InputError> {
        let s = self.next_str(what)?;
        parse_usize(self.file, self.line, s, what)
    }
    /// Error if tokens remain.
    pub fn finish(mut self) -> Result<(), InputError> {
        match self.toks.next() {
            None => Ok(()),
            Some(t) => Err(InputError::at(self.file, self.line, format!("unexpected extra field '{t}'"))),
        }
    }
}

/// One token as a finite f64, with a file:line error naming `what`.
pub(crate) fn parse_f64(file: &Path, line: usize, tok: &str, what: &str) -> Result<f64, InputError> {
    let v: f64 = tok.parse().map_err(|_| InputError::at(file, line, format!("{what}: '{tok}' is not a number")))?;
    if !v.is_finite() {
        return Err(InputError::at(file, line, format!("{what} is not finite ({tok})")));
    }
    Ok(v)
}

/// One token as a non-negative integer, with a file:line error naming `what`.
pub(crate) fn parse_usize(file: &Path, line: usize, tok: &str, what: &str) -> Result<usize, InputError> {
    tok.parse().map_err(|_| InputError::at(file, line, format!("{what}: '{tok}' is not a non-negative integer")))
}

/// Read a whole file, naming it in the error.
pub(crate) fn read_text(path: &Path) -> Result<String, InputError> {
    std::fs::read_to_string(path).map_err(|e| InputError::file(path, format!("cannot read: {e}")))
}
