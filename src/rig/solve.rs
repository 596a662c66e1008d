//! The joint rig calibration: starting values from [`super::init`], one
//! factor graph of IMU preintegration, bias random walks and target corners,
//! solved twice (the second time with the rates corrected by the first's gyro
//! bias), and the covariances of the calibration parameters.

use super::clusters::{robust_partitions, ClusterLabels};
use super::init::{self, RateIntegral};
use super::{CameraResult, CornerResidual, Reprojection, RigError, RigInput, RigOptions, RigResult};
use crate::model::geometry::to_nalgebra;
use crate::model::geometry::{gravity_aligned, parts, pose, preintegrate};
use nalgebra::{Matrix3, SVector, Vector1, Vector3, Vector6};
use std::collections::BTreeMap;
use std::sync::Arc;
use tumble_factors::camera::CameraModel;
use tumble_factors::imu_preint::PreintegrationParams;
use tumble_factors::rig::{TargetCorner, TargetGauge};
use tumble_factors::{bias_random_walk_axes, ImuFactor};
use tumble_solvers::sophus_lie::Isometry3F64;
use tumble_solvers::{AutoDiff, Covariances, Graph, Huber, Key, LmOptions, NoiseModel, Optimizer, Values, B, V, X};

/// The target's pose `T_WT`.
const TARGET: Key = Key::new('t', 0);
/// The time offset.
const OFFSET: Key = Key::new('d', 0);
/// Camera `c`'s `T_BC`.
fn extrinsic(c: usize) -> Key {
    Key::new('e', c as u64)
}
/// Camera `c`'s intrinsics.
fn intrinsics(c: usize) -> Key {
    Key::new('k', c as u64)
}

/// Huber threshold of the corners, in σ.
const HUBER_SIGMAS: f64 = 2.0;
/// σ of the target gauge (its position and yaw are fixed, not estimated).
const GAUGE_SIGMA: f64 = 1e-6;
/// Frames at most this far apart \[s\] give a camera's rotation rate for the time-offset correlation.
const RATE_MAX_GAP_S: f64 = 0.15;
/// The exposure-time rotation error `|b_g| · |td|` \[rad\] below which the
/// corners' rates need no second solve with the bias removed (1 % of the
/// angle of a pixel of a 460 px focal length).
const RATE_BIAS_TOLERANCE_RAD: f64 = 2e-5;
/// Below this rank correlation of camera and gyro rates the coarse time offset is reported as doubtful.
const WEAK_RATE_CORRELATION: f64 = 0.8;
/// A view whose every hand–eye pair disagrees with the gyro by more than
/// this \[deg\] is set aside: far above the pairs' residual for good views
/// (0.2–0.7° here, and 1.7° from a 10 ms time offset at 3 rad/s), far below
/// a flipped pose (tens of degrees).
const INCONSISTENT_VIEW_DEG: f64 = 10.0;
/// Hand–eye pairs span this many frames of a camera (≈ 0.25 s at 20 Hz: rotations well above the views' noise).
const HAND_EYE_SPAN: usize = 5;

/// One camera frame of the estimate: its time on the IMU axis and, per camera, the view seen then.
#[derive(Clone)]
pub(super) struct FrameSlot {
    pub t: f64,
    pub views: Vec<Option<usize>>,
}

/// Projection of the mean of rotation matrices onto SO(3) (chordal mean).
fn mean_rotation(rs: &[Matrix3<f64>]) -> Matrix3<f64> {
    let sum: Matrix3<f64> = rs.iter().sum();
    let svd = sum.svd(true, true);
    match (svd.u, svd.v_t) {
        (Some(u), Some(vt)) => {
            let d = if (u * vt).determinant() < 0.0 { -1.0 } else { 1.0 };
            u * Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, d)) * vt
        }
        _ => Matrix3::identity(),
    }
}

/// What the stages before the joint solve found.
pub(super) struct Start {
    /// Each camera's intrinsics and pixel σ from its views alone.
    pub cameras: Vec<init::CameraStart>,
    /// The frames of the estimate.
    pub frames: Vec<FrameSlot>,
    /// Each camera's hand–eye residual \[rad\].
    pub hand_eye_rms: Vec<f64>,
    /// The state the joint solve starts from.
    pub state: StartingState,
    /// The IMU's preintegration parameters (midpoint rule).
    pub params: PreintegrationParams,
    /// The time offset the frames are placed with on the IMU's axis \[s\]
    /// (the coarse one, then the joint solve's): the solve's own offset
    /// variable is what it finds beyond this.
    pub frame_offset: f64,
}

