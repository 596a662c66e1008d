//! Effects beyond the paper's eq. (1) error model, and the factors that fit
//! them jointly with the calibration (the model-discrepancy audit).
//!
//! The base model is the inverse model of [`crate::imu_calib`]:
//! `v = M_a (ã − b_a − δa)`, `u = M_g (ω̃ − b_g)`, with `δa` a slowly wandering
//! accelerometer bias and `b_g` the gyro bias at the time of the sample. Each
//! [`Effect`] subtracts one more term, in the calibrated frame:
//!
//! ```text
//! a = v − c_a ΔT [− q_a ΔT²] − d_a t − n_a ⊙ f(v) − s_a ⊙ v ΔT [− r_a ⊙ v ΔT²]
//! ω = u − G a − c_g ΔT [− q_g ΔT²] − d_g t − n_g ⊙ f(u) − s_g ⊙ u ΔT [− r_g ⊙ u ΔT²]
//! ```
//!
//! The scale nonlinearity has four forms ([`NonlinearityForm`]), one effect
//! each: `f(x) = x²` (even), `x|x|` (odd: a scale that grows with the rate,
//! the datasheet's "scale-factor nonlinearity"), `x³` (odd, cubic) and `|x|`
//! (a different scale for positive and negative inputs). The temperature
//! effects are linear in `ΔT` or, in their quadratic forms, linear plus quadratic.
//!
//! `ΔT` is the temperature minus the reference \[°C\], `t` the time since the
//! reference instant \[s\]. The parameters are sensor properties (what the
//! sensor adds), so they are what a simulator with that effect switched on uses,
//! up to the calibration matrices (≈ I).
//!
//! Jacobians are analytic: [`correct`] returns the derivative of `a` and `ω`
//! with respect to every parameter in the column layout of [`Layout`]; the
//! factors chain them (the motion factor through the rotation sweep of
//! [`crate::imu_calib::IntegratedRotationFactor`]).

use crate::imu_calib::{accel_matrix, gyro_matrix, AccelParams, GyroMatrix, UPPER};
use nalgebra::{DMatrix, Dyn, Matrix3, OMatrix, Vector3, U3};
use tumble_solvers::{FactorError, Vars};

/// A named extension of the error model (the audit's fixed vocabulary).
/// Effects of one [`Effect::family`] are alternative forms of one physical
/// effect; the audit chooses the form by BIC.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Effect {
    /// Gyro output caused by specific force, `G a` (3×3, row major) \[rad/s per m/s²\].
    GyroGSensitivity,
    /// Bias proportional to the temperature change: accel `c_a` \[m/s² per °C\], gyro `c_g` \[rad/s per °C\].
    TemperatureBias,
    /// Scale change proportional to the temperature change: accel `s_a`, gyro `s_g` \[1/°C\].
    TemperatureScale,
    /// Even gyro scale nonlinearity `n_g ⊙ ω²` \[1/(rad/s)\].
    GyroScaleNonlinearity,
    /// Even accelerometer scale nonlinearity `n_a ⊙ a²` \[1/(m/s²)\].
    AccelScaleNonlinearity,
    /// Time offset between accelerometer and gyro samples \[s\] (invisible to the
    /// calibration audit; fitted by the VIO audit, `tumble audit --vio`).
    AccelGyroTimeOffset,
    /// Time offset between camera and IMU \[s\] (needs a camera: fitted by the VIO audit, `tumble audit --vio`).
    CameraImuTimeOffset,
    /// Linear bias drift within the recording: accel `d_a` \[m/s³\], gyro `d_g` \[rad/s²\].
    BiasDrift,
    /// Odd gyro scale nonlinearity `n_g ⊙ ω|ω|` (a scale growing with the rate) \[1/(rad/s)\].
    GyroScaleNonlinearityOdd,
    /// Cubic gyro scale nonlinearity `n_g ⊙ ω³` \[1/(rad/s)²\].
    GyroScaleNonlinearityCubic,
    /// Gyro scale asymmetry `n_g ⊙ |ω|`: scale `1 + n` for positive rates, `1 − n` for negative \[1\].
    GyroScaleAsymmetry,
    /// Odd accelerometer scale nonlinearity `n_a ⊙ a|a|` \[1/(m/s²)\].
    AccelScaleNonlinearityOdd,
    /// Cubic accelerometer scale nonlinearity `n_a ⊙ a³` \[1/(m/s²)²\].
    AccelScaleNonlinearityCubic,
    /// Accelerometer scale asymmetry `n_a ⊙ |a|` \[1\].
    AccelScaleAsymmetry,
    /// Bias quadratic in the temperature change: `c ΔT + q ΔT²`, accel then gyro,
    /// linear terms then quadratic \[unit per °C, unit per °C²\].
    TemperatureBiasQuadratic,
    /// Scale change quadratic in the temperature change: `s ΔT + r ΔT²` \[1/°C, 1/°C²\].
    TemperatureScaleQuadratic,
}

