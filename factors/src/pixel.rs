//! What the camera factors share: small rotations on flat matrices, the
//! pixel residual of a projection and its Jacobians, and the [`Factor`]
//! implementation of a two-row pixel residual.

use crate::camera::{project_with, project_with_jacobians, DistortionKind};
use nalgebra::{Matrix2x3, Vector3};
use tumble_solvers::{FactorError, Linearization, Real};

/// Rotation matrix (row-major, 9) times a vector.
pub(crate) fn rot<T: Real>(r: &[T], v: [T; 3]) -> [T; 3] {
    [
        r[0] * v[0] + r[1] * v[1] + r[2] * v[2],
        r[3] * v[0] + r[4] * v[1] + r[5] * v[2],
        r[6] * v[0] + r[7] * v[1] + r[8] * v[2],
    ]
}

/// Transposed rotation matrix (row-major, 9) times a vector.
pub(crate) fn rot_t<T: Real>(r: &[T], v: [T; 3]) -> [T; 3] {
    [
        r[0] * v[0] + r[3] * v[1] + r[6] * v[2],
        r[1] * v[0] + r[4] * v[1] + r[7] * v[2],
        r[2] * v[0] + r[5] * v[1] + r[8] * v[2],
    ]
}

/// `Exp(φ) v` to third order in `φ`: `v + φ×v + ½ φ×(φ×v) + ⅙ φ×(φ×(φ×v))`.
pub(crate) fn small_rotation<T: Real>(phi: [T; 3], v: [T; 3]) -> [T; 3] {
    let cross =
        |a: [T; 3], b: [T; 3]| [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
    let a = cross(phi, v);
    let b = cross(phi, a);
    let c = cross(phi, b);
    [0, 1, 2].map(|i| v[i] + a[i] + b[i] * 0.5 + c[i] * (1.0 / 6.0))
}

/// `π(p_C) − uv` \[px\]; behind the camera a residual that is finite and
/// large, so a trial step there is rejected rather than failing the solve.
pub(crate) fn pixel_residual<T: Real>(kind: DistortionKind, k: &[T], pc: &[T; 3], measured: [f64; 2]) -> Vec<T> {
    match project_with(kind, k, pc) {
        Some(uv) => vec![uv[0] - measured[0], uv[1] - measured[1]],
        None => vec![T::from(1e4), T::from(1e4)],
    }
}

/// The projection's Jacobians with respect to the point in the camera frame
/// (2×3, px/m) and to the intrinsics (2×8), rows u, v.
pub(crate) type PixelJacobians = (Matrix2x3<f64>, [[f64; 8]; 2]);

/// `π(p_C) − uv` \[px\] at `f64` into `out`, reshaped to two rows and, with
/// `jac`, Jacobian blocks of `cols` columns for the caller to fill; returns
/// the projection's Jacobians with respect to the point (2×3) and the
/// intrinsics `k` (2×8) when `jac`. Behind the camera the residual is large
/// and flat (zero Jacobians), as [`pixel_residual`]'s, and `None` is returned.
pub(crate) fn pixel_linearization(
    kind: DistortionKind,
    k: &[f64; 8],
    pc: &Vector3<f64>,
    measured: [f64; 2],
    (jac, cols): (bool, &[usize]),
    out: &mut Linearization,
) -> Result<Option<PixelJacobians>, FactorError> {
    out.reshape(2, if jac { cols } else { &[] }.iter().copied());
    let Some((uv, jp, jk)) = project_with_jacobians(kind, k, &[pc.x, pc.y, pc.z]) else {
        out.residual.fill(1e4);
        out.jacobians.iter_mut().for_each(|j| j.fill(0.0));
        return Ok(None);
    };
    out.residual[0] = uv[0] - measured[0];
    out.residual[1] = uv[1] - measured[1];
    if !out.residual.iter().all(|r| r.is_finite()) {
        return Err(FactorError::NonFinite);
    }
    Ok(jac.then(|| (Matrix2x3::from_row_slice(&[jp[0][0], jp[0][1], jp[0][2], jp[1][0], jp[1][1], jp[1][2]]), jk)))
}

/// [`Factor`] for a two-row pixel residual whose `evaluate(vars, jac, out)`
/// writes the residual and, with `jac`, the Jacobians into `out`.
macro_rules! pixel_factor {
    ($t:ty) => {
        impl Factor for $t {
            fn keys(&self) -> &[Key] {
                &self.keys
            }
            fn residual_dim(&self) -> usize {
                2
            }
            fn residual(&self, vars: Vars<'_>) -> Result<DVector<f64>, FactorError> {
                let mut out = Linearization::default();
                self.evaluate(vars, false, &mut out)?;
                Ok(out.residual)
            }
            fn linearize(&self, vars: Vars<'_>) -> Result<Linearization, FactorError> {
                let mut out = Linearization::default();
                self.evaluate(vars, true, &mut out)?;
                Ok(out)
            }
            fn linearize_into(&self, vars: Vars<'_>, out: &mut Linearization) -> Result<(), FactorError> {
                self.evaluate(vars, true, out)
            }
        }
    };
}

pub(crate) use pixel_factor;
