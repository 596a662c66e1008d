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
//!   keyframe by the next frame ([`WindowOptions::solve_every_frame`]
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

mod aids;
mod auto_calib;
mod open;
pub use aids::{TargetTruth, TARGET_TRUTH_MAX_RMS_PX, TARGET_TRUTH_MIN_CORNERS};
pub use open::{OpenError, OpenedVio, VioSource};
pub(crate) mod estimator;
pub mod frontend;
#[doc(hidden)]
pub mod init;
pub(crate) mod input;
mod keyframe;
mod landmarks;
mod marginalization;
mod online_calib;
pub use online_calib::{AutoOutcome, CameraEstimate};
pub(crate) mod noise_meter;
pub(crate) mod options;
pub(crate) mod output;
#[cfg(feature = "rerun")]
pub(crate) mod record;
#[cfg(feature = "rerun")]
pub use record::{read_rrd, RrdContents};
mod rest;
mod startup;
mod window;
pub(crate) mod window_scale;

pub use crate::io::ImuNoise;
pub use estimator::{run, run_observed, Estimator, FrameEstimate, VioResult, WindowLength, WindowState};
pub use input::{read_eqvio, Frame, NoiseSource, StereoCamera, VioInput};
pub use marginalization::ResidualTally;
pub use options::{
    CameraCalibrationOptions, Estimate, GateOptions, Init, InitOptions, NoiseOptions, RestOptions, SolverOptions,
    VioOptions, WindowOptions, REST_NOISE_SIGMAS,
};
pub use output::{bias_track, piece_starts_s, summarize, trajectory, write_outputs, Summary};
pub use window_scale::{WindowScale, MIN_LENGTH_M as WINDOW_MIN_LENGTH_M};

/// Why the estimator cannot run or could not produce an estimate.
#[derive(Debug, thiserror::Error)]
pub enum VioError {
    /// An option cannot work (see [`VioOptions::validate`]).
    #[error(transparent)]
    Options(#[from] crate::OptionError),
    /// A file cannot be read or written (named with its line).
    #[error(transparent)]
    File(#[from] crate::InputError),
    /// The evaluation against ground truth failed.
    #[error(transparent)]
    Eval(#[from] crate::eval::EvalError),
    /// The input cannot be used, or the estimator could not start on it (the message says why and what to do).
    #[error("{0}")]
    Invalid(String),
}

crate::error::message_error_conversions!(VioError, VioError::Invalid);

/// [`run`], also recording the run into the rerun file `rerun` when given
/// (see `record`; needs the cargo feature `rerun`, an error without it).
/// Returns the result (with the recording's warnings, e.g. an unreadable
/// image) and the file written.
pub fn run_recorded(
    input: &VioInput,
    opts: &VioOptions,
    progress: Option<&mut dyn FnMut(usize, usize)>,
    rerun: Option<&std::path::Path>,
) -> Result<(VioResult, Option<std::path::PathBuf>), VioError> {
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
        Err(rerun_missing(path).into())
    }
}

/// Ok when this build can write the rerun file `path` (cargo feature
/// `rerun`); otherwise the error saying how to get it — for callers that
/// check before long work.
pub fn rerun_available(path: &std::path::Path) -> Result<(), VioError> {
    #[cfg(feature = "rerun")]
    {
        let _ = path;
        Ok(())
    }
    #[cfg(not(feature = "rerun"))]
    Err(rerun_missing(path).into())
}

#[cfg(not(feature = "rerun"))]
fn rerun_missing(path: &std::path::Path) -> String {
    format!(
        "{}: this tumble was built without rerun support; rebuild with `--features rerun` \
         (e.g. `cargo run --features rerun -- vio … --rerun FILE.rrd`)",
        path.display()
    )
}
