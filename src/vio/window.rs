//! The sliding window's states and what links them: a pose `X`, velocity
//! `V` and bias `B` per state, the IMU preintegration between consecutive
//! states, the first state's prior (or, once it is gone, the marginalization
//! prior), and the zero-velocity pseudo-measurements of states at rest.

use super::landmarks::RayTally;
use super::InitOptions;
use crate::model::geometry::parts;
use nalgebra::{DMatrix, Matrix3, UnitQuaternion, Vector3, Vector6};
use std::sync::Arc;
use tumble_factors::imu_preint::Preintegrated;
use tumble_factors::{bias_random_walk_axes, BetweenFactor, ImuFactor, PriorFactor};
use tumble_solvers::sophus_lie::Isometry3F64;
use tumble_solvers::{Graph, MarginalPrior, NoiseModel, Values, B, V, X};

/// A state of the window.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct State {
    /// Its id (keys `X(sid)`, `V(sid)`, `B(sid)`).
    pub sid: u64,
    /// Frame time \[s\].
    pub t: f64,
    /// At rest (zero-velocity pseudo-measurement), continuously since this
    /// time \[s\]; None while moving.
    pub rest_since: Option<f64>,
}

/// A state's pose, velocity and bias `[b_a, b_g]`.
pub(crate) type StateValues = (Isometry3F64, Vector3<f64>, Vector6<f64>);

/// Velocity prior σ of a start at rest or from a given state \[m/s\].
pub(crate) const STATIC_V_SIGMA: f64 = 0.01;

/// Gyro-bias prior σ of a start whose bias was measured (at rest) or given \[rad/s\].
pub(crate) const START_GYRO_BIAS_SIGMA: f64 = 5e-3;

/// Standard deviation of the zero-velocity pseudo-measurement of a frame at
/// rest \[m/s\] (and of its position change since a previous frame at rest,
/// times the time between them).
const REST_SPEED_SIGMA: f64 = 0.01;

/// The first state of a window and how sure it is.
#[derive(Debug, Clone)]
pub(crate) struct InitState {
    /// Pose.
    pub x: Isometry3F64,
    /// Velocity \[m/s\].
    pub v: Vector3<f64>,
    /// Bias `[b_a, b_g]`.
    pub b: Vector6<f64>,
    /// Velocity prior σ \[m/s\].
    pub v_sigma: f64,
    /// Roll/pitch prior σ \[rad\]; default: what the accelerometer-bias prior allows.
    pub tilt_sigma: Option<f64>,
    /// Gyro-bias prior σ \[rad/s\]; default [`START_GYRO_BIAS_SIGMA`] (a bias
    /// measured at rest, or given).
    pub gyro_bias_sigma: Option<f64>,
    /// A start in motion (or a restart): the window then fills
    /// ([`Window::filling`]), and a start its features contradict is made
    /// again ([`Window::contradicted_start`]).
    pub in_motion: bool,
}

impl InitState {
    /// A start at rest (or from a given state): velocity known to [`STATIC_V_SIGMA`].
    pub fn at_rest(x: Isometry3F64, v: Vector3<f64>, b: Vector6<f64>) -> Self {
        InitState { x, v, b, v_sigma: STATIC_V_SIGMA, tilt_sigma: None, gyro_bias_sigma: None, in_motion: false }
    }
}

/// The prior on the window's first state until it is marginalized.
#[derive(Debug, Clone)]
pub(crate) struct InitPrior {
    sid: u64,
    pose: Isometry3F64,
    pose_cov: DMatrix<f64>,
    v: Vector3<f64>,
    v_sigma: f64,
    b: Vector6<f64>,
    /// Bias prior σ `[b_a (m/s²), b_g (rad/s)]`.
    pub b_sigma: [f64; 6],
}

