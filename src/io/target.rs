//! Reading and writing a rig's calibration files: Kalibr's `target.yaml`, the
//! corners each camera saw (`camN/corners.csv`), the intrinsics of
//! `camN/sensor.yaml`, and a rig calibration written by `tumble calibrate-rig`.

use crate::error::InputError;
use crate::io::table::{read_table, TableSpec, TimeUnit};
use crate::io::yaml::read_yaml;
use crate::model::target::{Corner, Target, View};
use serde::Deserialize;
use std::path::{Path, PathBuf};

#[derive(Deserialize)]
#[allow(non_snake_case)]
struct TargetYaml {
    target_type: String,
    tagCols: Option<u32>,
    tagRows: Option<u32>,
    tagSize: Option<f64>,
    tagSpacing: Option<f64>,
    targetCols: Option<u32>,
    targetRows: Option<u32>,
    rowSpacingMeters: Option<f64>,
    colSpacingMeters: Option<f64>,
}

impl Target {
    /// Read Kalibr's `target.yaml` (`target_type: aprilgrid` with `tagCols`, `tagRows`,
    /// `tagSize`, `tagSpacing`, or `checkerboard` with `targetCols`, `targetRows`,
    /// `rowSpacingMeters`, `colSpacingMeters`).
    pub fn read(path: &Path) -> Result<Target, InputError> {
        let y: TargetYaml = read_yaml(path)?;
        let need_u = |v: Option<u32>, key: &str| match v {
            Some(n) if n > 0 => Ok(n),
            Some(n) => Err(InputError::file(path, format!("{key} must be a positive count, found {n}"))),
            None => Err(InputError::file(path, format!("missing {key}"))),
        };
        let need_f = |v: Option<f64>, key: &str, zero_ok: bool| match v {
            Some(x) if x.is_finite() && (x > 0.0 || (zero_ok && x == 0.0)) => Ok(x),
            Some(x) => Err(InputError::file(path, format!("{key} must be a positive number of metres, found {x}"))),
            None => Err(InputError::file(path, format!("missing {key}"))),
        };
        match y.target_type.trim_matches(['\'', '"']) {
            "aprilgrid" => {
                let (cols, rows) = (need_u(y.tagCols, "tagCols")?, need_u(y.tagRows, "tagRows")?);
                let grid = Target::AprilGrid {
                    cols,
                    rows,
                    size: need_f(y.tagSize, "tagSize", false)?,
                    spacing: need_f(y.tagSpacing, "tagSpacing", true)?,
                };
                grid.check_tag_family().map_err(|e| InputError::file(path, format!("tagCols × tagRows: {e}")))?;
                Ok(grid)
            }
            "checkerboard" => Ok(Target::Checkerboard {
                cols: need_u(y.targetCols, "targetCols")?,
                rows: need_u(y.targetRows, "targetRows")?,
                col_spacing: need_f(y.colSpacingMeters, "colSpacingMeters", false)?,
                row_spacing: need_f(y.rowSpacingMeters, "rowSpacingMeters", false)?,
            }),
            other => Err(InputError::file(path, format!("target_type '{other}' is not supported"))
                .with_hint("aprilgrid or checkerboard (Kalibr's keys)")),
        }
    }
}

/// Tolerance between a corner's position in `corners.csv` and the target's geometry \[m\].
const GEOMETRY_TOLERANCE_M: f64 = 1e-3;

