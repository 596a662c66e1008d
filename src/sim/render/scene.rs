//! What the rendered camera sees: textured rectangles in the world frame
//! (the six faces of a room or hall).

use super::texture::{dead_leaves, Texture};
use nalgebra::{Isometry3, Vector3};
use std::sync::Arc;

/// A textured rectangle: the points `origin + a·u_axis + b·v_axis` with
/// `a ∈ [0, size[0])`, `b ∈ [0, size[1])` \[m\]; texture coordinate u runs
/// along `u_axis`, v along `v_axis`, the texture spanning the whole rectangle.
#[derive(Debug, Clone)]
pub struct Plane {
    /// A corner \[m, world\].
    pub origin: Vector3<f64>,
    /// Unit direction of the texture's u (columns) \[world\].
    pub u_axis: Vector3<f64>,
    /// Unit direction of the texture's v (rows), orthogonal to `u_axis` \[world\].
    pub v_axis: Vector3<f64>,
    /// Extent along `u_axis` and `v_axis` \[m\].
    pub size: [f64; 2],
    /// Its surface.
    pub texture: Arc<Texture>,
}

impl Plane {
    /// Level-0 texels per metre along u and v.
    pub fn texels_per_m(&self) -> [f64; 2] {
        let [w, h] = self.texture.size();
        [w as f64 / self.size[0], h as f64 / self.size[1]]
    }
    /// Unit normal `u_axis × v_axis`.
    pub fn normal(&self) -> Vector3<f64> {
        self.u_axis.cross(&self.v_axis)
    }
}

/// The rendered world: planes, and the radiance of rays that hit none.
#[derive(Debug, Clone)]
pub struct RenderScene {
    /// The surfaces; a ray shows the nearest it hits.
    pub planes: Vec<Plane>,
    /// Radiance where nothing is hit, in \[0, 1\].
    pub background: f64,
}

/// Side of a room's texel \[m\] (before rounding to a power of two): finer
/// than a pixel at 2 m for EuRoC's lens (4.4 mm), so near walls stay sharp.
const ROOM_TEXEL_M: f64 = 0.004;

/// Smallest and largest side of a room texture's rectangles \[m\]: from a
/// poster's detail to a door or a cupboard.
const LEAF_SIDES_M: [f64; 2] = [0.05, 2.5];

/// Largest texture side \[texels\]: a 16 k × 16 k texture is 1 GiB; walls
/// longer than 4096 texels get coarser texels (a 20 m hall wall: 5 mm).
const MAX_TEXTURE_SIDE: usize = 4096;

/// Texture side for `metres` at about `texel_m` per texel, a power of two.
fn texture_side(metres: f64, texel_m: f64) -> usize {
    ((metres / texel_m).ceil() as usize).next_power_of_two().clamp(16, MAX_TEXTURE_SIDE)
}

impl RenderScene {
    /// The six inner faces of the box `centre ± half` \[m\], each with its
    /// own dead-leaves texture (seeded by `seed` and the face).
    pub fn room(centre: Vector3<f64>, half: [f64; 3], seed: u64) -> RenderScene {
        let h = Vector3::from(half);
        let lo = centre - h;
        let e = [Vector3::x(), Vector3::y(), Vector3::z()];
        let mut planes = Vec::new();
        for axis in 0..3 {
            let (a, b) = ((axis + 1) % 3, (axis + 2) % 3);
            for side in 0..2 {
                let mut origin = lo;
                origin[axis] += 2.0 * h[axis] * side as f64;
                let size = [2.0 * h[a], 2.0 * h[b]];
                let [w, ht] = size.map(|m| texture_side(m, ROOM_TEXEL_M));
                let texel_m = size[0] / w as f64;
                let sides = LEAF_SIDES_M.map(|m| m / texel_m);
                let face_seed = seed.wrapping_mul(6).wrapping_add((2 * axis + side) as u64);
                let texture = Arc::new(dead_leaves(w, ht, sides, face_seed));
                planes.push(Plane { origin, u_axis: e[a], v_axis: e[b], size, texture });
            }
        }
        RenderScene { planes, background: 0.5 }
    }

    /// The planes as seen from the camera pose `world_from_camera`, for
    /// [`SeenPlanes::hit`] with camera-frame rays.
    pub fn seen_from(&self, world_from_camera: &Isometry3<f64>) -> SeenPlanes {
        let r = world_from_camera.rotation.inverse();
        let eye = world_from_camera.translation.vector;
        let planes = self
            .planes
            .iter()
            .map(|p| {
                let [su, sv] = p.texels_per_m();
                let n = p.normal();
                // In texels: u = su·u_axis·(eye + t·ray − origin), likewise v.
                SeenPlane {
                    normal: r * n,
                    distance: n.dot(&(p.origin - eye)),
                    u: r * p.u_axis * su,
                    u0: p.u_axis.dot(&(eye - p.origin)) * su,
                    v: r * p.v_axis * sv,
                    v0: p.v_axis.dot(&(eye - p.origin)) * sv,
                    size: [p.size[0] * su, p.size[1] * sv],
                    texels_per_m: 0.5 * (su + sv),
                }
            })
            .collect();
        SeenPlanes { planes }
    }
}

/// A plane in a camera's frame: ray `t·r` (camera frame) hits it at
/// `t = distance / (normal·r)`, at texels `(u·r·t + u0, v·r·t + v0)`.
#[derive(Debug, Clone, Copy)]
struct SeenPlane {
    normal: Vector3<f64>,
    distance: f64,
    u: Vector3<f64>,
    u0: f64,
    v: Vector3<f64>,
    v0: f64,
    size: [f64; 2],
    texels_per_m: f64,
}

/// Where a camera pose sees a scene's planes ([`RenderScene::seen_from`]).
#[derive(Debug, Clone)]
pub struct SeenPlanes {
    planes: Vec<SeenPlane>,
}

/// Where a ray meets the scene.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Hit {
    /// Index of the plane in [`RenderScene::planes`].
    pub plane: usize,
    /// Distance along the (unit) ray \[m\].
    pub distance_m: f64,
    /// `|cos|` of the angle between the ray and the plane's normal.
    pub incidence: f64,
    /// Texture coordinates \[level-0 texels\].
    pub uv: [f64; 2],
    /// Level-0 texels per metre on the plane (mean of its two axes).
    pub texels_per_m: f64,
}

impl SeenPlanes {
    /// The nearest plane the unit camera-frame ray `ray` hits beyond `near` \[m\].
    pub fn hit(&self, ray: &Vector3<f64>, near: f64) -> Option<Hit> {
        let mut best: Option<Hit> = None;
        for (k, p) in self.planes.iter().enumerate() {
            let cos = p.normal.dot(ray);
            let t = p.distance / cos;
            // A ray parallel to the plane gives an infinite or NaN t: no hit.
            if t.is_nan() || t <= near || best.is_some_and(|b| b.distance_m <= t) {
                continue;
            }
            let (a, b) = (p.u.dot(ray) * t + p.u0, p.v.dot(ray) * t + p.v0);
            if (0.0..p.size[0]).contains(&a) && (0.0..p.size[1]).contains(&b) {
                let (incidence, texels_per_m) = (cos.abs(), p.texels_per_m);
                best = Some(Hit { plane: k, distance_m: t, incidence, uv: [a, b], texels_per_m });
            }
        }
        best
    }
}
