//! What the estimator consumes: calibrated IMU samples, frames of feature
//! observations, the camera model and extrinsic, optional ground truth — from a
//! simulation, an ASL folder with a `tracks.csv`, or EqVIO's processed CSV.

use super::ImuNoise;
use super::VioError;
use crate::io::trajectory::read_asl_groundtruth;
use crate::io::{asl, trajectory::Trajectory};
use crate::model::calibration::ImuCalibration;
use crate::model::geometry::pose;
use crate::model::ImuData;
use crate::InputError;
use nalgebra::{UnitQuaternion, Vector3};
use std::collections::BTreeMap;
use std::path::Path;
use tumble_factors::camera::{CameraModel, Distortion};
use tumble_factors::imu_preint::PreintegrationParams;
use tumble_solvers::sophus_lie::Isometry3F64;

/// One camera frame: its time and the features seen, as `(track id, pixel [u, v])`.
#[derive(Debug, Clone, Default)]
pub struct Frame {
    /// Frame time \[s\] on the IMU's time axis.
    pub t: f64,
    /// Observed features.
    pub features: Vec<(u64, [f64; 2])>,
}

/// A second camera rigidly mounted beside the first (stereo): what it saw at
/// the times of [`VioInput::frames`], under the first camera's track ids.
/// The closed-form initialization uses it for metric depth ([`super::init`]).
#[derive(Debug, Clone)]
pub struct StereoCamera {
    /// Camera model of the pixel coordinates in `features`.
    pub camera: CameraModel,
    /// This camera's pose in the body (IMU) frame, `T_BC1`.
    pub body_from_camera: Isometry3F64,
    /// Per frame of [`VioInput::frames`] (same index), the features matched
    /// into this camera: `(track id, pixel [u, v])`.
    pub features: Vec<Vec<(u64, [f64; 2])>>,
}

/// Where a run's IMU noise came from ([`VioInput::apply_noise`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NoiseSource {
    /// Given by the caller.
    Given,
    /// The input's own figures ([`VioInput::noise`]).
    Input,
    /// Neither: the preintegration defaults (EuRoC's ADIS16448).
    Default,
}

/// Everything the estimator needs for one run.
#[derive(Debug, Clone)]
pub struct VioInput {
    /// Name for messages and reports.
    pub name: String,
    /// Absolute time of `t = 0` \[ns\].
    pub t0_ns: i64,
    /// Calibrated IMU.
    pub imu: ImuData,
    /// Frames in time order.
    pub frames: Vec<Frame>,
    /// Camera model of the pixel coordinates in `frames`.
    pub camera: CameraModel,
    /// Camera pose in the body (IMU) frame, `T_BC`.
    pub body_from_camera: Isometry3F64,
    /// A second camera's matches of the same features, when there is one.
    pub stereo: Option<StereoCamera>,
    /// Ground truth (body poses, and biases when known), for evaluation only.
    pub groundtruth: Option<Trajectory>,
    /// IMU noise figures the input itself gives (ASL `imu0/sensor.yaml`, the
    /// simulator's model), if any.
    pub noise: Option<ImuNoise>,
    /// The camera's image files by time \[ns\] (absolute, like `t0_ns`) when
    /// the input came from an image folder; for viewers, not the estimator.
    pub images: Vec<(i64, std::path::PathBuf)>,
}

impl VioInput {
    /// Drop the IMU samples before time `t` \[s\] and the frames up to it
    /// (with the second camera's matches in them), as if the recording began
    /// there (to start it in motion, say); the ground truth is kept.
    pub fn drop_before(&mut self, t: f64) {
        let k = self.imu.t.partition_point(|&s| s < t);
        self.imu.t.drain(..k);
        self.imu.gyro.drain(..k);
        self.imu.acc.drain(..k);
        let n = self.frames.partition_point(|f| f.t <= t);
        self.frames.drain(..n);
        if let Some(st) = self.stereo.as_mut() {
            st.features.drain(..n.min(st.features.len()));
        }
    }

