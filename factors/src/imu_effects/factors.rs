//! The audit's factors: a static interval's mean reading and a turn's
//! integrated rotation under the calibration and its effects.

use super::{check_effects, cols, correct, effect_blocks, read, Context, Layout, ModelParams, Read};
use crate::imu_calib::{accel_matrix, gyro_matrix, orthogonal_basis, AccelParams, GyroMatrix};
use nalgebra::{DMatrix, DVector, Dyn, Matrix3, Matrix3x2, OMatrix, Vector3, U3};
use tumble_solvers::lie::{hat, so3_exp, so3_right_jacobian};
use tumble_solvers::{Factor, FactorError, Key, Linearization, Vars};

/// One static interval: `r = [‖a‖ − g, ω]` (4 rows: \[m/s²\], \[rad/s\]) from the
/// interval's mean raw readings. Keys `[M_a/b_a (AccelParams), M_g (GyroMatrix),
/// b_g (Vector3), δa (Vector3), one `DynVector` per effect]`.
///
/// ```
/// use tumble_factors::imu_effects::{Context, Effect, Layout, StaticFactor};
/// use tumble_factors::imu_calib::{AccelParams, GyroMatrix};
/// use tumble_solvers::{check_jacobians, DynVector, Key};
/// use nalgebra::Vector3;
/// let layout = Layout { effects: vec![Effect::GyroGSensitivity] };
/// let keys = vec![Key::new('a', 0), Key::new('g', 0), Key::new('b', 0), Key::new('w', 0), Key::new('e', 0)];
/// let f = StaticFactor::new(keys, layout, Vector3::new(0.2, 3.0, 9.1), Vector3::new(0.01, 0.0, -0.02),
///     Context { dtemp: 2.0, time: 30.0 }, 9.81).unwrap();
/// let a = AccelParams::from_row_slice(&[1.0, 0.01, 0.0, 1.0, 0.02, 1.0, 0.0, 0.1, 0.0]);
/// let g = GyroMatrix::from_row_slice(&[1.0, 0.01, 0.0, -0.01, 1.0, 0.02, 0.0, 0.0, 1.0]);
/// let e = DynVector::from_slice(&[1e-3, 2e-4, 0.0, 0.0, 1e-3, 0.0, 3e-4, 0.0, 1e-3]);
/// let b = Vector3::new(0.011, 0.001, -0.019);
/// assert!(check_jacobians(&f, &[&a, &g, &b, &Vector3::zeros(), &e]).unwrap().passes(1e-6));
/// ```
#[derive(Clone, Debug)]
pub struct StaticFactor {
    keys: Vec<Key>,
    layout: Layout,
    raw_accel: Vector3<f64>,
    raw_gyro: Vector3<f64>,
    ctx: Context,
    gravity: f64,
}

impl StaticFactor {
    /// Factor of an interval with mean raw readings `raw_accel`, `raw_gyro`
    /// taken at `ctx`, under gravity `gravity` \[m/s²\].
    pub fn new(
        keys: Vec<Key>,
        layout: Layout,
        raw_accel: Vector3<f64>,
        raw_gyro: Vector3<f64>,
        ctx: Context,
        gravity: f64,
    ) -> Result<Self, FactorError> {
        check_effects(&layout, keys.len(), 4)?;
        Ok(StaticFactor { keys, layout, raw_accel, raw_gyro, ctx, gravity })
    }

