//! What a rig calibration writes: Kalibr's `camchain-imucam.yaml`, an ASL
//! `camN/sensor.yaml` per camera (what `tumble vio` reads), `rig.json` with
//! every σ, and `report.md` with its figures — all or nothing, and nothing
//! when the result must not be used ([`super::RigResult::refusal`]).

use super::{rotation, BiasSample, CornerResidual, RigInput, RigResult};
use crate::error::OutputError;
use crate::io::kalibr::camchain_blocks;
use crate::model::target::RigCamera;
use crate::plot::{write_panels, ScatterChart, Series, AXIS_COLORS};
use nalgebra::Isometry3;
use plotters::style::RGBColor;
use serde::Serialize;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use tumble_factors::camera::Distortion;

#[derive(Serialize)]
struct CameraJson {
    name: String,
    resolution: [u32; 2],
    camera_model: &'static str,
    distortion_model: &'static str,
    intrinsics: [f64; 4],
    intrinsics_sigma: [f64; 4],
    distortion_coeffs: [f64; 4],
    distortion_sigma: [f64; 4],
    /// IMU ← camera, row-major 4×4.
    t_imu_cam: [[f64; 4]; 4],
    rotation_sigma_deg_body_axes: [f64; 3],
    translation_sigma_m_body_axes: [f64; 3],
    pixel_sigma_px: f64,
    reprojection: super::Reprojection,
    hand_eye_residual_deg: f64,
}

#[derive(Serialize)]
struct RigJson<'a> {
    cameras: Vec<CameraJson>,
    timeshift_cam_imu_s: f64,
    timeshift_cam_imu_sigma_s: Option<f64>,
    coarse_timeshift_s: Option<f64>,
    coarse_rate_correlation: Option<f64>,
    /// Camera n ← camera n−1, row-major 4×4, for n = 1…
    t_cn_cnm1: Vec<[[f64; 4]; 4]>,
    gravity_in_target_m_s2: [f64; 3],
    imu_noise_source: &'a str,
    imu_chi2_per_dof: f64,
    sigma_source: super::SigmaSource,
    frames: usize,
    iterations: usize,
    converged: bool,
    seconds: f64,
    verdicts: Vec<super::Verdict>,
    notes: &'a [String],
    /// The halves of the recording compared (the σ above are widened to cover them).
    #[serde(skip_serializing_if = "Option::is_none")]
    split: Option<&'a crate::model::split::SplitCheck>,
}

fn m4(t: &Isometry3<f64>) -> [[f64; 4]; 4] {
    let m = t.to_homogeneous();
    [0, 1, 2, 3].map(|i| [0, 1, 2, 3].map(|j| m[(i, j)]))
}

fn distortion_name(d: &Distortion) -> (&'static str, &'static str) {
    match d {
        Distortion::None => ("none", "none"),
        Distortion::RadTan { .. } => ("radtan", "radial-tangential"),
        Distortion::Equidistant { .. } => ("equidistant", "equidistant"),
    }
}

/// The rig's cameras as the exporters see them.
pub fn rig_cameras(rig: &RigResult) -> Vec<RigCamera> {
    rig.cameras
        .iter()
        .map(|c| RigCamera {
            model: c.model,
            resolution: c.resolution,
            rate_hz: c.rate_hz,
            t_imu_cam: c.t_bc,
            topic: format!("/{}/image_raw", c.name),
        })
        .collect()
}

/// Kalibr's `camchain-imucam.yaml`.
pub fn camchain_yaml(rig: &RigResult) -> String {
    let mut s = String::from("# Written by tumble calibrate-rig (Kalibr's keys: T_cam_imu maps IMU-frame points into the camera frame; t_imu = t_cam + timeshift_cam_imu).\n");
    s.push_str(&camchain_blocks(&rig_cameras(rig), rig.time_offset_s, false));
    s
}

