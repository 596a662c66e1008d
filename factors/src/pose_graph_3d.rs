//! Ceres' `pose_graph_3d` edge error, for comparing pose-graph minima with Ceres.

use nalgebra::{DVector, Matrix3, Vector3};
use tumble_solvers::lie::hat;
use tumble_solvers::sophus_lie::prelude::*;
use tumble_solvers::sophus_lie::Isometry3F64;
use tumble_solvers::{AutoDiffResidual, Factor, FactorError, Key, Linearization, Real, Variable, Vars};

/// Relative-pose error of Ceres' `pose_graph_3d` example
/// (`PoseGraph3dErrorTerm`) between two SE(3) poses `X₁ = (R₁, p₁)`,
/// `X₂ = (R₂, p₂)` (body to world) and a measured relative pose
/// `Z = (q_z, p_z)` of `X₂` in the frame of `X₁`:
///
/// `r = [R₁ᵀ(p₂ − p₁) − p_z ;  2·vec(q_z ⊗ q₁₂⁻¹)]`, `q₁₂ = q₁⁻¹ ⊗ q₂`,
///
/// position first (metres), then twice the vector part of the rotation
/// error's unit quaternion (radians to first order), taken with a
/// non-negative real part. The order is g2o's (`x y z qx qy qz`), so a g2o
/// information matrix applies unpermuted. For a small error
/// `X₂ = X₁ Z Exp([ω, ν])` it is `[R_z ν, −R_z ω]` to first order, where
/// [`crate::BetweenFactor`]'s `Log(Z⁻¹ X₁⁻¹ X₂)` is `[ω, ν]`: with information
/// isotropic per block the two costs agree to second order near the minimum
/// and differ away from it, so an optimizer can settle in different minima
/// with each.
///
/// Analytic Jacobians (checked against central differences and against the
/// automatic differentiation of the same residual, written generically as an
/// [`AutoDiffResidual`], in tests).
///
/// ```
/// use tumble_factors::pose_graph_3d::QuaternionPoseError;
/// use tumble_solvers::{check_jacobians, se3_from_quaternion, X};
/// use nalgebra::Vector3;
/// let z = se3_from_quaternion([0.9, 0.1, -0.2, 0.3], Vector3::new(1.0, 0.5, -0.2));
/// let f = QuaternionPoseError::new(X(0), X(1), &z);
/// let x1 = se3_from_quaternion([1.0, 0.2, 0.1, 0.0], Vector3::new(0.3, 0.0, 1.0));
/// let x2 = se3_from_quaternion([0.8, -0.1, 0.3, 0.4], Vector3::new(1.0, 2.0, 0.5));
/// assert!(check_jacobians(&f, &[&x1, &x2]).unwrap().passes(1e-6));
/// ```
#[derive(Clone, Debug)]
pub struct QuaternionPoseError {
    keys: [Key; 2],
    /// Measured rotation `R_z`, row-major.
    rot: [f64; 9],
    /// Measured translation `p_z` \[m\].
    trans: [f64; 3],
}

impl QuaternionPoseError {
    /// The error of measurement `z` (`X₁⁻¹ X₂`).
    pub fn new(k1: Key, k2: Key, z: &Isometry3F64) -> Self {
        let p = Variable::params(z);
        QuaternionPoseError {
            keys: [k1, k2],
            rot: std::array::from_fn(|i| p[i]),
            trans: std::array::from_fn(|i| p[9 + i]),
        }
    }
}

/// A pose's rotation and translation, from sophus' accessors (no allocation:
/// this runs once per edge and linearization).
fn rotation_translation(x: &Isometry3F64) -> (Matrix3<f64>, Vector3<f64>) {
    (x.rotation().matrix(), x.translation())
}

