//! Small closed-form helpers for SO(3) and SE(3) on nalgebra types.
//!
//! The group elements themselves are sophus-rs types ([`sophus_lie::Rotation3F64`],
//! [`sophus_lie::Isometry3F64`]); these helpers add what a factor needs for
//! analytic Jacobians: hat, right Jacobians and their inverses, in the
//! right-perturbation convention `x ⊞ δ = x · Exp(δ)` used throughout tumble.
//! SE(3) tangents are ordered `[ω, ν]` (rotation first), as in sophus and GTSAM.

use nalgebra::{Matrix3, Matrix6, Vector3, Vector6};

/// Skew-symmetric matrix `[v]×` with `[v]× w = v × w`.
pub fn hat(v: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -v.z, v.y, v.z, 0.0, -v.x, -v.y, v.x, 0.0)
}

/// SO(3) exponential as a rotation matrix (Rodrigues).
pub fn so3_exp(w: &Vector3<f64>) -> Matrix3<f64> {
    let t2 = w.norm_squared();
    let k = hat(w);
    let (a, b) = if t2 < 1e-10 {
        (1.0 - t2 / 6.0, 0.5 - t2 / 24.0)
    } else {
        let t = t2.sqrt();
        (t.sin() / t, (1.0 - t.cos()) / t2)
    };
    Matrix3::identity() + k * a + k * k * b
}

/// SO(3) logarithm of a rotation matrix, angle in \[0, π\].
///
/// Closed form (Shepperd's quaternion extraction, then `2 atan2(|v|, w)`), accurate
/// to rounding at every angle; `r` must be a rotation matrix.
pub fn so3_log(r: &Matrix3<f64>) -> Vector3<f64> {
    let q = nalgebra::UnitQuaternion::from_rotation_matrix(&nalgebra::Rotation3::from_matrix_unchecked(*r));
    let (mut w, mut v) = (q.w, q.vector().into_owned());
    if w < 0.0 {
        w = -w;
        v = -v;
    }
    let s = v.norm();
    if s < 1e-300 {
        return v * 2.0;
    }
    let angle = 2.0 * s.atan2(w);
    v * (angle / s)
}

/// Right Jacobian of SO(3): `Exp(w + δ) ≈ Exp(w) Exp(Jr(w) δ)`.
pub fn so3_right_jacobian(w: &Vector3<f64>) -> Matrix3<f64> {
    let t2 = w.norm_squared();
    let k = hat(w);
    let (a, b) = if t2 < 1e-10 {
        (0.5 - t2 / 24.0, 1.0 / 6.0 - t2 / 120.0)
    } else {
        let t = t2.sqrt();
        ((1.0 - t.cos()) / t2, (t - t.sin()) / (t2 * t))
    };
    Matrix3::identity() - k * a + k * k * b
}

/// Inverse of the SO(3) right Jacobian.
pub fn so3_right_jacobian_inv(w: &Vector3<f64>) -> Matrix3<f64> {
    let t2 = w.norm_squared();
    let k = hat(w);
    let c = if t2 < 1e-10 {
        1.0 / 12.0 + t2 / 720.0
    } else {
        let t = t2.sqrt();
        1.0 / t2 - (1.0 + t.cos()) / (2.0 * t * t.sin())
    };
    Matrix3::identity() + k * 0.5 + k * k * c
}

/// The `Q` block of the SE(3) left Jacobian (Barfoot), for tangent `[ω, ν]`.
fn se3_q(w: &Vector3<f64>, v: &Vector3<f64>) -> Matrix3<f64> {
    let t2 = w.norm_squared();
    let (wx, vx) = (hat(w), hat(v));
    let (a, b, c) = if t2 < 1e-8 {
        (1.0 / 6.0 - t2 / 120.0, 1.0 / 24.0 - t2 / 720.0, 1.0 / 120.0 - t2 / 5040.0)
    } else {
        let t = t2.sqrt();
        let (s, co) = t.sin_cos();
        let a = (t - s) / (t2 * t);
        let b = (t2 + 2.0 * co - 2.0) / (2.0 * t2 * t2);
        let c = (2.0 * t - 3.0 * s + t * co) / (2.0 * t2 * t2 * t);
        (a, b, c)
    };
    vx * 0.5
        + (wx * vx + vx * wx + wx * vx * wx) * a
        + (wx * wx * vx + vx * wx * wx - wx * vx * wx * 3.0) * b
        + (wx * vx * wx * wx + wx * wx * vx * wx) * c
}

/// SE(3) right Jacobian for tangent `ξ = [ω, ν]`.
pub fn se3_right_jacobian(xi: &Vector6<f64>) -> Matrix6<f64> {
    // Jr(ξ) = Jl(−ξ).
    let w: Vector3<f64> = -xi.fixed_rows::<3>(0).into_owned();
    let v: Vector3<f64> = -xi.fixed_rows::<3>(3).into_owned();
    let jl = so3_right_jacobian(&(-w)); // Jl_SO3(w) = Jr_SO3(−w)
    let q = se3_q(&w, &v);
    let mut m = Matrix6::zeros();
    m.fixed_view_mut::<3, 3>(0, 0).copy_from(&jl);
    m.fixed_view_mut::<3, 3>(3, 3).copy_from(&jl);
    m.fixed_view_mut::<3, 3>(3, 0).copy_from(&q);
    m
}

