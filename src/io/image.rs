//! Camera images (feature `opencv`).

use crate::error::InputError;
use opencv::core::Mat;
use opencv::imgcodecs;
use opencv::prelude::*;
use std::path::Path;

/// Read one image as 8-bit grayscale, with errors naming the file.
pub fn read_gray(path: &Path) -> Result<Mat, InputError> {
    let img = imgcodecs::imread(path, imgcodecs::IMREAD_GRAYSCALE).map_err(|e| InputError::file(path, e))?;
    if img.empty() {
        return Err(InputError::file(path, "not a readable image (missing, truncated or an unknown format)"));
    }
    Ok(img)
}