impl Factor for QuaternionPoseError {
    fn keys(&self) -> &[Key] {
        &self.keys
    }
    fn residual_dim(&self) -> usize {
        6
    }
    fn residual(&self, vars: Vars<'_>) -> Result<DVector<f64>, FactorError> {
        let (a, b): (&Isometry3F64, &Isometry3F64) = (vars.get(0)?, vars.get(1)?);
        Ok(DVector::from_vec(AutoDiffResidual::residual(self, &[&Variable::params(a)[..], &Variable::params(b)[..]])))
    }
    fn linearize(&self, vars: Vars<'_>) -> Result<Linearization, FactorError> {
        let mut out = Linearization::default();
        self.linearize_into(vars, &mut out)?;
        Ok(out)
    }
    /// With `Xᵢ ⊞ [ωᵢ, νᵢ] = (Rᵢ Exp(ωᵢ), pᵢ + Rᵢ νᵢ)` to first order,
    /// `d = R₁ᵀ(p₂ − p₁)`, `R₁₂ = R₁ᵀR₂` and `(w, v)` the error quaternion
    /// (`δR = R_z R₁₂ᵀ` moves to `δR Exp(ω₁ − R₁₂ ω₂)`, and `2·vec` of
    /// `q ⊗ (1, φ/2)` moves by `(w I + [v]×) φ`):
    /// `∂r/∂X₁ = [[d]×, −I; M, 0]`, `∂r/∂X₂ = [0, R₁₂; −M R₁₂, 0]`, `M = w I + [v]×`.
    fn linearize_into(&self, vars: Vars<'_>, out: &mut Linearization) -> Result<(), FactorError> {
        let (a, b): (&Isometry3F64, &Isometry3F64) = (vars.get(0)?, vars.get(1)?);
        let ((r1, p1), (r2, p2)) = (rotation_translation(a), rotation_translation(b));
        let r12 = r1.transpose() * r2;
        let d = r1.transpose() * (p2 - p1);
        let rz = Matrix3::from_row_slice(&self.rot);
        let dr = rz * r12.transpose();
        let dr_rows: [f64; 9] = std::array::from_fn(|i| dr[(i / 3, i % 3)]);
        let e_r = Vector3::from(twice_quaternion_vector(&dr_rows));
        let v = e_r * 0.5;
        let w = (1.0 - v.norm_squared()).max(0.0).sqrt();
        let m = Matrix3::identity() * w + hat(&v);
        out.reshape(6, [6, 6]);
        for k in 0..3 {
            out.residual[k] = d[k] - self.trans[k];
            out.residual[3 + k] = e_r[k];
        }
        let [j1, j2] = &mut out.jacobians[..] else { unreachable!("reshaped to two blocks") };
        j1.fill(0.0);
        j2.fill(0.0);
        j1.fixed_view_mut::<3, 3>(0, 0).copy_from(&hat(&d));
        j1.fixed_view_mut::<3, 3>(0, 3).copy_from(&-Matrix3::identity());
        j1.fixed_view_mut::<3, 3>(3, 0).copy_from(&m);
        j2.fixed_view_mut::<3, 3>(0, 3).copy_from(&r12);
        j2.fixed_view_mut::<3, 3>(3, 0).copy_from(&-(m * r12));
        Ok(())
    }
}