/// An IMU link linearized at the window's values ([`Window::link_linearization`]).
pub(crate) struct LinkLinearization {
    /// `[X(a), V(a), B(a), X(b), V(b)]`.
    pub keys: [tumble_solvers::Key; 5],
    /// Raw residual `[θ, p, v]`.
    pub residual: nalgebra::DVector<f64>,
    /// Jacobian over the keys, 9 × 24.
    pub jacobian: DMatrix<f64>,
    /// The covariance the factor is weighed with.
    pub covariance: DMatrix<f64>,
    /// The noise figures it was integrated with.
    pub params: tumble_factors::imu_preint::PreintegrationParams,
}

/// The window: states, values, IMU links and priors.
#[derive(Default)]
pub(crate) struct Window {
    /// The states' (and the landmarks') values.
    pub values: Values,
    /// The states, oldest first.
    pub states: Vec<State>,
    /// Preintegration from state `i` to `i + 1`, with its covariance scale (weakened over IMU gaps).
    pub links: Vec<(Arc<Preintegrated>, f64)>,
    /// The marginalization prior of what left the window.
    pub marginal: Option<MarginalPrior>,
    /// The first state's prior, until that state is marginalized.
    pub init_prior: Option<InitPrior>,
    next_sid: u64,
    /// Gravity in the world \[m/s²\] (`[0, 0, −g]`).
    pub gravity: Vector3<f64>,
    /// The camera's online calibration, when it is estimated.
    pub camera: Option<super::online_calib::CameraPrior>,
    /// States marginalized since the window started.
    pub marginalized: usize,
    /// Whether the window started in motion ([`InitState::in_motion`]).
    started_in_motion: bool,
    /// When it started \[s\].
    started_at: f64,
    /// The most landmarks it has held since ([`Window::watch_landmarks`]).
    most_landmarks: usize,
    /// The recent triangulations: time \[s\], whether the frame had enough
    /// features, how the rays met ([`Window::watch_landmarks`]).
    rays: std::collections::VecDeque<(f64, bool, RayTally)>,
}

impl Window {
    /// An empty window under gravity `g` \[m/s²\].
    pub fn new(g: f64) -> Window {
        Window { gravity: Vector3::new(0.0, 0.0, -g), ..Default::default() }
    }

    /// The window with the camera's online calibration `camera`.
    pub fn with_camera(self, camera: Option<super::online_calib::CameraPrior>) -> Window {
        Window { camera, ..self }
    }

    /// Whether the window is still filling after a start in motion (or a
    /// restart): it began from one state and no landmark, and holds fewer
    /// than `size` states, none marginalized yet. While it fills, a frame that
    /// the window's landmarks cannot place (none seen by enough of its
    /// states) stays in it as a keyframe whatever its parallax, as VINS-Mono
    /// keeps every frame until its window is full. Dropped instead, each such
    /// frame was solved against the first state alone — two views over an
    /// ever longer IMU link — and moved that state before leaving: on EuRoC's
    /// imu_april (a planar target a metre away, parallax under the keyframe
    /// threshold for 0.8 s) sixteen such solves walked the gyro bias 0.14
    /// rad/s off with a σ of 1.3·10⁻³.
    pub fn filling(&self, size: usize) -> bool {
        self.started_in_motion && self.marginalized == 0 && self.states.len() < size
    }

    /// Whether the window started in motion (or from a restart) and nothing
    /// has confirmed that start yet: fewer than a window's length (`size`) of
    /// its states have been marginalized, so the window and its prior rest on
    /// the start's estimate and one window of frames (the online camera
    /// calibration is held for as long, for the same reason).
    pub fn unconfirmed(&self, size: usize) -> bool {
        self.started_in_motion && self.marginalized < size
    }

    /// When the window started \[s\].
    pub fn started_at(&self) -> f64 {
        self.started_at
    }

