//! A camera–IMU rig waved in front of a calibration target, with known truth:
//! the recording `tumble calibrate-rig` calibrates ([`crate::rig`]).
//!
//! World `W` z up; the body starts at the origin looking along +x (the
//! camera's optical axis is body x for the default [`CameraSettings`]); the
//! target hangs on a wall `distance_m` ahead, its x axis along world −y and its
//! y axis along world +z, centred on the optical axis: upright in the image
//! and seen from its printed side, as a real one is (from its x axis to its y
//! axis is a counter-clockwise turn on the screen, as in imu_april's corners).
//!
//! ```
//! use tumble::sim::target::{simulate_rig, RigSimSettings};
//! let sim = simulate_rig(&RigSimSettings { duration_s: 15.0, ..RigSimSettings::default() }, 1);
//! assert!(sim.input.cameras[0].views.iter().filter(|v| v.corners.len() > 50).count() > 200);
//! ```

use super::camera::CameraSettings;
use super::motion::{Loop, Motion};
use super::{simulate_imu, Effects, ImuModel, TriadModel};
use crate::model::target::{CameraCorners, Corner, RigInput, Target, View};
use crate::model::ImuData;
use nalgebra::{Isometry3, Matrix3, Vector3};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use tumble_factors::camera::CameraModel;
use tumble_factors::imu_preint::PreintegrationParams;

/// The simulated rig IMU's sample rate \[Hz\].
pub(crate) const RIG_IMU_RATE_HZ: f64 = 200.0;

/// Settings of a simulated rig calibration recording.
#[derive(Debug, Clone)]
pub struct RigSimSettings {
    /// Length \[s\] (3 s still at both ends).
    pub duration_s: f64,
    /// The camera (intrinsics, distortion, `T_BC`, time offset, pixel noise, rate).
    pub camera: CameraSettings,
    /// The target.
    pub target: Target,
    /// Distance from the start position to the target \[m\].
    pub distance_m: f64,
    /// IMU noise and bias random walk (continuous time, as the estimator is told).
    pub noise: PreintegrationParams,
    /// Turn-on biases `[b_a (m/s²), b_g (rad/s)]`.
    pub bias: [[f64; 3]; 2],
    /// Gravity \[m/s²\].
    pub gravity: f64,
    /// Amplitudes of the wave's position \[m\] and rotation vector \[rad\] per
    /// body axis ([`Loop::target_wave_with`]).
    pub amplitudes: [[f64; 3]; 2],
}

impl Default for RigSimSettings {
    /// EuRoC's cam0 and ADIS16448 noise, 0.3 px corners, a 3 ms time offset,
    /// EuRoC's AprilGrid 1 m ahead, 40 s.
    fn default() -> Self {
        let camera = CameraSettings { pixel_noise_px: 0.3, time_offset_s: 3e-3, ..CameraSettings::default() };
        RigSimSettings {
            duration_s: 40.0,
            camera,
            target: Target::AprilGrid { cols: 6, rows: 6, size: 0.088, spacing: 0.3 },
            distance_m: 1.0,
            noise: PreintegrationParams::default(),
            bias: [[0.05, -0.08, 0.03], [0.004, -0.003, 0.002]],
            gravity: 9.81,
            amplitudes: [[0.3, 0.3, 0.2], [0.8, 0.8, 0.8]],
        }
    }
}

/// The truth behind a simulated rig recording.
#[derive(Debug, Clone)]
pub struct RigTruth {
    /// The camera model.
    pub model: CameraModel,
    /// Camera to body.
    pub t_bc: Isometry3<f64>,
    /// Kalibr's `timeshift_cam_imu` \[s\].
    pub time_offset_s: f64,
    /// The second camera's pose in the body (camera to body; same model and
    /// time offset as the first), when the camera settings give a stereo baseline.
    pub second_t_bc: Option<Isometry3<f64>>,
}

/// A simulated recording and its truth.
#[derive(Debug, Clone)]
pub struct SimulatedRig {
    /// What `calibrate_rig` reads.
    pub input: RigInput,
    /// The truth.
    pub truth: RigTruth,
}

