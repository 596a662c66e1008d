//! A real recording's IMU with a simulated camera along its ground truth
//! (`tumble sim replay --from DIR`): a window of the recording written as an
//! ASL folder — the IMU's samples as recorded, the ground truth, and a
//! camera flown along the path the body moved (the ground truth below the
//! band where it stops following the IMU, the IMU's own motion above)
//! through the box around the whole path that `tumble vio --simulate-camera`
//! uses (a hall-sized one on a Machine Hall flight). The camera gives
//! feature tracks, or with images its frames rendered through the same
//! lens. A window that starts mid-flight tests an estimator's start in
//! motion, on a real IMU, with pictures whose truth is exact.
//!
//! ```text
//! OUT/mav0/imu0/data.csv (+ sensor.yaml when the source has one)   the window's samples
//! OUT/mav0/state_groundtruth_estimate0/data.csv                   the window's ground truth
//! OUT/mav0/cam0/{sensor.yaml,data.csv,tracks.csv | data/*.png}    the simulated camera
//! OUT/truth/{tracks.csv,observations.csv,landmarks.csv}, OUT/truth.json
//! ```

use super::camera::{room_around, simulate_tracks, Observation};
use super::images::render_cameras;
use super::motion::Replay;
use super::render::{scene::RenderScene, ImageSettings};
use super::replay_bands::camera_path;
use super::writer::{write_text, CameraFiles};
use super::{CameraSettings, Scene, SimError, SimulatedTracks};
use crate::io::asl::{read_asl, AslDataset};
use crate::io::trajectory::{write_asl_groundtruth, Trajectory};
use std::path::{Path, PathBuf};

/// What to replay and how the camera sees it.
#[derive(Debug, Clone)]
pub struct ReplaySettings {
    /// Start of the window after the recording's first IMU sample \[s\].
    pub start_s: f64,
    /// Length of the window \[s\] (None: to the end of the recording).
    pub duration_s: Option<f64>,
    /// The camera; its scene's box is grown to hold the whole path with
    /// the landmarks' density kept.
    pub camera: CameraSettings,
    /// How the frames are rendered (None: feature tracks only, in
    /// `cam0/tracks.csv`).
    pub images: Option<ImageSettings>,
    /// Seed of the landmarks, the pixel noise, the scene's textures and the
    /// sensor's noise.
    pub seed: u64,
}

impl ReplaySettings {
    /// Check for values that cannot be replayed.
    pub fn check(&self) -> Result<(), SimError> {
        if !(self.start_s.is_finite() && self.start_s >= 0.0) {
            return Err(format!("replay: the start must be a time ≥ 0 s, found {}", self.start_s).into());
        }
        if let Some(d) = self.duration_s {
            if !(d.is_finite() && d > 0.0) {
                return Err(format!("replay: the duration must be positive, found {d}").into());
            }
        }
        self.camera.check()?;
        if let Some(images) = &self.images {
            images.check()?;
        }
        Ok(())
    }
}

/// What was written.
#[derive(Debug, Clone)]
pub struct Replayed {
    /// The window written, from the source's first IMU sample \[s\].
    pub window_s: [f64; 2],
    /// IMU samples written.
    pub imu_samples: usize,
    /// Camera frames written.
    pub frames: usize,
    /// Feature observations of cam0.
    pub observations: usize,
    /// Half extents of the box the camera sees \[m\].
    pub scene_half_extent: [f64; 3],
    /// Notes for the user: where the camera's path leaves the ground truth
    /// for the IMU's motion, what the source lacked.
    pub notes: Vec<String>,
}

/// Shortest window replayed \[s\].
const MIN_WINDOW_S: f64 = 1.0;

