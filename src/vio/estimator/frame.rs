//! One camera frame through the estimator: predicted by the IMU, decided
//! (keyframe, at rest, tracked), solved, and committed — or recovered from.

use super::{Estimator, FrameEstimate, BLIND_FEATURES, MIN_LANDMARKS_TO_TRACK, MIN_TRACK_OBSERVATIONS};
use crate::model::geometry::{parts, pose, preintegrate};
use crate::vio::keyframe::{is_keyframe, FeatureMotion, FrameObs};
use crate::vio::landmarks::{observation_factors, pixel_noise};
use crate::vio::marginalization::window_graph;
use crate::vio::noise_meter::NoiseMeter;
use crate::vio::online_calib::{EXTRINSIC, TIME_OFFSET};
use crate::vio::window::{add_rest_prior, State};
use nalgebra::{Matrix3, Vector3, Vector6};
use std::time::Instant;
use tumble_factors::imu_preint::Preintegrated;
use tumble_solvers::sophus_lie::Isometry3F64;
use tumble_solvers::{Covariances, FactorEntry, Graph, Values, B, L, V, X};

/// A frame's state as the IMU predicts it from the window's newest state.
struct Prediction {
    /// The new state's id.
    sid: u64,
    /// Pose, velocity and bias (the newest state's).
    x: Isometry3F64,
    v: Vector3<f64>,
    b: Vector6<f64>,
    /// Its rotation (world ← body).
    rotation: Matrix3<f64>,
    /// The IMU from the newest state, and the weakening of its factor (1 without a gap).
    pim: Preintegrated,
    scale: f64,
    /// The newest state's rotation.
    newest_rotation: Matrix3<f64>,
}

