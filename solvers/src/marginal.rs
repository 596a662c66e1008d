//! Marginalization (Schur complement into a linear prior) and covariance recovery.

use crate::error::{FactorError, SolveError};
use crate::factor::{Factor, Linearization, Vars};
use crate::graph::{FactorEntry, Graph};
use crate::key::Key;
use crate::layout::{Layout, Role};
use crate::linear::{LinearSolver, Structure, System};
use crate::linearized::linearize_all;
use crate::values::Values;
use crate::variable::DynVariable;
use nalgebra::{DMatrix, DVector};
use std::collections::{BTreeMap, HashMap};

/// A linear prior on a set of variables left by marginalization:
/// `r(x) = R · [x_k ⊟_{x0_k}]_k + e`, already whitened (use [`crate::NoiseModel::Unit`]).
///
/// The Jacobians are held at the linearization point (first-estimate Jacobians),
/// as VINS-Mono and Basalt do, so the prior stays consistent.
#[derive(Clone, Debug)]
pub struct MarginalPrior {
    keys: Vec<Key>,
    dims: Vec<usize>,
    anchors: Vec<Box<dyn DynVariable>>,
    /// Square-root information `R` (rank × Σ dims).
    pub sqrt_information: DMatrix<f64>,
    /// Offset `e` (rank).
    pub offset: DVector<f64>,
}

impl MarginalPrior {
    /// Information matrix RᵀR of the prior, over the stacked tangents of its keys.
    pub fn information(&self) -> DMatrix<f64> {
        self.sqrt_information.tr_mul(&self.sqrt_information)
    }
}

impl Factor for MarginalPrior {
    fn keys(&self) -> &[Key] {
        &self.keys
    }
    fn residual_dim(&self) -> usize {
        self.offset.len()
    }
    fn residual(&self, vars: Vars<'_>) -> Result<DVector<f64>, FactorError> {
        let n: usize = self.dims.iter().sum();
        let mut dx = DVector::zeros(n);
        let mut off = 0;
        for (i, a) in self.anchors.iter().enumerate() {
            let d = a.local_dyn(vars.get_dyn(i)).ok_or(FactorError::WrongVariableType {
                index: i,
                expected: a.type_name(),
                got: vars.get_dyn(i).type_name(),
            })?;
            dx.rows_mut(off, d.len()).copy_from_slice(&d);
            off += d.len();
        }
        Ok(&self.sqrt_information * dx + &self.offset)
    }
    fn linearize(&self, vars: Vars<'_>) -> Result<Linearization, FactorError> {
        let residual = self.residual(vars)?;
        let mut jacobians = Vec::with_capacity(self.dims.len());
        let mut off = 0;
        for &d in &self.dims {
            jacobians.push(self.sqrt_information.columns(off, d).into_owned());
            off += d;
        }
        Ok(Linearization { residual, jacobians })
    }
    fn constant_jacobians(&self) -> bool {
        true
    }
}

/// Result of [`marginalize`].
pub struct Marginalization {
    /// The prior on the separator variables (add it with [`crate::NoiseModel::Unit`]).
    pub prior: MarginalPrior,
    /// Indices (in the input graph) of the factors it replaces.
    pub removed_factors: Vec<usize>,
}

/// Pivots below this are dropped from the prior and from the generalized
/// inverses of the marginalized blocks: every factorization is a pivoted
/// Cholesky of the information scaled to a unit diagonal (see `ScaledCholesky`).
pub const PRIOR_RANK_TOLERANCE: f64 = 1e-10;

