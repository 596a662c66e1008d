//! Starting values of the rig calibration, with no guess from the user:
//! each camera's intrinsics from homographies (Zhang's closed form, then a
//! camera-only bundle adjustment on a subset of views), every view's target
//! pose from its homography, the coarse time offset from the correlation of
//! camera and gyro rotation rates, the camera–IMU rotation from hand–eye
//! rotations (VINS-Mono's `InitialEXRotation`), and gravity in the target
//! frame from the mean specific force.

use crate::model::geometry::pose;
use crate::model::numeric::median;
use crate::model::target::View;
use crate::model::ImuData;
use nalgebra::{DMatrix, Matrix3, Matrix4, UnitQuaternion, Vector3, Vector4};
use tumble_factors::camera::{CameraModel, DistortionKind};
use tumble_factors::rig::CameraCorner;
use tumble_solvers::sophus_lie::prelude::*;
use tumble_solvers::sophus_lie::Isometry3F64;
use tumble_solvers::{AutoDiff, Huber, Key, LmOptions, NoiseModel, Optimizer, Values, X};

/// Fewest corners a view needs to give a homography and a pose.
pub const MIN_CORNERS: usize = 8;

/// Homography `H` with `[u, v, 1] ∝ H [x, y, 1]` by the normalized DLT (Hartley);
/// None when the points are degenerate.
pub fn homography(obj: &[[f64; 2]], img: &[[f64; 2]]) -> Option<Matrix3<f64>> {
    let n = obj.len();
    if n < 4 || img.len() != n {
        return None;
    }
    let normalizer = |p: &[[f64; 2]]| {
        let m = p.iter().fold([0.0, 0.0], |a, q| [a[0] + q[0], a[1] + q[1]]).map(|s| s / n as f64);
        let d = p.iter().map(|q| ((q[0] - m[0]).powi(2) + (q[1] - m[1]).powi(2)).sqrt()).sum::<f64>() / n as f64;
        if d <= 0.0 {
            return None;
        }
        let s = std::f64::consts::SQRT_2 / d;
        Some(Matrix3::new(s, 0.0, -s * m[0], 0.0, s, -s * m[1], 0.0, 0.0, 1.0))
    };
    let (to, ti) = (normalizer(obj)?, normalizer(img)?);
    let mut a = DMatrix::<f64>::zeros(2 * n, 9);
    for i in 0..n {
        let p = to * Vector3::new(obj[i][0], obj[i][1], 1.0);
        let q = ti * Vector3::new(img[i][0], img[i][1], 1.0);
        let (x, y, u, v) = (p.x, p.y, q.x / q.z, q.y / q.z);
        let r0 = [-x, -y, -1.0, 0.0, 0.0, 0.0, u * x, u * y, u];
        let r1 = [0.0, 0.0, 0.0, -x, -y, -1.0, v * x, v * y, v];
        for c in 0..9 {
            a[(2 * i, c)] = r0[c];
            a[(2 * i + 1, c)] = r1[c];
        }
    }
    let h = smallest_right_singular(&a)?;
    let hn = Matrix3::from_row_slice(h.as_slice());
    let hm = ti.try_inverse()? * hn * to;
    (hm[(2, 2)].abs() > 1e-300).then(|| hm / hm[(2, 2)])
}

/// The right singular vector of the smallest singular value (via the 9×9 or
/// 6×6 normal matrix's eigenvectors).
fn smallest_right_singular(a: &DMatrix<f64>) -> Option<nalgebra::DVector<f64>> {
    let ata = a.transpose() * a;
    let eig = nalgebra::SymmetricEigen::new(ata);
    let (k, _) = eig.eigenvalues.iter().enumerate().min_by(|x, y| x.1.total_cmp(y.1))?;
    let v = eig.eigenvectors.column(k).into_owned();
    v.iter().all(|x| x.is_finite()).then_some(v)
}