/// An ASL (EuRoC) camera `sensor.yaml`, with the time offset as a comment and key.
pub fn sensor_yaml(rig: &RigResult, c: usize) -> String {
    let cam = &rig.cameras[c];
    let m = &cam.model;
    let (_, dist) = distortion_name(&m.distortion);
    let d = m.distortion.coefficients();
    let t = m4(&cam.t_bc);
    let mut s = String::from("%YAML:1.0\n# Written by tumble calibrate-rig.\nsensor_type: camera\n");
    let _ = writeln!(s, "comment: {} calibrated on a target by tumble", cam.name);
    let _ = writeln!(s, "# Sensor extrinsics wrt. the body (IMU) frame: p_B = T_BS p_C.");
    let _ = writeln!(
        s,
        "T_BS:\n  cols: 4\n  rows: 4\n  data: [{}]",
        t.iter().flatten().map(|x| format!("{x:?}")).collect::<Vec<_>>().join(", ")
    );
    let _ = writeln!(s, "rate_hz: {:.3}", cam.rate_hz);
    let _ = writeln!(s, "resolution: [{}, {}]", cam.resolution[0], cam.resolution[1]);
    let _ = writeln!(s, "camera_model: pinhole");
    let _ = writeln!(s, "intrinsics: [{:?}, {:?}, {:?}, {:?}] # fu, fv, cu, cv", m.fx, m.fy, m.cx, m.cy);
    let _ = writeln!(s, "distortion_model: {dist}");
    let _ = writeln!(s, "distortion_coefficients: [{:?}, {:?}, {:?}, {:?}]", d[0], d[1], d[2], d[3]);
    let _ = writeln!(s, "# t_imu = t_cam + timeshift_cam_imu [s]");
    let _ = writeln!(s, "timeshift_cam_imu: {:?}", rig.time_offset_s);
    s
}

/// `rig.json`: every parameter with its σ, the verdicts and the notes.
pub fn rig_json(rig: &RigResult) -> Result<String, OutputError> {
    let cameras = rig
        .cameras
        .iter()
        .map(|c| {
            let m = &c.model;
            let (model, _) = distortion_name(&m.distortion);
            let s = c.model_sigma;
            CameraJson {
                name: c.name.clone(),
                resolution: c.resolution,
                camera_model: "pinhole",
                distortion_model: model,
                intrinsics: [m.fx, m.fy, m.cx, m.cy],
                intrinsics_sigma: [s[0], s[1], s[2], s[3]],
                distortion_coeffs: m.distortion.coefficients(),
                distortion_sigma: [s[4], s[5], s[6], s[7]],
                t_imu_cam: m4(&c.t_bc),
                rotation_sigma_deg_body_axes: c.rotation_sigma.map(f64::to_degrees).into(),
                translation_sigma_m_body_axes: c.translation_sigma.into(),
                pixel_sigma_px: c.pixel_sigma,
                reprojection: c.reprojection.clone(),
                hand_eye_residual_deg: c.hand_eye_rms.to_degrees(),
            }
        })
        .collect();
    let j = RigJson {
        cameras,
        timeshift_cam_imu_s: rig.time_offset_s,
        timeshift_cam_imu_sigma_s: rig.time_offset_sigma_s.is_finite().then_some(rig.time_offset_sigma_s),
        coarse_timeshift_s: rig.coarse_time_offset.map(|c| c.0),
        coarse_rate_correlation: rig.coarse_time_offset.map(|c| c.1),
        t_cn_cnm1: rig.chain.iter().map(m4).collect(),
        gravity_in_target_m_s2: rig.gravity_in_target.into(),
        imu_noise_source: &rig.noise_source,
        imu_chi2_per_dof: rig.imu_chi2_per_dof,
        sigma_source: rig.sigma_source.clone(),
        frames: rig.frames,
        iterations: rig.iterations,
        converged: rig.converged,
        seconds: rig.seconds,
        verdicts: rig.verdicts(),
        notes: &rig.notes,
        split: rig.split.as_ref(),
    };
    serde_json::to_string_pretty(&j).map_err(|e| OutputError::Failed(format!("rig.json: {e}")))
}

