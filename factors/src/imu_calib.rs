//! Factors of turntable-free IMU calibration (paper §2, after Tedaldi, Pretto
//! and Menegatti, ICRA 2014 — the method of imu_tk).
//!
//! Both factors work on the *inverse* sensor model, the map from raw readings
//! to physical quantities, because it is linear in its parameters:
//!
//! ```text
//! a = M_a (ã − b_a)      M_a = (T_a K_a)⁻¹, upper triangular (6 entries)
//! ω = M_g (ω̃ − b_g)      M_g = (T_g K_g)⁻¹, full 3×3 (9 entries)
//! ```
//!
//! `M = T'·K'` with unit-diagonal `T'` and diagonal `K'` is exactly imu_tk's
//! `calibrated = T·K·(raw − b)`; the paper's `T`, `K` follow from `M⁻¹` (its
//! diagonal is `K`). Raw readings are in the sensor's units (counts or SI);
//! `a` is in m/s², `ω` in rad/s.

use nalgebra::{DMatrix, DVector, Matrix3, Matrix3x2, Quaternion, SMatrix, SVector, UnitQuaternion, Vector2, Vector3};
use tumble_solvers::lie::hat;
use tumble_solvers::{Factor, FactorError, Key, Linearization, Vars};

/// Rodrigues' coefficients of one integration step `w` \[rad\]:
/// `sin θ/θ`, `(1 − cos θ)/θ²` and `(θ − sin θ)/θ³`, by their series through
/// θ⁶ below θ = 0.05 (the next term is under 10⁻¹⁶: exact to rounding, without
/// the sine and cosine that dominated the calibration's time; a gyro step at
/// 100 Hz turns less than 0.05 rad below 5 rad/s).
fn rodrigues(t2: f64) -> (f64, f64, f64) {
    if t2 >= 2.5e-3 {
        let t = t2.sqrt();
        let (sin, cos) = t.sin_cos();
        return (sin / t, (1.0 - cos) / t2, (t - sin) / (t2 * t));
    }
    // Horner's rule on the series' coefficients: products, no divisions (a
    // division costs several products' time, and these run for every step).
    let a = 1.0 + t2 * (-1.0 / 6.0 + t2 * (1.0 / 120.0 - t2 * (1.0 / 5040.0)));
    let b = 0.5 + t2 * (-1.0 / 24.0 + t2 * (1.0 / 720.0 - t2 * (1.0 / 40320.0)));
    let c = 1.0 / 6.0 + t2 * (-1.0 / 120.0 + t2 * (1.0 / 5040.0 - t2 * (1.0 / 362880.0)));
    (a, b, c)
}

/// The unit quaternion of `Exp(w)` for one integration step: `cos(θ/2)` and
/// `sin(θ/2)/θ` by their series through (θ/2)⁶ below θ = 0.05 (as [`rodrigues`]).
#[inline]
fn step_quaternion(w: &Vector3<f64>) -> Quaternion<f64> {
    let t2 = w.norm_squared();
    let (c, s) = if t2 >= 2.5e-3 {
        let t = t2.sqrt();
        let (sin, cos) = (0.5 * t).sin_cos();
        (cos, sin / t)
    } else {
        let h2 = 0.25 * t2;
        (
            1.0 + h2 * (-0.5 + h2 * (1.0 / 24.0 + h2 * (-1.0 / 720.0 + h2 * (1.0 / 40320.0)))),
            0.5 + h2 * (-1.0 / 12.0 + h2 * (1.0 / 240.0 - h2 * (1.0 / 10080.0))),
        )
    };
    Quaternion::new(c, s * w.x, s * w.y, s * w.z)
}

/// `a·[w]×`: each row of `a` crossed with `w`.
#[inline]
fn times_hat(a: &Matrix3<f64>, w: &Vector3<f64>) -> Matrix3<f64> {
    let row = |k: usize| {
        let (x, y, z) = (a[(k, 0)], a[(k, 1)], a[(k, 2)]);
        [y * w.z - z * w.y, z * w.x - x * w.z, x * w.y - y * w.x]
    };
    let (r0, r1, r2) = (row(0), row(1), row(2));
    Matrix3::new(r0[0], r0[1], r0[2], r1[0], r1[1], r1[2], r2[0], r2[1], r2[2])
}

/// Accelerometer parameters `[m00, m01, m02, m11, m12, m22, b0, b1, b2]`: the
/// upper triangle of `M_a` (row major) and the bias `b_a` \[raw units\].
pub type AccelParams = SVector<f64, 9>;

