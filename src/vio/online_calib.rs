//! The camera's extrinsic `T_BC` and time offset `td` as variables of the
//! window ([`super::CameraCalibrationOptions`]): their keys, the prior at the
//! given values, and the values the landmarks and factors read.
//!
//! Each is one variable for the whole run. Their prior stays in every window
//! graph; the information of the measurements that leave the window reaches
//! them through the marginalization prior (they are in its separator), so
//! nothing is counted twice. A parameter that is not estimated is held
//! constant at its value; the estimator also holds them until a window's
//! length of keyframes is in the prior, and after an estimate that
//! `CameraPrior::implausible` rejects.

use super::geometry::{parts, pose};
use super::ImuData;
use super::{Estimate, VioInput, VioOptions};
use nalgebra::{Matrix3, Vector1, Vector3, Vector6};
use tumble_factors::reprojection::ExposureMotion;
use tumble_factors::PriorFactor;
use tumble_solvers::sophus_lie::Isometry3F64;
use tumble_solvers::{Covariances, Graph, Key, NoiseModel, Values};

/// Key of the first camera's pose in the IMU frame `T_BC` (SE(3)).
pub(crate) const EXTRINSIC: Key = Key::new('c', 0);
/// Key of the time offset `td` \[s\] (R¹).
pub(crate) const TIME_OFFSET: Key = Key::new('d', 0);

/// The estimate of the camera's calibration at the end of a run.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct CameraEstimate {
    /// `T_BC`: rotation body←camera `[w, x, y, z]`.
    pub rotation: [f64; 4],
    /// `T_BC`: the camera's centre in the body frame \[m\].
    pub translation: [f64; 3],
    /// Time offset \[s\] (t_imu = t_cam + td).
    pub time_offset_s: f64,
    /// σ of the rotation about the camera's axes \[deg\] (NaN when not estimated or not recovered).
    pub rotation_sigma_deg: [f64; 3],
    /// σ of the translation along the camera's axes \[m\] (NaN as above).
    pub translation_sigma_m: [f64; 3],
    /// σ of the time offset \[s\] (NaN as above).
    pub time_offset_sigma_s: f64,
    /// Rotation from the given `T_BC` to the estimate \[deg\].
    pub rotation_change_deg: f64,
    /// Distance from the given `T_BC`'s translation to the estimate's \[m\].
    pub translation_change_m: f64,
    /// Whether `T_BC` was estimated.
    pub extrinsics_estimated: bool,
    /// Whether `td` was estimated.
    pub time_offset_estimated: bool,
}

impl CameraEstimate {
    /// The rotation \[deg\] and the distance between the translations \[m\]
    /// from `body_from_camera` (a reference `T_BC`) to this estimate.
    pub fn difference(&self, body_from_camera: &Isometry3F64) -> (f64, f64) {
        let [w, x, y, z] = self.rotation;
        let q = nalgebra::UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(w, x, y, z));
        let estimate = pose(q.to_rotation_matrix().matrix(), &Vector3::from(self.translation));
        let (rot, t) = deviation(body_from_camera, &estimate);
        (rot.norm().to_degrees(), t.norm())
    }

    /// One line for the terminal: what was estimated, its σ and how far it moved from the given values.
    pub fn line(&self) -> String {
        let mut parts = Vec::new();
        if self.extrinsics_estimated {
            let [a, b, c] = self.rotation_sigma_deg;
            let [x, y, z] = self.translation_sigma_m.map(|s| s * 1e3);
            let t = self.translation;
            parts.push(format!(
                "T_BC translation [{:.4}, {:.4}, {:.4}] m (σ {x:.1} {y:.1} {z:.1} mm), rotation σ {a:.3} {b:.3} {c:.3}°; \
                 moved {:.3}° and {:.1} mm from the given",
                t[0],
                t[1],
                t[2],
                self.rotation_change_deg,
                self.translation_change_m * 1e3
            ));
        }
        if self.time_offset_estimated {
            parts.push(format!(
                "time offset {:.2} ms (σ {:.2} ms, t_imu = t_cam + offset)",
                self.time_offset_s * 1e3,
                self.time_offset_sigma_s * 1e3
            ));
        }
        format!(
            "camera estimated online: {} (σ are the window's precision and optimistic: docs/vio.md)",
            parts.join("; ")
        )
    }
}

/// The prior of the online calibration: the given values and their σ.
#[derive(Debug, Clone)]
pub(crate) struct CameraPrior {
    body_from_camera: Isometry3F64,
    pose_sigma: [f64; 6],
    td_sigma: f64,
    extrinsics: bool,
    time_offset: bool,
}

impl CameraPrior {
    /// The prior for `input` under `opts`; None when nothing is estimated.
    pub fn new(input: &VioInput, opts: &VioOptions) -> Option<CameraPrior> {
        let c = &opts.camera;
        if !c.online() {
            return None;
        }
        let r = c.rotation_sigma_deg.to_radians();
        let t = c.translation_sigma_m;
        Some(CameraPrior {
            body_from_camera: input.body_from_camera,
            pose_sigma: [r, r, r, t, t, t],
            td_sigma: c.time_offset_sigma_s,
            extrinsics: c.extrinsics == Estimate::On,
            time_offset: c.time_offset == Estimate::On,
        })
    }

