//! Initialization from a moving start: the closed-form visual–inertial
//! solution (Martinelli 2014; Kaiser, Martinelli et al. 2017), with gravity
//! refined on its sphere as VINS-Mono does.
//!
//! Over a short window of frames the gyro gives the body rotations relative
//! to the first frame (`R_k`) and the preintegrated accelerometer the metric
//! displacement `Δp_k`. With the first frame's velocity `v₀` and the gravity
//! `g` (both in the first body frame) unknown, the body position is linear in
//! them, `p_k = v₀ t_k + ½ g t_k² + Δp_k`, and so is every observation of a
//! landmark at depth `λ` along its first ray `u_a`:
//! `[û_k]× R_ckᵀ (p_ca + λ R_ca u_a − p_ck) = 0`. One linear least-squares
//! problem in `(v₀, g, λ…)` gives velocity, gravity direction — roll and pitch —
//! and metric scale at once, without visual SfM. The gyro bias is found
//! first, from the features alone ([`gyro_bias`]): a raw MEMS gyro's bias
//! (EuRoC's ADIS16448: 0.08 rad/s about z) turns the window's rotations by
//! several degrees and spoils every row; the window refines it afterwards.
//!
//! Two things spoil it and are guarded against. A mismatched observation
//! enters every row of its track; mismatches are removed first, free of the
//! unknown scale, by the coplanarity of each frame pair's parallax with the
//! camera's translation (one mismatch anchoring a track bent the whole
//! solution), then rows that miss far more than the others. The equations
//! also vanish for the trivial solution — nothing moves, every landmark at
//! the camera — which noise favours when the window's parallax is small (a
//! walk at 0.1 m/s over 1.5 s): a solution whose median depth comes out
//! under 0.3 m is refused, and the estimator tries a window twice as long.
//!
//! With a second camera ([`super::StereoCamera`]) its matches add rows of
//! the same form seen from `t_BC1`; those at a landmark's anchor frame fix
//! its depth by the baseline alone, so scale no longer waits for parallax:
//! a slow window that the single camera refuses initializes.
//!
//! Noise-free, the solution is exact (the unit tests: tilt 1e-4°, velocity
//! 1e-4 m/s); with the default simulated noise, over 1.5 s of a one-minute
//! walk, tilt within 1.5° and velocity within 0.12 m/s.

use super::VioError;
use super::VioInput;
use crate::model::geometry::{gravity_aligned, parts, preintegrate};
use nalgebra::{DMatrix, DVector, Matrix3, Matrix3x6, Vector3};
use std::collections::BTreeMap;
use tumble_factors::camera::CameraModel;
use tumble_factors::imu_preint::{Preintegrated, PreintegrationParams};

/// What the closed-form initialization found, at the window's last frame.
#[derive(Debug, Clone, PartialEq)]
pub struct MotionInit {
    /// Rotation world←body at the last frame (world z up, yaw of the first
    /// frame taken as 0).
    pub rotation: Matrix3<f64>,
    /// Velocity at the last frame in the world frame \[m/s\].
    pub velocity: Vector3<f64>,
    /// Gyro bias found from the features \[rad/s\] ([`gyro_bias`]); None
    /// when they do not determine it to within the start prior's σ (the
    /// window's rotations were then integrated with a zero bias).
    pub bias_gyro: Option<Vector3<f64>>,
    /// Gravity magnitude of the unconstrained solution \[m/s²\] (a check of
    /// the motion's excitation: far from the true value means the window did
    /// not observe scale).
    pub free_gravity: f64,
    /// Landmarks used.
    pub landmarks: usize,
    /// Observations of the second camera used (0 without one).
    pub stereo_observations: usize,
}

