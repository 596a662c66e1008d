//! Every built-in factor's Jacobians against central differences.

use nalgebra::{Vector3, Vector6};
use tumble_factors::pose_graph_3d::QuaternionPoseError;
use tumble_factors::{BetweenFactor, PartialPriorFactor, PriorFactor, SnavelyReprojection};
use tumble_solvers::sophus_lie::{Isometry3F64, Rotation3F64};
use tumble_solvers::{check_jacobians, se2, AutoDiff, DynVariable, Factor, Linearization, Vars, C, L, X};

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
    assert_ok(&PartialPriorFactor::new(X(0), z3, vec![0, 4, 5]), &[&a3]);
    assert_ok(&BetweenFactor::new(X(0), X(1), z3), &[&a3, &b3]);
    assert_ok(&QuaternionPoseError::new(X(0), X(1), &z3), &[&a3, &b3]);

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
    assert_ok(&PartialPriorFactor::new(X(0), v2, vec![2, 0]), &[&v1]);
}

#[test]
fn snavely_autodiff_matches_numeric() {
    let f = AutoDiff::new(SnavelyReprojection::new(C(0), L(0), [10.0, -5.0]));
    let cam = nalgebra::SVector::<f64, 9>::from_column_slice(&[0.01, -0.02, 0.03, 0.1, -0.2, -3.0, 500.0, -1e-3, 1e-6]);
    let pt = Vector3::new(0.5, -0.3, 1.0);
    assert_ok(&f, &[&cam, &pt]);
    assert_linearize_into_matches(&f, &[&cam, &pt]);
    // Zero rotation: the first-order branch of the angle-axis rotation.
    let cam0 = nalgebra::SVector::<f64, 9>::from_column_slice(&[0.0, 0.0, 0.0, 0.1, -0.2, -3.0, 500.0, -1e-3, 1e-6]);
    assert_ok(&f, &[&cam0, &pt]);
}