    /// Put the variables into `values` at `current` (`T_BC`, `td`) or, without
    /// one, at the given values, held constant (see [`CameraPrior::free`]).
    pub fn insert(&self, values: &mut Values, current: Option<(Isometry3F64, f64)>) {
        let (x, td) = current.unwrap_or((self.body_from_camera, 0.0));
        values.insert(EXTRINSIC, x);
        values.insert(TIME_OFFSET, Vector1::new(td));
        self.free(values, false);
    }

    /// Free the estimated parameters in `values` (`free`), or hold them at
    /// their values (the estimator decides when).
    pub fn free(&self, values: &mut Values, free: bool) {
        values.set_constant(EXTRINSIC, !(free && self.extrinsics));
        values.set_constant(TIME_OFFSET, !(free && self.time_offset));
    }

    /// Add the priors of the estimated parameters to `g`.
    pub fn add_factors(&self, g: &mut Graph) {
        if self.extrinsics {
            let n = NoiseModel::diagonal(&self.pose_sigma).expect("validated positive σ");
            g.add(PriorFactor::new(EXTRINSIC, self.body_from_camera), n);
        }
        if self.time_offset {
            let n = NoiseModel::isotropic(1, self.td_sigma).expect("validated positive σ");
            g.add(PriorFactor::new(TIME_OFFSET, Vector1::new(0.0)), n);
        }
    }

    /// Why the calibration in `values` cannot be right, or None: its distance
    /// from the given values, normalized by the prior's σ, beyond the 99.9 %
    /// quantile of χ² with as many degrees of freedom as are estimated (a
    /// wrong minimum of the window's solve, or a prior that does not hold).
    pub fn implausible(&self, values: &Values) -> Option<String> {
        let (x, td) = current(values)?;
        let (rot, t) = deviation(&self.body_from_camera, &x);
        let mut d2 = 0.0;
        let mut dof = 0;
        if self.extrinsics {
            d2 += (rot / self.pose_sigma[0]).norm_squared() + (t / self.pose_sigma[3]).norm_squared();
            dof += 6;
        }
        if self.time_offset {
            d2 += (td / self.td_sigma).powi(2);
            dof += 1;
        }
        // χ² quantiles at 0.999 for 1, 6 and 7 degrees of freedom.
        let limit = match dof {
            1 => 10.83,
            6 => 22.46,
            _ => 24.32,
        };
        (d2 > limit).then(|| {
            format!(
                "{:.1}° and {:.0} mm from the given T_BC, time offset {:.1} ms ({:.0} σ² of its prior, limit {limit})",
                rot.norm().to_degrees(),
                t.norm() * 1e3,
                td * 1e3,
                d2
            )
        })
    }

    /// The keys whose covariances the window's solve should recover: the
    /// parameters free in `values`.
    pub fn keys(&self, values: &Values) -> Vec<Key> {
        [EXTRINSIC, TIME_OFFSET].into_iter().filter(|&k| values.contains(k) && !values.is_constant(k)).collect()
    }

    /// The estimate in `values`, its σ from `covariances` when given.
    pub fn estimate(&self, values: &Values, covariances: Option<&Covariances>) -> CameraEstimate {
        let x = current(values).map_or(self.body_from_camera, |c| c.0);
        let (r, t) = parts(&x);
        let q = nalgebra::UnitQuaternion::from_matrix(&r);
        let std = |k: Key, i: usize, estimated: bool| {
            covariances.filter(|_| estimated).and_then(|c| c.sigma(k, i)).unwrap_or(f64::NAN)
        };
        let (change_rot, change_t) = deviation(&self.body_from_camera, &x);
        CameraEstimate {
            rotation: [q.w, q.i, q.j, q.k],
            translation: [t.x, t.y, t.z],
            time_offset_s: time_offset(values),
            rotation_sigma_deg: [0, 1, 2].map(|i| std(EXTRINSIC, i, self.extrinsics).to_degrees()),
            translation_sigma_m: [3, 4, 5].map(|i| std(EXTRINSIC, i, self.extrinsics)),
            time_offset_sigma_s: std(TIME_OFFSET, 0, self.time_offset),
            rotation_change_deg: change_rot.norm().to_degrees(),
            translation_change_m: change_t.norm(),
            extrinsics_estimated: self.extrinsics,
            time_offset_estimated: self.time_offset,
        }
    }
}

/// From `from` to `to` (two `T_BC`): the rotation vector `log(R_fromᵀ R_to)`
/// \[rad, camera frame\] and the translation difference \[m, body frame\].
fn deviation(from: &Isometry3F64, to: &Isometry3F64) -> (Vector3<f64>, Vector3<f64>) {
    let (r0, t0) = parts(from);
    let (r, t) = parts(to);
    (tumble_solvers::lie::so3_log(&(r0.transpose() * r)), t - t0)
}

