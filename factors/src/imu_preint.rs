//! IMU preintegration on the manifold (Forster et al. 2017), in two schemes:
//!
//! - [`Scheme::ZeroOrderHold`]: GTSAM's `PreintegratedImuMeasurements` with its
//!   default tangent-space integration — sample k held over `[t_k, t_k + dt]`,
//!   state `[θ, p, v]` with `ΔR = Exp(θ)`, `θ ← θ + Jr(θ)⁻¹ ω dt`. Equal to GTSAM
//!   to rounding (tested against GTSAM's own numbers, `anchors/gtsam_preint/` of the
//!   datasets in docs/datasets.md).
//! - [`Scheme::Midpoint`]: VINS-Mono's midpoint rule on the manifold,
//!   `ΔR ← ΔR Exp(½(ω_k + ω_{k+1}) dt)`, acceleration averaged over both ends.
//!
//! Frames and units: body (IMU) frame, specific force \[m/s²\], rate \[rad/s\],
//! time \[s\]. Deltas are gravity-free: `Δv = Σ ΔR_k (a_k − b_a) dt`, so
//! `R_iᵀ (v_j − v_i − g Δt) = Δv` with `g` the world gravity vector.
//!
//! The covariance is the 9×9 covariance of `[δθ, δp, δv]` (GTSAM's order, not
//! VINS-Mono's `[p, q, v]`); continuous-time noise densities are discretised as
//! GTSAM does (`σ² / dt`). Bias Jacobians are first order; [`Preintegrated::reintegrate`]
//! redoes the integration from the stored samples when the bias estimate moves far.
//!
//! ```
//! use tumble_factors::imu_preint::{Preintegrated, PreintegrationParams, Scheme};
//! use nalgebra::Vector3;
//! let params = PreintegrationParams { scheme: Scheme::ZeroOrderHold, ..PreintegrationParams::default() };
//! let mut pim = Preintegrated::new(params, Vector3::zeros(), Vector3::zeros());
//! for _ in 0..200 {
//!     pim.integrate(Vector3::new(0.0, 0.0, 9.81), Vector3::new(0.0, 0.0, 0.1), 0.005);
//! }
//! assert!((pim.delta_t() - 1.0).abs() < 1e-12);
//! assert!((pim.delta_velocity().z - 9.81).abs() < 1e-9); // gravity-free deltas
//! ```

use nalgebra::{Matrix3, SMatrix, Vector3};
use tumble_solvers::lie::{hat, so3_exp, so3_log, so3_right_jacobian, so3_right_jacobian_inv};

/// 9×9 matrix over `[θ, p, v]`.
pub type Matrix9 = SMatrix<f64, 9, 9>;
/// 9×3 matrix: `[θ, p, v]` rows, one 3-vector of columns.
pub type Matrix93 = SMatrix<f64, 9, 3>;

/// Integration rule.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Scheme {
    /// GTSAM's tangent-space preintegration, zero-order hold of each sample.
    #[default]
    ZeroOrderHold,
    /// VINS-Mono's midpoint rule (needs the next sample; see [`Preintegrated::integrate`]).
    Midpoint,
}

/// Noise and integration settings (Kalibr's continuous-time `imu.yaml` quantities).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PreintegrationParams {
    /// Accelerometer white noise density \[m/s²/√Hz\].
    pub accel_noise_density: f64,
    /// Gyroscope white noise density \[rad/s/√Hz\].
    pub gyro_noise_density: f64,
    /// Accelerometer bias random walk \[m/s³/√Hz\] (used by the bias factor).
    pub accel_random_walk: f64,
    /// Gyroscope bias random walk \[rad/s²/√Hz\] (used by the bias factor).
    pub gyro_random_walk: f64,
    /// Extra position integration noise density \[m/s/√Hz\] (GTSAM's integrationCovariance; 0 = none).
    pub integration_sigma: f64,
    /// Integration rule.
    pub scheme: Scheme,
    /// Per-axis densities that replace the four scalars above when given
    /// (Kalibr's `imu.yaml` has one figure per triad; a MEMS part's axes can
    /// differ by 5×, and its largest axis' figure overstates the others).
    pub axes: Option<NoiseAxes>,
}