/// Marginalize `keys` out of `graph` at `values`: the factors touching them are
/// linearized, the marginalized variables eliminated by the Schur complement,
/// and the result returned as a [`MarginalPrior`] on the remaining variables of
/// those factors. The caller removes `removed_factors` and the marginalized
/// values, and adds the prior.
///
/// ```
/// use tumble_solvers::{Graph, Values, NoiseModel, marginalize, X};
/// use tumble_solvers::testing::LinearFactor;
/// use nalgebra::{DMatrix, DVector, Vector1};
/// let mut g = Graph::new();
/// let i = DMatrix::identity(1, 1);
/// g.add(LinearFactor::new(vec![X(0)], vec![i.clone()], DVector::zeros(1)), NoiseModel::Unit);
/// g.add(LinearFactor::new(vec![X(0), X(1)], vec![-i.clone(), i.clone()], DVector::zeros(1)), NoiseModel::Unit);
/// let mut v = Values::new();
/// v.insert(X(0), Vector1::new(0.0));
/// v.insert(X(1), Vector1::new(0.0));
/// let m = marginalize(&g, &v, &[X(0)]).unwrap();
/// assert!((m.prior.information()[(0, 0)] - 0.5).abs() < 1e-12);
/// ```
pub fn marginalize(graph: &Graph, values: &Values, keys: &[Key]) -> Result<Marginalization, SolveError> {
    let removed: Vec<usize> =
        (0..graph.len()).filter(|&i| graph.entries()[i].factor.keys().iter().any(|k| keys.contains(k))).collect();
    // Ordered variables: the independent marginalized blocks first, then the
    // other marginalized variables, then the separator.
    let independent = independent_keys(graph, &removed, keys);
    let mut order: Vec<Key> = independent.clone();
    order.extend(keys.iter().filter(|k| !independent.contains(k)));
    for &i in &removed {
        for k in graph.entries()[i].factor.keys() {
            if !order.contains(k) {
                order.push(*k);
            }
        }
    }
    let mut offsets = HashMap::new();
    let mut n = 0;
    let mut dims = Vec::new();
    for k in &order {
        let d = values.get_dyn(*k)?.dim();
        offsets.insert(*k, n);
        dims.push(d);
        n += d;
    }
    let ni: usize = dims[..independent.len()].iter().sum();
    let nm: usize = dims[..keys.len()].iter().sum();
    let mut h = DMatrix::zeros(n, n);
    let mut g = DVector::zeros(n);
    add_normal_equations(graph, values, &removed, &offsets, &mut h, &mut g)?;
    let mut start = 0;
    for &d in &dims[..independent.len()] {
        eliminate_block(&mut h, &mut g, start..start + d, ni)?;
        start += d;
    }
    let (hstar, gstar) = schur_complement(&h, &g, ni..nm)?;
    let (r, e) = ScaledCholesky::new(&hstar, "marginal information")?.sqrt_with_offset(n - nm, &gstar);
    let sep_keys: Vec<Key> = order[keys.len()..].to_vec();
    let anchors = sep_keys.iter().map(|k| values.get_dyn(*k).map(|v| v.clone_box())).collect::<Result<_, _>>()?;
    Ok(Marginalization {
        prior: MarginalPrior {
            keys: sep_keys,
            dims: dims[keys.len()..].to_vec(),
            anchors,
            sqrt_information: r,
            offset: e,
        },
        removed_factors: removed,
    })
}

/// The marginalized keys that no factor of `removed` links to one another
/// (the landmarks leaving a sliding window with their anchor state), chosen
/// greedily, those whose factors reach the fewest variables first: each is
/// eliminated on its own block, which is the same Schur complement as
/// eliminating them jointly — the cubic cost of the joint block is what this
/// avoids.
fn independent_keys(graph: &Graph, removed: &[usize], keys: &[Key]) -> Vec<Key> {
    let index: HashMap<Key, usize> = keys.iter().enumerate().map(|(i, &k)| (k, i)).collect();
    // Per marginalized key: the other marginalized keys its factors reach,
    // and how many variables they reach in all (the cost of eliminating it).
    let mut linked: Vec<Vec<usize>> = vec![Vec::new(); keys.len()];
    let mut reach = vec![0; keys.len()];
    for &fi in removed {
        let fk = graph.entries()[fi].factor.keys();
        let marginalized: Vec<usize> = fk.iter().filter_map(|k| index.get(k).copied()).collect();
        for &a in &marginalized {
            reach[a] += fk.len();
            linked[a].extend(marginalized.iter().filter(|&&b| b != a));
        }
    }
    let mut by_reach: Vec<usize> = (0..keys.len()).collect();
    by_reach.sort_by_key(|&i| (reach[i], i));
    let mut chosen = vec![false; keys.len()];
    for i in by_reach {
        chosen[i] = !linked[i].iter().any(|&j| chosen[j]);
    }
    // In the caller's order.
    keys.iter().zip(&chosen).filter(|(_, &c)| c).map(|(&k, _)| k).collect()
}

