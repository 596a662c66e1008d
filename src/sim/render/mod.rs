//! Camera images with known truth: the simulated camera's frames rendered
//! (pure Rust, `rayon` across image rows) from a textured scene through the
//! same lens model the estimators use.
//!
//! - **Scene** ([`scene`]): textured rectangles and elliptical walls — a
//!   room's or hall's six faces, a ring corridor's walls, floor and ceiling —
//!   with "dead leaves" textures (sharp edges and corners at every scale, the
//!   power spectrum of natural images).
//! - **Anti-aliasing that moves no edge** ([`texture`]): each pixel shows its
//!   surface's mean over the pixel's footprint, read from a mip pyramid of box
//!   filters that keeps the texel-centre convention on every level, so
//!   rendered edges and corners stay where they project (tests measure it).
//!   A printed target's pattern is averaged exactly over a 2 px square of
//!   the image, whatever the lens' magnification does across a corner
//!   ([`frame`]; the square's preimage through the projective map its
//!   corners' rays give).
//! - **Lens** ([`lens`]): every pixel's ray from `CameraModel::unproject`,
//!   kept only where it projects back to the pixel within 10⁻⁶ px.
//! - **Exposure** ([`frame`]): motion blur from sub-frame poses (as many as keep
//!   the image from moving more than [`ImageSettings::max_blur_step_px`]
//!   between two, counted per tile of pixels from the motion of what the
//!   tile shows), an optional rolling shutter, the frame's gain, vignetting,
//!   shot and read noise, 8-bit output.
//!
//! Times: an image stamped `t` is centred at IMU time `t + time_offset_s`
//! (the simulator's convention); with a rolling shutter that is the middle
//! row's time, row `j` read `(j − (height − 1)/2)·line_delay_s` later.

pub mod frame;
pub mod lens;
mod quad;
pub mod scene;
pub mod texture;

use super::motion::Motion;
use nalgebra::{Isometry3, Rotation3, Translation3, UnitQuaternion};
use serde::{Deserialize, Serialize};

/// How frames are exposed and digitized (YAML key `images` of the
/// simulation's config; every key optional).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ImageSettings {
    /// Exposure time \[s\], centred on the frame's time (motion blur).
    pub exposure_s: f64,
    /// Largest image motion between two sub-exposure samples \[px\]: the
    /// exposure is sampled this finely (16 samples at most).
    pub max_blur_step_px: f64,
    /// Rolling shutter's delay between consecutive rows \[s\] (0: global shutter).
    pub line_delay_s: f64,
    /// Read noise \[grey levels of 255\], σ.
    pub read_noise_dn: f64,
    /// Electrons at full scale (shot noise σ = √(signal·full well)/full well;
    /// 0: no shot noise).
    pub full_well_electrons: f64,
    /// Brightness lost in the image's corners to vignetting (fraction; falls
    /// off with the squared distance from the centre).
    pub vignetting: f64,
    /// σ of the frame-to-frame gain change (relative; auto-exposure's flicker).
    pub gain_jitter: f64,
}

impl Default for ImageSettings {
    /// A global-shutter machine-vision camera as EuRoC's MT9V034 in a lit
    /// room: 3 ms exposure, 2 grey levels of read noise, 10 000 electrons,
    /// 25 % vignetting, 2 % gain flicker.
    fn default() -> Self {
        ImageSettings {
            exposure_s: 3e-3,
            max_blur_step_px: 1.0,
            line_delay_s: 0.0,
            read_noise_dn: 2.0,
            full_well_electrons: 1e4,
            vignetting: 0.25,
            gain_jitter: 0.02,
        }
    }
}

/// Most sub-exposure samples of one frame.
const MAX_BLUR_SAMPLES: usize = 16;

/// Spacing of the rays whose hits bound a frame's nearest surface \[px\]
/// ([`nearest_surface_m`]).
const DEPTH_PROBE_STEP_PX: usize = 16;

impl ImageSettings {
    /// Check for values that cannot be rendered.
    pub fn check(&self) -> Result<(), String> {
        let finite_nonneg = |x: f64| x.is_finite() && x >= 0.0;
        if !(finite_nonneg(self.exposure_s) && self.exposure_s < 1.0) {
            return Err(format!("images.exposure_s must be in [0, 1) s, found {}", self.exposure_s));
        }
        if !(self.max_blur_step_px.is_finite() && self.max_blur_step_px > 0.0) {
            return Err(format!("images.max_blur_step_px must be positive, found {}", self.max_blur_step_px));
        }
        for (name, x) in [
            ("line_delay_s", self.line_delay_s),
            ("read_noise_dn", self.read_noise_dn),
            ("full_well_electrons", self.full_well_electrons),
            ("gain_jitter", self.gain_jitter),
        ] {
            if !finite_nonneg(x) {
                return Err(format!("images.{name} must be finite and ≥ 0, found {x}"));
            }
        }
        if !(0.0..1.0).contains(&self.vignetting) {
            return Err(format!("images.vignetting must be in [0, 1), found {}", self.vignetting));
        }
        Ok(())
    }
}

/// World ← camera at IMU time `t` \[s\] (clamped to the motion).
pub fn camera_pose(motion: &dyn Motion, body_from_camera: &Isometry3<f64>, t: f64) -> Isometry3<f64> {
    let k = motion.at(t.clamp(0.0, motion.duration()));
    let rot = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(k.rotation));
    Isometry3::from_parts(Translation3::from(k.position), rot) * body_from_camera
}

