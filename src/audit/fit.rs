//! The audit's joint problem: calibration + per-interval biases (random walks)
//! + the effects switched on, as one factor graph on the solver.

use super::data::AuditData;
use super::AuditError;
use nalgebra::{DMatrix, Vector3};
use tumble_factors::imu_calib::{AccelParams, GyroMatrix};
use tumble_factors::imu_effects::{Layout, MotionFactor, StaticFactor};
use tumble_factors::BetweenFactor;
use tumble_solvers::{covariances, DynVector, Graph, Key, LmOptions, NoiseModel, Optimizer, Values, Vars};

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
pub struct Noise {
    statics: Vec<NoiseModel>,
    motions: Vec<NoiseModel>,
    gyro_walk: Vec<NoiseModel>,
    accel_walk: Vec<NoiseModel>,
}

impl Noise {
    /// Noise models at `values` (the base calibration) with bias random walks
    /// `gyro_rw`, `accel_rw` \[raw units/√s\].
    pub fn new(data: &AuditData, values: &Values, gyro_rw: f64, accel_rw: f64) -> Result<Noise, AuditError> {
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
        let walk = |rw: f64| -> Result<Vec<NoiseModel>, String> {
            data.statics
                .windows(2)
                .map(|w| {
                    let dt = (w[1].context.time - w[0].context.time).abs().max(1e-3);
                    NoiseModel::isotropic(3, (rw * dt.sqrt()).max(1e-12)).map_err(|e| e.to_string())
                })
                .collect()
        };
        Ok(Noise { statics, motions, gyro_walk: walk(gyro_rw)?, accel_walk: walk(accel_rw)? })
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
    /// Degrees of freedom (residuals − parameters, ≥ 1).
    pub fn dof(&self) -> usize {
        self.residuals().saturating_sub(self.parameters).max(1)
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
    let lm = Optimizer::new(LmOptions { function_tolerance: 1e-12, max_iterations: 60, ..LmOptions::default() });
    let (values, _) = lm.optimize(&graph, &values).map_err(|e| e.to_string())?;
    // χ² per group, in the order the factors were added.
    let n = [data.statics.len(), data.motions.len(), data.motions.len(), data.motions.len()];
    let mut chi2_groups = [0.0; 5];
    let mut dims = [0usize; 5];
    for (i, entry) in graph.entries().iter().enumerate() {
        let vars: Vec<&dyn tumble_solvers::DynVariable> = entry
            .factor
            .keys()
            .iter()
            .map(|k| values.get_dyn(*k))
            .collect::<Result<_, _>>()
            .map_err(|e| e.to_string())?;
        let (w, _) = entry.evaluate(Vars::new(&vars)).map_err(|e| e.to_string())?;
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
    let mut fit = Fit { layout: layout.clone(), values, chi2_groups, dims, parameters, effect_std: Vec::new() };
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
    }
    Ok(fit)
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
    for (k, n) in noise.gyro_walk.iter().enumerate() {
        graph.add(BetweenFactor::new(key_bias(k), key_bias(k + 1), Vector3::<f64>::zeros()), n.clone());
    }
    for (k, n) in noise.accel_walk.iter().enumerate() {
        graph.add(BetweenFactor::new(key_wander(k), key_wander(k + 1), Vector3::<f64>::zeros()), n.clone());
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
