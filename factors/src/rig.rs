//! Factors of the visual-inertial rig calibration on a known target (a
//! checkerboard or an AprilGrid): a target corner seen by a camera whose
//! intrinsics, pose in the IMU frame and time offset are unknowns, and the
//! gauge that fixes the target's free yaw and position in a gravity-aligned world.
//!
//! Frames and conventions:
//! - World `W`: z up, gravity `[0, 0, −g]`. The target `T` is an SE(3) variable
//!   `T_WT` (a corner's target coordinates `c` map to `R_WT c + t_WT`).
//! - Body (IMU) poses `T_WB` at the camera's frame stamps, velocities `v_W` \[m/s\],
//!   as in [`crate::ImuFactor`].
//! - Camera extrinsic `T_BC` (camera to body: `p_B = R_BC p_C + t_BC`), an SE(3) variable per camera.
//! - Intrinsics `[fx, fy, cx, cy, c0, c1, c2, c3]` \[px, px, px, px, –\] (an R⁸
//!   variable per camera; see [`crate::camera::project_with`]).
//! - Time offset `td` \[s\] (an R¹ variable, Kalibr's `timeshift_cam_imu`): an
//!   image stamped `t` by the camera was exposed at IMU time `t + td`. The body
//!   pose at exposure is the frame's pose moved by `td` along the measured,
//!   bias-corrected rate `ω` and the velocity: `R_WB Exp(ω td)`, `t_WB + v td`
//!   (first order in `td`; the rotation's series is kept to third order, so it
//!   is exact to `(|ω| td)⁴/24` — below 10⁻⁸ for 2 rad/s and 10 ms).
//!
//! ```
//! use nalgebra::{Vector1, Vector3, SVector};
//! use tumble_factors::camera::DistortionKind;
//! use tumble_factors::rig::TargetCorner;
//! use tumble_solvers::{check_jacobians, se3_from_quaternion, AutoDiff, Key, X, V};
//! let keys = [X(3), V(3), Key::new('t', 0), Key::new('e', 0), Key::new('k', 0), Key::new('d', 0)];
//! let f = AutoDiff::new(TargetCorner::new(keys, [0.1, 0.2, 0.0], [300.0, 200.0], [0.3, -0.2, 0.5], DistortionKind::RadTan));
//! let x = se3_from_quaternion([0.9, 0.1, 0.3, 0.1], Vector3::new(0.2, -0.1, 1.0));
//! let v = Vector3::new(0.3, 0.1, -0.2);
//! let t_wt = se3_from_quaternion([0.5, 0.5, -0.5, 0.5], Vector3::new(1.5, 0.0, 1.0));
//! let t_bc = se3_from_quaternion([0.7, 0.0, 0.0, 0.7], Vector3::new(0.05, -0.02, 0.01));
//! let k = SVector::<f64, 8>::from_column_slice(&[460.0, 458.0, 370.0, 250.0, -0.28, 0.07, 2e-4, 2e-5]);
//! let td = Vector1::new(0.004);
//! assert!(check_jacobians(&f, &[&x, &v, &t_wt, &t_bc, &k, &td]).unwrap().passes(1e-6));
//! ```

use crate::camera::{project_with, DistortionKind};
use tumble_solvers::{AutoDiffResidual, Key, Real};

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

/// A target corner seen in one image: residual `π(p_C) − uv` \[px\] on
/// `[X (T_WB), V, T_WT, T_BC, intrinsics, td]`; see the module docs. Wrap it
/// in [`tumble_solvers::AutoDiff`] (30 tangent dimensions) and give it an
/// isotropic pixel noise and a robust loss.
#[derive(Clone, Debug)]
pub struct TargetCorner {
    keys: [Key; 6],
    corner: [f64; 3],
    measured: [f64; 2],
    rate: [f64; 3],
    kind: DistortionKind,
}

impl TargetCorner {
    /// Corner at `corner` \[m, target frame\] measured at `measured_uv` \[px, distorted
    /// image\], with the body's bias-corrected rate `rate` \[rad/s, body frame\] at
    /// the frame's stamp and the camera's distortion model `kind`.
    pub fn new(keys: [Key; 6], corner: [f64; 3], measured_uv: [f64; 2], rate: [f64; 3], kind: DistortionKind) -> Self {
        TargetCorner { keys, corner, measured: measured_uv, rate, kind }
    }
    /// The measured pixel.
    pub fn measured(&self) -> [f64; 2] {
        self.measured
    }
}

impl AutoDiffResidual<30> for TargetCorner {
    fn keys(&self) -> &[Key] {
        &self.keys
    }
    fn residual_dim(&self) -> usize {
        2
    }
    fn residual<T: Real>(&self, p: &[&[T]]) -> Vec<T> {
        let (x, v, twt, tbc, k, td) = (p[0], p[1], p[2], p[3], p[4], p[5][0]);
        let c = self.corner.map(T::from);
        let cw = rot(&twt[..9], c);
        let pw = [0, 1, 2].map(|i| cw[i] + twt[9 + i]);
        // Body pose at exposure: R_WB Exp(ω td), t_WB + v td.
        let d = [0, 1, 2].map(|i| pw[i] - x[9 + i] - v[i] * td);
        let b_rot = rot_t(&x[..9], d);
        let phi = self.rate.map(|w| td * w);
        // Exp(φ)ᵀ b = Exp(−φ) b.
        let pb = small_rotation(phi.map(|a| -a), b_rot);
        let pc = rot_t(&tbc[..9], [0, 1, 2].map(|i| pb[i] - tbc[9 + i]));
        pixel_residual(self.kind, k, &pc, self.measured)
    }
}