/// Zhang's closed-form pinhole intrinsics `[fx, fy, cx, cy]` (zero skew
/// assumed) from ≥ 3 homographies of a planar target in different
/// orientations; None when the views do not determine them.
pub fn zhang(homographies: &[Matrix3<f64>]) -> Option<[f64; 4]> {
    if homographies.len() < 3 {
        return None;
    }
    let vij = |h: &Matrix3<f64>, i: usize, j: usize| {
        let (a, b) = (h.column(i), h.column(j));
        [
            a[0] * b[0],
            a[0] * b[1] + a[1] * b[0],
            a[1] * b[1],
            a[2] * b[0] + a[0] * b[2],
            a[2] * b[1] + a[1] * b[2],
            a[2] * b[2],
        ]
    };
    let mut v = DMatrix::<f64>::zeros(2 * homographies.len(), 6);
    for (k, h) in homographies.iter().enumerate() {
        let h = h / h.column(0).norm().max(1e-300);
        let (v12, v11, v22) = (vij(&h, 0, 1), vij(&h, 0, 0), vij(&h, 1, 1));
        for c in 0..6 {
            v[(2 * k, c)] = v12[c];
            v[(2 * k + 1, c)] = v11[c] - v22[c];
        }
    }
    let b = smallest_right_singular(&v)?;
    let (b11, b12, b22, b13, b23, b33) = (b[0], b[1], b[2], b[3], b[4], b[5]);
    let den = b11 * b22 - b12 * b12;
    if den.abs() < 1e-300 || b11.abs() < 1e-300 {
        return None;
    }
    let cy = (b12 * b13 - b11 * b23) / den;
    let lambda = b33 - (b13 * b13 + cy * (b12 * b13 - b11 * b23)) / b11;
    let fx = (lambda / b11).sqrt();
    let fy = (lambda * b11 / den).sqrt();
    let gamma = -b12 * fx * fx * fy / lambda;
    let cx = gamma * cy / fy - b13 * fx * fx / lambda;
    [fx, fy, cx, cy].iter().all(|x| x.is_finite()).then_some([fx, fy, cx, cy]).filter(|k| k[0] > 0.0 && k[1] > 0.0)
}

/// One focal length (fx = fy) from homographies when the principal point
/// `centre` is known: each view's two orthogonality constraints on the
/// rotation's first columns give `f²`; the median of the positive ones.
pub fn focal_with_centre(homographies: &[Matrix3<f64>], centre: [f64; 2]) -> Option<f64> {
    let shift = Matrix3::new(1.0, 0.0, -centre[0], 0.0, 1.0, -centre[1], 0.0, 0.0, 1.0);
    let mut f2 = Vec::new();
    for h in homographies {
        let h = shift * h;
        let (a, b) = (h.column(0), h.column(1));
        let num = a[0] * b[0] + a[1] * b[1];
        let den = a[2] * b[2];
        if den.abs() > 1e-12 {
            f2.push(-num / den);
        }
        let num = a[0] * a[0] + a[1] * a[1] - b[0] * b[0] - b[1] * b[1];
        let den = a[2] * a[2] - b[2] * b[2];
        if den.abs() > 1e-12 {
            f2.push(-num / den);
        }
    }
    let mut f: Vec<f64> = f2.into_iter().filter(|x| x.is_finite() && *x > 0.0).map(f64::sqrt).collect();
    median(&mut f)
}

/// Target-to-camera pose `T_CT` from the homography of target `(x, y)` to
/// undistorted normalized image coordinates; the target in front of the camera.
pub fn pose_from_homography(h: &Matrix3<f64>) -> Option<Isometry3F64> {
    let (h1, h2, h3) = (h.column(0).into_owned(), h.column(1).into_owned(), h.column(2).into_owned());
    let s = 2.0 / (h1.norm() + h2.norm());
    let sign = if h3.z * s < 0.0 { -1.0 } else { 1.0 };
    let (r1, r2, t) = (h1 * s * sign, h2 * s * sign, h3 * s * sign);
    let m = Matrix3::from_columns(&[r1, r2, r1.cross(&r2)]);
    let svd = m.svd(true, true);
    let (u, vt) = (svd.u?, svd.v_t?);
    let mut r = u * vt;
    if r.determinant() < 0.0 {
        r = u * Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, -1.0)) * vt;
    }
    t.iter().all(|x| x.is_finite()).then(|| pose(&r, &t))
}