    /// Empty the window: no state, link or prior; the camera's calibration
    /// keeps what it learnt, under its prior alone.
    pub fn clear(&mut self) {
        let camera_now = super::online_calib::current(&self.values);
        self.values = Values::new();
        if let Some(c) = &self.camera {
            c.insert(&mut self.values, camera_now);
        }
        self.states.clear();
        self.links.clear();
        self.marginal = None;
        self.init_prior = None;
        self.marginalized = 0;
        self.most_landmarks = 0;
        self.rays.clear();
    }

    /// Note, after frame `t`'s triangulation, the landmarks the window holds,
    /// the features the frame had and how the rays of the other tracks met
    /// (`rays`), for [`Window::contradicted`]; `span` \[s\] is how long
    /// the tallies are kept.
    pub fn watch_landmarks(
        &mut self,
        t: f64,
        landmarks: usize,
        features: usize,
        rays: RayTally,
        min_landmarks: usize,
        span: f64,
    ) {
        self.most_landmarks = self.most_landmarks.max(landmarks);
        self.rays.push_back((t, features >= min_landmarks, rays));
        while self.rays.front().is_some_and(|(t0, ..)| *t0 < t - span) {
            self.rays.pop_front();
        }
    }

    /// Whether the estimate is contradicted by the features at time `t`, and
    /// since when \[s\] (its estimates from then on are wrong), with why;
    /// `min_landmarks` is the fewest features (and landmarks) that carry an
    /// estimate, and `span` \[s\] the span of evidence (the span a start in
    /// motion is estimated from, [`super::InitOptions::motion_window_s`]).
    ///
    /// - A start in motion whose window, for longer than that span, never
    ///   held `min_landmarks` landmarks while the frames had that many
    ///   features: its poses put the features' rays behind one another or
    ///   apart (a velocity or an attitude off). On EuRoC V2_01 started at 40
    ///   s (0.26 m/s, a gyro bias of 0.08 rad/s the features did not
    ///   determine) the start was 5° and 0.44 m/s off, no landmark was ever
    ///   triangulated, and the estimate reached 300 m/s unreported.
    /// - Any window, once it has lasted that span: over the last span every
    ///   frame had the features, and at most of the triangulations' tries (of
    ///   the tracks seen by two states or more) the rays missed one another
    ///   from its poses, though they had the parallax to meet. Where the
    ///   estimate is right they miss at 0–6 % of the tries over a whole run
    ///   and at most 37 % over any such span (EuRoC with a simulated camera,
    ///   V1_01 with EqVIO's tracks, imu_april, a simulated walk); a camera at
    ///   rest or turning on the spot gives nearly parallel rays, which do not
    ///   count as missing. On a simulated walk whose gyro read 2 rad/s too
    ///   much over 1 s (a shock) they missed at up to 62 %, and the estimate
    ///   flew on for 17 s at up to 250 m/s until a position jump reset it.
    pub fn contradicted(&self, t: f64, min_landmarks: usize, span: f64) -> Option<(f64, String)> {
        if self.started_in_motion && self.most_landmarks < min_landmarks {
            // This frame had the features (and, as the window never held
            // them, too few landmarks).
            let features = self.rays.back().is_some_and(|(_, enough, _)| *enough);
            let span_now = t - self.started_at;
            return (features && span_now > span).then(|| {
                (
                    self.started_at,
                    format!(
                        "the start in motion at {:.3} s is contradicted by the features: over {span_now:.2} s they \
                         gave fewer than {min_landmarks} landmarks from its poses (its velocity or attitude is off)",
                        self.started_at
                    ),
                )
            });
        }
        let (t0, ..) = *self.rays.front()?;
        let (agreed, disagreed) = self.rays.iter().fold((0, 0), |(a, d), (_, _, r)| (a + r.agreed, d + r.disagreed));
        let seen = self.rays.iter().all(|(_, enough, _)| *enough);
        // The tallies must cover the span (to within a frame or two: a
        // single frame's tally decides nothing) and outvote the rest, by at
        // least the landmarks an estimate needs.
        let covered = t - self.started_at > span && t - t0 > 0.9 * span;
        if !(covered && seen && disagreed > agreed.max(min_landmarks)) {
            return None;
        }
        // Withdrawn from the first triangulation at which most rays missed.
        let from = self.rays.iter().find(|(_, _, r)| r.disagreed > r.agreed).map_or(t0, |(t, ..)| *t);
        Some((
            from,
            format!(
                "the estimate is contradicted by the features from {from:.3} s on: over {:.2} s the rays of the \
                 tracks missed one another from its poses at {disagreed} of {} tries (its velocity or attitude is \
                 off: an IMU shock or saturation?)",
                t - t0,
                agreed + disagreed
            ),
        ))
    }

