//! The sliding-window estimator: a thin orchestrator over its parts — the
//! window of states (`vio/window.rs`), the landmarks (`vio/landmarks.rs`),
//! the keyframe policy (`vio/keyframe.rs`), rest detection (`vio/rest.rs`),
//! the initialization (`vio/startup.rs`) and marginalization
//! (`vio/marginalization.rs`) — that predicts each frame
//! with the IMU, decides what it is, solves, and recovers from failures.

mod frame;

use super::keyframe::FrameObs;
use super::landmarks::{Added, Landmarks};
use super::marginalization::{marginalize_oldest, ResidualTally};
use super::noise_meter::{NoiseMeter, NoiseReport};
use super::online_calib::{CameraEstimate, CameraPrior};
use super::rest::RestDetector;
use super::startup::Startup;
use super::window::{InitState, StateValues, Window};
use super::{Init, VioError, VioInput, VioOptions, WindowOptions};
use crate::model::geometry::parts;
use nalgebra::{UnitQuaternion, Vector3, Vector6};
use std::time::Instant;
use tumble_solvers::sophus_lie::Isometry3F64;
use tumble_solvers::{Covariances, Graph, LmOptions, Optimizer, Values, B, V, X};

/// Landmarks below which a frame between keyframes is solved with the whole
/// window (its IMU link then holds the window's velocities and biases).
const MIN_LANDMARKS_TO_TRACK: usize = 30;
/// Observations a landmark needs before a tracked frame uses it.
const MIN_TRACK_OBSERVATIONS: usize = 4;
/// Features below which a frame counts as blind: a pose from fewer points is
/// ill-conditioned (a PnP needs 4 in general position, a robust one several
/// times that), so the IMU carries the estimate alone.
pub const BLIND_FEATURES: usize = 10;

/// The estimate at one camera frame.
#[derive(Debug, Clone, PartialEq)]
pub struct FrameEstimate {
    /// Frame time \[s\] (input time axis).
    pub t: f64,
    /// Whether the frame became a keyframe.
    pub keyframe: bool,
    /// Body position in the world frame \[m\].
    pub position: [f64; 3],
    /// Rotation world←body `[w, x, y, z]`.
    pub rotation: [f64; 4],
    /// Velocity in the world frame \[m/s\].
    pub velocity: [f64; 3],
    /// Accelerometer bias \[m/s²\].
    pub bias_accel: [f64; 3],
    /// Gyro bias \[rad/s\].
    pub bias_gyro: [f64; 3],
    /// Marginal standard deviations: rotation (body, rad), position (m),
    /// velocity (m/s), b_a (m/s²), b_g (rad/s); NaN when not recovered.
    pub std: [[f64; 3]; 5],
    /// Landmarks in the window.
    pub landmarks: usize,
    /// Time spent on this frame's solve \[s\].
    pub solve_s: f64,
    /// At a keyframe solved with covariances: how far the window reaches
    /// and how well it knows that distance.
    pub window_length: Option<WindowLength>,
}

/// The distance from the window's oldest state to its newest (a keyframe)
/// and that distance's σ from the solve's joint covariance of the two
/// poses (marginalization prior included).
///
/// `sigma_m / length_m` bounds the relative σ of the scale the window
/// holds: a window that knows its own length to 1 % cannot be 5 % off in
/// scale without the estimator saying so. Against a ground truth the
/// normalized errors `(length − true length) / σ` check that claim
/// (`Summary::window_length`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WindowLength {
    /// Time of the window's oldest state \[s\] (input time axis).
    pub from_t: f64,
    /// Straight-line distance from the oldest state to this one \[m\].
    pub length_m: f64,
    /// Its standard deviation \[m\].
    pub sigma_m: f64,
}

