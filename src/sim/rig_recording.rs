//! `tumble sim rig`: a camera–IMU rig waved before a target on a wall (a
//! checkerboard, or Kalibr's AprilGrid as Kalibr prints it)
//! ([`super::target`]), written as the ASL folder `tumble calibrate-rig`
//! reads, with the truth beside it. Without images each camera gets the
//! target's corners (`camN/corners.csv`, projections plus the configured
//! pixel noise: no detector needed); with images every frame is rendered
//! (`camN/data/<stamp>.png`, the detector finds the corners) and the exact
//! projections go to `truth/`.
//!
//! The folder: `mav0/imu0/{data.csv, sensor.yaml}`, `mav0/camN/{data.csv,
//! sensor.yaml}` and the corners or the images, `target.yaml` (Kalibr's
//! keys), `truth.json` (the camera model, each camera's `T_BC`, the time
//! offset, the IMU's turn-on biases and noise).

use super::images::{CameraFrames, Progress};
use super::render::scene::{Plane, RenderScene};
use super::render::texture::Texture;
use super::render::ImageSettings;
use super::target::{rig_motion, simulate_rig, target_in_world, RigSimSettings, SimulatedRig, RIG_IMU_RATE_HZ};
use super::writer::{camera_sensor_yaml, imu_sensor_yaml, write_text};
use super::SimError;
use crate::model::tag36h11;
use crate::model::target::{CameraCorners, Target};
use nalgebra::Vector3;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// The target of `tumble sim rig`: a checkerboard of 7 × 6 inner corners
/// (8 × 7 squares of 8 cm, 0.64 × 0.56 m), OpenCV's and Kalibr's kind (an
/// AprilGrid is rendered too: [`rig_settings`]' caller may set `target`).
pub const RIG_CHECKERBOARD: Target = Target::Checkerboard { cols: 7, rows: 6, col_spacing: 0.08, row_spacing: 0.08 };

/// Absolute time of the recording's first IMU sample \[ns\]: the other scenarios' default.
const T0_NS: i64 = super::DEFAULT_T0_NS;

/// The settings of `tumble sim rig`: [`RigSimSettings`]' defaults (EuRoC's
/// cam0 lens, a 3 ms time offset, 0.3 px corner noise, the target 1 m
/// ahead) with the checkerboard [`RIG_CHECKERBOARD`], `duration_s` long,
/// a second camera `stereo_baseline_m` to the right when positive.
pub fn rig_settings(duration_s: f64, stereo_baseline_m: f64) -> RigSimSettings {
    let mut s = RigSimSettings { duration_s, target: RIG_CHECKERBOARD, ..RigSimSettings::default() };
    s.camera.stereo_baseline_m = stereo_baseline_m;
    s
}

