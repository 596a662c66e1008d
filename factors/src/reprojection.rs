//! Reprojection of a landmark parametrized by its inverse depth in the first
//! keyframe that observed it.
//!
//! The landmark is `p_Ca = f / ρ` in the anchor camera, with `ρ` \[1/m\] the
//! inverse depth and `f` the bearing, in one of two forms ([`Landmark`]):
//! - a `Vector1` variable `[ρ]`: `f = f_a = [x, y, 1]`, the anchor
//!   observation's undistorted normalized coordinates, held fixed
//!   (VINS-Mono's parametrization). The anchor's pixel noise then enters every
//!   other observation's residual and is counted nowhere: the residuals of one
//!   landmark are correlated and the poses' σ come out too small.
//! - a `Vector3` variable `[δx, δy, ρ]`: `f = [x + δx, y + δy, 1]`, the
//!   bearing estimated too, with the anchor observation a residual of its own
//!   ([`AnchorObservation`]) — the anchored inverse depth of OpenVINS and
//!   Basalt (three degrees of freedom per landmark), where every pixel is one
//!   independent measurement.
//!
//! Poses are body-in-world SE(3)
//! (`Isometry3F64`, right perturbation); `body_from_camera` is the fixed
//! camera-to-IMU extrinsic `T_BC`. The residual is `π(p_Cj) − uv_j` in pixels
//! of the given [`CameraModel`] (pinhole, radial–tangential or equidistant);
//! for tracks already in normalized coordinates use a model with unit focal
//! lengths and no distortion. Pair it with a Huber loss.
//!
//! ```
//! use nalgebra::{Vector1, Vector3};
//! use tumble_factors::camera::{CameraModel, Distortion};
//! use tumble_factors::InverseDepthReprojection;
//! use tumble_solvers::{check_jacobians, se3_from_quaternion, X, L};
//! let cam = CameraModel { fx: 460.0, fy: 460.0, cx: 376.0, cy: 240.0,
//!     distortion: Distortion::RadTan { k1: -0.28, k2: 0.07, p1: 2e-4, p2: 2e-5 } };
//! let t_bc = se3_from_quaternion([1.0, 0.0, 0.0, 0.0], Vector3::new(0.05, 0.0, 0.0));
//! let f = InverseDepthReprojection::new([X(0), X(1), L(7)], [0.1, -0.05], [380.0, 230.0], cam, &t_bc);
//! let xa = se3_from_quaternion([1.0, 0.0, 0.0, 0.0], Vector3::zeros());
//! let xj = se3_from_quaternion([0.999, 0.02, -0.03, 0.01], Vector3::new(0.2, 0.05, -0.1));
//! let rho = Vector1::new(0.4);
//! assert!(check_jacobians(&f, &[&xa, &xj, &rho]).unwrap().passes(1e-6));
//! ```

use crate::camera::CameraModel;
use nalgebra::{DMatrix, DVector, Matrix2x3, Matrix3, Vector1, Vector3};
use tumble_solvers::lie::hat;
use tumble_solvers::sophus_lie::prelude::*;
use tumble_solvers::sophus_lie::Isometry3F64;
use tumble_solvers::{DynVariable, Factor, FactorError, Key, Linearization, Vars};

/// A landmark variable read by the factors of this module: the bearing
/// `f` (anchor camera, `z = 1`) and the inverse depth `ρ` \[1/m\], from a
/// `Vector1` `[ρ]` (bearing fixed at the anchor observation) or a `Vector3`
/// `[δx, δy, ρ]` (bearing `f_a + [δx, δy, 0]`); see the module docs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Landmark {
    /// The bearing `f` in the anchor camera (`z = 1`).
    pub bearing: Vector3<f64>,
    /// The inverse depth ρ \[1/m\].
    pub rho: f64,
    /// The variable's dimension: 1 (`[ρ]`) or 3 (`[δx, δy, ρ]`).
    pub dim: usize,
}

impl Landmark {
    /// Variable `v` as a landmark anchored at bearing `anchor` (`z = 1`);
    /// None when it is neither a `Vector1` nor a `Vector3`.
    pub fn of(v: &dyn DynVariable, anchor: &Vector3<f64>) -> Option<Landmark> {
        let any = v.as_any();
        if let Some(l) = any.downcast_ref::<Vector3<f64>>() {
            return Some(Landmark { bearing: anchor + Vector3::new(l[0], l[1], 0.0), rho: l[2], dim: 3 });
        }
        any.downcast_ref::<Vector1<f64>>().map(|rho| Landmark { bearing: *anchor, rho: rho[0], dim: 1 })
    }

