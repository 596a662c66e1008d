//! The audit's joint problem: calibration + per-interval biases (random walks)
//! + the effects switched on, as one factor graph on the solver.

use super::data::AuditData;
use super::AuditError;
use nalgebra::{DMatrix, Vector3};
use tumble_factors::imu_calib::{AccelParams, GyroMatrix};
use tumble_factors::imu_effects::{Layout, MotionFactor, StaticFactor};
use tumble_factors::BetweenFactor;
use tumble_solvers::{
    covariances, information_log_det, DynVector, Graph, Key, LmOptions, NoiseModel, Optimizer, Values, Vars,
};

/// Key of the accelerometer parameters.
pub const KEY_ACCEL: Key = Key::new('a', 0);
/// Key of the gyro matrix.
pub const KEY_GYRO: Key = Key::new('g', 0);
/// Gyro bias at static interval `k`.
pub fn key_bias(k: usize) -> Key {
    Key::new('b', k as u64)
}
/// Accelerometer bias wander at static interval `k`.
pub fn key_wander(k: usize) -> Key {
    Key::new('w', k as u64)
}
/// Parameters of the `j`-th effect switched on.
pub fn key_effect(j: usize) -> Key {
    Key::new('e', j as u64)
}

/// Residual groups whose χ² is reported separately.
pub const GROUPS: [&str; 5] = ["accel_norm", "gyro_static", "rotation", "gyro_bias_walk", "accel_bias_walk"];

/// The noise of every factor, fixed for the whole audit (computed once at the
/// starting calibration so that χ² values of different models compare).
#[derive(Clone)]
pub struct Noise {
    statics: Vec<NoiseModel>,
    motions: Vec<NoiseModel>,
    /// Time between consecutive static intervals \[s\].
    walk_dt: Vec<f64>,
    /// Bias random walks per axis \[raw units/√s\]: gyro, accelerometer.
    pub walks: Walks,
}

/// Bias random walks per axis \[raw units/√s\]: gyro, accelerometer.
pub type Walks = ([f64; 3], [f64; 3]);

/// Root mean square of the three axes' walks.
pub fn pooled(w: &[f64; 3]) -> f64 {
    (w.iter().map(|x| x * x).sum::<f64>() / 3.0).sqrt()
}

impl Noise {
    /// Noise models at `values` (the base calibration) with bias random walks
    /// `walks` per axis \[raw units/√s\].
    pub fn new(data: &AuditData, values: &Values, walks: Walks) -> Result<Noise, AuditError> {
        let a = *values.get::<AccelParams>(KEY_ACCEL).map_err(|e| e.to_string())?;
        let g = *values.get::<GyroMatrix>(KEY_GYRO).map_err(|e| e.to_string())?;
        let base = Layout { effects: Vec::new() };
        let floor = |c: DMatrix<f64>| {
            let n = c.nrows();
            let scale = (0..n).map(|i| c[(i, i)]).fold(0.0, f64::max).max(1e-300);
            NoiseModel::from_covariance(&(c + DMatrix::identity(n, n) * scale * 1e-12)).map_err(|e| e.to_string())
        };
        let statics = statics_factors(data, &base)?
            .iter()
            .zip(&data.statics)
            .map(|(f, s)| floor(f.noise_covariance(&a, &g, &data.var_accel, &data.var_gyro, s.samples)))
            .collect::<Result<_, _>>()?;
        let motions = motion_factors(data, &base)?
            .iter()
            .enumerate()
            .map(|(k, f)| {
                let b0 = values.get::<Vector3<f64>>(key_bias(k)).map_err(|e| e.to_string())?;
                let b1 = values.get::<Vector3<f64>>(key_bias(k + 1)).map_err(|e| e.to_string())?;
                let c = f.noise_covariance(&a, &g, &(0.5 * (b0 + b1)), &data.var_accel, &data.var_gyro);
                floor(DMatrix::from_iterator(2, 2, c.iter().copied()))
            })
            .collect::<Result<_, _>>()?;
        let walk_dt =
            data.statics.windows(2).map(|w| (w[1].context.time - w[0].context.time).abs().max(1e-3)).collect();
        Ok(Noise { statics, motions, walk_dt, walks })
    }