/// The online calibration's current `T_BC` and `td` in `values`, when it is there.
pub(crate) fn current(values: &Values) -> Option<(Isometry3F64, f64)> {
    let x = values.get::<Isometry3F64>(EXTRINSIC).ok()?;
    Some((*x, time_offset(values)))
}

/// The camera's `T_BC` for the window: the online estimate in `values` when
/// there is one, else the input's.
pub(crate) fn body_from_camera(input: &VioInput, values: &Values) -> Isometry3F64 {
    current(values).map_or(input.body_from_camera, |c| c.0)
}

/// The time offset in `values` \[s\] (0 without online calibration).
fn time_offset(values: &Values) -> f64 {
    values.get::<Vector1<f64>>(TIME_OFFSET).map_or(0.0, |v| v[0])
}

/// The body's motion around the stamp `t` \[s\] from the IMU, for the time
/// offset: the gyro minus its bias (`bias` = `[b_a, b_g]`) fitted by a
/// quadratic in time by least squares over the samples within `half_width`
/// \[s\] of `t` (at least the two on each side), and the specific force at `t`
/// minus its bias. Too few samples give the rate at `t` alone.
pub(crate) fn exposure_motion(imu: &ImuData, t: f64, bias: &Vector6<f64>, half_width: f64) -> ExposureMotion {
    let (f, w) = imu.at(t);
    let (ba, bg) = (bias.fixed_rows::<3>(0).into_owned(), bias.fixed_rows::<3>(3).into_owned());
    let f = f - ba;
    let mut out = ExposureMotion { rate: [[0.0; 3]; 3], specific_force: [f.x, f.y, f.z] };
    let w0 = w - bg;
    out.rate[0] = [w0.x, w0.y, w0.z];
    let centre = imu.t.partition_point(|&s| s < t);
    let lo = imu.t.partition_point(|&s| s < t - half_width).min(centre.saturating_sub(2));
    let hi = imu.t.partition_point(|&s| s <= t + half_width).max((centre + 2).min(imu.t.len()));
    if hi < lo + 5 {
        return out;
    }
    // Normal equations of ω(s) = c₀ + c₁ s + c₂ s², s = t_k − t, per axis.
    let mut a = Matrix3::zeros();
    let mut b = Matrix3::zeros();
    for k in lo..hi {
        let s = imu.t[k] - t;
        let row = Vector3::new(1.0, s, s * s);
        a += row * row.transpose();
        b += row * (imu.gyro[k] - bg).transpose();
    }
    if let Some(c) = a.cholesky().map(|ch| ch.solve(&b)) {
        for (k, r) in out.rate.iter_mut().enumerate() {
            *r = [c[(k, 0)], c[(k, 1)], c[(k, 2)]];
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_fit_recovers_a_quadratic_rate_and_the_specific_force() {
        let rate = |s: f64| Vector3::new(1.0 + 2.0 * s + 30.0 * s * s, -0.5 + 40.0 * s, 0.2 - 10.0 * s * s);
        let t: Vec<f64> = (0..400).map(|k| k as f64 * 0.005).collect();
        let imu = ImuData {
            gyro: t.iter().map(|&s| rate(s - 1.0) + Vector3::new(0.01, 0.0, 0.0)).collect(),
            acc: t.iter().map(|_| Vector3::new(0.1, 0.2, 9.9)).collect(),
            t,
        };
        let bias = Vector6::new(0.1, 0.0, 0.0, 0.01, 0.0, 0.0);
        let m = exposure_motion(&imu, 1.0, &bias, 0.02);
        let want = [[1.0, -0.5, 0.2], [2.0, 40.0, 0.0], [30.0, 0.0, -10.0]];
        for (got, want) in m.rate.iter().zip(want) {
            for (g, w) in got.iter().zip(want) {
                assert!((g - w).abs() < 1e-6 * (1.0 + w.abs()), "{:?}", m.rate);
            }
        }
        assert!((Vector3::from(m.specific_force) - Vector3::new(0.0, 0.2, 9.9)).norm() < 1e-12);
    }

    #[test]
    fn an_estimate_far_outside_the_prior_is_implausible() {
        let input = VioInput::for_tests(ImuData::default(), Vec::new());
        let mut opts = VioOptions::default();
        opts.camera.extrinsics = Estimate::On;
        opts.camera.time_offset = Estimate::On;
        let prior = CameraPrior::new(&input, &opts).unwrap();
        let mut values = Values::new();
        prior.insert(&mut values, None);
        assert!(prior.implausible(&values).is_none());
        // 10° (2 σ) and 5 ms: within the prior.
        let turned = |deg: f64| {
            pose(nalgebra::Rotation3::from_euler_angles(deg.to_radians(), 0.0, 0.0).matrix(), &Vector3::zeros())
        };
        prior.insert(&mut values, Some((input.body_from_camera * turned(10.0), 0.005)));
        assert!(prior.implausible(&values).is_none());
        // 50° (10 σ): a wrong minimum.
        prior.insert(&mut values, Some((input.body_from_camera * turned(50.0), 0.0)));
        let why = prior.implausible(&values).expect("implausible");
        assert!(why.contains("50.0°"), "{why}");
    }
}