/// Per-axis IMU noise (body axes x, y, z; units as in [`PreintegrationParams`]).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NoiseAxes {
    /// Accelerometer white noise density \[m/s²/√Hz\].
    pub accel_noise_density: [f64; 3],
    /// Gyroscope white noise density \[rad/s/√Hz\].
    pub gyro_noise_density: [f64; 3],
    /// Accelerometer bias random walk \[m/s³/√Hz\].
    pub accel_random_walk: [f64; 3],
    /// Gyroscope bias random walk \[rad/s²/√Hz\].
    pub gyro_random_walk: [f64; 3],
}

impl PreintegrationParams {
    /// Accelerometer white noise density per axis \[m/s²/√Hz\].
    pub fn accel_noise(&self) -> Vector3<f64> {
        self.axes.map_or(Vector3::repeat(self.accel_noise_density), |a| a.accel_noise_density.into())
    }
    /// Gyroscope white noise density per axis \[rad/s/√Hz\].
    pub fn gyro_noise(&self) -> Vector3<f64> {
        self.axes.map_or(Vector3::repeat(self.gyro_noise_density), |a| a.gyro_noise_density.into())
    }
    /// Accelerometer bias random walk per axis \[m/s³/√Hz\].
    pub fn accel_walk(&self) -> Vector3<f64> {
        self.axes.map_or(Vector3::repeat(self.accel_random_walk), |a| a.accel_random_walk.into())
    }
    /// Gyroscope bias random walk per axis \[rad/s²/√Hz\].
    pub fn gyro_walk(&self) -> Vector3<f64> {
        self.axes.map_or(Vector3::repeat(self.gyro_random_walk), |a| a.gyro_random_walk.into())
    }
}

impl Default for PreintegrationParams {
    /// EuRoC's ADIS16448 values as Kalibr publishes them.
    fn default() -> Self {
        PreintegrationParams {
            accel_noise_density: 2.0e-3,
            gyro_noise_density: 1.6968e-4,
            accel_random_walk: 3.0e-3,
            gyro_random_walk: 1.9393e-5,
            integration_sigma: 0.0,
            scheme: Scheme::ZeroOrderHold,
            axes: None,
        }
    }
}

/// One stored IMU sample: `(dt, specific force, rate)` as given to [`Preintegrated::integrate`].
#[derive(Debug, Clone, Copy, PartialEq)]
struct Sample {
    dt: f64,
    acc: Vector3<f64>,
    gyro: Vector3<f64>,
}

/// Preintegrated IMU measurements between two states, with their covariance and
/// first-order bias Jacobians. See the module docs for frames and conventions.
#[derive(Debug, Clone)]
pub struct Preintegrated {
    params: PreintegrationParams,
    bias_acc: Vector3<f64>,
    bias_gyro: Vector3<f64>,
    dt_sum: f64,
    /// Rotation as a tangent vector (zero-order hold) — GTSAM's `θ`.
    theta: Vector3<f64>,
    /// Rotation as a matrix (both schemes keep it current).
    rot: Matrix3<f64>,
    pos: Vector3<f64>,
    vel: Vector3<f64>,
    cov: Matrix9,
    h_ba: Matrix93,
    h_bg: Matrix93,
    samples: Vec<Sample>,
    /// Midpoint: the previous sample (the first end of the next step).
    last: Option<(Vector3<f64>, Vector3<f64>)>,
}