/// Fewest landmarks the solution needs.
const MIN_LANDMARKS: usize = 15;
/// Most landmarks used (the longest tracks).
const MAX_LANDMARKS: usize = 120;
/// Rows missing by less than this are never dropped as mismatches \[m\]
/// (half a pixel at 2 m for a focal length of 500 px).
const ROW_MISS_FLOOR_M: f64 = 2e-3;
/// Median landmark depth below which the solution is taken for the trivial
/// one \[m\].
const MIN_DEPTH_M: f64 = 0.3;
/// Parallax-plane misses below this angle are never taken for mismatches
/// \[rad\].
const PAIR_ANGLE_FLOOR_RAD: f64 = 2e-3;
/// Fewest features a frame pair needs for its mismatches to be looked for.
const MIN_PAIR_FEATURES: usize = 8;
/// Most rounds of dropping mismatched observations.
const MISMATCH_ROUNDS: usize = 4;
/// Relative error of the free gravity magnitude accepted.
const MAX_GRAVITY_ERROR: f64 = 0.1;
/// The σ of the gyro-bias prior of a window's start \[rad/s\]
/// (`super::window::START_GYRO_BIAS_SIGMA`): the features' estimate of the
/// bias is used when it is better determined than that, else the bias starts at 0.
const GYRO_BIAS_PRIOR_SIGMA: f64 = super::window::START_GYRO_BIAS_SIGMA;
/// Rounds of the gyro-bias estimate, each with the IMU integrated again at
/// the last one (the bias enters the rotations to first order only).
const GYRO_BIAS_ROUNDS: usize = 3;

/// Solve the closed-form initialization over the frames `frames` (indices
/// into `input.frames`, in time order, at least 4), the IMU already corrected
/// by the calibration, preintegrated with the noise `imu`, under local
/// `gravity` \[m/s²\]. With [`VioInput::stereo`] the second camera's matches
/// in those frames join the equations. An error says why the window cannot
/// initialize (too few landmarks, too little motion) — the caller tries a
/// later window.
pub fn closed_form(
    input: &VioInput,
    frames: &[usize],
    imu: &PreintegrationParams,
    gravity: f64,
) -> Result<MotionInit, VioError> {
    if frames.len() < 4 {
        return Err(format!("{} frames in the window, 4 needed", frames.len()).into());
    }
    let by_track = bearings(frames, |k| input.frames[k].features.iter(), &input.camera);
    let (r_bc, t_bc) = parts(&input.body_from_camera);
    let (bias_gyro, determined) = window_gyro_bias(input, frames, &by_track, &r_bc, imu);
    let motion = Motion::integrate(input, frames, bias_gyro, imu);
    // The second camera's matches of the same tracks, when there is one.
    let stereo = match &input.stereo {
        Some(st) => bearings(frames, |k| st.features.get(k).into_iter().flatten(), &st.camera),
        None => BTreeMap::new(),
    };
    // Camera c's (R_BC, t_BC): 0 the first, 1 the second.
    let extrinsics = [(r_bc, t_bc), input.stereo.as_ref().map_or((r_bc, t_bc), |st| parts(&st.body_from_camera))];
    let used = landmarks(by_track, &stereo, &motion.rot, &r_bc);
    if used.len() < MIN_LANDMARKS {
        return Err(format!("{} landmarks seen 3 or more times, {MIN_LANDMARKS} needed", used.len()).into());
    }
    let (rows, stereo_rows) = rows(&used, &motion, &extrinsics);
    let (x, kept_rows) = solve_robustly(&rows, used.len())?;
    let mut active = vec![false; used.len()];
    for ((j, ..), _) in rows.iter().zip(&kept_rows).filter(|(_, &k)| k) {
        active[*j] = true;
    }
    let kept = active.iter().filter(|&&a| a).count();
    let stereo_observations = kept_rows.iter().zip(&stereo_rows).filter(|(&k, &st)| k && st).count();
    if kept < MIN_LANDMARKS {
        return Err(format!("{kept} landmarks fit the motion, {MIN_LANDMARKS} needed").into());
    }
    let depths: Vec<f64> = (0..used.len()).filter(|&j| active[j]).map(|j| x[6 + j]).collect();
    check_scale_observed(depths, Vector3::new(x[3], x[4], x[5]).norm(), gravity)?;
    let free_g = Vector3::new(x[3], x[4], x[5]);
    let free_gravity = free_g.norm();
    // Gravity on its sphere: g = |g| ĝ + B w, w in the tangent plane, solved
    // again a few times.
    let mut g = free_g * (gravity / free_gravity);
    let mut v0 = Vector3::new(x[0], x[1], x[2]);
    for _ in 0..4 {
        let y = solve_rows(&rows, used.len(), &kept_rows, Some(&g))?;
        g = (g + tangent_basis(&g) * nalgebra::Vector2::new(y[3], y[4])).normalize() * gravity;
        v0 = Vector3::new(y[0], y[1], y[2]);
    }
    let last = frames.len() - 1;
    // World ← first body: gravity down, yaw 0.
    let r_w0 = gravity_aligned(&(-g));
    Ok(MotionInit {
        rotation: r_w0 * motion.rot[last],
        velocity: r_w0 * (v0 + g * motion.time[last] + motion.dv[last]),
        bias_gyro: determined.then_some(bias_gyro),
        free_gravity,
        landmarks: kept,
        stereo_observations,
    })
}

