//! The calibrated error model in the paper's convention, its conversions to
//! and from imu_tk's, and correction of raw samples (eq. 16).
//!
//! ```text
//! paper:  ã = T_a K_a a + b_a        ω̃ = T_g K_g ω + b_g
//! imu_tk: a = T'_a K'_a (ã − b_a)    ω = T'_g K'_g (ω̃ − b_g)
//! ```
//!
//! `T_a` is upper triangular and `T_g` full, both with a unit diagonal; `K`
//! are diagonal. `ã`, `ω̃`, `b` are in the input's units (counts or SI); `a`
//! is in m/s², `ω` in rad/s. Both conventions describe the same map:
//! `T' K' = (T K)⁻¹`, with the same bias.

use super::ModelError;
use nalgebra::{Matrix3, Vector3};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use tumble_factors::imu_calib::{AccelParams, GyroMatrix, UPPER};
use tumble_factors::imu_effects::{correct, Context, Effect, Layout, ModelParams};

/// Units of the raw input and of the corrected output.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Units {
    /// Unit of raw accelerometer readings and of `b_a` ("counts" or "m/s^2").
    pub accel_input: String,
    /// Unit of raw gyro readings and of `b_g` ("counts" or "rad/s").
    pub gyro_input: String,
    /// Unit of corrected specific force.
    pub accel: String,
    /// Unit of corrected angular rate.
    pub gyro: String,
}

impl Default for Units {
    fn default() -> Self {
        Units { accel_input: "m/s^2".into(), gyro_input: "rad/s".into(), accel: "m/s^2".into(), gyro: "rad/s".into() }
    }
}

/// One sensor triad's deterministic model `raw = T K x + b`, with 1-σ uncertainties.
#[derive(Debug, Clone, PartialEq)]
pub struct Triad {
    /// Misalignment `T` (unit diagonal).
    pub t: Matrix3<f64>,
    /// Scale: the diagonal of `K` \[raw units per SI unit\].
    pub k: Vector3<f64>,
    /// Bias \[raw units\].
    pub b: Vector3<f64>,
    /// Standard deviations of `T`'s entries (0 on the fixed ones).
    pub t_std: Matrix3<f64>,
    /// Standard deviations of `K`.
    pub k_std: Vector3<f64>,
    /// Standard deviations of `b`.
    pub b_std: Vector3<f64>,
}

impl Triad {
    /// Mean absolute scale `mean |K|` \[raw units per SI unit\]: converts a
    /// physical noise figure into the triad's raw units (the audit's
    /// `random_walk_raw` and its reading by `tumble export`).
    pub fn mean_scale(&self) -> f64 {
        self.k.iter().map(|x| x.abs()).sum::<f64>() / 3.0
    }
    /// The identity model (no error).
    pub fn identity() -> Triad {
        Triad {
            t: Matrix3::identity(),
            k: Vector3::repeat(1.0),
            b: Vector3::zeros(),
            t_std: Matrix3::zeros(),
            k_std: Vector3::zeros(),
            b_std: Vector3::zeros(),
        }
    }
    /// `T K`: maps SI to unbiased raw readings (`raw = T K x + b`).
    pub fn matrix(&self) -> Matrix3<f64> {
        self.t * Matrix3::from_diagonal(&self.k)
    }
    /// `(T K)⁻¹`: maps unbiased raw readings to SI; `None` when singular.
    pub fn inverse_matrix(&self) -> Option<Matrix3<f64>> {
        self.matrix().try_inverse()
    }
    /// imu_tk's `(T', K', b)` with `T' K' = (T K)⁻¹`.
    pub fn to_imu_tk(&self) -> Option<ImuTkTriad> {
        let m = self.inverse_matrix()?;
        let (t, k) = split_unit_diagonal(&m)?;
        Some((t, k, self.b))
    }
    /// From imu_tk's `(T', K', b)`.
    pub fn from_imu_tk(t: &Matrix3<f64>, k: &Vector3<f64>, b: &Vector3<f64>) -> Option<Triad> {
        let n = (t * Matrix3::from_diagonal(k)).try_inverse()?;
        let (t, k) = split_unit_diagonal(&n)?;
        Some(Triad { t, k, b: *b, ..Triad::identity() })
    }
}