/// A start from `joint`'s solution at the frames of `range` (the frames'
/// placement kept), with the offset variable starting at `offset` \[s\].
pub(super) fn start_from_solution(
    start: &Start,
    joint: &Joint,
    range: std::ops::Range<usize>,
    offset: f64,
) -> Result<Start, RigError> {
    let s = &joint.solution;
    let pose = |k: usize| -> Result<Isometry3F64, RigError> { Ok(*s.get::<Isometry3F64>(X(k as u64))?) };
    let vel = |k: usize| -> Result<Vector3<f64>, RigError> { Ok(*s.get::<Vector3<f64>>(V(k as u64))?) };
    let bias = |k: usize| -> Result<Vector6<f64>, RigError> { Ok(*s.get::<Vector6<f64>>(B(k as u64))?) };
    let state = StartingState {
        t_bc: (0..start.cameras.len())
            .map(|c| Ok(*s.get::<Isometry3F64>(extrinsic(c))?))
            .collect::<Result<_, RigError>>()?,
        t_wt: *s.get::<Isometry3F64>(TARGET)?,
        body: range.clone().map(pose).collect::<Result<_, _>>()?,
        vel: range.clone().map(vel).collect::<Result<_, _>>()?,
        offset,
        bias: range.clone().map(bias).collect::<Result<_, _>>()?,
    };
    let mut cameras = start.cameras.clone();
    for (c, cam) in cameras.iter_mut().enumerate() {
        let k = s.get::<SVector<f64, 8>>(intrinsics(c))?;
        cam.model = CameraModel::from_vector(cam.model.distortion.kind(), k.as_slice());
    }
    Ok(Start {
        cameras,
        frames: start.frames[range].to_vec(),
        hand_eye_rms: start.hand_eye_rms.clone(),
        state,
        params: start.params,
        frame_offset: start.frame_offset,
    })
}

/// The joint solve's starting values.
pub(super) struct StartingState {
    /// Each camera's `T_BC`.
    pub t_bc: Vec<Isometry3F64>,
    /// The target's pose in the gravity-aligned world.
    pub t_wt: Isometry3F64,
    /// Body poses at the frames.
    pub body: Vec<Isometry3F64>,
    /// Velocities at the frames \[m/s\].
    pub vel: Vec<Vector3<f64>>,
    /// The time offset beyond the frames' (coarse) one \[s\].
    pub offset: f64,
    /// Biases `[b_a, b_g]` at the frames (zeros at the first start).
    pub bias: Vec<Vector6<f64>>,
}

/// Seconds on the IMU's axis of a stamp \[ns\].
fn stamp(input: &RigInput, t_ns: i64) -> f64 {
    (t_ns - input.imu_t0_ns) as f64 * 1e-9
}

/// Stage 1: each camera alone — its intrinsics (or the ones held), every
/// view's target pose, and the view poses the gyro cannot reach set aside.
pub(super) type CameraStarts = (Vec<init::CameraStart>, Vec<Vec<Option<Isometry3F64>>>);
pub(super) fn calibrate_cameras(
    input: &RigInput,
    o: &RigOptions,
    progress: &mut dyn FnMut(&str),
) -> Result<CameraStarts, RigError> {
    let mut starts = Vec::new();
    let mut view_poses: Vec<Vec<Option<Isometry3F64>>> = Vec::new();
    for cam in &input.cameras {
        progress(&format!("{}: intrinsics from {} views (Zhang, then bundle adjustment)", cam.name, cam.views.len()));
        let fixed = o.fixed_intrinsics.get(starts.len());
        let s = init::calibrate_camera(&cam.views, o.distortion, fixed, cam.resolution)
            .map_err(|e| RigError::Recording(format!("{}: {e}", cam.path.display())))?;
        progress(&format!(
            "{}: fx {:.1} fy {:.1} cx {:.1} cy {:.1} px, corner σ {:.3} px",
            cam.name, s.model.fx, s.model.fy, s.model.cx, s.model.cy, s.pixel_sigma
        ));
        view_poses.push(cam.views.iter().map(|v| init::view_pose(v, &s.model)).collect());
        starts.push(s);
    }
    for (c, cam) in input.cameras.iter().enumerate() {
        let stamps: Vec<f64> = cam.views.iter().map(|v| stamp(input, v.t_ns)).collect();
        let n =
            init::drop_unreachable_poses(&stamps, &mut view_poses[c], &input.imu, RATE_MAX_GAP_S, o.max_time_offset_s);
        if n > 0 {
            progress(&format!("{}: {n} view pose(s) the gyro cannot reach from their neighbours set aside", cam.name));
        }
    }
    Ok((starts, view_poses))
}