    /// Keep only the frames the IMU covers: frames before the first or after
    /// the last IMU sample cannot be propagated to. Returns a warning naming
    /// what was dropped; refuses when camera and IMU do not overlap at all
    /// (their clocks differ).
    pub fn limit_to_imu(&mut self) -> Result<Option<String>, InputError> {
        let (Some(&a), Some(&b)) = (self.imu.t.first(), self.imu.t.last()) else {
            return Err(InputError::file(std::path::Path::new(&self.name), "no IMU samples"));
        };
        let (Some(f0), Some(f1)) = (self.frames.first().map(|f| f.t), self.frames.last().map(|f| f.t)) else {
            return Ok(None);
        };
        let keep = |t: f64| (a..=b).contains(&t);
        let kept = self.frames.iter().filter(|f| keep(f.t)).count();
        if kept == self.frames.len() {
            return Ok(None);
        }
        if kept < 2 {
            return Err(InputError::file(
                std::path::Path::new(&self.name),
                format!(
                    "camera and IMU do not overlap in time: frames at t = {f0:.3}…{f1:.3} s, IMU samples at \
                     t = {a:.3}…{b:.3} s (on the IMU's clock): their stamps come from different clocks or units"
                ),
            )
            .with_hint("stamp both with one clock (ns since the epoch, as EuRoC does)"));
        }
        let before = self.frames.iter().filter(|f| f.t < a).count();
        let after = self.frames.len() - kept - before;
        if let Some(s) = self.stereo.as_mut() {
            let features = std::mem::take(&mut s.features);
            s.features = features.into_iter().zip(&self.frames).filter(|(_, f)| keep(f.t)).map(|(x, _)| x).collect();
        }
        self.frames.retain(|f| keep(f.t));
        Ok(Some(format!(
            "the IMU covers t = {a:.1}…{b:.1} s and the camera t = {f0:.1}…{f1:.1} s: {before} frame(s) before and \
             {after} after the IMU's samples are not used"
        )))
    }

    /// Set the IMU noise of a run: `given` (e.g. `tumble allan`'s `imu.yaml`)
    /// when there, else the input's own figures, else `p`'s defaults are kept.
    /// Returns which it was.
    pub fn apply_noise(&self, given: Option<ImuNoise>, p: &mut PreintegrationParams) -> NoiseSource {
        match (given, self.noise) {
            (Some(n), _) => {
                n.apply(p);
                NoiseSource::Given
            }
            (None, Some(n)) => {
                n.apply(p);
                NoiseSource::Input
            }
            (None, None) => NoiseSource::Default,
        }
    }

    /// The input with its time offsets corrected: camera frames moved onto the
    /// IMU's time axis by `camera_imu_s` (a frame stamped `t` was taken at IMU
    /// time `t + camera_imu_s`), and the accelerometer resampled at the gyro's
    /// stamps by `accel_gyro_s` (an accelerometer sample stamped `t` measured
    /// the motion at `t + accel_gyro_s`; linear interpolation, held at the ends).
    /// The audit's `camera_imu_time_offset` and `accel_gyro_time_offset` \[s\].
    pub fn with_time_offsets(&self, camera_imu_s: f64, accel_gyro_s: f64) -> VioInput {
        let mut out = self.clone();
        for f in &mut out.frames {
            f.t += camera_imu_s;
        }
        if accel_gyro_s != 0.0 {
            let acc: Vec<[f64; 3]> = self.imu.acc.iter().map(|a| [a.x, a.y, a.z]).collect();
            let shifted = crate::io::imu::resample_delayed(&self.imu.t, &acc, accel_gyro_s);
            out.imu.acc = shifted.into_iter().map(Vector3::from).collect();
        }
        out
    }

    /// Distance between the two cameras \[m\], with a second one.
    pub fn stereo_baseline_m(&self) -> Option<f64> {
        let st = self.stereo.as_ref()?;
        let (_, t0) = crate::model::geometry::parts(&self.body_from_camera);
        let (_, t1) = crate::model::geometry::parts(&st.body_from_camera);
        Some((t1 - t0).norm())
    }