    /// The same noise with other bias random walks \[raw units/√s\].
    pub fn with_walks(&self, walks: Walks) -> Noise {
        Noise { walks, ..self.clone() }
    }

    /// Standard deviation of the bias change over the gap after static interval `k` with walk `rw`.
    fn walk_sigma(&self, rw: f64, k: usize) -> f64 {
        (rw * self.walk_dt[k].sqrt()).max(1e-12)
    }
}

fn base_keys(k: usize) -> Vec<Key> {
    vec![KEY_ACCEL, KEY_GYRO, key_bias(k), key_wander(k)]
}

fn effect_keys(layout: &Layout) -> impl Iterator<Item = Key> + '_ {
    (0..layout.effects.len()).map(key_effect)
}

fn statics_factors(data: &AuditData, layout: &Layout) -> Result<Vec<StaticFactor>, AuditError> {
    data.statics
        .iter()
        .enumerate()
        .map(|(k, s)| {
            let keys = base_keys(k).into_iter().chain(effect_keys(layout)).collect();
            StaticFactor::new(keys, layout.clone(), s.raw_accel, s.raw_gyro, s.context, data.gravity)
                .map_err(|e| AuditError(format!("static interval {k}: {e}")))
        })
        .collect()
}

fn motion_factors(data: &AuditData, layout: &Layout) -> Result<Vec<MotionFactor>, AuditError> {
    data.motions
        .iter()
        .enumerate()
        .map(|(k, m)| {
            let keys = [KEY_ACCEL, KEY_GYRO, key_bias(k), key_bias(k + 1), key_wander(k), key_wander(k + 1)]
                .into_iter()
                .chain(effect_keys(layout))
                .collect();
            let (s0, s1) = (&data.statics[k], &data.statics[k + 1]);
            MotionFactor::new(
                keys,
                layout.clone(),
                m.clone(),
                [s0.raw_accel, s1.raw_accel],
                [s0.context, s1.context],
                [s0.samples, s1.samples],
            )
            .map_err(|e| AuditError(format!("motion {k}: {e}")))
        })
        .collect()
}

/// A solved model.
#[derive(Clone, Debug)]
pub struct Fit {
    /// The effects switched on.
    pub layout: Layout,
    /// The solution.
    pub values: Values,
    /// χ² (sum of squared whitened residuals) per group of [`GROUPS`].
    pub chi2_groups: [f64; 5],
    /// Residual count per group.
    pub dims: [usize; 5],
    /// Free parameters.
    pub parameters: usize,
    /// Per-parameter standard deviation of each effect (from the marginal covariance, scaled by max(1, χ²/dof)).
    pub effect_std: Vec<Vec<f64>>,
    /// Wald statistic `θᵀ C⁻¹ θ` of each effect's parameters θ with their
    /// marginal covariance C (not inflated): what the χ² drop on adding the
    /// effect would be if the model were linear in it around the solution.
    pub effect_wald: Vec<f64>,
    /// Bias random walks the fit was whitened with \[raw units/√s\].
    pub walks: Walks,
}

impl Fit {
    /// Total χ².
    pub fn chi2(&self) -> f64 {
        self.chi2_groups.iter().sum()
    }
    /// Residuals.
    pub fn residuals(&self) -> usize {
        self.dims.iter().sum()
    }
    /// Measurements: the static and motion residuals (the walk residuals are
    /// priors on the biases, not data) — BIC's `n`.
    pub fn measurements(&self) -> usize {
        self.dims[..3].iter().sum()
    }
    /// Degrees of freedom (residuals − parameters, ≥ 1).
    pub fn dof(&self) -> usize {
        self.residuals().saturating_sub(self.parameters).max(1)
    }
    /// Probability of a χ² at least this large if the noise explained everything (χ²(dof)).
    pub fn p_value(&self) -> f64 {
        use statrs::distribution::{ChiSquared, ContinuousCDF};
        ChiSquared::new(self.dof() as f64).map(|c| c.sf(self.chi2())).unwrap_or(1.0)
    }
    /// The gap: χ²/dof − 1, floored at 0.
    pub fn gap(&self) -> f64 {
        (self.chi2() / self.dof() as f64 - 1.0).max(0.0)
    }
    /// Values of effect `j`.
    pub fn effect(&self, j: usize) -> Vec<f64> {
        self.values.get_dyn(key_effect(j)).map(|v| v.params_dyn()).unwrap_or_default()
    }
}

