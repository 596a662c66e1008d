//! What the rendered camera sees, in the world frame: textured rectangles
//! (the six faces of a room or hall) and elliptical walls (a ring
//! corridor's, with its floor and ceiling as rectangles cut to the ring).

use super::super::corridor::Corridor;
use super::texture::{dead_leaves, Texture};
use nalgebra::{Isometry3, Vector3};
use rayon::prelude::*;
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
    /// Only the part of the rectangle within this elliptical ring is there
    /// (a ring corridor's floor and ceiling); None: all of it.
    pub ring: Option<PlaneRing>,
}

/// An elliptical ring on a [`Plane`], in the plane's own coordinates \[m
/// along `u_axis` and `v_axis` from `origin`\]: the points outside the
/// inner ellipse and inside the outer one, both about `centre`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlaneRing {
    /// Centre of both ellipses \[m\].
    pub centre: [f64; 2],
    /// Semi-axes of the inner ellipse along u and v \[m\].
    pub inner: [f64; 2],
    /// Semi-axes of the outer ellipse along u and v \[m\].
    pub outer: [f64; 2],
}

/// A vertical wall on the ellipse `x²/a² + y²/b² = 1` about the world's z
/// axis, from `z0` up `height` \[m\], seen from either side. Texture u runs
/// with the angle θ of `(x/a, y/b)` (counter-clockwise from +x, the whole
/// texture width once around), v upwards over the height.
#[derive(Debug, Clone)]
pub struct EllipticWall {
    /// Semi-axes along world x and y \[m\].
    pub semi_axes: [f64; 2],
    /// Height of the wall's foot \[m, world z\].
    pub z0: f64,
    /// Height of the wall \[m\].
    pub height: f64,
    /// Its surface.
    pub texture: Arc<Texture>,
}

impl EllipticWall {
    /// Level-0 texels per radian of θ and per metre of height.
    fn texels_per_unit(&self) -> [f64; 2] {
        let [w, h] = self.texture.size();
        [w as f64 / (2.0 * std::f64::consts::PI), h as f64 / self.height]
    }
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

/// The rendered world: planes and curved walls, and the radiance of rays
/// that hit none.
#[derive(Debug, Clone)]
pub struct RenderScene {
    /// The flat surfaces; a ray shows the nearest surface it hits.
    pub planes: Vec<Plane>,
    /// The curved walls (a ring corridor's).
    pub walls: Vec<EllipticWall>,
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

/// Most texels of a curved wall's texture (a power of two: 64 MiB of level 0).
const MAX_WALL_TEXELS: usize = 1 << 24;

/// Texture side for `metres` at about `texel_m` per texel, a power of two
/// of at most [`MAX_TEXTURE_SIDE`].
fn texture_side(metres: f64, texel_m: f64) -> usize {
    wall_side(metres, texel_m).min(MAX_TEXTURE_SIDE)
}

/// [`texture_side`] without its cap: a curved wall's length (at least 16).
fn wall_side(metres: f64, texel_m: f64) -> usize {
    ((metres / texel_m).ceil() as usize).next_power_of_two().max(16)
}

impl RenderScene {
    /// The six inner faces of the box `centre ± half` \[m\], each with its
    /// own dead-leaves texture (seeded by `seed` and the face).
    pub fn room(centre: Vector3<f64>, half: [f64; 3], seed: u64) -> RenderScene {
        let h = Vector3::from(half);
        let lo = centre - h;
        let e = [Vector3::x(), Vector3::y(), Vector3::z()];
        // The faces' textures are drawn in parallel, each from its own seed.
        let planes = (0..6)
            .into_par_iter()
            .map(|face| {
                let (axis, side) = (face / 2, face % 2);
                let (a, b) = ((axis + 1) % 3, (axis + 2) % 3);
                let mut origin = lo;
                origin[axis] += 2.0 * h[axis] * side as f64;
                let size = [2.0 * h[a], 2.0 * h[b]];
                let [w, ht] = size.map(|m| texture_side(m, ROOM_TEXEL_M));
                let texel_m = size[0] / w as f64;
                let sides = LEAF_SIDES_M.map(|m| m / texel_m);
                let face_seed = seed.wrapping_mul(6).wrapping_add(face as u64);
                let texture = Arc::new(dead_leaves(w, ht, sides, face_seed));
                Plane { origin, u_axis: e[a], v_axis: e[b], size, texture, ring: None }
            })
            .collect();
        RenderScene { planes, walls: Vec::new(), background: 0.5 }
    }

