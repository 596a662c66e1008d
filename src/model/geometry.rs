//! Small geometric helpers every estimator shares: poses and their
//! conversions, gravity alignment, IMU preintegration over a time interval,
//! multi-view triangulation.

use super::ImuData;
use nalgebra::{Matrix3, UnitQuaternion, Vector3};
use tumble_factors::imu_preint::{Preintegrated, PreintegrationParams, Scheme};
use tumble_solvers::lie::so3_exp;
use tumble_solvers::sophus_lie::prelude::*;
use tumble_solvers::sophus_lie::{Isometry3F64, Rotation3F64};

/// SE(3) body-in-world pose from a rotation matrix and a position.
pub fn pose(r: &Matrix3<f64>, p: &Vector3<f64>) -> Isometry3F64 {
    let q = UnitQuaternion::from_rotation_matrix(&nalgebra::Rotation3::from_matrix_unchecked(*r));
    Isometry3F64::from_rotation_and_translation(Rotation3F64::exp(q.scaled_axis()), *p)
}

/// Rotation matrix and position of a pose.
pub fn parts(x: &Isometry3F64) -> (Matrix3<f64>, Vector3<f64>) {
    (x.rotation().matrix(), x.translation())
}

/// The smallest rotation `R` (world ← body) with `R f̂ = e_z`, for the mean
/// specific force `f` of a body at rest (world z up, gravity `[0, 0, −g]`).
pub fn gravity_aligned(f: &Vector3<f64>) -> Matrix3<f64> {
    let a = f.normalize();
    let z = Vector3::z();
    let axis = a.cross(&z);
    let s = axis.norm();
    let c = a.dot(&z);
    if s < 1e-12 {
        return if c > 0.0 { Matrix3::identity() } else { so3_exp(&Vector3::new(std::f64::consts::PI, 0.0, 0.0)) };
    }
    so3_exp(&(axis / s * s.atan2(c)))
}

/// nalgebra's isometry as the solver's SE(3).
pub fn from_nalgebra(t: &nalgebra::Isometry3<f64>) -> Isometry3F64 {
    pose(t.rotation.to_rotation_matrix().matrix(), &t.translation.vector)
}

/// The solver's SE(3) as nalgebra's (the inverse of [`from_nalgebra`]).
pub fn to_nalgebra(x: &Isometry3F64) -> nalgebra::Isometry3<f64> {
    let (r, t) = parts(x);
    nalgebra::Isometry3::from_parts(
        nalgebra::Translation3::from(t),
        nalgebra::UnitQuaternion::from_rotation_matrix(&nalgebra::Rotation3::from_matrix_unchecked(r)),
    )
}

/// Preintegrate the IMU over `[ta, tb]` \[s\] at bias `(b_a, b_g)`. Zero-order
/// hold integrates each sample over its share of the interval; the midpoint
/// rule interpolates samples at both ends. Also returns the longest spacing of
/// the samples used \[s\] (to detect gaps).
pub fn preintegrate(
    imu: &ImuData,
    ta: f64,
    tb: f64,
    bias: (Vector3<f64>, Vector3<f64>),
    params: PreintegrationParams,
) -> (Preintegrated, f64) {
    let mut pim = Preintegrated::new(params, bias.0, bias.1);
    let n = imu.t.len();
    // First sample whose hold interval ends after ta.
    let mut k = imu.t.partition_point(|&t| t <= ta).saturating_sub(1);
    let mut max_gap: f64 = 0.0;
    match params.scheme {
        Scheme::ZeroOrderHold => {
            while k < n && imu.t[k] < tb {
                let end = if k + 1 < n { imu.t[k + 1].min(tb) } else { tb };
                let dt = end - imu.t[k].max(ta);
                if k + 1 < n {
                    max_gap = max_gap.max(imu.t[k + 1] - imu.t[k]);
                }
                if dt > 0.0 {
                    pim.integrate(imu.acc[k], imu.gyro[k], dt);
                }
                k += 1;
            }
        }
        Scheme::Midpoint => {
            let (a0, g0) = imu.at(ta);
            pim.integrate(a0, g0, 0.0);
            let mut last = ta;
            k = imu.t.partition_point(|&t| t <= ta);
            while k < n && imu.t[k] < tb {
                max_gap = max_gap.max(imu.t[k] - last);
                pim.integrate(imu.acc[k], imu.gyro[k], imu.t[k] - last);
                last = imu.t[k];
                k += 1;
            }
            let (a1, g1) = imu.at(tb);
            max_gap = max_gap.max(tb - last);
            pim.integrate(a1, g1, tb - last);
        }
    }
    (pim, max_gap)
}

/// Triangulate a point from camera centres `c` and unit world-frame rays `d`
/// (least-squares closest point to all rays). Returns the point and the
/// largest angle between two rays \[rad\]; None when the rays are (nearly) parallel.
pub fn triangulate(c: &[Vector3<f64>], d: &[Vector3<f64>]) -> Option<(Vector3<f64>, f64)> {
    let mut a = Matrix3::zeros();
    let mut b = Vector3::zeros();
    for (ci, di) in c.iter().zip(d) {
        let p = Matrix3::identity() - di * di.transpose();
        a += p;
        b += p * ci;
    }
    let mut angle: f64 = 0.0;
    for i in 0..d.len() {
        for j in i + 1..d.len() {
            angle = angle.max(d[i].dot(&d[j]).clamp(-1.0, 1.0).acos());
        }
    }
    let eig = nalgebra::SymmetricEigen::new(a);
    if eig.eigenvalues.min() < 1e-9 * eig.eigenvalues.max().max(1e-300) {
        return None;
    }
    Some((a.try_inverse()? * b, angle))
}
