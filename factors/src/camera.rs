//! Camera models: pinhole projection with radial–tangential (OpenCV `plumb_bob`)
//! or equidistant (Kannala–Brandt / OpenCV fisheye) distortion.
//!
//! Frames: a point `p_c = [x, y, z]` in the camera frame (z forward, x right,
//! y down) projects to pixel `[u, v]`. Projection is generic over the scalar
//! so reprojection residuals can be differentiated automatically.
//!
//! ```
//! use tumble_factors::camera::{CameraModel, Distortion};
//! let cam = CameraModel { fx: 458.654, fy: 457.296, cx: 367.215, cy: 248.375,
//!     distortion: Distortion::RadTan { k1: -0.28340811, k2: 0.07395907, p1: 0.00019359, p2: 1.76187114e-05 } };
//! let uv = cam.project(&[0.1, -0.05, 2.0]).unwrap();
//! let xy = cam.unproject(uv).unwrap(); // normalized [x/z, y/z]
//! assert!((xy[0] - 0.05).abs() < 1e-9 && (xy[1] + 0.025).abs() < 1e-9);
//! ```

use num_dual::{Derivative, DualSVec64};
use tumble_solvers::Real;

/// Lens distortion of a [`CameraModel`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Distortion {
    /// No distortion.
    None,
    /// Radial–tangential: radial `k1 r² + k2 r⁴`, tangential `p1, p2`.
    RadTan {
        /// r² coefficient.
        k1: f64,
        /// r⁴ coefficient.
        k2: f64,
        /// First tangential coefficient.
        p1: f64,
        /// Second tangential coefficient.
        p2: f64,
    },
    /// Equidistant: `θ_d = θ (1 + k1 θ² + k2 θ⁴ + k3 θ⁶ + k4 θ⁸)`.
    Equidistant {
        /// θ² coefficient.
        k1: f64,
        /// θ⁴ coefficient.
        k2: f64,
        /// θ⁶ coefficient.
        k3: f64,
        /// θ⁸ coefficient.
        k4: f64,
    },
}

/// A pinhole camera with focal lengths and principal point in pixels.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CameraModel {
    /// Focal length along u \[px\].
    pub fx: f64,
    /// Focal length along v \[px\].
    pub fy: f64,
    /// Principal point u \[px\].
    pub cx: f64,
    /// Principal point v \[px\].
    pub cy: f64,
    /// Lens distortion.
    pub distortion: Distortion,
}

/// Which distortion model, without its coefficients (for estimating them).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DistortionKind {
    /// No distortion.
    None,
    /// Radial–tangential `[k1, k2, p1, p2]`.
    RadTan,
    /// Equidistant `[k1, k2, k3, k4]`.
    Equidistant,
}

impl Distortion {
    /// The model's kind.
    pub fn kind(&self) -> DistortionKind {
        match self {
            Distortion::None => DistortionKind::None,
            Distortion::RadTan { .. } => DistortionKind::RadTan,
            Distortion::Equidistant { .. } => DistortionKind::Equidistant,
        }
    }
    /// The coefficients in Kalibr's order (`[k1, k2, p1, p2]` or `[k1, k2, k3, k4]`; zeros for none).
    pub fn coefficients(&self) -> [f64; 4] {
        match *self {
            Distortion::None => [0.0; 4],
            Distortion::RadTan { k1, k2, p1, p2 } => [k1, k2, p1, p2],
            Distortion::Equidistant { k1, k2, k3, k4 } => [k1, k2, k3, k4],
        }
    }
    /// The model of `kind` with coefficients `c` (ignored for none).
    pub fn from_coefficients(kind: DistortionKind, c: [f64; 4]) -> Distortion {
        match kind {
            DistortionKind::None => Distortion::None,
            DistortionKind::RadTan => Distortion::RadTan { k1: c[0], k2: c[1], p1: c[2], p2: c[3] },
            DistortionKind::Equidistant => Distortion::Equidistant { k1: c[0], k2: c[1], k3: c[2], k4: c[3] },
        }
    }
}

