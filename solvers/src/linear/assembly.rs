//! Filling the normal equations from whitened linearizations, in parallel over
//! disjoint parts of the system, with results bit-identical to one thread.
//!
//! The kept blocks are cut into a fixed number of chunks of consecutive blocks
//! (and the eliminated blocks likewise). A chunk owns its slices of H, g (or of
//! H_ll, g_l, H_cl) and the list of factor terms landing in them, sorted by
//! factor: every entry receives its terms in factor order, whatever the number
//! of threads. The cut depends on the structure only, never on the threads.

use super::{dot, ElimPlan, Structure, System};
use crate::linearized::{split_at_ends, Linearized};
use nalgebra::SMatrix;
use rayon::prelude::*;
use std::ops::Range;

/// Factors below which the assembly runs on the calling thread, in one chunk:
/// a VIO window's few hundred factors cost less than waking the thread pool.
/// Below it a solve does not keep the pool awake either
/// ([`crate::LmOptions::keep_threads_awake`]): its passes are too short.
pub(crate) const PARALLEL_MIN_FACTORS: usize = 4096;
/// Chunks each part of the system is cut into when it is filled in parallel.
pub(super) const CHUNKS: usize = 64;

/// One factor's term landing in a kept chunk.
#[derive(Clone, Copy, Debug)]
enum KeptTerm {
    /// `g_b += J_pᵀ r` for entry `k` = (p, b) of the factor's plan `kept`.
    Grad { factor: usize, k: usize },
    /// `H_pq += J_pᵀ J_q` for entry `k` of the factor's plan `pairs`, whose
    /// entries start at `entry_off` in the factor's cached JᵀJ.
    Pair { factor: usize, k: usize, entry_off: usize },
}

/// Consecutive kept blocks and the factor terms landing in them, by factor
/// (one pass over the linearizations, whose Jacobians are read once).
#[derive(Debug)]
struct KeptChunk {
    blocks: Range<usize>,
    terms: Vec<KeptTerm>,
}

/// Consecutive eliminated blocks and the factors touching them, in order.
#[derive(Debug)]
struct ElimChunk {
    blocks: Range<usize>,
    factors: Vec<usize>,
}

/// Where every factor term goes, chunk by chunk: built once per structure.
#[derive(Debug, Default)]
pub(super) struct AssemblyPlan {
    kept: Vec<KeptChunk>,
    elim: Vec<ElimChunk>,
}

/// Cut blocks with these amounts of work into about `chunks` (at most one
/// more) ranges of consecutive blocks of about equal work.
pub(super) fn cut(work: &[usize], chunks: usize) -> Vec<Range<usize>> {
    if chunks <= 1 {
        return std::iter::once(0..work.len()).collect();
    }
    let target = work.iter().sum::<usize>().div_ceil(chunks).max(1);
    let mut out = Vec::new();
    let (mut start, mut acc) = (0, 0);
    for (b, w) in work.iter().enumerate() {
        acc += w;
        if acc >= target {
            out.push(start..b + 1);
            (start, acc) = (b + 1, 0);
        }
    }
    if start < work.len() || out.is_empty() {
        out.push(start..work.len());
    }
    out
}

/// Which range of `cut` each block is in.
pub(super) fn chunk_index(ranges: &[Range<usize>], n: usize) -> Vec<usize> {
    let mut idx = vec![0; n];
    for (c, r) in ranges.iter().enumerate() {
        idx[r.clone()].fill(c);
    }
    idx
}

/// Stored entries of pair block (big, small) of the upper triangle.
fn pair_entries(d_big: usize, d_small: usize, diagonal: bool) -> usize {
    if diagonal {
        d_big * (d_big + 1) / 2
    } else {
        d_big * d_small
    }
}

