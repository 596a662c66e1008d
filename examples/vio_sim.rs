//! Simulate the paper's hand-held walk (BMI055-like IMU + camera), run the
//! sliding-window estimator on it and print drift, ATE and bias errors.
//!
//! `cargo run --example vio_sim -- [duration_s] [seed] [keyframe_parallax_px keyframe_interval_s]`
//!
//! The IMU is corrected with the simulation's true calibration (what a
//! perfect `tumble calibrate` would give); the pixel noise is the simulator's.

use tumble::sim::{simulate, Scenario, SimConfig};
use tumble::vio::{run, summarize, VioInput, VioOptions};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let duration: f64 = args.get(1).and_then(|s| s.parse().ok()).unwrap_or(60.0);
    let seed: u64 = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(1);
    let cfg = SimConfig { duration_s: Some(duration), ..SimConfig::default() };
    let sim = simulate(Scenario::Walk, &cfg, seed).expect("simulation");
    let input = VioInput::from_simulation(&sim).expect("input");
    let mut opts = VioOptions::for_simulation(&cfg);
    if let (Some(p), Some(i)) = (args.get(3).and_then(|s| s.parse().ok()), args.get(4).and_then(|s| s.parse().ok())) {
        (opts.keyframe_parallax_px, opts.keyframe_max_interval_s) = (p, i);
    }
    let out = run(&input, &opts, None).expect("vio");
    let s = summarize(&input, &opts, &out, 20.0);
    println!("{}", s.table());
    if let Some(ev) = &s.evaluation {
        println!("rotation RMSE {:.2}°", ev.metrics.rotation_rmse_deg);
    }
    for w in out.warnings.iter().take(10) {
        println!("warning: {w}");
    }
}
