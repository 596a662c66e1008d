//! The whitened, robust-corrected linearizations of every factor of a graph,
//! in one buffer, and the parallel pass that fills it.
//!
//! One buffer instead of a residual vector and a matrix per Jacobian per
//! factor: a bundle adjustment of 31 102 reprojections otherwise allocates
//! ~250 000 small blocks in its first two passes and frees them at the end,
//! which cost it a fifth of its solve time.

use crate::error::SolveError;
use crate::factor::Vars;
use crate::graph::{FactorEntry, WhitenedLinearization};
use crate::layout::Layout;
use crate::variable::DynVariable;
use rayon::prelude::*;
use std::ops::Range;

/// Whitened linearizations of all factors, laid out factor after factor:
/// the residual (`rows` entries), then each Jacobian column-major
/// (`rows × cols`), in the factor's key order.
#[derive(Clone, Debug, Default)]
pub(crate) struct Linearized {
    /// Factor `fi`'s numbers are `data[start[fi]..start[fi + 1]]`.
    start: Vec<usize>,
    /// Residual rows of each factor.
    rows: Vec<usize>,
    /// Factor `fi`'s Jacobian column counts are `cols[col_start[fi]..col_start[fi + 1]]`.
    col_start: Vec<usize>,
    cols: Vec<usize>,
    data: Vec<f64>,
    /// ρ(‖r‖²) of each factor (twice its cost).
    rho: Vec<f64>,
}

/// Factors per parallel task of [`linearize_all_into`] at least, so that a
/// task's scratch buffers serve many factors.
const MIN_TASK_FACTORS: usize = 16;

/// Tasks [`linearize_all_into`] cuts a large graph into.
const TASKS: usize = 64;

impl Linearized {
    /// Lay out the buffer for `entries` (no-op when it already is).
    fn shape(&mut self, entries: &[FactorEntry], layout: &Layout, vars: &[Box<dyn DynVariable>]) {
        if self.rows.len() == entries.len() && !entries.is_empty() {
            return;
        }
        *self = Linearized::default();
        self.start.push(0);
        self.col_start.push(0);
        for (e, fv) in entries.iter().zip(&layout.factor_vars) {
            let m = e.factor.residual_dim();
            let dims = fv.iter().map(|&v| vars[v].dim());
            self.cols.extend(dims);
            let n: usize = self.cols[*self.col_start.last().expect("non-empty")..].iter().sum();
            self.rows.push(m);
            self.col_start.push(self.cols.len());
            self.start.push(self.start.last().expect("non-empty") + m * (1 + n));
        }
        self.data = vec![0.0; *self.start.last().expect("non-empty")];
        self.rho = vec![0.0; entries.len()];
    }

    /// Whitened residual of factor `fi`.
    pub fn residual(&self, fi: usize) -> &[f64] {
        &self.data[self.start[fi]..self.start[fi] + self.rows[fi]]
    }

    /// Column count of factor `fi`'s `k`-th Jacobian.
    pub fn ncols(&self, fi: usize, k: usize) -> usize {
        self.cols[self.col_start[fi] + k]
    }

    /// Factor `fi`'s `k`-th whitened Jacobian, column-major (`rows × ncols`).
    pub fn jacobian(&self, fi: usize, k: usize) -> &[f64] {
        let m = self.rows[fi];
        let cols = &self.cols[self.col_start[fi]..self.col_start[fi] + k];
        let o = self.start[fi] + m * (1 + cols.iter().sum::<usize>());
        &self.data[o..o + m * self.ncols(fi, k)]
    }

    /// Half the sum of ρ: the cost.
    pub fn cost(&self) -> f64 {
        0.5 * self.rho.iter().sum::<f64>()
    }

    /// The Gauss–Newton model's value at a zero step, `½ Σ ‖r‖²` over the
    /// whitened (and, under a robust loss, reweighted) residuals the normal
    /// equations are assembled from: the cost without robust losses. No
    /// step's model decrease exceeds it.
    pub fn model_value(&self) -> f64 {
        0.5 * (0..self.rows.len()).map(|fi| self.residual(fi).iter().map(|v| v * v).sum::<f64>()).sum::<f64>()
    }
}

fn gather<'a>(vars: &'a [Box<dyn DynVariable>], idx: &[usize]) -> smallvec::SmallVec<[&'a dyn DynVariable; 4]> {
    idx.iter().map(|&i| vars[i].as_ref()).collect()
}

/// Linearize every factor (in parallel; the numbers do not depend on the
/// thread count) into `out`, reusing its buffer when it already holds this
/// graph's; returns the cost.
pub(crate) fn linearize_all_into(
    entries: &[FactorEntry],
    layout: &Layout,
    vars: &[Box<dyn DynVariable>],
    out: &mut Linearized,
) -> Result<f64, SolveError> {
    out.shape(entries, layout, vars);
    let n = entries.len();
    let per_task = n.div_ceil(TASKS).max(MIN_TASK_FACTORS);
    let tasks: Vec<Range<usize>> = (0..n).step_by(per_task.max(1)).map(|a| a..(a + per_task).min(n)).collect();
    let Linearized { start, rows, data, rho, .. } = out;
    let (start, rows) = (&*start, &*rows);
    let datas = split_at_ends(data, tasks.iter().map(|t| start[t.end]));
    let rhos = split_at_ends(rho, tasks.iter().map(|t| t.end));
    tasks.into_par_iter().zip(datas).zip(rhos).try_for_each(|((task, data), rho)| {
        let mut scratch = WhitenedLinearization::default();
        let (base, first) = (start[task.start], task.start);
        for fi in task {
            let (e, fv) = (&entries[fi], &layout.factor_vars[fi]);
            let v = gather(vars, fv);
            e.linearize_whitened_into(Vars::new(&v), &mut scratch)
                .map_err(|source| SolveError::Factor { factor: fi, source })?;
            let (lin, m) = (&scratch.lin, rows[fi]);
            if lin.jacobians.len() != fv.len()
                || lin.residual.len() != m
                || lin.jacobians.iter().zip(&v).any(|(j, x)| j.nrows() != m || j.ncols() != x.dim())
            {
                return Err(SolveError::BadFactor {
                    factor: fi,
                    what: "Jacobian or residual has the wrong shape".into(),
                });
            }
            let mut o = start[fi] - base;
            for part in std::iter::once(lin.residual.as_slice()).chain(lin.jacobians.iter().map(|j| j.as_slice())) {
                data[o..o + part.len()].copy_from_slice(part);
                o += part.len();
            }
            rho[fi - first] = scratch.rho;
        }
        Ok(())
    })?;
    Ok(out.cost())
}

/// [`linearize_all_into`] into a new buffer: the linearization and the cost.
pub(crate) fn linearize_all(
    entries: &[FactorEntry],
    layout: &Layout,
    vars: &[Box<dyn DynVariable>],
) -> Result<(Linearized, f64), SolveError> {
    let mut out = Linearized::default();
    let cost = linearize_all_into(entries, layout, vars, &mut out)?;
    Ok((out, cost))
}

/// Split `s` into consecutive slices ending at `ends` (ascending, the last = `s.len()`).
pub(crate) fn split_at_ends<T>(mut s: &mut [T], ends: impl Iterator<Item = usize>) -> Vec<&mut [T]> {
    let (mut out, mut start) = (Vec::new(), 0);
    for end in ends {
        let (a, b) = std::mem::take(&mut s).split_at_mut(end - start);
        out.push(a);
        s = b;
        start = end;
    }
    out
}
