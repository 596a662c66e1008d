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
//! // The factor's own (analytic) Jacobians, for both distortion models.
//! for kind in [DistortionKind::RadTan, DistortionKind::Equidistant] {
//!     let f = TargetCorner::new(keys, [0.1, 0.2, 0.0], [300.0, 200.0], [0.3, -0.2, 0.5], kind);
//!     assert!(check_jacobians(&f, &[&x, &v, &t_wt, &t_bc, &k, &td]).unwrap().passes(1e-6));
//! }
//! ```

use crate::camera::DistortionKind;
use crate::pixel::{pixel_linearization, pixel_residual, rot, rot_t, small_rotation};
use nalgebra::{DVector, Matrix3, SVector, Vector1, Vector3};
use tumble_solvers::lie::hat;
use tumble_solvers::sophus_lie::prelude::*;
use tumble_solvers::sophus_lie::Isometry3F64;
use tumble_solvers::{AutoDiffResidual, Factor, FactorError, Key, Linearization, Real, Vars};

/// A target corner seen in one image: residual `π(p_C) − uv` \[px\] on
/// `[X (T_WB), V, T_WT, T_BC, intrinsics, td]` (30 tangent dimensions); see
/// the module docs. A [`Factor`] with hand-written Jacobians; wrapped in
/// [`tumble_solvers::AutoDiff`] the same expression is differentiated
/// automatically (2.5× slower in the rig's solve). Give it an isotropic pixel
/// noise and a robust loss.
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

impl TargetCorner {
    /// Residual \[px\] into `out.residual` and, with `jac`, its six Jacobian
    /// blocks `[X, V, T_WT, T_BC, intrinsics, td]` (6, 3, 6, 6, 8, 1 columns),
    /// derived by hand from [`AutoDiffResidual::residual`]'s expression (right
    /// perturbations, `[ω, ν]` for SE(3)): the autodiff form costs 30 dual
    /// directions per corner, and the rig's solve is ≈ 360 000 corners.
    fn evaluate(&self, vars: Vars<'_>, jac: bool, out: &mut Linearization) -> Result<(), FactorError> {
        let x: &Isometry3F64 = vars.get(0)?;
        let v: &Vector3<f64> = vars.get(1)?;
        let twt: &Isometry3F64 = vars.get(2)?;
        let tbc: &Isometry3F64 = vars.get(3)?;
        let k: &SVector<f64, 8> = vars.get(4)?;
        let td = vars.get::<Vector1<f64>>(5)?[0];
        let (r_wb, t_wb) = (x.rotation().matrix(), x.translation());
        let (r_wt, t_wt) = (twt.rotation().matrix(), twt.translation());
        let (r_bc, t_bc) = (tbc.rotation().matrix(), tbc.translation());
        let c = Vector3::from(self.corner);
        let b = r_wb.transpose() * (r_wt * c + t_wt - t_wb - v * td);
        // Exp(−ω td) to third order, as `small_rotation`: M = I + A td + A² td²/2 + A³ td³/6, A = [−ω]×.
        let a = hat(&-Vector3::from(self.rate));
        let (a2, a3) = (a * a, a * a * a);
        let m = Matrix3::identity() + a * td + a2 * (0.5 * td * td) + a3 * (td * td * td / 6.0);
        let pc = r_bc.transpose() * (m * b - t_bc);
        let kv: [f64; 8] = k.as_slice().try_into().expect("an R⁸ variable");
        let cols = [6, 3, 6, 6, 8, 1];
        let Some((jpi, jk)) = pixel_linearization(self.kind, &kv, &pc, self.measured, (jac, &cols), out)? else {
            return Ok(());
        };
        let g = jpi * r_bc.transpose();
        let gm = g * m;
        let to_b = gm * r_wb.transpose();
        let [jx, jv, jt, je, jk_out, jd] = &mut out.jacobians[..] else { unreachable!("reshaped to six blocks") };
        jx.fixed_view_mut::<2, 3>(0, 0).copy_from(&(gm * hat(&b)));
        jx.fixed_view_mut::<2, 3>(0, 3).copy_from(&(-gm));
        jv.copy_from(&(-to_b * td));
        jt.fixed_view_mut::<2, 3>(0, 0).copy_from(&(-to_b * r_wt * hat(&c)));
        jt.fixed_view_mut::<2, 3>(0, 3).copy_from(&(to_b * r_wt));
        je.fixed_view_mut::<2, 3>(0, 0).copy_from(&(jpi * hat(&pc)));
        je.fixed_view_mut::<2, 3>(0, 3).copy_from(&(-jpi));
        for (row, r) in jk.iter().enumerate() {
            for (col, v) in r.iter().enumerate() {
                jk_out[(row, col)] = *v;
            }
        }
        let db = -(r_wb.transpose() * v);
        let dm_b = a * b + a2 * b * td + a3 * b * (0.5 * td * td);
        jd.copy_from(&(g * (m * db + dm_b)));
        Ok(())
    }
}

crate::pixel::pixel_factor!(TargetCorner);

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
