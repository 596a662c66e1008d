//! Calibration of a visual-inertial rig on a known target (`tumble
//! calibrate-rig`, Kalibr's job): each camera's intrinsics and distortion,
//! its pose in the IMU frame `T_BC`, the camera–IMU time offset, the
//! target's pose against gravity and the IMU biases, estimated jointly with
//! their covariances on the one solver.
//!
//! The state is discrete: a body pose, velocity and bias at every camera
//! frame, IMU preintegration and bias random walks between frames
//! ([`tumble_factors::ImuFactor`]), and every target corner seen as a
//! [`tumble_factors::rig::TargetCorner`] (Huber loss, pixel σ measured by the
//! camera-only calibration). The time offset moves each frame's pose along
//! the measured rate and the velocity. Nothing is guessed by the user: see
//! [`init`] for the starting values.
//!
//! ```no_run
//! use tumble::rig::{calibrate_rig, RigInput, RigOptions};
//! let opts = RigOptions { resolution: Some([752, 480]), ..RigOptions::default() };
//! let input = RigInput::from_asl("imu_april".as_ref(), "target.yaml".as_ref(), None, None, &opts).unwrap();
//! let rig = calibrate_rig(&input, &opts, &mut |msg| eprintln!("{msg}")).unwrap();
//! for c in &rig.cameras {
//!     println!("{}: fx {:.2} px, T_BC translation {:?}", c.name, c.model.fx, c.t_bc.translation);
//! }
//! println!("time offset {:.3} ms ± {:.3}", rig.time_offset_s * 1e3, rig.time_offset_sigma_s * 1e3);
//! ```

mod calibrate;
mod clusters;
pub mod detect;
#[doc(hidden)]
pub mod init;
pub(crate) mod input;
pub(crate) mod output;
mod solve;
mod split;

pub use crate::model::target::{CameraCorners, Corner, RigInput, Target, View};
pub use calibrate::calibrate_rig;
pub use clusters::COARSE_BLOCKS;
pub use output::{summary_markdown, write_rig};

use crate::error::OptionError;
use nalgebra::{Isometry3, Matrix3, Vector3};
use tumble_factors::camera::{CameraModel, DistortionKind};

