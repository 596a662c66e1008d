//! The target's corners found in the images, for a recording that has no
//! `camN/corners.csv` (the detector itself needs the cargo feature `opencv`).
//!
//! - **AprilGrid**: the tags are found by OpenCV's ArUco detector with its
//!   AprilTag 36h11 dictionary. Each tag corner is then refined to the
//!   X-junction it forms with the grid's corner squares (`cornerSubPix`, as
//!   Kalibr does). The window holds that junction alone: its half-size is a
//!   third of the gap between tags as the image shows it (at least 2 px).
//!   ArUco's own corners, from the border's contour, lie a pixel or two inside
//!   the tag and would be biased by that much. A corner the refinement cannot
//!   place within its window is dropped.
//! - **The tags' black border**: Kalibr prints 2 cells, AprilTag's and
//!   OpenCV's own tag images 1, and a decoder set for one misreads the
//!   other. Until images show tags each is tried; the one that finds more is
//!   kept for the recording and reported.
//! - **Which detected corner is which corner of the tag is not assumed.**
//!   Printed grids and detectors differ in the tag's orientation and in the
//!   order they list its corners. The tag centres do not depend on that order,
//!   so a homography from the target's tag centres to the detected ones
//!   predicts every corner of a view. Each view with four tags or more, not
//!   all on one line, votes for the order, among the eight of a square (four rotations,
//!   two directions), that fits its corners best. The recording's majority is
//!   used, and the vote is reported. A view whose tags do not follow the
//!   layout (a misread or foreign tag) is left out. The same fit checks the
//!   target file: when
//!   the tag centres do not follow its layout (wrong `tagCols`, a different
//!   grid), the detection is refused.
//! - **Checkerboard**: OpenCV's `findChessboardCornersSB`, each corner refined
//!   to its X-junction by `cornerSubPix` (the detector's own corners are
//!   about 0.01 px off on rendered boards). A checkerboard's corner order
//!   is ambiguous under a 180° turn. Each view takes the order closest to the previous view's, so the
//!   order stays continuous through a recording. The first view sets it; an
//!   AprilGrid has no such ambiguity and is the better target.

use super::init::homography;
use crate::model::target::{Corner, OrderVote, Target, ORDERS};
use nalgebra::Vector3;

/// Fewest tags, not all on one line, for a view to vote on the corner order.
const MIN_VOTING_TAGS: usize = 4;

/// Largest median distance between a detected tag centre and the homography's,
/// as a fraction of the tag's side in the image, for a view to follow the target's layout.
const LAYOUT_TOLERANCE: f64 = 0.25;

/// One tag as the detector reports it.
#[derive(Debug, Clone, PartialEq)]
pub struct TagDetection {
    /// Tag id (the AprilTag code's number).
    pub id: usize,
    /// The four corners in the detector's order \[px\], as detected.
    pub raw: [[f64; 2]; 4],
    /// The same corners after the sub-pixel refinement; None where it failed or moved too far.
    pub refined: [Option<[f64; 2]>; 4],
}

/// How a view's tags fit the target's layout.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ViewOrder {
    /// Too few tags, or all in one row or column: no vote.
    Abstains,
    /// The tag centres do not follow the target's layout.
    OffLayout,
    /// The best order ([`ORDERS`] index).
    Votes(usize),
}

fn mean(p: &[[f64; 2]; 4]) -> [f64; 2] {
    let s = p.iter().fold([0.0, 0.0], |a, q| [a[0] + q[0], a[1] + q[1]]);
    [s[0] / 4.0, s[1] / 4.0]
}

fn apply(h: &nalgebra::Matrix3<f64>, p: [f64; 3]) -> [f64; 2] {
    let q = h * Vector3::new(p[0], p[1], 1.0);
    [q.x / q.z, q.y / q.z]
}

fn dist(a: [f64; 2], b: [f64; 2]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)).sqrt()
}

/// Whether points lie on one line (a row, a column or a diagonal of tags):
/// their spread across the line is under a tenth of their spread along it, and
/// no homography follows from them.
fn collinear(p: &[[f64; 2]]) -> bool {
    let n = p.len() as f64;
    let m = p.iter().fold([0.0, 0.0], |a, q| [a[0] + q[0] / n, a[1] + q[1] / n]);
    let (mut sxx, mut sxy, mut syy) = (0.0, 0.0, 0.0);
    for q in p {
        let (dx, dy) = (q[0] - m[0], q[1] - m[1]);
        sxx += dx * dx;
        sxy += dx * dy;
        syy += dy * dy;
    }
    let half_trace = (sxx + syy) / 2.0;
    let root = ((sxx - syy).powi(2) / 4.0 + sxy * sxy).sqrt();
    let (small, large) = (half_trace - root, half_trace + root);
    large <= 0.0 || small < 0.01 * large
}

