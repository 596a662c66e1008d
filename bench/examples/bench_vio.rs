//! Speed of the VIO backend at EuRoC rates (200 Hz IMU, 20 Hz camera, 150
//! tracked features per frame) on one core, against the target of 20×
//! real time. VINS-Mono itself (C++, ROS, Ceres) cannot be built here, so the
//! peer figure is the target rate; the real-data run on EqVIO's V1_01 tracks
//! is printed too, and the same flight with the whole window solved at every
//! frame (VINS-Mono's scheme, `--solve-every-frame`) as an in-run reference,
//! and with VINS-Mono's landmarks (the bearing fixed at the anchor pixel,
//! `--inverse-depth-only`).
//! Covariance recovery is included (each frame's σ).
//!
//! `cargo run --release -p tumble-bench --example bench_vio [-- --duration S] [--repeat N]`
//!
//! With `--repeat N` each case runs N times and the run of median speed is
//! printed, with every run's speed (the wall time of a 2-core virtual machine
//! varies by ±20 % from run to run).

use tumble::sim::{simulate, Scenario, SimConfig};
use tumble::vio::{read_eqvio, run, summarize, VioInput, VioOptions};

const TARGET_REALTIME: f64 = 20.0;

fn main() {
    let usage = "usage: bench_vio [--duration S (60, at least 20)] [--repeat N (1)]";
    let v = tumble_bench::numeric_args(usage, &[("--duration", 60.0), ("--repeat", 1.0)]);
    let (duration, repeat) = (v[0], (v[1] as usize).max(1));
    let pool = rayon::ThreadPoolBuilder::new().num_threads(1).build().expect("thread pool");
    let cfg = SimConfig { duration_s: Some(duration.max(20.0)), ..SimConfig::default() };
    let sim = simulate(Scenario::Flight, &cfg, 11).expect("simulation");
    let input = VioInput::from_simulation(&sim).expect("input");
    let per_frame = input.frames.iter().map(|f| f.features.len()).sum::<usize>() as f64 / input.frames.len() as f64;
    let opts = VioOptions::for_simulation(&cfg);
    let report = |name: &str, input: &VioInput, opts: &VioOptions| -> f64 {
        let mut runs: Vec<_> = (0..repeat)
            .map(|_| {
                let out = pool.install(|| run(input, opts, None)).expect("vio");
                summarize(input, opts, &out, 10.0)
            })
            .collect();
        runs.sort_by(|a, b| a.realtime_factor.total_cmp(&b.realtime_factor));
        let speeds: Vec<String> = runs.iter().map(|s| format!("{:.1}×", s.realtime_factor)).collect();
        let s = &runs[repeat / 2];
        println!("{name}:");
        if repeat > 1 {
            println!("  {repeat} runs, real-time factors {} (the median run below)", speeds.join(", "));
        }
        println!("  {}", s.table().replace('\n', "\n  "));
        println!(
            "  backend speed on one core: {:.1}× real time vs target {TARGET_REALTIME:.0}× → ratio {:.2}",
            s.realtime_factor,
            s.realtime_factor / TARGET_REALTIME
        );
        s.realtime_factor
    };
    println!(
        "simulated EuRoC-like flight: {:.0} s, IMU 200 Hz, camera 20 Hz, {per_frame:.0} features per frame",
        input.frames.last().map_or(0.0, |f| f.t)
    );
    let tracked = report("simulated flight", &input, &opts);
    let every = report(
        "simulated flight, the whole window solved at every frame (--solve-every-frame, VINS-Mono's way)",
        &input,
        &{
            let mut o = opts.clone();
            o.window.solve_every_frame = true;
            o
        },
    );
    println!(
        "keyframe-only window solves: {:.1}× real time vs {:.1}× solving the window at every frame → {:.2}× faster",
        tracked,
        every,
        tracked / every
    );
    let inverse_depth = report(
        "simulated flight, VINS-Mono's landmarks (--inverse-depth-only: the bearing fixed at the anchor pixel)",
        &input,
        &{
            let mut o = opts.clone();
            o.window.landmark_bearings = false;
            o
        },
    );
    println!(
        "landmarks with their bearings (the default): {tracked:.1}× real time vs {inverse_depth:.1}× with the inverse depth alone → {:.2}× the time",
        inverse_depth / tracked
    );
    if let Some(csv) = tumble::io::datasets::dataset("euroc/eqvio_V1_01_30s.csv") {
        let gt = csv.with_file_name("groundtruth/V1_01_easy.csv");
        let real = read_eqvio(&csv, gt.is_file().then_some(gt.as_path())).expect("eqvio");
        report("EuRoC V1_01 (EqVIO tracks, 12–38 per frame)", &real, &VioOptions::with_pixel_sigma(1.93));
    }
}
