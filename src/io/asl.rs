//! EuRoC / ASL (and TUM-VI) dataset folders.
//!
//! Layout: `mav0/imu0/data.csv` (+ `sensor.yaml`), `mav0/camN/data.csv` with
//! `data/*.png` (+ `sensor.yaml`), ground truth in
//! `mav0/state_groundtruth_estimate0/data.csv` (EuRoC), `mav0/gt0/data.csv`
//! or `mav0/mocap0/data.csv` (TUM-VI). Every function accepts the dataset
//! folder (the one holding `mav0/`) or `mav0/` itself.
//!
//! ```no_run
//! let ds = tumble::io::asl::read_asl(std::path::Path::new("V1_01_easy"), &Default::default()).unwrap();
//! println!("{} IMU samples, {} cameras", ds.imu.len(), ds.cameras.len());
//! ```

use super::imu::ImuRecording;
use super::imu_text::{read_imu_text, ImuTextFormat};
use super::table::{read_table, TableSpec, TimeUnit};
use super::trajectory::{read_asl_groundtruth, Trajectory};
use super::yaml::{parse_yaml, YamlMatrix};
use crate::error::InputError;
use nalgebra::Isometry3;
use serde::Deserialize;
use std::path::{Path, PathBuf};
use tumble_factors::camera::{CameraModel, Distortion};

/// The `mav0/` folder of a dataset given either as the dataset folder or as `mav0/`.
pub fn resolve_mav0(path: &Path) -> Result<PathBuf, InputError> {
    if !path.exists() {
        return Err(InputError::file(path, "does not exist"));
    }
    if path.join("imu0").is_dir() {
        return Ok(path.to_path_buf());
    }
    if path.join("mav0").join("imu0").is_dir() {
        return Ok(path.join("mav0"));
    }
    Err(InputError::file(path, "is not an ASL dataset: no mav0/imu0/ (nor imu0/) inside")
        .with_hint("give the folder holding mav0/, or mav0/ itself"))
}

/// IMU figures from `imu0/sensor.yaml` (Kalibr/EuRoC keys, continuous-time SI).
#[derive(Debug, Clone, PartialEq)]
pub struct ImuSensor {
    /// Sensor-to-body transform (body ← sensor).
    pub t_bs: Isometry3<f64>,
    /// Sample rate \[Hz\].
    pub rate_hz: f64,
    /// Gyro white-noise density \[rad/s/√Hz\].
    pub gyroscope_noise_density: Option<f64>,
    /// Gyro bias random walk \[rad/s²/√Hz\].
    pub gyroscope_random_walk: Option<f64>,
    /// Accelerometer white-noise density \[m/s²/√Hz\].
    pub accelerometer_noise_density: Option<f64>,
    /// Accelerometer bias random walk \[m/s³/√Hz\].
    pub accelerometer_random_walk: Option<f64>,
    /// Per-axis figures (tumble's `axes:` key, see [`super::ImuNoise::axes`]).
    pub axes: Option<super::ImuNoiseAxes>,
}

/// A camera of the dataset: its model, extrinsics and frames.
#[derive(Debug, Clone, PartialEq)]
pub struct Camera {
    /// Folder name (`cam0`, `cam1`).
    pub name: String,
    /// Intrinsics and distortion (None when the folder has no `sensor.yaml`).
    pub model: Option<CameraModel>,
    /// Camera-to-body transform (body ← camera).
    pub t_bs: Option<Isometry3<f64>>,
    /// Image size `[width, height]` \[px\].
    pub resolution: Option<[u32; 2]>,
    /// Frame rate \[Hz\].
    pub rate_hz: Option<f64>,
    /// Frame times \[ns\] and image paths, in time order.
    pub frames: Vec<(i64, PathBuf)>,
}

/// A loaded ASL dataset.
#[derive(Debug, Clone)]
pub struct AslDataset {
    /// The `mav0/` folder.
    pub root: PathBuf,
    /// IMU samples (validated).
    pub imu: ImuRecording,
    /// IMU figures from `imu0/sensor.yaml`, if present.
    pub imu_sensor: Option<ImuSensor>,
    /// Cameras `cam0`, `cam1`, … found.
    pub cameras: Vec<Camera>,
    /// Ground truth, if the dataset has one.
    pub groundtruth: Option<Trajectory>,
    /// Notes on what was missing or repaired.
    pub warnings: Vec<String>,
}