    /// A new state id.
    pub fn next_id(&mut self) -> u64 {
        let sid = self.next_sid;
        self.next_sid += 1;
        sid
    }

    /// Start the window afresh at time `t` from `init`: one state with a
    /// prior. Roll and pitch are as uncertain as an accelerometer bias makes
    /// them (or `init.tilt_sigma`); yaw and position are fixed (the gauge of VIO).
    pub fn start(&mut self, t: f64, init: InitState, opts: &InitOptions) {
        let InitState { x, v, b, v_sigma, tilt_sigma, gyro_bias_sigma, in_motion } = init;
        let sid = self.next_id();
        self.clear();
        self.values.insert(X(sid), x);
        self.values.insert(V(sid), v);
        self.values.insert(B(sid), b);
        self.states = vec![State { sid, t, rest_since: None }];
        self.started_in_motion = in_motion;
        self.started_at = t;
        let (r, _) = parts(&x);
        let tilt = tilt_sigma.unwrap_or((opts.bias_accel_sigma / -self.gravity.z).max(1e-3));
        let u = r.transpose() * Vector3::z();
        let rot_cov = Matrix3::identity() * tilt * tilt + u * u.transpose() * (1e-6 - tilt * tilt);
        let mut pose_cov = DMatrix::identity(6, 6) * 1e-6;
        pose_cov.view_mut((0, 0), (3, 3)).copy_from(&rot_cov);
        let sa = opts.bias_accel_sigma;
        let sg = gyro_bias_sigma.unwrap_or(START_GYRO_BIAS_SIGMA);
        self.init_prior = Some(InitPrior { sid, pose: x, pose_cov, v, v_sigma, b, b_sigma: [sa, sa, sa, sg, sg, sg] });
    }

    /// State `sid`'s values.
    pub fn state_values(&self, sid: u64) -> StateValues {
        (
            *self.values.get::<Isometry3F64>(X(sid)).expect("window state"),
            *self.values.get::<Vector3<f64>>(V(sid)).expect("window state"),
            *self.values.get::<Vector6<f64>>(B(sid)).expect("window state"),
        )
    }

    /// The ids of the states, oldest first.
    pub fn ids(&self) -> Vec<u64> {
        self.states.iter().map(|s| s.sid).collect()
    }

    /// Append state `sid` at `t` with its predicted values and the IMU link
    /// from the newest state (covariance scaled by `scale`).
    pub fn push(&mut self, state: State, x: StateValues, link: (Preintegrated, f64)) {
        self.values.insert(X(state.sid), x.0);
        self.values.insert(V(state.sid), x.1);
        self.values.insert(B(state.sid), x.2);
        self.states.push(state);
        self.links.push((Arc::new(link.0), link.1));
    }

    /// Remove the newest state (a frame that is not a keyframe) and its link;
    /// returns its id.
    pub fn drop_newest(&mut self) -> u64 {
        let s = self.states.pop().expect("a newest state");
        self.links.pop();
        for k in [X(s.sid), V(s.sid), B(s.sid)] {
            self.values.remove(k);
        }
        s.sid
    }