/// imu_tk's `(T', K', b)`: misalignment, scale diagonal, bias.
pub type ImuTkTriad = (Matrix3<f64>, Vector3<f64>, Vector3<f64>);

/// Write `m = T·diag(k)` with unit-diagonal `T`: `k = diag(m)`, `T = m diag(k)⁻¹`.
pub fn split_unit_diagonal(m: &Matrix3<f64>) -> Option<(Matrix3<f64>, Vector3<f64>)> {
    let k = m.diagonal();
    if k.iter().any(|x| x.abs() < 1e-300 || !x.is_finite()) {
        return None;
    }
    let mut t = *m;
    for c in 0..3 {
        for r in 0..3 {
            t[(r, c)] /= k[c];
        }
    }
    Some((t, k))
}

/// A full IMU calibration in the paper's convention (the keys of `calibration.json`).
#[derive(Debug, Clone, PartialEq)]
pub struct ImuCalibration {
    /// Accelerometer (`T_a` upper triangular).
    pub accel: Triad,
    /// Gyroscope (`T_g` full).
    pub gyro: Triad,
    /// Local gravity used \[m/s²\].
    pub gravity: f64,
    /// Units of input and output.
    pub units: Units,
    /// Effects beyond eq. (1) found by `tumble audit` (`None`: the plain model).
    pub effects: Option<ModelEffects>,
    /// Time offsets found by `tumble audit --vio` (`None`: none known).
    pub time_offsets: Option<TimeOffsets>,
}

/// Sensor time offsets \[s\], the audit's `camera_imu_time_offset` and
/// `accel_gyro_time_offset`. The VIO applies them when it builds its input
/// with the calibration ([`crate::vio::VioInput::with_time_offsets`]);
/// `tumble apply` resamples the accelerometer by `accel_gyro_s`
/// ([`crate::io::imu::resample_delayed`]).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TimeOffsets {
    /// A camera frame stamped `t` was taken at IMU time `t + camera_imu_s`.
    #[serde(default)]
    pub camera_imu_s: f64,
    /// Its standard deviation (0: not estimated).
    #[serde(default)]
    pub camera_imu_s_std: f64,
    /// An accelerometer sample stamped `t` measured the motion at `t + accel_gyro_s`.
    #[serde(default)]
    pub accel_gyro_s: f64,
    /// Its standard deviation (0: not estimated).
    #[serde(default)]
    pub accel_gyro_s_std: f64,
}

impl TimeOffsets {
    /// Check that both offsets are finite and within ±1 s.
    pub fn check(&self) -> Result<(), ModelError> {
        for (name, v) in [("camera_imu_s", self.camera_imu_s), ("accel_gyro_s", self.accel_gyro_s)] {
            if !(v.is_finite() && v.abs() <= 1.0) {
                return Err(format!("time_offsets: {name} = {v} is not a time offset within ±1 s").into());
            }
        }
        Ok(())
    }
}

/// Effects beyond the paper's model, with the references they are measured from
/// (see [`tumble_factors::imu_effects`] for each effect's equation and units).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ModelEffects {
    /// Temperature where the temperature effects are zero \[°C\].
    pub reference_temperature_c: f64,
    /// Recording time where the bias drift is zero \[s\] (only meaningful for the recording it was fitted on).
    pub reference_time_s: f64,
    /// The effects, in the order they were found.
    pub effects: Vec<EffectTerm>,
}

/// One effect's parameters (names from [`Effect::param_names`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EffectTerm {
    /// Identifier from the audit vocabulary (`gyro_g_sensitivity`, …).
    pub id: String,
    /// Parameter values.
    pub params: BTreeMap<String, f64>,
    /// Their standard deviations.
    #[serde(default)]
    pub std: BTreeMap<String, f64>,
}

