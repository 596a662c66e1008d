//! Results of a VIO run: the summary figures (drift, IMU-only drift, ATE, bias
//! errors, speed) and the files `tumble vio` writes.

use super::geometry::preintegrate;
use super::{FrameEstimate, VioInput, VioOptions, VioResult};
use crate::io::trajectory::{write_tum, Trajectory};
use nalgebra::{UnitQuaternion, Vector3};
use serde::Serialize;
use std::path::{Path, PathBuf};

/// The figures of one run (`summary.json`).
#[derive(Debug, Clone, Serialize)]
pub struct Summary {
    /// Data duration from initialization to the last frame \[s\].
    pub duration_s: f64,
    /// Length of the estimated path \[m\].
    pub distance_m: f64,
    /// Distance between the last and the first estimated position \[m\].
    pub closed_loop_error_m: f64,
    /// The same for IMU-only dead reckoning from the initial state \[m\].
    pub imu_only_closed_loop_error_m: f64,
    /// Whether the ground truth returns to its start (within 5 cm), when known.
    pub returns_to_start: Option<bool>,
    /// Data time / wall time of the estimator.
    pub realtime_factor: f64,
    /// Frames estimated, keyframes among them.
    pub frames: usize,
    /// Keyframes.
    pub keyframes: usize,
    /// Failure resets.
    pub resets: usize,
    /// Median per-frame solve time \[ms\].
    pub solve_ms_median: f64,
    /// 95th percentile per-frame solve time \[ms\].
    pub solve_ms_p95: f64,
    /// ATE RMSE after position + yaw alignment \[m\] (with ground truth).
    pub ate_rmse_m: Option<f64>,
    /// Gyro bias RMSE against the ground truth, after `bias_rmse_from_s` \[rad/s\].
    pub bias_rmse_gyro: Option<f64>,
    /// Accelerometer bias RMSE against the ground truth, after `bias_rmse_from_s` \[m/s²\].
    pub bias_rmse_accel: Option<f64>,
    /// Start of the bias RMSE window \[s\] (convergence time skipped).
    pub bias_rmse_from_s: f64,
    /// Warnings of the run.
    pub warnings: Vec<String>,
}

fn percentile(v: &mut [f64], p: f64) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(|a, b| a.total_cmp(b));
    v[((v.len() - 1) as f64 * p).round() as usize]
}

/// Ground truth at time `t` \[s since t0\]: position (linear interpolation),
/// rotation (nearest), biases (nearest); None outside its span.
#[allow(clippy::type_complexity)]
fn truth_at(
    gt: &Trajectory,
    t0_ns: i64,
    t: f64,
) -> Option<(Vector3<f64>, [f64; 4], Option<[f64; 3]>, Option<[f64; 3]>)> {
    let ns = t0_ns as f64 + t * 1e9;
    let k = gt.t_ns.partition_point(|&s| (s as f64) < ns);
    if k == 0 || k >= gt.len() {
        if k < gt.len() && (gt.t_ns[k] as f64 - ns).abs() < 1e6 {
            let p = Vector3::from(gt.p[k]);
            return Some((p, gt.q[k], gt.bias_gyro.as_ref().map(|b| b[k]), gt.bias_accel.as_ref().map(|b| b[k])));
        }
        return None;
    }
    let (a, b) = (gt.t_ns[k - 1] as f64, gt.t_ns[k] as f64);
    if b - a > 0.2e9 {
        return None;
    }
    let w = (ns - a) / (b - a);
    let p = Vector3::from(gt.p[k - 1]) * (1.0 - w) + Vector3::from(gt.p[k]) * w;
    let n = if w < 0.5 { k - 1 } else { k };
    Some((p, gt.q[n], gt.bias_gyro.as_ref().map(|b| b[n]), gt.bias_accel.as_ref().map(|b| b[n])))
}

