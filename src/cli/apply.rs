//! `tumble apply`: correct a recording with a calibration.

use super::common::{paths, CalibInput};
use super::CliResult;
use clap::Args;
use std::path::PathBuf;
use tumble::calib::ImuCalibration;

/// Flags of `tumble apply`.
#[derive(Args)]
pub struct ApplyArgs {
    #[command(flatten)]
    input: CalibInput,
    /// calibration.json or .yaml from `tumble calibrate`.
    #[arg(long)]
    calibration: PathBuf,
    /// Output folder.
    #[arg(long)]
    out: PathBuf,
}

impl ApplyArgs {
    pub fn run(self) -> CliResult {
        let cal = ImuCalibration::read(&self.calibration)?;
        let source = self.input.source()?;
        let rec = source.open()?;
        let applied = tumble::calib::apply_calibration(rec, &cal, &self.calibration)?;
        for w in &applied.warnings {
            eprintln!("warning: {w}");
        }
        for n in &applied.notes {
            println!("{n}");
        }
        let written = tumble::calib::write_like_input(&applied.recording, &source.path, &source.options, &self.out)?;
        println!(
            "corrected {} samples (eq. 16{}) into {}",
            applied.recording.len(),
            if applied.effects.is_empty() { String::new() } else { format!(" + {}", applied.effects.join(", ")) },
            paths(&written)
        );
        Ok(())
    }
}