/// The shape `f` of a scale nonlinearity term `n ⊙ f(x)`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum NonlinearityForm {
    /// `x²`.
    Even,
    /// `x|x|`.
    Odd,
    /// `x³`.
    Cubic,
    /// `|x|`.
    Asymmetric,
}

impl NonlinearityForm {
    /// `f(x)` and `f'(x)` (`f'(0)` of `|x|` taken as 0).
    pub fn eval(self, x: f64) -> (f64, f64) {
        match self {
            NonlinearityForm::Even => (x * x, 2.0 * x),
            NonlinearityForm::Odd => (x * x.abs(), 2.0 * x.abs()),
            NonlinearityForm::Cubic => (x * x * x, 3.0 * x * x),
            NonlinearityForm::Asymmetric => (x.abs(), if x == 0.0 { 0.0 } else { x.signum() }),
        }
    }
}

/// An effect name [`Effect`]'s `FromStr` does not know (the message lists those it does).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct UnknownEffect(pub String);

impl std::fmt::Display for UnknownEffect {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let ids: Vec<&str> = Effect::ALL.iter().map(|e| e.id()).collect();
        write!(f, "unknown effect `{}` (known: {})", self.0, ids.join(", "))
    }
}

impl std::error::Error for UnknownEffect {}

impl std::str::FromStr for Effect {
    type Err = UnknownEffect;
    /// The effect with this identifier ([`Effect::id`]), surrounding spaces ignored.
    fn from_str(s: &str) -> Result<Effect, UnknownEffect> {
        Effect::from_id(s.trim()).ok_or_else(|| UnknownEffect(s.to_string()))
    }
}

/// Which triad a term acts on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Triad {
    /// The accelerometer.
    Accel,
    /// The gyro.
    Gyro,
}

impl Effect {
    /// Every effect, in vocabulary order.
    pub const ALL: [Effect; 16] = [
        Effect::GyroGSensitivity,
        Effect::TemperatureBias,
        Effect::TemperatureBiasQuadratic,
        Effect::TemperatureScale,
        Effect::TemperatureScaleQuadratic,
        Effect::GyroScaleNonlinearity,
        Effect::GyroScaleNonlinearityOdd,
        Effect::GyroScaleNonlinearityCubic,
        Effect::GyroScaleAsymmetry,
        Effect::AccelScaleNonlinearity,
        Effect::AccelScaleNonlinearityOdd,
        Effect::AccelScaleNonlinearityCubic,
        Effect::AccelScaleAsymmetry,
        Effect::AccelGyroTimeOffset,
        Effect::CameraImuTimeOffset,
        Effect::BiasDrift,
    ];