/// Why a rig calibration could not be made.
#[derive(Debug, thiserror::Error)]
pub enum RigError {
    /// An option cannot work.
    #[error(transparent)]
    Options(#[from] OptionError),
    /// The recording cannot calibrate the rig (too few frames, views or
    /// rotation; the message says which).
    #[error("{0}")]
    Recording(String),
    /// The solver failed on the joint graph or its covariances.
    #[error("{what}: {source}")]
    Solver {
        /// What was being solved.
        what: &'static str,
        /// The solver's error.
        #[source]
        source: tumble_solvers::SolveError,
    },
    /// A noise model could not be built from the IMU's figures.
    #[error("the IMU's noise: {0}")]
    Noise(#[from] tumble_solvers::NoiseError),
    /// A bug: something every stage before guarantees was missing.
    #[error("internal error of the rig calibration: {0}")]
    Internal(String),
}

impl From<tumble_solvers::ValueError> for RigError {
    fn from(e: tumble_solvers::ValueError) -> RigError {
        RigError::Internal(e.to_string())
    }
}

/// Options of a rig calibration (validated by [`RigOptions::validate`]).
#[derive(Debug, Clone, PartialEq)]
pub struct RigOptions {
    /// Distortion model to estimate for every camera (`--distortion`).
    pub distortion: DistortionKind,
    /// Estimate the camera–IMU time offset (`--time-offset on|off`); off holds it at 0.
    pub estimate_time_offset: bool,
    /// Largest time offset the coarse search considers \[s\] (`--max-time-offset`).
    pub max_time_offset_s: f64,
    /// Local gravity \[m/s²\] (`--gravity`).
    pub gravity: f64,
    /// Image size `[width, height]` \[px\] of every camera, when the folder's
    /// `camN/sensor.yaml` does not give it (`--resolution WxH`).
    pub resolution: Option<[u32; 2]>,
    /// Iterations of each joint solve at most.
    pub max_iterations: usize,
    /// Intrinsics to hold fixed, per camera in order (Kalibr's two-step
    /// workflow: cameras calibrated first, then the camera–IMU calibration
    /// with their intrinsics fixed; `--intrinsics DIR`). Empty: all estimated.
    pub fixed_intrinsics: Vec<CameraModel>,
}

impl Default for RigOptions {
    fn default() -> Self {
        RigOptions {
            distortion: DistortionKind::RadTan,
            estimate_time_offset: true,
            max_time_offset_s: 0.1,
            gravity: 9.81,
            resolution: None,
            max_iterations: 60,
            fixed_intrinsics: Vec::new(),
        }
    }
}

impl RigOptions {
    /// Refuse options no calibration can honour.
    pub fn validate(&self) -> Result<(), OptionError> {
        if self.distortion == DistortionKind::None {
            return Err(OptionError::new("--distortion", "must be radtan or equidistant"));
        }
        OptionError::positive("--gravity", self.gravity, "m/s²")?;
        if !(self.max_time_offset_s.is_finite() && self.max_time_offset_s > 0.0 && self.max_time_offset_s <= 1.0) {
            return Err(OptionError::new(
                "--max-time-offset",
                format!("must be a number of seconds in (0, 1], got {}", self.max_time_offset_s),
            ));
        }
        if let Some(r) = self.resolution {
            if r[0] == 0 || r[1] == 0 {
                return Err(OptionError::new("--resolution", "must be WIDTHxHEIGHT in pixels, both > 0"));
            }
        }
        if self.fixed_intrinsics.iter().any(|m| m.distortion.kind() == DistortionKind::None) {
            return Err(OptionError::new(
                "--intrinsics",
                "cameras without distortion cannot be held: give radtan or equidistant",
            ));
        }
        if self.max_iterations == 0 {
            return Err(OptionError::new("max_iterations", "must be at least 1"));
        }
        Ok(())
    }
}

/// How well a recording determines a parameter: its 3σ against the accuracy a
/// rig calibration is expected to reach ([`accuracy`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Determination {
    /// 3σ within the accuracy.
    Determined,
    /// 3σ within 5× the accuracy: usable, but a better recording would help.
    Weak,
    /// 3σ beyond 5× the accuracy: the recording does not determine it.
    NotDetermined,
}

impl Determination {
    /// From a standard deviation and the accuracy expected of it (same units).
    pub fn of(sigma: f64, accuracy: f64) -> Determination {
        if !sigma.is_finite() {
            Determination::NotDetermined
        } else if 3.0 * sigma <= accuracy {
            Determination::Determined
        } else if 3.0 * sigma <= 5.0 * accuracy {
            Determination::Weak
        } else {
            Determination::NotDetermined
        }
    }
    /// Word for reports.
    pub fn word(self) -> &'static str {
        match self {
            Determination::Determined => "determined",
            Determination::Weak => "weak",
            Determination::NotDetermined => "NOT determined",
        }
    }
}

/// The accuracy a rig calibration is expected to reach (what the verdicts
/// compare 3σ with): what a VIO needs not to be limited by its calibration
/// — 0.15° and 1 cm of `T_BC`, 0.5 % of focal length, 3 px of principal
/// point, 0.5 ms of time offset.
pub mod accuracy {
    /// `T_BC` rotation \[deg\].
    pub const ROTATION_DEG: f64 = 0.15;
    /// `T_BC` translation \[m\].
    pub const TRANSLATION_M: f64 = 0.01;
    /// Focal length, relative.
    pub const FOCAL_RELATIVE: f64 = 0.005;
    /// Principal point \[px\].
    pub const PRINCIPAL_POINT_PX: f64 = 3.0;
    /// Time offset \[s\].
    pub const TIME_OFFSET_S: f64 = 5e-4;
}

