//! What an IMU's gyro shows in flight against a ground truth: the Allan
//! deviation of `gyro − ω_truth − b_truth` per axis, next to what the noise
//! figures of its `sensor.yaml` (else EuRoC's, the estimator's defaults)
//! predict (`√(N²/τ + K²τ/3)`).
//!
//! `cargo run --release --example imu_in_flight -- [SEQUENCE_DIR ...]`
//! (default: every sequence under `$TUMBLE_DATA/euroc/full_imu/`, docs/datasets.md).
//!
//! The error is `tumble::allan::in_motion::error_in_motion` (what `tumble
//! allan --groundtruth` analyses): the truth's rate is the rotation between
//! consecutive ground-truth poses over their interval, at its middle,
//! interpolated to the IMU's stamps; flight is from 2 s after the truth's
//! speed first exceeds 0.2 m/s to 2 s before it last does. At short τ the figure includes the ground truth's own
//! noise, differentiated; from about 0.5 s on it is the IMU's: where it lies
//! above the prediction, the IMU's error in flight is larger at that time
//! scale than the figures say, and an estimator that uses them claims biases
//! more precise than they are (`docs/vio.md`, "The bias random walk").

use std::path::PathBuf;
use tumble::allan::in_motion::error_in_motion;
use tumble::allan::{allan_deviation, AllanOptions};
use tumble::io::asl::read_asl;

/// The τ shown \[s\].
const TAUS: [f64; 8] = [0.05, 0.1, 0.2, 0.5, 1.0, 2.0, 5.0, 10.0];

