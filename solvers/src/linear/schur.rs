//! The Schur complement: eliminating landmark-like blocks from the normal
//! equations to leave the reduced (camera) system.
//!
//! Each eliminated block `l` is independent of the others given the kept
//! unknowns, so `H_cc − H_cl H_ll⁻¹ H_lc` and `g_c − H_cl H_ll⁻¹ g_l` are sums of
//! one small term per block. The loops are written once for any block size and
//! instantiated for the common sizes (1: inverse depths, 3: points) so the
//! compiler unrolls them; nothing is allocated per block.

use super::Structure;
use crate::error::SolveError;
use crate::linear::System;

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

impl Structure {
    /// The reduced system: `h` ← upper triangle of `H + diag(damping)` over the
    /// kept unknowns minus the Schur complement of the eliminated blocks; returns
    /// the reduced gradient and the eliminated blocks' (damped) inverses, laid
    /// out as [`System::hll`].
    pub(super) fn reduce(
        &self,
        sys: &System,
        damping: Option<&[f64]>,
        h: &mut Vec<f64>,
    ) -> Result<(Vec<f64>, Vec<f64>), SolveError> {
        h.clear();
        h.extend_from_slice(&sys.h);
        let mut g = sys.g.clone();
        if let Some(d) = damping {
            for (k, &p) in self.diag_positions.iter().enumerate() {
                h[p] += d[k];
            }
        }
        let mut elim_inv = vec![0.0; sys.hll.len()];
        let mut scratch = Scratch::default();
        for (e, &d) in self.elim_dims.iter().enumerate() {
            // Literal sizes let the compiler unroll the inlined loops.
            let mut elim = |d| self.eliminate(e, d, sys, damping, &mut elim_inv, &mut scratch, h, &mut g);
            match d {
                1 => elim(1),
                2 => elim(2),
                3 => elim(3),
                _ => elim(d),
            }?;
        }
        Ok((g, elim_inv))
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
        let (off, ho) = (self.elim_offsets[e], self.hll_offsets[e]);
        let inv = &mut elim_inv[ho..ho + d * d];
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
        let hcl = &sys.hcl[h0..self.hcl_offsets[e + 1]];
        let Scratch { w, slot_offsets } = scratch;
        w.clear();
        w.resize(hcl.len(), 0.0);
        slot_offsets.clear();
        for (_, o, len) in self.elim_slots(e) {
            slot_offsets.push(o - h0);
            let (hc, ws) = (&hcl[o - h0..o - h0 + len], &mut w[o - h0..o - h0 + len]);
            let dc = len / d;
            for b in 0..d {
                for a in 0..dc {
                    ws[a + b * dc] = (0..d).map(|k| hc[a + k * dc] * inv[k + b * d]).sum::<f64>();
                }
            }
        }
        slot_offsets.push(hcl.len());
        let slot = |s: usize| slot_offsets[s]..slot_offsets[s + 1];
        for &(sa, sb, pair) in &self.elim_pairs[e] {
            self.sub_w_ht(h, pair, &w[slot(sa)], &hcl[slot(sb)], d);
        }
        let gl = &sys.gl[off - self.n..off - self.n + d];
        for (s, &c) in self.elim_cams[e].iter().enumerate() {
            let ws = &w[slot(s)];
            let (o, dc) = (self.kept_offsets[c], self.kept_dims[c]);
            for (k, gk) in g[o..o + dc].iter_mut().enumerate() {
                *gk -= (0..d).map(|b| ws[k + b * dc] * gl[b]).sum::<f64>();
            }
        }
        Ok(())
    }

    /// `H_(big, small) −= W_big H_smallᵀ` (one Schur term), without a temporary.
    /// `w_big` is `d_big × dl`, `h_small` is `d_small × dl`, both column-major.
    #[inline(always)]
    fn sub_w_ht(&self, h: &mut [f64], pair: usize, w_big: &[f64], h_small: &[f64], dl: usize) {
        let (rows, cols) = (w_big.len() / dl, h_small.len() / dl);
        let mut wr = [0.0; MAX_STACK_DIM];
        for (r, base, n) in self.pair_rows(pair) {
            let out = &mut h[base..base + n];
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
    use super::spd_invert;
    use nalgebra::DMatrix;

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