    /// Add the priors, the IMU links and the rest pseudo-measurements to `g`.
    pub fn add_factors(&self, g: &mut Graph) {
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
        if let Some(c) = &self.camera {
            c.add_factors(g);
        }
        for i in 0..self.links.len() {
            self.add_link(g, i);
        }
        for (i, s) in self.states.iter().enumerate() {
            let Some(rest_since) = s.rest_since else { continue };
            add_rest_prior(g, s.sid);
            // At rest ever since the previous state: the position stays (the
            // IMU factor alone lets it wander by the accelerometer's noise,
            // centimetres per second for a MEMS part).
            if let Some(prev) = i.checked_sub(1).map(|k| &self.states[k]).filter(|p| p.t >= rest_since) {
                let sp = (REST_SPEED_SIGMA * (s.t - prev.t)).max(1e-4);
                let noise = NoiseModel::diagonal(&[10.0, 10.0, 10.0, sp, sp, sp]).expect("positive");
                g.add(BetweenFactor::new(X(prev.sid), X(s.sid), Isometry3F64::identity()), noise);
            }
        }
    }

    /// Add link `i`'s IMU factor and bias random walk (state `i` to `i + 1`,
    /// the walks of the noise it was preintegrated with) to `g`.
    pub fn add_link(&self, g: &mut Graph, i: usize) {
        let (pim, scale) = &self.links[i];
        let (a, b) = (self.states[i].sid, self.states[i + 1].sid);
        let f = ImuFactor::new([X(a), V(a), B(a), X(b), V(b)], pim.clone(), self.gravity);
        if let Ok(n) = f.noise_model_scaled(*scale) {
            g.add(f, n);
        }
        let dt = pim.delta_t().max(1e-3);
        let imu = pim.params();
        if let Ok((rw, n)) = bias_random_walk_axes(B(a), B(b), imu.accel_walk().into(), imu.gyro_walk().into(), dt) {
            g.add(rw, n);
        }
    }

    /// Link `i`'s IMU factor linearized at the window's values: its keys
    /// `[X, V, B, X, V]`, raw residual (9), Jacobian (9 × 24) and the
    /// covariance it is weighed with (9 × 9); None when it cannot be evaluated.
    pub fn link_linearization(&self, i: usize) -> Option<LinkLinearization> {
        let (pim, scale) = self.links.get(i)?;
        let (a, b) = (self.states[i].sid, self.states[i + 1].sid);
        let keys = [X(a), V(a), B(a), X(b), V(b)];
        let lin = self.values.linearize(&ImuFactor::new(keys, pim.clone(), self.gravity))?;
        let cols: usize = lin.jacobians.iter().map(|j| j.ncols()).sum();
        let mut j = DMatrix::zeros(9, cols);
        let mut c0 = 0;
        for jk in &lin.jacobians {
            j.view_mut((0, c0), (9, jk.ncols())).copy_from(jk);
            c0 += jk.ncols();
        }
        let cov = pim.covariance() * *scale;
        Some(LinkLinearization {
            keys,
            residual: lin.residual,
            jacobian: j,
            covariance: DMatrix::from_fn(9, 9, |r, c| cov[(r, c)]),
            params: *pim.params(),
        })
    }

    /// Integrate every link again with the noise figures `params` (their
    /// samples and bias estimates kept).
    pub fn reweight_links(&mut self, params: tumble_factors::imu_preint::PreintegrationParams) {
        for link in &mut self.links {
            let mut p = (*link.0).clone();
            p.reintegrate_with(params);
            link.0 = Arc::new(p);
        }
    }

