//! faer's sparse Cholesky factorization of the reduced system: the symbolic
//! analysis once per structure, then numeric factorizations and triangular
//! solves into reused buffers, supernodal or simplicial by the factor's work
//! per entry, each reading the triangle it works on.

use crate::error::SolveError;
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::llt::factor::LltRegularization;
use faer::sparse::linalg::cholesky::supernodal::SupernodalLltRef;
use faer::sparse::linalg::cholesky::{
    factorize_symbolic_cholesky, CholeskySymbolicParams, LltRef, SymbolicCholesky, SymbolicCholeskyRaw,
    SymmetricOrdering,
};
use faer::sparse::linalg::SupernodalThreshold;
use faer::sparse::{SparseColMatRef, SymbolicSparseColMat};
use faer::{Conj, Par, Side};

/// The work per entry of the factor (faer's measure: divisions and
/// multiply–subtracts of the factorization over the factor's nonzeros) above
/// which the supernodal factorization is used, the simplicial one below. On
/// the benchmark pose graphs (`bench_solver`) a solve with the simplicial one
/// took 0.70–0.84 × the supernodal one's time at ratios up to 9.8 (kitti_00,
/// CSAIL, MIT, ais2klinik, intel), and the supernodal one 0.6–0.87 × the
/// simplicial one's from 18.8 up (M3500, manhattan, parking-garage,
/// city10000, sphere2500); this sits between the two. faer's own default,
/// 40, put parking-garage (27) on the slower path.
const SUPERNODAL_FLOPS_PER_ENTRY: f64 = 14.0;

/// The ratio faer's [`SupernodalThreshold`] multiplies (its
/// `CHOLESKY_SUPERNODAL_RATIO_FACTOR`): `SupernodalThreshold(1.0)` is 40
/// operations per entry.
const FAER_SUPERNODAL_RATIO_UNIT: f64 = 40.0;

/// faer's sparse Cholesky on our pattern, whose blocks are already in a
/// fill-reducing (block AMD) order: symbolic analysis once, then only numeric
/// factorizations into reused buffers.
pub(super) struct SparseFactor {
    pub(super) symbolic: SymbolicCholesky<usize>,
    pub(super) l_values: Vec<f64>,
    pub(super) mem: MemBuffer,
    /// `l_values` hold a factor: the last numeric factorization succeeded.
    pub(super) factored: bool,
    /// The factor is supernodal (many operations per entry, see
    /// [`SUPERNODAL_FLOPS_PER_ENTRY`]): a factorization costs many solves
    /// with it, and trying it for every step pays
    /// ([`super::Structure::chord_step`]). A simplicial factor costs about as much
    /// to compute as a few solves, so failed chord tries waste what the
    /// successful ones save (MIT and ais2klinik were 15–25 % slower); it
    /// serves the stationarity check only, whose system is the nearest to
    /// the factored one ([`super::Structure::solve_with_last_factor`]).
    pub(super) worth_reusing: bool,
    /// The pattern the numeric factorization reads, checked once (faer
    /// checks a borrowed pattern at every factorization): the lower triangle
    /// for a supernodal factor, the upper one (as the structure holds it)
    /// for a simplicial one — the triangle each of faer's factorizations
    /// works on. Given the other, faer transposes it at every factorization
    /// (a counting sort rebuilding the pattern, 3–5 % of a pose graph's
    /// solve); a gather through `from_upper` is one pass over the values.
    triangle: SymbolicSparseColMat<usize>,
    /// Which triangle `triangle` is.
    side: Side,
    /// Where each entry of the lower triangle sits in the upper one's values
    /// (empty for the upper triangle).
    from_upper: Vec<usize>,
    /// The lower triangle's values, gathered through `from_upper`.
    lower_values: Vec<f64>,
}

/// The lower triangle of the symmetric matrix whose upper triangle has
/// pattern (`col_ptr`, `row_idx`), with each entry's position in the upper
/// triangle's values. Column i of the lower triangle is row i of the upper
/// one; visiting the upper columns in order leaves its rows sorted.
fn lower_triangle(n: usize, col_ptr: &[usize], row_idx: &[usize]) -> (SymbolicSparseColMat<usize>, Vec<usize>) {
    let mut lower_ptr = vec![0; n + 1];
    for &i in row_idx {
        lower_ptr[i + 1] += 1;
    }
    for i in 0..n {
        lower_ptr[i + 1] += lower_ptr[i];
    }
    let mut next = lower_ptr[..n].to_vec();
    let (mut lower_rows, mut from_upper) = (vec![0; row_idx.len()], vec![0; row_idx.len()]);
    for j in 0..n {
        for p in col_ptr[j]..col_ptr[j + 1] {
            let slot = &mut next[row_idx[p]];
            (lower_rows[*slot], from_upper[*slot]) = (j, p);
            *slot += 1;
        }
    }
    (SymbolicSparseColMat::new_checked(n, n, lower_ptr, None, lower_rows), from_upper)
}

