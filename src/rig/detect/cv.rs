//! The detector itself, on OpenCV (feature `opencv`).

use super::{
    board_corners_are_junctions, checkerboard_corners, outer_square_centres, tag_corners, view_order, vote,
    TagDetection,
};
use crate::error::InputError;
use crate::model::target::DetectionStats;
use crate::model::target::{Target, View};
use opencv::core::{Mat, Point2f, Ptr, Size, TermCriteria, TermCriteria_Type, Vector};
use opencv::prelude::*;
use opencv::{aruco, calib3d, imgproc};
use rayon::prelude::*;
use std::path::PathBuf;

/// Images detected between two progress lines (and in parallel within them).
const CHUNK: usize = 64;

/// Smallest half-size of the refinement window \[px\] (a 5 × 5 window, Kalibr's).
const REFINE_HALF_WINDOW: i32 = 2;

/// Half-size of the refinement window as a share of the gap between tags in
/// the image (along the tag's shortest side, so foreshortening is allowed for).
const WINDOW_SHARE: f64 = 0.35;

/// Largest half-size of the refinement window \[px\], for tags seen large.
const MAX_HALF_WINDOW: i32 = 8;

/// The black borders a printed tag may have, in cells: Kalibr's AprilGrid
/// first (its `blackTagBorder`, 2), then AprilTag's and OpenCV's own tag
/// images (1). A decoder set for one border misreads the other's tags, so a
/// recording's first images that show tags decide which one it is.
const TAG_BORDERS: [i32; 2] = [2, 1];

struct Detector {
    dictionary: Ptr<aruco::Dictionary>,
    /// The ArUco parameters for each border of [`TAG_BORDERS`].
    parameters: Vec<Ptr<aruco::DetectorParameters>>,
}

enum Found {
    Tags(Vec<TagDetection>, usize),
    /// The board, when found.
    Board(Option<Board>),
}

/// A checkerboard found in an image.
struct Board {
    /// Its corners, in OpenCV's order \[px\].
    corners: Vec<[f64; 2]>,
    /// The grey levels beyond its four corners ([`outer_square_centres`]).
    shades: Option<[f64; 4]>,
}

/// What one image gave: its size \[px\] and what was found in it (an
/// AprilGrid's tags for each border tried).
type ImageResult = Result<([u32; 2], Vec<Found>), InputError>;

/// The mean grey level of the 3 × 3 pixels around `p` \[px\]; None beyond the image.
fn grey_around(img: &Mat, p: [f64; 2]) -> Option<f64> {
    let (c, r) = (p[0].round() as i32, p[1].round() as i32);
    if c < 1 || r < 1 || c + 1 >= img.cols() || r + 1 >= img.rows() {
        return None;
    }
    let mut sum = 0.0;
    for dr in -1..=1 {
        for dc in -1..=1 {
            sum += f64::from(*img.at_2d::<u8>(r + dr, c + dc).ok()?);
        }
    }
    Some(sum / 9.0)
}

fn cv_error(path: &std::path::Path, what: &str, e: impl std::fmt::Display) -> InputError {
    InputError::file(path, format!("{what}: {e}"))
}

impl Detector {
    fn new() -> opencv::Result<Detector> {
        Ok(Detector {
            dictionary: aruco::get_predefined_dictionary(aruco::PREDEFINED_DICTIONARY_NAME::DICT_APRILTAG_36h11)?,
            parameters: TAG_BORDERS
                .iter()
                .map(|&border| {
                    let mut p = aruco::DetectorParameters::create()?;
                    // Corners from lines fitted to the border's contour (sub-pixel, and
                    // blind to the grid's corner squares), then refined below.
                    p.set_corner_refinement_method(aruco::CORNER_REFINE_CONTOUR);
                    p.set_marker_border_bits(border);
                    Ok(p)
                })
                .collect::<opencv::Result<_>>()?,
        })
    }

    /// The target in the image at `path`; for an AprilGrid, the tags read
    /// with each border of `borders` (indices into [`TAG_BORDERS`]).
    fn detect(&self, target: &Target, path: &std::path::Path, borders: &[usize]) -> ImageResult {
        let img = crate::io::image::read_gray(path)?;
        let size = [img.cols().max(0) as u32, img.rows().max(0) as u32];
        let found = match *target {
            Target::AprilGrid { spacing, .. } => borders
                .iter()
                .map(|&b| self.tags(&img, spacing, &self.parameters[b]))
                .collect::<opencv::Result<Vec<Found>>>()
                .map_err(|e| cv_error(path, "AprilTag detection", e)),
            Target::Checkerboard { cols, rows, .. } => {
                let mut pts = Vector::<Point2f>::new();
                let size = Size::new(cols as i32, rows as i32);
                let flags = calib3d::CALIB_CB_EXHAUSTIVE | calib3d::CALIB_CB_ACCURACY;
                let found = calib3d::find_chessboard_corners_sb(&img, size, &mut pts, flags)
                    .map_err(|e| cv_error(path, "checkerboard detection", e))?;
                if found {
                    refine_board_corners(&img, &mut pts, cols as usize)
                        .map_err(|e| cv_error(path, "checkerboard corner refinement", e))?;
                }
                let pts: Vec<[f64; 2]> = pts.iter().map(|p| [p.x as f64, p.y as f64]).collect();
                let found = found && board_corners_are_junctions(&pts, cols as usize, &|p| grey_around(&img, p));
                let shades = outer_square_centres(&pts, cols as usize)
                    .and_then(|c| c.iter().map(|&p| grey_around(&img, p)).collect::<Option<Vec<f64>>>())
                    .map(|g| [g[0], g[1], g[2], g[3]]);
                Ok(vec![Found::Board(found.then_some(Board { corners: pts, shades }))])
            }
        }?;
        Ok((size, found))
    }