impl AssemblyPlan {
    /// The plan for `s`'s factors (its `plans` and block layout set).
    pub(super) fn new(s: &Structure) -> Self {
        let (nk, ne) = (s.kept_dims.len(), s.elim_dims.len());
        // One chunk (the factors in order, streamed through the caches) unless
        // the graph is big. The kept part of a bundle adjustment (each camera's
        // diagonal block, from hundreds of factors scattered over the list) is
        // slower cut by destination than streamed: it stays in one chunk.
        let (kranges, eranges) = if s.plans.len() < PARALLEL_MIN_FACTORS {
            (std::iter::once(0..nk).collect(), std::iter::once(0..ne).collect())
        } else {
            let (mut kwork, mut ework) = (vec![0; nk], vec![0; ne]);
            for plan in &s.plans {
                for &(_, _, pair) in &plan.pairs {
                    kwork[s.pairs[pair].0] += 1;
                }
                for &(_, b) in &plan.kept {
                    kwork[b] += 1;
                }
                if let Some(ep) = &plan.elim {
                    ework[ep.block] += 1 + ep.slots.len();
                }
            }
            (cut(&kwork, if ne == 0 { CHUNKS } else { 1 }), cut(&ework, CHUNKS))
        };
        let (kidx, eidx) = (chunk_index(&kranges, nk), chunk_index(&eranges, ne));
        let mut kept: Vec<KeptChunk> =
            kranges.into_iter().map(|blocks| KeptChunk { blocks, terms: Vec::new() }).collect();
        let mut elim: Vec<ElimChunk> =
            eranges.into_iter().map(|blocks| ElimChunk { blocks, factors: Vec::new() }).collect();
        for (fi, plan) in s.plans.iter().enumerate() {
            for (k, &(_, b)) in plan.kept.iter().enumerate() {
                kept[kidx[b]].terms.push(KeptTerm::Grad { factor: fi, k });
            }
            let mut entry_off = 0;
            for (k, &(_, _, pair)) in plan.pairs.iter().enumerate() {
                let (i, j, _) = s.pairs[pair];
                kept[kidx[i]].terms.push(KeptTerm::Pair { factor: fi, k, entry_off });
                entry_off += pair_entries(s.kept_dims[i], s.kept_dims[j], i == j);
            }
            if let Some(ep) = &plan.elim {
                elim[eidx[ep.block]].factors.push(fi);
            }
        }
        AssemblyPlan { kept, elim }
    }
}

/// `g += Jᵀ r` for a Jacobian `j` of `m` rows (column-major) and its residual `r`.
#[inline(always)]
fn add_jtr(g: &mut [f64], j: &[f64], r: &[f64], m: usize) {
    for (gk, col) in g.iter_mut().zip(j.chunks_exact(m)) {
        *gk += dot(col, r);
    }
}

impl Structure {
    /// Each entry of `J_bigᵀ J_small` stored for pair `pair`, as (position in
    /// H, value), row by row; `m` is the Jacobians' row count (a literal at the
    /// hot call sites, so the column dot products unroll).
    #[inline(always)]
    fn jtj_visit(&self, pair: usize, big: &[f64], small: &[f64], m: usize, mut f: impl FnMut(usize, f64)) {
        for (r, base, n) in self.pair_rows(pair) {
            let cr = &big[r * m..(r + 1) * m];
            for (c, cs) in small.chunks_exact(m).take(n).enumerate() {
                f(base + c, dot(cr, cs));
            }
        }
    }

    /// `H_(big, small) += J_bigᵀ J_small` into `h`, which starts at position `h0` of H.
    #[inline(always)]
    fn add_jtj(&self, h: &mut [f64], h0: usize, pair: usize, big: &[f64], small: &[f64], m: usize) {
        self.jtj_visit(pair, big, small, m, |pos, v| h[pos - h0] += v);
    }

    /// [`Structure::add_jtj`] for square M × M Jacobian blocks (a pose-graph
    /// edge between two poses of the residual's dimension): the block is one
    /// fixed-size product, vectorized, instead of M² dot products.
    #[inline(always)]
    fn add_jtj_square<const M: usize>(&self, h: &mut [f64], h0: usize, pair: usize, big: &[f64], small: &[f64]) {
        let product =
            SMatrix::<f64, M, M>::from_column_slice(big).transpose() * SMatrix::<f64, M, M>::from_column_slice(small);
        for (r, base, n) in self.pair_rows(pair) {
            for (c, hv) in h[base - h0..base - h0 + n].iter_mut().enumerate() {
                *hv += product[(r, c)];
            }
        }
    }

    /// Mark the factors whose JᵀJ never changes (see [`crate::Factor::constant_jacobians`]).
    pub fn set_constant_hessians(&mut self, constant: &[bool]) {
        for (plan, &c) in self.plans.iter_mut().zip(constant) {
            plan.constant = c;
        }
        self.hessian_cache = vec![Vec::new(); self.plans.len()];
    }

    /// The kept-pair entries of a factor's JᵀJ, pair after pair in plan order,
    /// each in the order `add_jtj` visits it.
    fn jtj_entries(&self, lins: &Linearized, fi: usize) -> Vec<f64> {
        let mut out = Vec::new();
        let m = lins.residual(fi).len();
        for &(p, q, pair) in &self.plans[fi].pairs {
            self.jtj_visit(pair, lins.jacobian(fi, p), lins.jacobian(fi, q), m, |_, v| out.push(v));
        }
        out
    }

