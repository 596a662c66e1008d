//! Shi–Tomasi corners ("Good features to track", Shi & Tomasi 1994): the
//! smaller eigenvalue of the image gradients' structure tensor, local maxima
//! above a fraction of the strongest, taken strongest first at a minimum
//! distance from each other. The same definition as OpenCV's
//! `goodFeaturesToTrack` without the Harris option (3×3 Sobel gradients summed
//! over a 3×3 block, mirrored borders, the image's outermost pixels never
//! corners, ties between equal scores to the later pixel), written out so that
//! the tracker's detection does not pay for OpenCV's general filters (6.5 ms
//! of a 752×480 frame on one core; with this detector the KLT tracker's whole
//! frame went from 12 to 8 ms on rendered frames, with the same corners).

/// An 8-bit grayscale image, row-major without padding.
#[derive(Debug, Clone, Copy)]
pub struct GrayImage<'a> {
    /// `width · height` grey levels, row after row.
    pub pixels: &'a [u8],
    /// Columns \[px\].
    pub width: usize,
    /// Rows \[px\].
    pub height: usize,
}

/// Where corners are looked for, how many and how far apart.
#[derive(Debug, Clone, Copy)]
pub struct CornerSearch<'a> {
    /// One byte per pixel (the image's layout): corners only where nonzero.
    pub mask: &'a [u8],
    /// Most corners returned.
    pub max_corners: usize,
    /// A corner's score must exceed this fraction of the best score in the mask.
    pub quality: f64,
    /// Least distance between two returned corners \[px\].
    pub min_distance: f64,
}

/// A Shi–Tomasi detector that keeps its per-pixel buffers between images
/// (fresh megabytes per frame cost more in page faults than the filters).
#[derive(Debug, Clone, Default)]
pub struct ShiTomasi {
    /// Gradient products `[xx, xy, yy]` per pixel.
    products: [Vec<f32>; 3],
    /// The score per pixel.
    score: Vec<f32>,
}

impl ShiTomasi {
    /// Corners of `image` under `search`, strongest first, as pixel
    /// coordinates `[u, v]` (pixel centres at integers). Empty when the image
    /// is smaller than 3×3, the mask's size differs from the image's, or
    /// nothing in the mask has texture.
    pub fn detect(&mut self, image: &GrayImage, search: &CornerSearch) -> Vec<[f32; 2]> {
        let (w, h) = (image.width, image.height);
        if w < 3 || h < 3 || image.pixels.len() != w * h || search.mask.len() != w * h || search.max_corners == 0 {
            return Vec::new();
        }
        self.min_eigenvalues(image);
        let score = &self.score;
        let best = score.iter().zip(search.mask).map(|(&s, &m)| if m != 0 { s } else { 0.0 }).fold(0.0f32, |a, b| {
            if b > a {
                b
            } else {
                a
            }
        });
        if best <= 0.0 {
            return Vec::new();
        }
        let threshold = (search.quality * best as f64) as f32;
        let mut candidates = local_maxima(score, w, h, search.mask, threshold);
        // Strongest first; between equal scores the later pixel first (OpenCV's order).
        candidates.sort_unstable_by(|a, b| score[*b].total_cmp(&score[*a]).then(b.cmp(a)));
        spaced(&candidates, w, h, search.min_distance, search.max_corners)
    }
}

/// Shi–Tomasi corners of `image` under `search` ([`ShiTomasi::detect`] with fresh buffers).
pub fn shi_tomasi(image: &GrayImage, search: &CornerSearch) -> Vec<[f32; 2]> {
    ShiTomasi::default().detect(image, search)
}

/// Interior pixels (not on the image's outer rows or columns) in the mask
/// whose score exceeds `threshold` and is not below any of its 8 neighbours'.
fn local_maxima(score: &[f32], w: usize, h: usize, mask: &[u8], threshold: f32) -> Vec<usize> {
    let mut out = Vec::new();
    for y in 1..h - 1 {
        for x in 1..w - 1 {
            let i = y * w + x;
            if mask[i] == 0 || score[i] <= threshold {
                continue;
            }
            let s = score[i];
            let peak =
                [i - w - 1, i - w, i - w + 1, i - 1, i + 1, i + w - 1, i + w, i + w + 1].iter().all(|&j| score[j] <= s);
            if peak {
                out.push(i);
            }
        }
    }
    out
}