/// A view's corners as target `(x, y)` and pixel arrays.
fn view_points(v: &View) -> (Vec<[f64; 2]>, Vec<[f64; 2]>) {
    (v.corners.iter().map(|c| [c.target[0], c.target[1]]).collect(), v.corners.iter().map(|c| c.uv).collect())
}

/// `T_CT` of a view under `model` (corners undistorted, then a homography); None
/// when fewer than [`MIN_CORNERS`] corners undistort.
pub fn view_pose(v: &View, model: &CameraModel) -> Option<Isometry3F64> {
    let (mut obj, mut img) = (Vec::new(), Vec::new());
    for c in &v.corners {
        if let Some(xy) = model.unproject(c.uv) {
            obj.push([c.target[0], c.target[1]]);
            img.push(xy);
        }
    }
    if obj.len() < MIN_CORNERS {
        return None;
    }
    pose_from_homography(&homography(&obj, &img)?)
}

/// `T_CT` of a view under a known camera `model`: the homography pose
/// ([`view_pose`]) refined by Levenberg–Marquardt on the corners'
/// reprojection (Huber, 2 px), the intrinsics held. Returns the pose and the
/// RMS reprojection error \[px\]; None with fewer than [`MIN_CORNERS`] corners
/// or when the solve fails. A per-frame PnP: ground truth of a target recording.
pub fn refine_view_pose(v: &View, model: &CameraModel) -> Option<(Isometry3F64, f64)> {
    let start = view_pose(v, model)?;
    let kind = model.distortion.kind();
    let kkey = Key::new('k', 0);
    let mut values = Values::new();
    values.insert(X(0), start);
    values.insert(kkey, nalgebra::SVector::<f64, 8>::from_column_slice(&model.to_vector()));
    values.set_constant(kkey, true);
    let mut graph = tumble_solvers::Graph::new();
    let noise = NoiseModel::isotropic(2, 1.0).ok()?;
    for c in &v.corners {
        graph.add_robust(
            AutoDiff::new(CameraCorner::new([X(0), kkey], c.target, c.uv, kind)),
            noise.clone(),
            Huber(2.0),
        );
    }
    let opts = LmOptions { max_iterations: 30, log_iterations: false, ..LmOptions::default() };
    let (sol, _) = Optimizer::new(opts).optimize(&graph, &values).ok()?;
    let t = *sol.get::<Isometry3F64>(X(0)).ok()?;
    let squares: Vec<f64> =
        graph.entries().iter().filter_map(|e| sol.residual_of(e.factor.as_ref())).map(|r| r.norm_squared()).collect();
    let rms = (squares.iter().sum::<f64>() / squares.len().max(1) as f64).sqrt();
    Some((t, rms))
}

/// The result of the camera-only calibration of one camera.
#[derive(Debug, Clone)]
pub struct CameraStart {
    /// Intrinsics and distortion.
    pub model: CameraModel,
    /// Robust standard deviation of the corners' reprojection (1.4826·MAD per coordinate) \[px\].
    pub pixel_sigma: f64,
    /// Views used.
    pub views: usize,
}

/// Views used by the camera-only calibration: at most this many, spread in time.
pub const CAMERA_ONLY_VIEWS: usize = 120;