/// `Jr(θ) c` differentiated with respect to θ (c held fixed).
fn d_right_jacobian_times(theta: &Vector3<f64>, c: &Vector3<f64>) -> Matrix3<f64> {
    let t2 = theta.norm_squared();
    let (a, b, da, db) = if t2 < 1e-8 {
        (
            0.5 - t2 / 24.0 + t2 * t2 / 720.0,
            1.0 / 6.0 - t2 / 120.0 + t2 * t2 / 5040.0,
            -1.0 / 12.0 + t2 / 180.0,
            -1.0 / 60.0 + t2 / 1260.0,
        )
    } else {
        let t = t2.sqrt();
        let a = (1.0 - t.cos()) / t2;
        let b = (t - t.sin()) / (t2 * t);
        (a, b, (t.sin() / t - 2.0 * a) / t2, (a - 3.0 * b) / t2)
    };
    let txc = theta.cross(c);
    let ttc = theta.cross(&txc);
    hat(c) * a + Matrix3::identity() * (theta.dot(c) * b) + (theta * c.transpose()) * b
        - (c * theta.transpose()) * (2.0 * b)
        - txc * theta.transpose() * da
        + ttc * theta.transpose() * db
}

impl Preintegrated {
    /// Start an empty preintegration with the bias estimate `(b_a, b_g)` it is linearized at.
    pub fn new(params: PreintegrationParams, bias_acc: Vector3<f64>, bias_gyro: Vector3<f64>) -> Self {
        Preintegrated {
            params,
            bias_acc,
            bias_gyro,
            dt_sum: 0.0,
            theta: Vector3::zeros(),
            rot: Matrix3::identity(),
            pos: Vector3::zeros(),
            vel: Vector3::zeros(),
            cov: Matrix9::zeros(),
            h_ba: Matrix93::zeros(),
            h_bg: Matrix93::zeros(),
            samples: Vec::new(),
            last: None,
        }
    }

    /// Add one sample held over `dt` \[s\]. With [`Scheme::Midpoint`] the step
    /// from the previous sample to this one is integrated (the first call only
    /// stores the sample, so give the sample at the start of the interval first
    /// and the one at its end last, with `dt` the time since the previous sample).
    pub fn integrate(&mut self, acc: Vector3<f64>, gyro: Vector3<f64>, dt: f64) {
        self.samples.push(Sample { dt, acc, gyro });
        match self.params.scheme {
            Scheme::ZeroOrderHold => self.step_tangent(acc, gyro, dt),
            Scheme::Midpoint => {
                if let Some((a0, g0)) = self.last {
                    self.step_midpoint(a0, g0, acc, gyro, dt);
                }
                self.last = Some((acc, gyro));
            }
        }
    }

    /// GTSAM's `TangentPreintegration::update` + covariance propagation.
    fn step_tangent(&mut self, acc: Vector3<f64>, gyro: Vector3<f64>, dt: f64) {
        let a_body = acc - self.bias_acc;
        let w_body = gyro - self.bias_gyro;
        let theta = self.theta;
        let jr = so3_right_jacobian(&theta);
        let jr_inv = so3_right_jacobian_inv(&theta);
        let w_tangent = jr_inv * w_body;
        let w_tangent_h_theta = -jr_inv * d_right_jacobian_times(&theta, &w_tangent);
        let r = self.rot;
        let a_nav = r * a_body;
        let dt22 = 0.5 * dt * dt;
        let a_nav_h_theta = r * hat(&(-a_body)) * jr;
        let mut a = Matrix9::identity();
        a.fixed_view_mut::<3, 3>(0, 0).copy_from(&(Matrix3::identity() + w_tangent_h_theta * dt));
        a.fixed_view_mut::<3, 3>(3, 0).copy_from(&(a_nav_h_theta * dt22));
        a.fixed_view_mut::<3, 3>(3, 6).copy_from(&(Matrix3::identity() * dt));
        a.fixed_view_mut::<3, 3>(6, 0).copy_from(&(a_nav_h_theta * dt));
        let mut b = Matrix93::zeros();
        b.fixed_view_mut::<3, 3>(3, 0).copy_from(&(r * dt22));
        b.fixed_view_mut::<3, 3>(6, 0).copy_from(&(r * dt));
        let mut c = Matrix93::zeros();
        c.fixed_view_mut::<3, 3>(0, 0).copy_from(&(jr_inv * dt));

        self.theta = theta + w_tangent * dt;
        self.pos += self.vel * dt + a_nav * dt22;
        self.vel += a_nav * dt;
        self.rot = so3_exp(&self.theta);
        self.dt_sum += dt;
        self.h_ba = a * self.h_ba - b;
        self.h_bg = a * self.h_bg - c;
        let (qa, qg) = self.sample_variances(dt, 1.0);
        self.cov = a * self.cov * a.transpose() + b * qa * b.transpose() + c * qg * c.transpose();
        let qi = self.params.integration_sigma.powi(2) * dt;
        for k in 3..6 {
            self.cov[(k, k)] += qi;
        }
    }