    /// The identifier used in files (`gyro_g_sensitivity`, …).
    pub fn id(self) -> &'static str {
        match self {
            Effect::GyroGSensitivity => "gyro_g_sensitivity",
            Effect::TemperatureBias => "temperature_bias",
            Effect::TemperatureScale => "temperature_scale",
            Effect::GyroScaleNonlinearity => "gyro_scale_nonlinearity",
            Effect::AccelScaleNonlinearity => "accel_scale_nonlinearity",
            Effect::AccelGyroTimeOffset => "accel_gyro_time_offset",
            Effect::CameraImuTimeOffset => "camera_imu_time_offset",
            Effect::BiasDrift => "bias_drift",
            Effect::GyroScaleNonlinearityOdd => "gyro_scale_nonlinearity_odd",
            Effect::GyroScaleNonlinearityCubic => "gyro_scale_nonlinearity_cubic",
            Effect::GyroScaleAsymmetry => "gyro_scale_asymmetry",
            Effect::AccelScaleNonlinearityOdd => "accel_scale_nonlinearity_odd",
            Effect::AccelScaleNonlinearityCubic => "accel_scale_nonlinearity_cubic",
            Effect::AccelScaleAsymmetry => "accel_scale_asymmetry",
            Effect::TemperatureBiasQuadratic => "temperature_bias_quadratic",
            Effect::TemperatureScaleQuadratic => "temperature_scale_quadratic",
        }
    }

    /// The effect with this identifier.
    pub fn from_id(id: &str) -> Option<Effect> {
        Effect::ALL.into_iter().find(|e| e.id() == id)
    }

    /// The physical effect this is one form of (`gyro_scale_nonlinearity` for
    /// its four forms, `temperature_bias` for the linear and quadratic ones, …).
    pub fn family(self) -> &'static str {
        match self {
            Effect::GyroScaleNonlinearityOdd | Effect::GyroScaleNonlinearityCubic | Effect::GyroScaleAsymmetry => {
                Effect::GyroScaleNonlinearity.id()
            }
            Effect::AccelScaleNonlinearityOdd | Effect::AccelScaleNonlinearityCubic | Effect::AccelScaleAsymmetry => {
                Effect::AccelScaleNonlinearity.id()
            }
            Effect::TemperatureBiasQuadratic => Effect::TemperatureBias.id(),
            Effect::TemperatureScaleQuadratic => Effect::TemperatureScale.id(),
            e => e.id(),
        }
    }

    /// The form within the family, for reports (`even: n ⊙ ω²`, `linear in ΔT`, …).
    pub fn form(self) -> &'static str {
        match self {
            Effect::GyroScaleNonlinearity => "even, n ⊙ ω²",
            Effect::GyroScaleNonlinearityOdd => "odd, n ⊙ ω|ω|",
            Effect::GyroScaleNonlinearityCubic => "odd cubic, n ⊙ ω³",
            Effect::GyroScaleAsymmetry => "sign-asymmetric, n ⊙ |ω|",
            Effect::AccelScaleNonlinearity => "even, n ⊙ a²",
            Effect::AccelScaleNonlinearityOdd => "odd, n ⊙ a|a|",
            Effect::AccelScaleNonlinearityCubic => "odd cubic, n ⊙ a³",
            Effect::AccelScaleAsymmetry => "sign-asymmetric, n ⊙ |a|",
            Effect::TemperatureBias | Effect::TemperatureScale => "linear in ΔT",
            Effect::TemperatureBiasQuadratic | Effect::TemperatureScaleQuadratic => "quadratic in ΔT",
            Effect::BiasDrift => "linear in time",
            Effect::GyroGSensitivity => "linear in specific force",
            Effect::AccelGyroTimeOffset | Effect::CameraImuTimeOffset => "constant offset",
        }
    }

    /// The triad and shape of a scale nonlinearity form.
    pub fn nonlinearity(self) -> Option<(Triad, NonlinearityForm)> {
        use NonlinearityForm::*;
        Some(match self {
            Effect::GyroScaleNonlinearity => (Triad::Gyro, Even),
            Effect::GyroScaleNonlinearityOdd => (Triad::Gyro, Odd),
            Effect::GyroScaleNonlinearityCubic => (Triad::Gyro, Cubic),
            Effect::GyroScaleAsymmetry => (Triad::Gyro, Asymmetric),
            Effect::AccelScaleNonlinearity => (Triad::Accel, Even),
            Effect::AccelScaleNonlinearityOdd => (Triad::Accel, Odd),
            Effect::AccelScaleNonlinearityCubic => (Triad::Accel, Cubic),
            Effect::AccelScaleAsymmetry => (Triad::Accel, Asymmetric),
            _ => return None,
        })
    }

    /// Names of the parameters, in order (their count is the effect's degrees of freedom).
    pub fn param_names(self) -> &'static [&'static str] {
        const AG: [&str; 6] = ["accel_x", "accel_y", "accel_z", "gyro_x", "gyro_y", "gyro_z"];
        const AG2: [&str; 12] = [
            "accel_x",
            "accel_y",
            "accel_z",
            "gyro_x",
            "gyro_y",
            "gyro_z",
            "accel_x_2",
            "accel_y_2",
            "accel_z_2",
            "gyro_x_2",
            "gyro_y_2",
            "gyro_z_2",
        ];
        match self {
            Effect::GyroGSensitivity => &["G_xx", "G_xy", "G_xz", "G_yx", "G_yy", "G_yz", "G_zx", "G_zy", "G_zz"],
            Effect::TemperatureBias | Effect::TemperatureScale | Effect::BiasDrift => &AG,
            Effect::TemperatureBiasQuadratic | Effect::TemperatureScaleQuadratic => &AG2,
            Effect::AccelGyroTimeOffset | Effect::CameraImuTimeOffset => &["offset_s"],
            e => match e.nonlinearity() {
                Some((Triad::Gyro, _)) => &["gyro_x", "gyro_y", "gyro_z"],
                _ => &["accel_x", "accel_y", "accel_z"],
            },
        }
    }

    /// Unit of parameter `i` (in [`Effect::param_names`]' order; "" past the end).
    pub fn param_unit(self, i: usize) -> &'static str {
        // Accelerometer parameters come first where both triads have them.
        let accel = |i: usize| i % 6 < 3;
        let triad = |i: usize, a: &'static str, g: &'static str| if accel(i) { a } else { g };
        if i >= self.dim() {
            return "";
        }
        match self {
            Effect::GyroGSensitivity => "rad/s per m/s²",
            Effect::TemperatureBias => triad(i, "m/s² per °C", "rad/s per °C"),
            Effect::TemperatureBiasQuadratic => match (i < 6, accel(i)) {
                (true, true) => "m/s² per °C",
                (true, false) => "rad/s per °C",
                (false, true) => "m/s² per °C²",
                (false, false) => "rad/s per °C²",
            },
            Effect::TemperatureScale => "1/°C",
            Effect::TemperatureScaleQuadratic => {
                if i < 6 {
                    "1/°C"
                } else {
                    "1/°C²"
                }
            }
            Effect::BiasDrift => triad(i, "m/s³", "rad/s²"),
            Effect::AccelGyroTimeOffset | Effect::CameraImuTimeOffset => "s",
            e => match e.nonlinearity() {
                Some((Triad::Gyro, NonlinearityForm::Even | NonlinearityForm::Odd)) => "1/(rad/s)",
                Some((Triad::Gyro, NonlinearityForm::Cubic)) => "1/(rad/s)²",
                Some((Triad::Accel, NonlinearityForm::Even | NonlinearityForm::Odd)) => "1/(m/s²)",
                Some((Triad::Accel, NonlinearityForm::Cubic)) => "1/(m/s²)²",
                _ => "1",
            },
        }
    }

    /// Number of parameters.
    pub fn dim(self) -> usize {
        self.param_names().len()
    }

    /// Whether the effect needs a temperature column.
    pub fn needs_temperature(self) -> bool {
        self.family() == "temperature_bias" || self.family() == "temperature_scale"
    }

    /// Whether [`correct`] models it (the calibration audit can fit it).
    pub fn in_sensor_model(self) -> bool {
        !matches!(self, Effect::AccelGyroTimeOffset | Effect::CameraImuTimeOffset)
    }
}

