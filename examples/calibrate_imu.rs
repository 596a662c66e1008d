//! Turntable-free calibration (paper eq. 1) of a simulated hand tumble with
//! known truth, through the library: read → calibrate → correct. Give a
//! recording (ASL folder, bag, or `t,gx,gy,gz,ax,ay,az` CSV in ns/rad/s/m/s²)
//! to calibrate yours instead.
//!
//! ```sh
//! cargo run --example calibrate_imu [-- RECORDING]
//! ```

use tumble::calib::{calibrate, CalibOptions};
use tumble::io::{open_recording, RecordingOptions};
use tumble::sim::{simulate, Scenario, SimConfig};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let cfg = SimConfig::default();
    let (rec, truth) = match std::env::args().nth(1) {
        Some(path) => (open_recording(path.as_ref(), &RecordingOptions::default())?, None),
        None => {
            // ≈ 50 s still, then ~50 poses held 1–4 s each, turned by hand in between.
            let sim = simulate(Scenario::Tumble, &cfg, 7)?;
            (sim.imu.to_recording(), Some(cfg.imu.clone()))
        }
    };
    let opts = CalibOptions { gravity: cfg.gravity, ..Default::default() };
    let result = calibrate(&rec, &opts).map_err(|e| e.message)?;
    print!("{}", result.summary_table());
    for w in &result.warnings {
        println!("warning: {w}");
    }

    let (a, g) = (&result.calibration.accel, &result.calibration.gyro);
    if let Some(truth) = truth {
        // Estimates against the simulator's truth, in units of their own σ.
        println!("\n{:<10} {:>10} {:>10} {:>7}", "", "truth", "estimate", "err/σ");
        let row =
            |name: String, t: f64, e: f64, sd: f64| println!("{name:<10} {t:>10.6} {e:>10.6} {:>7.1}", (e - t) / sd);
        for k in 0..3 {
            row(format!("accel K{k}"), truth.accel.scale[k], a.k[k], a.k_std[k]);
            row(format!("gyro K{k}"), truth.gyro.scale[k], g.k[k], g.k_std[k]);
            row(format!("accel b{k}"), truth.accel.bias[k], a.b[k], a.b_std[k]);
        }
    }

    // Correct (eq. 16) the first second, at rest: it should read ≈ g and ≈ 0 on average.
    let corr = result.calibration.corrector().ok_or("singular calibration")?;
    let n = (rec.mean_rate() as usize).clamp(1, rec.len());
    let (mut acc, mut gyro) = ([0.0; 3], [0.0; 3]);
    for i in 0..n {
        let (a, g) = (corr.accel(rec.accel[i]), corr.gyro(rec.gyro[i]));
        for k in 0..3 {
            acc[k] += a[k] / n as f64;
            gyro[k] += g[k] / n as f64;
        }
    }
    let norm = (acc[0] * acc[0] + acc[1] * acc[1] + acc[2] * acc[2]).sqrt();
    println!(
        "\nfirst second corrected (mean of {n} samples): |a| = {norm:.4} m/s², ω = [{:+.5}, {:+.5}, {:+.5}] rad/s",
        gyro[0], gyro[1], gyro[2]
    );
    Ok(())
}
