//! Small factors for tests, examples and documentation.

use crate::error::FactorError;
use crate::factor::{Factor, Linearization, Vars};
use crate::key::Key;
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