/// Reprojection statistics of one camera's corners at the solution \[px\].
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct Reprojection {
    /// Corners used.
    pub corners: usize,
    /// RMS of the residual norm.
    pub rms_px: f64,
    /// Median of the residual norm.
    pub median_px: f64,
    /// Share of corners beyond the Huber threshold (down-weighted).
    pub outlier_fraction: f64,
}

/// One corner at the solution: time \[s, IMU axis\], measured pixel and residual \[px\].
pub type CornerResidual = (f64, [f64; 2], [f64; 2]);

/// The biases at one frame: time \[s\], `b_a` \[m/s²\], `b_g` \[rad/s\].
pub type BiasSample = (f64, Vector3<f64>, Vector3<f64>);

/// One camera's calibration.
#[derive(Debug, Clone)]
pub struct CameraResult {
    /// Folder name (`cam0`).
    pub name: String,
    /// Intrinsics and distortion.
    pub model: CameraModel,
    /// σ of `[fx, fy, cx, cy, c0..c3]` (zeros when held fixed).
    pub model_sigma: [f64; 8],
    /// The intrinsics were held fixed ([`RigOptions::fixed_intrinsics`]).
    pub intrinsics_fixed: bool,
    /// Image size \[px\].
    pub resolution: [u32; 2],
    /// Frame rate \[Hz\] (from the median spacing of the frames).
    pub rate_hz: f64,
    /// Camera to body (IMU) transform.
    pub t_bc: Isometry3<f64>,
    /// σ of the rotation about the body axes \[rad\].
    pub rotation_sigma: Vector3<f64>,
    /// σ of the translation along the body axes \[m\].
    pub translation_sigma: Vector3<f64>,
    /// Pixel σ of the corners used (camera-only calibration's robust estimate) \[px\].
    pub pixel_sigma: f64,
    /// Reprojection at the solution.
    pub reprojection: Reprojection,
    /// Hand–eye rotation residual of the start \[rad\].
    pub hand_eye_rms: f64,
    /// Per corner at the solution: time \[s, IMU axis\], pixel and residual \[px\] (for figures).
    pub residuals: Vec<CornerResidual>,
}

/// The result of a rig calibration.
#[derive(Debug, Clone)]
pub struct RigResult {
    /// Every camera.
    pub cameras: Vec<CameraResult>,
    /// Kalibr's `timeshift_cam_imu` \[s\]: `t_imu = t_cam + shift`.
    pub time_offset_s: f64,
    /// Its σ \[s\] (NaN when not estimated).
    pub time_offset_sigma_s: f64,
    /// The coarse offset of the rate correlation \[s\] and its correlation.
    pub coarse_time_offset: Option<(f64, f64)>,
    /// The rate correlation at each shift of the coarse search `(shift [s], correlation)`.
    pub time_offset_profile: Vec<(f64, f64)>,
    /// Gravity in the target frame \[m/s²\].
    pub gravity_in_target: Vector3<f64>,
    /// Camera-1-from-camera-0 style chain `T_cn_cnm1` for cameras 1.. (camera n ← camera n−1).
    pub chain: Vec<Isometry3<f64>>,
    /// Biases `(t [s], b_a [m/s²], b_g [rad/s])` at the frames.
    pub biases: Vec<BiasSample>,
    /// Whitened χ² per degree of freedom of the IMU factors (≈ 1 when the noise is right).
    pub imu_chi2_per_dof: f64,
    /// How the σ were found.
    pub sigma_source: SigmaSource,
    /// Frames in the estimate.
    pub frames: usize,
    /// Joint-solve iterations and its final cost.
    pub iterations: usize,
    /// Whether both joint solves converged.
    pub converged: bool,
    /// Wall time \[s\].
    pub seconds: f64,
    /// Noise source (for the report).
    pub noise_source: String,
    /// What the calibration noticed.
    pub notes: Vec<String>,
    /// The halves of the recording compared (None when too short or not run).
    pub split: Option<crate::model::split::SplitCheck>,
}

