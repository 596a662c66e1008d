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
        let mut out = Linearization::default();
        self.linearize_into(vars, &mut out)?;
        Ok(out)
    }
    /// `J₂ = Jr⁻¹(r)`, `J₁ = −Jr⁻¹(r) Ad(X₁₂⁻¹)`, into reused buffers: no
    /// allocation for groups of up to 6 dimensions.
    fn linearize_into(&self, vars: Vars<'_>, out: &mut Linearization) -> Result<(), FactorError> {
        const MAX: usize = 6;
        let x1: &G = vars.get(0)?;
        let x2: &G = vars.get(1)?;
        let d = G::DIM;
        out.reshape(d, [d, d]);
        let x12 = x1.inverse_elem().compose(x2);
        self.measured_inv.compose(&x12).log_into(out.residual.as_mut_slice());
        let [j1, j2] = &mut out.jacobians[..] else { unreachable!("reshaped to two blocks") };
        G::right_jacobian_inv_into(out.residual.as_slice(), j2.as_mut_slice());
        let (mut adj_small, mut adj_big) = ([0.0; MAX * MAX], Vec::new());
        let adj: &mut [f64] = if d <= MAX {
            &mut adj_small[..d * d]
        } else {
            adj_big.resize(d * d, 0.0);
            &mut adj_big
        };
        x12.inverse_elem().adjoint_into(adj);
        let (jinv, j1) = (j2.as_slice(), j1.as_mut_slice());
        for c in 0..d {
            for r in 0..d {
                j1[r + c * d] = -(0..d).map(|k| jinv[r + k * d] * adj[k + c * d]).sum::<f64>();
            }
        }
        Ok(())
    }
}