/// Inverse of the SE(3) right Jacobian for tangent `ξ = [ω, ν]`.
pub fn se3_right_jacobian_inv(xi: &Vector6<f64>) -> Matrix6<f64> {
    let w: Vector3<f64> = -xi.fixed_rows::<3>(0).into_owned();
    let v: Vector3<f64> = -xi.fixed_rows::<3>(3).into_owned();
    let jl_inv = so3_right_jacobian_inv(&(-w));
    let q = se3_q(&w, &v);
    let mut m = Matrix6::zeros();
    m.fixed_view_mut::<3, 3>(0, 0).copy_from(&jl_inv);
    m.fixed_view_mut::<3, 3>(3, 3).copy_from(&jl_inv);
    m.fixed_view_mut::<3, 3>(3, 0).copy_from(&(-jl_inv * q * jl_inv));
    m
}

/// Adjoint of an SE(3) element `(R, t)` for tangent order `[ω, ν]`.
pub fn se3_adjoint(r: &Matrix3<f64>, t: &Vector3<f64>) -> Matrix6<f64> {
    let mut m = Matrix6::zeros();
    m.fixed_view_mut::<3, 3>(0, 0).copy_from(r);
    m.fixed_view_mut::<3, 3>(3, 3).copy_from(r);
    m.fixed_view_mut::<3, 3>(3, 0).copy_from(&(hat(t) * r));
    m
}

/// SE(2) right Jacobian for tangent `[θ, ρx, ρy]`.
pub fn se2_right_jacobian(xi: &Vector3<f64>) -> Matrix3<f64> {
    let (th, r1, r2) = (xi[0], xi[1], xi[2]);
    let (a, b, c13, c23) = if th.abs() < 1e-6 {
        (1.0 - th * th / 6.0, th / 2.0, -r2 / 2.0 + r1 * th / 6.0, r1 / 2.0 + r2 * th / 6.0)
    } else {
        let (s, co) = th.sin_cos();
        (
            s / th,
            (1.0 - co) / th,
            (th * r1 - r2 + r2 * co - r1 * s) / (th * th),
            (r1 + th * r2 - r1 * co - r2 * s) / (th * th),
        )
    };
    // Rows/cols in [θ, ρx, ρy] order.
    Matrix3::new(1.0, 0.0, 0.0, c13, a, b, c23, -b, a)
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    fn se3_exp(xi: &Vector6<f64>) -> (Matrix3<f64>, Vector3<f64>) {
        let w = xi.fixed_rows::<3>(0).into_owned();
        let v = xi.fixed_rows::<3>(3).into_owned();
        // V = Jl(w) = Jr(−w)
        (so3_exp(&w), so3_right_jacobian(&(-w)) * v)
    }
    fn se3_log(r: &Matrix3<f64>, t: &Vector3<f64>) -> Vector6<f64> {
        let w = so3_log(r);
        let v = so3_right_jacobian(&(-w)).try_inverse().unwrap() * t;
        Vector6::new(w.x, w.y, w.z, v.x, v.y, v.z)
    }

    #[test]
    fn so3_right_jacobian_numeric() {
        for w in [Vector3::new(0.3, -0.2, 0.9), Vector3::new(1e-7, 2e-7, 0.0)] {
            let jr = so3_right_jacobian(&w);
            assert_relative_eq!(jr * so3_right_jacobian_inv(&w), Matrix3::identity(), epsilon = 1e-10);
            let r0 = so3_exp(&w);
            for i in 0..3 {
                let mut d = Vector3::zeros();
                d[i] = 1e-6;
                let num = so3_log(&(r0.transpose() * so3_exp(&(w + d)))) / 1e-6;
                assert_relative_eq!(num, jr.column(i).into_owned(), epsilon = 1e-5);
            }
        }
    }

    #[test]
    fn se3_right_jacobian_numeric() {
        for xi in [Vector6::new(0.3, -0.2, 0.9, 1.0, -2.0, 0.5), Vector6::new(1e-9, 0.0, 2e-9, 1.0, 2.0, 3.0)] {
            let jr = se3_right_jacobian(&xi);
            assert_relative_eq!(jr * se3_right_jacobian_inv(&xi), Matrix6::identity(), epsilon = 1e-9);
            let (r0, t0) = se3_exp(&xi);
            for i in 0..6 {
                let mut d = Vector6::zeros();
                d[i] = 1e-6;
                let (r1, t1) = se3_exp(&(xi + d));
                // (R0,t0)^-1 (R1,t1)
                let rr = r0.transpose() * r1;
                let tt = r0.transpose() * (t1 - t0);
                let num = se3_log(&rr, &tt) / 1e-6;
                assert_relative_eq!(num, jr.column(i).into_owned(), epsilon = 1e-5);
            }
        }
    }
}