    /// A ring corridor ([`Corridor`]): its inner wall (the block's face), its
    /// outer wall, and the floor (z = 0) and ceiling between them, each with
    /// its own dead-leaves texture seeded by `seed`.
    pub fn corridor(c: &Corridor, seed: u64) -> RenderScene {
        let face_seed = |k: u64| seed.wrapping_mul(6).wrapping_add(k);
        let [ao, bo] = c.outer();
        let ring = PlaneRing { centre: [ao, bo], inner: c.inner(), outer: [ao, bo] };
        let size = [2.0 * ao, 2.0 * bo];
        let planes = [0.0, c.height]
            .into_par_iter()
            .enumerate()
            .map(|(k, z)| {
                let [w, h] = size.map(|m| texture_side(m, ROOM_TEXEL_M));
                let sides = LEAF_SIDES_M.map(|m| m / (size[0] / w as f64));
                let texture = Arc::new(dead_leaves(w, h, sides, face_seed(k as u64)));
                let origin = Vector3::new(-ao, -bo, z);
                Plane { origin, u_axis: Vector3::x(), v_axis: Vector3::y(), size, texture, ring: Some(ring) }
            })
            .collect();
        let walls = [c.inner(), c.outer()]
            .into_par_iter()
            .enumerate()
            .map(|(k, semi_axes)| {
                // Texels of ROOM_TEXEL_M, both sides halved together until the
                // texture fits the budget (the perimeter is tens of metres):
                // the texels stay about as long as they are high.
                let around = super::super::corridor::ellipse_perimeter(semi_axes[0], semi_axes[1]);
                let (mut w, mut h) = (wall_side(around, ROOM_TEXEL_M), wall_side(c.height, ROOM_TEXEL_M));
                while w * h > MAX_WALL_TEXELS && w > 16 && h > 16 {
                    (w, h) = (w / 2, h / 2);
                }
                let texel_m = (around / w as f64).max(c.height / h as f64);
                let sides = LEAF_SIDES_M.map(|m| m / texel_m);
                let texture = Arc::new(dead_leaves(w, h, sides, face_seed(2 + k as u64)));
                EllipticWall { semi_axes, z0: 0.0, height: c.height, texture }
            })
            .collect();
        RenderScene { planes, walls, background: 0.5 }
    }

    /// The texture of surface `k` of a [`Hit`]: the planes, then the walls.
    pub fn texture(&self, k: usize) -> &Texture {
        match self.planes.get(k) {
            Some(p) => &p.texture,
            None => &self.walls[k - self.planes.len()].texture,
        }
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
                    ring: p.ring.map(|r| SeenRing::new(&r, [su, sv])),
                    texels: [su, sv],
                }
            })
            .collect();
        let walls = self
            .walls
            .iter()
            .map(|w| {
                let [a, b] = w.semi_axes;
                let eye_unit = [eye.x / a, eye.y / b];
                SeenWall {
                    inverse_axes: [1.0 / a, 1.0 / b],
                    semi_axes: w.semi_axes,
                    z: [w.z0, w.z0 + w.height],
                    texels_per_unit: w.texels_per_unit(),
                    eye_unit,
                    eye_c: eye_unit[0] * eye_unit[0] + eye_unit[1] * eye_unit[1] - 1.0,
                }
            })
            .collect();
        SeenPlanes {
            planes,
            walls,
            world_from_camera: world_from_camera.rotation.to_rotation_matrix(),
            eye,
            first_wall: self.planes.len(),
        }
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
    ring: Option<SeenRing>,
    /// Level-0 texels per metre along u and v.
    texels: [f64; 2],
}

