//! The files of each target, as text (see `docs/export.md` for the example
//! configuration each layout follows).

use super::intrinsics::{rotation_times_lower, upper_times_rotation};
use super::{ExportInputs, NoiseConvention, Target};
use crate::error::OutputError;
use crate::io::kalibr::{camchain_blocks, list, m3, m4, num, rows};
use crate::model::target::RigCamera;
use nalgebra::{Isometry3, Matrix3, Vector3};
use std::fmt::Write;
use tumble_factors::camera::Distortion;

/// (file name, contents) per file, and notes for the user.
type Rendered = (Vec<(String, String)>, Vec<String>);

/// A number as the shortest text that reads back to the same f64.
/// An OpenCV FileStorage matrix (`!!opencv-matrix`, row-major, doubles) as a key's value.
fn cv_matrix(m: &[Vec<f64>]) -> String {
    let data: Vec<f64> = m.iter().flatten().copied().collect();
    format!(
        "!!opencv-matrix\n   rows: {}\n   cols: {}\n   dt: d\n   data: [{}]\n",
        m.len(),
        m.first().map_or(0, Vec::len),
        list(&data)
    )
}

/// The comment block every file starts with: sources, noise convention, inflation.
fn header(target: Target, inp: &ExportInputs, comment: &str) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "{comment} Written by `tumble export --for {}`.", target.id());
    for src in &inp.sources {
        let _ = writeln!(s, "{comment}   {src}");
    }
    let conv = match target.convention() {
        NoiseConvention::Continuous => "continuous-time densities (unit/sqrt(Hz), unit/s/sqrt(Hz))".to_string(),
        NoiseConvention::DiscretePerSample => {
            format!("discrete-time sigmas per sample at {:.3} Hz (continuous x sqrt(rate))", inp.rate_hz)
        }
    };
    let _ = writeln!(s, "{comment} IMU noise: {conv}.");
    for r in &inp.inflation.reasons {
        let _ = writeln!(s, "{comment}   inflation: {r}");
    }
    s
}

/// `(M_a, M_g, b_a, b_g)` of `raw = M x + b` in SI.
type SiModel = (Matrix3<f64>, Matrix3<f64>, Vector3<f64>, Vector3<f64>);

/// The calibration in SI (None when there is none, or it maps raw counts).
fn si_calibration(inp: &ExportInputs, notes: &mut Vec<String>) -> Option<SiModel> {
    let c = inp.calibration.as_ref()?;
    if c.units.accel_input != "m/s^2" || c.units.gyro_input != "rad/s" {
        notes.push(format!(
            "the calibration maps raw counts ({} / {}): no intrinsics written; feed the estimator the recording \
             corrected by `tumble apply`",
            c.units.accel_input, c.units.gyro_input
        ));
        return None;
    }
    Some((c.accel.matrix(), c.gyro.matrix(), c.accel.b, c.gyro.b))
}

/// The gyro g-sensitivity `G` of the calibration (rad/s per m/s², in the corrected frame), if found.
fn g_sensitivity(inp: &ExportInputs) -> Option<Matrix3<f64>> {
    let e = inp.calibration.as_ref()?.effects.as_ref()?;
    let term = e.effects.iter().find(|t| t.id == "gyro_g_sensitivity")?;
    let (_, v) = term.values().ok()?;
    Some(Matrix3::from_row_slice(&v))
}

/// What the user must do about the parts of the calibration `target` cannot carry.
/// `intrinsics`: the target models scale and misalignment; `modelled`: the effects it models.
fn apply_note(inp: &ExportInputs, target: Target, intrinsics: bool, modelled: &[&str], notes: &mut Vec<String>) {
    if inp.calibration.is_none() {
        return;
    }
    let missing = inp.unmodelled_effects(modelled);
    let also = if missing.is_empty() { String::new() } else { format!(" and {}", missing.join(", ")) };
    if !intrinsics {
        notes.push(format!(
            "{} models no IMU intrinsics: run it on the recording corrected by `tumble apply` (scale, misalignment{also})",
            target.id()
        ));
    } else if !missing.is_empty() {
        notes.push(format!(
            "{} does not model {}: run it on the recording corrected by `tumble apply`, with files exported without \
             --calibration (identity intrinsics), or accept the error",
            target.id(),
            missing.join(", ")
        ));
    }
}