/// The corner order one view votes for (AprilGrid only; a checkerboard abstains).
pub fn view_order(tags: &[TagDetection], target: &Target) -> ViewOrder {
    let Target::AprilGrid { .. } = *target else { return ViewOrder::Abstains };
    let tags: Vec<&TagDetection> = tags.iter().filter(|t| target.corner(4 * t.id).is_some()).collect();
    let centre = |id: usize| {
        let c: Vec<[f64; 3]> = (0..4).filter_map(|k| target.corner(4 * id + k)).collect();
        [(c[0][0] + c[2][0]) / 2.0, (c[0][1] + c[2][1]) / 2.0]
    };
    let obj: Vec<[f64; 2]> = tags.iter().map(|t| centre(t.id)).collect();
    if tags.len() < MIN_VOTING_TAGS || collinear(&obj) {
        return ViewOrder::Abstains;
    }
    let img: Vec<[f64; 2]> = tags.iter().map(|t| mean(&t.raw)).collect();
    let Some(h) = homography(&obj, &img) else { return ViewOrder::Abstains };
    let mut off: Vec<f64> = tags
        .iter()
        .zip(&obj)
        .map(|(t, o)| {
            let side = (0..4).map(|j| dist(t.raw[j], t.raw[(j + 1) % 4])).sum::<f64>() / 4.0;
            dist(apply(&h, [o[0], o[1], 0.0]), mean(&t.raw)) / side.max(1e-9)
        })
        .collect();
    if crate::model::numeric::median(&mut off).is_none_or(|m| m > LAYOUT_TOLERANCE) {
        return ViewOrder::OffLayout;
    }
    let cost = |order: &[usize; 4]| -> f64 {
        tags.iter()
            .map(|t| {
                (0..4)
                    .filter_map(|j| target.corner(4 * t.id + order[j]).map(|p| dist(t.raw[j], apply(&h, p)).powi(2)))
                    .sum::<f64>()
            })
            .sum()
    };
    let best = (0..ORDERS.len()).min_by(|&a, &b| cost(&ORDERS[a]).total_cmp(&cost(&ORDERS[b]))).unwrap_or(0);
    ViewOrder::Votes(best)
}

/// Count the views' votes (`voters` is 0 when no view could vote: too few
/// tags off one line anywhere, or none following the layout).
pub fn vote(views: &[ViewOrder]) -> OrderVote {
    let mut counts = [0usize; 8];
    let mut off_layout = 0;
    for v in views {
        match v {
            ViewOrder::Votes(k) => counts[*k] += 1,
            ViewOrder::OffLayout => off_layout += 1,
            ViewOrder::Abstains => {}
        }
    }
    let voters: usize = counts.iter().sum();
    let (order, &agree) = counts.iter().enumerate().max_by_key(|(_, c)| **c).unwrap_or((0, &0));
    OrderVote { order, agree, voters, off_layout }
}

/// A view's corners from its tags in the recording's order (refined corners only),
/// sorted by corner id; tags beyond the target are left out.
pub fn tag_corners(tags: &[TagDetection], target: &Target, order: usize) -> Vec<Corner> {
    let mut out: Vec<Corner> = tags
        .iter()
        .flat_map(|t| {
            (0..4).filter_map(move |j| {
                let id = 4 * t.id + ORDERS[order][j];
                Some(Corner { id, target: target.corner(id)?, uv: t.refined[j]? })
            })
        })
        .collect();
    out.sort_by_key(|c| c.id);
    out
}

