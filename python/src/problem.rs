//! `tumble.Problem`: a least-squares problem whose residuals are Python
//! functions, solved by tumble's sparse Levenberg–Marquardt.
//!
//! Variables are numpy arrays: `euclidean` a vector, `so3` a 3×3 rotation
//! matrix, `se3` a 4×4 and `se2` a 3×3 homogeneous transform. A residual
//! function takes one array per variable and returns the residual (1-D), or
//! `(residual, [J_1, …])` with each `J_k` the derivative with respect to
//! variable k's tangent: `x ⊞ δ = x + δ` (euclidean), `R Exp(δ)` (so3),
//! `T Exp(δ)` with δ = [ω, ν] (se3) or [θ, ν] (se2). Without Jacobians they
//! come from central differences on the manifold.

use crate::{tumble_error, TumbleError};
use nalgebra::{DMatrix, DVector, Matrix3, Vector3};
use numpy::{PyArray1, PyArray2, PyArrayMethods, PyReadonlyArray1};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};
use std::collections::HashMap;
use tumble_solvers::lie::so3_log;
use tumble_solvers::sophus_lie::{Isometry3F64, Rotation3F64};
use tumble_solvers::{
    covariances, numeric_linearize, DynVariable, DynVector, Factor, FactorError, Graph, Key, Linearization, LmOptions,
    NoiseModel, Optimizer, Values, Vars,
};

/// What a variable is, and so how it goes to and from numpy.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Kind {
    Euclidean,
    So3,
    Se3,
    Se2,
}

impl Kind {
    fn parse(s: &str) -> PyResult<Kind> {
        match s {
            "euclidean" => Ok(Kind::Euclidean),
            "so3" => Ok(Kind::So3),
            "se3" => Ok(Kind::Se3),
            "se2" => Ok(Kind::Se2),
            _ => Err(TumbleError::new_err(format!("kind must be euclidean, so3, se3 or se2, got `{s}`"))),
        }
    }

    /// The variable from a numpy value (a vector, or a matrix of the group).
    fn variable(self, value: &Bound<'_, PyAny>) -> PyResult<Box<dyn DynVariable>> {
        let flat = flat_f64(value).map_err(|_| TumbleError::new_err("a variable's value must be a number array"))?;
        if flat.iter().any(|v| !v.is_finite()) {
            return Err(TumbleError::new_err("a variable's value must be finite"));
        }
        let need = |n: usize, what: &str| -> PyResult<()> {
            if flat.len() == n {
                Ok(())
            } else {
                Err(TumbleError::new_err(format!("a {what} needs {n} numbers, got {}", flat.len())))
            }
        };
        let rotation = |m: &[f64]| Rotation3F64::exp(so3_log(&Matrix3::from_row_slice(m)));
        Ok(match self {
            Kind::Euclidean => Box::new(DynVector::from_slice(&flat)),
            Kind::So3 => {
                need(9, "so3 value (3×3 rotation matrix)")?;
                Box::new(rotation(&flat))
            }
            Kind::Se3 => {
                need(16, "se3 value (4×4 transform)")?;
                let r = [&flat[0..3], &flat[4..7], &flat[8..11]].concat();
                let t = Vector3::new(flat[3], flat[7], flat[11]);
                Box::new(Isometry3F64::from_rotation_and_translation(rotation(&r), t))
            }
            Kind::Se2 => {
                need(9, "se2 value (3×3 transform)")?;
                Box::new(tumble_solvers::se2(flat[2], flat[5], flat[3].atan2(flat[0])))
            }
        })
    }

    /// The numpy value of a variable.
    fn array<'py>(self, py: Python<'py>, v: &dyn DynVariable) -> PyResult<Bound<'py, PyAny>> {
        let p = v.params_dyn();
        let matrix = |rows: Vec<Vec<f64>>| -> PyResult<Bound<'py, PyAny>> {
            Ok(PyArray2::from_vec2(py, &rows).map_err(|e| TumbleError::new_err(e.to_string()))?.into_any())
        };
        match self {
            Kind::Euclidean => Ok(PyArray1::from_vec(py, p).into_any()),
            Kind::So3 => matrix(p.chunks(3).map(<[f64]>::to_vec).collect()),
            Kind::Se3 => matrix(vec![
                vec![p[0], p[1], p[2], p[9]],
                vec![p[3], p[4], p[5], p[10]],
                vec![p[6], p[7], p[8], p[11]],
                vec![0.0, 0.0, 0.0, 1.0],
            ]),
            Kind::Se2 => matrix(vec![vec![p[0], -p[1], p[2]], vec![p[1], p[0], p[3]], vec![0.0, 0.0, 1.0]]),
        }
    }
}