/// Stage 2: the coarse time offset from the first camera's rotation rates
/// against the gyro's (None when not estimated or nothing to correlate, with a note).
pub(super) fn coarse_time_offset(
    input: &RigInput,
    o: &RigOptions,
    view_poses: &[Option<Isometry3F64>],
    gyro: &RateIntegral,
    notes: &mut Vec<String>,
    progress: &mut dyn FnMut(&str),
) -> Option<init::OffsetSearch> {
    if !o.estimate_time_offset {
        return None;
    }
    let stamps: Vec<f64> = input.cameras[0].views.iter().map(|v| stamp(input, v.t_ns)).collect();
    let rates = init::camera_rates(&stamps, view_poses, RATE_MAX_GAP_S);
    let c = init::correlate_time_offset(&rates, gyro, o.max_time_offset_s);
    match &c {
        Some((tau, r, _)) => {
            progress(&format!("coarse time offset {:.1} ms (rate correlation {r:.3})", tau * 1e3));
            if *r < WEAK_RATE_CORRELATION {
                notes.push(format!(
                    "the camera's and the gyro's rotation rates correlate only {r:.2} at the best shift ({:.1} ms): \
                     the coarse time offset is doubtful (views too noisy, or too little rotation)",
                    tau * 1e3
                ));
            }
        }
        None => {
            notes.push("too little rotation to correlate camera and gyro rates: the time offset starts at 0".into())
        }
    }
    c
}

/// Stage 3: the frames — every stamp at which some camera has a pose, on the
/// IMU's axis shifted by the coarse offset `td0`, within the IMU's span.
pub(super) fn frame_slots(
    input: &RigInput,
    view_poses: &[Vec<Option<Isometry3F64>>],
    td0: f64,
) -> Result<Vec<FrameSlot>, RigError> {
    let n_cams = input.cameras.len();
    let mut slots: BTreeMap<i64, FrameSlot> = BTreeMap::new();
    for (c, cam) in input.cameras.iter().enumerate() {
        for (i, v) in cam.views.iter().enumerate() {
            if view_poses[c][i].is_some() {
                let s = slots
                    .entry(v.t_ns)
                    .or_insert_with(|| FrameSlot { t: stamp(input, v.t_ns) + td0, views: vec![None; n_cams] });
                s.views[c] = Some(i);
            }
        }
    }
    let (t_first, t_last) = (input.imu.t.first().copied().unwrap_or(0.0), input.imu.t.last().copied().unwrap_or(0.0));
    let frames: Vec<FrameSlot> = slots.into_values().filter(|s| s.t > t_first && s.t < t_last).collect();
    if frames.len() < 10 {
        return Err(RigError::Recording(format!(
            "{} frame(s) with the target in view within the IMU's time span: too few",
            frames.len()
        )));
    }
    Ok(frames)
}

/// Each camera's `R_BC` and hand–eye residual \[rad\], and how many views were set aside.
pub(super) type HandEye = (Vec<Matrix3<f64>>, Vec<f64>, usize);

/// Stage 4: each camera's rotation in the IMU frame by hand–eye over pairs
/// [`HAND_EYE_SPAN`] frames apart, with its residual \[rad\]. A view whose
/// every pair disagrees with the gyro by more than
/// [`INCONSISTENT_VIEW_DEG`] under that rotation is set aside (a pose from
/// a few corners at the image's edge can come out flipped) and the rotation
/// found again without it; returns how many views were set aside.
pub(super) fn hand_eye_rotations(
    input: &RigInput,
    frames: &[FrameSlot],
    view_poses: &mut [Vec<Option<Isometry3F64>>],
    params: PreintegrationParams,
    progress: &mut dyn FnMut(&str),
) -> Result<HandEye, RigError> {
    let mut r_bc = Vec::new();
    let mut hand_eye_rms = Vec::new();
    let mut set_aside = 0;
    for (c, cam) in input.cameras.iter().enumerate() {
        let too_few = || {
            RigError::Recording(format!("{}: too few views to relate the camera's rotation to the gyro's", cam.name))
        };
        let pairs = hand_eye_pairs(input, frames, &view_poses[c], c, params);
        let rotations: Vec<_> = pairs.iter().map(|p| p.1).collect();
        let (mut r, mut rms) = init::hand_eye_rotation(&rotations).ok_or_else(too_few)?;
        let mut used = rotations.len();
        let inconsistent = init::views_inconsistent_with_gyro(&pairs, &r, INCONSISTENT_VIEW_DEG.to_radians());
        if !inconsistent.is_empty() {
            for &v in &inconsistent {
                view_poses[c][v] = None;
            }
            let kept = pairs.iter().filter(|p| !p.0.iter().any(|v| inconsistent.contains(v)));
            let rotations: Vec<_> = kept.map(|p| p.1).collect();
            (r, rms) = init::hand_eye_rotation(&rotations).ok_or_else(too_few)?;
            used = rotations.len();
            progress(&format!(
                "{}: {} view pose(s) that disagree with the gyro by over {INCONSISTENT_VIEW_DEG}° set aside",
                cam.name,
                inconsistent.len()
            ));
            set_aside += inconsistent.len();
        }
        progress(&format!(
            "{}: camera–IMU rotation from {} hand–eye pairs, residual {:.2}°",
            cam.name,
            used,
            rms.to_degrees()
        ));
        r_bc.push(r);
        hand_eye_rms.push(rms);
    }
    Ok((r_bc, hand_eye_rms, set_aside))
}

