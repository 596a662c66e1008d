//! Textures with a mip pyramid that keeps the texel-centre convention, and
//! the procedural "dead leaves" texture of the rendered scenes.
//!
//! Coordinates are continuous in level-0 texels: texel `i` covers `[i, i + 1)`
//! and its value is the mean of the surface over that square (its centre is
//! `i + ½`). Level `k` texel `i` is the mean of the four level-`k − 1` texels
//! it covers, so it covers `[i·2ᵏ, (i + 1)·2ᵏ)` of level 0 and its centre is
//! `(i + ½)·2ᵏ`: the same convention on every level. A sample at `u` on level
//! `k` interpolates bilinearly about `u/2ᵏ − ½`. Box filters and a symmetric
//! interpolation move no edge: a rendered edge or corner stays where it projects.

use super::quad;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

/// One level of a pyramid: `width × height` texels, row-major, values in
/// \[0, 1\] held as multiples of [`TEXEL_STEP`] (16 bits: half the memory of
/// `f32`; the step is 1/257 of an 8-bit grey level).
#[derive(Debug, Clone)]
struct Level {
    width: usize,
    height: usize,
    data: Vec<u16>,
}

/// The value of one unit of a stored texel.
const TEXEL_STEP: f32 = 1.0 / 65535.0;

/// A value in \[0, 1\] as a stored texel (rounded to the nearest step).
fn quantized(x: f32) -> u16 {
    (x.clamp(0.0, 1.0) * 65535.0 + 0.5) as u16
}

/// A level from `width × height` values in \[0, 1\] (row-major).
fn stored(width: usize, height: usize, values: &[f32]) -> Level {
    Level { width, height, data: values.par_iter().map(|&x| quantized(x)).collect() }
}

/// Each texel of the next level of `values` (`width × height`, row-major):
/// the mean of the 2 × 2 it covers, edges clamped. Returns its sides too.
fn halved(width: usize, height: usize, values: &[f32]) -> (usize, usize, Vec<f32>) {
    let (w, h) = ((width / 2).max(1), (height / 2).max(1));
    let at = |i: usize, j: usize| values[j.min(height - 1) * width + i.min(width - 1)];
    let data = (0..w * h)
        .into_par_iter()
        .map(|k| {
            let (i, j) = (2 * (k % w), 2 * (k / w));
            0.25 * (at(i, j) + at(i + 1, j) + at(i, j + 1) + at(i + 1, j + 1))
        })
        .collect();
    (w, h, data)
}

/// `⌊x⌋` as an integer (without a call into libm).
#[inline(always)]
fn floor_i(x: f64) -> isize {
    let t = x as isize;
    t - isize::from((t as f64) > x)
}

impl Level {
    fn at(&self, i: isize, j: isize) -> f32 {
        let i = i.clamp(0, self.width as isize - 1) as usize;
        let j = j.clamp(0, self.height as isize - 1) as usize;
        f32::from(self.data[j * self.width + i]) * TEXEL_STEP
    }

    /// Bilinear interpolation between texel centres; `(x, y)` in this level's texels.
    #[inline(always)]
    fn bilinear(&self, x: f64, y: f64) -> f64 {
        let (x, y) = (x - 0.5, y - 0.5);
        let (i, j) = (floor_i(x), floor_i(y));
        let (fx, fy) = ((x - i as f64) as f32, (y - j as f64) as f32);
        let (w, h) = (self.width as isize, self.height as isize);
        let [a, b, c, d] = if i >= 0 && j >= 0 && i + 1 < w && j + 1 < h {
            let k = (j * w + i) as usize;
            let (top, bottom) = (&self.data[k..k + 2], &self.data[k + w as usize..k + w as usize + 2]);
            [top[0], top[1], bottom[0], bottom[1]].map(|t| f32::from(t) * TEXEL_STEP)
        } else {
            [self.at(i, j), self.at(i + 1, j), self.at(i, j + 1), self.at(i + 1, j + 1)]
        };
        let top = a + (b - a) * fx;
        let bottom = c + (d - c) * fx;
        f64::from(top + (bottom - top) * fy)
    }
}