/// Eliminate the variable at rows/columns `block` of the normal equations
/// `(h, g)` into the rows from `rest` on: `H_rr −= H_rb H_bb⁺ H_br`,
/// `g_r −= H_rb H_bb⁺ g_b`, on the rows the block is coupled to (the others
/// are unchanged). The rows of `block` are left as they were.
fn eliminate_block(
    h: &mut DMatrix<f64>,
    g: &mut DVector<f64>,
    block: std::ops::Range<usize>,
    rest: usize,
) -> Result<(), SolveError> {
    let d = block.len();
    let n = h.nrows();
    let coupled: Vec<usize> = (rest..n).filter(|&r| block.clone().any(|c| h[(r, c)] != 0.0)).collect();
    let hbb = h.view((block.start, block.start), (d, d)).into_owned();
    let inv = ScaledCholesky::new(&hbb, "information of a marginalized variable")?.pseudo_inverse(d);
    // W = H_rb H_bb⁺ on the coupled rows.
    let w = DMatrix::from_fn(coupled.len(), d, |a, j| {
        (0..d).map(|k| h[(coupled[a], block.start + k)] * inv[(k, j)]).sum::<f64>()
    });
    for (a, &ra) in coupled.iter().enumerate() {
        for &rb in &coupled {
            h[(ra, rb)] -= (0..d).map(|k| w[(a, k)] * h[(rb, block.start + k)]).sum::<f64>();
        }
        g[ra] -= (0..d).map(|k| w[(a, k)] * g[block.start + k]).sum::<f64>();
    }
    Ok(())
}

/// The Schur complement of rows/columns `m` of `(h, g)` onto the rows after
/// them (the separator): `H_ss − H_sm H_mm⁺ H_ms` and `g_s − H_sm H_mm⁺ g_m`.
fn schur_complement(
    h: &DMatrix<f64>,
    g: &DVector<f64>,
    m: std::ops::Range<usize>,
) -> Result<(DMatrix<f64>, DVector<f64>), SolveError> {
    let (m0, nm, ns) = (m.start, m.len(), h.nrows() - m.end);
    let hss = h.view((m.end, m.end), (ns, ns)).into_owned();
    let gs = g.rows(m.end, ns).into_owned();
    let hmm = h.view((m0, m0), (nm, nm)).into_owned();
    let hms = h.view((m0, m.end), (nm, ns)).into_owned();
    let gm = g.rows(m0, nm).into_owned();
    let hmm_inv = ScaledCholesky::new(&hmm, "information of the marginalized variables")?.pseudo_inverse(nm);
    let w = hms.transpose() * hmm_inv;
    Ok((hss - &w * &hms, gs - w * gm))
}

/// Add the whitened normal equations of the factors `factors` of `graph` at
/// `values` — `JᵀJ` to `h` and `Jᵀr` to `g`, robust weights included — over
/// the variables placed by `offsets` (others are held fixed); the sum of their
/// `ρ(‖r‖²)` (their χ² without robust losses) back.
fn add_normal_equations(
    graph: &Graph,
    values: &Values,
    factors: &[usize],
    offsets: &HashMap<Key, usize>,
    h: &mut DMatrix<f64>,
    g: &mut DVector<f64>,
) -> Result<f64, SolveError> {
    let mut cost = 0.0;
    for &fi in factors {
        let e: &FactorEntry = &graph.entries()[fi];
        let vars: Vec<&dyn DynVariable> =
            e.factor.keys().iter().map(|k| values.get_dyn(*k)).collect::<Result<_, _>>()?;
        let wl = e.linearize_whitened(Vars::new(&vars)).map_err(|source| SolveError::Factor { factor: fi, source })?;
        cost += wl.rho;
        for (a, ka) in e.factor.keys().iter().enumerate() {
            let Some(&oa) = offsets.get(ka) else { continue };
            let ja = &wl.lin.jacobians[a];
            // In place (`+= Jₐᵀ r`, `+= Jₐᵀ J_b`): no temporary per block.
            g.rows_mut(oa, ja.ncols()).gemv_tr(1.0, ja, &wl.lin.residual, 1.0);
            for (b, kb) in e.factor.keys().iter().enumerate() {
                let Some(&ob) = offsets.get(kb) else { continue };
                let jb = &wl.lin.jacobians[b];
                h.view_mut((oa, ob), (ja.ncols(), jb.ncols())).gemm_tr(1.0, ja, jb, 1.0);
            }
        }
    }
    Ok(cost)
}

/// The pivoted Cholesky factorization of the symmetric positive
/// semi-definite `h` (an information matrix) scaled to a unit diagonal
/// (Jacobi): `S h S = P L Lᵀ Pᵀ` on its rows with a positive diagonal
/// (`live`, with `scale` = S = diag^-½), `L` lower-trapezoidal of the rank
/// found, `P` the order of the pivots. Rows with a zero diagonal (variables no
/// factor constrains) are left out.
///
/// Each step takes the largest diagonal left as its pivot and stops when it
/// is at most [`PRIOR_RANK_TOLERANCE`] (the scaled diagonal is 1): what is
/// left then is a semi-definite remainder whose eigenvalues are all below
/// `m` × that tolerance, dropped as the directions the information does not
/// determine (a sliding window's gauge), and rounding's negative ones with
/// them. Any generalized inverse gives the same Schur complement of a
/// semi-definite matrix, and any square root the same prior up to an
/// orthogonal rotation of its rows; this one is far cheaper than an
/// eigen-decomposition (in `bench_vio`'s profile 0.8 % of the time, where
/// the eigen-decompositions it replaced took ~6 %).
///
/// Without the scaling, information spanning ten orders of magnitude (a gyro
/// bias next to an unobserved landmark) would be truncated by its units.
struct ScaledCholesky {
    live: Vec<usize>,
    scale: Vec<f64>,
    /// Pivot order: position `i` of the factorization is live row `pivots[i]`.
    pivots: Vec<usize>,
    /// `L` (m × rank), in pivot order.
    l: DMatrix<f64>,
}

