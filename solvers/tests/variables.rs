//! The manifold invariants of every variable type the solver ships, checked
//! with the battery a user runs on their own ([`check_variable`]), and the
//! battery catching a broken type.

use nalgebra::{DMatrix, SVector, Vector3};
use tumble_solvers::sophus_lie::{Isometry2F64, Isometry3F64, Rotation3F64};
use tumble_solvers::testing::check_variable;
use tumble_solvers::Variable;

/// Small steps of every direction and a larger one, `dim` long.
fn steps(dim: usize) -> Vec<Vec<f64>> {
    let mut out: Vec<Vec<f64>> = (0..dim)
        .map(|k| {
            let mut d = vec![0.0; dim];
            d[k] = 1e-3;
            d
        })
        .collect();
    out.push((0..dim).map(|k| 0.3 * (k as f64 + 1.0) / dim as f64 * if k % 2 == 0 { 1.0 } else { -1.0 }).collect());
    out
}

#[test]
fn shipped_variables_pass_the_battery() {
    let r = Rotation3F64::identity().retract(&[0.4, -0.2, 1.1]);
    check_variable(&r, &steps(3), 1e-9).unwrap();
    check_variable(&Rotation3F64::identity(), &steps(3), 1e-9).unwrap();
    let x = Isometry3F64::identity().retract(&[0.4, -0.2, 1.1, 3.0, -1.0, 0.5]);
    check_variable(&x, &steps(6), 1e-9).unwrap();
    let p = Isometry2F64::identity().retract(&[0.7, 2.0, -3.0]);
    check_variable(&p, &steps(3), 1e-9).unwrap();
    check_variable(&Vector3::new(1.0, -2.0, 3.0), &steps(3), 1e-12).unwrap();
    check_variable(&SVector::<f64, 9>::from_element(0.5), &steps(9), 1e-12).unwrap();
}

/// A scalar whose `local` halves what it subtracts: wrong away from zero.
#[derive(Clone, Debug)]
struct BrokenLocal(f64);

impl Variable for BrokenLocal {
    const DIM: usize = 1;
    fn retract(&self, delta: &[f64]) -> Self {
        BrokenLocal(self.0 + delta[0])
    }
    fn local(&self, other: &Self) -> Vec<f64> {
        vec![other.0 - self.0 * 0.5]
    }
    fn params(&self) -> Vec<f64> {
        vec![self.0]
    }
}

/// A scalar with the right `local` but a wrong Jacobian of its parameters.
#[derive(Clone, Debug)]
struct BrokenJacobian(f64);

impl Variable for BrokenJacobian {
    const DIM: usize = 1;
    fn retract(&self, delta: &[f64]) -> Self {
        BrokenJacobian(self.0 + delta[0])
    }
    fn local(&self, other: &Self) -> Vec<f64> {
        vec![other.0 - self.0]
    }
    fn params(&self) -> Vec<f64> {
        vec![self.0]
    }
    fn params_jacobian(&self) -> DMatrix<f64> {
        DMatrix::from_element(1, 1, 2.0)
    }
}

#[test]
fn the_battery_names_what_is_broken() {
    let e = check_variable(&BrokenLocal(2.0), &steps(1), 1e-9).unwrap_err();
    assert_eq!(e.check, "local-of-self", "{e}");
    // At zero `local(x, x)` and the round trip from x hold; going back from y does not.
    let e = check_variable(&BrokenLocal(0.0), &steps(1), 1e-9).unwrap_err();
    assert_eq!(e.check, "retract-of-local", "{e}");
    let e = check_variable(&BrokenJacobian(1.0), &steps(1), 1e-9).unwrap_err();
    assert_eq!(e.check, "params-jacobian", "{e}");
}
