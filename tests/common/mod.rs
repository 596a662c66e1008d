//! Helpers shared by the integration tests.

#![allow(dead_code)]

pub mod cdr;
pub mod vio;

use std::path::{Path, PathBuf};

/// A path under the datasets' folder (`$TUMBLE_DATA`, else `../shared/data/`
/// beside the project), or None (with a printed SKIPPED line) when it is absent.
pub fn shared(rel: &str) -> Option<PathBuf> {
    let root = std::env::var_os(tumble::io::datasets::DATA_VAR)
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data"));
    let p = root.join(rel);
    if p.exists() {
        Some(p)
    } else {
        println!("SKIPPED: {} is absent (docs/datasets.md)", p.display());
        None
    }
}

/// A rig calibration's error against a simulation's truth, for camera 0:
/// the rotation error about the body axes \[rad\], the translation error
/// along them \[m\], and every parameter's error over its σ (rotation x y z,
/// translation x y z, fx, fy, cx, cy, time offset).
pub fn rig_errors(
    rig: &tumble::rig::RigResult,
    truth: &tumble::sim::target::RigTruth,
) -> (nalgebra::Vector3<f64>, nalgebra::Vector3<f64>, [f64; 11]) {
    camera_errors(rig, 0, truth, &truth.t_bc)
}

/// [`rig_errors`] for camera `c`, whose true `T_BC` is `t_bc` (the model and
/// the time offset are the truth's).
pub fn camera_errors(
    rig: &tumble::rig::RigResult,
    c: usize,
    truth: &tumble::sim::target::RigTruth,
    t_bc: &nalgebra::Isometry3<f64>,
) -> (nalgebra::Vector3<f64>, nalgebra::Vector3<f64>, [f64; 11]) {
    let c = &rig.cameras[c];
    let r = |t: &nalgebra::Isometry3<f64>| *t.rotation.to_rotation_matrix().matrix();
    let dr = tumble::solvers::lie::so3_log(&(r(&c.t_bc) * r(t_bc).transpose()));
    let dt = c.t_bc.translation.vector - t_bc.translation.vector;
    let (m, s) = (&c.model, &c.model_sigma);
    let normalized = [
        dr.x / c.rotation_sigma.x,
        dr.y / c.rotation_sigma.y,
        dr.z / c.rotation_sigma.z,
        dt.x / c.translation_sigma.x,
        dt.y / c.translation_sigma.y,
        dt.z / c.translation_sigma.z,
        (m.fx - truth.model.fx) / s[0],
        (m.fy - truth.model.fy) / s[1],
        (m.cx - truth.model.cx) / s[2],
        (m.cy - truth.model.cy) / s[3],
        (rig.time_offset_s - truth.time_offset_s) / rig.time_offset_sigma_s,
    ];
    (dr, dt, normalized)
}
