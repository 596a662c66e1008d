//! Reading calibration files: tumble's `calibration.json` / `.yaml` and imu_tk's `.calib`.

use crate::error::InputError;
use crate::model::calibration::{CalibrationFile, ImuCalibration, ImuTkTriad};
use nalgebra::{Matrix3, Vector3};
use std::path::Path;

impl ImuCalibration {
    /// Read a `calibration.json` (or `.yaml`) written by `tumble calibrate`
    /// (diagnostic keys are ignored; the `*_std` keys are optional).
    pub fn read(path: &Path) -> Result<ImuCalibration, InputError> {
        let file: CalibrationFile = if path.extension().is_some_and(|e| e == "yaml" || e == "yml") {
            super::yaml::read_yaml(path)?
        } else {
            let text = std::fs::read_to_string(path).map_err(|e| InputError::file(path, e.to_string()))?;
            serde_json::from_str(&text).map_err(|e| InputError::at(path, e.line(), e.to_string()))?
        };
        file.to_calibration().map_err(|m| InputError::file(path, m))
    }
}

/// Read an imu_tk `.calib` file: `(T', K', b)` (21 numbers: 9, 9, 3).
pub fn read_imu_tk_calib(path: &Path) -> Result<ImuTkTriad, InputError> {
    let text = std::fs::read_to_string(path).map_err(|e| InputError::file(path, e.to_string()))?;
    let mut v = Vec::with_capacity(21);
    for (i, line) in text.lines().enumerate() {
        for tok in line.split_whitespace() {
            let x: f64 = tok.parse().map_err(|_| InputError::at(path, i + 1, format!("'{tok}' is not a number")))?;
            if !x.is_finite() {
                return Err(InputError::at(path, i + 1, format!("'{tok}' is not finite")));
            }
            v.push(x);
        }
    }
    if v.len() != 21 {
        return Err(InputError::file(
            path,
            format!("has {} numbers; an imu_tk .calib file has 21 (T 3×3, K 3×3, b 3)", v.len()),
        ));
    }
    let t = Matrix3::from_row_slice(&v[0..9]);
    let kk = Matrix3::from_row_slice(&v[9..18]);
    if (0..3).any(|r| (0..3).any(|c| r != c && kk[(r, c)] != 0.0)) {
        return Err(InputError::file(path, "the scale matrix K (numbers 10–18) is not diagonal"));
    }
    Ok((t, kk.diagonal(), Vector3::new(v[18], v[19], v[20])))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::calibration::{imu_tk_calib_text, sample_triad};

    #[test]
    fn imu_tk_calib_round_trip() {
        let (t, k, b) = sample_triad().to_imu_tk().unwrap();
        let dir = std::env::temp_dir().join(format!("tumble-calib-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("x.calib");
        std::fs::write(&p, imu_tk_calib_text(&t, &k, &b)).unwrap();
        let (t2, k2, b2) = read_imu_tk_calib(&p).unwrap();
        assert_eq!((t2, k2, b2), (t, k, b));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
