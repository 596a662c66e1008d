//! The estimator's settings, grouped by the part of the estimator they steer
//! (window and keyframes, measurement gates, initialization, rest detection,
//! noise, the per-frame solve), readable from and printable as YAML, and
//! checked once by [`VioOptions::validate`] (every run calls it).

use crate::{InputError, OptionError};
use serde::{Deserialize, Serialize};
use std::path::Path;
use tumble_factors::imu_preint::{PreintegrationParams, Scheme};

/// How the first state is found.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Init {
    /// [`Init::Static`] when the recording starts at rest, else [`Init::Motion`].
    #[default]
    Auto,
    /// From the first [`InitOptions::static_window_s`] of data, which must be
    /// at rest: gyro bias = mean rate, roll and pitch from the mean specific
    /// force, v = 0.
    Static,
    /// From a moving start: the closed-form visual–inertial solution over the
    /// frames of the last [`InitOptions::motion_window_s`], or of twice that
    /// when the shorter window saw too little parallax (velocity, roll, pitch
    /// and metric scale from the IMU and the feature tracks; see
    /// [`super::init`]). The gyro bias starts at zero (the calibration removed it).
    Motion,
    /// From a given state (evaluation aid, e.g. ground truth): time \[s\],
    /// rotation world←body `[w, x, y, z]`, position \[m\], velocity \[m/s\],
    /// accelerometer and gyro biases.
    Given {
        /// Rotation world←body `[w, x, y, z]`.
        q: [f64; 4],
        /// Position \[m\].
        p: [f64; 3],
        /// Velocity \[m/s\].
        v: [f64; 3],
        /// Accelerometer bias \[m/s²\].
        bias_accel: [f64; 3],
        /// Gyro bias \[rad/s\].
        bias_gyro: [f64; 3],
        /// Time of that state \[s\] (on the input's time axis).
        t: f64,
    },
}

/// Features at rest move by pixel noise alone: over a span, the median
/// motion stays below this many `pixel_sigma` (it is 1.67 σ for a pure
/// Gaussian noise); see [`RestOptions::span_s`].
pub const REST_NOISE_SIGMAS: f64 = 2.5;

/// The sliding window and its keyframes.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct WindowOptions {
    /// Keyframes kept in the window (VINS-Mono: 10).
    pub size: usize,
    /// Median feature parallax (rotation taken out) to the last keyframe that makes a keyframe \[px\].
    pub keyframe_parallax_px: f64,
    /// Longest time between keyframes \[s\].
    pub keyframe_max_interval_s: f64,
    /// Shortest time between keyframes made by parallax \[s\] (a frame
    /// that lost half of the last keyframe's features is one regardless).
    /// In fast flight the parallax threshold is reached at every frame: on
    /// EuRoC MH_03 every other frame was a keyframe, a 10-keyframe window
    /// spanned 0.6 s, and with one camera the windows' lengths came out 3 %
    /// short with errors 2.5 times their σ (RMS); with one keyframe at most
    /// every 0.15 s, 0.2 % short at 1.4 σ, and the estimator about twice as
    /// fast (docs/findings/vio.md, "Keyframes in fast flight").
    pub keyframe_min_interval_s: f64,
    /// Solve the whole window at every frame (VINS-Mono's way) instead of
    /// only at keyframes, with the frames in between tracked against the
    /// fixed window (motion-only: their own pose, velocity and bias).
    pub solve_every_frame: bool,
    /// With a second camera ([`super::VioInput::stereo`]): also put its matches into
    /// the window (reprojections from cam1, and at a landmark's anchor a
    /// factor on its depth alone; single-frame stereo tracks triangulated).
    /// On by default: the baseline fixes far landmarks' depths, which the
    /// motion's parallax alone does not in a large hall (docs/vio.md).
    /// Off, or with the online camera calibration, the second camera serves
    /// the initialization only.
    pub stereo: bool,
    /// Estimate each landmark's bearing with its inverse depth (three
    /// parameters, the anchor observation a residual like every other: the
    /// anchored inverse depth of OpenVINS and Basalt; the default) instead of
    /// fixing the bearing at the anchor pixel (one parameter, VINS-Mono's,
    /// about 1.4× faster). Fixed, the anchor pixel's noise enters every other
    /// observation of the landmark and is counted nowhere: the window's σ come
    /// out too small, the noise meter reads that noise as the gyro's, and the
    /// path comes out short (docs/findings/vio.md).
    pub landmark_bearings: bool,
}

