//! The IMU preintegration factor (rotation, position, velocity) between two
//! navigation states, and the bias random-walk factor between their biases.
//!
//! States: pose `X` as SE(3) body-in-world (`Isometry3F64`, right perturbation:
//! `R ← R Exp(ω)`, `p ← p + R ν`), velocity `V` in the world frame \[m/s\] (`Vector3`),
//! bias `B = [b_a (m/s²), b_g (rad/s)]` (`Vector6`). Gravity is the world vector
//! `g` (e.g. `[0, 0, −9.81]`), so a body at rest measures `−Rᵀ g`.
//!
//! ```
//! use std::sync::Arc;
//! use nalgebra::{Vector3, Vector6};
//! use tumble_factors::imu_preint::{Preintegrated, PreintegrationParams};
//! use tumble_factors::ImuFactor;
//! use tumble_solvers::{check_jacobians, se3_from_quaternion, X, V, B};
//! let mut pim = Preintegrated::new(PreintegrationParams::default(), Vector3::zeros(), Vector3::zeros());
//! for _ in 0..100 {
//!     pim.integrate(Vector3::new(0.1, 0.0, 9.81), Vector3::new(0.0, 0.0, 0.2), 0.005);
//! }
//! let f = ImuFactor::new([X(0), V(0), B(0), X(1), V(1)], Arc::new(pim), Vector3::new(0.0, 0.0, -9.81));
//! let noise = f.noise_model().unwrap();
//! let x0 = se3_from_quaternion([1.0, 0.0, 0.0, 0.0], Vector3::zeros());
//! let x1 = se3_from_quaternion([0.995, 0.0, 0.0, 0.0998], Vector3::new(0.1, 0.0, 0.0));
//! let (v0, v1, b0) = (Vector3::<f64>::zeros(), Vector3::new(0.2, 0.0, 0.0), Vector6::<f64>::zeros());
//! let report = check_jacobians(&f, &[&x0, &v0, &b0, &x1, &v1]).unwrap();
//! assert!(report.passes(1e-6));
//! ```

use crate::imu_preint::Preintegrated;
use crate::BetweenFactor;
use nalgebra::{DMatrix, DVector, Matrix3, Vector3, Vector6};
use std::sync::Arc;
use tumble_solvers::lie::{hat, so3_log, so3_right_jacobian_inv};
use tumble_solvers::sophus_lie::prelude::*;
use tumble_solvers::sophus_lie::Isometry3F64;
use tumble_solvers::{Factor, FactorError, Key, Linearization, NoiseError, NoiseModel, Vars};

/// IMU factor on `[X_i, V_i, B_i, X_j, V_j]` with residual `[r_θ, r_p, r_v]`:
/// `r_θ = Log(ΔR(b_g)ᵀ R_iᵀ R_j)`,
/// `r_p = R_iᵀ(p_j − p_i − v_i Δt − ½ g Δt²) − Δp(b)`,
/// `r_v = R_iᵀ(v_j − v_i − g Δt) − Δv(b)`, with the deltas corrected to first
/// order for the bias `B_i` (paper eq. 17). Whiten with [`ImuFactor::noise_model`].
#[derive(Clone, Debug)]
pub struct ImuFactor {
    keys: [Key; 5],
    pim: Arc<Preintegrated>,
    gravity: Vector3<f64>,
}

fn pose_parts(x: &Isometry3F64) -> (Matrix3<f64>, Vector3<f64>) {
    (x.rotation().matrix(), x.translation())
}

impl ImuFactor {
    /// Factor on keys `[X_i, V_i, B_i, X_j, V_j]` with world gravity `gravity` \[m/s²\].
    pub fn new(keys: [Key; 5], pim: Arc<Preintegrated>, gravity: Vector3<f64>) -> Self {
        ImuFactor { keys, pim, gravity }
    }
    /// The preintegrated measurements.
    pub fn preintegrated(&self) -> &Preintegrated {
        &self.pim
    }
    /// Noise model from the preintegration covariance.
    pub fn noise_model(&self) -> Result<NoiseModel, NoiseError> {
        self.noise_model_scaled(1.0)
    }
    /// Noise model from the preintegration covariance times `scale` (> 1
    /// weakens the factor, e.g. across an IMU gap).
    pub fn noise_model_scaled(&self, scale: f64) -> Result<NoiseModel, NoiseError> {
        let c = self.pim.covariance() * scale;
        NoiseModel::from_covariance(&DMatrix::from_fn(9, 9, |i, j| c[(i, j)]))
    }