/// A checkerboard view's corners from OpenCV's list (row by row, `cols` per
/// row). The list is taken with the rows reversed when it is mirrored: seen
/// from its printed side, the target's x axis turns counter-clockwise on the
/// screen into its y axis, and an order that does not is no pose of the
/// board. Of the two orders left (a half turn apart):
/// - on a board whose squares differ in parity along its two sides (inner
///   corners `cols + rows` odd) the colours tell them apart: corner 0 is the
///   one whose outer square is dark. `shades` are the grey levels of the
///   image at the centres of the squares beyond the list's four corners
///   ([`outer_square_centres`]'s order); a view whose two candidate squares
///   differ by less than [`MIN_SHADE_CONTRAST`] is not decided so;
/// - otherwise the order closer to the previous view's is taken.
pub fn checkerboard_corners(
    target: &Target,
    pts: &[[f64; 2]],
    shades: Option<[f64; 4]>,
    previous: Option<&[Corner]>,
) -> Vec<Corner> {
    let n = target.corner_count();
    let Target::Checkerboard { cols, .. } = *target else { return Vec::new() };
    let cols = cols as usize;
    if pts.len() != n || n < 2 * cols || cols < 2 {
        return Vec::new();
    }
    let rows = n / cols;
    let (dx, dy) =
        ([pts[1][0] - pts[0][0], pts[1][1] - pts[0][1]], [pts[cols][0] - pts[0][0], pts[cols][1] - pts[0][1]]);
    let mirrored = dx[0] * dy[1] - dx[1] * dy[0] > 0.0;
    let pts: Vec<[f64; 2]> =
        if mirrored { (0..n).map(|k| pts[(rows - 1 - k / cols) * cols + k % cols]).collect() } else { pts.to_vec() };
    let index = |flip: bool, k: usize| if flip { n - 1 - k } else { k };
    // The shades beyond the (unmirrored) list's first and last corners: of
    // the raw list's lower-left/upper-right pair when mirrored.
    let by_colour = shades.filter(|_| (cols + rows) % 2 == 1).and_then(|s| {
        let (first, last) = if mirrored { (s[2], s[1]) } else { (s[0], s[3]) };
        ((first - last).abs() >= MIN_SHADE_CONTRAST * (first + last)).then_some(first > last)
    });
    let gap = |flip: bool| match previous {
        Some(prev) => prev.iter().map(|c| dist(c.uv, pts[index(flip, c.id)])).sum::<f64>(),
        None => 0.0,
    };
    let flip = by_colour.unwrap_or_else(|| previous.is_some_and(|p| !p.is_empty()) && gap(true) < gap(false));
    (0..n).filter_map(|id| Some(Corner { id, target: target.corner(id)?, uv: pts[index(flip, id)] })).collect()
}

/// Whether every corner of a checkerboard view (`pts`, `cols` per row) is an
/// X-junction in the image `grey` samples: of the four squares about it,
/// sampled 0.3 of the local corner spacing along both grid directions, the
/// two on one diagonal match and differ from the two on the other by at
/// least [`MIN_JUNCTION_CONTRAST`] of the view's strongest junction. A board
/// partly outside the image can be "found" with a row or column made up of
/// its outer squares' corners against the margin (one dark square, three
/// light) or of the wall behind it: such a view is refused, not mislabelled.
pub fn board_corners_are_junctions(pts: &[[f64; 2]], cols: usize, grey: &dyn Fn([f64; 2]) -> Option<f64>) -> bool {
    if cols < 2 || pts.len() < 2 * cols || pts.len() % cols != 0 {
        return false;
    }
    let rows = pts.len() / cols;
    let at = |r: usize, c: usize| nalgebra::Vector2::from(pts[r * cols + c]);
    // The step to the next corner along a row and a column, inwards at the edges.
    let step = |r: usize, c: usize| {
        let a = if c + 1 < cols { at(r, c + 1) - at(r, c) } else { at(r, c) - at(r, c - 1) };
        let b = if r + 1 < rows { at(r + 1, c) - at(r, c) } else { at(r, c) - at(r - 1, c) };
        (a, b)
    };
    let mut junctions = Vec::with_capacity(pts.len());
    for r in 0..rows {
        for c in 0..cols {
            let (a, b) = step(r, c);
            let p = at(r, c);
            let q = |sa: f64, sb: f64| grey((p + (a * sa + b * sb) * JUNCTION_REACH).into());
            let (Some(pp), Some(mm), Some(pm), Some(mp)) = (q(1.0, 1.0), q(-1.0, -1.0), q(1.0, -1.0), q(-1.0, 1.0))
            else {
                return false;
            };
            let contrast = (0.5 * (pp + mm) - 0.5 * (pm + mp)).abs();
            junctions.push((contrast, (pp - mm).abs().max((pm - mp).abs())));
        }
    }
    let strongest = junctions.iter().map(|j| j.0).fold(0.0, f64::max);
    strongest > 0.0
        && junctions
            .iter()
            .all(|&(contrast, mismatch)| contrast >= MIN_JUNCTION_CONTRAST * strongest && mismatch <= 0.5 * contrast)
}

/// How far from a corner its four squares are sampled, in corner spacings
/// along each grid direction (inside the squares, clear of their edges under blur).
const JUNCTION_REACH: f64 = 0.3;

/// Smallest contrast of a board's junction, as a share of the view's strongest.
pub const MIN_JUNCTION_CONTRAST: f64 = 0.3;

