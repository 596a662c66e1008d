//! Test support for users of the solver: a linear factor, and a check
//! battery for a user's own [`Variable`] type ([`check_variable`]).

use crate::error::FactorError;
use crate::factor::{Factor, Linearization, Vars};
use crate::key::Key;
use crate::variable::Variable;
use nalgebra::{DMatrix, DVector};

/// A linear factor `r = Σ_k A_k x_k + b` on vector-space variables
/// (any `SVector<f64, N>`; uses the variables' ambient parameters).
#[derive(Clone, Debug)]
pub struct LinearFactor {
    keys: Vec<Key>,
    a: Vec<DMatrix<f64>>,
    b: DVector<f64>,
}

impl LinearFactor {
    /// `r = Σ A_k x_k + b`.
    pub fn new(keys: Vec<Key>, a: Vec<DMatrix<f64>>, b: DVector<f64>) -> Self {
        LinearFactor { keys, a, b }
    }
}

impl Factor for LinearFactor {
    fn keys(&self) -> &[Key] {
        &self.keys
    }
    fn residual_dim(&self) -> usize {
        self.b.len()
    }
    fn residual(&self, vars: Vars<'_>) -> Result<DVector<f64>, FactorError> {
        let mut r = self.b.clone();
        for (i, a) in self.a.iter().enumerate() {
            let p = DVector::from_vec(vars.get_dyn(i).params_dyn());
            if p.len() != a.ncols() {
                return Err(FactorError::Other(format!(
                    "variable {i} has {} parameters, A has {} columns",
                    p.len(),
                    a.ncols()
                )));
            }
            r += a * p;
        }
        Ok(r)
    }
    fn linearize(&self, vars: Vars<'_>) -> Result<Linearization, FactorError> {
        Ok(Linearization { residual: self.residual(vars)?, jacobians: self.a.clone() })
    }
    fn constant_jacobians(&self) -> bool {
        true
    }
}

/// What [`check_variable`] found wrong with a [`Variable`] implementation.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("variable check `{check}` failed: {detail}")]
pub struct VariableCheckError {
    /// Which invariant: `dimension`, `identity`, `local-of-self`, `round-trip`, `retract-of-local` or `params-jacobian`.
    pub check: &'static str,
    /// The numbers that broke it.
    pub detail: String,
}

/// Check a [`Variable`] implementation at `x` against the manifold
/// invariants Ceres asks of a `Manifold` (its `manifold_test_utils`), for
/// each tangent step in `deltas` (each `V::DIM` long, small, e.g. 1e-3):
///
/// - `local(x, x)` has `DIM` entries, all zero (within `tol`);
/// - `retract(x, 0) = x` (identity: `local(x, retract(x, 0)) ≈ 0`);
/// - `local(x, retract(x, δ)) ≈ δ` (round trip);
/// - `retract(x, local(x, y)) ≈ y` for `y = retract(x, δ)`;
/// - [`Variable::params_jacobian`] equals central differences of `params(x ⊞ δ)`.
///
/// ```
/// use tumble_solvers::sophus_lie::Isometry3F64;
/// use tumble_solvers::testing::check_variable;
/// let x = Isometry3F64::identity();
/// check_variable(&x, &[vec![1e-3, -2e-3, 5e-4, 0.1, 0.2, -0.3]], 1e-9).unwrap();
/// ```
pub fn check_variable<V: Variable>(x: &V, deltas: &[Vec<f64>], tol: f64) -> Result<(), VariableCheckError> {
    let fail = |check, detail: String| Err(VariableCheckError { check, detail });
    let max_abs = |v: &[f64]| v.iter().fold(0.0f64, |m, a| m.max(a.abs()));
    let zero = x.local(x);
    if zero.len() != V::DIM {
        return fail("dimension", format!("local(x, x) has {} entries, DIM is {}", zero.len(), V::DIM));
    }
    if max_abs(&zero) > tol {
        return fail("local-of-self", format!("local(x, x) = {zero:?}"));
    }
    let same = x.local(&x.retract(&vec![0.0; V::DIM]));
    if max_abs(&same) > tol {
        return fail("identity", format!("local(x, retract(x, 0)) = {same:?}"));
    }
    for d in deltas {
        if d.len() != V::DIM {
            return fail("dimension", format!("a test step has {} entries, DIM is {}", d.len(), V::DIM));
        }
        let y = x.retract(d);
        let back = x.local(&y);
        let err: Vec<f64> = back.iter().zip(d).map(|(a, b)| a - b).collect();
        if max_abs(&err) > tol * (1.0 + max_abs(d)) {
            return fail("round-trip", format!("local(x, retract(x, {d:?})) = {back:?}"));
        }
        let again = x.retract(&back);
        let gap = y.local(&again);
        if max_abs(&gap) > tol * (1.0 + max_abs(d)) {
            return fail("retract-of-local", format!("retract(x, local(x, y)) is {gap:?} from y"));
        }
    }
    let analytic = x.params_jacobian();
    let p0 = x.params();
    if analytic.shape() != (p0.len(), V::DIM) {
        return fail("params-jacobian", format!("shape {:?}, expected {:?}", analytic.shape(), (p0.len(), V::DIM)));
    }
    let numeric = crate::variable::numeric_params_jacobian(x);
    for ((r, c), n) in numeric.iter().enumerate().map(|(i, n)| ((i % p0.len(), i / p0.len()), *n)) {
        if (n - analytic[(r, c)]).abs() > 1e-6 * (1.0 + n.abs()) {
            return fail("params-jacobian", format!("entry ({r}, {c}): {} analytic vs {n} numeric", analytic[(r, c)]));
        }
    }
    Ok(())
}