/// Distort normalized coordinates `[x/z, y/z]` by a model of `kind` whose
/// coefficients `c` are themselves of the generic scalar (so they can be
/// estimated with automatic differentiation).
pub fn distort_with<T: Real>(kind: DistortionKind, c: &[T; 4], x: T, y: T) -> [T; 2] {
    match kind {
        DistortionKind::None => [x, y],
        DistortionKind::RadTan => {
            let [k1, k2, p1, p2] = *c;
            let r2 = x * x + y * y;
            let radial = T::one() + r2 * k1 + r2 * r2 * k2;
            let xy = x * y;
            [x * radial + xy * p1 * 2.0 + (r2 + x * x * 2.0) * p2, y * radial + (r2 + y * y * 2.0) * p1 + xy * p2 * 2.0]
        }
        DistortionKind::Equidistant => {
            let [k1, k2, k3, k4] = *c;
            let r2 = x * x + y * y;
            if r2.re() < 1e-16 {
                return [x, y];
            }
            let r = r2.sqrt();
            let th = r.atan();
            let t2 = th * th;
            let thd = th * (T::one() + t2 * (t2 * (t2 * (t2 * k4 + k3) + k2) + k1));
            let s = thd / r;
            [x * s, y * s]
        }
    }
}

/// Project a point `p` of the camera frame to pixels through intrinsics
/// `k = [fx, fy, cx, cy, c0, c1, c2, c3]` (focal lengths and principal point
/// in px, then the distortion coefficients of `kind`), all of the generic
/// scalar; None behind the camera (z ≤ 1 mm).
pub fn project_with<T: Real>(kind: DistortionKind, k: &[T], p: &[T; 3]) -> Option<[T; 2]> {
    if p[2].re() <= 1e-3 {
        return None;
    }
    let [xd, yd] = distort_with(kind, &[k[4], k[5], k[6], k[7]], p[0] / p[2], p[1] / p[2]);
    Some([xd * k[0] + k[2], yd * k[1] + k[3]])
}

/// [`project_with`] at `f64` with its Jacobians: with respect to the point
/// (2×3) and to the intrinsics `k` (2×8), rows u, v. The distortion's part
/// comes from forward-mode dual numbers over the point and the four
/// coefficients (7 directions); the focal lengths' and principal point's
/// columns are `[x_d, 0]`, `[0, y_d]`, `[1, 0]`, `[0, 1]`. None behind the camera.
#[allow(clippy::type_complexity)]
pub fn project_with_jacobians(
    kind: DistortionKind,
    k: &[f64; 8],
    p: &[f64; 3],
) -> Option<([f64; 2], [[f64; 3]; 2], [[f64; 8]; 2])> {
    if p[2] <= 1e-3 {
        return None;
    }
    let lift = |i: usize, x: f64| {
        let mut e = nalgebra::SVector::<f64, 7>::zeros();
        e[i] = 1.0;
        DualSVec64::<7>::new(x, Derivative::some(e))
    };
    let c = [lift(3, k[4]), lift(4, k[5]), lift(5, k[6]), lift(6, k[7])];
    let (x, y, z) = (lift(0, p[0]), lift(1, p[1]), lift(2, p[2]));
    let d = distort_with(kind, &c, x / z, y / z);
    let mut jp = [[0.0; 3]; 2];
    let mut jk = [[0.0; 8]; 2];
    for (row, (dv, f)) in d.iter().zip([k[0], k[1]]).enumerate() {
        let eps = dv.eps.unwrap_generic(nalgebra::Const::<7>, nalgebra::Const::<1>);
        for i in 0..3 {
            jp[row][i] = f * eps[i];
        }
        for i in 0..4 {
            jk[row][4 + i] = f * eps[3 + i];
        }
        jk[row][row] = dv.re;
        jk[row][2 + row] = 1.0;
    }
    Some(([d[0].re * k[0] + k[2], d[1].re * k[1] + k[3]], jp, jk))
}

impl CameraModel {
    /// The intrinsics as one vector `[fx, fy, cx, cy, c0, c1, c2, c3]` (see [`project_with`]).
    pub fn to_vector(&self) -> [f64; 8] {
        let c = self.distortion.coefficients();
        [self.fx, self.fy, self.cx, self.cy, c[0], c[1], c[2], c[3]]
    }
    /// The model of `kind` from `[fx, fy, cx, cy, c0, c1, c2, c3]`.
    pub fn from_vector(kind: DistortionKind, k: &[f64]) -> CameraModel {
        CameraModel {
            fx: k[0],
            fy: k[1],
            cx: k[2],
            cy: k[3],
            distortion: Distortion::from_coefficients(kind, [k[4], k[5], k[6], k[7]]),
        }
    }