/// How the rig's σ were found: each is the largest of the noise model's
/// (the corners' scatter, the IMU's noise figures) and the cluster-robust
/// ("sandwich") ones
/// - over blocks of consecutive frames, which also hold when the corners'
///   errors are alike in neighbouring views (a detector's bias that depends
///   on the view, a lens the model fits imperfectly);
/// - over the target's corners, which also hold when each corner's error is
///   alike in every view (a target printed or mounted imperfectly, a
///   detector's bias where a corner is usually seen) — errors common to every
///   block and to both halves of a recording.
///
/// The scatter alone shows neither.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct SigmaSource {
    /// The partitions of the frames into blocks, finest first: ⌊√frames⌋
    /// frames per block (the batch-means rule), then
    /// [`COARSE_BLOCKS`] blocks (errors alike for seconds).
    pub partitions: Vec<BlockPartition>,
    /// The target's corners seen: the clusters of the cluster-robust σ over corners.
    pub corners: usize,
    /// The largest ratio of a cluster-robust σ to the noise model's, over the
    /// estimated parameters and clusterings (≈ 1 when the corners' errors are
    /// independent).
    pub largest_ratio: f64,
}

/// One partition of the frames into blocks of consecutive frames (clusters
/// of the cluster-robust covariance).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct BlockPartition {
    /// Frames per block.
    pub block_frames: usize,
    /// Blocks of frames (clusters; the target's gauge is one more of its own).
    pub blocks: usize,
}

/// A determined / weak / not determined verdict on one parameter.
#[derive(Debug, Clone, serde::Serialize)]
pub struct Verdict {
    /// What (e.g. `cam0 T_BC rotation`).
    pub parameter: String,
    /// Its largest σ in the verdict's units.
    pub sigma: f64,
    /// The accuracy compared with.
    pub accuracy: f64,
    /// Units of both.
    pub units: &'static str,
    /// The verdict.
    pub determination: Determination,
    /// Why it is no better than weak although its σ would allow more (the halves disagree).
    pub reason: Option<String>,
}

impl RigResult {
    /// Verdict on every parameter (see [`accuracy`]).
    pub fn verdicts(&self) -> Vec<Verdict> {
        let mut out = Vec::new();
        let mut add = |parameter: String, sigma: f64, accuracy: f64, units: &'static str| {
            let mut determination = Determination::of(sigma, accuracy);
            let reason = self.split_disagreement(&parameter);
            if reason.is_some() && determination == Determination::Determined {
                determination = Determination::Weak;
            }
            out.push(Verdict { parameter, sigma, accuracy, units, determination, reason })
        };
        for c in &self.cameras {
            add(
                format!("{} T_BC rotation", c.name),
                c.rotation_sigma.max().to_degrees(),
                accuracy::ROTATION_DEG,
                "deg",
            );
            add(format!("{} T_BC translation", c.name), c.translation_sigma.max(), accuracy::TRANSLATION_M, "m");
            if c.intrinsics_fixed {
                continue;
            }
            let f = c.model_sigma[0] / c.model.fx;
            add(
                format!("{} focal length", c.name),
                f.max(c.model_sigma[1] / c.model.fy),
                accuracy::FOCAL_RELATIVE,
                "relative",
            );
            add(
                format!("{} principal point", c.name),
                c.model_sigma[2].max(c.model_sigma[3]),
                accuracy::PRINCIPAL_POINT_PX,
                "px",
            );
        }
        if self.time_offset_sigma_s.is_finite() {
            add("time offset".into(), self.time_offset_sigma_s, accuracy::TIME_OFFSET_S, "s");
        }
        out
    }

    /// The halves' worst disagreement on a parameter of the verdict named
    /// `parameter` (`cam0 principal point` covers `cam0 cx` and `cam0 cy`).
    fn split_disagreement(&self, parameter: &str) -> Option<String> {
        let split = self.split.as_ref()?;
        let worst = split.disagreements().into_iter().find(|d| verdict_of(&d.parameter) == parameter)?;
        Some(format!("the halves disagree at {:.1}σ on {}", worst.z.abs(), worst.parameter))
    }

    /// Why the result must not be used, if it must not: a solve that did not
    /// converge or a parameter the recording does not determine.
    pub fn refusal(&self) -> Option<String> {
        let mut why = Vec::new();
        let bad: Vec<String> = self
            .verdicts()
            .into_iter()
            .filter(|v| v.determination == Determination::NotDetermined)
            .map(|v| format!("{} (3σ {:.3e} {})", v.parameter, 3.0 * v.sigma, v.units))
            .collect();
        if !bad.is_empty() {
            why.push(format!("the recording does not determine {}", bad.join(", ")));
        }
        if !self.converged {
            why.push("the joint solve did not converge".into());
        }
        (!why.is_empty()).then(|| why.join("; "))
    }
}

