//! The geometry of a pixel's square on a flat printed pattern: the
//! projective map between the image's square and its preimage on the
//! pattern, and the share of the square a convex polygon covers.

use nalgebra::{Matrix3, Vector3};

/// Most vertices a convex quadrilateral clipped to a square can have.
const MAX_VERTICES: usize = 8;

/// The projective map from the unit square's corners `(0, 0)`, `(1, 0)`,
/// `(1, 1)`, `(0, 1)` to `quad`'s (in that order; Heckbert 1989), acting on
/// homogeneous points `(s, t, 1)`. None for a quad with three corners on a line.
pub fn square_to_quad(quad: [[f64; 2]; 4]) -> Option<Matrix3<f64>> {
    let [[x0, y0], [x1, y1], [x2, y2], [x3, y3]] = quad;
    let (dx1, dx2, dx3) = (x1 - x2, x3 - x2, x0 - x1 + x2 - x3);
    let (dy1, dy2, dy3) = (y1 - y2, y3 - y2, y0 - y1 + y2 - y3);
    let det = dx1 * dy2 - dx2 * dy1;
    if det == 0.0 || !det.is_finite() {
        return None;
    }
    let g = (dx3 * dy2 - dx2 * dy3) / det;
    let h = (dx1 * dy3 - dx3 * dy1) / det;
    Some(Matrix3::new(x1 - x0 + g * x1, x3 - x0 + h * x3, x0, y1 - y0 + g * y1, y3 - y0 + h * y3, y0, g, h, 1.0))
}

/// The point `p` through the projective map `m`; None at or beyond its
/// line at infinity (a non-positive weight: the map folds there).
pub fn apply(m: &Matrix3<f64>, p: [f64; 2]) -> Option<[f64; 2]> {
    let q = m * Vector3::new(p[0], p[1], 1.0);
    (q.z > 0.0).then(|| [q.x / q.z, q.y / q.z])
}

/// The area of the convex polygon `polygon` (either orientation) within the
/// unit square `[0, 1]²` (Sutherland–Hodgman against its four sides).
pub fn area_in_unit_square(polygon: [[f64; 2]; 4]) -> f64 {
    let mut poly = [[0.0; 2]; MAX_VERTICES];
    poly[..4].copy_from_slice(&polygon);
    let mut n = 4;
    // Each side as (axis, bound, keep the side below the bound).
    for (axis, bound, below) in [(0, 0.0, false), (0, 1.0, true), (1, 0.0, false), (1, 1.0, true)] {
        let inside = |p: &[f64; 2]| if below { p[axis] <= bound } else { p[axis] >= bound };
        let mut out = [[0.0; 2]; MAX_VERTICES];
        let mut m = 0;
        for k in 0..n {
            let (a, b) = (poly[k], poly[(k + 1) % n]);
            if inside(&a) && m < MAX_VERTICES {
                out[m] = a;
                m += 1;
            }
            if inside(&a) != inside(&b) && m < MAX_VERTICES {
                let f = (bound - a[axis]) / (b[axis] - a[axis]);
                out[m] = [a[0] + f * (b[0] - a[0]), a[1] + f * (b[1] - a[1])];
                m += 1;
            }
        }
        (poly, n) = (out, m);
        if n < 3 {
            return 0.0;
        }
    }
    let twice: f64 = (0..n).map(|k| poly[k][0] * poly[(k + 1) % n][1] - poly[(k + 1) % n][0] * poly[k][1]).sum();
    0.5 * twice.abs()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_square_maps_to_its_quad_corner_by_corner() {
        let quad = [[2.0, 1.0], [5.0, 1.5], [4.5, 4.0], [1.5, 3.0]];
        let m = square_to_quad(quad).unwrap();
        for (k, s) in [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]].into_iter().enumerate() {
            let p = apply(&m, s).unwrap();
            assert!((p[0] - quad[k][0]).abs() < 1e-12 && (p[1] - quad[k][1]).abs() < 1e-12, "{p:?}");
        }
        assert!(square_to_quad([[0.0, 0.0], [1.0, 1.0], [2.0, 2.0], [3.0, 3.0]]).is_none());
    }

    #[test]
    fn a_polygon_covers_its_share_of_the_unit_square() {
        let square = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]];
        assert!((area_in_unit_square(square) - 1.0).abs() < 1e-15);
        // Shifted by (0.25, 0.5), clockwise: a quarter by a half remains.
        let shifted = [[0.25, 0.5], [0.25, 1.5], [1.25, 1.5], [1.25, 0.5]];
        assert!((area_in_unit_square(shifted) - 0.375).abs() < 1e-15);
        // A diamond about the right side's midpoint: its left half remains.
        let diamond = [[1.0, 0.0], [1.5, 0.5], [1.0, 1.0], [0.5, 0.5]];
        assert!((area_in_unit_square(diamond) - 0.25).abs() < 1e-15);
        assert_eq!(area_in_unit_square([[2.0, 2.0], [3.0, 2.0], [3.0, 3.0], [2.0, 3.0]]), 0.0);
    }
}
