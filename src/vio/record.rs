//! Recording a VIO run for the [rerun](https://rerun.io) viewer (cargo feature
//! `rerun`): camera images with the tracked features, the body pose, the
//! window's keyframes, its landmarks, the ground truth, and the biases as
//! time series — all on one timeline `time` (seconds on the input's time axis).
//!
//! Open the file with the viewer of the same version:
//! `pip install rerun-sdk==0.36.3 && rerun out.rrd`.
//!
//! Entities (world frame of the estimator: z up, origin and yaw at the first state):
//!
//! | entity | what |
//! |---|---|
//! | `world/body` | body pose per frame (Transform3D) |
//! | `world/body/camera` | `T_BC` and the pinhole model (static) |
//! | `world/body/camera/image` | the frame's image, when image files are given |
//! | `world/body/camera/image/features` | the frame's feature observations \[px\] |
//! | `world/trajectory` | estimated positions so far (line strip, once a second), of the current piece |
//! | `world/window` | positions of the window's states |
//! | `world/landmarks` | the window's landmarks \[m\] |
//! | `world/groundtruth` | ground truth, aligned at the current piece's first state (static) |
//! | `biases/{accel,gyro}/{x,y,z}` | estimated biases \[m/s², rad/s\] |
//! | `biases/{accel,gyro}_truth/{x,y,z}` | ground-truth biases, when known |
//! | `status/{landmarks,solve_ms}` | landmarks in the window, solve time |
//! | `status/window_length_sigma_pct` | at keyframes: the window's length σ in % of it, the bound on its scale's σ (`vio::WindowLength`) |
//! | `status/events` | estimates withdrawn (text) |
//!
//! When the estimator withdraws estimates and starts again at the origin
//! ([`Estimator::withdrawals`]), the trajectory's line strip begins again
//! with the new piece, the ground truth is aligned again at its first state,
//! and `status/events` says from when the estimates were withdrawn (they stay
//! on the timeline, where they were estimated, but out of `tumble vio`'s files).
//!
//! ```no_run
//! use tumble::sim::{simulate, Scenario, SimConfig};
//! use tumble::vio::{record::Recorder, run_observed, VioInput, VioOptions};
//! let sim = simulate(Scenario::Walk, &SimConfig::default(), 1).unwrap();
//! let input = VioInput::from_simulation(&sim).unwrap();
//! let mut rec = Recorder::create("walk.rrd".as_ref(), &input).unwrap();
//! let out = run_observed(&input, &VioOptions::default(), None, &mut |est, i, e| rec.frame(est, i, e)).unwrap();
//! rec.finish().unwrap();
//! ```

use super::VioError;
use super::{Estimator, FrameEstimate, VioInput};
use crate::eval::{biases_at, iso, pose_at};
use nalgebra::{Point3, UnitQuaternion, Vector3};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// Longest run of positions in one `world/trajectory` line strip (older
/// positions are thinned so the file grows linearly with the run).
const TRAJECTORY_POINTS: usize = 1000;

/// Longest ground-truth gap interpolated across \[ns\] (as `tumble eval`'s default).
const MAX_TRUTH_GAP_NS: f64 = 0.1e9;

/// Writes a VIO run into an `.rrd` file, frame by frame.
pub struct Recorder<'a> {
    rec: rerun::RecordingStream,
    path: PathBuf,
    input: &'a VioInput,
    /// Image file by frame time \[ns\] (absolute, as the dataset's file names).
    images: BTreeMap<i64, PathBuf>,
    /// The current piece's positions.
    trajectory: Vec<[f32; 3]>,
    last_strip_t: f64,
    groundtruth_logged: bool,
    /// Withdrawals ([`Estimator::withdrawals`]) already acted on.
    withdrawals_seen: usize,
    /// The first logging error met (logging goes on without it: a viewer file
    /// is not worth stopping an estimate for), reported by [`Recorder::finish`].
    error: Option<String>,
    /// Images that could not be read.
    warnings: Vec<String>,
}

fn f32x3(p: &[f64; 3]) -> [f32; 3] {
    [p[0] as f32, p[1] as f32, p[2] as f32]
}

fn transform(p: &[f64; 3], q: &[f64; 4]) -> rerun::Transform3D {
    rerun::Transform3D::from_translation_rotation(
        f32x3(p),
        rerun::Quaternion::from_wxyz([q[0] as f32, q[1] as f32, q[2] as f32, q[3] as f32]),
    )
}

