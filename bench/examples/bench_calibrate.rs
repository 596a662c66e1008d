//! Full calibration of imu_tk's Xsens recording (file reading included) with
//! tumble, against imu_tk's wall time on the same machine.
//!
//! imu_tk (C++, Ceres) is not buildable here without Ceres; its figure is the
//! median of 3 runs of imu_tk's `test_imu_calib` on this machine class (≈ 2.3 s), printed
//! as the peer's. `cargo run --release -p tumble-bench --example bench_calibrate [-- --repeat N]`

use std::time::Instant;
use tumble::calib::{calibrate, CalibOptions};
use tumble::io::{open_recording, AccelUnit, GyroUnit, RecordingOptions, TimeUnit};

const IMU_TK_SECONDS: f64 = 2.3;

fn main() {
    let usage = "usage: bench_calibrate [--repeat N (5)]";
    let repeat = tumble_bench::numeric_args(usage, &[("--repeat", 5.0)])[0] as usize;
    let Some(dir) = tumble::io::datasets::dataset("imu_tk_xsens") else {
        return;
    };
    let mut o = RecordingOptions::default();
    o.format.time_unit = TimeUnit::S;
    o.format.accel_unit = AccelUnit::Counts { scale: None, offset: 0.0 };
    o.format.gyro_unit = GyroUnit::Counts { scale: None, offset: 0.0 };
    o.gyro_file = Some(dir.join("xsens_gyro.mat"));
    let opts = CalibOptions { gravity: 9.81744, ..Default::default() };
    let mut times = Vec::new();
    for _ in 0..repeat.max(1) {
        let t = Instant::now();
        let rec = open_recording(&dir.join("xsens_acc.mat"), &o).expect("read");
        let res = calibrate(&rec, &opts).expect("calibrate");
        times.push(t.elapsed().as_secs_f64());
        assert!(res.intervals.len() >= 12);
    }
    times.sort_by(f64::total_cmp);
    let ours = times[times.len() / 2];
    println!("Xsens calibration (51,175 samples, read + detect + accel sweep + gyro + covariances)");
    println!("  tumble: {ours:.4} s (median of {})", times.len());
    println!("  imu_tk: {IMU_TK_SECONDS:.1} s (recorded on this machine class)");
    println!("  ratio:  {:.1}× faster (target ≥ 20×)", IMU_TK_SECONDS / ours);
}
