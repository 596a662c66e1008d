//! YAML files (EuRoC `sensor.yaml`, Kalibr `imu.yaml`, simulator configs) via
//! `serde-saphyr`, with errors naming file and line. OpenCV's `%YAML:1.0`
//! first line, which EuRoC uses and strict YAML parsers refuse, is accepted.

use crate::error::InputError;
use serde::Deserialize;
use std::path::Path;

/// Parse YAML `text` (from `path`, for messages) into `T`.
pub fn parse_yaml<T: for<'de> Deserialize<'de>>(path: &Path, text: &str) -> Result<T, InputError> {
    // Keep line numbers: blank the OpenCV directive instead of removing it.
    let cleaned;
    let text = if text.trim_start().starts_with("%YAML:") {
        let nl = text.find('\n').unwrap_or(text.len());
        cleaned = format!("#{}", &text[nl..]);
        cleaned.as_str()
    } else {
        text
    };
    serde_saphyr::from_str::<T>(text).map_err(|e| {
        let msg = e.without_snippet().to_string();
        let msg = msg.lines().next().unwrap_or("invalid YAML").to_string();
        match e.location() {
            Some(l) if l.line() > 0 => InputError::at(path, l.line() as usize, msg),
            _ => InputError::file(path, msg),
        }
    })
}

/// Read and parse a YAML file.
pub fn read_yaml<T: for<'de> Deserialize<'de>>(path: &Path) -> Result<T, InputError> {
    parse_yaml(path, &super::tokens::read_text(path)?)
}

/// A row-major matrix as OpenCV/EuRoC YAML writes it (`rows`, `cols`, `data`).
#[derive(Debug, Clone, PartialEq, Deserialize, serde::Serialize)]
pub struct YamlMatrix {
    /// Rows.
    pub rows: usize,
    /// Columns.
    pub cols: usize,
    /// Row-major entries.
    pub data: Vec<f64>,
}

impl YamlMatrix {
    /// As a 4×4 homogeneous transform, checking the shape and that the rotation is orthonormal.
    pub fn to_transform(&self, path: &Path, what: &str) -> Result<nalgebra::Isometry3<f64>, InputError> {
        if self.rows != 4 || self.cols != 4 || self.data.len() != 16 {
            return Err(InputError::file(
                path,
                format!(
                    "{what} must be 4×4 with 16 entries, found {}×{} with {}",
                    self.rows,
                    self.cols,
                    self.data.len()
                ),
            ));
        }
        if self.data.iter().any(|v| !v.is_finite()) {
            return Err(InputError::file(path, format!("{what} has a non-finite entry")));
        }
        let m = nalgebra::Matrix4::from_row_slice(&self.data);
        let r = m.fixed_view::<3, 3>(0, 0).into_owned();
        let err = (r.transpose() * r - nalgebra::Matrix3::identity()).abs().max();
        if err > 1e-3 || (r.determinant() - 1.0).abs() > 1e-3 {
            return Err(InputError::file(
                path,
                format!("{what}: the rotation part is not a rotation (‖RᵀR − I‖ = {err:.2e})"),
            ));
        }
        let rot = nalgebra::UnitQuaternion::from_matrix(&r);
        Ok(nalgebra::Isometry3::from_parts(nalgebra::Translation3::new(m[(0, 3)], m[(1, 3)], m[(2, 3)]), rot))
    }
}
