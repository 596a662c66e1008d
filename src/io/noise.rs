//! IMU noise in Kalibr's `imu.yaml` form: what `tumble allan` writes and the
//! audit and the VIO read.

use serde::{Deserialize, Serialize};
use tumble_factors::imu_preint::PreintegrationParams;

/// Kalibr `imu.yaml` noise parameters (continuous time, SI).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ImuNoise {
    /// Accelerometer white noise \[m/s²/√Hz\].
    pub accelerometer_noise_density: f64,
    /// Accelerometer bias random walk \[m/s³/√Hz\].
    pub accelerometer_random_walk: f64,
    /// Gyroscope white noise \[rad/s/√Hz\].
    pub gyroscope_noise_density: f64,
    /// Gyroscope bias random walk \[rad/s²/√Hz\].
    pub gyroscope_random_walk: f64,
}

impl ImuNoise {
    /// The continuous-time noise of a simulator model (largest axis of each triad):
    /// what `tumble allan` would identify on its static log.
    pub fn from_model(m: &crate::sim::ImuModel) -> ImuNoise {
        let max = |v: [f64; 3]| v.iter().fold(0.0f64, |a, b| a.max(b.abs()));
        ImuNoise {
            accelerometer_noise_density: max(m.accel.noise_density),
            accelerometer_random_walk: max(m.accel.random_walk).max(1e-6),
            gyroscope_noise_density: max(m.gyro.noise_density),
            gyroscope_random_walk: max(m.gyro.random_walk).max(1e-7),
        }
    }
    /// Read Kalibr's `imu.yaml` (as written by `tumble allan`); unknown keys are ignored.
    pub fn read(path: &std::path::Path) -> Result<ImuNoise, crate::InputError> {
        let n: ImuNoise = crate::io::yaml::read_yaml(path)?;
        for (v, what) in [
            (n.accelerometer_noise_density, "accelerometer_noise_density"),
            (n.accelerometer_random_walk, "accelerometer_random_walk"),
            (n.gyroscope_noise_density, "gyroscope_noise_density"),
            (n.gyroscope_random_walk, "gyroscope_random_walk"),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(crate::InputError::file(path, format!("{what} must be a positive number, found {v}")));
            }
        }
        Ok(n)
    }
    /// Apply to preintegration settings.
    pub fn apply(&self, p: &mut PreintegrationParams) {
        p.accel_noise_density = self.accelerometer_noise_density;
        p.accel_random_walk = self.accelerometer_random_walk;
        p.gyro_noise_density = self.gyroscope_noise_density;
        p.gyro_random_walk = self.gyroscope_random_walk;
    }
}