/// Kalibr's camera block fields (model, distortion name and coefficients, intrinsics).
fn kalibr_cameras(inp: &ExportInputs, t_imu_cam_key: bool) -> String {
    camchain_blocks(&inp.cameras, inp.camera_time_offset(), t_imu_cam_key)
}

fn kalibr_imu_lines(inp: &ExportInputs, indent: &str) -> String {
    let [gn, an, gw, aw] = inp.scalars(NoiseConvention::Continuous);
    let mut s = String::new();
    let _ = writeln!(s, "{indent}accelerometer_noise_density: {}", num(an));
    let _ = writeln!(s, "{indent}accelerometer_random_walk: {}", num(aw));
    let _ = writeln!(s, "{indent}gyroscope_noise_density: {}", num(gn));
    let _ = writeln!(s, "{indent}gyroscope_random_walk: {}", num(gw));
    let _ = writeln!(s, "{indent}rostopic: {}", inp.imu_topic);
    let _ = writeln!(s, "{indent}update_rate: {}", num(inp.rate_hz));
    s
}

fn kalibr(inp: &ExportInputs) -> Rendered {
    let mut notes = Vec::new();
    let mut imu = header(Target::Kalibr, inp, "#");
    imu.push_str(&kalibr_imu_lines(inp, ""));
    let mut files = vec![("imu.yaml".to_string(), imu)];
    if !inp.cameras.is_empty() {
        let mut cam = header(Target::Kalibr, inp, "#");
        cam.push_str(&kalibr_cameras(inp, false));
        files.push(("camchain-imucam.yaml".into(), cam));
    }
    apply_note(inp, Target::Kalibr, false, &[], &mut notes);
    (files, notes)
}

fn openvins(inp: &ExportInputs) -> Result<Rendered, OutputError> {
    let mut notes = Vec::new();
    let mut s = String::from("%YAML:1.0\n");
    s.push_str(&header(Target::OpenVins, inp, "#"));
    let id = Matrix3::identity();
    let (mut tw, mut rg, mut ta, mut tg) = (id, id, id, Matrix3::zeros());
    if let Some((ma, mg, ba, bg)) = si_calibration(inp, &mut notes) {
        // OpenVINS: w_m = Tw R_IMUtoGYRO w + Tg a + b_g, a_m = Ta R_IMUtoACC a + b_a; rpng: Tw, Ta upper triangular.
        let (u, r) = upper_times_rotation(&mg).ok_or("the gyro matrix T_g K_g has a non-positive determinant")?;
        (tw, rg, ta) = (u, r, ma);
        if let Some(g) = g_sensitivity(inp) {
            tg = mg * g;
        }
        s.push_str(&format!(
            "# Intrinsics from tumble's calibration (model rpng: Tw, Ta upper triangular; the accelerometer frame is the IMU frame).\n# Biases are estimated online; tumble found b_a = [{}] m/s^2, b_g = [{}] rad/s.\n",
            list(ba.as_slice()),
            list(bg.as_slice())
        ));
    } else if inp.calibration.is_none() {
        notes.push("no calibration: identity intrinsics written".into());
    }
    apply_note(inp, Target::OpenVins, true, &["gyro_g_sensitivity"], &mut notes);
    s.push_str("imu0:\n  T_i_b:\n");
    s.push_str(&rows(&m4(&Isometry3::identity()), 4));
    s.push_str(&kalibr_imu_lines(inp, "  "));
    s.push_str("  time_offset: 0.0\n  model: \"rpng\"\n");
    for (name, m) in [("Tw", tw), ("R_IMUtoGYRO", rg), ("Ta", ta), ("R_IMUtoACC", id), ("Tg", tg)] {
        let _ = writeln!(s, "  {name}:");
        s.push_str(&rows(&m3(&m), 4));
    }
    let mut files = vec![("kalibr_imu_chain.yaml".to_string(), s)];
    if !inp.cameras.is_empty() {
        let mut c = String::from("%YAML:1.0\n");
        c.push_str(&header(Target::OpenVins, inp, "#"));
        c.push_str(&kalibr_cameras(inp, true));
        files.push(("kalibr_imucam_chain.yaml".into(), c));
    } else {
        notes.push("no cameras (give --asl): kalibr_imucam_chain.yaml not written".into());
    }
    Ok((files, notes))
}