/// Gyroscope matrix `M_g`, row major (9 entries).
pub type GyroMatrix = SVector<f64, 9>;

/// Index pairs `(row, col)` of the upper triangle in [`AccelParams`] order.
pub const UPPER: [(usize, usize); 6] = [(0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)];

/// `M_a` from accelerometer parameters.
pub fn accel_matrix(p: &AccelParams) -> Matrix3<f64> {
    let mut m = Matrix3::zeros();
    for (k, &(r, c)) in UPPER.iter().enumerate() {
        m[(r, c)] = p[k];
    }
    m
}

/// `M_g` from its row-major parameters.
pub fn gyro_matrix(p: &GyroMatrix) -> Matrix3<f64> {
    Matrix3::from_row_slice(p.as_slice())
}

/// Gravity-norm factor (paper eq. 5–6) of one static interval:
/// `r = g² − ‖M_a (ā − b_a)‖²` \[m²/s⁴\], with `ā` the mean raw accelerometer
/// reading of the interval and `g` the local gravity \[m/s²\]. One key: [`AccelParams`].
///
/// ```
/// use tumble_factors::imu_calib::{AccelParams, GravityNormFactor};
/// use tumble_solvers::{check_jacobians, Factor, Key};
/// use nalgebra::Vector3;
/// let f = GravityNormFactor::new(Key::new('a', 0), Vector3::new(0.1, -0.2, 9.7), 9.81);
/// let p = AccelParams::from_row_slice(&[1.0, 0.01, 0.0, 1.0, 0.02, 1.0, 0.0, 0.1, 0.0]);
/// assert!(check_jacobians(&f, &[&p]).unwrap().passes(1e-6));
/// ```
#[derive(Clone, Debug)]
pub struct GravityNormFactor {
    keys: [Key; 1],
    raw_mean: Vector3<f64>,
    gravity: f64,
}

impl GravityNormFactor {
    /// Factor for one interval with mean raw reading `raw_mean` and gravity `gravity` \[m/s²\].
    pub fn new(key: Key, raw_mean: Vector3<f64>, gravity: f64) -> Self {
        GravityNormFactor { keys: [key], raw_mean, gravity }
    }
    /// Calibrated specific force of this interval under `p` \[m/s²\].
    pub fn calibrated(&self, p: &AccelParams) -> Vector3<f64> {
        accel_matrix(p) * (self.raw_mean - Vector3::new(p[6], p[7], p[8]))
    }
}

impl Factor for GravityNormFactor {
    fn keys(&self) -> &[Key] {
        &self.keys
    }
    fn residual_dim(&self) -> usize {
        1
    }
    fn residual(&self, vars: Vars<'_>) -> Result<DVector<f64>, FactorError> {
        let p: &AccelParams = vars.get(0)?;
        Ok(DVector::from_element(1, self.gravity * self.gravity - self.calibrated(p).norm_squared()))
    }
    fn linearize(&self, vars: Vars<'_>) -> Result<Linearization, FactorError> {
        let p: &AccelParams = vars.get(0)?;
        let d = self.raw_mean - Vector3::new(p[6], p[7], p[8]);
        let m = accel_matrix(p);
        let c = m * d;
        let mut j = DMatrix::zeros(1, 9);
        for (k, &(r, col)) in UPPER.iter().enumerate() {
            j[(0, k)] = -2.0 * c[r] * d[col];
        }
        let jb = 2.0 * m.transpose() * c;
        for k in 0..3 {
            j[(0, 6 + k)] = jb[k];
        }
        let r = DVector::from_element(1, self.gravity * self.gravity - c.norm_squared());
        Ok(Linearization { residual: r, jacobians: vec![j] })
    }
}

