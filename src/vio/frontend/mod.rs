//! The visual frontend: camera images in, feature tracks out — the tracks the
//! estimator fuses, in the plain `t[ns], track_id, u[px], v[px]` file that
//! the simulator writes and other frontends can write too.
//!
//! The tracker itself (`KltTracker`, VINS-Mono's recipe: Shi–Tomasi corners
//! spread by a minimum-distance mask, pyramidal KLT with a forward–backward
//! check, RANSAC on the fundamental matrix of undistorted points) uses OpenCV
//! and is built with the cargo feature `opencv`
//! (`apt-get install libopencv-dev clang libclang-dev`, then
//! `cargo build --features opencv`). Options, statistics, the tracks file and
//! the corner detector ([`corners`]) are here without it.

pub mod anchor;
pub mod corners;
pub mod prediction;
pub use prediction::gyro_rotations;
#[cfg(feature = "opencv")]
mod klt;
#[cfg(feature = "opencv")]
pub use klt::{draw_tracks, match_stereo, moving_window, track_camera, track_stereo, KltTracker};

use crate::error::InputError;
#[cfg(doc)]
use crate::io::asl::AslDataset;
use serde::Serialize;
use std::io::Write;
use std::path::Path;

/// One observation: time \[ns\], track id, pixel `[u, v]` (distorted, as in the image).
pub type Observation = (i64, u64, [f64; 2]);

/// Settings of the KLT frontend (defaults: VINS-Mono's EuRoC configuration).
#[derive(Debug, Clone, Serialize)]
pub struct FrontendOptions {
    /// Features kept per frame.
    pub max_features: usize,
    /// Smallest distance between two features \[px\].
    pub min_distance: f64,
    /// Shi–Tomasi quality level (fraction of the strongest corner's score).
    pub quality: f64,
    /// KLT window side \[px\].
    pub window: i32,
    /// KLT pyramid levels above the full image.
    pub pyramid_levels: i32,
    /// Largest forward–backward KLT disagreement \[px\].
    pub fb_threshold: f64,
    /// RANSAC threshold on the epipolar distance, in pixels of the undistorted image.
    pub ransac_threshold: f64,
    /// Contrast-limited histogram equalization (CLAHE) before tracking, VINS-Mono's
    /// `equalize`: helps dark or low-contrast sequences, but its tiles stay put while
    /// the scene moves, so tracks drift more (on a known motion, 95th percentile
    /// 0.80 px instead of 0.26 px after up to 40 frames; `tests/frontend.rs`). Off by default.
    pub equalize: bool,
    /// Also match each cam0 frame's features into cam1's image of the same
    /// time ([`track_asl_stereo`]); `track_asl_into` then writes `tracks_cam1.csv`.
    pub stereo: bool,
    /// Start each feature's KLT where the gyro's rotation between the two
    /// frames moves it ([`gyro_rotations`]; an ASL folder's IMU samples and
    /// the camera's `T_BS`), instead of at its old place: in fast rotation
    /// the image moves tens of pixels per frame, more than the pyramid
    /// follows reliably. Off, or without the IMU or `T_BS`, KLT starts at the old place.
    pub gyro_prediction: bool,
    /// Hold each track to the patch where it began ([`anchor`]): after KLT,
    /// the feature's first patch is aligned to the new image by an affine
    /// warp, so that KLT's frame-to-frame errors do not add up along the
    /// track. Where the alignment fails, KLT's position stays and the
    /// track's anchor starts again there. Off: plain frame-to-frame KLT.
    pub anchored: bool,
}

impl Default for FrontendOptions {
    fn default() -> Self {
        FrontendOptions {
            max_features: 150,
            min_distance: 30.0,
            quality: 0.01,
            window: 21,
            pyramid_levels: 3,
            fb_threshold: 0.5,
            ransac_threshold: 1.0,
            equalize: false,
            stereo: false,
            gyro_prediction: true,
            anchored: true,
        }
    }
}

/// What the frontend did over a sequence.
#[derive(Debug, Clone, Default, Serialize)]
pub struct FrontendStats {
    /// Frames processed.
    pub frames: usize,
    /// Mean features per frame (after rejection and detection).
    pub features_per_frame: f64,
    /// Mean length of the finished and still-running tracks \[frames\].
    pub mean_track_length: f64,
    /// Tracks started.
    pub tracks: usize,
    /// Of the features KLT tracked, the fraction the forward–backward check kept.
    pub fb_ratio: f64,
    /// Of the features entering RANSAC, the fraction it kept as inliers.
    pub inlier_ratio: f64,
    /// Of the tracked features with an anchor, the fraction aligned to it
    /// ([`FrontendOptions::anchored`]; NaN when off).
    pub anchored_ratio: f64,
    /// Tracking time per frame, image decoding excluded \[ms\].
    pub ms_per_frame: f64,
    /// What the reader should know (skipped images, …).
    pub warnings: Vec<String>,
    /// Stereo matching into the second camera, when asked for.
    pub stereo: Option<StereoStats>,
}

