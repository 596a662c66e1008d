//! IMU samples as the estimators consume them: calibrated, in SI units, in
//! the body (IMU) frame, on one time axis.

use nalgebra::Vector3;

/// Calibrated IMU samples in the body (IMU) frame.
#[derive(Debug, Clone, Default)]
pub struct ImuData {
    /// Sample times \[s\] (input time axis, strictly increasing).
    pub t: Vec<f64>,
    /// Angular rate \[rad/s\].
    pub gyro: Vec<Vector3<f64>>,
    /// Specific force \[m/s²\].
    pub acc: Vec<Vector3<f64>>,
}

impl ImuData {
    /// Specific force and rate at `t` \[s\], interpolated linearly between the
    /// samples around it (held at the ends); at least two samples.
    pub fn at(&self, t: f64) -> (Vector3<f64>, Vector3<f64>) {
        let n = self.t.len();
        let j = self.t.partition_point(|&s| s <= t).clamp(1, n.max(2) - 1);
        let (t0, t1) = (self.t[j - 1], self.t[j]);
        let w = if t1 > t0 { ((t - t0) / (t1 - t0)).clamp(0.0, 1.0) } else { 0.0 };
        (self.acc[j - 1] * (1.0 - w) + self.acc[j] * w, self.gyro[j - 1] * (1.0 - w) + self.gyro[j] * w)
    }
}