    /// VINS-Mono's `midPointIntegration`, states reordered to `[θ, p, v]`, with its
    /// first-order rotation terms (`I − [ω]× dt`, `I dt`) replaced by their exact forms.
    fn step_midpoint(&mut self, a0: Vector3<f64>, g0: Vector3<f64>, a1: Vector3<f64>, g1: Vector3<f64>, dt: f64) {
        let (ba, bg) = (self.bias_acc, self.bias_gyro);
        let r0 = self.rot;
        let w = (g0 + g1) * 0.5 - bg;
        let step = so3_exp(&(w * dt));
        let r1 = r0 * step;
        // Exact forms of VINS-Mono's first-order I − [ω]× dt and I dt.
        let step_t = step.transpose();
        let jr_dt = so3_right_jacobian(&(w * dt)) * dt;
        let (a0b, a1b) = (a0 - ba, a1 - ba);
        let acc = (r0 * a0b + r1 * a1b) * 0.5;
        let i3 = Matrix3::identity();
        let (a0x, a1x) = (hat(&a0b), hat(&a1b));
        let dt2 = dt * dt;
        let mut f = Matrix9::identity();
        // θ
        f.fixed_view_mut::<3, 3>(0, 0).copy_from(&step_t);
        // p
        f.fixed_view_mut::<3, 3>(3, 0).copy_from(&((r0 * a0x * (-0.25) - r1 * a1x * step_t * 0.25) * dt2));
        f.fixed_view_mut::<3, 3>(3, 6).copy_from(&(i3 * dt));
        // v
        f.fixed_view_mut::<3, 3>(6, 0).copy_from(&((r0 * a0x * (-0.5) - r1 * a1x * step_t * 0.5) * dt));
        let mut fba = Matrix93::zeros();
        fba.fixed_view_mut::<3, 3>(3, 0).copy_from(&((r0 + r1) * (-0.25 * dt2)));
        fba.fixed_view_mut::<3, 3>(6, 0).copy_from(&((r0 + r1) * (-0.5 * dt)));
        let mut fbg = Matrix93::zeros();
        fbg.fixed_view_mut::<3, 3>(0, 0).copy_from(&(-jr_dt));
        fbg.fixed_view_mut::<3, 3>(3, 0).copy_from(&(r1 * a1x * jr_dt * (0.25 * dt2)));
        fbg.fixed_view_mut::<3, 3>(6, 0).copy_from(&(r1 * a1x * jr_dt * (0.5 * dt)));
        // Noise inputs: accelerometer at both ends, gyro at both ends.
        let mut va0 = Matrix93::zeros();
        va0.fixed_view_mut::<3, 3>(3, 0).copy_from(&(r0 * (0.25 * dt2)));
        va0.fixed_view_mut::<3, 3>(6, 0).copy_from(&(r0 * (0.5 * dt)));
        let mut va1 = Matrix93::zeros();
        va1.fixed_view_mut::<3, 3>(3, 0).copy_from(&(r1 * (0.25 * dt2)));
        va1.fixed_view_mut::<3, 3>(6, 0).copy_from(&(r1 * (0.5 * dt)));
        let mut vg = Matrix93::zeros();
        vg.fixed_view_mut::<3, 3>(0, 0).copy_from(&(jr_dt * 0.5));
        vg.fixed_view_mut::<3, 3>(3, 0).copy_from(&(r1 * a1x * jr_dt * (-0.125 * dt2)));
        vg.fixed_view_mut::<3, 3>(6, 0).copy_from(&(r1 * a1x * jr_dt * (-0.25 * dt)));

        self.pos += self.vel * dt + acc * (0.5 * dt2);
        self.vel += acc * dt;
        self.rot = r1;
        self.theta = so3_log(&r1);
        self.dt_sum += dt;
        self.h_ba = f * self.h_ba + fba;
        self.h_bg = f * self.h_bg + fbg;
        // Each sample enters two adjacent steps with weight ½; giving each end twice
        // the sample variance makes the summed noise equal the continuous-time one
        // (the correlation between adjacent steps is neglected, as in VINS-Mono).
        let (qa, qg) = self.sample_variances(dt, 2.0);
        self.cov = f * self.cov * f.transpose()
            + va0 * qa * va0.transpose()
            + va1 * qa * va1.transpose()
            + vg * (qg * 2.0) * vg.transpose();
        let qi = self.params.integration_sigma.powi(2) * dt;
        for k in 3..6 {
            self.cov[(k, k)] += qi;
        }
    }

