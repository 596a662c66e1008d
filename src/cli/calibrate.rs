//! `tumble calibrate`: deterministic calibration from a hand tumble.

use super::common::{paths, CalibInput};
use super::CliResult;
use clap::Args;
use std::path::PathBuf;
use tumble::calib::{local_gravity, parse_multipliers, CalibOptions};

/// Flags of `tumble calibrate`.
#[derive(Args)]
pub struct CalibrateArgs {
    #[command(flatten)]
    input: CalibInput,
    /// Several hand tumbles of one sensor, described in a YAML file (a
    /// `tumbles:` list, each entry with the keys of `tumble run --inputs`):
    /// each calibrated alone, the sensor's scales and misalignments pooled
    /// and checked for agreement (docs/calibration.md).
    #[arg(long, conflicts_with_all = ["recording", "accel", "gyro"])]
    inputs: Option<PathBuf>,
    /// Output folder.
    #[arg(long)]
    out: PathBuf,
    /// Local gravity [m/s²] (default: WGS-84 at --latitude/--height, else 9.80665).
    #[arg(long, conflicts_with = "latitude")]
    gravity: Option<f64>,
    /// Geodetic latitude [deg] for WGS-84 normal gravity.
    #[arg(long)]
    latitude: Option<f64>,
    /// Ellipsoidal height [m] for WGS-84 normal gravity (with --latitude).
    #[arg(long, default_value_t = 0.0, requires = "latitude")]
    height: f64,
    /// Length of the initial static period [s] (default: found in the data, the
    /// longest rest of ≥ 1 s in the first quarter of the recording).
    #[arg(long)]
    init_static: Option<f64>,
    /// Window of the sliding accelerometer variance [s] (imu_tk: 101 samples).
    #[arg(long, default_value_t = 0.5)]
    window: f64,
    /// Shortest usable static interval [s] (imu_tk: 100 samples).
    #[arg(long, default_value_t = 0.5)]
    min_interval: f64,
    /// Threshold multipliers to sweep: FIRST:LAST (integers) or a comma list.
    #[arg(long, default_value = "2:10")]
    multipliers: String,
    /// Estimate the gyro bias with the other gyro parameters (default: mean of the initial static period).
    #[arg(long)]
    estimate_gyro_bias: bool,
    /// Fewest static intervals accepted.
    #[arg(long, default_value_t = 12)]
    min_intervals: usize,
    /// Detect static intervals from the accelerometer alone, as imu_tk does
    /// (default: the gyro must be still too).
    #[arg(long)]
    accel_only_detection: bool,
}

impl CalibrateArgs {
    pub fn run(self) -> CliResult {
        let gravity = local_gravity(self.gravity, self.latitude, self.height)?;
        if let Some(note) = gravity.note {
            eprintln!("note: {note}");
        }
        let opts = CalibOptions {
            gravity: gravity.value,
            init_static_s: self.init_static,
            window_s: self.window,
            min_interval_s: self.min_interval,
            multipliers: parse_multipliers(&self.multipliers)?,
            estimate_gyro_bias: self.estimate_gyro_bias,
            min_intervals: self.min_intervals,
            detect_with_gyro: !self.accel_only_detection,
        };
        opts.validate()?;
        if let Some(inputs) = &self.inputs {
            return calibrate_several(inputs, &opts, &self.out);
        }
        let start = std::time::Instant::now();
        let source = self.input.source()?;
        let rec = source.open()?;
        for w in &rec.warnings {
            eprintln!("warning: {w}");
        }
        eprintln!("read {} samples ({:.1} s) in {:.2} s", rec.len(), rec.duration(), start.elapsed().as_secs_f64());
        let t = std::time::Instant::now();
        let result = match tumble::calib::calibrate(&rec, &opts) {
            Ok(r) => r,
            Err(mut e) => {
                if let Some(d) = e.diagnosis.take() {
                    print!("{}", d.summary_table());
                    let files = d.write_diagnosis(&rec, &opts, &self.out)?;
                    eprintln!("wrote the diagnosis (not a calibration): {}", paths(&files));
                    let stale = self.out.join("calibration.json");
                    if stale.exists() {
                        eprintln!(
                            "note: {} is from an earlier run; this run failed and did not replace it",
                            stale.display()
                        );
                    }
                }
                return Err(e.into());
            }
        };
        let elapsed = t.elapsed().as_secs_f64();
        print!("{}", result.summary_table());
        for w in &result.warnings {
            eprintln!("warning: {w}");
        }
        let files = result.write_all(&rec, &opts, &self.out)?;
        println!("calibrated in {elapsed:.3} s; wrote {}", paths(&files));
        Ok(())
    }
}

/// `--inputs`: read every tumble the file describes, pool them, write.
fn calibrate_several(inputs: &std::path::Path, opts: &CalibOptions, out: &std::path::Path) -> CliResult {
    let (recs, names) = super::common::read_tumbles(inputs)?;
    let t = std::time::Instant::now();
    let result = tumble::calib::calibrate_recordings(&recs, &names, opts)?;
    let elapsed = t.elapsed().as_secs_f64();
    print!("{}", result.summary_table());
    for w in &result.warnings {
        eprintln!("warning: {w}");
    }
    let files = result.write_all(&recs, &names, opts, out)?;
    println!(
        "calibrated {} recordings in {elapsed:.3} s; wrote {} files into {}",
        recs.len(),
        files.len(),
        out.display()
    );
    Ok(())
}