/// A [`PlaneRing`] in its plane's texels, for the test per ray.
#[derive(Debug, Clone, Copy)]
struct SeenRing {
    /// Centre \[texels\].
    centre: [f64; 2],
    /// Reciprocal semi-axes of the inner and outer ellipse \[1/texels\].
    inner: [f64; 2],
    outer: [f64; 2],
}

impl SeenPlane {
    /// How far along the unit camera-frame ray `ray` it meets this plane,
    /// beyond `near` \[m\], and the cosine of the ray with the plane's
    /// normal; None behind the eye or parallel (and no division then).
    #[inline]
    fn meet(&self, ray: &Vector3<f64>, near: f64) -> Option<(f64, f64)> {
        let cos = self.normal.dot(ray);
        if self.distance * cos <= 0.0 {
            return None;
        }
        let t = self.distance / cos;
        (t > near).then_some((t, cos))
    }

    /// The texture coordinates \[level-0 texels\] of the point `t` along `ray`.
    #[inline]
    fn uv_at(&self, ray: &Vector3<f64>, t: f64) -> [f64; 2] {
        [self.u.dot(ray) * t + self.u0, self.v.dot(ray) * t + self.v0]
    }
}

impl SeenRing {
    /// `ring` on a plane of `texels` per metre along u and v.
    fn new(ring: &PlaneRing, texels: [f64; 2]) -> SeenRing {
        let per_texel = |s: [f64; 2]| [1.0 / (s[0] * texels[0]), 1.0 / (s[1] * texels[1])];
        SeenRing {
            centre: [ring.centre[0] * texels[0], ring.centre[1] * texels[1]],
            inner: per_texel(ring.inner),
            outer: per_texel(ring.outer),
        }
    }

    /// Whether the point `(a, b)` \[texels\] is on the ring: outside the
    /// inner ellipse and inside the outer one.
    fn holds(&self, a: f64, b: f64) -> bool {
        let (x, y) = (a - self.centre[0], b - self.centre[1]);
        let inside = |s: [f64; 2]| (x * s[0]).powi(2) + (y * s[1]).powi(2) < 1.0;
        inside(self.outer) && !inside(self.inner)
    }
}

/// A curved wall as the world holds it (it is intersected in the world frame).
#[derive(Debug, Clone, Copy)]
struct SeenWall {
    semi_axes: [f64; 2],
    z: [f64; 2],
    texels_per_unit: [f64; 2],
    /// The eye in the ellipse's unit-circle coordinates `(x/a, y/b)`, and
    /// its squared norm less one (the ray's quadratic's constant term).
    eye_unit: [f64; 2],
    eye_c: f64,
    /// `[1/a, 1/b]` of the semi-axes.
    inverse_axes: [f64; 2],
}

/// Where a camera pose sees a scene's surfaces ([`RenderScene::seen_from`]).
#[derive(Debug, Clone)]
pub struct SeenPlanes {
    planes: Vec<SeenPlane>,
    walls: Vec<SeenWall>,
    world_from_camera: nalgebra::Rotation3<f64>,
    eye: Vector3<f64>,
    first_wall: usize,
}

/// Where a ray meets the scene.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Hit {
    /// Index of the surface: [`RenderScene::planes`], then
    /// [`RenderScene::walls`] (see [`RenderScene::texture`]).
    pub plane: usize,
    /// Distance along the (unit) ray \[m\].
    pub distance_m: f64,
    /// `|cos|` of the angle between the ray and the plane's normal.
    pub incidence: f64,
    /// Texture coordinates \[level-0 texels\].
    pub uv: [f64; 2],
    /// Level-0 texels per metre on the surface there (mean of its two axes).
    pub texels_per_m: f64,
}