/// Which feature observations enter the solve, and how they are weighed.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct GateOptions {
    /// Huber threshold on the whitened reprojection error (in σ; the knee of
    /// the paper's ρ(s) placed at the 95 % χ²₂ gate, √5.99).
    pub huber: f64,
    /// Observations whose error exceeds this after a solve are dropped \[σ\].
    pub outlier_sigmas: f64,
    /// A new observation of a triangulated landmark farther than this from
    /// where the IMU-predicted pose projects it is left out before the solve
    /// (a gross outlier: after the solve, [`GateOptions::outlier_sigmas`]
    /// judges the rest) \[px\].
    pub prediction_px: f64,
    /// A track is triangulated only when every observation lies within this
    /// of where the triangulated point projects \[px\]. Otherwise, with three
    /// rays or more, the worst observation (a gross outlier) leaves the track
    /// and the rest is tried again; with two, triangulation waits for the
    /// next observation. An outlier that entered a new landmark used to pull
    /// the whole keyframe solve by up to 2° before it was dropped.
    pub triangulation_px: f64,
    /// Smallest angle between the rays of a landmark to triangulate it \[deg\].
    pub min_triangulation_deg: f64,
}

/// How the first state is found.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct InitOptions {
    /// The method.
    pub mode: Init,
    /// Length of the static window used by [`Init::Static`] \[s\].
    pub static_window_s: f64,
    /// Length of the frame window used by [`Init::Motion`] \[s\] (twice
    /// this is tried when it sees too little parallax).
    pub motion_window_s: f64,
    /// Prior standard deviation of the accelerometer bias at the start \[m/s²\].
    pub bias_accel_sigma: f64,
}

/// Zero-velocity (rest) detection from the feature motion.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RestOptions {
    /// A frame whose features moved less than this since the previous frame
    /// is treated as at rest (zero-velocity pseudo-measurement) \[px\].
    pub zero_velocity_px: f64,
    /// A frame is also at rest when its features moved less than
    /// max(`zero_velocity_px`, [`REST_NOISE_SIGMAS`] · `pixel_sigma`) over the
    /// last `span_s` \[s\] (from frames at least 80 % of it back): between two
    /// frames pixel noise alone moves features by more than
    /// `zero_velocity_px` (median 1.67 σ), so a camera at rest was never
    /// detected, and with nothing triangulated the velocity then drifted as
    /// the IMU's (0.17 m in 2 s on the simulated walk's static start).
    pub span_s: f64,
}

/// The measurement noise and the physical constants.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct NoiseOptions {
    /// IMU noise (continuous time) and integration rule.
    pub imu: PreintegrationParams,
    /// Standard deviation of a feature observation \[px\].
    pub pixel_sigma: f64,
    /// Gravity magnitude \[m/s²\].
    pub gravity: f64,
    /// Raise the white-noise densities to what the static start measured when
    /// the given ones are smaller (vibration). Off by default: vibration is
    /// reported as a warning, but on EuRoC V1_01 raising the noise made the
    /// ATE 6× worse (0.29 vs 0.05 m).
    pub from_static: bool,
    /// Measure the IMU's white noise in motion from the window's own IMU
    /// residuals (variance component estimation, see `vio/noise_meter.rs`)
    /// and integrate with it where it exceeds the given figures (vibration,
    /// unmodelled effects). Off: the given figures throughout.
    pub measure_in_motion: bool,
    /// IMU spacing above which an interval is reported as a gap \[s\].
    pub max_imu_gap_s: f64,
}

/// The per-frame Levenberg–Marquardt solve.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SolverOptions {
    /// Levenberg–Marquardt iterations per frame.
    pub max_iterations: usize,
    /// Relative cost decrease at which a frame's solve stops.
    pub function_tolerance: f64,
    /// Recover marginal standard deviations of every frame's state.
    pub covariances: bool,
}

/// Whether a camera parameter is estimated in the window.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Estimate {
    /// Held at the given value.
    #[default]
    Off,
    /// A variable of the window, under a prior at the given value with the
    /// σ of [`CameraCalibrationOptions`]; its information leaves the window
    /// through the marginalization prior like the states'. Held at its value
    /// until a window's length of keyframes has left the window, and after an
    /// estimate beyond its prior's 99.9 % χ² quantile (rejected, with a warning).
    On,
    /// As `On`, but only along the directions the recording determines
    /// (docs/vio.md, "`auto`"): at each keyframe, from the time `On`
    /// would free it, the window's covariance of the parameter — as if it
    /// were free under its plain prior — is compared with the prior's; a
    /// direction is determined when its σ there is below
    /// [`DETERMINED_FRACTION`](crate::model::DETERMINED_FRACTION)
    /// of the prior's (the data carry at least 3× the prior's information,
    /// the rule of the IMU calibration's misalignments). The parameter is
    /// free once one direction is; the others stay at the given value under
    /// a prior 10⁶ times as informative until they are determined too. The
    /// summary names what stayed held. Motions that leave a direction
    /// unobservable (rotation about one axis only leaves the translation
    /// along it; no rotation, the time offset) would otherwise let it drift
    /// within its prior and take up other errors.
    Auto,
}

