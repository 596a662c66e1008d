//! A track held to where it began: each feature's patch from the image in
//! which its track started (its *anchor*), aligned by an affine warp to
//! every later image, after KLT has found the feature there.
//!
//! Why: frame-to-frame KLT matches each image to the one before, so its
//! small errors (≈ 0.05 px a frame on rendered frames) add up along a track
//! as a random walk (0.2 px after ten frames, beyond 1 px for a sixth of the
//! positions in tracks older than 40 frames). The estimator takes a track's
//! observations for independent measurements of one point; a slow slide is
//! none of that, and the forward–backward check and RANSAC cannot see it.
//! Aligning to the first patch instead leaves each position with its own,
//! independent error. The warp is affine, as in Shi & Tomasi's feature
//! monitoring ("Good features to track", 1994) and SVO's feature alignment,
//! so that the patch may turn, scale and shear as the view changes; the
//! brightness is compared after removing each patch's mean and scaling its
//! contrast, so a change of exposure or gain does not move the fit.
//!
//! The alignment is the inverse-compositional Gauss–Newton of Baker &
//! Matthews ("Lucas–Kanade 20 years on", 2004): the template's gradients and
//! its 6 × 6 normal matrix are computed once, when the anchor is made.
//! Where the alignment fails — the patch left the image, the fit does not
//! converge, the aligned patch no longer looks like the anchor (an occlusion,
//! a view changed beyond an affine warp), or it lands far from KLT's answer
//! — the caller keeps KLT's position and starts a new anchor there, so
//! drift can only accumulate from one anchor to the next.

use super::corners::GrayImage;
use nalgebra::{Matrix3, Matrix6, Vector6};

/// Half the side of an anchor's patch \[px\]: 13 × 13 samples.
pub const PATCH_RADIUS: i32 = 6;
/// The aligned patch must correlate with its anchor at least this well
/// (zero-mean normalized cross-correlation).
pub const MIN_CORRELATION: f64 = 0.85;
/// Largest distance between the aligned position and KLT's \[px\].
pub const MAX_DISAGREEMENT_PX: f64 = 1.0;
/// Gauss–Newton iterations at most, and the translation update \[px\] below
/// which the alignment has converged.
const MAX_ITERATIONS: usize = 10;
const CONVERGED_PX: f64 = 1e-2;

/// A feature's patch from the image where its track began, and the affine
/// warp that last carried it into an image.
#[derive(Debug, Clone)]
pub struct Anchor {
    /// Zero-mean grey levels at the patch's `(2r+1)²` offsets, row after row.
    template: Vec<f32>,
    /// Steepest-descent images: the template's gradient times the warp's
    /// Jacobian at identity, per offset (`[Tx·x, Tx·y, Ty·x, Ty·y, Tx, Ty]`).
    descent: Vec<[f32; 6]>,
    /// Inverse of `Σ descent descentᵀ` (lightly regularized).
    normal_inverse: Matrix6<f64>,
    /// The template's standard deviation (grey levels).
    contrast: f64,
    /// The warp's linear part at the last alignment: template offsets → image offsets.
    linear: nalgebra::Matrix2<f64>,
}

/// Whether `(u, v)` (pixel centres at integers) has the four pixels a
/// bilinear read needs inside `img`.
#[inline]
fn inside(img: &GrayImage, u: f64, v: f64) -> bool {
    u >= 0.0 && v >= 0.0 && u < img.width as f64 - 1.0 && v < img.height as f64 - 1.0
}

/// Bilinear read of `img` at `(u, v)`, which must be [`inside`] (the
/// indices are clamped against rounding at the last row and column), in
/// single precision: the alignment's inner loop.
#[inline]
fn bilinear(img: &GrayImage, u: f32, v: f32) -> f32 {
    let (x0, y0) = (u.floor(), v.floor());
    let (fx, fy) = (u - x0, v - y0);
    let (p, stride) = (img.pixels, img.width);
    let i = (y0 as usize).min(img.height - 2) * stride + (x0 as usize).min(stride - 2);
    let (a, b, c, d) = (p[i] as f32, p[i + 1] as f32, p[i + stride] as f32, p[i + stride + 1] as f32);
    let top = a + fx * (b - a);
    top + fy * (c + fx * (d - c) - top)
}

