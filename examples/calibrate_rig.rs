//! Calibrate EuRoC's camera–IMU rig on its `imu_april` sequence and compare
//! with EuRoC's published calibration; prints the wall time against the
//! 30 s target (the benchmark of `tumble calibrate-rig`).
//!
//! `cargo run --release --example calibrate_rig [-- <data dir>] [--timed-only]`
//! (default `$TUMBLE_DATA/euroc`, docs/datasets.md; `--timed-only` skips the second
//! calibration, with EuRoC's intrinsics held).

use std::path::PathBuf;
use tumble::rig::{calibrate_rig, RigInput, RigOptions};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let timed_only = args.iter().any(|a| a == "--timed-only");
    let root = match args.iter().find(|a| !a.starts_with("--")) {
        Some(dir) => PathBuf::from(dir),
        None => match tumble::io::datasets::dataset("euroc") {
            Some(dir) => dir,
            None => return Ok(()),
        },
    };
    let seq = root.join("imu_april");
    if !seq.is_dir() {
        println!("skipped: {} is absent", seq.display());
        return Ok(());
    }
    let micro = root.join("V1_01_easy_micro/mav0");
    let opts = RigOptions { resolution: Some([752, 480]), ..RigOptions::default() };
    let t = std::time::Instant::now();
    let input = RigInput::from_asl(&seq, &seq.join("target.yaml"), Some(&micro.join("imu0/sensor.yaml")), None, &opts)?;
    let rig = calibrate_rig(&input, &opts, &mut |m| eprintln!("{m}"))?;
    let seconds = t.elapsed().as_secs_f64();
    println!("{}", tumble::rig::summary_markdown(&rig));
    let mut reference = Vec::new();
    for c in &rig.cameras {
        let (m, t_bs, _, _) = tumble::io::asl::read_camera_sensor(&micro.join(&c.name).join("sensor.yaml"))?;
        reference.push((m, t_bs.ok_or("reference without T_BS")?));
    }
    println!("Against EuRoC's published calibration (V1_01_easy/mav0/camN/sensor.yaml):\n");
    println!("| camera | rotation [°] | translation [mm] x y z | fx, fy [%] | cx, cy [px] |\n|---|---|---|---|---|");
    for d in rig.compare(&reference) {
        let t = d.translation_m.map(|x| x * 1e3);
        println!(
            "| {} | {:.3} | {:.1} {:.1} {:.1} | {:.2}, {:.2} | {:.2}, {:.2} |",
            d.name,
            d.rotation_deg,
            t[0],
            t[1],
            t[2],
            d.focal_relative[0] * 100.0,
            d.focal_relative[1] * 100.0,
            d.principal_point_px[0],
            d.principal_point_px[1]
        );
    }
    println!("\ntime offset {:.3} ms (hardware-triggered: ≈ 0)", rig.time_offset_s * 1e3);
    println!("wall time {seconds:.1} s including reading (target ≤ 30 s): ratio {:.2}", seconds / 30.0);
    if timed_only {
        return Ok(());
    }
    // Kalibr's own workflow: the cameras' intrinsics fixed, then T_BC and the offset.
    let fixed = RigOptions { fixed_intrinsics: reference.iter().map(|r| r.0).collect(), ..opts.clone() };
    let held = calibrate_rig(&input, &fixed, &mut |_| {})?;
    println!("\nWith EuRoC's intrinsics held fixed (as Kalibr's camera–IMU step does):\n");
    println!(
        "| camera | rotation [°] (largest σ) | translation [mm] x y z (largest σ) | reprojection RMS / median [px] |\n|---|---|---|---|"
    );
    for (d, c) in held.compare(&reference).iter().zip(&held.cameras) {
        let t = d.translation_m.map(|x| x * 1e3);
        println!(
            "| {} | {:.3} ({:.3}) | {:.1} {:.1} {:.1} ({:.1}) | {:.3} / {:.3} |",
            d.name,
            d.rotation_deg,
            c.rotation_sigma.max().to_degrees(),
            t[0],
            t[1],
            t[2],
            c.translation_sigma.max() * 1e3,
            c.reprojection.rms_px,
            c.reprojection.median_px
        );
    }
    println!("time offset {:.3} ms ± {:.3}", held.time_offset_s * 1e3, held.time_offset_sigma_s * 1e3);
    Ok(())
}
