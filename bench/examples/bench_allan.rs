//! Allan-deviation speed: tumble against `allantools.oadev` (PyPI) on the same
//! data and request — 3 M samples × 6 axes (BMI055-like gyro and
//! accelerometer noise), 1000 log-spaced τ from τ0 to 10⁶·τ0 (762 distinct
//! cluster sizes) — plus the memory-streaming floor of the straightforward
//! O(N)-per-τ method on this machine.
//!
//! ```sh
//! pip install allantools   # the peer
//! cargo run --release -p tumble-bench --example bench_allan -- [--samples 3000000] [--taus 1000] [--repeat 5] [--peer-axes 6] [--no-peer]
//! ```
//! tumble's time includes what allantools does not compute: noise
//! identification and Greenhall confidence intervals at every τ.

use std::path::PathBuf;
use std::process::Command;
use std::time::Instant;
use tumble::allan::{allan_deviation_axes, AllanOptions, DeviationKind, TauGrid};
use tumble::sim::{noise_series, AxisNoise, ImuModel};
use tumble_bench::{median, peak_rss_mb};

/// Read bandwidth of this machine \[bytes/s\]: summing a 512 MiB array (best of 3).
fn read_bandwidth() -> f64 {
    let n = 64 << 20;
    let v: Vec<f64> = (0..n).map(|i| i as f64).collect();
    let mut best = f64::INFINITY;
    let mut sink = 0.0;
    for _ in 0..3 {
        let t = Instant::now();
        // Eight independent accumulators so the adds do not serialize.
        let mut acc = [0.0f64; 8];
        for c in v.chunks_exact(8) {
            for k in 0..8 {
                acc[k] += c[k];
            }
        }
        sink += acc.iter().sum::<f64>();
        best = best.min(t.elapsed().as_secs_f64());
    }
    std::hint::black_box(sink);
    (n * 8) as f64 / best
}

/// Resident memory now \[MB\].
fn current_rss_mb() -> f64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines().find(|l| l.starts_with("VmRSS:")).and_then(|l| l.split_whitespace().nth(1)?.parse::<f64>().ok())
        })
        .map_or(f64::NAN, |kb| kb / 1024.0)
}

fn main() {
    // As the `tumble` binary does: large buffers always mmap'd, so memory
    // freed between axes goes back to the system (glibc otherwise raises its
    // mmap threshold after the first free and keeps the heap).
    #[cfg(target_os = "linux")]
    // SAFETY: called before any other thread exists; only tunes the allocator.
    unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, 1 << 20);
    }
    let usage =
        "usage: bench_allan [--samples N (3000000)] [--taus N (1000)] [--repeat N (5)] [--peer-axes N (6)] [--no-peer]";
    let flags = [("--samples", 3e6), ("--taus", 1000.0), ("--repeat", 5.0), ("--peer-axes", 6.0)];
    let (v, switches) = tumble_bench::args_with_switches(usage, &flags, &["--no-peer"]);
    let (n, n_taus) = (v[0] as usize, v[1] as usize);
    let (repeat, peer_axes) = (v[2].max(1.0) as usize, (v[3] as usize).clamp(1, 6));
    let no_peer = switches[0];
    let rate = 200.0;
    let tau0 = 1.0 / rate;

    // Six axes with the default model's noise (gyro rad/s, accel m/s²).
    let model = ImuModel::bmi055();
    let axes: Vec<Vec<f64>> = (0..6)
        .map(|k| {
            let t = if k < 3 { &model.gyro } else { &model.accel };
            let spec = AxisNoise {
                noise_density: t.noise_density[k % 3],
                random_walk: t.random_walk[k % 3],
                bias_instability: t.bias_instability[k % 3],
                bias_instability_band: t.bias_instability_band,
                angle_quantization: 0.0,
            };
            noise_series(&spec, rate, n, 7 + k as u64)
        })
        .collect();
    let taus: Vec<f64> = (0..n_taus).map(|i| tau0 * 10f64.powf(6.0 * i as f64 / (n_taus - 1) as f64)).collect();
    let opts = AllanOptions {
        kind: DeviationKind::Oadev,
        taus: TauGrid::Explicit(taus.clone()),
        max_tau_fraction: 1.0,
        confidence: 0.683,
    };
    let distinct = tumble::allan::cluster_sizes(&opts.taus, n, tau0, opts.kind, 1.0);
    println!(
        "{n} samples × 6 axes at {rate} Hz, {n_taus} requested log-spaced τ ({} distinct cluster sizes, m ≤ {})",
        distinct.len(),
        distinct.last().copied().unwrap_or(0)
    );

    // Reset the peak-RSS mark (Linux ≥ 4.0) so the peak below is the Allan run's.
    let _ = std::fs::write("/proc/self/clear_refs", "5");
    let rss_before = current_rss_mb();
    let mut times = Vec::new();
    let mut curves = Vec::new();
    for _ in 0..repeat {
        let t = Instant::now();
        let refs: Vec<&[f64]> = axes.iter().map(|a| a.as_slice()).collect();
        curves = allan_deviation_axes(&refs, tau0, &opts, &|| {}).expect("valid input");
        times.push(t.elapsed().as_secs_f64());
    }
    let ours = median(&mut times);
    let input_mb = (6 * n * 8) as f64 / (1024.0 * 1024.0);
    let working = peak_rss_mb() - rss_before;
    println!("tumble: {ours:.3} s for 6 axes (median of {repeat}; with noise identification and intervals)");
    println!(
        "working memory: peak {working:.0} MB above the {rss_before:.0} MB held before (the six axes: {input_mb:.0} MB) = {:.2}× the data",
        working / input_mb
    );

    // The floor of any O(N)-per-τ method: one pass over the phase per τ.
    let bw = read_bandwidth();
    let bytes: f64 = 6.0 * distinct.iter().map(|&m| 8.0 * (n + 1 - 2 * m) as f64).sum::<f64>();
    println!(
        "memory-streaming floor of the O(N)-per-τ method: {:.1} GB read ÷ {:.1} GB/s = {:.2} s; tumble is {:.1}× below that floor (it shares the work across τ through one FFT per axis)",
        bytes / 1e9,
        bw / 1e9,
        bytes / bw,
        bytes / bw / ours
    );
    if no_peer {
        println!("allantools: not run (--no-peer)");
        return;
    }
    allantools(&axes, &taus, rate, peer_axes, &curves, ours);
}