/// Bilinear sample of `img` at `(u, v)` in double precision (an anchor's
/// template, read once); None outside the image.
#[inline]
fn sample(img: &GrayImage, u: f64, v: f64) -> Option<f64> {
    if !inside(img, u, v) {
        return None;
    }
    let (x0, y0) = (u.floor(), v.floor());
    let (fx, fy) = (u - x0, v - y0);
    let i = y0 as usize * img.width + x0 as usize;
    let p = img.pixels;
    let (a, b, c, d) = (p[i] as f64, p[i + 1] as f64, p[i + img.width] as f64, p[i + img.width + 1] as f64);
    Some((a + fx * (b - a)) * (1.0 - fy) + (c + fx * (d - c)) * fy)
}

impl Anchor {
    /// The anchor of a feature at `at` `[u, v]` in `img`; None where its
    /// patch (and a pixel of margin for the gradients) leaves the image or
    /// has no texture to align on.
    pub fn new(img: &GrayImage, at: [f64; 2]) -> Option<Anchor> {
        let r = PATCH_RADIUS;
        let side = (2 * r + 3) as usize;
        // Samples with a one-pixel margin, for central differences.
        let mut grid = Vec::with_capacity(side * side);
        for i in -(r + 1)..=(r + 1) {
            for j in -(r + 1)..=(r + 1) {
                grid.push(sample(img, at[0] + j as f64, at[1] + i as f64)?);
            }
        }
        let n = ((2 * r + 1) * (2 * r + 1)) as usize;
        let mut values = Vec::with_capacity(n);
        let mut descent = Vec::with_capacity(n);
        let mut normal = Matrix6::<f64>::zeros();
        for i in -r..=r {
            for j in -r..=r {
                let at = |di: i32, dj: i32| grid[(i + di + r + 1) as usize * side + (j + dj + r + 1) as usize];
                values.push(at(0, 0));
                let (tx, ty) = (0.5 * (at(0, 1) - at(0, -1)), 0.5 * (at(1, 0) - at(-1, 0)));
                let (x, y) = (j as f64, i as f64);
                let sd = Vector6::new(tx * x, tx * y, ty * x, ty * y, tx, ty);
                normal += sd * sd.transpose();
                descent.push(sd.map(|v| v as f32).into());
            }
        }
        let mean = values.iter().sum::<f64>() / n as f64;
        let contrast = (values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n as f64).sqrt();
        // The translation's 2 × 2 block must be well conditioned: a corner,
        // not an edge or a flat patch (the detector's criterion, per sample).
        let (gxx, gxy, gyy) = (normal[(4, 4)], normal[(4, 5)], normal[(5, 5)]);
        let min_eig = 0.5 * (gxx + gyy) - (0.25 * (gxx - gyy).powi(2) + gxy * gxy).sqrt();
        if contrast < 1.0 || min_eig < n as f64 {
            return None;
        }
        for k in 0..6 {
            normal[(k, k)] *= 1.0 + 1e-6;
        }
        let normal_inverse = normal.try_inverse()?;
        Some(Anchor {
            template: values.iter().map(|v| (v - mean) as f32).collect(),
            descent,
            normal_inverse,
            contrast,
            linear: nalgebra::Matrix2::identity(),
        })
    }