impl<'a> Recorder<'a> {
    /// Create `path` (and its folder) and log what does not change: the world's up axis, the
    /// camera's mounting and pinhole model (resolution taken as twice the
    /// principal point; distortion is not drawn).
    pub fn create(path: &Path, input: &'a VioInput) -> Result<Self, VioError> {
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir).map_err(|e| format!("{}: cannot create the folder: {e}", dir.display()))?;
        }
        let rec = rerun::RecordingStreamBuilder::new("tumble")
            .save(path)
            .map_err(|e| format!("{}: cannot write the rerun recording: {e}", path.display()))?;
        let mut r = Recorder {
            rec,
            path: path.to_path_buf(),
            input,
            images: BTreeMap::new(),
            trajectory: Vec::new(),
            last_strip_t: f64::NEG_INFINITY,
            groundtruth_logged: false,
            withdrawals_seen: 0,
            error: None,
            warnings: Vec::new(),
        };
        let cam = &input.camera;
        let (r_bc, p) = crate::model::geometry::parts(&input.body_from_camera);
        let q = UnitQuaternion::from_matrix(&r_bc);
        let result = (|| {
            r.rec.log_static("world", &rerun::ViewCoordinates::RIGHT_HAND_Z_UP())?;
            r.rec.log_static("world/body/camera", &transform(&[p.x, p.y, p.z], &[q.w, q.i, q.j, q.k]))?;
            r.rec.log_static(
                "world/body/camera",
                &rerun::Pinhole::from_focal_length_and_resolution(
                    [cam.fx as f32, cam.fy as f32],
                    [(2.0 * cam.cx) as f32, (2.0 * cam.cy) as f32],
                )
                .with_principal_point([cam.cx as f32, cam.cy as f32]),
            )
        })();
        r.check(result);
        match r.error.take() {
            Some(e) => Err(e.into()),
            None => Ok(r),
        }
    }

    /// Log these camera images (time \[ns\], absolute like
    /// [`VioInput::t0_ns`], and file) at the frames with the same time.
    pub fn with_images(mut self, images: impl IntoIterator<Item = (i64, PathBuf)>) -> Self {
        self.images.extend(images);
        self
    }

    fn check<E: std::fmt::Display>(&mut self, r: Result<(), E>) {
        if let (Err(e), None) = (r, &self.error) {
            self.error = Some(format!("{}: rerun: {e}", self.path.display()));
        }
    }

    /// Log frame `index` of the input after the estimator processed it into `e`.
    pub fn frame(&mut self, est: &Estimator, index: usize, e: &FrameEstimate) {
        let frame = &self.input.frames[index];
        self.rec.set_duration_secs("time", e.t);
        let new = est.withdrawals().get(self.withdrawals_seen..).unwrap_or_default();
        if !new.is_empty() {
            // A new piece, at the origin: its own strip and its own alignment of the truth.
            self.trajectory.clear();
            self.last_strip_t = f64::NEG_INFINITY;
            self.groundtruth_logged = false;
        }
        for from in new {
            let text = format!(
                "the estimates from {from:.3} s on are withdrawn (the run's warnings say why); \
                 the estimate begins again at the origin"
            );
            let r = self.rec.log("status/events", &rerun::TextLog::new(text).with_level(rerun::TextLogLevel::WARN));
            self.check(r);
        }
        self.withdrawals_seen = est.withdrawals().len();
        if !self.groundtruth_logged {
            self.groundtruth_logged = true;
            let r = self.log_groundtruth(e);
            self.check(r);
        }
        let r = self.log_frame(est, frame, e);
        self.check(r);
    }

    fn log_frame(
        &mut self,
        est: &Estimator,
        frame: &super::Frame,
        e: &FrameEstimate,
    ) -> Result<(), rerun::RecordingStreamError> {
        let rec = &self.rec;
        rec.log("world/body", &transform(&e.position, &e.rotation))?;
        if let Some(file) = self.images.get(&self.t_ns(frame.t)) {
            match rerun::EncodedImage::from_file(file) {
                Ok(img) => rec.log("world/body/camera/image", &img)?,
                Err(err) => self.warnings.push(format!(
                    "rerun recording: {}: cannot read the image ({err}); frame at {:.3} s recorded without it",
                    file.display(),
                    frame.t
                )),
            }
        }
        let uv: Vec<[f32; 2]> = frame.features.iter().map(|(_, uv)| [uv[0] as f32, uv[1] as f32]).collect();
        rec.log("world/body/camera/image/features", &rerun::Points2D::new(uv).with_radii([2.0]))?;
        let window: Vec<[f32; 3]> = est.window().iter().map(|s| f32x3(&s.position)).collect();
        rec.log("world/window", &rerun::Points3D::new(window).with_radii([0.03]).with_colors([[255, 160, 0]]))?;
        let landmarks: Vec<[f32; 3]> = est.landmarks().iter().map(|(_, p)| f32x3(p)).collect();
        rec.log("world/landmarks", &rerun::Points3D::new(landmarks).with_radii([0.02]))?;
        self.trajectory.push(f32x3(&e.position));
        if e.t - self.last_strip_t >= 1.0 {
            self.last_strip_t = e.t;
            let step = self.trajectory.len().div_ceil(TRAJECTORY_POINTS);
            let mut strip: Vec<[f32; 3]> = self.trajectory.iter().step_by(step).copied().collect();
            strip.push(*self.trajectory.last().expect("just pushed"));
            rec.log("world/trajectory", &rerun::LineStrips3D::new([strip]).with_colors([[0, 120, 255]]))?;
        }
        for (name, b) in [("accel", &e.bias_accel), ("gyro", &e.bias_gyro)] {
            for (axis, v) in ["x", "y", "z"].iter().zip(b) {
                rec.log(format!("biases/{name}/{axis}"), &rerun::Scalars::single(*v))?;
            }
        }
        if let Some((ba, bg)) = self.truth_biases(frame.t) {
            for (name, b) in [("accel_truth", ba), ("gyro_truth", bg)] {
                for (axis, v) in ["x", "y", "z"].iter().zip(b) {
                    rec.log(format!("biases/{name}/{axis}"), &rerun::Scalars::single(v))?;
                }
            }
        }
        rec.log("status/landmarks", &rerun::Scalars::single(e.landmarks as f64))?;
        if let Some(w) = e.window_length.filter(|w| w.length_m >= crate::vio::WINDOW_MIN_LENGTH_M) {
            rec.log("status/window_length_sigma_pct", &rerun::Scalars::single(100.0 * w.sigma_m / w.length_m))?;
        }
        rec.log("status/solve_ms", &rerun::Scalars::single(e.solve_s * 1e3))
    }

    /// Absolute time \[ns\] of input time `t` \[s\].
    fn t_ns(&self, t: f64) -> i64 {
        self.input.t0_ns + (t * 1e9).round() as i64
    }

    fn truth_biases(&self, t: f64) -> Option<([f64; 3], [f64; 3])> {
        biases_at(self.input.groundtruth.as_ref()?, self.t_ns(t), MAX_TRUTH_GAP_NS)
    }

    /// The ground truth as a static line strip, moved so that its pose at the
    /// first estimate coincides with that estimate.
    fn log_groundtruth(&self, first: &FrameEstimate) -> Result<(), rerun::RecordingStreamError> {
        let Some(gt) = self.input.groundtruth.as_ref() else { return Ok(()) };
        let Some(truth) = pose_at(gt, self.t_ns(first.t), MAX_TRUTH_GAP_NS) else { return Ok(()) };
        let align = iso(first.position, first.rotation) * truth.inverse();
        let step = gt.len().div_ceil(20 * TRAJECTORY_POINTS).max(1);
        let strip: Vec<[f32; 3]> =
            gt.p.iter()
                .step_by(step)
                .map(|p| {
                    let w: Point3<f64> = align * Point3::from(Vector3::from(*p));
                    [w.x as f32, w.y as f32, w.z as f32]
                })
                .collect();
        self.rec.log_static("world/groundtruth", &rerun::LineStrips3D::new([strip]).with_colors([[0, 200, 80]]))
    }

    /// Flush the file; returns it and the warnings (images that could not be
    /// read), or the first error met while logging.
    pub fn finish(self) -> Result<(PathBuf, Vec<String>), VioError> {
        self.rec.flush_blocking().map_err(|e| format!("{}: rerun: {e}", self.path.display()))?;
        match self.error {
            Some(e) => Err(e.into()),
            None => Ok((self.path, self.warnings)),
        }
    }
}

