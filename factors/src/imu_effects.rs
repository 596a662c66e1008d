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

use crate::imu_calib::{accel_matrix, gyro_matrix, orthogonal_basis, AccelParams, GyroMatrix, UPPER};
use nalgebra::{DMatrix, DVector, Dyn, Matrix3, Matrix3x2, OMatrix, Vector3, U3};
use tumble_solvers::lie::{hat, so3_exp, so3_right_jacobian};
use tumble_solvers::{Factor, FactorError, Key, Linearization, Vars};

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
