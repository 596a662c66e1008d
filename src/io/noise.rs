//! Reading Kalibr's `imu.yaml` noise files (the type is [`crate::model::noise::ImuNoise`]).

pub use crate::model::noise::{estimator_random_walk, ImuNoise, ImuNoiseAxes, BIAS_INSTABILITY_MATCH_S};

impl ImuNoise {
    /// Read Kalibr's `imu.yaml` (as written by `tumble allan`); unknown keys are ignored.
    pub fn read(path: &std::path::Path) -> Result<ImuNoise, crate::InputError> {
        let n: ImuNoise = super::yaml::read_yaml(path)?;
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
        if let Some(a) = &n.axes {
            a.check().map_err(|m| crate::InputError::file(path, m))?;
        }
        Ok(n)
    }
}