/// The audit's solves stop at a relative decrease to come of 10⁻¹²: it
/// compares χ² between models that differ by one effect (differences of a few
/// units on costs of 10⁴–10⁶), so each cost must be resolved far below 1.
const AUDIT_FUNCTION_TOLERANCE: f64 = 1e-12;

/// The audit's iteration cap: its solves start from the calibration's
/// minimum and converge in a few iterations; one that needs more is a model
/// the data do not support, and is reported as such rather than waited for.
const AUDIT_MAX_ITERATIONS: usize = 60;

/// Solve with the effects of `layout`, starting from `start` (missing effect
/// values start at zero).
pub fn solve(data: &AuditData, noise: &Noise, layout: &Layout, start: &Values) -> Result<Fit, AuditError> {
    let mut values = start.clone();
    for (j, e) in layout.effects.iter().enumerate() {
        if !values.contains(key_effect(j)) {
            values.insert_dyn(key_effect(j), Box::new(DynVector::from_slice(&vec![0.0; e.dim()])));
        }
    }
    let graph = build(data, noise, layout)?;
    let lm = Optimizer::new(LmOptions {
        function_tolerance: AUDIT_FUNCTION_TOLERANCE,
        max_iterations: AUDIT_MAX_ITERATIONS,
        ..LmOptions::default()
    });
    let (values, _) = lm.optimize(&graph, &values).map_err(|e| e.to_string())?;
    // χ² per group, in the order the factors were added.
    let n = [data.statics.len(), data.motions.len(), data.motions.len(), data.motions.len()];
    let mut chi2_groups = [0.0; 5];
    let mut dims = [0usize; 5];
    for (i, entry) in graph.entries().iter().enumerate() {
        let w = whitened_entry(entry, &values)?;
        if i < n[0] {
            chi2_groups[0] += w[0] * w[0];
            chi2_groups[1] += w.rows(1, 3).norm_squared();
            dims[0] += 1;
            dims[1] += 3;
        } else {
            let g = if i < n[0] + n[1] {
                2
            } else if i < n[0] + n[1] + n[2] {
                3
            } else {
                4
            };
            chi2_groups[g] += w.norm_squared();
            dims[g] += w.len();
        }
    }
    let parameters = values
        .keys()
        .filter(|k| !values.is_constant(*k))
        .map(|k| values.get_dyn(k).map(|v| v.dim()).unwrap_or(0))
        .sum();
    let mut fit = Fit {
        layout: layout.clone(),
        values,
        chi2_groups,
        dims,
        parameters,
        effect_std: Vec::new(),
        effect_wald: Vec::new(),
        walks: noise.walks,
    };
    let inflation = (fit.chi2() / fit.dof() as f64).max(1.0);
    let keys: Vec<Key> = (0..layout.effects.len()).map(key_effect).collect();
    if !keys.is_empty() {
        let cov = covariances(&graph, &fit.values, &keys).map_err(|e| e.to_string())?;
        fit.effect_std = keys
            .iter()
            .map(|k| {
                cov.get(*k)
                    .map(|c| (0..c.nrows()).map(|i| (c[(i, i)] * inflation).max(0.0).sqrt()).collect())
                    .unwrap_or_default()
            })
            .collect();
        fit.effect_wald = keys
            .iter()
            .enumerate()
            .map(|(j, k)| {
                let theta = nalgebra::DVector::from_vec(fit.effect(j));
                cov.get(*k)
                    .and_then(|c| c.clone().pseudo_inverse(1e-300).ok())
                    .map(|ci| (theta.transpose() * ci * &theta)[(0, 0)])
                    .unwrap_or(f64::INFINITY)
            })
            .collect();
    }
    Ok(fit)
}

