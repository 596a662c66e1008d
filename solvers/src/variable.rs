//! Variables on manifolds: the [`Variable`] trait and the built-in types.
//!
//! Every variable has a tangent space of fixed dimension `DIM`, a retraction
//! `x ⊞ δ` and local coordinates `x ⊟ y` (the δ with `x ⊞ δ = y`). The Lie groups
//! use right perturbations, `x ⊞ δ = x · Exp(δ)`.
//!
//! Built in:
//! - `nalgebra::SVector<f64, N>`: R^N, `x ⊞ δ = x + δ`.
//! - [`DynVector`]: R^n with `n` chosen at run time (e.g. a model whose
//!   parameter count depends on the terms switched on).
//! - [`Rotation3F64`] (SO(3), from sophus-rs): tangent ω \[rad\], body frame.
//! - [`Isometry3F64`] (SE(3), from sophus-rs): tangent `[ω, ν]`, rotation first.
//! - [`Isometry2F64`] (SE(2), from sophus-rs): tangent `[θ, νx, νy]`, rotation first.
//!
//! For automatic differentiation each variable also exposes an ambient
//! parameter vector ([`Variable::params`]) and its derivative with respect to
//! the tangent at zero ([`Variable::params_jacobian`]); see [`crate::autodiff`].

use nalgebra::{DMatrix, SVector, Vector3, Vector6};
use sophus_lie::prelude::*;
use sophus_lie::{Isometry2F64, Isometry3F64, Rotation2F64, Rotation3F64};
use std::any::Any;
use std::fmt::Debug;

/// A type that can be optimized: a point on a manifold of dimension `DIM`.
///
/// Implement it for your own types to use them in factor graphs. Only
/// `retract`, `local` and `params` are required; `params_jacobian` defaults to
/// central differences of `params(x ⊞ δ)`.
pub trait Variable: Clone + Debug + Send + Sync + 'static {
    /// Tangent-space dimension.
    const DIM: usize;
    /// Whether `params()` are the tangent coordinates themselves (vector
    /// spaces), so that `params_jacobian()` is the identity.
    const PARAMS_ARE_TANGENT: bool = false;
    /// Retraction `self ⊞ delta` (`delta.len() == DIM`).
    fn retract(&self, delta: &[f64]) -> Self;
    /// Local coordinates `self ⊟ other`: the `delta` with `self ⊞ delta = other`.
    fn local(&self, other: &Self) -> Vec<f64>;
    /// Ambient parameters handed to automatic-differentiation residuals.
    fn params(&self) -> Vec<f64>;
    /// Derivative of `params(self ⊞ δ)` with respect to δ at δ = 0
    /// (`params().len()` × `DIM`).
    fn params_jacobian(&self) -> DMatrix<f64> {
        numeric_params_jacobian(self)
    }
}

/// Central differences (step 1e-6) of `params(x ⊞ δ)` at δ = 0: the default
/// [`Variable::params_jacobian`], and what [`crate::testing::check_variable`]
/// compares an analytic one with.
pub fn numeric_params_jacobian<V: Variable>(x: &V) -> DMatrix<f64> {
    let p0 = x.params();
    let h = 1e-6;
    let mut j = DMatrix::zeros(p0.len(), V::DIM);
    let mut d = vec![0.0; V::DIM];
    for c in 0..V::DIM {
        d[c] = h;
        let pp = x.retract(&d).params();
        d[c] = -h;
        let pm = x.retract(&d).params();
        d[c] = 0.0;
        for r in 0..p0.len() {
            j[(r, c)] = (pp[r] - pm[r]) / (2.0 * h);
        }
    }
    j
}

/// Object-safe view of any [`Variable`], used by the value store and solver.
pub trait DynVariable: Any + Debug + Send + Sync {
    /// Tangent dimension.
    fn dim(&self) -> usize;
    /// `self ⊞ delta`, boxed.
    fn retract_dyn(&self, delta: &[f64]) -> Box<dyn DynVariable>;
    /// `self ⊞ delta` into `out`, reusing its box when it holds the same type
    /// (the default allocates a new one).
    fn retract_into(&self, delta: &[f64], out: &mut Box<dyn DynVariable>) {
        *out = self.retract_dyn(delta);
    }
    /// `self ⊟ other`; `None` if `other` has another type.
    fn local_dyn(&self, other: &dyn DynVariable) -> Option<Vec<f64>>;
    /// See [`Variable::params`].
    fn params_dyn(&self) -> Vec<f64>;
    /// See [`Variable::params_jacobian`].
    fn params_jacobian_dyn(&self) -> DMatrix<f64>;
    /// See [`Variable::PARAMS_ARE_TANGENT`].
    fn params_are_tangent(&self) -> bool;
    /// Boxed clone.
    fn clone_box(&self) -> Box<dyn DynVariable>;
    /// For downcasting.
    fn as_any(&self) -> &dyn Any;
    /// Rust type name, for error messages.
    fn type_name(&self) -> &'static str;
}