/// What stereo matching (cam0 features into cam1's image of the same time) did.
#[derive(Debug, Clone, Default, Serialize)]
pub struct StereoStats {
    /// Stereo pairs matched.
    pub pairs: usize,
    /// cam0 features offered for matching.
    pub offered: usize,
    /// Of those, kept by KLT and its forward–backward check.
    pub klt_kept: usize,
    /// Epipolar distance of each final match \[px of cam1\].
    #[serde(skip)]
    pub epipolar_px: Vec<f64>,
    /// Depth of each final match in cam0 \[m\].
    #[serde(skip)]
    pub depths_m: Vec<f64>,
}

impl StereoStats {
    /// Final matches (KLT, forward–backward, epipolar and depth checks passed).
    pub fn matched(&self) -> usize {
        self.depths_m.len()
    }
    /// Fraction of the offered features matched.
    pub fn match_ratio(&self) -> f64 {
        self.matched() as f64 / self.offered.max(1) as f64
    }
    /// Of the KLT matches, the fraction the epipolar and depth checks kept.
    pub fn epipolar_ratio(&self) -> f64 {
        self.matched() as f64 / self.klt_kept.max(1) as f64
    }
    /// Median of `v` (NaN when empty).
    fn median(v: &[f64]) -> f64 {
        crate::model::numeric::median(&mut v.to_vec()).unwrap_or(f64::NAN)
    }
    /// Median epipolar distance of the matches \[px\].
    pub fn median_epipolar_px(&self) -> f64 {
        Self::median(&self.epipolar_px)
    }
    /// Median depth of the matches \[m\].
    pub fn median_depth_m(&self) -> f64 {
        Self::median(&self.depths_m)
    }
    /// One line for the terminal.
    pub fn line(&self) -> String {
        format!(
            "stereo: {} pairs, {:.1} % of cam0 features matched in cam1 (epipolar check kept {:.1} % of KLT's), \
             median epipolar distance {:.2} px, median depth {:.2} m",
            self.pairs,
            100.0 * self.match_ratio(),
            100.0 * self.epipolar_ratio(),
            self.median_epipolar_px(),
            self.median_depth_m()
        )
    }
}

impl FrontendStats {
    /// One line for the terminal.
    pub fn line(&self) -> String {
        let anchored = match self.anchored_ratio.is_nan() {
            true => String::new(),
            false => format!(", {:.1} % held to their anchors", 100.0 * self.anchored_ratio),
        };
        format!(
            "{} frames: {:.1} features/frame, mean track length {:.2} frames over {} tracks, \
             forward–backward kept {:.1} %{anchored}, RANSAC inliers {:.1} %, {:.2} ms/frame",
            self.frames,
            self.features_per_frame,
            self.mean_track_length,
            self.tracks,
            100.0 * self.fb_ratio,
            100.0 * self.inlier_ratio,
            self.ms_per_frame
        )
    }
}

/// Write observations as a tracks file (`#timestamp [ns],track_id,u [px],v [px]`).
pub fn write_tracks(path: &Path, obs: &[Observation]) -> Result<(), InputError> {
    let io_err = |e: std::io::Error| InputError::file(path, format!("cannot write: {e}"));
    let f = std::fs::File::create(path).map_err(io_err)?;
    let mut w = std::io::BufWriter::new(f);
    writeln!(w, "#timestamp [ns],track_id,u [px],v [px]").map_err(io_err)?;
    for (t, id, uv) in obs {
        writeln!(w, "{t},{id},{:.3},{:.3}", uv[0], uv[1]).map_err(io_err)?;
    }
    w.flush().map_err(io_err)
}

/// What to tell a user whose build lacks the frontend.
pub const NEEDS_OPENCV: &str = "the visual frontend needs the cargo feature `opencv`: \
    `sudo apt-get install -y libopencv-dev clang libclang-dev`, then `cargo run --features opencv -- …`";