impl AslDataset {
    /// The noise figures of `imu0/sensor.yaml`, when it gives all four.
    pub fn imu_noise(&self) -> Option<super::ImuNoise> {
        let s = self.imu_sensor.as_ref()?;
        Some(super::ImuNoise {
            accelerometer_noise_density: s.accelerometer_noise_density?,
            accelerometer_random_walk: s.accelerometer_random_walk?,
            gyroscope_noise_density: s.gyroscope_noise_density?,
            gyroscope_random_walk: s.gyroscope_random_walk?,
            axes: s.axes,
        })
    }
}

#[derive(Deserialize)]
#[allow(non_snake_case)]
struct ImuYaml {
    T_BS: Option<YamlMatrix>,
    rate_hz: Option<f64>,
    gyroscope_noise_density: Option<f64>,
    gyroscope_random_walk: Option<f64>,
    accelerometer_noise_density: Option<f64>,
    accelerometer_random_walk: Option<f64>,
    axes: Option<super::ImuNoiseAxes>,
}

#[derive(Deserialize)]
#[allow(non_snake_case)]
struct CameraYaml {
    T_BS: Option<YamlMatrix>,
    rate_hz: Option<f64>,
    resolution: Option<[u32; 2]>,
    camera_model: Option<String>,
    intrinsics: Option<Vec<f64>>,
    distortion_model: Option<String>,
    distortion_coefficients: Option<Vec<f64>>,
}

/// Read `imu0/sensor.yaml`.
pub fn read_imu_sensor(path: &Path) -> Result<ImuSensor, InputError> {
    parse_imu_sensor(path, &super::tokens::read_text(path)?)
}

/// Parse the text of an IMU `sensor.yaml` (`path` names it in errors).
pub fn parse_imu_sensor(path: &Path, text: &str) -> Result<ImuSensor, InputError> {
    let y: ImuYaml = parse_yaml(path, text)?;
    let t_bs = match &y.T_BS {
        Some(m) => m.to_transform(path, "T_BS")?,
        None => Isometry3::identity(),
    };
    let rate_hz = y.rate_hz.ok_or_else(|| InputError::file(path, "missing rate_hz"))?;
    if !(rate_hz.is_finite() && rate_hz > 0.0) {
        return Err(InputError::file(path, format!("rate_hz must be positive, found {rate_hz}")));
    }
    for (v, name) in [
        (y.gyroscope_noise_density, "gyroscope_noise_density"),
        (y.gyroscope_random_walk, "gyroscope_random_walk"),
        (y.accelerometer_noise_density, "accelerometer_noise_density"),
        (y.accelerometer_random_walk, "accelerometer_random_walk"),
    ] {
        if let Some(v) = v {
            if !(v.is_finite() && v >= 0.0) {
                return Err(InputError::file(path, format!("{name} must be a non-negative number, found {v}")));
            }
        }
    }
    if let Some(a) = &y.axes {
        a.check().map_err(|m| InputError::file(path, m))?;
    }
    Ok(ImuSensor {
        axes: y.axes,
        t_bs,
        rate_hz,
        gyroscope_noise_density: y.gyroscope_noise_density,
        gyroscope_random_walk: y.gyroscope_random_walk,
        accelerometer_noise_density: y.accelerometer_noise_density,
        accelerometer_random_walk: y.accelerometer_random_walk,
    })
}

/// Read a camera `sensor.yaml` into (model, T_BS, resolution, rate).
pub fn read_camera_sensor(path: &Path) -> Result<CameraSensor, InputError> {
    parse_camera_sensor(path, &super::tokens::read_text(path)?)
}

/// A camera `sensor.yaml`: model, body ← camera transform, resolution \[px\], rate \[Hz\].
pub type CameraSensor = (CameraModel, Option<Isometry3<f64>>, Option<[u32; 2]>, Option<f64>);