    /// Align the anchor's patch to `img`, starting with its centre at
    /// `guess` (KLT's position) and the warp's last linear part: the
    /// centre's position `[u, v]`, or None where the alignment fails (see
    /// the module's documentation). On success the warp is kept for the next image.
    pub fn align(&mut self, img: &GrayImage, guess: [f64; 2]) -> Option<[f64; 2]> {
        let r = PATCH_RADIUS;
        let n = self.template.len();
        let mut warp = Matrix3::identity();
        warp.fixed_view_mut::<2, 2>(0, 0).copy_from(&self.linear);
        warp[(0, 2)] = guess[0];
        warp[(1, 2)] = guess[1];
        let mut warped = vec![0.0f32; n];
        let mut converged = false;
        // The correlation at the last sampled warp (the converged one to
        // within the last, sub-0.01 px update).
        let mut correlation = 0.0;
        for _ in 0..MAX_ITERATIONS {
            let (mean, contrast) = self.sample_warped(img, &warp, &mut warped)?;
            if contrast <= 0.0 {
                return None;
            }
            let (scale, mean) = ((self.contrast / contrast) as f32, mean as f32);
            let (mut b, mut cross) = ([0.0f32; 6], 0.0f32);
            for ((w, t), sd) in warped.iter().zip(&self.template).zip(&self.descent) {
                let centred = (w - mean) * scale;
                cross += centred * t;
                let e = centred - t;
                for k in 0..6 {
                    b[k] += sd[k] * e;
                }
            }
            correlation = cross as f64 / (n as f64 * self.contrast * self.contrast);
            let dp = self.normal_inverse * Vector6::from(b.map(f64::from));
            let step = Matrix3::new(1.0 + dp[0], dp[1], dp[4], dp[2], 1.0 + dp[3], dp[5], 0.0, 0.0, 1.0);
            warp *= step.try_inverse()?;
            let det = warp[(0, 0)] * warp[(1, 1)] - warp[(0, 1)] * warp[(1, 0)];
            if !(0.5..2.0).contains(&det) {
                return None;
            }
            if dp[4].hypot(dp[5]) < CONVERGED_PX && dp.rows(0, 4).amax() * r as f64 <= CONVERGED_PX {
                converged = true;
                break;
            }
        }
        let at = [warp[(0, 2)], warp[(1, 2)]];
        let disagreement = (at[0] - guess[0]).hypot(at[1] - guess[1]);
        if !converged || correlation < MIN_CORRELATION || disagreement > MAX_DISAGREEMENT_PX {
            return None;
        }
        self.linear = warp.fixed_view::<2, 2>(0, 0).into_owned();
        Some(at)
    }

