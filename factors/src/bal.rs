//! The camera model of Bundle Adjustment in the Large (Agarwal et al. 2010).

use nalgebra::{DVector, Matrix2x3, Matrix3, Vector3};
use tumble_solvers::lie::{hat, so3_exp, so3_right_jacobian};
use tumble_solvers::{AutoDiffResidual, Factor, FactorError, Key, Linearization, Real, Vars};

/// Reprojection of a 3D point into a BAL camera. As a [`Factor`] it has
/// analytic Jacobians; its residual is also written generically, so that
/// [`tumble_solvers::AutoDiff`] (with `N = 12`) differentiates it
/// automatically — the tests check one against the other.
///
/// Camera (R^9): angle-axis rotation `w` \[rad\], translation `t`, focal length `f`
/// \[px\], radial distortion `k1`, `k2`. Point (R^3) in world coordinates.
/// `P = R(w) X + t`, `p = −P_xy / P_z`, `r = f (1 + k1‖p‖² + k2‖p‖⁴) p − observed` \[px\].
#[derive(Clone, Debug)]
pub struct SnavelyReprojection {
    keys: [Key; 2],
    observed: [f64; 2],
}

impl SnavelyReprojection {
    /// Observation of point `point` by camera `camera` at pixel `observed`
    /// (BAL convention: origin at the image center, y up).
    pub fn new(camera: Key, point: Key, observed: [f64; 2]) -> Self {
        SnavelyReprojection { keys: [camera, point], observed }
    }
}

/// The camera (R^9) and point (R^3) variables of a BAL factor.
fn camera_and_point<'a>(vars: &Vars<'a>) -> Result<(&'a nalgebra::SVector<f64, 9>, &'a Vector3<f64>), FactorError> {
    Ok((vars.get(0)?, vars.get(1)?))
}

impl Factor for SnavelyReprojection {
    fn keys(&self) -> &[Key] {
        &self.keys
    }
    fn residual_dim(&self) -> usize {
        2
    }
    fn residual(&self, vars: Vars<'_>) -> Result<DVector<f64>, FactorError> {
        let (cam, x) = camera_and_point(&vars)?;
        Ok(DVector::from_vec(AutoDiffResidual::residual(self, &[cam.as_slice(), x.as_slice()])))
    }
    fn linearize(&self, vars: Vars<'_>) -> Result<Linearization, FactorError> {
        let mut out = Linearization::default();
        self.linearize_into(vars, &mut out)?;
        Ok(out)
    }
    /// With `P = R(w) X + t`: `∂P/∂w = −R [X]× Jr(w)` (Jr the SO(3) right
    /// Jacobian; `−[X]×` on the first-order branch near `w = 0`),
    /// `∂P/∂t = I`, `∂P/∂X = R`, chained through the projection and the
    /// distortion; `f`, `k1`, `k2` enter linearly.
    fn linearize_into(&self, vars: Vars<'_>, out: &mut Linearization) -> Result<(), FactorError> {
        let (cam, x) = camera_and_point(&vars)?;
        let w = Vector3::new(cam[0], cam[1], cam[2]);
        let (rot, dq_dw) = if w.norm_squared() > f64::EPSILON {
            let r = so3_exp(&w);
            (r, -r * hat(x) * so3_right_jacobian(&w))
        } else {
            (Matrix3::identity() + hat(&w), -hat(x))
        };
        let q = Vector3::from(angle_axis_rotate([w.x, w.y, w.z], [x.x, x.y, x.z]));
        let pc = q + Vector3::new(cam[3], cam[4], cam[5]);
        let (f, k1, k2) = (cam[6], cam[7], cam[8]);
        let (u, v) = (-pc.x / pc.z, -pc.y / pc.z);
        let r2 = u * u + v * v;
        let d = 1.0 + r2 * (k1 + k2 * r2);
        out.reshape(2, [9, 3]);
        out.residual[0] = f * d * u - self.observed[0];
        out.residual[1] = f * d * v - self.observed[1];
        // ∂(residual)/∂(u, v), then ∂(u, v)/∂P.
        let dd = 2.0 * (k1 + 2.0 * k2 * r2);
        let (ddu, ddv) = (dd * u, dd * v);
        let j_uv = nalgebra::Matrix2::new(f * (d + u * ddu), f * u * ddv, f * v * ddu, f * (d + v * ddv));
        let iz = 1.0 / pc.z;
        let uv_p = Matrix2x3::new(-iz, 0.0, pc.x * iz * iz, 0.0, -iz, pc.y * iz * iz);
        let j_p = j_uv * uv_p;
        let (jc, jx) = out.jacobians.split_at_mut(1);
        let (jc, jx) = (&mut jc[0], &mut jx[0]);
        jc.fixed_view_mut::<2, 3>(0, 0).copy_from(&(j_p * dq_dw));
        jc.fixed_view_mut::<2, 3>(0, 3).copy_from(&j_p);
        for (row, p) in [u, v].into_iter().enumerate() {
            jc[(row, 6)] = d * p;
            jc[(row, 7)] = f * r2 * p;
            jc[(row, 8)] = f * r2 * r2 * p;
        }
        jx.copy_from(&(j_p * rot));
        Ok(())
    }
}

/// Rotate `p` by the angle-axis vector `w` (Rodrigues, with the first-order
/// form near zero as Ceres' `AngleAxisRotatePoint`).
pub fn angle_axis_rotate<T: Real>(w: [T; 3], p: [T; 3]) -> [T; 3] {
    let theta2 = w[0] * w[0] + w[1] * w[1] + w[2] * w[2];
    let cross =
        |a: [T; 3], b: [T; 3]| [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
    if theta2.re() > f64::EPSILON {
        let theta = theta2.sqrt();
        let (s, c) = theta.sin_cos();
        let k = [w[0] / theta, w[1] / theta, w[2] / theta];
        let kxp = cross(k, p);
        let kdp = k[0] * p[0] + k[1] * p[1] + k[2] * p[2];
        let one = T::from(1.0);
        [0, 1, 2].map(|i| p[i] * c + kxp[i] * s + k[i] * kdp * (one - c))
    } else {
        let wxp = cross(w, p);
        [0, 1, 2].map(|i| p[i] + wxp[i])
    }
}

impl AutoDiffResidual<12> for SnavelyReprojection {
    fn keys(&self) -> &[Key] {
        &self.keys
    }
    fn residual_dim(&self) -> usize {
        2
    }
    fn residual<T: Real>(&self, p: &[&[T]]) -> Vec<T> {
        let (cam, x) = (p[0], p[1]);
        let q = angle_axis_rotate([cam[0], cam[1], cam[2]], [x[0], x[1], x[2]]);
        let pc = [q[0] + cam[3], q[1] + cam[4], q[2] + cam[5]];
        let (u, v) = (-pc[0] / pc[2], -pc[1] / pc[2]);
        let r2 = u * u + v * v;
        let d = T::from(1.0) + r2 * (cam[7] + cam[8] * r2);
        vec![cam[6] * d * u - self.observed[0], cam[6] * d * v - self.observed[1]]
    }
}
