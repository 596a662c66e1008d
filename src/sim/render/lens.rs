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

    /// The unit ray through the image point `(u, v)` \[px\]: at a pixel
    /// centre its own ray; between centres the rays of the four around it
    /// interpolated bilinearly (within a pixel the lens bends a ray by a
    /// negligible amount, so this is the model's ray without its iterative
    /// inversion); beyond the outermost centres the model's own ray. None
    /// where the model does not invert.
    pub fn ray_at(&self, u: f64, v: f64) -> Option<Vector3<f64>> {
        let (right, bottom) = ((self.width - 1) as f64, (self.height - 1) as f64);
        if !(0.0..=right).contains(&u) || !(0.0..=bottom).contains(&v) || self.width < 2 || self.height < 2 {
            return ray(&self.model, [u, v]);
        }
        let (i, j) = ((u as usize).min(self.width - 2), (v as usize).min(self.height - 2));
        let (fu, fv) = (u - i as f64, v - j as f64);
        let at = |di: usize, dj: usize| self.rays[(j + dj) * self.width + i + di];
        let (a, b, c, d) = (at(0, 0)?, at(1, 0)?, at(0, 1)?, at(1, 1)?);
        let ray = (a * (1.0 - fu) + b * fu) * (1.0 - fv) + (c * (1.0 - fu) + d * fu) * fv;
        Some(ray.normalize())
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
        // At the centres their own rays; between them, interpolated rays
        // that project within a few thousandths of a pixel where the
        // distortion bends most (the image's corners); beyond the outermost
        // centres the model's rays.
        assert_eq!(t.ray_at(10.0, 20.0), t.rays[20 * 752 + 10]);
        let mut worst = [0.0f64; 2];
        for (u, v) in [(0.3, 0.7), (750.5, 478.5), (100.83, 300.17), (375.5, 240.5), (-1.0, -1.0), (752.0, 480.0)] {
            let r = t.ray_at(u, v).unwrap();
            let uv = model.project(&[r.x, r.y, r.z]).unwrap();
            let beyond = usize::from(!(0.0..=751.0).contains(&u));
            worst[beyond] = worst[beyond].max((uv[0] - u).abs().max((uv[1] - v).abs()));
        }
        println!("interpolated rays within {:.1e} px, the model's beyond the centres {:.1e} px", worst[0], worst[1]);
        assert!(worst[0] < 2e-3 && worst[1] < 1e-6, "{worst:?} px");
    }
}
