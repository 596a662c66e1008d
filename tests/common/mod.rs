//! Helpers shared by the integration tests.

#![allow(dead_code)]

pub mod cdr;

use std::path::{Path, PathBuf};

/// A path under `../shared/data/`, or None (with a printed SKIPPED line) when
/// the shared data folder is not beside the project.
pub fn shared(rel: &str) -> Option<PathBuf> {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data").join(rel);
    if p.exists() {
        Some(p)
    } else {
        println!("SKIPPED: {} is absent (the shared data folder is not beside the project)", p.display());
        None
    }
}