/// Online calibration of the camera against the IMU (VINS-Mono's
/// `estimate_extrinsic` / `estimate_td`): the first camera's pose in the IMU
/// frame `T_BC` and the time offset `td` (an image stamped `t` was exposed at
/// IMU time `t + td`, Kalibr's `timeshift_cam_imu`). Both need rotation about
/// more than one axis and motion; the summary reports their σ.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CameraCalibrationOptions {
    /// Estimate `T_BC`.
    pub extrinsics: Estimate,
    /// Estimate `td`.
    pub time_offset: Estimate,
    /// σ of the given `T_BC`'s rotation, per axis \[deg\] (how far a hand-measured
    /// or datasheet mounting can be off).
    pub rotation_sigma_deg: f64,
    /// σ of the given `T_BC`'s translation, per axis \[m\].
    pub translation_sigma_m: f64,
    /// σ of the given time offset (0 unless a calibration says otherwise) \[s\];
    /// also the half-width of the IMU samples the body's motion around each
    /// stamp is fitted over (the offsets the prior expects).
    pub time_offset_sigma_s: f64,
}

impl Default for CameraCalibrationOptions {
    fn default() -> Self {
        CameraCalibrationOptions {
            extrinsics: Estimate::Off,
            time_offset: Estimate::Off,
            rotation_sigma_deg: 5.0,
            translation_sigma_m: 0.05,
            time_offset_sigma_s: 0.02,
        }
    }
}

impl CameraCalibrationOptions {
    /// Whether anything is estimated (`on` or `auto`).
    pub fn online(&self) -> bool {
        self.extrinsics != Estimate::Off || self.time_offset != Estimate::Off
    }
}

/// Settings of the estimator.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
#[serde(default, deny_unknown_fields)]
pub struct VioOptions {
    /// The sliding window and its keyframes.
    pub window: WindowOptions,
    /// Which observations enter the solve.
    pub gates: GateOptions,
    /// How the first state is found.
    pub init: InitOptions,
    /// Rest detection.
    pub rest: RestOptions,
    /// Noise and gravity.
    pub noise: NoiseOptions,
    /// The per-frame solve.
    pub solver: SolverOptions,
    /// Online calibration of the camera's extrinsic and time offset.
    pub camera: CameraCalibrationOptions,
}

impl Default for WindowOptions {
    fn default() -> Self {
        WindowOptions {
            size: 10,
            keyframe_parallax_px: 15.0,
            keyframe_min_interval_s: 0.15,
            keyframe_max_interval_s: 1.0,
            solve_every_frame: false,
            stereo: true,
            landmark_bearings: true,
        }
    }
}

impl Default for GateOptions {
    fn default() -> Self {
        GateOptions {
            huber: 5.99f64.sqrt(),
            outlier_sigmas: 8.0,
            prediction_px: 30.0,
            triangulation_px: 12.0,
            min_triangulation_deg: 1.0,
        }
    }
}

impl Default for InitOptions {
    fn default() -> Self {
        InitOptions { mode: Init::Auto, static_window_s: 1.0, motion_window_s: 1.5, bias_accel_sigma: 0.1 }
    }
}

impl Default for RestOptions {
    fn default() -> Self {
        RestOptions { zero_velocity_px: 0.3, span_s: 0.5 }
    }
}

impl Default for NoiseOptions {
    fn default() -> Self {
        NoiseOptions {
            imu: PreintegrationParams { scheme: Scheme::Midpoint, ..PreintegrationParams::default() },
            pixel_sigma: 1.0,
            gravity: 9.81,
            from_static: false,
            measure_in_motion: true,
            max_imu_gap_s: 0.05,
        }
    }
}

impl Default for SolverOptions {
    fn default() -> Self {
        SolverOptions { max_iterations: 8, function_tolerance: 1e-3, covariances: true }
    }
}

