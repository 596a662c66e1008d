//! Block-sparse normal equations, assembled directly from factor Jacobians
//! (never a full sparse Jacobian), with optional Schur elimination of
//! landmark-like variables and sparse (faer) or dense (nalgebra) Cholesky.
//!
//! The sparsity pattern of the reduced system and the symbolic factorization
//! (with faer's fill-reducing ordering) are computed once per graph structure;
//! each iteration only refills numbers.

use crate::error::SolveError;
use crate::layout::{Layout, Role, Roles};
use crate::variable::DynVariable;
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::llt::factor::LltRegularization;
use faer::sparse::linalg::amd;
use faer::sparse::SymbolicSparseColMatRef;
use faer::{Conj, Par};
use nalgebra::DMatrix;
use smallvec::SmallVec;

mod assembly;
mod cholesky;
mod refactor;
mod schur;
use assembly::AssemblyPlan;
pub(crate) use assembly::PARALLEL_MIN_FACTORS;
use cholesky::SparseFactor;
use schur::SchurPlan;

/// Which factorization solves the reduced system.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum LinearSolver {
    /// Dense Cholesky up to 200 unknowns, sparse above.
    #[default]
    Auto,
    /// Always faer's sparse Cholesky (supernodal or simplicial by the factor's density).
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
    pairs: SmallVec<[(usize, usize, usize); 3]>,
    /// Kept positions and their block.
    kept: SmallVec<[(usize, usize); 2]>,
    /// The factor's eliminated variable, if any.
    elim: Option<ElimPlan>,
    /// Its JᵀJ never changes: formed once into [`Structure::hessian_cache`].
    constant: bool,
}

/// Where a factor's eliminated variable goes.
#[derive(Clone, Debug)]
struct ElimPlan {
    /// Position in the factor's key list.
    pos: usize,
    /// Eliminated block index.
    block: usize,
    /// For each kept position of the factor: (position, offset of its H_cl block in [`System::hcl`]).
    slots: SmallVec<[(usize, usize); 2]>,
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
    /// Offset of each eliminated block's H_ll (d × d) in [`System::hll`]; one past the end last.
    hll_offsets: Vec<usize>,
    /// Offset of each eliminated block's first H_cl in [`System::hcl`]; its
    /// slots follow in `elim_cams` order, each `kept_dim × d` column-major.
    hcl_offsets: Vec<usize>,
    dense: bool,
    /// Original kept-block index → position in the fill-reducing order.
    rank: Vec<usize>,
    /// Where each factor's terms go when the system is filled.
    assembly: AssemblyPlan,
    /// How the Schur complement is split over threads (empty: one thread).
    schur: SchurPlan,
    factor: Option<SparseFactor>,
    /// Buffers of [`Structure::reduce`], reused from solve to solve (large
    /// ones are otherwise returned to the OS and page-faulted back each time).
    scratch: ReduceBuffers,
    /// Per factor with constant JᵀJ: its kept-pair entries, in the order
    /// [`Structure::assemble_into`] adds them (empty until first formed).
    hessian_cache: Vec<Vec<f64>>,
}

/// What [`Structure::reduce`] leaves behind besides the reduced gradient.
#[derive(Default)]
pub(crate) struct ReduceBuffers {
    /// The reduced (damped, Schur-complemented) H, as [`System::h`].
    pub h: Vec<f64>,
    /// The damped inverse of every eliminated block, laid out as [`System::hll`].
    pub elim_inv: Vec<f64>,
    /// `W = H_cl H_ll⁻¹` of every eliminated block, laid out as [`System::hcl`]
    /// (used by the parallel Schur complement only).
    pub w: Vec<f64>,
}