    /// Distort normalized coordinates `[x/z, y/z]`.
    pub fn distort<T: Real>(&self, x: T, y: T) -> [T; 2] {
        let c = self.distortion.coefficients().map(T::from);
        distort_with(self.distortion.kind(), &c, x, y)
    }

    /// Project a point in the camera frame to pixels; None behind the camera
    /// (z ≤ 1 mm) or past the equidistant model's 180° field.
    pub fn project<T: Real>(&self, p: &[T; 3]) -> Option<[T; 2]> {
        if p[2].re() <= 1e-3 {
            return None;
        }
        let [xd, yd] = self.distort(p[0] / p[2], p[1] / p[2]);
        Some([xd * self.fx + self.cx, yd * self.fy + self.cy])
    }

    /// [`CameraModel::project`] with its 2×3 Jacobian with respect to the point
    /// (forward-mode dual numbers through the distortion); rows u, v.
    pub fn project_with_jacobian(&self, p: &[f64; 3]) -> Option<([f64; 2], [[f64; 3]; 2])> {
        let lift = |k: usize| {
            let mut e = nalgebra::SVector::<f64, 3>::zeros();
            e[k] = 1.0;
            DualSVec64::<3>::new(p[k], Derivative::some(e))
        };
        let uv = self.project(&[lift(0), lift(1), lift(2)])?;
        let mut j = [[0.0; 3]; 2];
        for (row, d) in uv.iter().enumerate() {
            let eps = d.eps.unwrap_generic(nalgebra::Const::<3>, nalgebra::Const::<1>);
            j[row] = [eps[0], eps[1], eps[2]];
        }
        Some(([uv[0].re, uv[1].re], j))
    }

    /// Pixel to normalized undistorted coordinates `[x/z, y/z]` (Gauss–Newton
    /// on the distortion, 20 iterations at most); None if it does not converge.
    pub fn unproject(&self, uv: [f64; 2]) -> Option<[f64; 2]> {
        let xd = [(uv[0] - self.cx) / self.fx, (uv[1] - self.cy) / self.fy];
        let mut x = xd;
        for _ in 0..20 {
            let f = self.distort(x[0], x[1]);
            let r = [f[0] - xd[0], f[1] - xd[1]];
            if r[0].abs() + r[1].abs() < 1e-14 {
                return Some(x);
            }
            // Numeric 2×2 Jacobian of the distortion.
            let h = 1e-7;
            let fx = self.distort(x[0] + h, x[1]);
            let fy = self.distort(x[0], x[1] + h);
            let (a, c) = ((fx[0] - f[0]) / h, (fx[1] - f[1]) / h);
            let (b, d) = ((fy[0] - f[0]) / h, (fy[1] - f[1]) / h);
            let det = a * d - b * c;
            if det.abs() < 1e-12 {
                return None;
            }
            x[0] -= (d * r[0] - b * r[1]) / det;
            x[1] -= (-c * r[0] + a * r[1]) / det;
        }
        let f = self.distort(x[0], x[1]);
        ((f[0] - xd[0]).abs() + (f[1] - xd[1]).abs() < 1e-9).then_some(x)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unproject_inverts_project_for_both_models() {
        let dists = [
            Distortion::None,
            Distortion::RadTan { k1: -0.28, k2: 0.07, p1: 2e-4, p2: 1.8e-5 },
            Distortion::Equidistant { k1: 0.01, k2: -0.005, k3: 0.001, k4: -0.0002 },
        ];
        for d in dists {
            let cam = CameraModel { fx: 400.0, fy: 410.0, cx: 320.0, cy: 240.0, distortion: d };
            for p in [[0.3, -0.2, 1.0], [-0.5, 0.4, 2.0], [0.0, 0.0, 3.0]] {
                let uv = cam.project(&p).unwrap();
                let xy = cam.unproject(uv).unwrap();
                assert!((xy[0] - p[0] / p[2]).abs() < 1e-9 && (xy[1] - p[1] / p[2]).abs() < 1e-9, "{d:?} {p:?}");
            }
            assert!(cam.project(&[0.0, 0.0, -1.0]).is_none());
        }
    }
}