/// Read `camN/corners.csv` (`timestamp_ns,tag_id,corner_idx,u_px,v_px,x_m,y_m,z_m`;
/// for a checkerboard `tag_id` is 0 and `corner_idx` the corner's index), check
/// each corner against the target's geometry, and group them by frame. Frames
/// of `frames.csv` (one stamp per line), when present, are kept even without corners.
pub fn read_corners(cam_dir: &Path, target: &Target) -> Result<Vec<View>, InputError> {
    let path = cam_dir.join("corners.csv");
    let spec = TableSpec {
        time: Some((0, TimeUnit::Ns)),
        values: vec![1, 2, 3, 4, 5, 6, 7],
        names: ["tag_id", "corner_idx", "u_px", "v_px", "x_m", "y_m", "z_m"].map(String::from).to_vec(),
        ..TableSpec::default()
    };
    let t = read_table(&path, &spec)?;
    let mut views: Vec<View> = Vec::new();
    for i in 0..t.t_ns.len() {
        let line = || t.lines.line(i);
        let col = |c: usize| t.columns[c][i];
        let (tag, idx) = (col(0), col(1));
        if tag < 0.0 || tag.fract() != 0.0 || idx < 0.0 || idx.fract() != 0.0 {
            return Err(InputError::at(
                &path,
                line(),
                format!("tag_id {tag} and corner_idx {idx} must be non-negative integers"),
            ));
        }
        let id = match target {
            Target::AprilGrid { .. } => {
                if idx > 3.0 {
                    return Err(InputError::at(
                        &path,
                        line(),
                        format!("corner_idx {idx} of an AprilGrid tag must be 0–3"),
                    ));
                }
                4 * tag as usize + idx as usize
            }
            Target::Checkerboard { .. } => idx as usize,
        };
        let p = [col(4), col(5), col(6)];
        let expected = target.corner(id).ok_or_else(|| {
            InputError::at(
                &path,
                line(),
                format!(
                    "corner {id} (tag {tag}, corner {idx}) is beyond the target's {} corners",
                    target.corner_count()
                ),
            )
            .with_hint("check --target against the target the corners were detected on")
        })?;
        let off = (0..3).map(|k| (p[k] - expected[k]).powi(2)).sum::<f64>().sqrt();
        if off > GEOMETRY_TOLERANCE_M {
            return Err(InputError::at(
                &path,
                line(),
                format!(
                    "corner {id} at ({:.4}, {:.4}, {:.4}) m, but the target puts it at ({:.4}, {:.4}, {:.4}) m",
                    p[0], p[1], p[2], expected[0], expected[1], expected[2]
                ),
            )
            .with_hint("the target file does not describe the target of these corners"));
        }
        let uv = [col(2), col(3)];
        let t_ns = t.t_ns[i];
        match views.last_mut() {
            Some(v) if v.t_ns == t_ns => v.corners.push(Corner { id, target: expected, uv }),
            Some(v) if v.t_ns > t_ns => {
                return Err(InputError::at(&path, line(), "corners must be in time order"));
            }
            _ => views.push(View { t_ns, corners: vec![Corner { id, target: expected, uv }] }),
        }
    }
    let frames_csv = cam_dir.join("frames.csv");
    if frames_csv.is_file() {
        let spec = TableSpec { time: Some((0, TimeUnit::Ns)), ..TableSpec::default() };
        let f = read_table(&frames_csv, &spec)?;
        let mut all: Vec<View> = f.t_ns.iter().map(|&t_ns| View { t_ns, corners: Vec::new() }).collect();
        for v in views {
            match all.binary_search_by_key(&v.t_ns, |w| w.t_ns) {
                Ok(k) => all[k] = v,
                Err(_) => {
                    return Err(InputError::file(
                        &path,
                        format!("corners stamped {} ns, a frame {} does not list", v.t_ns, frames_csv.display()),
                    ))
                }
            }
        }
        views = all;
    }
    if views.iter().all(|v| v.corners.is_empty()) {
        return Err(InputError::file(&path, "holds no corners"));
    }
    Ok(views)
}

/// The views as `corners.csv` text (the layout [`read_corners`] reads; for a
/// checkerboard `tag_id` is 0) and as `frames.csv` text (every view's stamp).
pub fn corners_csv(views: &[View], target: &Target) -> (String, String) {
    use std::fmt::Write;
    let mut corners = String::from("timestamp_ns,tag_id,corner_idx,u_px,v_px,x_m,y_m,z_m\n");
    let mut frames = String::from("#timestamp [ns]\n");
    for v in views {
        let _ = writeln!(frames, "{}", v.t_ns);
        for c in &v.corners {
            let (tag, idx) = match target {
                Target::AprilGrid { .. } => (c.id / 4, c.id % 4),
                Target::Checkerboard { .. } => (0, c.id),
            };
            let _ = writeln!(
                corners,
                "{},{tag},{idx},{:.4},{:.4},{:.6},{:.6},{:.6}",
                v.t_ns, c.uv[0], c.uv[1], c.target[0], c.target[1], c.target[2]
            );
        }
    }
    (corners, frames)
}