/// allantools.oadev on the first `peer_axes` of `axes` at the same `taus`:
/// its time, its agreement with tumble's `curves`, and the ratio to
/// tumble's time `ours` \[s\].
fn allantools(
    axes: &[Vec<f64>],
    taus: &[f64],
    rate: f64,
    peer_axes: usize,
    curves: &[tumble::allan::AllanCurve],
    ours: f64,
) {
    let n = axes[0].len();
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../target/bench-data");
    std::fs::create_dir_all(&dir).expect("target dir writable");
    let path = dir.join(format!("allan_{n}x6.f64"));
    let mut raw = Vec::with_capacity(6 * n * 8);
    for y in axes {
        for v in y {
            raw.extend_from_slice(&v.to_le_bytes());
        }
    }
    std::fs::write(&path, raw).expect("write bench data");
    let script = format!(
        r#"
import json, time, numpy as np, allantools
d = np.fromfile("{path}", dtype="<f8").reshape(6, {n})
taus = np.array({taus:?})
t = time.perf_counter()
res = [allantools.oadev(d[k], rate={rate}, data_type="freq", taus=taus) for k in range({peer_axes})]
el = time.perf_counter() - t
print(json.dumps({{"seconds": el, "taus": list(res[0][0]), "devs": [list(r[1]) for r in res]}}))
"#,
        path = path.display(),
    );
    println!("running allantools.oadev on {peer_axes} axis/axes (single-threaded numpy; the issue measured ≈ 22 s per axis on its machine) …");
    match Command::new("python3").arg("-c").arg(&script).output() {
        Ok(o) if o.status.success() => {
            let v: serde_json::Value = match serde_json::from_slice(&o.stdout) {
                Ok(v) => v,
                Err(e) => {
                    println!("allantools: unreadable output ({e})");
                    return;
                }
            };
            let peer = v["seconds"].as_f64().unwrap_or(f64::NAN);
            let peer6 = peer * 6.0 / peer_axes as f64;
            // Agreement of the numbers, all measured axes.
            let mut worst: f64 = 0.0;
            for (k, devs) in v["devs"].as_array().into_iter().flatten().enumerate() {
                for (i, d) in devs.as_array().into_iter().flatten().enumerate() {
                    let theirs = d.as_f64().unwrap_or(f64::NAN);
                    worst = worst.max((curves[k].dev[i] - theirs).abs() / theirs);
                }
            }
            println!(
                "allantools.oadev: {peer:.2} s for {peer_axes} axis/axes{}; results agree with tumble to {worst:.1e} relative",
                if peer_axes < 6 { format!(" (→ {peer6:.1} s for 6 axes, scaled)") } else { String::new() }
            );
            println!("ratio allantools / tumble = {:.0}× (target ≥ 50×)", peer6 / ours);
        }
        Ok(o) => println!(
            "allantools: not measured ({}); install it with `pip install allantools`",
            String::from_utf8_lossy(&o.stderr).lines().last().unwrap_or("python3 failed")
        ),
        Err(e) => println!("allantools: not measured (python3: {e})"),
    }
}