/// A residual and, when the function gives them, its Jacobians.
type Output = (DVector<f64>, Option<Vec<DMatrix<f64>>>);

/// A residual written in Python.
struct PyFactor {
    keys: Vec<Key>,
    kinds: Vec<Kind>,
    dim: usize,
    func: Py<PyAny>,
    /// The function returns `(residual, [jacobians])`.
    analytic: bool,
}

impl PyFactor {
    /// Call the function at `vars`: the residual, and the Jacobians when it gives them.
    fn call(&self, vars: Vars<'_>) -> Result<Output, FactorError> {
        Python::attach(|py| {
            let args: Vec<Bound<'_, PyAny>> = (0..vars.len())
                .map(|k| self.kinds[k].array(py, vars.get_dyn(k)))
                .collect::<PyResult<_>>()
                .map_err(|e| FactorError::Other(e.to_string()))?;
            let out = self
                .func
                .call1(py, PyTuple::new(py, args).map_err(|e| FactorError::Other(e.to_string()))?)
                .map_err(|e| FactorError::Other(format!("the residual function raised {e}")))?;
            parse_output(out.bind(py), self.analytic, &self.kinds, vars).map_err(|e| FactorError::Other(e.to_string()))
        })
    }
}

/// Any array-like as its float64 entries, flattened in row-major order
/// (a contiguous float64 array is read directly; anything else through
/// `numpy.asarray`).
fn flat_f64(a: &Bound<'_, PyAny>) -> PyResult<Vec<f64>> {
    // Copies without numpy's borrow tracking (the array is only read, here).
    if let Ok(v) = a.cast::<PyArray1<f64>>() {
        if let Ok(s) = v.to_vec() {
            return Ok(s);
        }
    }
    if let Ok(v) = a.cast::<PyArray2<f64>>() {
        if let Ok(s) = v.to_vec() {
            return Ok(s);
        }
    }
    static NUMPY: pyo3::sync::PyOnceLock<Py<PyModule>> = pyo3::sync::PyOnceLock::new();
    let np = NUMPY.get_or_try_init(a.py(), || a.py().import("numpy").map(Bound::unbind))?.bind(a.py());
    let arr = np.call_method1("asarray", (a, "float64"))?.call_method0("ravel")?;
    Ok(arr.extract::<PyReadonlyArray1<f64>>()?.as_array().to_vec())
}

/// A function's output: a vector, or `(vector, [matrices])` when `analytic`.
fn parse_output(out: &Bound<'_, PyAny>, analytic: bool, kinds: &[Kind], vars: Vars<'_>) -> PyResult<Output> {
    let vector = flat_f64;
    if !analytic {
        return Ok((DVector::from_vec(vector(out)?), None));
    }
    let (r, js): (Bound<'_, PyAny>, Bound<'_, PyAny>) = out.extract()?;
    let r = DVector::from_vec(vector(&r)?);
    let js: Vec<Bound<'_, PyAny>> = js.extract()?;
    if js.len() != kinds.len() {
        return Err(TumbleError::new_err(format!("{} Jacobians for {} variables", js.len(), kinds.len())));
    }
    let mut mats = Vec::with_capacity(js.len());
    for (k, j) in js.iter().enumerate() {
        let d = vars.get_dyn(k).dim();
        let flat = vector(j)?;
        if flat.len() != r.len() * d {
            let shape: Vec<usize> = j.getattr("shape").and_then(|s| s.extract()).unwrap_or_else(|_| vec![flat.len()]);
            return Err(TumbleError::new_err(format!(
                "Jacobian {k} has shape {shape:?}, expected ({}, {d}) (residual × tangent dimension)",
                r.len()
            )));
        }
        mats.push(DMatrix::from_row_slice(r.len(), d, &flat));
    }
    Ok((r, Some(mats)))
}

impl Factor for PyFactor {
    fn keys(&self) -> &[Key] {
        &self.keys
    }
    fn residual_dim(&self) -> usize {
        self.dim
    }
    fn residual(&self, vars: Vars<'_>) -> Result<DVector<f64>, FactorError> {
        self.call(vars).map(|(r, _)| r)
    }
    fn linearize(&self, vars: Vars<'_>) -> Result<Linearization, FactorError> {
        if !self.analytic {
            return numeric_linearize(self, vars);
        }
        let (residual, jacobians) = self.call(vars)?;
        Ok(Linearization { residual, jacobians: jacobians.unwrap_or_default() })
    }
}