    /// The image under the warped patch into `out`; its mean and standard
    /// deviation, or None where the patch leaves the image.
    fn sample_warped(&self, img: &GrayImage, warp: &Matrix3<f64>, out: &mut [f32]) -> Option<(f64, f64)> {
        let r = PATCH_RADIUS as f64;
        let (a, b, c, d, tx, ty) = (warp[(0, 0)], warp[(0, 1)], warp[(1, 0)], warp[(1, 1)], warp[(0, 2)], warp[(1, 2)]);
        // The patch's image is the parallelogram of its four corners' images:
        // all inside, every sample is.
        if [(-r, -r), (r, -r), (-r, r), (r, r)]
            .iter()
            .any(|&(x, y)| !inside(img, a * x + b * y + tx, c * x + d * y + ty))
        {
            return None;
        }
        let (a, b, c, d) = (a as f32, b as f32, c as f32, d as f32);
        let (tx, ty) = (tx as f32, ty as f32);
        let ri = PATCH_RADIUS;
        let mut k = 0;
        let (mut sum, mut sum2) = (0.0f32, 0.0f32);
        for i in -ri..=ri {
            let y = i as f32;
            // Along a row of the patch, the image position moves by (a, c) per sample.
            let (mut u, mut v) = (b * y + tx - a * ri as f32, d * y + ty - c * ri as f32);
            for _ in -ri..=ri {
                let value = bilinear(img, u, v);
                out[k] = value;
                sum += value;
                sum2 += value * value;
                k += 1;
                u += a;
                v += c;
            }
        }
        let n = out.len() as f64;
        let mean = sum as f64 / n;
        Some((mean, (sum2 as f64 / n - mean * mean).max(0.0).sqrt()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A smooth textured image: a sum of a few sinusoids and a blob, with
    /// corners everywhere at the scale of the patch.
    fn texture(w: usize, h: usize, shift: [f64; 2], angle: f64, gain: f64) -> Vec<u8> {
        let (c, s) = (angle.cos(), angle.sin());
        let (cx, cy) = (w as f64 / 2.0, h as f64 / 2.0);
        let mut out = vec![0u8; w * h];
        for y in 0..h {
            for x in 0..w {
                // The scene point seen at (x, y): undo the rotation about the centre and the shift.
                let (dx, dy) = (x as f64 - cx - shift[0], y as f64 - cy - shift[1]);
                let (u, v) = (c * dx + s * dy, -s * dx + c * dy);
                let f = (u * 0.31).sin() * (v * 0.23).cos()
                    + 0.5 * ((u + 2.0 * v) * 0.17).sin()
                    + 0.3 * ((u * u + v * v).sqrt() * 0.4).cos();
                out[y * w + x] = (gain * (128.0 + 50.0 * f)).round().clamp(0.0, 255.0) as u8;
            }
        }
        out
    }

    #[test]
    fn an_anchor_finds_its_patch_after_a_shift_a_turn_and_a_gain() {
        let (w, h) = (96, 96);
        let first = texture(w, h, [0.0, 0.0], 0.0, 1.0);
        let img0 = GrayImage { pixels: &first, width: w, height: h };
        let at = [50.0, 44.0];
        let mut anchor = Anchor::new(&img0, at).expect("textured patch");
        // The scene moved by (2.37, −1.61) px and turned by 4° about the
        // image centre; the gain rose by 10 %.
        let (shift, angle) = ([2.37, -1.61], 4f64.to_radians());
        let moved = texture(w, h, shift, angle, 1.1);
        let img1 = GrayImage { pixels: &moved, width: w, height: h };
        let (c, s) = (angle.cos(), angle.sin());
        let (dx, dy) = (at[0] - w as f64 / 2.0, at[1] - h as f64 / 2.0);
        let truth = [w as f64 / 2.0 + c * dx - s * dy + shift[0], h as f64 / 2.0 + s * dx + c * dy + shift[1]];
        // Started 0.6 px off, as a drifted KLT position might be.
        let got = anchor.align(&img1, [truth[0] + 0.4, truth[1] - 0.45]).expect("aligned");
        let err = (got[0] - truth[0]).hypot(got[1] - truth[1]);
        assert!(err < 0.05, "aligned {got:?}, truth {truth:?}: {err} px");
        // The warp's linear part is the turn.
        assert!((anchor.linear[(1, 0)] - s).abs() < 0.01, "{}", anchor.linear);
    }

    #[test]
    fn an_anchor_refuses_a_patch_that_is_not_its_own() {
        let (w, h) = (96, 96);
        let first = texture(w, h, [0.0, 0.0], 0.0, 1.0);
        let img0 = GrayImage { pixels: &first, width: w, height: h };
        let mut anchor = Anchor::new(&img0, [50.0, 44.0]).expect("textured patch");
        // Another scene entirely: a different texture.
        let other: Vec<u8> = (0..w * h).map(|i| ((i * 7919 % 251) as u8).wrapping_mul(3)).collect();
        let img1 = GrayImage { pixels: &other, width: w, height: h };
        assert!(anchor.align(&img1, [50.0, 44.0]).is_none());
        // Flat patches and the image's border make no anchor.
        let flat = vec![100u8; w * h];
        assert!(Anchor::new(&GrayImage { pixels: &flat, width: w, height: h }, [50.0, 44.0]).is_none());
        assert!(Anchor::new(&img0, [3.0, 44.0]).is_none());
    }
}