impl ScaledCholesky {
    fn new(h: &DMatrix<f64>, what: &str) -> Result<ScaledCholesky, SolveError> {
        if !h.iter().all(|x| x.is_finite()) {
            return Err(SolveError::Singular(format!("the {what} is not finite")));
        }
        let live: Vec<usize> = (0..h.nrows()).filter(|&i| h[(i, i)] > 0.0).collect();
        let scale: Vec<f64> = live.iter().map(|&i| 1.0 / h[(i, i)].sqrt()).collect();
        let m = live.len();
        let a =
            DMatrix::from_fn(m, m, |r, c| 0.5 * (h[(live[r], live[c])] + h[(live[c], live[r])]) * scale[r] * scale[c]);
        let mut pivots: Vec<usize> = (0..m).collect();
        let mut l = DMatrix::<f64>::zeros(m, m);
        // The diagonal left after the steps so far, in pivot order.
        let mut left: Vec<f64> = (0..m).map(|i| a[(i, i)]).collect();
        let mut rank = 0;
        while rank < m {
            let k = rank;
            let p = (k..m).max_by(|&i, &j| left[i].total_cmp(&left[j])).unwrap_or(k);
            if left[p].is_nan() || left[p] <= PRIOR_RANK_TOLERANCE {
                break;
            }
            pivots.swap(k, p);
            left.swap(k, p);
            l.swap_rows(k, p);
            let d = left[k].sqrt();
            l[(k, k)] = d;
            for i in k + 1..m {
                let dot: f64 = (0..k).map(|j| l[(i, j)] * l[(k, j)]).sum();
                let v = (a[(pivots[i], pivots[k])] - dot) / d;
                l[(i, k)] = v;
                left[i] -= v * v;
            }
            rank += 1;
        }
        if !l.iter().all(|x| x.is_finite()) {
            return Err(SolveError::Singular(format!("the factorization of the {what} failed")));
        }
        let l = l.columns(0, rank).into_owned();
        Ok(ScaledCholesky { live, scale, pivots, l })
    }

    /// The rank found: the pivots kept.
    fn rank(&self) -> usize {
        self.l.ncols()
    }

    /// `L₁₁⁻¹ b` for the leading rank × rank block of `L` (forward substitution).
    fn forward(&self, b: &mut [f64]) {
        for i in 0..self.rank() {
            let s: f64 = (0..i).map(|j| self.l[(i, j)] * b[j]).sum();
            b[i] = (b[i] - s) / self.l[(i, i)];
        }
    }

    /// A generalized inverse of `h` (n × n): `S P (L₁₁ L₁₁ᵀ)⁻¹ Pᵀ S` on the
    /// pivots kept, zero elsewhere (`h G h = h` on the rank found).
    fn pseudo_inverse(&self, n: usize) -> DMatrix<f64> {
        let r = self.rank();
        // W = L₁₁⁻¹ column by column, then (L₁₁ L₁₁ᵀ)⁻¹ = Wᵀ W.
        let mut w = DMatrix::<f64>::zeros(r, r);
        for c in 0..r {
            let mut e = vec![0.0; r];
            e[c] = 1.0;
            self.forward(&mut e);
            w.column_mut(c).copy_from_slice(&e);
        }
        let g11 = w.tr_mul(&w);
        let mut inv = DMatrix::zeros(n, n);
        for a in 0..r {
            let (ra, sa) = (self.live[self.pivots[a]], self.scale[self.pivots[a]]);
            for b in 0..r {
                let (rb, sb) = (self.live[self.pivots[b]], self.scale[self.pivots[b]]);
                inv[(ra, rb)] = sa * g11[(a, b)] * sb;
            }
        }
        inv
    }