/// Position + yaw alignment (4 DOF, the gauge of VIO) of `est` onto `gt`;
/// returns the RMSE of the aligned positions \[m\].
pub fn ate_posyaw(est: &[Vector3<f64>], gt: &[Vector3<f64>]) -> f64 {
    let n = est.len() as f64;
    let ce: Vector3<f64> = est.iter().sum::<Vector3<f64>>() / n;
    let cg: Vector3<f64> = gt.iter().sum::<Vector3<f64>>() / n;
    let (mut s, mut c) = (0.0, 0.0);
    for (e, g) in est.iter().zip(gt) {
        let (e, g) = (e - ce, g - cg);
        s += e.x * g.y - e.y * g.x;
        c += e.x * g.x + e.y * g.y;
    }
    let yaw = s.atan2(c);
    let r = nalgebra::Rotation3::from_axis_angle(&Vector3::z_axis(), yaw);
    let se: f64 = est.iter().zip(gt).map(|(e, g)| (r * (e - ce) + cg - g).norm_squared()).sum();
    (se / n).sqrt()
}

/// IMU-only dead reckoning from the first estimate to the last frame time:
/// end position \[m\] with the initial bias held.
fn imu_only_end(input: &VioInput, opts: &VioOptions, first: &FrameEstimate, t_end: f64) -> Vector3<f64> {
    let bias = (Vector3::from(first.bias_accel), Vector3::from(first.bias_gyro));
    let (pim, _) = preintegrate(&input.imu, first.t, t_end, bias, opts.imu);
    let q = first.rotation;
    let r = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(q[0], q[1], q[2], q[3])).to_rotation_matrix();
    let g = Vector3::new(0.0, 0.0, -opts.gravity);
    let dt = pim.delta_t();
    Vector3::from(first.position) + Vector3::from(first.velocity) * dt + g * (0.5 * dt * dt) + r * pim.delta_position()
}

/// The summary figures of a run; biases are compared from `bias_from_s`
/// seconds after initialization on.
pub fn summarize(input: &VioInput, opts: &VioOptions, result: &VioResult, bias_from_s: f64) -> Summary {
    let e = &result.estimates;
    let first = e.first();
    let duration_s = match (first, e.last()) {
        (Some(a), Some(b)) => b.t - a.t,
        _ => 0.0,
    };
    let pos: Vec<Vector3<f64>> = e.iter().map(|x| Vector3::from(x.position)).collect();
    let distance_m = pos.windows(2).map(|w| (w[1] - w[0]).norm()).sum();
    let closed_loop_error_m = match (pos.first(), pos.last()) {
        (Some(a), Some(b)) => (b - a).norm(),
        _ => f64::NAN,
    };
    let imu_only_closed_loop_error_m = match (first, e.last()) {
        (Some(a), Some(b)) => (imu_only_end(input, opts, a, b.t) - Vector3::from(a.position)).norm(),
        _ => f64::NAN,
    };
    let mut solve: Vec<f64> = e.iter().map(|x| x.solve_s * 1e3).collect();
    let (mut ate, mut bg_rmse, mut ba_rmse, mut returns) = (None, None, None, None);
    let t_from = first.map_or(0.0, |f| f.t) + bias_from_s;
    if let Some(gt) = &input.groundtruth {
        let (mut pe, mut pg) = (Vec::new(), Vec::new());
        let (mut sg, mut sa, mut nb) = (0.0, 0.0, 0usize);
        for x in e {
            if let Some((p, _, bgt, bat)) = truth_at(gt, input.t0_ns, x.t) {
                pe.push(Vector3::from(x.position));
                pg.push(p);
                if let (Some(bgt), Some(bat), true) = (bgt, bat, x.t >= t_from) {
                    sg += (Vector3::from(x.bias_gyro) - Vector3::from(bgt)).norm_squared();
                    sa += (Vector3::from(x.bias_accel) - Vector3::from(bat)).norm_squared();
                    nb += 1;
                }
            }
        }
        if pe.len() >= 3 {
            ate = Some(ate_posyaw(&pe, &pg));
            returns = Some((pg[0] - pg[pg.len() - 1]).norm() < 0.05);
        }
        if nb > 0 {
            bg_rmse = Some((sg / nb as f64).sqrt());
            ba_rmse = Some((sa / nb as f64).sqrt());
        }
    }
    Summary {
        duration_s,
        distance_m,
        closed_loop_error_m,
        imu_only_closed_loop_error_m,
        returns_to_start: returns,
        realtime_factor: if result.wall_s > 0.0 { duration_s / result.wall_s } else { f64::INFINITY },
        frames: e.len(),
        keyframes: e.iter().filter(|x| x.keyframe).count(),
        resets: result.resets,
        solve_ms_median: percentile(&mut solve, 0.5),
        solve_ms_p95: percentile(&mut solve, 0.95),
        ate_rmse_m: ate,
        bias_rmse_gyro: bg_rmse,
        bias_rmse_accel: ba_rmse,
        bias_rmse_from_s: t_from,
        warnings: result.warnings.clone(),
    }
}