impl EffectTerm {
    /// A term from values in [`Effect::param_names`] order.
    pub fn new(effect: Effect, values: &[f64], std: Option<&[f64]>) -> EffectTerm {
        let names = effect.param_names();
        EffectTerm {
            id: effect.id().to_string(),
            params: names.iter().zip(values).map(|(n, v)| (n.to_string(), *v)).collect(),
            std: std.map(|s| names.iter().zip(s).map(|(n, v)| (n.to_string(), *v)).collect()).unwrap_or_default(),
        }
    }

    /// The effect and its values in parameter order; errors name what is wrong.
    pub fn values(&self) -> Result<(Effect, Vec<f64>), ModelError> {
        let effect = Effect::from_id(&self.id).ok_or_else(|| format!("unknown effect `{}`", self.id))?;
        if !effect.in_sensor_model() {
            return Err(format!("effect `{}` is not applied to IMU samples", self.id).into());
        }
        let names = effect.param_names();
        if let Some(k) = self.params.keys().find(|k| !names.contains(&k.as_str())) {
            return Err(format!("effect `{}` has no parameter `{k}` (it has {})", self.id, names.join(", ")).into());
        }
        let values = names
            .iter()
            .map(|n| match self.params.get(*n) {
                Some(v) if v.is_finite() => Ok(*v),
                Some(v) => Err(format!("effect `{}`: {n} = {v} is not finite", self.id).into()),
                None => Err(format!("effect `{}` lacks parameter `{n}`", self.id).into()),
            })
            .collect::<Result<_, ModelError>>()?;
        Ok((effect, values))
    }
}

/// Serialized form of [`ImuCalibration`] with the issue's key names.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[allow(non_snake_case)]
pub struct CalibrationFile {
    /// Accelerometer misalignment (row major).
    pub T_a: [[f64; 3]; 3],
    /// Its standard deviations.
    #[serde(default)]
    pub T_a_std: [[f64; 3]; 3],
    /// Accelerometer scale (diagonal of `K_a`) \[input units per m/s²\].
    pub K_a: [f64; 3],
    /// Its standard deviations.
    #[serde(default)]
    pub K_a_std: [f64; 3],
    /// Accelerometer bias \[input units\].
    pub b_a: [f64; 3],
    /// Its standard deviations.
    #[serde(default)]
    pub b_a_std: [f64; 3],
    /// Gyro misalignment (row major).
    pub T_g: [[f64; 3]; 3],
    /// Its standard deviations.
    #[serde(default)]
    pub T_g_std: [[f64; 3]; 3],
    /// Gyro scale (diagonal of `K_g`) \[input units per rad/s\].
    pub K_g: [f64; 3],
    /// Its standard deviations.
    #[serde(default)]
    pub K_g_std: [f64; 3],
    /// Gyro bias \[input units\].
    pub b_g: [f64; 3],
    /// Its standard deviations.
    #[serde(default)]
    pub b_g_std: [f64; 3],
    /// Local gravity \[m/s²\].
    #[serde(default = "default_gravity")]
    pub gravity: f64,
    /// Units.
    #[serde(default)]
    pub units: Units,
    /// Effects found by `tumble audit`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub effects: Option<ModelEffects>,
    /// Time offsets found by `tumble audit --vio`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub time_offsets: Option<TimeOffsets>,
    /// The calibration's verdict (`ok`, `weak`, `failed`; see `tumble::calib::verdict`):
    /// a file marked `failed` is refused when read.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub verdict: Option<String>,
}

fn default_gravity() -> f64 {
    super::STANDARD_GRAVITY
}

fn rows(m: &Matrix3<f64>) -> [[f64; 3]; 3] {
    [0, 1, 2].map(|r| [0, 1, 2].map(|c| m[(r, c)]))
}
fn mat(a: &[[f64; 3]; 3]) -> Matrix3<f64> {
    Matrix3::from_fn(|r, c| a[r][c])
}
fn arr(v: &Vector3<f64>) -> [f64; 3] {
    [v.x, v.y, v.z]
}