/// The features of the window's frames by track: (window position,
/// undistorted normalized `[x, y, 1]`), through `camera`.
fn bearings<'a, I>(frames: &[usize], features: impl Fn(usize) -> I, camera: &CameraModel) -> BTreeMap<u64, Vec<Bearing>>
where
    I: Iterator<Item = &'a (u64, [f64; 2])>,
{
    let mut by_track: BTreeMap<u64, Vec<Bearing>> = BTreeMap::new();
    for (w, &k) in frames.iter().enumerate() {
        for (id, uv) in features(k) {
            if let Some(xy) = camera.unproject(*uv) {
                by_track.entry(*id).or_default().push((w, Vector3::new(xy[0], xy[1], 1.0)));
            }
        }
    }
    by_track
}

/// The window's IMU preintegrated from its first frame to each frame at gyro
/// bias `bg` (None for the first frame).
fn integrate(
    input: &VioInput,
    frames: &[usize],
    bg: Vector3<f64>,
    imu: &PreintegrationParams,
) -> Vec<Option<Preintegrated>> {
    let t0 = input.frames[frames[0]].t;
    frames
        .iter()
        .map(|&k| {
            let t = input.frames[k].t;
            (t > t0).then(|| preintegrate(&input.imu, t0, t, (Vector3::zeros(), bg), *imu).0)
        })
        .collect()
}

/// The gyro bias from the features, then the IMU integrated with it, a few
/// rounds; used only where the features determine it to better than the
/// window's start prior on the gyro bias assumes (else 0, and false).
fn window_gyro_bias(
    input: &VioInput,
    frames: &[usize],
    by_track: &BTreeMap<u64, Vec<Bearing>>,
    r_bc: &Matrix3<f64>,
    imu: &PreintegrationParams,
) -> (Vector3<f64>, bool) {
    let mut bias_gyro = Vector3::zeros();
    for _ in 0..GYRO_BIAS_ROUNDS {
        let pims = integrate(input, frames, bias_gyro, imu);
        let rot: Vec<Matrix3<f64>> =
            pims.iter().map(|p| p.as_ref().map_or(Matrix3::identity(), |p| p.delta_rotation())).collect();
        let mut cleaned: Vec<Vec<Bearing>> = by_track.values().cloned().collect();
        drop_mismatches(&mut cleaned, &rot, r_bc);
        let tracks: Vec<&Vec<Bearing>> = cleaned.iter().collect();
        match gyro_bias(&pims, &tracks, r_bc, bias_gyro) {
            Some((b, sigma)) if sigma < GYRO_BIAS_PRIOR_SIGMA => {
                let done = (b - bias_gyro).norm() < 1e-6;
                bias_gyro = b;
                if done {
                    break;
                }
            }
            _ => return (Vector3::zeros(), false),
        }
    }
    (bias_gyro, true)
}

/// The body's rotation, metric displacement and velocity change since the
/// window's first frame, and the time since it \[s\], at each frame.
struct Motion {
    rot: Vec<Matrix3<f64>>,
    dp: Vec<Vector3<f64>>,
    dv: Vec<Vector3<f64>>,
    time: Vec<f64>,
}

