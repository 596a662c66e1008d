//! IMU noise in Kalibr's `imu.yaml` form: what `tumble allan` writes and the
//! audit and the VIO read (the reader is [`crate::io::noise`]).

use super::ModelError;
use serde::{Deserialize, Serialize};
use tumble_factors::imu_preint::{NoiseAxes, PreintegrationParams};

/// Kalibr `imu.yaml` noise parameters (continuous time, SI).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ImuNoise {
    /// Accelerometer white noise \[m/s²/√Hz\].
    pub accelerometer_noise_density: f64,
    /// Accelerometer bias random walk \[m/s³/√Hz\].
    pub accelerometer_random_walk: f64,
    /// Gyroscope white noise \[rad/s/√Hz\].
    pub gyroscope_noise_density: f64,
    /// Gyroscope bias random walk \[rad/s²/√Hz\].
    pub gyroscope_random_walk: f64,
    /// The same four per body axis (x, y, z), when known (`tumble allan`
    /// writes them; Kalibr ignores the key): the estimator then weighs each
    /// axis by its own figures instead of the triad's single one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub axes: Option<ImuNoiseAxes>,
}

/// Per-axis noise figures in `imu.yaml` (key `axes`), each `[x, y, z]`, units as in [`ImuNoise`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ImuNoiseAxes {
    /// Accelerometer white noise \[m/s²/√Hz\].
    pub accelerometer_noise_density: [f64; 3],
    /// Accelerometer bias random walk \[m/s³/√Hz\].
    pub accelerometer_random_walk: [f64; 3],
    /// Gyroscope white noise \[rad/s/√Hz\].
    pub gyroscope_noise_density: [f64; 3],
    /// Gyroscope bias random walk \[rad/s²/√Hz\].
    pub gyroscope_random_walk: [f64; 3],
}

impl ImuNoiseAxes {
    /// Check that every figure is a positive number; the error names the key.
    pub fn check(&self) -> Result<(), ModelError> {
        for (v, what) in [
            (self.accelerometer_noise_density, "accelerometer_noise_density"),
            (self.accelerometer_random_walk, "accelerometer_random_walk"),
            (self.gyroscope_noise_density, "gyroscope_noise_density"),
            (self.gyroscope_random_walk, "gyroscope_random_walk"),
        ] {
            if !v.iter().all(|x| x.is_finite() && *x > 0.0) {
                return Err(format!("axes.{what} must be three positive numbers, found {v:?}").into());
            }
        }
        Ok(())
    }
    /// The `axes:` block of an `imu.yaml` or `sensor.yaml` (two-space indent, one key per line).
    pub fn yaml_block(&self) -> String {
        let mut s = String::from("axes:\n");
        for (name, v) in [
            ("accelerometer_noise_density", self.accelerometer_noise_density),
            ("accelerometer_random_walk", self.accelerometer_random_walk),
            ("gyroscope_noise_density", self.gyroscope_noise_density),
            ("gyroscope_random_walk", self.gyroscope_random_walk),
        ] {
            s.push_str(&format!("  {name}: [{:e}, {:e}, {:e}]\n", v[0], v[1], v[2]));
        }
        s
    }
}

/// Time over which the estimator's bias random walk is matched to a bias
/// instability \[s\] (see [`estimator_random_walk`]): about the span of the
/// VIO's window of keyframes.
pub const BIAS_INSTABILITY_MATCH_S: f64 = 10.0;

/// The bias random walk \[unit/s/√Hz\] an estimator should assume for a
/// sensor with random walk `k` \[unit/s/√Hz\] and bias instability `b`
/// \[unit\] (Allan floor 0.664·b): `√(k² + 3 (0.664 b)² / τ)` with τ =
/// [`BIAS_INSTABILITY_MATCH_S`], the random walk whose Allan deviation at τ
/// adds the flicker floor to the random walk's own.
///
/// A random walk alone lets the bias drift too slowly over the window's
/// seconds when the flicker floor dominates there: on the simulated BMI055,
/// whose gyro-z bias instability (3.7e-4 rad/s) is 30× its x/y ones, the z
/// bias error was 2.7× its reported variance on average; with this, 0.85.
///
/// ```
/// use tumble::model::noise::estimator_random_walk;
/// assert_eq!(estimator_random_walk(2e-5, 0.0), 2e-5);
/// assert!((estimator_random_walk(0.0, 1e-3) - 0.664e-3 * (0.3f64).sqrt()).abs() < 1e-15);
/// ```
pub fn estimator_random_walk(k: f64, b: f64) -> f64 {
    (k * k + 3.0 * (0.664 * b).powi(2) / BIAS_INSTABILITY_MATCH_S).sqrt()
}

