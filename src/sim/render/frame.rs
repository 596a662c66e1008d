//! One camera frame: the scene's radiance through the lens over the
//! exposure (motion blur; a rolling shutter's rows at their own times), then
//! the sensor (gain, vignetting, shot and read noise, 8 bits).

use super::lens::RayTable;
use super::scene::{Hit, RenderScene, SeenPlanes};
use super::texture::PRINT_BLUR_FOOTPRINTS;
use super::ImageSettings;
use nalgebra::{Isometry3, Point3};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

/// Nearest surface a ray may show \[m\] (the lens' own near limit).
pub(super) const NEAR_M: f64 = 0.02;

/// Side of the square tiles of pixels that share a count of sub-exposure
/// samples \[px\].
const TILE_PX: usize = 16;

/// Spacing of the rays whose motion sets each tile's samples \[px\].
const MOTION_PROBE_PX: usize = 4;

/// How one frame's exposure is sampled ([`radiance_image`]).
pub struct Exposure<'a> {
    /// Sub-exposure samples where the image moves fastest (the frame's
    /// bound; 1: no motion blur).
    pub samples: usize,
    /// Largest image motion between two sub-exposure samples of a pixel \[px\].
    pub max_step_px: f64,
    /// World ← camera for image row `row` at `within` ∈ \[−½, ½\] of the
    /// exposure (0: its middle).
    pub pose_at: &'a dyn Fn(usize, f64) -> Isometry3<f64>,
}