/// A texture with its mip pyramid. Sides are powers of two, so that every
/// level halves exactly. A printed pattern ([`Texture::printed`]) is sampled
/// from its exact shape instead.
#[derive(Debug, Clone)]
pub struct Texture {
    levels: Vec<Level>,
    printed: Option<Rectilinear>,
}

/// Width of the square a printed pattern is averaged over, in pixels (on
/// the image; [`Texture::sample`]'s fallback: in pixel footprints on the
/// pattern): a pixel's own box (σ 0.29 px) blurred by a lens' point spread
/// of about half a pixel gives σ 0.58 px, a box of two pixels. The pyramid
/// blurs the rest of the scene alike (its trilinear filter: σ 0.5–1
/// footprint). A box of one pixel alone leaves a sharp edge's rendered
/// profile dependent on where it falls within a pixel (on a rendered
/// AprilGrid, seed 1: focal length 2.6σ short).
pub const PRINT_BLUR_FOOTPRINTS: f64 = 2.0;

/// A pattern constant on the cells of a rectilinear grid (a printed target's
/// squares, tags and cells), held as its integral at the grid's nodes: the
/// mean over any axis-aligned box is exact, whatever its size and wherever
/// its edges fall. A mip pyramid's prefiltered texels are not: their filter
/// is centred on the texel grid, not on the sample, so an edge or corner
/// that falls within a texel is rendered displaced by a fraction of a texel.
/// That fixed pattern of errors, the same in every frame, is harmless on a
/// random texture but biases a calibration that sees the same corners
/// throughout (a rendered AprilGrid's focal length 2.2σ short, seed 1).
#[derive(Debug, Clone)]
struct Rectilinear {
    /// The grid's lines along x and y \[level-0 texels\], increasing, from 0 to the side.
    xs: Vec<f64>,
    ys: Vec<f64>,
    /// The integral from the origin to node `(i, j)`, row-major (`xs.len()` a row).
    sums: Vec<f64>,
    /// Each cell's grey, row-major (`xs.len() − 1` a row).
    values: Vec<f32>,
}

impl Rectilinear {
    /// The grid through every edge of `rects` (`[x0, y0, x1, y1]`, level-0
    /// texels, within `width × height`), each cell `paper + (ink − paper)·c`
    /// with `c` the sum of the `amounts` of the rectangles that hold it,
    /// clamped to \[0, 1\].
    fn new(width: usize, height: usize, rects: &[([f64; 4], f32)], paper: f32, ink: f32) -> Rectilinear {
        let lines = |lo: usize, hi: usize, side: f64| {
            let mut v: Vec<f64> = std::iter::once(0.0)
                .chain(rects.iter().flat_map(|(r, _)| [r[lo], r[hi]]))
                .chain(std::iter::once(side))
                .map(|x| x.clamp(0.0, side))
                .collect();
            v.sort_by(f64::total_cmp);
            v.dedup();
            v
        };
        let (xs, ys) = (lines(0, 2, width as f64), lines(1, 3, height as f64));
        let (nx, ny) = (xs.len() - 1, ys.len() - 1);
        let mut cover = vec![0.0f32; nx * ny];
        for ([x0, y0, x1, y1], amount) in rects {
            let (i0, i1) = (xs.partition_point(|x| x < x0), xs.partition_point(|x| x < x1));
            let (j0, j1) = (ys.partition_point(|y| y < y0), ys.partition_point(|y| y < y1));
            for j in j0..j1.min(ny) {
                for c in &mut cover[j * nx + i0..j * nx + i1.min(nx)] {
                    *c += amount;
                }
            }
        }
        let values: Vec<f32> = cover.iter().map(|c| paper + (ink - paper) * c.clamp(0.0, 1.0)).collect();
        let mut sums = vec![0.0; (nx + 1) * (ny + 1)];
        for j in 0..ny {
            let mut row = 0.0;
            for i in 0..nx {
                row += f64::from(values[j * nx + i]) * (xs[i + 1] - xs[i]) * (ys[j + 1] - ys[j]);
                sums[(j + 1) * (nx + 1) + i + 1] = sums[j * (nx + 1) + i + 1] + row;
            }
        }
        Rectilinear { xs, ys, sums, values }
    }

