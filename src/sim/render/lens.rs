//! The lens, inverted once per camera: every pixel's ray through the same
//! [`CameraModel`] the estimators use, so a point rendered at a pixel is
//! exactly where `CameraModel::project` puts it.
//!
//! Pixel convention (OpenCV's, Kalibr's): pixel `(i, j)` has its centre at
//! `u = i, v = j` and covers `[i − ½, i + ½) × [j − ½, j + ½)`.

use nalgebra::Vector3;
use rayon::prelude::*;
use tumble_factors::camera::CameraModel;

/// Per-pixel rays of one camera, row-major.
#[derive(Debug, Clone)]
pub struct RayTable {
    /// The lens model the rays come from.
    pub model: CameraModel,
    /// Image width \[px\].
    pub width: usize,
    /// Image height \[px\].
    pub height: usize,
    /// Unit ray of each pixel's centre in the camera frame (z forward); None
    /// where the distortion model cannot be inverted (outside its valid field).
    pub rays: Vec<Option<Vector3<f64>>>,
    /// Angle one pixel spans at each pixel \[rad\] (the larger of its two sides).
    pub spread: Vec<f64>,
}

/// The unit ray through pixel `uv` \[px\], if the model inverts there.
fn ray(model: &CameraModel, uv: [f64; 2]) -> Option<Vector3<f64>> {
    let [x, y] = model.unproject(uv)?;
    // Unprojection's fixed point can be a fold of the distortion polynomial
    // far outside the lens' field: keep only rays that project back.
    let back = model.project(&[x, y, 1.0])?;
    ((back[0] - uv[0]).abs() + (back[1] - uv[1]).abs() < 1e-6).then(|| Vector3::new(x, y, 1.0).normalize())
}

impl RayTable {
    /// The rays of a `width × height` image through `model`.
    pub fn new(model: &CameraModel, width: usize, height: usize) -> RayTable {
        // Every pixel on its own, in parallel.
        let (rays, spread) = (0..width * height)
            .into_par_iter()
            .map(|k| {
                let (u, v) = ((k % width) as f64, (k / width) as f64);
                let side = |du: f64, dv: f64| match (ray(model, [u - du, v - dv]), ray(model, [u + du, v + dv])) {
                    (Some(a), Some(b)) => a.angle(&b),
                    _ => 1.0 / model.fx.min(model.fy),
                };
                (ray(model, [u, v]), side(0.5, 0.0).max(side(0.0, 0.5)))
            })
            .unzip();
        RayTable { model: *model, width, height, rays, spread }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use tumble_factors::camera::Distortion;

    #[test]
    fn every_ray_projects_back_to_its_pixel_centre() {
        let model = CameraModel {
            fx: 458.654,
            fy: 457.296,
            cx: 367.215,
            cy: 248.375,
            distortion: Distortion::RadTan { k1: -0.28340811, k2: 0.07395907, p1: 0.00019359, p2: 1.76187114e-05 },
        };
        let t = RayTable::new(&model, 752, 480);
        let mut worst: f64 = 0.0;
        for j in 0..480 {
            for i in 0..752 {
                let r = t.rays[j * 752 + i].expect("EuRoC's lens inverts over its whole image");
                let uv = model.project(&[r.x, r.y, r.z]).unwrap();
                worst = worst.max((uv[0] - i as f64).abs().max((uv[1] - j as f64).abs()));
            }
        }
        assert!(worst < 1e-6, "{worst} px");
        // A pixel spans about 1/f at the centre.
        let centre = t.spread[248 * 752 + 367];
        assert!((centre * 458.0 - 1.0).abs() < 0.01, "{centre}");
    }
}
