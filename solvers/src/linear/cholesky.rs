//! faer's sparse Cholesky factorization of the reduced system: the symbolic
//! analysis once per structure, then numeric factorizations and triangular
//! solves into reused buffers, supernodal or simplicial by the factor's work
//! per entry.

use crate::error::SolveError;
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::llt::factor::LltRegularization;
use faer::sparse::linalg::cholesky::supernodal::SupernodalLltRef;
use faer::sparse::linalg::cholesky::{
    factorize_symbolic_cholesky, CholeskySymbolicParams, LltRef, SymbolicCholesky, SymbolicCholeskyRaw,
    SymmetricOrdering,
};
use faer::sparse::linalg::SupernodalThreshold;
use faer::sparse::{SparseColMatRef, SymbolicSparseColMatRef};
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
}

impl SparseFactor {
    pub(super) fn new(n: usize, col_ptr: &[usize], row_idx: &[usize]) -> Result<Self, SolveError> {
        let sym = SymbolicSparseColMatRef::new_checked(n, n, col_ptr, None, row_idx);
        let symbolic = factorize_symbolic_cholesky(
            sym,
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
        Ok(SparseFactor { symbolic, l_values, mem, factored: false, worth_reusing })
    }

    /// Factorize `h` (upper CSC values on the structure's pattern), then solve
    /// in place for each column of `rhs`. Returns factorization seconds.
    pub(super) fn factor_solve(
        &mut self,
        col_ptr: &[usize],
        row_idx: &[usize],
        h: &[f64],
        rhs: faer::MatMut<'_, f64>,
    ) -> Result<(f64, f64), SolveError> {
        let t = std::time::Instant::now();
        let n = col_ptr.len() - 1;
        let a = SparseColMatRef::new(SymbolicSparseColMatRef::new_checked(n, n, col_ptr, None, row_idx), h);
        self.factored = false;
        self.symbolic
            .factorize_numeric_llt(
                &mut self.l_values,
                a,
                Side::Upper,
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