/// Smallest bias random walks an estimate may take \[physical units/√s\]: gyro
/// 10⁻⁷ rad/s²/√Hz and accelerometer 10⁻⁶ m/s³/√Hz, below navigation-grade
/// sensors, so a recording that shows no walk keeps a finite weight.
pub const MIN_RANDOM_WALK: (f64, f64) = (1e-7, 1e-6);

/// Iterations of the walk estimate at most.
const WALK_ITERATIONS: usize = 60;

/// [`solve`], estimating the bias random walks of every axis from the
/// recording with the model of `layout` (when `estimate`; otherwise `noise`'s
/// are kept): variance-component estimation (Helmert/Förstner, which
/// converges to REML) alternates a solve with `σ² ← σ² · χ²_axis / r_axis`,
/// `r_axis` the redundancy of that axis's walk residuals (their count minus
/// the trace of their part of the hat matrix), so the walk is what the bias
/// changes left by this model imply; every three iterates an Aitken Δ² step
/// extrapolates the slow, linear convergence. It stops when no walk moves by
/// 1 %. `floor` is the smallest walk \[raw units/√s\] (gyro,
/// accelerometer).
pub fn solve_walks(
    data: &AuditData,
    noise: &Noise,
    layout: &Layout,
    start: &Values,
    estimate: bool,
    floor: (f64, f64),
) -> Result<(Fit, Noise), AuditError> {
    let mut noise = noise.clone();
    let mut fit = solve(data, &noise, layout, start)?;
    if !estimate {
        return Ok((fit, noise));
    }
    // The last plain iterates of ln w per axis (gyro x y z, accel x y z), for
    // Aitken's Δ² step. The iteration converges linearly, at a rate near 1
    // where the data say little about a walk: steps of 1 % can then be far
    // from the limit, which three iterates extrapolate to.
    let mut history: Vec<[f64; 6]> = Vec::new();
    for _ in 0..WALK_ITERATIONS {
        let WalkComponents { chi2, redundancy: r, .. } = walk_components(data, &noise, &fit, false)?;
        let mut change: f64 = 0.0;
        let mut update = |w: &mut [f64; 3], chi2: &[f64; 3], r: &[f64; 3], lo: f64| {
            for a in 0..3 {
                // An axis whose walk residuals carry less than one independent residual: nothing to estimate from.
                if r[a] >= 0.5 {
                    let new = (w[a] * (chi2[a] / r[a]).sqrt()).max(lo);
                    change = change.max((new / w[a]).ln().abs());
                    w[a] = new;
                }
            }
        };
        let mut walks = noise.walks;
        update(&mut walks.0, &chi2.0, &r.0, floor.0);
        update(&mut walks.1, &chi2.1, &r.1, floor.1);
        if change >= 0.01 {
            history.push(log_walks(&walks));
            if history.len() == 3 {
                walks = aitken(&history, walks, floor);
                history.clear();
            }
        }
        noise = noise.with_walks(walks);
        fit = solve(data, &noise, layout, &fit.values)?;
        if change < 0.01 {
            break;
        }
    }
    Ok((fit, noise))
}

/// ln w per axis: gyro x, y, z, accelerometer x, y, z.
fn log_walks(w: &Walks) -> [f64; 6] {
    [w.0[0].ln(), w.0[1].ln(), w.0[2].ln(), w.1[0].ln(), w.1[1].ln(), w.1[2].ln()]
}

/// Aitken's Δ² extrapolation of three consecutive iterates `h` of ln w per
/// axis (`x* = x₂ − (x₂ − x₁)² / (x₂ − 2x₁ + x₀)`) where they converge
/// monotonically (two steps of one sign, the second shorter); the jump is at
/// most a factor 10 and the walk not below `floor`; other axes keep `walks`.
fn aitken(h: &[[f64; 6]], walks: Walks, floor: (f64, f64)) -> Walks {
    let mut out = walks;
    let slots = out.0.iter_mut().map(|w| (w, floor.0)).chain(out.1.iter_mut().map(|w| (w, floor.1)));
    for (i, (w, lo)) in slots.enumerate() {
        let (d1, d2) = (h[1][i] - h[0][i], h[2][i] - h[1][i]);
        if d1 * d2 <= 0.0 || d2.abs() >= d1.abs() {
            continue;
        }
        let jump = (-d2 * d2 / (d2 - d1)).clamp(-10f64.ln(), 10f64.ln());
        *w = (h[2][i] + jump).exp().max(lo);
    }
    out
}

