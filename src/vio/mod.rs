//! Online bias estimation with vision (paper §4): a sliding-window
//! visual-inertial estimator in the style of VINS-Mono, built from the
//! factors of [`tumble_factors`] and solved by [`tumble_solvers`].
//!
//! - State per window frame: pose `X` (body in world, SE(3)), velocity `V`
//!   (world, m/s), bias `B = [b_a, b_g]`; landmarks as inverse depth `L` in
//!   their first observing window frame.
//! - Cost (eq. 13): marginalization prior + IMU preintegration factors on the
//!   calibrated samples (eq. 16–19) + bias random walks + reprojection factors
//!   under a Huber loss, solved by Levenberg–Marquardt with the landmarks
//!   eliminated by the Schur complement.
//! - The window is solved when a frame becomes a keyframe (parallax, time);
//!   a frame in between is tracked against the fixed window (its own pose,
//!   velocity and bias only) and dropped, its IMU measured again from the last
//!   keyframe by the next frame ([`VioOptions::solve_window_every_frame`]
//!   solves the whole window at every frame instead); when the window holds
//!   more than N keyframes the oldest is marginalized.
//! - Initialization without ground truth from a static start (gyro bias,
//!   gravity direction, zero velocity) or from a moving start (closed form,
//!   see [`init`]); see [`Init`].
//!
//! World frame: z up, gravity `[0, 0, −g]`, origin and yaw at the first state.
//!
//! ```
//! use tumble::sim::{simulate, Scenario, SimConfig};
//! use tumble::vio::{run, VioInput, VioOptions};
//! let mut cfg = SimConfig::default();
//! cfg.duration_s = Some(40.0);
//! let sim = simulate(Scenario::Walk, &cfg, 1).unwrap();
//! let mut input = VioInput::from_simulation(&sim).unwrap();
//! input.frames.retain(|f| f.t < 8.0); // the first 8 s, to keep the example short
//! let out = run(&input, &VioOptions::default(), None).unwrap();
//! let last = out.estimates.last().unwrap();
//! assert!(last.position.iter().all(|x| x.is_finite()));
//! ```

pub mod estimator;
pub mod frontend;
pub mod geometry;
pub mod init;
pub mod input;
pub mod output;
#[cfg(feature = "rerun")]
pub mod record;

pub use crate::io::ImuNoise;
pub use estimator::{run, run_observed, Estimator, FrameEstimate, ResidualTally, VioResult, WindowState};
pub use input::{read_eqvio, Frame, ImuData, NoiseSource, StereoCamera, VioInput};
pub use output::{bias_track, summarize, trajectory, write_outputs, Summary};

use tumble_factors::imu_preint::{PreintegrationParams, Scheme};