    fn eval(&self, vars: Vars<'_>, jac: bool) -> Result<(DVector<f64>, DMatrix<f64>), FactorError> {
        check_effects(&self.layout, vars.len(), 4)?;
        let v = read(vars, 2)?;
        let p = ModelParams {
            accel: &v.accel,
            gyro: &v.gyro,
            gyro_bias: v.extra[0],
            wander: v.extra[1],
            effects: &v.effects,
        };
        let c = correct(&self.layout, &p, &self.raw_accel, &self.raw_gyro, self.ctx, jac);
        let n = c.accel.norm();
        let r = DVector::from_vec(vec![n - self.gravity, c.gyro.x, c.gyro.y, c.gyro.z]);
        let mut j = DMatrix::zeros(if jac { 4 } else { 0 }, if jac { self.layout.cols() } else { 0 });
        if jac {
            let u = c.accel / n.max(1e-300);
            j.row_mut(0).copy_from(&(u.transpose() * &c.d_accel));
            j.rows_mut(1, 3).copy_from(&c.d_gyro);
        }
        Ok((r, j))
    }

    /// Covariance (4×4) of the residual from white noise of per-sample variance
    /// `var_accel`, `var_gyro` (raw units², per axis) averaged over `samples`.
    pub fn noise_covariance(
        &self,
        accel: &AccelParams,
        gyro: &GyroMatrix,
        var_accel: &Vector3<f64>,
        var_gyro: &Vector3<f64>,
        samples: usize,
    ) -> DMatrix<f64> {
        let n = samples.max(1) as f64;
        let (ma, mg) = (accel_matrix(accel), gyro_matrix(gyro));
        let u = (ma * (self.raw_accel - Vector3::new(accel[6], accel[7], accel[8]))).normalize();
        let sa = ma * Matrix3::from_diagonal(var_accel) * ma.transpose() / n;
        let sg = mg * Matrix3::from_diagonal(var_gyro) * mg.transpose() / n;
        let mut c = DMatrix::zeros(4, 4);
        c[(0, 0)] = (u.transpose() * sa * u)[0];
        c.view_mut((1, 1), (3, 3)).copy_from(&sg);
        c
    }
}

impl Factor for StaticFactor {
    fn keys(&self) -> &[Key] {
        &self.keys
    }
    fn residual_dim(&self) -> usize {
        4
    }
    fn residual(&self, vars: Vars<'_>) -> Result<DVector<f64>, FactorError> {
        Ok(self.eval(vars, false)?.0)
    }
    fn linearize(&self, vars: Vars<'_>) -> Result<Linearization, FactorError> {
        let (residual, j) = self.eval(vars, true)?;
        let mut jacobians = vec![
            cols(&j, 0, 9),
            cols(&j, Layout::GYRO, 9),
            cols(&j, Layout::GYRO_BIAS, 3),
            cols(&j, Layout::WANDER, 3),
        ];
        jacobians.extend(effect_blocks(&self.layout, &j));
        Ok(Linearization { residual, jacobians })
    }
}

