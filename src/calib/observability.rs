//! Which parameters the poses determine.
//!
//! Every misalignment carries a Gaussian prior in the fits: zero with σ =
//! [`MISALIGNMENT_PRIOR_SIGMA`] (relative to its row's scale). Where the poses
//! determine a misalignment the prior changes nothing measurable (the data's
//! σ is 10–100× smaller); where they do not, the estimate stays at the prior
//! (no misalignment) with about the prior's σ instead of wandering off with a
//! σ of 5. A misalignment is *determined* when its posterior σ (covariance
//! inflated by χ²/dof) is below [`DETERMINED_FRACTION`](crate::model::DETERMINED_FRACTION) of the prior's, i.e.
//! the data carry at least 3× the prior's information; the others are
//! reported as not determined. Scales and biases have no usable prior (raw
//! units can be anything): every axis pointing up and down determines them,
//! and the detection refuses poses that do not.
//!
//! Which pose sets determine what (see docs/calibration.md): poses tilted
//! between the axes determine every parameter; axis-aligned poses (six faces
//! up and down) determine the accelerometer's scales and biases but not its
//! misalignments, whose effect on `|a|` is of second order when gravity lies
//! along one axis.

use crate::model::DETERMINED_FRACTION;
use nalgebra::{DMatrix, SVector};

/// Prior standard deviation of a misalignment or cross-axis term \[rad, or
/// fraction of the axis's scale\]: consumer MEMS datasheets give cross-axis
/// sensitivities up to 2 %, and mounting adds about as much.
pub const MISALIGNMENT_PRIOR_SIGMA: f64 = 0.05;

/// One off-diagonal parameter of a 9-vector model matrix.
#[derive(Debug, Clone, Copy)]
pub(super) struct OffDiagonal {
    /// Index in the parameter vector.
    pub index: usize,
    /// Row and column in the matrix (and in the paper's `T`).
    pub row: usize,
    pub col: usize,
    /// Index of the row's diagonal element (its scale).
    pub diagonal: usize,
}

const fn off(index: usize, row: usize, col: usize, diagonal: usize) -> OffDiagonal {
    OffDiagonal { index, row, col, diagonal }
}

/// The accelerometer's misalignments: `M_a` upper triangular,
/// `[m00, m01, m02, m11, m12, m22, b]`.
pub(super) const ACCEL_OFF_DIAGONAL: [OffDiagonal; 3] = [off(1, 0, 1, 0), off(2, 0, 2, 0), off(4, 1, 2, 3)];

/// The gyroscope's misalignments: `M_g` full, row major.
pub(super) const GYRO_OFF_DIAGONAL: [OffDiagonal; 6] =
    [off(1, 0, 1, 0), off(2, 0, 2, 0), off(3, 1, 0, 4), off(5, 1, 2, 4), off(6, 2, 0, 8), off(7, 2, 1, 8)];

/// Prior σ of an off-diagonal parameter in its own units.
pub(super) fn prior_sigma(p: &SVector<f64, 9>, o: &OffDiagonal) -> f64 {
    MISALIGNMENT_PRIOR_SIGMA * p[o.diagonal].abs()
}

/// The off-diagonal parameters the fit (`p`, covariance `cov` already
/// inflated, parameter order of `p` in its first 9 rows) does not determine.
pub(super) fn undetermined(p: &SVector<f64, 9>, cov: &DMatrix<f64>, offs: &[OffDiagonal]) -> Vec<OffDiagonal> {
    offs.iter()
        .filter(|o| {
            let sd = cov[(o.index, o.index)].max(0.0).sqrt();
            // NaN counts as not determined.
            sd.partial_cmp(&(DETERMINED_FRACTION * prior_sigma(p, o))) != Some(std::cmp::Ordering::Less)
        })
        .copied()
        .collect()
}

/// `sensor T[row][col]` for each undetermined parameter.
pub(super) fn names(sensor: &str, offs: &[OffDiagonal]) -> Vec<String> {
    offs.iter().map(|o| format!("{sensor} T[{}][{}]", o.row, o.col)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_parameter_is_determined_when_its_sigma_is_well_below_the_prior() {
        let mut p = SVector::<f64, 9>::zeros();
        p[0] = 2.0;
        p[3] = 1.0;
        p[5] = 1.0;
        let mut cov = DMatrix::identity(9, 9) * 1e-8;
        // σ(m01) = 0.04 < 0.5 · 0.05 · 2: determined; σ(m12) = 0.03 > 0.5 · 0.05 · 1: not determined.
        cov[(1, 1)] = 0.04f64.powi(2);
        cov[(4, 4)] = 0.03f64.powi(2);
        let found = undetermined(&p, &cov, &ACCEL_OFF_DIAGONAL);
        assert_eq!(found.iter().map(|o| o.index).collect::<Vec<_>>(), vec![4]);
        cov[(1, 1)] = 0.06f64.powi(2);
        assert_eq!(undetermined(&p, &cov, &ACCEL_OFF_DIAGONAL).len(), 2);
        assert_eq!(names("accelerometer", &found), vec!["accelerometer T[1][2]"]);
    }
}