/// Camera `c`'s hand–eye pairs: the two views' indices and (gyro rotation
/// over the pair's interval, camera rotation `R_CaT R_CbTᵀ`).
fn hand_eye_pairs(
    input: &RigInput,
    frames: &[FrameSlot],
    view_poses: &[Option<Isometry3F64>],
    c: usize,
    params: PreintegrationParams,
) -> Vec<init::HandEyePair> {
    let zero_bias = (Vector3::zeros(), Vector3::zeros());
    let seen: Vec<usize> = (0..frames.len()).filter(|&k| frames[k].views[c].is_some()).collect();
    let mut pairs = Vec::new();
    for w in seen.windows(HAND_EYE_SPAN + 1) {
        let (a, b) = (w[0], w[HAND_EYE_SPAN]);
        let (Some(va), Some(vb)) = (frames[a].views[c], frames[b].views[c]) else { continue };
        if frames[b].t - frames[a].t > 1.0 {
            continue;
        }
        if let (Some(pa), Some(pb)) = (view_poses[va].as_ref(), view_poses[vb].as_ref()) {
            let (pim, _) = preintegrate(&input.imu, frames[a].t, frames[b].t, zero_bias, params);
            let rc = pa.rotation().matrix() * pb.rotation().matrix().transpose();
            pairs.push(([va, vb], (pim.delta_rotation(), rc)));
        }
    }
    pairs
}

/// Stage 5: gravity in the target frame (the first camera's views and the
/// accelerometer), the world it sets, the other cameras' `T_BC` from the
/// frames both see, and the body poses and velocities at the frames.
pub(super) fn starting_state(
    input: &RigInput,
    frames: &[FrameSlot],
    view_poses: &[Vec<Option<Isometry3F64>>],
    r_bc: &[Matrix3<f64>],
) -> Result<StartingState, RigError> {
    let body_in_target = |k: usize, c: usize, t_bc: &Isometry3F64| -> Option<Isometry3F64> {
        let t_ct = view_poses[c][frames[k].views[c]?]?;
        Some(t_ct.inverse().group_mul(t_bc.inverse()))
    };
    let mut t_bc: Vec<Isometry3F64> = r_bc.iter().map(|r| pose(r, &Vector3::zeros())).collect();
    let mut g_sum = Vector3::zeros();
    let mut g_n = 0usize;
    for (k, f) in frames.iter().enumerate() {
        if let Some(tb) = body_in_target(k, 0, &t_bc[0]) {
            g_sum -= tb.rotation().matrix() * input.imu.at(f.t).0;
            g_n += 1;
        }
    }
    let g_t = g_sum / g_n.max(1) as f64;
    let t_wt = pose(&gravity_aligned(&(-g_t)), &Vector3::zeros());
    for c in 1..input.cameras.len() {
        let (mut rs, mut ts) = (Vec::new(), Vec::new());
        for (k, f) in frames.iter().enumerate() {
            if let (Some(tb), Some(v)) = (body_in_target(k, 0, &t_bc[0]), f.views[c]) {
                if let Some(t_ct) = view_poses[c][v] {
                    let (r, t) = parts(&tb.inverse().group_mul(t_ct.inverse()));
                    rs.push(r);
                    ts.push(t);
                }
            }
        }
        if rs.len() >= 3 {
            let t = ts.iter().sum::<Vector3<f64>>() / ts.len() as f64;
            t_bc[c] = pose(&mean_rotation(&rs), &t);
        }
    }
    let mut body: Vec<Isometry3F64> = Vec::with_capacity(frames.len());
    for k in 0..frames.len() {
        let tb = (0..input.cameras.len())
            .find_map(|c| body_in_target(k, c, &t_bc[c]))
            .ok_or_else(|| RigError::Internal("a frame without a pose".into()))?;
        body.push(t_wt.group_mul(tb));
    }
    let position = |k: usize| parts(&body[k]).1;
    let vel: Vec<Vector3<f64>> = (0..frames.len())
        .map(|k| {
            let (a, b) = (k.saturating_sub(1), (k + 1).min(frames.len() - 1));
            if b > a && frames[b].t > frames[a].t {
                (position(b) - position(a)) / (frames[b].t - frames[a].t)
            } else {
                Vector3::zeros()
            }
        })
        .collect();
    let bias = vec![Vector6::zeros(); frames.len()];
    Ok(StartingState { t_bc, t_wt, body, vel, offset: 0.0, bias })
}

