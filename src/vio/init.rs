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
//! `[u_k]× R_ckᵀ (p_ca + λ R_ca u_a − p_ck) = 0`. One linear least-squares
//! problem in `(v₀, g, λ…)` gives velocity, gravity direction — roll and pitch —
//! and metric scale at once, without visual SfM. The gyro bias is taken as
//! zero (the calibration removed it); the window refines it afterwards.

use super::geometry::{gravity_aligned, parts, preintegrate};
use super::{VioInput, VioOptions};
use nalgebra::{DMatrix, DVector, Matrix3, Vector3};
use std::collections::BTreeMap;

/// What the closed-form initialization found, at the window's last frame.
#[derive(Debug, Clone, PartialEq)]
pub struct MotionInit {
    /// Rotation world←body at the last frame (world z up, yaw of the first
    /// frame taken as 0).
    pub rotation: Matrix3<f64>,
    /// Velocity at the last frame in the world frame \[m/s\].
    pub velocity: Vector3<f64>,
    /// Gravity magnitude of the unconstrained solution \[m/s²\] (a check of
    /// the motion's excitation: far from the true value means the window did
    /// not observe scale).
    pub free_gravity: f64,
    /// Landmarks used.
    pub landmarks: usize,
}

/// Fewest landmarks the solution needs.
const MIN_LANDMARKS: usize = 15;
/// Most landmarks used (the longest tracks).
const MAX_LANDMARKS: usize = 120;
/// Relative error of the free gravity magnitude accepted.
const MAX_GRAVITY_ERROR: f64 = 0.1;

/// Solve the closed-form initialization over the frames `frames` (indices
/// into `input.frames`, in time order, at least 4), the IMU already corrected
/// by the calibration. An error says why the window cannot initialize
/// (too few landmarks, too little motion) — the caller tries a later window.
pub fn closed_form(input: &VioInput, frames: &[usize], opts: &VioOptions) -> Result<MotionInit, String> {
    if frames.len() < 4 {
        return Err(format!("{} frames in the window, 4 needed", frames.len()));
    }
    let t0 = input.frames[frames[0]].t;
    let zero = (Vector3::zeros(), Vector3::zeros());
    // Body rotation, metric displacement and velocity change since the first frame.
    let mut rot = Vec::with_capacity(frames.len());
    let mut dp = Vec::with_capacity(frames.len());
    let mut dv = Vec::with_capacity(frames.len());
    let mut time = Vec::with_capacity(frames.len());
    for &k in frames {
        let t = input.frames[k].t;
        if t <= t0 {
            rot.push(Matrix3::identity());
            dp.push(Vector3::zeros());
            dv.push(Vector3::zeros());
        } else {
            let (pim, _) = preintegrate(&input.imu, t0, t, zero, opts.imu);
            rot.push(pim.delta_rotation());
            dp.push(pim.delta_position());
            dv.push(pim.delta_velocity());
        }
        time.push(t - t0);
    }
    // Observations by track: (window position, undistorted normalized xy).
    let mut tracks: BTreeMap<u64, Vec<(usize, Vector3<f64>)>> = BTreeMap::new();
    for (w, &k) in frames.iter().enumerate() {
        for (id, uv) in &input.frames[k].features {
            if let Some(xy) = input.camera.unproject(*uv) {
                tracks.entry(*id).or_default().push((w, Vector3::new(xy[0], xy[1], 1.0)));
            }
        }
    }
    let mut used: Vec<Vec<(usize, Vector3<f64>)>> = tracks.into_values().filter(|o| o.len() >= 3).collect();
    used.sort_by_key(|o| std::cmp::Reverse(o.len()));
    used.truncate(MAX_LANDMARKS);
    if used.len() < MIN_LANDMARKS {
        return Err(format!("{} landmarks seen in 3 or more frames, {MIN_LANDMARKS} needed", used.len()));
    }
    let (r_bc, t_bc) = parts(&input.body_from_camera);
    let n = 6 + used.len();
    // Normal equations of the rows [u_k]× R_ckᵀ (…) = 0 in (v₀, g, λ…).
    let mut h = DMatrix::<f64>::zeros(n, n);
    let mut b = DVector::<f64>::zeros(n);
    for (j, obs) in used.iter().enumerate() {
        let (a, ua) = obs[0];
        let ray = rot[a] * r_bc * ua;
        for &(k, uk) in &obs[1..] {
            let m = cross(&uk) * (rot[k] * r_bc).transpose();
            let mut row = DMatrix::<f64>::zeros(3, n);
            row.view_mut((0, 0), (3, 3)).copy_from(&(m * (time[a] - time[k])));
            row.view_mut((0, 3), (3, 3)).copy_from(&(m * (0.5 * (time[a] * time[a] - time[k] * time[k]))));
            row.view_mut((0, 6 + j), (3, 1)).copy_from(&(m * ray));
            let c = m * ((dp[a] - dp[k]) + (rot[a] - rot[k]) * t_bc);
            h += row.transpose() * &row;
            b -= row.transpose() * c;
        }
    }
    let solve = |h: &DMatrix<f64>, b: &DVector<f64>| -> Result<DVector<f64>, String> {
        h.clone().cholesky().map(|c| c.solve(b)).ok_or_else(|| "the window's equations are singular".to_string())
    };
    let x = solve(&h, &b)?;
    let free_g = Vector3::new(x[3], x[4], x[5]);
    let free_gravity = free_g.norm();
    if !free_gravity.is_finite() || (free_gravity / opts.gravity - 1.0).abs() > MAX_GRAVITY_ERROR {
        return Err(format!(
            "gravity came out {free_gravity:.2} m/s² (expected {:.2}): too little motion to observe scale",
            opts.gravity
        ));
    }
    // Gravity on its sphere: g = |g| ĝ + B w, w in the tangent plane, re-solved a few times.
    let mut g = free_g * (opts.gravity / free_gravity);
    let mut x = x;
    for _ in 0..4 {
        let basis = tangent_basis(&g);
        // Substitute g: columns 3..6 of H become H₃ B (2 columns), the constant moves to b.
        let mut p = DMatrix::<f64>::zeros(n, n - 1);
        p.view_mut((0, 0), (3, 3)).fill_with_identity();
        p.view_mut((3, 3), (3, 2)).copy_from(&basis);
        p.view_mut((6, 5), (n - 6, n - 6)).fill_with_identity();
        let mut g_full = DVector::<f64>::zeros(n);
        g_full.rows_mut(3, 3).copy_from(&g);
        let hr = p.transpose() * &h * &p;
        let br = p.transpose() * (&b - &h * g_full);
        let y = solve(&hr, &br)?;
        g = (g + basis * Vector3::new(y[3], y[4], 0.0).xy()).normalize() * opts.gravity;
        x = &p * &y;
        x.rows_mut(3, 3).copy_from(&g);
    }
    let positive = (0..used.len()).filter(|&j| x[6 + j] > 0.0).count();
    if positive * 5 < used.len() * 4 {
        return Err(format!("only {positive} of {} landmarks came out in front of the camera", used.len()));
    }
    let v0 = Vector3::new(x[0], x[1], x[2]);
    let last = frames.len() - 1;
    // World ← first body: gravity down, yaw 0.
    let r_w0 = gravity_aligned(&(-g));
    Ok(MotionInit {
        rotation: r_w0 * rot[last],
        velocity: r_w0 * (v0 + g * time[last] + dv[last]),
        free_gravity,
        landmarks: used.len(),
    })
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