    /// Accumulate `H = Σ JᵀJ`, `g = Σ Jᵀr` from whitened linearizations.
    pub(crate) fn assemble(&mut self, lins: &Linearized) -> System {
        let mut sys = System::default();
        self.assemble_into(lins, &mut sys);
        sys
    }

    /// As [`Structure::assemble`], reusing the buffers of `sys` (large `h`
    /// buffers are otherwise returned to the OS and page-faulted back every iteration).
    pub(crate) fn assemble_into(&mut self, lins: &Linearized, sys: &mut System) {
        fn zeroed(v: &mut Vec<f64>, n: usize) {
            v.clear();
            v.resize(n, 0.0);
        }
        zeroed(&mut sys.h, self.nnz());
        zeroed(&mut sys.g, self.n);
        zeroed(&mut sys.hll, *self.hll_offsets.last().unwrap_or(&0));
        zeroed(&mut sys.gl, self.elim_dims.iter().sum());
        zeroed(&mut sys.hcl, *self.hcl_offsets.last().unwrap_or(&0));
        // Constant JᵀJ: formed at the first assembly, added from the cache after.
        let mut cache = std::mem::take(&mut self.hessian_cache);
        for (fi, c) in cache.iter_mut().enumerate() {
            let m = lins.residual(fi).len();
            if self.plans[fi].constant && c.is_empty() && m > 0 {
                *c = self.jtj_entries(lins, fi);
            }
        }
        self.hessian_cache = cache;
        let this = &*self;
        let plan = &self.assembly;
        let System { h, g, hll, gl, hcl } = sys;

        let hs = split_at_ends(h, plan.kept.iter().map(|c| this.col_ptr[this.kept_offsets[c.blocks.end]]));
        let gs = split_at_ends(g, plan.kept.iter().map(|c| this.kept_offsets[c.blocks.end]));
        let kept_job = |(c, (h, g)): (&KeptChunk, (&mut [f64], &mut [f64]))| this.assemble_kept(c, lins, h, g);
        if plan.kept.len() > 1 {
            plan.kept.par_iter().zip(hs.into_par_iter().zip(gs)).for_each(kept_job);
        } else {
            plan.kept.iter().zip(hs.into_iter().zip(gs)).for_each(kept_job);
        }

        if self.elim_dims.is_empty() {
            return;
        }
        let hlls = split_at_ends(hll, plan.elim.iter().map(|c| this.hll_offsets[c.blocks.end]));
        let gls = split_at_ends(gl, plan.elim.iter().map(|c| this.elim_start(c.blocks.end)));
        let hcls = split_at_ends(hcl, plan.elim.iter().map(|c| this.hcl_offsets[c.blocks.end]));
        type ElimParts<'a> = ((&'a mut [f64], &'a mut [f64]), &'a mut [f64]);
        let elim_job = |(c, ((hll, gl), hcl)): (&ElimChunk, ElimParts<'_>)| this.assemble_elim(c, lins, hll, gl, hcl);
        if plan.elim.len() > 1 {
            plan.elim.par_iter().zip(hlls.into_par_iter().zip(gls).zip(hcls)).for_each(elim_job);
        } else {
            plan.elim.iter().zip(hlls.into_iter().zip(gls).zip(hcls)).for_each(elim_job);
        }
    }

    /// Offset in [`System::gl`] of eliminated block `e` (the end for `e` = their number).
    pub(super) fn elim_start(&self, e: usize) -> usize {
        match self.elim_offsets.get(e) {
            Some(o) => o - self.n,
            None => self.elim_offsets.last().map_or(0, |o| o - self.n + self.elim_dims[e - 1]),
        }
    }

