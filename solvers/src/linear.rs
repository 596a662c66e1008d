//! Block-sparse normal equations, assembled directly from factor Jacobians
//! (never a full sparse Jacobian), with optional Schur elimination of
//! landmark-like variables and sparse (faer) or dense (nalgebra) Cholesky.
//!
//! The sparsity pattern of the reduced system and the symbolic factorization
//! (with faer's fill-reducing ordering) are computed once per graph structure;
//! each iteration only refills numbers.

use crate::error::SolveError;
use crate::graph::WhitenedLinearization;
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::llt::factor::LltRegularization;
use faer::sparse::linalg::amd;
use faer::sparse::linalg::cholesky::{
    factorize_symbolic_cholesky, CholeskySymbolicParams, LltRef, SymbolicCholesky, SymmetricOrdering,
};
use faer::sparse::{SparseColMatRef, SymbolicSparseColMatRef};
use faer::{Conj, Par, Side};
use nalgebra::{DMatrix, DVector};
use std::collections::{BTreeSet, HashMap};

/// Role of a variable in the linear system.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Role {
    /// Held constant: no column.
    Const,
    /// Kept in the reduced system, as block `b`.
    Kept(usize),
    /// Eliminated first by the Schur complement, as eliminated block `e`.
    Elim(usize),
}

/// Which factorization solves the reduced system.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum LinearSolver {
    /// Dense Cholesky up to 200 unknowns, sparse above.
    #[default]
    Auto,
    /// Always faer's supernodal sparse Cholesky.
    SparseCholesky,
    /// Always nalgebra's dense Cholesky.
    DenseCholesky,
}

/// Unknowns below which [`LinearSolver::Auto`] goes dense.
pub const DENSE_THRESHOLD: usize = 200;

/// Per-factor scatter plan into the block system.
#[derive(Clone, Debug, Default)]
struct FactorPlan {
    /// (position p, position q, pair id) for kept positions with blk(p) ≥ blk(q).
    pairs: Vec<(usize, usize, usize)>,
    /// Kept positions and their block.
    kept: Vec<(usize, usize)>,
    /// The factor's eliminated variable, if any.
    elim: Option<ElimPlan>,
}

/// Where a factor's eliminated variable goes.
#[derive(Clone, Debug)]
struct ElimPlan {
    /// Position in the factor's key list.
    pos: usize,
    /// Eliminated block index.
    block: usize,
    /// For each kept position of the factor: (position, slot among the block's kept neighbours).
    slots: Vec<(usize, usize)>,
}

/// Normal-equation blocks of one eliminated variable l.
pub(crate) struct ElimBlock {
    /// H_ll.
    pub hll: DMatrix<f64>,
    /// g_l.
    pub gl: DVector<f64>,
    /// H_cl (d_cam × d_l) per neighbouring kept block, in slot order.
    pub hcl: Vec<DMatrix<f64>>,
}

/// Sparsity structure: the upper triangle of the reduced system, in CSC,
/// with the kept blocks in a fill-reducing order.
pub(crate) struct Structure {
    pub kept_dims: Vec<usize>,
    pub kept_offsets: Vec<usize>,
    pub n: usize,
    pub elim_dims: Vec<usize>,
    /// Offset of each eliminated block in the step vector (after the `n` reduced unknowns).
    pub elim_offsets: Vec<usize>,
    col_ptr: Vec<usize>,
    row_idx: Vec<usize>,
    /// Per pair: (row block, col block, index into `bases`).
    pairs: Vec<(usize, usize, usize)>,
    bases: Vec<usize>,
    diag_positions: Vec<usize>,
    plans: Vec<FactorPlan>,
    /// Per eliminated block: the kept blocks it touches, in slot order.
    elim_cams: Vec<Vec<usize>>,
    /// Per eliminated block: (slot a, slot b, pair) with blk(a) ≥ blk(b).
    elim_pairs: Vec<Vec<(usize, usize, usize)>>,
    dense: bool,
    /// Original kept-block index → position in the fill-reducing order.
    rank: Vec<usize>,
    factor: Option<SparseFactor>,
    /// Reused copy of H for damping and the Schur complement.
    scratch: Vec<f64>,
}