/// What the joint solve found.
pub(super) struct Joint {
    /// The solution.
    solution: Values,
    /// The last pass's graph, and its corner factors.
    graph: Graph,
    corners: Vec<CornerEntry>,
    /// The covariances of `cov_keys`: the noise model's, then the
    /// cluster-robust ones over each partition into blocks of frames and
    /// over the target's corners.
    covs: Vec<Covariances>,
    cov_keys: Vec<Key>,
    /// The partitions into blocks of frames of the cluster-robust
    /// covariances, as `covs[1..]`; the last of `covs` is over the corners.
    partitions: Vec<super::BlockPartition>,
    /// The target's corners seen (the clusters of the last covariance).
    corner_clusters: usize,
    /// Every pass converged; iterations over all passes.
    pub converged: bool,
    iterations: usize,
    /// Whitened χ²/dof of the IMU factors.
    imu_chi2_per_dof: f64,
}

impl Joint {
    /// The solve's offset variable: the time offset beyond the frames' placement \[s\].
    pub(super) fn offset(&self) -> Result<f64, RigError> {
        Ok(self.solution.get::<Vector1<f64>>(OFFSET)?[0])
    }

    /// Kalibr's `timeshift_cam_imu` \[s\] (the frames' placement of `start`
    /// plus the solve's offset) and its σ, the larger of the two
    /// covariances' (NaN when the offset is not estimated).
    pub(super) fn time_offset(&self, start: &Start, o: &RigOptions) -> Result<(f64, f64), RigError> {
        let td = start.frame_offset + self.offset()?;
        let sigma = if o.estimate_time_offset {
            self.covs.iter().map(|c| c.get(OFFSET).map_or(f64::NAN, |m| m[(0, 0)].sqrt())).fold(0.0, f64::max)
        } else {
            f64::NAN
        };
        Ok((td, sigma))
    }
}

/// The joint graph of one pass and what the covariances need of it.
struct JointGraph {
    graph: Graph,
    /// The corner factors' entries.
    corners: Vec<CornerEntry>,
    /// The IMU factors' indices.
    imu_factors: Vec<usize>,
    /// Each factor's cluster label ([`ClusterLabels`]).
    labels: Vec<Option<usize>>,
}

/// Stage 6 (one pass): the joint graph — IMU preintegration and bias walks
/// between frames (preintegrated at `solution`'s biases), the target's
/// gauge, every corner with its rate at exposure less `gyro_bias` — each
/// factor labelled by `label`.
fn joint_graph(
    input: &RigInput,
    start: &Start,
    solution: &Values,
    gyro_integral: &RateIntegral,
    gyro_bias: &[Vector3<f64>],
    gravity: Vector3<f64>,
    label: ClusterLabels,
) -> Result<JointGraph, RigError> {
    let frames = &start.frames;
    let params = start.params;
    let mut graph = Graph::new();
    let mut corners = Vec::new();
    let mut imu_factors = Vec::new();
    let mut labels = Vec::new();
    for k in 0..frames.len() - 1 {
        let b = solution.get::<Vector6<f64>>(B(k as u64))?;
        let bias = (b.fixed_rows::<3>(0).into_owned(), b.fixed_rows::<3>(3).into_owned());
        let (pim, _) = preintegrate(&input.imu, frames[k].t, frames[k + 1].t, bias, params);
        let (i, j) = (k as u64, k as u64 + 1);
        let f = ImuFactor::new([X(i), V(i), B(i), X(j), V(j)], Arc::new(pim), gravity);
        let noise = f.noise_model()?;
        imu_factors.push(graph.add(f, noise));
        let dt = frames[k + 1].t - frames[k].t;
        let (f, noise) = bias_random_walk_axes(B(i), B(j), params.accel_walk().into(), params.gyro_walk().into(), dt)?;
        graph.add(f, noise);
        labels.extend([Some(label.motion(k)); 2]);
    }
    graph.add(AutoDiff::new(TargetGauge::new(TARGET, &start.state.t_wt)), NoiseModel::isotropic(4, GAUGE_SIGMA)?);
    labels.push(None);
    for (k, f) in frames.iter().enumerate() {
        let rate = gyro_integral.mean(f.t - 2.5e-3, f.t + 2.5e-3).unwrap_or_else(Vector3::zeros) - gyro_bias[k];
        for (c, cam) in input.cameras.iter().enumerate() {
            let Some(v) = f.views[c] else { continue };
            let noise = NoiseModel::isotropic(2, start.cameras[c].pixel_sigma)?;
            for corner in &cam.views[v].corners {
                let keys = [X(k as u64), V(k as u64), TARGET, extrinsic(c), intrinsics(c), OFFSET];
                corners.push(CornerEntry { entry: graph.len(), camera: c, frame: k, uv: corner.uv });
                let kind = start.cameras[c].model.distortion.kind();
                graph.add_robust(
                    TargetCorner::new(keys, corner.target, corner.uv, rate.into(), kind),
                    noise.clone(),
                    Huber(HUBER_SIGMAS),
                );
                labels.push(Some(label.corner(k, corner.id)));
            }
        }
    }
    Ok(JointGraph { graph, corners, imu_factors, labels })
}

