//! Simulate the paper's hand-held walk (BMI055-like IMU + camera), run the
//! sliding-window estimator on it and print drift, ATE and bias errors.
//!
//! `cargo run --release --example vio_sim -- [duration_s] [seed]`

use tumble::sim::{simulate, Scenario, SimConfig};
use tumble::vio::{run, summarize, ImuNoise, VioInput, VioOptions};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let duration: f64 = args.get(1).and_then(|s| s.parse().ok()).unwrap_or(60.0);
    let seed: u64 = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(1);
    let mut cfg = SimConfig::default();
    cfg.duration_s = Some(duration);
    let sim = simulate(Scenario::Walk, &cfg, seed).expect("simulation");
    let input = VioInput::from_simulation(&sim).expect("input");
    if std::env::var("VIO_DEBUG").is_ok() {
        let n = 200;
        let m: nalgebra::Vector3<f64> = input.imu.gyro[..n].iter().sum::<nalgebra::Vector3<f64>>() / n as f64;
        let a: nalgebra::Vector3<f64> = input.imu.acc[..n].iter().sum::<nalgebra::Vector3<f64>>() / n as f64;
        println!(
            "mean gyro first 1 s {m:?}, accel {a:?}, true bg {:?}",
            input.groundtruth.as_ref().unwrap().bias_gyro.as_ref().unwrap()[0]
        );
        println!("raw gyro[0..3] {:?}", &sim.imu.gyro[..3]);
    }
    let mut opts = VioOptions::default();
    ImuNoise::from_model(&cfg.imu).apply(&mut opts.imu);
    opts.gravity = cfg.gravity;
    opts.pixel_sigma = cfg.camera.pixel_noise_px;
    opts.covariances = std::env::var("VIO_NOCOV").is_err();
    if let Ok(f) = std::env::var("VIO_FTOL") {
        opts.function_tolerance = f.parse().unwrap();
    }
    let out = run(&input, &opts, None).expect("vio");
    if std::env::var("VIO_DEBUG").is_ok() {
        debug(&input, &out);
    }
    let s = summarize(&input, &opts, &out, 20.0);
    println!("{}", s.table());
    for w in out.warnings.iter().take(10) {
        println!("warning: {w}");
    }
}

#[allow(dead_code)]
fn debug(input: &VioInput, out: &tumble::vio::VioResult) {
    let gt = input.groundtruth.as_ref().unwrap();
    for e in out.estimates.iter().step_by(80) {
        let k = gt.t_ns.partition_point(|&s| s < input.t0_ns + (e.t * 1e9) as i64).min(gt.len() - 1);
        println!(
            "t {:6.2} ba {:?} true {:?} | bg {:?} true {:?} | std ba {:?} bg {:?}",
            e.t,
            e.bias_accel.map(|x| (x * 1e3).round() / 1e3),
            gt.bias_accel.as_ref().unwrap()[k].map(|x| (x * 1e3).round() / 1e3),
            e.bias_gyro.map(|x| (x * 1e4).round() / 1e4),
            gt.bias_gyro.as_ref().unwrap()[k].map(|x| (x * 1e4).round() / 1e4),
            e.std[3].map(|x| (x * 1e3).round() / 1e3),
            e.std[4].map(|x| (x * 1e4).round() / 1e4),
        );
    }
}
