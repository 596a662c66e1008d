//! The settings of a calibration ([`CalibOptions`]) and the recording the
//! paper asks for.

use crate::OptionError;

/// Settings of [`calibrate`](crate::calib::calibrate).
#[derive(Debug, Clone, PartialEq)]
pub struct CalibOptions {
    /// Local gravity magnitude \[m/s²\] (see [`super::normal_gravity`]).
    pub gravity: f64,
    /// Length of the initial static period \[s\] (its variance sets the threshold; its mean the gyro bias);
    /// `None`: found from the data (`find_initial_rest`: the longest early rest of at least
    /// `MIN_INITIAL_REST_S`).
    pub init_static_s: Option<f64>,
    /// Window of the sliding accelerometer variance \[s\] (imu_tk: 101 samples).
    pub window_s: f64,
    /// Shortest usable static interval \[s\] (imu_tk: 100 samples).
    pub min_interval_s: f64,
    /// Threshold multipliers `k` to sweep (imu_tk: 2, 3, …, 10).
    pub multipliers: Vec<f64>,
    /// Estimate the gyro bias with the other gyro parameters instead of taking
    /// the mean of the initial static period.
    pub estimate_gyro_bias: bool,
    /// Fewest static intervals accepted (imu_tk: 12).
    pub min_intervals: usize,
    /// Require the gyro to be as still as the accelerometer (windowed variance
    /// below `k` × its initial variance too, and the window's mean rate near the
    /// rest's). imu_tk uses the accelerometer only, which counts the slow start
    /// and end of a turn as static.
    pub detect_with_gyro: bool,
}

impl Default for CalibOptions {
    fn default() -> Self {
        CalibOptions {
            gravity: crate::io::STANDARD_GRAVITY,
            init_static_s: None,
            window_s: 0.5,
            min_interval_s: 0.5,
            multipliers: (2..=10).map(f64::from).collect(),
            estimate_gyro_bias: false,
            min_intervals: 12,
            detect_with_gyro: true,
        }
    }
}

impl CalibOptions {
    /// Check every option once, before any work (every [`calibrate`](crate::calib::calibrate) calls it):
    /// gravity, periods and windows positive, multipliers positive, at least
    /// one interval asked for.
    pub fn validate(&self) -> Result<(), OptionError> {
        OptionError::earth_gravity(self.gravity, "every scale is calibrated against it")?;
        if let Some(t) = self.init_static_s {
            OptionError::positive("--init-static", t, "seconds")?;
        }
        OptionError::positive("--window", self.window_s, "seconds")?;
        OptionError::positive("--min-interval", self.min_interval_s, "seconds")?;
        if self.multipliers.is_empty() || self.multipliers.iter().any(|k| !(k.is_finite() && *k > 0.0)) {
            return Err(OptionError::new(
                "--multipliers",
                format!("must be positive numbers, got {:?}", self.multipliers),
            ));
        }
        if self.min_intervals < MIN_STATIC_INTERVALS {
            return Err(OptionError::new(
                "--min-intervals",
                format!(
                    "must be at least {MIN_STATIC_INTERVALS} (the accelerometer model has 9 parameters, one gravity-norm \
                     residual per interval), got {}",
                    self.min_intervals
                ),
            ));
        }
        Ok(())
    }
}

/// `FIRST:LAST` (integer steps) or a comma-separated list of positive
/// threshold multipliers (`tumble calibrate --multipliers`).
pub fn parse_multipliers(s: &str) -> Result<Vec<f64>, OptionError> {
    let bad = || {
        OptionError::new("--multipliers", format!("takes FIRST:LAST or a comma list of positive numbers, got `{s}`"))
    };
    let v: Vec<f64> = if let Some((a, b)) = s.split_once(':') {
        let (a, b): (u32, u32) = (a.trim().parse().map_err(|_| bad())?, b.trim().parse().map_err(|_| bad())?);
        (a..=b).map(f64::from).collect()
    } else {
        s.split(',').map(|x| x.trim().parse::<f64>().map_err(|_| bad())).collect::<Result<_, _>>()?
    };
    if v.is_empty() || v.iter().any(|x| !(x.is_finite() && *x > 0.0)) {
        return Err(bad());
    }
    Ok(v)
}

/// Shortest initial rest [`find_initial_rest`] accepts \[s\]: a second of samples
/// gives the noise level to a few per cent and the gyro bias to σ/√rate.
pub const MIN_INITIAL_REST_S: f64 = 1.0;

/// The shortest hold the paper asks for \[s\]; shorter holds (down to
/// [`CalibOptions::min_interval_s`]) are used with a warning.
pub const PAPER_MIN_HOLD_S: f64 = 1.0;

/// The initial static period the paper asks for \[s\]; shorter rests are used
/// with a warning.
pub const PAPER_INITIAL_REST_S: f64 = 10.0;

/// Fewest static intervals [`CalibOptions::min_intervals`] may ask for: one
/// more than the accelerometer model's 9 parameters, so that its fit has a
/// residual to judge it by.
pub const MIN_STATIC_INTERVALS: usize = 10;

/// How to record a usable tumble session (printed with errors).
pub const RECORDING_ADVICE: &str = "record ≥ 50 s perfectly still first, then ≥ 20 (better 50) different \
orientations, each held still for 1–4 s (rest the IMU against something), turning by hand between them so \
that every axis points up and down at least once";