/// faer's sparse Cholesky on our pattern, whose blocks are already in a
/// fill-reducing (block AMD) order: symbolic analysis once, then only numeric
/// factorizations into reused buffers.
struct SparseFactor {
    symbolic: SymbolicCholesky<usize>,
    l_values: Vec<f64>,
    mem: MemBuffer,
}

impl SparseFactor {
    fn new(n: usize, col_ptr: &[usize], row_idx: &[usize]) -> Result<Self, SolveError> {
        let sym = SymbolicSparseColMatRef::new_checked(n, n, col_ptr, None, row_idx);
        let symbolic =
            // Supernodal always: with 3- to 9-wide variable blocks it beat the
            // simplicial path on every benchmark graph (e.g. sphere2500 7×).
            factorize_symbolic_cholesky(
                sym,
                Side::Upper,
                SymmetricOrdering::Identity,
                CholeskySymbolicParams {
                    supernodal_flop_ratio_threshold: faer::sparse::linalg::SupernodalThreshold::FORCE_SUPERNODAL,
                    ..Default::default()
                },
            )
                .map_err(|e| SolveError::Singular(format!("symbolic factorization: {e:?}")))?;
        let req = symbolic
            .factorize_numeric_llt_scratch::<f64>(Par::Seq, Default::default())
            .or(symbolic.solve_in_place_scratch::<f64>(1, Par::Seq));
        let mem = MemBuffer::try_new(req).map_err(|_| SolveError::Singular("out of memory".into()))?;
        let l_values = vec![0.0; symbolic.len_val()];
        Ok(SparseFactor { symbolic, l_values, mem })
    }

    /// Factorize `h` (upper CSC values on the structure's pattern), then solve
    /// in place for each column of `rhs`. Returns factorization seconds.
    fn factor_solve(
        &mut self,
        col_ptr: &[usize],
        row_idx: &[usize],
        h: &[f64],
        rhs: faer::MatMut<'_, f64>,
    ) -> Result<(f64, f64), SolveError> {
        let t = std::time::Instant::now();
        let n = col_ptr.len() - 1;
        let a = SparseColMatRef::new(SymbolicSparseColMatRef::new_checked(n, n, col_ptr, None, row_idx), h);
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
        let fact_s = t.elapsed().as_secs_f64();
        let t = std::time::Instant::now();
        let llt = LltRef::new(&self.symbolic, &self.l_values);
        let req = self.symbolic.solve_in_place_scratch::<f64>(rhs.ncols(), Par::Seq);
        let mut mem = MemBuffer::try_new(req).map_err(|_| SolveError::Singular("out of memory".into()))?;
        llt.solve_in_place_with_conj(Conj::No, rhs, Par::Seq, MemStack::new(&mut mem));
        Ok((fact_s, t.elapsed().as_secs_f64()))
    }
}

/// Fill-reducing order of the kept blocks: AMD on the block graph (including
/// the fill the Schur complement of eliminated blocks creates). Returns the
/// rank of each block.
fn block_amd(nk: usize, factor_roles: &[Vec<Role>]) -> Vec<usize> {
    let mut adj: Vec<BTreeSet<usize>> = vec![BTreeSet::new(); nk];
    let mut elim_nbrs: HashMap<usize, BTreeSet<usize>> = HashMap::new();
    for roles in factor_roles {
        let kept: Vec<usize> =
            roles.iter().filter_map(|r| if let Role::Kept(b) = r { Some(*b) } else { None }).collect();
        for &a in &kept {
            for &b in &kept {
                if a != b {
                    adj[a].insert(b);
                }
            }
        }
        for r in roles {
            if let Role::Elim(e) = r {
                elim_nbrs.entry(*e).or_default().extend(kept.iter().copied());
            }
        }
    }
    for nb in elim_nbrs.values() {
        for &a in nb {
            for &b in nb {
                if a != b {
                    adj[a].insert(b);
                }
            }
        }
    }
    let mut col_ptr = Vec::with_capacity(nk + 1);
    let mut row_idx = Vec::new();
    for a in &adj {
        col_ptr.push(row_idx.len());
        row_idx.extend(a.iter().copied());
    }
    col_ptr.push(row_idx.len());
    let mut perm = vec![0usize; nk];
    let mut perm_inv = vec![0usize; nk];
    let sym = SymbolicSparseColMatRef::new_checked(nk, nk, &col_ptr, None, &row_idx);
    let ok = MemBuffer::try_new(amd::order_scratch::<usize>(nk, row_idx.len())).ok().and_then(|mut mem| {
        amd::order(&mut perm, &mut perm_inv, sym, amd::Control::default(), MemStack::new(&mut mem)).ok()
    });
    if ok.is_none() {
        return (0..nk).collect();
    }
    // perm[new] = old, perm_inv[old] = new.
    perm_inv
}