/// Integrated-rotation factor (paper eq. 8–9) of one motion between two static
/// intervals: the calibrated gravity direction `g₀` of the interval before is
/// carried by the integral of the calibrated gyro samples and compared with
/// the direction `g₁` of the interval after.
///
/// `R = Π_i Exp(M_g (ū_i − b_g) Δt_i)` with `ū_i` the mean of raw samples `i`
/// and `i+1` (exact SO(3) steps at the mid-interval rate, second order like
/// imu_tk's RK4 on linearly interpolated rates); the residual is
/// `r = Bᵀ Rᵀ g₀` \[rad\], `B` an orthonormal 3×2 basis orthogonal to `g₁`, i.e.
/// the small-angle error of the predicted direction. Keys: [`GyroMatrix`] and the
/// gyro bias (`Vector3`, raw units; hold it constant to use the static-period mean).
///
/// ```
/// use tumble_factors::imu_calib::{GyroMatrix, IntegratedRotationFactor};
/// use tumble_solvers::{check_jacobians, Key};
/// use nalgebra::Vector3;
/// let raw: Vec<[f64; 3]> = (0..50).map(|i| [0.3, 0.1 * (i as f64 * 0.1).sin(), -0.2]).collect();
/// let f = IntegratedRotationFactor::new([Key::new('g', 0), Key::new('g', 1)], raw, vec![0.01; 49],
///     Vector3::z(), Vector3::new(0.1, 0.0, 1.0).normalize()).unwrap();
/// let m = GyroMatrix::from_row_slice(&[1.0, 0.01, 0.0, -0.01, 1.0, 0.02, 0.0, 0.0, 1.0]);
/// let b = Vector3::new(0.01, 0.0, -0.01);
/// assert!(check_jacobians(&f, &[&m, &b]).unwrap().passes(1e-6));
/// ```
#[derive(Clone, Debug)]
pub struct IntegratedRotationFactor {
    keys: [Key; 2],
    /// Each step's mean raw rate (trapezoid of its two samples).
    mid: Vec<Vector3<f64>>,
    dt: Vec<f64>,
    g0: Vector3<f64>,
    basis: Matrix3x2<f64>,
}

impl IntegratedRotationFactor {
    /// Factor over raw gyro samples `raw` (n ≥ 2) with step lengths `dt`
    /// (n − 1, \[s\]) from unit direction `g0` to `g1` (calibrated, sensor frame).
    pub fn new(
        keys: [Key; 2],
        raw: Vec<[f64; 3]>,
        dt: Vec<f64>,
        g0: Vector3<f64>,
        g1: Vector3<f64>,
    ) -> Result<Self, FactorError> {
        if raw.len() < 2 || dt.len() + 1 != raw.len() {
            return Err(FactorError::Other(format!(
                "{} gyro samples need {} steps, got {}",
                raw.len(),
                raw.len().max(1) - 1,
                dt.len()
            )));
        }
        if dt.iter().any(|d| !(d.is_finite() && *d > 0.0)) {
            return Err(FactorError::Other("gyro steps must be positive".into()));
        }
        let (n0, n1) = (g0.norm(), g1.norm());
        if !(n0 > 0.0 && n1 > 0.0 && n0.is_finite() && n1.is_finite()) {
            return Err(FactorError::Other("gravity directions must be finite and non-zero".into()));
        }
        let mid = raw.windows(2).map(|w| (Vector3::from(w[0]) + Vector3::from(w[1])) * 0.5).collect();
        Ok(IntegratedRotationFactor { keys, mid, dt, g0: g0 / n0, basis: orthogonal_basis(&(g1 / n1)) })
    }

    /// The same motion compared between other gravity directions.
    pub fn with_directions(&self, g0: Vector3<f64>, g1: Vector3<f64>) -> Self {
        IntegratedRotationFactor { g0: g0.normalize(), basis: orthogonal_basis(&g1.normalize()), ..self.clone() }
    }

    /// Rotation from the first to the last sample's frame under `M_g`, `b_g`.
    /// The steps are multiplied as quaternions (16 products a step, against
    /// 27 for matrices): the rotation is the same to rounding.
    pub fn rotation(&self, m: &Matrix3<f64>, b: &Vector3<f64>) -> Matrix3<f64> {
        let mut q = Quaternion::identity();
        for (w, dt) in self.mid.iter().zip(&self.dt) {
            q *= step_quaternion(&(m * (w - b) * *dt));
        }
        UnitQuaternion::new_normalize(q).to_rotation_matrix().into_inner()
    }

    /// The rotation `R`, visiting each step `i` with `D_i = C_i J_r(φ_i) Δt_i`,
    /// `C_i` the product of the steps through `i`: a rate error `δω_i` moves
    /// `R` to `R Exp(Rᵀ Σ D_i δω_i)` (`Rᵀ C_i` is the inverse of the steps
    /// after `i`, so one forward pass gives what a backward one would).
    ///
    /// With `E = Exp(φ) = I + a[φ]× + b[φ]×²` and `E J_r(φ) = J_l(φ) = I +
    /// b[φ]× + c[φ]×²`, both `C_i = C_{i−1} E` and `D_i = C_{i−1} J_l Δt` are
    /// sums of `C_{i−1}`, `P = C_{i−1}[φ]×` and `P[φ]×` (rows crossed with
    /// φ): two cross-product passes instead of building two matrices and
    /// multiplying `C` by each.
    fn sweep(&self, m: &Matrix3<f64>, b: &Vector3<f64>, mut visit: impl FnMut(usize, &Matrix3<f64>)) -> Matrix3<f64> {
        let mut c = Matrix3::identity();
        for i in 0..self.dt.len() {
            let dt = self.dt[i];
            let phi = m * (self.mid[i] - b) * dt;
            let (ca, cb, cc) = rodrigues(phi.norm_squared());
            let p = times_hat(&c, &phi);
            let q = times_hat(&p, &phi);
            let d = c * dt + p * (cb * dt) + q * (cc * dt);
            c += p * ca + q * cb;
            visit(i, &d);
        }
        c
    }

