//! Noise models: how a raw residual is whitened before it enters the cost.
//!
//! A residual `r` with covariance `Σ` contributes `‖W r‖²` with `WᵀW = Σ⁻¹`
//! (W is the square-root information).

use crate::error::NoiseError;
use nalgebra::{DMatrix, DVector, SMatrix, SVector};

/// A Gaussian noise model for one factor.
#[derive(Clone, Debug, PartialEq)]
pub enum NoiseModel {
    /// Residuals are already whitened.
    Unit,
    /// Same standard deviation on every component.
    Isotropic {
        /// Residual dimension.
        dim: usize,
        /// Standard deviation (units of the residual).
        sigma: f64,
    },
    /// Independent components with these standard deviations.
    Diagonal(DVector<f64>),
    /// Full square-root information `W` (upper triangular, `WᵀW = Σ⁻¹`).
    SqrtInformation(DMatrix<f64>),
}

fn check_sigma(s: f64) -> Result<f64, NoiseError> {
    if s.is_finite() && s > 0.0 {
        Ok(s)
    } else {
        Err(NoiseError::BadSigma(s))
    }
}

fn check_symmetric(m: &DMatrix<f64>) -> Result<(), NoiseError> {
    if !m.is_square() {
        return Err(NoiseError::Dimension(format!("{}×{} is not square", m.nrows(), m.ncols())));
    }
    if m.iter().any(|v| !v.is_finite()) {
        return Err(NoiseError::NotPositiveDefinite);
    }
    let scale = m.amax().max(f64::MIN_POSITIVE);
    if (m - m.transpose()).amax() > 1e-9 * scale {
        return Err(NoiseError::NotPositiveDefinite);
    }
    Ok(())
}

fn is_upper_triangular(w: &DMatrix<f64>) -> bool {
    let n = w.nrows();
    n == w.ncols() && (0..n).all(|c| (c + 1..n).all(|r| w[(r, c)] == 0.0))
}

/// `x ← W x` for upper-triangular `W` (n × n, `x.len() == n`), in place:
/// row i only reads x\[k ≥ i\], which are still the input's. Row i of W
/// from its diagonal on is every n-th entry of W's column-major storage.
fn upper_mul_in_place(w: &DMatrix<f64>, x: &mut [f64]) {
    let n = x.len();
    let ws = w.as_slice();
    for i in 0..n {
        x[i] = x[i..].iter().zip(ws[i * (n + 1)..].iter().step_by(n)).map(|(xk, wik)| wik * xk).sum();
    }
}

/// `J ← W J` for an N × N `W` and a column-major `j` of N rows, N columns at
/// a time as fixed-size products (vectorized, unrolled: the 3- and 6-row
/// pose-graph edges), the remaining columns one by one.
fn mul_in_place_by_blocks<const N: usize>(w: &DMatrix<f64>, j: &mut [f64]) {
    let w = SMatrix::<f64, N, N>::from_column_slice(w.as_slice());
    let mut blocks = j.chunks_exact_mut(N * N);
    for block in &mut blocks {
        let product = w * SMatrix::<f64, N, N>::from_column_slice(block);
        block.copy_from_slice(product.as_slice());
    }
    for col in blocks.into_remainder().chunks_exact_mut(N) {
        let product = w * SVector::<f64, N>::from_column_slice(col);
        col.copy_from_slice(product.as_slice());
    }
}