/// Degrees of freedom the walk estimate rests on per axis at `fit` (gyro
/// x y z, accelerometer x y z): `ν = tr(R²)` of that axis's block of the
/// residual projector `R = I − H` of the walk residuals (`H` the hat matrix),
/// twice the Fisher information of `ln σ²`, so the walk's variance is
/// uncertain by `√(2/ν)` as from `ν` independent residuals. It is at most
/// the redundancy `tr(R)` the estimate iterates on, and well below it where
/// each residual carries a fraction of one.
pub fn walk_degrees_of_freedom(data: &AuditData, noise: &Noise, fit: &Fit) -> Result<Walks, AuditError> {
    walk_components(data, noise, fit, true).map(|c| c.information)
}

/// Per axis at `fit`: the χ² of the gyro and accelerometer walk residuals,
/// their redundancy `tr(R)` and `tr(R²)` (see [`walk_degrees_of_freedom`]).
struct WalkComponents {
    chi2: Walks,
    redundancy: Walks,
    information: Walks,
}

/// [`WalkComponents`] at `fit` (`tr(R²)` only `with_information`: it takes
/// every pair of intervals). For the between factors of biases `k`, `k+1`
/// and `l`, `l+1` of one axis, with `Σ` the biases' joint covariance and
/// `σ_k` the walk over gap `k`, `H_kl = (Σ_k+1,l+1 − Σ_k+1,l − Σ_k,l+1 +
/// Σ_k,l)_aa / (σ_k σ_l)`, `tr(R) = Σ_k (1 − H_kk)` and `tr(R²) = Σ_k (1 −
/// H_kk)² + Σ_k≠l H_kl²`.
fn walk_components(
    data: &AuditData,
    noise: &Noise,
    fit: &Fit,
    with_information: bool,
) -> Result<WalkComponents, AuditError> {
    let graph = build(data, noise, &fit.layout)?;
    let n = data.statics.len();
    let free = |k: &Key| !fit.values.is_constant(*k);
    let keys: Vec<Key> = (0..n).map(key_bias).chain((0..n).map(key_wander)).filter(free).collect();
    let cov = covariances(&graph, &fit.values, &keys).map_err(|e| e.to_string())?;
    let entry = |x: Key, y: Key, a: usize| -> f64 {
        if free(&x) && free(&y) {
            cov.block(x, y).map(|m| m[(a, a)]).unwrap_or(0.0)
        } else {
            0.0
        }
    };
    let value = |k: Key| fit.values.get::<Vector3<f64>>(k).copied().unwrap_or_else(|_| Vector3::zeros());
    let group = |key: fn(usize) -> Key, rw: &[f64; 3]| {
        let (mut chi2, mut r, mut info) = ([0.0; 3], [0.0; 3], [0.0; 3]);
        for a in 0..3 {
            let s: Vec<f64> = (0..n - 1).map(|k| noise.walk_sigma(rw[a], k)).collect();
            let h = |k: usize, l: usize| {
                (entry(key(k + 1), key(l + 1), a) - entry(key(k + 1), key(l), a) - entry(key(k), key(l + 1), a)
                    + entry(key(k), key(l), a))
                    / (s[k] * s[l])
            };
            for (k, sk) in s.iter().enumerate() {
                let d = value(key(k + 1))[a] - value(key(k))[a];
                chi2[a] += d * d / (sk * sk);
                let rkk = 1.0 - h(k, k);
                r[a] += rkk;
                info[a] += rkk * rkk;
                if with_information {
                    info[a] += (0..n - 1).filter(|&l| l != k).map(|l| h(k, l).powi(2)).sum::<f64>();
                }
            }
        }
        (chi2, r, info)
    };
    let (cg, rg, ig) = group(key_bias, &noise.walks.0);
    let (ca, ra, ia) = group(key_wander, &noise.walks.1);
    Ok(WalkComponents { chi2: (cg, ca), redundancy: (rg, ra), information: (ig, ia) })
}