impl Motion {
    fn integrate(input: &VioInput, frames: &[usize], bias_gyro: Vector3<f64>, imu: &PreintegrationParams) -> Motion {
        let t0 = input.frames[frames[0]].t;
        let n = frames.len();
        let mut m = Motion {
            rot: Vec::with_capacity(n),
            dp: Vec::with_capacity(n),
            dv: Vec::with_capacity(n),
            time: Vec::with_capacity(n),
        };
        for (&k, pim) in frames.iter().zip(integrate(input, frames, bias_gyro, imu)) {
            match pim {
                None => {
                    m.rot.push(Matrix3::identity());
                    m.dp.push(Vector3::zeros());
                    m.dv.push(Vector3::zeros());
                }
                Some(pim) => {
                    m.rot.push(pim.delta_rotation());
                    m.dp.push(pim.delta_position());
                    m.dv.push(pim.delta_velocity());
                }
            }
            m.time.push(input.frames[k].t - t0);
        }
        m
    }
}

/// The landmarks the solution uses: per track its anchor (the first camera's
/// first observation) and every other observation as (window position,
/// camera, bearing), mismatches dropped, at least two others; the
/// [`MAX_LANDMARKS`] longest.
fn landmarks(
    by_track: BTreeMap<u64, Vec<Bearing>>,
    stereo: &BTreeMap<u64, Vec<Bearing>>,
    rot: &[Matrix3<f64>],
    r_bc: &Matrix3<f64>,
) -> Vec<(Bearing, Vec<CameraBearing>)> {
    let (ids, mut tracks): (Vec<u64>, Vec<Vec<Bearing>>) = by_track.into_iter().unzip();
    drop_mismatches(&mut tracks, rot, r_bc);
    let mut used: Vec<(Bearing, Vec<CameraBearing>)> = ids
        .iter()
        .zip(tracks)
        .filter_map(|(id, obs)| {
            let (&anchor, rest) = obs.split_first()?;
            let second = stereo.get(id).into_iter().flatten().map(|&(w, u)| (w, 1, u));
            let others: Vec<_> = rest.iter().map(|&(w, u)| (w, 0, u)).chain(second).collect();
            (others.len() >= 2).then_some((anchor, others))
        })
        .collect();
    used.sort_by_key(|(_, others)| std::cmp::Reverse(others.len()));
    used.truncate(MAX_LANDMARKS);
    used
}

/// The rows `[û_k]× R_ckᵀ (…) = 0`, linear in `(v₀, g, λ_j)`: per observation
/// the 3×6 block of `(v₀, g)`, the column of `λ_j` and the constant; and
/// whether each is the second camera's. An observation of the second camera
/// sees the landmark from `t_BC1` instead: one at the anchor's own frame
/// fixes `λ_j` by the baseline alone.
fn rows(
    used: &[(Bearing, Vec<CameraBearing>)],
    m: &Motion,
    extrinsics: &[(Matrix3<f64>, Vector3<f64>); 2],
) -> (Vec<Row>, Vec<bool>) {
    let (r_bc, t_bc) = &extrinsics[0];
    let (time, rot) = (&m.time, &m.rot);
    let mut rows: Vec<Row> = Vec::new();
    let mut stereo_rows = Vec::new();
    for (j, ((a, ua), others)) in used.iter().enumerate() {
        let ray = rot[*a] * r_bc * ua;
        for &(k, c, uk) in others {
            let (r_c, t_c) = &extrinsics[c];
            let mm = cross(&uk.normalize()) * (rot[k] * r_c).transpose();
            let mut jvg = Matrix3x6::zeros();
            jvg.fixed_view_mut::<3, 3>(0, 0).copy_from(&(mm * (time[*a] - time[k])));
            jvg.fixed_view_mut::<3, 3>(0, 3).copy_from(&(mm * (0.5 * (time[*a] * time[*a] - time[k] * time[k]))));
            // The camera's lever arm between the two frames.
            let lever = if c == 0 { (rot[*a] - rot[k]) * t_bc } else { rot[*a] * t_bc - rot[k] * t_c };
            stereo_rows.push(c == 1);
            rows.push((j, jvg, mm * ray, mm * ((m.dp[*a] - m.dp[k]) + lever)));
        }
    }
    (rows, stereo_rows)
}

