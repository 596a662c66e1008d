//! The IMU error model of the paper's eq. (1), in full:
//!
//! ```text
//! ω̃ = T_g K_g(1 + s_T,g ΔT) f_g(ω) + b_g(t) + η_g(ΔT) + G a + n_g
//! ã = T_a K_a(1 + s_T,a ΔT) f_a(a) + b_a(t) + η_a(ΔT)       + n_a
//! ```
//!
//! with `f(x) = x + c ⊙ h(x)` (scale nonlinearity of shape `h` =
//! [`TriadModel::nonlinearity_form`]: `x²`, `x|x|`, `x³` or `|x|`), `b(t)` = turn-on
//! bias + random walk + bias instability (flicker, approximated by a sum of
//! Gauss–Markov processes), `η = c_T ΔT + q_T ΔT²` the temperature-driven bias with
//! `ΔT = T(t) − T_ref` (and a scale `1 + s_T ΔT + r_T ΔT²`), `G` the gyro g-sensitivity \[rad/s per m/s²\], white
//! noise `n`, then saturation at ±range and quantization to the LSB. Sample
//! instants jitter around their stamps. `ω` \[rad/s\] and `a` \[m/s²\] are the
//! true angular rate and specific force in the body (accelerometer) frame.
//!
//! Defaults are the paper's BMI055 results (eq. 20–21) and its Table 1 noise;
//! see [`ImuModel::bmi055`] for how Table 1 was read.

use super::ModelError;
use serde::{Deserialize, Serialize};

/// The deterministic and random error terms of one triad (gyro or accelerometer).
/// Units are those of the sensor: rad/s for the gyro, m/s² for the accelerometer.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TriadModel {
    /// Misalignment `T` (3×3, row major; unit diagonal).
    pub misalignment: [[f64; 3]; 3],
    /// Scale factors: the diagonal of `K`.
    pub scale: [f64; 3],
    /// Nonlinearity coefficient `c` in `f(x) = x + c ⊙ h(x)` \[unit^(1−p) for `h`
    /// of degree p: 1/unit for `x²` and `x|x|`, 1/unit² for `x³`, 1 for `|x|`\].
    pub nonlinearity: [f64; 3],
    /// Shape `h` of the nonlinearity.
    pub nonlinearity_form: NonlinearityShape,
    /// Turn-on bias \[unit\].
    pub bias: [f64; 3],
    /// White-noise density N \[unit/√Hz\].
    pub noise_density: [f64; 3],
    /// Bias random walk K \[unit·√Hz/s\] (rad/s²/√Hz for the gyro).
    pub random_walk: [f64; 3],
    /// Bias instability B \[unit\] (the Allan floor is 0.664 B).
    pub bias_instability: [f64; 3],
    /// Range of correlation times \[s\] over which the bias instability is flat.
    pub bias_instability_band: [f64; 2],
    /// Temperature bias coefficient \[unit/°C\].
    pub temperature_bias: [f64; 3],
    /// Quadratic temperature bias coefficient \[unit/°C²\].
    pub temperature_bias_quadratic: [f64; 3],
    /// Temperature scale coefficient \[1/°C\] (relative change of K).
    pub temperature_scale: [f64; 3],
    /// Quadratic temperature scale coefficient \[1/°C²\].
    pub temperature_scale_quadratic: [f64; 3],
    /// Deterministic bias drift: the bias grows linearly from power-on \[unit/s\]
    /// (gyro rad/s², accelerometer m/s³); applied when `effects.bias_drift` is on.
    pub bias_drift: [f64; 3],
    /// Quantization step (LSB) \[unit\]; 0 for none.
    pub lsb: f64,
    /// Measurement range ±range \[unit\]; values beyond are clipped.
    pub range: f64,
}

/// Shape `h` of a triad's scale nonlinearity `c ⊙ h(x)`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum NonlinearityShape {
    /// `x²` (even).
    #[default]
    Even,
    /// `x|x|` (odd: the scale grows with the input's size).
    Odd,
    /// `x³`.
    Cubic,
    /// `|x|` (a different scale for positive and negative inputs).
    Asymmetric,
}

impl NonlinearityShape {
    /// `h(x)`.
    pub fn eval(self, x: f64) -> f64 {
        match self {
            NonlinearityShape::Even => x * x,
            NonlinearityShape::Odd => x * x.abs(),
            NonlinearityShape::Cubic => x * x * x,
            NonlinearityShape::Asymmetric => x.abs(),
        }
    }
}