/// Everything a run produced.
#[derive(Debug, Clone, Default)]
pub struct VioResult {
    /// One estimate per frame after initialization.
    pub estimates: Vec<FrameEstimate>,
    /// Warnings (gaps, resets, noise raised, frames without features), in order.
    pub warnings: Vec<String>,
    /// Number of failure resets.
    pub resets: usize,
    /// Time at which the estimator initialized \[s\].
    pub init_time: Option<f64>,
    /// Times \[s\] at which the estimates begin in a frame of their own: the
    /// first initialization that kept estimates, and each later one (after a
    /// withdrawn start). Position and yaw begin again at the origin at each,
    /// so with more than one the trajectory is in pieces that must be
    /// aligned or used separately (a warning says so).
    pub starts: Vec<f64>,
    /// Wall time of the whole run \[s\].
    pub wall_s: f64,
    /// The measurement residuals at their final estimates, for the audit.
    pub residuals: ResidualTally,
    /// Spans `[from, to]` \[s\] of frames with fewer than `BLIND_FEATURES`
    /// features, where the estimate was the IMU's alone.
    pub blind_spans: Vec<[f64; 2]>,
    /// The IMU noise given, measured at rest and in motion, and in use at the end.
    pub noise: Option<NoiseReport>,
    /// The camera's online calibration at the end ([`super::CameraCalibrationOptions`]).
    pub camera: Option<CameraEstimate>,
    /// Its estimate after each keyframe's solve, with the keyframe's time \[s\].
    pub camera_track: Vec<(f64, CameraEstimate)>,
}

/// The sliding-window estimator; feed it frames in time order with [`Estimator::process`].
pub struct Estimator<'a> {
    opts: VioOptions,
    input: &'a VioInput,
    window: Window,
    landmarks: Landmarks,
    rest: RestDetector,
    startup: Startup,
    /// The last keyframe's features.
    keyframe_obs: FrameObs,
    last_good: Option<StateValues>,
    /// Warnings so far.
    pub warnings: Vec<String>,
    /// Resets so far.
    pub resets: usize,
    /// Time of initialization.
    pub init_time: Option<f64>,
    /// Marginal σ of the last keyframe (added to the conditional σ of the
    /// frames tracked against it).
    keyframe_std: [[f64; 3]; 5],
    /// The last frame tracked against the window: time \[s\] and state.
    last_tracked: Option<(f64, Isometry3F64, Vector3<f64>, Vector6<f64>)>,
    /// Since when (time, frames) the frames have been blind ([`BLIND_FEATURES`]).
    blind_since: Option<(f64, usize)>,
    blind_spans: Vec<[f64; 2]>,
    residuals: ResidualTally,
    /// The IMU noise in motion ([`super::NoiseOptions::measure_in_motion`]), from initialization on.
    noise: Option<NoiseMeter>,
    /// The IMU noise in use: the run's (`opts.noise.imu`) at each start,
    /// raised by a static start's measurement or the noise meter.
    imu: tumble_factors::imu_preint::PreintegrationParams,
    /// The camera's online calibration after each keyframe solve.
    camera_track: Vec<(f64, CameraEstimate)>,
    /// Keyframes for which the camera's calibration stays held after an implausible estimate.
    camera_held: usize,
    /// Every time from which estimates were withdrawn (a start or an
    /// estimate the features contradicted), in order.
    withdrawals: Vec<f64>,
    /// How many of them [`Estimator::take_withdrawn`] has handed out.
    withdrawals_taken: usize,
    /// The initializations so far \[s\] ([`VioResult::starts`]).
    starts: Vec<f64>,
}

fn vec3(v: &Vector3<f64>) -> [f64; 3] {
    [v.x, v.y, v.z]
}

/// A window state as [`Estimator::window`] reports it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WindowState {
    /// State time \[s\] (input time axis).
    pub t: f64,
    /// Body position in the world frame \[m\].
    pub position: [f64; 3],
    /// Rotation world←body `[w, x, y, z]`.
    pub rotation: [f64; 4],
}