/// The noise keys of Kalibr's `imu.yaml` (with their units) and
/// `update_rate`, preceded by the discrete-time equivalents at that rate as
/// comments. `c` = \[gyro noise, accel noise, gyro walk, accel walk\],
/// continuous time, SI.
pub fn kalibr_keys(c: [f64; 4], rate_hz: f64) -> String {
    let [gn, an, gw, aw] = c;
    let dt = 1.0 / rate_hz;
    let mut s = format!("# Discrete-time equivalents at {rate_hz:.3} Hz (do not mix them up):\n");
    s += &format!("#   gyro  sigma_d = {:.4e} rad/s, sigma_bd = {:.4e} rad/s\n", gn / dt.sqrt(), gw * dt.sqrt());
    s += &format!("#   accel sigma_d = {:.4e} m/s^2, sigma_bd = {:.4e} m/s^2\n", an / dt.sqrt(), aw * dt.sqrt());
    s += &format!("accelerometer_noise_density: {an:e}  # [m/s^2/sqrt(Hz)]\n");
    s += &format!("accelerometer_random_walk: {aw:e}  # [m/s^3/sqrt(Hz)]\n");
    s += &format!("gyroscope_noise_density: {gn:e}  # [rad/s/sqrt(Hz)]\n");
    s += &format!("gyroscope_random_walk: {gw:e}  # [rad/s^2/sqrt(Hz)]\n");
    s += &format!("update_rate: {rate_hz}  # [Hz]\n");
    s
}

impl ImuNoise {
    /// The continuous-time noise of a simulator model (largest axis of each
    /// triad, and each axis in [`ImuNoise::axes`]): what `tumble allan` would
    /// identify on its static log. The per-axis random walks include the
    /// bias instability (see [`estimator_random_walk`]); the Kalibr scalars
    /// keep the model's random walk.
    pub fn from_model(m: &super::imu_model::ImuModel) -> ImuNoise {
        let max = |v: [f64; 3]| v.iter().fold(0.0f64, |a, b| a.max(b.abs()));
        let walk = |t: &super::imu_model::TriadModel| {
            let b = if m.effects.bias_instability { t.bias_instability } else { [0.0; 3] };
            [0, 1, 2].map(|i| estimator_random_walk(t.random_walk[i], b[i]))
        };
        ImuNoise {
            accelerometer_noise_density: max(m.accel.noise_density),
            accelerometer_random_walk: max(m.accel.random_walk).max(1e-6),
            gyroscope_noise_density: max(m.gyro.noise_density),
            gyroscope_random_walk: max(m.gyro.random_walk).max(1e-7),
            axes: Some(ImuNoiseAxes {
                accelerometer_noise_density: m.accel.noise_density,
                accelerometer_random_walk: walk(&m.accel).map(|k| k.max(1e-6)),
                gyroscope_noise_density: m.gyro.noise_density,
                gyroscope_random_walk: walk(&m.gyro).map(|k| k.max(1e-7)),
            }),
        }
    }
    /// The figures per axis: [`ImuNoise::axes`] where given, else the Kalibr
    /// scalars (the worst axis') on all three.
    pub fn per_axis(&self) -> ImuNoiseAxes {
        self.axes.unwrap_or(ImuNoiseAxes {
            accelerometer_noise_density: [self.accelerometer_noise_density; 3],
            accelerometer_random_walk: [self.accelerometer_random_walk; 3],
            gyroscope_noise_density: [self.gyroscope_noise_density; 3],
            gyroscope_random_walk: [self.gyroscope_random_walk; 3],
        })
    }