impl std::fmt::Display for Effect {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.id())
    }
}

/// When a sample was taken, relative to the references of the effects.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Context {
    /// Temperature minus the reference temperature \[°C\] (0 without a temperature column).
    pub dtemp: f64,
    /// Time since the reference instant \[s\].
    pub time: f64,
}

/// The parameters [`correct`] needs, and the column layout of its Jacobians:
/// `[M_a, b_a (9) | M_g (9) | b_g (3) | δa (3) | effect parameters in order]`.
#[derive(Clone, Debug)]
pub struct Layout {
    /// The effects switched on, in key order.
    pub effects: Vec<Effect>,
}

impl Layout {
    /// Column of `M_g`.
    pub const GYRO: usize = 9;
    /// Column of `b_g`.
    pub const GYRO_BIAS: usize = 18;
    /// Column of `δa`.
    pub const WANDER: usize = 21;
    /// Columns before the effects.
    pub const BASE: usize = 24;

    /// Total number of columns.
    pub fn cols(&self) -> usize {
        Self::BASE + self.effects.iter().map(|e| e.dim()).sum::<usize>()
    }

    /// First column of each effect.
    pub fn offsets(&self) -> Vec<usize> {
        let mut o = Self::BASE;
        self.effects
            .iter()
            .map(|e| {
                let here = o;
                o += e.dim();
                here
            })
            .collect()
    }
}

