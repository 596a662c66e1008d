//! One camera frame: the scene's radiance through the lens over the
//! exposure (motion blur; a rolling shutter's rows at their own times), then
//! the sensor (gain, vignetting, shot and read noise, 8 bits).

use super::lens::RayTable;
use super::scene::{RenderScene, SeenPlanes};
use super::ImageSettings;
use nalgebra::{Isometry3, Vector3};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

/// Nearest surface a ray may show \[m\] (the lens' own near limit).
pub(super) const NEAR_M: f64 = 0.02;

/// The radiance one pixel sees along the camera-frame unit ray `ray`: the
/// nearest surface's texture averaged over the pixel's footprint on it (mip
/// level from the distance, the incidence and the pixel's angular size `spread`).
fn radiance(scene: &RenderScene, seen: &SeenPlanes, ray: &Vector3<f64>, spread: f64) -> f64 {
    let Some(hit) = seen.hit(ray, NEAR_M) else { return scene.background };
    // The footprint's two sides are t·spread and t·spread / cos: their
    // geometric mean (the longer alone blurs walls seen at a glance).
    let metres = hit.distance_m * spread / hit.incidence.max(1e-3).sqrt();
    scene.texture(hit.plane).sample(hit.uv[0], hit.uv[1], metres * hit.texels_per_m)
}

/// The radiance of every pixel in \[0, 1\] (row-major), averaged over the
/// exposure: `pose_at(row, s)` is world ← camera for image row `row` at
/// sub-exposure sample `s` of `samples`. One thread: frames render in parallel.
pub fn radiance_image(
    scene: &RenderScene,
    lens: &RayTable,
    samples: usize,
    pose_at: &dyn Fn(usize, usize) -> Isometry3<f64>,
) -> Vec<f64> {
    let mut out = vec![0.0; lens.width * lens.height];
    // A global shutter's rows share their poses: the planes are moved once.
    let mut seen: Vec<(Isometry3<f64>, SeenPlanes)> = Vec::new();
    for (j, row) in out.chunks_mut(lens.width).enumerate() {
        for s in 0..samples {
            let pose = pose_at(j, s);
            if seen.get(s).is_none_or(|(p, _)| *p != pose) {
                let planes = scene.seen_from(&pose);
                if s < seen.len() {
                    seen[s] = (pose, planes);
                } else {
                    seen.push((pose, planes));
                }
            }
        }
        for (i, px) in row.iter_mut().enumerate() {
            let k = j * lens.width + i;
            *px = match &lens.rays[k] {
                Some(ray) => {
                    seen.iter().map(|(_, planes)| radiance(scene, planes, ray, lens.spread[k])).sum::<f64>()
                        / samples as f64
                }
                None => 0.0,
            };
        }
    }
    out
}

/// The sensor: `radiance` (row-major, `width` wide) to 8-bit grey levels
/// with the frame's `gain`, the lens' vignetting, shot and read noise (drawn
/// from `seed`).
pub fn expose(radiance: &[f64], width: usize, gain: f64, s: &ImageSettings, seed: u64) -> Vec<u8> {
    let height = radiance.len() / width.max(1);
    let (cx, cy) = ((width as f64 - 1.0) * 0.5, (height as f64 - 1.0) * 0.5);
    let corner2 = cx * cx + cy * cy;
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    radiance
        .iter()
        .enumerate()
        .map(|(k, &l)| {
            let (x, y) = ((k % width) as f64 - cx, (k / width) as f64 - cy);
            let signal = (gain * l * (1.0 - s.vignetting * (x * x + y * y) / corner2)).max(0.0);
            let shot = if s.full_well_electrons > 0.0 { (signal / s.full_well_electrons).sqrt() } else { 0.0 };
            let read = s.read_noise_dn / 255.0;
            let sigma = (shot * shot + read * read).sqrt();
            let noise: f64 = StandardNormal.sample(&mut rng);
            // Rounded to the nearest grey level (`as` saturates at 0 and 255).
            ((signal + sigma * noise) * 255.0 + 0.5) as u8
        })
        .collect()
}