/// How the first state is found.
#[derive(Debug, Clone, PartialEq, Default)]
pub enum Init {
    /// [`Init::Static`] when the recording starts at rest, else [`Init::Motion`].
    #[default]
    Auto,
    /// From the first `init_window_s` of data, which must be at rest: gyro
    /// bias = mean rate, roll and pitch from the mean specific force, v = 0.
    Static,
    /// From a moving start: the closed-form visual–inertial solution over the
    /// frames of the last `init_motion_window_s`, or of twice that when the
    /// shorter window saw too little parallax (velocity, roll, pitch and
    /// metric scale from the IMU and the feature tracks; see [`init`]). The
    /// gyro bias starts at zero (the calibration removed it).
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
/// Gaussian noise); see [`VioOptions::zero_velocity_span_s`].
pub const REST_NOISE_SIGMAS: f64 = 2.5;

/// Settings of the estimator.
#[derive(Debug, Clone, PartialEq)]
pub struct VioOptions {
    /// Keyframes kept in the window (VINS-Mono: 10).
    pub window: usize,
    /// Median feature parallax (rotation taken out) to the last keyframe that makes a keyframe \[px\].
    pub keyframe_parallax_px: f64,
    /// Longest time between keyframes \[s\].
    pub keyframe_max_interval_s: f64,
    /// Standard deviation of a feature observation \[px\].
    pub pixel_sigma: f64,
    /// Huber threshold on the whitened reprojection error (in σ; the knee of
    /// the paper's ρ(s) placed at the 95 % χ²₂ gate, √5.99).
    pub huber: f64,
    /// Observations whose error exceeds this after a solve are dropped \[σ\].
    pub outlier_sigmas: f64,
    /// A new observation of a triangulated landmark farther than this from
    /// where the IMU-predicted pose projects it is left out before the solve
    /// (a gross outlier: after the solve, [`VioOptions::outlier_sigmas`]
    /// judges the rest) \[px\].
    pub prediction_gate_px: f64,
    /// A track is triangulated only when every observation lies within this
    /// of where the triangulated point projects \[px\]. Otherwise, with three
    /// rays or more, the worst observation (a gross outlier) leaves the track
    /// and the rest is tried again; with two, triangulation waits for the
    /// next observation. An outlier that entered a new landmark used to pull
    /// the whole keyframe solve by up to 2° before it was dropped.
    pub triangulation_gate_px: f64,
    /// Smallest angle between the rays of a landmark to triangulate it \[deg\].
    pub min_triangulation_deg: f64,
    /// IMU noise (continuous time) and integration rule.
    pub imu: PreintegrationParams,
    /// Gravity magnitude \[m/s²\].
    pub gravity: f64,
    /// Levenberg–Marquardt iterations per frame.
    pub max_iterations: usize,
    /// How the first state is found.
    pub init: Init,
    /// Length of the static window used by [`Init::Static`] \[s\].
    pub init_window_s: f64,
    /// Length of the frame window used by [`Init::Motion`] \[s\] (twice
    /// this is tried when it sees too little parallax).
    pub init_motion_window_s: f64,
    /// Prior standard deviation of the accelerometer bias at the start \[m/s²\].
    pub init_bias_accel_sigma: f64,
    /// Raise the white-noise densities to what the static start measured when
    /// the given ones are smaller (vibration). Off by default: vibration is
    /// reported as a warning, but on EuRoC V1_01 raising the noise made the
    /// ATE 6× worse (0.29 vs 0.05 m).
    pub noise_from_static: bool,
    /// Relative cost decrease at which a frame's solve stops.
    pub function_tolerance: f64,
    /// A frame whose features moved less than this since the previous frame
    /// is treated as at rest (zero-velocity pseudo-measurement) \[px\].
    pub zero_velocity_px: f64,
    /// A frame is also at rest when its features moved less than
    /// max(`zero_velocity_px`, [`REST_NOISE_SIGMAS`] · `pixel_sigma`) over the
    /// last `zero_velocity_span_s` \[s\] (from frames at least 80 % of it
    /// back): between two frames pixel noise alone moves features by more
    /// than `zero_velocity_px` (median 1.67 σ), so a camera at rest was never
    /// detected, and with nothing triangulated the velocity then drifted as
    /// the IMU's (0.17 m in 2 s on the simulated walk's static start).
    pub zero_velocity_span_s: f64,
    /// IMU spacing above which an interval is reported as a gap \[s\].
    pub max_imu_gap_s: f64,
    /// Recover marginal standard deviations of every frame's state.
    pub covariances: bool,
    /// Solve the whole window at every frame (VINS-Mono's way) instead of
    /// only at keyframes, with the frames in between tracked against the
    /// fixed window (motion-only: their own pose, velocity and bias).
    pub solve_window_every_frame: bool,
    /// With a second camera ([`VioInput::stereo`]): also put its matches into
    /// the window (reprojections from cam1, and at a landmark's anchor a
    /// factor on its depth alone; single-frame stereo tracks triangulated).
    /// Off, the second camera serves the initialization only.
    pub stereo_window: bool,
}

impl Default for VioOptions {
    fn default() -> Self {
        VioOptions {
            window: 10,
            keyframe_parallax_px: 15.0,
            keyframe_max_interval_s: 1.0,
            pixel_sigma: 1.0,
            huber: 5.99f64.sqrt(),
            outlier_sigmas: 8.0,
            prediction_gate_px: 30.0,
            triangulation_gate_px: 12.0,
            min_triangulation_deg: 1.0,
            imu: PreintegrationParams { scheme: Scheme::ZeroOrderHold, ..PreintegrationParams::default() },
            gravity: 9.81,
            max_iterations: 8,
            init: Init::Auto,
            init_window_s: 1.0,
            init_motion_window_s: 1.5,
            init_bias_accel_sigma: 0.1,
            noise_from_static: false,
            function_tolerance: 1e-3,
            zero_velocity_px: 0.3,
            zero_velocity_span_s: 0.5,
            max_imu_gap_s: 0.05,
            covariances: true,
            solve_window_every_frame: false,
            stereo_window: false,
        }
    }
}

impl VioOptions {
    /// Defaults with the noise, gravity and pixel noise a simulation was made with
    /// (what `tumble allan` and the camera's specification would tell).
    pub fn for_simulation(cfg: &crate::sim::SimConfig) -> VioOptions {
        let mut o =
            VioOptions { gravity: cfg.gravity, pixel_sigma: cfg.camera.pixel_noise_px.max(0.1), ..Default::default() };
        ImuNoise::from_model(&cfg.imu).apply(&mut o.imu);
        o
    }
}

/// [`run`], also recording the run into the rerun file `rerun` when given
/// (see `record`; needs the cargo feature `rerun`, an error without it).
/// Returns the result (with the recording's warnings, e.g. an unreadable
/// image) and the file written.
pub fn run_recorded(
    input: &VioInput,
    opts: &VioOptions,
    progress: Option<&mut dyn FnMut(usize, usize)>,
    rerun: Option<&std::path::Path>,
) -> Result<(VioResult, Option<std::path::PathBuf>), String> {
    let Some(path) = rerun else {
        return run(input, opts, progress).map(|r| (r, None));
    };
    #[cfg(feature = "rerun")]
    {
        let mut rec = record::Recorder::create(path, input)?.with_images(input.images.iter().cloned());
        let mut result = run_observed(input, opts, progress, &mut |est, i, e| rec.frame(est, i, e))?;
        let (written, warnings) = rec.finish()?;
        result.warnings.extend(warnings);
        Ok((result, Some(written)))
    }
    #[cfg(not(feature = "rerun"))]
    {
        let _ = progress;
        Err(rerun_missing(path))
    }
}

/// Ok when this build can write the rerun file `path` (cargo feature
/// `rerun`); otherwise the error saying how to get it — for callers that
/// check before long work.
pub fn rerun_available(path: &std::path::Path) -> Result<(), String> {
    #[cfg(feature = "rerun")]
    {
        let _ = path;
        Ok(())
    }
    #[cfg(not(feature = "rerun"))]
    Err(rerun_missing(path))
}

#[cfg(not(feature = "rerun"))]
fn rerun_missing(path: &std::path::Path) -> String {
    format!(
        "{}: this tumble was built without rerun support; rebuild with `--features rerun` \
         (e.g. `cargo run --features rerun -- vio … --rerun FILE.rrd`)",
        path.display()
    )
}