/// The restricted deviance of the walks at `fit`: `−2 ln` of the likelihood
/// with every parameter integrated out under a flat prior (REML, exact for a
/// model linear around `fit`): `χ² + ln det H + Σ ln σ²` over the walk
/// factors, `H` the Gauss–Newton information of the free parameters. Constant
/// terms (the data's noise, 2π) are left out: only differences between walks
/// on one recording mean anything.
pub fn restricted_deviance(data: &AuditData, noise: &Noise, fit: &Fit) -> Result<f64, AuditError> {
    let graph = build(data, noise, &fit.layout)?;
    let (chi2, log_det) = information_log_det(&graph, &fit.values).map_err(|e| e.to_string())?;
    let walk_log_det: f64 = (0..noise.walk_dt.len())
        .flat_map(|k| (0..3).flat_map(move |a| [noise.walks.0[a], noise.walks.1[a]].map(|w| (k, w))))
        .map(|(k, w)| 2.0 * noise.walk_sigma(w, k).ln())
        .sum();
    Ok(chi2 + log_det + walk_log_det)
}

/// Marginal covariance of the calibration blocks (`M_a/b_a`, `M_g`, `b_g` of the first interval).
pub fn calibration_covariance(data: &AuditData, noise: &Noise, fit: &Fit) -> Result<[DMatrix<f64>; 3], AuditError> {
    let graph = build(data, noise, &fit.layout)?;
    let keys = [KEY_ACCEL, KEY_GYRO, key_bias(0)];
    let cov = covariances(&graph, &fit.values, &keys).map_err(|e| e.to_string())?;
    let inflation = (fit.chi2() / fit.dof() as f64).max(1.0);
    let get = |k: Key| cov.get(k).map(|c| c * inflation).ok_or_else(|| format!("no covariance for {k:?}"));
    Ok([get(keys[0])?, get(keys[1])?, get(keys[2])?])
}

fn build(data: &AuditData, noise: &Noise, layout: &Layout) -> Result<Graph, AuditError> {
    let mut graph = Graph::new();
    for (f, n) in statics_factors(data, layout)?.into_iter().zip(&noise.statics) {
        graph.add(f, n.clone());
    }
    for (f, n) in motion_factors(data, layout)?.into_iter().zip(&noise.motions) {
        graph.add(f, n.clone());
    }
    let walk =
        |rw: &[f64; 3], k: usize| NoiseModel::diagonal(&rw.map(|w| noise.walk_sigma(w, k))).map_err(|e| e.to_string());
    for k in 0..noise.walk_dt.len() {
        graph.add(BetweenFactor::new(key_bias(k), key_bias(k + 1), Vector3::<f64>::zeros()), walk(&noise.walks.0, k)?);
    }
    for k in 0..noise.walk_dt.len() {
        graph.add(
            BetweenFactor::new(key_wander(k), key_wander(k + 1), Vector3::<f64>::zeros()),
            walk(&noise.walks.1, k)?,
        );
    }
    Ok(graph)
}

/// Starting values: the calibration's accelerometer and gyro parameters, every
/// interval's gyro bias at `gyro_bias`, no accelerometer wander (the first held
/// constant: it is the gauge of `b_a`).
pub fn start_values(data: &AuditData, accel: AccelParams, gyro: GyroMatrix, gyro_bias: Vector3<f64>) -> Values {
    let mut values = Values::new();
    values.insert(KEY_ACCEL, accel);
    values.insert(KEY_GYRO, gyro);
    for k in 0..data.statics.len() {
        values.insert(key_bias(k), gyro_bias);
        values.insert(key_wander(k), Vector3::<f64>::zeros());
    }
    values.set_constant(key_wander(0), true);
    values
}

