//! Camera simulation: landmarks on the walls of a room, feature tracks with
//! pixel noise, track loss and outliers, seen through a pinhole camera with
//! distortion mounted on the body at `T_BC`, with a time offset.
//!
//! Time offset convention (Kalibr, VINS-Mono): an image stamped `t` was taken
//! at IMU time `t + time_offset_s`.

use super::corridor::Corridor;
use super::motion::Motion;
use super::SimError;
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use serde::{Deserialize, Serialize};
use tumble_factors::camera::{CameraModel, Distortion};

/// Distortion model names used in configs and `sensor.yaml`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum DistortionKind {
    /// `radial-tangential` (k1, k2, p1, p2).
    RadialTangential,
    /// `equidistant` (k1, k2, k3, k4).
    Equidistant,
}

/// Camera settings of a simulation.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CameraSettings {
    /// Frame rate \[Hz\].
    pub rate_hz: f64,
    /// Image size `[width, height]` \[px\].
    pub resolution: [u32; 2],
    /// `[fu, fv, cu, cv]` \[px\].
    pub intrinsics: [f64; 4],
    /// Distortion model.
    pub distortion_model: DistortionKind,
    /// Its four coefficients.
    pub distortion_coefficients: [f64; 4],
    /// Camera position in the body frame \[m\].
    pub body_t_camera: [f64; 3],
    /// Camera orientation in the body frame as a quaternion `[w, x, y, z]`.
    pub body_q_camera: [f64; 4],
    /// Image time offset \[s\] (image stamped t was taken at IMU time t + offset).
    pub time_offset_s: f64,
    /// Pixel noise standard deviation \[px\].
    pub pixel_noise_px: f64,
    /// Probability per frame that a tracked feature is lost.
    pub track_loss: f64,
    /// Fraction of observations replaced by a random pixel.
    pub outlier_fraction: f64,
    /// Most features reported per frame.
    pub max_features: usize,
    /// Number of landmarks on the room's walls, floor and ceiling.
    pub landmarks: usize,
    /// Half extents of the room around the motion's centre \[m\].
    pub room_half_extent: [f64; 3],
    /// Baseline of a second camera \[m\] (0: none): the same model, placed
    /// this far along the first camera's x axis (to its right, as EuRoC's
    /// cam1 at 0.11 m), seeing the first camera's features at the same times
    /// with its own pixel noise (stereo matches under the same track ids).
    pub stereo_baseline_m: f64,
}

impl Default for CameraSettings {
    /// EuRoC's cam0 (MT9M034): 752×480 at 20 Hz, looking forward (z_C along x_B).
    fn default() -> Self {
        // Camera z forward = body x, camera x right = body −y, camera y down = body −z.
        let r = nalgebra::Matrix3::new(0.0, 0.0, 1.0, -1.0, 0.0, 0.0, 0.0, -1.0, 0.0);
        let q = UnitQuaternion::from_matrix(&r);
        CameraSettings {
            rate_hz: 20.0,
            resolution: [752, 480],
            intrinsics: [458.654, 457.296, 367.215, 248.375],
            distortion_model: DistortionKind::RadialTangential,
            distortion_coefficients: [-0.28340811, 0.07395907, 0.00019359, 1.76187114e-05],
            body_t_camera: [0.05, -0.02, 0.01],
            body_q_camera: [q.w, q.i, q.j, q.k],
            time_offset_s: 0.0,
            pixel_noise_px: 0.5,
            track_loss: 0.02,
            outlier_fraction: 0.01,
            max_features: 150,
            landmarks: 2000,
            room_half_extent: [3.0, 3.0, 1.5],
            stereo_baseline_m: 0.0,
        }
    }
}