impl From<&ImuCalibration> for CalibrationFile {
    fn from(c: &ImuCalibration) -> Self {
        CalibrationFile {
            T_a: rows(&c.accel.t),
            T_a_std: rows(&c.accel.t_std),
            K_a: arr(&c.accel.k),
            K_a_std: arr(&c.accel.k_std),
            b_a: arr(&c.accel.b),
            b_a_std: arr(&c.accel.b_std),
            T_g: rows(&c.gyro.t),
            T_g_std: rows(&c.gyro.t_std),
            K_g: arr(&c.gyro.k),
            K_g_std: arr(&c.gyro.k_std),
            b_g: arr(&c.gyro.b),
            b_g_std: arr(&c.gyro.b_std),
            gravity: c.gravity,
            units: c.units.clone(),
            effects: c.effects.clone(),
            time_offsets: c.time_offsets,
            verdict: None,
        }
    }
}

impl CalibrationFile {
    /// Check and convert to the in-memory model.
    pub fn to_calibration(&self) -> Result<ImuCalibration, ModelError> {
        if self.verdict.as_deref() == Some("failed") {
            return Err(ModelError::from(
                "this calibration failed its verdict (`verdict: failed`; the reasons are in the file): its \
                 parameters do not explain the recording and must not be used",
            ));
        }
        let triad = |t: &[[f64; 3]; 3], ts, k: &[f64; 3], ks, b: &[f64; 3], bs, name: &str| -> Result<Triad, String> {
            let all: Vec<f64> = t.as_flattened().iter().chain(k).chain(b).copied().collect();
            if all.iter().any(|x| !x.is_finite()) {
                return Err(format!("{name}: every entry of T, K and b must be finite"));
            }
            let tr = Triad {
                t: mat(t),
                k: Vector3::from(*k),
                b: Vector3::from(*b),
                t_std: mat(ts),
                k_std: Vector3::from(ks),
                b_std: Vector3::from(bs),
            };
            if tr.inverse_matrix().is_none_or(|m| !m.iter().all(|x| x.is_finite())) {
                return Err(format!("{name}: T·K is singular"));
            }
            Ok(tr)
        };
        let accel = triad(&self.T_a, &self.T_a_std, &self.K_a, self.K_a_std, &self.b_a, self.b_a_std, "accelerometer")?;
        let cal = ImuCalibration {
            accel,
            gyro: triad(&self.T_g, &self.T_g_std, &self.K_g, self.K_g_std, &self.b_g, self.b_g_std, "gyro")?,
            gravity: self.gravity,
            units: self.units.clone(),
            effects: match &self.effects {
                Some(e) => {
                    for t in &e.effects {
                        t.values()?;
                    }
                    if !(e.reference_temperature_c.is_finite() && e.reference_time_s.is_finite()) {
                        return Err("effects: the reference temperature and time must be finite".into());
                    }
                    Some(e.clone())
                }
                None => None,
            },
            time_offsets: match self.time_offsets {
                Some(o) => {
                    o.check()?;
                    Some(o)
                }
                None => None,
            },
        };
        if cal.effects.as_ref().is_some_and(|e| !e.effects.is_empty()) {
            cal.inverse_params().map_err(|m| format!("effects: {m}"))?;
        }
        Ok(cal)
    }
}

impl ImuCalibration {
    /// The identity calibration (SI input, no error, standard gravity): samples
    /// pass unchanged; a start for offsets or effects known from elsewhere.
    pub fn identity() -> ImuCalibration {
        ImuCalibration {
            accel: Triad::identity(),
            gyro: Triad::identity(),
            gravity: super::STANDARD_GRAVITY,
            units: Units::default(),
            effects: None,
            time_offsets: None,
        }
    }

