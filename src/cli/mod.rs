//! The command line: one module per command, each an `Args` struct (clap) and
//! a `run` that maps its flags to the library's options, calls the library
//! and prints. Decisions (what an input is, what is valid, what is written)
//! live in the library; progress bars live here and are driven by the
//! library's callbacks.

mod allan;
mod apply;
mod audit;
mod calibrate;
mod common;
mod convert;
mod demo;
mod eval;
mod export;
mod inspect;
mod noise;
mod rig;
mod run;
mod sim;
mod solve;
mod track;
mod vio;

use clap::{Parser, Subcommand};
use std::process::ExitCode;

/// What a command returns: any library error, printed with its causes.
pub(crate) type CliResult = Result<(), Box<dyn std::error::Error>>;

#[derive(Parser)]
#[command(
    name = "tumble",
    version,
    about = "Turntable-free IMU calibration, Allan noise identification and visual-inertial bias estimation"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Simulate a recording with known truth and write it as an ASL dataset folder.
    Sim(sim::SimArgs),
    /// Read an IMU recording, check it, and print what it holds and what looks wrong.
    Inspect(inspect::InspectArgs),
    /// Identify IMU noise from a static recording by Allan variance: writes
    /// allan.json, Kalibr's imu.yaml and allan_gyro.png / allan_accel.png.
    Allan(allan::AllanArgs),
    /// Calibrate accelerometer and gyroscope from one hand-tumbled recording
    /// (≥ 50 s still, then many poses held still): writes calibration.json/.yaml,
    /// imu_tk_acc.calib, imu_tk_gyro.calib and static_detection.png.
    Calibrate(calibrate::CalibrateArgs),
    /// Calibrate a camera–IMU rig on a target (Kalibr's job): each camera's
    /// intrinsics, its pose in the IMU frame and the time offset, with σ, from
    /// an ASL folder with camN/corners.csv. Writes camchain-imucam.yaml,
    /// camN/sensor.yaml, rig.json and report.md.
    CalibrateRig(rig::RigArgs),
    /// Correct a recording with a calibration (paper eq. 16) and write it in the format it was read.
    Apply(apply::ApplyArgs),
    /// Model-discrepancy audit of a calibration recording: find the effect the
    /// calibration lacks, add it, show the gap shrink. Writes audit.json,
    /// audit.md, calibration.json (with the effects) and figures. With --vio,
    /// the audit of a VIO run instead: camera–IMU and accelerometer–gyro time offsets.
    Audit(audit::AuditArgs),
    /// Visual-inertial bias estimation (sliding window, paper §4): writes
    /// trajectory.txt (TUM), biases.csv and summary.json.
    Vio(vio::VioArgs),
    /// Track features in an ASL folder's camera images (visual frontend, cargo
    /// feature `opencv`): writes tracks.csv, frontend.json and tracks.png.
    Track(track::TrackArgs),
    /// Evaluate a trajectory against ground truth: ATE after alignment, RPE over
    /// distances, bias errors; writes metrics.json and plots.
    Eval(eval::EvalArgs),
    /// The whole chain on your recordings: calibrate → allan → audit → vio, each
    /// stage in its own folder of --out, then report.md with every table and figure.
    Run(run::RunArgs),
    /// The whole chain on simulated recordings with known truth: calibrate a hand
    /// tumble with a hidden effect, identify the noise (Allan), audit, and run the
    /// VIO on the 6-minute walk; prints every estimate next to the truth.
    Demo(demo::DemoArgs),
    /// Convert a ROS recording (rosbag2 folder, .db3, .mcap, .bag) into an ASL/EuRoC
    /// folder: IMU, camera images as PNG with data.csv, camera_info as sensor.yaml, ground truth.
    Convert(convert::ConvertArgs),
    /// Write another estimator's configuration from tumble's results: Kalibr, VINS-Mono,
    /// VINS-Fusion, OpenVINS, ORB-SLAM3 or Basalt (noise in its convention, intrinsics where it models them).
    Export(export::ExportArgs),
    /// Datasheet noise figures (ARW, VRW, bias instability, random walks, with units) as Kalibr's imu.yaml.
    Noise(noise::NoiseArgs),
    /// Solve a g2o pose graph (.g2o) or a Bundle Adjustment in the Large file (other extensions).
    Solve(solve::SolveArgs),
}