    /// Variable `i` of `vars` as a landmark anchored at bearing `anchor` (`z = 1`).
    pub fn read(vars: &Vars<'_>, i: usize, anchor: &Vector3<f64>) -> Result<Landmark, FactorError> {
        if let Some(l) = (i < vars.len()).then(|| Landmark::of(vars.get_dyn(i), anchor)).flatten() {
            return Ok(l);
        }
        // No variable i, or another type: the error that names them.
        Err(vars.get::<Vector1<f64>>(i).err().unwrap_or(FactorError::Other(format!("variable {i} is no landmark"))))
    }

    /// The point `f / ρ` in the anchor camera \[m\].
    pub fn point(&self) -> Vector3<f64> {
        self.bearing / self.rho
    }

    /// `∂(f / ρ)/∂[δx, δy, ρ]` (3 × 3); a `[ρ]` landmark's is the last column.
    pub fn point_jacobian(&self) -> Matrix3<f64> {
        let inv = 1.0 / self.rho;
        let d_rho = -self.bearing * (inv * inv);
        Matrix3::new(inv, 0.0, d_rho.x, 0.0, inv, d_rho.y, 0.0, 0.0, d_rho.z)
    }

    /// `jl = m ∂(f / ρ)/∂(variable)`: the residual's Jacobian by the landmark
    /// (2 × [`Landmark::dim`]) from `m`, its Jacobian by the point `f / ρ`
    /// in the anchor camera (2 × 3).
    pub fn chain_into(&self, m: &Matrix2x3<f64>, jl: &mut DMatrix<f64>) {
        let j = m * self.point_jacobian();
        let first = 3 - self.dim;
        for c in 0..self.dim {
            jl[(0, c)] = j[(0, first + c)];
            jl[(1, c)] = j[(1, first + c)];
        }
    }
}

/// The anchor observation of a landmark whose bearing is estimated (a
/// `Vector3` `[δx, δy, ρ]`, see [`Landmark`]): `r = π(f_a + [δx, δy, 0]) −
/// uv_a` \[px\], a factor on the landmark alone. With it the anchor's pixel
/// is one measurement like every other, not a constant. Pair it with a Huber loss.
///
/// ```
/// use nalgebra::Vector3;
/// use tumble_factors::camera::{CameraModel, Distortion};
/// use tumble_factors::reprojection::AnchorObservation;
/// use tumble_solvers::{check_jacobians, L};
/// let cam = CameraModel { fx: 460.0, fy: 460.0, cx: 376.0, cy: 240.0,
///     distortion: Distortion::RadTan { k1: -0.28, k2: 0.07, p1: 2e-4, p2: 2e-5 } };
/// let f = AnchorObservation::new(L(7), [0.1, -0.05], [420.0, 217.0], cam);
/// assert!(check_jacobians(&f, &[&Vector3::new(0.002, -0.001, 0.4)]).unwrap().passes(1e-6));
/// ```
#[derive(Clone, Debug)]
pub struct AnchorObservation {
    keys: [Key; 1],
    bearing: Vector3<f64>,
    measured: [f64; 2],
    camera: CameraModel,
}

impl AnchorObservation {
    /// Factor on `landmark` (`[δx, δy, ρ]`): anchor observation `anchor_xy`
    /// (undistorted normalized: the bearing the landmark's δ correct), its
    /// pixel `measured_uv` \[px\] and the camera's model.
    pub fn new(landmark: Key, anchor_xy: [f64; 2], measured_uv: [f64; 2], camera: CameraModel) -> Self {
        AnchorObservation {
            keys: [landmark],
            bearing: Vector3::new(anchor_xy[0], anchor_xy[1], 1.0),
            measured: measured_uv,
            camera,
        }
    }