/// Which terms of the model are applied. Each can be switched on its own.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Effects {
    /// Misalignment `T`.
    pub misalignment: bool,
    /// Scale `K`.
    pub scale: bool,
    /// Quadratic scale nonlinearity `f(·)`.
    pub nonlinearity: bool,
    /// Turn-on bias.
    pub bias: bool,
    /// Bias random walk.
    pub random_walk: bool,
    /// Bias instability (flicker).
    pub bias_instability: bool,
    /// White noise.
    pub white_noise: bool,
    /// Temperature-driven bias and scale change.
    pub temperature: bool,
    /// Gyro g-sensitivity `G a`.
    pub g_sensitivity: bool,
    /// Quantization to the LSB.
    pub quantization: bool,
    /// Saturation at ±range.
    pub saturation: bool,
    /// Deterministic linear bias drift (`TriadModel::bias_drift`).
    pub bias_drift: bool,
    /// Sample-time jitter.
    pub jitter: bool,
}

impl Default for Effects {
    /// The paper's eq. (1) model of a factory-corrected BMI055: everything on
    /// except the three effects the paper lists but does not calibrate
    /// (nonlinearity, temperature, g-sensitivity), which the discrepancy
    /// workflow is meant to find.
    fn default() -> Self {
        Effects {
            misalignment: true,
            scale: true,
            nonlinearity: false,
            bias: true,
            random_walk: true,
            bias_instability: true,
            white_noise: true,
            temperature: false,
            g_sensitivity: false,
            quantization: true,
            saturation: true,
            bias_drift: false,
            jitter: false,
        }
    }
}

impl Effects {
    /// Every effect off: the ideal sensor.
    pub fn none() -> Self {
        Effects {
            misalignment: false,
            scale: false,
            nonlinearity: false,
            bias: false,
            random_walk: false,
            bias_instability: false,
            white_noise: false,
            temperature: false,
            g_sensitivity: false,
            quantization: false,
            saturation: false,
            bias_drift: false,
            jitter: false,
        }
    }
}

/// Temperature trace: warm-up from `start` towards `end` with time constant
/// `warmup_s`, plus a sinusoidal ripple; `reference` is where η = 0 \[°C\].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TemperatureTrace {
    /// Temperature at power-on \[°C\].
    pub start: f64,
    /// Temperature after warm-up \[°C\].
    pub end: f64,
    /// Warm-up time constant \[s\].
    pub warmup_s: f64,
    /// Ripple amplitude \[°C\].
    pub ripple: f64,
    /// Ripple period \[s\].
    pub ripple_period_s: f64,
    /// Reference temperature of the calibration \[°C\].
    pub reference: f64,
}

impl Default for TemperatureTrace {
    fn default() -> Self {
        TemperatureTrace {
            start: 25.0,
            end: 35.0,
            warmup_s: 600.0,
            ripple: 0.5,
            ripple_period_s: 300.0,
            reference: 25.0,
        }
    }
}

impl TemperatureTrace {
    /// Temperature at time `t` \[s\] \[°C\].
    pub fn at(&self, t: f64) -> f64 {
        let warm = if self.warmup_s > 0.0 { (-t / self.warmup_s).exp() } else { 0.0 };
        let ripple = if self.ripple_period_s > 0.0 {
            self.ripple * (2.0 * std::f64::consts::PI * t / self.ripple_period_s).sin()
        } else {
            0.0
        };
        self.end + (self.start - self.end) * warm + ripple
    }
}

/// A complete IMU: both triads, g-sensitivity, timing and which effects are on.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ImuModel {
    /// Sample rate \[Hz\].
    pub rate_hz: f64,
    /// Gyro error terms (rad/s).
    pub gyro: TriadModel,
    /// Accelerometer error terms (m/s²).
    pub accel: TriadModel,
    /// Gyro g-sensitivity `G` (3×3 row major) \[rad/s per m/s²\].
    pub g_sensitivity: [[f64; 3]; 3],
    /// Standard deviation of the sample instants about their stamps \[s\].
    pub jitter_s: f64,
    /// Time offset of the accelerometer against the gyro \[s\]: an accelerometer
    /// sample stamped `t` measures the motion at `t + accel_time_offset_s`
    /// (0: both triads sampled together; the audit's `accel_gyro_time_offset`).
    pub accel_time_offset_s: f64,
    /// Temperature trace.
    pub temperature: TemperatureTrace,
    /// Which effects are applied.
    pub effects: Effects,
}

impl Default for ImuModel {
    fn default() -> Self {
        ImuModel::bmi055()
    }
}

const I3: [[f64; 3]; 3] = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];