/// A target corner seen by a camera alone (no IMU): residual `π(R_CT c + t_CT) − uv`
/// \[px\] on `[T_CT, intrinsics]` (target-to-camera SE(3), R⁸); the camera-only
/// calibration that starts the rig's (14 tangent dimensions).
///
/// ```
/// use nalgebra::{Vector3, SVector};
/// use tumble_factors::camera::DistortionKind;
/// use tumble_factors::rig::CameraCorner;
/// use tumble_solvers::{check_jacobians, se3_from_quaternion, AutoDiff, Key, X};
/// let f = AutoDiff::new(CameraCorner::new([X(0), Key::new('k', 0)], [0.1, 0.2, 0.0], [300.0, 200.0], DistortionKind::Equidistant));
/// let t_ct = se3_from_quaternion([0.9, 0.1, 0.3, 0.1], Vector3::new(0.2, -0.1, 1.0));
/// let k = SVector::<f64, 8>::from_column_slice(&[460.0, 458.0, 370.0, 250.0, 0.01, -0.005, 0.001, -2e-4]);
/// assert!(check_jacobians(&f, &[&t_ct, &k]).unwrap().passes(1e-6));
/// ```
#[derive(Clone, Debug)]
pub struct CameraCorner {
    keys: [Key; 2],
    corner: [f64; 3],
    measured: [f64; 2],
    kind: DistortionKind,
}

impl CameraCorner {
    /// Corner at `corner` \[m, target frame\] measured at `measured_uv` \[px\] by a camera of distortion `kind`.
    pub fn new(keys: [Key; 2], corner: [f64; 3], measured_uv: [f64; 2], kind: DistortionKind) -> Self {
        CameraCorner { keys, corner, measured: measured_uv, kind }
    }
}

impl AutoDiffResidual<14> for CameraCorner {
    fn keys(&self) -> &[Key] {
        &self.keys
    }
    fn residual_dim(&self) -> usize {
        2
    }
    fn residual<T: Real>(&self, p: &[&[T]]) -> Vec<T> {
        let (t, k) = (p[0], p[1]);
        let c = rot(&t[..9], self.corner.map(T::from));
        let pc = [0, 1, 2].map(|i| c[i] + t[9 + i]);
        pixel_residual(self.kind, k, &pc, self.measured)
    }
}

/// The gauge of a target in a gravity-aligned world: IMU and camera data fix
/// the target's tilt against gravity but not its yaw about gravity nor its
/// position. Residual on `[T_WT]`: `[t_WT − t₀, ½ (M₁₀ − M₀₁)]` with
/// `M = R_WT R₀ᵀ` (the world-z component of the rotation from `R₀`, exact at
/// zero), to be given a tiny σ. 6 tangent dimensions.
///
/// ```
/// use nalgebra::Vector3;
/// use tumble_factors::rig::TargetGauge;
/// use tumble_solvers::{check_jacobians, se3_from_quaternion, AutoDiff, Key};
/// let t0 = se3_from_quaternion([0.5, 0.5, -0.5, 0.5], Vector3::new(1.5, 0.0, 1.0));
/// let f = AutoDiff::new(TargetGauge::new(Key::new('t', 0), &t0));
/// let t = se3_from_quaternion([0.52, 0.5, -0.48, 0.5], Vector3::new(1.4, 0.1, 1.0));
/// assert!(check_jacobians(&f, &[&t]).unwrap().passes(1e-6));
/// ```
#[derive(Clone, Debug)]
pub struct TargetGauge {
    keys: [Key; 1],
    r0: [f64; 9],
    t0: [f64; 3],
}

impl TargetGauge {
    /// Gauge holding `T_WT`'s position and yaw at those of `initial`.
    pub fn new(key: Key, initial: &tumble_solvers::sophus_lie::Isometry3F64) -> Self {
        use tumble_solvers::sophus_lie::prelude::*;
        let r = initial.rotation().matrix();
        let t = initial.translation();
        TargetGauge { keys: [key], r0: [0, 1, 2, 3, 4, 5, 6, 7, 8].map(|i| r[(i / 3, i % 3)]), t0: [t[0], t[1], t[2]] }
    }
}

impl AutoDiffResidual<6> for TargetGauge {
    fn keys(&self) -> &[Key] {
        &self.keys
    }
    fn residual_dim(&self) -> usize {
        4
    }
    fn residual<T: Real>(&self, p: &[&[T]]) -> Vec<T> {
        let r = &p[0][..9];
        // M = R R0ᵀ: M_ij = Σ_k R_ik R0_jk.
        let m = |i: usize, j: usize| (0..3).fold(T::zero(), |acc, k| acc + r[3 * i + k] * self.r0[3 * j + k]);
        let yaw = (m(1, 0) - m(0, 1)) * 0.5;
        vec![p[0][9] - self.t0[0], p[0][10] - self.t0[1], p[0][11] - self.t0[2], yaw]
    }
}