/// The joint solve's starting values (intrinsics held where given, the
/// time offset held at 0 when not estimated).
fn starting_values(o: &RigOptions, start: &Start) -> Values {
    let s = &start.state;
    let mut values = Values::new();
    for k in 0..start.frames.len() {
        values.insert(X(k as u64), s.body[k]);
        values.insert(V(k as u64), s.vel[k]);
        values.insert(B(k as u64), s.bias[k]);
    }
    values.insert(TARGET, s.t_wt);
    values.insert(OFFSET, Vector1::new(s.offset));
    if !o.estimate_time_offset {
        values.set_constant(OFFSET, true);
    }
    for (c, cam) in start.cameras.iter().enumerate() {
        values.insert(extrinsic(c), s.t_bc[c]);
        values.insert(intrinsics(c), SVector::<f64, 8>::from_column_slice(&cam.model.to_vector()));
        values.set_constant(intrinsics(c), c < o.fixed_intrinsics.len());
    }
    values
}

/// Whitened χ² per degree of freedom of the IMU factors `imu_factors` at `values`.
fn imu_chi2_per_dof(graph: &Graph, values: &Values, imu_factors: &[usize]) -> f64 {
    let mut chi2 = 0.0;
    for &i in imu_factors {
        let e = &graph.entries()[i];
        if let Some(mut r) = values.residual_of(e.factor.as_ref()) {
            e.noise.whiten(&mut r);
            chi2 += r.norm_squared();
        }
    }
    chi2 / (9 * imu_factors.len()).max(1) as f64
}

/// Stage 6: the joint solve, twice when the corners' rates need the gyro
/// bias the first solve found; the covariances of the calibration.
///
/// The σ are the largest of the noise model's and the cluster-robust ones
/// over blocks of √N consecutive frames (batch means' rule), over
/// [`COARSE_BLOCKS`] blocks and over the target's corners: corner errors
/// that depend on the view's geometry (the detector's bias, the lens
/// model's misfit) are alike in neighbouring views, those of the target
/// itself (its print, its flatness) alike in every view, and the corners'
/// scatter alone shows neither.
pub(super) fn joint_solve(
    input: &RigInput,
    o: &RigOptions,
    start: &Start,
    gyro_integral: &RateIntegral,
    progress: &mut dyn FnMut(&str),
) -> Result<Joint, RigError> {
    let frames = &start.frames;
    let n_cams = input.cameras.len();
    let gravity = Vector3::new(0.0, 0.0, -o.gravity);
    let gyro_of = |b: &Vector6<f64>| -> Vector3<f64> { b.fixed_rows::<3>(3).into_owned() };
    let mut gyro_bias: Vec<Vector3<f64>> = start.state.bias.iter().map(gyro_of).collect();
    let mut keys: Vec<Key> = Vec::new();
    let mut solution = starting_values(o, start);
    let (mut converged, mut iterations) = (true, 0);
    let mut last = None;
    let cluster_labels = ClusterLabels::of(input);
    for pass in 0..2 {
        progress(&format!("joint solve {}: {} frames, {} cameras", pass + 1, frames.len(), n_cams));
        let JointGraph { graph, corners, imu_factors, labels } =
            joint_graph(input, start, &solution, gyro_integral, &gyro_bias, gravity, cluster_labels)?;
        let opts = LmOptions { max_iterations: o.max_iterations, log_iterations: false, ..LmOptions::default() };
        keys = (0..n_cams).flat_map(|c| [extrinsic(c), intrinsics(c)]).filter(|k| !solution.is_constant(*k)).collect();
        if o.estimate_time_offset {
            keys.push(OFFSET);
        }
        let (sol, summary, c) = Optimizer::new(opts)
            .optimize_with_robust_covariances(&graph, &solution, &keys, &labels)
            .map_err(|e| RigError::Solver { what: "joint solve", source: e })?;
        progress(&format!(
            "  {} iterations, cost {:.4e} → {:.4e} ({:?}, {:.1} s)",
            summary.iterations, summary.initial_cost, summary.final_cost, summary.termination, summary.time_total
        ));
        converged &= summary.converged();
        iterations += summary.iterations;
        solution = sol;
        let mut largest_change: f64 = 0.0;
        for (k, b) in gyro_bias.iter_mut().enumerate() {
            let found = gyro_of(solution.get::<Vector6<f64>>(B(k as u64))?);
            largest_change = largest_change.max((found - *b).norm());
            *b = found;
        }
        let chi2 = imu_chi2_per_dof(&graph, &solution, &imu_factors);
        last = Some((graph, corners, c, chi2));
        // The corners' rates were taken with the gyro bias of the start:
        // solve again only if the bias found moves the exposure-time rotation
        // `Δb_g · td` by more than a small fraction of a pixel's angle.
        let td = solution.get::<Vector1<f64>>(OFFSET)?[0];
        if largest_change * td.abs() < RATE_BIAS_TOLERANCE_RAD {
            break;
        }
    }
    let (graph, corners, cov, imu_chi2_per_dof) = last.ok_or_else(|| RigError::Internal("no solve ran".into()))?;
    let cov = cov.map_err(|e| RigError::Solver { what: "covariances", source: e })?;
    let (partitions, corner_clusters, robust) = robust_partitions(&cov, cluster_labels, frames.len());
    let covs = std::iter::once(cov.model).chain(robust).collect();
    Ok(Joint {
        solution,
        graph,
        corners,
        covs,
        cov_keys: keys,
        partitions,
        corner_clusters,
        converged,
        iterations,
        imu_chi2_per_dof,
    })
}