/// Fill-reducing order of the kept blocks: AMD on the block graph (including
/// the fill the Schur complement of eliminated blocks creates). Returns the
/// rank of each block.
fn block_amd(nk: usize, factor_roles: &[Roles]) -> Vec<usize> {
    let mut adj: Vec<Vec<usize>> = vec![Vec::new(); nk];
    let mut elim_nbrs: Vec<Vec<usize>> = Vec::new();
    let mut kept = Vec::new();
    for roles in factor_roles {
        kept.clear();
        kept.extend(roles.iter().filter_map(|r| if let Role::Kept(b) = r { Some(*b) } else { None }));
        for &a in &kept {
            adj[a].extend(kept.iter().copied().filter(|&b| b != a));
        }
        for r in roles {
            if let Role::Elim(e) = r {
                if elim_nbrs.len() <= *e {
                    elim_nbrs.resize_with(e + 1, Vec::new);
                }
                elim_nbrs[*e].extend_from_slice(&kept);
            }
        }
    }
    for nb in &mut elim_nbrs {
        nb.sort_unstable();
        nb.dedup();
        for &a in nb.iter() {
            adj[a].extend(nb.iter().copied().filter(|&b| b != a));
        }
    }
    for a in &mut adj {
        a.sort_unstable();
        a.dedup();
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
///
/// The eliminated blocks live in flat buffers (no allocation per landmark and
/// iteration): block `e` of dimension `d` has H_ll at `hll[hll_offsets[e]..]`
/// (d × d, column-major), g_l at `gl[elim_offsets[e] − n..]` and, per
/// neighbouring kept block in slot order, H_cl (d_cam × d, column-major) from
/// `hcl[hcl_offsets[e]..]`.
#[derive(Default)]
pub(crate) struct System {
    /// Upper-triangular CSC values of H over kept blocks.
    pub h: Vec<f64>,
    /// Gradient over kept blocks.
    pub g: Vec<f64>,
    /// H_ll of every eliminated block.
    pub hll: Vec<f64>,
    /// g_l of every eliminated block (the gradient's eliminated part).
    pub gl: Vec<f64>,
    /// H_cl of every eliminated block's kept neighbours.
    pub hcl: Vec<f64>,
}

impl Layout {
    /// The linear system's structure for this layout (`vars` in the layout's key order).
    pub(crate) fn structure(
        &self,
        vars: &[Box<dyn DynVariable>],
        solver: LinearSolver,
    ) -> Result<Structure, SolveError> {
        let kept_dims = self.kept_vars.iter().map(|&v| vars[v].dim()).collect();
        let elim_dims = self.elim_vars.iter().map(|&v| vars[v].dim()).collect();
        let factor_roles: Vec<Roles> =
            self.factor_vars.iter().map(|fv| fv.iter().map(|&v| self.roles[v]).collect()).collect();
        let mut s = Structure::new(kept_dims, elim_dims, &factor_roles, solver)?;
        s.set_constant_hessians(&self.constant_hessian);
        Ok(s)
    }
}

/// The block pattern of the reduced system's upper triangle: per column
/// block its row blocks (sorted, ≤ the column), and per eliminated block the
/// kept blocks it connects (which its Schur complement fills in).
struct BlockPattern {
    cols: Vec<Vec<usize>>,
    elim_cams: Vec<Vec<usize>>,
    /// Pair (j, i), i ≤ j, has id `first_pair[j] + position of i in cols[j]`.
    first_pair: Vec<usize>,
}

impl BlockPattern {
    fn new(nk: usize, n_elim: usize, factor_roles: &[Roles]) -> Result<BlockPattern, SolveError> {
        let mut cols: Vec<Vec<usize>> = (0..nk).map(|b| vec![b]).collect();
        let mut elim_cams: Vec<Vec<usize>> = vec![Vec::new(); n_elim];
        for (fi, roles) in factor_roles.iter().enumerate() {
            let kept = roles.iter().filter_map(|r| if let Role::Kept(b) = r { Some(*b) } else { None });
            for a in kept.clone() {
                for b in kept.clone() {
                    if a > b {
                        cols[a].push(b);
                    }
                }
            }
            let mut elims = roles.iter().filter_map(|r| if let Role::Elim(e) = r { Some(*e) } else { None });
            let first = elims.next();
            if first.is_some() && elims.next().is_some() {
                return Err(SolveError::Config(format!(
                    "factor {fi} connects {} eliminated (landmark) variables; Schur elimination needs at most one per factor",
                    roles.iter().filter(|r| matches!(r, Role::Elim(_))).count()
                )));
            }
            if let Some(e) = first {
                for a in kept {
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
                        cols[a].push(b);
                    }
                }
            }
        }
        for c in &mut cols {
            c.sort_unstable();
            c.dedup();
        }
        let mut first_pair = Vec::with_capacity(nk + 1);
        let mut np = 0;
        for c in &cols {
            first_pair.push(np);
            np += c.len();
        }
        first_pair.push(np);
        Ok(BlockPattern { cols, elim_cams, first_pair })
    }

    fn pair_id(&self, j: usize, i: usize) -> usize {
        self.first_pair[j] + self.cols[j].binary_search(&i).expect("pair in the block pattern")
    }

    /// The scalar CSC pattern of the upper triangle (column pointers, row
    /// indices), each pair's `(big, small, base)` and the bases (`bases[b0 +
    /// r]` is the position of row `offset(small)` in column `offset(big) + r`;
    /// pair (big, small) lives in the columns of `big`), and the positions of
    /// the diagonal entries.
    fn scalar_pattern(&self, kept_dims: &[usize], kept_offsets: &[usize]) -> ScalarPattern {
        let n = *kept_offsets.last().unwrap_or(&0);
        let mut p = ScalarPattern {
            col_ptr: Vec::with_capacity(n + 1),
            row_idx: Vec::new(),
            pairs: Vec::with_capacity(*self.first_pair.last().unwrap_or(&0)),
            bases: Vec::new(),
            diag_positions: vec![0; n],
        };
        for (j, rows) in self.cols.iter().enumerate() {
            let first_base = p.bases.len();
            for &i in rows {
                p.pairs.push((j, i, p.bases.len()));
                p.bases.extend(std::iter::repeat_n(0, kept_dims[j]));
            }
            for c in 0..kept_dims[j] {
                p.col_ptr.push(p.row_idx.len());
                for (slot, &i) in rows.iter().enumerate() {
                    p.bases[first_base + slot * kept_dims[j] + c] = p.row_idx.len();
                    if i == j {
                        p.diag_positions[kept_offsets[j] + c] = p.row_idx.len() + c;
                        p.row_idx.extend(kept_offsets[j]..=kept_offsets[j] + c);
                    } else {
                        p.row_idx.extend(kept_offsets[i]..kept_offsets[i + 1]);
                    }
                }
            }
        }
        p.col_ptr.push(p.row_idx.len());
        p
    }

    /// Each factor's plan: its kept blocks, the pairs its JᵀJ adds to, and its
    /// eliminated block's slots in the camera–landmark blocks (`hcl_offsets`).
    fn factor_plans(
        &self,
        factor_roles: &[Roles],
        kept_dims: &[usize],
        elim_dims: &[usize],
        hcl_offsets: &[usize],
    ) -> Vec<FactorPlan> {
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
                        plan.pairs.push((p, q, self.pair_id(bp, bq)));
                    }
                }
            }
            for (p, r) in roles.iter().enumerate() {
                if let Role::Elim(e) = r {
                    let d = elim_dims[*e];
                    let slots = plan
                        .kept
                        .iter()
                        .map(|&(q, bq)| {
                            let cams = &self.elim_cams[*e];
                            let slot = cams.iter().position(|&c| c == bq).unwrap_or(0);
                            (q, hcl_offsets[*e] + cams[..slot].iter().map(|&c| kept_dims[c] * d).sum::<usize>())
                        })
                        .collect();
                    plan.elim = Some(ElimPlan { pos: p, block: *e, slots });
                }
            }
            plans.push(plan);
        }
        plans
    }

    /// Per eliminated block, the pairs of kept blocks its Schur complement
    /// adds to: `(slot a, slot b, pair id)`.
    fn elim_pairs(&self) -> Vec<Vec<(usize, usize, usize)>> {
        self.elim_cams
            .iter()
            .map(|cams| {
                let mut v = Vec::new();
                for (sa, &a) in cams.iter().enumerate() {
                    for (sb, &b) in cams.iter().enumerate() {
                        if a >= b {
                            v.push((sa, sb, self.pair_id(a, b)));
                        }
                    }
                }
                v
            })
            .collect()
    }
}