/// Parse the command line, run the command, print any error with its causes.
pub fn main() -> ExitCode {
    // Die quietly on a closed pipe (`tumble inspect … | head`) instead of panicking in println!.
    #[cfg(unix)]
    // SAFETY: restoring the default disposition of SIGPIPE before any thread starts.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
    // Large buffers always mmap'd, so what one stage frees goes back to the
    // system (glibc otherwise raises its mmap threshold after the first free
    // and keeps the memory in its heap: the Allan stage's axes would add up).
    #[cfg(target_os = "linux")]
    // SAFETY: called before any other thread starts; only tunes the allocator.
    unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, 1 << 20);
    }
    let result = match Cli::parse().command {
        Command::Sim(a) => a.run(),
        Command::Inspect(a) => a.run(),
        Command::Allan(a) => a.run(),
        Command::Calibrate(a) => a.run(),
        Command::CalibrateRig(a) => a.run(),
        Command::Apply(a) => a.run(),
        Command::Audit(a) => a.run(),
        Command::Vio(a) => a.run(),
        Command::Track(a) => a.run(),
        Command::Eval(a) => a.run(),
        Command::Run(a) => a.run(),
        Command::Demo(a) => a.run(),
        Command::Convert(a) => a.run(),
        Command::Export(a) => a.run(),
        Command::Noise(a) => a.run(),
        Command::Solve(a) => a.run(),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            // The causes a message does not already quote.
            let mut shown = e.to_string();
            let mut cause = e.source();
            while let Some(c) = cause {
                let text = c.to_string();
                if !shown.contains(&text) {
                    eprintln!("  caused by: {text}");
                    shown.push_str(&text);
                }
                cause = c.source();
            }
            ExitCode::FAILURE
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::CommandFactory;

    #[test]
    fn the_command_line_is_well_formed() {
        Cli::command().debug_assert();
    }

    /// Every command parses its flags into their types (a value parser whose
    /// type does not match its field panics here, not in a user's hands).
    #[test]
    fn every_command_parses_its_flags() {
        let cases: &[&[&str]] = &[
            &["sim", "walk", "--out", "o", "--pause", "10,2", "--hide", "g_sensitivity:2", "--stereo-baseline", "0.1"],
            &["inspect", "r.csv", "--columns", "t,gx,gy,gz,ax,ay,az", "--time-unit", "s", "--gyro-unit", "deg/s"],
            &[
                "allan",
                "r.csv",
                "--out",
                "o",
                "--kind",
                "adev",
                "--taus",
                "octave",
                "--axis-stat",
                "mean",
                "--span",
                "0:10",
            ],
            &["calibrate", "r.csv", "--out", "o", "--multipliers", "2,3.5", "--latitude", "45", "--height", "100"],
            &["calibrate", "--accel", "a", "--gyro", "g", "--format", "imu-tk", "--out", "o"],
            &["apply", "r.csv", "--calibration", "c.json", "--out", "o"],
            &[
                "calibrate-rig",
                "d",
                "--target",
                "t.yaml",
                "--out",
                "o",
                "--resolution",
                "752x480",
                "--distortion",
                "equidistant",
            ],
            &["audit", "r.csv", "--calibration", "c.json", "--out", "o", "--candidates", "temperature_bias,bias_drift"],
            &["audit", "--vio", "v", "--out", "o", "--offset-step-ms", "2"],
            &[
                "vio",
                "v",
                "--out",
                "o",
                "--init",
                "motion",
                "--window",
                "8",
                "--keyframe-parallax",
                "20",
                "--zoh",
                "--fixed-noise",
                "--estimate-extrinsics",
                "--estimate-time-offset",
            ],
            &["vio", "v", "--out", "o", "--estimate-extrinsics", "auto", "--estimate-time-offset", "off"],
            &["vio", "v", "--estimate-time-offset", "--out", "o"],
            &["vio", "v", "--out", "o", "--rig", "rig/"],
            &["vio", "--print-config"],
            &["sim", "flight", "--print-config"],
            &["sim", "rig", "--print-config"],
            &["sim", "replay", "--from", "MH_03", "--start", "40", "--duration", "30", "--images", "--out", "o"],
            &["track", "v", "--out", "o", "--stereo"],
            &["eval", "--estimate", "e", "--groundtruth", "g", "--align", "sim3", "--rpe-distances", "1,2"],
            &["run", "--vio", "v", "--out", "o", "--skip", "calibrate,allan", "--pixel-sigma", "2"],
            &["demo", "--walk", "room", "--seed", "3"],
            &["solve", "f.g2o", "--method", "gn", "--edge-error", "ceres-then-log"],
        ];
        for args in cases {
            let argv = std::iter::once("tumble").chain(args.iter().copied());
            if let Err(e) = Cli::try_parse_from(argv) {
                panic!("{args:?}: {e}");
            }
        }
        // Values the library refuses are refused while parsing.
        for bad in [
            &["calibrate", "r.csv", "--out", "o", "--gyro-unit", "furlongs"][..],
            &["run", "--vio", "v", "--out", "o", "--skip", "nothing"],
            &["allan", "r.csv", "--out", "o", "--span", "5:1"],
            &["sim", "walk"],
            &["sim", "replay", "--out", "o"],
        ] {
            let argv = std::iter::once("tumble").chain(bad.iter().copied());
            assert!(Cli::try_parse_from(argv).is_err(), "{bad:?}");
        }
    }
}