impl Summary {
    /// A few lines for the terminal.
    pub fn table(&self) -> String {
        let opt = |v: Option<f64>, unit: &str| v.map_or("—".to_string(), |x| format!("{x:.4} {unit}"));
        format!(
            "duration {:.1} s, path {:.2} m, {} frames ({} keyframes), {} resets\n\
             closed-loop error: fused {:.3} m ({:.3} % of the path) vs IMU only {:.3} m\n\
             ATE (position+yaw aligned) {}\n\
             bias RMSE after {:.1} s: gyro {}, accel {}\n\
             speed: {:.1}× real time; per-frame solve median {:.2} ms, 95th percentile {:.2} ms",
            self.duration_s,
            self.distance_m,
            self.frames,
            self.keyframes,
            self.resets,
            self.closed_loop_error_m,
            100.0 * self.closed_loop_error_m / self.distance_m.max(1e-9),
            self.imu_only_closed_loop_error_m,
            opt(self.ate_rmse_m, "m"),
            self.bias_rmse_from_s,
            opt(self.bias_rmse_gyro, "rad/s"),
            opt(self.bias_rmse_accel, "m/s²"),
            self.realtime_factor,
            self.solve_ms_median,
            self.solve_ms_p95,
        )
    }
}

/// Write `trajectory.txt` (TUM), `biases.csv` and `summary.json` into `dir`.
pub fn write_outputs(
    dir: &Path,
    input: &VioInput,
    result: &VioResult,
    summary: &Summary,
) -> Result<Vec<PathBuf>, String> {
    std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let e = &result.estimates;
    let tr = Trajectory {
        t_ns: e.iter().map(|x| input.t0_ns + (x.t * 1e9).round() as i64).collect(),
        p: e.iter().map(|x| x.position).collect(),
        q: e.iter().map(|x| x.rotation).collect(),
        ..Default::default()
    };
    let traj = dir.join("trajectory.txt");
    write_tum(&traj, &tr).map_err(|e| e.to_string())?;
    let mut csv = String::from(
        "#timestamp [ns],b_a_x [m/s^2],b_a_y,b_a_z,b_g_x [rad/s],b_g_y,b_g_z,std_b_a_x,std_b_a_y,std_b_a_z,std_b_g_x,std_b_g_y,std_b_g_z,keyframe\n",
    );
    for x in e {
        let s = &x.std;
        csv.push_str(&format!(
            "{},{},{},{},{},{},{},{},{},{},{},{},{},{}\n",
            input.t0_ns + (x.t * 1e9).round() as i64,
            x.bias_accel[0],
            x.bias_accel[1],
            x.bias_accel[2],
            x.bias_gyro[0],
            x.bias_gyro[1],
            x.bias_gyro[2],
            s[3][0],
            s[3][1],
            s[3][2],
            s[4][0],
            s[4][1],
            s[4][2],
            u8::from(x.keyframe)
        ));
    }
    let biases = dir.join("biases.csv");
    std::fs::write(&biases, csv).map_err(|e| format!("{}: {e}", biases.display()))?;
    let sj = dir.join("summary.json");
    let text = serde_json::to_string_pretty(summary).map_err(|e| e.to_string())?;
    std::fs::write(&sj, text).map_err(|e| format!("{}: {e}", sj.display()))?;
    Ok(vec![traj, biases, sj])
}
