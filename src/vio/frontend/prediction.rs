//! Where the gyro says a feature goes between two frames: the camera's
//! rotation over the IMU samples between their stamps. A point far away
//! moves in the image by the rotation alone; KLT then only has to find
//! what the translation adds.

use crate::io::imu::{ImuRecording, Stored};
use nalgebra::{Rotation3, Vector3};

/// The camera's rotation between consecutive frames from the gyro: entry `k`
/// (k ≥ 1) is `R_{c_k ← c_{k−1}}`, which takes a bearing in frame `k − 1`'s
/// camera frame to frame `k`'s. Entry 0 is None, as is any pair of frames the
/// samples do not cover, and every entry when the gyro is in raw counts.
///
/// `camera_from_imu` turns the IMU's axes into the camera's (`R_cb · R_bs`);
/// `frame_times_ns` are the frames' stamps in the IMU's clock \[ns\]. The
/// rate is interpolated linearly between samples and integrated at each
/// piece's midpoint. The gyro's bias is not removed: over EuRoC's 50 ms
/// between frames, 0.01 rad/s of bias turns the prediction by 0.5 mrad, a
/// quarter of a pixel at a focal length of 460 px — well inside KLT's reach.
pub fn gyro_rotations(
    imu: &ImuRecording,
    camera_from_imu: &Rotation3<f64>,
    frame_times_ns: &[i64],
) -> Vec<Option<Rotation3<f64>>> {
    let mut out = vec![None; frame_times_ns.len()];
    if imu.gyro_units != Stored::Si || imu.t.len() < 2 || imu.gyro.len() != imu.t.len() {
        return out;
    }
    let seconds = |ns: i64| (ns - imu.t0_ns) as f64 * 1e-9;
    for (k, pair) in frame_times_ns.windows(2).enumerate() {
        out[k + 1] = imu_rotation(imu, seconds(pair[0]), seconds(pair[1]))
            .map(|r_a_b| camera_from_imu * r_a_b.inverse() * camera_from_imu.inverse());
    }
    out
}

/// `R_{i_a ← i_b}`: the IMU's orientation at `tb` in its axes at `ta`
/// (times \[s\] from the recording's first sample); None outside the samples.
fn imu_rotation(imu: &ImuRecording, ta: f64, tb: f64) -> Option<Rotation3<f64>> {
    let t = &imu.t;
    if !(ta >= t[0] && tb >= ta && tb <= t[t.len() - 1]) {
        return None;
    }
    let rate = |s: f64| -> Vector3<f64> {
        let i = t.partition_point(|&x| x <= s).clamp(1, t.len() - 1);
        let w = ((s - t[i - 1]) / (t[i] - t[i - 1])).clamp(0.0, 1.0);
        let (a, b) = (imu.gyro[i - 1], imu.gyro[i]);
        Vector3::new(a[0] + w * (b[0] - a[0]), a[1] + w * (b[1] - a[1]), a[2] + w * (b[2] - a[2]))
    };
    let inner = &t[t.partition_point(|&x| x <= ta)..t.partition_point(|&x| x < tb)];
    let knots = std::iter::once(ta).chain(inner.iter().copied()).chain(std::iter::once(tb));
    let mut r = Rotation3::identity();
    let mut prev = ta;
    for s in knots.skip(1) {
        r *= Rotation3::new(rate(0.5 * (prev + s)) * (s - prev));
        prev = s;
    }
    Some(r)
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
        assert!(got.angle_to(&expect) < 1e-12, "{got:?} vs {expect:?}");
        let raw = ImuRecording { gyro_units: Stored::RawCounts, ..imu };
        assert!(gyro_rotations(&raw, &c, &stamps).iter().all(Option::is_none));
    }

    /// A rate that changes between samples is integrated piece by piece:
    /// a ramp about one axis gives the ramp's integral.
    #[test]
    fn a_changing_rate_is_integrated_between_samples() {
        let mut imu = spinning([0.0; 3], 100.0, 1.0);
        imu.gyro = imu.t.iter().map(|&t| [0.0, 0.0, 4.0 * t]).collect();
        let r = imu_rotation(&imu, 0.105, 0.4).expect("covered");
        let angle = 2.0 * (0.4f64.powi(2) - 0.105f64.powi(2));
        assert!((r.scaled_axis().z - angle).abs() < 1e-12, "{} vs {angle}", r.scaled_axis().z);
    }
}