    /// A [`Corrector`] applying eq. 16 (and the audit's effects, if any) to raw
    /// samples; `None` when a matrix is singular.
    pub fn corrector(&self) -> Option<Corrector> {
        let extended = match &self.effects {
            Some(e) if !e.effects.is_empty() => {
                let terms: Vec<(Effect, Vec<f64>)> =
                    e.effects.iter().map(|t| t.values().ok()).collect::<Option<_>>()?;
                let (accel, gyro, b_g) = self.inverse_params().ok()?;
                Some(Box::new(Extended {
                    layout: Layout { effects: terms.iter().map(|t| t.0).collect() },
                    values: terms.into_iter().map(|t| t.1).collect(),
                    accel,
                    gyro,
                    b_g,
                    reference_temperature: e.reference_temperature_c,
                    reference_time: e.reference_time_s,
                }))
            }
            _ => None,
        };
        Some(Corrector {
            accel: self.accel.inverse_matrix()?,
            b_a: self.accel.b,
            gyro: self.gyro.inverse_matrix()?,
            b_g: self.gyro.b,
            extended,
        })
    }

    /// The inverse model's parameters ([`tumble_factors::imu_calib`]): `M_a`
    /// (upper triangle) with `b_a`, `M_g` row major, `b_g`. Errors when a matrix
    /// is singular or `(T_a K_a)⁻¹` is not upper triangular.
    pub fn inverse_params(&self) -> Result<(AccelParams, GyroMatrix, Vector3<f64>), ModelError> {
        let ma = self.accel.inverse_matrix().ok_or("accelerometer T·K is singular")?;
        let scale = ma.amax().max(1e-300);
        if [(1, 0), (2, 0), (2, 1)].iter().any(|&(r, c)| ma[(r, c)].abs() > 1e-9 * scale) {
            return Err(
                "the accelerometer's (T_a K_a)⁻¹ is not upper triangular: the extended model needs the \
                        paper's upper-triangular accelerometer misalignment (as tumble calibrate and imu_tk write it)"
                    .into(),
            );
        }
        let mut a = AccelParams::zeros();
        for (k, &(r, c)) in UPPER.iter().enumerate() {
            a[k] = ma[(r, c)];
        }
        for k in 0..3 {
            a[6 + k] = self.accel.b[k];
        }
        let mg = self.gyro.inverse_matrix().ok_or("gyro T·K is singular")?;
        Ok((a, GyroMatrix::from_row_slice(mg.transpose().as_slice()), self.gyro.b))
    }

    /// Names of the effects the calibration carries.
    pub fn effect_ids(&self) -> Vec<String> {
        self.effects.as_ref().map(|e| e.effects.iter().map(|t| t.id.clone()).collect()).unwrap_or_default()
    }
}

/// The audit's extended model, ready to apply.
#[derive(Debug, Clone)]
struct Extended {
    layout: Layout,
    values: Vec<Vec<f64>>,
    accel: AccelParams,
    gyro: GyroMatrix,
    b_g: Vector3<f64>,
    reference_temperature: f64,
    reference_time: f64,
}

/// Eq. 16 with the inverses precomputed: `a = (T_a K_a)⁻¹(ã − b_a)`, `ω = (T_g K_g)⁻¹(ω̃ − b_g)`,
/// plus the audit's effects when the calibration has them ([`Corrector::sample`]).
#[derive(Debug, Clone)]
pub struct Corrector {
    accel: Matrix3<f64>,
    b_a: Vector3<f64>,
    gyro: Matrix3<f64>,
    b_g: Vector3<f64>,
    extended: Option<Box<Extended>>,
}

impl Corrector {
    /// Whether the calibration carries effects beyond eq. (1).
    pub fn has_effects(&self) -> bool {
        self.extended.is_some()
    }

    /// Whether an effect needs the temperature column.
    pub fn needs_temperature(&self) -> bool {
        self.extended.as_ref().is_some_and(|x| x.layout.effects.iter().any(|e| e.needs_temperature()))
    }

