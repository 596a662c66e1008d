//! Reading a rig's recording for calibration ([`RigInput::from_asl`]): the
//! IMU and its noise, the target, and each camera's corners — read from
//! `camN/corners.csv`, or detected in the images ([`super::detect`]).

use crate::error::InputError;
use crate::io::target::read_corners;
use crate::io::ImuNoise;
use crate::model::calibration::ImuCalibration;
use crate::model::target::{CameraCorners, DetectionStats, RigInput, Target, View};
use std::path::{Path, PathBuf};
use tumble_factors::imu_preint::PreintegrationParams;

use super::RigOptions;

impl RigInput {
    /// Read an ASL folder (`mav0/imu0/data.csv`, `mav0/camN/corners.csv`) and
    /// the target. The IMU noise is `noise` (Kalibr `imu.yaml`, e.g. from
    /// `tumble allan`), else `imu0/sensor.yaml`'s; without either the input is
    /// refused. `calibration` (`calibration.json` of `tumble calibrate`)
    /// corrects the IMU samples first. Each camera's resolution comes from its
    /// `sensor.yaml`, else from `options.resolution` (for images searched by
    /// [`RigInput::from_asl_with_progress`], from the images, which must agree).
    pub fn from_asl(
        path: &Path,
        target: &Path,
        noise: Option<&Path>,
        calibration: Option<&Path>,
        options: &RigOptions,
    ) -> Result<RigInput, InputError> {
        Self::from_asl_with_progress(path, target, noise, calibration, options, &mut |_| {})
    }

    /// [`RigInput::from_asl`], for a folder that may have images instead of
    /// `camN/corners.csv`: a camera whose folder has no `corners.csv` but
    /// images (`camN/data.csv`) has its corners detected (`detect`, feature
    /// `opencv`; refused with a hint without it), with progress lines to `progress`.
    pub fn from_asl_with_progress(
        path: &Path,
        target: &Path,
        noise: Option<&Path>,
        calibration: Option<&Path>,
        options: &RigOptions,
        progress: &mut dyn FnMut(&str),
    ) -> Result<RigInput, InputError> {
        let target_path = target;
        let target = Target::read(target)?;
        let ds = crate::io::asl::read_asl(path, &Default::default())?;
        let calibration = calibration.map(ImuCalibration::read).transpose()?;
        let mut params = PreintegrationParams::default();
        let sensor_yaml = ds.root.join("imu0").join("sensor.yaml");
        let noise_source = match (noise, ds.imu_noise()) {
            (Some(p), _) => {
                ImuNoise::read(p)?.apply(&mut params);
                p.display().to_string()
            }
            (None, Some(n)) => {
                n.apply(&mut params);
                sensor_yaml.display().to_string()
            }
            (None, None) => {
                return Err(InputError::file(&sensor_yaml, "absent or without the IMU's four noise figures").with_hint(
                    "give --noise imu.yaml (from `tumble allan`, or Kalibr's imu.yaml with the datasheet's figures)",
                ))
            }
        };
        let mut cameras = Vec::new();
        let mut sources = vec![target_path.to_path_buf(), ds.imu.sources.first().cloned().unwrap_or_default()];
        for k in 0..8 {
            let name = format!("cam{k}");
            let dir = ds.root.join(&name);
            let camera = ds.cameras.iter().find(|c| c.name == name);
            let resolution = camera.and_then(|c| c.resolution).or(options.resolution);
            let csv = dir.join("corners.csv");
            if csv.is_file() {
                let views = read_corners(&dir, &target)?;
                sources.push(csv.clone());
                cameras.push(CameraCorners { name, path: csv, views, resolution, detection: None });
            } else if let Some(cam) = camera.filter(|c| !c.frames.is_empty()) {
                progress(&format!("{name}: no corners.csv; detecting the target in {} images", cam.frames.len()));
                let (views, stats) = detect_corners(&cam.frames, &target, progress)?;
                progress(&format!("{name}: {}", stats.line()));
                let data_csv = dir.join("data.csv");
                if let Some(r) = resolution.filter(|r| *r != stats.image_size) {
                    return Err(InputError::file(
                        &data_csv,
                        format!(
                            "the images are {}×{} px, but the camera's size is given as {}×{}",
                            stats.image_size[0], stats.image_size[1], r[0], r[1]
                        ),
                    )
                    .with_hint("check camN/sensor.yaml's resolution or --resolution"));
                }
                let resolution = Some(stats.image_size);
                sources.push(data_csv.clone());
                cameras.push(CameraCorners { name, path: data_csv, views, resolution, detection: Some(stats) });
            }
        }
        if cameras.is_empty() {
            return Err(InputError::file(&ds.root, "has neither camN/corners.csv nor camN/data.csv with images")
                .with_hint("give the target's corners as camN/corners.csv, or the images with camN/data.csv (detected with the `opencv` feature)"));
        }
        if let Some(c) = cameras.iter().find(|c| c.resolution.is_none()) {
            return Err(InputError::file(
                &c.path,
                "the camera's image size is unknown (no sensor.yaml with resolution)",
            )
            .with_hint("give --resolution WIDTHxHEIGHT"));
        }
        let imu = ds.imu.calibrated(calibration.as_ref());
        Ok(RigInput { imu, imu_t0_ns: ds.imu.t0_ns, noise: params, noise_source, cameras, target, sources })
    }
}

#[cfg(feature = "opencv")]
fn detect_corners(
    frames: &[(i64, PathBuf)],
    target: &Target,
    progress: &mut dyn FnMut(&str),
) -> Result<(Vec<View>, DetectionStats), InputError> {
    super::detect::detect_camera(frames, target, progress)
}

#[cfg(not(feature = "opencv"))]
fn detect_corners(
    frames: &[(i64, PathBuf)],
    _target: &Target,
    _progress: &mut dyn FnMut(&str),
) -> Result<(Vec<View>, DetectionStats), InputError> {
    let folder = frames.first().and_then(|(_, p)| p.parent()).unwrap_or(Path::new("."));
    Err(InputError::file(folder, "has images but no corners.csv, and this tumble was built without the target detector")
        .with_hint("build with `--features opencv` (after `apt-get install libopencv-dev clang libclang-dev`), or give camN/corners.csv"))
}