/// `2·vec(q)` of the unit quaternion `q` (real part ≥ 0) of a rotation matrix
/// (row-major), by Shepperd's method: the branch of the largest diagonal
/// combination, so no division by a vanishing term.
fn twice_quaternion_vector<T: Real>(m: &[T; 9]) -> [T; 3] {
    let at = |r: usize, c: usize| m[3 * r + c];
    let tr = at(0, 0) + at(1, 1) + at(2, 2);
    let diag = [at(0, 0).re(), at(1, 1).re(), at(2, 2).re()];
    let (imax, dmax) = diag.iter().enumerate().fold((0, f64::MIN), |a, (i, &d)| if d > a.1 { (i, d) } else { a });
    let one = T::from(1.0);
    // The trace branch when it is the largest, else the largest diagonal
    // entry's; either way the real part w is taken ≥ 0.
    if tr.re() >= dmax {
        // w = √(1 + tr)/2, 2·vec = (R32 − R23, R13 − R31, R21 − R12) / (2w).
        let two_w = (one + tr).sqrt();
        [(at(2, 1) - at(1, 2)) / two_w, (at(0, 2) - at(2, 0)) / two_w, (at(1, 0) - at(0, 1)) / two_w]
    } else {
        let (i, j, k) = (imax, (imax + 1) % 3, (imax + 2) % 3);
        // 2·q_i = √(1 + R_ii − R_jj − R_kk); the others follow from the
        // off-diagonal sums, w from the skew part.
        let two_qi = (one + at(i, i) - at(j, j) - at(k, k)).sqrt();
        let four_w_qi = at(k, j) - at(j, k);
        let two_qj = (at(j, i) + at(i, j)) / two_qi;
        let two_qk = (at(k, i) + at(i, k)) / two_qi;
        // w·q_i has the sign of four_w_qi; flip all so that w ≥ 0.
        let s = if four_w_qi.re() < 0.0 { -one } else { one };
        let mut v = [T::from(0.0); 3];
        v[i] = two_qi * s;
        v[j] = two_qj * s;
        v[k] = two_qk * s;
        v
    }
}