    /// Covariance (2×2, \[rad²\]) of the residual caused by white noise of
    /// per-sample variance `raw_var` (per raw axis) on the gyro samples, at `M_g`, `b_g`.
    pub fn noise_covariance(
        &self,
        m: &Matrix3<f64>,
        b: &Vector3<f64>,
        raw_var: &Vector3<f64>,
    ) -> nalgebra::Matrix2<f64> {
        let sw = m * Matrix3::from_diagonal(raw_var) * m.transpose();
        let mut sum = Matrix3::zeros();
        let r = self.sweep(m, b, |_, di| sum += di * sw * di.transpose());
        let cov_phi = r.transpose() * sum * r;
        let d = self.basis.transpose() * hat(&(r.transpose() * self.g0));
        d * cov_phi * d.transpose()
    }

    /// Total time integrated \[s\].
    pub fn duration(&self) -> f64 {
        self.dt.iter().sum()
    }

    /// The residual \[rad\] of a turn with rotation `r` (from [`Self::rotation`])
    /// between other gravity directions `g0`, `g1` (any length): the factor's
    /// residual after [`Self::with_directions`], without integrating again.
    pub fn residual_between(r: &Matrix3<f64>, g0: &Vector3<f64>, g1: &Vector3<f64>) -> Vector2<f64> {
        orthogonal_basis(&g1.normalize()).transpose() * (r.transpose() * g0.normalize())
    }
}

/// An orthonormal basis (3×2) of the plane orthogonal to unit vector `n`.
pub(crate) fn orthogonal_basis(n: &Vector3<f64>) -> Matrix3x2<f64> {
    let helper = if n.x.abs() < 0.9 { Vector3::x() } else { Vector3::y() };
    let e1 = n.cross(&helper).normalize();
    let e2 = n.cross(&e1);
    Matrix3x2::from_columns(&[e1, e2])
}