/// Huber's loss with threshold `k` (in whitened residual units).
#[pyclass(module = "tumble")]
#[derive(Clone)]
pub struct Huber {
    #[pyo3(get)]
    k: f64,
}

#[pymethods]
impl Huber {
    #[new]
    fn new(k: f64) -> PyResult<Huber> {
        positive(k, "Huber's k").map(|k| Huber { k })
    }
}

/// Cauchy's loss with scale `k` (in whitened residual units).
#[pyclass(module = "tumble")]
#[derive(Clone)]
pub struct Cauchy {
    #[pyo3(get)]
    k: f64,
}

#[pymethods]
impl Cauchy {
    #[new]
    fn new(k: f64) -> PyResult<Cauchy> {
        positive(k, "Cauchy's k").map(|k| Cauchy { k })
    }
}

fn positive(k: f64, what: &str) -> PyResult<f64> {
    if k.is_finite() && k > 0.0 {
        Ok(k)
    } else {
        Err(TumbleError::new_err(format!("{what} must be a positive number, got {k}")))
    }
}

/// A least-squares problem with residuals written in Python.
#[pyclass(module = "tumble", unsendable)]
#[derive(Default)]
pub struct Problem {
    values: Values,
    graph: Graph,
    names: HashMap<String, (Key, Kind)>,
    order: Vec<String>,
}

#[pymethods]
impl Problem {
    #[new]
    fn new() -> Problem {
        Problem::default()
    }

    /// Add variable `name` with initial `value` of `kind`.
    #[pyo3(signature = (name, value, *, kind = "euclidean"))]
    fn add_variable(&mut self, name: String, value: &Bound<'_, PyAny>, kind: &str) -> PyResult<()> {
        if self.names.contains_key(&name) {
            return Err(TumbleError::new_err(format!("variable `{name}` was added before")));
        }
        let kind = Kind::parse(kind)?;
        let key = Key::new('v', self.order.len() as u64);
        self.values.insert_dyn(key, kind.variable(value)?);
        self.names.insert(name.clone(), (key, kind));
        self.order.push(name);
        Ok(())
    }

