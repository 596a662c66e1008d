//! `tumble demo`: the whole chain on simulated recordings with known truth.

use super::CliResult;
use clap::{Args, ValueEnum};
use std::path::PathBuf;

/// `tumble demo --walk`.
#[derive(Clone, Copy, ValueEnum)]
enum DemoWalkArg {
    /// Hand motion in a room, within about a metre (38.5 m in 6 minutes).
    Room,
    /// Laps of a 28 m × 14 m elliptical corridor at about 1 m/s (347 m in 6 minutes).
    Corridor,
}

/// Flags of `tumble demo`.
#[derive(Args)]
pub struct DemoArgs {
    /// Folder for the chain's files and report.md.
    #[arg(long, default_value = "tumble-demo")]
    out: PathBuf,
    /// The 6-minute walk: laps of a corridor at walking speed, or hand motion in a room.
    #[arg(long, value_enum, default_value = "corridor")]
    walk: DemoWalkArg,
    /// Seed of every simulation.
    #[arg(long, default_value_t = 1)]
    seed: u64,
}

impl DemoArgs {
    pub fn run(self) -> CliResult {
        println!("tumble demo: the whole chain on simulated recordings with known truth (BMI055-like IMU)");
        let opts = tumble::demo::DemoOptions {
            walk: match self.walk {
                DemoWalkArg::Room => tumble::sim::Scenario::Walk,
                DemoWalkArg::Corridor => tumble::sim::Scenario::Corridor,
            },
            seed: self.seed,
            ..Default::default()
        };
        let report = tumble::demo::run(&opts, &self.out, &mut |stage| eprintln!("{stage}"))?;
        print!("{}", report.table());
        Ok(())
    }
}