/// Replay the ASL recording `source` as `s` says into `out` (written only
/// when everything succeeded), calling `progress(done, total)` as frames are
/// rendered. Errors: a source without ground truth, a window outside the
/// recording, a file that cannot be read or written.
pub fn replay_and_write(
    source: &Path,
    s: &ReplaySettings,
    out: &Path,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<Replayed, SimError> {
    s.check()?;
    let ds = read_asl(source, &Default::default())?;
    let gt = ds.groundtruth.as_ref().ok_or_else(|| {
        crate::InputError::file(&ds.root, "no ground truth (state_groundtruth_estimate0/, gt0/ or mocap0/)")
            .with_hint("the camera is flown along the true path")
    })?;
    let recorded = Replay::new(gt, ds.imu.t0_ns).map_err(|e| crate::InputError::file(&ds.root, e.to_string()))?;
    let (motion, note) = camera_path(recorded, &ds.imu.calibrated(None));
    let window = window_of(&ds, gt, s)?;
    let (scene, camera) = room_around(motion.positions(), &s.camera);
    let tracks = within(simulate_tracks(&motion, &camera, &scene, s.seed), window);
    let stamp = |t: f64| ds.imu.t0_ns + (t * 1e9).round() as i64;
    let mut imu_samples = 0;
    crate::io::staging::write_staged(out, |stage| -> Result<Vec<PathBuf>, SimError> {
        imu_samples = write_sensors(&ds, gt, window, &stamp, stage)?;
        let comment = match s.images {
            Some(_) => "simulated camera along a recorded path (rendered images in data/)",
            None => "simulated camera along a recorded path (no images; features in tracks.csv)",
        };
        CameraFiles { camera: &camera, comment, images: s.images.is_some() }.write(&tracks, &stamp, stage)?;
        if let Some(images) = &s.images {
            let Scene::Room(centre) = scene else { unreachable!("room_around gives a room") };
            let render = RenderScene::room(centre, camera.room_half_extent, s.seed);
            render_cameras(&render, &camera, &motion, &tracks.frames, &stamp, images, s.seed, stage, progress)?;
        }
        write_text(&stage.join("truth.json"), &truth_json(&ds, s, &camera, &scene, window, note.as_deref())?)?;
        crate::io::staging::files_under(stage).map_err(|e| SimError::from(format!("{}: {e}", stage.display())))
    })?;
    Ok(Replayed {
        window_s: window,
        imu_samples,
        frames: tracks.frames.len(),
        observations: tracks.observations.len(),
        scene_half_extent: camera.room_half_extent,
        notes: note.into_iter().chain(ds.warnings.iter().cloned()).collect(),
    })
}

/// The window `[start, end]` \[s from the first IMU sample\] where both the
/// IMU and the ground truth are, cut to `s`' start and duration.
fn window_of(ds: &AslDataset, gt: &Trajectory, s: &ReplaySettings) -> Result<[f64; 2], SimError> {
    let rel = |t_ns: i64| (t_ns - ds.imu.t0_ns) as f64 * 1e-9;
    let (Some(&gt_first), Some(&gt_last)) = (gt.t_ns.first(), gt.t_ns.last()) else {
        return Err(crate::InputError::file(&ds.root, "the ground truth is empty").into());
    };
    let covered = [rel(gt_first).max(0.0), rel(gt_last).min(ds.imu.duration())];
    let start = covered[0].max(s.start_s);
    let end = s.duration_s.map_or(covered[1], |d| (s.start_s + d).min(covered[1]));
    if end - start < MIN_WINDOW_S {
        return Err(SimError::Invalid(format!(
            "replay: {}: the IMU and the ground truth overlap over {:.1}–{:.1} s from the first IMU sample; \
             a window from {} s{} leaves under {MIN_WINDOW_S} s",
            ds.root.display(),
            covered[0],
            covered[1],
            s.start_s,
            s.duration_s.map(|d| format!(" of {d} s")).unwrap_or_default()
        )));
    }
    Ok([start, end])
}

/// `tracks` with only the frames and observations within `window` \[s\].
fn within(mut tracks: SimulatedTracks, window: [f64; 2]) -> SimulatedTracks {
    let inside = |t: f64| t >= window[0] && t <= window[1];
    tracks.frames.retain(|&t| inside(t));
    let keep = |obs: &mut Vec<Observation>| obs.retain(|o| inside(o.t));
    keep(&mut tracks.observations);
    keep(&mut tracks.stereo);
    tracks
}

/// The window's IMU samples (and the source's `imu0/sensor.yaml`) and ground
/// truth into `out/mav0/` (the window's ends stamped `stamp_ns`); returns
/// the samples written.
fn write_sensors(
    ds: &AslDataset,
    gt: &Trajectory,
    window: [f64; 2],
    stamp_ns: &dyn Fn(f64) -> i64,
    out: &Path,
) -> Result<usize, SimError> {
    let mav0 = out.join("mav0");
    let imu_dir = mav0.join("imu0");
    std::fs::create_dir_all(&imu_dir).map_err(|e| format!("{}: {e}", imu_dir.display()))?;
    // The end inclusive: a sample stamped at the window's end is kept.
    let imu = ds.imu.slice_time(window[0], window[1] + 1e-9);
    crate::io::imu_write::write_asl_imu(&imu_dir.join("data.csv"), &imu)?;
    let yaml = ds.root.join("imu0").join("sensor.yaml");
    if yaml.is_file() {
        let to = imu_dir.join("sensor.yaml");
        std::fs::copy(&yaml, &to).map_err(|e| format!("{} → {}: {e}", yaml.display(), to.display()))?;
    }
    let gt_dir = mav0.join("state_groundtruth_estimate0");
    std::fs::create_dir_all(&gt_dir).map_err(|e| format!("{}: {e}", gt_dir.display()))?;
    write_asl_groundtruth(&gt_dir.join("data.csv"), &gt.between(stamp_ns(window[0]), stamp_ns(window[1])))?;
    Ok(imu.len())
}

/// `truth.json`: the source, the window, the camera and its scene.
fn truth_json(
    ds: &AslDataset,
    s: &ReplaySettings,
    camera: &CameraSettings,
    scene: &Scene,
    window: [f64; 2],
    path_note: Option<&str>,
) -> Result<String, SimError> {
    let Scene::Room(centre) = scene else { unreachable!("room_around gives a room") };
    let truth = serde_json::json!({
        "generator": format!("tumble {}", env!("CARGO_PKG_VERSION")),
        "scenario": "replay",
        "source": ds.root.display().to_string(),
        "source_t0_ns": ds.imu.t0_ns,
        "window_s": window,
        "seed": s.seed,
        "camera": camera,
        "images": s.images,
        "scene": { "centre": [centre.x, centre.y, centre.z], "half_extent": camera.room_half_extent },
        "camera_path": path_note.unwrap_or("the ground truth as recorded (its accelerations follow the IMU's in every band)"),
        "convention": "IMU samples and ground truth copied from the source; the camera flies the body's path (ground truth below the cut, the IMU's motion above); an image stamped t was exposed at IMU time t + camera.time_offset_s",
    });
    serde_json::to_string_pretty(&truth).map_err(|e| SimError::from(format!("truth.json: {e}")))
}
