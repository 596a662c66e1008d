//! Prior on one variable.

use nalgebra::DVector;
use tumble_solvers::{Factor, FactorError, Key, LieGroup, Linearization, Vars};

/// Prior `r = prior ⊟ x = Log(prior⁻¹ x)` (tangent units of the variable;
/// for SE(3) `[ω rad, ν m]`).
///
/// ```
/// use tumble_factors::PriorFactor;
/// use tumble_solvers::{Graph, NoiseModel, Optimizer, LmOptions, Values, X};
/// use nalgebra::Vector3;
/// let mut g = Graph::new();
/// g.add(PriorFactor::new(X(0), Vector3::new(1.0, 2.0, 3.0)), NoiseModel::isotropic(3, 0.1).unwrap());
/// let mut v = Values::new();
/// v.insert(X(0), Vector3::zeros());
/// let (sol, _) = Optimizer::new(LmOptions::default()).optimize(&g, &v).unwrap();
/// assert!((sol.get::<Vector3<f64>>(X(0)).unwrap() - Vector3::new(1.0, 2.0, 3.0)).norm() < 1e-8);
/// ```
#[derive(Clone, Debug)]
pub struct PriorFactor<G: LieGroup> {
    keys: [Key; 1],
    prior: G,
}

impl<G: LieGroup> PriorFactor<G> {
    /// Prior on `key` at `prior`.
    pub fn new(key: Key, prior: G) -> Self {
        PriorFactor { keys: [key], prior }
    }
}

impl<G: LieGroup> Factor for PriorFactor<G> {
    fn keys(&self) -> &[Key] {
        &self.keys
    }
    fn residual_dim(&self) -> usize {
        G::DIM
    }
    fn residual(&self, vars: Vars<'_>) -> Result<DVector<f64>, FactorError> {
        let x: &G = vars.get(0)?;
        Ok(self.prior.inverse_elem().compose(x).log_vec())
    }
    fn linearize(&self, vars: Vars<'_>) -> Result<Linearization, FactorError> {
        let r = self.residual(vars)?;
        let j = G::right_jacobian_inv(&r);
        Ok(Linearization { residual: r, jacobians: vec![j] })
    }
}

/// Prior on some tangent components of one variable (GTSAM's
/// `PartialPriorFactor`): `r = [Log(prior⁻¹ x)]_indices`, in the tangent
/// units of the variable. Holds parameters the data does not determine at
/// their prior while the others are estimated.
///
/// ```
/// use tumble_factors::PartialPriorFactor;
/// use tumble_solvers::{Factor, DynVariable, Vars, X};
/// use nalgebra::Vector3;
/// let f = PartialPriorFactor::new(X(0), Vector3::new(0.0, 5.0, 0.0), vec![1]);
/// let x = Vector3::new(1.0, 2.0, 3.0);
/// let vars: [&dyn DynVariable; 1] = [&x];
/// assert_eq!(f.residual(Vars::new(&vars)).unwrap()[0], -3.0);
/// ```
#[derive(Clone, Debug)]
pub struct PartialPriorFactor<G: LieGroup> {
    keys: [Key; 1],
    prior: G,
    indices: Vec<usize>,
}

impl<G: LieGroup> PartialPriorFactor<G> {
    /// Prior on components `indices` (each `< G::DIM`) of `key`'s tangent at `prior`.
    pub fn new(key: Key, prior: G, indices: Vec<usize>) -> Self {
        PartialPriorFactor { keys: [key], prior, indices }
    }
}

impl<G: LieGroup> Factor for PartialPriorFactor<G> {
    fn keys(&self) -> &[Key] {
        &self.keys
    }
    fn residual_dim(&self) -> usize {
        self.indices.len()
    }
    fn residual(&self, vars: Vars<'_>) -> Result<DVector<f64>, FactorError> {
        let x: &G = vars.get(0)?;
        let full = self.prior.inverse_elem().compose(x).log_vec();
        Ok(DVector::from_iterator(self.indices.len(), self.indices.iter().map(|&i| full[i])))
    }
    fn linearize(&self, vars: Vars<'_>) -> Result<Linearization, FactorError> {
        let x: &G = vars.get(0)?;
        let full = self.prior.inverse_elem().compose(x).log_vec();
        let j = G::right_jacobian_inv(&full).select_rows(&self.indices);
        let r = DVector::from_iterator(self.indices.len(), self.indices.iter().map(|&i| full[i]));
        Ok(Linearization { residual: r, jacobians: vec![j] })
    }
}