    /// Residual \[px\] and, with `jac`, its derivative by `[δx, δy, ρ]` (none by ρ).
    fn evaluate(&self, vars: Vars<'_>, jac: bool, out: &mut Linearization) -> Result<(), FactorError> {
        let l = Landmark::read(&vars, 0, &self.bearing)?;
        if l.dim != 3 {
            return Err(FactorError::Other("an anchor observation needs a [δx, δy, ρ] landmark (Vector3)".into()));
        }
        let Some(jpi) = pixel_residual(&self.camera, &l.bearing, self.measured, (jac, &[3]), out)? else {
            return Ok(());
        };
        let j = &mut out.jacobians[0];
        for r in 0..2 {
            j[(r, 0)] = jpi[(r, 0)];
            j[(r, 1)] = jpi[(r, 1)];
            j[(r, 2)] = 0.0;
        }
        Ok(())
    }
}

crate::pixel::pixel_factor!(AnchorObservation);

/// Reprojection factor on `[X_anchor, X_j, L]` (`L` a [`Landmark`]); see the module docs.
#[derive(Clone, Debug)]
pub struct InverseDepthReprojection {
    keys: [Key; 3],
    bearing: Vector3<f64>,
    measured: [f64; 2],
    /// Model of the observing camera.
    camera: CameraModel,
    /// The anchor camera's `T_BC`.
    r_bc: Matrix3<f64>,
    t_bc: Vector3<f64>,
    /// The observing camera's `T_BC` (the anchor camera's unless
    /// [`InverseDepthReprojection::seen_by`] set another).
    r_bcj: Matrix3<f64>,
    t_bcj: Vector3<f64>,
}

impl InverseDepthReprojection {
    /// Factor on `[X_anchor, X_j, L]`: anchor observation `anchor_xy` (undistorted
    /// normalized), observation `measured_uv` \[px\] in frame j, camera model and `T_BC`.
    pub fn new(
        keys: [Key; 3],
        anchor_xy: [f64; 2],
        measured_uv: [f64; 2],
        camera: CameraModel,
        body_from_camera: &Isometry3F64,
    ) -> Self {
        let (r_bc, t_bc) = (body_from_camera.rotation().matrix(), body_from_camera.translation());
        InverseDepthReprojection {
            keys,
            bearing: Vector3::new(anchor_xy[0], anchor_xy[1], 1.0),
            measured: measured_uv,
            camera,
            r_bc,
            t_bc,
            r_bcj: r_bc,
            t_bcj: t_bc,
        }
    }

    /// The observation made by another camera of the rig (stereo: the
    /// second camera at frame j), with its model and `T_BC`; the anchor stays
    /// the first camera's.
    pub fn seen_by(mut self, camera: CameraModel, body_from_camera: &Isometry3F64) -> Self {
        self.camera = camera;
        self.r_bcj = body_from_camera.rotation().matrix();
        self.t_bcj = body_from_camera.translation();
        self
    }

    /// Residual \[px\] into `out.residual` and, when `out` is given Jacobian
    /// room (`jac`), the three Jacobian blocks (anchor pose, observing pose,
    /// inverse depth).
    fn evaluate(&self, vars: Vars<'_>, jac: bool, out: &mut Linearization) -> Result<(), FactorError> {
        let xa: &Isometry3F64 = vars.get(0)?;
        let xj: &Isometry3F64 = vars.get(1)?;
        let l = Landmark::read(&vars, 2, &self.bearing)?;
        let (ra, pa) = (xa.rotation().matrix(), xa.translation());
        let (rj, pj) = (xj.rotation().matrix(), xj.translation());
        let p_ca = l.point();
        let p_ba = self.r_bc * p_ca + self.t_bc;
        let p_w = ra * p_ba + pa;
        let p_bj = rj.transpose() * (p_w - pj);
        let p_cj = self.r_bcj.transpose() * (p_bj - self.t_bcj);
        let Some(jpi) = pixel_residual(&self.camera, &p_cj, self.measured, (jac, &[6, 6, l.dim]), out)? else {
            return Ok(());
        };
        let rcb_rjt = self.r_bcj.transpose() * rj.transpose();
        let j_pw = jpi * rcb_rjt * ra;
        let [jxa, jxj, jl] = &mut out.jacobians[..] else { unreachable!("reshaped to three blocks") };
        jxa.fixed_view_mut::<2, 3>(0, 0).copy_from(&(j_pw * (-hat(&p_ba))));
        jxa.fixed_view_mut::<2, 3>(0, 3).copy_from(&j_pw);
        jxj.fixed_view_mut::<2, 3>(0, 0).copy_from(&(jpi * self.r_bcj.transpose() * hat(&p_bj)));
        jxj.fixed_view_mut::<2, 3>(0, 3).copy_from(&(-jpi * self.r_bcj.transpose()));
        l.chain_into(&(j_pw * self.r_bc), jl);
        Ok(())
    }
}