/// Calibrate a camera alone: Zhang's closed form on the homographies of up to
/// [`CAMERA_ONLY_VIEWS`] views spread in time, then a bundle adjustment of
/// intrinsics, distortion and those views' poses (Huber on the corners).
/// With `fixed` intrinsics only the poses are adjusted (to measure the corners' σ).
/// `resolution` (when known) bounds the principal point and centres the fallback.
pub fn calibrate_camera(
    views: &[View],
    kind: DistortionKind,
    fixed: Option<&CameraModel>,
    resolution: Option<[u32; 2]>,
) -> Result<CameraStart, String> {
    // Views showing a good part of the target: partial views at the image's
    // edge constrain the intrinsics little and their homographies are poor.
    let most = views.iter().map(|v| v.corners.len()).max().unwrap_or(0);
    let least = MIN_CORNERS.max(most * 3 / 10);
    let usable: Vec<&View> = views.iter().filter(|v| v.corners.len() >= least).collect();
    if usable.len() < 3 {
        return Err(format!(
            "{} view(s) with ≥ {least} corners: a camera's intrinsics need ≥ 3 views of the target in different orientations",
            usable.len()
        ));
    }
    let step = (usable.len() as f64 / CAMERA_ONLY_VIEWS as f64).max(1.0);
    let chosen: Vec<&View> =
        (0..usable.len().min(CAMERA_ONLY_VIEWS)).map(|i| usable[(i as f64 * step) as usize]).collect();
    // Pixels scaled to ~1 for conditioning.
    let scale = 1e-3;
    let homs: Vec<Matrix3<f64>> = chosen
        .iter()
        .filter_map(|v| {
            let (o, i) = view_points(v);
            let i: Vec<[f64; 2]> = i.iter().map(|p| [p[0] * scale, p[1] * scale]).collect();
            homography(&o, &i)
        })
        .collect();
    let mut model = match fixed {
        Some(m) => *m,
        None => {
            // Zhang's closed form, unless it fails or puts the principal point
            // off the image: then a focal length per view with the principal
            // point at the image centre.
            let inside = |k: &[f64; 4]| {
                resolution.is_none_or(|r| {
                    (0.0..r[0] as f64 * scale).contains(&k[2]) && (0.0..r[1] as f64 * scale).contains(&k[3])
                })
            };
            let k = zhang(&homs)
                .filter(inside)
                .or_else(|| {
                    let r = resolution?;
                    let centre = [0.5 * r[0] as f64 * scale, 0.5 * r[1] as f64 * scale];
                    let f = focal_with_centre(&homs, centre)?;
                    Some([f, f, centre[0], centre[1]])
                })
                .ok_or("the views do not determine the focal lengths (is the target seen from different angles?)")?;
            CameraModel {
                fx: k[0] / scale,
                fy: k[1] / scale,
                cx: k[2] / scale,
                cy: k[3] / scale,
                distortion: tumble_factors::camera::Distortion::from_coefficients(kind, [0.0; 4]),
            }
        }
    };
    let kind = model.distortion.kind();
    let kkey = Key::new('k', 0);
    let mut pixel_sigma = 1.0;
    // Twice: the second pass sets the Huber threshold from the first's robust σ.
    for _ in 0..2 {
        let mut graph = tumble_solvers::Graph::new();
        let mut values = Values::new();
        values.insert(kkey, nalgebra::SVector::<f64, 8>::from_column_slice(&model.to_vector()));
        values.set_constant(kkey, fixed.is_some());
        let noise = NoiseModel::isotropic(2, pixel_sigma).map_err(|e| e.to_string())?;
        for (i, v) in chosen.iter().enumerate() {
            let Some(t) = view_pose(v, &model) else { continue };
            values.insert(X(i as u64), t);
            for c in &v.corners {
                graph.add_robust(
                    AutoDiff::new(CameraCorner::new([X(i as u64), kkey], c.target, c.uv, kind)),
                    noise.clone(),
                    Huber(2.0),
                );
            }
        }
        let opts = LmOptions { max_iterations: 100, log_iterations: false, ..LmOptions::default() };
        let (sol, _) = Optimizer::new(opts).optimize(&graph, &values).map_err(|e| e.to_string())?;
        let kv: &nalgebra::SVector<f64, 8> = sol.get(kkey).map_err(|e| e.to_string())?;
        model = CameraModel::from_vector(kind, kv.as_slice());
        let mut res = Vec::new();
        for e in graph.entries() {
            if let Some(r) = sol.residual_of(e.factor.as_ref()) {
                res.extend(r.iter().map(|x| x.abs()));
            }
        }
        pixel_sigma = 1.4826 * median(&mut res).ok_or("no corner residuals")?;
    }
    Ok(CameraStart { model, pixel_sigma, views: chosen.len() })
}

