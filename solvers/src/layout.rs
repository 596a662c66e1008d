//! Which variables of a graph are solved for, and how: held constant, kept
//! in the reduced system, or eliminated first by the Schur complement; and
//! each factor's variables by index.

use crate::error::SolveError;
use crate::graph::Graph;
use crate::key::Key;
use crate::values::Values;
use smallvec::SmallVec;

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

/// The roles of one factor's variables, in key order (inline up to four keys).
pub(crate) type Roles = SmallVec<[Role; 4]>;

/// Variables and factors laid out for the linear algebra.
pub(crate) struct Layout {
    /// All variables referenced by factors, ascending.
    pub keys: Vec<Key>,
    pub roles: Vec<Role>,
    /// Variable index of each key position of each factor.
    pub factor_vars: Vec<smallvec::SmallVec<[usize; 4]>>,
    pub kept_vars: Vec<usize>,
    pub elim_vars: Vec<usize>,
    /// Per factor: its JᵀJ never changes (constant Jacobians, no robust loss).
    pub constant_hessian: Vec<bool>,
}

impl Layout {
    pub fn new(graph: &Graph, values: &Values, eliminate: &[char]) -> Result<Self, SolveError> {
        let mut keys: Vec<Key> = Vec::new();
        for (fi, e) in graph.entries().iter().enumerate() {
            let ks = e.factor.keys();
            for (a, k) in ks.iter().enumerate() {
                if ks[..a].contains(k) {
                    return Err(SolveError::BadFactor { factor: fi, what: format!("key {k} appears twice") });
                }
            }
            keys.extend_from_slice(ks);
            if let Some(d) = e.noise.dim() {
                if d != e.factor.residual_dim() {
                    return Err(SolveError::BadFactor {
                        factor: fi,
                        what: format!(
                            "noise model of dimension {d} on a residual of dimension {}",
                            e.factor.residual_dim()
                        ),
                    });
                }
            }
        }
        keys.sort_unstable();
        keys.dedup();
        // Each key looked up once; the first factor naming a missing one is reported.
        if let Some(&missing) = keys.iter().find(|&&k| !values.contains(k)) {
            let fi = graph.entries().iter().position(|e| e.factor.keys().contains(&missing)).unwrap_or(0);
            return Err(SolveError::MissingVariable { factor: fi, key: missing });
        }
        let index = |k: &Key| keys.binary_search(k).expect("every factor key is in `keys`");
        let mut roles = Vec::with_capacity(keys.len());
        let (mut kept_vars, mut elim_vars) = (Vec::new(), Vec::new());
        for (i, k) in keys.iter().enumerate() {
            if values.is_constant(*k) {
                roles.push(Role::Const);
            } else if eliminate.contains(&k.chr()) {
                roles.push(Role::Elim(elim_vars.len()));
                elim_vars.push(i);
            } else {
                roles.push(Role::Kept(kept_vars.len()));
                kept_vars.push(i);
            }
        }
        let factor_vars = graph.entries().iter().map(|e| e.factor.keys().iter().map(index).collect()).collect();
        let constant_hessian =
            graph.entries().iter().map(|e| e.loss.is_none() && e.factor.constant_jacobians()).collect();
        Ok(Layout { keys, roles, factor_vars, kept_vars, elim_vars, constant_hessian })
    }
}