/// VINS's camera file fields: model type and its two blocks.
fn vins_camera(c: &RigCamera) -> String {
    let m = &c.model;
    let mut s = String::new();
    match m.distortion {
        Distortion::Equidistant { k1, k2, k3, k4 } => {
            let _ = writeln!(s, "model_type: KANNALA_BRANDT\ncamera_name: camera");
            let _ = writeln!(s, "image_width: {}\nimage_height: {}", c.resolution[0], c.resolution[1]);
            let _ = writeln!(s, "projection_parameters:");
            for (k, v) in
                [("k2", k1), ("k3", k2), ("k4", k3), ("k5", k4), ("mu", m.fx), ("mv", m.fy), ("u0", m.cx), ("v0", m.cy)]
            {
                let _ = writeln!(s, "   {k}: {}", num(v));
            }
        }
        d => {
            let (k1, k2, p1, p2) = match d {
                Distortion::RadTan { k1, k2, p1, p2 } => (k1, k2, p1, p2),
                _ => (0.0, 0.0, 0.0, 0.0),
            };
            let _ = writeln!(s, "model_type: PINHOLE\ncamera_name: camera");
            let _ = writeln!(s, "image_width: {}\nimage_height: {}", c.resolution[0], c.resolution[1]);
            let _ = writeln!(s, "distortion_parameters:");
            for (k, v) in [("k1", k1), ("k2", k2), ("p1", p1), ("p2", p2)] {
                let _ = writeln!(s, "   {k}: {}", num(v));
            }
            let _ = writeln!(s, "projection_parameters:");
            for (k, v) in [("fx", m.fx), ("fy", m.fy), ("cx", m.cx), ("cy", m.cy)] {
                let _ = writeln!(s, "   {k}: {}", num(v));
            }
        }
    }
    s
}

fn vins_imu(inp: &ExportInputs, s: &mut String) {
    let [gn, an, gw, aw] = inp.scalars(NoiseConvention::DiscretePerSample);
    let g = inp.calibration.as_ref().map(|c| c.gravity).unwrap_or(crate::io::STANDARD_GRAVITY);
    for (k, v) in [("acc_n", an), ("gyr_n", gn), ("acc_w", aw), ("gyr_w", gw), ("g_norm", g)] {
        let _ = writeln!(s, "{k}: {}", num(v));
    }
    let _ = writeln!(s, "estimate_td: 0\ntd: {}", num(inp.camera_time_offset()));
}

fn need_camera(inp: &ExportInputs, target: Target) -> Result<&RigCamera, OutputError> {
    inp.cameras.first().ok_or_else(|| {
        OutputError::Failed(format!(
            "{} needs a camera: give --asl FOLDER whose mav0/cam0/sensor.yaml has intrinsics, resolution and T_BS",
            target.id()
        ))
    })
}

