//! Simulation speed: 4 hours of a static 200 Hz IMU with the full default
//! error model (BMI055), simulated and written as an ASL folder, against the
//! issue's 2 s target and against the usual Python way (numpy white noise and
//! random walk, quantized, written with pandas `to_csv`), on the same machine.
//!
//! ```sh
//! pip install numpy pandas   # the peer
//! cargo run --release -p tumble-bench --example bench_sim -- [--hours 4] [--repeat 3] [--no-peer]
//! ```

use std::path::PathBuf;
use std::process::Command;
use std::time::Instant;
use tumble::sim::{simulate_and_write, Scenario, SimConfig};

fn main() {
    let usage = "usage: bench_sim [--hours H (4)] [--repeat N (3)] [--no-peer]";
    let (v, switches) = tumble_bench::args_with_switches(usage, &[("--hours", 4.0), ("--repeat", 3.0)], &["--no-peer"]);
    let (hours, repeat, no_peer) = (v[0], v[1].max(1.0) as usize, switches[0]);
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../target/bench-data/sim");
    let cfg = SimConfig { duration_s: Some(hours * 3600.0), ..SimConfig::default() };
    let mut times = Vec::new();
    let mut rows = 0;
    for r in 0..repeat {
        let out = root.join(format!("run{r}"));
        let _ = std::fs::remove_dir_all(&out);
        let t = Instant::now();
        match simulate_and_write(Scenario::Static, &cfg, 1, &out) {
            Ok(sim) => rows = sim.imu.t.len(),
            Err(e) => {
                eprintln!("error: {e}");
                std::process::exit(1);
            }
        }
        times.push(t.elapsed().as_secs_f64());
    }
    times.sort_by(f64::total_cmp);
    let ours = times[times.len() / 2];
    let csv = root.join("run0/mav0/imu0/data.csv");
    let bytes = std::fs::metadata(&csv).map(|m| m.len()).unwrap_or(0) as f64;
    println!(
        "tumble sim static ({hours} h, 200 Hz, full BMI055 model): {rows} rows, {:.0} MB written in {ours:.3} s (median of {repeat}; target < 2 s for 4 h)",
        bytes / 1e6
    );
    if no_peer {
        return;
    }
    let out = root.join("python.csv");
    let script = format!(
        "import time, numpy as np, pandas as pd\n\
         n = int({hours} * 3600 * 200) + 1; dt = 1 / 200\n\
         t = time.perf_counter()\n\
         rng = np.random.default_rng(1)\n\
         N = np.array([1.05e-3, 1.06e-3, 5.25e-3, 0.0191, 0.0177, 0.0428]); K = np.array([2e-5] * 3 + [3e-4] * 3)\n\
         x = rng.standard_normal((n, 6)) * N / np.sqrt(dt) + np.cumsum(rng.standard_normal((n, 6)) * K * np.sqrt(dt), axis=0)\n\
         x[:, 5] += 9.81\n\
         lsb = np.array([1.065e-3] * 3 + [1.916e-2] * 3); x = np.round(x / lsb) * lsb\n\
         df = pd.DataFrame(x, columns=['wx', 'wy', 'wz', 'ax', 'ay', 'az'])\n\
         df.insert(0, 't', 1700000000000000000 + np.arange(n, dtype=np.int64) * 5000000)\n\
         df.to_csv({:?}, index=False, float_format='%.9f')\n\
         print(time.perf_counter() - t)",
        out.display().to_string()
    );
    match Command::new("python3").arg("-c").arg(&script).output() {
        Ok(o) if o.status.success() => {
            let theirs: f64 = String::from_utf8_lossy(&o.stdout).trim().parse().unwrap_or(f64::NAN);
            println!("numpy + pandas.to_csv (white noise, random walk, quantization only): {theirs:.3} s");
            println!("ratio python / tumble: {:.1}×", theirs / ours);
        }
        Ok(o) => println!(
            "python peer: not measured ({}); install with `pip install numpy pandas`",
            String::from_utf8_lossy(&o.stderr).lines().last().unwrap_or("python3 failed")
        ),
        Err(e) => println!("python peer: not measured (python3: {e})"),
    }
    let _ = std::fs::remove_file(&out);
}