/// Cumulative integral of the gyro over the IMU's samples (trapezoid), to
/// average the rate over any interval in O(log n).
pub struct RateIntegral {
    t: Vec<f64>,
    cum: Vec<Vector3<f64>>,
}

impl RateIntegral {
    /// From the IMU samples.
    pub fn new(imu: &ImuData) -> Self {
        let mut cum = vec![Vector3::zeros(); imu.t.len()];
        for i in 1..imu.t.len() {
            cum[i] = cum[i - 1] + (imu.gyro[i] + imu.gyro[i - 1]) * 0.5 * (imu.t[i] - imu.t[i - 1]);
        }
        RateIntegral { t: imu.t.clone(), cum }
    }
    fn at(&self, t: f64) -> Option<Vector3<f64>> {
        let n = self.t.len();
        if n < 2 || t < self.t[0] || t > self.t[n - 1] {
            return None;
        }
        let j = self.t.partition_point(|&s| s <= t).clamp(1, n - 1);
        let w = (t - self.t[j - 1]) / (self.t[j] - self.t[j - 1]);
        Some(self.cum[j - 1] * (1.0 - w) + self.cum[j] * w)
    }
    /// Mean rate over `[a, b]` \[rad/s\]; None outside the samples.
    pub fn mean(&self, a: f64, b: f64) -> Option<Vector3<f64>> {
        Some((self.at(b)? - self.at(a)?) / (b - a))
    }
}

/// The camera's rotation rate between consecutive views: `(t_a, t_b, |ω|)`
/// \[s on the camera's axis, rad/s\] from the views' poses `T_CT`.
pub fn camera_rates(stamps: &[f64], poses: &[Option<Isometry3F64>], max_gap: f64) -> Vec<(f64, f64, f64)> {
    let mut out = Vec::new();
    for k in 1..stamps.len() {
        if let (Some(a), Some(b)) = (&poses[k - 1], &poses[k]) {
            let dt = stamps[k] - stamps[k - 1];
            if dt > 0.0 && dt <= max_gap {
                let rel = a.rotation().inverse().group_mul(b.rotation());
                out.push((stamps[k - 1], stamps[k], rel.log().norm() / dt));
            }
        }
    }
    out
}