/// Project `p_c` (camera frame \[m\]) and write `π(p_c) − measured` \[px\] into
/// `out.residual`. With `jac`, `out` gets Jacobian blocks of `cols` columns
/// for the caller to fill and the projection's Jacobian is returned to chain;
/// without, `out` holds the residual alone and None is returned.
fn pixel_residual(
    camera: &CameraModel,
    p_c: &Vector3<f64>,
    measured: [f64; 2],
    (jac, cols): (bool, &[usize]),
    out: &mut Linearization,
) -> Result<Option<Matrix2x3<f64>>, FactorError> {
    let Some((uv, jp)) = camera.project_with_jacobian(&[p_c.x, p_c.y, p_c.z]) else {
        return Err(FactorError::Other(format!("landmark behind camera (depth {:.3} m)", p_c.z)));
    };
    let residual = [uv[0] - measured[0], uv[1] - measured[1]];
    if !residual.iter().all(|x| x.is_finite()) {
        return Err(FactorError::NonFinite);
    }
    out.reshape(2, if jac { cols } else { &[] }.iter().copied());
    out.residual.copy_from_slice(&residual);
    Ok(jac.then(|| Matrix2x3::from_row_slice(&[jp[0][0], jp[0][1], jp[0][2], jp[1][0], jp[1][1], jp[1][2]])))
}

crate::pixel::pixel_factor!(InverseDepthReprojection);

/// A landmark's anchor observation matched in a second camera at the same
/// time (stereo): a factor on the landmark alone (a [`Landmark`]: `[ρ]` or
/// `[δx, δy, ρ]`).
///
/// The landmark `p_B = R_BC f / ρ + t_BC` in the body frame at the anchor
/// (first camera `T_BC`, `f` the bearing: `f_a = [x, y, 1]`, the anchor
/// observation's undistorted normalized coordinates, plus its correction) seen by the second camera
/// (`T_BC1`): `r = π₁(R_BC1ᵀ (p_B − t_BC1)) − uv₁` in its pixels. The
/// baseline makes the depth observable without motion. Pair it with a Huber loss.
///
/// ```
/// use nalgebra::{Vector1, Vector3};
/// use tumble_factors::camera::{CameraModel, Distortion};
/// use tumble_factors::reprojection::StereoInverseDepth;
/// use tumble_solvers::{check_jacobians, se3_from_quaternion, L};
/// let cam = CameraModel { fx: 460.0, fy: 460.0, cx: 376.0, cy: 240.0, distortion: Distortion::None };
/// let t_bc0 = se3_from_quaternion([1.0, 0.0, 0.0, 0.0], Vector3::zeros());
/// let t_bc1 = se3_from_quaternion([1.0, 0.0, 0.0, 0.0], Vector3::new(0.11, 0.0, 0.0));
/// let f = StereoInverseDepth::new(L(7), [0.1, -0.05], [400.0, 215.0], (cam, &t_bc1), &t_bc0);
/// assert!(check_jacobians(&f, &[&Vector1::new(0.4)]).unwrap().passes(1e-6));
/// ```
#[derive(Clone, Debug)]
pub struct StereoInverseDepth {
    keys: [Key; 1],
    /// The anchor observation's bearing `f_a`, and the first camera's `T_BC`.
    bearing: Vector3<f64>,
    r_bc: Matrix3<f64>,
    t_bc: Vector3<f64>,
    measured: [f64; 2],
    camera: CameraModel,
    r_bc1: Matrix3<f64>,
    t_bc1: Vector3<f64>,
}

impl StereoInverseDepth {
    /// Factor on `landmark` (inverse depth): anchor observation `anchor_xy`
    /// (undistorted normalized, first camera `body_from_camera`), its match
    /// `measured_uv` \[px\] in the second camera `(model, T_BC1)`.
    pub fn new(
        landmark: Key,
        anchor_xy: [f64; 2],
        measured_uv: [f64; 2],
        (camera, body_from_second): (CameraModel, &Isometry3F64),
        body_from_camera: &Isometry3F64,
    ) -> Self {
        StereoInverseDepth {
            keys: [landmark],
            bearing: Vector3::new(anchor_xy[0], anchor_xy[1], 1.0),
            r_bc: body_from_camera.rotation().matrix(),
            t_bc: body_from_camera.translation(),
            measured: measured_uv,
            camera,
            r_bc1: body_from_second.rotation().matrix(),
            t_bc1: body_from_second.translation(),
        }
    }

