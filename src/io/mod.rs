//! Reading users' files. Every parser reports errors with file and line.

pub mod bal;
pub mod g2o;
pub(crate) mod tokens;