    /// The grey of cell `(i, j)`.
    fn cell_value(&self, i: usize, j: usize) -> f64 {
        f64::from(self.values[j * (self.xs.len() - 1) + i])
    }

    /// The cell along one axis (`lines`) that holds `x` (the first or the
    /// last beyond the pattern).
    fn cell_at(lines: &[f64], x: f64) -> usize {
        lines.partition_point(|l| *l <= x).clamp(1, lines.len() - 1) - 1
    }

    /// The cells the box `[lo, hi]` touches (columns, rows), if it lies
    /// within the pattern.
    fn cells_under(&self, lo: [f64; 2], hi: [f64; 2]) -> Option<[std::ops::RangeInclusive<usize>; 2]> {
        let (w, h) = (self.xs[self.xs.len() - 1], self.ys[self.ys.len() - 1]);
        let within = lo[0] >= 0.0 && lo[1] >= 0.0 && hi[0] <= w && hi[1] <= h;
        within.then(|| {
            [
                Self::cell_at(&self.xs, lo[0])..=Self::cell_at(&self.xs, hi[0]),
                Self::cell_at(&self.ys, lo[1])..=Self::cell_at(&self.ys, hi[1]),
            ]
        })
    }

    /// The one grey of every cell the box `[lo, hi]` touches, if they share
    /// one (a box within the pattern).
    fn one_grey_under(&self, lo: [f64; 2], hi: [f64; 2]) -> Option<f64> {
        let [columns, rows] = self.cells_under(lo, hi)?;
        let first = self.cell_value(*columns.start(), *rows.start());
        let same = rows.flat_map(|j| columns.clone().map(move |i| (i, j))).all(|(i, j)| self.cell_value(i, j) == first);
        same.then_some(first)
    }

    /// The mean over an image's square whose corners `(0, 0)`, `(1, 0)`,
    /// `(1, 1)`, `(0, 1)` fall at `corners` on the pattern (level-0 texels),
    /// the square seen through the projective map they give: each cell the
    /// square's preimage touches weighted by the share of the *square* it
    /// covers, so the average is uniform over the image, not over the
    /// pattern. None where the preimage leaves the pattern or the map folds.
    fn mean_over_square(&self, corners: [[f64; 2]; 4]) -> Option<f64> {
        let (lo, hi) = corners.iter().fold(([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]), |(lo, hi), p| {
            ([lo[0].min(p[0]), lo[1].min(p[1])], [hi[0].max(p[0]), hi[1].max(p[1])])
        });
        let [columns, rows] = self.cells_under(lo, hi)?;
        // The cells' shares of the square add up to one: the mean is the
        // first cell's grey plus each other grey's excess times its share
        // (none where the square sees one grey: most of a target's pixels).
        let base = self.cell_value(*columns.start(), *rows.start());
        let mut to_square = None;
        let mut excess = 0.0;
        for j in rows {
            for i in columns.clone() {
                let grey = self.cell_value(i, j);
                if grey == base {
                    continue;
                }
                let m = match to_square {
                    Some(m) => m,
                    None => *to_square.insert(quad::square_to_quad(corners)?.try_inverse()?),
                };
                let (x, y) = ([self.xs[i], self.xs[i + 1]], [self.ys[j], self.ys[j + 1]]);
                let cell = [[x[0], y[0]], [x[1], y[0]], [x[1], y[1]], [x[0], y[1]]].map(|p| quad::apply(&m, p));
                let [Some(a), Some(b), Some(c), Some(d)] = cell else { return None };
                excess += quad::area_in_unit_square([a, b, c, d]) * (grey - base);
            }
        }
        Some(base + excess)
    }