    /// Residual \[px\] and, with `jac`, its derivative by the landmark.
    fn evaluate(&self, vars: Vars<'_>, jac: bool, out: &mut Linearization) -> Result<(), FactorError> {
        let l = Landmark::read(&vars, 0, &self.bearing)?;
        let p_c1 = self.r_bc1.transpose() * (self.r_bc * l.point() + self.t_bc - self.t_bc1);
        let Some(jpi) = pixel_residual(&self.camera, &p_c1, self.measured, (jac, &[l.dim]), out)? else {
            return Ok(());
        };
        l.chain_into(&(jpi * self.r_bc1.transpose() * self.r_bc), &mut out.jacobians[0]);
        Ok(())
    }
}

crate::pixel::pixel_factor!(StereoInverseDepth);

/// How a body moves around a frame's stamp, for [`CalibratingReprojection`]:
/// the bias-corrected rate as a quadratic in the time `τ` from the stamp,
/// `ω(τ) = ω₀ + ω₁ τ + ω₂ τ²` \[rad/s, rad/s², rad/s³; body frame\], and the
/// bias-corrected specific force at the stamp \[m/s², body frame\].
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ExposureMotion {
    /// `[ω₀, ω₁, ω₂]`.
    pub rate: [[f64; 3]; 3],
    /// Specific force `f`.
    pub specific_force: [f64; 3],
}

impl ExposureMotion {
    /// The rotation vector `φ(td) = ω₀ td + ω₁ td²/2 + ω₂ td³/3` \[rad, body
    /// frame\] by which the body turns from the stamp to `td` \[s\] after it.
    pub fn rotation_vector(&self, td: f64) -> Vector3<f64> {
        let [w0, w1, w2] = self.rate.map(Vector3::from);
        w0 * td + w1 * (0.5 * td * td) + w2 * (td * td * td / 3.0)
    }
}