/// The first `max` of `candidates` (pixel indices, in order of preference)
/// that lie at least `min_distance` from every one taken before, found
/// through a grid of cells `min_distance` wide.
fn spaced(candidates: &[usize], w: usize, h: usize, min_distance: f64, max: usize) -> Vec<[f32; 2]> {
    let cell = min_distance.max(1.0);
    let (gw, gh) = ((w as f64 / cell).ceil() as usize, (h as f64 / cell).ceil() as usize);
    let mut grid: Vec<Vec<[f32; 2]>> = vec![Vec::new(); gw * gh];
    let mut out = Vec::new();
    let d2 = (min_distance * min_distance) as f32;
    for &i in candidates {
        let p = [(i % w) as f32, (i / w) as f32];
        let (cx, cy) = ((p[0] as f64 / cell) as usize, (p[1] as f64 / cell) as usize);
        let near = (cy.saturating_sub(1)..(cy + 2).min(gh)).any(|gy| {
            (cx.saturating_sub(1)..(cx + 2).min(gw))
                .any(|gx| grid[gy * gw + gx].iter().any(|q| (q[0] - p[0]).powi(2) + (q[1] - p[1]).powi(2) < d2))
        });
        if near {
            continue;
        }
        grid[cy * gw + cx].push(p);
        out.push(p);
        if out.len() == max {
            break;
        }
    }
    out
}

/// Mirror index `i` (which may be −1 or `n`) into `0..n` without repeating
/// the edge (OpenCV's BORDER_REFLECT_101).
fn reflect(i: isize, n: usize) -> usize {
    if i < 0 {
        1
    } else if i as usize >= n {
        n - 2
    } else {
        i as usize
    }
}

impl ShiTomasi {
    /// The smaller eigenvalue of every pixel's structure tensor into
    /// `self.score`: 3×3 Sobel gradients scaled as OpenCV's
    /// `cornerMinEigenVal` scales them for 8-bit images (1 / (4·3·255)), their
    /// products summed over the 3×3 block, mirrored borders. Separable passes
    /// over whole rows, so that the compiler vectorizes them.
    fn min_eigenvalues(&mut self, image: &GrayImage) {
        let (w, h) = (image.width, image.height);
        let scale = 1.0 / (4.0 * 3.0 * 255.0);
        for buffer in self.products.iter_mut().chain([&mut self.score]) {
            buffer.resize(w * h, 0.0);
        }
        let [xx, xy, yy] = &mut self.products;
        let (mut smooth, mut diff) = (vec![0.0f32; w], vec![0.0f32; w]);
        let (mut dx, mut dy) = (vec![0.0f32; w], vec![0.0f32; w]);
        for y in 0..h {
            let row = |r: isize| &image.pixels[reflect(r, h) * w..][..w];
            let (above, here, below) = (row(y as isize - 1), row(y as isize), row(y as isize + 1));
            // Down the columns: [1 2 1] for d/dx, [−1 0 1] for d/dy.
            for (((s, d), (&a, &b)), &c) in
                smooth.iter_mut().zip(diff.iter_mut()).zip(above.iter().zip(here)).zip(below)
            {
                *s = a as f32 + 2.0 * b as f32 + c as f32;
                *d = c as f32 - a as f32;
            }
            // Along the row: [−1 0 1] and [1 2 1], mirrored at both ends.
            row_filters(&smooth, &diff, &mut dx, &mut dy);
            let span = y * w..(y + 1) * w;
            for ((((gx, gy), pxx), pxy), pyy) in
                dx.iter().zip(&dy).zip(&mut xx[span.clone()]).zip(&mut xy[span.clone()]).zip(&mut yy[span])
            {
                let (gx, gy) = (gx * scale, gy * scale);
                (*pxx, *pxy, *pyy) = (gx * gx, gx * gy, gy * gy);
            }
        }
        let mut sums = [vec![0.0f32; w], vec![0.0f32; w], vec![0.0f32; w]];
        let mut column = vec![0.0f32; w];
        for y in 0..h {
            let (a, b) = (reflect(y as isize - 1, h) * w, reflect(y as isize + 1, h) * w);
            for (sum, v) in sums.iter_mut().zip([&*xx, &*xy, &*yy]) {
                block_row(&v[a..a + w], &v[y * w..][..w], &v[b..b + w], &mut column, sum);
            }
            let [sxx, sxy, syy] = &sums;
            for (((out, &xx), &xy), &yy) in self.score[y * w..][..w].iter_mut().zip(sxx).zip(sxy).zip(syy) {
                let (a, c) = (0.5 * xx, 0.5 * yy);
                *out = (a + c) - ((a - c) * (a - c) + xy * xy).sqrt();
            }
        }
    }
}

