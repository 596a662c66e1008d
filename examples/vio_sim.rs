//! Simulate the paper's hand-held walk (BMI055-like IMU + camera), run the
//! sliding-window estimator on it and print drift, ATE and bias errors.
//!
//! `cargo run --example vio_sim -- [--scenario walk|corridor|flight|planar] [--duration S] [--seed N]
//! [--keyframe-parallax PX] [--keyframe-interval S] [--window N]
//! [--max-iterations N] [--prediction-gate PX] [--triangulation-gate PX]
//! [--gyro-rw-scale K] [--accel-rw-scale K] [--pixel-noise PX] [--imu-noise-scale K]
//! [--pixel-sigma PX] [--online on|auto] [--out DIR]`
//!
//! `planar` is a ground robot's motion (`Loop::planar`: in the horizontal
//! plane, turning about the vertical only) in a room. `--online` estimates
//! the camera's `T_BC` and time offset online from a wrong start (turned
//! 2°, moved 2 cm along the camera's x and y, stamps 8 ms late) and prints
//! the estimate's errors.
//! The rw scales multiply the estimator's bias random walks (per axis, the
//! model's own with its bias instability folded in, by default); `--pixel-noise` and
//! `--imu-noise-scale` change the simulated pixel noise and multiply the
//! IMU's white noise densities (the estimator is told either);
//! `--pixel-sigma` sets the estimator's pixel σ alone.
//! The IMU is corrected with the simulation's true calibration (what a
//! perfect `tumble calibrate` would give); the pixel noise is the simulator's.
//! With `--out` the run's files and figures are written as `tumble vio` does.

use nalgebra::Vector3;
use tumble::sim::{simulate, simulate_motion, Loop, Scenario, Scene, SimConfig};
use tumble::vio::{run, summarize, write_outputs, Estimate, VioInput, VioOptions};

/// How late the camera's stamps are made with `--online` \[s\].
const ONLINE_SHIFT_S: f64 = 0.008;

/// The value after `--name`, parsed; the default when absent.
fn flag<T: std::str::FromStr>(args: &[String], name: &str, default: T) -> T {
    match args.iter().position(|a| a == name) {
        Some(i) => match args.get(i + 1).map(|v| v.parse()) {
            Some(Ok(v)) => v,
            _ => {
                eprintln!("{name} needs a value");
                std::process::exit(2);
            }
        },
        None => default,
    }
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let duration: f64 = flag(&args, "--duration", 60.0);
    let seed: u64 = flag(&args, "--seed", 1);
    let mut cfg = SimConfig { duration_s: Some(duration), ..SimConfig::default() };
    cfg.camera.pixel_noise_px = flag(&args, "--pixel-noise", cfg.camera.pixel_noise_px);
    let white = flag(&args, "--imu-noise-scale", 1.0);
    for triad in [&mut cfg.imu.gyro, &mut cfg.imu.accel] {
        triad.noise_density = triad.noise_density.map(|n| n * white);
    }
    let name: String = flag(&args, "--scenario", "walk".to_string());
    let sim = if name == "planar" {
        let motion = Box::new(Loop::planar(duration, seed));
        simulate_motion(Scenario::Walk, motion, Scene::Room(Vector3::zeros()), &cfg, seed)
    } else {
        let scenario = match name.to_ascii_lowercase().parse::<Scenario>() {
            Ok(s @ (Scenario::Walk | Scenario::Corridor | Scenario::Flight)) => s,
            _ => {
                eprintln!("--scenario: walk, corridor, flight or planar, found {name}");
                std::process::exit(2);
            }
        };
        simulate(scenario, &cfg, seed)
    };
    let mut input = VioInput::from_simulation(&sim.expect("simulation")).expect("input");
    let mut opts = VioOptions::for_simulation(&cfg);
    opts.window.keyframe_parallax_px = flag(&args, "--keyframe-parallax", opts.window.keyframe_parallax_px);
    opts.window.keyframe_max_interval_s = flag(&args, "--keyframe-interval", opts.window.keyframe_max_interval_s);
    opts.window.size = flag(&args, "--window", opts.window.size);
    opts.solver.max_iterations = flag(&args, "--max-iterations", opts.solver.max_iterations);
    opts.gates.prediction_px = flag(&args, "--prediction-gate", opts.gates.prediction_px);
    opts.gates.triangulation_px = flag(&args, "--triangulation-gate", opts.gates.triangulation_px);
    opts.noise.pixel_sigma = flag(&args, "--pixel-sigma", opts.noise.pixel_sigma);
    let (gyro_rw, accel_rw) = (flag(&args, "--gyro-rw-scale", 1.0), flag(&args, "--accel-rw-scale", 1.0));
    opts.noise.imu.gyro_random_walk *= gyro_rw;
    opts.noise.imu.accel_random_walk *= accel_rw;
    if let Some(axes) = opts.noise.imu.axes.as_mut() {
        axes.gyro_random_walk = axes.gyro_random_walk.map(|k| k * gyro_rw);
        axes.accel_random_walk = axes.accel_random_walk.map(|k| k * accel_rw);
    }
    let online: String = flag(&args, "--online", String::new());
    let mut correct = None;
    if !online.is_empty() {
        let mode = match online.as_str() {
            "on" => Estimate::On,
            "auto" => Estimate::Auto,
            _ => {
                eprintln!("--online: on or auto, found {online}");
                std::process::exit(2);
            }
        };
        (opts.camera.extrinsics, opts.camera.time_offset) = (mode, mode);
        let (moved, c) =
            input.with_camera_error(Vector3::new(0.02, -0.02, 0.02), Vector3::new(0.02, 0.02, 0.0), ONLINE_SHIFT_S);
        (input, correct) = (moved, Some(c));
    }
    let out = run(&input, &opts, None).expect("vio");
    let s = summarize(&input, &opts, &out, 20.0);
    println!("{}", s.table());
    if let Some(ev) = &s.evaluation {
        println!("rotation RMSE {:.2}°", ev.metrics.rotation_rmse_deg);
    }
    if let (Some(correct), Some(c)) = (correct, &out.camera) {
        let (rotation_deg, _) = c.difference(&correct);
        let t = c.translation_error(&correct) * 1e3;
        println!(
            "online calibration errors: rotation {rotation_deg:.3}°, translation [{:.1} {:.1} {:.1}] mm (camera axes), \
             time offset {:.3} ms",
            t.x,
            t.y,
            t.z,
            (c.time_offset_s + ONLINE_SHIFT_S) * 1e3
        );
    }
    for w in out.warnings.iter().take(10) {
        println!("warning: {w}");
    }
    let dir: String = flag(&args, "--out", String::new());
    if !dir.is_empty() {
        let files = write_outputs(std::path::Path::new(&dir), &input, &out, &s).expect("writing the outputs");
        println!("wrote {}", files.iter().map(|f| f.display().to_string()).collect::<Vec<_>>().join(", "));
    }
}