/// See [`BlockPattern::scalar_pattern`].
struct ScalarPattern {
    col_ptr: Vec<usize>,
    row_idx: Vec<usize>,
    pairs: Vec<(usize, usize, usize)>,
    bases: Vec<usize>,
    diag_positions: Vec<usize>,
}

/// Offsets of running sums of `sizes`, with the total last.
fn offsets(sizes: impl Iterator<Item = usize>) -> Vec<usize> {
    let mut out = vec![0];
    for s in sizes {
        out.push(out[out.len() - 1] + s);
    }
    out
}

impl Structure {
    /// Build the structure. `factor_roles[f]` gives the role of each key position of factor f.
    pub fn new(
        kept_dims: Vec<usize>,
        elim_dims: Vec<usize>,
        factor_roles: &[Roles],
        solver: LinearSolver,
    ) -> Result<Self, SolveError> {
        let nk = kept_dims.len();
        let n: usize = kept_dims.iter().sum();
        let dense = match solver {
            LinearSolver::DenseCholesky => true,
            LinearSolver::SparseCholesky => false,
            LinearSolver::Auto => n <= DENSE_THRESHOLD,
        };
        // A dense factorization does not care about the order.
        let rank = if dense { (0..nk).collect() } else { block_amd(nk, factor_roles) };
        let mut dims_new = vec![0; nk];
        for (b, &d) in kept_dims.iter().enumerate() {
            dims_new[rank[b]] = d;
        }
        let kept_dims = dims_new;
        let remapped: Vec<Roles> = factor_roles
            .iter()
            .map(|roles| roles.iter().map(|r| if let Role::Kept(b) = r { Role::Kept(rank[*b]) } else { *r }).collect())
            .collect();
        let kept_offsets = offsets(kept_dims.iter().copied());
        let pattern = BlockPattern::new(nk, elim_dims.len(), &remapped)?;
        let ScalarPattern { col_ptr, row_idx, pairs, bases, diag_positions } =
            pattern.scalar_pattern(&kept_dims, &kept_offsets);
        let hll_offsets = offsets(elim_dims.iter().map(|d| d * d));
        let hcl_offsets = offsets(
            pattern.elim_cams.iter().zip(&elim_dims).map(|(cams, &d)| cams.iter().map(|&c| kept_dims[c] * d).sum()),
        );
        let plans = pattern.factor_plans(&remapped, &kept_dims, &elim_dims, &hcl_offsets);
        let elim_pairs = pattern.elim_pairs();
        let elim_offsets = offsets(elim_dims.iter().copied()).iter().take(elim_dims.len()).map(|o| o + n).collect();
        let mut s = Structure {
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
            elim_cams: pattern.elim_cams,
            elim_pairs,
            hll_offsets,
            hcl_offsets,
            dense,
            rank,
            factor: None,
            scratch: ReduceBuffers::default(),
            hessian_cache: Vec::new(),
            assembly: AssemblyPlan::default(),
            schur: SchurPlan::default(),
        };
        s.assembly = AssemblyPlan::new(&s);
        s.schur = SchurPlan::new(&s);
        Ok(s)
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

    /// The rows of pair `pair`'s block in `h`: `(r, position of the row's
    /// first entry, entries stored)` for each row `r` of the bigger block —
    /// all the smaller block's columns, or `r + 1` on a diagonal block (upper triangle).
    #[inline]
    fn pair_rows(&self, pair: usize) -> impl Iterator<Item = (usize, usize, usize)> + '_ {
        let (i, j, b0) = self.pairs[pair];
        let cols = self.kept_dims[j];
        (0..self.kept_dims[i]).map(move |r| (r, self.bases[b0 + r], if i == j { r + 1 } else { cols }))
    }