/// Numeric content of the normal equations `H δ = −g` at one linearization.
pub(crate) struct System {
    /// Upper-triangular CSC values of H over kept blocks.
    pub h: Vec<f64>,
    /// Gradient over kept blocks.
    pub g: Vec<f64>,
    /// Per eliminated block.
    pub elim: Vec<ElimBlock>,
}

impl Structure {
    /// Build the structure. `factor_roles[f]` gives the role of each key position of factor f.
    pub fn new(
        kept_dims: Vec<usize>,
        elim_dims: Vec<usize>,
        factor_roles: &[Vec<Role>],
        solver: LinearSolver,
    ) -> Result<Self, SolveError> {
        let nk = kept_dims.len();
        let rank = block_amd(nk, factor_roles);
        let mut dims_new = vec![0; nk];
        for (b, &d) in kept_dims.iter().enumerate() {
            dims_new[rank[b]] = d;
        }
        let kept_dims = dims_new;
        let remapped: Vec<Vec<Role>> = factor_roles
            .iter()
            .map(|roles| roles.iter().map(|r| if let Role::Kept(b) = r { Role::Kept(rank[*b]) } else { *r }).collect())
            .collect();
        let factor_roles = &remapped[..];
        let mut kept_offsets = Vec::with_capacity(nk + 1);
        let mut n = 0;
        for d in &kept_dims {
            kept_offsets.push(n);
            n += d;
        }
        kept_offsets.push(n);

        // Block pattern (upper triangle): col block → set of row blocks ≤ col.
        let mut cols: Vec<BTreeSet<usize>> = (0..nk).map(|b| BTreeSet::from([b])).collect();
        let mut elim_cams: Vec<Vec<usize>> = vec![Vec::new(); elim_dims.len()];
        for (fi, roles) in factor_roles.iter().enumerate() {
            let kept: Vec<usize> =
                roles.iter().filter_map(|r| if let Role::Kept(b) = r { Some(*b) } else { None }).collect();
            for &a in &kept {
                for &b in &kept {
                    if a > b {
                        cols[a].insert(b);
                    }
                }
            }
            let elims: Vec<usize> =
                roles.iter().filter_map(|r| if let Role::Elim(e) = r { Some(*e) } else { None }).collect();
            if elims.len() > 1 {
                return Err(SolveError::Config(format!(
                    "factor {fi} connects {} eliminated (landmark) variables; Schur elimination needs at most one per factor",
                    elims.len()
                )));
            }
            if let Some(&e) = elims.first() {
                for &a in &kept {
                    if !elim_cams[e].contains(&a) {
                        elim_cams[e].push(a);
                    }
                }
            }
        }
        for cams in &elim_cams {
            for &a in cams {
                for &b in cams {
                    if a > b {
                        cols[a].insert(b);
                    }
                }
            }
        }

        // Scalar CSC pattern and per-pair bases.
        let mut col_ptr = Vec::with_capacity(n + 1);
        let mut row_idx = Vec::new();
        let mut pair_id: HashMap<(usize, usize), usize> = HashMap::new();
        let mut pairs = Vec::new();
        let mut bases = Vec::new();
        let mut diag_positions = vec![0; n];
        // Pair (big, small) lives in the columns of `big`; `bases[b0 + r]` is the
        // position of row `offset(small)` in column `offset(big) + r`.
        for (j, rows) in cols.iter().enumerate() {
            for &i in rows {
                pair_id.insert((j, i), pairs.len());
                pairs.push((j, i, bases.len()));
                bases.extend(std::iter::repeat_n(0, kept_dims[j]));
            }
            for c in 0..kept_dims[j] {
                col_ptr.push(row_idx.len());
                for &i in rows {
                    let base_slot = pairs[pair_id[&(j, i)]].2 + c;
                    bases[base_slot] = row_idx.len();
                    if i == j {
                        diag_positions[kept_offsets[j] + c] = row_idx.len() + c;
                        row_idx.extend(kept_offsets[j]..=kept_offsets[j] + c);
                    } else {
                        row_idx.extend(kept_offsets[i]..kept_offsets[i + 1]);
                    }
                }
            }
        }
        col_ptr.push(row_idx.len());

        let mut plans = Vec::with_capacity(factor_roles.len());
        for roles in factor_roles {
            let mut plan = FactorPlan::default();
            for (p, r) in roles.iter().enumerate() {
                if let Role::Kept(b) = r {
                    plan.kept.push((p, *b));
                }
            }
            for &(p, bp) in &plan.kept {
                for &(q, bq) in &plan.kept {
                    if bp >= bq {
                        plan.pairs.push((p, q, pair_id[&(bp, bq)]));
                    }
                }
            }
            for (p, r) in roles.iter().enumerate() {
                if let Role::Elim(e) = r {
                    let slots = plan
                        .kept
                        .iter()
                        .map(|&(q, bq)| (q, elim_cams[*e].iter().position(|&c| c == bq).unwrap_or(0)))
                        .collect();
                    plan.elim = Some(ElimPlan { pos: p, block: *e, slots });
                }
            }
            plans.push(plan);
        }
        let elim_pairs = elim_cams
            .iter()
            .map(|cams| {
                let mut v = Vec::new();
                for (sa, &a) in cams.iter().enumerate() {
                    for (sb, &b) in cams.iter().enumerate() {
                        if a >= b {
                            v.push((sa, sb, pair_id[&(a, b)]));
                        }
                    }
                }
                v
            })
            .collect();
        let dense = match solver {
            LinearSolver::DenseCholesky => true,
            LinearSolver::SparseCholesky => false,
            LinearSolver::Auto => n <= DENSE_THRESHOLD,
        };
        let elim_offsets = elim_dims
            .iter()
            .scan(n, |o, d| {
                let here = *o;
                *o += d;
                Some(here)
            })
            .collect();
        Ok(Structure {
            kept_dims,
            kept_offsets,
            n,
            elim_dims,
            elim_offsets,
            col_ptr,
            row_idx,
            pairs,
            bases,
            diag_positions,
            plans,
            elim_cams,
            elim_pairs,
            dense,
            rank,
            factor: None,
            scratch: Vec::new(),
        })
    }