    /// The integral over `[0, x] × [0, y]` (clamped to the pattern): bilinear
    /// within a cell, as the integral of a constant is.
    fn integral(&self, x: f64, y: f64) -> f64 {
        let locate = |lines: &[f64], x: f64| {
            let x = x.clamp(0.0, lines[lines.len() - 1]);
            let i = Self::cell_at(lines, x);
            (i, (x - lines[i]) / (lines[i + 1] - lines[i]))
        };
        let ((i, fx), (j, fy)) = (locate(&self.xs, x), locate(&self.ys, y));
        let n = self.xs.len();
        let at = |i: usize, j: usize| self.sums[j * n + i];
        let low = at(i, j) + (at(i + 1, j) - at(i, j)) * fx;
        let high = at(i, j + 1) + (at(i + 1, j + 1) - at(i, j + 1)) * fx;
        low + (high - low) * fy
    }

    /// The mean over the box `[x0, x1] × [y0, y1]` cut to the pattern.
    fn mean(&self, [x0, y0, x1, y1]: [f64; 4]) -> f64 {
        let (w, h) = (self.xs[self.xs.len() - 1], self.ys[self.ys.len() - 1]);
        let [x0, x1] = [x0.clamp(0.0, w), x1.clamp(0.0, w)];
        let [y0, y1] = [y0.clamp(0.0, h), y1.clamp(0.0, h)];
        let area = (x1 - x0) * (y1 - y0);
        if area <= 0.0 {
            // A box beside the pattern: its nearest texel-sized box.
            let (x, y) = (x0.clamp(0.0, w - 1.0), y0.clamp(0.0, h - 1.0));
            return self.mean([x, y, x + 1.0, y + 1.0]);
        }
        let f = |x, y| self.integral(x, y);
        (f(x1, y1) - f(x0, y1) - f(x1, y0) + f(x0, y0)) / area
    }
}

impl Texture {
    /// A texture from level-0 texels (row-major, values in \[0, 1\]); `width`
    /// and `height` must be powers of two.
    ///
    /// # Panics
    /// When the sides are not powers of two or `data` has another length (a
    /// programming error: the scene builds its textures).
    pub fn new(width: usize, height: usize, data: Vec<f32>) -> Texture {
        assert!(width.is_power_of_two() && height.is_power_of_two() && data.len() == width * height);
        // Every level from the one below before it is stored: no rounding accumulates.
        let mut levels = vec![stored(width, height, &data)];
        let (mut w, mut h, mut values) = (width, height, data);
        while w > 1 || h > 1 {
            (w, h, values) = halved(w, h, &values);
            levels.push(stored(w, h, &values));
        }
        Texture { levels, printed: None }
    }

    /// A printed pattern of axis-aligned rectangles on paper: `rects` are
    /// `[x0, y0, x1, y1]` in level-0 texels of a `width × height` texture
    /// with the amount of ink each adds (1: a black square; −1: a white cell
    /// cut out of it). Sampled exactly ([`Texture::sample`]); its texels hold
    /// the pattern's mean over each.
    ///
    /// # Panics
    /// When the sides are not powers of two (as [`Texture::new`]).
    pub fn printed(width: usize, height: usize, rects: &[([f64; 4], f32)], paper: f32, ink: f32) -> Texture {
        let pattern = Rectilinear::new(width, height, rects, paper, ink);
        let data = (0..width * height)
            .map(|k| {
                let (i, j) = ((k % width) as f64, (k / width) as f64);
                pattern.mean([i, j, i + 1.0, j + 1.0]) as f32
            })
            .collect();
        Texture { printed: Some(pattern), ..Texture::new(width, height, data) }
    }

    /// Whether this is a printed pattern ([`Texture::printed`]).
    pub fn is_printed(&self) -> bool {
        self.printed.is_some()
    }

