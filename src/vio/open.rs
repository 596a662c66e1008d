//! Opening a VIO input by its path, as `tumble vio`, `audit --vio` and `run`
//! take it: an EqVIO `.csv`, or an ASL folder with feature tracks, with
//! images (tracked by the visual frontend into a folder), or with only an
//! IMU and a ground truth (seen by a simulated camera, an evaluation aid).
//!

use super::frontend::{track_asl_into, FrontendOptions, FrontendReport};
use super::VioInput;
use crate::calib::ImuCalibration;
use crate::InputError;
use std::path::{Path, PathBuf};

/// How to open a VIO input (see [`VioInput::open`]).
#[derive(Debug, Clone, Default)]
pub struct VioSource {
    /// Calibration applied to every IMU sample (eq. 16; not to EqVIO files,
    /// which hold corrected samples).
    pub calibration: Option<ImuCalibration>,
    /// Ground truth (ASL CSV) instead of the folder's own.
    pub groundtruth: Option<PathBuf>,
    /// No camera data: a simulated camera (EuRoC cam0 model) flies the ground
    /// truth, with this seed for its landmarks and noise.
    pub simulate_camera: Option<u64>,
    /// The simulated camera's second camera, this far to the right of the
    /// first \[m\] (`Some(0.0)`: one camera). `None`: as the dataset has
    /// them — the distance between `cam0` and `cam1` when both have a
    /// `sensor.yaml` (EuRoC: 0.110 m), else one camera.
    pub simulated_stereo_baseline_m: Option<f64>,
    /// One camera: ignore `cam0/tracks_cam1.csv`, and keep the frontend from
    /// matching cam0's features into cam1 (it does when `cam1/` has images
    /// and both cameras their extrinsics).
    pub mono: bool,
    /// The frontend's settings, used when cam0 has images but no `tracks.csv`.
    pub frontend: FrontendOptions,
    /// Where the frontend writes its tracks and figures.
    pub frontend_dir: PathBuf,
    /// A rig calibration (`tumble calibrate-rig`) whose cameras and time
    /// offset replace the dataset's own.
    pub rig: Option<crate::io::target::RigCalibration>,
}

/// An opened VIO input and what opening it did.
#[derive(Debug)]
pub struct OpenedVio {
    /// The input.
    pub input: VioInput,
    /// What was chosen (e.g. the simulated camera), for the user.
    pub notes: Vec<String>,
    /// What was ignored or doubtful, for the user.
    pub warnings: Vec<String>,
    /// The frontend's report when it tracked the images.
    pub frontend: Option<FrontendReport>,
}