impl CameraSettings {
    /// The camera model.
    pub fn model(&self) -> CameraModel {
        let [k1, k2, a, b] = self.distortion_coefficients;
        let distortion = match self.distortion_model {
            DistortionKind::RadialTangential => Distortion::RadTan { k1, k2, p1: a, p2: b },
            DistortionKind::Equidistant => Distortion::Equidistant { k1, k2, k3: a, k4: b },
        };
        let [fx, fy, cx, cy] = self.intrinsics;
        CameraModel { fx, fy, cx, cy, distortion }
    }
    /// Body ← camera transform.
    pub fn body_from_camera(&self) -> Isometry3<f64> {
        let [w, x, y, z] = self.body_q_camera;
        let q = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(w, x, y, z));
        Isometry3::from_parts(Translation3::from(Vector3::from(self.body_t_camera)), q)
    }
    /// Body ← second camera transform (see [`CameraSettings::stereo_baseline_m`]).
    pub fn body_from_second_camera(&self) -> Isometry3<f64> {
        self.body_from_camera() * Translation3::new(self.stereo_baseline_m, 0.0, 0.0)
    }
    /// Check for values that cannot be simulated.
    pub fn check(&self) -> Result<(), SimError> {
        if !(self.rate_hz > 0.0 && self.rate_hz.is_finite()) {
            return Err("camera.rate_hz must be positive".into());
        }
        if self.resolution[0] == 0 || self.resolution[1] == 0 || self.intrinsics[0] <= 0.0 || self.intrinsics[1] <= 0.0
        {
            return Err("camera resolution and focal lengths must be positive".into());
        }
        let qn = self.body_q_camera.iter().map(|x| x * x).sum::<f64>().sqrt();
        if (qn - 1.0).abs() > 1e-3 {
            return Err(format!("camera.body_q_camera has norm {qn:.4}, not 1").into());
        }
        for (p, what) in [(self.track_loss, "track_loss"), (self.outlier_fraction, "outlier_fraction")] {
            if !(0.0..=1.0).contains(&p) {
                return Err(format!("camera.{what} must be in [0, 1], found {p}").into());
            }
        }
        if !(self.stereo_baseline_m >= 0.0 && self.stereo_baseline_m.is_finite()) {
            return Err(format!("camera.stereo_baseline_m must be ≥ 0 m, found {}", self.stereo_baseline_m).into());
        }
        if self.pixel_noise_px < 0.0 || self.room_half_extent.iter().any(|x| *x <= 0.0) {
            return Err("camera.pixel_noise_px must be ≥ 0 and the room extents > 0".into());
        }
        Ok(())
    }
}

/// One feature observation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Observation {
    /// Frame stamp \[s\].
    pub t: f64,
    /// Track id (a landmark gets a new id each time its track is re-acquired).
    pub track: u64,
    /// Landmark index in the truth list.
    pub landmark: usize,
    /// Measured pixel `[u, v]` \[px\].
    pub uv: [f64; 2],
    /// Where the landmark projects, without noise (an outlier's too) \[px\].
    pub true_uv: [f64; 2],
    /// True when this observation is an injected outlier.
    pub outlier: bool,
}

/// Simulated tracks with the landmarks behind them.
#[derive(Debug, Clone, Default)]
pub struct SimulatedTracks {
    /// Frame stamps \[s\].
    pub frames: Vec<f64>,
    /// Landmarks in the world frame \[m\].
    pub landmarks: Vec<[f64; 3]>,
    /// Observations in time order.
    pub observations: Vec<Observation>,
    /// The second camera's observations of the same features at the same
    /// times, in time order (empty without [`CameraSettings::stereo_baseline_m`]).
    pub stereo: Vec<Observation>,
}

/// Landmarks uniformly on the six faces of a box around `centre`.
fn room_landmarks(n: usize, centre: Vector3<f64>, half: [f64; 3], rng: &mut ChaCha8Rng) -> Vec<[f64; 3]> {
    (0..n)
        .map(|_| {
            let face = rng.random_range(0..6);
            let axis = face / 2;
            let sign = if face % 2 == 0 { -1.0 } else { 1.0 };
            let mut p = [0.0; 3];
            for (k, pk) in p.iter_mut().enumerate() {
                *pk = if k == axis { sign * half[k] } else { rng.random_range(-half[k]..half[k]) };
                *pk += centre[k];
            }
            p
        })
        .collect()
}