    /// A printed pattern's mean over a square of the image whose corners
    /// (in the order `(0, 0)`, `(1, 0)`, `(1, 1)`, `(0, 1)` of the square)
    /// fall at `corners` on the pattern \[level-0 texels\]: exact for a
    /// square seen through a projective map (a pinhole on a plane; through
    /// a distorting lens, to the distortion's bend over the square). Each
    /// cell weighs by the share of the image square it covers. None for
    /// any other texture, and where the square leaves the pattern.
    pub fn mean_over_image_square(&self, corners: [[f64; 2]; 4]) -> Option<f64> {
        self.printed.as_ref()?.mean_over_square(corners)
    }

    /// A printed pattern's grey over the box `[u0, v0, u1, v1]` (level-0
    /// texels) where it is one grey all over the box; None elsewhere, and
    /// for any other texture.
    pub fn uniform_over(&self, [u0, v0, u1, v1]: [f64; 4]) -> Option<f64> {
        self.printed.as_ref()?.one_grey_under([u0, v0], [u1, v1])
    }

    /// Width and height of level 0 \[texels\].
    pub fn size(&self) -> [usize; 2] {
        [self.levels[0].width, self.levels[0].height]
    }

    /// The surface's mean over a footprint `footprint` level-0 texels wide
    /// about `(u, v)` (level-0 texels): trilinear interpolation between the
    /// two levels whose texels bracket the footprint. A footprint under one
    /// texel reads level 0 bilinearly.
    ///
    /// Edges stay unbiased: every level's texels are centred as level 0's
    /// and the interpolation is symmetric, so an edge's rendered position
    /// errs only by where it falls within a texel and a pixel (its phase),
    /// which averages out over positions (`tests/render.rs` measures both).
    ///
    /// A printed pattern returns its exact mean over a square
    /// [`PRINT_BLUR_FOOTPRINTS`] footprints (at least one texel) wide centred
    /// on `(u, v)`: a filter symmetric about the sample, so an edge or corner
    /// is rendered where it projects in every frame, not only on average.
    pub fn sample(&self, u: f64, v: f64, footprint: f64) -> f64 {
        if let Some(p) = &self.printed {
            let half = 0.5 * (PRINT_BLUR_FOOTPRINTS * footprint).max(1.0);
            return p.mean([u - half, v - half, u + half, v + half]);
        }
        let lod = lod_of(footprint).min((self.levels.len() - 1) as f64);
        let k = lod as usize;
        let f = lod - k as f64;
        if f < 1e-6 || k + 1 >= self.levels.len() {
            return self.bilinear_on(k, u, v);
        }
        self.bilinear_on(k, u, v) * (1.0 - f) + self.bilinear_on(k + 1, u, v) * f
    }

    /// Level `k` read bilinearly at `(u, v)` \[level-0 texels\].
    #[inline(always)]
    fn bilinear_on(&self, k: usize, u: f64, v: f64) -> f64 {
        // Level k's coordinates are level 0's times 2⁻ᵏ, an exact product.
        let s = f64::from_bits((1023 - k as u64) << 52);
        self.levels[k].bilinear(u * s, v * s)
    }
}

/// The mip level for a footprint of `texels` (≥ 1): log₂ linearly
/// interpolated between powers of two (exact at them, continuous and
/// increasing between, within 0.09 of log₂), read from the float's bits.
fn lod_of(texels: f64) -> f64 {
    let x = texels.max(1.0);
    let bits = x.to_bits();
    let exponent = ((bits >> 52) & 0x7ff) as i64 - 1023;
    let mantissa = f64::from_bits((bits & ((1u64 << 52) - 1)) | (1023u64 << 52));
    exponent as f64 + mantissa - 1.0
}

/// Paint the axis-aligned rectangle `[x0, x1) × [y0, y1)` (level-0 texels)
/// with `value`, each texel blended by the fraction of it the rectangle
/// covers: the texture holds the surface's exact mean per texel.
pub fn paint_rect(width: usize, height: usize, data: &mut [f32], rect: [f64; 4], value: f32) {
    paint_rows(width, 0..height, data, rect, value);
}