    /// Preintegrate a link again where its state's bias moved away from the
    /// one it was integrated with (by 0.05 m/s² or 0.005 rad/s).
    pub fn reintegrate_if_needed(&mut self) {
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

    /// Remove the oldest state, its link and its keys `keys` (with the
    /// landmarks marginalized with it), after `prior` took their information.
    pub fn remove_oldest(&mut self, prior: MarginalPrior, keys: &[tumble_solvers::Key]) {
        let old = self.states[0].sid;
        self.marginal = Some(prior);
        self.marginalized += 1;
        if self.init_prior.as_ref().is_some_and(|p| p.sid == old) {
            self.init_prior = None;
        }
        for &k in keys {
            self.values.remove(k);
        }
        self.states.remove(0);
        self.links.remove(0);
    }

    /// Each state's time, position \[m\] and rotation world←body `[w, x, y, z]`.
    pub fn poses(&self) -> Vec<(f64, [f64; 3], [f64; 4])> {
        self.states
            .iter()
            .filter_map(|s| {
                let x = self.values.get::<Isometry3F64>(X(s.sid)).ok()?;
                let (r, p) = parts(x);
                let q = UnitQuaternion::from_matrix(&r);
                Some((s.t, [p.x, p.y, p.z], [q.w, q.i, q.j, q.k]))
            })
            .collect()
    }
}

/// The zero-velocity pseudo-measurement of state `sid`, at rest.
pub(crate) fn add_rest_prior(g: &mut Graph, sid: u64) {
    g.add(PriorFactor::new(V(sid), Vector3::zeros()), NoiseModel::isotropic(3, REST_SPEED_SIGMA).expect("positive"));
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::geometry::pose;
    use crate::vio::VioOptions;
    use tumble_factors::imu_preint::PreintegrationParams;
    use tumble_solvers::{LmOptions, Optimizer};

    /// A window of `n` states 0.1 s apart, at rest, IMU reading gravity.
    fn at_rest(n: usize, rest: bool) -> (Window, VioOptions) {
        let opts = VioOptions::default();
        let mut w = Window::new(opts.noise.gravity);
        w.start(
            0.0,
            InitState::at_rest(pose(&Matrix3::identity(), &Vector3::zeros()), Vector3::zeros(), Vector6::zeros()),
            &opts.init,
        );
        for k in 1..n {
            let mut pim = Preintegrated::new(PreintegrationParams::default(), Vector3::zeros(), Vector3::zeros());
            for _ in 0..20 {
                pim.integrate(Vector3::new(0.0, 0.0, opts.noise.gravity), Vector3::zeros(), 0.005);
            }
            let sid = w.next_id();
            let rest_since = rest.then_some(0.0);
            let x = w.state_values(w.states.last().unwrap().sid);
            w.push(State { sid, t: 0.1 * k as f64, rest_since }, x, (pim, 1.0));
        }
        (w, opts)
    }

    #[test]
    fn a_window_at_rest_stays_at_rest() {
        let (mut w, _) = at_rest(5, true);
        // Disturb the newest state; the IMU links and rest priors pull it back.
        let newest = w.states.last().unwrap().sid;
        w.values.insert(V(newest), Vector3::new(0.3, 0.0, 0.0));
        let mut g = Graph::new();
        w.add_factors(&mut g);
        let (solved, _) = Optimizer::new(LmOptions::default()).optimize(&g, &w.values).unwrap();
        let v = solved.get::<Vector3<f64>>(V(newest)).unwrap();
        let (_, p) = parts(solved.get::<Isometry3F64>(X(newest)).unwrap());
        assert!(v.norm() < 1e-3 && p.norm() < 1e-3, "v {v:?}, p {p:?}");
    }

    #[test]
    fn dropping_and_removing_states_keeps_links_in_step() {
        let (mut w, _) = at_rest(4, false);
        assert_eq!((w.states.len(), w.links.len()), (4, 3));
        let dropped = w.drop_newest();
        assert_eq!(dropped, 3);
        assert!(!w.values.contains(X(3)));
        let mut g = Graph::new();
        w.add_link(&mut g, 0);
        let m = tumble_solvers::marginalize(&g, &w.values, &[X(0), V(0), B(0)]).unwrap();
        w.remove_oldest(m.prior, &[X(0), V(0), B(0)]);
        assert_eq!(w.ids(), vec![1, 2]);
        assert_eq!(w.links.len(), 1);
        assert!(w.init_prior.is_none() && w.marginal.is_some());
    }
}