impl Estimator<'_> {
    /// Process camera frame `index` of the input; returns its estimate once initialized.
    ///
    /// The steps: start the window when it is empty; else predict the frame
    /// with the IMU, decide what it is (keyframe, at rest), and either track
    /// it against the fixed window or solve the window with it, then commit
    /// the solution (or recover from a failure).
    pub fn process(&mut self, index: usize) -> Option<FrameEstimate> {
        let t = self.input.frames[index].t;
        let t_start = Instant::now();
        if self.window.states.is_empty() {
            return self.begin(index, t, t_start);
        }
        let p = self.predict(t)?;
        let obs = self.frame_obs(index);
        let (keyframe, rest_since) = self.decide(t, &p, &obs);
        let sid = p.sid;
        self.window.push(State { sid, t, rest_since }, (p.x, p.v, p.b), (p.pim.clone(), p.scale));
        let added = self.add_observations(index, &obs);
        if let Some(gated) = self.watch_blindness(t, obs.len(), added) {
            // The prediction from a start nothing has confirmed put the
            // features beyond the gate: the start, not the frame, is off.
            self.withdraw_start(format!(
                "the start in motion at {:.3} s is contradicted by the features: at {t:.3} s {gated}",
                self.window.started_at()
            ));
            return None;
        }
        self.rest.push(t, &obs, p.rotation);
        // A frame the window's landmarks cannot place while a start in motion
        // fills the window stays in it (Window::filling).
        let enough_landmarks = self.landmarks.count() >= MIN_LANDMARKS_TO_TRACK;
        let placed = enough_landmarks && self.landmarks.placing(sid, MIN_TRACK_OBSERVATIONS) >= BLIND_FEATURES;
        let keyframe = keyframe || (enough_landmarks && !placed && self.window.filling(self.opts.window.size));
        // A frame at rest, a window with few landmarks or a frame that fewer
        // than BLIND_FEATURES of them can place still gets the full solve: its
        // zero-velocity prior or its IMU link is what holds the window's
        // velocities and biases then. (Without the last condition the frames
        // after a start in motion — whose landmarks are seen by the first
        // state alone — were tracked by nothing, so they were the IMU's
        // prediction from a bias of 0.)
        if !keyframe && rest_since.is_none() && !self.opts.window.solve_every_frame && placed {
            // Not triangulated from here: this frame's pose is only the IMU's
            // prediction now, and the landmark's depth would stay fixed.
            return self.track_frame(index, &p, obs, t_start);
        }
        if !self.triangulate(t, obs.len()) {
            return None;
        }
        let free_camera = self.free_camera();
        let (graph, solved) = self.solve_window(t, sid, &p.x, keyframe, free_camera);
        let covariances = match solved {
            Ok(c) => c,
            Err(why) => return self.recover(index, &why, (p.x, p.v, p.b), obs, t_start),
        };
        self.commit(t, sid, (keyframe, free_camera), graph, covariances, obs, t_start)
    }

    /// The first frame of a window: initialize (from the figures given to the
    /// run: a new start after a withdrawn one carries the scales its meter had
    /// in use, not figures scaled again) and start measuring the noise.
    fn begin(&mut self, index: usize, t: f64, t_start: Instant) -> Option<FrameEstimate> {
        self.imu = self.opts.noise.imu;
        let init = self.startup.initialize(self.input, &mut self.imu, &mut self.warnings, index, t)?;
        let x = init.x;
        self.init_time = Some(t);
        self.starts.push(t);
        if self.opts.noise.measure_in_motion {
            let meter = match &self.noise {
                Some(previous) => NoiseMeter::continuing(self.imu, previous),
                None => NoiseMeter::new(self.imu),
            };
            self.imu = meter.params();
            self.noise = Some(meter);
        }
        self.start(t, init);
        let obs = self.frame_obs(index);
        self.add_observations(index, &obs);
        self.keyframe_obs = obs.clone();
        self.rest.restart(obs, parts(&x).0);
        Some(self.estimate(self.window.states[0].sid, true, t_start, None))
    }

    /// The frame at `t` predicted by the IMU: from the last frame tracked
    /// since the newest window state when there is one (a shorter IMU span),
    /// else from that state. None when the frame is not after the newest
    /// state or no IMU sample precedes it; a gap weakens the link (warned).
    fn predict(&mut self, t: f64) -> Option<Prediction> {
        let last = self.window.states.last().expect("state");
        let (ta, last_sid) = (last.t, last.sid);
        if t <= ta {
            return None;
        }
        let (xl, vl, bl) = self.window.state_values(last_sid);
        let bias = (bl.fixed_rows::<3>(0).into_owned(), bl.fixed_rows::<3>(3).into_owned());
        let (pim, gap) = preintegrate(&self.input.imu, ta, t, bias, self.imu);
        let mut scale = 1.0;
        if gap > self.opts.noise.max_imu_gap_s {
            self.warn(format!(
                "IMU gap of {:.0} ms before the frame at {t:.3} s: that interval's IMU factor is weakened",
                gap * 1e3
            ));
            scale = (gap / self.opts.noise.max_imu_gap_s).powi(2) * 100.0;
        }
        if pim.is_empty() || pim.delta_t() <= 0.0 {
            self.warn(format!("no IMU samples before the frame at {t:.3} s: frame skipped"));
            return None;
        }
        let tracked = self.last_tracked.filter(|(tt, ..)| *tt > ta && *tt < t).map(|(tt, xt, vt, bt)| {
            let bias = (bt.fixed_rows::<3>(0).into_owned(), bt.fixed_rows::<3>(3).into_owned());
            (xt, vt, preintegrate(&self.input.imu, tt, t, bias, self.imu).0)
        });
        let (x0, v0, p0) = match &tracked {
            Some((xt, vt, pt)) => (*xt, *vt, pt),
            None => (xl, vl, &pim),
        };
        let (r0, q0) = parts(&x0);
        let dt = p0.delta_t();
        let g = self.window.gravity;
        let rj = r0 * p0.delta_rotation();
        let vj = v0 + g * dt + r0 * p0.delta_velocity();
        let pj = q0 + v0 * dt + g * (0.5 * dt * dt) + r0 * p0.delta_position();
        let sid = self.window.next_id();
        let newest_rotation = parts(&xl).0;
        Some(Prediction { sid, x: pose(&rj, &pj), v: vj, b: bl, rotation: rj, pim, scale, newest_rotation })
    }

    /// Whether the frame at `t` is a keyframe (parallax, time, features lost
    /// since the last keyframe) and since when the body has been at rest.
    fn decide(&mut self, t: f64, p: &Prediction, obs: &FrameObs) -> (bool, Option<f64>) {
        let motion = FeatureMotion {
            obs,
            rotation: p.rotation,
            r_bc: parts(&self.input.body_from_camera).0,
            fx: self.input.camera.fx,
        };
        let (par_kf, common_kf) = motion.parallax(&self.keyframe_obs, &p.newest_rotation);
        let rest_since = self.rest.update(t, &motion);
        let kf_t = self.window.states.last().map_or(t, |s| s.t);
        let keyframe = is_keyframe(&self.opts.window, par_kf, t - kf_t, common_kf, self.keyframe_obs.len());
        (keyframe, rest_since)
    }

    /// Triangulate the window's tracks and watch its landmarks; false (the
    /// estimates withdrawn) when the features contradict the window.
    fn triangulate(&mut self, t: f64, features: usize) -> bool {
        let rays = self.landmarks.triangulate(self.input, &self.window.ids(), &mut self.window.values, &self.opts);
        let span = self.opts.init.motion_window_s;
        self.window.watch_landmarks(t, self.landmarks.count(), features, rays, BLIND_FEATURES, span);
        if let Some((since, why)) = self.window.contradicted(t, BLIND_FEATURES, span) {
            self.withdraw(since, why);
            return false;
        }
        true
    }

    /// Whether the camera's calibration is free in this solve: once a
    /// window's length of keyframes has left into the prior (its first
    /// estimate then rests on two windows of frames: a first window of a
    /// couple of seconds cannot determine seven more unknowns, and a wild
    /// first estimate carries the states with it), and not held after an
    /// implausible estimate.
    fn free_camera(&mut self) -> bool {
        let free = self.window.marginalized >= self.opts.window.size && self.camera_held == 0;
        if let Some(c) = &self.window.camera {
            c.free(&mut self.window.values, free);
        }
        free
    }

    /// Solve the window with state `sid` (`predicted` by the IMU): its graph and, on success (the
    /// window's values updated), the covariances of the new state, of the
    /// link leaving the window (to measure the noise) and of the camera's
    /// calibration at a keyframe; on failure, why. A calibration far outside
    /// its prior is a wrong minimum, not a finding: solved again with it
    /// held, and held for a window's length.
    fn solve_window(
        &mut self,
        t: f64,
        sid: u64,
        predicted: &Isometry3F64,
        keyframe: bool,
        free_camera: bool,
    ) -> (Graph, Result<Option<Covariances>, String>) {
        let graph = window_graph(&self.window, &self.landmarks, self.input, &self.opts);
        let leaving = keyframe && self.window.states.len() > self.opts.window.size;
        let mut cov_keys = vec![X(sid), V(sid), B(sid)];
        if leaving && self.noise.is_some() {
            let (a, b) = (self.window.states[0].sid, self.window.states[1].sid);
            cov_keys.extend([X(a), V(a), B(a), X(b), V(b)].into_iter().filter(|k| ![X(sid), V(sid)].contains(k)));
        }
        if keyframe {
            // The window's length and its σ (FrameEstimate::window_length).
            if let Some(first) = self.window.states.first().map(|s| X(s.sid)).filter(|k| !cov_keys.contains(k)) {
                cov_keys.push(first);
            }
            cov_keys.extend(self.window.camera.iter().flat_map(|c| c.keys(&self.window.values)));
        }
        let (mut solved, mut covariances) = self.solve(&graph, &self.window.values, &cov_keys, vec!['l']);
        let implausible = match (&solved, &self.window.camera) {
            (Ok((v, _)), Some(c)) if free_camera => c.implausible(v),
            _ => None,
        };
        if let Some(why) = implausible {
            self.warn(format!(
                "at {t:.3} s the window's estimate of the camera's calibration was {why}: rejected, \
                 held for {} keyframes",
                self.opts.window.size
            ));
            self.camera_held = self.opts.window.size;
            if let Some(c) = &self.window.camera {
                c.free(&mut self.window.values, false);
            }
            cov_keys.retain(|k| ![EXTRINSIC, TIME_OFFSET].contains(k));
            (solved, covariances) = self.solve(&graph, &self.window.values, &cov_keys, vec!['l']);
        }
        let result = match solved {
            Ok((v, _)) => {
                self.window.values = v;
                match self.failed(sid, predicted) {
                    Some(why) => Err(why),
                    None => Ok(covariances),
                }
            }
            Err(e) => Err(format!("the solver failed: {e}")),
        };
        (graph, result)
    }

    /// After a successful solve of the window with the frame at `t` (state
    /// `sid`): probe the camera's calibration, reintegrate links, drop
    /// outliers, and at a keyframe record the camera, measure the noise and
    /// marginalize the oldest state when the window is full; a frame that is
    /// not a keyframe leaves the window.
    #[allow(clippy::too_many_arguments)]
    fn commit(
        &mut self,
        t: f64,
        sid: u64,
        (keyframe, free_camera): (bool, bool),
        mut graph: Graph,
        covariances: Option<Covariances>,
        obs: FrameObs,
        t_start: Instant,
    ) -> Option<FrameEstimate> {
        let leaving = keyframe && self.window.states.len() > self.opts.window.size;
        if keyframe && free_camera {
            self.probe_camera(t, &mut graph);
        }
        self.window.reintegrate_if_needed();
        self.landmarks.reject_outliers(self.input, &mut self.window.values, &self.opts);
        let est = self.estimate(sid, keyframe, t_start, covariances.as_ref());
        self.last_good = Some(self.window.state_values(sid));
        if keyframe {
            self.camera_held = self.camera_held.saturating_sub(1);
            if let Some(c) = &self.window.camera {
                self.camera_track.push((t, c.estimate(&self.window.values, covariances.as_ref())));
            }
            self.keyframe_std = est.std;
            self.keyframe_obs = obs;
            if leaving {
                if let Some(c) = covariances.as_ref() {
                    self.measure_noise(t, c);
                }
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
    fn track_frame(&mut self, index: usize, p: &Prediction, obs: FrameObs, t_start: Instant) -> Option<FrameEstimate> {
        let (sid, predicted) = (p.sid, &p.x);
        let t = self.input.frames[index].t;
        let n = self.window.states.len();
        let prev = self.window.states[n - 2].sid;
        let mut g = Graph::new();
        self.window.add_link(&mut g, n - 2);
        if self.window.states[n - 1].rest_since.is_some() {
            add_rest_prior(&mut g, sid);
        }
        let mut values = Values::new();
        let copy = |values: &mut Values, key, constant: bool| {
            if !values.contains(key) {
                if let Ok(v) = self.window.values.get_dyn(key) {
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
        let (noise, huber) = pixel_noise(&self.opts);
        for tr in self.landmarks.tracks().values() {
            let Some((lid, a, o)) = tr.places(sid, MIN_TRACK_OBSERVATIONS) else { continue };
            let anchor = a.sid;
            copy(&mut values, X(anchor), true);
            copy(&mut values, L(lid), true);
            if self.opts.camera.online() {
                for key in [V(anchor), EXTRINSIC, TIME_OFFSET] {
                    copy(&mut values, key, true);
                }
            }
            for (factor, _) in observation_factors(self.input, &self.opts, a, lid, o) {
                g.add_entry(FactorEntry { factor, noise: noise.clone(), loss: Some(huber.clone()) });
            }
        }
        let keys = [X(sid), V(sid), B(sid)];
        let (solved, covariances) = self.solve(&g, &values, &keys, Vec::new());
        let failure = match solved {
            Ok((v, _)) => {
                for key in keys {
                    if let Ok(x) = v.get_dyn(key) {
                        self.window.values.insert_dyn(key, x.clone_box());
                    }
                }
                self.failed(sid, predicted)
            }
            Err(e) => Some(format!("the solver failed: {e}")),
        };
        if let Some(why) = failure {
            return self.recover(index, &why, (p.x, p.v, p.b), obs, t_start);
        }
        let mut est = self.estimate(sid, false, t_start, covariances.as_ref());
        for (row, kf) in est.std.iter_mut().zip(&self.keyframe_std) {
            for (s, k) in row.iter_mut().zip(kf) {
                if k.is_finite() {
                    *s = s.hypot(*k);
                }
            }
        }
        self.last_good = Some(self.window.state_values(sid));
        let (x, v, b) = self.window.state_values(sid);
        self.last_tracked = Some((t, x, v, b));
        self.drop_newest();
        est.solve_s = t_start.elapsed().as_secs_f64();
        Some(est)
    }
}
