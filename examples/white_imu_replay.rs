//! A recording's path flown again by an IMU that has exactly the noise the
//! estimator is told: white noise and a bias random walk per axis from an
//! `imu.yaml`, nothing else (no scale, misalignment, vibration or
//! quantization: `ImuNoise::noise_only_model`). It tells the estimator's own
//! inconsistency from the real sensor's unmodelled errors: run `tumble vio`
//! on the real recording and on this one, with the same noise file and a
//! simulated camera, and compare the windows' normalized length errors.
//!
//! The path is the recording's ground truth smoothed by a Gaussian of 50 ms
//! (`sim::SmoothedReplay`; a tracker's positions hold accelerations the IMU
//! does not feel), so it is the recording's flight without its fastest
//! shakes. Writes `OUT/mav0/imu0/data.csv` and
//! `OUT/mav0/state_groundtruth_estimate0/data.csv` (the smoothed path at the
//! IMU's stamps, with the true velocity and biases).
//!
//! ```sh
//! cargo run --release --example white_imu_replay -- $TUMBLE_DATA/euroc/full_imu/MH_03_medium white_mh03 v2_01_flight/imu.yaml [SEED]
//! cargo run --release -- vio white_mh03 --simulate-camera --mono --noise v2_01_flight/imu.yaml --out vio_white
//! ```

use std::path::Path;
use tumble::io::trajectory::write_asl_groundtruth;
use tumble::io::write_asl_imu;
use tumble::sim::SmoothedReplay;

/// Width of the Gaussian the ground truth is smoothed with \[s\].
const SMOOTHING_S: f64 = 0.05;

/// Gravity the IMU is simulated under \[m/s²\] (the estimator's default).
const GRAVITY: f64 = 9.81;

fn run(src: &Path, out: &Path, noise: &Path, seed: u64) -> Result<(), String> {
    let ds = tumble::io::asl::read_asl(src, &Default::default()).map_err(|e| e.to_string())?;
    let gt = ds.groundtruth.ok_or_else(|| format!("{}: no ground truth", src.display()))?;
    let noise = tumble::io::ImuNoise::read(noise).map_err(|e| e.to_string())?;
    let path = SmoothedReplay::new(&gt, SMOOTHING_S).map_err(|e| format!("{}: {e}", src.display()))?;
    let (imu, truth) = path.simulate(&noise.noise_only_model(), GRAVITY, seed);
    let mav = out.join("mav0");
    write_asl_imu(&mav.join("imu0/data.csv"), &imu).map_err(|e| e.to_string())?;
    let gt_dir = mav.join("state_groundtruth_estimate0");
    std::fs::create_dir_all(&gt_dir).map_err(|e| format!("{}: {e}", gt_dir.display()))?;
    write_asl_groundtruth(&gt_dir.join("data.csv"), &truth).map_err(|e| e.to_string())?;
    println!("{}: {} IMU samples along {}'s smoothed path", out.display(), imu.len(), src.display());
    Ok(())
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let usage = "usage: white_imu_replay RECORDING OUT NOISE_YAML [SEED]";
    if !(3..=4).contains(&args.len()) {
        eprintln!("{usage}");
        std::process::exit(2);
    }
    let seed = match args.get(3).map(|s| s.parse::<u64>()) {
        None => 1,
        Some(Ok(s)) => s,
        Some(Err(_)) => {
            eprintln!("SEED must be a whole number, found {:?}\n{usage}", args[3]);
            std::process::exit(2);
        }
    };
    if let Err(e) = run(Path::new(&args[0]), Path::new(&args[1]), Path::new(&args[2]), seed) {
        eprintln!("error: {e}");
        std::process::exit(1);
    }
}
