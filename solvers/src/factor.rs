//! The [`Factor`] trait: one term of the cost, with its Jacobians.
//!
//! A factor maps the variables named by its keys to a raw residual. The graph
//! attaches a [`crate::NoiseModel`] (whitening) and optionally a
//! [`crate::RobustLoss`]. Jacobians come from one of three sources:
//! - analytic: override [`Factor::linearize`];
//! - automatic: write the residual generically and wrap it in [`crate::AutoDiff`];
//! - numeric: keep the default [`Factor::linearize`], central differences on the manifold.

use crate::error::FactorError;
use crate::key::Key;
use crate::variable::{DynVariable, Variable};
use nalgebra::{DMatrix, DVector};

/// Read-only view of the variables a factor acts on, in the order of its keys.
#[derive(Clone, Copy)]
pub struct Vars<'a> {
    vars: &'a [&'a dyn DynVariable],
}

impl<'a> Vars<'a> {
    /// Wrap a slice of variables.
    pub fn new(vars: &'a [&'a dyn DynVariable]) -> Self {
        Vars { vars }
    }
    /// The `i`-th variable as type `V`.
    pub fn get<V: Variable>(&self, i: usize) -> Result<&'a V, FactorError> {
        let v = self.vars.get(i).ok_or_else(|| FactorError::Other(format!("factor has no variable {i}")))?;
        v.as_any().downcast_ref::<V>().ok_or(FactorError::WrongVariableType {
            index: i,
            expected: std::any::type_name::<V>(),
            got: v.type_name(),
        })
    }
    /// The `i`-th variable, untyped.
    pub fn get_dyn(&self, i: usize) -> &'a dyn DynVariable {
        self.vars[i]
    }
    /// Number of variables.
    pub fn len(&self) -> usize {
        self.vars.len()
    }
    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.vars.is_empty()
    }
}

/// Residual and one Jacobian block per key (rows = residual dimension,
/// columns = tangent dimension of that key's variable), both unwhitened.
#[derive(Clone, Debug)]
pub struct Linearization {
    /// Raw residual.
    pub residual: DVector<f64>,
    /// ∂residual/∂δ_k for each key k, with x_k ⊞ δ_k.
    pub jacobians: Vec<DMatrix<f64>>,
}

impl Default for Linearization {
    fn default() -> Self {
        Linearization { residual: DVector::zeros(0), jacobians: Vec::new() }
    }
}

impl Linearization {
    /// Give the residual `rows` entries and the Jacobians `rows × cols[k]`
    /// shapes, reusing the buffers when they already have them (contents are
    /// then left as they were: the caller overwrites them).
    pub fn reshape<I>(&mut self, rows: usize, cols: I)
    where
        I: IntoIterator<Item = usize>,
        I::IntoIter: ExactSizeIterator,
    {
        let cols = cols.into_iter();
        if self.residual.len() != rows {
            self.residual = DVector::zeros(rows);
        }
        self.jacobians.resize_with(cols.len(), || DMatrix::zeros(0, 0));
        for (j, c) in self.jacobians.iter_mut().zip(cols) {
            if j.shape() != (rows, c) {
                *j = DMatrix::zeros(rows, c);
            }
        }
    }
}

