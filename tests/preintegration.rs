//! IMU preintegration against GTSAM's `PreintegratedImuMeasurements`
//! (`../shared/data/anchors/gtsam_preint/`, printed by GTSAM itself).

mod common;

use nalgebra::{Matrix3, Vector3};
use serde_json::Value;
use std::f64::consts::PI;
use tumble_factors::imu_preint::{Preintegrated, PreintegrationParams, Scheme};
use tumble_solvers::lie::so3_log;

fn vec_of(v: &Value) -> Vec<f64> {
    v.as_array().unwrap().iter().map(|x| x.as_f64().unwrap()).collect()
}
fn mat_of(v: &Value) -> Vec<Vec<f64>> {
    v.as_array().unwrap().iter().map(vec_of).collect()
}

/// The anchor's signal, integrated the way the anchor script does.
fn anchor_preintegration(a: &Value, bias_acc: Vector3<f64>, bias_gyro: Vector3<f64>) -> Preintegrated {
    let n = a["N"].as_u64().unwrap() as usize;
    let dt = a["dt"].as_f64().unwrap();
    let ba = Vector3::from_vec(vec_of(&a["bias_acc"]));
    let bg = Vector3::from_vec(vec_of(&a["bias_gyro"]));
    let params = PreintegrationParams {
        accel_noise_density: a["acc_noise_density"].as_f64().unwrap(),
        gyro_noise_density: a["gyro_noise_density"].as_f64().unwrap(),
        integration_sigma: 0.0,
        scheme: Scheme::ZeroOrderHold,
        ..Default::default()
    };
    let mut p = Preintegrated::new(params, bias_acc, bias_gyro);
    for k in 0..n {
        let t = k as f64 * dt;
        let w = Vector3::new(0.3 * (2.0 * PI * 0.5 * t).sin(), 0.2 * (2.0 * PI * 0.3 * t).cos(), 0.1 + 0.05 * t);
        let f = Vector3::new(0.5 + 0.1 * t, -0.3 * (2.0 * PI * 1.0 * t).sin(), 9.81 + 0.2 * (2.0 * PI * 1.0 * t).cos());
        p.integrate(f + ba, w + bg, dt);
    }
    p
}

#[test]
fn zero_order_hold_equals_gtsam_to_1e_8() {
    let Some(path) = common::shared("anchors/gtsam_preint/preint_crosscheck.json") else { return };
    let a: Value = serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
    let ba = Vector3::from_vec(vec_of(&a["bias_acc"]));
    let bg = Vector3::from_vec(vec_of(&a["bias_gyro"]));
    let p = anchor_preintegration(&a, ba, bg);

    let mut worst: Vec<(&str, f64)> = Vec::new();
    worst.push(("deltaTij", (p.delta_t() - a["deltaTij"].as_f64().unwrap()).abs()));
    let r = mat_of(&a["deltaRij_matrix"]);
    let rg = Matrix3::from_fn(|i, j| r[i][j]);
    worst.push(("deltaRij", (p.delta_rotation() - rg).amax()));
    worst.push(("rotvec", (so3_log(&p.delta_rotation()) - Vector3::from_vec(vec_of(&a["deltaRij_rotvec"]))).amax()));
    worst.push(("deltaPij", (p.delta_position() - Vector3::from_vec(vec_of(&a["deltaPij"]))).amax()));
    worst.push(("deltaVij", (p.delta_velocity() - Vector3::from_vec(vec_of(&a["deltaVij"]))).amax()));
    // Covariance: GTSAM's preintMeasCov in [R, P, V] order = ours; compared relative to its largest entry.
    let c = mat_of(&a["preintMeasCov_9x9_order_R_P_V"]);
    let cov = p.raw_covariance();
    let scale = c.iter().flatten().fold(0.0f64, |m, x| m.max(x.abs()));
    let mut dc = 0.0f64;
    for i in 0..9 {
        for j in 0..9 {
            dc = dc.max((cov[(i, j)] - c[i][j]).abs() / scale);
        }
    }
    worst.push(("preintMeasCov (relative to its largest entry)", dc));
    // Bias Jacobians: GTSAM's printed ones are central differences (step 1e-6) of its
    // first-order prediction, so they carry ~1e-9 of difference noise themselves.
    let jf = mat_of(&a["bias_jacobian_first_order_rows_theta_p_v_cols_dba_dbg"]);
    let (hba, hbg) = p.bias_jacobians();
    let mut dj = 0.0f64;
    for i in 0..9 {
        for j in 0..3 {
            dj = dj.max((hba[(i, j)] - jf[i][j]).abs()).max((hbg[(i, j)] - jf[i][j + 3]).abs());
        }
    }
    worst.push(("bias Jacobians", dj));
    // First-order correction for the anchor's bias update, against GTSAM's predict().
    let dba = Vector3::repeat(0.01);
    let dbg = Vector3::repeat(0.001);
    let (r1, p1, v1, _) = p.corrected(&(ba + dba), &(bg + dbg));
    let want = vec_of(&a["corrected_delta_for_dba_0.01_dbg_0.001_theta_p_v"]);
    let got: Vec<f64> = so3_log(&r1).iter().chain(p1.iter()).chain(v1.iter()).copied().collect();
    // GTSAM ran this one with g = 0 (same deltas).
    worst.push(("corrected delta", got.iter().zip(&want).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max)));
    for (what, d) in &worst {
        println!("{what:<48} max |tumble − GTSAM| = {d:.2e}");
    }
    for (what, d) in worst {
        assert!(d <= 1e-8, "{what} differs from GTSAM by {d:e}");
    }
}

#[test]
fn zero_order_hold_bias_jacobians_match_gtsam_reintegration() {
    let Some(path) = common::shared("anchors/gtsam_preint/preint_crosscheck.json") else { return };
    let a: Value = serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
    let ba = Vector3::from_vec(vec_of(&a["bias_acc"]));
    let bg = Vector3::from_vec(vec_of(&a["bias_gyro"]));
    // Re-integrating at a perturbed bias must give GTSAM's re-integrated deltas.
    let dba = Vector3::repeat(0.01);
    let dbg = Vector3::repeat(0.001);
    let mut p = anchor_preintegration(&a, ba, bg);
    p.reintegrate(ba + dba, bg + dbg);
    let want = vec_of(&a["reintegrated_delta_for_dba_0.01_dbg_0.001_theta_p_v"]);
    let got: Vec<f64> = so3_log(&p.delta_rotation())
        .iter()
        .chain(p.delta_position().iter())
        .chain(p.delta_velocity().iter())
        .copied()
        .collect();
    let d = got.iter().zip(&want).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max);
    println!("re-integrated delta: max |tumble − GTSAM| = {d:.2e}");
    assert!(d < 1e-8, "{got:?} vs {want:?}");
}