/// Why a VIO input cannot be opened.
#[derive(Debug, thiserror::Error)]
pub enum OpenError {
    /// A file of the input is wrong (named with its line).
    #[error(transparent)]
    Input(#[from] InputError),
    /// An option of the source is invalid.
    #[error("{0}")]
    Option(String),
    /// The visual frontend failed on the images.
    #[error("{}: the visual frontend failed: {message}", path.display())]
    Frontend {
        /// The dataset.
        path: PathBuf,
        /// What failed.
        message: String,
    },
}

impl VioInput {
    /// Open `path` as a VIO input, as `tumble vio` takes it; `progress(done, total)`
    /// follows the frontend when it has to track images.
    pub fn open(
        path: &Path,
        source: &VioSource,
        progress: &mut dyn FnMut(usize, usize),
    ) -> Result<OpenedVio, OpenError> {
        let cal = source.calibration.as_ref();
        let is_csv = path.extension().is_some_and(|e| e.eq_ignore_ascii_case("csv"));
        let (mut notes, mut warnings, mut frontend) = (Vec::new(), Vec::new(), None);
        let mut input = if is_csv {
            if cal.is_some() {
                warnings.push("EqVIO files hold corrected samples already; the calibration is not applied".to_string());
            }
            crate::vio::read_eqvio(path, source.groundtruth.as_deref())?
        } else {
            let mut ds = crate::io::asl::read_asl(path, &Default::default())?;
            if let Some(rig) = &source.rig {
                rig.apply_to(&mut ds)?;
                notes.push(format!(
                    "cameras: the rig calibration of {} (time offset {:.3} ms)",
                    rig.dir.display(),
                    rig.time_offset_s * 1e3
                ));
            }
            if let Some(seed) = source.simulate_camera {
                let baseline = source.simulated_stereo_baseline_m.unwrap_or_else(|| dataset_baseline(&ds));
                let cam = crate::sim::CameraSettings { stereo_baseline_m: baseline, ..Default::default() };
                cam.check().map_err(|e| OpenError::Option(format!("the simulated camera: {e}")))?;
                notes.push(format!(
                    "camera: simulated (EuRoC cam0 model{}) along the ground truth, seed {seed}",
                    if baseline > 0.0 {
                        format!(", and a second camera {baseline:.3} m to its right")
                    } else {
                        String::new()
                    }
                ));
                if source.simulated_stereo_baseline_m.is_none() && baseline == 0.0 {
                    notes.push(format!(
                        "camera: one, as {} to place a second; --simulate-stereo 0.11 simulates EuRoC's pair \
                         (far landmarks, as in a hall, get their depths, and the path its scale, from the second \
                         camera: docs/vio.md)",
                        missing_camera_poses(&ds.cameras)
                    ));
                }
                let (input, smoothing) = VioInput::from_dataset_with_simulated_camera(ds, cal, &cam, seed)?;
                notes.extend(smoothing.into_iter().map(|n| format!("camera: {n}")));
                input
            } else {
                let needs_frontend = ds
                    .cameras
                    .first()
                    .is_some_and(|c| !ds.root.join(&c.name).join("tracks.csv").is_file() && !c.frames.is_empty());
                // The frontend matches cam0's features into cam1 when the
                // folder has a second camera with its extrinsic, as a
                // simulated camera is given one: with 11 cm between EuRoC's
                // cameras the matches' depths carry the scale where the
                // parallax between keyframes does not (a hall).
                let frontend_options =
                    FrontendOptions { stereo: !source.mono && has_stereo_pair(&ds), ..source.frontend.clone() };
                let input = if needs_frontend {
                    let (obs, report) = track_asl_into(&ds, 0, &frontend_options, &source.frontend_dir, progress)
                        .map_err(|e| OpenError::Frontend { path: ds.root.clone(), message: e.0 })?;
                    frontend = Some(report);
                    let right = frontend_options.stereo.then(|| source.frontend_dir.join("tracks_cam1.csv"));
                    VioInput::from_dataset_with_stereo(ds, cal, Some(obs), right.as_deref())?
                } else {
                    // Stereo matches next to cam0's tracks.csv.
                    VioInput::from_dataset(ds, cal, None, !source.mono)?
                };
                match &source.rig {
                    Some(rig) if rig.time_offset_s != 0.0 => input.with_time_offsets(rig.time_offset_s, 0.0),
                    _ => input,
                }
            }
        };
        if let (Some(rig), true) = (&source.rig, is_csv) {
            warnings.push(format!(
                "{}: not applied (an EqVIO file carries normalized features of its own camera)",
                rig.dir.display()
            ));
        }
        if let (Some(g), false) = (&source.groundtruth, is_csv) {
            input.groundtruth = Some(crate::io::trajectory::read_asl_groundtruth(g)?);
        }
        input.name = path.display().to_string();
        warnings.extend(input.limit_to_imu()?);
        Ok(OpenedVio { input, notes, warnings, frontend })
    }
}

/// The distance between the dataset's `cam0` and `cam1` \[m\], when both
/// have their pose in the body frame (`sensor.yaml`); 0 otherwise.
fn dataset_baseline(ds: &crate::io::asl::AslDataset) -> f64 {
    let pose = |name: &str| ds.cameras.iter().find(|c| c.name == name).and_then(|c| c.t_bs);
    match (pose("cam0"), pose("cam1")) {
        (Some(a), Some(b)) => (a.translation.vector - b.translation.vector).norm(),
        _ => 0.0,
    }
}

/// What keeps [`dataset_baseline`] from placing a second camera, for a note:
/// the folder's camera poses (`camN/sensor.yaml`'s `T_BS`) that are missing.
fn missing_camera_poses(cameras: &[crate::io::asl::Camera]) -> String {
    let missing: Vec<&str> = ["cam0", "cam1"]
        .into_iter()
        .filter(|name| !cameras.iter().any(|c| c.name == *name && c.t_bs.is_some()))
        .collect();
    match missing.as_slice() {
        [] => "the folder's two cameras are at one place".to_string(),
        [one] => format!("the folder places no {one} (no {one}/sensor.yaml with its T_BS)"),
        _ => "the folder places no camera (no cam0/ or cam1/sensor.yaml with its T_BS)".to_string(),
    }
}

/// Whether `ds` has a second camera the frontend can match cam0's features
/// into: `cam1/` with its intrinsics, both cameras' extrinsics and images.
fn has_stereo_pair(ds: &crate::io::asl::AslDataset) -> bool {
    let cam = |name: &str| ds.cameras.iter().find(|c| c.name == name);
    match (cam("cam0"), cam("cam1")) {
        (Some(c0), Some(c1)) => c0.t_bs.is_some() && c1.t_bs.is_some() && c1.model.is_some() && !c1.frames.is_empty(),
        _ => false,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::asl::Camera;

    fn camera(name: &str, placed: bool) -> Camera {
        Camera {
            name: name.to_string(),
            model: None,
            t_bs: placed.then(nalgebra::Isometry3::identity),
            resolution: None,
            rate_hz: None,
            frames: Vec::new(),
        }
    }

    #[test]
    fn the_one_camera_note_names_what_is_missing() {
        assert!(missing_camera_poses(&[]).contains("no camera"));
        assert!(missing_camera_poses(&[camera("cam0", false)]).contains("no camera"));
        // A real monocular rig: cam0 placed, no cam1.
        let mono = missing_camera_poses(&[camera("cam0", true)]);
        assert!(mono.contains("no cam1/sensor.yaml"), "{mono}");
        let unplaced = missing_camera_poses(&[camera("cam0", true), camera("cam1", false)]);
        assert!(unplaced.contains("no cam1"), "{unplaced}");
        assert!(missing_camera_poses(&[camera("cam0", true), camera("cam1", true)]).contains("at one place"));
    }
}