/// Raw (unwhitened) residuals at `values` under `layout`: per static interval
/// `[‖a‖ − g, ω]` \[m/s², rad/s\] and per motion the 2 direction errors \[rad\].
pub type Residuals = (Vec<[f64; 4]>, Vec<[f64; 2]>);

/// See [`Residuals`].
pub fn residuals(data: &AuditData, layout: &Layout, values: &Values) -> Result<Residuals, AuditError> {
    fn eval<F: tumble_solvers::Factor>(f: &F, values: &Values) -> Result<Vec<f64>, AuditError> {
        let vars: Vec<&dyn tumble_solvers::DynVariable> =
            f.keys().iter().map(|k| values.get_dyn(*k)).collect::<Result<_, _>>().map_err(|e| e.to_string())?;
        Ok(f.residual(Vars::new(&vars)).map_err(|e| e.to_string())?.as_slice().to_vec())
    }
    let statics = statics_factors(data, layout)?
        .iter()
        .map(|f| eval(f, values).map(|r| [r[0], r[1], r[2], r[3]]))
        .collect::<Result<_, _>>()?;
    let motions = motion_factors(data, layout)?
        .iter()
        .map(|f| eval(f, values).map(|r| [r[0], r[1]]))
        .collect::<Result<_, _>>()?;
    Ok((statics, motions))
}

/// Whitened residuals of `fit` under `noise`: per static interval the 4 rows
/// `[‖a‖ − g, ω]`, per motion the 2 direction rows (unit variance when the
/// noise explains them).
pub fn whitened(data: &AuditData, noise: &Noise, fit: &Fit) -> Result<Residuals, AuditError> {
    let graph = build(data, noise, &fit.layout)?;
    let mut statics = Vec::with_capacity(data.statics.len());
    let mut motions = Vec::with_capacity(data.motions.len());
    for entry in graph.entries().iter().take(data.statics.len() + data.motions.len()) {
        let w = whitened_entry(entry, &fit.values)?;
        match w.len() {
            4 => statics.push([w[0], w[1], w[2], w[3]]),
            _ => motions.push([w[0], w[1]]),
        }
    }
    Ok((statics, motions))
}

/// The whitened residual of one graph entry at `values` (what [`solve`]'s χ²
/// groups and [`whitened`] read).
fn whitened_entry(entry: &tumble_solvers::FactorEntry, values: &Values) -> Result<nalgebra::DVector<f64>, AuditError> {
    let vars: Vec<&dyn tumble_solvers::DynVariable> =
        entry.factor.keys().iter().map(|k| values.get_dyn(*k)).collect::<Result<_, _>>().map_err(|e| e.to_string())?;
    Ok(entry.evaluate(Vars::new(&vars)).map_err(|e| e.to_string())?.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A geometric approach `ln w = L + c ρⁿ` is extrapolated to its limit L;
    /// an axis that turns back, or one whose steps grow, is left alone; the
    /// floor holds.
    #[test]
    fn aitken_jumps_to_the_limit_of_a_geometric_approach() {
        let (limit, c, rho) = (-12.0f64, 1.5f64, 0.9f64);
        let x = |n: i32| limit + c * rho.powi(n);
        let mut h = [[0.0; 6]; 3];
        for (n, row) in h.iter_mut().enumerate() {
            let n = n as i32;
            *row = [x(n), x(n), 1.0 + [0.0, 0.1, 0.05][n as usize], x(n), -5.0 - [0.0, 0.1, 0.3][n as usize], x(n)];
        }
        let walks = ([x(2).exp(), x(2).exp(), 7.0], [x(2).exp(), 9.0, x(2).exp()]);
        let out = aitken(&h, walks, (1e-300, (limit + 0.5).exp()));
        assert!((out.0[0].ln() - limit).abs() < 1e-9, "{}", out.0[0].ln());
        assert_eq!(out.0[2], 7.0, "a step that turns back");
        assert_eq!(out.1[1], 9.0, "steps that grow");
        assert_eq!(out.1[0], (limit + 0.5).exp(), "the floor");
    }
}