/// What an `.rrd` file holds: rows per entity path (static rows included).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RrdContents {
    /// Rows logged per entity path (e.g. `/world/body`).
    pub rows: BTreeMap<String, u64>,
}

impl RrdContents {
    /// Rows of `entity` (with or without the leading `/`), 0 when absent.
    pub fn rows_of(&self, entity: &str) -> u64 {
        let key = if entity.starts_with('/') { entity.to_string() } else { format!("/{entity}") };
        self.rows.get(&key).copied().unwrap_or(0)
    }
}

/// Read an `.rrd` file back (e.g. to check what a run recorded).
pub fn read_rrd(path: &Path) -> Result<RrdContents, VioError> {
    use re_log_encoding::DecoderApp;
    let err = |e: &dyn std::fmt::Display| format!("{}: not a readable rerun recording: {e}", path.display());
    let file = std::fs::File::open(path).map_err(|e| format!("{}: {e}", path.display()))?;
    let decoder = DecoderApp::decode_eager(std::io::BufReader::new(file)).map_err(|e| err(&e))?;
    let mut out = RrdContents::default();
    for msg in decoder {
        if let rerun::log::LogMsg::ArrowMsg(_, arrow) = msg.map_err(|e| err(&e))? {
            let chunk = rerun::log::Chunk::from_arrow_msg(&arrow).map_err(|e| err(&e))?;
            *out.rows.entry(chunk.entity_path().to_string()).or_default() += chunk.num_rows() as u64;
        }
    }
    Ok(out)
}