impl Default for TriadModel {
    fn default() -> Self {
        TriadModel {
            misalignment: I3,
            scale: [1.0; 3],
            nonlinearity: [0.0; 3],
            nonlinearity_form: NonlinearityShape::Even,
            bias: [0.0; 3],
            noise_density: [0.0; 3],
            random_walk: [0.0; 3],
            bias_instability: [0.0; 3],
            bias_instability_band: [1.0, 1000.0],
            temperature_bias: [0.0; 3],
            temperature_bias_quadratic: [0.0; 3],
            temperature_scale: [0.0; 3],
            temperature_scale_quadratic: [0.0; 3],
            bias_drift: [0.0; 3],
            lsb: 0.0,
            range: f64::MAX,
        }
    }
}

impl ImuModel {
    /// The paper's BMI055 at 200 Hz.
    ///
    /// Deterministic terms: eq. (20) (gyro) and (21) (accelerometer).
    /// Noise: the paper's Table 1, whose extracted layout is ambiguous; its
    /// four rows, each with the mean of its three axes, read as accelerometer
    /// white noise N = (0.0191, 0.0177, 0.0428) m/s²/√Hz, accelerometer bias
    /// instability B = (1.14, 0.95, 3.03)·10⁻³ m/s², gyro white noise N =
    /// (1.05, 1.06, 5.25)·10⁻³ rad/s/√Hz and gyro bias instability B =
    /// (1.18·10⁻⁵, 9.1·10⁻⁶, 3.74·10⁻⁴) rad/s. The paper gives no random walk;
    /// the defaults (gyro 2·10⁻⁵ rad/s²/√Hz, accelerometer 3·10⁻⁴ m/s³/√Hz)
    /// are typical of MEMS parts of this class. Datasheet figures: range
    /// ±2000 °/s with 16-bit output (LSB 1.065·10⁻³ rad/s), ±4 g with 12-bit
    /// output (LSB 1.916·10⁻² m/s²). Nonlinearity, temperature and
    /// g-sensitivity coefficients are typical magnitudes, applied only when
    /// their effect is switched on.
    pub fn bmi055() -> ImuModel {
        let gyro = TriadModel {
            misalignment: [[1.0, -0.00867285, -0.0144341], [0.00635068, 1.0, 0.00333975], [0.0160995, 0.0067665, 1.0]],
            scale: [0.994162, 0.999354, 0.99726],
            nonlinearity: [2e-3, -1.5e-3, 1e-3],
            nonlinearity_form: NonlinearityShape::Even,
            bias: [-2.39227e-5, -2.03875e-5, 1.73784e-6],
            noise_density: [1.05e-3, 1.06e-3, 5.25e-3],
            random_walk: [2e-5; 3],
            bias_instability: [1.18e-5, 9.1e-6, 3.74e-4],
            bias_instability_band: [1.0, 1000.0],
            temperature_bias: [2e-4, -1.5e-4, 1e-4],
            temperature_bias_quadratic: [4e-5, -3e-5, 2.5e-5],
            temperature_scale: [3e-4, -2e-4, 2.5e-4],
            temperature_scale_quadratic: [6e-5, -4e-5, 5e-5],
            bias_drift: [1e-5, -8e-6, 6e-6],
            lsb: 2000f64.to_radians() / 32768.0,
            range: 2000f64.to_radians(),
        };
        let accel = TriadModel {
            misalignment: [[1.0, -0.0107435, -0.00719295], [0.0, 1.0, 0.0141747], [0.0, 0.0, 1.0]],
            scale: [0.994721, 1.00251, 0.999592],
            nonlinearity: [1e-3, -8e-4, 6e-4],
            nonlinearity_form: NonlinearityShape::Even,
            bias: [0.0148413, 0.120341, -0.0155797],
            noise_density: [0.0191, 0.0177, 0.0428],
            random_walk: [3e-4; 3],
            bias_instability: [1.14e-3, 9.5e-4, 3.03e-3],
            bias_instability_band: [1.0, 1000.0],
            temperature_bias: [1.5e-3, -1e-3, 2e-3],
            temperature_bias_quadratic: [3e-4, -2e-4, 4e-4],
            temperature_scale: [2e-4, 1.5e-4, -1e-4],
            temperature_scale_quadratic: [4e-5, 3e-5, -2.5e-5],
            bias_drift: [1e-4, -8e-5, 6e-5],
            lsb: 8.0 * 9.80665 / 4096.0,
            range: 4.0 * 9.80665,
        };
        ImuModel {
            rate_hz: 200.0,
            gyro,
            accel,
            g_sensitivity: [[2e-4, 5e-5, -3e-5], [-4e-5, 1.5e-4, 6e-5], [3e-5, -5e-5, 1e-4]],
            jitter_s: 2e-5,
            accel_time_offset_s: 0.0,
            temperature: TemperatureTrace::default(),
            effects: Effects::default(),
        }
    }