/// The shortest τ of the white + walk fit \[s\]: below it the curve falls
/// as 1/τ, the signature of the ground truth's own pose noise differentiated.
const FIT_FROM_S: f64 = 0.5;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    check_the_fit()?;
    let mut dirs: Vec<PathBuf> = std::env::args().skip(1).map(PathBuf::from).collect();
    if dirs.is_empty() {
        let Some(full) = tumble::io::datasets::dataset("euroc/full_imu") else {
            return Ok(());
        };
        dirs = std::fs::read_dir(&full)
            .map(|d| d.filter_map(|e| e.ok().map(|e| e.path())).filter(|p| p.join("mav0").is_dir()).collect())
            .unwrap_or_default();
        dirs.sort();
        if dirs.is_empty() {
            println!("SKIPPED: no sequence under {}", full.display());
            return Ok(());
        }
    }
    for dir in dirs {
        let ds = read_asl(&dir, &Default::default())?;
        let gt = ds.groundtruth.as_ref().ok_or_else(|| format!("{}: no ground truth", dir.display()))?;
        if gt.bias_gyro.is_none() {
            // The residual needs the truth's bias (EuRoC's Machine Hall ground truths carry none).
            println!("{}: skipped, the ground truth has no gyro bias", dir.display());
            continue;
        }
        let (error, span) = error_in_motion(&ds.imu, gt, 9.81)?;
        let (from, to) = (span.from_s, span.to_s);
        let residual: [Vec<f64>; 3] = std::array::from_fn(|a| error.gyro.iter().map(|g| g[a]).collect());
        // The truth's rate plus its bias at the same samples.
        let truth: Vec<[f64; 3]> = ds
            .imu
            .slice_time(from, to)
            .gyro
            .iter()
            .zip(&error.gyro)
            .map(|(g, e)| std::array::from_fn(|a| g[a] - e[a]))
            .collect();
        let tau0 = (ds.imu.t[ds.imu.t.len() - 1] - ds.imu.t[0]) / (ds.imu.t.len() - 1) as f64;
        let curves = residual
            .iter()
            .map(|r| allan_deviation(r, tau0, &AllanOptions::default()))
            .collect::<Result<Vec<_>, _>>()?;
        // The sequence's sensor.yaml, else the estimator's defaults (EuRoC's
        // ADIS16448 as Kalibr publishes it).
        let sensor = ds.imu_sensor.as_ref();
        let default = tumble_factors::imu_preint::PreintegrationParams::default();
        let n = sensor.and_then(|s| s.gyroscope_noise_density).unwrap_or(default.gyro_noise_density);
        let k = sensor.and_then(|s| s.gyroscope_random_walk).unwrap_or(default.gyro_random_walk);
        let source = if sensor.is_some() { "sensor.yaml" } else { "EuRoC's figures" };
        let name = dir.file_name().unwrap_or_default().to_string_lossy();
        println!("{name}: gyro − truth in flight ({:.0} s of {:.0} s)", to - from, ds.imu.t[ds.imu.t.len() - 1]);
        println!("  {source}: white {n:.2e} rad/s/√Hz, walk {k:.2e} rad/s²/√Hz");
        println!("  τ [s]   Allan deviation x, y, z [rad/s]   the figures predict   ratio x, y, z");
        for tau in TAUS {
            let at = |c: &tumble::allan::AllanCurve| -> Option<(f64, f64)> {
                let miss = |t: f64| (t / tau).ln().abs();
                c.tau.iter().zip(&c.dev).map(|(t, d)| (*t, *d)).min_by(|a, b| miss(a.0).total_cmp(&miss(b.0)))
            };
            let Some((t_near, _)) = at(&curves[0]) else { continue };
            if (t_near / tau).ln().abs() > 0.2 {
                continue;
            }
            let dev: Vec<f64> = curves.iter().map(|c| at(c).map_or(f64::NAN, |(_, d)| d)).collect();
            let m = white_and_walk_dev(n, k, t_near);
            println!(
                "  {t_near:5.2}   {:.1e} {:.1e} {:.1e}          {m:.1e}               {:.1} {:.1} {:.1}",
                dev[0],
                dev[1],
                dev[2],
                dev[0] / m,
                dev[1] / m,
                dev[2] / m
            );
        }
        let fits: Vec<String> = curves
            .iter()
            .map(|c| {
                let (n, k) = fit_white_and_walk(c, FIT_FROM_S);
                format!("{n:.1e}, {k:.1e}")
            })
            .collect();
        println!(
            "  white + walk fitted over τ ≥ {FIT_FROM_S} s (rad/s/√Hz, rad/s²/√Hz): x {}; y {}; z {}",
            fits[0], fits[1], fits[2]
        );
        // Scale and misalignment: the error's means over 0.5 s blocks against
        // the truth's rate (and a constant), per axis.
        let (sm, rms) = scale_misalignment(&residual, &error.t, &truth);
        println!(
            "  error against the truth's rate (0.5 s means), scale x y z {:+.3} {:+.3} {:+.3} %, \
             largest misalignment {:.3} %; RMS {:.1e} → {:.1e} rad/s",
            100.0 * sm[(0, 0)],
            100.0 * sm[(1, 1)],
            100.0 * sm[(2, 2)],
            100.0 * (0..9).filter(|i| i % 4 != 0).map(|i| sm[(i / 3, i % 3)].abs()).fold(0.0, f64::max),
            rms.0,
            rms.1
        );
    }
    Ok(())
}

