//! The sliding-window estimator: window bookkeeping, graph building,
//! keyframe decisions, marginalization, failure detection.

use super::geometry::{gravity_aligned, parts, pose, preintegrate, triangulate};
use super::{Init, VioInput, VioOptions};
use nalgebra::{DMatrix, Matrix3, UnitQuaternion, Vector1, Vector2, Vector3, Vector6};
use std::collections::{BTreeMap, HashMap, VecDeque};
use std::sync::Arc;
use std::time::Instant;
use tumble_factors::camera::CameraModel;
use tumble_factors::imu_preint::Preintegrated;
use tumble_factors::reprojection::StereoInverseDepth;
use tumble_factors::{bias_random_walk_axes, BetweenFactor, ImuFactor, InverseDepthReprojection, PriorFactor};
use tumble_solvers::sophus_lie::Isometry3F64;
use tumble_solvers::Factor;
use tumble_solvers::{
    marginalize, Covariances, Graph, Huber, LmOptions, MarginalPrior, NoiseModel, Optimizer, Values, B, L, V, X,
};

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
    /// Wall time of the whole run \[s\].
    pub wall_s: f64,
    /// The measurement residuals at their final estimates, for the audit.
    pub residuals: ResidualTally,
}

/// Whitened measurement residuals of a run, each factor counted once: at the
/// estimate it had when its oldest state was marginalized (reprojections of
/// the landmarks anchored in that state, the IMU and bias random-walk factors
/// to the next state). Priors are not measurements and are left out. The
/// model-discrepancy audit of a VIO run compares them with what the noise explains.
///
/// A reprojection residual is whitened by `σ_px √2`: the landmark's ray is
/// fixed by its anchor observation, whose pixel noise therefore enters every
/// other residual of the landmark about as much as the observation's own (the
/// solver's factor weighs by `σ_px` alone, as VINS-Mono's does).
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize)]
pub struct ResidualTally {
    /// Σ ‖r/(σ_px √2)‖² of the reprojections (no robust loss).
    pub reprojection_chi2: f64,
    /// Number of reprojection residual rows (2 per observation).
    pub reprojection_rows: usize,
    /// Landmarks whose observations were counted (one inverse depth each).
    pub landmarks: usize,
    /// Σ of squared whitened IMU-factor and bias random-walk residuals.
    pub imu_chi2: f64,
    /// Their rows (15 per link: 9 IMU, 6 bias random walk).
    pub imu_rows: usize,
    /// Marginalized states (15 parameters each: pose, velocity, biases).
    pub states: usize,
}

impl ResidualTally {
    /// χ² of every counted residual.
    pub fn chi2(&self) -> f64 {
        self.reprojection_chi2 + self.imu_chi2
    }

    /// Degrees of freedom: residual rows minus the parameters estimated from them.
    pub fn dof(&self) -> usize {
        (self.reprojection_rows + self.imu_rows).saturating_sub(self.landmarks + 15 * self.states)
    }

    /// The gap χ²/dof − 1, floored at 0 (0 when the noise explains the residuals;
    /// NaN without degrees of freedom).
    pub fn gap(&self) -> f64 {
        match self.dof() {
            0 => f64::NAN,
            d => (self.chi2() / d as f64 - 1.0).max(0.0),
        }
    }
}

struct State {
    sid: u64,
    t: f64,
    /// At rest (zero-velocity pseudo-measurement), continuously since this
    /// time \[s\]; None while moving.
    rest_since: Option<f64>,
}

struct Obs {
    sid: u64,
    uv: [f64; 2],
    xy: [f64; 2],
    /// The second camera's match at the same time \[px\], when there is one
    /// and `VioOptions::stereo_window` puts it into the window.
    uv1: Option<[f64; 2]>,
}

#[derive(Default)]
struct Track {
    obs: Vec<Obs>,
    /// Landmark id and its anchor state.
    landmark: Option<(u64, u64)>,
}

struct InitPrior {
    sid: u64,
    pose: Isometry3F64,
    pose_cov: DMatrix<f64>,
    v: Vector3<f64>,
    v_sigma: f64,
    b: Vector6<f64>,
    b_sigma: [f64; 6],
}

/// Velocity prior σ of a start at rest or from a given state \[m/s\].
const STATIC_V_SIGMA: f64 = 0.01;
/// Velocity prior σ of a start in motion (the closed form's accuracy) \[m/s\].
const MOTION_V_SIGMA: f64 = 0.1;
/// Roll/pitch prior σ of a start in motion \[rad\] (2°).
const MOTION_TILT_SIGMA: f64 = 0.035;

/// Why a static start did not work (yet).
enum AtRest {
    /// Not enough IMU data before the frame.
    TooEarly,
    /// The IMU moved in the window.
    Moving,
}

/// The first state of a window and how sure it is.
struct InitState {
    x: Isometry3F64,
    v: Vector3<f64>,
    b: Vector6<f64>,
    /// Velocity prior σ \[m/s\].
    v_sigma: f64,
    /// Roll/pitch prior σ \[rad\]; default: what the accelerometer-bias prior allows.
    tilt_sigma: Option<f64>,
}

impl InitState {
    fn at_rest(x: Isometry3F64, v: Vector3<f64>, b: Vector6<f64>) -> Self {
        InitState { x, v, b, v_sigma: STATIC_V_SIGMA, tilt_sigma: None }
    }
}

/// The sliding-window estimator; feed it frames in time order with [`Estimator::process`].
pub struct Estimator<'a> {
    opts: VioOptions,
    input: &'a VioInput,
    values: Values,
    states: Vec<State>,
    links: Vec<(Arc<Preintegrated>, f64)>,
    tracks: BTreeMap<u64, Track>,
    next_sid: u64,
    next_lid: u64,
    marginal: Option<MarginalPrior>,
    init_prior: Option<InitPrior>,
    last_keyframe_obs: HashMap<u64, [f64; 2]>,
    prev_frame_obs: HashMap<u64, [f64; 2]>,
    prev_frame_rotation: Matrix3<f64>,
    /// The frames of the last `zero_velocity_span_s`: time and observations,
    /// oldest first (rest detection over a span).
    recent: VecDeque<(f64, HashMap<u64, [f64; 2]>)>,
    /// Since when every frame was at rest \[s\] (None: the last one moved).
    rest_since: Option<f64>,
    last_good: Option<(Isometry3F64, Vector3<f64>, Vector6<f64>)>,
    /// Warnings so far.
    pub warnings: Vec<String>,
    /// Resets so far.
    pub resets: usize,
    /// Time of initialization.
    pub init_time: Option<f64>,
    /// Why the last initialization in motion failed (for the error when none worked).
    init_failure: Option<String>,
    /// Marginal σ of the last keyframe (added to the conditional σ of the
    /// frames tracked against it).
    keyframe_std: [[f64; 3]; 5],
    /// The last frame tracked against the window: time \[s\] and state.
    last_tracked: Option<(f64, Isometry3F64, Vector3<f64>, Vector6<f64>)>,
    gravity: Vector3<f64>,
    no_feature_since: Option<f64>,
    residuals: ResidualTally,
}