/// A motion between two static intervals: the gyro integrated with the extended
/// model must turn the gravity direction of the first interval into that of the
/// second. `r = Bᵀ(Rᵀ ĝ₀ − ĝ₁)` (2 rows \[rad\]), `B` a fixed basis of the plane
/// orthogonal to the second direction. Keys `[M_a/b_a, M_g, b_g at the first
/// interval, b_g at the second, δa at the first, δa at the second, effects…]`;
/// the motion uses the mean of the two intervals' biases.
///
/// ```
/// use tumble_factors::imu_effects::{Context, Effect, Layout, MotionFactor, MotionSamples};
/// use tumble_factors::imu_calib::{AccelParams, GyroMatrix};
/// use tumble_solvers::{check_jacobians, DynVector, Key};
/// use nalgebra::Vector3;
/// let n = 40;
/// let samples = MotionSamples {
///     raw_gyro: (0..n).map(|i| Vector3::new(0.8, 0.2 * (i as f64 * 0.1).sin(), -0.3)).collect(),
///     raw_accel: (0..n).map(|i| Vector3::new(1.0, 2.0 + 0.1 * i as f64, 9.0)).collect(),
///     context: (0..n).map(|i| Context { dtemp: 1.0 + 0.01 * i as f64, time: 20.0 + 0.01 * i as f64 }).collect(),
///     dt: vec![0.01; n - 1],
/// };
/// let layout = Layout { effects: vec![Effect::GyroScaleNonlinearity, Effect::GyroGSensitivity] };
/// let keys = (0..8).map(|i| Key::new('k', i)).collect();
/// let c0 = Context { dtemp: 1.0, time: 19.0 };
/// let c1 = Context { dtemp: 1.5, time: 21.0 };
/// let f = MotionFactor::new(keys, layout, samples, [Vector3::new(0.0, 0.5, 9.8), Vector3::new(0.0, 3.5, 9.1)],
///     [c0, c1], [100, 100]).unwrap();
/// let a = AccelParams::from_row_slice(&[1.0, 0.01, 0.0, 1.0, 0.02, 1.0, 0.0, 0.1, 0.0]);
/// let g = GyroMatrix::from_row_slice(&[1.0, 0.01, 0.0, -0.01, 1.0, 0.02, 0.0, 0.0, 1.0]);
/// let (b0, b1) = (Vector3::new(0.01, 0.0, 0.0), Vector3::new(0.012, 0.0, 0.001));
/// let (w0, w1) = (Vector3::new(0.0, 0.01, 0.0), Vector3::new(0.01, 0.0, 0.0));
/// let e0 = DynVector::from_slice(&[1e-2, -2e-3, 3e-3]);
/// let e1 = DynVector::from_slice(&[1e-3, 2e-4, 0.0, 0.0, 1e-3, 0.0, 3e-4, 0.0, 1e-3]);
/// assert!(check_jacobians(&f, &[&a, &g, &b0, &b1, &w0, &w1, &e0, &e1]).unwrap().passes(1e-6));
/// ```
#[derive(Clone, Debug)]
pub struct MotionFactor {
    keys: Vec<Key>,
    layout: Layout,
    samples: MotionSamples,
    ends: [Vector3<f64>; 2],
    end_context: [Context; 2],
    end_samples: [usize; 2],
    basis: Matrix3x2<f64>,
}

/// Raw samples of one motion (from the last sample of one static interval to
/// the first of the next).
#[derive(Clone, Debug)]
pub struct MotionSamples {
    /// Raw gyro readings (n ≥ 2).
    pub raw_gyro: Vec<Vector3<f64>>,
    /// Raw accelerometer readings (n).
    pub raw_accel: Vec<Vector3<f64>>,
    /// Context of each sample (n).
    pub context: Vec<Context>,
    /// Step lengths (n − 1) \[s\].
    pub dt: Vec<f64>,
}

/// One step's contribution: rotation increment, `J_r(φ) Δt`, and ∂ω/∂parameters.
type Step = (Matrix3<f64>, Matrix3<f64>, OMatrix<f64, U3, Dyn>);

impl MotionFactor {
    /// Factor over `samples`, between static intervals with mean raw
    /// accelerometer readings `ends` taken at `end_context` (averaged over
    /// `end_samples` samples each).
    pub fn new(
        keys: Vec<Key>,
        layout: Layout,
        samples: MotionSamples,
        ends: [Vector3<f64>; 2],
        end_context: [Context; 2],
        end_samples: [usize; 2],
    ) -> Result<Self, FactorError> {
        check_effects(&layout, keys.len(), 6)?;
        let n = samples.raw_gyro.len();
        if n < 2 || samples.raw_accel.len() != n || samples.context.len() != n || samples.dt.len() + 1 != n {
            return Err(FactorError::Other(format!(
                "motion needs n ≥ 2 gyro, accel and context samples and n − 1 steps; got {n}, {}, {}, {}",
                samples.raw_accel.len(),
                samples.context.len(),
                samples.dt.len()
            )));
        }
        if samples.dt.iter().any(|d| !(d.is_finite() && *d > 0.0)) {
            return Err(FactorError::Other("motion steps must be positive".into()));
        }
        if ends.iter().any(|e| !(e.norm() > 0.0 && e.norm().is_finite())) {
            return Err(FactorError::Other("static readings must be finite and non-zero".into()));
        }
        let basis = orthogonal_basis(&ends[1].normalize());
        Ok(MotionFactor { keys, layout, samples, ends, end_context, end_samples, basis })
    }

