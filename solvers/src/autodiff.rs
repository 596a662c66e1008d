//! Forward-mode automatic differentiation for factors written generically
//! over the scalar, with dual numbers from the `num-dual` crate.
//!
//! Write an [`AutoDiffResidual`] whose `residual` is generic over [`Real`], wrap
//! it in [`AutoDiff`], and it is a [`Factor`] with exact Jacobians. Each variable
//! reaches the residual as its ambient parameters ([`crate::Variable::params`]):
//! R^n as its entries, SO(3) as the 9 entries of its rotation matrix (row-major),
//! SE(3) as those 9 followed by the translation, SE(2) as `[cos θ, sin θ, x, y]`.
//! `N` is the sum of the tangent dimensions of the factor's variables.
//!
//! ```
//! use tumble_solvers::{AutoDiff, AutoDiffResidual, Real, Key, X, check_jacobians};
//! use nalgebra::Vector2;
//! /// Rosenbrock as a two-residual factor on one R² variable.
//! struct Rosenbrock(Vec<Key>);
//! impl AutoDiffResidual<2> for Rosenbrock {
//!     fn keys(&self) -> &[Key] { &self.0 }
//!     fn residual_dim(&self) -> usize { 2 }
//!     fn residual<T: Real>(&self, p: &[&[T]]) -> Vec<T> {
//!         let (x, y) = (p[0][0], p[0][1]);
//!         vec![T::from(1.0) - x, (y - x * x) * 10.0]
//!     }
//! }
//! let f = AutoDiff::new(Rosenbrock(vec![X(0)]));
//! let x = Vector2::new(-1.2, 1.0);
//! assert!(check_jacobians(&f, &[&x]).unwrap().passes(1e-6));
//! ```

use crate::error::FactorError;
use crate::factor::{Factor, Linearization, Vars};
use crate::key::Key;
use nalgebra::{DMatrix, DVector, SVector};
use num_dual::{Derivative, DualNum, DualSVec64};

/// Scalar a generic residual is written over: `f64` or a dual number.
pub trait Real: DualNum<f64> + Copy + nalgebra::Scalar + Send + Sync {}
impl<T: DualNum<f64> + Copy + nalgebra::Scalar + Send + Sync> Real for T {}

/// A residual written generically over the scalar; see the module docs.
pub trait AutoDiffResidual<const N: usize>: Send + Sync {
    /// Keys of the variables.
    fn keys(&self) -> &[Key];
    /// Residual dimension.
    fn residual_dim(&self) -> usize;
    /// The residual, from each variable's ambient parameters.
    fn residual<T: Real>(&self, params: &[&[T]]) -> Vec<T>;
}

/// Adapter turning an [`AutoDiffResidual`] into a [`Factor`].
pub struct AutoDiff<R, const N: usize>(pub R);

impl<R: AutoDiffResidual<N>, const N: usize> AutoDiff<R, N> {
    /// Wrap a generic residual.
    pub fn new(r: R) -> Self {
        AutoDiff(r)
    }
}

fn finite(v: &DVector<f64>) -> Result<(), FactorError> {
    if v.iter().all(|x| x.is_finite()) {
        Ok(())
    } else {
        Err(FactorError::NonFinite)
    }
}

impl<R: AutoDiffResidual<N>, const N: usize> Factor for AutoDiff<R, N> {
    fn keys(&self) -> &[Key] {
        self.0.keys()
    }
    fn residual_dim(&self) -> usize {
        self.0.residual_dim()
    }
    fn residual(&self, vars: Vars<'_>) -> Result<DVector<f64>, FactorError> {
        let params: Vec<Vec<f64>> = (0..vars.len()).map(|i| vars.get_dyn(i).params_dyn()).collect();
        let refs: Vec<&[f64]> = params.iter().map(|p| p.as_slice()).collect();
        let r = DVector::from_vec(self.0.residual(&refs));
        finite(&r)?;
        Ok(r)
    }
    fn linearize(&self, vars: Vars<'_>) -> Result<Linearization, FactorError> {
        let total: usize = (0..vars.len()).map(|i| vars.get_dyn(i).dim()).sum();
        if total != N {
            return Err(FactorError::Other(format!(
                "AutoDiff<_, {N}> used with variables whose tangent dimensions sum to {total}"
            )));
        }
        let mut lifted: Vec<Vec<DualSVec64<N>>> = Vec::with_capacity(vars.len());
        let mut offset = 0;
        for i in 0..vars.len() {
            let v = vars.get_dyn(i);
            let p = v.params_dyn();
            let lv = if v.params_are_tangent() {
                p.iter()
                    .enumerate()
                    .map(|(row, &re)| {
                        let mut eps = SVector::<f64, N>::zeros();
                        eps[offset + row] = 1.0;
                        DualSVec64::<N>::new(re, Derivative::some(eps))
                    })
                    .collect()
            } else {
                let jp = v.params_jacobian_dyn();
                p.iter()
                    .enumerate()
                    .map(|(row, &re)| {
                        let mut eps = SVector::<f64, N>::zeros();
                        for c in 0..v.dim() {
                            eps[offset + c] = jp[(row, c)];
                        }
                        DualSVec64::<N>::new(re, Derivative::some(eps))
                    })
                    .collect()
            };
            lifted.push(lv);
            offset += v.dim();
        }
        let refs: Vec<&[DualSVec64<N>]> = lifted.iter().map(|p| p.as_slice()).collect();
        let out = self.0.residual(&refs);
        let m = out.len();
        let residual = DVector::from_iterator(m, out.iter().map(|d| d.re));
        finite(&residual)?;
        let mut full = DMatrix::zeros(m, N);
        for (r, d) in out.iter().enumerate() {
            let eps = d.eps.unwrap_generic(nalgebra::Const::<N>, nalgebra::Const::<1>);
            for c in 0..N {
                full[(r, c)] = eps[c];
            }
        }
        let mut jacobians = Vec::with_capacity(vars.len());
        let mut offset = 0;
        for i in 0..vars.len() {
            let d = vars.get_dyn(i).dim();
            jacobians.push(full.columns(offset, d).into_owned());
            offset += d;
        }
        if full.iter().any(|x| !x.is_finite()) {
            return Err(FactorError::NonFinite);
        }
        Ok(Linearization { residual, jacobians })
    }
}