/// Drop the view poses `T_CT` the gyro cannot reach from their neighbours:
/// a pose whose rotation from every neighbouring view within `max_gap`
/// \[s\] exceeds the largest measured rate (over the interval widened by
/// `max_offset` \[s\] each side, for the unknown time offset) times the
/// interval, plus 3° for the views' own noise. A pose flipped by the planar
/// ambiguity of a partial view is caught so. Returns how many were dropped.
pub fn drop_unreachable_poses(
    stamps: &[f64],
    poses: &mut [Option<Isometry3F64>],
    imu: &ImuData,
    max_gap: f64,
    max_offset: f64,
) -> usize {
    let largest_rate = |a: f64, b: f64| {
        let (i, j) = (imu.t.partition_point(|&t| t < a - max_offset), imu.t.partition_point(|&t| t <= b + max_offset));
        imu.gyro[i.min(imu.t.len())..j.min(imu.t.len())].iter().map(|g| g.norm()).fold(0.0, f64::max)
    };
    let reachable = |i: usize, j: usize, poses: &[Option<Isometry3F64>]| -> Option<bool> {
        let (a, b) = (poses[i].as_ref()?, poses[j].as_ref()?);
        let (ta, tb) = (stamps[i].min(stamps[j]), stamps[i].max(stamps[j]));
        if tb - ta > max_gap {
            return None;
        }
        let angle = a.rotation().inverse().group_mul(b.rotation()).log().norm();
        Some(angle <= largest_rate(ta, tb) * (tb - ta) + 3f64.to_radians())
    };
    let mut drop = Vec::new();
    for i in 0..poses.len() {
        let checks: Vec<bool> = [i.checked_sub(1), Some(i + 1).filter(|&j| j < poses.len())]
            .into_iter()
            .flatten()
            .filter_map(|j| reachable(i, j, poses))
            .collect();
        if !checks.is_empty() && checks.iter().all(|ok| !ok) {
            drop.push(i);
        }
    }
    for &i in &drop {
        poses[i] = None;
    }
    drop.len()
}

/// The coarse offset \[s\], its correlation, and the correlation at every shift `(shift [s], correlation)`.
pub type OffsetSearch = (f64, f64, Vec<(f64, f64)>);

/// The coarse camera-to-IMU time offset \[s\] in `[−max, max]`: the shift that
/// best correlates (by ranks) the camera's rotation rate with the gyro's (1 ms grid, then
/// a parabola through the peak), the peak correlation, and the correlation
/// at every shift of the grid. None without enough rotation.
pub fn correlate_time_offset(rates: &[(f64, f64, f64)], gyro: &RateIntegral, max: f64) -> Option<OffsetSearch> {
    let step = 1e-3;
    let n = (max / step).round() as i64;
    let corr = |tau: f64| -> Option<f64> {
        let pairs: Vec<(f64, f64)> =
            rates.iter().filter_map(|&(a, b, w)| Some((w, gyro.mean(a + tau, b + tau)?.norm()))).collect();
        if pairs.len() < 20 {
            return None;
        }
        // Ranks (Spearman): a view pose gone wrong makes one huge rate, which
        // would dominate a Pearson correlation.
        let rank = |x: Vec<f64>| {
            let mut idx: Vec<usize> = (0..x.len()).collect();
            idx.sort_by(|&i, &j| x[i].total_cmp(&x[j]));
            let mut r = vec![0.0; x.len()];
            for (k, &i) in idx.iter().enumerate() {
                r[i] = k as f64;
            }
            r
        };
        let (ra, rb) = (rank(pairs.iter().map(|p| p.0).collect()), rank(pairs.iter().map(|p| p.1).collect()));
        let pairs: Vec<(f64, f64)> = ra.into_iter().zip(rb).collect();
        let m = pairs.len() as f64;
        let (ma, mb) = pairs.iter().fold((0.0, 0.0), |s, p| (s.0 + p.0 / m, s.1 + p.1 / m));
        let (mut sab, mut saa, mut sbb) = (0.0, 0.0, 0.0);
        for (a, b) in &pairs {
            sab += (a - ma) * (b - mb);
            saa += (a - ma).powi(2);
            sbb += (b - mb).powi(2);
        }
        (saa > 0.0 && sbb > 0.0).then(|| sab / (saa * sbb).sqrt())
    };
    let scores: Vec<(f64, f64)> = (-n..=n).filter_map(|i| Some((i as f64 * step, corr(i as f64 * step)?))).collect();
    let (k, &(tau, best)) = scores.iter().enumerate().max_by(|a, b| a.1 .1.total_cmp(&b.1 .1))?;
    let refined = if k > 0 && k + 1 < scores.len() {
        let (y0, y1, y2) = (scores[k - 1].1, best, scores[k + 1].1);
        let den = y0 - 2.0 * y1 + y2;
        if den < 0.0 {
            tau + 0.5 * step * (y0 - y2) / den
        } else {
            tau
        }
    } else {
        tau
    };
    Some((refined, best, scores))
}