    fn params<'a>(v: &'a Read, bias: Vector3<f64>, wander: Vector3<f64>) -> ModelParams<'a> {
        ModelParams { accel: &v.accel, gyro: &v.gyro, gyro_bias: bias, wander, effects: &v.effects }
    }

    /// Gravity direction at end `k` and its Jacobian (3 × cols; the `δa` slot is that end's).
    fn direction(&self, v: &Read, k: usize, jac: bool) -> (Vector3<f64>, DMatrix<f64>) {
        let p = Self::params(v, Vector3::zeros(), v.extra[2 + k]);
        let c = correct(&self.layout, &p, &self.ends[k], &Vector3::zeros(), self.end_context[k], jac);
        let n = c.accel.norm().max(1e-300);
        let g = c.accel / n;
        let j = if jac {
            let proj = (Matrix3::identity() - g * g.transpose()) / n;
            let d = proj * &c.d_accel;
            DMatrix::from_iterator(3, d.ncols(), d.iter().copied())
        } else {
            DMatrix::zeros(0, 0)
        };
        (g, j)
    }

    /// Integrate: rotation and, per step, (Exp, J_r Δt, ∂ω/∂θ).
    fn steps(&self, v: &Read, jac: bool) -> Vec<Step> {
        let s = &self.samples;
        let bias = 0.5 * (v.extra[0] + v.extra[1]);
        let wander = 0.5 * (v.extra[2] + v.extra[3]);
        let p = Self::params(v, bias, wander);
        (0..s.dt.len())
            .map(|i| {
                let mid = |x: &[Vector3<f64>]| 0.5 * (x[i] + x[i + 1]);
                let (c0, c1) = (s.context[i], s.context[i + 1]);
                let ctx = Context { dtemp: 0.5 * (c0.dtemp + c1.dtemp), time: 0.5 * (c0.time + c1.time) };
                let c = correct(&self.layout, &p, &mid(&s.raw_accel), &mid(&s.raw_gyro), ctx, jac);
                let phi = c.gyro * s.dt[i];
                (so3_exp(&phi), so3_right_jacobian(&phi) * s.dt[i], c.d_gyro)
            })
            .collect()
    }

    fn eval(&self, vars: Vars<'_>, jac: bool) -> Result<(DVector<f64>, Vec<DMatrix<f64>>), FactorError> {
        check_effects(&self.layout, vars.len(), 6)?;
        let v = read(vars, 4)?;
        let steps = self.steps(&v, jac);
        let r_mat = steps.iter().fold(Matrix3::identity(), |r, s| r * s.0);
        let (g0, j0) = self.direction(&v, 0, jac);
        let (g1, j1) = self.direction(&v, 1, jac);
        let x = r_mat.transpose() * g0;
        let bt = self.basis.transpose();
        let r = bt * (x - g1);
        let residual = DVector::from_column_slice(r.as_slice());
        if !jac {
            return Ok((residual, Vec::new()));
        }
        // A rate error δω_i moves R to R·Exp(Σ A_i δω_i), A_i = S_iᵀ J_r(φ_i) Δt_i.
        let cols_n = self.layout.cols();
        let mut j_phi = DMatrix::zeros(3, cols_n);
        let mut s_after = Matrix3::identity();
        for (e, jr, dw) in steps.iter().rev() {
            let a = s_after.transpose() * jr;
            j_phi +=
                DMatrix::from_iterator(3, 3, a.iter().copied()) * DMatrix::from_iterator(3, cols_n, dw.iter().copied());
            s_after = e * s_after;
        }
        let d_rate = DMatrix::from_iterator(2, 3, (bt * hat(&x)).iter().copied()) * j_phi;
        let bt_d = DMatrix::from_iterator(2, 3, bt.iter().copied());
        let rt = DMatrix::from_iterator(3, 3, r_mat.transpose().iter().copied());
        let d_g0 = &bt_d * rt * j0;
        let d_g1 = -(&bt_d * j1);
        let all = &d_rate + &d_g0 + &d_g1;
        let half_rate = |from: usize| cols(&d_rate, from, 3) * 0.5;
        let mut jacobians = vec![
            cols(&all, 0, 9),
            cols(&d_rate, Layout::GYRO, 9),
            half_rate(Layout::GYRO_BIAS),
            half_rate(Layout::GYRO_BIAS),
            half_rate(Layout::WANDER) + cols(&d_g0, Layout::WANDER, 3),
            half_rate(Layout::WANDER) + cols(&d_g1, Layout::WANDER, 3),
        ];
        jacobians.extend(effect_blocks(&self.layout, &all));
        Ok((residual, jacobians))
    }

    /// Covariance (2×2, \[rad²\]) of the residual from white noise of
    /// per-sample variance `var_accel`, `var_gyro` (raw units², per axis): the
    /// gyro noise integrated over the motion plus the noise of the two static
    /// directions (means of `end_samples` samples), at the given parameters
    /// (base model, no effects).
    pub fn noise_covariance(
        &self,
        accel: &AccelParams,
        gyro: &GyroMatrix,
        bias: &Vector3<f64>,
        var_accel: &Vector3<f64>,
        var_gyro: &Vector3<f64>,
    ) -> nalgebra::Matrix2<f64> {
        let mg = gyro_matrix(gyro);
        let ma = accel_matrix(accel);
        let mut r = Matrix3::identity();
        let mut steps = Vec::with_capacity(self.samples.dt.len());
        for i in 0..self.samples.dt.len() {
            let raw = 0.5 * (self.samples.raw_gyro[i] + self.samples.raw_gyro[i + 1]);
            let phi = mg * (raw - bias) * self.samples.dt[i];
            let e = so3_exp(&phi);
            r *= e;
            steps.push((e, so3_right_jacobian(&phi) * self.samples.dt[i]));
        }
        let sw = mg * Matrix3::from_diagonal(var_gyro) * mg.transpose();
        let mut cov_phi = Matrix3::zeros();
        let mut s_after = Matrix3::identity();
        for (e, jr) in steps.iter().rev() {
            let a = s_after.transpose() * jr;
            cov_phi += a * sw * a.transpose();
            s_after = e * s_after;
        }
        let b_a = Vector3::new(accel[6], accel[7], accel[8]);
        let sa = ma * Matrix3::from_diagonal(var_accel) * ma.transpose();
        let dir_cov = |k: usize| {
            let a = ma * (self.ends[k] - b_a);
            let g = a.normalize();
            let proj = (Matrix3::identity() - g * g.transpose()) / a.norm();
            proj * sa * proj.transpose() / self.end_samples[k].max(1) as f64
        };
        let g0 = (ma * (self.ends[0] - b_a)).normalize();
        let bt = self.basis.transpose();
        let d = bt * hat(&(r.transpose() * g0));
        let rt = bt * r.transpose();
        d * cov_phi * d.transpose() + rt * dir_cov(0) * rt.transpose() + bt * dir_cov(1) * self.basis
    }
}

impl Factor for MotionFactor {
    fn keys(&self) -> &[Key] {
        &self.keys
    }
    fn residual_dim(&self) -> usize {
        2
    }
    fn residual(&self, vars: Vars<'_>) -> Result<DVector<f64>, FactorError> {
        Ok(self.eval(vars, false)?.0)
    }
    fn linearize(&self, vars: Vars<'_>) -> Result<Linearization, FactorError> {
        let (residual, jacobians) = self.eval(vars, true)?;
        Ok(Linearization { residual, jacobians })
    }
}