    /// Add the residual `fn(*values of names)`, optionally under a robust loss.
    #[pyo3(signature = (func, names, *, loss = None))]
    fn add_residual(
        &mut self,
        py: Python<'_>,
        func: Py<PyAny>,
        names: Vec<String>,
        loss: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<()> {
        let (keys, kinds): (Vec<Key>, Vec<Kind>) = names
            .iter()
            .map(|n| self.names.get(n).copied().ok_or_else(|| TumbleError::new_err(format!("no variable `{n}`"))))
            .collect::<PyResult<Vec<_>>>()?
            .into_iter()
            .unzip();
        // One call at the initial values gives the residual's size and form.
        let args: Vec<Bound<'_, PyAny>> = keys
            .iter()
            .zip(&kinds)
            .map(|(k, kind)| kind.array(py, self.values.get_dyn(*k).map_err(tumble_error)?))
            .collect::<PyResult<_>>()?;
        let out = func.call1(py, PyTuple::new(py, args)?)?;
        let analytic = out.bind(py).is_instance_of::<PyTuple>() && out.bind(py).len()? == 2;
        let vars: Vec<&dyn DynVariable> =
            keys.iter().map(|k| self.values.get_dyn(*k)).collect::<Result<_, _>>().map_err(tumble_error)?;
        let (r, _) = parse_output(out.bind(py), analytic, &kinds, Vars::new(&vars))?;
        let factor = PyFactor { keys, kinds, dim: r.len(), func, analytic };
        match loss {
            None => self.graph.add(factor, NoiseModel::Unit),
            Some(l) => {
                if let Ok(h) = l.extract::<Huber>() {
                    self.graph.add_robust(factor, NoiseModel::Unit, tumble_solvers::Huber(h.k))
                } else if let Ok(c) = l.extract::<Cauchy>() {
                    self.graph.add_robust(factor, NoiseModel::Unit, tumble_solvers::Cauchy(c.k))
                } else {
                    return Err(TumbleError::new_err("loss must be tumble.Huber(k) or tumble.Cauchy(k)"));
                }
            }
        };
        Ok(())
    }

    /// Hold variable `name` at its value.
    fn set_constant(&mut self, name: &str) -> PyResult<()> {
        let (key, _) = self.names.get(name).ok_or_else(|| TumbleError::new_err(format!("no variable `{name}`")))?;
        self.values.set_constant(*key, true);
        Ok(())
    }

    /// Solve; keywords are `LmOptions` fields (`max_iterations`,
    /// `function_tolerance`, `gradient_tolerance`, `parameter_tolerance`).
    #[pyo3(signature = (**options))]
    fn solve(&self, py: Python<'_>, options: Option<&Bound<'_, PyDict>>) -> PyResult<Solution> {
        let lm = lm_options(options)?;
        lm.validate().map_err(tumble_error)?;
        if self.graph.is_empty() {
            return Err(TumbleError::new_err("the problem has no residuals"));
        }
        let (graph, values) = (&self.graph, &self.values);
        // One thread: every residual holds the interpreter, so workers would
        // only take turns at it (and pay for the hand-overs).
        let pool =
            rayon::ThreadPoolBuilder::new().num_threads(1).build().map_err(|e| TumbleError::new_err(e.to_string()))?;
        let (solved, summary) =
            py.detach(|| pool.install(|| Optimizer::new(lm).optimize(graph, values))).map_err(tumble_error)?;
        let free: Vec<Key> = self.order.iter().map(|n| self.names[n].0).filter(|k| !solved.is_constant(*k)).collect();
        let cov = py.detach(|| covariances(graph, &solved, &free)).ok();
        let out = PyDict::new(py);
        let mut cov_of = HashMap::new();
        for name in &self.order {
            let (key, kind) = self.names[name];
            out.set_item(name, kind.array(py, solved.get_dyn(key).map_err(tumble_error)?)?)?;
            if let Some(c) = cov.as_ref().and_then(|c| c.get(key)) {
                let rows: Vec<Vec<f64>> = c.row_iter().map(|r| r.iter().copied().collect()).collect();
                cov_of.insert(name.clone(), rows);
            }
        }
        Ok(Solution {
            values: out.unbind(),
            final_cost: summary.final_cost,
            initial_cost: summary.initial_cost,
            iterations: summary.iterations,
            termination: format!("{:?}", summary.termination),
            converged: summary.converged(),
            covariances: cov_of,
        })
    }
}

/// The optimizer's options from Python keywords.
fn lm_options(options: Option<&Bound<'_, PyDict>>) -> PyResult<LmOptions> {
    let mut lm = LmOptions::default();
    for (k, v) in options.into_iter().flat_map(|d| d.iter()) {
        let key: String = k.extract()?;
        match key.as_str() {
            "max_iterations" => lm.max_iterations = v.extract()?,
            "function_tolerance" => lm.function_tolerance = v.extract()?,
            "gradient_tolerance" => lm.gradient_tolerance = v.extract()?,
            "parameter_tolerance" => lm.parameter_tolerance = v.extract()?,
            _ => {
                return Err(TumbleError::new_err(format!(
                "unknown option `{key}` (max_iterations, function_tolerance, gradient_tolerance, parameter_tolerance)"
            )))
            }
        }
    }
    Ok(lm)
}

/// What `Problem.solve` found.
#[pyclass(module = "tumble")]
pub struct Solution {
    /// Each variable's value, by name.
    #[pyo3(get)]
    values: Py<PyDict>,
    /// ½ Σ ρ(‖r‖²) at the end.
    #[pyo3(get)]
    final_cost: f64,
    /// ½ Σ ρ(‖r‖²) at the start.
    #[pyo3(get)]
    initial_cost: f64,
    /// Iterations (linearizations after the first).
    #[pyo3(get)]
    iterations: usize,
    /// Why the solve ended (`FunctionTolerance`, `Stalled`, …).
    #[pyo3(get)]
    termination: String,
    /// Whether it ended at a minimum.
    #[pyo3(get)]
    converged: bool,
    covariances: HashMap<String, Vec<Vec<f64>>>,
}

#[pymethods]
impl Solution {
    /// The marginal covariance of variable `name` in its tangent space
    /// (the residuals taken as unit-variance).
    fn covariance<'py>(&self, py: Python<'py>, name: &str) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let rows = self.covariances.get(name).ok_or_else(|| {
            TumbleError::new_err(format!("no covariance for `{name}` (unknown, held constant, or not determined)"))
        })?;
        PyArray2::from_vec2(py, rows).map_err(|e| TumbleError::new_err(e.to_string()))
    }

    fn __repr__(&self) -> String {
        format!(
            "Solution(final_cost={:.6e}, iterations={}, termination={})",
            self.final_cost, self.iterations, self.termination
        )
    }
}