/// Parse the text of a camera `sensor.yaml` (`path` names it in errors).
pub fn parse_camera_sensor(path: &Path, text: &str) -> Result<CameraSensor, InputError> {
    let y: CameraYaml = parse_yaml(path, text)?;
    if let Some(m) = y.camera_model.as_deref() {
        if m != "pinhole" {
            return Err(InputError::file(path, format!("camera_model '{m}' is not supported (only pinhole)")));
        }
    }
    let k = y.intrinsics.ok_or_else(|| InputError::file(path, "missing intrinsics [fu, fv, cu, cv]"))?;
    if k.len() != 4 || k.iter().any(|v| !v.is_finite()) || k[0] <= 0.0 || k[1] <= 0.0 {
        return Err(InputError::file(
            path,
            format!("intrinsics must be 4 finite numbers with positive focal lengths, found {k:?}"),
        ));
    }
    let d = y.distortion_coefficients.unwrap_or_default();
    let need = |n: usize, model: &str| -> Result<(), InputError> {
        if d.len() != n || d.iter().any(|v| !v.is_finite()) {
            return Err(InputError::file(
                path,
                format!("{model} distortion needs {n} finite coefficients, found {d:?}"),
            ));
        }
        Ok(())
    };
    let distortion = match y.distortion_model.as_deref() {
        None | Some("none") => Distortion::None,
        Some("radial-tangential") | Some("radtan") | Some("plumb_bob") => {
            need(4, "radial-tangential")?;
            Distortion::RadTan { k1: d[0], k2: d[1], p1: d[2], p2: d[3] }
        }
        Some("equidistant") | Some("fisheye") => {
            need(4, "equidistant")?;
            Distortion::Equidistant { k1: d[0], k2: d[1], k3: d[2], k4: d[3] }
        }
        Some(other) => {
            return Err(InputError::file(path, format!("distortion_model '{other}' is not supported"))
                .with_hint("use radial-tangential or equidistant"))
        }
    };
    if let Some(r) = y.resolution.filter(|r| r[0] == 0 || r[1] == 0) {
        return Err(InputError::file(
            path,
            format!("resolution must be [width, height] in pixels, both > 0, found {r:?}"),
        ));
    }
    if let Some(r) = y.rate_hz.filter(|r| !(r.is_finite() && *r > 0.0)) {
        return Err(InputError::file(path, format!("rate_hz must be a positive number of Hz, found {r}")));
    }
    let t_bs = y.T_BS.as_ref().map(|m| m.to_transform(path, "T_BS")).transpose()?;
    let model = CameraModel { fx: k[0], fy: k[1], cx: k[2], cy: k[3], distortion };
    Ok((model, t_bs, y.resolution, y.rate_hz))
}

/// Read a camera folder's `data.csv` (`t[ns], filename`).
pub fn read_frames(cam_dir: &Path) -> Result<Vec<(i64, PathBuf)>, InputError> {
    let csv = cam_dir.join("data.csv");
    let text = super::tokens::read_text(&csv)?;
    let mut frames = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let l = line.trim();
        if l.is_empty() || l.starts_with('#') {
            continue;
        }
        let mut it = l.splitn(2, ',');
        let t = it.next().unwrap_or("").trim();
        let name = it.next().map(str::trim).unwrap_or("");
        let t: i64 =
            t.parse().map_err(|_| InputError::at(&csv, i + 1, format!("timestamp '{t}' is not an integer [ns]")))?;
        if name.is_empty() {
            return Err(InputError::at(&csv, i + 1, "missing image file name"));
        }
        if let Some((tp, _)) = frames.last() {
            if t <= *tp {
                return Err(InputError::at(&csv, i + 1, "frame timestamps must increase strictly"));
            }
        }
        frames.push((t, cam_dir.join("data").join(name)));
    }
    Ok(frames)
}

