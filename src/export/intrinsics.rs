//! tumble's IMU model in the forms other estimators parameterize it.
//!
//! tumble: `raw = M x + b` per triad (`M_a = T_a K_a` upper triangular, the
//! accelerometer's axes define the body frame; `M_g = T_g K_g` full). Other
//! estimators restrict `M` to a triangle and put the rest in a rotation:
//!
//! - OpenVINS' `rpng` model: `M = T · R` with `T` upper triangular
//!   ([`upper_times_rotation`]);
//! - Basalt: a lower-triangular accelerometer correction `(I + S_a) = Q M_a⁻¹`
//!   in a body frame rotated by `Q` from tumble's ([`rotation_times_lower`]).

use nalgebra::{Matrix3, Vector3};

/// `m = u · r` with `u` upper triangular (positive diagonal) and `r` a
/// rotation, for `det m > 0` (Gram–Schmidt on the rows from the last).
pub fn upper_times_rotation(m: &Matrix3<f64>) -> Option<(Matrix3<f64>, Matrix3<f64>)> {
    if m.determinant() <= 0.0 {
        return None;
    }
    let rows: Vec<Vector3<f64>> = (0..3).map(|i| m.row(i).transpose()).collect();
    let mut q = [Vector3::zeros(); 3];
    let mut u = Matrix3::zeros();
    for i in (0..3).rev() {
        let mut v = rows[i];
        for j in i + 1..3 {
            u[(i, j)] = rows[i].dot(&q[j]);
            v -= u[(i, j)] * q[j];
        }
        u[(i, i)] = v.norm();
        q[i] = v / u[(i, i)];
    }
    let r = Matrix3::from_rows(&[q[0].transpose(), q[1].transpose(), q[2].transpose()]);
    Some((u, r))
}

/// `m = q · l` with `q` a rotation and `l` lower triangular (positive
/// diagonal), for `det m > 0` (Gram–Schmidt on the columns from the last).
pub fn rotation_times_lower(m: &Matrix3<f64>) -> Option<(Matrix3<f64>, Matrix3<f64>)> {
    let (u, r) = upper_times_rotation(&m.transpose())?;
    // mᵀ = u r  ⇒  m = rᵀ uᵀ, with uᵀ lower triangular.
    Some((r.transpose(), u.transpose()))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> Matrix3<f64> {
        Matrix3::new(1.004, -0.0098, -0.0166, 0.0084, 0.999, 0.0037, 0.0163, 0.0070, 0.9954)
    }

    #[test]
    fn decompositions_reproduce_the_matrix() {
        let m = sample();
        let (u, r) = upper_times_rotation(&m).unwrap();
        assert!((u * r - m).norm() < 1e-14);
        assert!((r * r.transpose() - Matrix3::identity()).norm() < 1e-14 && r.determinant() > 0.0);
        assert!(u[(1, 0)] == 0.0 && u[(2, 0)] == 0.0 && u[(2, 1)] == 0.0 && u[(0, 0)] > 0.0);
        let (q, l) = rotation_times_lower(&m).unwrap();
        assert!((q * l - m).norm() < 1e-14);
        assert!(l[(0, 1)] == 0.0 && l[(0, 2)] == 0.0 && l[(1, 2)] == 0.0);
        assert!((q * q.transpose() - Matrix3::identity()).norm() < 1e-14 && q.determinant() > 0.0);
        assert!(upper_times_rotation(&-Matrix3::<f64>::identity()).is_none());
    }
}