/// One row of 3×3 block sums from the rows above, at and below it, mirrored
/// at the ends; `column` is scratch of the row's length.
fn block_row(above: &[f32], here: &[f32], below: &[f32], column: &mut [f32], out: &mut [f32]) {
    let w = out.len();
    for (((c, &a), &b), &d) in column.iter_mut().zip(above).zip(here).zip(below) {
        *c = a + b + d;
    }
    for (o, c) in out[1..w - 1].iter_mut().zip(column.windows(3)) {
        *o = c[0] + c[1] + c[2];
    }
    out[0] = 2.0 * column[1] + column[0];
    out[w - 1] = 2.0 * column[w - 2] + column[w - 1];
}

/// `dx = smooth[x+1] − smooth[x−1]` and `dy = diff[x−1] + 2·diff[x] + diff[x+1]`, mirrored at the ends.
fn row_filters(smooth: &[f32], diff: &[f32], dx: &mut [f32], dy: &mut [f32]) {
    let w = smooth.len();
    for (x, (gx, gy)) in dx.iter_mut().zip(dy.iter_mut()).enumerate().take(w - 1).skip(1) {
        *gx = smooth[x + 1] - smooth[x - 1];
        *gy = diff[x - 1] + 2.0 * diff[x] + diff[x + 1];
    }
    (dx[0], dy[0]) = (0.0, 2.0 * diff[1] + 2.0 * diff[0]);
    (dx[w - 1], dy[w - 1]) = (0.0, 2.0 * diff[w - 2] + 2.0 * diff[w - 1]);
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A checkerboard of `side`-pixel squares, offset by `origin`.
    fn checkerboard(w: usize, h: usize, side: usize, origin: usize) -> Vec<u8> {
        (0..w * h)
            .map(|i| {
                let (x, y) = ((i % w + side - origin) / side, (i / w + side - origin) / side);
                if (x + y) % 2 == 0 {
                    40
                } else {
                    220
                }
            })
            .collect()
    }

    #[test]
    fn corners_are_the_board_junctions_spaced_and_masked() {
        let (w, h, side) = (120, 90, 20);
        let pixels = checkerboard(w, h, side, 10);
        let image = GrayImage { pixels: &pixels, width: w, height: h };
        let mut mask = vec![255u8; w * h];
        let search = CornerSearch { mask: &mask, max_corners: 100, quality: 0.01, min_distance: 10.0 };
        let found = shi_tomasi(&image, &search);
        // Junctions at x = 10 + 20k, y = 10 + 20k, between pixel x−1 and x.
        let junctions: Vec<[f32; 2]> =
            (0..4).flat_map(|j| (0..6).map(move |i| [10.0 + 20.0 * i as f32, 10.0 + 20.0 * j as f32])).collect();
        assert_eq!(found.len(), junctions.len(), "{found:?}");
        for p in &found {
            let near = junctions.iter().any(|q| (q[0] - p[0]).abs() <= 1.0 && (q[1] - p[1]).abs() <= 1.0);
            assert!(near, "{p:?} is not at a junction");
        }
        for (k, p) in found.iter().enumerate() {
            for q in &found[..k] {
                assert!((p[0] - q[0]).hypot(p[1] - q[1]) >= 10.0);
            }
        }
        // Nothing where the mask is zero; at most max_corners.
        mask[..w * h / 2].fill(0);
        let search = CornerSearch { mask: &mask, max_corners: 3, quality: 0.01, min_distance: 10.0 };
        let found = shi_tomasi(&image, &search);
        assert_eq!(found.len(), 3);
        assert!(found.iter().all(|p| p[1] >= (h / 2) as f32));
    }

    #[test]
    fn flat_small_or_mismatched_images_give_no_corners() {
        let flat = vec![128u8; 50 * 40];
        let mask = vec![255u8; 50 * 40];
        let search = CornerSearch { mask: &mask, max_corners: 10, quality: 0.01, min_distance: 5.0 };
        assert!(shi_tomasi(&GrayImage { pixels: &flat, width: 50, height: 40 }, &search).is_empty());
        assert!(shi_tomasi(&GrayImage { pixels: &flat[..4], width: 2, height: 2 }, &search).is_empty());
        assert!(shi_tomasi(&GrayImage { pixels: &flat[..100], width: 10, height: 10 }, &search).is_empty());
    }
}