impl SparseFactor {
    pub(super) fn new(n: usize, col_ptr: &[usize], row_idx: &[usize]) -> Result<Self, SolveError> {
        let upper = SymbolicSparseColMat::new_checked(n, n, col_ptr.to_vec(), None, row_idx.to_vec());
        let symbolic = factorize_symbolic_cholesky(
            upper.as_ref(),
            Side::Upper,
            SymmetricOrdering::Identity,
            CholeskySymbolicParams {
                supernodal_flop_ratio_threshold: SupernodalThreshold(
                    SUPERNODAL_FLOPS_PER_ENTRY / FAER_SUPERNODAL_RATIO_UNIT,
                ),
                ..Default::default()
            },
        )
        .map_err(|e| SolveError::Singular(format!("symbolic factorization: {e:?}")))?;
        let req = symbolic
            .factorize_numeric_llt_scratch::<f64>(Par::Seq, Default::default())
            .or(symbolic.solve_in_place_scratch::<f64>(1, Par::Seq));
        let mem = MemBuffer::try_new(req).map_err(|_| SolveError::Singular("out of memory".into()))?;
        let l_values = vec![0.0; symbolic.len_val()];
        let worth_reusing = matches!(symbolic.raw(), SymbolicCholeskyRaw::Supernodal(_));
        let (triangle, side, from_upper) = if worth_reusing {
            let (lower, from_upper) = lower_triangle(n, col_ptr, row_idx);
            (lower, Side::Lower, from_upper)
        } else {
            (upper, Side::Upper, Vec::new())
        };
        let lower_values = vec![0.0; from_upper.len()];
        Ok(SparseFactor {
            symbolic,
            l_values,
            mem,
            factored: false,
            worth_reusing,
            triangle,
            side,
            from_upper,
            lower_values,
        })
    }

    /// Factorize `h` (upper CSC values on the pattern the factor was made
    /// for), then solve in place for each column of `rhs`. Returns the
    /// factorization's and the solve's seconds.
    pub(super) fn factor_solve(&mut self, h: &[f64], rhs: faer::MatMut<'_, f64>) -> Result<(f64, f64), SolveError> {
        let t = std::time::Instant::now();
        let values = if self.from_upper.is_empty() {
            h
        } else {
            for (v, &p) in self.lower_values.iter_mut().zip(&self.from_upper) {
                *v = h[p];
            }
            &self.lower_values
        };
        let a = SparseColMatRef::new(self.triangle.as_ref(), values);
        self.factored = false;
        self.symbolic
            .factorize_numeric_llt(
                &mut self.l_values,
                a,
                self.side,
                LltRegularization::default(),
                Par::Seq,
                MemStack::new(&mut self.mem),
                Default::default(),
            )
            .map_err(|e| SolveError::Singular(format!("sparse Cholesky: {e:?}")))?;
        self.factored = true;
        let fact_s = t.elapsed().as_secs_f64();
        let t = std::time::Instant::now();
        let llt = LltRef::new(&self.symbolic, &self.l_values);
        let req = self.symbolic.solve_in_place_scratch::<f64>(rhs.ncols(), Par::Seq);
        let mut mem = MemBuffer::try_new(req).map_err(|_| SolveError::Singular("out of memory".into()))?;
        llt.solve_in_place_with_conj(Conj::No, rhs, Par::Seq, MemStack::new(&mut mem));
        Ok((fact_s, t.elapsed().as_secs_f64()))
    }

    /// `v ← L⁻¹ v` with the held supernodal factor (`factored` and
    /// `worth_reusing`), whose order is the system's (no permutation): the
    /// first half of [`SparseFactor::apply_inverse`], [`SparseFactor::backward`]
    /// the second.
    pub(super) fn forward(&mut self, v: &mut [f64]) {
        self.supernodal_solve(v, |llt, rhs, stack| llt.l_solve_with_conj(Conj::No, rhs, Par::Seq, stack));
    }

    /// `v ← L⁻ᵀ v`, as [`SparseFactor::forward`].
    pub(super) fn backward(&mut self, v: &mut [f64]) {
        self.supernodal_solve(v, |llt, rhs, stack| llt.l_transpose_solve_with_conj(Conj::No, rhs, Par::Seq, stack));
    }