/// [`paint_rect`] on the texture's rows `rows` only, held in `strip`
/// (`rows.len()` rows of `width` texels): each texel painted as the whole
/// texture's would be.
fn paint_rows(width: usize, rows: std::ops::Range<usize>, strip: &mut [f32], [x0, y0, x1, y1]: [f64; 4], value: f32) {
    let cover = |lo: f64, hi: f64, i: usize| (hi.min(i as f64 + 1.0) - lo.max(i as f64)).max(0.0);
    let (i0, i1) = (x0.floor().max(0.0) as usize, (x1.ceil().max(0.0) as usize).min(width));
    let j0 = (y0.floor().max(0.0) as usize).max(rows.start);
    let j1 = (y1.ceil().max(0.0) as usize).min(rows.end);
    if i0 >= i1 {
        return;
    }
    let blend = |t: &mut f32, c: f32| *t = *t * (1.0 - c) + value * c;
    for j in j0..j1 {
        let cy = cover(y0, y1, j);
        let row = &mut strip[(j - rows.start) * width..][i0..i1];
        let last = row.len() - 1;
        // The columns between the first and the last are covered whole.
        let inner = cy as f32;
        for (k, t) in row.iter_mut().enumerate() {
            let c = if k == 0 || k == last { (cover(x0, x1, i0 + k) * cy) as f32 } else { inner };
            blend(t, c);
        }
    }
}

/// Rows of the strips [`dead_leaves`] paints in parallel.
const STRIP_ROWS: usize = 32;

/// Fraction of [`dead_leaves`]' rectangles of any grey; the others are
/// within [`WEAK_CONTRAST`] of the surface's base grey.
const STRONG_LEAVES: f64 = 0.1;

/// Largest grey difference of a weak rectangle from its surface's base (of 1).
const WEAK_CONTRAST: f32 = 0.08;

/// A "dead leaves" texture: rectangles of random grey, sides drawn from a
/// `1/s³` law between `sides` \[level-0 texels\], painted over one another until the
/// surface is covered several times over. The model reproduces the
/// statistics of natural images that matter to a feature tracker: a
/// scale-invariant (1/f²) power spectrum, sharp occluding edges and corners at
/// every scale, and a heavy-tailed gradient distribution (Lee, Mumford and
/// Huang, "Occlusion models for natural images", IJCV 2001).
pub fn dead_leaves(width: usize, height: usize, sides: [f64; 2], seed: u64) -> Texture {
    let (base, leaves) = draw_leaves(width, height, sides, seed);
    Texture::new(width, height, paint_leaves(width, height, base, &leaves))
}

/// A rectangle `[x0, y0, x1, y1]` \[level-0 texels\] and its grey.
type Leaf = ([f64; 4], f32);

/// [`dead_leaves`]' base grey and its rectangles in the order they are
/// painted (the later over the earlier).
fn draw_leaves(width: usize, height: usize, sides: [f64; 2], seed: u64) -> (f32, Vec<Leaf>) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let base: f32 = rng.random_range(0.35..0.75);
    let [lo, hi] = sides;
    let hi = hi.min(width.max(height) as f64);
    // Mean area of a leaf, its two sides drawn independently from p(s) ∝ s⁻³ on
    // [lo, hi]: E[s]², E[s] = 2 / (1/lo + 1/hi).
    let mean_side = 2.0 / (1.0 / lo + 1.0 / hi);
    let mean_area = mean_side * mean_side;
    let count = (6.0 * (width * height) as f64 / mean_area).ceil() as usize;
    let leaves = (0..count)
        .map(|_| {
            // Inverse CDF of p(s) ∝ s⁻³: 1/s² uniform between 1/hi² and 1/lo².
            let side = |rng: &mut ChaCha8Rng| {
                let q: f64 = rng.random_range(0.0..1.0);
                (1.0 / (1.0 / (lo * lo) - q * (1.0 / (lo * lo) - 1.0 / (hi * hi)))).sqrt()
            };
            let (w, h) = (side(&mut rng), side(&mut rng));
            let x = rng.random_range(-w..width as f64);
            let y = rng.random_range(-h..height as f64);
            // Most surfaces differ little from their neighbours (walls, floors,
            // furniture of one material); a few stand out (posters, frames, shadows).
            let value = if rng.random_bool(STRONG_LEAVES) {
                rng.random_range(0.08f32..0.92)
            } else {
                (base + WEAK_CONTRAST * rng.random_range(-1.0f32..1.0)).clamp(0.0, 1.0)
            };
            ([x, y, x + w, y + h], value)
        })
        .collect();
    (base, leaves)
}