impl<'a> Estimator<'a> {
    /// An estimator over `input` (frames are given to [`Estimator::process`] by index).
    pub fn new(input: &'a VioInput, opts: &VioOptions) -> Self {
        Estimator {
            window: Window::new(opts.noise.gravity).with_camera(CameraPrior::new(input, &opts.camera)),
            opts: opts.clone(),
            input,
            landmarks: Landmarks::default(),
            rest: RestDetector::new(&opts.rest, opts.noise.pixel_sigma),
            startup: Startup::new(&opts.init, &opts.noise),
            keyframe_obs: FrameObs::new(),
            last_good: None,
            warnings: Vec::new(),
            resets: 0,
            init_time: None,
            keyframe_std: [[f64::NAN; 3]; 5],
            last_tracked: None,
            blind_since: None,
            blind_spans: Vec::new(),
            residuals: ResidualTally::default(),
            noise: None,
            imu: opts.noise.imu,
            camera_track: Vec::new(),
            camera_held: 0,
            withdrawals: Vec::new(),
            withdrawals_taken: 0,
            starts: Vec::new(),
        }
    }

    /// The states in the window now (keyframes, and the newest frame while it
    /// is being decided), oldest first.
    pub fn window(&self) -> Vec<WindowState> {
        self.window.poses().into_iter().map(|(t, position, rotation)| WindowState { t, position, rotation }).collect()
    }

    /// The time \[s\] from which the estimates [`Estimator::process`] has
    /// returned are withdrawn (a start or an estimate the features
    /// contradicted: the warnings say why), once; None when nothing was.
    /// Whoever keeps the estimates drops those at or after it, as [`run`] does;
    /// the starts and the camera's calibration track drop theirs here.
    pub fn take_withdrawn(&mut self) -> Option<f64> {
        let t0 = self.withdrawals[self.withdrawals_taken..].iter().copied().reduce(f64::min)?;
        self.withdrawals_taken = self.withdrawals.len();
        self.starts.retain(|t| *t < t0);
        self.camera_track.retain(|(t, _)| *t < t0);
        Some(t0)
    }

    /// Every time \[s\] from which estimates have been withdrawn so far, in
    /// order (each followed by a new start at the origin, in a frame of its
    /// own): for an observer of [`run_observed`], which sees the estimates as
    /// they come, to drop what was withdrawn.
    pub fn withdrawals(&self) -> &[f64] {
        &self.withdrawals
    }

    /// The landmarks in the window now, by track id, in the world frame \[m\].
    pub fn landmarks(&self) -> Vec<(u64, [f64; 3])> {
        self.landmarks
            .world_points(self.input, &self.window.values, self.opts.noise.gravity)
            .into_iter()
            .map(|(id, p)| (id, vec3(&p)))
            .collect()
    }

    fn warn(&mut self, msg: String) {
        self.warnings.push(msg);
    }

    /// Start the window at time `t` from `init`.
    fn start(&mut self, t: f64, init: InitState) {
        let (x, v, b) = (init.x, init.v, init.b);
        self.window.start(t, init, &self.opts.init);
        self.landmarks.clear();
        self.last_good = Some((x, v, b));
    }

    fn reset_to_newest(&mut self) {
        let (x, v, b) = self.last_good.expect("initialized");
        let t = self.window.states.last().map_or(0.0, |s| s.t);
        self.resets += 1;
        self.start(t, InitState { x, v, b, v_sigma: 0.5, tilt_sigma: None, gyro_bias_sigma: None, in_motion: true });
        if let Some(p) = self.window.init_prior.as_mut() {
            // Position and yaw stay the gauge; roll, pitch and biases loosen.
            p.b_sigma = [0.2, 0.2, 0.2, 0.02, 0.02, 0.02];
        }
    }