/// Smallest difference of the two candidate outer squares' grey levels, as
/// a share of their sum, for the colours to decide a checkerboard's order
/// (printed black and white differ by over 0.8; blur and glare by less).
pub const MIN_SHADE_CONTRAST: f64 = 0.2;

/// The image points at the centres of the squares beyond the four corners of
/// a checkerboard's list (`cols` per row): beyond the first row's first and
/// last corners, then the last row's first and last — half a corner spacing
/// outwards along both of the grid's directions there.
pub fn outer_square_centres(pts: &[[f64; 2]], cols: usize) -> Option<[[f64; 2]; 4]> {
    if cols < 2 || pts.len() < 2 * cols || pts.len() % cols != 0 {
        return None;
    }
    let rows = pts.len() / cols;
    let at = |r: usize, c: usize| pts[r * cols + c];
    let centre = |r: usize, c: usize| {
        let (rn, cn) = (if r == 0 { 1 } else { r - 1 }, if c == 0 { 1 } else { c - 1 });
        let (p, pr, pc) = (at(r, c), at(rn, c), at(r, cn));
        [0, 1].map(|i| p[i] + 0.5 * (p[i] - pr[i]) + 0.5 * (p[i] - pc[i]))
    };
    Some([centre(0, 0), centre(0, cols - 1), centre(rows - 1, 0), centre(rows - 1, cols - 1)])
}

#[cfg(feature = "opencv")]
mod cv;
#[cfg(feature = "opencv")]
pub use cv::detect_camera;

#[cfg(test)]
mod tests {
    use super::*;

    fn grid() -> Target {
        Target::AprilGrid { cols: 6, rows: 6, size: 0.088, spacing: 0.3 }
    }

    /// Tags seen through a homography, their corners listed in `order`'s inverse.
    fn seen(ids: &[usize], order: usize) -> Vec<TagDetection> {
        let t = grid();
        let h = nalgebra::Matrix3::new(900.0, 40.0, 120.0, -30.0, -880.0, 400.0, 0.05, 0.1, 1.0);
        ids.iter()
            .map(|&id| {
                let mut raw = [[0.0; 2]; 4];
                for (j, r) in raw.iter_mut().enumerate() {
                    *r = apply(&h, t.corner(4 * id + ORDERS[order][j]).unwrap());
                }
                TagDetection { id, raw, refined: raw.map(Some) }
            })
            .collect()
    }

    #[test]
    fn every_corner_order_is_recovered_from_the_layout() {
        for (order, perm) in ORDERS.iter().enumerate() {
            let tags = seen(&[0, 1, 6, 7, 14, 20], order);
            assert_eq!(view_order(&tags, &grid()), ViewOrder::Votes(order), "order {order}");
            let corners = tag_corners(&tags, &grid(), order);
            assert_eq!(corners.len(), 24);
            let tag0 = &tags[0];
            let c0 = corners.iter().find(|c| c.id == 0).unwrap();
            assert_eq!(c0.uv, tag0.raw[perm.iter().position(|&k| k == 0).unwrap()]);
        }
    }

    #[test]
    fn one_row_abstains_and_a_wrong_layout_is_found() {
        assert_eq!(view_order(&seen(&[0, 1, 2, 3, 4], 0), &grid()), ViewOrder::Abstains);
        // A diagonal spans rows and columns and is still a line.
        assert_eq!(view_order(&seen(&[0, 7, 14, 21, 28], 0), &grid()), ViewOrder::Abstains);
        // The same tags read against a grid of 5 columns: ids land in other places.
        let five = Target::AprilGrid { cols: 5, rows: 7, size: 0.088, spacing: 0.3 };
        assert_eq!(view_order(&seen(&[0, 1, 6, 7, 14, 20, 33], 0), &five), ViewOrder::OffLayout);
        let v = vote(&[ViewOrder::Votes(3), ViewOrder::Votes(3), ViewOrder::OffLayout, ViewOrder::Abstains]);
        assert_eq!((v.order, v.agree, v.voters, v.off_layout), (3, 2, 2, 1));
        assert_eq!(vote(&[ViewOrder::Abstains]).voters, 0);
    }

    #[test]
    fn a_checkerboard_keeps_its_order_through_a_half_turn_ambiguity() {
        let t = Target::Checkerboard { cols: 4, rows: 3, col_spacing: 0.05, row_spacing: 0.05 };
        let pts: Vec<[f64; 2]> =
            (0..12).map(|k| [100.0 + 30.0 * (k % 4) as f64, 50.0 + 30.0 * (k / 4) as f64]).collect();
        let first = checkerboard_corners(&t, &pts, None, None);
        let mut reversed = pts.clone();
        reversed.reverse();
        let second = checkerboard_corners(&t, &reversed, None, Some(&first));
        assert_eq!(first, second);
        assert!(checkerboard_corners(&t, &pts[..11], None, None).is_empty());
    }