/// A hand–eye pair: its two views' indices, and (the gyro's rotation over
/// the pair's interval `R_BaBb`, the camera's `R_CaCb`).
pub type HandEyePair = ([usize; 2], (Matrix3<f64>, Matrix3<f64>));

/// The views every pair of which (at least one) disagrees with the gyro by
/// more than `threshold` \[rad\] under the camera–IMU rotation `r_bc`.
pub fn views_inconsistent_with_gyro(pairs: &[HandEyePair], r_bc: &Matrix3<f64>, threshold: f64) -> Vec<usize> {
    let mut verdicts: std::collections::BTreeMap<usize, (usize, usize)> = std::collections::BTreeMap::new();
    for (views, (rb, rc)) in pairs {
        let angle = tumble_solvers::lie::so3_log(&((rb * r_bc).transpose() * (r_bc * rc))).norm();
        for v in views {
            let e = verdicts.entry(*v).or_default();
            e.0 += 1;
            e.1 += usize::from(angle > threshold);
        }
    }
    verdicts.into_iter().filter(|(_, (n, bad))| n == bad).map(|(v, _)| v).collect()
}

/// Reweighting rounds of [`hand_eye_rotation`].
pub const HAND_EYE_ITERATIONS: usize = 8;

/// `[w, x, y, z]` left- and right-multiplication matrices of a quaternion.
fn quat_mul_matrices(q: &UnitQuaternion<f64>) -> (Matrix4<f64>, Matrix4<f64>) {
    let (w, x, y, z) = (q.w, q.i, q.j, q.k);
    let l = Matrix4::new(w, -x, -y, -z, x, w, -z, y, y, z, w, -x, z, -y, x, w);
    let r = Matrix4::new(w, -x, -y, -z, x, w, z, -y, y, -z, w, x, z, y, -x, w);
    (l, r)
}

/// The camera-to-body rotation `R_BC` from pairs of relative rotations
/// `(R_BiBj, R_CiCj)` (body from the gyro, camera from the views): the
/// hand–eye equation `R_BiBj R_BC = R_BC R_CiCj` solved in quaternions by
/// iteratively reweighted least squares (pairs whose residual exceeds 1°
/// down-weighted as by Huber, [`HAND_EYE_ITERATIONS`] rounds). Also returns
/// the RMS angular residual of the pairs within 5° \[rad\].
pub fn hand_eye_rotation(pairs: &[(Matrix3<f64>, Matrix3<f64>)]) -> Option<(Matrix3<f64>, f64)> {
    if pairs.len() < 3 {
        return None;
    }
    let quat = |m: &Matrix3<f64>| UnitQuaternion::from_rotation_matrix(&nalgebra::Rotation3::from_matrix_unchecked(*m));
    let mut weights = vec![1.0; pairs.len()];
    let mut rbc = Matrix3::identity();
    let mut rms = f64::NAN;
    for _ in 0..HAND_EYE_ITERATIONS {
        let mut a = DMatrix::<f64>::zeros(4 * pairs.len(), 4);
        for (i, (rb, rc)) in pairs.iter().enumerate() {
            let (l, _) = quat_mul_matrices(&quat(rb));
            let (_, r) = quat_mul_matrices(&quat(rc));
            let m = (l - r) * weights[i];
            a.view_mut((4 * i, 0), (4, 4)).copy_from(&m);
        }
        let v = smallest_right_singular(&a)?;
        let q =
            UnitQuaternion::from_quaternion(nalgebra::Quaternion::from_vector(Vector4::new(v[1], v[2], v[3], v[0])));
        rbc = q.to_rotation_matrix().into_inner();
        let (mut sum, mut n) = (0.0, 0usize);
        for (i, (rb, rc)) in pairs.iter().enumerate() {
            let e = (rb * rbc).transpose() * (rbc * rc);
            let angle = tumble_solvers::lie::so3_log(&e).norm();
            if angle < 5f64.to_radians() {
                sum += angle * angle;
                n += 1;
            }
            let threshold = 1f64.to_radians();
            weights[i] = if angle > threshold { threshold / angle } else { 1.0 };
        }
        rms = (sum / n.max(1) as f64).sqrt();
    }
    Some((rbc, rms))
}

