//! The value store: current estimates of all variables, keyed by [`Key`].

use crate::error::ValueError;
use crate::factor::{Factor, Linearization, Vars};
use crate::key::Key;
use crate::variable::{DynVariable, Variable};
use std::collections::{BTreeMap, HashSet};

/// Current estimates of the variables of a problem, with a set of variables
/// held constant.
///
/// ```
/// use tumble_solvers::{Values, X};
/// use nalgebra::Vector3;
/// let mut v = Values::new();
/// v.insert(X(0), Vector3::new(1.0, 2.0, 3.0));
/// let x: &Vector3<f64> = v.get(X(0)).unwrap();
/// assert_eq!(x.y, 2.0);
/// assert!(v.get::<Vector3<f64>>(X(1)).is_err());
/// ```
#[derive(Clone, Default, Debug)]
pub struct Values {
    map: BTreeMap<Key, Box<dyn DynVariable>>,
    constant: HashSet<Key>,
}

impl Values {
    /// Empty store.
    pub fn new() -> Self {
        Self::default()
    }
    /// Insert or replace the value of `key`.
    pub fn insert<V: Variable>(&mut self, key: Key, value: V) {
        self.map.insert(key, Box::new(value));
    }
    /// Insert or replace a boxed value.
    pub fn insert_dyn(&mut self, key: Key, value: Box<dyn DynVariable>) {
        self.map.insert(key, value);
    }
    /// Typed access; errors for a missing key or a different type.
    pub fn get<V: Variable>(&self, key: Key) -> Result<&V, ValueError> {
        let v = self.map.get(&key).ok_or(ValueError::Missing(key))?;
        v.as_any().downcast_ref::<V>().ok_or(ValueError::WrongType {
            key,
            stored: v.type_name(),
            requested: std::any::type_name::<V>(),
        })
    }
    /// Untyped access.
    pub fn get_dyn(&self, key: Key) -> Result<&dyn DynVariable, ValueError> {
        self.map.get(&key).map(|b| b.as_ref()).ok_or(ValueError::Missing(key))
    }
    /// A factor's raw (unwhitened) residual at these values; None when one of
    /// its variables is missing or the factor cannot be evaluated there.
    pub fn residual_of(&self, f: &dyn Factor) -> Option<nalgebra::DVector<f64>> {
        f.residual(Vars::new(&self.variables_of(f)?)).ok()
    }
    /// A factor's raw residual and Jacobians at these values (None as [`Values::residual_of`]).
    pub fn linearize(&self, f: &dyn Factor) -> Option<Linearization> {
        f.linearize(Vars::new(&self.variables_of(f)?)).ok()
    }
    /// A factor's variables, in its keys' order (None when one is missing).
    fn variables_of(&self, f: &dyn Factor) -> Option<Vec<&dyn DynVariable>> {
        f.keys().iter().map(|&k| self.get_dyn(k).ok()).collect()
    }
    /// Whether `key` has a value.
    pub fn contains(&self, key: Key) -> bool {
        self.map.contains_key(&key)
    }
    /// Remove `key`, returning its value.
    pub fn remove(&mut self, key: Key) -> Option<Box<dyn DynVariable>> {
        self.constant.remove(&key);
        self.map.remove(&key)
    }
    /// Hold `key` constant (or free it again) during optimization.
    pub fn set_constant(&mut self, key: Key, constant: bool) {
        if constant {
            self.constant.insert(key);
        } else {
            self.constant.remove(&key);
        }
    }
    /// Whether `key` is held constant.
    pub fn is_constant(&self, key: Key) -> bool {
        self.constant.contains(&key)
    }
    /// Number of variables.
    pub fn len(&self) -> usize {
        self.map.len()
    }
    /// Whether the store is empty.
    pub fn is_empty(&self) -> bool {
        self.map.is_empty()
    }
    /// Keys in ascending order.
    pub fn keys(&self) -> impl Iterator<Item = Key> + '_ {
        self.map.keys().copied()
    }
    /// Sum of tangent dimensions of all variables.
    pub fn tangent_dim(&self) -> usize {
        self.map.values().map(|v| v.dim()).sum()
    }
}