impl NoiseModel {
    /// Isotropic model with standard deviation `sigma`.
    pub fn isotropic(dim: usize, sigma: f64) -> Result<Self, NoiseError> {
        Ok(NoiseModel::Isotropic { dim, sigma: check_sigma(sigma)? })
    }
    /// Diagonal model from standard deviations.
    pub fn diagonal(sigmas: &[f64]) -> Result<Self, NoiseError> {
        for s in sigmas {
            check_sigma(*s)?;
        }
        Ok(NoiseModel::Diagonal(DVector::from_column_slice(sigmas)))
    }
    /// Full model from a covariance matrix (symmetric positive definite).
    pub fn from_covariance(cov: &DMatrix<f64>) -> Result<Self, NoiseError> {
        check_symmetric(cov)?;
        let info = cov.clone().try_inverse().ok_or(NoiseError::NotPositiveDefinite)?;
        Self::from_information(&((&info + info.transpose()) * 0.5))
    }
    /// Full model from an information matrix Σ⁻¹ (symmetric positive definite).
    pub fn from_information(info: &DMatrix<f64>) -> Result<Self, NoiseError> {
        check_symmetric(info)?;
        let l = nalgebra::Cholesky::new(info.clone()).ok_or(NoiseError::NotPositiveDefinite)?;
        Ok(NoiseModel::SqrtInformation(l.l().transpose()))
    }
    /// Full model from a square-root information matrix `W` (`WᵀW = Σ⁻¹`).
    pub fn from_sqrt_information(w: DMatrix<f64>) -> Result<Self, NoiseError> {
        if !w.is_square() || w.iter().any(|v| !v.is_finite()) {
            return Err(NoiseError::NotPositiveDefinite);
        }
        Ok(NoiseModel::SqrtInformation(w))
    }
    /// Residual dimension this model expects, if it fixes one.
    pub fn dim(&self) -> Option<usize> {
        match self {
            NoiseModel::Unit => None,
            NoiseModel::Isotropic { dim, .. } => Some(*dim),
            NoiseModel::Diagonal(s) => Some(s.len()),
            NoiseModel::SqrtInformation(w) => Some(w.nrows()),
        }
    }
    /// Whiten a residual in place.
    pub fn whiten(&self, r: &mut DVector<f64>) {
        match self {
            NoiseModel::Unit => {}
            NoiseModel::Isotropic { sigma, .. } => *r /= *sigma,
            NoiseModel::Diagonal(s) => r.component_div_assign(s),
            NoiseModel::SqrtInformation(w) => {
                if is_upper_triangular(w) && w.nrows() == r.len() {
                    upper_mul_in_place(w, r.as_mut_slice());
                } else {
                    *r = w * &*r
                }
            }
        }
    }
    /// Whiten a Jacobian block (rows = residual components) in place.
    pub fn whiten_jacobian(&self, j: &mut DMatrix<f64>) {
        match self {
            NoiseModel::Unit => {}
            NoiseModel::Isotropic { sigma, .. } => *j /= *sigma,
            NoiseModel::Diagonal(s) => {
                for (mut row, si) in j.row_iter_mut().zip(s.iter()) {
                    row /= *si;
                }
            }
            NoiseModel::SqrtInformation(w) => {
                let n = j.nrows();
                if w.nrows() == n && n == 6 {
                    mul_in_place_by_blocks::<6>(w, j.as_mut_slice());
                } else if w.nrows() == n && n == 3 {
                    mul_in_place_by_blocks::<3>(w, j.as_mut_slice());
                } else if is_upper_triangular(w) && w.nrows() == n && n > 0 {
                    for col in j.as_mut_slice().chunks_exact_mut(n) {
                        upper_mul_in_place(w, col);
                    }
                } else {
                    *j = w * &*j
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn full_whitening_matches_mahalanobis() {
        let cov = DMatrix::from_row_slice(2, 2, &[4.0, 1.0, 1.0, 2.0]);
        let m = NoiseModel::from_covariance(&cov).unwrap();
        let r0 = DVector::from_column_slice(&[1.0, -2.0]);
        let mut r = r0.clone();
        m.whiten(&mut r);
        let maha = (r0.transpose() * cov.try_inverse().unwrap() * &r0)[0];
        assert_relative_eq!(r.norm_squared(), maha, epsilon = 1e-12);
    }

    #[test]
    fn whitening_equals_the_matrix_product() {
        // 3 and 6 rows take fixed-size blocks (7 and 13 columns leave a
        // remainder), 4 rows the triangular loop.
        for (n, cols) in [(3, 7), (6, 12), (6, 13), (4, 9)] {
            let info =
                DMatrix::from_fn(n, n, |i, j| if i == j { 4.0 + i as f64 } else { 0.3 / (1.0 + (i + j) as f64) });
            let m = NoiseModel::from_information(&info).unwrap();
            let NoiseModel::SqrtInformation(w) = &m else { panic!("full model") };
            assert!(is_upper_triangular(w));
            let j0 = DMatrix::from_fn(n, cols, |i, j| ((i * cols + j) as f64 * 0.37).sin());
            let mut j = j0.clone();
            m.whiten_jacobian(&mut j);
            assert_relative_eq!(j, w * &j0, epsilon = 1e-14);
            let r0 = DVector::from_fn(n, |i, _| 1.0 - 0.3 * i as f64);
            let mut r = r0.clone();
            m.whiten(&mut r);
            assert_relative_eq!(r, w * &r0, epsilon = 1e-14);
        }
    }

    #[test]
    fn rejects_bad_input() {
        assert!(NoiseModel::isotropic(3, 0.0).is_err());
        assert!(NoiseModel::diagonal(&[1.0, f64::NAN]).is_err());
        let not_pd = DMatrix::from_row_slice(2, 2, &[1.0, 2.0, 2.0, 1.0]);
        assert_eq!(NoiseModel::from_information(&not_pd), Err(NoiseError::NotPositiveDefinite));
        let asym = DMatrix::from_row_slice(2, 2, &[1.0, 0.5, 0.0, 1.0]);
        assert!(NoiseModel::from_information(&asym).is_err());
    }
}