    /// Check what a run needs: samples, frames in order, finite numbers.
    pub fn check(&self) -> Result<(), VioError> {
        let name = &self.name;
        if self.imu.t.len() < 10 {
            return Err(format!("{name}: fewer than 10 IMU samples").into());
        }
        if self.frames.is_empty() {
            return Err(format!("{name}: no camera frames (feature tracks) to fuse").into());
        }
        if let Some(i) = self.imu.t.windows(2).position(|w| w[1] <= w[0]) {
            return Err((format!("{name}: IMU sample {} is not later than the one before", i + 1)).into());
        }
        if let Some(i) = self.frames.windows(2).position(|w| w[1].t <= w[0].t) {
            return Err((format!("{name}: frame {} is not later than the one before", i + 1)).into());
        }
        if let Some(st) = &self.stereo {
            if st.features.len() != self.frames.len() {
                return Err(format!(
                    "{name}: the second camera has features for {} frames, the first for {}",
                    st.features.len(),
                    self.frames.len()
                )
                .into());
            }
            if self.stereo_baseline_m().is_some_and(|b| b < 1e-3) {
                return Err(format!("{name}: the two cameras are less than 1 mm apart: no stereo baseline").into());
            }
        }
        if let Some(i) = (0..self.imu.t.len())
            .find(|&i| !(self.imu.gyro[i].iter().chain(self.imu.acc[i].iter()).all(|x| x.is_finite())))
        {
            return Err(format!("{name}: IMU sample {i} is not finite").into());
        }
        Ok(())
    }

    /// An ASL folder with `imu0/`, `cam0/sensor.yaml` and `cam0/tracks.csv`
    /// (as `tumble sim walk` writes, or a frontend's output), corrected with
    /// `calibration` when given.
    pub fn from_asl(path: &Path, calibration: Option<&ImuCalibration>) -> Result<VioInput, InputError> {
        let ds = asl::read_asl(path, &crate::io::imu_text::ImuTextFormat::default())?;
        Self::from_dataset(ds, calibration, None, true)
    }

    /// As [`VioInput::from_asl`] on a loaded dataset, with the cam0
    /// observations given (e.g. from the [`frontend`](super::frontend) on the
    /// folder's images) or, when None, read from `cam0/tracks.csv`. With
    /// `stereo_tracks`, `cam0/tracks_cam1.csv` (cam0's features matched into
    /// cam1 at the same times, as `tumble track --stereo` writes), when
    /// present, makes it a stereo input ([`StereoCamera`], cam1's model and
    /// extrinsic from `cam1/sensor.yaml`).
    pub fn from_dataset(
        ds: asl::AslDataset,
        calibration: Option<&ImuCalibration>,
        tracks: Option<Vec<(i64, u64, [f64; 2])>>,
        stereo_tracks: bool,
    ) -> Result<VioInput, InputError> {
        let beside_cam0 = ds.cameras.first().map(|c| ds.root.join(&c.name).join("tracks_cam1.csv"));
        Self::from_dataset_with_stereo(ds, calibration, tracks, beside_cam0.filter(|_| stereo_tracks).as_deref())
    }