/// [`InverseDepthReprojection`] with the camera's extrinsic `T_BC` and time
/// offset `td` as unknowns, for their online calibration in a sliding window
/// (VINS-Mono's `estimate_extrinsic` / `estimate_td`): a factor on
/// `[X_a, V_a, X_j, V_j, L, T_BC, td]` (SE(3), R³, SE(3), R³, a [`Landmark`]
/// `[ρ]` or `[δx, δy, ρ]`, SE(3), R¹; 26 or 28 tangent dimensions), with
/// hand-written Jacobians (wrapped in [`tumble_solvers::AutoDiff`] with 26 or
/// 28 dual directions, the same residual is differentiated automatically).
///
/// An image stamped `t` by the camera was exposed at IMU time `t + td`
/// (Kalibr's `timeshift_cam_imu`). Each body pose (state at the stamp,
/// velocity `v` \[m/s, world\]) is moved to the exposure with the IMU's motion
/// around the stamp ([`ExposureMotion`]): `R Exp(φ)` with
/// `φ = ω₀ td + ω₁ td²/2 + ω₂ td³/3`, and `p + v td + (R f + g) td²/2`. A
/// constant rate alone (VINS-Mono's feature velocity, the first order) leaves
/// 1.6 px RMS at 8 ms on a hand-held motion of 4 rad/s and 80 rad/s². The
/// landmark `p_Ba = R_BC f / ρ + t_BC` of the anchor goes through the world
/// into the observing camera: `r = π(R_BCᵀ (p_Bj − t_BC)) − uv_j` \[px\].
/// Behind the camera the residual is finite and large, so a trial step there
/// is rejected.
///
/// ```
/// use nalgebra::{Vector1, Vector3};
/// use tumble_factors::camera::{CameraModel, Distortion};
/// use tumble_factors::reprojection::{CalibratingReprojection, ExposureMotion};
/// use tumble_solvers::{check_jacobians, se3_from_quaternion, AutoDiff, Key, L, V, X};
/// let cam = CameraModel { fx: 460.0, fy: 460.0, cx: 376.0, cy: 240.0,
///     distortion: Distortion::RadTan { k1: -0.28, k2: 0.07, p1: 2e-4, p2: 2e-5 } };
/// let keys = [X(0), V(0), X(1), V(1), L(7), Key::new('c', 0), Key::new('d', 0)];
/// let m = |w: [f64; 3]| ExposureMotion { rate: [w, [2.0, -1.0, 3.0], [5.0, 4.0, -6.0]], specific_force: [0.3, 0.1, 9.8] };
/// let motion = [m([0.3, -0.2, 0.5]), m([0.1, 0.4, -0.3])];
/// let f = CalibratingReprojection::new(keys, [0.1, -0.05], [380.0, 230.0], motion, cam, [0.0, 0.0, -9.81]);
/// let xa = se3_from_quaternion([1.0, 0.0, 0.0, 0.0], Vector3::zeros());
/// let xj = se3_from_quaternion([0.999, 0.02, -0.03, 0.01], Vector3::new(0.2, 0.05, -0.1));
/// let (va, vj) = (Vector3::new(0.5, 0.1, 0.0), Vector3::new(0.4, -0.2, 0.1));
/// let t_bc = se3_from_quaternion([0.7, 0.0, 0.0, 0.7], Vector3::new(0.05, -0.02, 0.01));
/// let (rho, td) = (Vector1::new(0.4), Vector1::new(0.006));
/// let vars: [&dyn tumble_solvers::DynVariable; 7] = [&xa, &va, &xj, &vj, &rho, &t_bc, &td];
/// // The factor's own (analytic) Jacobians, and the autodiff form of the same residual.
/// assert!(check_jacobians(&f, &vars).unwrap().passes(1e-6));
/// assert!(check_jacobians(&AutoDiff::<_, 26>::new(f.clone()), &vars).unwrap().passes(1e-6));
/// // The landmark with its bearing estimated: [δx, δy, ρ].
/// let l = Vector3::new(0.003, -0.002, 0.4);
/// let vars: [&dyn tumble_solvers::DynVariable; 7] = [&xa, &va, &xj, &vj, &l, &t_bc, &td];
/// assert!(check_jacobians(&f, &vars).unwrap().passes(1e-6));
/// assert!(check_jacobians(&AutoDiff::<_, 28>::new(f.clone()), &vars).unwrap().passes(1e-6));
/// ```
#[derive(Clone, Debug)]
pub struct CalibratingReprojection {
    keys: [Key; 7],
    bearing: [f64; 3],
    measured: [f64; 2],
    motion: [ExposureMotion; 2],
    gravity: [f64; 3],
    kind: crate::camera::DistortionKind,
    intrinsics: [f64; 8],
}

impl CalibratingReprojection {
    /// Factor on `[X_a, V_a, X_j, V_j, L, T_BC, td]`: anchor observation
    /// `anchor_xy` (undistorted normalized), observation `measured_uv` \[px\]
    /// in frame j, the body's motion around the two frames' stamps, the
    /// camera's model (intrinsics fixed) and gravity in the world \[m/s²\].
    pub fn new(
        keys: [Key; 7],
        anchor_xy: [f64; 2],
        measured_uv: [f64; 2],
        motion: [ExposureMotion; 2],
        camera: CameraModel,
        gravity: [f64; 3],
    ) -> Self {
        CalibratingReprojection {
            keys,
            bearing: [anchor_xy[0], anchor_xy[1], 1.0],
            measured: measured_uv,
            motion,
            gravity,
            kind: camera.distortion.kind(),
            intrinsics: camera.to_vector(),
        }
    }

    /// The rotation vector `φ(td)` and the position change `v td + (R f + g) td²/2`
    /// \[m, world\] of frame `k` (0 anchor, 1 observing) with pose `x` and velocity `v`.
    fn moved<T: tumble_solvers::Real>(&self, k: usize, x: &[T], v: &[T], td: T) -> ([T; 3], [T; 3]) {
        let m = &self.motion[k];
        let (t2, t3) = (td * td, td * td * td);
        let phi = [0, 1, 2].map(|i| td * m.rate[0][i] + t2 * (0.5 * m.rate[1][i]) + t3 * (m.rate[2][i] / 3.0));
        let rf = crate::pixel::rot(&x[..9], m.specific_force.map(T::from));
        let dp = [0, 1, 2].map(|i| v[i] * td + (rf[i] + self.gravity[i]) * (t2 * 0.5));
        (phi, dp)
    }
}