impl SeenPlanes {
    /// The nearest surface the unit camera-frame ray `ray` hits beyond `near` \[m\].
    pub fn hit(&self, ray: &Vector3<f64>, near: f64) -> Option<Hit> {
        let mut best: Option<Hit> = None;
        for (k, p) in self.planes.iter().enumerate() {
            let Some((t, cos)) = p.meet(ray, near) else { continue };
            if best.is_some_and(|b| b.distance_m <= t) {
                continue;
            }
            let [a, b] = p.uv_at(ray, t);
            let on_ring = |r: &SeenRing| r.holds(a, b);
            if (0.0..p.size[0]).contains(&a) && (0.0..p.size[1]).contains(&b) && p.ring.as_ref().is_none_or(on_ring) {
                let (incidence, texels_per_m) = (cos.abs(), 0.5 * (p.texels[0] + p.texels[1]));
                best = Some(Hit { plane: k, distance_m: t, incidence, uv: [a, b], texels_per_m });
            }
        }
        if !self.walls.is_empty() {
            // The nearest wall first, its texture coordinates only then.
            let d = self.world_from_camera * ray;
            let mut nearest = best.map_or(f64::INFINITY, |b| b.distance_m);
            let mut wall = None;
            for (k, w) in self.walls.iter().enumerate() {
                if let Some(t) = w.distance(self.eye.z, &d, near, nearest) {
                    (nearest, wall) = (t, Some(k));
                }
            }
            if let Some(k) = wall {
                best = Some(Hit { plane: self.first_wall + k, ..self.walls[k].hit_at(self.eye.z, &d, nearest) });
            }
        }
        best
    }

    /// Where the unit camera-frame ray `ray` meets the plane of surface
    /// `plane` (an index of [`RenderScene::planes`]) beyond `near` \[m\],
    /// in its texture coordinates \[level-0 texels\], within the plane's
    /// bounds or not; None for a wall, or a ray parallel to the plane or
    /// meeting it behind.
    pub fn uv_on(&self, plane: usize, ray: &Vector3<f64>, near: f64) -> Option<[f64; 2]> {
        let p = self.planes.get(plane)?;
        p.meet(ray, near).map(|(t, _)| p.uv_at(ray, t))
    }
}

impl SeenWall {
    /// How far along the world-frame unit ray `d` from the eye (at height
    /// `eye_z`) it first meets the wall beyond `near` and before `nearest` \[m\].
    fn distance(&self, eye_z: f64, d: &Vector3<f64>, near: f64, nearest: f64) -> Option<f64> {
        let [ia, ib] = self.inverse_axes;
        let [ex, ey] = self.eye_unit;
        // |e + t·d|² = 1 in the ellipse's unit-circle coordinates: A t² + 2B t + C = 0.
        let (dx, dy) = (d.x * ia, d.y * ib);
        let (qa, qb) = (dx * dx + dy * dy, ex * dx + ey * dy);
        let disc = qb * qb - qa * self.eye_c;
        if qa <= 0.0 || disc < 0.0 {
            return None;
        }
        let (root, over) = (disc.sqrt(), 1.0 / qa);
        [(-qb - root) * over, (-qb + root) * over].into_iter().find(|&t| {
            let z = eye_z + t * d.z;
            t > near && t < nearest && z >= self.z[0] && z < self.z[1]
        })
    }

    /// Where the world-frame unit ray `d` from the eye (at height `eye_z`)
    /// meets the wall at distance `t` \[m\] (`plane` left 0 for the caller to set).
    fn hit_at(&self, eye_z: f64, d: &Vector3<f64>, t: f64) -> Hit {
        let [a, b] = self.semi_axes;
        let ([ex, ey], [ia, ib]) = (self.eye_unit, self.inverse_axes);
        let (dx, dy) = (d.x * ia, d.y * ib);
        let (x, y, z) = (ex + t * dx, ey + t * dy, eye_z + t * d.z);
        // (x, y) = (cos θ, sin θ): the wall's normal there is along
        // (x/a, y/b), and a radian of θ is |d(a cos θ, b sin θ)/dθ| metres.
        let normal = Vector3::new(x * ia, y * ib, 0.0).normalize();
        let theta = y.atan2(x).rem_euclid(2.0 * std::f64::consts::PI);
        let metres_per_rad = (a * a * y * y + b * b * x * x).sqrt();
        let [tu, tv] = self.texels_per_unit;
        Hit {
            plane: 0,
            distance_m: t,
            incidence: normal.dot(d).abs(),
            uv: [theta * tu, (z - self.z[0]) * tv],
            texels_per_m: 0.5 * (tu / metres_per_rad + tv),
        }
    }
}