    /// Discrete per-sample noise covariances (accelerometer, gyro) of a step
    /// of `dt`: `scale · diag(σ²) / dt`.
    fn sample_variances(&self, dt: f64, scale: f64) -> (Matrix3<f64>, Matrix3<f64>) {
        let q = |n: Vector3<f64>| Matrix3::from_diagonal(&n.map(|x| scale * x * x / dt));
        (q(self.params.accel_noise()), q(self.params.gyro_noise()))
    }

    /// Redo the integration from the stored samples at a new bias estimate.
    pub fn reintegrate(&mut self, bias_acc: Vector3<f64>, bias_gyro: Vector3<f64>) {
        let samples = std::mem::take(&mut self.samples);
        *self = Preintegrated::new(self.params, bias_acc, bias_gyro);
        for s in samples {
            self.integrate(s.acc, s.gyro, s.dt);
        }
    }

    /// Redo the integration from the stored samples with other settings
    /// (e.g. the noise measured since), at the same bias estimate.
    pub fn reintegrate_with(&mut self, params: PreintegrationParams) {
        self.params = params;
        self.reintegrate(self.bias_acc, self.bias_gyro);
    }

    /// The settings.
    pub fn params(&self) -> &PreintegrationParams {
        &self.params
    }
    /// Bias estimate `(b_a, b_g)` the integration is linearized at.
    pub fn bias(&self) -> (Vector3<f64>, Vector3<f64>) {
        (self.bias_acc, self.bias_gyro)
    }
    /// Integrated time Δt \[s\].
    pub fn delta_t(&self) -> f64 {
        self.dt_sum
    }
    /// Number of samples given.
    pub fn len(&self) -> usize {
        self.samples.len()
    }
    /// Whether no sample was given.
    pub fn is_empty(&self) -> bool {
        self.samples.is_empty()
    }
    /// The last sample given, `(specific force, rate)` (midpoint: the start of the next interval).
    pub fn last_sample(&self) -> Option<(Vector3<f64>, Vector3<f64>)> {
        self.samples.last().map(|s| (s.acc, s.gyro))
    }
    /// ΔR: body at the end in body at the start.
    pub fn delta_rotation(&self) -> Matrix3<f64> {
        self.rot
    }
    /// GTSAM's tangent θ with ΔR = Exp(θ) \[rad\] (midpoint: Log ΔR).
    pub fn theta(&self) -> Vector3<f64> {
        self.theta
    }
    /// Δp \[m\], in the start body frame, gravity-free.
    pub fn delta_position(&self) -> Vector3<f64> {
        self.pos
    }
    /// Δv \[m/s\], in the start body frame, gravity-free.
    pub fn delta_velocity(&self) -> Vector3<f64> {
        self.vel
    }
    /// Covariance of `[θ, p, v]` in the scheme's own rotation coordinates
    /// (zero-order hold: GTSAM's `preintMeasCov`, perturbation of θ; midpoint:
    /// right perturbation of ΔR).
    pub fn raw_covariance(&self) -> &Matrix9 {
        &self.cov
    }
    /// Covariance of `[δθ, δp, δv]` with the rotation error a right perturbation,
    /// `ΔR_true = ΔR Exp(δθ)` (what [`crate::ImuFactor`] whitens with).
    pub fn covariance(&self) -> Matrix9 {
        match self.params.scheme {
            Scheme::Midpoint => self.cov,
            Scheme::ZeroOrderHold => {
                let mut t = Matrix9::identity();
                t.fixed_view_mut::<3, 3>(0, 0).copy_from(&so3_right_jacobian(&self.theta));
                t * self.cov * t.transpose()
            }
        }
    }
    /// First-order Jacobians of `[θ, p, v]` with respect to `b_a` (9×3) and `b_g` (9×3),
    /// in the scheme's own rotation coordinates (GTSAM's `preintegrated_H_biasAcc/Omega`).
    pub fn bias_jacobians(&self) -> (&Matrix93, &Matrix93) {
        (&self.h_ba, &self.h_bg)
    }