/// One term of a nonlinear least-squares cost.
pub trait Factor: Send + Sync {
    /// Keys of the variables this factor depends on (no duplicates).
    fn keys(&self) -> &[Key];
    /// Dimension of the residual.
    fn residual_dim(&self) -> usize;
    /// Raw (unwhitened) residual at the given variables.
    fn residual(&self, vars: Vars<'_>) -> Result<DVector<f64>, FactorError>;
    /// Residual and Jacobians. The default uses central differences on the manifold.
    fn linearize(&self, vars: Vars<'_>) -> Result<Linearization, FactorError> {
        numeric_linearize(self, vars)
    }
    /// As [`Factor::linearize`], into `out`, whose buffers hold an earlier
    /// linearization of this factor: a factor evaluated many times per solve
    /// can overwrite them ([`Linearization::reshape`]) instead of allocating.
    /// The default calls [`Factor::linearize`].
    fn linearize_into(&self, vars: Vars<'_>, out: &mut Linearization) -> Result<(), FactorError> {
        *out = self.linearize(vars)?;
        Ok(())
    }
    /// Whether the Jacobians [`Factor::linearize`] returns never change (a
    /// linear factor, or a prior whose Jacobians are held at its linearization
    /// point). The optimizer then forms this factor's JᵀJ once per solve
    /// instead of every iteration (unless a robust loss reweights it).
    fn constant_jacobians(&self) -> bool {
        false
    }
}

/// Step of the central differences used by [`numeric_linearize`].
pub const NUMERIC_STEP: f64 = 1e-6;

/// Central-difference Jacobians on the manifold: column j of block k is
/// `(r(x_k ⊞ h e_j) − r(x_k ⊞ −h e_j)) / 2h`.
pub fn numeric_linearize<F: Factor + ?Sized>(f: &F, vars: Vars<'_>) -> Result<Linearization, FactorError> {
    let residual = f.residual(vars)?;
    let m = residual.len();
    let mut jacobians = Vec::with_capacity(vars.len());
    let base: Vec<&dyn DynVariable> = (0..vars.len()).map(|i| vars.get_dyn(i)).collect();
    for k in 0..vars.len() {
        let d = base[k].dim();
        let mut j = DMatrix::zeros(m, d);
        let mut delta = vec![0.0; d];
        for c in 0..d {
            delta[c] = NUMERIC_STEP;
            let plus = base[k].retract_dyn(&delta);
            delta[c] = -NUMERIC_STEP;
            let minus = base[k].retract_dyn(&delta);
            delta[c] = 0.0;
            let mut v = base.clone();
            v[k] = plus.as_ref();
            let rp = f.residual(Vars::new(&v))?;
            v[k] = minus.as_ref();
            let rm = f.residual(Vars::new(&v))?;
            j.set_column(c, &((rp - rm) / (2.0 * NUMERIC_STEP)));
        }
        jacobians.push(j);
    }
    Ok(Linearization { residual, jacobians })
}

/// Result of [`check_jacobians`]: how far a factor's Jacobians are from numeric ones.
#[derive(Clone, Debug)]
pub struct JacobianCheck {
    /// Per key: max absolute difference, and that difference relative to
    /// max(1, largest entry of the numeric block).
    pub blocks: Vec<(f64, f64)>,
    /// Index (in the factor's key list) of the worst block.
    pub worst_block: usize,
    /// Worst relative error over all blocks.
    pub max_relative_error: f64,
    /// Difference between `residual()` and the residual `linearize()` returned.
    pub residual_mismatch: f64,
}

impl JacobianCheck {
    /// Whether every block agrees within `tol` (relative).
    pub fn passes(&self, tol: f64) -> bool {
        self.max_relative_error <= tol && self.residual_mismatch <= tol
    }
}

/// Compare a factor's [`Factor::linearize`] with central differences.
///
/// ```
/// use tumble_solvers::{check_jacobians, Factor, Vars, Linearization, FactorError, Key, X};
/// use nalgebra::{DMatrix, DVector, Vector2};
/// struct Square(Vec<Key>);
/// impl Factor for Square {
///     fn keys(&self) -> &[Key] { &self.0 }
///     fn residual_dim(&self) -> usize { 1 }
///     fn residual(&self, v: Vars<'_>) -> Result<DVector<f64>, FactorError> {
///         let x: &Vector2<f64> = v.get(0)?;
///         Ok(DVector::from_element(1, x[0] * x[1]))
///     }
///     fn linearize(&self, v: Vars<'_>) -> Result<Linearization, FactorError> {
///         let x: &Vector2<f64> = v.get(0)?;
///         Ok(Linearization { residual: self.residual(v)?,
///             jacobians: vec![DMatrix::from_row_slice(1, 2, &[x[1], x[0]])] })
///     }
/// }
/// let x = Vector2::new(2.0, 3.0);
/// let report = check_jacobians(&Square(vec![X(0)]), &[&x]).unwrap();
/// assert!(report.passes(1e-6));
/// ```
pub fn check_jacobians<F: Factor + ?Sized>(f: &F, vars: &[&dyn DynVariable]) -> Result<JacobianCheck, FactorError> {
    let v = Vars::new(vars);
    let analytic = f.linearize(v)?;
    let numeric = numeric_linearize(f, v)?;
    let mut blocks = Vec::new();
    let (mut worst_block, mut worst) = (0, 0.0);
    for (k, (a, n)) in analytic.jacobians.iter().zip(&numeric.jacobians).enumerate() {
        if a.shape() != n.shape() {
            return Err(FactorError::Other(format!("Jacobian block {k} is {:?}, expected {:?}", a.shape(), n.shape())));
        }
        let abs = (a - n).amax();
        let rel = abs / n.amax().max(1.0);
        if rel > worst {
            worst = rel;
            worst_block = k;
        }
        blocks.push((abs, rel));
    }
    if analytic.jacobians.len() != vars.len() {
        return Err(FactorError::Other(format!(
            "{} Jacobian blocks for {} variables",
            analytic.jacobians.len(),
            vars.len()
        )));
    }
    let residual_mismatch = (&analytic.residual - &numeric.residual).amax() / numeric.residual.amax().max(1.0);
    Ok(JacobianCheck { blocks, worst_block, max_relative_error: worst, residual_mismatch })
}