    /// A simulator model at 200 Hz with this noise and nothing else: white
    /// noise and bias random walk per axis (the Kalibr scalars on all three
    /// where there are no [`ImuNoise::axes`]), a small constant turn-on
    /// bias, and every other effect off (no misalignment, scale,
    /// nonlinearity, bias instability, temperature, g-sensitivity,
    /// quantization, saturation or jitter): what an estimator told this
    /// noise assumes the sensor is. A real sensor against it shows what the
    /// model lacks. [`ImuNoise::from_model`] reads the same figures back.
    pub fn noise_only_model(&self) -> super::imu_model::ImuModel {
        let axes = self.per_axis();
        let mut model = super::imu_model::ImuModel::bmi055();
        model.gyro.noise_density = axes.gyroscope_noise_density;
        model.gyro.random_walk = axes.gyroscope_random_walk;
        model.gyro.bias = [2e-3, -1e-3, 1e-3];
        model.accel.noise_density = axes.accelerometer_noise_density;
        model.accel.random_walk = axes.accelerometer_random_walk;
        model.accel.bias = [0.05, -0.03, 0.04];
        let none = super::imu_model::Effects::none();
        model.effects = super::imu_model::Effects { bias: true, random_walk: true, white_noise: true, ..none };
        model
    }

    /// The noise of several recordings of one sensor taken together: each
    /// figure (per axis where every one has axes) the root mean square over
    /// `all` — the density whose variance is their mean, as pooling their
    /// Allan variances over equal spans gives. None when `all` is empty.
    ///
    /// ```
    /// use tumble::model::noise::ImuNoise;
    /// let a = ImuNoise { accelerometer_noise_density: 1.0, accelerometer_random_walk: 1.0,
    ///     gyroscope_noise_density: 3.0, gyroscope_random_walk: 1.0, axes: None };
    /// let b = ImuNoise { gyroscope_noise_density: 4.0, ..a };
    /// let p = ImuNoise::pooled(&[a, b]).unwrap();
    /// assert!((p.gyroscope_noise_density - 12.5f64.sqrt()).abs() < 1e-12);
    /// assert_eq!(p.accelerometer_noise_density, 1.0);
    /// ```
    pub fn pooled(all: &[ImuNoise]) -> Option<ImuNoise> {
        let rms =
            |f: &dyn Fn(&ImuNoise) -> f64| (all.iter().map(|n| f(n).powi(2)).sum::<f64>() / all.len() as f64).sqrt();
        let rms3 = |f: &dyn Fn(&ImuNoiseAxes) -> [f64; 3]| {
            let axes: Vec<ImuNoiseAxes> = all.iter().map(|n| n.axes).collect::<Option<_>>()?;
            Some([0, 1, 2].map(|i| (axes.iter().map(|a| f(a)[i].powi(2)).sum::<f64>() / axes.len() as f64).sqrt()))
        };
        if all.is_empty() {
            return None;
        }
        let axes = (|| {
            Some(ImuNoiseAxes {
                accelerometer_noise_density: rms3(&|a| a.accelerometer_noise_density)?,
                accelerometer_random_walk: rms3(&|a| a.accelerometer_random_walk)?,
                gyroscope_noise_density: rms3(&|a| a.gyroscope_noise_density)?,
                gyroscope_random_walk: rms3(&|a| a.gyroscope_random_walk)?,
            })
        })();
        Some(ImuNoise {
            accelerometer_noise_density: rms(&|n| n.accelerometer_noise_density),
            accelerometer_random_walk: rms(&|n| n.accelerometer_random_walk),
            gyroscope_noise_density: rms(&|n| n.gyroscope_noise_density),
            gyroscope_random_walk: rms(&|n| n.gyroscope_random_walk),
            axes,
        })
    }
    /// Apply to preintegration settings.
    pub fn apply(&self, p: &mut PreintegrationParams) {
        p.accel_noise_density = self.accelerometer_noise_density;
        p.accel_random_walk = self.accelerometer_random_walk;
        p.gyro_noise_density = self.gyroscope_noise_density;
        p.gyro_random_walk = self.gyroscope_random_walk;
        p.axes = self.axes.map(|a| NoiseAxes {
            accel_noise_density: a.accelerometer_noise_density,
            gyro_noise_density: a.gyroscope_noise_density,
            accel_random_walk: a.accelerometer_random_walk,
            gyro_random_walk: a.gyroscope_random_walk,
        });
    }
}