impl<'a> Exposure<'a> {
    /// An instant: one sample per pixel, at `pose_at(row, 0)`.
    pub fn instant(pose_at: &'a dyn Fn(usize, f64) -> Isometry3<f64>) -> Exposure<'a> {
        Exposure { samples: 1, max_step_px: 1.0, pose_at }
    }
}

/// The radiance pixel `k` of `lens` sees: the nearest surface's texture
/// averaged over the pixel's footprint on it (mip level from the distance,
/// the incidence and the pixel's angular size), a printed pattern over a
/// square of the image ([`printed_radiance`]).
fn radiance(scene: &RenderScene, seen: &SeenPlanes, lens: &RayTable, k: usize) -> f64 {
    let Some(ray) = &lens.rays[k] else { return scene.background };
    let Some(hit) = seen.hit(ray, NEAR_M) else { return scene.background };
    let texture = scene.texture(hit.plane);
    if texture.is_printed() {
        return printed_radiance(scene, seen, lens, k, &hit);
    }
    texture.sample(hit.uv[0], hit.uv[1], footprint_texels(&hit, lens.spread[k]))
}

/// A pixel's footprint on the surface it sees at `hit` \[level-0 texels\],
/// `spread` its angular size \[rad\]: the footprint's two sides are
/// t·spread and t·spread / cos, their geometric mean (the longer alone
/// blurs walls seen at a glance).
fn footprint_texels(hit: &Hit, spread: f64) -> f64 {
    hit.distance_m * spread / hit.incidence.max(1e-3).sqrt() * hit.texels_per_m
}

/// The radiance of pixel `k`, which sees a printed pattern at `hit`: the
/// mean over a square of the *image* [`PRINT_BLUR_FOOTPRINTS`] pixels wide,
/// as a sensor (and a lens' point spread) integrate. A square on the
/// pattern instead would follow the lens' local magnification, which a
/// distortion changes across a corner's window; the blur then differs from
/// one side of an X-junction to the other and moves the corner a detector
/// finds (on rendered checkerboards through EuRoC's lens, cx 3–5 σ low).
///
/// Most of a target's pixels see one grey over their whole square: where
/// a box about the pixel's hit that holds the square's preimage holds one
/// grey, that grey. The preimage of a corner of the square, a pixel's
/// diagonal away, lies within two pixel sides (`spread`, the larger) of
/// the ray, so within t·2·spread / cos on the pattern (t the distance, cos
/// the incidence), in texels at the denser of the pattern's two axes; the
/// box is a quarter larger for the change of t and cos across the square.
/// Elsewhere the square's preimage on the pattern comes from the projective
/// map its four corners' rays give, and each of the pattern's cells counts
/// with the share of the square it covers
/// ([`Texture::mean_over_image_square`]). Where the square leaves the
/// pattern (its sheet's edge), the pattern's mean over a square of its own,
/// as other textures are read.
fn printed_radiance(scene: &RenderScene, seen: &SeenPlanes, lens: &RayTable, k: usize, hit: &Hit) -> f64 {
    let texture = scene.texture(hit.plane);
    if let Some(plane) = scene.planes.get(hit.plane) {
        let texels_per_m = plane.texels_per_m().into_iter().fold(0.0, f64::max);
        let reach = 1.25 * PRINT_BLUR_FOOTPRINTS * hit.distance_m * lens.spread[k] / hit.incidence * texels_per_m;
        let [u, v] = hit.uv;
        if let Some(grey) = texture.uniform_over([u - reach, v - reach, u + reach, v + reach]) {
            return grey;
        }
    }
    let (i, j, half) = ((k % lens.width) as f64, (k / lens.width) as f64, 0.5 * PRINT_BLUR_FOOTPRINTS);
    let corner =
        |du: f64, dv: f64| lens.ray_at(i + du * half, j + dv * half).and_then(|r| seen.uv_on(hit.plane, &r, NEAR_M));
    if let [Some(a), Some(b), Some(c), Some(d)] =
        [corner(-1.0, -1.0), corner(1.0, -1.0), corner(1.0, 1.0), corner(-1.0, 1.0)]
    {
        if let Some(value) = texture.mean_over_image_square([a, b, c, d]) {
            return value;
        }
    }
    texture.sample(hit.uv[0], hit.uv[1], footprint_texels(hit, lens.spread[k]))
}

/// Index of sample `k` of `n` in a table that holds, for every count `n ≥ 1`,
/// its `n` samples one after another.
fn sample_slot(n: usize, k: usize) -> usize {
    n * (n - 1) / 2 + k
}

/// The exposure's fraction \[−½, ½\] at sample `k` of `n`: the samples
/// split the exposure evenly, each at the middle of its share.
fn within(n: usize, k: usize) -> f64 {
    (k as f64 + 0.5) / n as f64 - 0.5
}

/// The sub-exposure samples of every [`TILE_PX`] tile (row-major, `tiles_x`
/// a row): enough that the image moves at most `max_step_px` between two.
/// The motion is measured at rays [`MOTION_PROBE_PX`] apart: the point each
/// shows at the exposure's middle, projected through the lens from the
/// exposure's start and from its end. A tile takes the most over its
/// probes and its neighbours' as far as a near surface's edge can sweep
/// (half the frame's largest motion, `e.samples · max_step_px / 2`, either
/// side of where the probes see it; at least the eight tiles around). Never
/// more than `e.samples`; a probe that hits nothing or leaves the lens'
/// field takes `e.samples`.
fn tile_samples(scene: &RenderScene, lens: &RayTable, e: &Exposure) -> (Vec<usize>, usize) {
    let (tiles_x, tiles_y) = (lens.width.div_ceil(TILE_PX), lens.height.div_ceil(TILE_PX));
    if e.samples <= 1 {
        return (vec![1; tiles_x * tiles_y], tiles_x);
    }
    let mut own = vec![1usize; tiles_x * tiles_y];
    let mut row_poses: Option<([Isometry3<f64>; 3], SeenPlanes)> = None;
    for j in (0..lens.height).step_by(MOTION_PROBE_PX) {
        let poses = [-0.5, 0.0, 0.5].map(|w| (e.pose_at)(j, w));
        if row_poses.as_ref().is_none_or(|(p, _)| *p != poses) {
            row_poses = Some((poses, scene.seen_from(&poses[1])));
        }
        let Some(([start, middle, end], seen)) = &row_poses else { continue };
        for i in (0..lens.width).step_by(MOTION_PROBE_PX) {
            let k = j * lens.width + i;
            let Some(ray) = lens.rays[k] else { continue };
            let n = match seen.hit(&ray, NEAR_M) {
                Some(hit) => {
                    let point: Point3<f64> = middle * Point3::from(ray * hit.distance_m);
                    let project =
                        |pose: &Isometry3<f64>| lens.model.project(&pose.inverse_transform_point(&point).into());
                    match (project(start), project(end)) {
                        (Some(a), Some(b)) => ((a[0] - b[0]).hypot(a[1] - b[1]) / e.max_step_px).ceil() as usize,
                        _ => e.samples,
                    }
                }
                None => e.samples,
            };
            let tile = &mut own[(j / TILE_PX) * tiles_x + i / TILE_PX];
            *tile = (*tile).max(n.clamp(1, e.samples));
        }
    }
    let sweep_px = 0.5 * e.samples as f64 * e.max_step_px;
    let reach = (sweep_px / TILE_PX as f64).ceil().clamp(1.0, tiles_x.max(tiles_y) as f64) as usize;
    // The tiles within `reach` of tile `x` of `n` along one axis.
    let span = |x: usize, n: usize| x.saturating_sub(reach)..=(x + reach).min(n - 1);
    let own = &own;
    let dilated = (0..tiles_x * tiles_y)
        .map(|t| {
            let (tx, ty) = (t % tiles_x, t / tiles_x);
            span(ty, tiles_y).flat_map(|y| span(tx, tiles_x).map(move |x| own[y * tiles_x + x])).max().unwrap_or(1)
        })
        .collect();
    (dilated, tiles_x)
}

/// The radiance of every pixel in \[0, 1\] (row-major), averaged over the
/// exposure `e`: each pixel at as many evenly spaced instants as its tile
/// needs ([`Exposure::max_step_px`]; the fastest at `e.samples`). One
/// thread: frames render in parallel.
pub fn radiance_image(scene: &RenderScene, lens: &RayTable, e: &Exposure) -> Vec<f64> {
    let (tiles, tiles_x) = tile_samples(scene, lens, e);
    let mut out = vec![0.0; lens.width * lens.height];
    // Every sample of every count, as the camera sees the scene then; a
    // global shutter's rows share their poses, so the planes move once.
    let mut seen: Vec<Option<(Isometry3<f64>, SeenPlanes)>> = vec![None; sample_slot(e.samples + 1, 0)];
    for (j, row) in out.chunks_mut(lens.width).enumerate() {
        let counts = &tiles[(j / TILE_PX) * tiles_x..][..tiles_x];
        for (n, k) in (1..=e.samples).filter(|n| counts.contains(n)).flat_map(|n| (0..n).map(move |k| (n, k))) {
            let pose = (e.pose_at)(j, within(n, k));
            let slot = &mut seen[sample_slot(n, k)];
            if slot.as_ref().is_none_or(|(p, _)| *p != pose) {
                *slot = Some((pose, scene.seen_from(&pose)));
            }
        }
        for (i, px) in row.iter_mut().enumerate() {
            let k = j * lens.width + i;
            if lens.rays[k].is_none() {
                continue;
            }
            let n = counts[i / TILE_PX];
            let sum: f64 = seen[sample_slot(n, 0)..sample_slot(n + 1, 0)]
                .iter()
                .flatten()
                .map(|(_, planes)| radiance(scene, planes, lens, k))
                .sum();
            *px = sum / n as f64;
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

#[cfg(test)]
mod tests {
    use super::super::scene::Plane;
    use super::super::texture::dead_leaves;
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion, Vector3};
    use std::sync::Arc;
    use tumble_factors::camera::{CameraModel, Distortion};

    /// A pinhole 752 × 480 lens.
    fn lens() -> RayTable {
        let model = CameraModel { fx: 458.0, fy: 458.0, cx: 375.5, cy: 239.5, distortion: Distortion::None };
        RayTable::new(&model, 752, 480)
    }

    /// A textured rectangle facing the camera (at the origin, looking along
    /// +z) at `depth`, over `x ∈ [x0, x0 + width)` and `y ∈ [−10, 10)` \[m\].
    fn panel(depth: f64, x0: f64, width: f64, seed: u64) -> Plane {
        Plane {
            origin: Vector3::new(x0, -10.0, depth),
            u_axis: Vector3::x(),
            v_axis: Vector3::y(),
            size: [width, 20.0],
            texture: Arc::new(dead_leaves(1024, 1024, [4.0, 300.0], seed)),
            ring: None,
        }
    }

    /// A wall 4 m ahead; with `near`, a panel 1 m ahead over the image's left half.
    fn scene(near: bool) -> RenderScene {
        let mut planes = vec![panel(4.0, -10.0, 20.0, 1)];
        if near {
            planes.push(panel(1.0, -5.0, 5.0, 2));
        }
        RenderScene { planes, walls: Vec::new(), background: 0.5 }
    }

    /// The camera slid sideways by `metres` over the exposure.
    fn slide(metres: f64) -> impl Fn(usize, f64) -> Isometry3<f64> {
        move |_, w| Isometry3::from_parts(Translation3::new(metres * w, 0.0, 0.0), UnitQuaternion::identity())
    }

    #[test]
    fn each_tile_takes_the_samples_its_own_motion_needs() {
        let lens = lens();
        // 2 cm sideways: 458 · 0.02 / 4 = 2.29 px on the wall, 9.16 px on the panel.
        let pose_at = slide(0.02);
        let e = Exposure { samples: 16, max_step_px: 1.0, pose_at: &pose_at };
        let (tiles, tiles_x) = tile_samples(&scene(false), &lens, &e);
        assert!(tiles.iter().all(|&n| n == 3), "{tiles:?}");
        let (tiles, tiles_x2) = tile_samples(&scene(true), &lens, &e);
        assert_eq!(tiles_x, tiles_x2);
        // The panel's edge x = 0 projects to column 375.5 (tile 23); a tile
        // beside a tile that shows the panel takes the panel's count.
        for (t, &n) in tiles.iter().enumerate() {
            let tx = t % tiles_x;
            let expected = if tx <= 24 { 10 } else { 3 };
            assert_eq!(n, expected, "tile column {tx}");
        }
        // Never more than the frame's bound; one sample without blur.
        let e = Exposure { samples: 4, ..e };
        assert!(tile_samples(&scene(true), &lens, &e).0.iter().all(|&n| n <= 4));
        let still = slide(0.0);
        assert!(tile_samples(&scene(true), &lens, &Exposure { pose_at: &still, ..e }).0.iter().all(|&n| n == 1));
    }

    #[test]
    fn fewer_samples_where_the_image_moves_less_leave_the_blur_as_it_was() {
        let (lens, scene) = (lens(), scene(true));
        let pose_at = slide(0.02);
        let adaptive = radiance_image(&scene, &lens, &Exposure { samples: 10, max_step_px: 1.0, pose_at: &pose_at });
        // A step this small puts every tile at the frame's bound.
        let everywhere = radiance_image(&scene, &lens, &Exposure { samples: 10, max_step_px: 1e-9, pose_at: &pose_at });
        let (mut sum, mut n, mut worst) = (0.0, 0, 0.0f64);
        for j in 0..lens.height {
            for i in 0..lens.width {
                let k = j * lens.width + i;
                let d = (adaptive[k] - everywhere[k]).abs();
                if i < 25 * TILE_PX {
                    // The panel's tiles and their neighbours: the same samples.
                    assert_eq!(d, 0.0, "pixel ({i}, {j})");
                } else {
                    (sum, n, worst) = (sum + d, n + 1, worst.max(d));
                }
            }
        }
        let mean = sum / n as f64;
        println!("3 samples against 10 over 2.3 px of blur: mean difference {mean:.5}, largest {worst:.4}");
        assert!(mean < 1e-3 && worst < 0.03, "mean {mean}, largest {worst}");
    }

    /// A printed sheet 25 cm a side centred 1 m ahead, turned by `yaw` about
    /// the image's vertical, with ink where its coordinates are beyond `edge`
    /// (x ≥ edge\[0\], y ≥ edge\[1\] \[m\]; 4096 texels a metre, a pixel 9
    /// texels wide), rendered still; and its x axis in the camera frame.
    fn printed_sheet(yaw: f64, edge: [f64; 2]) -> (Vec<f64>, Vector3<f64>) {
        use super::super::texture::Texture;
        let turn = nalgebra::Rotation3::from_axis_angle(&Vector3::y_axis(), yaw);
        let (u_axis, v_axis) = (turn * Vector3::x(), Vector3::y());
        let texel = |m: f64| (m + 0.125) * 4096.0;
        let ink = [([texel(edge[0]), texel(edge[1]), 1024.0, 1024.0], 1.0)];
        let sheet = Plane {
            origin: Vector3::new(0.0, 0.0, 1.0) - (u_axis + v_axis) * 0.125,
            u_axis,
            v_axis,
            size: [0.25, 0.25],
            texture: Arc::new(Texture::printed(1024, 1024, &ink, 0.9, 0.1)),
            ring: None,
        };
        let scene = RenderScene { planes: vec![sheet], walls: Vec::new(), background: 0.5 };
        let still = slide(0.0);
        (radiance_image(&scene, &lens(), &Exposure::instant(&still)), u_axis)
    }

    /// The ink's share of the 2 px square about column (or row) `c` when
    /// it starts at `at` \[px\].
    fn ink_share(c: usize, at: f64) -> f64 {
        ((c as f64 + 1.0 - at) / 2.0).clamp(0.0, 1.0)
    }

    #[test]
    fn a_printed_pattern_is_averaged_over_a_square_of_the_image() {
        // Facing the camera: ink over the quadrant beyond (x, y) = (1.3, −2.1)
        // mm, a corner off the pixel grid; each pixel's value is the ink's
        // share of the 2 px square about it, to the texture's precision.
        let edge = [0.0013, -0.0021];
        let (image, _) = printed_sheet(0.0, edge);
        let (mut worst, mut on_edges) = (0.0f64, 0);
        for j in 200..280 {
            for i in 340..420 {
                let ink = ink_share(i, 375.5 + 458.0 * edge[0]) * ink_share(j, 239.5 + 458.0 * edge[1]);
                worst = worst.max((image[j * 752 + i] - (0.9 - 0.8 * ink)).abs());
                on_edges += usize::from(ink > 0.0 && ink < 1.0);
            }
        }
        assert!(on_edges > 100 && worst < 1e-6, "{on_edges} pixels on the edges, largest difference {worst}");
        // Turned by 40°, the sheet's x = const lines stay image columns: the
        // edge x = 1.3 mm at column 375.5 + f·x·cos / (1 + x·sin), each
        // pixel below the corner the share of its square on the ink's side,
        // wherever the edge falls within a pixel.
        for step in 0..8 {
            let edge = [0.0013 + step as f64 * 0.25 / 458.0, -0.0021];
            let (image, x_axis) = printed_sheet(0.7, edge);
            let column = 375.5 + 458.0 * edge[0] * x_axis.x / (1.0 + edge[0] * x_axis.z);
            let worst = (250..280)
                .flat_map(|j| (340..420).map(move |i| (i, j)))
                .map(|(i, j)| (image[j * 752 + i] - (0.9 - 0.8 * ink_share(i, column))).abs())
                .fold(0.0, f64::max);
            assert!(worst < 1e-6, "edge at column {column}: largest difference {worst}");
        }
    }
}