    /// As [`VioInput::from_dataset`], cam1's matches read from `stereo_tracks`
    /// when it is given and exists (e.g. the frontend's `tracks_cam1.csv`
    /// beside the cam0 tracks it made; None: one camera).
    pub fn from_dataset_with_stereo(
        ds: asl::AslDataset,
        calibration: Option<&ImuCalibration>,
        tracks: Option<Vec<(i64, u64, [f64; 2])>>,
        stereo_tracks: Option<&Path>,
    ) -> Result<VioInput, InputError> {
        let cam = ds.cameras.first().ok_or_else(|| {
            InputError::file(&ds.root, "no cam0/ folder: the estimator needs feature tracks")
                .with_hint("simulate one with `tumble sim walk --out DIR`, or give an EqVIO .csv")
        })?;
        let cam_dir = ds.root.join(&cam.name);
        let camera =
            cam.model.ok_or_else(|| InputError::file(&cam_dir.join("sensor.yaml"), "camera intrinsics missing"))?;
        let obs = match tracks {
            Some(t) => t,
            None => {
                let tracks_path = cam_dir.join("tracks.csv");
                if !tracks_path.is_file() {
                    let hint = if cam.frames.is_empty() {
                        "give tracks as `t[ns],track_id,u,v` in cam0/tracks.csv"
                    } else {
                        "the folder has images: `tumble vio` tracks them with the visual frontend (cargo feature `opencv`), \
                         or `tumble track` writes cam0's tracks"
                    };
                    return Err(InputError::file(&tracks_path, "no feature tracks").with_hint(hint));
                }
                let (obs, lines) = asl::read_tracks_with_lines(&tracks_path)?;
                check_track_stamps(&tracks_path, &obs, &lines, &cam.frames)?;
                obs
            }
        };
        let t0 = ds.imu.t0_ns;
        let mut by_time: BTreeMap<i64, Vec<(u64, [f64; 2])>> = BTreeMap::new();
        for (t, id, uv) in obs {
            by_time.entry(t).or_default().push((id, uv));
        }
        let frame_ns: Vec<i64> = by_time.keys().copied().collect();
        let frames = by_time.into_iter().map(|(t, features)| Frame { t: (t - t0) as f64 * 1e-9, features }).collect();
        let imu_t_bs = ds.imu_sensor.as_ref().map(|s| s.t_bs);
        let body_from = |cam_t_bs: Option<nalgebra::Isometry3<f64>>| {
            let cam_t_bs = cam_t_bs.unwrap_or_else(nalgebra::Isometry3::identity);
            crate::model::geometry::from_nalgebra(&imu_t_bs.map_or(cam_t_bs, |b| b.inverse() * cam_t_bs))
        };
        let body_from_camera = body_from(cam.t_bs);
        let stereo = match stereo_tracks.filter(|p| p.is_file()) {
            None => None,
            Some(stereo_path) => {
                let cam1 = ds.cameras.get(1).ok_or_else(|| {
                    InputError::file(stereo_path, "stereo matches but no cam1/ folder with the second camera")
                })?;
                let yaml1 = ds.root.join(&cam1.name).join("sensor.yaml");
                let camera = cam1.model.ok_or_else(|| InputError::file(&yaml1, "camera intrinsics missing"))?;
                if cam1.t_bs.is_none() || cam.t_bs.is_none() {
                    return Err(InputError::file(&yaml1, "T_BS missing: stereo needs both cameras' extrinsics"));
                }
                let (obs1, lines) = asl::read_tracks_with_lines(stereo_path)?;
                let mut features = vec![Vec::new(); frame_ns.len()];
                for ((t, id, uv), line) in obs1.into_iter().zip(lines) {
                    let k = frame_ns.binary_search(&t).map_err(|_| {
                        InputError::at(stereo_path, line, format!("no cam0 observation at {t} ns to match"))
                    })?;
                    features[k].push((id, uv));
                }
                Some(StereoCamera { camera, body_from_camera: body_from(cam1.t_bs), features })
            }
        };
        let imu = ds.imu.calibrated(calibration);
        let noise = ds.imu_noise();
        let images = cam.frames.clone();
        Ok(with_calibrated_offsets(
            VioInput {
                name: ds.root.display().to_string(),
                t0_ns: t0,
                imu,
                frames,
                camera,
                body_from_camera,
                stereo,
                groundtruth: ds.groundtruth,
                noise,
                images,
            },
            calibration,
        ))
    }
}