/// Simulate the rig recording `seed` and write it into `out` (created;
/// written only when everything succeeded), rendering its frames with
/// `images` when given, calling `progress(done, total)` after each batch of
/// rendered frames. Returns the simulation (its corners are the exact
/// projections when rendering).
///
/// Errors: a recording under 12 s, a negative stereo baseline, images of an
/// AprilGrid with more tags than its family, image settings out of range, a
/// file not written.
pub fn write_rig_recording(
    settings: &RigSimSettings,
    images: Option<&ImageSettings>,
    seed: u64,
    out: &Path,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<SimulatedRig, SimError> {
    check(settings, images)?;
    let mut settings = settings.clone();
    if images.is_some() {
        // The image's own noise replaces the corners': the truth is exact.
        settings.camera.pixel_noise_px = 0.0;
    }
    let sim = simulate_rig(&settings, seed);
    crate::io::staging::write_staged(out, |stage| -> Result<Vec<PathBuf>, SimError> {
        write_folder(&settings, &sim, seed, images.is_some(), stage)?;
        if let Some(images) = images {
            render_frames(&settings, &sim, images, seed, stage, progress)?;
        }
        crate::io::staging::files_under(stage).map_err(|e| SimError::from(format!("{}: {e}", stage.display())))
    })?;
    Ok(sim)
}

/// Refuse what the recording cannot be made from, before anything is simulated.
fn check(s: &RigSimSettings, images: Option<&ImageSettings>) -> Result<(), SimError> {
    // The wave needs 10 s beyond its still ends ([`super::Loop::target_wave_with`]).
    if !(s.duration_s.is_finite() && s.duration_s >= 12.0) {
        return Err(format!("rig: the recording must last at least 12 s, found {} s", s.duration_s).into());
    }
    let baseline = s.camera.stereo_baseline_m;
    if !(baseline.is_finite() && baseline >= 0.0) {
        return Err(
            format!("rig: the stereo baseline must be 0 (one camera) or positive metres, found {baseline}").into()
        );
    }
    if let Some(images) = images {
        images.check()?;
        s.target.check_tag_family().map_err(|e| format!("rig: {e}"))?;
    }
    Ok(())
}

/// The IMU, each camera's stamps and sensor.yaml, the corners (without
/// images: in the camera's folder; with: in `truth/`), the target and the truth.
fn write_folder(s: &RigSimSettings, sim: &SimulatedRig, seed: u64, images: bool, out: &Path) -> Result<(), SimError> {
    let mav0 = out.join("mav0");
    write_imu(&mav0.join("imu0"), sim)?;
    let mounts = std::iter::once(sim.truth.t_bc).chain(sim.truth.second_t_bc);
    for (cam, t_bc) in sim.input.cameras.iter().zip(mounts) {
        let dir = mav0.join(&cam.name);
        let comment = if images {
            "simulated rig camera (rendered images in data/)"
        } else {
            "simulated rig camera (no images; the target's corners in corners.csv)"
        };
        write_text(&dir.join("sensor.yaml"), &camera_sensor_yaml(&s.camera, &t_bc, comment))?;
        let mut frames = String::from("#timestamp [ns],filename\n");
        for v in &cam.views {
            frames.push_str(&format!("{0},{0}.png\n", T0_NS + v.t_ns));
        }
        write_text(&dir.join("data.csv"), &frames)?;
        let (corners, _) = crate::io::target::corners_csv(&absolute(cam).views, &s.target);
        let corners_path =
            if images { out.join("truth").join(format!("corners_{}.csv", cam.name)) } else { dir.join("corners.csv") };
        write_text(&corners_path, &corners)?;
    }
    write_text(&out.join("target.yaml"), &target_yaml(&s.target))?;
    write_text(&out.join("truth.json"), &truth_json(s, sim, seed)?)?;
    Ok(())
}

/// The camera's views with absolute stamps.
fn absolute(cam: &CameraCorners) -> CameraCorners {
    let mut cam = cam.clone();
    for v in &mut cam.views {
        v.t_ns += T0_NS;
    }
    cam
}

/// `imu0/data.csv` (ASL, ns, rad/s, m/s²) and `imu0/sensor.yaml` with the simulation's noise.
fn write_imu(dir: &Path, sim: &SimulatedRig) -> Result<(), SimError> {
    let imu = &sim.input.imu;
    let mut csv = crate::io::imu_write::asl_imu_header(false);
    for i in 0..imu.t.len() {
        let (g, a) = (imu.gyro[i], imu.acc[i]);
        let t_ns = T0_NS + (imu.t[i] * 1e9).round() as i64;
        let values = [g.x, g.y, g.z, a.x, a.y, a.z].map(|x| ryu::Buffer::new().format(x).to_string());
        csv.push_str(&format!("{t_ns},{}\n", values.join(",")));
    }
    write_text(&dir.join("data.csv"), &csv)?;
    let n = &sim.input.noise;
    let noise = [n.gyro_noise_density, n.gyro_random_walk, n.accel_noise_density, n.accel_random_walk];
    let header = "Simulated by tumble (scenario rig). Noise figures: continuous time, SI.";
    let yaml = imu_sensor_yaml(header, "simulated rig IMU", RIG_IMU_RATE_HZ, noise);
    Ok(write_text(&dir.join("sensor.yaml"), &yaml)?)
}

/// Kalibr's `target.yaml` of `target`.
fn target_yaml(target: &Target) -> String {
    match *target {
        Target::Checkerboard { cols, rows, col_spacing, row_spacing } => format!(
            "target_type: 'checkerboard'\ntargetCols: {cols}\ntargetRows: {rows}\nrowSpacingMeters: {row_spacing}\n\
             colSpacingMeters: {col_spacing}\n"
        ),
        Target::AprilGrid { cols, rows, size, spacing } => format!(
            "target_type: 'aprilgrid'\ntagCols: {cols}\ntagRows: {rows}\ntagSize: {size}\ntagSpacing: {spacing}\n"
        ),
    }
}

/// The truth: camera model, each camera's `T_BC` (4×4, row major), the time
/// offset, the IMU's turn-on biases and noise, the seed.
fn truth_json(s: &RigSimSettings, sim: &SimulatedRig, seed: u64) -> Result<String, SimError> {
    let t = &sim.truth;
    let matrix =
        |m: &nalgebra::Isometry3<f64>| -> Vec<f64> { m.to_homogeneous().transpose().iter().copied().collect() };
    let mut cameras = vec![serde_json::json!({ "name": "cam0", "T_BC": matrix(&t.t_bc) })];
    if let Some(second) = &t.second_t_bc {
        cameras.push(serde_json::json!({ "name": "cam1", "T_BC": matrix(second) }));
    }
    let n = &sim.input.noise;
    let truth = serde_json::json!({
        "generator": format!("tumble {}", env!("CARGO_PKG_VERSION")),
        "scenario": "rig",
        "seed": seed,
        "t0_ns": T0_NS,
        "duration_s": s.duration_s,
        "gravity": s.gravity,
        "intrinsics": [t.model.fx, t.model.fy, t.model.cx, t.model.cy],
        "distortion_model": format!("{:?}", s.camera.distortion_model),
        "distortion_coefficients": s.camera.distortion_coefficients,
        "resolution": s.camera.resolution,
        "cameras": cameras,
        "time_offset_s": t.time_offset_s,
        "accel_bias": s.bias[0],
        "gyro_bias": s.bias[1],
        "noise": {
            "gyroscope_noise_density": n.gyro_noise_density,
            "gyroscope_random_walk": n.gyro_random_walk,
            "accelerometer_noise_density": n.accel_noise_density,
            "accelerometer_random_walk": n.accel_random_walk,
        },
        "corner_noise_px": s.camera.pixel_noise_px,
        "convention": "T_BC maps camera to body (IMU) coordinates, row major; an image stamped t was exposed at IMU time t + time_offset_s (Kalibr's timeshift_cam_imu)",
    });
    serde_json::to_string_pretty(&truth).map_err(|e| SimError::from(format!("truth.json: {e}")))
}

/// Render every camera's frames into `out/mav0/camN/data/`.
fn render_frames(
    s: &RigSimSettings,
    sim: &SimulatedRig,
    images: &ImageSettings,
    seed: u64,
    out: &Path,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<(), SimError> {
    let scene = rig_scene(s, seed);
    let motion = rig_motion(s, seed);
    let mounts: Vec<_> = std::iter::once(sim.truth.t_bc).chain(sim.truth.second_t_bc).collect();
    let total = sim.input.cameras.iter().map(|c| c.views.len()).sum();
    let mut progress = Progress { done: 0, total, report: progress };
    for (index, (cam, body_from_camera)) in sim.input.cameras.iter().zip(&mounts).enumerate() {
        // Each view exposed at its stamp plus the time offset (IMU time).
        let frames: Vec<(f64, i64)> =
            cam.views.iter().map(|v| (v.t_ns as f64 * 1e-9 + s.camera.time_offset_s, T0_NS + v.t_ns)).collect();
        let camera = CameraFrames {
            scene: &scene,
            camera: &s.camera,
            motion: &motion,
            body_from_camera,
            settings: images,
            seed,
            index,
        };
        camera.render(&frames, &out.join("mav0").join(&cam.name).join("data"), &mut progress)?;
    }
    Ok(())
}

/// Side of a target's texture \[texels\] (the texels serve the
/// footprint's units: the pattern itself is sampled exactly, [`Texture::printed`]).
const BOARD_TEXELS: usize = 1024;

/// Grey of the board's paper and ink (of 1): black print on white paper.
const BOARD_GREYS: [f32; 2] = [0.9, 0.08];

/// The rig's scene: a room whose front wall stands 5 cm behind the target,
/// and the target printed on a sheet with a white margin around it.
fn rig_scene(s: &RigSimSettings, seed: u64) -> RenderScene {
    let half = [2.0, 3.0, 2.0];
    let centre = Vector3::new(s.distance_m + 0.05 - half[0], 0.0, 0.0);
    let mut scene = RenderScene::room(centre, half, seed);
    let (lo, hi, ink) = match s.target {
        Target::Checkerboard { cols, rows, col_spacing, row_spacing } => {
            checkerboard_ink([cols as usize, rows as usize], [col_spacing, row_spacing])
        }
        Target::AprilGrid { cols, rows, size, spacing } => aprilgrid_ink([cols as usize, rows as usize], size, spacing),
    };
    scene.planes.push(sheet(s, lo, hi, &ink));
    scene
}

/// The target's ink: rectangles `[x0, y0, x1, y1]` in the target's frame \[m\]
/// with the ink each adds (1 black, −1 a white cell cut out of a black square).
type Ink = Vec<([f64; 4], f32)>;

/// A checkerboard of `inner` corners spaced `spacing` \[m\]: `inner + 1`
/// squares a side, corner `(0, 0)` its first inner corner, square `(0, 0)`
/// dark; the sheet's corners (a margin of one square).
fn checkerboard_ink(inner: [usize; 2], spacing: [f64; 2]) -> ([f64; 2], [f64; 2], Ink) {
    let squares = inner.map(|n| n + 1);
    let mut ink = Vec::new();
    for j in 0..squares[1] {
        for i in 0..squares[0] {
            if (i + j) % 2 == 0 {
                let [x0, y0] = [(i as f64 - 1.0) * spacing[0], (j as f64 - 1.0) * spacing[1]];
                ink.push(([x0, y0, x0 + spacing[0], y0 + spacing[1]], 1.0));
            }
        }
    }
    let lo = [-2.0 * spacing[0], -2.0 * spacing[1]];
    let hi = [0, 1].map(|a| squares[a] as f64 * spacing[a]);
    (lo, hi, ink)
}

/// Kalibr's AprilGrid of `tags` (columns, rows) tags of side `size` \[m\],
/// `spacing` × `size` apart, as `kalibr_create_target_pdf` prints it: each
/// AprilTag 36h11 (tag `row·cols + col` from the lower left) within its
/// black border of [`tag36h11::KALIBR_BORDER_BITS`] cells, a black square
/// of the gap's side at every crossing of the gaps (each tag corner an
/// X-junction); the sheet's corners (a margin of one tag).
fn aprilgrid_ink(tags: [usize; 2], size: f64, spacing: f64) -> ([f64; 2], [f64; 2], Ink) {
    let gap = spacing * size;
    let pitch = size + gap;
    let mut ink = Vec::new();
    // Every crossing of the gaps, the outer ones too, touches a tag's corner.
    for r in 0..=tags[1] {
        for c in 0..=tags[0] {
            let [x, y] = [c as f64 * pitch - gap, r as f64 * pitch - gap];
            ink.push(([x, y, x + gap, y + gap], 1.0));
        }
    }
    let border = tag36h11::KALIBR_BORDER_BITS;
    let cell = size / (2 * border + tag36h11::DATA_BITS) as f64;
    for id in 0..tags[0] * tags[1] {
        let [x0, y0] = [(id % tags[0]) as f64 * pitch, (id / tags[0]) as f64 * pitch];
        ink.push(([x0, y0, x0 + size, y0 + size], 1.0));
        for row in 0..tag36h11::DATA_BITS {
            for col in 0..tag36h11::DATA_BITS {
                if tag36h11::data_cell_is_white(id, row, col) == Some(true) {
                    let x = x0 + (border + col) as f64 * cell;
                    let y = y0 + (border + tag36h11::DATA_BITS - 1 - row) as f64 * cell;
                    ink.push(([x, y, x + cell, y + cell], -1.0));
                }
            }
        }
    }
    let lo = [-gap - size; 2];
    let hi = tags.map(|n| n as f64 * pitch + size);
    (lo, hi, ink)
}

/// The sheet from `lo` to `hi` in the target's frame \[m\], printed with
/// `ink`, as a plane in the world ([`target_in_world`]).
fn sheet(s: &RigSimSettings, lo: [f64; 2], hi: [f64; 2], ink: &Ink) -> Plane {
    let extent = [hi[0] - lo[0], hi[1] - lo[1]];
    let per_metre = [0, 1].map(|a| BOARD_TEXELS as f64 / extent[a]);
    let texels: Ink = ink
        .iter()
        .map(|&([x0, y0, x1, y1], amount)| {
            let (x, y) = (|x: f64| (x - lo[0]) * per_metre[0], |y: f64| (y - lo[1]) * per_metre[1]);
            ([x(x0), y(y0), x(x1), y(y1)], amount)
        })
        .collect();
    let [paper, black] = BOARD_GREYS;
    let (r_wt, t_wt) = target_in_world(s);
    Plane {
        origin: r_wt * Vector3::new(lo[0], lo[1], 0.0) + t_wt,
        u_axis: r_wt * Vector3::x(),
        v_axis: r_wt * Vector3::y(),
        size: extent,
        texture: Arc::new(Texture::printed(BOARD_TEXELS, BOARD_TEXELS, &texels, paper, black)),
        ring: None,
    }
}
