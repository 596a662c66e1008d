//! The Schur complement: eliminating landmark-like blocks from the normal
//! equations to leave the reduced (camera) system.
//!
//! Each eliminated block `l` is independent of the others given the kept
//! unknowns, so `H_cc − H_cl H_ll⁻¹ H_lc` and `g_c − H_cl H_ll⁻¹ g_l` are sums of
//! one small term per block. The loops are written once for any block size and
//! instantiated for the common sizes (1: inverse depths, 3: points) so the
//! compiler unrolls them; nothing is allocated per block.
//!
//! Big problems run in parallel with results bit-identical to one thread:
//! first every block's inverse and `W = H_cl H_ll⁻¹` (independent per block),
//! then, per chunk of consecutive kept blocks, the terms landing in that
//! chunk's part of H and g in ascending eliminated-block order — the order the
//! one-thread loop applies them in.

use super::assembly::{chunk_index, cut, CHUNKS, PARALLEL_MIN_FACTORS};
use super::{ReduceBuffers, Structure};
use crate::error::SolveError;
use crate::linear::System;
use crate::linearized::split_at_ends;
use rayon::prelude::*;
use std::ops::Range;

/// Largest eliminated block whose row of `W` is kept on the stack.
const MAX_STACK_DIM: usize = 16;

/// Invert the symmetric positive-definite `d × d` matrix `a` (column-major,
/// both triangles) in place by Cholesky: `a = L Lᵀ`, `a⁻¹ = L⁻ᵀ L⁻¹`.
/// Returns false, leaving `a` undefined, when `a` is not positive definite.
#[inline(always)]
fn spd_invert(a: &mut [f64], d: usize) -> bool {
    // L in the lower triangle.
    for j in 0..d {
        let s = a[j + j * d] - (0..j).map(|k| a[j + k * d] * a[j + k * d]).sum::<f64>();
        if !(s > 0.0 && s.is_finite()) {
            return false;
        }
        let ljj = s.sqrt();
        a[j + j * d] = ljj;
        for i in j + 1..d {
            a[i + j * d] = (a[i + j * d] - (0..j).map(|k| a[i + k * d] * a[j + k * d]).sum::<f64>()) / ljj;
        }
    }
    // M = L⁻¹ over L, column by column: column j's rows below j still hold L
    // when they are read, the rows above are already M.
    for j in 0..d {
        a[j + j * d] = 1.0 / a[j + j * d];
        for i in j + 1..d {
            a[i + j * d] = -(j..i).map(|k| a[i + k * d] * a[k + j * d]).sum::<f64>() / a[i + i * d];
        }
    }
    // a⁻¹ = Mᵀ M into the upper triangle, row by row (row r's diagonal last:
    // later rows only read M's columns right of r), then mirrored.
    for r in 0..d {
        for c in (r..d).rev() {
            a[r + c * d] = (c..d).map(|k| a[k + r * d] * a[k + c * d]).sum::<f64>();
        }
    }
    for c in 0..d {
        for r in c + 1..d {
            a[r + c * d] = a[c + r * d];
        }
    }
    true
}

/// Reused buffers of one elimination pass.
#[derive(Default)]
struct Scratch {
    /// `W = H_cl H_ll⁻¹` of the current block's slots, laid out as its H_cl.
    w: Vec<f64>,
    /// Offset of each slot of the current block in `w` (and from its first H_cl).
    slot_offsets: Vec<usize>,
}

/// The parallel Schur complement's work, cut once per structure (empty for
/// small problems, which take the one-thread loop).
#[derive(Debug, Default)]
pub(super) struct SchurPlan {
    /// Consecutive eliminated blocks whose inverses and `W` are formed together.
    elim: Vec<Range<usize>>,
    /// Consecutive kept blocks and the terms landing in their part of H and g.
    kept: Vec<SchurChunk>,
}

/// One chunk of kept blocks: its Schur terms in ascending eliminated block.
#[derive(Debug)]
struct SchurChunk {
    blocks: Range<usize>,
    /// `H_pair −= W_a H_bᵀ`: (eliminated block, offset of slot a in `W`/H_cl,
    /// offset of slot b, pair), with the pair's row block in `blocks`.
    pairs: Vec<(usize, usize, usize, usize)>,
    /// `g_c −= W_s g_l`: (eliminated block, offset of slot s, kept block c in `blocks`).
    grads: Vec<(usize, usize, usize)>,
}