/// Tracks read from a file must be at the stamps of the camera's images (when
/// the folder lists them): tracks that match none are stamped in another unit
/// or clock.
fn check_track_stamps(
    path: &std::path::Path,
    obs: &[(i64, u64, [f64; 2])],
    lines: &[usize],
    images: &[(i64, std::path::PathBuf)],
) -> Result<(), InputError> {
    if images.is_empty() {
        return Ok(());
    }
    let stamps: Vec<i64> = images.iter().map(|(t, _)| *t).collect();
    let unmatched = obs.iter().position(|(t, _, _)| stamps.binary_search(t).is_err());
    match unmatched {
        Some(i) => Err(InputError::at(
            path,
            lines.get(i).copied().unwrap_or(0),
            format!(
                "stamp {} ns matches no image in data.csv (images at {}…{} ns): tracks must carry their image's stamp",
                obs[i].0,
                stamps[0],
                stamps[stamps.len() - 1]
            ),
        )
        .with_hint("check the tracks' time unit (nanoseconds) and clock")),
        None => Ok(()),
    }
}

/// `input` with the calibration's time offsets applied, when it has any.
pub(crate) fn with_calibrated_offsets(input: VioInput, calibration: Option<&ImuCalibration>) -> VioInput {
    match calibration.and_then(|c| c.time_offsets) {
        Some(o) if o.camera_imu_s != 0.0 || o.accel_gyro_s != 0.0 => {
            input.with_time_offsets(o.camera_imu_s, o.accel_gyro_s)
        }
        _ => input,
    }
}

/// Read EqVIO's processed CSV (`row_type,t_abs,…`; IMU rows in rad/s and m/s²,
/// features in normalized coordinates, intrinsics and `T_ci` in `meta` rows).
/// Features are returned in pixels of an undistorted pinhole camera with the
/// file's intrinsics. `groundtruth`, when given, is an ASL ground-truth CSV.
pub fn read_eqvio(path: &Path, groundtruth: Option<&Path>) -> Result<VioInput, InputError> {
    let text = std::fs::read_to_string(path).map_err(|e| InputError::file(path, format!("cannot read: {e}")))?;
    let mut meta: BTreeMap<String, String> = BTreeMap::new();
    let mut imu_rows: Vec<(f64, [f64; 6])> = Vec::new();
    let mut feats: Vec<(f64, u64, [f64; 2])> = Vec::new();
    let num = |s: &str, line: usize, what: &str| -> Result<f64, InputError> {
        let v: f64 =
            s.trim().parse().map_err(|_| InputError::at(path, line, format!("{what}: '{s}' is not a number")))?;
        if !v.is_finite() {
            return Err(InputError::at(path, line, format!("{what} is not finite")));
        }
        Ok(v)
    };
    for (i, l) in text.lines().enumerate() {
        let line = i + 1;
        let c: Vec<&str> = l.split(',').collect();
        match c[0] {
            "row_type" | "" => {}
            "meta" => {
                if c.len() >= 22 {
                    meta.insert(c[20].to_string(), c[21].to_string());
                }
            }
            "imu" | "vision_feature" if c.len() < 20 => {
                return Err(InputError::at(path, line, format!("{} columns, expected at least 20", c.len())));
            }
            "imu" => {
                let t = num(c[1], line, "t_abs")?;
                let mut v = [0.0; 6];
                for (k, x) in v.iter_mut().enumerate() {
                    *x = num(c[6 + k], line, "IMU value")?;
                }
                imu_rows.push((t, v));
            }
            "vision_feature" => {
                let t = num(c[1], line, "t_abs")?;
                let id = num(c[5], line, "landmark_id")?;
                if id < 0.0 || id.fract() != 0.0 {
                    return Err(InputError::at(path, line, format!("landmark_id {id} is not a non-negative integer")));
                }
                feats.push((t, id as u64, [num(c[18], line, "u_norm")?, num(c[19], line, "v_norm")?]));
            }
            other => return Err(InputError::at(path, line, format!("unknown row type '{other}'"))),
        }
    }
    let m = |k: &str| -> Result<f64, InputError> {
        let s = meta.get(k).ok_or_else(|| InputError::file(path, format!("meta key {k} missing")))?;
        s.parse().map_err(|_| InputError::file(path, format!("meta key {k}: '{s}' is not a number")))
    };
    if imu_rows.is_empty() {
        return Err(InputError::file(path, "no imu rows"));
    }
    let (fx, fy, cx, cy) = (m("camera_fx")?, m("camera_fy")?, m("camera_cx")?, m("camera_cy")?);
    let q = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(
        m("T_ci_qw")?,
        m("T_ci_qx")?,
        m("T_ci_qy")?,
        m("T_ci_qz")?,
    ));
    let t_ci = Vector3::new(m("T_ci_tx")?, m("T_ci_ty")?, m("T_ci_tz")?);
    let t0 = imu_rows[0].0;
    let t0_ns = (t0 * 1e9).round() as i64;
    let imu = ImuData {
        t: imu_rows.iter().map(|r| r.0 - t0).collect(),
        gyro: imu_rows.iter().map(|r| Vector3::new(r.1[0], r.1[1], r.1[2])).collect(),
        acc: imu_rows.iter().map(|r| Vector3::new(r.1[3], r.1[4], r.1[5])).collect(),
    };
    let mut frames: Vec<Frame> = Vec::new();
    for (t, id, xy) in feats {
        let t = t - t0;
        if frames.last().is_none_or(|f| (f.t - t).abs() > 1e-6) {
            if frames.last().is_some_and(|f| t < f.t) {
                return Err(InputError::file(path, format!("feature rows go back in time at t = {t:.6} s")));
            }
            frames.push(Frame { t, features: Vec::new() });
        }
        frames.last_mut().expect("frame").features.push((id, [xy[0] * fx + cx, xy[1] * fy + cy]));
    }
    let groundtruth = groundtruth.map(read_asl_groundtruth).transpose()?;
    Ok(VioInput {
        name: path.display().to_string(),
        t0_ns,
        imu,
        frames,
        camera: CameraModel { fx, fy, cx, cy, distortion: Distortion::None },
        body_from_camera: pose(q.to_rotation_matrix().matrix(), &t_ci),
        stereo: None,
        groundtruth,
        noise: None,
        images: Vec::new(),
    })
}