/// The gyro error `residual` (per axis, at the stamps `t`) averaged over
/// 0.5 s blocks and fitted as `M ω + c` against the truth's rate `truth`
/// (with its bias, which the constant takes): `M` (scale on the diagonal,
/// misalignment off it) and the blocks' RMS error before and after.
fn scale_misalignment(residual: &[Vec<f64>; 3], t: &[f64], truth: &[[f64; 3]]) -> (nalgebra::Matrix3<f64>, (f64, f64)) {
    let per_block = ((0.5 / ((t[t.len() - 1] - t[0]) / (t.len() - 1) as f64)).round() as usize).max(1);
    let mut rows: Vec<([f64; 4], [f64; 3])> = Vec::new();
    for (b, chunk) in truth.chunks(per_block).enumerate().filter(|(_, c)| c.len() == per_block) {
        let i0 = b * per_block;
        let mean = |f: &dyn Fn(usize) -> f64| (0..chunk.len()).map(f).sum::<f64>() / chunk.len() as f64;
        let w: [f64; 3] = std::array::from_fn(|a| mean(&|k| chunk[k][a]));
        let e: [f64; 3] = std::array::from_fn(|a| mean(&|k| residual[a][i0 + k]));
        rows.push(([w[0], w[1], w[2], 1.0], e));
    }
    let x = nalgebra::DMatrix::from_fn(rows.len(), 4, |i, j| rows[i].0[j]);
    let mut m = nalgebra::Matrix3::zeros();
    let (mut before, mut after) = (0.0, 0.0);
    for a in 0..3 {
        let y = nalgebra::DVector::from_fn(rows.len(), |i, _| rows[i].1[a]);
        let beta = x.clone().svd(true, true).solve(&y, 1e-12).unwrap_or_else(|_| nalgebra::DVector::zeros(4));
        for c in 0..3 {
            m[(a, c)] = beta[c];
        }
        before += y.norm_squared();
        after += (&y - &x * &beta).norm_squared();
    }
    let n = (3 * rows.len()).max(1) as f64;
    (m, ((before / n).sqrt(), (after / n).sqrt()))
}

/// The fit on a simulated series of known white density and walk (10 min
/// at 200 Hz): each is recovered within 30 % (the curve's own scatter at
/// the longest τ, and the grid's 26 % steps), or the program fails.
fn check_the_fit() -> Result<(), String> {
    use rand::SeedableRng;
    use rand_distr::{Distribution, StandardNormal};
    let (n, k, dt): (f64, f64, f64) = (1e-3, 2e-4, 0.005);
    let mut rng = rand::rngs::StdRng::seed_from_u64(1);
    let mut bias = 0.0;
    let y: Vec<f64> = (0..120_000)
        .map(|_| {
            let (w, v): (f64, f64) = (StandardNormal.sample(&mut rng), StandardNormal.sample(&mut rng));
            bias += k * dt.sqrt() * w;
            bias + n / dt.sqrt() * v
        })
        .collect();
    let curve = allan_deviation(&y, dt, &AllanOptions::default()).map_err(|e| e.to_string())?;
    let (nf, kf) = fit_white_and_walk(&curve, FIT_FROM_S);
    if (nf / n - 1.0).abs() > 0.3 || (kf / k - 1.0).abs() > 0.3 {
        return Err(format!("the white + walk fit on a simulated series: {nf:.2e}, {kf:.2e} against {n:.0e}, {k:.0e}"));
    }
    println!("fit check (simulated, white {n:.0e}, walk {k:.0e}): {nf:.2e}, {kf:.2e}");
    Ok(())
}

/// The white density `N` and random walk `K` whose deviation
/// `√(N²/τ + K²τ/3)` fits the curve's `ln σ` best (least squares) over
/// τ ≥ `from` — a grid search, 10 steps per decade.
fn fit_white_and_walk(c: &tumble::allan::AllanCurve, from: f64) -> (f64, f64) {
    let pts: Vec<(f64, f64)> = c.tau.iter().zip(&c.dev).filter(|(t, _)| **t >= from).map(|(t, d)| (*t, *d)).collect();
    let grid = |lo: i32, hi: i32| (lo..=hi).map(|i| 10f64.powf(i as f64 / 10.0));
    let mut best = (f64::INFINITY, 0.0, 0.0);
    for n in grid(-70, -10) {
        for k in grid(-80, -10) {
            let cost: f64 = pts.iter().map(|(t, d)| (white_and_walk_dev(n, k, *t) / d).ln().powi(2)).sum();
            if cost < best.0 {
                best = (cost, n, k);
            }
        }
    }
    (best.1, best.2)
}

/// The Allan deviation of white noise `n` and a random walk `k` at `tau`,
/// from the allan module's term basis (`√(N²/τ + K²τ/3)`).
fn white_and_walk_dev(n: f64, k: f64, tau: f64) -> f64 {
    let b = tumble::allan::identify::basis(tau);
    (n * n * b[1] + k * k * b[3]).sqrt()
}