impl SchurPlan {
    /// The plan for `s` (its elimination layout set).
    pub(super) fn new(s: &Structure) -> Self {
        let (nk, ne) = (s.kept_dims.len(), s.elim_dims.len());
        if ne == 0 || s.plans.len() < PARALLEL_MIN_FACTORS {
            return SchurPlan::default();
        }
        let mut kwork = vec![0; nk];
        for pairs in &s.elim_pairs {
            for &(_, _, pair) in pairs {
                kwork[s.pairs[pair].0] += 1;
            }
        }
        let ework: Vec<usize> = s.elim_cams.iter().map(|c| c.len() * c.len()).collect();
        let kranges = cut(&kwork, CHUNKS);
        let kidx = chunk_index(&kranges, nk);
        // Terms per chunk, counted first so that each list is allocated once.
        let (mut npairs, mut ngrads) = (vec![0; kranges.len()], vec![0; kranges.len()]);
        for (pairs, cams) in s.elim_pairs.iter().zip(&s.elim_cams) {
            for &(_, _, pair) in pairs {
                npairs[kidx[s.pairs[pair].0]] += 1;
            }
            for &c in cams {
                ngrads[kidx[c]] += 1;
            }
        }
        let mut kept: Vec<SchurChunk> = kranges
            .into_iter()
            .zip(npairs.into_iter().zip(ngrads))
            .map(|(blocks, (np, ng))| SchurChunk {
                blocks,
                pairs: Vec::with_capacity(np),
                grads: Vec::with_capacity(ng),
            })
            .collect();
        let mut offs = Vec::new();
        for e in 0..ne {
            offs.clear();
            offs.extend(s.elim_slots(e).map(|(_, o, _)| o));
            for &(sa, sb, pair) in &s.elim_pairs[e] {
                kept[kidx[s.pairs[pair].0]].pairs.push((e, offs[sa], offs[sb], pair));
            }
            for (slot, &c) in s.elim_cams[e].iter().enumerate() {
                kept[kidx[c]].grads.push((e, offs[slot], c));
            }
        }
        SchurPlan { elim: cut(&ework, CHUNKS), kept }
    }
}

impl Structure {
    /// The reduced system: `h` ← upper triangle of `H + diag(damping)` over the
    /// kept unknowns minus the Schur complement of the eliminated blocks; returns
    /// the reduced gradient and the eliminated blocks' (damped) inverses, laid
    /// out as [`System::hll`].
    pub(super) fn reduce(
        &self,
        sys: &System,
        damping: Option<&[f64]>,
        buf: &mut ReduceBuffers,
    ) -> Result<Vec<f64>, SolveError> {
        let ReduceBuffers { h, elim_inv, w } = buf;
        h.clear();
        h.extend_from_slice(&sys.h);
        let mut g = sys.g.clone();
        if let Some(d) = damping {
            for (k, &p) in self.diag_positions.iter().enumerate() {
                h[p] += d[k];
            }
        }
        // Every entry is overwritten: the contents may stay from the last call.
        elim_inv.resize(sys.hll.len(), 0.0);
        if !self.schur.kept.is_empty() {
            w.resize(sys.hcl.len(), 0.0);
            self.reduce_parallel(sys, damping, h, &mut g, elim_inv, w)?;
            return Ok(g);
        }
        let mut scratch = Scratch::default();
        for (e, &d) in self.elim_dims.iter().enumerate() {
            // Literal sizes let the compiler unroll the inlined loops (each
            // arm its own copy: through a closure the size stayed a variable).
            let s = &mut scratch;
            match d {
                1 => self.eliminate(e, 1, sys, damping, elim_inv, s, h, &mut g),
                2 => self.eliminate(e, 2, sys, damping, elim_inv, s, h, &mut g),
                3 => self.eliminate(e, 3, sys, damping, elim_inv, s, h, &mut g),
                _ => self.eliminate(e, d, sys, damping, elim_inv, s, h, &mut g),
            }?;
        }
        Ok(g)
    }