    /// A drawn board: corners 30 px apart from (100, 50), squares alternating
    /// dark and light, a light margin of one square, a wall beyond that.
    fn drawn_board(p: [f64; 2]) -> Option<f64> {
        let (x, y) = ((p[0] - 100.0) / 30.0, (p[1] - 50.0) / 30.0);
        if !(-2.0..7.0).contains(&x) || !(-2.0..6.0).contains(&y) {
            return Some(120.0);
        }
        if !(-1.0..6.0).contains(&x) || !(-1.0..5.0).contains(&y) {
            return Some(230.0);
        }
        Some(if (x.floor() as i64 + y.floor() as i64).rem_euclid(2) == 0 { 20.0 } else { 230.0 })
    }

    #[test]
    fn a_board_whose_corners_are_not_all_junctions_is_refused() {
        // 6 × 5 inner corners at x 0..5, y 0..4 of the drawn board.
        let board = |x0: f64, y0: f64| -> Vec<[f64; 2]> {
            (0..30).map(|k| [100.0 + 30.0 * (x0 + (k % 6) as f64), 50.0 + 30.0 * (y0 + (k / 6) as f64)]).collect()
        };
        assert!(board_corners_are_junctions(&board(0.0, 0.0), 6, &drawn_board));
        // One row too high: its corners are the outer squares' against the margin.
        assert!(!board_corners_are_junctions(&board(0.0, -1.0), 6, &drawn_board));
        // One column too far right: into the margin and the wall.
        assert!(!board_corners_are_junctions(&board(1.0, 0.0), 6, &drawn_board));
        // Beyond the image.
        assert!(!board_corners_are_junctions(&board(0.0, 0.0), 6, &|p| drawn_board(p).filter(|_| p[0] < 200.0)));
    }

    /// On a board of 5 × 4 squares the squares beyond corner 0 and the last
    /// corner differ in colour: the order follows the colours, whatever the
    /// previous view says, and a list given in reverse gives the same corners.
    #[test]
    fn a_checkerboard_order_follows_its_colours_where_they_differ() {
        let t = Target::Checkerboard { cols: 4, rows: 3, col_spacing: 0.05, row_spacing: 0.05 };
        let pts: Vec<[f64; 2]> =
            (0..12).map(|k| [100.0 + 30.0 * (k % 4) as f64, 50.0 + 30.0 * (k / 4) as f64]).collect();
        let centres = outer_square_centres(&pts, 4).unwrap();
        assert_eq!(centres[0], [85.0, 35.0]);
        assert_eq!(centres[3], [205.0, 125.0]);
        // Beyond the first row dark, beyond the last light (the raw list's four corners).
        let shades = [20.0, 20.0, 230.0, 230.0];
        let a = checkerboard_corners(&t, &pts, Some(shades), None);
        let mut reversed = pts.clone();
        reversed.reverse();
        let misleading: Vec<Corner> = a.iter().map(|c| Corner { uv: a[11 - c.id].uv, ..*c }).collect();
        let b = checkerboard_corners(&t, &reversed, Some([230.0, 230.0, 20.0, 20.0]), Some(&misleading));
        assert_eq!(a, b);
        // Dark at the other end: the other order.
        let c = checkerboard_corners(&t, &pts, Some([230.0, 230.0, 20.0, 20.0]), None);
        assert_eq!(c[0].uv, a[11].uv);
        // Too little contrast, or a board whose two ends match: continuity decides.
        let d = checkerboard_corners(&t, &pts, Some([120.0, 120.0, 110.0, 110.0]), Some(&misleading));
        assert_eq!(d[0].uv, a[11].uv);
        let square = Target::Checkerboard { cols: 4, rows: 4, col_spacing: 0.05, row_spacing: 0.05 };
        let pts16: Vec<[f64; 2]> =
            (0..16).map(|k| [100.0 + 30.0 * (k % 4) as f64, 50.0 + 30.0 * (k / 4) as f64]).collect();
        let e = checkerboard_corners(&square, &pts16, Some([20.0, 230.0, 230.0, 230.0]), None);
        let f = checkerboard_corners(&square, &pts16, Some([230.0, 230.0, 230.0, 20.0]), None);
        assert_eq!(e, f);
    }
}
