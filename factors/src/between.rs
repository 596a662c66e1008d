//! Relative measurement between two variables.

use nalgebra::DVector;
use tumble_solvers::{Factor, FactorError, Key, LieGroup, Linearization, Vars};

/// Between factor `r = Log(Z⁻¹ · X₁⁻¹ · X₂)` for a measured relative
/// transform `Z` of `X₂` in the frame of `X₁` (GTSAM's `BetweenFactor`).
///
/// ```
/// use tumble_factors::{BetweenFactor, PriorFactor};
/// use tumble_solvers::{Graph, NoiseModel, Optimizer, LmOptions, Values, X, se2};
/// let mut g = Graph::new();
/// let n = NoiseModel::isotropic(3, 0.1).unwrap();
/// g.add(PriorFactor::new(X(0), se2(0.0, 0.0, 0.0)), n.clone());
/// g.add(BetweenFactor::new(X(0), X(1), se2(1.0, 0.0, 0.5)), n);
/// let mut v = Values::new();
/// v.insert(X(0), se2(0.1, -0.1, 0.1));
/// v.insert(X(1), se2(0.0, 0.0, 0.0));
/// let (_, s) = Optimizer::new(LmOptions::default()).optimize(&g, &v).unwrap();
/// assert!(s.final_cost < 1e-12);
/// ```
#[derive(Clone, Debug)]
pub struct BetweenFactor<G: LieGroup> {
    keys: [Key; 2],
    measured_inv: G,
}

impl<G: LieGroup> BetweenFactor<G> {
    /// Measurement `measured` of `X₁⁻¹ X₂`.
    pub fn new(k1: Key, k2: Key, measured: G) -> Self {
        BetweenFactor { keys: [k1, k2], measured_inv: measured.inverse_elem() }
    }
    /// The measured relative transform.
    pub fn measured(&self) -> G {
        self.measured_inv.inverse_elem()
    }
}

impl<G: LieGroup> Factor for BetweenFactor<G> {
    fn keys(&self) -> &[Key] {
        &self.keys
    }
    fn residual_dim(&self) -> usize {
        G::DIM
    }
    fn residual(&self, vars: Vars<'_>) -> Result<DVector<f64>, FactorError> {
        let x1: &G = vars.get(0)?;
        let x2: &G = vars.get(1)?;
        Ok(self.measured_inv.compose(&x1.inverse_elem().compose(x2)).log_vec())
    }
    fn linearize(&self, vars: Vars<'_>) -> Result<Linearization, FactorError> {
        let x1: &G = vars.get(0)?;
        let x2: &G = vars.get(1)?;
        let x12 = x1.inverse_elem().compose(x2);
        let r = self.measured_inv.compose(&x12).log_vec();
        let jinv = G::right_jacobian_inv(&r);
        let mut j1 = &jinv * x12.inverse_elem().adjoint_mat();
        j1.neg_mut();
        Ok(Linearization { residual: r, jacobians: vec![j1, jinv] })
    }
}