/// Least squares over the rows still `kept`, with `n` landmark depths (a
/// landmark left without any row has its depth pinned to 0 by a unit
/// diagonal). `fixed_g` moves a known gravity to the constants and solves
/// for its tangent-plane correction instead (5 columns, not 6).
fn solve_rows(rows: &[Row], n: usize, kept: &[bool], fixed_g: Option<&Vector3<f64>>) -> Result<DVector<f64>, String> {
    let cols = if fixed_g.is_some() { 5 } else { 6 };
    let m = cols + n;
    let mut h = DMatrix::<f64>::zeros(m, m);
    let mut b = DVector::<f64>::zeros(m);
    let mut seen = vec![false; n];
    let basis = fixed_g.map(tangent_basis);
    for ((j, jvg, jl, c), _) in rows.iter().zip(kept).filter(|(_, &k)| k) {
        seen[*j] = true;
        let (jr, cr) = match (fixed_g, &basis) {
            (Some(g), Some(basis)) => {
                let mut jr = DMatrix::<f64>::zeros(3, 5);
                jr.view_mut((0, 0), (3, 3)).copy_from(&jvg.fixed_view::<3, 3>(0, 0));
                jr.view_mut((0, 3), (3, 2)).copy_from(&(jvg.fixed_view::<3, 3>(0, 3) * basis));
                (jr, c + jvg.fixed_view::<3, 3>(0, 3) * g)
            }
            _ => (DMatrix::from_column_slice(3, 6, jvg.as_slice()), *c),
        };
        let l = cols + j;
        let mut hvg = h.view_mut((0, 0), (cols, cols));
        hvg += jr.transpose() * &jr;
        let cross_term = jr.transpose() * jl;
        for i in 0..cols {
            h[(i, l)] += cross_term[i];
            h[(l, i)] += cross_term[i];
        }
        h[(l, l)] += jl.norm_squared();
        let mut bvg = b.rows_mut(0, cols);
        bvg -= jr.transpose() * cr;
        b[l] -= jl.dot(&cr);
    }
    for (j, _) in seen.iter().enumerate().filter(|(_, &s)| !s) {
        h[(cols + j, cols + j)] = 1.0;
    }
    h.cholesky().map(|ch| ch.solve(&b)).ok_or_else(|| "the window's equations are singular".to_string())
}

/// The free solution `(v₀, g, λ…)` over every row, then again without the
/// rows that miss by more than 3× the median (rows are the ray's miss at the
/// landmark in metres: what [`drop_mismatches`] could not see), a few
/// rounds, until the set kept no longer changes. Returns it and the rows kept.
fn solve_robustly(rows: &[Row], n: usize) -> Result<(DVector<f64>, Vec<bool>), String> {
    let mut kept_rows = vec![true; rows.len()];
    let mut x = solve_rows(rows, n, &kept_rows, None)?;
    for _ in 0..MISMATCH_ROUNDS {
        let xvg = x.fixed_rows::<6>(0).into_owned();
        let miss: Vec<f64> = rows.iter().map(|(j, jvg, jl, c)| (jvg * xvg + jl * x[6 + j] + c).norm()).collect();
        let mut sorted: Vec<f64> = miss.iter().zip(&kept_rows).filter(|(_, &k)| k).map(|(e, _)| *e).collect();
        sorted.sort_by(f64::total_cmp);
        let limit = (3.0 * sorted[sorted.len() / 2]).max(ROW_MISS_FLOOR_M);
        let next: Vec<bool> = miss.iter().map(|&e| e <= limit).collect();
        if next == kept_rows {
            break;
        }
        kept_rows = next;
        x = solve_rows(rows, n, &kept_rows, None)?;
    }
    Ok((x, kept_rows))
}