    /// Why the solved state `sid` cannot be right (non-finite, biases grown
    /// beyond a MEMS part's, a jump from the IMU prediction), or None.
    fn failed(&self, sid: u64, predicted: &Isometry3F64) -> Option<String> {
        let (x, v, b) = self.window.state_values(sid);
        let (r, p) = parts(&x);
        if !(p.iter().chain(v.iter()).chain(b.iter()).all(|z| z.is_finite())) {
            return Some("non-finite state".into());
        }
        if b.fixed_rows::<3>(0).norm() > 2.5 {
            return Some(format!("accelerometer bias grew to {:.2} m/s²", b.fixed_rows::<3>(0).norm()));
        }
        if b.fixed_rows::<3>(3).norm() > 1.0 {
            return Some(format!("gyro bias grew to {:.2} rad/s", b.fixed_rows::<3>(3).norm()));
        }
        let (rp, pp) = parts(predicted);
        let jump = (p - pp).norm();
        if jump > 5.0 {
            return Some(format!("the newest position jumped {jump:.1} m from the IMU prediction"));
        }
        let ang = tumble_solvers::lie::so3_log(&(rp.transpose() * r)).norm().to_degrees();
        if ang > 50.0 {
            return Some(format!("the newest rotation jumped {ang:.0}° from the IMU prediction"));
        }
        None
    }

    /// Whether the keyframe solved at time `t` (its window's `graph`, whose
    /// calibration priors the probe replaces) determines the calibration
    /// parameters estimated `auto` that are still held: those it does are
    /// freed from the next keyframe on (the summary's camera line says when).
    fn probe_camera(&mut self, t: f64, graph: &mut Graph) {
        let Some(c) = self.window.camera.as_mut() else { return };
        if let Err(e) = c.probe(t, graph, &self.window.values) {
            self.warn(format!("at {t:.3} s the camera calibration's covariance was not recovered ({e})"));
        }
    }

    /// Marginalize the oldest state; on failure, warn and restart the window from its newest state.
    fn marginalize_oldest(&mut self) {
        let (window, landmarks) = (&mut self.window, &mut self.landmarks);
        if let Err(e) = marginalize_oldest(window, landmarks, self.input, &self.opts, &mut self.residuals) {
            self.warn(format!("marginalization failed ({e}); the window restarts from its newest state"));
            self.reset_to_newest();
        }
    }

    /// Follow blind frames at time `t`: fewer than [`BLIND_FEATURES`]
    /// `features`, or as many observations of the window's landmarks of which
    /// most, and all but fewer than that, disagree with the IMU's prediction
    /// (`added`: the prediction gate kept them out; tracks not yet
    /// triangulated do not place the frame). A warning when vision is lost,
    /// the span when it returns. When the gate keeps them out while the
    /// window's start in motion is unconfirmed, the frame is not blind: the
    /// start is refuted, and the returned text says by what.
    fn watch_blindness(&mut self, t: f64, features: usize, added: Added) -> Option<String> {
        let kept_out = added.landmarks_seen - added.landmarks;
        let rejected =
            added.landmarks_seen >= BLIND_FEATURES && added.landmarks < BLIND_FEATURES && kept_out > added.landmarks;
        let gated = || {
            format!(
                "{kept_out} of its {} observations of the window's landmarks lie beyond the {:.0} px prediction gate",
                added.landmarks_seen, self.opts.gates.prediction_px
            )
        };
        if rejected && self.window.unconfirmed(self.opts.window.size) {
            return Some(gated());
        }
        match (&mut self.blind_since, features < BLIND_FEATURES || rejected) {
            (None, true) => {
                self.blind_since = Some((t, 1));
                let why = if features < BLIND_FEATURES {
                    format!("{features} features, fewer than {BLIND_FEATURES}")
                } else {
                    format!("{}: the IMU's prediction is off", gated())
                };
                self.warn(format!("vision lost at {t:.3} s ({why}): IMU only until features return"));
            }
            (Some((_, n)), true) => *n += 1,
            (Some(_), false) => {
                let (t0, n) = self.blind_since.take().expect("blind");
                self.blind_spans.push([t0, t]);
                self.warn(format!(
                    "features back at {t:.3} s after {:.2} s blind ({n} frames): the estimate over that span is the IMU's alone",
                    t - t0
                ));
            }
            (None, false) => {}
        }
        None
    }

    /// Close a blind span still open at the last frame `t`.
    fn finish_blindness(&mut self, t: f64) {
        if let Some((t0, n)) = self.blind_since.take() {
            self.blind_spans.push([t0, t]);
            self.warn(format!(
                "blind from {t0:.3} s to the end ({:.2} s, {n} frames): the estimate over that span is the IMU's alone",
                t - t0
            ));
        }
    }