/// `S(φ) = I + [φ]× + [φ]×²/2 + [φ]×³/6`, the third-order series of `Exp(φ)`
/// that [`crate::rig`]'s `small_rotation` applies.
fn series(phi: &Vector3<f64>) -> Matrix3<f64> {
    let a = hat(phi);
    Matrix3::identity() + a + a * a * 0.5 + a * a * a * (1.0 / 6.0)
}

/// `∂(S(φ) u)/∂φ` (3×3) for [`series`].
fn series_derivative(phi: &Vector3<f64>, u: &Vector3<f64>) -> Matrix3<f64> {
    let a = hat(phi);
    let w = phi.cross(u);
    let z = phi.cross(&w);
    let hu = hat(u);
    -hu + (-hat(&w) - a * hu) * 0.5 + (-hat(&z) - a * hat(&w) - a * a * hu) * (1.0 / 6.0)
}

impl CalibratingReprojection {
    /// `φ(td)`, its derivative by `td`, the specific force `f` \[m/s², body\]
    /// of frame `k` (0 anchor, 1 observing).
    fn exposure(&self, k: usize, td: f64) -> (Vector3<f64>, Vector3<f64>, Vector3<f64>) {
        let m = &self.motion[k];
        let [w0, w1, w2] = m.rate.map(Vector3::from);
        (m.rotation_vector(td), w0 + w1 * td + w2 * (td * td), m.specific_force.into())
    }

    /// Residual \[px\] and, with `jac`, its seven Jacobian blocks
    /// `[X_a, V_a, X_j, V_j, L, T_BC, td]` (6, 3, 6, 3, 1 or 3, 6, 1 columns), by
    /// hand from [`tumble_solvers::AutoDiffResidual::residual`]'s expression
    /// (right perturbations, `[ω, ν]` for SE(3)); the autodiff form, 26 dual
    /// directions per observation, made the window's solve ≈ 3× slower.
    fn evaluate(&self, vars: Vars<'_>, jac: bool, out: &mut Linearization) -> Result<(), FactorError> {
        let xa: &Isometry3F64 = vars.get(0)?;
        let va: &Vector3<f64> = vars.get(1)?;
        let xj: &Isometry3F64 = vars.get(2)?;
        let vj: &Vector3<f64> = vars.get(3)?;
        let l = Landmark::read(&vars, 4, &Vector3::from(self.bearing))?;
        let tbc: &Isometry3F64 = vars.get(5)?;
        let td = vars.get::<Vector1<f64>>(6)?[0];
        let (ra, pa) = (xa.rotation().matrix(), xa.translation());
        let (rj, pj) = (xj.rotation().matrix(), xj.translation());
        let (r_bc, t_bc) = (tbc.rotation().matrix(), tbc.translation());
        let g = Vector3::from(self.gravity);
        let p_ca = l.point();
        let (phi_a, dphi_a, fa) = self.exposure(0, td);
        let (phi_j, dphi_j, fj) = self.exposure(1, td);
        let pba = r_bc * p_ca + t_bc;
        let sa = series(&phi_a);
        let qa = sa * pba;
        let pw = ra * qa + pa + va * td + (ra * fa + g) * (0.5 * td * td);
        let e = rj.transpose() * (pw - pj - vj * td - (rj * fj + g) * (0.5 * td * td));
        let sj = series(&-phi_j);
        let pc = r_bc.transpose() * (sj * e - t_bc);
        let cols = [6, 3, 6, 3, l.dim, 6, 1];
        let Some((jpi, _)) =
            crate::pixel::pixel_linearization(self.kind, &self.intrinsics, &pc, self.measured, (jac, &cols), out)?
        else {
            return Ok(());
        };
        // d uv / d pbj, d e, d pw; and d pw / d pba.
        let gb = jpi * r_bc.transpose();
        let h = gb * sj;
        let k = h * rj.transpose();
        let kq = k * ra * sa;
        let half_t2 = 0.5 * td * td;
        let [jxa, jva, jxj, jvj, jl, je, jtd] = &mut out.jacobians[..] else {
            unreachable!("reshaped to seven blocks")
        };
        jxa.fixed_view_mut::<2, 3>(0, 0).copy_from(&(-k * ra * (hat(&qa) + hat(&fa) * half_t2)));
        jxa.fixed_view_mut::<2, 3>(0, 3).copy_from(&(k * ra));
        jva.copy_from(&(k * td));
        jxj.fixed_view_mut::<2, 3>(0, 0).copy_from(&(h * (hat(&e) + hat(&fj) * half_t2)));
        jxj.fixed_view_mut::<2, 3>(0, 3).copy_from(&(-h));
        jvj.copy_from(&(-k * td));
        l.chain_into(&(kq * r_bc), jl);
        je.fixed_view_mut::<2, 3>(0, 0).copy_from(&(jpi * hat(&pc) - kq * r_bc * hat(&p_ca)));
        je.fixed_view_mut::<2, 3>(0, 3).copy_from(&(-jpi + kq * r_bc));
        let dpw = ra * series_derivative(&phi_a, &pba) * dphi_a + va + (ra * fa + g) * td;
        let dd = dpw - vj - (rj * fj + g) * td;
        let dpbj = sj * (rj.transpose() * dd) - series_derivative(&-phi_j, &e) * dphi_j;
        jtd.copy_from(&(gb * dpbj));
        Ok(())
    }
}