/// The most sub-exposure samples a pixel of the frame at IMU time `t` may
/// need (each tile then takes what its own motion needs, see
/// [`frame::radiance_image`]): enough that the image moves at most
/// [`ImageSettings::max_blur_step_px`] between two. A ray
/// turns at most at the rotation rate plus the speed over the distance of
/// the point it shows, so the motion is bounded by the rates and the nearest
/// surface in view, `nearest_m`.
fn blur_samples(motion: &dyn Motion, t: f64, focal_px: f64, nearest_m: f64, s: &ImageSettings) -> usize {
    if s.exposure_s == 0.0 {
        return 1;
    }
    let k = motion.at(t.clamp(0.0, motion.duration()));
    let rate = k.omega.norm() + k.velocity.norm() / nearest_m;
    let moved_px = rate * s.exposure_s * focal_px;
    ((moved_px / s.max_blur_step_px).ceil() as usize).clamp(1, MAX_BLUR_SAMPLES)
}

/// The nearest surface the camera at `world_from_camera` shows \[m\]: the
/// least hit distance over a grid of its rays [`DEPTH_PROBE_STEP_PX`] apart
/// (the image's last row and column included; a surface's distance varies
/// smoothly between them), infinite where they hit nothing.
fn nearest_surface_m(scene: &scene::RenderScene, lens: &lens::RayTable, world_from_camera: &Isometry3<f64>) -> f64 {
    let seen = scene.seen_from(world_from_camera);
    let probes = |n: usize| (0..n).step_by(DEPTH_PROBE_STEP_PX).chain(std::iter::once(n.saturating_sub(1)));
    probes(lens.height)
        .flat_map(|j| probes(lens.width).map(move |i| j * lens.width + i))
        .filter_map(|k| lens.rays.get(k).copied().flatten())
        .filter_map(|ray| seen.hit(&ray, frame::NEAR_M))
        .map(|hit| hit.distance_m)
        .fold(f64::INFINITY, f64::min)
}

/// One 8-bit frame (row-major) of a camera with rays `lens`, mounted at
/// `body_from_camera`, centred at IMU time `t` \[s\], with relative gain
/// `gain`; the sensor's noise drawn from `seed`.
#[allow(clippy::too_many_arguments)]
pub fn render_frame(
    scene: &scene::RenderScene,
    lens: &lens::RayTable,
    focal_px: f64,
    motion: &dyn Motion,
    body_from_camera: &Isometry3<f64>,
    t: f64,
    gain: f64,
    s: &ImageSettings,
    seed: u64,
) -> Vec<u8> {
    let nearest_m = nearest_surface_m(scene, lens, &camera_pose(motion, body_from_camera, t));
    let samples = blur_samples(motion, t, focal_px, nearest_m, s);
    let mid_row = (lens.height as f64 - 1.0) * 0.5;
    let pose_at = |row: usize, within: f64| {
        let readout = (row as f64 - mid_row) * s.line_delay_s;
        camera_pose(motion, body_from_camera, t + readout + within * s.exposure_s)
    };
    let exposure = frame::Exposure { samples, max_step_px: s.max_blur_step_px, pose_at: &pose_at };
    let radiance = frame::radiance_image(scene, lens, &exposure);
    frame::expose(&radiance, lens.width, gain, s, seed)
}

#[cfg(test)]
mod tests {
    use super::scene::{Plane, RenderScene};
    use super::texture::Texture;
    use super::*;
    use nalgebra::{Matrix3, Vector3};
    use std::sync::Arc;
    use tumble_factors::camera::{CameraModel, Distortion};

    /// A plane of a blank 16-texel texture.
    fn plane(origin: [f64; 3], u_axis: [f64; 3], v_axis: [f64; 3], size: [f64; 2]) -> Plane {
        Plane {
            origin: origin.into(),
            u_axis: u_axis.into(),
            v_axis: v_axis.into(),
            size,
            texture: Arc::new(Texture::printed(16, 16, &[], 0.5, 0.5)),
            ring: None,
        }
    }

    #[test]
    fn the_blur_is_bounded_by_the_nearest_surface_in_view() {
        let model = CameraModel { fx: 458.0, fy: 458.0, cx: 376.0, cy: 240.0, distortion: Distortion::None };
        let lens = lens::RayTable::new(&model, 752, 480);
        // A camera at the origin looking along world +x (its y down = world −z).
        let r = Matrix3::from_columns(&[-Vector3::y(), -Vector3::z(), Vector3::x()]);
        let rot = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(r));
        let pose = Isometry3::from_parts(Translation3::identity(), rot);
        let wall = plane([2.0, -5.0, -5.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [10.0, 10.0]);
        let mut scene = RenderScene { planes: vec![wall], walls: Vec::new(), background: 0.5 };
        // The wall 2 m ahead is nearest where the optical axis meets it.
        let d = nearest_surface_m(&scene, &lens, &pose);
        assert!((d - 2.0).abs() < 1e-3, "{d}");
        // A floor 0.6 m below comes nearest at the image's bottom edge:
        // along the ray (0, 239/458, 1), 0.6 m down.
        scene.planes.push(plane([0.0, -5.0, -0.6], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [10.0, 10.0]));
        let slope: f64 = 239.0 / 458.0;
        let expected = 0.6 * (1.0 + slope * slope).sqrt() / slope;
        let d = nearest_surface_m(&scene, &lens, &pose);
        assert!((d - expected).abs() < 2e-3, "{d} vs {expected}");
        // Nothing in view: only the rotation blurs.
        let away = Isometry3::from_parts(Translation3::new(3.0, 0.0, 0.0), rot);
        assert_eq!(nearest_surface_m(&RenderScene { planes: Vec::new(), ..scene }, &lens, &away), f64::INFINITY);
    }
}