/// Refuse a solution that did not observe scale: the landmarks' `depths`
/// near the trivial solution — nothing moves, every landmark at the camera,
/// which noise favours when the parallax is small — or a free gravity
/// magnitude far from `gravity`.
fn check_scale_observed(mut depths: Vec<f64>, free_gravity: f64, gravity: f64) -> Result<(), String> {
    let kept = depths.len();
    depths.sort_by(f64::total_cmp);
    let median_depth = depths[depths.len() / 2];
    let positive = depths.iter().filter(|&&d| d > 0.0).count();
    if median_depth < MIN_DEPTH_M || positive * 5 < kept * 4 {
        return Err(format!(
            "the landmarks came out {median_depth:.2} m from the camera ({positive} of {kept} in front): \
             too little parallax to observe scale"
        ));
    }
    if !free_gravity.is_finite() || (free_gravity / gravity - 1.0).abs() > MAX_GRAVITY_ERROR {
        return Err(format!(
            "gravity came out {free_gravity:.2} m/s² (expected {gravity:.2}): too little motion to observe scale"
        ));
    }
    Ok(())
}

/// The gyro bias that makes the window's rotations agree with its features
/// (after the eigenvalue formulation of Kneip and Lynen, 2013): between two
/// frames `a`, `b` every landmark's bearings `u_a`, `R_ab u_b` and the
/// camera's translation are coplanar, so the normals `u_a × R_ab u_b` of all
/// the pair's landmarks are orthogonal to the translation and the scatter of
/// their directions has a zero smallest eigenvalue — at the right rotation
/// only. Pairs are each track's first frame with each later one. `R_ab(b_g)` comes from the
/// preintegrated rotations (`pims[w]`, None for the first frame) corrected to
/// first order from `start`; the sum over frame pairs of the smallest
/// eigenvalues is minimized over `b_g` by Levenberg–Marquardt (one residual
/// √λ_min per pair, numerical derivatives). None when fewer than three pairs
/// share 8 features (`MIN_PAIR_FEATURES`) or the solve fails. Returns the
/// bias \[rad/s\] and the largest of its standard deviations \[rad/s\] (over
/// a slow walk with far landmarks a sideways translation looks like a yaw
/// rate, and the features hardly determine it).
pub fn gyro_bias(
    pims: &[Option<Preintegrated>],
    tracks: &[&Vec<Bearing>],
    r_bc: &Matrix3<f64>,
    start: Vector3<f64>,
) -> Option<(Vector3<f64>, f64)> {
    let mut pairs: BTreeMap<(usize, usize), Vec<BearingPair>> = BTreeMap::new();
    // Each track's first observation against each later one: the longest
    // baselines the window has (consecutive frames' parallax is too small to
    // tell a translation from a rotation).
    for obs in tracks {
        let Some((&(a, ua), rest)) = obs.split_first() else { continue };
        for &(b, ub) in rest {
            pairs.entry((a, b)).or_default().push((ua.normalize(), ub.normalize()));
        }
    }
    let key = tumble_solvers::Key::new('w', 0);
    let mut graph = tumble_solvers::Graph::new();
    let pims: std::sync::Arc<Vec<Option<Preintegrated>>> = std::sync::Arc::new(pims.to_vec());
    for ((a, b), list) in pairs.into_iter().filter(|(_, l)| l.len() >= MIN_PAIR_FEATURES) {
        let f = CoplanarityFactor { keys: [key], pims: pims.clone(), frames: (a, b), bearings: list, r_bc: *r_bc };
        graph.add(f, tumble_solvers::NoiseModel::Unit);
    }
    if graph.entries().len() < 3 {
        return None;
    }
    let mut values = tumble_solvers::Values::new();
    values.insert(key, start);
    let lm = tumble_solvers::LmOptions { max_iterations: 20, log_iterations: false, ..Default::default() };
    let (sol, summary) = tumble_solvers::Optimizer::new(lm).optimize(&graph, &values).ok()?;
    let b = sol.get::<Vector3<f64>>(key).ok().copied().filter(|b| b.iter().all(|x| x.is_finite()))?;
    // Its covariance: the inverse Gauss–Newton information scaled by the
    // residuals' own variance (one residual per pair, three unknowns).
    let m = graph.entries().len();
    let s2 = 2.0 * summary.final_cost / (m - 3) as f64;
    let cov = tumble_solvers::covariances(&graph, &sol, &[key]).ok()?.get(key)?;
    let sigma = (0..3).map(|i| (cov[(i, i)] * s2).max(0.0).sqrt()).fold(0.0, f64::max);
    Some((b, sigma))
}