crate::pixel::pixel_factor!(CalibratingReprojection);

impl CalibratingReprojection {
    /// The residual of [`tumble_solvers::AutoDiffResidual`], for a landmark
    /// `[ρ]` or `[δx, δy, ρ]` (`p[4]`).
    fn generic_residual<T: tumble_solvers::Real>(&self, p: &[&[T]]) -> Vec<T> {
        use crate::pixel::{pixel_residual, rot, rot_t, small_rotation};
        let (xa, va, xj, vj, tbc, td) = (p[0], p[1], p[2], p[3], p[5], p[6][0]);
        let (bearing, rho) = match p[4] {
            [dx, dy, rho] => ([*dx + self.bearing[0], *dy + self.bearing[1], T::one()], *rho),
            _ => (self.bearing.map(T::from), p[4][0]),
        };
        let inv = T::one() / rho;
        // The landmark in the anchor body frame at its exposure.
        let r_pca = rot(&tbc[..9], bearing.map(|b| inv * b));
        let pba = [0, 1, 2].map(|i| r_pca[i] + tbc[9 + i]);
        // Anchor pose at exposure: R_a Exp(φ_a), p_a + Δp_a.
        let (phi_a, dp_a) = self.moved(0, xa, va, td);
        let rw = rot(&xa[..9], small_rotation(phi_a, pba));
        let pw = [0, 1, 2].map(|i| rw[i] + xa[9 + i] + dp_a[i]);
        // Into the observing body at its exposure: Exp(φ_j)ᵀ R_jᵀ (p_W − p_j − Δp_j).
        let (phi_j, dp_j) = self.moved(1, xj, vj, td);
        let d = [0, 1, 2].map(|i| pw[i] - xj[9 + i] - dp_j[i]);
        let pbj = small_rotation(phi_j.map(|a| -a), rot_t(&xj[..9], d));
        let pc = rot_t(&tbc[..9], [0, 1, 2].map(|i| pbj[i] - tbc[9 + i]));
        let k = self.intrinsics.map(T::from);
        pixel_residual(self.kind, &k, &pc, self.measured)
    }
}

/// The autodiff form with the anchor bearing fixed (a `[ρ]` landmark).
impl tumble_solvers::AutoDiffResidual<26> for CalibratingReprojection {
    fn keys(&self) -> &[Key] {
        &self.keys
    }
    fn residual_dim(&self) -> usize {
        2
    }
    fn residual<T: tumble_solvers::Real>(&self, p: &[&[T]]) -> Vec<T> {
        self.generic_residual(p)
    }
}

/// The autodiff form with the bearing estimated (a `[δx, δy, ρ]` landmark).
impl tumble_solvers::AutoDiffResidual<28> for CalibratingReprojection {
    fn keys(&self) -> &[Key] {
        &self.keys
    }
    fn residual_dim(&self) -> usize {
        2
    }
    fn residual<T: tumble_solvers::Real>(&self, p: &[&[T]]) -> Vec<T> {
        self.generic_residual(p)
    }
}