fn vins_mono(inp: &ExportInputs) -> Result<Rendered, OutputError> {
    let mut notes = Vec::new();
    let c = need_camera(inp, Target::VinsMono)?;
    let mut s = String::from("%YAML:1.0\n");
    s.push_str(&header(Target::VinsMono, inp, "#"));
    s.push_str("# Tracker, solver and loop settings: VINS-Mono's EuRoC example values.\n");
    let _ = writeln!(
        s,
        "imu_topic: \"{}\"\nimage_topic: \"{}\"\noutput_path: \"/tmp/vins_output/\"",
        inp.imu_topic, c.topic
    );
    s.push_str(&vins_camera(c));
    let t = c.t_imu_cam;
    let r = t.rotation.to_rotation_matrix();
    s.push_str("estimate_extrinsic: 0\n");
    s.push_str(&format!("extrinsicRotation: {}", cv_matrix(&m3(r.matrix()))));
    s.push_str(&format!(
        "extrinsicTranslation: {}",
        cv_matrix(&t.translation.vector.iter().map(|v| vec![*v]).collect::<Vec<_>>())
    ));
    s.push_str("max_cnt: 150\nmin_dist: 30\nfreq: 10\nF_threshold: 1.0\nshow_track: 1\nequalize: 1\n");
    let fisheye = matches!(c.model.distortion, Distortion::Equidistant { .. });
    let _ = writeln!(s, "fisheye: {}", u8::from(fisheye));
    s.push_str("max_solver_time: 0.04\nmax_num_iterations: 8\nkeyframe_parallax: 10.0\n");
    vins_imu(inp, &mut s);
    s.push_str("loop_closure: 0\nload_previous_pose_graph: 0\nfast_relocalization: 0\npose_graph_save_path: \"/tmp/vins_output/pose_graph/\"\n");
    s.push_str("rolling_shutter: 0\nrolling_shutter_tr: 0\nsave_image: 0\nvisualize_imu_forward: 0\nvisualize_camera_size: 0.4\n");
    if inp.cameras.len() > 1 {
        notes.push("VINS-Mono is monocular: cam0 written, the other cameras left out".into());
    }
    apply_note(inp, Target::VinsMono, false, &[], &mut notes);
    Ok((vec![("vins_mono_config.yaml".into(), s)], notes))
}

fn vins_fusion(inp: &ExportInputs) -> Result<Rendered, OutputError> {
    let mut notes = Vec::new();
    need_camera(inp, Target::VinsFusion)?;
    let cams = &inp.cameras[..inp.cameras.len().min(2)];
    let mut s = String::from("%YAML:1.0\n");
    s.push_str(&header(Target::VinsFusion, inp, "#"));
    s.push_str("# Tracker and solver settings: VINS-Fusion's EuRoC example values.\n");
    let _ = writeln!(s, "imu: 1\nnum_of_cam: {}\nimu_topic: \"{}\"", cams.len(), inp.imu_topic);
    for (i, c) in cams.iter().enumerate() {
        let _ = writeln!(s, "image{i}_topic: \"{}\"", c.topic);
    }
    s.push_str("output_path: \"/tmp/vins_output/\"\n");
    let mut files = Vec::new();
    for (i, c) in cams.iter().enumerate() {
        let _ = writeln!(s, "cam{i}_calib: \"cam{i}.yaml\"");
        let mut cam = String::from("%YAML:1.0\n---\n");
        cam.push_str(&vins_camera(c));
        files.push((format!("cam{i}.yaml"), cam));
    }
    let _ = writeln!(s, "image_width: {}\nimage_height: {}", cams[0].resolution[0], cams[0].resolution[1]);
    s.push_str("estimate_extrinsic: 0\n");
    for (i, c) in cams.iter().enumerate() {
        s.push_str(&format!("body_T_cam{i}: {}", cv_matrix(&m4(&c.t_imu_cam))));
    }
    s.push_str(
        "multiple_thread: 1\nmax_cnt: 150\nmin_dist: 30\nfreq: 10\nF_threshold: 1.0\nshow_track: 1\nflow_back: 1\n",
    );
    s.push_str("max_solver_time: 0.04\nmax_num_iterations: 8\nkeyframe_parallax: 10.0\n");
    vins_imu(inp, &mut s);
    s.push_str("load_previous_pose_graph: 0\npose_graph_save_path: \"/tmp/vins_output/pose_graph/\"\nsave_image: 0\n");
    files.insert(0, ("vins_fusion_config.yaml".into(), s));
    apply_note(inp, Target::VinsFusion, false, &[], &mut notes);
    Ok((files, notes))
}