    /// faer's dense Cholesky of the reduced system: the lower factor L (H = L Lᵀ),
    /// blocked and vectorized, several times faster than nalgebra's on the
    /// 100–200 unknowns of a VIO window. Always sequential (`Par::Seq`): with
    /// faer's `rayon` feature on (a dependent crate may turn it on) faer's
    /// default would spread a 150×150 factorization over every thread.
    fn dense_cholesky(&self, h: &[f64]) -> Option<faer::Mat<f64>> {
        use faer::linalg::cholesky::llt::factor::{cholesky_in_place, cholesky_in_place_scratch};
        let mut m = faer::Mat::<f64>::zeros(self.n, self.n);
        for c in 0..self.n {
            for (&r, &v) in
                self.row_idx[self.col_ptr[c]..self.col_ptr[c + 1]].iter().zip(&h[self.col_ptr[c]..self.col_ptr[c + 1]])
            {
                let (i, j) = if r >= c { (r, c) } else { (c, r) };
                m[(i, j)] = v;
            }
        }
        let mut mem =
            MemBuffer::try_new(cholesky_in_place_scratch::<f64>(self.n, Par::Seq, Default::default())).ok()?;
        let reg = LltRegularization::default();
        cholesky_in_place(m.as_mut(), reg, Par::Seq, MemStack::new(&mut mem), Default::default()).ok()?;
        Some(m)
    }