/// A landmark's unit bearings in two frames.
type BearingPair = (Vector3<f64>, Vector3<f64>);

/// `√λ_min` of one frame pair's coplanarity normals as a function of the gyro
/// bias (see [`gyro_bias`]).
struct CoplanarityFactor {
    keys: [tumble_solvers::Key; 1],
    pims: std::sync::Arc<Vec<Option<Preintegrated>>>,
    frames: (usize, usize),
    bearings: Vec<BearingPair>,
    r_bc: Matrix3<f64>,
}

impl tumble_solvers::Factor for CoplanarityFactor {
    fn keys(&self) -> &[tumble_solvers::Key] {
        &self.keys
    }
    fn residual_dim(&self) -> usize {
        1
    }
    fn residual(&self, vars: tumble_solvers::Vars<'_>) -> Result<DVector<f64>, tumble_solvers::FactorError> {
        let bg: &Vector3<f64> = vars.get(0)?;
        let rot = |w: usize| self.pims[w].as_ref().map_or(Matrix3::identity(), |p| p.corrected(&p.bias().0, bg).0);
        let r_ab = self.r_bc.transpose() * rot(self.frames.0).transpose() * rot(self.frames.1) * self.r_bc;
        // Directions only (floored): a rotation that cancels the parallax
        // would otherwise shrink every normal and look like a fit.
        let dirs: Vec<Vector3<f64>> = self
            .bearings
            .iter()
            .map(|(ua, ub)| {
                let n = ua.cross(&(r_ab * ub));
                n / n.norm().max(PAIR_ANGLE_FLOOR_RAD)
            })
            .collect();
        let smallest = |ds: &mut dyn Iterator<Item = &Vector3<f64>>| {
            let (m, k) = ds.fold((Matrix3::zeros(), 0usize), |(m, k), d| (m + d * d.transpose(), k + 1));
            let e = m.symmetric_eigen();
            let i = e.eigenvalues.imin();
            (e.eigenvalues[i].max(0.0) / k.max(1) as f64, e.eigenvectors.column(i).into_owned())
        };
        // A mismatched observation's normal points anywhere: trimmed at 3×
        // the median miss of the plane (as `drop_mismatches`), then again.
        let (_, mut t) = smallest(&mut dirs.iter());
        let mut lambda = 0.0;
        for _ in 0..2 {
            let mut miss: Vec<f64> = dirs.iter().map(|d| d.dot(&t).abs()).collect();
            let limit =
                (3.0 * crate::model::numeric::median(&mut miss.clone()).unwrap_or(0.0)).max(PAIR_ANGLE_FLOOR_RAD);
            miss.iter_mut().for_each(|m| *m = if *m <= limit { 1.0 } else { 0.0 });
            let (l, tn) = smallest(&mut dirs.iter().zip(&miss).filter(|(_, &k)| k > 0.0).map(|(d, _)| d));
            lambda = l;
            t = tn;
        }
        Ok(DVector::from_element(1, lambda.sqrt()))
    }
}

/// An observation: window position and undistorted normalized `[x, y, 1]`.
type Bearing = (usize, Vector3<f64>);

/// An observation by either camera: window position, camera (0, 1), bearing.
type CameraBearing = (usize, usize, Vector3<f64>);

/// One observation's row: landmark index, the 3×6 block of `(v₀, g)`, the
/// depth's column and the constant.
type Row = (usize, Matrix3x6<f64>, Vector3<f64>, Vector3<f64>);

/// A frame pair's parallax vector: track, index of its later observation, vector.
type Parallax = (usize, usize, Vector3<f64>);

