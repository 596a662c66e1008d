//! Reading speed: tumble's IMU CSV reader (with all its checks) against pandas
//! `read_csv` (C engine) on the same file, a static log simulated by tumble in
//! EuRoC layout (default: 4 hours at 1 kHz, six axes, 14.4 M rows, ≈1.3 GB).
//!
//! ```sh
//! pip install pandas   # the peer
//! cargo run --release -p tumble-bench --example bench_read_imu -- [--hours 4] [--rate 1000] [--repeat 3] [--no-peer]
//! ```
//! The file is made once under `target/bench-data/` and reused. Both readers
//! run on a warm page cache (each is run once before timing). Prints the median
//! time of each and the ratio pandas / tumble.

use std::path::PathBuf;
use std::process::Command;
use std::time::Instant;
use tumble::io::{read_imu_text, ImuTextFormat};
use tumble::sim::{simulate_and_write, Scenario, SimConfig};

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() {
    let usage = "usage: bench_read_imu [--hours H (4)] [--rate HZ (1000)] [--repeat N (3)] [--no-peer]";
    let flags = [("--hours", 4.0), ("--rate", 1000.0), ("--repeat", 3.0)];
    let (v, switches) = tumble_bench::args_with_switches(usage, &flags, &["--no-peer"]);
    let (hours, rate, repeat, no_peer) = (v[0], v[1], v[2].max(1.0) as usize, switches[0]);
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join(format!("../target/bench-data/static_{hours}h_{rate}hz"));
    let csv = dir.join("mav0/imu0/data.csv");
    if !csv.is_file() {
        println!("making {} ({hours} h at {rate} Hz) …", csv.display());
        let mut cfg =
            SimConfig { duration_s: Some(hours * 3600.0), groundtruth_rate_hz: Some(1.0), ..SimConfig::default() };
        cfg.imu.rate_hz = rate;
        if let Err(e) = simulate_and_write(Scenario::Static, &cfg, 1, &dir) {
            eprintln!("error: {e}");
            std::process::exit(1);
        }
    }
    let bytes = std::fs::metadata(&csv).map(|m| m.len()).unwrap_or(0) as f64;
    let fmt = ImuTextFormat::default();
    let mut rows = 0;
    let mut times = Vec::new();
    for i in 0..=repeat {
        let t = Instant::now();
        let rec = match read_imu_text(&csv, &fmt) {
            Ok(r) => r,
            Err(e) => {
                eprintln!("error: {e}");
                std::process::exit(1);
            }
        };
        if i > 0 {
            times.push(t.elapsed().as_secs_f64());
        }
        rows = rec.len();
    }
    let ours = median(times);
    println!(
        "tumble read_imu_text (with validation): {rows} rows, {:.0} MB in {ours:.3} s ({:.1} M rows/s, {:.0} MB/s)",
        bytes / 1e6,
        rows as f64 / ours / 1e6,
        bytes / ours / 1e6
    );
    let script = format!(
        "import time, pandas\np = {:?}\npandas.read_csv(p)\nts = []\nfor _ in range({repeat}):\n    t = time.perf_counter(); df = pandas.read_csv(p); ts.append(time.perf_counter() - t)\nts.sort(); print(ts[len(ts)//2], len(df), pandas.__version__)",
        csv.display().to_string()
    );
    if no_peer {
        return;
    }
    match Command::new("python3").arg("-c").arg(&script).output() {
        Ok(o) if o.status.success() => {
            let out = String::from_utf8_lossy(&o.stdout);
            let f: Vec<&str> = out.split_whitespace().collect();
            let theirs: f64 = f.first().and_then(|s| s.parse().ok()).unwrap_or(f64::NAN);
            println!(
                "pandas {} read_csv: {} rows in {theirs:.3} s",
                f.get(2).unwrap_or(&"?"),
                f.get(1).unwrap_or(&"?")
            );
            println!("ratio pandas / tumble: {:.2}× (target ≥ 2×)", theirs / ours);
        }
        Ok(o) => println!(
            "pandas: not measured ({}); install it with `pip install pandas`",
            String::from_utf8_lossy(&o.stderr).lines().last().unwrap_or("python3 failed")
        ),
        Err(e) => println!("pandas: not measured (python3: {e})"),
    }
}