impl VioOptions {
    /// Check every option once, before any work (as Ceres'
    /// `Solver::Options::IsValid`): sizes, times, gates and noise figures
    /// positive and finite where they must be. [`super::run`] calls it.
    pub fn validate(&self) -> Result<(), OptionError> {
        let w = &self.window;
        if w.size < 2 {
            return Err(OptionError::new("--window", format!("must hold at least 2 keyframes, got {}", w.size)));
        }
        OptionError::positive("--keyframe-parallax", w.keyframe_parallax_px, "pixels")?;
        OptionError::positive("--keyframe-interval", w.keyframe_max_interval_s, "seconds")?;
        if !(w.keyframe_min_interval_s >= 0.0 && w.keyframe_min_interval_s < w.keyframe_max_interval_s) {
            return Err(OptionError::new(
                "--keyframe-min-interval",
                format!(
                    "must be at least 0 and shorter than --keyframe-interval ({} s), got {}",
                    w.keyframe_max_interval_s, w.keyframe_min_interval_s
                ),
            ));
        }
        let g = &self.gates;
        OptionError::positive("gates.huber", g.huber, "σ")?;
        OptionError::positive("gates.outlier_sigmas", g.outlier_sigmas, "σ")?;
        OptionError::positive("--prediction-gate", g.prediction_px, "pixels")?;
        OptionError::positive("--triangulation-gate", g.triangulation_px, "pixels")?;
        if !(g.min_triangulation_deg.is_finite() && g.min_triangulation_deg >= 0.0) {
            return Err(OptionError::new("gates.min_triangulation_deg", "must be a non-negative number of degrees"));
        }
        let i = &self.init;
        OptionError::positive("init.static_window_s", i.static_window_s, "seconds")?;
        OptionError::positive("init.motion_window_s", i.motion_window_s, "seconds")?;
        OptionError::positive("init.bias_accel_sigma", i.bias_accel_sigma, "m/s²")?;
        OptionError::positive("rest.zero_velocity_px", self.rest.zero_velocity_px, "pixels")?;
        OptionError::positive("rest.span_s", self.rest.span_s, "seconds")?;
        let n = &self.noise;
        if !(n.pixel_sigma.is_finite() && n.pixel_sigma > 0.0) {
            return Err(OptionError::new("--pixel-sigma", format!("must be positive, got {}", n.pixel_sigma)));
        }
        OptionError::positive("--gravity", n.gravity, "m/s²")?;
        OptionError::earth_gravity(
            n.gravity,
            "the estimator levels the trajectory and the accelerometer biases against it",
        )?;
        OptionError::positive("noise.max_imu_gap_s", n.max_imu_gap_s, "seconds")?;
        for (v, name) in [
            (n.imu.accel_noise_density, "noise.imu.accel_noise_density"),
            (n.imu.gyro_noise_density, "noise.imu.gyro_noise_density"),
            (n.imu.accel_random_walk, "noise.imu.accel_random_walk"),
            (n.imu.gyro_random_walk, "noise.imu.gyro_random_walk"),
        ] {
            OptionError::positive(name, v, "SI units")?;
        }
        if !(n.imu.integration_sigma.is_finite() && n.imu.integration_sigma >= 0.0) {
            return Err(OptionError::new("noise.imu.integration_sigma", "must be ≥ 0"));
        }
        if let Some(a) = &n.imu.axes {
            let all = [a.accel_noise_density, a.gyro_noise_density, a.accel_random_walk, a.gyro_random_walk];
            if all.iter().flatten().any(|x| !(x.is_finite() && *x > 0.0)) {
                return Err(OptionError::new("noise.imu.axes", "must hold positive figures only"));
            }
        }
        if self.solver.max_iterations == 0 {
            return Err(OptionError::new("solver.max_iterations", "must be at least 1"));
        }
        OptionError::positive("solver.function_tolerance", self.solver.function_tolerance, "(relative)")?;
        let c = &self.camera;
        OptionError::positive("camera.rotation_sigma_deg", c.rotation_sigma_deg, "degrees")?;
        OptionError::positive("camera.translation_sigma_m", c.translation_sigma_m, "metres")?;
        OptionError::positive("camera.time_offset_sigma_s", c.time_offset_sigma_s, "seconds")?;
        if let Init::Given { q, p, v, bias_accel, bias_gyro, t } = &i.mode {
            let finite = q.iter().chain(p).chain(v).chain(bias_accel).chain(bias_gyro).all(|x| x.is_finite());
            let norm = q.iter().map(|x| x * x).sum::<f64>().sqrt();
            if !finite || !t.is_finite() || (norm - 1.0).abs() > 1e-6 {
                return Err(OptionError::new("init.mode", "must be a finite given state with a unit quaternion"));
            }
        }
        Ok(())
    }

    /// The defaults with a feature observation noise of `pixel_sigma` \[px\].
    pub fn with_pixel_sigma(pixel_sigma: f64) -> VioOptions {
        let mut o = VioOptions::default();
        o.noise.pixel_sigma = pixel_sigma;
        o
    }

    /// Read options from YAML (every key optional; unknown keys are errors),
    /// checked with [`VioOptions::validate`].
    pub fn read(path: &Path) -> Result<VioOptions, InputError> {
        let o: VioOptions = crate::io::yaml::read_yaml(path)?;
        o.validate().map_err(|e| InputError::file(path, e.to_string()))?;
        Ok(o)
    }

    /// The options as YAML, every key written (what [`VioOptions::read`] takes).
    pub fn to_yaml(&self) -> Result<String, serde_saphyr::ser::Error> {
        serde_saphyr::to_string(self)
    }
}