    /// Run `solve` on `v` with the supernodal factor and the factor's scratch
    /// (nothing for a simplicial factor).
    fn supernodal_solve(
        &mut self,
        v: &mut [f64],
        solve: impl FnOnce(SupernodalLltRef<'_, usize, f64>, faer::MatMut<'_, f64>, &mut MemStack),
    ) {
        if let SymbolicCholeskyRaw::Supernodal(sym) = self.symbolic.raw() {
            let n = v.len();
            let rhs = faer::MatMut::from_column_major_slice_mut(v, n, 1);
            solve(SupernodalLltRef::new(sym, &self.l_values), rhs, MemStack::new(&mut self.mem));
        }
    }

    /// `v ← (L Lᵀ)⁻¹ v` with the held factor (`factored`).
    pub(super) fn apply_inverse(&mut self, v: &mut [f64]) {
        let n = v.len();
        let llt = LltRef::new(&self.symbolic, &self.l_values);
        let rhs = faer::MatMut::from_column_major_slice_mut(v, n, 1);
        // `mem` holds the larger of the factorization's and a one-column solve's scratch.
        llt.solve_in_place_with_conj(Conj::No, rhs, Par::Seq, MemStack::new(&mut self.mem));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The lower triangle holds every upper entry once, mirrored, with
    /// sorted rows; and a factor read from it solves as the upper one does.
    #[test]
    fn the_lower_triangle_mirrors_the_upper_one() {
        // Upper triangle of a 5 × 5 arrowhead-and-band matrix.
        let n = 5;
        let cols: [&[usize]; 5] = [&[0], &[0, 1], &[1, 2], &[0, 2, 3], &[0, 1, 3, 4]];
        let (mut col_ptr, mut row_idx) = (vec![0], Vec::new());
        for rows in cols {
            row_idx.extend_from_slice(rows);
            col_ptr.push(row_idx.len());
        }
        let (lower, from_upper) = lower_triangle(n, &col_ptr, &row_idx);
        let (lp, lr) = (lower.col_ptr(), lower.row_idx());
        assert_eq!(lr.len(), row_idx.len());
        let mut seen = vec![false; row_idx.len()];
        for c in 0..n {
            let rows = &lr[lp[c]..lp[c + 1]];
            assert!(rows.windows(2).all(|w| w[0] < w[1]), "column {c}: {rows:?}");
            for (k, &r) in rows.iter().enumerate() {
                let p = from_upper[lp[c] + k];
                assert!(!seen[p]);
                seen[p] = true;
                // Upper entry p is (row_idx[p], its column) = (c, r).
                assert_eq!(row_idx[p], c);
                assert!((col_ptr[r]..col_ptr[r + 1]).contains(&p));
            }
        }
        assert!(seen.iter().all(|&s| s));

        // Diagonally dominant values: the factorization through the lower
        // triangle (forced supernodal) against a dense solve.
        let h: Vec<f64> = (0..n)
            .flat_map(|c| {
                let rows = &row_idx[col_ptr[c]..col_ptr[c + 1]];
                rows.iter().map(move |&r| if r == c { 10.0 + c as f64 } else { 0.5 + 0.1 * (r + 2 * c) as f64 })
            })
            .collect();
        let mut dense = nalgebra::DMatrix::<f64>::zeros(n, n);
        for c in 0..n {
            for p in col_ptr[c]..col_ptr[c + 1] {
                dense[(row_idx[p], c)] = h[p];
                dense[(c, row_idx[p])] = h[p];
            }
        }
        let b = nalgebra::DVector::from_fn(n, |i, _| 1.0 + i as f64);
        let expect = dense.cholesky().expect("SPD").solve(&b);
        for supernodal in [false, true] {
            let mut f = SparseFactor::new(n, &col_ptr, &row_idx).expect("factor");
            if supernodal {
                (f.triangle, f.from_upper) = (lower.clone(), from_upper.clone());
                (f.side, f.lower_values) = (Side::Lower, vec![0.0; from_upper.len()]);
            }
            let mut x = faer::Mat::<f64>::from_fn(n, 1, |i, _| b[i]);
            f.factor_solve(&h, x.as_mut()).expect("solve");
            for i in 0..n {
                assert!(
                    (x[(i, 0)] - expect[i]).abs() < 1e-12,
                    "supernodal {supernodal}: {} vs {}",
                    x[(i, 0)],
                    expect[i]
                );
            }
        }
    }
}