impl<V: Variable> DynVariable for V {
    fn dim(&self) -> usize {
        V::DIM
    }
    fn retract_dyn(&self, delta: &[f64]) -> Box<dyn DynVariable> {
        Box::new(self.retract(delta))
    }
    fn retract_into(&self, delta: &[f64], out: &mut Box<dyn DynVariable>) {
        // `&mut dyn DynVariable` → `&mut dyn Any`: trait upcasting (Rust 1.86).
        let any: &mut dyn Any = &mut **out;
        match any.downcast_mut::<V>() {
            Some(o) => *o = self.retract(delta),
            None => *out = self.retract_dyn(delta),
        }
    }
    fn local_dyn(&self, other: &dyn DynVariable) -> Option<Vec<f64>> {
        other.as_any().downcast_ref::<V>().map(|o| self.local(o))
    }
    fn params_dyn(&self) -> Vec<f64> {
        self.params()
    }
    fn params_jacobian_dyn(&self) -> DMatrix<f64> {
        self.params_jacobian()
    }
    fn params_are_tangent(&self) -> bool {
        V::PARAMS_ARE_TANGENT
    }
    fn clone_box(&self) -> Box<dyn DynVariable> {
        Box::new(self.clone())
    }
    fn as_any(&self) -> &dyn Any {
        self
    }
    fn type_name(&self) -> &'static str {
        std::any::type_name::<V>()
    }
}

impl Clone for Box<dyn DynVariable> {
    fn clone(&self) -> Self {
        self.clone_box()
    }
}

impl<const N: usize> Variable for SVector<f64, N> {
    const DIM: usize = N;
    const PARAMS_ARE_TANGENT: bool = true;
    fn retract(&self, delta: &[f64]) -> Self {
        self + SVector::<f64, N>::from_column_slice(delta)
    }
    fn local(&self, other: &Self) -> Vec<f64> {
        (other - self).as_slice().to_vec()
    }
    fn params(&self) -> Vec<f64> {
        self.as_slice().to_vec()
    }
    fn params_jacobian(&self) -> DMatrix<f64> {
        DMatrix::identity(N, N)
    }
}

/// R^n with the dimension chosen at run time, `x ⊞ δ = x + δ`. It implements
/// [`DynVariable`] directly (the [`Variable`] trait needs a compile-time `DIM`),
/// so it enters a value store with [`crate::Values::insert_dyn`].
///
/// ```
/// use tumble_solvers::{DynVector, Values, Key};
/// let mut values = Values::new();
/// values.insert_dyn(Key::new('e', 0), Box::new(DynVector::from_slice(&[0.1, 0.2, 0.3, 0.4])));
/// assert_eq!(values.get_dyn(Key::new('e', 0)).unwrap().dim(), 4);
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct DynVector(pub nalgebra::DVector<f64>);

impl DynVector {
    /// A vector with these entries.
    pub fn from_slice(x: &[f64]) -> Self {
        DynVector(nalgebra::DVector::from_column_slice(x))
    }
}

