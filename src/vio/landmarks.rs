//! The window's landmarks: feature tracks by id, their observations in the
//! window's states, triangulation behind two gates (rays that agree, an
//! angle between them), the prediction gate for new observations, outlier
//! removal after a solve, and the reprojection factors they add to a graph.
//! A landmark `L(lid)` is its inverse depth `[ρ]` \[1/m\] along its anchor
//! observation's ray, or with [`super::WindowOptions::landmark_bearings`]
//! `[δx, δy, ρ]`: its bearing in the anchor camera (the anchor observation's
//! undistorted normalized point plus `δ`) too, the anchor observation then a
//! residual like every other ([`tumble_factors::reprojection::Landmark`]).

use super::online_calib::{body_at_exposure, body_from_camera, exposure_motion, EXTRINSIC, TIME_OFFSET};
use super::{VioInput, VioOptions};
use crate::model::geometry::{parts, triangulate};
use nalgebra::{Matrix3, Vector1, Vector2, Vector3};
use std::collections::{BTreeMap, HashMap, HashSet};
use std::sync::Arc;
use tumble_factors::camera::CameraModel;
use tumble_factors::reprojection::{
    AnchorObservation, CalibratingReprojection, ExposureMotion, Landmark, StereoInverseDepth,
};
use tumble_factors::InverseDepthReprojection;
use tumble_solvers::sophus_lie::Isometry3F64;
use tumble_solvers::{Factor, FactorEntry, Graph, Huber, NoiseModel, Values, B, L, V, X};

/// One observation of a track in a window state.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Obs {
    /// The state.
    pub sid: u64,
    /// Pixel \[px\].
    pub uv: [f64; 2],
    /// Normalized image point (undistorted).
    pub xy: [f64; 2],
    /// The second camera's match at the same time \[px\], when there is one
    /// and [`super::WindowOptions::stereo`] puts it into the window.
    pub uv1: Option<[f64; 2]>,
    /// The body's motion around the frame's stamp (moves the pose to the
    /// exposure when the time offset is estimated).
    pub motion: ExposureMotion,
}

/// A feature track and, once triangulated, its landmark.
#[derive(Debug, Clone, Default, PartialEq)]
pub(crate) struct Track {
    /// Observations, oldest first.
    pub obs: Vec<Obs>,
    /// Landmark id and its anchor state.
    pub landmark: Option<(u64, u64)>,
}

impl Track {
    /// The landmark id and its anchor observation, when the landmark is
    /// constrained: seen by another observation than the anchor's (or matched
    /// by the second camera there). Alone, the anchor observation fixes the
    /// bearing but not the depth, and the landmark gets no factor.
    pub fn anchored(&self) -> Option<(u64, &Obs)> {
        let (lid, anchor) = self.landmark?;
        let a = self.obs.iter().find(|o| o.sid == anchor)?;
        (self.obs.len() > 1 || a.uv1.is_some()).then_some((lid, a))
    }

    /// The landmark id, the anchor's observation and state `sid`'s, when this
    /// track's landmark can place state `sid` with the window held fixed:
    /// triangulated, anchored in another state, seen at `sid`, and seen at
    /// least `min_observations` times in the window (its depth rests on more
    /// than the anchor and one other view).
    pub fn places(&self, sid: u64, min_observations: usize) -> Option<(u64, &Obs, &Obs)> {
        let (lid, anchor) = self.landmark?;
        if anchor == sid || self.obs.len() < min_observations {
            return None;
        }
        let a = self.obs.iter().find(|o| o.sid == anchor)?;
        let o = self.obs.iter().find(|o| o.sid == sid)?;
        Some((lid, a, o))
    }
}

/// What [`Landmarks::add_observations`] did with a frame's features.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub(crate) struct Added {
    /// Observations of the window's landmarks in the frame.
    pub landmarks_seen: usize,
    /// Of those, added (within the prediction gate).
    pub landmarks: usize,
}