    /// A square root `R` of `h` (rank × n, RᵀR = h on the rank found) and the
    /// offset `e` with Rᵀe = `g` (the gradient) on the same subspace.
    fn sqrt_with_offset(&self, n: usize, g: &DVector<f64>) -> (DMatrix<f64>, DVector<f64>) {
        let r = self.rank();
        let mut sqrt = DMatrix::zeros(r, n);
        for (i, &p) in self.pivots.iter().enumerate() {
            let col = self.live[p];
            for k in 0..r.min(i + 1) {
                sqrt[(k, col)] = self.l[(i, k)] / self.scale[p];
            }
        }
        let mut e: Vec<f64> = self.pivots[..r].iter().map(|&p| self.scale[p] * g[self.live[p]]).collect();
        self.forward(&mut e);
        (sqrt, DVector::from_vec(e))
    }
}

/// Marginal covariances of chosen variables at a solution, in their tangent spaces.
#[derive(Clone, Debug)]
pub struct Covariances {
    keys: Vec<Key>,
    offsets: Vec<usize>,
    joint: DMatrix<f64>,
}

impl Covariances {
    /// Marginal covariance of one requested key.
    pub fn get(&self, key: Key) -> Option<DMatrix<f64>> {
        self.block(key, key)
    }
    /// Standard deviation of tangent component `i` of a requested key (None
    /// when the key was not requested or has no such component).
    pub fn sigma(&self, key: Key, i: usize) -> Option<f64> {
        let (o, d) = self.span(key)?;
        (i < d).then(|| self.joint[(o + i, o + i)].max(0.0).sqrt())
    }
    /// Cross-covariance block between two requested keys.
    pub fn block(&self, a: Key, b: Key) -> Option<DMatrix<f64>> {
        let (oa, da) = self.span(a)?;
        let (ob, db) = self.span(b)?;
        Some(self.joint.view((oa, ob), (da, db)).into_owned())
    }
    /// Joint covariance of some of the requested keys, in the order given
    /// (None when one was not requested).
    pub fn joint(&self, keys: &[Key]) -> Option<DMatrix<f64>> {
        let spans: Vec<(usize, usize)> = keys.iter().map(|k| self.span(*k)).collect::<Option<_>>()?;
        let idx: Vec<usize> = spans.iter().flat_map(|&(o, d)| o..o + d).collect();
        Some(DMatrix::from_fn(idx.len(), idx.len(), |r, c| self.joint[(idx[r], idx[c])]))
    }
    /// Offset and dimension of a requested key in the joint matrix.
    fn span(&self, k: Key) -> Option<(usize, usize)> {
        let i = self.keys.iter().position(|x| *x == k)?;
        Some((self.offsets[i], self.offsets[i + 1] - self.offsets[i]))
    }
}

/// Covariance blocks (inverse of the Gauss–Newton information JᵀJ, robust
/// weights included) of `keys` at `values`. Constant variables are conditioned on.
pub fn covariances(graph: &Graph, values: &Values, keys: &[Key]) -> Result<Covariances, SolveError> {
    covariances_eliminating(graph, values, keys, &[])
}

/// [`covariances`], eliminating the variables whose key characters are in
/// `eliminate` first (landmarks of a bundle-adjustment-like graph): the blocks
/// are the same, computed from the much smaller reduced system. The requested
/// keys must not be eliminated.
pub fn covariances_eliminating(
    graph: &Graph,
    values: &Values,
    keys: &[Key],
    eliminate: &[char],
) -> Result<Covariances, SolveError> {
    let layout = Layout::new(graph, values, eliminate)?;
    let vars: Vec<Box<dyn DynVariable>> =
        layout.keys.iter().map(|&k| values.get_dyn(k).map(|v| v.clone_box())).collect::<Result<_, _>>()?;
    let mut structure = layout.structure(&vars, LinearSolver::Auto)?;
    let (lins, _) = linearize_all(graph.entries(), &layout, &vars)?;
    let sys = structure.assemble(&lins);
    covariances_of_system(&layout, &mut structure, &sys, keys)
}

/// Covariance blocks of `keys` from an assembled system (`sys` from
/// `structure.assemble` at the solution): shared by [`covariances_eliminating`]
/// and [`crate::Optimizer::optimize_with_covariances`], which reuses its last
/// linearization instead of a second one.
pub(crate) fn covariances_of_system(
    layout: &Layout,
    structure: &mut Structure,
    sys: &System,
    keys: &[Key],
) -> Result<Covariances, SolveError> {
    let (cols, offsets) = key_columns(layout, structure, keys)?;
    let full = structure.inverse_columns(sys, &cols)?;
    Ok(Covariances { keys: keys.to_vec(), offsets, joint: rows_of(&full, &cols) })
}