    /// Solve L Lᵀ X = B in place (B's columns), L from [`Self::dense_cholesky`].
    fn dense_solve(l: &faer::Mat<f64>, rhs: faer::MatMut<'_, f64>) {
        // The triangular solves need no scratch memory (their scratch request is empty).
        faer::linalg::cholesky::llt::solve::solve_in_place_with_conj(
            l.as_ref(),
            Conj::No,
            rhs,
            Par::Seq,
            MemStack::new(&mut []),
        );
    }

    /// Diagonal of H over kept unknowns followed by eliminated ones.
    pub fn diagonal(&self, sys: &System) -> Vec<f64> {
        let mut d: Vec<f64> = self.diag_positions.iter().map(|&p| sys.h[p]).collect();
        for (e, &de) in self.elim_dims.iter().enumerate() {
            let o = self.hll_offsets[e];
            d.extend((0..de).map(|k| sys.hll[o + k * (de + 1)]));
        }
        d
    }

    /// Slot ranges of eliminated block `e`'s H_cl blocks: (kept block, offset, length).
    fn elim_slots(&self, e: usize) -> impl Iterator<Item = (usize, usize, usize)> + '_ {
        let d = self.elim_dims[e];
        self.elim_cams[e].iter().scan(self.hcl_offsets[e], move |o, &c| {
            let here = *o;
            *o += self.kept_dims[c] * d;
            Some((c, here, self.kept_dims[c] * d))
        })
    }

    /// Solve `(H + diag(damping)) δ = −g`; δ over kept unknowns then eliminated ones.
    /// Returns `(δ, factorize_seconds, solve_seconds, build_seconds)`.
    pub fn solve(&mut self, sys: &System, damping: Option<&[f64]>) -> Result<(Vec<f64>, f64, f64, f64), SolveError> {
        let t_build = std::time::Instant::now();
        let mut buf = std::mem::take(&mut self.scratch);
        let g = self.reduce(sys, damping, &mut buf)?;
        let (h, elim_inv) = (&buf.h, &buf.elim_inv);
        let build_s = t_build.elapsed().as_secs_f64();

        let t_fact = std::time::Instant::now();
        let mut x: Vec<f64> = g.iter().map(|v| -v).collect();
        let mut fact_s = 0.0;
        let mut solve_s = 0.0;
        if self.n == 0 {
        } else if self.dense {
            let l = self.dense_cholesky(h).ok_or_else(|| SolveError::Singular("dense Cholesky failed".into()))?;
            fact_s = t_fact.elapsed().as_secs_f64();
            let t_solve = std::time::Instant::now();
            Self::dense_solve(&l, faer::MatMut::from_column_major_slice_mut(&mut x, self.n, 1));
            solve_s = t_solve.elapsed().as_secs_f64();
        } else {
            if self.factor.is_none() {
                self.factor = Some(SparseFactor::new(self.n, &self.col_ptr, &self.row_idx)?);
            }
            let factor = self.factor.as_mut().expect("set above");
            let mut rhs = faer::Mat::<f64>::from_fn(self.n, 1, |i, _| x[i]);
            let (fs, ss) = factor.factor_solve(h, rhs.as_mut())?;
            fact_s = fs;
            solve_s = ss;
            for (i, xi) in x.iter_mut().enumerate() {
                *xi = rhs[(i, 0)];
            }
        }
        // Back-substitution for eliminated blocks: δ_l = −H_ll⁻¹ (g_l + Σ H_lc δ_c).
        let t_back = std::time::Instant::now();
        let mut rhs = Vec::new();
        for (e, &d) in self.elim_dims.iter().enumerate() {
            let go = self.elim_offsets[e] - self.n;
            rhs.clear();
            rhs.extend_from_slice(&sys.gl[go..go + d]);
            for (c, off, len) in self.elim_slots(e) {
                let o = self.kept_offsets[c];
                let dc = self.kept_dims[c];
                for (b, col) in sys.hcl[off..off + len].chunks_exact(dc).enumerate() {
                    rhs[b] += dot(col, &x[o..o + dc]);
                }
            }
            let inv = &elim_inv[self.hll_offsets[e]..self.hll_offsets[e + 1]];
            for a in 0..d {
                x.push(-(0..d).map(|b| inv[a + b * d] * rhs[b]).sum::<f64>());
            }
        }
        if x.iter().any(|v| !v.is_finite()) {
            return Err(SolveError::Singular("non-finite step".into()));
        }
        self.scratch = buf;
        Ok((x, fact_s, solve_s + t_back.elapsed().as_secs_f64(), build_s))
    }

    /// `Hδ` for the predicted decrease, over kept then eliminated unknowns (undamped H).
    pub fn h_times(&self, sys: &System, x: &[f64]) -> Vec<f64> {
        let mut y = vec![0.0; x.len()];
        for pair in 0..self.pairs.len() {
            match self.kept_dims[self.pairs[pair].1] {
                3 => self.pair_times(pair, 3, &sys.h, x, &mut y),
                6 => self.pair_times(pair, 6, &sys.h, x, &mut y),
                d => self.pair_times(pair, d, &sys.h, x, &mut y),
            }
        }
        if self.h_times_elim_parallel(sys, x, &mut y) {
            return y;
        }
        for (e, &d) in self.elim_dims.iter().enumerate() {
            self.h_times_elim_block(e, d, sys, x, &mut y[self.elim_offsets[e]..self.elim_offsets[e] + d]);
            let off = self.elim_offsets[e];
            for (c, o, len) in self.elim_slots(e) {
                let (oc, dc) = (self.kept_offsets[c], self.kept_dims[c]);
                // y_c += H_cl x_l.
                for (b, col) in sys.hcl[o..o + len].chunks_exact(dc).enumerate() {
                    for (k, &v) in col.iter().enumerate() {
                        y[oc + k] += v * x[off + b];
                    }
                }
            }
        }
        y
    }

    /// Pair block `pair` of the upper triangle `h` and its mirror times `x`,
    /// added to `y`; `small` is the dimension of its smaller block (a literal
    /// at the hot call sites: the runs of the column-wise storage unroll).
    /// Each column of the block is one contiguous run: a dot product for the
    /// column's own row of Hx, an axpy for the mirror's rows.
    #[inline(always)]
    fn pair_times(&self, pair: usize, small: usize, h: &[f64], x: &[f64], y: &mut [f64]) {
        let (big, smaller, _) = self.pairs[pair];
        let (ob, os) = (self.kept_offsets[big], self.kept_offsets[smaller]);
        for (r, base, n) in self.pair_rows(pair) {
            let run = &h[base..base + n];
            let n_rows = if big == smaller { n } else { small };
            let xs = &x[os..os + n_rows];
            y[ob + r] += dot(run, xs);
            // A diagonal block's run ends at its diagonal entry, counted once above.
            let mirrored = if big == smaller { r } else { n_rows };
            let xr = x[ob + r];
            for (yk, v) in y[os..os + mirrored].iter_mut().zip(run) {
                *yk += v * xr;
            }
        }
    }

    /// Eliminated block `e`'s rows of `Hδ` into `y` (its `d` entries):
    /// `H_ll x_l`, then `H_clᵀ x_c` slot after slot.
    pub(super) fn h_times_elim_block(&self, e: usize, d: usize, sys: &System, x: &[f64], y: &mut [f64]) {
        let (off, ho) = (self.elim_offsets[e], self.hll_offsets[e]);
        let hll = &sys.hll[ho..ho + d * d];
        for a in 0..d {
            y[a] += (0..d).map(|b| hll[a + b * d] * x[off + b]).sum::<f64>();
        }
        for (c, o, len) in self.elim_slots(e) {
            let (oc, dc) = (self.kept_offsets[c], self.kept_dims[c]);
            for (b, col) in sys.hcl[o..o + len].chunks_exact(dc).enumerate() {
                y[b] += dot(col, &x[oc..oc + dc]);
            }
        }
    }

    /// Selected columns of H⁻¹ over kept unknowns. With eliminated blocks, the
    /// inverse of their Schur complement: the same columns of the full inverse.
    pub fn inverse_columns(&mut self, sys: &System, cols: &[usize]) -> Result<DMatrix<f64>, SolveError> {
        let mut buf = ReduceBuffers::default();
        self.reduce(sys, None, &mut buf)?;
        let h = buf.h;
        let mut out = DMatrix::zeros(self.n, cols.len());
        if self.dense || self.n == 0 {
            if self.n == 0 {
                return Ok(out);
            }
            let l =
                self.dense_cholesky(&h).ok_or_else(|| SolveError::Singular("information matrix is singular".into()))?;
            let mut rhs = faer::Mat::<f64>::from_fn(self.n, cols.len(), |i, j| if i == cols[j] { 1.0 } else { 0.0 });
            Self::dense_solve(&l, rhs.as_mut());
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
            .factor_solve(&h, rhs.as_mut())
            .map_err(|_| SolveError::Singular("information matrix is singular (unobservable variables?)".into()))?;
        for j in 0..cols.len() {
            for i in 0..self.n {
                out[(i, j)] = rhs[(i, j)];
            }
        }
        Ok(out)
    }
}