/// Standard deviation of the zero-velocity pseudo-measurement of a frame at
/// rest \[m/s\] (and of its position change since a previous frame at rest,
/// times the time between them).
const REST_SPEED_SIGMA: f64 = 0.01;

/// The zero-velocity pseudo-measurement of state `sid`, at rest.
fn add_rest_prior(g: &mut Graph, sid: u64) {
    g.add(PriorFactor::new(V(sid), Vector3::zeros()), NoiseModel::isotropic(3, REST_SPEED_SIGMA).expect("positive"));
}

fn vec3(v: &Vector3<f64>) -> [f64; 3] {
    [v.x, v.y, v.z]
}

/// One camera ray of a track: the camera's rotation (world ← camera) and
/// centre in the world, the normalized image point, and which observation
/// (index in the track, second camera or not) it comes from.
struct Ray {
    rotation: Matrix3<f64>,
    centre: Vector3<f64>,
    xy: Vector2<f64>,
    obs: usize,
    stereo: bool,
}

/// The rays of a track's observations in both cameras, from the cameras'
/// poses per state (`poses`, `poses1`: world ← camera rotation and centre).
fn rays(
    tr: &Track,
    poses: &HashMap<u64, (Matrix3<f64>, Vector3<f64>)>,
    poses1: &HashMap<u64, (Matrix3<f64>, Vector3<f64>)>,
    stereo_camera: Option<&CameraModel>,
) -> Vec<Ray> {
    let mut out = Vec::with_capacity(tr.obs.len());
    for (k, o) in tr.obs.iter().enumerate() {
        let (rotation, centre) = poses[&o.sid];
        out.push(Ray { rotation, centre, xy: o.xy.into(), obs: k, stereo: false });
        let xy1 = stereo_camera.zip(o.uv1).and_then(|(cam, uv1)| cam.unproject(uv1));
        if let (Some(xy1), Some(&(rotation, centre))) = (xy1, poses1.get(&o.sid)) {
            out.push(Ray { rotation, centre, xy: xy1.into(), obs: k, stereo: true });
        }
    }
    out
}