/// The reduced system's columns of `keys` (which must be kept, not
/// eliminated or constant) and each key's offset among them.
fn key_columns(layout: &Layout, structure: &Structure, keys: &[Key]) -> Result<(Vec<usize>, Vec<usize>), SolveError> {
    let mut cols = Vec::new();
    let mut offsets = vec![0];
    for k in keys {
        let vi =
            layout.keys.iter().position(|x| x == k).ok_or(SolveError::Config(format!("key {k} is in no factor")))?;
        let b = match layout.roles[vi] {
            Role::Kept(b) => b,
            Role::Elim(_) => {
                return Err(SolveError::Config(format!("key {k} is eliminated: its covariance is not kept")))
            }
            _ => return Err(SolveError::Config(format!("key {k} is held constant"))),
        };
        let o = structure.kept_offset(b);
        cols.extend(o..o + structure.kept_dim(b));
        offsets.push(cols.len());
    }
    Ok((cols, offsets))
}

/// Rows `cols` of `full` (the columns `cols` of H⁻¹): their joint block.
fn rows_of(full: &DMatrix<f64>, cols: &[usize]) -> DMatrix<f64> {
    DMatrix::from_fn(cols.len(), cols.len(), |i, j| full[(cols[i], j)])
}

/// Covariances of the same keys two ways (see [`cluster_robust_covariances`]).
#[derive(Clone, Debug)]
pub struct RobustCovariances {
    /// From the noise models: the inverse of the information `JᵀJ`.
    pub model: Covariances,
    /// Cluster-robust (sandwich): `H⁻¹ (G/(G−1)) Σ_c g_c g_cᵀ H⁻¹`, with
    /// `g_c` the gradient `Jᵀr` of cluster `c`'s factors. Honest when the
    /// errors are correlated within a cluster, independent between clusters,
    /// or not as large as the noise models say.
    pub robust: Covariances,
    /// Clusters `G`.
    pub clusters: usize,
    /// Each cluster's influence on the keys, `H⁻¹ g_c` (rows as in
    /// `model`'s joint matrix), with its label (`None`: a factor's own
    /// cluster), in label order: what [`RobustCovariances::regrouped`] sums.
    pub influences: Vec<(Option<usize>, DVector<f64>)>,
}

impl RobustCovariances {
    /// The cluster-robust covariances of the same keys with the clusters
    /// merged into coarser ones: labelled cluster `c` into `group(c)`
    /// (unlabelled ones stay alone). E.g. per-frame labels grouped into
    /// blocks of `b` frames with `|c| c / b`: one linearization gives the
    /// sandwich at every block length. The number of groups is returned with it.
    pub fn regrouped(&self, group: impl Fn(usize) -> usize) -> (Covariances, usize) {
        let p = self.model.joint.nrows();
        let mut grouped: BTreeMap<usize, DVector<f64>> = BTreeMap::new();
        let mut alone = Vec::new();
        for (c, u) in &self.influences {
            match c {
                Some(c) => *grouped.entry(group(*c)).or_insert_with(|| DVector::zeros(p)) += u,
                None => alone.push(u),
            }
        }
        let g = grouped.len() + alone.len();
        let joint = sandwich(grouped.values().chain(alone), g, p);
        (Covariances { keys: self.model.keys.clone(), offsets: self.model.offsets.clone(), joint }, g)
    }
}

/// `(G/(G−1)) Σ_c u_c u_cᵀ` over the `g` clusters' influences `u_c`.
fn sandwich<'a>(influences: impl Iterator<Item = &'a DVector<f64>>, g: usize, p: usize) -> DMatrix<f64> {
    let mut robust = DMatrix::zeros(p, p);
    for u in influences {
        robust += u * u.transpose();
    }
    if g > 1 {
        robust *= g as f64 / (g - 1) as f64;
    }
    robust
}

