//! A visual-inertial rig before a calibration target: the target's geometry
//! (Kalibr's AprilGrid or checkerboard), the corners each camera saw, the
//! recording a rig calibration reads, and a calibrated camera's description.
//! Reading and writing these is `io`'s ([`crate::io::target`]); detecting
//! corners and calibrating is `rig`'s; the simulator produces them.

use super::ImuData;
use nalgebra::Isometry3;
use std::path::PathBuf;
use tumble_factors::camera::CameraModel;
use tumble_factors::imu_preint::PreintegrationParams;

/// A calibration target in Kalibr's terms.
#[derive(Debug, Clone, PartialEq)]
pub enum Target {
    /// AprilGrid: `cols`×`rows` tags of side `size` \[m\], `spacing` the gap as a fraction of `size`.
    AprilGrid {
        /// Tags per row.
        cols: u32,
        /// Tag rows.
        rows: u32,
        /// Tag side \[m\].
        size: f64,
        /// Gap between tags as a fraction of `size`.
        spacing: f64,
    },
    /// Checkerboard: `cols`×`rows` inner corners, spaced `col_spacing` × `row_spacing` \[m\].
    Checkerboard {
        /// Inner corners per row.
        cols: u32,
        /// Inner-corner rows.
        rows: u32,
        /// Spacing along a row \[m\].
        col_spacing: f64,
        /// Spacing along a column \[m\].
        row_spacing: f64,
    },
}

impl Target {
    /// Number of corners: 4 per tag, or the inner corners of a checkerboard.
    pub fn corner_count(&self) -> usize {
        match *self {
            Target::AprilGrid { cols, rows, .. } => 4 * (cols * rows) as usize,
            Target::Checkerboard { cols, rows, .. } => (cols * rows) as usize,
        }
    }

    /// Whether the target can be printed: an AprilGrid needs no more tags
    /// than AprilTag 36h11 has codes (the reason when it does).
    pub fn check_tag_family(&self) -> Result<(), String> {
        let family = super::tag36h11::CODES.len();
        match *self {
            Target::AprilGrid { cols, rows, .. } if cols as usize * rows as usize > family => {
                Err(format!("an AprilGrid of {cols} × {rows} tags: AprilTag 36h11 has {family}"))
            }
            _ => Ok(()),
        }
    }

    /// Target-frame position \[m\] of corner `id` (z = 0): for an AprilGrid
    /// `id = 4·tag + corner` with Kalibr's layout (tag `row·cols + col`, corners
    /// counter-clockwise from the lower left: (0,0), (s,0), (s,s), (0,s));
    /// for a checkerboard `id = row·cols + col`. None for an id beyond the target.
    pub fn corner(&self, id: usize) -> Option<[f64; 3]> {
        if id >= self.corner_count() {
            return None;
        }
        Some(match *self {
            Target::AprilGrid { cols, size, spacing, .. } => {
                let (tag, c) = (id / 4, id % 4);
                let pitch = size * (1.0 + spacing);
                let (col, row) = ((tag % cols as usize) as f64, (tag / cols as usize) as f64);
                let (dx, dy) = [(0.0, 0.0), (size, 0.0), (size, size), (0.0, size)][c];
                [col * pitch + dx, row * pitch + dy, 0.0]
            }
            Target::Checkerboard { cols, col_spacing, row_spacing, .. } => {
                let (col, row) = ((id % cols as usize) as f64, (id / cols as usize) as f64);
                [col * col_spacing, row * row_spacing, 0.0]
            }
        })
    }
}

/// One detected corner: its id on the target, its target-frame position \[m\] and its pixel.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Corner {
    /// Corner id ([`Target::corner`]).
    pub id: usize,
    /// Position on the target \[m\].
    pub target: [f64; 3],
    /// Pixel in the raw (distorted) image \[px\].
    pub uv: [f64; 2],
}

/// One image of a camera: its stamp and the corners detected in it.
#[derive(Debug, Clone, PartialEq)]
pub struct View {
    /// Camera stamp \[ns\].
    pub t_ns: i64,
    /// Corners detected (possibly none).
    pub corners: Vec<Corner>,
}