    /// Corrected specific force \[m/s²\] and rate \[rad/s\] of one sample with every
    /// effect of the calibration: `temperature` \[°C\] (`None`: the reference, i.e.
    /// no temperature correction) and recording time `t` \[s\] (for the bias drift).
    pub fn sample(
        &self,
        raw_accel: [f64; 3],
        raw_gyro: [f64; 3],
        temperature: Option<f64>,
        t: f64,
    ) -> ([f64; 3], [f64; 3]) {
        let Some(x) = &self.extended else {
            return (self.accel(raw_accel), self.gyro(raw_gyro));
        };
        let p = ModelParams {
            accel: &x.accel,
            gyro: &x.gyro,
            gyro_bias: x.b_g,
            wander: Vector3::zeros(),
            effects: &x.values,
        };
        let ctx = Context {
            dtemp: temperature.map(|c| c - x.reference_temperature).unwrap_or(0.0),
            time: t - x.reference_time,
        };
        let c = correct(&x.layout, &p, &Vector3::from(raw_accel), &Vector3::from(raw_gyro), ctx, false);
        (arr(&c.accel), arr(&c.gyro))
    }

    /// Problems applying the effects to `rec` (missing temperature, a drift
    /// fitted on another recording), for the user, on a recording with or without temperatures.
    pub fn warnings(&self, has_temperature: bool) -> Vec<String> {
        let mut w = Vec::new();
        if let Some(x) = &self.extended {
            if self.needs_temperature() && !has_temperature {
                w.push(
                    "the calibration has temperature effects but the recording has no temperature column: \
                        they are not applied"
                        .to_string(),
                );
            }
            if x.layout.effects.contains(&Effect::BiasDrift) {
                w.push(format!(
                    "the calibration has a bias drift (zero at t = {:.1} s of the recording it was fitted on): it is \
                     applied with this recording's time stamps",
                    x.reference_time
                ));
            }
        }
        w
    }

    /// Corrected specific force \[m/s²\] from a raw accelerometer reading (eq. 16 only).
    pub fn accel(&self, raw: [f64; 3]) -> [f64; 3] {
        arr(&(self.accel * (Vector3::from(raw) - self.b_a)))
    }
    /// Corrected angular rate \[rad/s\] from a raw gyro reading (eq. 16 only).
    pub fn gyro(&self, raw: [f64; 3]) -> [f64; 3] {
        arr(&(self.gyro * (Vector3::from(raw) - self.b_g)))
    }
}

/// imu_tk's `.calib` text: `T'` (3 rows), a blank line, `K'` as a 3×3 diagonal
/// matrix, a blank line, `b` (3 rows).
pub fn imu_tk_calib_text(t: &Matrix3<f64>, k: &Vector3<f64>, b: &Vector3<f64>) -> String {
    let mut s = String::new();
    let row = |s: &mut String, v: [f64; 3]| {
        s.push_str(&format!("{:>24} {:>24} {:>24}\n", v[0], v[1], v[2]));
    };
    for r in 0..3 {
        row(&mut s, [t[(r, 0)], t[(r, 1)], t[(r, 2)]]);
    }
    s.push('\n');
    for r in 0..3 {
        let mut v = [0.0; 3];
        v[r] = k[r];
        row(&mut s, v);
    }
    s.push('\n');
    for r in 0..3 {
        s.push_str(&format!("{:>24}\n", b[r]));
    }
    s
}

/// A triad with misalignment, scale and bias, for tests.
#[cfg(test)]
pub(crate) fn sample_triad() -> Triad {
    Triad {
        t: Matrix3::new(1.0, -0.01, 0.02, 0.003, 1.0, 0.01, -0.02, 0.005, 1.0),
        k: Vector3::new(1.01, 0.99, 1.002),
        b: Vector3::new(0.1, -0.2, 0.3),
        ..Triad::identity()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn conventions_round_trip() {
        let tr = sample_triad();
        let (t, k, b) = tr.to_imu_tk().unwrap();
        let back = Triad::from_imu_tk(&t, &k, &b).unwrap();
        assert!((back.t - tr.t).amax() < 1e-14 && (back.k - tr.k).amax() < 1e-14);
    }
}