/// `leaves` painted in order over a `width × height` surface of `base`
/// grey ([`paint_rect`]). Strips of rows are painted in parallel, each with
/// every leaf that reaches it in the order drawn: the same texels as
/// painting the leaves one by one.
fn paint_leaves(width: usize, height: usize, base: f32, leaves: &[Leaf]) -> Vec<f32> {
    let strips = height.div_ceil(STRIP_ROWS);
    let mut reaching: Vec<Vec<usize>> = vec![Vec::new(); strips];
    for (k, (r, _)) in leaves.iter().enumerate() {
        let first = (r[1].max(0.0) as usize / STRIP_ROWS).min(strips);
        let end = (r[3].ceil().max(0.0) as usize).div_ceil(STRIP_ROWS).min(strips);
        (first..end).for_each(|s| reaching[s].push(k));
    }
    let mut data = vec![base; width * height];
    data.par_chunks_mut(STRIP_ROWS * width).zip(&reaching).enumerate().for_each(|(s, (strip, reach))| {
        let rows = s * STRIP_ROWS..s * STRIP_ROWS + strip.len() / width;
        for &(rect, value) in reach.iter().map(|&k| &leaves[k]) {
            paint_rows(width, rows.clone(), strip, rect, value);
        }
    });
    data
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A printed square with a white cell cut out of it: every box mean is
    /// the exact ink coverage, wherever its edges fall. Two squares meeting at
    /// a corner (an X-junction, as a grid's tag and corner square do): samples
    /// at points mirrored about the junction are equal (the filter is
    /// symmetric about the sample, so the junction is rendered where it is).
    #[test]
    fn a_printed_pattern_is_sampled_exactly_wherever_its_edges_fall() {
        let (paper, ink) = (0.9f32, 0.1f32);
        let square = [10.3, 20.7, 30.9, 41.2];
        let cell = [15.0, 25.55, 20.25, 30.0];
        let beside = [3.1, 12.4, 10.3, 20.7];
        let t = Texture::printed(64, 64, &[(square, 1.0), (cell, -1.0), (beside, 1.0)], paper, ink);
        let overlap = |b: [f64; 4], r: [f64; 4]| {
            (b[2].min(r[2]) - b[0].max(r[0])).max(0.0) * (b[3].min(r[3]) - b[1].max(r[1])).max(0.0)
        };
        for (u, v, half) in
            [(10.3, 20.7, 0.5), (12.37, 22.11, 1.65), (17.6, 27.0, 1.25), (30.9, 41.2, 0.85), (50.0, 5.0, 2.0)]
        {
            let b = [u - half, v - half, u + half, v + half];
            let coverage = (overlap(b, square) - overlap(b, cell) + overlap(b, beside)) / (4.0 * half * half);
            let exact = f64::from(paper) + f64::from(ink - paper) * coverage;
            let got = t.sample(u, v, 2.0 * half / PRINT_BLUR_FOOTPRINTS);
            assert!((got - exact).abs() < 1e-9, "box at ({u}, {v}): {got} against {exact}");
        }
        for d in [[0.31, 0.17], [1.4, -0.6], [-0.9, 2.2], [0.05, -0.45]] {
            let (a, b) = (t.sample(10.3 + d[0], 20.7 + d[1], 1.3), t.sample(10.3 - d[0], 20.7 - d[1], 1.3));
            assert!((a - b).abs() < 1e-9, "{d:?}: {a} against {b}");
        }
    }

    #[test]
    fn every_level_keeps_the_texel_centre_convention() {
        // A dark square [24, 40) × [8, 16) in a 64 × 32 texture: its centroid
        // (32, 12) is where every level and every footprint puts it.
        let mut data = vec![1.0f32; 64 * 32];
        paint_rect(64, 32, &mut data, [24.0, 8.0, 40.0, 16.0], 0.0);
        let t = Texture::new(64, 32, data);
        for footprint in [1.0, 1.7, 2.0, 3.3, 4.0, 8.0] {
            let (mut m, mut mx, mut my) = (0.0, 0.0, 0.0);
            // Sample on a fine grid of points (0.25 texel), as pixels would.
            for j in 0..128 {
                for i in 0..256 {
                    let (u, v) = (i as f64 * 0.25 + 0.125, j as f64 * 0.25 + 0.125);
                    let d = 1.0 - t.sample(u, v, footprint);
                    m += d;
                    mx += d * u;
                    my += d * v;
                }
            }
            let (cx, cy) = (mx / m, my / m);
            assert!((cx - 32.0).abs() < 1e-3 && (cy - 12.0).abs() < 1e-3, "footprint {footprint}: ({cx}, {cy})");
        }
    }

    #[test]
    fn the_level_of_detail_follows_log2() {
        for x in [1.0, 1.5, 2.0, 3.0, 4.0, 7.9, 1024.0, 3000.0] {
            assert!((lod_of(x) - f64::log2(x)).abs() < 0.09, "{x}");
        }
        assert_eq!((lod_of(0.2), lod_of(8.0)), (0.0, 3.0));
        assert_eq!(floor_i(-0.5), -1);
        assert_eq!(floor_i(2.0), 2);
    }

    /// Painting in parallel strips of rows, a leaf's inner columns blended
    /// with one factor per row, gives the texels of the plain rule: every
    /// leaf in turn, every texel blended by the fraction of it the leaf covers.
    #[test]
    fn leaves_painted_in_strips_are_the_leaves_painted_one_by_one() {
        let (width, height) = (256, 200);
        let (base, leaves) = draw_leaves(width, height, [0.7, 90.0], 5);
        let mut plain = vec![base; width * height];
        let cover = |lo: f64, hi: f64, i: usize| (hi.min(i as f64 + 1.0) - lo.max(i as f64)).max(0.0);
        for &([x0, y0, x1, y1], value) in &leaves {
            for j in 0..height {
                for i in 0..width {
                    let c = (cover(x0, x1, i) * cover(y0, y1, j)) as f32;
                    let t = &mut plain[j * width + i];
                    *t = *t * (1.0 - c) + value * c;
                }
            }
        }
        let strips = paint_leaves(width, height, base, &leaves);
        let differing = plain.iter().zip(&strips).filter(|(a, b)| a.to_bits() != b.to_bits()).count();
        assert_eq!(differing, 0, "of {} texels, over {} leaves", width * height, leaves.len());
    }

    #[test]
    fn dead_leaves_cover_the_texture_with_edges_at_every_scale() {
        let t = dead_leaves(256, 256, [3.0, 400.0], 3);
        let l = &t.levels[0];
        let base = l.data[0];
        let untouched = l.data.iter().filter(|&&x| x == base).count();
        assert!(untouched < 256, "{untouched} texels never painted");
        // Gradients on level 0 and level 3 alike: edges at both scales.
        for k in [0, 3] {
            let l = &t.levels[k];
            let strong = (1..l.width)
                .flat_map(|i| (0..l.height).map(move |j| (i, j)))
                .filter(|&(i, j)| (l.at(i as isize, j as isize) - l.at(i as isize - 1, j as isize)).abs() > 0.1)
                .count();
            let fraction = strong as f64 / (l.width * l.height) as f64;
            assert!(fraction > 0.02 && fraction < 0.6, "level {k}: {fraction}");
        }
    }
}