    /// One kept chunk's terms into its slices `h` and `g` of H and g.
    fn assemble_kept(&self, chunk: &KeptChunk, lins: &Linearized, h: &mut [f64], g: &mut [f64]) {
        let h0 = self.col_ptr[self.kept_offsets[chunk.blocks.start]];
        let g0 = self.kept_offsets[chunk.blocks.start];
        for &term in &chunk.terms {
            let fi = match term {
                KeptTerm::Grad { factor, .. } | KeptTerm::Pair { factor, .. } => factor,
            };
            let r = lins.residual(fi);
            let m = r.len();
            if m == 0 {
                // E.g. a marginalization prior of rank 0: nothing to add.
                continue;
            }
            let plan = &self.plans[fi];
            match term {
                KeptTerm::Grad { k, .. } => {
                    let (p, b) = plan.kept[k];
                    let o = self.kept_offsets[b] - g0;
                    let j = lins.jacobian(fi, p);
                    // Literal row counts unroll the dot products: reprojections
                    // (2), planar and 3-D pose-graph edges (3, 6).
                    match m {
                        2 => add_jtr(&mut g[o..], j, r, 2),
                        3 => add_jtr(&mut g[o..], j, r, 3),
                        6 => add_jtr(&mut g[o..], j, r, 6),
                        _ => add_jtr(&mut g[o..], j, r, m),
                    }
                }
                KeptTerm::Pair { k, entry_off, .. } => {
                    let (p, q, pair) = plan.pairs[k];
                    match self.hessian_cache.get(fi) {
                        Some(entries) if plan.constant => {
                            let mut e = entry_off;
                            for (_, base, n) in self.pair_rows(pair) {
                                for (hv, x) in h[base - h0..base - h0 + n].iter_mut().zip(&entries[e..e + n]) {
                                    *hv += x;
                                }
                                e += n;
                            }
                        }
                        _ => {
                            let (big, small) = (lins.jacobian(fi, p), lins.jacobian(fi, q));
                            match (m, big.len(), small.len()) {
                                (2, ..) => self.add_jtj(h, h0, pair, big, small, 2),
                                (3, 9, 9) => self.add_jtj_square::<3>(h, h0, pair, big, small),
                                (6, 36, 36) => self.add_jtj_square::<6>(h, h0, pair, big, small),
                                _ => self.add_jtj(h, h0, pair, big, small, m),
                            }
                        }
                    }
                }
            }
        }
    }

    /// One eliminated chunk's factors into its slices of H_ll, g_l and H_cl.
    fn assemble_elim(&self, chunk: &ElimChunk, lins: &Linearized, hll: &mut [f64], gl: &mut [f64], hcl: &mut [f64]) {
        let e0 = chunk.blocks.start;
        let at = (self.hll_offsets[e0], self.elim_start(e0), self.hcl_offsets[e0]);
        for &fi in &chunk.factors {
            let m = lins.residual(fi).len();
            let Some(ep) = &self.plans[fi].elim else { continue };
            // Literal row counts of the common factors unroll the dot products
            // (each arm its own inlined copy).
            match m {
                0 => {}
                2 => self.add_elim_factor(fi, ep, lins, 2, at, (hll, gl, hcl)),
                _ => self.add_elim_factor(fi, ep, lins, m, at, (hll, gl, hcl)),
            }
        }
    }

    /// Factor `fi`'s terms (`m` rows) on its eliminated block into the
    /// chunk's slices of H_ll, g_l and H_cl, which start at `(hll0, gl0, hcl0)`.
    #[inline(always)]
    fn add_elim_factor(
        &self,
        fi: usize,
        ep: &ElimPlan,
        lins: &Linearized,
        m: usize,
        (hll0, gl0, hcl0): (usize, usize, usize),
        (hll, gl, hcl): (&mut [f64], &mut [f64], &mut [f64]),
    ) {
        let r = lins.residual(fi);
        let (ho, go) = (self.hll_offsets[ep.block] - hll0, self.elim_start(ep.block) - gl0);
        let jl = lins.jacobian(fi, ep.pos);
        let d = self.elim_dims[ep.block];
        for (a, ca) in jl.chunks_exact(m).enumerate() {
            gl[go + a] += dot(ca, r);
            for (b, cb) in jl.chunks_exact(m).enumerate() {
                hll[ho + a + b * d] += dot(ca, cb);
            }
        }
        for &(q, off) in &ep.slots {
            let (jq, dc) = (lins.jacobian(fi, q), lins.ncols(fi, q));
            let off = off - hcl0;
            for (b, cb) in jl.chunks_exact(m).enumerate() {
                for (a, ca) in jq.chunks_exact(m).enumerate() {
                    hcl[off + a + b * dc] += dot(ca, cb);
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cut_covers_every_block_once() {
        for (work, chunks) in
            [(vec![], 64), (vec![0; 5], 64), (vec![1; 1000], 64), (vec![5, 0, 0, 300, 1, 1, 1], 3), (vec![1; 10], 1)]
        {
            let r = cut(&work, chunks);
            assert!(!r.is_empty() && r.len() <= chunks + 1);
            assert_eq!(r[0].start, 0);
            assert_eq!(r.last().unwrap().end, work.len());
            assert!(r.windows(2).all(|w| w[0].end == w[1].start));
        }
    }
}