impl AutoDiffResidual<12> for QuaternionPoseError {
    fn keys(&self) -> &[Key] {
        &self.keys
    }
    fn residual_dim(&self) -> usize {
        6
    }
    /// Parameters: each pose's rotation (9, row-major) then translation (3).
    fn residual<T: Real>(&self, p: &[&[T]]) -> Vec<T> {
        let (a, b) = (p[0], p[1]);
        let ra = |r: usize, c: usize| a[3 * r + c];
        let rb = |r: usize, c: usize| b[3 * r + c];
        // R₁₂ = R₁ᵀ R₂ and p₁₂ = R₁ᵀ (p₂ − p₁).
        let r12: [T; 9] = std::array::from_fn(|i| {
            let (r, c) = (i / 3, i % 3);
            (0..3).fold(T::from(0.0), |s, k| s + ra(k, r) * rb(k, c))
        });
        let d: [T; 3] = std::array::from_fn(|k| b[9 + k] - a[9 + k]);
        let p12: [T; 3] = std::array::from_fn(|r| (0..3).fold(T::from(0.0), |s, k| s + ra(k, r) * d[k]));
        // δR = R_z R₁₂ᵀ.
        let dr: [T; 9] = std::array::from_fn(|i| {
            let (r, c) = (i / 3, i % 3);
            (0..3).fold(T::from(0.0), |s, k| s + r12[3 * c + k] * self.rot[3 * r + k])
        });
        let v = twice_quaternion_vector(&dr);
        vec![p12[0] - self.trans[0], p12[1] - self.trans[1], p12[2] - self.trans[2], v[0], v[1], v[2]]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;
    use tumble_solvers::{check_jacobians, se3_from_quaternion, AutoDiff, Factor, LieGroup, Variable, Vars, X};

    fn rotation_vector(theta: f64, axis: [f64; 3]) -> [f64; 4] {
        let n = (axis[0] * axis[0] + axis[1] * axis[1] + axis[2] * axis[2]).sqrt();
        let (s, c) = ((theta / 2.0).sin(), (theta / 2.0).cos());
        [c, s * axis[0] / n, s * axis[1] / n, s * axis[2] / n]
    }

    /// 2·vec(q) of every Shepperd branch (rotations near 0, and near π about
    /// each axis) equals the quaternion the rotation was made from.
    #[test]
    fn quaternion_vector_on_every_branch() {
        for (theta, axis) in [
            (0.3, [1.0, -2.0, 0.5]),
            (3.0, [1.0, 0.1, 0.2]),
            (3.0, [0.1, 1.0, -0.2]),
            (3.1, [0.2, -0.1, 1.0]),
            (-2.9, [0.5, 0.5, 0.6]),
        ] {
            let q = rotation_vector(theta, axis);
            let x = se3_from_quaternion(q, Vector3::zeros());
            let p = Variable::params(&x);
            let r: [f64; 9] = std::array::from_fn(|i| p[i]);
            let v = twice_quaternion_vector(&r);
            let sign = if q[0] < 0.0 { -1.0 } else { 1.0 };
            for k in 0..3 {
                assert!((v[k] - 2.0 * sign * q[k + 1]).abs() < 1e-12, "θ {theta}: {v:?} vs {q:?}");
            }
        }
    }

    /// Zero at the measurement, and the Jacobians match central differences
    /// away from it, on the small- and the large-angle branch.
    #[test]
    fn zero_at_the_measurement_and_jacobians_checked() {
        let z = se3_from_quaternion(rotation_vector(0.7, [0.3, 1.0, -0.4]), Vector3::new(1.0, -0.5, 2.0));
        let f = QuaternionPoseError::new(X(0), X(1), &z);
        let x1 = se3_from_quaternion(rotation_vector(1.2, [1.0, 0.2, 0.3]), Vector3::new(0.5, 0.1, -1.0));
        let x2 = x1.compose(&z);
        let r = Factor::residual(&f, Vars::new(&[&x1, &x2])).unwrap();
        assert!(r.amax() < 1e-12, "{r}");
        let ad = AutoDiff::<_, 12>::new(f.clone());
        for angle in [0.4, 2.8] {
            let x2 = se3_from_quaternion(rotation_vector(angle, [0.2, -1.0, 0.7]), Vector3::new(2.0, 0.3, -0.4));
            let report = check_jacobians(&f, &[&x1, &x2]).unwrap();
            assert!(report.passes(1e-6), "angle {angle}: {report:?}");
            let (lf, la) =
                (f.linearize(Vars::new(&[&x1, &x2])).unwrap(), ad.linearize(Vars::new(&[&x1, &x2])).unwrap());
            assert!((&lf.residual - &la.residual).amax() < 1e-12);
            for (jf, ja) in lf.jacobians.iter().zip(&la.jacobians) {
                assert!((jf - ja).amax() < 1e-9, "angle {angle}: analytic\n{jf}\nautodiff\n{ja}");
            }
        }
    }

    /// For a small error `X₂ = X₁ Z Exp([ω, ν])` it is `[R_z ν, −R_z ω]` to
    /// first order, where BetweenFactor's is `[ω, ν]`.
    #[test]
    fn agrees_with_the_log_error_near_the_minimum() {
        let z = se3_from_quaternion(rotation_vector(0.5, [0.0, 1.0, 1.0]), Vector3::new(1.0, 0.0, 0.5));
        let x1 = se3_from_quaternion(rotation_vector(0.2, [1.0, 0.0, 0.0]), Vector3::new(0.0, 1.0, 0.0));
        let eps = 1e-4;
        let x2 = x1.compose(&z).retract(&[eps, -eps, 2.0 * eps, -eps, eps, 0.5 * eps]);
        let q = QuaternionPoseError::new(X(0), X(1), &z);
        let rq = Factor::residual(&q, Vars::new(&[&x1, &x2])).unwrap();
        let b = crate::BetweenFactor::new(X(0), X(1), z);
        let rb = b.residual(Vars::new(&[&x1, &x2])).unwrap();
        let p = Variable::params(&z);
        let rz = nalgebra::Matrix3::from_row_slice(&p[..9]);
        let (omega, nu) = (rb.fixed_rows::<3>(0), rb.fixed_rows::<3>(3));
        let expect_p = rz * nu;
        let expect_r = -(rz * omega);
        for k in 0..3 {
            assert!((rq[k] - expect_p[k]).abs() < 1e-7, "position {k}: {rq} vs {expect_p}");
            assert!((rq[k + 3] - expect_r[k]).abs() < 1e-7, "rotation {k}: {rq} vs {expect_r}");
        }
    }
}