    /// Scalar offset of original kept block `b` in the reduced system.
    pub fn kept_offset(&self, b: usize) -> usize {
        self.kept_offsets[self.rank[b]]
    }

    /// Tangent dimension of original kept block `b`.
    pub fn kept_dim(&self, b: usize) -> usize {
        self.kept_dims[self.rank[b]]
    }

    /// Number of stored entries of the upper triangle of the reduced system.
    pub fn nnz(&self) -> usize {
        self.row_idx.len()
    }

    /// `H_(big, small) −= W_big H_smallᵀ` (Schur update), without a temporary.
    #[inline]
    fn sub_w_ht(&self, h: &mut [f64], pair: usize, w_big: &DMatrix<f64>, h_small: &DMatrix<f64>) {
        let (i, j, b0) = self.pairs[pair];
        let dl = w_big.ncols();
        for r in 0..w_big.nrows() {
            let base = self.bases[b0 + r];
            let cmax = if i == j { r + 1 } else { h_small.nrows() };
            for c in 0..cmax {
                let mut s = 0.0;
                for k in 0..dl {
                    s += w_big[(r, k)] * h_small[(c, k)];
                }
                h[base + c] -= s;
            }
        }
    }

    /// `H_(big, small) += J_bigᵀ J_small`, without a temporary.
    #[inline]
    fn add_jtj(&self, h: &mut [f64], pair: usize, j_big: &DMatrix<f64>, j_small: &DMatrix<f64>) {
        let (i, j, b0) = self.pairs[pair];
        for (r, cr) in j_big.column_iter().enumerate() {
            let base = self.bases[b0 + r];
            let cmax = if i == j { r + 1 } else { j_small.ncols() };
            for c in 0..cmax {
                h[base + c] += cr.dot(&j_small.column(c));
            }
        }
    }