    fn tags(&self, img: &Mat, spacing: f64, parameters: &Ptr<aruco::DetectorParameters>) -> opencv::Result<Found> {
        let mut corners = Vector::<Vector<Point2f>>::new();
        let mut ids = Vector::<i32>::new();
        let mut rejected = Vector::<Vector<Point2f>>::new();
        aruco::detect_markers(img, &self.dictionary, &mut corners, &mut ids, parameters, &mut rejected)?;
        let criteria = subpix_criteria()?;
        let mut tags = Vec::with_capacity(ids.len());
        let mut dropped = 0;
        for (id, quad) in ids.iter().zip(corners.iter()) {
            if id < 0 || quad.len() != 4 {
                continue;
            }
            let raw: Vec<[f64; 2]> = quad.iter().map(|p| [p.x as f64, p.y as f64]).collect();
            let raw = [raw[0], raw[1], raw[2], raw[3]];
            // The window holds the X-junction of the tag and its corner square
            // alone: the square's next corner is a gap (spacing × side) away.
            let side = (0..4).map(|j| super::dist(raw[j], raw[(j + 1) % 4])).fold(f64::INFINITY, f64::min);
            let half = ((WINDOW_SHARE * spacing * side).floor() as i32).clamp(REFINE_HALF_WINDOW, MAX_HALF_WINDOW);
            let mut pts = quad.clone();
            imgproc::corner_sub_pix(img, &mut pts, Size::new(half, half), Size::new(-1, -1), criteria)?;
            let mut refined = [None; 4];
            for (j, r) in refined.iter_mut().enumerate() {
                let p = pts.get(j)?;
                let q = [p.x as f64, p.y as f64];
                // cornerSubPix puts a corner that left its window back where it
                // started: unmoved is a failure too.
                let moved = super::dist(q, raw[j]);
                if moved > 0.0 && moved <= half as f64 && q.iter().all(|v| v.is_finite()) {
                    *r = Some(q);
                } else {
                    dropped += 1;
                }
            }
            tags.push(TagDetection { id: id as usize, raw, refined });
        }
        Ok(Found::Tags(tags, dropped))
    }
}

/// Refine a checkerboard's corners to their X-junctions (`cornerSubPix`, as
/// Kalibr does), the window a third of the shortest distance between
/// neighbouring corners in the image (2 to 8 px either side). On rendered
/// boards `findChessboardCornersSB`'s own corners sit (+0.013, +0.009) px
/// from their exact projections on average (4 seeds); refined, within 0.001 px.
fn refine_board_corners(img: &Mat, pts: &mut Vector<Point2f>, cols: usize) -> opencv::Result<()> {
    let p: Vec<[f64; 2]> = pts.iter().map(|p| [p.x as f64, p.y as f64]).collect();
    let mut nearest = f64::INFINITY;
    for k in 0..p.len() {
        if (k + 1) % cols != 0 && k + 1 < p.len() {
            nearest = nearest.min(super::dist(p[k], p[k + 1]));
        }
        if k + cols < p.len() {
            nearest = nearest.min(super::dist(p[k], p[k + cols]));
        }
    }
    let half = ((nearest / 3.0).floor() as i32).clamp(REFINE_HALF_WINDOW, MAX_HALF_WINDOW);
    let criteria = subpix_criteria()?;
    imgproc::corner_sub_pix(img, pts, Size::new(half, half), Size::new(-1, -1), criteria)
}

/// When `cornerSubPix` stops: after 40 iterations or a move below 0.01 px.
fn subpix_criteria() -> opencv::Result<TermCriteria> {
    TermCriteria::new(TermCriteria_Type::COUNT as i32 + TermCriteria_Type::EPS as i32, 40, 0.01)
}

/// Tags found in the images of a batch by the detection at `index` (of each image's list).
fn tags_in(part: &[([u32; 2], Vec<Found>)], index: usize) -> usize {
    part.iter().map(|(_, f)| if let Some(Found::Tags(t, _)) = f.get(index) { t.len() } else { 0 }).sum()
}

/// The index, of `tried` detections per image, that found the most tags in
/// the batch (the first on a tie: Kalibr's border).
fn most_tags(part: &[([u32; 2], Vec<Found>)], tried: usize) -> usize {
    (0..tried).rev().max_by_key(|&k| tags_in(part, k)).unwrap_or(0)
}