impl DynVariable for DynVector {
    fn dim(&self) -> usize {
        self.0.len()
    }
    fn retract_dyn(&self, delta: &[f64]) -> Box<dyn DynVariable> {
        Box::new(DynVector(&self.0 + nalgebra::DVector::from_column_slice(delta)))
    }
    fn retract_into(&self, delta: &[f64], out: &mut Box<dyn DynVariable>) {
        let any: &mut dyn Any = &mut **out;
        match any.downcast_mut::<DynVector>() {
            Some(o) if o.0.len() == self.0.len() => {
                for ((x, a), d) in o.0.iter_mut().zip(self.0.iter()).zip(delta) {
                    *x = a + d;
                }
            }
            _ => *out = self.retract_dyn(delta),
        }
    }
    fn local_dyn(&self, other: &dyn DynVariable) -> Option<Vec<f64>> {
        let o = other.as_any().downcast_ref::<DynVector>()?;
        (o.0.len() == self.0.len()).then(|| (&o.0 - &self.0).as_slice().to_vec())
    }
    fn params_dyn(&self) -> Vec<f64> {
        self.0.as_slice().to_vec()
    }
    fn params_jacobian_dyn(&self) -> DMatrix<f64> {
        DMatrix::identity(self.0.len(), self.0.len())
    }
    fn params_are_tangent(&self) -> bool {
        true
    }
    fn clone_box(&self) -> Box<dyn DynVariable> {
        Box::new(self.clone())
    }
    fn as_any(&self) -> &dyn Any {
        self
    }
    fn type_name(&self) -> &'static str {
        "DynVector"
    }
}

/// Row-major entries of a 3×3 matrix.
fn row_major(m: &nalgebra::Matrix3<f64>) -> [f64; 9] {
    let mut out = [0.0; 9];
    for r in 0..3 {
        for c in 0..3 {
            out[3 * r + c] = m[(r, c)];
        }
    }
    out
}

/// d vec_rowmajor(R·Exp(δ)) / dδ at 0: column i is R·\[e_i\]×.
fn rot_params_jacobian(r: &nalgebra::Matrix3<f64>) -> DMatrix<f64> {
    let mut j = DMatrix::zeros(9, 3);
    for i in 0..3 {
        let d = r * crate::lie::hat(&Vector3::ith(i, 1.0));
        for (k, v) in row_major(&d).iter().enumerate() {
            j[(k, i)] = *v;
        }
    }
    j
}

/// SO(3). Autodiff parameters: the rotation matrix, row-major (9 numbers).
impl Variable for Rotation3F64 {
    const DIM: usize = 3;
    fn retract(&self, delta: &[f64]) -> Self {
        self.group_mul(Rotation3F64::exp(Vector3::from_column_slice(delta)))
    }
    fn local(&self, other: &Self) -> Vec<f64> {
        self.inverse().group_mul(*other).log().as_slice().to_vec()
    }
    fn params(&self) -> Vec<f64> {
        row_major(&self.matrix()).to_vec()
    }
    fn params_jacobian(&self) -> DMatrix<f64> {
        rot_params_jacobian(&self.matrix())
    }
}

/// SE(3), tangent `[ω, ν]`. Autodiff parameters: rotation matrix row-major,
/// then translation (12 numbers).
impl Variable for Isometry3F64 {
    const DIM: usize = 6;
    fn retract(&self, delta: &[f64]) -> Self {
        self.group_mul(Isometry3F64::exp(Vector6::from_column_slice(delta)))
    }
    fn local(&self, other: &Self) -> Vec<f64> {
        self.inverse().group_mul(*other).log().as_slice().to_vec()
    }
    fn params(&self) -> Vec<f64> {
        let mut p = row_major(&self.rotation().matrix()).to_vec();
        p.extend_from_slice(self.translation().as_slice());
        p
    }
    fn params_jacobian(&self) -> DMatrix<f64> {
        let r = self.rotation().matrix();
        let mut j = DMatrix::zeros(12, 6);
        j.view_mut((0, 0), (9, 3)).copy_from(&rot_params_jacobian(&r));
        j.view_mut((9, 3), (3, 3)).copy_from(&r);
        j
    }
}

/// SE(2), tangent `[θ, νx, νy]`. Autodiff parameters: `[cos θ, sin θ, x, y]`.
impl Variable for Isometry2F64 {
    const DIM: usize = 3;
    fn retract(&self, delta: &[f64]) -> Self {
        self.group_mul(Isometry2F64::exp(Vector3::from_column_slice(delta)))
    }
    fn local(&self, other: &Self) -> Vec<f64> {
        self.inverse().group_mul(*other).log().as_slice().to_vec()
    }
    fn params(&self) -> Vec<f64> {
        let r = self.rotation().matrix();
        let t = self.translation();
        vec![r[(0, 0)], r[(1, 0)], t[0], t[1]]
    }
    fn params_jacobian(&self) -> DMatrix<f64> {
        let r = self.rotation().matrix();
        let (c, s) = (r[(0, 0)], r[(1, 0)]);
        let mut j = DMatrix::zeros(4, 3);
        j[(0, 0)] = -s;
        j[(1, 0)] = c;
        j.view_mut((2, 1), (2, 2)).copy_from(&r);
        j
    }
}