/// Stage 7, one camera: its calibration with σ (the larger of the two
/// covariances'), reprojection statistics and residuals.
pub(super) fn camera_result(
    input: &RigInput,
    o: &RigOptions,
    start: &Start,
    joint: &Joint,
    c: usize,
) -> Result<CameraResult, RigError> {
    let cam = &input.cameras[c];
    let solution = &joint.solution;
    let e: &Isometry3F64 = solution.get(extrinsic(c))?;
    let kv: &SVector<f64, 8> = solution.get(intrinsics(c))?;
    let fixed = c < o.fixed_intrinsics.len();
    let model = CameraModel::from_vector(start.cameras[c].model.distortion.kind(), kv.as_slice());
    let r = e.rotation().matrix();
    let sd = |m: &Matrix3<f64>| Vector3::new(m[(0, 0)].sqrt(), m[(1, 1)].sqrt(), m[(2, 2)].sqrt());
    let (mut rotation_sigma, mut translation_sigma) = (Vector3::zeros(), Vector3::zeros());
    let mut model_sigma = [0.0f64; 8];
    for cv in &joint.covs {
        let ce = cv.get(extrinsic(c)).ok_or_else(|| RigError::Internal("no covariance of T_BC".into()))?;
        // Tangent [ω, ν] on the right: rotation about camera axes, translation along them.
        rotation_sigma = rotation_sigma.sup(&sd(&(r * ce.fixed_view::<3, 3>(0, 0) * r.transpose())));
        translation_sigma = translation_sigma.sup(&sd(&(r * ce.fixed_view::<3, 3>(3, 3) * r.transpose())));
        if !fixed {
            let ck =
                cv.get(intrinsics(c)).ok_or_else(|| RigError::Internal("no covariance of the intrinsics".into()))?;
            for (i, s) in model_sigma.iter_mut().enumerate() {
                *s = s.max(ck[(i, i)].sqrt());
            }
        }
    }
    let pixel_sigma = start.cameras[c].pixel_sigma;
    let (reprojection, residuals) = reprojection(&joint.graph, solution, &joint.corners, c, &start.frames, pixel_sigma);
    let mut d: Vec<f64> = cam.views.windows(2).map(|w| (w[1].t_ns - w[0].t_ns) as f64 * 1e-9).collect();
    Ok(CameraResult {
        name: cam.name.clone(),
        model,
        model_sigma,
        intrinsics_fixed: fixed,
        resolution: cam.resolution.unwrap_or([0, 0]),
        rate_hz: crate::model::numeric::median(&mut d).map_or(f64::NAN, |m| 1.0 / m),
        t_bc: to_nalgebra(e),
        rotation_sigma,
        translation_sigma,
        pixel_sigma,
        reprojection,
        residuals,
        hand_eye_rms: start.hand_eye_rms[c],
    })
}