    /// Eliminate block `e` of size `d`: its damped inverse into `elim_inv`,
    /// `H_cc −= W H_lc` on every pair of its kept blocks, `g_c −= W g_l`.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn eliminate(
        &self,
        e: usize,
        d: usize,
        sys: &System,
        damping: Option<&[f64]>,
        elim_inv: &mut [f64],
        scratch: &mut Scratch,
        h: &mut [f64],
        g: &mut [f64],
    ) -> Result<(), SolveError> {
        let ho = self.hll_offsets[e];
        let h0 = self.hcl_offsets[e];
        let hcl = &sys.hcl[h0..self.hcl_offsets[e + 1]];
        let Scratch { w, slot_offsets } = scratch;
        w.clear();
        w.resize(hcl.len(), 0.0);
        self.invert_and_w(e, d, sys, damping, &mut elim_inv[ho..ho + d * d], w)?;
        slot_offsets.clear();
        slot_offsets.extend(self.elim_slots(e).map(|(_, o, _)| o - h0));
        slot_offsets.push(hcl.len());
        let slot = |s: usize| slot_offsets[s]..slot_offsets[s + 1];
        for &(sa, sb, pair) in &self.elim_pairs[e] {
            self.sub_w_ht(h, 0, pair, &w[slot(sa)], &hcl[slot(sb)], d);
        }
        for (s, &c) in self.elim_cams[e].iter().enumerate() {
            self.sub_w_g(g, 0, e, c, &w[slot(s)], sys, d);
        }
        Ok(())
    }

    /// Block `e`'s damped inverse into `inv` (`d × d`) and `W = H_cl H_ll⁻¹`
    /// into `w` (laid out as its H_cl: each slot `kept_dim × d`).
    #[inline(always)]
    fn invert_and_w(
        &self,
        e: usize,
        d: usize,
        sys: &System,
        damping: Option<&[f64]>,
        inv: &mut [f64],
        w: &mut [f64],
    ) -> Result<(), SolveError> {
        let (off, ho) = (self.elim_offsets[e], self.hll_offsets[e]);
        inv.copy_from_slice(&sys.hll[ho..ho + d * d]);
        if let Some(dmp) = damping {
            for k in 0..d {
                inv[k * (d + 1)] += dmp[off + k];
            }
        }
        let ok = if d == 1 {
            // Inverse depths: a scalar.
            let ok = inv[0] > 0.0 && inv[0].is_finite();
            inv[0] = 1.0 / inv[0];
            ok
        } else {
            spd_invert(inv, d)
        };
        if !ok {
            return Err(SolveError::Singular(format!("eliminated block {e} is not positive definite")));
        }
        // W_s = H_cl,s H_ll⁻¹ per slot, each `kept_dim × d` like its H_cl.
        let h0 = self.hcl_offsets[e];
        for (_, o, len) in self.elim_slots(e) {
            let (hc, ws) = (&sys.hcl[o..o + len], &mut w[o - h0..o - h0 + len]);
            let dc = len / d;
            for b in 0..d {
                for a in 0..dc {
                    ws[a + b * dc] = (0..d).map(|k| hc[a + k * dc] * inv[k + b * d]).sum::<f64>();
                }
            }
        }
        Ok(())
    }

    /// `g_c −= W_s g_l` for slot `ws` of eliminated block `e` on kept block
    /// `c`; `g` starts at offset `g0` of the reduced gradient.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn sub_w_g(&self, g: &mut [f64], g0: usize, e: usize, c: usize, ws: &[f64], sys: &System, d: usize) {
        let off = self.elim_offsets[e];
        let gl = &sys.gl[off - self.n..off - self.n + d];
        let (o, dc) = (self.kept_offsets[c] - g0, self.kept_dims[c]);
        for (k, gk) in g[o..o + dc].iter_mut().enumerate() {
            *gk -= (0..d).map(|b| ws[k + b * dc] * gl[b]).sum::<f64>();
        }
    }

    /// [`Structure::reduce`]'s eliminations in parallel (see the module doc):
    /// `h` and `g` hold H (damped) and g on entry.
    fn reduce_parallel(
        &self,
        sys: &System,
        damping: Option<&[f64]>,
        h: &mut [f64],
        g: &mut [f64],
        elim_inv: &mut [f64],
        w: &mut [f64],
    ) -> Result<(), SolveError> {
        let plan = &self.schur;
        // Every block's inverse and W (W laid out as sys.hcl).
        let invs = split_at_ends(elim_inv, plan.elim.iter().map(|r| self.hll_offsets[r.end]));
        let ws = split_at_ends(w, plan.elim.iter().map(|r| self.hcl_offsets[r.end]));
        let results: Vec<Result<(), SolveError>> = plan
            .elim
            .par_iter()
            .zip(invs.into_par_iter().zip(ws))
            .map(|(range, (inv, w))| {
                let (i0, w0) = (self.hll_offsets[range.start], self.hcl_offsets[range.start]);
                for e in range.clone() {
                    let d = self.elim_dims[e];
                    let (ho, h0, h1) =
                        (self.hll_offsets[e] - i0, self.hcl_offsets[e] - w0, self.hcl_offsets[e + 1] - w0);
                    let (inv, w) = (&mut inv[ho..ho + d * d], &mut w[h0..h1]);
                    match d {
                        1 => self.invert_and_w(e, 1, sys, damping, inv, w),
                        3 => self.invert_and_w(e, 3, sys, damping, inv, w),
                        _ => self.invert_and_w(e, d, sys, damping, inv, w),
                    }?;
                }
                Ok(())
            })
            .collect();
        // The first failing block, whatever the threads.
        results.into_iter().collect::<Result<(), _>>()?;
        // Each chunk's part of H and g, terms in eliminated-block order.
        let hs = split_at_ends(h, plan.kept.iter().map(|c| self.col_ptr[self.kept_offsets[c.blocks.end]]));
        let gs = split_at_ends(g, plan.kept.iter().map(|c| self.kept_offsets[c.blocks.end]));
        plan.kept.par_iter().zip(hs.into_par_iter().zip(gs)).for_each(|(chunk, (h, g))| {
            let (h0, g0) = (self.col_ptr[self.kept_offsets[chunk.blocks.start]], self.kept_offsets[chunk.blocks.start]);
            for &(e, a, b, pair) in &chunk.pairs {
                let d = self.elim_dims[e];
                let (i, j, _) = self.pairs[pair];
                let (wa, hb) = (&w[a..a + self.kept_dims[i] * d], &sys.hcl[b..b + self.kept_dims[j] * d]);
                match d {
                    1 => self.sub_w_ht(h, h0, pair, wa, hb, 1),
                    3 => self.sub_w_ht(h, h0, pair, wa, hb, 3),
                    _ => self.sub_w_ht(h, h0, pair, wa, hb, d),
                }
            }
            for &(e, s, c) in &chunk.grads {
                let d = self.elim_dims[e];
                self.sub_w_g(g, g0, e, c, &w[s..s + self.kept_dims[c] * d], sys, d);
            }
        });
        Ok(())
    }

    /// The eliminated blocks' terms of [`Structure::h_times`] in parallel
    /// along the Schur plan (`false`, with `y` untouched, when it has none):
    /// each eliminated chunk its blocks' rows, each kept chunk its `H_cl x_l`
    /// terms in eliminated-block order, the sums of the one-thread loop.
    pub(super) fn h_times_elim_parallel(&self, sys: &System, x: &[f64], y: &mut [f64]) -> bool {
        let plan = &self.schur;
        if plan.kept.is_empty() {
            return false;
        }
        let (yc, yl) = y.split_at_mut(self.n);
        let yls = split_at_ends(yl, plan.elim.iter().map(|r| self.elim_start(r.end)));
        plan.elim.par_iter().zip(yls).for_each(|(range, yl)| {
            let y0 = self.elim_start(range.start);
            for e in range.clone() {
                let (o, d) = (self.elim_start(e) - y0, self.elim_dims[e]);
                self.h_times_elim_block(e, d, sys, x, &mut yl[o..o + d]);
            }
        });
        let ycs = split_at_ends(yc, plan.kept.iter().map(|c| self.kept_offsets[c.blocks.end]));
        plan.kept.par_iter().zip(ycs).for_each(|(chunk, yc)| {
            let y0 = self.kept_offsets[chunk.blocks.start];
            for &(e, s, c) in &chunk.grads {
                let (off, d) = (self.elim_offsets[e], self.elim_dims[e]);
                let (oc, dc) = (self.kept_offsets[c] - y0, self.kept_dims[c]);
                for (b, col) in sys.hcl[s..s + dc * d].chunks_exact(dc).enumerate() {
                    for (k, &v) in col.iter().enumerate() {
                        yc[oc + k] += v * x[off + b];
                    }
                }
            }
        });
        true
    }

    /// `H_(big, small) −= W_big H_smallᵀ` (one Schur term), without a temporary;
    /// `h` starts at position `h0` of H. `w_big` is `d_big × dl`, `h_small` is
    /// `d_small × dl`, both column-major.
    #[inline(always)]
    fn sub_w_ht(&self, h: &mut [f64], h0: usize, pair: usize, w_big: &[f64], h_small: &[f64], dl: usize) {
        let (rows, cols) = (w_big.len() / dl, h_small.len() / dl);
        let mut wr = [0.0; MAX_STACK_DIM];
        for (r, base, n) in self.pair_rows(pair) {
            let out = &mut h[base - h0..base - h0 + n];
            if dl > MAX_STACK_DIM {
                for (c, hv) in out.iter_mut().enumerate() {
                    *hv -= (0..dl).map(|k| w_big[r + k * rows] * h_small[c + k * cols]).sum::<f64>();
                }
                continue;
            }
            // Row r of W_big, then each entry of the row in one unrolled sum.
            for (k, v) in wr[..dl].iter_mut().enumerate() {
                *v = w_big[r + k * rows];
            }
            for (c, hv) in out.iter_mut().enumerate() {
                let mut s = 0.0;
                for k in 0..dl {
                    s += wr[k] * h_small[c + k * cols];
                }
                *hv -= s;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::{spd_invert, SchurPlan};
    use crate::linear::{LinearSolver, ReduceBuffers, Role, Roles, Structure, System};
    use nalgebra::DMatrix;

    /// The parallel Schur complement (and product with H) equals the
    /// one-thread loop bit for bit:
    /// 6000 factors (a camera and a point each) over 30 cameras (9-dim) and
    /// 1500 points (3-dim), with pseudo-random but positive-definite blocks.
    #[test]
    fn parallel_schur_equals_the_one_thread_loop_bit_for_bit() {
        let (nc, np) = (30, 1500);
        let roles: Vec<Roles> =
            (0..6000).map(|f| smallvec::smallvec![Role::Kept((f * 7 + f / 50) % nc), Role::Elim(f % np)]).collect();
        let s = Structure::new(vec![9; nc], vec![3; np], &roles, LinearSolver::SparseCholesky).unwrap();
        assert!(!s.schur.kept.is_empty() && s.schur.kept.len() > 1, "the parallel plan is used");
        let mut x = 0.37_f64;
        let mut next = || {
            x = (x * 3.9 * (1.0 - x)).clamp(1e-6, 1.0 - 1e-6);
            x - 0.5
        };
        let mut sys = System {
            h: (0..s.nnz()).map(|_| next()).collect(),
            g: (0..s.n).map(|_| next()).collect(),
            hll: vec![0.0; *s.hll_offsets.last().unwrap()],
            gl: (0..3 * np).map(|_| next()).collect(),
            hcl: (0..*s.hcl_offsets.last().unwrap()).map(|_| next()).collect(),
        };
        for e in 0..np {
            let b = DMatrix::from_fn(3, 3, |_, _| next());
            let a = &b * b.transpose() + DMatrix::identity(3, 3);
            let o = s.hll_offsets[e];
            sys.hll[o..o + 9].copy_from_slice(a.as_slice());
        }
        let damping: Vec<f64> = (0..s.n + 3 * np).map(|_| next().abs()).collect();
        let (mut par, mut seq) = (ReduceBuffers::default(), ReduceBuffers::default());
        let g_par = s.reduce(&sys, Some(&damping), &mut par).unwrap();
        // Reused buffers give the same numbers.
        let g_again = s.reduce(&sys, Some(&damping), &mut par).unwrap();
        let y_par = s.h_times(&sys, &damping);
        let mut one_thread = s;
        one_thread.schur = SchurPlan::default();
        let g_seq = one_thread.reduce(&sys, Some(&damping), &mut seq).unwrap();
        let y_seq = one_thread.h_times(&sys, &damping);
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&y_par), bits(&y_seq), "H x");
        assert_eq!(bits(&par.h), bits(&seq.h));
        assert_eq!(bits(&g_par), bits(&g_seq));
        assert_eq!(bits(&g_again), bits(&g_seq));
        assert_eq!(bits(&par.elim_inv), bits(&seq.elim_inv));
        let h_par = &par.h;
        assert!(h_par.iter().zip(&sys.h).filter(|(a, b)| a != b).count() > 1000, "the complement changed H");
    }

    #[test]
    fn spd_invert_matches_a_dense_inverse() {
        for d in 1..=7 {
            // A = B Bᵀ + I, B with distinct entries.
            let b = DMatrix::from_fn(d, d, |i, j| ((i * 7 + j * 3) % 5) as f64 - 1.5 + 0.1 * i as f64);
            let a = &b * b.transpose() + DMatrix::identity(d, d);
            let mut m = a.as_slice().to_vec();
            assert!(spd_invert(&mut m, d));
            let inv = DMatrix::from_column_slice(d, d, &m);
            let err = (&a * inv - DMatrix::identity(d, d)).abs().max();
            assert!(err < 1e-10, "d = {d}: ‖A A⁻¹ − I‖ = {err}");
        }
        let mut not_pd = vec![1.0, 2.0, 2.0, 1.0];
        assert!(!spd_invert(&mut not_pd, 2));
        let mut nan = vec![f64::NAN];
        assert!(!spd_invert(&mut nan, 1));
    }
}
