//! `tumble noise`: datasheet noise figures as Kalibr's imu.yaml.

use super::CliResult;
use clap::Args;
use std::path::PathBuf;
use tumble::model::datasheet::{datasheet_yaml, Datasheet};

/// Flags of `tumble noise` (each figure is a number with its unit, e.g. "0.15 deg/sqrt(h)").
#[derive(Args)]
pub struct NoiseArgs {
    /// Gyro noise: angle random walk (deg/sqrt(h)) or density (deg/s/sqrt(Hz), mdps/sqrt(Hz), rad/s/sqrt(Hz)).
    #[arg(long)]
    gyro_noise: String,
    /// Accelerometer noise: velocity random walk (m/s/sqrt(h)) or density (ug/sqrt(Hz), mg/sqrt(Hz), m/s^2/sqrt(Hz)).
    #[arg(long)]
    accel_noise: String,
    /// Gyro rate random walk (deg/h/sqrt(h), rad/s^2/sqrt(Hz)).
    #[arg(long)]
    gyro_walk: Option<String>,
    /// Accelerometer random walk (m/s/h^1.5, m/s^3/sqrt(Hz)).
    #[arg(long)]
    accel_walk: Option<String>,
    /// Gyro bias instability (deg/h, deg/s): stands in for a missing random walk.
    #[arg(long)]
    gyro_instability: Option<String>,
    /// Accelerometer bias instability (ug, mg, m/s^2): stands in for a missing random walk.
    #[arg(long)]
    accel_instability: Option<String>,
    /// IMU update rate [Hz].
    #[arg(long)]
    rate: f64,
    /// The IMU's ROS topic.
    #[arg(long, default_value = "/imu0")]
    rostopic: String,
    /// Output imu.yaml (refuses to overwrite an existing file).
    #[arg(long)]
    out: PathBuf,
}

impl NoiseArgs {
    pub fn run(self) -> CliResult {
        tumble::OptionError::positive("--rate", self.rate, "Hz")?;
        let ds = Datasheet {
            gyro_noise: Some(self.gyro_noise),
            accel_noise: Some(self.accel_noise),
            gyro_walk: self.gyro_walk,
            accel_walk: self.accel_walk,
            gyro_instability: self.gyro_instability,
            accel_instability: self.accel_instability,
        };
        let (noise, lines) = ds.to_noise()?;
        for l in &lines {
            println!("{l}");
        }
        if self.out.exists() {
            return Err(format!("{}: exists; give a new file name", self.out.display()).into());
        }
        std::fs::write(&self.out, datasheet_yaml(&noise, self.rate, &self.rostopic, &lines))
            .map_err(|e| format!("{}: {e}", self.out.display()))?;
        println!("wrote {}", self.out.display());
        Ok(())
    }
}