#[test]
fn snavely_analytic_matches_numeric_and_autodiff() {
    let analytic = SnavelyReprojection::new(C(0), L(0), [10.0, -5.0]);
    let auto = AutoDiff::new(analytic.clone());
    let pt = Vector3::new(0.5, -0.3, 1.0);
    // A large rotation with strong distortion, a small one, and zero (the
    // first-order branch).
    for cam in [
        [0.4, -0.7, 1.1, 0.1, -0.2, -3.0, 500.0, -0.3, 0.05],
        [0.01, -0.02, 0.03, 0.1, -0.2, -3.0, 500.0, -1e-3, 1e-6],
        [0.0, 0.0, 0.0, 0.1, -0.2, -3.0, 500.0, -1e-3, 1e-6],
    ] {
        let cam = nalgebra::SVector::<f64, 9>::from_column_slice(&cam);
        let vars: [&dyn tumble_solvers::DynVariable; 2] = [&cam, &pt];
        assert_ok(&analytic, &vars);
        assert_linearize_into_matches(&analytic, &vars);
        let (a, b) = (analytic.linearize(Vars::new(&vars)).unwrap(), auto.linearize(Vars::new(&vars)).unwrap());
        assert!((&a.residual - &b.residual).norm() < 1e-12);
        for (ja, jb) in a.jacobians.iter().zip(&b.jacobians) {
            assert!((ja - jb).norm() <= 1e-9 * jb.norm().max(1.0), "analytic\n{ja}autodiff\n{jb}");
        }
    }
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

/// A preintegration over 0.5 s of a turning, accelerating motion.
fn preintegration(scheme: tumble_factors::imu_preint::Scheme) -> tumble_factors::imu_preint::Preintegrated {
    use tumble_factors::imu_preint::{Preintegrated, PreintegrationParams};
    let params = PreintegrationParams { scheme, ..Default::default() };
    let mut p = Preintegrated::new(params, Vector3::new(0.05, -0.02, 0.1), Vector3::new(0.01, 0.003, -0.02));
    for k in 0..100 {
        let t = k as f64 * 0.005;
        p.integrate(
            Vector3::new(0.8 * (2.0 * t).sin(), 0.3, 9.81 + 0.5 * t),
            Vector3::new(0.4, -0.3 * (3.0 * t).cos(), 0.7 * t),
            0.005,
        );
    }
    p
}

#[test]
fn imu_factor_and_bias_random_walk() {
    use std::sync::Arc;
    use tumble_factors::imu_preint::Scheme;
    use tumble_factors::{bias_random_walk, ImuFactor};
    use tumble_solvers::{B, V};
    let xi = Isometry3F64::exp(Vector6::new(0.3, -0.2, 1.0, 1.0, 2.0, 0.5));
    let xj = Isometry3F64::exp(Vector6::new(0.5, -0.1, 1.3, 1.4, 2.2, 0.3));
    let (vi, vj) = (Vector3::new(0.3, -0.2, 0.1), Vector3::new(0.5, 0.1, -0.2));
    let b = Vector6::new(0.08, -0.01, 0.12, 0.012, 0.001, -0.018);
    for scheme in [Scheme::ZeroOrderHold, Scheme::Midpoint] {
        let f = ImuFactor::new(
            [X(0), V(0), B(0), X(1), V(1)],
            Arc::new(preintegration(scheme)),
            Vector3::new(0.0, 0.0, -9.81),
        );
        assert_ok(&f, &[&xi, &vi, &b, &xj, &vj]);
        assert!(f.noise_model().is_ok());
    }
    let (rw, noise) = bias_random_walk(B(0), B(1), 3e-3, 2e-5, 0.5).unwrap();
    assert_eq!(noise.dim(), Some(6));
    assert_ok(&rw, &[&b, &(b * 1.1)]);
}

#[test]
fn inverse_depth_reprojection_for_every_camera_model() {
    use nalgebra::Vector1;
    use tumble_factors::camera::{CameraModel, Distortion};
    use tumble_factors::reprojection::{AnchorObservation, StereoInverseDepth};
    use tumble_factors::InverseDepthReprojection;
    let t_bc = Isometry3F64::exp(Vector6::new(0.05, -0.02, 0.01, 1.2, -1.2, 1.2));
    let xa = Isometry3F64::exp(Vector6::new(0.3, -0.2, 1.0, 1.0, 2.0, 0.5));
    let xj = Isometry3F64::exp(Vector6::new(0.35, -0.1, 1.0, 1.02, 2.1, 0.45));
    for distortion in [
        Distortion::None,
        Distortion::RadTan { k1: -0.28, k2: 0.07, p1: 2e-4, p2: 1.8e-5 },
        Distortion::Equidistant { k1: 0.01, k2: -0.005, k3: 0.001, k4: -0.0002 },
    ] {
        let cam = CameraModel { fx: 458.0, fy: 457.0, cx: 367.0, cy: 248.0, distortion };
        let f = InverseDepthReprojection::new([X(0), X(1), L(3)], [0.1, -0.08], [400.0, 200.0], cam, &t_bc);
        let rho = Vector1::new(0.35);
        assert_ok(&f, &[&xa, &xj, &rho]);
        assert_linearize_into_matches(&f, &[&xa, &xj, &rho]);
        // Stereo: the same landmark seen by a second camera 0.11 m to the
        // right, at frame j and at the anchor's own frame.
        let t_bc1 = t_bc * Isometry3F64::exp(Vector6::new(0.11, 0.0, 0.0, 0.01, -0.02, 0.005));
        let f1 = f.clone().seen_by(cam, &t_bc1);
        assert_ok(&f1, &[&xa, &xj, &rho]);
        assert_linearize_into_matches(&f1, &[&xa, &xj, &rho]);
        let s = StereoInverseDepth::new(L(3), [0.1, -0.08], [380.0, 240.0], (cam, &t_bc1), &t_bc);
        assert_ok(&s, &[&rho]);
        assert_linearize_into_matches(&s, &[&rho]);
        // The landmark with its bearing estimated ([δx, δy, ρ]) in each, and its anchor observation.
        let l = Vector3::new(0.004, -0.003, 0.35);
        assert_ok(&f, &[&xa, &xj, &l]);
        assert_ok(&f1, &[&xa, &xj, &l]);
        assert_linearize_into_matches(&f1, &[&xa, &xj, &l]);
        assert_ok(&s, &[&l]);
        let a = AnchorObservation::new(L(3), [0.1, -0.08], [410.0, 212.0], cam);
        assert_ok(&a, &[&l]);
        assert_linearize_into_matches(&a, &[&l]);
        assert!(a.residual(Vars::new(&[&rho])).is_err(), "an anchor observation needs the bearing estimated");
    }
}

/// `linearize_into` overwrites whatever buffers it is given — fresh ones, the
/// right shapes full of other numbers, or the wrong shapes — with what
/// `linearize` returns (to rounding: the products may be summed in another order).
fn assert_linearize_into_matches<F: Factor>(f: &F, vars: &[&dyn DynVariable]) {
    let want = f.linearize(Vars::new(vars)).unwrap();
    let mut garbage = want.clone();
    garbage.residual.fill(7.0);
    garbage.jacobians.iter_mut().for_each(|j| j.fill(-3.0));
    let wrong =
        Linearization { residual: nalgebra::DVector::zeros(5), jacobians: vec![nalgebra::DMatrix::zeros(1, 1); 4] };
    for mut out in [Linearization::default(), garbage, wrong] {
        f.linearize_into(Vars::new(vars), &mut out).unwrap();
        assert_eq!(out.residual, want.residual);
        assert_eq!(out.jacobians.len(), want.jacobians.len());
        for (a, b) in out.jacobians.iter().zip(&want.jacobians) {
            assert_eq!(a.shape(), b.shape());
            assert!((a - b).amax() <= 1e-14 * b.amax().max(1.0), "{a} vs {b}");
        }
    }
}

#[test]
fn between_linearize_into_on_every_group() {
    let a3 = Isometry3F64::exp(Vector6::new(0.4, -0.3, 1.1, 1.0, -2.0, 0.3));
    let b3 = Isometry3F64::exp(Vector6::new(-0.2, 0.5, 2.0, -1.0, 0.5, 2.0));
    let z3 = Isometry3F64::exp(Vector6::new(0.1, 0.2, 0.3, 0.3, 0.2, 0.1));
    assert_linearize_into_matches(&BetweenFactor::new(X(0), X(1), z3), &[&a3, &b3]);
    assert_linearize_into_matches(&QuaternionPoseError::new(X(0), X(1), &z3), &[&a3, &b3]);
    let r1 = Rotation3F64::exp(Vector3::new(0.4, -0.3, 1.1));
    let r2 = Rotation3F64::exp(Vector3::new(-1.4, 0.3, 0.1));
    let rz = Rotation3F64::exp(Vector3::new(0.2, 0.2, -0.1));
    assert_linearize_into_matches(&BetweenFactor::new(X(0), X(1), rz), &[&r1, &r2]);
    let (p1, p2) = (se2(1.0, 2.0, 0.3), se2(-1.0, 0.5, 2.8));
    assert_linearize_into_matches(&BetweenFactor::new(X(0), X(1), se2(0.5, 0.2, -0.4)), &[&p1, &p2]);
    let (v1, v2) = (Vector3::new(1.0, 2.0, 3.0), Vector3::new(-1.0, 0.0, 4.0));
    assert_linearize_into_matches(&BetweenFactor::new(X(0), X(1), Vector3::new(0.1, 0.2, 0.3)), &[&v1, &v2]);
    // Over 6 dimensions the adjoint goes to the heap.
    type V9 = nalgebra::SVector<f64, 9>;
    let (w1, w2, wz) = (V9::from_fn(|i, _| i as f64), V9::from_fn(|i, _| -(i as f64) * 0.5), V9::repeat(0.1));
    assert_ok(&BetweenFactor::new(X(0), X(1), wz), &[&w1, &w2]);
    assert_linearize_into_matches(&BetweenFactor::new(X(0), X(1), wz), &[&w1, &w2]);
}

/// The audit's factors with every modelled effect switched on at once, with
/// realistic magnitudes and a non-trivial temperature and time.
#[test]
fn audit_factors_with_every_effect() {
    use tumble_factors::imu_calib::{AccelParams, GyroMatrix};
    use tumble_factors::imu_effects::{Context, Effect, Layout, MotionFactor, MotionSamples, StaticFactor};
    use tumble_solvers::{DynVector, Key};
    let effects: Vec<Effect> = Effect::ALL.into_iter().filter(|e| e.in_sensor_model()).collect();
    let layout = Layout { effects: effects.clone() };
    let values: Vec<DynVector> = effects
        .iter()
        .map(|e| {
            DynVector::from_slice(
                &(0..e.dim()).map(|i| 1e-3 * (1.0 + i as f64) * (-1f64).powi(i as i32)).collect::<Vec<_>>(),
            )
        })
        .collect();
    let a = AccelParams::from_row_slice(&[1.01, 0.01, -0.02, 0.99, 0.015, 1.003, 0.05, 0.1, -0.07]);
    let g = GyroMatrix::from_row_slice(&[1.0, 0.01, 0.0, -0.01, 0.995, 0.02, 0.01, 0.0, 1.004]);
    let (b0, b1) = (Vector3::new(0.01, -0.002, 0.003), Vector3::new(0.0105, -0.0018, 0.0031));
    let (w0, w1) = (Vector3::new(0.001, 0.0, -0.002), Vector3::new(0.0, 0.003, 0.001));
    let key = |i: u64| Key::new('k', i);
    let mut vars: Vec<&dyn DynVariable> = vec![&a, &g, &b0, &w0];
    vars.extend(values.iter().map(|v| v as &dyn DynVariable));
    let keys = (0..vars.len() as u64).map(key).collect();
    let ctx = Context { dtemp: 6.5, time: 42.0 };
    let f = StaticFactor::new(
        keys,
        layout.clone(),
        Vector3::new(3.1, -4.0, 8.1),
        Vector3::new(0.013, -0.004, 0.002),
        ctx,
        9.81,
    )
    .unwrap();
    assert_ok(&f, &vars);
    let n = 60;
    let samples = MotionSamples {
        raw_gyro: (0..n).map(|i| Vector3::new(1.1 * (i as f64 * 0.05).sin(), 0.7, -0.4 + 0.01 * i as f64)).collect(),
        raw_accel: (0..n).map(|i| Vector3::new(1.0 + 0.05 * i as f64, 2.0, 9.0 - 0.03 * i as f64)).collect(),
        context: (0..n).map(|i| Context { dtemp: 6.0 + 0.01 * i as f64, time: 40.0 + 0.005 * i as f64 }).collect(),
        dt: vec![0.005; n - 1],
    };
    let mut vars: Vec<&dyn DynVariable> = vec![&a, &g, &b0, &b1, &w0, &w1];
    vars.extend(values.iter().map(|v| v as &dyn DynVariable));
    let keys = (0..vars.len() as u64).map(key).collect();
    let ends = [Vector3::new(0.5, 2.0, 9.6), Vector3::new(2.5, 1.0, 9.4)];
    let f = MotionFactor::new(
        keys,
        layout,
        samples,
        ends,
        [Context { dtemp: 5.9, time: 39.0 }, Context { dtemp: 6.7, time: 41.0 }],
        [300, 300],
    )
    .unwrap();
    assert_ok(&f, &vars);
}