    /// Measure the IMU noise on the window's oldest link, which leaves it at
    /// time `t` (`c`: the solve's covariances, with its states'); when the
    /// noise in use changes, integrate the window's links and the next ones with it.
    fn measure_noise(&mut self, t: f64, c: &Covariances) {
        let Some(meter) = self.noise.as_mut() else { return };
        let Some(link) = self.window.link_linearization(0) else { return };
        let Some(sigma) = c.joint(&link.keys).filter(|s| s.ncols() == link.jacobian.ncols()) else {
            return;
        };
        let given = meter.given();
        let scales = [
            link.params.gyro_noise_density / given.gyro_noise_density,
            link.params.accel_noise_density / given.accel_noise_density,
        ];
        meter.measure(t, &link.residual, &link.jacobian, &sigma, &link.covariance, scales);
        if meter.update(t) {
            self.imu = meter.params();
            self.window.reweight_links(self.imu);
        }
    }

    /// Remove the newest state (a frame that is not a keyframe).
    fn drop_newest(&mut self) {
        let sid = self.window.drop_newest();
        self.landmarks.remove_state(sid, &mut self.window.values);
    }

    /// One Levenberg–Marquardt solve of `graph` from `values` with the
    /// estimator's options, eliminating the key families `eliminate`; with
    /// [`super::SolverOptions::covariances`], the marginal covariances of
    /// `keys` from the solve's own last linearization too.
    #[allow(clippy::type_complexity)]
    fn solve(
        &self,
        graph: &Graph,
        values: &Values,
        keys: &[tumble_solvers::Key],
        eliminate: Vec<char>,
    ) -> (Result<(Values, tumble_solvers::Summary), tumble_solvers::SolveError>, Option<Covariances>) {
        let optimizer = Optimizer::new(LmOptions {
            max_iterations: self.opts.solver.max_iterations,
            function_tolerance: self.opts.solver.function_tolerance,
            eliminate,
            log_iterations: false,
            // An anytime solve with a fixed budget, re-solved at the next
            // frame: a tolerance ends it without the stationarity check, and
            // a step the model says gains less than the tolerance is not tried.
            check_stationarity: false,
            stop_on_predicted_decrease: true,
            ..LmOptions::default()
        });
        if !self.opts.solver.covariances {
            return (optimizer.optimize(graph, values), None);
        }
        let mut covariances = None;
        let solved = optimizer.optimize_with_covariances(graph, values, keys).map(|(v, s, c)| {
            covariances = c.ok();
            (v, s)
        });
        (solved, covariances)
    }

    /// Withdraw the window's start, for `why` ([`Estimator::withdraw`]).
    fn withdraw_start(&mut self, why: String) {
        self.withdraw(self.window.started_at(), why);
    }

    /// Withdraw the estimates from time `from` on, for `why`: a warning, they
    /// leave the output ([`run_observed`]), it counts as a reset, and the
    /// estimator initializes again from the next frame on (a new start, at
    /// the origin).
    fn withdraw(&mut self, from: f64, why: String) {
        self.warn(format!("{why}; its estimates are withdrawn and the estimator initializes again"));
        if let Some((t0, n)) = self.blind_since.take() {
            let t = self.window.states.last().map_or(t0, |s| s.t);
            self.blind_spans.push([t0, t]);
            self.warn(format!("blind from {t0:.3} s until the estimates were withdrawn at {t:.3} s ({n} frames)"));
        }
        self.withdrawals.push(from);
        self.resets += 1;
        self.window.clear();
        self.landmarks.clear();
        self.last_tracked = None;
    }