/// Stage 7: the rig's calibration from the joint solve (its `seconds` left at 0).
pub(super) fn results(
    input: &RigInput,
    o: &RigOptions,
    start: &Start,
    joint: &Joint,
    coarse: Option<init::OffsetSearch>,
    mut notes: Vec<String>,
) -> Result<RigResult, RigError> {
    let solution = &joint.solution;
    let mut largest_ratio: f64 = 0.0;
    for k in &joint.cov_keys {
        for robust in &joint.covs[1..] {
            if let (Some(m), Some(r)) = (joint.covs[0].get(*k), robust.get(*k)) {
                for i in 0..m.nrows() {
                    largest_ratio = largest_ratio.max((r[(i, i)] / m[(i, i)]).sqrt());
                }
            }
        }
    }
    let sigma_source =
        super::SigmaSource { partitions: joint.partitions.clone(), corners: joint.corner_clusters, largest_ratio };
    let (time_offset_s, time_offset_sigma_s) = joint.time_offset(start, o)?;
    let cameras =
        (0..input.cameras.len()).map(|c| camera_result(input, o, start, joint, c)).collect::<Result<Vec<_>, _>>()?;
    let chain = (1..cameras.len()).map(|c| cameras[c].t_bc.inverse() * cameras[c - 1].t_bc).collect();
    let frames = &start.frames;
    let biases = (0..frames.len())
        .filter_map(|k| {
            let b = solution.get::<Vector6<f64>>(B(k as u64)).ok()?;
            Some((frames[k].t, b.fixed_rows::<3>(0).into_owned(), b.fixed_rows::<3>(3).into_owned()))
        })
        .collect();
    let t_wt_final: &Isometry3F64 = solution.get(TARGET)?;
    let gravity_in_target = t_wt_final.rotation().matrix().transpose() * Vector3::new(0.0, 0.0, -o.gravity);
    if joint.imu_chi2_per_dof > 4.0 {
        notes.push(format!(
            "the IMU residuals are {:.1}× what the noise model predicts: the noise figures ({}) are too small for this IMU, so the σ given here are too small as well",
            joint.imu_chi2_per_dof, input.noise_source
        ));
    }
    Ok(RigResult {
        cameras,
        time_offset_s,
        time_offset_sigma_s,
        coarse_time_offset: coarse.as_ref().map(|c| (c.0, c.1)),
        time_offset_profile: coarse.map(|c| c.2).unwrap_or_default(),
        gravity_in_target,
        chain,
        biases,
        imu_chi2_per_dof: joint.imu_chi2_per_dof,
        sigma_source,
        frames: frames.len(),
        iterations: joint.iterations,
        converged: joint.converged,
        seconds: 0.0,
        noise_source: input.noise_source.clone(),
        notes,
        split: None,
    })
}

/// Weak parameters are written (a VIO refines them, or tolerates them), but said.
pub(super) fn note_weak_parameters(rig: &mut RigResult) {
    let weak: Vec<String> = rig
        .verdicts()
        .into_iter()
        .filter(|v| v.determination == super::Determination::Weak)
        .map(|v| format!("{} (3σ {:.3e} {} against {:.3e} sought)", v.parameter, 3.0 * v.sigma, v.units, v.accuracy))
        .collect();
    if !weak.is_empty() {
        rig.notes.push(format!(
            "weakly determined, written all the same: {}; more rotation about every axis and the target over the \
             whole image and tilted determine them better (docs/rig.md, recording advice)",
            weak.join(", ")
        ));
    }
}

/// A corner factor of the graph: its entry, camera, frame and pixel.
struct CornerEntry {
    entry: usize,
    camera: usize,
    frame: usize,
    uv: [f64; 2],
}

/// Reprojection statistics and per-corner residuals of camera `c` at the solution.
fn reprojection(
    graph: &Graph,
    values: &Values,
    corners: &[CornerEntry],
    c: usize,
    frames: &[FrameSlot],
    sigma: f64,
) -> (Reprojection, Vec<CornerResidual>) {
    let mut norms = Vec::new();
    let mut out = Vec::new();
    for ce in corners.iter().filter(|ce| ce.camera == c) {
        let Some(r) = values.residual_of(graph.entries()[ce.entry].factor.as_ref()) else { continue };
        norms.push(r.norm());
        out.push((frames[ce.frame].t, ce.uv, [r[0], r[1]]));
    }
    let n = norms.len();
    let rms = (norms.iter().map(|x| x * x).sum::<f64>() / n.max(1) as f64).sqrt();
    let outliers = norms.iter().filter(|&&x| x > HUBER_SIGMAS * sigma).count();
    let median = crate::model::numeric::median(&mut norms).unwrap_or(f64::NAN);
    (
        Reprojection {
            corners: n,
            rms_px: rms,
            median_px: median,
            outlier_fraction: outliers as f64 / n.max(1) as f64,
        },
        out,
    )
}