/// Track the images of camera `camera` (index into [`AslDataset::cameras`])
/// of an ASL folder; `progress(done, total)` after each frame. Errors name the
/// image or `sensor.yaml` at fault, or say that the build lacks the feature.
pub fn track_asl(
    ds: &crate::io::asl::AslDataset,
    camera: usize,
    opts: &FrontendOptions,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<(Vec<Observation>, FrontendStats), FrontendError> {
    let cam = ds.cameras.get(camera).ok_or_else(|| format!("{}: no camera {camera}", ds.root.display()))?;
    let dir = ds.root.join(&cam.name);
    if cam.frames.is_empty() {
        return Err(format!("{}: no images (data.csv and data/ are empty or missing)", dir.display()).into());
    }
    let model = cam.model.ok_or_else(|| format!("{}: camera intrinsics missing", dir.join("sensor.yaml").display()))?;
    // data.csv may list images the folder lacks (EuRoC extracts cut short): skipped, said.
    let frames: Vec<(i64, std::path::PathBuf)> = cam.frames.iter().filter(|f| f.1.is_file()).cloned().collect();
    if frames.is_empty() {
        return Err(format!("{}: none of the {} images data.csv lists exists", dir.display(), cam.frames.len()).into());
    }
    let mut warnings = Vec::new();
    if frames.len() < cam.frames.len() {
        let first = cam.frames.iter().find(|f| !f.1.is_file()).map(|f| f.1.display().to_string()).unwrap_or_default();
        warnings.push(format!(
            "{}: {} of {} images listed in data.csv are missing and were skipped (first: {first})",
            dir.display(),
            cam.frames.len() - frames.len(),
            cam.frames.len()
        ));
    }
    let stamps: Vec<i64> = frames.iter().map(|f| f.0).collect();
    let rotations = frame_rotations(ds, cam, &stamps, opts, &mut warnings);
    #[cfg(feature = "opencv")]
    {
        let (obs, mut stats) = track_camera(&frames, model, cam.resolution, opts, rotations.as_deref(), progress)?;
        stats.warnings.extend(warnings);
        Ok((obs, stats))
    }
    #[cfg(not(feature = "opencv"))]
    {
        let _ = (model, opts, progress, warnings, rotations);
        Err(format!("{}: {NEEDS_OPENCV}", dir.display()).into())
    }
}

/// Track cam0 of an ASL folder and match every frame's features into cam1's
/// image of the same time (the extrinsics of both `sensor.yaml`s give the
/// epipolar geometry). Returns the cam0 observations, the cam1 observations
/// (same track ids; for stereo initialization) and the statistics with
/// [`FrontendStats::stereo`] set.
pub fn track_asl_stereo(
    ds: &crate::io::asl::AslDataset,
    opts: &FrontendOptions,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<(Vec<Observation>, Vec<Observation>, FrontendStats), FrontendError> {
    let [c0, c1] = [0, 1].map(|k| ds.cameras.get(k));
    let (Some(c0), Some(c1)) = (c0, c1) else {
        return Err(format!("{}: stereo matching needs cam0 and cam1", ds.root.display()).into());
    };
    let yaml = |c: &crate::io::asl::Camera| ds.root.join(&c.name).join("sensor.yaml");
    let model =
        |c: &crate::io::asl::Camera| c.model.ok_or_else(|| format!("{}: camera intrinsics missing", yaml(c).display()));
    let pose = |c: &crate::io::asl::Camera| {
        c.t_bs.ok_or_else(|| format!("{}: T_BS missing: stereo needs both cameras' extrinsics", yaml(c).display()))
    };
    let (m0, m1) = (model(c0)?, model(c1)?);
    let right_from_left = pose(c1)?.inverse() * pose(c0)?;
    if right_from_left.translation.vector.norm() < 1e-3 {
        return Err(format!(
            "{}: cam0 and cam1 are less than 1 mm apart (T_BS): no stereo baseline",
            ds.root.display()
        )
        .into());
    }
    let right: std::collections::HashMap<i64, &std::path::PathBuf> =
        c1.frames.iter().filter(|f| f.1.is_file()).map(|(t, p)| (*t, p)).collect();
    let frames: Vec<_> = c0
        .frames
        .iter()
        .filter(|f| f.1.is_file())
        .map(|(t, p)| (*t, p.clone(), right.get(t).map(|p| (*p).clone())))
        .collect();
    if frames.is_empty() {
        return Err(format!("{}: no cam0 images", ds.root.join(&c0.name).display()).into());
    }
    let unpaired = frames.iter().filter(|f| f.2.is_none()).count();
    let stamps: Vec<i64> = frames.iter().map(|f| f.0).collect();
    let mut warnings = Vec::new();
    let rotations = frame_rotations(ds, c0, &stamps, opts, &mut warnings);
    #[cfg(feature = "opencv")]
    {
        let resolutions = [c0.resolution, c1.resolution];
        let (o0, o1, mut stats) =
            track_stereo(&frames, [m0, m1], resolutions, &right_from_left, opts, rotations.as_deref(), progress)?;
        stats.warnings.extend(warnings);
        if unpaired > 0 {
            stats.warnings.push(format!("{unpaired} cam0 frames have no cam1 image at the same time: not matched"));
        }
        Ok((o0, o1, stats))
    }
    #[cfg(not(feature = "opencv"))]
    {
        let _ = (m0, m1, opts, progress, unpaired, warnings, rotations);
        Err(format!("{}: {NEEDS_OPENCV}", ds.root.display()).into())
    }
}

/// The gyro's rotation of `cam` between its consecutive frames
/// ([`gyro_rotations`]) when [`FrontendOptions::gyro_prediction`] asks for
/// it; None, with a note in `warnings` saying why, when the folder cannot give it.
fn frame_rotations(
    ds: &crate::io::asl::AslDataset,
    cam: &crate::io::asl::Camera,
    stamps: &[i64],
    opts: &FrontendOptions,
    warnings: &mut Vec<String>,
) -> Option<Vec<Option<nalgebra::Rotation3<f64>>>> {
    if !opts.gyro_prediction {
        return None;
    }
    let Some(body_from_camera) = cam.t_bs else {
        warnings.push(format!(
            "{}: no T_BS, so KLT starts at each feature's old place (no gyro prediction)",
            ds.root.join(&cam.name).join("sensor.yaml").display()
        ));
        return None;
    };
    let body_from_imu = ds.imu_sensor.as_ref().map_or(nalgebra::Rotation3::identity(), |s| s.t_bs.rotation.into());
    let camera_from_imu = body_from_camera.rotation.to_rotation_matrix().inverse() * body_from_imu;
    let rotations = gyro_rotations(&ds.imu, &camera_from_imu, stamps);
    let covered = rotations.iter().filter(|r| r.is_some()).count();
    if covered + 1 < stamps.len() {
        warnings.push(format!(
            "{}: the gyro predicts the motion of {covered} of the {} frame pairs (the others are outside \
             imu0's samples, or its rates are raw counts): there KLT starts at each feature's old place",
            ds.root.join(&cam.name).display(),
            stamps.len().saturating_sub(1)
        ));
    }
    Some(rotations)
}

/// [`track_asl`], then write into `dir`: `tracks.csv`, `frontend.json` (the
/// statistics and options) and `tracks.png` (the middle frame with its tracks).
/// Returns the observations and the statistics with the files written.
pub fn track_asl_into(
    ds: &crate::io::asl::AslDataset,
    camera: usize,
    opts: &FrontendOptions,
    dir: &Path,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<(Vec<Observation>, FrontendReport), FrontendError> {
    let (obs, right, stats) = match opts.stereo {
        true if camera == 0 => {
            let (o0, o1, s) = track_asl_stereo(ds, opts, progress)?;
            (o0, Some(o1), s)
        }
        true => return Err(format!("{}: stereo matching starts from cam0", ds.root.display()).into()),
        false => {
            let (o, s) = track_asl(ds, camera, opts, progress)?;
            (o, None, s)
        }
    };
    std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let tracks = dir.join("tracks.csv");
    write_tracks(&tracks, &obs).map_err(|e| e.to_string())?;
    let mut files = vec![tracks];
    if let Some(o1) = &right {
        let p = dir.join("tracks_cam1.csv");
        write_tracks(&p, o1).map_err(|e| e.to_string())?;
        files.push(p);
    }
    let stereo = stats.stereo.as_ref().map(|s| {
        serde_json::json!({
            "match_ratio": s.match_ratio(),
            "epipolar_ratio": s.epipolar_ratio(),
            "median_epipolar_px": s.median_epipolar_px(),
            "median_depth_m": s.median_depth_m(),
        })
    });
    let json = dir.join("frontend.json");
    let text = serde_json::to_string_pretty(&serde_json::json!({ "stats": stats, "stereo": stereo, "options": opts }))
        .map_err(|e| e.to_string())?;
    std::fs::write(&json, text).map_err(|e| format!("{}: {e}", json.display()))?;
    files.push(json);
    #[cfg(feature = "opencv")]
    {
        // The middle tracked frame (observations are in time order).
        let mut times: Vec<i64> = obs.iter().map(|o| o.0).collect();
        times.dedup();
        if let Some(&t) = times.get(times.len() / 2) {
            if let Some((_, image)) = ds.cameras[camera].frames.iter().find(|f| f.0 == t) {
                let png = dir.join("tracks.png");
                draw_tracks(image, t, &obs, 10, &png)?;
                files.push(png);
            }
        }
    }
    Ok((obs, FrontendReport { stats, files }))
}

/// Why the visual frontend could not track a camera (the message names the file).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{0}")]
pub struct FrontendError(pub String);

crate::error::message_error_conversions!(FrontendError, FrontendError);

impl From<crate::InputError> for FrontendError {
    fn from(e: crate::InputError) -> FrontendError {
        FrontendError(e.to_string())
    }
}

/// What [`track_asl_into`] reports besides the observations.
#[derive(Debug, Clone)]
pub struct FrontendReport {
    /// Tracking statistics (and the stereo matching's).
    pub stats: FrontendStats,
    /// The files written (`tracks.csv`, `tracks_cam1.csv`, `frontend.json`, `tracks.png`).
    pub files: Vec<std::path::PathBuf>,
}
