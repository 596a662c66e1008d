//! Kalibr's YAML: the per-camera blocks of `camchain-imucam.yaml` and the
//! number and matrix formatting every exported YAML shares.

use crate::model::target::RigCamera;
use nalgebra::{Isometry3, Matrix3, Matrix4};
use std::fmt::Write;
use tumble_factors::camera::Distortion;

/// A number as YAML writes it (shortest round-trip form).
pub(crate) fn num(x: f64) -> String {
    format!("{x:?}")
}

/// Numbers as a YAML flow list's items.
pub(crate) fn list(v: &[f64]) -> String {
    v.iter().map(|x| num(*x)).collect::<Vec<_>>().join(", ")
}

/// A matrix as YAML rows (`- [a, b, c]`) at `indent` spaces.
pub(crate) fn rows(m: &[Vec<f64>], indent: usize) -> String {
    m.iter().map(|r| format!("{}- [{}]\n", " ".repeat(indent), list(r))).collect()
}

/// A 3×3 matrix as rows.
pub(crate) fn m3(m: &Matrix3<f64>) -> Vec<Vec<f64>> {
    (0..3).map(|i| (0..3).map(|j| m[(i, j)]).collect()).collect()
}

/// An isometry's 4×4 homogeneous matrix as rows.
pub(crate) fn m4(t: &Isometry3<f64>) -> Vec<Vec<f64>> {
    let m: Matrix4<f64> = t.to_homogeneous();
    (0..4).map(|i| (0..4).map(|j| m[(i, j)]).collect()).collect()
}

/// Kalibr's distortion model name and coefficients of a camera.
pub(crate) fn kalibr_camera(c: &RigCamera) -> (&'static str, Vec<f64>) {
    match c.model.distortion {
        Distortion::None => ("none", Vec::new()),
        Distortion::RadTan { k1, k2, p1, p2 } => ("radtan", vec![k1, k2, p1, p2]),
        Distortion::Equidistant { k1, k2, k3, k4 } => ("equidistant", vec![k1, k2, k3, k4]),
    }
}

/// Kalibr's per-camera blocks (`cam0:`, `cam1:` …) of `camchain-imucam.yaml`
/// (`T_cam_imu` and `T_cn_cnm1`) or, with `t_imu_cam_key`, of Basalt-style
/// `T_imu_cam` listings; `dt` is `timeshift_cam_imu` \[s\] (`t_imu = t_cam + dt`).
pub(crate) fn camchain_blocks(cameras: &[RigCamera], dt: f64, t_imu_cam_key: bool) -> String {
    let mut s = String::new();
    for (i, c) in cameras.iter().enumerate() {
        let (dist, d) = kalibr_camera(c);
        let _ = writeln!(s, "cam{i}:");
        if t_imu_cam_key {
            let _ = writeln!(s, "  T_imu_cam:");
            s.push_str(&rows(&m4(&c.t_imu_cam), 4));
        } else {
            let _ = writeln!(s, "  T_cam_imu:");
            s.push_str(&rows(&m4(&c.t_imu_cam.inverse()), 2));
            if i > 0 {
                let rel = c.t_imu_cam.inverse() * cameras[i - 1].t_imu_cam;
                let _ = writeln!(s, "  T_cn_cnm1:");
                s.push_str(&rows(&m4(&rel), 2));
            }
        }
        let overlaps: Vec<String> = (0..cameras.len()).filter(|&j| j != i).map(|j| j.to_string()).collect();
        let _ = writeln!(s, "  cam_overlaps: [{}]", overlaps.join(", "));
        let _ = writeln!(s, "  camera_model: pinhole");
        let _ = writeln!(s, "  distortion_coeffs: [{}]", list(&d));
        let _ = writeln!(s, "  distortion_model: {dist}");
        let m = &c.model;
        let _ = writeln!(s, "  intrinsics: [{}]", list(&[m.fx, m.fy, m.cx, m.cy]));
        let _ = writeln!(s, "  resolution: [{}, {}]", c.resolution[0], c.resolution[1]);
        let _ = writeln!(s, "  rostopic: {}", c.topic);
        let _ = writeln!(s, "  timeshift_cam_imu: {}", num(dt));
    }
    s
}