/// Cluster-robust covariances: [`RobustCovariances`] at a solution, from an
/// assembled system and its linearization (`clusters[fi]`: factor `fi`'s
/// cluster, `None` for a cluster of its own). Variables eliminated by the
/// Schur complement are not supported (their rows of H⁻¹ are not formed).
pub(crate) fn robust_covariances_of_system(
    layout: &Layout,
    structure: &mut Structure,
    sys: &System,
    lins: &crate::linearized::Linearized,
    keys: &[Key],
    clusters: &[Option<usize>],
) -> Result<RobustCovariances, SolveError> {
    if !layout.elim_vars.is_empty() {
        return Err(SolveError::Config("cluster-robust covariances with eliminated variables".into()));
    }
    if clusters.len() != layout.factor_vars.len() {
        return Err(SolveError::Config(format!(
            "{} cluster labels for {} factors",
            clusters.len(),
            layout.factor_vars.len()
        )));
    }
    let (cols, offsets) = key_columns(layout, structure, keys)?;
    let full = structure.inverse_columns(sys, &cols)?;
    let p = cols.len();
    let labelled = clusters.iter().flatten().max().map_or(0, |m| m + 1);
    // By cluster label, in order: the sum below must not follow a hash map's
    // per-instance order, or the σ would change in their last bits from run to run.
    let mut scores: BTreeMap<usize, DVector<f64>> = BTreeMap::new();
    for (fi, fv) in layout.factor_vars.iter().enumerate() {
        let c = clusters[fi].unwrap_or(labelled + fi);
        let r = lins.residual(fi);
        let m = r.len();
        let u = scores.entry(c).or_insert_with(|| DVector::zeros(p));
        for (k, &vi) in fv.iter().enumerate() {
            let Role::Kept(b) = layout.roles[vi] else { continue };
            let (o, n) = (structure.kept_offset(b), lins.ncols(fi, k));
            let j = lins.jacobian(fi, k);
            for col in 0..n {
                // (Jᵀ r)[col], then its image through the rows of H⁻¹.
                let g: f64 = (0..m).map(|row| j[col * m + row] * r[row]).sum();
                if g != 0.0 {
                    for q in 0..p {
                        u[q] += full[(o + col, q)] * g;
                    }
                }
            }
        }
    }
    let g = scores.len();
    let robust = sandwich(scores.values(), g, p);
    let influences = scores.into_iter().map(|(c, u)| ((c < labelled).then_some(c), u)).collect();
    Ok(RobustCovariances {
        model: Covariances { keys: keys.to_vec(), offsets: offsets.clone(), joint: rows_of(&full, &cols) },
        robust: Covariances { keys: keys.to_vec(), offsets, joint: robust },
        clusters: g,
        influences,
    })
}

/// [`covariances`] and the cluster-robust ("sandwich") covariances of `keys`
/// at `values` (see [`RobustCovariances`]): `clusters[fi]` labels factor
/// `fi`'s cluster (`None`: a cluster of its own). Factors whose errors may be
/// correlated — the corners of one view, the views of a few seconds — belong
/// in one cluster; the clusters' errors must be independent.
///
/// ```
/// use tumble_solvers::{cluster_robust_covariances, Graph, NoiseModel, Values, X};
/// use tumble_solvers::testing::LinearFactor;
/// use nalgebra::{DMatrix, DVector, Vector1};
/// // The mean of four measurements, in two clusters that disagree.
/// let y = [1.0, 1.0, 3.0, 3.0];
/// let mut g = Graph::new();
/// for v in y {
///     g.add(LinearFactor::new(vec![X(0)], vec![DMatrix::identity(1, 1)], DVector::from_element(1, -v)), NoiseModel::Unit);
/// }
/// let mut v = Values::new();
/// v.insert(X(0), Vector1::new(2.0));
/// let c = cluster_robust_covariances(&g, &v, &[X(0)], &[Some(0), Some(0), Some(1), Some(1)]).unwrap();
/// assert!((c.model.get(X(0)).unwrap()[(0, 0)] - 0.25).abs() < 1e-12);
/// // Scores ±2/4 per cluster: 2/(2−1) · 2 · 0.25 = 1.
/// assert!((c.robust.get(X(0)).unwrap()[(0, 0)] - 1.0).abs() < 1e-12);
/// ```
pub fn cluster_robust_covariances(
    graph: &Graph,
    values: &Values,
    keys: &[Key],
    clusters: &[Option<usize>],
) -> Result<RobustCovariances, SolveError> {
    let layout = Layout::new(graph, values, &[])?;
    let vars: Vec<Box<dyn DynVariable>> =
        layout.keys.iter().map(|&k| values.get_dyn(k).map(|v| v.clone_box())).collect::<Result<_, _>>()?;
    let mut structure = layout.structure(&vars, LinearSolver::Auto)?;
    let (lins, _) = linearize_all(graph.entries(), &layout, &vars)?;
    let sys = structure.assemble(&lins);
    robust_covariances_of_system(&layout, &mut structure, &sys, &lins, keys, clusters)
}