/// Where the landmarks of a simulation are.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Scene {
    /// [`CameraSettings::landmarks`] on the faces of a box of half extents
    /// [`CameraSettings::room_half_extent`] around this world point \[m\].
    Room(Vector3<f64>),
    /// The walls, floor and ceiling of a corridor, as densely covered as the
    /// room's faces would be; its inner block hides what lies behind it.
    Corridor(Corridor),
}

/// Room margin around a replayed path \[m\]: horizontally, and above and
/// below (the walls stay a few metres from the camera wherever it flies).
pub const ROOM_MARGIN_M: [f64; 3] = [2.0, 2.0, 1.0];

/// A room that holds the whole of `path` (world positions \[m\]): the box
/// of `s`' half extents grown to the path's bounding box plus
/// [`ROOM_MARGIN_M`], with as many landmarks as keep `s`' density on its
/// faces. Returns the scene and the settings to simulate it with. A room of
/// fixed size around the path's mean lost half of a 19 × 17 m Machine Hall
/// path: the camera flew outside it, blind.
pub fn room_around(path: &[Vector3<f64>], s: &CameraSettings) -> (Scene, CameraSettings) {
    let (mut lo, mut hi) = (Vector3::repeat(f64::INFINITY), Vector3::repeat(f64::NEG_INFINITY));
    for p in path.iter().filter(|p| p.iter().all(|x| x.is_finite())) {
        lo = lo.inf(p);
        hi = hi.sup(p);
    }
    if !lo.iter().all(|x| x.is_finite()) {
        return (Scene::Room(Vector3::zeros()), s.clone());
    }
    let centre = (lo + hi) * 0.5;
    let mut out = s.clone();
    for k in 0..3 {
        out.room_half_extent[k] = s.room_half_extent[k].max((hi[k] - lo[k]) * 0.5 + ROOM_MARGIN_M[k]);
    }
    let area = |h: &[f64; 3]| 8.0 * (h[0] * h[1] + h[1] * h[2] + h[0] * h[2]);
    out.landmarks = (s.landmarks as f64 * area(&out.room_half_extent) / area(&s.room_half_extent)).round() as usize;
    (Scene::Room(centre), out)
}