/// A track's landmark in the world frame \[m\]: its anchor observation's ray
/// at the estimated inverse depth, seen from the anchor state's camera.
fn landmark_world(values: &Values, body_from_camera: &Isometry3F64, tr: &Track) -> Option<Vector3<f64>> {
    let (lid, anchor) = tr.landmark?;
    let a = tr.obs.iter().find(|o| o.sid == anchor)?;
    let (ra, pa) = parts(values.get::<Isometry3F64>(X(anchor)).ok()?);
    let rho = values.get::<Vector1<f64>>(L(lid)).ok()?[0];
    let (r_bc, t_bc) = parts(body_from_camera);
    let pw = ra * (r_bc * (Vector3::new(a.xy[0], a.xy[1], 1.0) / rho) + t_bc) + pa;
    pw.iter().all(|x| x.is_finite()).then_some(pw)
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
            gravity: Vector3::new(0.0, 0.0, -opts.gravity),
            opts: opts.clone(),
            input,
            values: Values::new(),
            states: Vec::new(),
            links: Vec::new(),
            tracks: BTreeMap::new(),
            next_sid: 0,
            next_lid: 0,
            marginal: None,
            init_prior: None,
            last_keyframe_obs: HashMap::new(),
            prev_frame_obs: HashMap::new(),
            prev_frame_rotation: Matrix3::identity(),
            recent: VecDeque::new(),
            rest_since: None,
            last_good: None,
            warnings: Vec::new(),
            resets: 0,
            init_time: None,
            init_failure: None,
            keyframe_std: [[f64::NAN; 3]; 5],
            last_tracked: None,
            no_feature_since: None,
            residuals: ResidualTally::default(),
        }
    }

    /// The states in the window now (keyframes, and the newest frame while it
    /// is being decided), oldest first.
    pub fn window(&self) -> Vec<WindowState> {
        self.states
            .iter()
            .filter_map(|s| {
                let x = self.values.get::<Isometry3F64>(X(s.sid)).ok()?;
                let (r, p) = parts(x);
                let q = UnitQuaternion::from_matrix(&r);
                Some(WindowState { t: s.t, position: vec3(&p), rotation: [q.w, q.i, q.j, q.k] })
            })
            .collect()
    }

    /// The landmarks in the window now, by track id, in the world frame \[m\].
    pub fn landmarks(&self) -> Vec<(u64, [f64; 3])> {
        self.tracks
            .iter()
            .filter_map(|(id, tr)| {
                landmark_world(&self.values, &self.input.body_from_camera, tr).map(|p| (*id, vec3(&p)))
            })
            .collect()
    }

    fn warn(&mut self, msg: String) {
        self.warnings.push(msg);
    }

    /// Try to initialize at frame `index` (time `t`); returns the initial
    /// state and the velocity's prior σ \[m/s\] when it worked.
    fn initialize(&mut self, index: usize, t: f64) -> Option<InitState> {
        match &self.opts.init {
            Init::Given { q, p, v, bias_accel, bias_gyro, t: t0 } => {
                if t < *t0 {
                    return None;
                }
                let uq = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(q[0], q[1], q[2], q[3]));
                let b =
                    Vector6::new(bias_accel[0], bias_accel[1], bias_accel[2], bias_gyro[0], bias_gyro[1], bias_gyro[2]);
                Some(InitState::at_rest(
                    pose(uq.to_rotation_matrix().matrix(), &Vector3::from(*p)),
                    Vector3::from(*v),
                    b,
                ))
            }
            Init::Static => self.initialize_static(t).ok(),
            Init::Motion => self.initialize_moving(index, t),
            Init::Auto => match self.initialize_static(t) {
                Ok(state) => Some(state),
                Err(AtRest::Moving) => self.initialize_moving(index, t),
                Err(AtRest::TooEarly) => None,
            },
        }
    }

    /// [`Init::Static`] at time `t`.
    fn initialize_static(&mut self, t: f64) -> Result<InitState, AtRest> {
        let imu = &self.input.imu;
        let w = self.opts.init_window_s;
        let (i0, i1) = (imu.t.partition_point(|&s| s < t - w), imu.t.partition_point(|&s| s <= t));
        if t - w < imu.t.first().copied().unwrap_or(f64::INFINITY) - 1e-9 || i1 < i0 + 10 {
            return Err(AtRest::TooEarly);
        }
        // At rest, means over quarters of the window agree (vibration averages out).
        let quarter = (i1 - i0) / 4;
        let mean = |a: usize, b: usize, g: bool| -> Vector3<f64> {
            let s: Vector3<f64> = (a..b).map(|k| if g { imu.gyro[k] } else { imu.acc[k] }).sum();
            s / (b - a) as f64
        };
        let (mut dg, mut da) = (0.0f64, 0.0f64);
        let (gm, am) = (mean(i0, i1, true), mean(i0, i1, false));
        for q in 0..4 {
            let (a, b) = (i0 + q * quarter, i0 + (q + 1) * quarter);
            dg = dg.max((mean(a, b, true) - gm).amax());
            da = da.max((mean(a, b, false) - am).amax());
        }
        if dg > 0.02 || da > 0.3 {
            return Err(AtRest::Moving);
        }
        {
            let rate = (i1 - i0) as f64 / w;
            let std = |g: bool, m: &Vector3<f64>| -> f64 {
                let s: f64 =
                    (i0..i1).map(|k| (if g { imu.gyro[k] } else { imu.acc[k] } - m).norm_squared() / 3.0).sum();
                (s / (i1 - i0) as f64).sqrt()
            };
            let (sa, sg) = (std(false, &am) / rate.sqrt(), std(true, &gm) / rate.sqrt());
            let apply = self.opts.noise_from_static;
            let action = if apply { "using the measured value" } else { "kept (--noise-from-static uses it)" };
            let params = &mut self.opts.imu;
            for (what, unit, measured, density) in [
                ("accelerometer", "m/s²/√Hz, vibration?", sa, &mut params.accel_noise_density),
                ("gyroscope", "rad/s/√Hz", sg, &mut params.gyro_noise_density),
            ] {
                if measured > 1.5 * *density {
                    self.warnings.push(format!(
                                "the {what} at rest is noisier than the noise model says ({measured:.2e} vs {:.2e} {unit}): {action}",
                                *density
                            ));
                    if apply {
                        *density = measured;
                    }
                }
            }
        }
        let r = gravity_aligned(&am);
        let b = Vector6::new(0.0, 0.0, 0.0, gm.x, gm.y, gm.z);
        Ok(InitState::at_rest(pose(&r, &Vector3::zeros()), Vector3::zeros(), b))
    }

    /// [`Init::Motion`] at frame `index`: the closed form over the frames of
    /// the last `init_motion_window_s`, or of twice that when the shorter
    /// window saw too little parallax; `None` (tried again at the next frame)
    /// while the window is too short or does not observe scale.
    fn initialize_moving(&mut self, index: usize, t: f64) -> Option<InitState> {
        let frames = &self.input.frames;
        let mut failure = None;
        for span in [self.opts.init_motion_window_s, 2.0 * self.opts.init_motion_window_s] {
            let first = frames.partition_point(|f| f.t < t - span);
            if frames.first().is_none_or(|f| t - f.t < span - 1e-9) || index < first + 3 {
                break;
            }
            let window: Vec<usize> = (first..=index).collect();
            match super::init::closed_form(self.input, &window, &self.opts) {
                Ok(m) => {
                    let stereo = match m.stereo_observations {
                        0 => String::new(),
                        n => format!(", {n} stereo matches"),
                    };
                    self.warn(format!(
                        "initialized in motion at {t:.3} s from {} frames and {} landmarks{stereo} (speed {:.2} m/s, free gravity {:.2} m/s²)",
                        window.len(),
                        m.landmarks,
                        m.velocity.norm(),
                        m.free_gravity
                    ));
                    return Some(InitState {
                        x: pose(&m.rotation, &Vector3::zeros()),
                        v: m.velocity,
                        b: Vector6::zeros(),
                        v_sigma: MOTION_V_SIGMA,
                        tilt_sigma: Some(MOTION_TILT_SIGMA),
                    });
                }
                Err(why) => failure = Some(format!("at {t:.3} s over {span:.1} s: {why}")),
            }
        }
        if failure.is_some() {
            self.init_failure = failure;
        }
        None
    }

    fn start(&mut self, t: f64, init: InitState) {
        let InitState { x, v, b, v_sigma, tilt_sigma } = init;
        let sid = self.next_sid;
        self.next_sid += 1;
        self.values = Values::new();
        self.values.insert(X(sid), x);
        self.values.insert(V(sid), v);
        self.values.insert(B(sid), b);
        self.states = vec![State { sid, t, rest_since: None }];
        self.links.clear();
        self.tracks.clear();
        self.marginal = None;
        // Roll and pitch as uncertain as an accelerometer bias makes them; yaw and
        // position fixed (the gauge of VIO).
        let (r, _) = parts(&x);
        let tilt = tilt_sigma.unwrap_or((self.opts.init_bias_accel_sigma / self.opts.gravity).max(1e-3));
        let u = r.transpose() * Vector3::z();
        let rot_cov = Matrix3::identity() * tilt * tilt + u * u.transpose() * (1e-6 - tilt * tilt);
        let mut pose_cov = DMatrix::identity(6, 6) * 1e-6;
        pose_cov.view_mut((0, 0), (3, 3)).copy_from(&rot_cov);
        let sa = self.opts.init_bias_accel_sigma;
        let sg = 5e-3;
        self.init_prior = Some(InitPrior { sid, pose: x, pose_cov, v, v_sigma, b, b_sigma: [sa, sa, sa, sg, sg, sg] });
        self.last_good = Some((x, v, b));
    }

    fn state_values(&self, sid: u64) -> (Isometry3F64, Vector3<f64>, Vector6<f64>) {
        (
            *self.values.get::<Isometry3F64>(X(sid)).expect("window state"),
            *self.values.get::<Vector3<f64>>(V(sid)).expect("window state"),
            *self.values.get::<Vector6<f64>>(B(sid)).expect("window state"),
        )
    }

    fn build_graph(&self) -> Graph {
        let mut g = Graph::new();
        if let Some(p) = &self.init_prior {
            if let Ok(n) = NoiseModel::from_covariance(&p.pose_cov) {
                g.add(PriorFactor::new(X(p.sid), p.pose), n);
            }
            g.add(PriorFactor::new(V(p.sid), p.v), NoiseModel::isotropic(3, p.v_sigma).expect("positive"));
            g.add(PriorFactor::new(B(p.sid), p.b), NoiseModel::diagonal(&p.b_sigma).expect("positive"));
        }
        if let Some(m) = &self.marginal {
            g.add(m.clone(), NoiseModel::Unit);
        }
        for i in 0..self.links.len() {
            self.add_link(&mut g, i);
        }
        for (i, s) in self.states.iter().enumerate() {
            let Some(rest_since) = s.rest_since else { continue };
            add_rest_prior(&mut g, s.sid);
            // At rest ever since the previous state: the position stays (the
            // IMU factor alone lets it wander by the accelerometer's noise,
            // centimetres per second for a MEMS part).
            if let Some(prev) = i.checked_sub(1).map(|k| &self.states[k]).filter(|p| p.t >= rest_since) {
                let sp = (REST_SPEED_SIGMA * (s.t - prev.t)).max(1e-4);
                let noise = NoiseModel::diagonal(&[10.0, 10.0, 10.0, sp, sp, sp]).expect("positive");
                g.add(BetweenFactor::new(X(prev.sid), X(s.sid), Isometry3F64::identity()), noise);
            }
        }
        let noise = NoiseModel::isotropic(2, self.opts.pixel_sigma).expect("positive pixel sigma");
        let huber = Arc::new(Huber(self.opts.huber));
        for tr in self.tracks.values() {
            let Some((lid, anchor)) = tr.landmark else { continue };
            let Some(a) = tr.obs.iter().find(|o| o.sid == anchor) else { continue };
            for o in &tr.obs {
                for (factor, _) in self.observation_factors(anchor, lid, a.xy, o) {
                    g.add_entry(tumble_solvers::FactorEntry {
                        factor,
                        noise: noise.clone(),
                        loss: Some(huber.clone()),
                    });
                }
            }
        }
        g
    }

    /// Add link `i`'s IMU factor and bias random walk (state `i` to `i + 1`) to `g`.
    fn add_link(&self, g: &mut Graph, i: usize) {
        let (pim, scale) = &self.links[i];
        let (a, b) = (self.states[i].sid, self.states[i + 1].sid);
        let f = ImuFactor::new([X(a), V(a), B(a), X(b), V(b)], pim.clone(), self.gravity);
        if let Ok(n) = f.noise_model_scaled(*scale) {
            g.add(f, n);
        }
        let dt = pim.delta_t().max(1e-3);
        if let Ok((rw, n)) =
            bias_random_walk_axes(B(a), B(b), self.opts.imu.accel_walk().into(), self.opts.imu.gyro_walk().into(), dt)
        {
            g.add(rw, n);
        }
    }

    /// The reprojection factor of observation `uv` in state `sid` of landmark `lid`
    /// anchored in state `anchor` with anchor observation `anchor_xy`.
    fn reprojection(
        &self,
        anchor: u64,
        sid: u64,
        lid: u64,
        anchor_xy: [f64; 2],
        uv: [f64; 2],
    ) -> InverseDepthReprojection {
        InverseDepthReprojection::new(
            [X(anchor), X(sid), L(lid)],
            anchor_xy,
            uv,
            self.input.camera,
            &self.input.body_from_camera,
        )
    }

    /// The factors of observation `o` of landmark `lid` (anchored at state
    /// `anchor` with normalized anchor observation `anchor_xy`): the first
    /// camera's reprojection (none at the anchor itself) and the second
    /// camera's, when `o` has a stereo match — at the anchor a factor on the
    /// inverse depth alone. Each with whether it is the stereo one.
    fn observation_factors(&self, anchor: u64, lid: u64, anchor_xy: [f64; 2], o: &Obs) -> Vec<(Box<dyn Factor>, bool)> {
        let mut out: Vec<(Box<dyn Factor>, bool)> = Vec::new();
        if o.sid != anchor {
            out.push((Box::new(self.reprojection(anchor, o.sid, lid, anchor_xy, o.uv)), false));
        }
        if let (Some(uv1), Some(st)) = (o.uv1, &self.input.stereo) {
            let f: Box<dyn Factor> = if o.sid == anchor {
                let second = (st.camera, &st.body_from_camera);
                Box::new(StereoInverseDepth::new(L(lid), anchor_xy, uv1, second, &self.input.body_from_camera))
            } else {
                Box::new(self.reprojection(anchor, o.sid, lid, anchor_xy, uv1).seen_by(st.camera, &st.body_from_camera))
            };
            out.push((f, true));
        }
        out
    }

    /// A factor's raw residual at the current values (None when a variable
    /// is missing or the factor cannot be evaluated).
    fn residual_now(&self, f: &dyn Factor) -> Option<nalgebra::DVector<f64>> {
        let vars: Vec<&dyn tumble_solvers::DynVariable> =
            f.keys().iter().map(|&k| self.values.get_dyn(k).ok()).collect::<Option<_>>()?;
        f.residual(tumble_solvers::Vars::new(&vars)).ok()
    }

    fn landmark_count(&self) -> usize {
        self.tracks.values().filter(|t| t.landmark.is_some()).count()
    }

    /// Triangulate tracks seen from two or more window states.
    fn triangulate_new(&mut self) {
        let (r_bc, t_bc) = parts(&self.input.body_from_camera);
        let min_angle = self.opts.min_triangulation_deg.to_radians();
        let stereo = self.input.stereo.as_ref().map(|st| (st, parts(&st.body_from_camera)));
        // Per state: the first camera's pose in the world, and the second's.
        let mut poses: HashMap<u64, (Matrix3<f64>, Vector3<f64>)> = HashMap::new();
        let mut poses1: HashMap<u64, (Matrix3<f64>, Vector3<f64>)> = HashMap::new();
        for s in &self.states {
            let (x, _, _) = self.state_values(s.sid);
            let (r, p) = parts(&x);
            poses.insert(s.sid, (r * r_bc, r * t_bc + p));
            if let Some((_, (r_bc1, t_bc1))) = &stereo {
                poses1.insert(s.sid, (r * r_bc1, r * t_bc1 + p));
            }
        }
        // The gate in normalized image coordinates.
        let limit = self.opts.triangulation_gate_px / self.input.camera.fx;
        for tr in self.tracks.values_mut() {
            if tr.landmark.is_some() {
                continue;
            }
            // An observation that does not agree with the others (a gross
            // outlier) leaves the track before it is triangulated, so that it
            // never pulls the solve: the worst one while more than two rays
            // remain (a ray the point lies behind disagrees too). Two rays
            // that disagree cannot say which is wrong: the track waits for its
            // next observation.
            let agreed = loop {
                let rays = rays(tr, &poses, &poses1, stereo.as_ref().map(|(st, _)| &st.camera));
                if rays.len() < 2 {
                    break None;
                }
                let c: Vec<_> = rays.iter().map(|r| r.centre).collect();
                let d: Vec<_> = rays.iter().map(|r| (r.rotation * r.xy.push(1.0)).normalize()).collect();
                let Some((pw, angle)) = triangulate(&c, &d) else { break None };
                let error = |r: &Ray| {
                    let q = r.rotation.transpose() * (pw - r.centre);
                    if q.z <= 0.0 {
                        f64::INFINITY
                    } else {
                        (q.xy() / q.z - r.xy).norm()
                    }
                };
                let (worst, e) = rays.iter().map(error).enumerate().max_by(|a, b| a.1.total_cmp(&b.1)).expect("rays");
                if e <= limit {
                    break Some((pw, angle));
                }
                if rays.len() == 2 {
                    break None;
                }
                let (k, second) = (rays[worst].obs, rays[worst].stereo);
                if second {
                    tr.obs[k].uv1 = None;
                } else {
                    tr.obs.remove(k);
                }
            };
            let Some((pw, angle)) = agreed else { continue };
            if angle < min_angle {
                continue;
            }
            // The landmark as the window will hold it: on the anchor's ray at
            // the triangulated depth (not the rays' midpoint `pw`, which can
            // lie on the other side of a camera when the rays nearly agree).
            let anchor = tr.obs[0].sid;
            let (rc, pc) = poses[&anchor];
            let z = (rc.transpose() * (pw - pc)).z;
            let on_ray = pc + rc * Vector3::new(tr.obs[0].xy[0], tr.obs[0].xy[1], 1.0) * z;
            // In front of every camera that sees it, and not absurdly far.
            let in_front = |(rc, pc): &(Matrix3<f64>, Vector3<f64>)| {
                let depth = (rc.transpose() * (on_ray - pc)).z;
                depth > 0.1 && depth < 200.0
            };
            let ok = tr
                .obs
                .iter()
                .all(|o| in_front(&poses[&o.sid]) && (o.uv1.is_none() || poses1.get(&o.sid).is_none_or(in_front)));
            if !ok {
                continue;
            }
            let lid = self.next_lid;
            self.next_lid += 1;
            self.values.insert(L(lid), Vector1::new(1.0 / z));
            tr.landmark = Some((lid, anchor));
        }
    }

    /// Drop observations with large errors and landmarks with invalid depth.
    fn reject_outliers(&mut self) {
        let limit = self.opts.outlier_sigmas * self.opts.pixel_sigma;
        let mut drop_landmarks = Vec::new();
        let mut drop_obs: Vec<(u64, u64, bool)> = Vec::new();
        for (&id, tr) in &self.tracks {
            let Some((lid, anchor)) = tr.landmark else { continue };
            let rho = self.values.get::<Vector1<f64>>(L(lid)).map(|v| v[0]).unwrap_or(f64::NAN);
            if !(rho > 1.0 / 200.0 && rho < 10.0) {
                drop_landmarks.push(id);
                continue;
            }
            let Some(a) = tr.obs.iter().find(|o| o.sid == anchor).map(|o| o.xy) else { continue };
            for o in &tr.obs {
                for (f, stereo) in self.observation_factors(anchor, lid, a, o) {
                    if self.residual_now(f.as_ref()).is_none_or(|r| r.norm() > limit) {
                        drop_obs.push((id, o.sid, stereo));
                    }
                }
            }
        }
        for (id, sid, stereo) in drop_obs {
            if let Some(tr) = self.tracks.get_mut(&id) {
                if stereo {
                    // Only the second camera's match goes.
                    tr.obs.iter_mut().filter(|o| o.sid == sid).for_each(|o| o.uv1 = None);
                } else {
                    tr.obs.retain(|o| o.sid != sid);
                }
            }
        }
        for id in drop_landmarks {
            if let Some(tr) = self.tracks.get_mut(&id) {
                if let Some((lid, _)) = tr.landmark.take() {
                    self.values.remove(L(lid));
                }
                // Keep only the newest observation: the track may be triangulated again.
                let last = tr.obs.pop();
                tr.obs.clear();
                tr.obs.extend(last);
            }
        }
    }

    /// Remove the newest state (a frame that is not a keyframe).
    fn drop_newest(&mut self) {
        let s = self.states.pop().expect("a newest state");
        self.links.pop();
        for k in [X(s.sid), V(s.sid), B(s.sid)] {
            self.values.remove(k);
        }
        for tr in self.tracks.values_mut() {
            tr.obs.retain(|o| o.sid != s.sid);
        }
    }

    /// Marginalize the oldest state and the landmarks anchored in it.
    fn marginalize_oldest(&mut self) {
        let old = self.states[0].sid;
        let mut keys = vec![X(old), V(old), B(old)];
        let anchored: Vec<u64> = self
            .tracks
            .iter()
            .filter(|(_, t)| matches!(t.landmark, Some((_, a)) if a == old))
            .map(|(&id, _)| id)
            .collect();
        for id in &anchored {
            keys.push(L(self.tracks[id].landmark.expect("anchored").0));
        }
        self.tally_oldest(old);
        let graph = self.build_graph();
        match marginalize(&graph, &self.values, &keys) {
            Ok(m) => self.marginal = Some(m.prior),
            Err(e) => {
                let msg = format!("marginalization failed ({e}); the window restarts from its newest state");
                self.warn(msg);
                self.reset_to_newest();
                return;
            }
        }
        if self.init_prior.as_ref().is_some_and(|p| p.sid == old) {
            self.init_prior = None;
        }
        for k in keys {
            self.values.remove(k);
        }
        for id in anchored {
            let tr = self.tracks.get_mut(&id).expect("track");
            tr.landmark = None;
            // Every observation went into the prior: only new ones may be used again.
            tr.obs.clear();
        }
        for tr in self.tracks.values_mut() {
            tr.obs.retain(|o| o.sid != old);
        }
        self.states.remove(0);
        self.links.remove(0);
    }

    /// Add the residuals of the factors leaving with state `old` (the oldest) to the tally.
    fn tally_oldest(&mut self, old: u64) {
        let mut t = self.residuals;
        for tr in self.tracks.values() {
            let Some((lid, anchor)) = tr.landmark else { continue };
            if anchor != old {
                continue;
            }
            let Some(a) = tr.obs.iter().find(|o| o.sid == anchor) else { continue };
            let mut counted = false;
            for o in &tr.obs {
                for (f, _) in self.observation_factors(anchor, lid, a.xy, o) {
                    if let Some(r) = self.residual_now(f.as_ref()) {
                        // The anchor's own pixel noise enters through the ray it fixes: ≈ 2σ² per row.
                        t.reprojection_chi2 += r.norm_squared() / (2.0 * self.opts.pixel_sigma.powi(2));
                        t.reprojection_rows += 2;
                        counted = true;
                    }
                }
            }
            t.landmarks += usize::from(counted);
        }
        if !self.links.is_empty() {
            let mut g = Graph::new();
            self.add_link(&mut g, 0);
            if let Ok(c) = g.chi2(&self.values) {
                t.imu_chi2 += c;
                t.imu_rows += g.entries().iter().map(|e| e.factor.residual_dim()).sum::<usize>();
                t.states += 1;
            }
        }
        self.residuals = t;
    }

    fn reset_to_newest(&mut self) {
        let (x, v, b) = self.last_good.expect("initialized");
        let t = self.states.last().map_or(0.0, |s| s.t);
        self.resets += 1;
        self.start(t, InitState { x, v, b, v_sigma: 0.5, tilt_sigma: None });
        if let Some(p) = self.init_prior.as_mut() {
            // Position and yaw stay the gauge; roll, pitch and biases loosen.
            p.b_sigma = [0.2, 0.2, 0.2, 0.02, 0.02, 0.02];
        }
    }

    fn failed(&self, sid: u64, predicted: &Isometry3F64) -> Option<String> {
        let (x, v, b) = self.state_values(sid);
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

    /// Process camera frame `index` of the input; returns its estimate once initialized.
    pub fn process(&mut self, index: usize) -> Option<FrameEstimate> {
        let frame = &self.input.frames[index];
        let t = frame.t;
        let t_start = Instant::now();
        if self.states.is_empty() {
            let init = self.initialize(index, t)?;
            let x = init.x;
            self.init_time = Some(t);
            self.start(t, init);
            let obs = self.frame_obs(index);
            self.add_observations(index, &obs);
            self.last_keyframe_obs = obs.clone();
            self.prev_frame_obs = obs;
            self.prev_frame_rotation = parts(&x).0;
            return Some(self.estimate(self.states[0].sid, true, t_start, None));
        }
        // IMU from the newest window state to this frame.
        let last = self.states.last().expect("state");
        let (ta, last_sid) = (last.t, last.sid);
        if t <= ta {
            return None;
        }
        let (xl, vl, bl) = self.state_values(last_sid);
        let bias = (bl.fixed_rows::<3>(0).into_owned(), bl.fixed_rows::<3>(3).into_owned());
        let (pim, gap) = preintegrate(&self.input.imu, ta, t, bias, self.opts.imu);
        let mut scale = 1.0;
        if gap > self.opts.max_imu_gap_s {
            self.warn(format!(
                "IMU gap of {:.0} ms before the frame at {t:.3} s: that interval's IMU factor is weakened",
                gap * 1e3
            ));
            scale = (gap / self.opts.max_imu_gap_s).powi(2) * 100.0;
        }
        if pim.is_empty() || pim.delta_t() <= 0.0 {
            self.warn(format!("no IMU samples before the frame at {t:.3} s: frame skipped"));
            return None;
        }
        // Predict the new state: from the last frame tracked since the newest
        // window state when there is one (a shorter IMU span), else from that state.
        let (ri, _) = parts(&xl);
        let tracked = self.last_tracked.filter(|(tt, ..)| *tt > ta && *tt < t).map(|(tt, xt, vt, bt)| {
            let bias = (bt.fixed_rows::<3>(0).into_owned(), bt.fixed_rows::<3>(3).into_owned());
            (xt, vt, preintegrate(&self.input.imu, tt, t, bias, self.opts.imu).0)
        });
        let (x0, v0, p0) = match &tracked {
            Some((xt, vt, pt)) => (*xt, *vt, pt),
            None => (xl, vl, &pim),
        };
        let (r0, q0) = parts(&x0);
        let dt = p0.delta_t();
        let rj = r0 * p0.delta_rotation();
        let vj = v0 + self.gravity * dt + r0 * p0.delta_velocity();
        let pj = q0 + v0 * dt + self.gravity * (0.5 * dt * dt) + r0 * p0.delta_position();
        let predicted = pose(&rj, &pj);
        let sid = self.next_sid;
        self.next_sid += 1;
        self.values.insert(X(sid), predicted);
        self.values.insert(V(sid), vj);
        self.values.insert(B(sid), bl);
        let obs = self.frame_obs(index);
        // Keyframe and zero-velocity decisions from the feature motion.
        let fx = self.input.camera.fx;
        // Parallax with the rotation (IMU-predicted) taken out: only translation
        // triangulates. The median, not the mean: a few landmarks close to the
        // camera would otherwise make every frame a keyframe while it turns slowly.
        let (r_bc, _) = parts(&self.input.body_from_camera);
        let parallax = |a: &HashMap<u64, [f64; 2]>, r_then: &Matrix3<f64>| -> (f64, usize) {
            let rel = (r_then * r_bc).transpose() * (rj * r_bc);
            let mut d = Vec::with_capacity(obs.len());
            for (id, xy) in &obs {
                if let Some(q) = a.get(id) {
                    let f = rel.transpose() * Vector3::new(q[0], q[1], 1.0);
                    if f.z > 1e-6 {
                        d.push(((xy[0] - f.x / f.z).powi(2) + (xy[1] - f.y / f.z).powi(2)).sqrt() * fx);
                    }
                }
            }
            let n = d.len();
            if n == 0 {
                return (f64::INFINITY, 0);
            }
            let (_, median, _) = d.select_nth_unstable_by(n / 2, f64::total_cmp);
            (*median, n)
        };
        let (par_kf, common_kf) = parallax(&self.last_keyframe_obs, &ri);
        let (par_prev, common_prev) = parallax(&self.prev_frame_obs, &self.prev_frame_rotation);
        // At rest: hardly any motion since the previous frame, or motion within
        // the pixel noise over the last span — there without taking out the
        // rotation: the IMU-predicted one errs by more than the noise over
        // half a second (BMI055: 0.2°, 1.7 px), and at rest there is none.
        let span = self.opts.zero_velocity_span_s;
        let rest_over_span = self.recent.front().and_then(|(t_ref, obs_ref)| {
            let (par, common) = parallax(obs_ref, &rj);
            let limit = self.opts.zero_velocity_px.max(super::REST_NOISE_SIGMAS * self.opts.pixel_sigma);
            (t - t_ref >= 0.8 * span && common >= 10 && par < limit).then_some(*t_ref)
        });
        let rest_since_prev =
            (common_prev >= 10 && par_prev < self.opts.zero_velocity_px).then(|| self.recent.back().map_or(t, |f| f.0));
        self.rest_since =
            rest_over_span.or(rest_since_prev).map(|since| self.rest_since.map_or(since, |r| r.min(since)));
        let zero_velocity = self.rest_since.is_some();
        let kf_t = self.states.last().map_or(t, |s| s.t);
        let keyframe = par_kf >= self.opts.keyframe_parallax_px
            || t - kf_t >= self.opts.keyframe_max_interval_s
            || common_kf * 2 < self.last_keyframe_obs.len()
            || common_kf < 10;
        if obs.is_empty() {
            if self.no_feature_since.is_none() {
                self.no_feature_since = Some(t);
                self.warn(format!("no features from {t:.3} s on: IMU only until features return"));
            }
        } else if let Some(t0) = self.no_feature_since.take() {
            self.warn(format!("features back at {t:.3} s after {:.2} s without", t - t0));
        }
        self.states.push(State { sid, t, rest_since: self.rest_since });
        self.links.push((Arc::new(pim), scale));
        self.add_observations(index, &obs);
        self.prev_frame_obs = obs.clone();
        self.prev_frame_rotation = rj;
        self.recent.push_back((t, obs.clone()));
        while self.recent.front().is_some_and(|f| f.0 < t - span) {
            self.recent.pop_front();
        }
        // A frame at rest or a window with few landmarks still gets the full
        // solve: its zero-velocity prior or its IMU link is what holds the
        // window's velocities and biases then.
        if !keyframe && !zero_velocity && !self.opts.solve_window_every_frame && self.landmark_count() >= 30 {
            // Not triangulated from here: this frame's pose is only the IMU's
            // prediction now, and the landmark's depth would stay fixed.
            return self.track_frame(index, sid, &predicted, vj, bl, obs, t_start);
        }
        self.triangulate_new();
        // Solve.
        let graph = self.build_graph();
        // The σ of the new state, from the solve's own last linearization.
        let (solved, covariances) = self.solve(&graph, &self.values, &[X(sid), V(sid), B(sid)], vec!['l']);
        let failure = match solved {
            Ok((v, _)) => {
                self.values = v;
                self.failed(sid, &predicted)
            }
            Err(e) => Some(format!("the solver failed: {e}")),
        };
        if let Some(why) = failure {
            return self.recover(index, &why, (predicted, vj, bl), obs, t_start);
        }
        self.reintegrate_if_needed();
        self.reject_outliers();
        let est = self.estimate(sid, keyframe, t_start, covariances.as_ref());
        self.last_good = Some(self.state_values(sid));
        if keyframe {
            self.keyframe_std = est.std;
            self.last_keyframe_obs = obs;
            if self.states.len() > self.opts.window {
                self.marginalize_oldest();
            }
        } else {
            self.drop_newest();
        }
        Some(est)
    }

    /// A frame that will not become a keyframe, with the window held fixed:
    /// only its own pose, velocity and bias are solved, from the IMU factor to
    /// the last keyframe and its observations of the window's landmarks
    /// (motion-only, as a keyframe-based tracker does). Its σ adds the last
    /// keyframe's marginal variances to the conditional ones of this solve.
    #[allow(clippy::too_many_arguments)]
    fn track_frame(
        &mut self,
        index: usize,
        sid: u64,
        predicted: &Isometry3F64,
        vj: Vector3<f64>,
        bl: Vector6<f64>,
        obs: HashMap<u64, [f64; 2]>,
        t_start: Instant,
    ) -> Option<FrameEstimate> {
        let t = self.input.frames[index].t;
        let n = self.states.len();
        let prev = self.states[n - 2].sid;
        let mut g = Graph::new();
        self.add_link(&mut g, n - 2);
        if self.states[n - 1].rest_since.is_some() {
            add_rest_prior(&mut g, sid);
        }
        let mut values = Values::new();
        let copy = |values: &mut Values, key, constant: bool| {
            if !values.contains(key) {
                if let Ok(v) = self.values.get_dyn(key) {
                    values.insert_dyn(key, v.clone_box());
                    values.set_constant(key, constant);
                }
            }
        };
        for key in [X(prev), V(prev), B(prev)] {
            copy(&mut values, key, true);
        }
        for key in [X(sid), V(sid), B(sid)] {
            copy(&mut values, key, false);
        }
        let noise = NoiseModel::isotropic(2, self.opts.pixel_sigma).expect("positive pixel sigma");
        let huber = Arc::new(Huber(self.opts.huber));
        for tr in self.tracks.values() {
            let Some((lid, anchor)) = tr.landmark else { continue };
            if anchor == sid || tr.obs.len() < 4 {
                continue;
            }
            let (Some(a), Some(o)) = (tr.obs.iter().find(|o| o.sid == anchor), tr.obs.iter().find(|o| o.sid == sid))
            else {
                continue;
            };
            copy(&mut values, X(anchor), true);
            copy(&mut values, L(lid), true);
            for (factor, _) in self.observation_factors(anchor, lid, a.xy, o) {
                g.add_entry(tumble_solvers::FactorEntry { factor, noise: noise.clone(), loss: Some(huber.clone()) });
            }
        }
        let keys = [X(sid), V(sid), B(sid)];
        let (solved, covariances) = self.solve(&g, &values, &keys, Vec::new());
        let failure = match solved {
            Ok((v, _)) => {
                for key in keys {
                    if let Ok(x) = v.get_dyn(key) {
                        self.values.insert_dyn(key, x.clone_box());
                    }
                }
                self.failed(sid, predicted)
            }
            Err(e) => Some(format!("the solver failed: {e}")),
        };
        if let Some(why) = failure {
            return self.recover(index, &why, (*predicted, vj, bl), obs, t_start);
        }
        let mut est = self.estimate(sid, false, t_start, covariances.as_ref());
        for (row, kf) in est.std.iter_mut().zip(&self.keyframe_std) {
            for (s, k) in row.iter_mut().zip(kf) {
                if k.is_finite() {
                    *s = s.hypot(*k);
                }
            }
        }
        self.last_good = Some(self.state_values(sid));
        let (x, v, b) = self.state_values(sid);
        self.last_tracked = Some((t, x, v, b));
        self.drop_newest();
        est.solve_s = t_start.elapsed().as_secs_f64();
        Some(est)
    }

    /// One Levenberg–Marquardt solve of `graph` from `values` with the
    /// estimator's options, eliminating the key families `eliminate`; with
    /// `opts.covariances`, the marginal covariances of `keys` from the
    /// solve's own last linearization too.
    #[allow(clippy::type_complexity)]
    fn solve(
        &self,
        graph: &Graph,
        values: &Values,
        keys: &[tumble_solvers::Key],
        eliminate: Vec<char>,
    ) -> (Result<(Values, tumble_solvers::Summary), tumble_solvers::SolveError>, Option<Covariances>) {
        let optimizer = Optimizer::new(LmOptions {
            max_iterations: self.opts.max_iterations,
            function_tolerance: self.opts.function_tolerance,
            eliminate,
            log_iterations: false,
            ..LmOptions::default()
        });
        if !self.opts.covariances {
            return (optimizer.optimize(graph, values), None);
        }
        let mut covariances = None;
        let solved = optimizer.optimize_with_covariances(graph, values, keys).map(|(v, s, c)| {
            covariances = c.ok();
            (v, s)
        });
        (solved, covariances)
    }

    /// After a failed solve at frame `index`: warn, restart the window from
    /// `last_good` (the frame's predicted state), and report that start.
    fn recover(
        &mut self,
        index: usize,
        why: &str,
        last_good: (Isometry3F64, Vector3<f64>, Vector6<f64>),
        obs: HashMap<u64, [f64; 2]>,
        t_start: Instant,
    ) -> Option<FrameEstimate> {
        let t = self.input.frames[index].t;
        self.warn(format!("failure at {t:.3} s: {why}; reset from the last good state"));
        self.last_good = Some(last_good);
        self.reset_to_newest();
        self.add_observations(index, &obs);
        self.last_keyframe_obs = obs;
        Some(self.estimate(self.states[0].sid, true, t_start, None))
    }

    fn reintegrate_if_needed(&mut self) {
        for i in 0..self.links.len() {
            let sid = self.states[i].sid;
            let b = *self.values.get::<Vector6<f64>>(B(sid)).expect("state");
            let (ba, bg) = (b.fixed_rows::<3>(0).into_owned(), b.fixed_rows::<3>(3).into_owned());
            let (la, lg) = self.links[i].0.bias();
            if (ba - la).norm() > 0.05 || (bg - lg).norm() > 0.005 {
                let mut p = (*self.links[i].0).clone();
                p.reintegrate(ba, bg);
                self.links[i].0 = Arc::new(p);
            }
        }
    }

    fn frame_obs(&self, index: usize) -> HashMap<u64, [f64; 2]> {
        let cam = &self.input.camera;
        self.input.frames[index].features.iter().filter_map(|(id, uv)| cam.unproject(*uv).map(|xy| (*id, xy))).collect()
    }

    /// Add frame `index`'s observations (undistorted `obs` by track) to the newest state.
    fn add_observations(&mut self, index: usize, obs: &HashMap<u64, [f64; 2]>) {
        let sid = self.states.last().expect("state").sid;
        // The second camera's matches in this frame that it can undistort,
        // when they go into the window (`stereo_window`).
        let stereo: HashMap<u64, [f64; 2]> = match (&self.input.stereo, self.opts.stereo_window) {
            (Some(st), true) => {
                st.features[index].iter().filter(|(_, uv)| st.camera.unproject(*uv).is_some()).copied().collect()
            }
            _ => HashMap::new(),
        };
        let (r_bc, t_bc) = parts(&self.input.body_from_camera);
        let (rj, pj) = parts(self.values.get::<Isometry3F64>(X(sid)).expect("newest state"));
        for (id, uv) in &self.input.frames[index].features {
            let Some(&xy) = obs.get(id) else { continue };
            let tr = self.tracks.entry(*id).or_default();
            // A landmark the predicted pose would see behind the camera, or far
            // from where it is seen: skip the observation.
            if tr.landmark.is_some() {
                let Some(pw) = landmark_world(&self.values, &self.input.body_from_camera, tr) else {
                    continue;
                };
                let pc = r_bc.transpose() * (rj.transpose() * (pw - pj) - t_bc);
                if pc.z < 0.05 {
                    continue;
                }
                // Far from where the predicted pose sees it: a gross outlier,
                // kept out of the solve rather than only down-weighted there.
                let gate = self.opts.prediction_gate_px;
                match self.input.camera.project(&[pc.x, pc.y, pc.z]) {
                    Some(p) if (p[0] - uv[0]).hypot(p[1] - uv[1]) <= gate => {}
                    _ => continue,
                }
            }
            let uv1 = stereo.get(id).copied();
            tr.obs.push(Obs { sid, uv: *uv, xy, uv1 });
        }
        // Forget tracks that are no longer seen and have no landmark.
        let seen: std::collections::HashSet<u64> = self.input.frames[index].features.iter().map(|f| f.0).collect();
        self.tracks.retain(|id, t| seen.contains(id) || t.landmark.is_some());
    }

    /// The estimate of state `sid`; its σ from `covariances` (of the frame's
    /// solve, at the solution) when given, else NaN.
    fn estimate(&self, sid: u64, keyframe: bool, t0: Instant, covariances: Option<&Covariances>) -> FrameEstimate {
        let (x, v, b) = self.state_values(sid);
        let (r, p) = parts(&x);
        let q = UnitQuaternion::from_rotation_matrix(&nalgebra::Rotation3::from_matrix_unchecked(r));
        let mut std = [[f64::NAN; 3]; 5];
        if let Some(c) = covariances {
            let d = |k, i: usize| c.get(k).map_or(f64::NAN, |m| m[(i, i)].max(0.0).sqrt());
            let blocks = [(X(sid), 0), (X(sid), 3), (V(sid), 0), (B(sid), 0), (B(sid), 3)];
            for (row, (key, off)) in std.iter_mut().zip(blocks) {
                for (i, s) in row.iter_mut().enumerate() {
                    *s = d(key, i + off);
                }
            }
        }
        let state = self.states.iter().find(|s| s.sid == sid).expect("state");
        FrameEstimate {
            t: state.t,
            keyframe,
            position: vec3(&p),
            rotation: [q.w, q.i, q.j, q.k],
            velocity: vec3(&v),
            bias_accel: [b[0], b[1], b[2]],
            bias_gyro: [b[3], b[4], b[5]],
            std,
            landmarks: self.landmark_count(),
            solve_s: t0.elapsed().as_secs_f64(),
        }
    }
}