/// Remove the observations that do not fit the motion between two frames.
///
/// A track's rows all refer to its first observation, so a single mismatched
/// pixel can bend the whole linear solution — even towards the trivial one
/// in which nothing moves and every landmark sits at the camera. Mismatches
/// are found before, free of the unknown scale: between two frames `a`, `b`
/// whose rotation the gyro gives, every landmark's two bearings and the
/// camera's translation `t` are coplanar, `(u_a × R_ab u_b) · t = 0`. Per
/// frame pair, `t` is the direction most orthogonal to all those parallax
/// vectors (smallest eigenvector, twice with the worst fits left out); an
/// observation pair missing it by more than 3× the median (or
/// `PAIR_ANGLE_FLOOR_RAD`) is a mismatch and both its observations are
/// dropped. Frame pairs with fewer than `MIN_PAIR_FEATURES` are left as
/// they are.
fn drop_mismatches(tracks: &mut [Vec<(usize, Vector3<f64>)>], rot: &[Matrix3<f64>], r_bc: &Matrix3<f64>) {
    // Parallax vectors by frame pair: (track, index of the later observation, vector).
    let mut pairs: BTreeMap<(usize, usize), Vec<Parallax>> = BTreeMap::new();
    for (i, obs) in tracks.iter().enumerate() {
        for (n, w) in obs.windows(2).enumerate() {
            let ((a, ua), (b, ub)) = (w[0], w[1]);
            let r_ab = r_bc.transpose() * rot[a].transpose() * rot[b] * r_bc;
            let parallax = ua.normalize().cross(&(r_ab * ub.normalize()));
            pairs.entry((a, b)).or_default().push((i, n + 1, parallax));
        }
    }
    let mut bad: Vec<Vec<bool>> = tracks.iter().map(|o| vec![false; o.len()]).collect();
    for list in pairs.values().filter(|l| l.len() >= MIN_PAIR_FEATURES) {
        let mut on = vec![true; list.len()];
        let mut miss = vec![0.0; list.len()];
        let mut limit = f64::INFINITY;
        for _ in 0..3 {
            let scatter = list.iter().zip(&on).filter(|(_, &o)| o).fold(Matrix3::zeros(), |m, ((_, _, p), _)| {
                // Directions only: a mismatch's long parallax vector
                // would otherwise outweigh dozens of right ones.
                let d = p / p.norm().max(PAIR_ANGLE_FLOOR_RAD);
                m + d * d.transpose()
            });
            let eig = scatter.symmetric_eigen();
            let t = eig.eigenvectors.column(eig.eigenvalues.imin()).into_owned();
            for (m, (_, _, p)) in miss.iter_mut().zip(list) {
                *m = p.dot(&t).abs();
            }
            let mut sorted: Vec<f64> = miss.iter().zip(&on).filter(|(_, &o)| o).map(|(m, _)| *m).collect();
            sorted.sort_by(f64::total_cmp);
            limit = (3.0 * sorted[sorted.len() / 2]).max(PAIR_ANGLE_FLOOR_RAD);
            on = miss.iter().map(|m| *m <= limit).collect();
        }
        for ((i, n, _), m) in list.iter().zip(&miss) {
            if *m > limit {
                bad[*i][*n - 1] = true;
                bad[*i][*n] = true;
            }
        }
    }
    for (obs, bad) in tracks.iter_mut().zip(bad) {
        let mut flags = bad.into_iter();
        obs.retain(|_| !flags.next().unwrap_or(false));
    }
}

/// The skew-symmetric matrix of `v` (`[v]× w = v × w`).
fn cross(v: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -v.z, v.y, v.z, 0.0, -v.x, -v.y, v.x, 0.0)
}

/// Two unit vectors orthogonal to `g` and to each other (3×2).
fn tangent_basis(g: &Vector3<f64>) -> nalgebra::Matrix3x2<f64> {
    let a = g.normalize();
    let helper = if a.x.abs() < 0.9 { Vector3::x() } else { Vector3::y() };
    let b1 = (helper - a * a.dot(&helper)).normalize();
    let b2 = a.cross(&b1);
    nalgebra::Matrix3x2::from_columns(&[b1, b2])
}
