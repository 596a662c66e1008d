//! Where the gyro says a feature goes between two frames: the camera's
//! rotation over the IMU samples between their stamps. A point far away
//! moves in the image by the rotation alone; KLT then only has to find
//! what the translation adds.

use crate::io::imu::{ImuRecording, Stored};
use crate::model::geometry::preintegrate;
use nalgebra::{Rotation3, Vector3};
use tumble_factors::imu_preint::{PreintegrationParams, Scheme};

/// The camera's rotation between consecutive frames from the gyro: entry `k`
/// (k ≥ 1) is `R_{c_k ← c_{k−1}}`, which takes a bearing in frame `k − 1`'s
/// camera frame to frame `k`'s. Entry 0 is None, as is any pair of frames the
/// samples do not cover, and every entry when the gyro is in raw counts.
///
/// `camera_from_imu` turns the IMU's axes into the camera's (`R_cb · R_bs`);
/// `frame_times_ns` are the frames' stamps in the IMU's clock \[ns\]. The
/// gyro is integrated as the estimators preintegrate it
/// ([`preintegrate`], midpoint rule, the samples interpolated at both
/// stamps). The gyro's bias is not removed: over EuRoC's 50 ms
/// between frames, 0.01 rad/s of bias turns the prediction by 0.5 mrad, a
/// quarter of a pixel at a focal length of 460 px — well inside KLT's reach.
pub fn gyro_rotations(
    imu: &ImuRecording,
    camera_from_imu: &Rotation3<f64>,
    frame_times_ns: &[i64],
) -> Vec<Option<Rotation3<f64>>> {
    let mut out = vec![None; frame_times_ns.len()];
    let (Some(&first), Some(&last)) = (imu.t.first(), imu.t.last()) else { return out };
    if imu.gyro_units != Stored::Si || imu.t.len() < 2 || imu.gyro.len() != imu.t.len() {
        return out;
    }
    let samples = imu.calibrated(None);
    let params = PreintegrationParams { scheme: Scheme::Midpoint, ..Default::default() };
    let seconds = |ns: i64| (ns - imu.t0_ns) as f64 * 1e-9;
    for (k, pair) in frame_times_ns.windows(2).enumerate() {
        let (ta, tb) = (seconds(pair[0]), seconds(pair[1]));
        if !(ta >= first && tb >= ta && tb <= last) {
            continue;
        }
        let (pim, _) = preintegrate(&samples, ta, tb, (Vector3::zeros(), Vector3::zeros()), params);
        // R_{i_a ← i_b}, the IMU's orientation at `tb` in its axes at `ta`.
        let r_a_b = Rotation3::from_matrix(&pim.delta_rotation());
        out[k + 1] = Some(camera_from_imu * r_a_b.inverse() * camera_from_imu.inverse());
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn spinning(rate: [f64; 3], hz: f64, seconds: f64) -> ImuRecording {
        let n = (seconds * hz) as usize + 1;
        ImuRecording {
            t0_ns: 1_000_000_000,
            t: (0..n).map(|i| i as f64 / hz).collect(),
            gyro: vec![rate; n],
            accel: vec![[0.0, 0.0, 9.81]; n],
            ..Default::default()
        }
    }

    /// A constant rate ω (IMU axes) turns camera frame `a` into `b` by
    /// `Exp(−C ω Δt)` in the camera's axes; frames outside the samples, the
    /// first frame and raw counts give none.
    #[test]
    fn a_constant_rate_turns_the_camera_by_its_integral() {
        let w = [0.3, -1.2, 2.5];
        let imu = spinning(w, 200.0, 1.0);
        let c = Rotation3::from_euler_angles(0.4, -1.1, 2.0);
        let stamps = [1_000_000_000 + 12_345_678, 1_000_000_000 + 62_345_678, 1_000_000_000 + 2_000_000_000];
        let r = gyro_rotations(&imu, &c, &stamps);
        assert!(r[0].is_none() && r[2].is_none(), "{r:?}");
        let expect = Rotation3::new(-(c * Vector3::from(w)) * 0.05);
        let got = r[1].expect("covered");
        // `so3_log` is accurate to rounding near the identity, where the
        // arccos of `angle_to` resolves no better than 3e-8 rad.
        let angle = tumble_solvers::lie::so3_log((got.inverse() * expect).matrix()).norm();
        assert!(angle < 1e-12, "{angle:e}: {got:?} vs {expect:?}");
        let raw = ImuRecording { gyro_units: Stored::RawCounts, ..imu };
        assert!(gyro_rotations(&raw, &c, &stamps).iter().all(Option::is_none));
    }

    /// A rate that changes between samples is integrated piece by piece:
    /// a ramp about one axis gives the ramp's integral (the camera turns the
    /// other way, seen from its own axes).
    #[test]
    fn a_changing_rate_is_integrated_between_samples() {
        let mut imu = spinning([0.0; 3], 100.0, 1.0);
        imu.gyro = imu.t.iter().map(|&t| [0.0, 0.0, 4.0 * t]).collect();
        let stamps = [1_105_000_000, 1_400_000_000];
        let r = gyro_rotations(&imu, &Rotation3::identity(), &stamps)[1].expect("covered");
        let angle = 2.0 * (0.4f64.powi(2) - 0.105f64.powi(2));
        assert!((-r.scaled_axis().z - angle).abs() < 1e-12, "{} vs {angle}", -r.scaled_axis().z);
    }
}