/// The summary table printed on the terminal and in `report.md`.
pub fn summary_markdown(rig: &RigResult) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "| camera | fx | fy | cx | cy | distortion | T_BC translation [m] | T_BC rotation σ [°] | translation σ [mm] | reprojection RMS / median [px] |");
    let _ = writeln!(s, "|---|---|---|---|---|---|---|---|---|---|");
    for c in &rig.cameras {
        let m = &c.model;
        let s8 = c.model_sigma;
        let d = m.distortion.coefficients();
        let t = c.t_bc.translation.vector;
        let _ = writeln!(
            s,
            "| {} | {:.2} ± {:.2} | {:.2} ± {:.2} | {:.2} ± {:.2} | {:.2} ± {:.2} | [{:.4}, {:.4}, {:.2e}, {:.2e}] | [{:.4}, {:.4}, {:.4}] | {:.3} | {:.2} | {:.3} / {:.3} |",
            c.name, m.fx, s8[0], m.fy, s8[1], m.cx, s8[2], m.cy, s8[3], d[0], d[1], d[2], d[3], t.x, t.y, t.z,
            c.rotation_sigma.max().to_degrees(), c.translation_sigma.max() * 1e3, c.reprojection.rms_px, c.reprojection.median_px
        );
    }
    let _ = writeln!(s);
    if rig.time_offset_sigma_s.is_finite() {
        let _ = writeln!(
            s,
            "Time offset (t_imu = t_cam + shift): {:.3} ms ± {:.3} ms.",
            rig.time_offset_s * 1e3,
            rig.time_offset_sigma_s * 1e3
        );
    } else {
        let _ = writeln!(s, "Time offset held at {:.3} ms (not estimated).", rig.time_offset_s * 1e3);
    }
    for (i, t) in rig.chain.iter().enumerate() {
        let angle = tumble_solvers::lie::so3_log(&rotation(t)).norm().to_degrees();
        let _ = writeln!(
            s,
            "cam{} ← cam{}: baseline {:.4} m, rotation {:.3}°.",
            i + 1,
            i,
            t.translation.vector.norm(),
            angle
        );
    }
    let _ = writeln!(
        s,
        "IMU residuals: χ²/dof {:.2} with the noise of {}. {} frames, {} iterations, {:.1} s.",
        rig.imu_chi2_per_dof, rig.noise_source, rig.frames, rig.iterations, rig.seconds
    );
    let q = &rig.sigma_source;
    let partitions: Vec<String> =
        q.partitions.iter().map(|p| format!("{} blocks of {} frames", p.blocks, p.block_frames)).collect();
    let _ = writeln!(
        s,
        "σ: the largest of the noise model's and the cluster-robust ones over {} and over the target's {} corners; the cluster-robust σ are up to {:.1}× the noise model's{}.",
        partitions.join(", "),
        q.corners,
        q.largest_ratio,
        if q.largest_ratio > 2.0 { " (the corners' errors are alike between views)" } else { "" }
    );
    if let Some(split) = &rig.split {
        let _ = writeln!(
            s,
            "Halves of the recording: RMS normalized difference {:.2} over {} parameters (≈ 1 when the σ are honest); \
             the σ above are widened to cover them.",
            split.rms_z(),
            split.parameters.len()
        );
    }
    let _ = writeln!(s, "\n| parameter | 3σ | accuracy sought | verdict |\n|---|---|---|---|");
    for v in rig.verdicts() {
        let _ = writeln!(
            s,
            "| {} | {:.3e} {} | {:.3e} {} | {} |",
            v.parameter,
            3.0 * v.sigma,
            v.units,
            v.accuracy,
            v.units,
            match &v.reason {
                Some(why) => format!("{} ({why})", v.determination.word()),
                None => v.determination.word().to_string(),
            }
        );
    }
    for n in &rig.notes {
        let _ = writeln!(s, "\n- {n}");
    }
    s
}

const GREY: RGBColor = RGBColor(150, 150, 150);
const RED: RGBColor = RGBColor(200, 30, 30);

fn camera_figure(rig: &RigResult, c: usize, path: &Path) -> Result<(), OutputError> {
    let cam = &rig.cameras[c];
    let bound = 3.0 * cam.pixel_sigma;
    let norm = |r: &[f64; 2]| (r[0] * r[0] + r[1] * r[1]).sqrt();
    let (inl, out): (Vec<&CornerResidual>, Vec<_>) = cam.residuals.iter().partition(|x| norm(&x.2) <= bound);
    let over_time = ScatterChart {
        title: format!("{}: corner reprojection residual over time", cam.name),
        x_label: "t [s]".into(),
        y_label: "|residual| [px]".into(),
        series: vec![Series {
            label: String::new(),
            color: AXIS_COLORS[2],
            points: cam.residuals.iter().map(|x| (x.0, norm(&x.2))).collect(),
            line: false,
        }],
        ..ScatterChart::default()
    };
    let over_image = ScatterChart {
        title: format!("{}: corners over the image (v grows downwards in the image, upwards here)", cam.name),
        x_label: "u [px]".into(),
        y_label: "v [px]".into(),
        series: vec![
            Series {
                label: format!("≤ {bound:.2} px"),
                color: GREY,
                points: inl.iter().map(|x| (x.1[0], x.1[1])).collect(),
                line: false,
            },
            Series {
                label: format!("> {bound:.2} px"),
                color: RED,
                points: out.iter().map(|x| (x.1[0], x.1[1])).collect(),
                line: false,
            },
        ],
        equal_aspect: true,
        ..ScatterChart::default()
    };
    let cloud = ScatterChart {
        title: format!("{}: residual vectors", cam.name),
        x_label: "du [px]".into(),
        y_label: "dv [px]".into(),
        series: vec![Series {
            label: String::new(),
            color: AXIS_COLORS[0],
            points: cam.residuals.iter().map(|x| (x.2[0], x.2[1])).collect(),
            line: false,
        }],
        equal_aspect: true,
        ..ScatterChart::default()
    };
    write_panels(path, &[over_time, over_image, cloud], 900, 1500).map_err(OutputError::from)
}