/// Parameter values for [`correct`].
#[derive(Clone, Debug)]
pub struct ModelParams<'a> {
    /// Accelerometer `[M_a upper triangle, b_a]` \[raw units\].
    pub accel: &'a AccelParams,
    /// `M_g` row major.
    pub gyro: &'a GyroMatrix,
    /// Gyro bias at the sample \[raw units\].
    pub gyro_bias: Vector3<f64>,
    /// Accelerometer bias wander added to `b_a` \[raw units\].
    pub wander: Vector3<f64>,
    /// Values of each effect of the layout.
    pub effects: &'a [Vec<f64>],
}

/// Corrected specific force and rate with their Jacobians (3 × [`Layout::cols`]).
#[derive(Clone, Debug)]
pub struct Corrected {
    /// Specific force \[m/s²\].
    pub accel: Vector3<f64>,
    /// Angular rate \[rad/s\].
    pub gyro: Vector3<f64>,
    /// ∂accel/∂parameters (empty when not asked for).
    pub d_accel: OMatrix<f64, U3, Dyn>,
    /// ∂gyro/∂parameters (empty when not asked for).
    pub d_gyro: OMatrix<f64, U3, Dyn>,
}

/// Apply the extended inverse model to one raw sample (see the module docs).
/// With `jacobians`, also its derivatives in the column layout of `layout`.
pub fn correct(
    layout: &Layout,
    p: &ModelParams,
    raw_accel: &Vector3<f64>,
    raw_gyro: &Vector3<f64>,
    ctx: Context,
    jacobians: bool,
) -> Corrected {
    let cols = if jacobians { layout.cols() } else { 0 };
    let ma = accel_matrix(p.accel);
    let ra = raw_accel - Vector3::new(p.accel[6], p.accel[7], p.accel[8]) - p.wander;
    let v = ma * ra;
    let mut a = v;
    let mut da_dv = Matrix3::<f64>::identity();
    let mut ja = OMatrix::<f64, U3, Dyn>::zeros(cols);
    let mg = gyro_matrix(p.gyro);
    let rg = raw_gyro - p.gyro_bias;
    let u = mg * rg;
    let mut w = u;
    let mut dw_du = Matrix3::<f64>::identity();
    let mut jw = OMatrix::<f64, U3, Dyn>::zeros(cols);
    let mut g_sens: Option<Matrix3<f64>> = None;
    let offsets = layout.offsets();
    // Accelerometer terms.
    for ((e, th), &o) in layout.effects.iter().zip(p.effects).zip(&offsets) {
        for c in 0..3 {
            let Some(t) = term(*e, th, Triad::Accel, c, v[c], ctx) else { break };
            a[c] -= t.delta;
            da_dv[(c, c)] -= t.d_input;
            if jacobians {
                for &(col, d) in &t.d_params[..t.n] {
                    ja[(c, o + col)] -= d;
                }
            }
        }
    }
    // Gyro terms (g-sensitivity uses the corrected specific force).
    for ((e, th), &o) in layout.effects.iter().zip(p.effects).zip(&offsets) {
        if *e == Effect::GyroGSensitivity {
            let g = Matrix3::from_row_slice(th);
            w -= g * a;
            if jacobians {
                for r in 0..3 {
                    for c in 0..3 {
                        jw[(r, o + 3 * r + c)] -= a[c];
                    }
                }
            }
            g_sens = Some(g);
            continue;
        }
        for c in 0..3 {
            let Some(t) = term(*e, th, Triad::Gyro, c, u[c], ctx) else { break };
            w[c] -= t.delta;
            dw_du[(c, c)] -= t.d_input;
            if jacobians {
                for &(col, d) in &t.d_params[..t.n] {
                    jw[(c, o + col)] -= d;
                }
            }
        }
    }
    if jacobians {
        // ∂v/∂(M_a, b_a, δa) and ∂u/∂(M_g, b_g), chained through the effects.
        let mut jv = OMatrix::<f64, U3, Dyn>::zeros(cols);
        for (k, &(r, c)) in UPPER.iter().enumerate() {
            jv[(r, k)] = ra[c];
        }
        for c in 0..3 {
            for r in 0..3 {
                jv[(r, 6 + c)] = -ma[(r, c)];
                jv[(r, Layout::WANDER + c)] = -ma[(r, c)];
            }
        }
        ja += da_dv * jv;
        let mut ju = OMatrix::<f64, U3, Dyn>::zeros(cols);
        for r in 0..3 {
            for c in 0..3 {
                ju[(r, Layout::GYRO + 3 * r + c)] = rg[c];
                ju[(r, Layout::GYRO_BIAS + c)] = -mg[(r, c)];
            }
        }
        jw += dw_du * ju;
        if let Some(g) = g_sens {
            jw -= g * &ja;
        }
    }
    Corrected { accel: a, gyro: w, d_accel: ja, d_gyro: jw }
}