/// Dot product of two equally long slices.
#[inline]
fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

#[cfg(test)]
mod tests {
    use super::{LinearSolver, Role, Roles, Structure, System};

    /// `h_times` against the dense symmetric matrix its upper triangle
    /// stands for, on blocks of 1, 2, 3 and 6 dimensions linked in a ring
    /// and across it (off-diagonal blocks of every shape).
    #[test]
    fn h_times_equals_the_dense_product() {
        let dims = vec![6, 3, 1, 6, 2, 3, 6, 1];
        let nb = dims.len();
        let mut roles: Vec<Roles> =
            (0..nb).map(|b| smallvec::smallvec![Role::Kept(b), Role::Kept((b + 1) % nb)]).collect();
        roles.extend((0..nb / 2).map(|b| -> Roles { smallvec::smallvec![Role::Kept(b), Role::Kept(b + nb / 2)] }));
        let s = Structure::new(dims, Vec::new(), &roles, LinearSolver::SparseCholesky).unwrap();
        let n = s.n;
        let h: Vec<f64> = (0..s.nnz()).map(|k| ((k * 37 % 101) as f64 - 50.0) / 7.0).collect();
        let mut dense = vec![0.0; n * n];
        for c in 0..n {
            let range = s.col_ptr[c]..s.col_ptr[c + 1];
            for (&r, &v) in s.row_idx[range.clone()].iter().zip(&h[range]) {
                dense[r + c * n] = v;
                dense[c + r * n] = v;
            }
        }
        let x: Vec<f64> = (0..n).map(|i| ((i * 13 % 17) as f64 - 8.0) / 3.0).collect();
        let sys = System { h, g: vec![0.0; n], ..System::default() };
        let y = s.h_times(&sys, &x);
        for (i, yi) in y.iter().enumerate() {
            let expected: f64 = (0..n).map(|c| dense[i + c * n] * x[c]).sum();
            assert!((yi - expected).abs() <= 1e-12 * (1.0 + expected.abs()), "row {i}: {yi} vs {expected}");
        }
    }
}