fn imu_figure(rig: &RigResult, path: &Path) -> Result<(), OutputError> {
    let series = |f: &dyn Fn(&BiasSample) -> nalgebra::Vector3<f64>| {
        (0..3)
            .map(|a| Series {
                label: ["x", "y", "z"][a].into(),
                color: AXIS_COLORS[a],
                points: rig.biases.iter().map(|b| (b.0, f(b)[a])).collect(),
                line: true,
            })
            .collect()
    };
    let mut charts = vec![
        ScatterChart {
            title: "gyro bias".into(),
            x_label: "t [s]".into(),
            y_label: "b_g [rad/s]".into(),
            series: series(&|b| b.2),
            ..ScatterChart::default()
        },
        ScatterChart {
            title: "accelerometer bias".into(),
            x_label: "t [s]".into(),
            y_label: "b_a [m/s²]".into(),
            series: series(&|b| b.1),
            ..ScatterChart::default()
        },
    ];
    if !rig.time_offset_profile.is_empty() {
        charts.push(ScatterChart {
            title: "camera and gyro rotation rates: correlation against the camera's time shift".into(),
            x_label: "shift [ms]".into(),
            y_label: "correlation".into(),
            series: vec![Series {
                label: String::new(),
                color: AXIS_COLORS[0],
                points: rig.time_offset_profile.iter().map(|p| (p.0 * 1e3, p.1)).collect(),
                line: true,
            }],
            ..ScatterChart::default()
        });
    }
    let h = 400 * charts.len() as u32;
    write_panels(path, &charts, 900, h).map_err(OutputError::from)
}

/// Write `camchain-imucam.yaml`, `camN/sensor.yaml`, `rig.json`, `report.md`
/// and its figures into `out` (all or nothing); refuses, writing nothing,
/// when [`RigResult::refusal`] says the result must not be used. The corners
/// of a camera whose images were searched ([`RigInput::from_asl_with_progress`])
/// are written too, as `camN/corners.csv` and `camN/frames.csv`: copied next to
/// the images, they spare the next run the detection.
pub fn write_rig(rig: &RigResult, input: &RigInput, out: &Path) -> Result<Vec<PathBuf>, OutputError> {
    if let Some(why) = rig.refusal() {
        return Err(OutputError::Failed(format!("nothing written to {}: {why}", out.display())));
    }
    crate::io::staging::write_staged(out, |dir| {
        let mut files = Vec::new();
        let mut put = |name: &str, text: String| -> Result<(), OutputError> {
            let p = dir.join(name);
            if let Some(parent) = p.parent() {
                std::fs::create_dir_all(parent).map_err(|e| format!("{}: {e}", parent.display()))?;
            }
            std::fs::write(&p, text).map_err(|e| format!("{}: {e}", p.display()))?;
            files.push(p);
            Ok(())
        };
        put("camchain-imucam.yaml", camchain_yaml(rig))?;
        for c in 0..rig.cameras.len() {
            put(&format!("{}/sensor.yaml", rig.cameras[c].name), sensor_yaml(rig, c))?;
        }
        put("rig.json", rig_json(rig)?)?;
        let mut md = String::from("# Rig calibration\n\n");
        for cam in &input.cameras {
            if let Some(stats) = &cam.detection {
                let (corners, frames) = crate::io::target::corners_csv(&cam.views, &input.target);
                put(&format!("{}/corners.csv", cam.name), corners)?;
                put(&format!("{}/frames.csv", cam.name), frames)?;
                let _ = writeln!(md, "- {} corners detected in the images: {}", cam.name, stats.line());
            }
        }
        if input.cameras.iter().any(|c| c.detection.is_some()) {
            md.push('\n');
        }
        md.push_str(&summary_markdown(rig));
        if let Some(split) = &rig.split {
            let _ = write!(md, "\n## The recording checked against itself\n\n{}", split.markdown());
        }
        for (c, cam) in rig.cameras.iter().enumerate() {
            let name = format!("reprojection_{}.png", cam.name);
            camera_figure(rig, c, &dir.join(&name))?;
            let _ = write!(md, "\n![{} reprojection]({name})\n", cam.name);
            files.push(dir.join(name));
        }
        imu_figure(rig, &dir.join("imu.png"))?;
        md.push_str("\n![IMU biases and time-offset correlation](imu.png)\n");
        files.push(dir.join("imu.png"));
        let p = dir.join("report.md");
        std::fs::write(&p, md).map_err(|e| format!("{}: {e}", p.display()))?;
        files.push(p);
        Ok(files)
    })
}