impl super::Init {
    /// The ground-truth state at `input`'s first frame, as an initialization
    /// (evaluation aid: `tumble vio --init-from-groundtruth`).
    pub fn from_groundtruth(input: &VioInput) -> Result<super::Init, super::VioError> {
        let err = |m: &str| super::VioError::Invalid(format!("{}: {m}", input.name));
        let gt = input.groundtruth.as_ref().ok_or_else(|| {
            err("--init-from-groundtruth needs ground truth (--groundtruth FILE, or the folder's own)")
        })?;
        let t_first = input.frames.first().ok_or_else(|| err("no frames"))?.t;
        let want = input.t0_ns + (t_first * 1e9).round() as i64;
        let k = gt.t_ns.partition_point(|&s| s < want);
        if k >= gt.len() {
            return Err(err("the ground truth ends before the first frame"));
        }
        let t = (gt.t_ns[k] - input.t0_ns) as f64 * 1e-9;
        let v = gt.v.as_ref().map_or([0.0; 3], |x| x[k]);
        let bias_accel = gt.bias_accel.as_ref().map_or([0.0; 3], |x| x[k]);
        let bias_gyro = gt.bias_gyro.as_ref().map_or([0.0; 3], |x| x[k]);
        Ok(super::Init::Given { q: gt.q[k], p: gt.p[k], v, bias_accel, bias_gyro, t })
    }
}

#[cfg(test)]
impl VioInput {
    /// An input for the estimator's unit tests: a pinhole camera (500 px
    /// focal length, principal point (320, 240), no distortion) at the body
    /// origin looking along the body's z axis, with these samples and frames.
    pub(crate) fn for_tests(imu: ImuData, frames: Vec<Frame>) -> VioInput {
        VioInput {
            name: "test".into(),
            t0_ns: 0,
            imu,
            frames,
            camera: CameraModel { fx: 500.0, fy: 500.0, cx: 320.0, cy: 240.0, distortion: Distortion::None },
            body_from_camera: pose(&nalgebra::Matrix3::identity(), &Vector3::zeros()),
            stereo: None,
            groundtruth: None,
            noise: None,
            images: Vec::new(),
        }
    }
}
