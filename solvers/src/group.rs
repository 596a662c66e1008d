//! The [`LieGroup`] operations of the built-in variable types, on the
//! closed forms of [`crate::lie`].

use crate::lie::{se2_right_jacobian, se3_adjoint, se3_right_jacobian_inv, so3_right_jacobian_inv};
use nalgebra::{Matrix3, Vector3, Vector6};

/// Group operations and right-Jacobian algebra a factor needs, for the
/// built-in variable types (vector spaces are groups under addition).
pub trait LieGroup: crate::Variable + Copy {
    /// `self · other`.
    fn compose(&self, other: &Self) -> Self;
    /// `self⁻¹`.
    fn inverse_elem(&self) -> Self;
    /// `Log(self)` as a tangent vector (length `DIM`).
    fn log_vec(&self) -> nalgebra::DVector<f64>;
    /// Adjoint `Ad(self)`: `self · Exp(δ) = Exp(Ad δ) · self`.
    fn adjoint_mat(&self) -> nalgebra::DMatrix<f64>;
    /// Inverse right Jacobian `Jr⁻¹(ξ)` at tangent `ξ`.
    fn right_jacobian_inv(xi: &nalgebra::DVector<f64>) -> nalgebra::DMatrix<f64>;
    /// [`LieGroup::log_vec`] into `out` (length `DIM`), without allocating
    /// (the default allocates; the built-in groups override it).
    fn log_into(&self, out: &mut [f64]) {
        out.copy_from_slice(self.log_vec().as_slice());
    }
    /// [`LieGroup::adjoint_mat`] into `out` (`DIM × DIM`, column-major).
    fn adjoint_into(&self, out: &mut [f64]) {
        out.copy_from_slice(self.adjoint_mat().as_slice());
    }
    /// [`LieGroup::right_jacobian_inv`] at `xi` (length `DIM`) into `out`
    /// (`DIM × DIM`, column-major).
    fn right_jacobian_inv_into(xi: &[f64], out: &mut [f64]) {
        out.copy_from_slice(Self::right_jacobian_inv(&nalgebra::DVector::from_column_slice(xi)).as_slice());
    }
}

use sophus_lie::prelude::*;

impl<const N: usize> LieGroup for nalgebra::SVector<f64, N> {
    fn compose(&self, other: &Self) -> Self {
        self + other
    }
    fn inverse_elem(&self) -> Self {
        -self
    }
    fn log_vec(&self) -> nalgebra::DVector<f64> {
        nalgebra::DVector::from_column_slice(self.as_slice())
    }
    fn adjoint_mat(&self) -> nalgebra::DMatrix<f64> {
        nalgebra::DMatrix::identity(N, N)
    }
    fn right_jacobian_inv(_xi: &nalgebra::DVector<f64>) -> nalgebra::DMatrix<f64> {
        nalgebra::DMatrix::identity(N, N)
    }
    fn log_into(&self, out: &mut [f64]) {
        out.copy_from_slice(self.as_slice());
    }
    fn adjoint_into(&self, out: &mut [f64]) {
        identity_into(N, out);
    }
    fn right_jacobian_inv_into(_xi: &[f64], out: &mut [f64]) {
        identity_into(N, out);
    }
}

/// The `n × n` identity into `out` (column-major).
fn identity_into(n: usize, out: &mut [f64]) {
    out.fill(0.0);
    for k in 0..n {
        out[k * (n + 1)] = 1.0;
    }
}