    /// Bias-corrected deltas for biases `(b_a, b_g)` (first order), with the
    /// right-perturbation derivative of the rotation with respect to `b_g`:
    /// returns `(ΔR, Δp, Δv, ∂ΔR/∂b_g)`.
    pub fn corrected(
        &self,
        bias_acc: &Vector3<f64>,
        bias_gyro: &Vector3<f64>,
    ) -> (Matrix3<f64>, Vector3<f64>, Vector3<f64>, Matrix3<f64>) {
        let dba = bias_acc - self.bias_acc;
        let dbg = bias_gyro - self.bias_gyro;
        let hr_g: Matrix3<f64> = self.h_bg.fixed_view::<3, 3>(0, 0).into_owned();
        let dp = self.pos + self.h_ba.fixed_view::<3, 3>(3, 0) * dba + self.h_bg.fixed_view::<3, 3>(3, 0) * dbg;
        let dv = self.vel + self.h_ba.fixed_view::<3, 3>(6, 0) * dba + self.h_bg.fixed_view::<3, 3>(6, 0) * dbg;
        let (r, dr) = match self.params.scheme {
            Scheme::ZeroOrderHold => {
                let th = self.theta + hr_g * dbg;
                (so3_exp(&th), so3_right_jacobian(&th) * hr_g)
            }
            Scheme::Midpoint => {
                let d = hr_g * dbg;
                (self.rot * so3_exp(&d), so3_right_jacobian(&d) * hr_g)
            }
        };
        (r, dp, dv, dr)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// At rest without rotation, Δv sums the accelerometer noise and θ the
    /// gyro's: their covariances grow as diag(σ²)·T, each axis with its own σ
    /// (both schemes), and equal axes give the scalar densities' covariance.
    #[test]
    fn per_axis_noise_reaches_each_axis() {
        let axes = NoiseAxes {
            accel_noise_density: [0.01, 0.02, 0.04],
            gyro_noise_density: [1e-3, 2e-3, 5e-3],
            accel_random_walk: [1e-4; 3],
            gyro_random_walk: [1e-5; 3],
        };
        for scheme in [Scheme::ZeroOrderHold, Scheme::Midpoint] {
            let params = PreintegrationParams { scheme, axes: Some(axes), ..Default::default() };
            let mut pim = Preintegrated::new(params, Vector3::zeros(), Vector3::zeros());
            for _ in 0..200 {
                pim.integrate(Vector3::zeros(), Vector3::zeros(), 0.005);
            }
            let (t, cov) = (pim.delta_t(), pim.covariance());
            for k in 0..3 {
                let (theta, v) = (cov[(k, k)], cov[(6 + k, 6 + k)]);
                assert!((theta / (axes.gyro_noise_density[k].powi(2) * t) - 1.0).abs() < 1e-9, "{scheme:?} θ{k}");
                assert!((v / (axes.accel_noise_density[k].powi(2) * t) - 1.0).abs() < 1e-9, "{scheme:?} v{k}");
            }
            let scalar = PreintegrationParams { scheme, ..Default::default() };
            let same = NoiseAxes {
                accel_noise_density: [scalar.accel_noise_density; 3],
                gyro_noise_density: [scalar.gyro_noise_density; 3],
                ..axes
            };
            let run = |p: PreintegrationParams| {
                let mut pim = Preintegrated::new(p, Vector3::zeros(), Vector3::zeros());
                for i in 0..50 {
                    let x = i as f64 * 0.1;
                    pim.integrate(Vector3::new(x.sin(), 9.8, x.cos()), Vector3::new(0.3, -x.cos(), 0.2), 0.005);
                }
                pim.covariance()
            };
            let (a, b) = (run(scalar), run(PreintegrationParams { axes: Some(same), ..scalar }));
            assert!((a - b).norm() <= 1e-14 * a.norm(), "{scheme:?}");
        }
    }

    #[test]
    fn derivative_of_right_jacobian_product_matches_central_differences() {
        let c = Vector3::new(0.3, -0.7, 0.2);
        for theta in [Vector3::new(0.2, -0.1, 0.4), Vector3::new(1e-5, 2e-5, -1e-5), Vector3::new(2.0, 0.5, -1.0)] {
            let d = d_right_jacobian_times(&theta, &c);
            let h = 1e-6;
            for k in 0..3 {
                let mut e = Vector3::zeros();
                e[k] = h;
                let num = (so3_right_jacobian(&(theta + e)) * c - so3_right_jacobian(&(theta - e)) * c) / (2.0 * h);
                assert!(
                    (num - d.column(k)).amax() < if theta.norm() < 1e-3 { 2e-6 } else { 1e-8 },
                    "{theta:?}: {num:?} vs {:?}",
                    d.column(k).into_owned()
                );
            }
        }
    }

    fn signal(scheme: Scheme, bias_acc: Vector3<f64>, bias_gyro: Vector3<f64>) -> Preintegrated {
        let params = PreintegrationParams { scheme, ..Default::default() };
        let mut p = Preintegrated::new(params, bias_acc, bias_gyro);
        for k in 0..200 {
            let t = k as f64 * 0.005;
            p.integrate(
                Vector3::new(0.5 + t, -0.3 * (6.0 * t).sin(), 9.81),
                Vector3::new(0.3 * (3.0 * t).sin(), 0.2, 0.1 + t),
                0.005,
            );
        }
        p
    }

    #[test]
    fn bias_jacobians_predict_reintegration_for_both_schemes() {
        for scheme in [Scheme::ZeroOrderHold, Scheme::Midpoint] {
            let (ba, bg) = (Vector3::new(0.1, -0.05, 0.02), Vector3::new(0.01, -0.02, 0.015));
            let p = signal(scheme, ba, bg);
            let (dba, dbg) = (Vector3::new(1e-4, -2e-4, 1e-4), Vector3::new(-1e-5, 2e-5, 1e-5));
            let (r, dp, dv, _) = p.corrected(&(ba + dba), &(bg + dbg));
            let q = signal(scheme, ba + dba, bg + dbg);
            let e = [
                so3_log(&(r.transpose() * q.delta_rotation())).amax(),
                (dp - q.delta_position()).amax(),
                (dv - q.delta_velocity()).amax(),
            ];
            // Second-order remainders only (a first-order error would be ~1e-7 here).
            assert!(e[0] < 1e-9 && e[1] < 1e-8 && e[2] < 1e-8, "{scheme:?} {e:?}");
        }
    }

    #[test]
    fn both_schemes_propagate_the_same_noise() {
        let z = signal(Scheme::ZeroOrderHold, Vector3::zeros(), Vector3::zeros()).covariance();
        let m = signal(Scheme::Midpoint, Vector3::zeros(), Vector3::zeros()).covariance();
        for k in 0..9 {
            let ratio = m[(k, k)] / z[(k, k)];
            // Midpoint averages two samples per step: same continuous-time noise, one step fewer.
            assert!((ratio - 1.0).abs() < 0.05, "state {k}: midpoint/ZOH variance ratio {ratio}");
        }
    }
}