/// The verdict ([`RigResult::verdicts`]) that covers a parameter of the
/// halves' check: `cam0 cx` → `cam0 principal point`, `cam0 T_BC rotation x`
/// → `cam0 T_BC rotation`, `fx`/`fy` → `focal length`; others are their own.
pub fn verdict_of(parameter: &str) -> String {
    let Some((camera, rest)) = parameter.split_once(' ') else { return parameter.to_string() };
    let group = match rest {
        "fx" | "fy" => "focal length",
        "cx" | "cy" => "principal point",
        r if r.starts_with("T_BC rotation") => "T_BC rotation",
        r if r.starts_with("T_BC translation") => "T_BC translation",
        _ => return parameter.to_string(),
    };
    format!("{camera} {group}")
}

/// Rotation matrix of an isometry (nalgebra), for reports.
pub(crate) fn rotation(t: &Isometry3<f64>) -> Matrix3<f64> {
    t.rotation.to_rotation_matrix().into_inner()
}

/// One camera of a rig calibration against a reference calibration of the
/// same rig (e.g. an earlier Kalibr `camchain` or a dataset's `sensor.yaml`).
#[derive(Debug, Clone, serde::Serialize)]
pub struct Comparison {
    /// Camera name.
    pub name: String,
    /// Angle of `R_BC,refᵀ R_BC` \[deg\].
    pub rotation_deg: f64,
    /// `t_BC − t_BC,ref` along the body axes \[m\].
    pub translation_m: [f64; 3],
    /// `(fx − fx_ref)/fx_ref`, `(fy − fy_ref)/fy_ref`.
    pub focal_relative: [f64; 2],
    /// `cx − cx_ref`, `cy − cy_ref` \[px\].
    pub principal_point_px: [f64; 2],
    /// Each difference over its σ: rotation (angle / largest axis σ),
    /// translation x y z, fx, fy, cx, cy (NaN for intrinsics held fixed).
    pub normalized: [f64; 8],
}

impl RigResult {
    /// Compare each camera with a reference `(model, T_BC)`, in camera order.
    pub fn compare(&self, reference: &[(CameraModel, Isometry3<f64>)]) -> Vec<Comparison> {
        self.cameras
            .iter()
            .zip(reference)
            .map(|(c, (m, t))| {
                let dr = rotation(t).transpose() * rotation(&c.t_bc);
                let rotation_deg = tumble_solvers::lie::so3_log(&dr).norm().to_degrees();
                let dt = c.t_bc.translation.vector - t.translation.vector;
                let s = c.model_sigma;
                let (ts, rs) = (c.translation_sigma, c.rotation_sigma.max().to_degrees());
                Comparison {
                    name: c.name.clone(),
                    rotation_deg,
                    translation_m: dt.into(),
                    focal_relative: [(c.model.fx - m.fx) / m.fx, (c.model.fy - m.fy) / m.fy],
                    principal_point_px: [c.model.cx - m.cx, c.model.cy - m.cy],
                    normalized: [
                        rotation_deg / rs,
                        dt.x / ts.x,
                        dt.y / ts.y,
                        dt.z / ts.z,
                        (c.model.fx - m.fx) / s[0],
                        (c.model.fy - m.fy) / s[1],
                        (c.model.cx - m.cx) / s[2],
                        (c.model.cy - m.cy) / s[3],
                    ],
                }
            })
            .collect()
    }
}