/// Simulate the rig: IMU at 200 Hz with white noise and bias random walks on
/// the given turn-on biases, and the target's corners at the camera's rate
/// (in both cameras when `camera.stereo_baseline_m` > 0),
/// projected at each image's exposure time (`stamp + time offset`) with
/// Gaussian pixel noise; corners outside the image are not seen.
pub fn simulate_rig(s: &RigSimSettings, seed: u64) -> SimulatedRig {
    let motion = rig_motion(s, seed);
    let p = &s.noise;
    let triad = |noise: [f64; 3], walk: [f64; 3], bias: [f64; 3]| TriadModel {
        noise_density: noise,
        random_walk: walk,
        bias,
        ..TriadModel::default()
    };
    let model = ImuModel {
        rate_hz: RIG_IMU_RATE_HZ,
        gyro: triad(p.gyro_noise().into(), p.gyro_walk().into(), s.bias[1]),
        accel: triad(p.accel_noise().into(), p.accel_walk().into(), s.bias[0]),
        effects: Effects { bias: true, random_walk: true, white_noise: true, ..Effects::none() },
        ..ImuModel::bmi055()
    };
    let imu = simulate_imu(&motion, &model, s.gravity, seed, 1000);
    let cam = &s.camera;
    let camera = cam.model();
    let t_bc = cam.body_from_camera();
    let (r_wt, t_wt) = target_in_world(s);
    let n = s.target.corner_count();
    let noise = Normal::new(0.0, cam.pixel_noise_px.max(1e-300)).expect("finite σ");
    let [w, h] = cam.resolution.map(f64::from);
    let frames = (s.duration_s * cam.rate_hz).floor() as i64;
    let second_t_bc = (cam.stereo_baseline_m > 0.0).then(|| cam.body_from_second_camera());
    let mut cameras = Vec::new();
    for (i, t_bc) in std::iter::once(t_bc).chain(second_t_bc).enumerate() {
        // The first camera's noise as before stereo existed; the second's its own.
        let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x636f726e ^ ((i as u64) << 40));
        let mut views = Vec::new();
        for k in 0..frames {
            let stamp = k as f64 / cam.rate_hz;
            let exposure = stamp + cam.time_offset_s;
            if exposure < 0.0 || exposure > s.duration_s {
                continue;
            }
            let st = motion.at(exposure);
            let mut corners = Vec::new();
            for id in 0..n {
                let Some(c) = s.target.corner(id) else { continue };
                let pw = r_wt * Vector3::from(c) + t_wt;
                let pb = st.rotation.transpose() * (pw - st.position);
                let pc = t_bc.inverse_transform_point(&pb.into());
                let Some(uv) = camera.project(&[pc.x, pc.y, pc.z]) else { continue };
                let uv = [uv[0] + noise.sample(&mut rng), uv[1] + noise.sample(&mut rng)];
                if pc.z > 0.1 && uv[0] >= 0.0 && uv[0] < w && uv[1] >= 0.0 && uv[1] < h {
                    corners.push(Corner { id, target: c, uv });
                }
            }
            views.push(View { t_ns: (stamp * 1e9).round() as i64, corners });
        }
        cameras.push(CameraCorners {
            name: format!("cam{i}"),
            path: format!("<simulation>/cam{i}/corners.csv").into(),
            views,
            resolution: Some(cam.resolution),
            detection: None,
        });
    }
    let input = RigInput {
        imu: ImuData {
            t: imu.t.clone(),
            gyro: imu.gyro.iter().map(|g| Vector3::from(*g)).collect(),
            acc: imu.accel.iter().map(|a| Vector3::from(*a)).collect(),
        },
        imu_t0_ns: 0,
        noise: s.noise,
        noise_source: "the simulation's".into(),
        cameras,
        target: s.target.clone(),
        sources: Vec::new(),
    };
    SimulatedRig { input, truth: RigTruth { model: camera, t_bc, time_offset_s: cam.time_offset_s, second_t_bc } }
}

/// The body's motion of the recording `seed` ([`Loop::target_wave_with`] with
/// the settings' amplitudes): what [`simulate_rig`] samples, for rendering.
pub fn rig_motion(s: &RigSimSettings, seed: u64) -> Loop {
    let [pa, ra] = s.amplitudes.map(Vector3::from);
    Loop::target_wave_with(s.duration_s, seed, pa, ra)
}

/// The target's pose in the world: `p_W = R p_T + t` (see the module docs:
/// its x along world −y, its y along world +z, its z towards the camera,
/// its corners centred on the optical axis `distance_m` ahead).
pub fn target_in_world(s: &RigSimSettings) -> (Matrix3<f64>, Vector3<f64>) {
    let r_wt = Matrix3::new(0.0, 0.0, -1.0, -1.0, 0.0, 0.0, 0.0, 1.0, 0.0);
    let n = s.target.corner_count();
    let centre =
        (0..n).filter_map(|i| s.target.corner(i)).fold(Vector3::zeros(), |a, c| a + Vector3::from(c)) / n as f64;
    (r_wt, Vector3::new(s.distance_m, 0.0, 0.0) - r_wt * centre)
}