    /// Check the model for values that cannot be simulated; the error names the field.
    pub fn check(&self) -> Result<(), ModelError> {
        if !(self.rate_hz.is_finite() && self.rate_hz > 0.0) {
            return Err(format!("rate_hz must be positive, found {}", self.rate_hz).into());
        }
        for (t, name) in [(&self.gyro, "gyro"), (&self.accel, "accel")] {
            let finite = |v: &[f64]| v.iter().all(|x| x.is_finite());
            let nonneg = |v: &[f64]| v.iter().all(|x| x.is_finite() && *x >= 0.0);
            if !finite(t.misalignment.as_flattened())
                || !finite(&t.bias)
                || !finite(&t.nonlinearity)
                || !finite(&t.temperature_bias_quadratic)
                || !finite(&t.temperature_scale_quadratic)
                || !finite(&t.bias_drift)
            {
                return Err(format!("{name}: misalignment, bias, bias_drift and nonlinearity must be finite").into());
            }
            if t.scale.iter().any(|s| !(s.is_finite() && *s > 0.0)) {
                return Err(format!("{name}.scale must be positive, found {:?}", t.scale).into());
            }
            if !nonneg(&t.noise_density) || !nonneg(&t.random_walk) || !nonneg(&t.bias_instability) {
                return Err(format!("{name}: noise_density, random_walk and bias_instability must be ≥ 0").into());
            }
            let [lo, hi] = t.bias_instability_band;
            if !(lo > 0.0 && hi > lo && hi.is_finite()) {
                return Err(format!("{name}.bias_instability_band must be 0 < lo < hi, found [{lo}, {hi}]").into());
            }
            if !(t.lsb.is_finite() && t.lsb >= 0.0 && t.range.is_finite() && t.range > 0.0) {
                return Err(format!("{name}: lsb must be ≥ 0 and range > 0").into());
            }
        }
        if !(self.jitter_s.is_finite() && self.jitter_s >= 0.0) {
            return Err("jitter_s must be ≥ 0".into());
        }
        if !(self.accel_time_offset_s.is_finite() && self.accel_time_offset_s.abs() <= 1.0) {
            return Err(format!("accel_time_offset_s must be within ±1 s, found {}", self.accel_time_offset_s).into());
        }
        Ok(())
    }
}

/// Allan variance of a first-order Gauss–Markov process with stationary
/// variance `q2` and correlation time `tc` at averaging time `tau`.
pub fn gauss_markov_avar(q2: f64, tc: f64, tau: f64) -> f64 {
    let x = tau / tc;
    q2 / (x * x) * gauss_markov_shape(x)
}

/// 2x − 3 + 4e^(−x) − e^(−2x), by its series where the closed form cancels
/// catastrophically (x ≪ 1: the terms are ~1, the result ~x³).
pub fn gauss_markov_shape(x: f64) -> f64 {
    if x < 1e-2 {
        x * x * x * (2.0 / 3.0 - x / 2.0 + 7.0 * x * x / 30.0 - x * x * x / 12.0)
    } else {
        2.0 * x - 3.0 + 4.0 * (-x).exp() - (-2.0 * x).exp()
    }
}

/// Correlation times (one per decade over `band`) and the common stationary
/// std of Gauss–Markov processes whose sum has a flat Allan deviation of
/// 0.664·B across the band (the IEEE flicker floor), for bias instability `b`.
pub fn flicker_components(b: f64, band: [f64; 2]) -> (Vec<f64>, f64) {
    flicker_components_per_decade(b, band, 1)
}

/// [`flicker_components`] with `per_decade` components per decade: the Allan
/// deviation of the sum ripples by about ±2 % across the band with one per
/// decade and by well under 1 % with three.
pub fn flicker_components_per_decade(b: f64, band: [f64; 2], per_decade: usize) -> (Vec<f64>, f64) {
    let decades = (band[1] / band[0]).log10();
    let n = ((decades * per_decade.max(1) as f64).ceil() as usize).max(1) + 1;
    let tcs: Vec<f64> = (0..n).map(|i| band[0] * 10f64.powf(decades * i as f64 / (n - 1).max(1) as f64)).collect();
    // Scale so the ADEV at the band's geometric centre is 0.664·B.
    let mid = (band[0] * band[1]).sqrt() * 1.9;
    let unit: f64 = tcs.iter().map(|&tc| gauss_markov_avar(1.0, tc, mid)).sum();
    let q = if unit > 0.0 { 0.664 * b / unit.sqrt() } else { 0.0 };
    (tcs, q)
}