fn orbslam3(inp: &ExportInputs) -> Result<Rendered, OutputError> {
    let mut notes = Vec::new();
    let c = need_camera(inp, Target::OrbSlam3)?;
    let mut s = String::from("%YAML:1.0\n");
    s.push_str(&header(Target::OrbSlam3, inp, "#"));
    s.push_str("# ORB extractor and viewer settings: ORB-SLAM3's EuRoC example values.\nFile.version: \"1.0\"\n");
    let m = &c.model;
    let (kind, d): (&str, Vec<(&str, f64)>) = match m.distortion {
        Distortion::Equidistant { k1, k2, k3, k4 } => {
            ("KannalaBrandt8", vec![("k1", k1), ("k2", k2), ("k3", k3), ("k4", k4)])
        }
        Distortion::RadTan { k1, k2, p1, p2 } => ("PinHole", vec![("k1", k1), ("k2", k2), ("p1", p1), ("p2", p2)]),
        Distortion::None => ("PinHole", vec![("k1", 0.0), ("k2", 0.0), ("p1", 0.0), ("p2", 0.0)]),
    };
    let _ = writeln!(s, "Camera.type: \"{kind}\"");
    for (k, v) in [("fx", m.fx), ("fy", m.fy), ("cx", m.cx), ("cy", m.cy)].into_iter().chain(d) {
        let _ = writeln!(s, "Camera1.{k}: {}", num(v));
    }
    let _ = writeln!(
        s,
        "Camera.width: {}\nCamera.height: {}\nCamera.fps: {}\nCamera.RGB: 1",
        c.resolution[0],
        c.resolution[1],
        c.rate_hz.round()
    );
    s.push_str(&format!("IMU.T_b_c1: {}", cv_matrix(&m4(&c.t_imu_cam))));
    let [gn, an, gw, aw] = inp.scalars(NoiseConvention::Continuous);
    for (k, v) in [("NoiseGyro", gn), ("NoiseAcc", an), ("GyroWalk", gw), ("AccWalk", aw), ("Frequency", inp.rate_hz)] {
        let _ = writeln!(s, "IMU.{k}: {}", num(v));
    }
    s.push_str("ORBextractor.nFeatures: 1000\nORBextractor.scaleFactor: 1.2\nORBextractor.nLevels: 8\nORBextractor.iniThFAST: 20\nORBextractor.minThFAST: 7\n");
    s.push_str("Viewer.KeyFrameSize: 0.05\nViewer.KeyFrameLineWidth: 1.0\nViewer.GraphLineWidth: 0.9\nViewer.PointSize: 2.0\nViewer.CameraSize: 0.08\nViewer.CameraLineWidth: 3.0\nViewer.ViewpointX: 0.0\nViewer.ViewpointY: -0.7\nViewer.ViewpointZ: -1.8\nViewer.ViewpointF: 500.0\n");
    if inp.camera_time_offset() != 0.0 {
        notes.push(format!(
            "ORB-SLAM3 has no camera–IMU time offset setting: shift the image stamps by {:+.6} s",
            inp.camera_time_offset()
        ));
    }
    if inp.cameras.len() > 1 {
        notes.push("written as monocular-inertial with cam0".into());
    }
    apply_note(inp, Target::OrbSlam3, false, &[], &mut notes);
    Ok((vec![("orbslam3_settings.yaml".into(), s)], notes))
}