/// One axis's term of an effect: its value, its derivative with respect to
/// the axis's input, and its derivatives with respect to the effect's
/// parameters (`n` of them, as `(parameter index, ∂term/∂parameter)`).
struct Term {
    delta: f64,
    d_input: f64,
    d_params: [(usize, f64); 2],
    n: usize,
}

/// Axis `c` of `triad`'s term of effect `e` with parameters `th` at input `x`
/// (`v[c]` or `u[c]`); `None` when the effect has no term on that triad.
fn term(e: Effect, th: &[f64], triad: Triad, c: usize, x: f64, ctx: Context) -> Option<Term> {
    // Effects with accelerometer and gyro parameters: the gyro's follow the accelerometer's 3.
    let k = if triad == Triad::Gyro { 3 + c } else { c };
    let (dt, dt2) = (ctx.dtemp, ctx.dtemp * ctx.dtemp);
    let one =
        |delta: f64, d_input: f64, col: usize, d: f64| Term { delta, d_input, d_params: [(col, d), (0, 0.0)], n: 1 };
    Some(match e {
        Effect::TemperatureBias => one(th[k] * dt, 0.0, k, dt),
        Effect::BiasDrift => one(th[k] * ctx.time, 0.0, k, ctx.time),
        Effect::TemperatureScale => one(th[k] * x * dt, th[k] * dt, k, x * dt),
        Effect::TemperatureBiasQuadratic => {
            Term { delta: th[k] * dt + th[6 + k] * dt2, d_input: 0.0, d_params: [(k, dt), (6 + k, dt2)], n: 2 }
        }
        Effect::TemperatureScaleQuadratic => {
            let s = th[k] * dt + th[6 + k] * dt2;
            Term { delta: s * x, d_input: s, d_params: [(k, x * dt), (6 + k, x * dt2)], n: 2 }
        }
        e => match e.nonlinearity() {
            Some((t, form)) if t == triad => {
                let (f, df) = form.eval(x);
                one(th[c] * f, th[c] * df, c, f)
            }
            _ => return None,
        },
    })
}