/// Detect the target in every image of one camera (`frames`: stamp \[ns\] and
/// image path, in time order), with a progress line every few dozen images.
/// Every frame is kept as a view, with or without corners. Refused when no
/// image shows the target, or when the AprilGrid's tags do not follow the
/// target's layout in most views that show enough of it.
pub fn detect_camera(
    frames: &[(i64, PathBuf)],
    target: &Target,
    progress: &mut dyn FnMut(&str),
) -> Result<(Vec<View>, DetectionStats), InputError> {
    let start = std::time::Instant::now();
    let mut found = Vec::with_capacity(frames.len());
    let mut first_size: Option<[u32; 2]> = None;
    // The tags' border: undecided (every one tried) until images show tags.
    let mut border: Option<usize> = None;
    for (c, chunk) in frames.chunks(CHUNK).enumerate() {
        let tried: Vec<usize> = match (border, target) {
            (Some(b), _) => vec![b],
            (None, Target::AprilGrid { .. }) => (0..TAG_BORDERS.len()).collect(),
            (None, Target::Checkerboard { .. }) => vec![0],
        };
        let part: Vec<([u32; 2], Vec<Found>)> = chunk
            .par_iter()
            .map_init(Detector::new, |d, (_, path)| match d {
                Ok(d) => d.detect(target, path, &tried),
                Err(e) => Err(cv_error(path, "OpenCV's ArUco detector could not be created", &*e)),
            })
            .collect::<Result<_, InputError>>()?;
        let pick = most_tags(&part, tried.len());
        if border.is_none() && tags_in(&part, pick) > 0 {
            border = Some(tried[pick]);
        }
        for (k, (size, mut f)) in part.into_iter().enumerate() {
            let first = *first_size.get_or_insert(size);
            if first != size {
                return Err(InputError::file(
                    &chunk[k].1,
                    format!("is {}×{} px, the images before it {}×{}", size[0], size[1], first[0], first[1]),
                ));
            }
            found.push(f.swap_remove(pick));
        }
        let done = (c * CHUNK + chunk.len()).min(frames.len());
        if c % 8 == 7 || done == frames.len() {
            progress(&format!("  detecting the target: {done}/{} images", frames.len()));
        }
    }
    let mut stats = DetectionStats {
        frames: frames.len(),
        frames_with_target: 0,
        corners: 0,
        dropped: 0,
        order: None,
        image_size: first_size.unwrap_or([0, 0]),
        tag_border_cells: border.map(|b| TAG_BORDERS[b] as usize),
        seconds: 0.0,
    };
    let mut views: Vec<View> = frames.iter().map(|(t_ns, _)| View { t_ns: *t_ns, corners: Vec::new() }).collect();
    let folder = frames.first().and_then(|(_, p)| p.parent()).unwrap_or(std::path::Path::new("."));
    match target {
        Target::AprilGrid { .. } => {
            let orders: Vec<_> = found
                .iter()
                .map(|f| match f {
                    Found::Tags(tags, _) => view_order(tags, target),
                    Found::Board(_) => super::ViewOrder::Abstains,
                })
                .collect();
            let v = vote(&orders);
            if v.off_layout > v.voters {
                return Err(InputError::file(
                    folder,
                    format!(
                        "the tags follow the target's layout in only {} of {} views: the target file does not describe this grid",
                        v.voters,
                        v.voters + v.off_layout
                    ),
                )
                .with_hint("check tagCols and tagRows (tags are numbered row by row from the lower left)"));
            }
            if v.voters == 0 {
                return Err(InputError::file(folder, "no image shows four or more of the grid's tags off one line")
                    .with_hint(
                        "check the target file (tag family 36h11, tagCols, tagRows) and that the images show the grid",
                    ));
            }
            // A view whose tags do not follow the layout holds a misread or a
            // foreign tag: left out whole (counted in the vote's line).
            for ((view, f), o) in views.iter_mut().zip(&found).zip(&orders) {
                if *o == super::ViewOrder::OffLayout {
                    continue;
                }
                if let Found::Tags(tags, dropped) = f {
                    view.corners = tag_corners(tags, target, v.order);
                    stats.dropped += dropped;
                }
            }
            stats.order = Some(v);
        }
        Target::Checkerboard { .. } => {
            let mut previous: Option<usize> = None;
            for (k, f) in found.iter().enumerate() {
                if let Found::Board(Some(board)) = f {
                    let prev = previous.map(|p| views[p].corners.clone());
                    views[k].corners = checkerboard_corners(target, &board.corners, board.shades, prev.as_deref());
                    previous = Some(k);
                }
            }
        }
    }
    stats.frames_with_target = views.iter().filter(|v| !v.corners.is_empty()).count();
    stats.corners = views.iter().map(|v| v.corners.len()).sum();
    stats.seconds = start.elapsed().as_secs_f64();
    if stats.frames_with_target == 0 {
        return Err(InputError::file(folder, "the target was found in none of the images"));
    }
    Ok((views, stats))
}