    /// After a failed solve at frame `index`: warn, restart the window from
    /// `last_good` (the frame's predicted state), and report that start.
    fn recover(
        &mut self,
        index: usize,
        why: &str,
        last_good: StateValues,
        obs: FrameObs,
        t_start: Instant,
    ) -> Option<FrameEstimate> {
        let t = self.input.frames[index].t;
        if self.window.unconfirmed(self.opts.window.size) {
            // The last good state descends from a start nothing has confirmed:
            // restarting from it carries the start's error on (each restart
            // again unconfirmed), so the start goes.
            self.withdraw_start(format!(
                "failure at {t:.3} s ({why}) before the start in motion at {:.3} s was confirmed: the start was wrong",
                self.window.started_at()
            ));
            return None;
        }
        self.warn(format!("failure at {t:.3} s: {why}; reset from the last good state"));
        self.last_good = Some(last_good);
        self.reset_to_newest();
        self.add_observations(index, &obs);
        self.keyframe_obs = obs;
        Some(self.estimate(self.window.states[0].sid, true, t_start, None))
    }

    /// Frame `index`'s features, undistorted, by track.
    fn frame_obs(&self, index: usize) -> FrameObs {
        let cam = &self.input.camera;
        self.input.frames[index].features.iter().filter_map(|(id, uv)| cam.unproject(*uv).map(|xy| (*id, xy))).collect()
    }

    /// Add frame `index`'s observations to the newest state.
    fn add_observations(&mut self, index: usize, obs: &FrameObs) -> Added {
        let sid = self.window.states.last().expect("state").sid;
        self.landmarks.add_observations(self.input, index, sid, obs, &self.window.values, &self.opts)
    }

    /// The estimate of state `sid`; its σ from `covariances` (of the frame's
    /// solve, at the solution) when given, else NaN.
    fn estimate(&self, sid: u64, keyframe: bool, t0: Instant, covariances: Option<&Covariances>) -> FrameEstimate {
        let (x, v, b) = self.window.state_values(sid);
        let (r, p) = parts(&x);
        let q = UnitQuaternion::from_rotation_matrix(&nalgebra::Rotation3::from_matrix_unchecked(r));
        let mut std = [[f64::NAN; 3]; 5];
        if let Some(c) = covariances {
            let blocks = [(X(sid), 0), (X(sid), 3), (V(sid), 0), (B(sid), 0), (B(sid), 3)];
            for (row, (key, off)) in std.iter_mut().zip(blocks) {
                for (i, s) in row.iter_mut().enumerate() {
                    *s = c.sigma(key, i + off).unwrap_or(f64::NAN);
                }
            }
        }
        let state = self.window.states.iter().find(|s| s.sid == sid).expect("state");
        let window_length = covariances.filter(|_| keyframe).and_then(|c| self.window_length(sid, c));
        FrameEstimate {
            t: state.t,
            keyframe,
            position: vec3(&p),
            rotation: [q.w, q.i, q.j, q.k],
            velocity: vec3(&v),
            bias_accel: [b[0], b[1], b[2]],
            bias_gyro: [b[3], b[4], b[5]],
            std,
            landmarks: self.landmarks.count(),
            solve_s: t0.elapsed().as_secs_f64(),
            window_length,
        }
    }

    /// The window's length from its oldest state to state `sid` and its σ
    /// (None without the two poses' joint covariance or when they coincide).
    /// Pose tangents are `[ω, ν]` with `T ⊞ δ = T·Exp(δ)`, so a position
    /// moves by `R ν` in the world.
    fn window_length(&self, sid: u64, c: &Covariances) -> Option<WindowLength> {
        let first = self.window.states.first().filter(|f| f.sid != sid)?;
        let joint = c.joint(&[X(first.sid), X(sid)])?;
        let (ra, pa) = parts(&self.window.state_values(first.sid).0);
        let (rb, pb) = parts(&self.window.state_values(sid).0);
        let d = pb - pa;
        let length_m = d.norm();
        if length_m <= 0.0 || !length_m.is_finite() || joint.shape() != (12, 12) {
            return None;
        }
        let u = d / length_m;
        let mut g = nalgebra::DVector::zeros(12);
        g.rows_mut(3, 3).copy_from(&-(ra.transpose() * u));
        g.rows_mut(9, 3).copy_from(&(rb.transpose() * u));
        let var = (g.transpose() * joint * &g)[(0, 0)];
        Some(WindowLength { from_t: first.t, length_m, sigma_m: var.max(0.0).sqrt() })
    }
}