impl Factor for IntegratedRotationFactor {
    fn keys(&self) -> &[Key] {
        &self.keys
    }
    fn residual_dim(&self) -> usize {
        2
    }
    fn residual(&self, vars: Vars<'_>) -> Result<DVector<f64>, FactorError> {
        let p: &GyroMatrix = vars.get(0)?;
        let b: &Vector3<f64> = vars.get(1)?;
        let r = self.rotation(&gyro_matrix(p), b);
        let e = self.basis.transpose() * (r.transpose() * self.g0);
        Ok(DVector::from_column_slice(e.as_slice()))
    }
    fn linearize(&self, vars: Vars<'_>) -> Result<Linearization, FactorError> {
        let p: &GyroMatrix = vars.get(0)?;
        let b: &Vector3<f64> = vars.get(1)?;
        let m = gyro_matrix(p);
        // Σ D_i ⊗ u_i (column 3·row + col: D_i's column `row` times u_i[col]) and Σ D_i.
        let mut jm = SMatrix::<f64, 3, 9>::zeros();
        let mut sum_d = Matrix3::zeros();
        let r = self.sweep(&m, b, |i, di| {
            let u = self.mid[i] - b;
            for row in 0..3 {
                for col in 0..3 {
                    let mut c = jm.column_mut(3 * row + col);
                    c += di.column(row) * u[col];
                }
            }
            sum_d += di;
        });
        let rg = r.transpose() * self.g0;
        let d = self.basis.transpose() * hat(&rg) * r.transpose();
        let jm = d * jm;
        let jb = -(d * sum_d * m);
        let e = self.basis.transpose() * rg;
        Ok(Linearization {
            residual: DVector::from_column_slice(e.as_slice()),
            jacobians: vec![
                DMatrix::from_column_slice(2, 9, jm.as_slice()),
                DMatrix::from_column_slice(2, 3, jb.as_slice()),
            ],
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use tumble_solvers::lie::{so3_exp, so3_right_jacobian};

    // The step's rotation and right Jacobian from the series' coefficients,
    // as matrices: what the quaternion and the sweep's products compute.
    /// `I + x·[w]× + y·[w]×²`, with `[w]×² = w wᵀ − |w|² I`.
    fn rodrigues_matrix(w: &Vector3<f64>, x: f64, y: f64) -> Matrix3<f64> {
        let d = 1.0 - y * w.norm_squared();
        let (p, q, r) = (w.x, w.y, w.z);
        Matrix3::new(
            d + y * p * p,
            y * p * q - x * r,
            y * p * r + x * q,
            y * p * q + x * r,
            d + y * q * q,
            y * q * r - x * p,
            y * p * r - x * q,
            y * q * r + x * p,
            d + y * r * r,
        )
    }

    /// `Exp(w)` for one integration step ([`rodrigues`]).
    fn step_exp(w: &Vector3<f64>) -> Matrix3<f64> {
        let (a, b, _) = rodrigues(w.norm_squared());
        rodrigues_matrix(w, a, b)
    }

    /// `Exp(w)` and the right Jacobian `J_r(w) = I − b·[w]× + c·[w]×²` of one step.
    fn step_exp_and_jacobian(w: &Vector3<f64>) -> (Matrix3<f64>, Matrix3<f64>) {
        let (a, b, c) = rodrigues(w.norm_squared());
        (rodrigues_matrix(w, a, b), rodrigues_matrix(w, -b, c))
    }

    #[test]
    fn step_exp_and_quaternion_are_so3_exp_to_rounding() {
        for &t in &[0.0, 1e-9, 1e-4, 0.01, 0.049, 0.0501, 0.3] {
            let w = Vector3::new(0.6, -0.48, 0.64) * t;
            let d = (step_exp(&w) - so3_exp(&w)).amax();
            assert!(d < 4e-16, "θ = {t}: {d:e}");
            let (e, jr) = step_exp_and_jacobian(&w);
            assert!((e - step_exp(&w)).amax() == 0.0);
            let q = UnitQuaternion::new_unchecked(step_quaternion(&w)).to_rotation_matrix().into_inner();
            let d = (q - so3_exp(&w)).amax();
            assert!(d < 4e-16, "θ = {t}: quaternion off by {d:e}");
            // J_r(w) = Σ_k (−[w]×)^k / (k + 1)!, summed to rounding.
            let (mut term, mut reference) = (Matrix3::identity(), Matrix3::identity());
            for k in 1..30 {
                term = term * -hat(&w) / (k + 1) as f64;
                reference += term;
            }
            let d = (jr - reference).amax();
            assert!(d < 4e-16, "θ = {t}: J_r off by {d:e}");
            let a = Matrix3::new(0.3, -1.2, 0.5, 2.0, 0.1, -0.7, -0.4, 0.9, 1.1);
            assert!((times_hat(&a, &w) - a * hat(&w)).amax() < 1e-15);
            // The solver's closed form agrees where its cancellation is small.
            if t > 0.01 {
                assert!((jr - so3_right_jacobian(&w)).amax() < 1e-12);
            }
        }
    }

    #[test]
    fn sweep_agrees_with_the_matrix_products() {
        let raw: Vec<[f64; 3]> =
            (0..400).map(|i| [3.0 + (i as f64 * 0.05).sin(), -2.0, 1.5 * (i as f64 * 0.02).cos()]).collect();
        let f = IntegratedRotationFactor::new(
            [Key::new('g', 0), Key::new('g', 1)],
            raw,
            vec![0.01; 399],
            Vector3::z(),
            Vector3::x(),
        )
        .unwrap();
        let m = Matrix3::new(1.01, 0.02, -0.01, 0.0, 0.98, 0.03, 0.01, -0.02, 1.02);
        let b = Vector3::new(0.1, -0.05, 0.02);
        let (mut c, mut visited): (Matrix3<f64>, usize) = (Matrix3::identity(), 0);
        let r = f.sweep(&m, &b, |i, d: &Matrix3<f64>| {
            let (e, jr) = step_exp_and_jacobian(&(m * (f.mid[i] - b) * f.dt[i]));
            c *= e;
            assert!((d - c * jr * f.dt[i]).amax() < 1e-14, "step {i}");
            visited += 1;
        });
        assert_eq!(visited, 399);
        assert!((r - c).amax() < 1e-13);
        assert!((f.rotation(&m, &b) - c).amax() < 1e-13);
    }
}