    /// Accumulate `H = Σ JᵀJ`, `g = Σ Jᵀr` from whitened linearizations.
    pub fn assemble(&self, lins: &[WhitenedLinearization]) -> System {
        let mut sys = System { h: Vec::new(), g: Vec::new(), elim: Vec::new() };
        self.assemble_into(lins, &mut sys);
        sys
    }

    /// As [`Structure::assemble`], reusing the buffers of `sys` (large `h`
    /// buffers are otherwise returned to the OS and page-faulted back every iteration).
    pub fn assemble_into(&self, lins: &[WhitenedLinearization], sys: &mut System) {
        let mut h = std::mem::take(&mut sys.h);
        h.clear();
        h.resize(self.nnz(), 0.0);
        let mut g = std::mem::take(&mut sys.g);
        g.clear();
        g.resize(self.n, 0.0);
        let mut elim: Vec<ElimBlock> = self
            .elim_dims
            .iter()
            .zip(&self.elim_cams)
            .map(|(&d, cams)| ElimBlock {
                hll: DMatrix::zeros(d, d),
                gl: DVector::zeros(d),
                hcl: cams.iter().map(|&c| DMatrix::zeros(self.kept_dims[c], d)).collect(),
            })
            .collect();
        for (plan, wl) in self.plans.iter().zip(lins) {
            let (r, js) = (&wl.lin.residual, &wl.lin.jacobians);
            for &(p, b) in &plan.kept {
                let o = self.kept_offsets[b];
                for (k, col) in js[p].column_iter().enumerate() {
                    g[o + k] += col.dot(r);
                }
            }
            for &(p, q, pair) in &plan.pairs {
                self.add_jtj(&mut h, pair, &js[p], &js[q]);
            }
            if let Some(ep) = &plan.elim {
                let b = &mut elim[ep.block];
                let jl = &js[ep.pos];
                b.hll.gemm_tr(1.0, jl, jl, 1.0);
                b.gl.gemv_tr(1.0, jl, r, 1.0);
                for &(q, s) in &ep.slots {
                    b.hcl[s].gemm_tr(1.0, &js[q], jl, 1.0);
                }
            }
        }
        *sys = System { h, g, elim };
    }

    /// Dense symmetric copy of triangular CSC values `h`.
    /// faer's dense Cholesky of the reduced system (lower triangle filled):
    /// blocked and vectorized, several times faster than nalgebra's on the
    /// 100–200 unknowns of a VIO window.
    fn dense_llt(&self, h: &[f64]) -> Option<faer::linalg::solvers::Llt<f64>> {
        let mut m = faer::Mat::<f64>::zeros(self.n, self.n);
        for c in 0..self.n {
            for (&r, &v) in
                self.row_idx[self.col_ptr[c]..self.col_ptr[c + 1]].iter().zip(&h[self.col_ptr[c]..self.col_ptr[c + 1]])
            {
                let (i, j) = if r >= c { (r, c) } else { (c, r) };
                m[(i, j)] = v;
            }
        }
        m.llt(faer::Side::Lower).ok()
    }

    /// Diagonal of H over kept unknowns followed by eliminated ones.
    pub fn diagonal(&self, sys: &System) -> Vec<f64> {
        let mut d: Vec<f64> = self.diag_positions.iter().map(|&p| sys.h[p]).collect();
        for b in &sys.elim {
            d.extend(b.hll.diagonal().iter());
        }
        d
    }