/// How the rays of the tracks not yet landmarks met in one
/// [`Landmarks::triangulate`] (tracks seen by two or more of the window's states).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub(crate) struct RayTally {
    /// Tracks whose rays meet within the triangulation gate, in front of the
    /// cameras (landmarks now, or waiting for parallax).
    pub agreed: usize,
    /// Tracks whose rays do not meet from the window's poses (beyond the gate,
    /// or behind a camera) though they have the parallax to, even with their
    /// worst observations dropped.
    pub disagreed: usize,
}

impl RayTally {
    /// Count a track whose rays did not meet: a disagreement where they had
    /// the parallax to (`parallax`), else an agreement (nearly parallel rays
    /// meet anywhere along their direction).
    fn note(&mut self, parallax: bool) {
        if parallax {
            self.disagreed += 1;
        } else {
            self.agreed += 1;
        }
    }
}

/// The tracks of the window, by track id.
#[derive(Debug, Default)]
pub(crate) struct Landmarks {
    tracks: BTreeMap<u64, Track>,
    next_lid: u64,
}

/// Per window state: a camera's rotation (world ← camera) and centre in the world.
type CameraPoses = HashMap<u64, (Matrix3<f64>, Vector3<f64>)>;

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
/// poses per state (`poses`, `poses1`).
fn rays(tr: &Track, poses: &CameraPoses, poses1: &CameraPoses, stereo_camera: Option<&CameraModel>) -> Vec<Ray> {
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

/// A landmark's bearing in the anchor camera (`z = 1`) and inverse depth
/// \[1/m\] in `values`, from its anchor observation's normalized point `xy`.
pub(crate) fn bearing_and_inverse_depth(values: &Values, lid: u64, xy: [f64; 2]) -> Option<(Vector3<f64>, f64)> {
    let l = Landmark::of(values.get_dyn(L(lid)).ok()?, &Vector3::new(xy[0], xy[1], 1.0))?;
    Some((l.bearing, l.rho))
}

/// Insert landmark `lid` triangulated at depth `z` \[m\] along its anchor
/// observation's ray: `[1/z]`, or `[0, 0, 1/z]` when `bearings` are estimated.
pub(crate) fn insert_landmark(values: &mut Values, lid: u64, z: f64, bearings: bool) {
    if bearings {
        values.insert(L(lid), Vector3::new(0.0, 0.0, 1.0 / z));
    } else {
        values.insert(L(lid), Vector1::new(1.0 / z));
    }
}

/// A track's landmark in the world frame \[m\]: its estimated bearing
/// at the estimated inverse depth, seen from the anchor state's camera at
/// its exposure (moved by the time offset in `values`, as the factors see it;
/// `gravity` \[m/s²\]).
fn landmark_world(values: &Values, body_from_camera: &Isometry3F64, tr: &Track, gravity: f64) -> Option<Vector3<f64>> {
    let (lid, anchor) = tr.landmark?;
    let a = tr.obs.iter().find(|o| o.sid == anchor)?;
    let (ra, pa) = body_at_exposure(values, anchor, &a.motion, gravity)?;
    let (bearing, rho) = bearing_and_inverse_depth(values, lid, a.xy)?;
    let (r_bc, t_bc) = parts(body_from_camera);
    let pw = ra * (r_bc * (bearing / rho) + t_bc) + pa;
    pw.iter().all(|x| x.is_finite()).then_some(pw)
}

/// The reprojection factor of observation `uv` in state `sid` of landmark `lid`
/// anchored in state `anchor` with anchor observation `anchor_xy`.
fn reprojection(
    input: &VioInput,
    anchor: u64,
    sid: u64,
    lid: u64,
    anchor_xy: [f64; 2],
    uv: [f64; 2],
) -> InverseDepthReprojection {
    InverseDepthReprojection::new([X(anchor), X(sid), L(lid)], anchor_xy, uv, input.camera, &input.body_from_camera)
}

/// The factors of observation `o` of landmark `lid` anchored in observation
/// `a`: the first camera's reprojection (at the anchor itself the anchor
/// observation, a factor on the landmark alone, when its bearing is
/// estimated) and the second camera's, when
/// `o` has a stereo match — at the anchor a factor on the landmark alone too.
/// Each with whether it is the stereo one. When
/// `opts` calibrate the camera online (its `T_BC` and time offset are
/// variables of the window), the first camera's is a [`CalibratingReprojection`] on them too.
pub(crate) fn observation_factors(
    input: &VioInput,
    opts: &VioOptions,
    a: &Obs,
    lid: u64,
    o: &Obs,
) -> Vec<(Box<dyn Factor>, bool)> {
    let (anchor, anchor_xy) = (a.sid, a.xy);
    let mut out: Vec<(Box<dyn Factor>, bool)> = Vec::new();
    if o.sid == anchor {
        if opts.window.landmark_bearings {
            out.push((Box::new(AnchorObservation::new(L(lid), anchor_xy, o.uv, input.camera)), false));
        }
    } else {
        let f: Box<dyn Factor> = if opts.camera.online() {
            let keys = [X(anchor), V(anchor), X(o.sid), V(o.sid), L(lid), EXTRINSIC, TIME_OFFSET];
            let g = [0.0, 0.0, -opts.noise.gravity];
            Box::new(CalibratingReprojection::new(keys, anchor_xy, o.uv, [a.motion, o.motion], input.camera, g))
        } else {
            Box::new(reprojection(input, anchor, o.sid, lid, anchor_xy, o.uv))
        };
        out.push((f, false));
    }
    if let (Some(uv1), Some(st)) = (o.uv1, &input.stereo) {
        let f: Box<dyn Factor> = if o.sid == anchor {
            let second = (st.camera, &st.body_from_camera);
            Box::new(StereoInverseDepth::new(L(lid), anchor_xy, uv1, second, &input.body_from_camera))
        } else {
            Box::new(reprojection(input, anchor, o.sid, lid, anchor_xy, uv1).seen_by(st.camera, &st.body_from_camera))
        };
        out.push((f, true));
    }
    out
}

/// The reprojection noise and robust loss of the window's observations.
pub(crate) fn pixel_noise(opts: &VioOptions) -> (NoiseModel, Arc<Huber>) {
    (NoiseModel::isotropic(2, opts.noise.pixel_sigma).expect("positive pixel sigma"), Arc::new(Huber(opts.gates.huber)))
}

impl Landmarks {
    /// The tracks, by id.
    pub fn tracks(&self) -> &BTreeMap<u64, Track> {
        &self.tracks
    }

    /// Forget every track (a restart).
    pub fn clear(&mut self) {
        self.tracks.clear();
    }

    /// Number of triangulated landmarks.
    pub fn count(&self) -> usize {
        self.tracks.values().filter(|t| t.landmark.is_some()).count()
    }

    /// How many landmarks can place state `sid` with the window held fixed
    /// ([`Track::places`]).
    pub fn placing(&self, sid: u64, min_observations: usize) -> usize {
        self.tracks.values().filter(|t| t.places(sid, min_observations).is_some()).count()
    }

    /// The landmarks in the world frame \[m\], by track id (`input`'s camera,
    /// or its online estimate in `values`; `gravity` \[m/s²\]).
    pub fn world_points(&self, input: &VioInput, values: &Values, gravity: f64) -> Vec<(u64, Vector3<f64>)> {
        let body_from_camera = body_from_camera(input, values);
        self.tracks
            .iter()
            .filter_map(|(id, tr)| landmark_world(values, &body_from_camera, tr, gravity).map(|p| (*id, p)))
            .collect()
    }

    /// Add every landmark's reprojection factors (robust) to `g`.
    pub fn add_factors(&self, g: &mut Graph, input: &VioInput, opts: &VioOptions) {
        let (noise, huber) = pixel_noise(opts);
        for tr in self.tracks.values() {
            let Some((lid, a)) = tr.anchored() else { continue };
            for o in &tr.obs {
                for (factor, _) in observation_factors(input, opts, a, lid, o) {
                    g.add_entry(FactorEntry { factor, noise: noise.clone(), loss: Some(huber.clone()) });
                }
            }
        }
    }

    /// Add frame `index`'s observations (`obs`: undistorted, by track) to state
    /// `sid`, whose predicted pose is in `values`. An observation of a
    /// landmark the predicted pose would see behind the camera, or farther
    /// than [`super::GateOptions::prediction_px`] from where it projects (a
    /// gross outlier, kept out of the solve), is skipped. Tracks no longer
    /// seen and without a landmark are forgotten. Returns what was added.
    pub fn add_observations(
        &mut self,
        input: &VioInput,
        index: usize,
        sid: u64,
        obs: &HashMap<u64, [f64; 2]>,
        values: &Values,
        opts: &VioOptions,
    ) -> Added {
        // The second camera's matches in this frame that it can undistort,
        // when they go into the window.
        let stereo: HashMap<u64, [f64; 2]> = match (&input.stereo, opts.window.stereo) {
            (Some(st), true) => {
                st.features[index].iter().filter(|(_, uv)| st.camera.unproject(*uv).is_some()).copied().collect()
            }
            _ => HashMap::new(),
        };
        let body_from_camera = body_from_camera(input, values);
        let (r_bc, t_bc) = parts(&body_from_camera);
        // The motion around the stamp moves the pose to the exposure, for the time offset alone.
        let motion = match values.get::<nalgebra::Vector6<f64>>(B(sid)) {
            Ok(b) if opts.camera.online() && input.imu.t.len() >= 2 => {
                exposure_motion(&input.imu, input.frames[index].t, b, opts.camera.time_offset_sigma_s)
            }
            _ => ExposureMotion::default(),
        };
        let gravity = opts.noise.gravity;
        let (rj, pj) = body_at_exposure(values, sid, &motion, gravity).expect("newest state");
        let mut added = Added::default();
        for (id, uv) in &input.frames[index].features {
            let Some(&xy) = obs.get(id) else { continue };
            let tr = self.tracks.entry(*id).or_default();
            if tr.landmark.is_some() {
                added.landmarks_seen += 1;
                let Some(pw) = landmark_world(values, &body_from_camera, tr, gravity) else {
                    continue;
                };
                let pc = r_bc.transpose() * (rj.transpose() * (pw - pj) - t_bc);
                if pc.z < 0.05 {
                    continue;
                }
                let gate = opts.gates.prediction_px;
                match input.camera.project(&[pc.x, pc.y, pc.z]) {
                    Some(p) if (p[0] - uv[0]).hypot(p[1] - uv[1]) <= gate => {}
                    _ => continue,
                }
                added.landmarks += 1;
            }
            let uv1 = stereo.get(id).copied();
            tr.obs.push(Obs { sid, uv: *uv, xy, uv1, motion });
        }
        let seen: HashSet<u64> = input.frames[index].features.iter().map(|f| f.0).collect();
        self.tracks.retain(|id, t| seen.contains(id) || t.landmark.is_some());
        added
    }

    /// Triangulate tracks seen from two or more of the window's `states`
    /// (their poses in `values`), inserting each new landmark's inverse depth
    /// into `values`; returns how the tracks' rays met.
    pub fn triangulate(
        &mut self,
        input: &VioInput,
        states: &[u64],
        values: &mut Values,
        opts: &VioOptions,
    ) -> RayTally {
        let mut tally = RayTally::default();
        let (r_bc, t_bc) = parts(&body_from_camera(input, values));
        let min_angle = opts.gates.min_triangulation_deg.to_radians();
        let stereo = input.stereo.as_ref().map(|st| (st, parts(&st.body_from_camera)));
        // Per state: the first camera's pose in the world at the frame's
        // exposure (as the factors see it), and the second's.
        let mut motion: HashMap<u64, ExposureMotion> = HashMap::new();
        if opts.camera.online() {
            for o in self.tracks.values().flat_map(|t| &t.obs) {
                motion.entry(o.sid).or_insert(o.motion);
            }
        }
        let mut poses: CameraPoses = HashMap::new();
        let mut poses1: CameraPoses = HashMap::new();
        for &sid in states {
            let m = motion.get(&sid).copied().unwrap_or_default();
            let (r, p) = body_at_exposure(values, sid, &m, opts.noise.gravity).expect("window state");
            poses.insert(sid, (r * r_bc, r * t_bc + p));
            if let Some((_, (r_bc1, t_bc1))) = &stereo {
                poses1.insert(sid, (r * r_bc1, r * t_bc1 + p));
            }
        }
        // The gate in normalized image coordinates.
        let limit = opts.gates.triangulation_px / input.camera.fx;
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
                // Rays that miss one another contradict the poses only where
                // they have the parallax to: nearly parallel ones (a camera at
                // rest or turning on the spot) put their midpoint anywhere.
                let parallax = || {
                    let cos = d.iter().enumerate().flat_map(|(i, a)| d[i + 1..].iter().map(move |b| a.dot(b)));
                    cos.fold(1.0f64, f64::min).clamp(-1.0, 1.0).acos()
                };
                let Some((pw, angle)) = triangulate(&c, &d) else {
                    tally.note(parallax() >= min_angle);
                    break None;
                };
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
                    tally.note(angle >= min_angle);
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
            tally.agreed += 1;
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
            insert_landmark(values, lid, z, opts.window.landmark_bearings);
            tr.landmark = Some((lid, anchor));
        }
        tally
    }

    /// After a solve: drop observations whose error exceeds
    /// [`super::GateOptions::outlier_sigmas`] σ (a second camera's match alone
    /// when it is the one), and landmarks with an implausible depth or whose
    /// anchor observation is the one (their track keeps its newest observation
    /// and may be triangulated again).
    pub fn reject_outliers(&mut self, input: &VioInput, values: &mut Values, opts: &VioOptions) {
        let limit = opts.gates.outlier_sigmas * opts.noise.pixel_sigma;
        let mut drop_landmarks = Vec::new();
        let mut drop_obs: Vec<(u64, u64, bool)> = Vec::new();
        for (&id, tr) in &self.tracks {
            let Some((lid, anchor)) = tr.landmark else { continue };
            let Some((_, a)) = tr.anchored() else { continue };
            let rho = bearing_and_inverse_depth(values, lid, a.xy).map_or(f64::NAN, |(_, rho)| rho);
            if !(rho > 1.0 / 200.0 && rho < 10.0) {
                drop_landmarks.push(id);
                continue;
            }
            let mut outliers = Vec::new();
            for o in &tr.obs {
                for (f, stereo) in observation_factors(input, opts, a, lid, o) {
                    if values.residual_of(f.as_ref()).is_none_or(|r| r.norm() > limit) {
                        outliers.push((id, o.sid, stereo));
                    }
                }
            }
            // The anchor observation carries the landmark: when it is the
            // outlier the landmark goes.
            if outliers.iter().any(|&(_, sid, stereo)| sid == anchor && !stereo) {
                drop_landmarks.push(id);
            } else {
                drop_obs.extend(outliers);
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
                    values.remove(L(lid));
                }
                // Keep only the newest observation: the track may be triangulated again.
                let last = tr.obs.pop();
                tr.obs.clear();
                tr.obs.extend(last);
            }
        }
    }

    /// Remove state `sid`'s observations from every track. A landmark still
    /// anchored in it (a stereo track triangulated in a frame then dropped
    /// as not a keyframe; those anchored in the oldest state are forgotten
    /// before it is marginalized) leaves `values`, and its track is
    /// triangulated again from the observations left: kept, it would stay in
    /// the window without its anchor, never projected nor triangulated again.
    pub fn remove_state(&mut self, sid: u64, values: &mut Values) {
        for tr in self.tracks.values_mut() {
            if let Some((lid, _)) = tr.landmark.filter(|&(_, anchor)| anchor == sid) {
                values.remove(L(lid));
                tr.landmark = None;
            }
            tr.obs.retain(|o| o.sid != sid);
        }
    }

    /// The tracks whose landmark is anchored in state `sid`, with the landmark ids.
    pub fn anchored_in(&self, sid: u64) -> Vec<(u64, u64)> {
        self.tracks
            .iter()
            .filter_map(|(&id, t)| match t.landmark {
                Some((lid, a)) if a == sid => Some((id, lid)),
                _ => None,
            })
            .collect()
    }

    /// Forget the landmarks of `tracks` (marginalized: every observation went
    /// into the prior, only new ones may be used again).
    pub fn forget(&mut self, tracks: &[u64]) {
        for id in tracks {
            let tr = self.tracks.get_mut(id).expect("track");
            tr.landmark = None;
            tr.obs.clear();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::geometry::pose;
    use crate::model::ImuData;
    use crate::vio::Frame;

    fn input(frames: Vec<Frame>) -> VioInput {
        VioInput::for_tests(ImuData::default(), frames)
    }

    /// Pixels of world point `p` seen from a camera at `c` (identity rotation).
    fn pixel(p: Vector3<f64>, c: Vector3<f64>) -> [f64; 2] {
        let q = p - c;
        [320.0 + 500.0 * q.x / q.z, 240.0 + 500.0 * q.y / q.z]
    }

    /// Five states 0.25 m apart along x looking at point (0.3, −0.2, 5); the
    /// middle one's observation `outlier_px` off across the epipolar line.
    fn five_views(outlier_px: f64) -> (VioInput, Values, Landmarks) {
        let point = Vector3::new(0.3, -0.2, 5.0);
        let centres = [0.0, 0.25, 0.5, 0.75, 1.0].map(|x| Vector3::new(x, 0.0, 0.0));
        let frames: Vec<Frame> = centres
            .iter()
            .enumerate()
            .map(|(k, c)| {
                let mut uv = pixel(point, *c);
                if k == 2 {
                    uv[1] += outlier_px;
                }
                Frame { t: k as f64, features: vec![(7, uv)] }
            })
            .collect();
        let inp = input(frames);
        let mut values = Values::new();
        let mut lm = Landmarks::default();
        let opts = VioOptions::default();
        for (k, c) in centres.iter().enumerate() {
            values.insert(X(k as u64), pose(&Matrix3::identity(), c));
            let obs: HashMap<u64, [f64; 2]> =
                inp.frames[k].features.iter().map(|(id, uv)| (*id, inp.camera.unproject(*uv).unwrap())).collect();
            lm.add_observations(&inp, k, k as u64, &obs, &values, &opts);
        }
        (inp, values, lm)
    }

    #[test]
    fn triangulates_agreeing_rays_on_the_anchor_ray() {
        let (inp, mut values, mut lm) = five_views(0.0);
        lm.triangulate(&inp, &[0, 1, 2, 3, 4], &mut values, &VioOptions::default());
        assert_eq!(lm.count(), 1);
        let points = lm.world_points(&inp, &values, 9.81);
        assert!((points[0].1 - Vector3::new(0.3, -0.2, 5.0)).norm() < 1e-9, "{:?}", points);
        assert_eq!(lm.anchored_in(0), vec![(7, 0)]);
    }

    /// A landmark anchored in the newest state (as a stereo track
    /// triangulated in one frame is) leaves with that state when it is not a
    /// keyframe, and its track is triangulated again from the rest (it
    /// stayed anchorless: on MH_03 in stereo, 56 of 65 of a frame's
    /// landmarks were then counted as beyond the prediction gate and vision
    /// was lost for 9.7 s).
    #[test]
    fn a_landmark_anchored_in_a_dropped_frame_leaves_with_it() {
        let (inp, mut values, mut lm) = five_views(0.0);
        let seen = [0, 1, 2, 3, 4];
        lm.triangulate(&inp, &seen, &mut values, &VioOptions::default());
        let (lid, _) = lm.tracks[&7].landmark.expect("triangulated");
        lm.tracks.get_mut(&7).expect("track").landmark = Some((lid, 4));
        lm.remove_state(4, &mut values);
        assert!(lm.tracks[&7].landmark.is_none() && !values.contains(L(lid)));
        lm.triangulate(&inp, &seen[..4], &mut values, &VioOptions::default());
        assert_eq!(lm.anchored_in(0).len(), 1, "triangulated again from the four frames left");
    }

    #[test]
    fn a_gross_outlier_leaves_the_track_before_triangulation() {
        let (inp, mut values, mut lm) = five_views(40.0);
        lm.triangulate(&inp, &[0, 1, 2, 3, 4], &mut values, &VioOptions::default());
        assert_eq!(lm.count(), 1);
        let tr = &lm.tracks()[&7];
        assert_eq!(tr.obs.iter().map(|o| o.sid).collect::<Vec<_>>(), vec![0, 1, 3, 4], "the outlier in state 2 left");
        let p = lm.world_points(&inp, &values, 9.81)[0].1;
        assert!((p - Vector3::new(0.3, -0.2, 5.0)).norm() < 1e-9);
    }

    #[test]
    fn two_disagreeing_rays_wait() {
        let (inp, mut values, mut lm) = five_views(40.0);
        for sid in [1, 3, 4] {
            lm.remove_state(sid, &mut values);
        }
        lm.triangulate(&inp, &[0, 2], &mut values, &VioOptions::default());
        assert_eq!(lm.count(), 0);
        assert_eq!(lm.tracks()[&7].obs.len(), 2);
    }

    #[test]
    fn outliers_after_a_solve_are_dropped_and_implausible_depths_forgotten() {
        let (inp, mut values, mut lm) = five_views(0.0);
        let opts = VioOptions::default();
        lm.triangulate(&inp, &[0, 1, 2, 3, 4], &mut values, &opts);
        // State 4 moved 0.2 m sideways: its observation is now 20 px off (> 8 σ).
        values.insert(X(4), pose(&Matrix3::identity(), &Vector3::new(1.2, 0.0, 0.0)));
        lm.reject_outliers(&inp, &mut values, &opts);
        assert_eq!(lm.tracks()[&7].obs.iter().map(|o| o.sid).collect::<Vec<_>>(), vec![0, 1, 2, 3]);
        // A landmark 1000 m away (inverse depth 1e-3) is forgotten; its newest observation stays.
        insert_landmark(&mut values, 0, 1e3, false);
        lm.reject_outliers(&inp, &mut values, &opts);
        assert_eq!(lm.count(), 0);
        assert!(!values.contains(L(0)));
        assert_eq!(lm.tracks()[&7].obs.len(), 1);
    }

    #[test]
    fn the_prediction_gate_skips_far_observations_of_landmarks() {
        let (inp, mut values, mut lm) = five_views(0.0);
        let opts = VioOptions::default();
        lm.triangulate(&inp, &[0, 1, 2, 3, 4], &mut values, &opts);
        let c = Vector3::new(1.5, 0.0, 0.0);
        values.insert(X(5), pose(&Matrix3::identity(), &c));
        let seen = pixel(Vector3::new(0.3, -0.2, 5.0), c);
        let far = [seen[0] + 35.0, seen[1]];
        let inp = input(vec![Frame { t: 5.0, features: vec![(7, far)] }; 6]);
        let obs = HashMap::from([(7, inp.camera.unproject(far).unwrap())]);
        lm.add_observations(&inp, 5, 5, &obs, &values, &opts);
        assert!(lm.tracks()[&7].obs.iter().all(|o| o.sid != 5), "35 px off the prediction: skipped");
        // Within the gate it is added.
        let near = [seen[0] + 5.0, seen[1]];
        let inp = input(vec![Frame { t: 5.0, features: vec![(7, near)] }; 6]);
        let obs = HashMap::from([(7, inp.camera.unproject(near).unwrap())]);
        lm.add_observations(&inp, 5, 5, &obs, &values, &opts);
        assert!(lm.tracks()[&7].obs.iter().any(|o| o.sid == 5));
    }
}