/// `dir/camN/sensor.yaml` read for N = 0, 1, … until one is missing, with their paths.
fn camera_sensors(dir: &Path) -> Result<Vec<(PathBuf, crate::io::asl::CameraSensor)>, InputError> {
    let mut out = Vec::new();
    while let Some(p) = Some(dir.join(format!("cam{}", out.len())).join("sensor.yaml")).filter(|p| p.is_file()) {
        let s = crate::io::asl::read_camera_sensor(&p)?;
        out.push((p, s));
    }
    Ok(out)
}

/// The intrinsics of `dir/camN/sensor.yaml` (or `dir/mav0/camN/…`) for N = 0, 1, … until one is missing.
pub fn read_intrinsics(dir: &Path) -> Result<Vec<tumble_factors::camera::CameraModel>, InputError> {
    let base = if dir.join("mav0").is_dir() { dir.join("mav0") } else { dir.to_path_buf() };
    let out: Vec<_> = camera_sensors(&base)?.into_iter().map(|(_, s)| s.0).collect();
    if out.is_empty() {
        return Err(InputError::file(dir, "holds no cam0/sensor.yaml with intrinsics"));
    }
    Ok(out)
}

/// A rig calibration as `tumble calibrate-rig` wrote it, read back for use:
/// each camera's model and pose in the IMU frame, and the time offset.
#[derive(Debug, Clone, PartialEq)]
pub struct RigCalibration {
    /// The folder it was read from.
    pub dir: PathBuf,
    /// Per camera (`cam0`, `cam1`, …): model, IMU ← camera, image size \[px\].
    pub cameras: Vec<(tumble_factors::camera::CameraModel, nalgebra::Isometry3<f64>, Option<[u32; 2]>)>,
    /// Kalibr's `timeshift_cam_imu` \[s\]: `t_imu = t_cam + shift`.
    pub time_offset_s: f64,
}

#[derive(Deserialize)]
struct RigJsonOffset {
    timeshift_cam_imu_s: f64,
}

impl RigCalibration {
    /// Read `dir/camN/sensor.yaml` (N = 0, 1, … while present) and `dir/rig.json`'s time offset.
    pub fn read(dir: &Path) -> Result<RigCalibration, InputError> {
        let json = dir.join("rig.json");
        let text = crate::io::tokens::read_text(&json)?;
        let offset: RigJsonOffset = serde_json::from_str(&text)
            .map_err(|e| InputError::at(&json, e.line(), format!("not a rig.json of `tumble calibrate-rig`: {e}")))?;
        let mut cameras = Vec::new();
        for (p, (model, t_bs, resolution, _)) in camera_sensors(dir)? {
            let t_bs = t_bs.ok_or_else(|| InputError::file(&p, "has no T_BS: the camera's pose in the IMU frame"))?;
            cameras.push((model, t_bs, resolution));
        }
        if cameras.is_empty() {
            return Err(InputError::file(
                dir,
                "holds no cam0/sensor.yaml: not an output folder of `tumble calibrate-rig`",
            ));
        }
        if !offset.timeshift_cam_imu_s.is_finite() {
            return Err(InputError::file(&json, "timeshift_cam_imu_s is not a finite number"));
        }
        Ok(RigCalibration { dir: dir.to_path_buf(), cameras, time_offset_s: offset.timeshift_cam_imu_s })
    }

    /// Put the rig's cameras into a dataset in place of its own `camN/sensor.yaml`
    /// figures (intrinsics, distortion, image size, and `T_BS` through the
    /// dataset's `imu0` `T_BS`, so that the IMU ← camera transform is the rig's).
    /// Refuses a dataset with more cameras than the rig.
    pub fn apply_to(&self, ds: &mut crate::io::asl::AslDataset) -> Result<(), InputError> {
        if ds.cameras.len() > self.cameras.len() {
            return Err(InputError::file(
                &self.dir,
                format!(
                    "calibrates {} camera(s), the dataset {} has {}",
                    self.cameras.len(),
                    ds.root.display(),
                    ds.cameras.len()
                ),
            ));
        }
        let body_imu = ds.imu_sensor.as_ref().map_or_else(nalgebra::Isometry3::identity, |s| s.t_bs);
        for (cam, (model, t_bc, resolution)) in ds.cameras.iter_mut().zip(&self.cameras) {
            cam.model = Some(*model);
            cam.t_bs = Some(body_imu * t_bc);
            cam.resolution = resolution.or(cam.resolution);
        }
        Ok(())
    }
}
