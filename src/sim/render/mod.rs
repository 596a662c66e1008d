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
//! - **Lens** ([`lens`]): every pixel's ray from `CameraModel::unproject`,
//!   kept only where it projects back to the pixel within 10⁻⁶ px.
//! - **Exposure** ([`frame`]): motion blur from sub-frame poses (as many as keep
//!   the image from moving more than [`ImageSettings::max_blur_step_px`]
//!   between two), an optional rolling shutter, the frame's gain, vignetting,
//!   shot and read noise, 8-bit output.
//!
//! Times: an image stamped `t` is centred at IMU time `t + time_offset_s`
//! (the simulator's convention); with a rolling shutter that is the middle
//! row's time, row `j` read `(j − (height − 1)/2)·line_delay_s` later.

pub mod frame;
pub mod lens;
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

/// Nearest depth assumed when bounding the image motion over the exposure \[m\].
const BLUR_DEPTH_M: f64 = 1.0;

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

/// Sub-exposure samples for a frame at IMU time `t`: enough that the image
/// moves at most [`ImageSettings::max_blur_step_px`] between two, bounded
/// by the rotation rate and by the speed at [`BLUR_DEPTH_M`].
fn blur_samples(motion: &dyn Motion, t: f64, focal_px: f64, s: &ImageSettings) -> usize {
    if s.exposure_s == 0.0 {
        return 1;
    }
    let k = motion.at(t.clamp(0.0, motion.duration()));
    let rate = k.omega.norm() + k.velocity.norm() / BLUR_DEPTH_M;
    let moved_px = rate * s.exposure_s * focal_px;
    ((moved_px / s.max_blur_step_px).ceil() as usize).clamp(1, MAX_BLUR_SAMPLES)
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
    let samples = blur_samples(motion, t, focal_px, s);
    let mid_row = (lens.height as f64 - 1.0) * 0.5;
    let pose_at = |row: usize, k: usize| {
        let readout = (row as f64 - mid_row) * s.line_delay_s;
        let within = ((k as f64 + 0.5) / samples as f64 - 0.5) * s.exposure_s;
        camera_pose(motion, body_from_camera, t + readout + within)
    };
    let radiance = frame::radiance_image(scene, lens, samples, &pose_at);
    frame::expose(&radiance, lens.width, gain, s, seed)
}