/// SE(2) from `(x, y, θ)` \[m, m, rad\].
pub fn se2(x: f64, y: f64, theta: f64) -> Isometry2F64 {
    Isometry2F64::from_rotation_and_translation(
        Rotation2F64::exp(nalgebra::Vector1::new(theta)),
        nalgebra::Vector2::new(x, y),
    )
}

/// SE(3) from a unit quaternion `(w, x, y, z)` and a translation \[m\].
/// The quaternion is normalized; it must not be zero.
pub fn se3_from_quaternion(q: [f64; 4], t: Vector3<f64>) -> Isometry3F64 {
    let uq = nalgebra::UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(q[0], q[1], q[2], q[3]));
    Isometry3F64::from_rotation_and_translation(Rotation3F64::exp(uq.scaled_axis()), t)
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    fn check_roundtrip<V: Variable>(x: &V, d: &[f64]) {
        let y = x.retract(d);
        let back = x.local(&y);
        for (a, b) in back.iter().zip(d) {
            assert_relative_eq!(*a, *b, epsilon = 1e-10);
        }
    }

    fn check_params_jacobian<V: Variable>(x: &V) {
        let analytic = x.params_jacobian();
        // Default numeric implementation, via the trait's provided method on a wrapper.
        let p0 = x.params();
        let h = 1e-6;
        for c in 0..V::DIM {
            let mut d = vec![0.0; V::DIM];
            d[c] = h;
            let pp = x.retract(&d).params();
            d[c] = -h;
            let pm = x.retract(&d).params();
            for r in 0..p0.len() {
                assert_relative_eq!(analytic[(r, c)], (pp[r] - pm[r]) / (2.0 * h), epsilon = 1e-7);
            }
        }
    }

    #[test]
    fn manifolds_roundtrip_and_params() {
        let r = Rotation3F64::exp(Vector3::new(0.3, -1.2, 0.5));
        check_roundtrip(&r, &[0.1, 0.2, -0.3]);
        check_params_jacobian(&r);
        let x = Isometry3F64::exp(Vector6::new(0.3, -1.2, 0.5, 1.0, 2.0, -3.0));
        check_roundtrip(&x, &[0.1, 0.2, -0.3, 0.5, -0.1, 0.2]);
        check_params_jacobian(&x);
        let p = se2(1.0, -2.0, 0.7);
        check_roundtrip(&p, &[0.1, 0.5, -0.2]);
        check_params_jacobian(&p);
        let v = nalgebra::Vector3::new(1.0, 2.0, 3.0);
        check_roundtrip(&v, &[0.1, 0.5, -0.2]);
    }

    #[test]
    fn sophus_se3_tangent_is_rotation_first() {
        let x = Isometry3F64::exp(Vector6::new(0.0, 0.0, 0.0, 1.0, 2.0, 3.0));
        assert_relative_eq!(x.translation(), Vector3::new(1.0, 2.0, 3.0), epsilon = 1e-12);
    }

    #[test]
    fn retract_into_reuses_or_replaces_the_box() {
        let x = Isometry3F64::exp(Vector6::new(0.1, -0.2, 0.3, 1.0, 2.0, 3.0));
        let d = [0.01, 0.02, -0.03, 0.1, 0.2, 0.3];
        let want = x.retract(&d);
        // Same type: overwritten in place; another type: replaced.
        let boxes: [Box<dyn DynVariable>; 2] =
            [Box::new(Isometry3F64::identity()), Box::new(Vector3::new(1.0, 2.0, 3.0))];
        for mut out in boxes {
            x.retract_into(&d, &mut out);
            let got: &Isometry3F64 = out.as_any().downcast_ref().unwrap();
            assert_eq!(Variable::params(got), Variable::params(&want));
        }
        let v = DynVector::from_slice(&[1.0, 2.0]);
        let boxes: [Box<dyn DynVariable>; 2] =
            [Box::new(DynVector::from_slice(&[0.0, 0.0])), Box::new(DynVector::from_slice(&[0.0]))];
        for mut out in boxes {
            v.retract_into(&[0.5, -1.0], &mut out);
            assert_eq!(out.params_dyn(), vec![1.5, 1.0]);
        }
    }
}
