//! The factor graph: factors with their noise models and robust losses.

use crate::error::{FactorError, SolveError};
use crate::factor::{Factor, Linearization, Vars};
use crate::key::Key;
use crate::loss::{apply_robust, RobustLoss};
use crate::noise::NoiseModel;
use crate::values::Values;
use crate::variable::DynVariable;
use std::sync::Arc;

/// A factor as stored in a graph: the factor, its noise model and an optional robust loss.
pub struct FactorEntry {
    /// The factor.
    pub factor: Box<dyn Factor>,
    /// Whitening of its residual.
    pub noise: NoiseModel,
    /// Robust loss on the squared whitened residual norm, if any.
    pub loss: Option<Arc<dyn RobustLoss>>,
}

/// A whitened, robust-corrected linearization of one factor.
#[derive(Clone, Debug, Default)]
pub(crate) struct WhitenedLinearization {
    pub lin: Linearization,
    /// ρ(s) (or s without a loss): twice this factor's cost.
    pub rho: f64,
}

impl FactorEntry {
    /// Whitened residual and ρ(‖r‖²) at `vars`.
    pub fn evaluate(&self, vars: Vars<'_>) -> Result<(nalgebra::DVector<f64>, f64), FactorError> {
        let mut r = self.factor.residual(vars)?;
        self.noise.whiten(&mut r);
        let s = r.norm_squared();
        if !s.is_finite() {
            return Err(FactorError::NonFinite);
        }
        let rho = self.loss.as_ref().map_or(s, |l| l.evaluate(s)[0]);
        Ok((r, rho))
    }

    pub(crate) fn linearize_whitened(&self, vars: Vars<'_>) -> Result<WhitenedLinearization, FactorError> {
        let mut out = WhitenedLinearization::default();
        self.linearize_whitened_into(vars, &mut out)?;
        Ok(out)
    }

    /// [`FactorEntry::linearize_whitened`] into `out`, reusing its buffers.
    pub(crate) fn linearize_whitened_into(
        &self,
        vars: Vars<'_>,
        out: &mut WhitenedLinearization,
    ) -> Result<(), FactorError> {
        let lin = &mut out.lin;
        self.factor.linearize_into(vars, lin)?;
        self.noise.whiten(&mut lin.residual);
        for j in lin.jacobians.iter_mut() {
            self.noise.whiten_jacobian(j);
        }
        // Over plain slices (nalgebra's matrix iterators do not vectorize).
        let finite = |s: &[f64]| s.iter().all(|v| v.is_finite());
        if !finite(lin.residual.as_slice()) || !lin.jacobians.iter().all(|j| finite(j.as_slice())) {
            return Err(FactorError::NonFinite);
        }
        out.rho = match &self.loss {
            None => lin.residual.norm_squared(),
            Some(l) => apply_robust(l.as_ref(), &mut lin.residual, &mut lin.jacobians),
        };
        Ok(())
    }
}

/// A nonlinear factor graph.
///
/// ```
/// use tumble_solvers::{Graph, Values, NoiseModel, Optimizer, LmOptions, X};
/// use tumble_solvers::testing::LinearFactor;
/// use nalgebra::{DMatrix, DVector, Vector2};
/// let mut graph = Graph::new();
/// // r = x − (1, 2)
/// graph.add(LinearFactor::new(vec![X(0)], vec![DMatrix::identity(2, 2)], DVector::from_vec(vec![-1.0, -2.0])),
///           NoiseModel::isotropic(2, 0.1).unwrap());
/// let mut values = Values::new();
/// values.insert(X(0), Vector2::new(0.0, 0.0));
/// let (solution, summary) = Optimizer::new(LmOptions::default()).optimize(&graph, &values).unwrap();
/// let x: &Vector2<f64> = solution.get(X(0)).unwrap();
/// assert!((x - Vector2::new(1.0, 2.0)).norm() < 1e-9);
/// assert!(summary.final_cost < 1e-12);
/// ```
#[derive(Default)]
pub struct Graph {
    entries: Vec<FactorEntry>,
}

impl Graph {
    /// Empty graph.
    pub fn new() -> Self {
        Self::default()
    }
    /// Add a factor with a noise model; returns its index.
    pub fn add<F: Factor + 'static>(&mut self, factor: F, noise: NoiseModel) -> usize {
        self.add_entry(FactorEntry { factor: Box::new(factor), noise, loss: None })
    }
    /// Add a factor with a noise model and a robust loss; returns its index.
    pub fn add_robust<F: Factor + 'static, L: RobustLoss + 'static>(
        &mut self,
        factor: F,
        noise: NoiseModel,
        loss: L,
    ) -> usize {
        self.add_entry(FactorEntry { factor: Box::new(factor), noise, loss: Some(Arc::new(loss)) })
    }
    /// Add a prepared entry; returns its index.
    pub fn add_entry(&mut self, entry: FactorEntry) -> usize {
        self.entries.push(entry);
        self.entries.len() - 1
    }
    /// Number of factors.
    pub fn len(&self) -> usize {
        self.entries.len()
    }
    /// Whether the graph has no factor.
    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }
    /// All entries in insertion order.
    pub fn entries(&self) -> &[FactorEntry] {
        &self.entries
    }
    /// Remove the factors at `indices` (any order) and return them in ascending index order.
    pub fn remove(&mut self, indices: &[usize]) -> Vec<FactorEntry> {
        let mut idx: Vec<usize> = indices.to_vec();
        idx.sort_unstable();
        idx.dedup();
        let mut out = Vec::with_capacity(idx.len());
        for &i in idx.iter().rev() {
            if i < self.entries.len() {
                out.push(self.entries.remove(i));
            }
        }
        out.reverse();
        out
    }
    /// Indices of the factors that involve `key`.
    pub fn factors_of(&self, key: Key) -> Vec<usize> {
        (0..self.entries.len()).filter(|&i| self.entries[i].factor.keys().contains(&key)).collect()
    }

    /// Cost ½ Σ ρ(‖W r‖²) at `values` (GTSAM's "error", Ceres' "cost").
    pub fn cost(&self, values: &Values) -> Result<f64, SolveError> {
        Ok(0.5 * self.per_factor(values, |e, v| e.evaluate(v).map(|x| x.1))?.iter().sum::<f64>())
    }

    /// χ² = Σ ‖W r‖², the sum of squared whitened residuals, ignoring robust losses.
    pub fn chi2(&self, values: &Values) -> Result<f64, SolveError> {
        Ok(self.per_factor(values, |e, v| e.evaluate(v).map(|x| x.0.norm_squared()))?.iter().sum())
    }

    fn per_factor(
        &self,
        values: &Values,
        f: impl Fn(&FactorEntry, Vars<'_>) -> Result<f64, FactorError>,
    ) -> Result<Vec<f64>, SolveError> {
        let mut out = Vec::with_capacity(self.entries.len());
        for (i, e) in self.entries.iter().enumerate() {
            let vars: Vec<&dyn DynVariable> = e
                .factor
                .keys()
                .iter()
                .map(|&k| values.get_dyn(k).map_err(|_| SolveError::MissingVariable { factor: i, key: k }))
                .collect::<Result<_, _>>()?;
            out.push(f(e, Vars::new(&vars)).map_err(|source| SolveError::Factor { factor: i, source })?);
        }
        Ok(out)
    }
}