/// Read the variables of a factor whose keys are `[M_a/b_a, M_g, then `extra`
/// per-interval keys, then the effects]`.
struct Read {
    accel: AccelParams,
    gyro: GyroMatrix,
    extra: Vec<Vector3<f64>>,
    effects: Vec<Vec<f64>>,
}

fn read(vars: Vars<'_>, extra: usize) -> Result<Read, FactorError> {
    let accel = *vars.get::<AccelParams>(0)?;
    let gyro = *vars.get::<GyroMatrix>(1)?;
    let extra = (0..extra).map(|i| vars.get::<Vector3<f64>>(2 + i).copied()).collect::<Result<Vec<_>, _>>()?;
    let effects = (2 + extra.len()..vars.len()).map(|i| vars.get_dyn(i).params_dyn()).collect();
    Ok(Read { accel, gyro, extra, effects })
}

/// The Jacobian columns `[from, from + n)` of `j`.
fn cols(j: &DMatrix<f64>, from: usize, n: usize) -> DMatrix<f64> {
    j.columns(from, n).into_owned()
}

/// Effect blocks of a Jacobian in layout columns.
fn effect_blocks(layout: &Layout, j: &DMatrix<f64>) -> Vec<DMatrix<f64>> {
    layout.effects.iter().zip(layout.offsets()).map(|(e, o)| cols(j, o, e.dim())).collect()
}

fn check_effects(layout: &Layout, n_keys: usize, fixed: usize) -> Result<(), FactorError> {
    if n_keys != fixed + layout.effects.len() {
        return Err(FactorError::Other(format!(
            "{} keys for {} fixed variables and {} effects",
            n_keys,
            fixed,
            layout.effects.len()
        )));
    }
    if let Some(e) = layout.effects.iter().find(|e| !e.in_sensor_model()) {
        return Err(FactorError::Other(format!("{e} is not part of the sensor model")));
    }
    Ok(())
}

mod factors;

pub use factors::{MotionFactor, MotionSamples, StaticFactor};

#[cfg(test)]
mod tests {
    use super::*;

    /// Every parameter has a unit, of its own triad: a gyro parameter's unit
    /// names rad/s and an accelerometer's m/s² wherever the unit has a
    /// sensor quantity in it (scale changes and asymmetries are relative).
    #[test]
    fn every_parameter_has_a_unit_of_its_triad() {
        for e in Effect::ALL {
            for (i, name) in e.param_names().iter().enumerate() {
                let unit = e.param_unit(i);
                assert!(!unit.is_empty(), "{e:?} {name}");
                let relative = unit == "1" || unit.starts_with("1/°C") || unit == "s";
                if name.starts_with("gyro") && !relative {
                    assert!(unit.contains("rad"), "{e:?} {name}: {unit}");
                }
                if name.starts_with("accel") && !relative {
                    assert!(unit.contains("m/s") && !unit.contains("rad"), "{e:?} {name}: {unit}");
                }
                if name.ends_with("_2") {
                    assert!(unit.contains("°C²"), "{e:?} {name}: {unit}");
                }
            }
            assert_eq!(e.param_unit(e.dim()), "");
        }
    }
}