#[cfg(test)]
mod tests {
    use super::*;
    use tumble_solvers::lie::so3_exp;

    /// Target poses `T_CT` looking at a 6×6 grid from different angles.
    fn views() -> Vec<(Matrix3<f64>, Vector3<f64>)> {
        [[0.3, -0.2, 0.1], [-0.4, 0.1, -0.2], [0.1, 0.5, 0.3], [-0.2, -0.4, 0.0], [0.5, 0.3, -0.1]]
            .iter()
            .enumerate()
            .map(|(i, w)| {
                (so3_exp(&Vector3::from(*w)), Vector3::new(-0.2 + 0.05 * i as f64, -0.2, 1.0 + 0.2 * i as f64))
            })
            .collect()
    }

    fn grid() -> Vec<[f64; 2]> {
        (0..36).map(|i| [(i % 6) as f64 * 0.08, (i / 6) as f64 * 0.08]).collect()
    }

    #[test]
    fn zhang_and_homography_poses_recover_a_pinhole_camera() {
        let k = [460.0, 455.0, 370.0, 250.0];
        let mut homs = Vec::new();
        for (r, t) in views() {
            let img: Vec<[f64; 2]> = grid()
                .iter()
                .map(|p| {
                    let c = r * Vector3::new(p[0], p[1], 0.0) + t;
                    [k[0] * c.x / c.z + k[2], k[1] * c.y / c.z + k[3]]
                })
                .collect();
            let scaled: Vec<[f64; 2]> = img.iter().map(|p| [p[0] * 1e-3, p[1] * 1e-3]).collect();
            homs.push(homography(&grid(), &scaled).unwrap());
            // The pose from normalized coordinates.
            let norm: Vec<[f64; 2]> = img.iter().map(|p| [(p[0] - k[2]) / k[0], (p[1] - k[3]) / k[1]]).collect();
            let pose = pose_from_homography(&homography(&grid(), &norm).unwrap()).unwrap();
            let (pr, pt) = crate::model::geometry::parts(&pose);
            assert!((pr - r).norm() < 1e-9 && (pt - t).norm() < 1e-9);
        }
        let est = zhang(&homs).unwrap();
        for i in 0..4 {
            assert!((est[i] * 1e3 - k[i]).abs() < 1e-6, "{est:?}");
        }
        // With the principal point known, one focal length between fx and fy.
        let f = focal_with_centre(&homs, [k[2] * 1e-3, k[3] * 1e-3]).unwrap() * 1e3;
        assert!(f > k[1] - 1.0 && f < k[0] + 1.0, "{f}");
    }

    #[test]
    fn hand_eye_recovers_the_camera_rotation() {
        let r_bc = so3_exp(&Vector3::new(0.1, -1.5, 0.3));
        let pairs: Vec<(Matrix3<f64>, Matrix3<f64>)> =
            [[0.2, 0.0, 0.1], [0.0, 0.3, -0.1], [-0.1, 0.1, 0.25], [0.15, -0.2, 0.0]]
                .iter()
                .map(|w| {
                    let rb = so3_exp(&Vector3::from(*w));
                    (rb, r_bc.transpose() * rb * r_bc)
                })
                .collect();
        let (est, rms) = hand_eye_rotation(&pairs).unwrap();
        assert!((est - r_bc).norm() < 1e-9 && rms < 1e-9);
    }
}