/// Run the estimator over every frame of `input`. `progress` is called with
/// `(frames done, frames total)`.
pub fn run(
    input: &VioInput,
    opts: &VioOptions,
    progress: Option<&mut dyn FnMut(usize, usize)>,
) -> Result<VioResult, String> {
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
) -> Result<VioResult, String> {
    input.check()?;
    let t0 = Instant::now();
    let mut est = Estimator::new(input, opts);
    let mut out = VioResult::default();
    for i in 0..input.frames.len() {
        if let Some(e) = est.process(i) {
            observe(&est, i, &e);
            out.estimates.push(e);
        }
        if let Some(p) = progress.as_mut() {
            p(i + 1, input.frames.len());
        }
    }
    if est.init_time.is_none() {
        return Err(match opts.init {
            Init::Static => format!(
                "could not initialize: no {:.1} s window at rest before any frame (the static initialization needs the recording to start at rest; \
                 use --init auto or motion for a moving start, or --init-from-groundtruth to evaluate from a known state)",
                opts.init_window_s
            ),
            Init::Motion | Init::Auto => format!(
                "could not initialize: {}no {:.1} s window of motion that observes scale \
                 (last attempt {}; give --init-from-groundtruth to evaluate from a known state)",
                if opts.init == Init::Auto { format!("no {:.1} s window at rest and ", opts.init_window_s) } else { String::new() },
                opts.init_motion_window_s,
                est.init_failure.as_deref().unwrap_or("none: too few frames")
            ),
            Init::Given { t, .. } => format!("could not initialize: no frame after the given initial state at {t:.3} s"),
        });
    }
    out.warnings = est.warnings;
    out.resets = est.resets;
    out.init_time = est.init_time;
    out.residuals = est.residuals;
    out.wall_s = t0.elapsed().as_secs_f64();
    Ok(out)
}
