//! `tumble export`: tumble's results as another estimator's configuration.

use super::common::paths;
use super::CliResult;
use clap::Args;
use std::path::PathBuf;
use tumble::export::{export, ExportInputs, ExportSources, Target};

/// Flags of `tumble export`.
#[derive(Args)]
pub struct ExportArgs {
    /// Results folder: of `tumble run` (calibrate/, allan/, audit/) or of one command (calibration.json, imu.yaml).
    results: Option<PathBuf>,
    /// The estimator: kalibr, vins-mono, vins-fusion, openvins, orbslam3 or basalt.
    #[arg(long = "for", value_parser = |s: &str| s.parse::<Target>())]
    target: Target,
    /// Output folder for the estimator's files.
    #[arg(long)]
    out: PathBuf,
    /// calibration.json to use (default: the results folder's; the audit's, with its effects, first).
    #[arg(long)]
    calibration: Option<PathBuf>,
    /// Kalibr imu.yaml to use (default: the results folder's allan/imu.yaml or imu.yaml).
    #[arg(long)]
    noise: Option<PathBuf>,
    /// audit.json of the same recording, for noise inflation measured in motion (default: the results folder's).
    #[arg(long)]
    audit: Option<PathBuf>,
    /// ASL folder whose mav0/camN/sensor.yaml (intrinsics, T_BS) and imu0/sensor.yaml give the cameras.
    #[arg(long)]
    asl: Option<PathBuf>,
}

impl ExportArgs {
    pub fn run(self) -> CliResult {
        let inputs = ExportInputs::gather(&ExportSources {
            results: self.results,
            calibration: self.calibration,
            noise: self.noise,
            audit: self.audit,
            asl: self.asl,
        })?;
        let report = export(self.target, &inputs, &self.out)?;
        for s in &inputs.sources {
            println!("from {s}");
        }
        for r in &inputs.inflation.reasons {
            println!("inflation: {r}");
        }
        for n in &report.notes {
            println!("note: {n}");
        }
        println!("wrote {}", paths(&report.files));
        Ok(())
    }
}
