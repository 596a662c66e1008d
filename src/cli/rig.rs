//! `tumble calibrate-rig`: cameras and camera–IMU extrinsics and time offset on a target.

use super::common::paths;
use super::CliResult;
use clap::Args;
use std::path::PathBuf;
use tumble::factors::camera::DistortionKind;
use tumble::rig::{calibrate_rig, summary_markdown, write_rig, RigInput, RigOptions};

/// Flags of `tumble calibrate-rig`.
#[derive(Args)]
pub struct RigArgs {
    /// ASL folder (mav0/ or its parent) with imu0/data.csv and, per camera, camN/corners.csv
    /// or the images (camN/data.csv; the target is detected with the `opencv` feature).
    input: PathBuf,
    /// The target, in Kalibr's keys (aprilgrid or checkerboard).
    #[arg(long)]
    target: PathBuf,
    /// Output folder: camchain-imucam.yaml, camN/sensor.yaml, rig.json, report.md.
    #[arg(long)]
    out: PathBuf,
    /// Kalibr imu.yaml with the IMU's noise (default: imu0/sensor.yaml's figures).
    #[arg(long)]
    noise: Option<PathBuf>,
    /// calibration.json of `tumble calibrate`: the IMU samples are corrected by it first.
    #[arg(long)]
    calibration: Option<PathBuf>,
    /// Distortion model to estimate: radtan or equidistant.
    #[arg(long, default_value = "radtan", value_parser = parse_distortion)]
    distortion: DistortionKind,
    /// Estimate the camera–IMU time offset (on) or hold it at 0 (off).
    #[arg(long, default_value = "on", value_parser = ["on", "off"])]
    time_offset: String,
    /// Largest time offset the coarse search considers [s].
    #[arg(long, default_value_t = 0.1)]
    max_time_offset: f64,
    /// Image size WIDTHxHEIGHT [px], when camN/sensor.yaml does not give it.
    #[arg(long, value_parser = parse_resolution)]
    resolution: Option<[u32; 2]>,
    /// Hold each camera's intrinsics at those of DIR/camN/sensor.yaml (an ASL
    /// folder or the output of an earlier calibration), as Kalibr's camera–IMU
    /// step does with its camchain; default: estimate them.
    #[arg(long)]
    intrinsics: Option<PathBuf>,
    /// Local gravity [m/s²].
    #[arg(long, default_value_t = 9.81)]
    gravity: f64,
}

fn parse_distortion(s: &str) -> Result<DistortionKind, String> {
    match s {
        "radtan" | "radial-tangential" => Ok(DistortionKind::RadTan),
        "equidistant" | "fisheye" => Ok(DistortionKind::Equidistant),
        _ => Err(format!("'{s}': radtan or equidistant")),
    }
}

fn parse_resolution(s: &str) -> Result<[u32; 2], String> {
    let (w, h) = s.split_once(['x', 'X']).ok_or_else(|| format!("'{s}': expected WIDTHxHEIGHT, e.g. 752x480"))?;
    let p = |v: &str| v.trim().parse::<u32>().map_err(|_| format!("'{s}': expected WIDTHxHEIGHT, e.g. 752x480"));
    Ok([p(w)?, p(h)?])
}

impl RigArgs {
    pub fn run(self) -> CliResult {
        let fixed_intrinsics = match &self.intrinsics {
            Some(dir) => tumble::io::target::read_intrinsics(dir)?,
            None => Vec::new(),
        };
        let options = RigOptions {
            fixed_intrinsics,
            distortion: self.distortion,
            estimate_time_offset: self.time_offset == "on",
            max_time_offset_s: self.max_time_offset,
            gravity: self.gravity,
            resolution: self.resolution,
            ..RigOptions::default()
        };
        options.validate()?;
        let input = RigInput::from_asl_with_progress(
            &self.input,
            &self.target,
            self.noise.as_deref(),
            self.calibration.as_deref(),
            &options,
            &mut |msg| eprintln!("{msg}"),
        )?;
        let rig = calibrate_rig(&input, &options, &mut |msg| eprintln!("{msg}"))?;
        println!("{}", summary_markdown(&rig));
        let files = write_rig(&rig, &input, &self.out)?;
        println!("wrote {}", paths(&files));
        Ok(())
    }
}