/// `ln det(JᵀJ)` of the whitened Gauss–Newton information of the free
/// (non-constant) variables of `graph` at `values`, with the χ² there
/// (robust weights included, as in [`covariances`]: `Σ ρ(‖r‖²)`): the terms a Laplace approximation of the
/// marginal likelihood needs (`−2 ln L = χ² + ln det(JᵀJ) + const`, exact for
/// linear factors), e.g. to compare noise models by restricted likelihood.
/// Dense: for graphs of a few hundred variables. An error when the
/// information is singular.
///
/// ```
/// use tumble_solvers::{Graph, Values, NoiseModel, information_log_det, X};
/// use tumble_solvers::testing::LinearFactor;
/// use nalgebra::{DMatrix, DVector, Vector1};
/// let mut g = Graph::new();
/// let i = DMatrix::identity(1, 1);
/// g.add(LinearFactor::new(vec![X(0)], vec![i.clone()], DVector::from_element(1, 1.0)), NoiseModel::isotropic(1, 0.5).unwrap());
/// let mut v = Values::new();
/// v.insert(X(0), Vector1::new(0.0));
/// let (chi2, log_det) = information_log_det(&g, &v).unwrap();
/// assert!((chi2 - 4.0).abs() < 1e-12 && (log_det - 4f64.ln()).abs() < 1e-12);
/// ```
pub fn information_log_det(graph: &Graph, values: &Values) -> Result<(f64, f64), SolveError> {
    let mut keys: Vec<Key> = values.keys().filter(|k| !values.is_constant(*k)).collect();
    keys.sort();
    let mut offsets = HashMap::new();
    let mut n = 0;
    for k in keys {
        offsets.insert(k, n);
        n += values.get_dyn(k)?.dim();
    }
    let mut h = DMatrix::<f64>::zeros(n, n);
    let factors: Vec<usize> = (0..graph.len()).collect();
    let chi2 = add_normal_equations(graph, values, &factors, &offsets, &mut h, &mut DVector::zeros(n))?;
    let chol = nalgebra::Cholesky::new(h)
        .ok_or_else(|| SolveError::Singular("the information of the free variables is singular".into()))?;
    Ok((chi2, 2.0 * chol.l_dirty().diagonal().iter().map(|d| d.ln()).sum::<f64>()))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `(S Jᵀ J S)` for Jacobian rows `rows` of four unknowns, the third of
    /// which no row constrains, scaled by S six orders of magnitude apart.
    fn information(rows: &[[f64; 4]]) -> DMatrix<f64> {
        let j = DMatrix::from_fn(rows.len(), 4, |r, c| rows[r][c]);
        let s = DMatrix::from_diagonal(&DVector::from_vec(vec![1e3, 1.0, 1.0, 1e-3]));
        &s * j.tr_mul(&j) * &s
    }

    const RANK_TWO: [[f64; 4]; 2] = [[1.0, 2.0, 0.0, 0.5], [0.0, 1.0, 0.0, -1.0]];

    #[test]
    fn the_factor_is_a_square_root_and_a_generalized_inverse() {
        let h = information(&RANK_TWO);
        let f = ScaledCholesky::new(&h, "test").unwrap();
        assert_eq!(f.rank(), 2);
        let scale = h.amax();
        // A gradient in the range of h: Rᵀe reproduces it.
        let g = &h * DVector::from_vec(vec![0.3, -1.0, 5.0, 2.0]);
        let (r, e) = f.sqrt_with_offset(4, &g);
        assert!((r.tr_mul(&r) - &h).amax() < 1e-12 * scale, "{}", (r.tr_mul(&r) - &h).amax());
        assert!((r.tr_mul(&e) - &g).amax() < 1e-12 * g.amax());
        let inv = f.pseudo_inverse(4);
        assert!((&h * &inv * &h - &h).amax() < 1e-9 * scale, "{}", (&h * &inv * &h - &h).amax());
        assert!(inv.row(2).iter().chain(inv.column(2).iter()).all(|x| *x == 0.0));
    }

    #[test]
    fn information_below_the_tolerance_is_dropped_and_non_finite_refused() {
        // A third row 10⁻⁹ of the others adds an eigenvalue ~10⁻¹⁸ of theirs.
        let h = information(&[RANK_TWO[0], RANK_TWO[1], [0.0, 0.0, 0.0, 1e-9]]);
        assert_eq!(ScaledCholesky::new(&h, "test").unwrap().rank(), 2);
        let h = information(&[RANK_TWO[0], RANK_TWO[1], [0.0, 0.0, 0.0, 1e-3]]);
        assert_eq!(ScaledCholesky::new(&h, "test").unwrap().rank(), 3);
        let mut h = information(&RANK_TWO);
        h[(0, 1)] = f64::NAN;
        assert!(ScaledCholesky::new(&h, "test").is_err());
        assert_eq!(ScaledCholesky::new(&DMatrix::zeros(0, 0), "test").unwrap().rank(), 0);
    }
}