impl AslDataset {
    /// The index of the camera folder `name` (e.g. `cam0`); the error lists the cameras there are.
    pub fn camera_index(&self, name: &str) -> Result<usize, InputError> {
        self.cameras.iter().position(|c| c.name == name).ok_or_else(|| {
            let names: Vec<&str> = self.cameras.iter().map(|c| c.name.as_str()).collect();
            InputError::file(&self.root, format!("no camera '{name}' (found: {})", names.join(", ")))
        })
    }
}

/// Load an ASL dataset: IMU (validated), sensors, cameras and ground truth.
pub fn read_asl(path: &Path, fmt: &ImuTextFormat) -> Result<AslDataset, InputError> {
    let root = resolve_mav0(path)?;
    let mut warnings = Vec::new();
    let imu_yaml = root.join("imu0").join("sensor.yaml");
    let imu_sensor = if imu_yaml.is_file() {
        Some(read_imu_sensor(&imu_yaml)?)
    } else {
        warnings.push(format!("{}: absent; rate and noise figures unknown", imu_yaml.display()));
        None
    };
    let mut fmt = fmt.clone();
    if fmt.validate.nominal_rate.is_none() {
        fmt.validate.nominal_rate = imu_sensor.as_ref().map(|s| s.rate_hz);
    }
    let imu = read_imu_text(&root.join("imu0").join("data.csv"), &fmt)?;
    let mut cameras = Vec::new();
    for k in 0..8 {
        let dir = root.join(format!("cam{k}"));
        if !dir.is_dir() {
            continue;
        }
        let yaml = dir.join("sensor.yaml");
        let (model, t_bs, resolution, rate_hz) = if yaml.is_file() {
            let (m, t, r, h) = read_camera_sensor(&yaml)?;
            (Some(m), t, r, h)
        } else {
            warnings.push(format!("{}: absent; intrinsics unknown", yaml.display()));
            (None, None, None, None)
        };
        let frames = if dir.join("data.csv").is_file() { read_frames(&dir)? } else { Vec::new() };
        cameras.push(Camera { name: format!("cam{k}"), model, t_bs, resolution, rate_hz, frames });
    }
    let mut groundtruth = None;
    for gt in ["state_groundtruth_estimate0", "gt0", "mocap0"] {
        let f = root.join(gt).join("data.csv");
        if f.is_file() {
            groundtruth = Some(read_asl_groundtruth(&f)?);
            break;
        }
    }
    Ok(AslDataset { root, imu, imu_sensor, cameras, groundtruth, warnings })
}

/// One feature observation of a tracks file: time \[ns\], track id, pixel `[u, v]`.
pub type TrackObservation = (i64, u64, [f64; 2]);

/// Read only the feature-track file `camN/tracks.csv` written by the simulator
/// or the frontend: `t[ns], track_id, u[px], v[px]` per observation.
pub fn read_tracks(path: &Path) -> Result<Vec<TrackObservation>, InputError> {
    read_tracks_with_lines(path).map(|(obs, _)| obs)
}

/// As [`read_tracks`], with each observation's line number in the file (for
/// errors found later, such as a stereo match without its cam0 frame).
pub fn read_tracks_with_lines(path: &Path) -> Result<(Vec<TrackObservation>, Vec<usize>), InputError> {
    let spec = TableSpec {
        time: Some((0, TimeUnit::Ns)),
        values: vec![1, 2, 3],
        names: vec!["track id".into(), "u".into(), "v".into()],
        ..TableSpec::default()
    };
    let t = read_table(path, &spec)?;
    let mut out = Vec::with_capacity(t.t_ns.len());
    for i in 0..t.t_ns.len() {
        let id = t.columns[0][i];
        if id < 0.0 || id.fract() != 0.0 {
            return Err(InputError::at(path, t.lines.line(i), format!("track id {id} is not a non-negative integer")));
        }
        if i > 0 && t.t_ns[i] < t.t_ns[i - 1] {
            return Err(InputError::at(path, t.lines.line(i), "observations must be in time order"));
        }
        out.push((t.t_ns[i], id as u64, [t.columns[1][i], t.columns[2][i]]));
    }
    let lines = (0..out.len()).map(|i| t.lines.line(i)).collect();
    Ok((out, lines))
}