fn basalt(inp: &ExportInputs) -> Result<Rendered, OutputError> {
    use serde_json::json;
    let mut notes = Vec::new();
    // Basalt: a_c = (I + S_a) a_raw − b_a with S_a lower triangular, ω_c = (I + S_g) ω_raw − b_g.
    // tumble: a = M_a⁻¹ (a_raw − b_a). With M_a⁻¹ = Qᵀ L: Basalt's frame is Q · tumble's.
    let mut q = Matrix3::identity();
    let mut accel = vec![0.0; 9];
    let mut gyro = vec![0.0; 12];
    if let Some((ma, mg, ba, bg)) = si_calibration(inp, &mut notes) {
        let ia = ma.try_inverse().ok_or("the accelerometer matrix T_a K_a is singular")?;
        let ig = mg.try_inverse().ok_or("the gyro matrix T_g K_g is singular")?;
        let (qt, l) = rotation_times_lower(&ia).ok_or("the accelerometer matrix has a non-positive determinant")?;
        q = qt.transpose();
        let sa = l - Matrix3::identity();
        let ba2 = l * ba;
        accel = vec![ba2[0], ba2[1], ba2[2], sa[(0, 0)], sa[(1, 0)], sa[(2, 0)], sa[(1, 1)], sa[(2, 1)], sa[(2, 2)]];
        let cg = q * ig;
        let sg = cg - Matrix3::identity();
        let bg2 = cg * bg;
        gyro = vec![bg2[0], bg2[1], bg2[2]];
        gyro.extend(sg.as_slice()); // column-major, as Basalt reads it
        let angle = nalgebra::Rotation3::from_matrix_unchecked(q).angle();
        notes.push(format!(
            "Basalt's accelerometer correction is lower triangular: its IMU frame is tumble's rotated by {:.3} mrad \
             (the camera extrinsics written are rotated with it)",
            angle * 1e3
        ));
    }
    apply_note(inp, Target::Basalt, true, &[], &mut notes);
    let rot = Isometry3::from_parts(Default::default(), nalgebra::UnitQuaternion::from_matrix(&q));
    let [gn, an, gw, aw] = inp.axes();
    let cams: Vec<_> = inp
        .cameras
        .iter()
        .map(|c| {
            let t = rot * c.t_imu_cam;
            let qq = t.rotation;
            let pose = json!({"px": t.translation.x, "py": t.translation.y, "pz": t.translation.z,
                "qx": qq.i, "qy": qq.j, "qz": qq.k, "qw": qq.w});
            let m = &c.model;
            let intr = match m.distortion {
                Distortion::Equidistant { k1, k2, k3, k4 } => json!({"camera_type": "kb4", "intrinsics":
                    {"fx": m.fx, "fy": m.fy, "cx": m.cx, "cy": m.cy, "k1": k1, "k2": k2, "k3": k3, "k4": k4}}),
                Distortion::RadTan { k1, k2, p1, p2 } => json!({"camera_type": "pinhole-radtan8", "intrinsics":
                    {"fx": m.fx, "fy": m.fy, "cx": m.cx, "cy": m.cy, "k1": k1, "k2": k2, "p1": p1, "p2": p2,
                     "k3": 0.0, "k4": 0.0, "k5": 0.0, "k6": 0.0, "rpmax": 0.0}}),
                Distortion::None => {
                    json!({"camera_type": "pinhole", "intrinsics": {"fx": m.fx, "fy": m.fy, "cx": m.cx, "cy": m.cy}})
                }
            };
            (pose, intr, json!([c.resolution[0], c.resolution[1]]))
        })
        .collect();
    let doc = json!({"value0": {
        "T_imu_cam": cams.iter().map(|c| c.0.clone()).collect::<Vec<_>>(),
        "intrinsics": cams.iter().map(|c| c.1.clone()).collect::<Vec<_>>(),
        "resolution": cams.iter().map(|c| c.2.clone()).collect::<Vec<_>>(),
        "calib_accel_bias": accel,
        "calib_gyro_bias": gyro,
        "imu_update_rate": inp.rate_hz,
        "accel_noise_std": an,
        "gyro_noise_std": gn,
        "accel_bias_std": aw,
        "gyro_bias_std": gw,
        "cam_time_offset_ns": (inp.camera_time_offset() * 1e9).round() as i64,
        "vignette": []
    }});
    let text = serde_json::to_string_pretty(&doc).map_err(|e| e.to_string())?;
    // JSON has no comments: the header goes into the notes file beside it.
    let readme = header(Target::Basalt, inp, "#");
    Ok((vec![("calibration.json".into(), text), ("calibration.notes.txt".into(), readme)], notes))
}

/// Every file of `target`, and notes.
pub(super) fn render(target: Target, inp: &ExportInputs) -> Result<Rendered, OutputError> {
    match target {
        Target::Kalibr => Ok(kalibr(inp)),
        Target::OpenVins => openvins(inp),
        Target::VinsMono => vins_mono(inp),
        Target::VinsFusion => vins_fusion(inp),
        Target::OrbSlam3 => orbslam3(inp),
        Target::Basalt => basalt(inp),
    }
}