    /// Solve `(H + diag(damping)) δ = −g`; δ over kept unknowns then eliminated ones.
    /// Returns `(δ, factorize_seconds, solve_seconds, build_seconds)`.
    pub fn solve(&mut self, sys: &System, damping: Option<&[f64]>) -> Result<(Vec<f64>, f64, f64, f64), SolveError> {
        let t_build = std::time::Instant::now();
        let mut h = std::mem::take(&mut self.scratch);
        let (g, elim_inv) = self.reduce(sys, damping, &mut h)?;
        let build_s = t_build.elapsed().as_secs_f64();

        let t_fact = std::time::Instant::now();
        let mut x: Vec<f64> = g.iter().map(|v| -v).collect();
        let mut fact_s = 0.0;
        let mut solve_s = 0.0;
        if self.n == 0 {
        } else if self.dense {
            use faer::linalg::solvers::Solve;
            let ch = self.dense_llt(&h).ok_or_else(|| SolveError::Singular("dense Cholesky failed".into()))?;
            fact_s = t_fact.elapsed().as_secs_f64();
            let t_solve = std::time::Instant::now();
            let mut rhs = faer::Mat::<f64>::from_fn(self.n, 1, |i, _| x[i]);
            ch.solve_in_place(rhs.as_mut());
            for (i, xi) in x.iter_mut().enumerate() {
                *xi = rhs[(i, 0)];
            }
            solve_s = t_solve.elapsed().as_secs_f64();
        } else {
            if self.factor.is_none() {
                self.factor = Some(SparseFactor::new(self.n, &self.col_ptr, &self.row_idx)?);
            }
            let factor = self.factor.as_mut().expect("set above");
            let mut rhs = faer::Mat::<f64>::from_fn(self.n, 1, |i, _| x[i]);
            let (fs, ss) = factor.factor_solve(&self.col_ptr, &self.row_idx, &h, rhs.as_mut())?;
            fact_s = fs;
            solve_s = ss;
            for (i, xi) in x.iter_mut().enumerate() {
                *xi = rhs[(i, 0)];
            }
        }
        // Back-substitution for eliminated blocks: δ_l = −H_ll⁻¹ (g_l + Σ H_lc δ_c).
        let t_back = std::time::Instant::now();
        for (e, ElimBlock { gl, hcl, .. }) in sys.elim.iter().enumerate() {
            let mut rhs = gl.clone();
            for (s, &c) in self.elim_cams[e].iter().enumerate() {
                let o = self.kept_offsets[c];
                let dc = DVector::from_column_slice(&x[o..o + self.kept_dims[c]]);
                rhs += hcl[s].tr_mul(&dc);
            }
            let dl = -(&elim_inv[e] * rhs);
            x.extend(dl.iter());
        }
        if x.iter().any(|v| !v.is_finite()) {
            return Err(SolveError::Singular("non-finite step".into()));
        }
        self.scratch = h;
        Ok((x, fact_s, solve_s + t_back.elapsed().as_secs_f64(), build_s))
    }

    /// The reduced system: `h` ← upper triangle of `H + diag(damping)` over the
    /// kept unknowns minus the Schur complement of the eliminated blocks; returns
    /// the reduced gradient and each eliminated block's (damped) inverse.
    fn reduce(
        &self,
        sys: &System,
        damping: Option<&[f64]>,
        h: &mut Vec<f64>,
    ) -> Result<(Vec<f64>, Vec<DMatrix<f64>>), SolveError> {
        h.clear();
        h.extend_from_slice(&sys.h);
        let mut g = sys.g.clone();
        if let Some(d) = damping {
            for (k, &p) in self.diag_positions.iter().enumerate() {
                h[p] += d[k];
            }
        }
        let mut elim_inv = Vec::with_capacity(sys.elim.len());
        for (e, ElimBlock { hll, gl, hcl }) in sys.elim.iter().enumerate() {
            let off = self.elim_offsets[e];
            let mut a = hll.clone();
            if let Some(d) = damping {
                for k in 0..a.nrows() {
                    a[(k, k)] += d[off + k];
                }
            }
            let singular = || SolveError::Singular(format!("eliminated block {e} is not positive definite"));
            let inv = match a.nrows() {
                // Inverse depths: a scalar, no factorization needed.
                1 if a[(0, 0)] > 0.0 && a[(0, 0)].is_finite() => DMatrix::from_element(1, 1, 1.0 / a[(0, 0)]),
                1 => return Err(singular()),
                _ => nalgebra::Cholesky::new(a).ok_or_else(singular)?.inverse(),
            };
            let w: Vec<DMatrix<f64>> = hcl.iter().map(|m| m * &inv).collect();
            for &(sa, sb, pair) in &self.elim_pairs[e] {
                self.sub_w_ht(h, pair, &w[sa], &hcl[sb]);
            }
            for (s, &c) in self.elim_cams[e].iter().enumerate() {
                let v = &w[s] * gl;
                let o = self.kept_offsets[c];
                for (k, x) in v.iter().enumerate() {
                    g[o + k] -= x;
                }
            }
            elim_inv.push(inv);
        }
        Ok((g, elim_inv))
    }

