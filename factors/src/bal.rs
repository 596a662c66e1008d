//! The camera model of Bundle Adjustment in the Large (Agarwal et al. 2010).

use tumble_solvers::{AutoDiffResidual, Key, Real};

/// Reprojection of a 3D point into a BAL camera, written generically and
/// differentiated automatically (wrap it in [`tumble_solvers::AutoDiff`] with `N = 12`).
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