/// Simulate feature tracks along `motion` in `scene`.
pub fn simulate_tracks(motion: &dyn Motion, s: &CameraSettings, scene: &Scene, seed: u64) -> SimulatedTracks {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    rng.set_stream(200);
    let landmarks = match scene {
        Scene::Room(centre) => room_landmarks(s.landmarks, *centre, s.room_half_extent, &mut rng),
        Scene::Corridor(c) => {
            let [x, y, z] = s.room_half_extent;
            let room_surface = 8.0 * (x * y + y * z + x * z);
            c.landmarks(s.landmarks as f64 / room_surface, &mut rng)
        }
    };
    let in_sight = |eye: &Vector3<f64>, l: &[f64; 3]| match scene {
        Scene::Room(_) => true,
        Scene::Corridor(c) => c.sees(eye, l),
    };
    let model = s.model();
    let b_t_c = s.body_from_camera();
    // The second camera draws its noise from its own stream: a mono
    // simulation's tracks are the same with or without it.
    let mut stereo_rng = ChaCha8Rng::seed_from_u64(seed);
    stereo_rng.set_stream(201);
    // Second camera ← first camera.
    let c1_t_c = Isometry3::from_parts(Translation3::new(-s.stereo_baseline_m, 0.0, 0.0), UnitQuaternion::identity());
    let mut stereo = Vec::new();
    let (w, h) = (s.resolution[0] as f64, s.resolution[1] as f64);
    let mut frames = Vec::new();
    let mut observations = Vec::new();
    let mut track_of: Vec<Option<u64>> = vec![None; landmarks.len()];
    let mut next_track = 0u64;
    let dt = 1.0 / s.rate_hz;
    let mut t = 0.0;
    while t <= motion.duration() {
        let k = motion.at((t + s.time_offset_s).clamp(0.0, motion.duration()));
        let rot = UnitQuaternion::from_matrix(&k.rotation);
        let w_t_b = Isometry3::from_parts(Translation3::from(k.position), rot);
        let w_t_c = w_t_b * b_t_c;
        let eye = w_t_c.translation.vector;
        let c_t_w = w_t_c.inverse();
        // The pixel where a point in a camera's frame is seen, if it is.
        let pixel = |pc: Point3<f64>| {
            let uv = if pc.z < 0.2 { None } else { model.project(&[pc.x, pc.y, pc.z]) }?;
            (uv[0] >= 0.0 && uv[0] < w && uv[1] >= 0.0 && uv[1] < h).then_some(uv)
        };
        let visible: Vec<(usize, [f64; 2])> = landmarks
            .iter()
            .enumerate()
            .filter_map(|(j, l)| pixel(c_t_w * Point3::from(*l)).filter(|_| in_sight(&eye, l)).map(|uv| (j, uv)))
            .collect();
        // Tracked features first, then new ones in random order, up to the cap.
        let (mut kept, mut fresh): (Vec<_>, Vec<_>) = visible.into_iter().partition(|(j, _)| track_of[*j].is_some());
        for i in (1..fresh.len()).rev() {
            let r = rng.random_range(0..=i);
            fresh.swap(i, r);
        }
        kept.extend(fresh);
        kept.truncate(s.max_features);
        let mut seen = vec![false; landmarks.len()];
        for (j, uv) in kept {
            seen[j] = true;
            let lost = rng.random_bool(s.track_loss);
            let track = match track_of[j] {
                Some(id) if !lost => id,
                _ => {
                    next_track += 1;
                    next_track - 1
                }
            };
            track_of[j] = Some(track);
            let outlier = rng.random_bool(s.outlier_fraction);
            let true_uv = uv;
            let uv = if outlier {
                [rng.random_range(0.0..w), rng.random_range(0.0..h)]
            } else {
                let nu: f64 = StandardNormal.sample(&mut rng);
                let nv: f64 = StandardNormal.sample(&mut rng);
                [uv[0] + s.pixel_noise_px * nu, uv[1] + s.pixel_noise_px * nv]
            };
            observations.push(Observation { t, track, landmark: j, uv, true_uv, outlier });
            if s.stereo_baseline_m > 0.0 {
                if let Some(uv1) = pixel(c1_t_c * c_t_w * Point3::from(landmarks[j])) {
                    let nu: f64 = StandardNormal.sample(&mut stereo_rng);
                    let nv: f64 = StandardNormal.sample(&mut stereo_rng);
                    let uv = [uv1[0] + s.pixel_noise_px * nu, uv1[1] + s.pixel_noise_px * nv];
                    stereo.push(Observation { t, track, landmark: j, uv, true_uv: uv1, outlier: false });
                }
            }
        }
        for (j, tr) in track_of.iter_mut().enumerate() {
            if !seen[j] {
                *tr = None;
            }
        }
        frames.push(t);
        t = frames.len() as f64 * dt;
    }
    SimulatedTracks { frames, landmarks, observations, stereo }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_room_around_a_path_holds_it_at_the_same_density() {
        let s = CameraSettings::default();
        let path = [Vector3::new(-8.0, 1.0, 0.2), Vector3::new(11.0, 18.0, 3.0), Vector3::new(0.0, 5.0, 1.0)];
        let (scene, big) = room_around(&path, &s);
        let Scene::Room(c) = scene else { panic!("a room") };
        for p in &path {
            for k in 0..3 {
                assert!((p[k] - c[k]).abs() + ROOM_MARGIN_M[k] <= big.room_half_extent[k] + 1e-9);
            }
        }
        let density = |s: &CameraSettings| {
            let h = s.room_half_extent;
            s.landmarks as f64 / (8.0 * (h[0] * h[1] + h[1] * h[2] + h[0] * h[2]))
        };
        assert!((density(&big) / density(&s) - 1.0).abs() < 1e-3);
        // A path smaller than the default room keeps the default room.
        let (_, small) = room_around(&[Vector3::zeros(), Vector3::new(1.0, 1.0, 0.5)], &s);
        assert_eq!((small.room_half_extent, small.landmarks), (s.room_half_extent, s.landmarks));
    }
}