/// Run the estimator over every frame of `input`. `progress` is called with
/// `(frames done, frames total)`.
pub fn run(
    input: &VioInput,
    opts: &VioOptions,
    progress: Option<&mut dyn FnMut(usize, usize)>,
) -> Result<VioResult, VioError> {
    run_observed(input, opts, progress, &mut |_, _, _| {})
}

/// As [`run`], calling `observe(estimator, frame index, estimate)` after each
/// frame that produced an estimate — e.g. to record the window and its
/// landmarks for a viewer ([`Estimator::window`], [`Estimator::landmarks`]).
pub fn run_observed(
    input: &VioInput,
    opts: &VioOptions,
    mut progress: Option<&mut dyn FnMut(usize, usize)>,
    observe: &mut dyn FnMut(&Estimator, usize, &FrameEstimate),
) -> Result<VioResult, VioError> {
    opts.validate()?;
    input.check()?;
    // The online camera calibration estimates the first camera alone: the
    // second one then serves the initialization only.
    let init_only = opts.camera.online() && opts.window.stereo && input.stereo.is_some();
    let mono_window;
    let opts = if init_only {
        mono_window = VioOptions { window: WindowOptions { stereo: false, ..opts.window.clone() }, ..opts.clone() };
        &mono_window
    } else {
        opts
    };
    let t0 = Instant::now();
    let mut est = Estimator::new(input, opts);
    if init_only {
        est.warnings.push(
            "the online camera calibration estimates the first camera alone: the second camera's matches serve \
             the initialization only, not the window"
                .into(),
        );
    }
    let mut out = VioResult::default();
    for i in 0..input.frames.len() {
        if let Some(e) = est.process(i) {
            observe(&est, i, &e);
            out.estimates.push(e);
        }
        if let Some(t0) = est.take_withdrawn() {
            out.estimates.retain(|e| e.t < t0);
        }
        if let Some(p) = progress.as_mut() {
            p(i + 1, input.frames.len());
        }
    }
    if est.init_time.is_none() {
        return Err((match opts.init.mode {
            Init::Static => format!(
                "could not initialize: no {:.1} s window at rest before any frame (the static initialization needs the recording to start at rest; \
                 use --init auto or motion for a moving start, or --init-from-groundtruth to evaluate from a known state)",
                opts.init.static_window_s
            ),
            Init::Motion | Init::Auto => format!(
                "could not initialize: {}no {:.1} s window of motion that observes scale \
                 (last attempt {}; give --init-from-groundtruth to evaluate from a known state)",
                if opts.init.mode == Init::Auto { format!("no {:.1} s window at rest and ", opts.init.static_window_s) } else { String::new() },
                opts.init.motion_window_s,
                est.startup.failure.as_deref().unwrap_or("none: too few frames")
            ),
            Init::Given { t, .. } => format!("could not initialize: no frame after the given initial state at {t:.3} s"),
        }).into());
    }
    if let Some(last) = out.estimates.last() {
        est.finish_blindness(last.t);
    }
    if est.starts.len() > 1 {
        let at: Vec<String> = est.starts.iter().map(|t| format!("{t:.3} s")).collect();
        est.warnings.push(format!(
            "the trajectory is in {} pieces, each in a frame of its own (started at {}): position and yaw begin \
             again at the origin at each start after a withdrawn one, so align or use the pieces separately",
            at.len(),
            at.join(", ")
        ));
    }
    out.warnings = est.warnings;
    out.starts = est.starts;
    out.blind_spans = est.blind_spans;
    out.resets = est.resets;
    out.init_time = est.init_time;
    out.residuals = est.residuals;
    out.noise = est.noise.as_ref().map(|m| m.report(est.startup.at_rest));
    out.camera = est.camera_track.last().map(|c| c.1.clone());
    out.camera_track = est.camera_track;
    out.wall_s = t0.elapsed().as_secs_f64();
    Ok(out)
}