impl LieGroup for sophus_lie::Rotation3F64 {
    fn compose(&self, other: &Self) -> Self {
        self.group_mul(*other)
    }
    fn inverse_elem(&self) -> Self {
        self.inverse()
    }
    fn log_vec(&self) -> nalgebra::DVector<f64> {
        nalgebra::DVector::from_column_slice(self.log().as_slice())
    }
    fn adjoint_mat(&self) -> nalgebra::DMatrix<f64> {
        nalgebra::DMatrix::from_column_slice(3, 3, self.matrix().as_slice())
    }
    fn right_jacobian_inv(xi: &nalgebra::DVector<f64>) -> nalgebra::DMatrix<f64> {
        let m = so3_right_jacobian_inv(&Vector3::new(xi[0], xi[1], xi[2]));
        nalgebra::DMatrix::from_column_slice(3, 3, m.as_slice())
    }
    fn log_into(&self, out: &mut [f64]) {
        out.copy_from_slice(self.log().as_slice());
    }
    fn adjoint_into(&self, out: &mut [f64]) {
        out.copy_from_slice(self.matrix().as_slice());
    }
    fn right_jacobian_inv_into(xi: &[f64], out: &mut [f64]) {
        out.copy_from_slice(so3_right_jacobian_inv(&Vector3::from_column_slice(xi)).as_slice());
    }
}

impl LieGroup for sophus_lie::Isometry3F64 {
    fn compose(&self, other: &Self) -> Self {
        self.group_mul(*other)
    }
    fn inverse_elem(&self) -> Self {
        self.inverse()
    }
    fn log_vec(&self) -> nalgebra::DVector<f64> {
        nalgebra::DVector::from_column_slice(self.log().as_slice())
    }
    fn adjoint_mat(&self) -> nalgebra::DMatrix<f64> {
        let m = se3_adjoint(&self.rotation().matrix(), &self.translation());
        nalgebra::DMatrix::from_column_slice(6, 6, m.as_slice())
    }
    fn right_jacobian_inv(xi: &nalgebra::DVector<f64>) -> nalgebra::DMatrix<f64> {
        let m = se3_right_jacobian_inv(&Vector6::from_column_slice(xi.as_slice()));
        nalgebra::DMatrix::from_column_slice(6, 6, m.as_slice())
    }
    fn log_into(&self, out: &mut [f64]) {
        out.copy_from_slice(self.log().as_slice());
    }
    fn adjoint_into(&self, out: &mut [f64]) {
        out.copy_from_slice(se3_adjoint(&self.rotation().matrix(), &self.translation()).as_slice());
    }
    fn right_jacobian_inv_into(xi: &[f64], out: &mut [f64]) {
        out.copy_from_slice(se3_right_jacobian_inv(&Vector6::from_column_slice(xi)).as_slice());
    }
}

impl LieGroup for sophus_lie::Isometry2F64 {
    fn compose(&self, other: &Self) -> Self {
        self.group_mul(*other)
    }
    fn inverse_elem(&self) -> Self {
        self.inverse()
    }
    fn log_vec(&self) -> nalgebra::DVector<f64> {
        nalgebra::DVector::from_column_slice(self.log().as_slice())
    }
    fn adjoint_mat(&self) -> nalgebra::DMatrix<f64> {
        let mut m = nalgebra::DMatrix::zeros(3, 3);
        self.adjoint_into(m.as_mut_slice());
        m
    }
    fn right_jacobian_inv(xi: &nalgebra::DVector<f64>) -> nalgebra::DMatrix<f64> {
        let mut m = nalgebra::DMatrix::zeros(3, 3);
        Self::right_jacobian_inv_into(xi.as_slice(), m.as_mut_slice());
        m
    }
    fn log_into(&self, out: &mut [f64]) {
        out.copy_from_slice(self.log().as_slice());
    }
    fn adjoint_into(&self, out: &mut [f64]) {
        let r = self.rotation().matrix();
        let t = self.translation();
        let m = Matrix3::new(1.0, 0.0, 0.0, t[1], r[(0, 0)], r[(0, 1)], -t[0], r[(1, 0)], r[(1, 1)]);
        out.copy_from_slice(m.as_slice());
    }
    fn right_jacobian_inv_into(xi: &[f64], out: &mut [f64]) {
        let jr = se2_right_jacobian(&Vector3::from_column_slice(xi));
        let inv = jr.try_inverse().unwrap_or_else(Matrix3::identity);
        out.copy_from_slice(inv.as_slice());
    }
}
