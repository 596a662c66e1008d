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
use nalgebra::{DVector, SVector};
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
        let mut out = Linearization::default();
        self.linearize_into(vars, &mut out)?;
        Ok(out)
    }
    /// One evaluation over dual numbers, written into `out`'s buffers.
    fn linearize_into(&self, vars: Vars<'_>, out: &mut Linearization) -> Result<(), FactorError> {
        let dim = |i: usize| vars.get_dyn(i).dim();
        let total: usize = (0..vars.len()).map(dim).sum();
        if total != N {
            return Err(FactorError::Other(format!(
                "AutoDiff<_, {N}> used with variables whose tangent dimensions sum to {total}"
            )));
        }
        // Each variable's ambient parameters as dual numbers whose derivative
        // part is ∂params/∂δ: a unit vector when the parameters are the tangent
        // coordinates, else a row of the parameters' Jacobian.
        let mut lifted: Vec<DualSVec64<N>> = Vec::with_capacity(N);
        let mut ends = Vec::with_capacity(vars.len());
        let mut offset = 0;
        for i in 0..vars.len() {
            let v = vars.get_dyn(i);
            let jp = (!v.params_are_tangent()).then(|| v.params_jacobian_dyn());
            lifted.extend(v.params_dyn().iter().enumerate().map(|(row, &re)| {
                let mut eps = SVector::<f64, N>::zeros();
                match &jp {
                    None => eps[offset + row] = 1.0,
                    Some(jp) => (0..v.dim()).for_each(|c| eps[offset + c] = jp[(row, c)]),
                }
                DualSVec64::<N>::new(re, Derivative::some(eps))
            }));
            ends.push(lifted.len());
            offset += v.dim();
        }
        let refs: Vec<&[DualSVec64<N>]> =
            ends.iter().scan(0, |start, &end| Some(&lifted[std::mem::replace(start, end)..end])).collect();
        let res = self.0.residual(&refs);
        out.reshape(res.len(), (0..vars.len()).map(dim));
        for (r, x) in out.residual.iter_mut().zip(&res) {
            *r = x.re;
        }
        finite(&out.residual)?;
        let mut offset = 0;
        for j in out.jacobians.iter_mut() {
            for (r, x) in res.iter().enumerate() {
                let eps = x.eps.unwrap_generic(nalgebra::Const::<N>, nalgebra::Const::<1>);
                for c in 0..j.ncols() {
                    j[(r, c)] = eps[offset + c];
                }
            }
            offset += j.ncols();
            if j.iter().any(|x| !x.is_finite()) {
                return Err(FactorError::NonFinite);
            }
        }
        Ok(())
    }
}