    /// `Hδ` for the predicted decrease, over kept then eliminated unknowns (undamped H).
    pub fn h_times(&self, sys: &System, x: &[f64]) -> Vec<f64> {
        let mut y = vec![0.0; x.len()];
        for c in 0..self.n {
            let range = self.col_ptr[c]..self.col_ptr[c + 1];
            for (&r, &v) in self.row_idx[range.clone()].iter().zip(&sys.h[range]) {
                y[r] += v * x[c];
                if r != c {
                    y[c] += v * x[r];
                }
            }
        }
        for (e, ElimBlock { hll, hcl, .. }) in sys.elim.iter().enumerate() {
            let (off, d) = (self.elim_offsets[e], hll.nrows());
            let xl = DVector::from_column_slice(&x[off..off + d]);
            let mut yl = hll * &xl;
            for (s, &c) in self.elim_cams[e].iter().enumerate() {
                let o = self.kept_offsets[c];
                let dc = self.kept_dims[c];
                let xc = DVector::from_column_slice(&x[o..o + dc]);
                yl += hcl[s].tr_mul(&xc);
                let yc = &hcl[s] * &xl;
                for k in 0..dc {
                    y[o + k] += yc[k];
                }
            }
            for k in 0..d {
                y[off + k] += yl[k];
            }
        }
        y
    }

    /// Selected columns of H⁻¹ over kept unknowns. With eliminated blocks, the
    /// inverse of their Schur complement: the same columns of the full inverse.
    pub fn inverse_columns(&mut self, sys: &System, cols: &[usize]) -> Result<DMatrix<f64>, SolveError> {
        let mut h = Vec::new();
        self.reduce(sys, None, &mut h)?;
        let mut out = DMatrix::zeros(self.n, cols.len());
        if self.dense || self.n == 0 {
            use faer::linalg::solvers::Solve;
            if self.n == 0 {
                return Ok(out);
            }
            let ch = self.dense_llt(&h).ok_or_else(|| SolveError::Singular("information matrix is singular".into()))?;
            let mut rhs = faer::Mat::<f64>::from_fn(self.n, cols.len(), |i, j| if i == cols[j] { 1.0 } else { 0.0 });
            ch.solve_in_place(rhs.as_mut());
            for j in 0..cols.len() {
                for i in 0..self.n {
                    out[(i, j)] = rhs[(i, j)];
                }
            }
            return Ok(out);
        }
        let mut factor = SparseFactor::new(self.n, &self.col_ptr, &self.row_idx)?;
        let mut rhs = faer::Mat::<f64>::from_fn(self.n, cols.len(), |i, j| if i == cols[j] { 1.0 } else { 0.0 });
        factor
            .factor_solve(&self.col_ptr, &self.row_idx, &h, rhs.as_mut())
            .map_err(|_| SolveError::Singular("information matrix is singular (unobservable variables?)".into()))?;
        for j in 0..cols.len() {
            for i in 0..self.n {
                out[(i, j)] = rhs[(i, j)];
            }
        }
        Ok(out)
    }
}