/// One camera's detections.
#[derive(Debug, Clone, PartialEq)]
pub struct CameraCorners {
    /// Folder name (`cam0`).
    pub name: String,
    /// The corners file, or the images' `data.csv` when the corners were detected.
    pub path: PathBuf,
    /// Views in time order (every frame of `frames.csv`, or every stamp with corners).
    pub views: Vec<View>,
    /// Image size `[width, height]` \[px\] when known (`sensor.yaml` or the options).
    pub resolution: Option<[u32; 2]>,
    /// When the corners were detected in the images here (no `corners.csv`):
    /// what the detection found. The rig's output then holds them as `camN/corners.csv`.
    pub detection: Option<DetectionStats>,
}

/// The eight orders of a square's corners: `ORDERS[k][j]` is the target's
/// corner (Kalibr's 0–3, counter-clockwise from the lower left) of the
/// detector's corner `j`.
pub const ORDERS: [[usize; 4]; 8] =
    [[0, 1, 2, 3], [1, 2, 3, 0], [2, 3, 0, 1], [3, 0, 1, 2], [0, 3, 2, 1], [3, 2, 1, 0], [2, 1, 0, 3], [1, 0, 3, 2]];

/// The recording's corner order: the majority of the views' votes.
#[derive(Debug, Clone, PartialEq)]
pub struct OrderVote {
    /// The order used ([`ORDERS`] index).
    pub order: usize,
    /// Views that voted for it.
    pub agree: usize,
    /// Views that voted.
    pub voters: usize,
    /// Views whose tags do not follow the target's layout.
    pub off_layout: usize,
}

/// What the detection found in one camera.
#[derive(Debug, Clone, PartialEq)]
pub struct DetectionStats {
    /// Images read.
    pub frames: usize,
    /// Images with corners.
    pub frames_with_target: usize,
    /// Corners kept.
    pub corners: usize,
    /// Tag corners dropped by the refinement.
    pub dropped: usize,
    /// The AprilGrid's corner order and its vote.
    pub order: Option<OrderVote>,
    /// The images' size `[width, height]` \[px\] (all the same: an image of
    /// another size is refused).
    pub image_size: [u32; 2],
    /// Width of the AprilGrid tags' black border, in cells (2: Kalibr's
    /// print; 1: AprilTag's own tag images); None for a checkerboard, or
    /// when no tag was found.
    pub tag_border_cells: Option<usize>,
    /// Wall time \[s\].
    pub seconds: f64,
}

impl DetectionStats {
    /// One line for the terminal and the report.
    pub fn line(&self) -> String {
        let mut s = format!(
            "target in {} of {} images, {} corners ({} tag corners dropped by the sub-pixel refinement), {:.1} s",
            self.frames_with_target, self.frames, self.corners, self.dropped, self.seconds
        );
        if let Some(v) = &self.order {
            s.push_str(&format!("; tag corner order {:?} ({} of {} views agree)", ORDERS[v.order], v.agree, v.voters));
            if v.off_layout > 0 {
                s.push_str(&format!("; {} views off the target's layout left out", v.off_layout));
            }
        }
        if let Some(b) = self.tag_border_cells {
            s.push_str(&format!("; tags printed with a {b}-cell black border"));
        }
        s
    }
}

/// Everything a rig calibration reads.
#[derive(Debug, Clone)]
pub struct RigInput {
    /// IMU samples (corrected by the IMU calibration when one is given), times
    /// relative to `imu_t0_ns` \[s\].
    pub imu: ImuData,
    /// Absolute time of the IMU's first sample \[ns\].
    pub imu_t0_ns: i64,
    /// IMU noise in use (its integration scheme is ignored: the calibration
    /// always uses the midpoint rule).
    pub noise: PreintegrationParams,
    /// Where the noise came from.
    pub noise_source: String,
    /// The cameras' detections.
    pub cameras: Vec<CameraCorners>,
    /// The target.
    pub target: Target,
    /// Files read.
    pub sources: Vec<PathBuf>,
}

/// One camera of the rig, from an ASL `sensor.yaml`.
#[derive(Debug, Clone)]
pub struct RigCamera {
    /// Intrinsics and distortion.
    pub model: CameraModel,
    /// Width and height \[px\].
    pub resolution: [u32; 2],
    /// Frame rate \[Hz\].
    pub rate_hz: f64,
    /// IMU ← camera (a point in the camera frame mapped into the IMU frame).
    pub t_imu_cam: Isometry3<f64>,
    /// Its image topic.
    pub topic: String,
}
