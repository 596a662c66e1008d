//! Every built-in factor's Jacobians against central differences.

use nalgebra::{Vector3, Vector6};
use tumble_factors::{BetweenFactor, PriorFactor, SnavelyReprojection};
use tumble_solvers::sophus_lie::{Isometry3F64, Rotation3F64};
use tumble_solvers::{check_jacobians, se2, AutoDiff, DynVariable, Factor, C, L, X};

fn assert_ok<F: Factor>(f: &F, vars: &[&dyn DynVariable]) {
    let r = check_jacobians(f, vars).unwrap();
    assert!(r.passes(1e-6), "Jacobian check failed: {r:?}");
}

#[test]
fn prior_and_between_on_every_group() {
    let a3 = Isometry3F64::exp(Vector6::new(0.4, -0.3, 1.1, 1.0, -2.0, 0.3));
    let b3 = Isometry3F64::exp(Vector6::new(-0.2, 0.5, 2.0, -1.0, 0.5, 2.0));
    let z3 = Isometry3F64::exp(Vector6::new(0.1, 0.2, 0.3, 0.3, 0.2, 0.1));
    assert_ok(&PriorFactor::new(X(0), z3), &[&a3]);
    assert_ok(&BetweenFactor::new(X(0), X(1), z3), &[&a3, &b3]);

    let r1 = Rotation3F64::exp(Vector3::new(0.4, -0.3, 1.1));
    let r2 = Rotation3F64::exp(Vector3::new(-1.4, 0.3, 0.1));
    let rz = Rotation3F64::exp(Vector3::new(0.2, 0.2, -0.1));
    assert_ok(&PriorFactor::new(X(0), rz), &[&r1]);
    assert_ok(&BetweenFactor::new(X(0), X(1), rz), &[&r1, &r2]);

    let p1 = se2(1.0, 2.0, 0.3);
    let p2 = se2(-1.0, 0.5, 2.8);
    let pz = se2(0.5, 0.2, -0.4);
    assert_ok(&PriorFactor::new(X(0), pz), &[&p1]);
    assert_ok(&BetweenFactor::new(X(0), X(1), pz), &[&p1, &p2]);
    // Near-zero rotation takes the series branches.
    assert_ok(&BetweenFactor::new(X(0), X(1), se2(0.5, 0.2, 0.0)), &[&se2(0.0, 0.0, 0.0), &se2(0.5, 0.2, 1e-9)]);

    let v1 = Vector3::new(1.0, 2.0, 3.0);
    let v2 = Vector3::new(-1.0, 0.0, 4.0);
    assert_ok(&BetweenFactor::new(X(0), X(1), Vector3::new(0.1, 0.2, 0.3)), &[&v1, &v2]);
}

#[test]
fn snavely_autodiff_matches_numeric() {
    let f = AutoDiff::new(SnavelyReprojection::new(C(0), L(0), [10.0, -5.0]));
    let cam = nalgebra::SVector::<f64, 9>::from_column_slice(&[0.01, -0.02, 0.03, 0.1, -0.2, -3.0, 500.0, -1e-3, 1e-6]);
    let pt = Vector3::new(0.5, -0.3, 1.0);
    assert_ok(&f, &[&cam, &pt]);
    // Zero rotation: the first-order branch of the angle-axis rotation.
    let cam0 = nalgebra::SVector::<f64, 9>::from_column_slice(&[0.0, 0.0, 0.0, 0.1, -0.2, -3.0, 500.0, -1e-3, 1e-6]);
    assert_ok(&f, &[&cam0, &pt]);
}

#[test]
fn imu_calibration_factors() {
    use tumble_factors::imu_calib::{AccelParams, GyroMatrix};
    use tumble_factors::{GravityNormFactor, IntegratedRotationFactor};
    let key = tumble_solvers::Key::new('a', 0);
    // Raw counts around 33000 with a scale of 1/415 m/s² per count, as the Xsens data.
    let p = AccelParams::from_row_slice(&[2.41e-3, -8e-6, 2e-5, 2.43e-3, 5e-5, 2.41e-3, 33124.0, 33275.0, 32364.0]);
    assert_ok(&GravityNormFactor::new(key, Vector3::new(33500.0, 29300.0, 33100.0), 9.81), &[&p]);
    // A 100-sample turn of ≈ 90° about a moving axis, with misalignment and bias.
    let raw: Vec<[f64; 3]> = (0..100)
        .map(|i| {
            let s = (i as f64 / 99.0 * std::f64::consts::PI).sin();
            [1.2 * s + 0.01, -0.6 * s * s, 0.3 * s + 0.2 * (i as f64 * 0.1).cos()]
        })
        .collect();
    let m = GyroMatrix::from_row_slice(&[1.01, 0.02, -0.01, -0.015, 0.99, 0.03, 0.02, -0.01, 1.005]);
    let b = Vector3::new(0.01, -0.02, 0.005);
    let f = IntegratedRotationFactor::new(
        [tumble_solvers::Key::new('g', 0), tumble_solvers::Key::new('g', 1)],
        raw,
        vec![0.02; 99],
        Vector3::new(0.1, 0.2, 1.0),
        Vector3::new(0.7, -0.1, 0.6),
    )
    .unwrap();
    assert_ok(&f, &[&m, &b]);
}