    fn evaluate(&self, vars: Vars<'_>, jac: bool) -> Result<Linearization, FactorError> {
        let (ri, pi) = pose_parts(vars.get::<Isometry3F64>(0)?);
        let vi: &Vector3<f64> = vars.get(1)?;
        let b: &Vector6<f64> = vars.get(2)?;
        let (rj, pj) = pose_parts(vars.get::<Isometry3F64>(3)?);
        let vj: &Vector3<f64> = vars.get(4)?;
        let ba = b.fixed_rows::<3>(0).into_owned();
        let bg = b.fixed_rows::<3>(3).into_owned();
        let dt = self.pim.delta_t();
        let (dr, dp, dv, dr_dbg) = self.pim.corrected(&ba, &bg);
        let e = dr.transpose() * ri.transpose() * rj;
        let r_th = so3_log(&e);
        let xp = pj - pi - vi * dt - self.gravity * (0.5 * dt * dt);
        let xv = vj - vi - self.gravity * dt;
        let rit = ri.transpose();
        let r_p = rit * xp - dp;
        let r_v = rit * xv - dv;
        let mut residual = DVector::zeros(9);
        residual.fixed_rows_mut::<3>(0).copy_from(&r_th);
        residual.fixed_rows_mut::<3>(3).copy_from(&r_p);
        residual.fixed_rows_mut::<3>(6).copy_from(&r_v);
        if !residual.iter().all(|x| x.is_finite()) {
            return Err(FactorError::NonFinite);
        }
        if !jac {
            return Ok(Linearization { residual, jacobians: Vec::new() });
        }
        let jinv = so3_right_jacobian_inv(&r_th);
        let (hba, hbg) = self.pim.bias_jacobians();
        let mut jxi = DMatrix::zeros(9, 6);
        let mut jvi = DMatrix::zeros(9, 3);
        let mut jb = DMatrix::zeros(9, 6);
        let mut jxj = DMatrix::zeros(9, 6);
        let mut jvj = DMatrix::zeros(9, 3);
        let set = |m: &mut DMatrix<f64>, r: usize, c: usize, b: &Matrix3<f64>| {
            m.fixed_view_mut::<3, 3>(r, c).copy_from(b);
        };
        set(&mut jxi, 0, 0, &(-jinv * rj.transpose() * ri));
        set(&mut jxi, 3, 0, &hat(&(rit * xp)));
        set(&mut jxi, 3, 3, &-Matrix3::identity());
        set(&mut jxi, 6, 0, &hat(&(rit * xv)));
        set(&mut jvi, 3, 0, &(-rit * dt));
        set(&mut jvi, 6, 0, &-rit);
        set(&mut jb, 0, 3, &(-jinv * e.transpose() * dr_dbg));
        set(&mut jb, 3, 0, &-hba.fixed_view::<3, 3>(3, 0).into_owned());
        set(&mut jb, 3, 3, &-hbg.fixed_view::<3, 3>(3, 0).into_owned());
        set(&mut jb, 6, 0, &-hba.fixed_view::<3, 3>(6, 0).into_owned());
        set(&mut jb, 6, 3, &-hbg.fixed_view::<3, 3>(6, 0).into_owned());
        set(&mut jxj, 0, 0, &jinv);
        set(&mut jxj, 3, 3, &(rit * rj));
        set(&mut jvj, 6, 0, &rit);
        Ok(Linearization { residual, jacobians: vec![jxi, jvi, jb, jxj, jvj] })
    }
}

impl Factor for ImuFactor {
    fn keys(&self) -> &[Key] {
        &self.keys
    }
    fn residual_dim(&self) -> usize {
        9
    }
    fn residual(&self, vars: Vars<'_>) -> Result<DVector<f64>, FactorError> {
        Ok(self.evaluate(vars, false)?.residual)
    }
    fn linearize(&self, vars: Vars<'_>) -> Result<Linearization, FactorError> {
        self.evaluate(vars, true)
    }
}

/// Bias random walk between `B_i` and `B_j` over `dt` \[s\]: a between factor
/// `r = b_j − b_i` whitened by `diag(σ_a² dt ·I₃, σ_g² dt ·I₃)`, with the random
/// walks `σ_a` \[m/s³/√Hz\] and `σ_g` \[rad/s²/√Hz\] (Kalibr's `*_random_walk`).
pub fn bias_random_walk(
    bi: Key,
    bj: Key,
    accel_random_walk: f64,
    gyro_random_walk: f64,
    dt: f64,
) -> Result<(BetweenFactor<Vector6<f64>>, NoiseModel), NoiseError> {
    bias_random_walk_axes(bi, bj, [accel_random_walk; 3], [gyro_random_walk; 3], dt)
}

/// [`bias_random_walk`] with one random walk per body axis (x, y, z) for each
/// triad (see [`crate::imu_preint::NoiseAxes`]).
pub fn bias_random_walk_axes(
    bi: Key,
    bj: Key,
    accel_random_walk: [f64; 3],
    gyro_random_walk: [f64; 3],
    dt: f64,
) -> Result<(BetweenFactor<Vector6<f64>>, NoiseModel), NoiseError> {
    let (a, g, s) = (accel_random_walk, gyro_random_walk, dt.sqrt());
    let noise = NoiseModel::diagonal(&[a[0] * s, a[1] * s, a[2] * s, g[0] * s, g[1] * s, g[2] * s])?;
    Ok((BetweenFactor::new(bi, bj, Vector6::zeros()), noise))
}
