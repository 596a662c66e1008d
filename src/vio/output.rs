//! Results of a VIO run: the summary figures (drift, IMU-only drift, ATE, bias
//! errors, speed) and the files `tumble vio` writes.

use super::VioError;
use super::{FrameEstimate, VioInput, VioOptions, VioResult};
use crate::eval::{evaluate, write_report, Alignment, EvalOptions, Evaluation};
use crate::io::biases::{write_biases, BiasTrack};
use crate::io::trajectory::{write_tum, Trajectory};
use crate::model::geometry::preintegrate;
use crate::model::numeric::percentile;
use nalgebra::{UnitQuaternion, Vector3};
use serde::Serialize;
use std::path::{Path, PathBuf};

/// The figures of one run (`summary.json`).
#[derive(Debug, Clone, Serialize)]
pub struct Summary {
    /// Data duration from initialization to the last frame \[s\].
    pub duration_s: f64,
    /// Length of the estimated path \[m\], through positions at least
    /// `PATH_STEP_M` apart.
    pub distance_m: f64,
    /// Length of the ground-truth path over the matched frames \[m\], when
    /// known.
    pub groundtruth_distance_m: Option<f64>,
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
    /// Times \[s\] at which the trajectory begins in a frame of its own
    /// ([`VioResult::starts`]); more than one: it is in pieces.
    pub starts: Vec<f64>,
    /// The recording's clock (`trajectory.txt`'s first column) at 0 in this
    /// summary's times \[s\].
    pub clock_t0_s: f64,
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
    /// The gyro bias's steady-state std per axis that the noise coefficients
    /// in use at the end predict, `√(N·K)` \[rad/s\] (see `allan_steady_std`).
    pub bias_allan_std_gyro: f64,
    /// The same for the accelerometer bias \[m/s²\].
    pub bias_allan_std_accel: f64,
    /// Measurement residuals at their final estimates and their gap
    /// χ²/dof − 1 (the model-discrepancy audit's figure for a VIO run).
    pub residuals: super::ResidualTally,
    /// `residuals.gap()`.
    pub residual_gap: f64,
    /// The IMU white noise given, measured and in use (with
    /// [`super::NoiseOptions::measure_in_motion`]).
    pub noise: Option<super::noise_meter::NoiseReport>,
    /// The camera's online calibration at the end (with [`super::CameraCalibrationOptions`]).
    pub camera: Option<super::CameraEstimate>,
    /// How well the keyframe windows knew their own length (the scale they
    /// carry), and against a ground truth whether they were right to.
    pub window_length: Option<super::window_scale::WindowScale>,
    /// Time with fewer than `super::estimator::BLIND_FEATURES` features per
    /// frame, the IMU alone carrying the estimate \[s\].
    pub blind_s: f64,
    /// The longest such span \[s\].
    pub blind_longest_s: f64,
    /// Warnings of the run.
    pub warnings: Vec<String>,
    /// The evaluation against the ground truth (written to `eval/`), when known.
    #[serde(skip)]
    pub evaluation: Option<Evaluation>,
}

/// Shortest step \[m\] of the path the estimated distance is measured along.
/// Summed frame to frame, the estimate's millimetre jitter makes a 6-minute
/// walk's 38.5 m path 59.9 m long; through positions at least 2 cm apart it is
/// 39.9 m (the ground truth's own is 38.3 m at that step), and a 2-minute
/// walk's 38.8 m path measures 38.7 m instead of 40.5 m.
pub const PATH_STEP_M: f64 = 0.02;

/// Length \[m\] of the path through `positions`, taking a position only once
/// it lies `min_step_m` or more from the last one taken; the last position
/// always closes the path.
fn path_length(positions: impl IntoIterator<Item = Vector3<f64>>, min_step_m: f64) -> f64 {
    let mut it = positions.into_iter();
    let Some(mut taken) = it.next() else { return 0.0 };
    let (mut length, mut last) = (0.0, taken);
    for p in it {
        last = p;
        if (p - taken).norm() >= min_step_m {
            length += (p - taken).norm();
            taken = p;
        }
    }
    length + (last - taken).norm()
}

/// Steady-state std \[unit\] per axis of a bias that walks randomly with
/// coefficient `k` \[unit/√s\] and is observed through white noise of density
/// `n` \[unit/√Hz\]: the stationary solution of the scalar Kalman–Bucy
/// Riccati equation `0 = k² − P²/n²`, `P = n k`, so `σ = √(n k)`. It is the
/// best any estimator does with those Allan coefficients (an estimator that
/// sees the bias only through the motion does worse), and the yardstick
/// for the bias RMSE after convergence (≤ 2× this).
pub fn allan_steady_std(n: f64, k: f64) -> f64 {
    (n * k).sqrt()
}

/// The warning a run whose noise meter raised the white noise gets, naming
/// the two causes: errors of the IMU the estimator is not given (an
/// uncalibrated scale or misalignment: on a simulated flight of the BMI055
/// model the meter reads the gyro ×4.9 with them and ×0.9 without), or a
/// platform that shakes its IMU beyond the figures given — the biases then also
/// wander more, over seconds, than the random walk given allows (on EuRoC's
/// flights the gyro's slow error is 5–18× what the datasheet's walk allows
/// over 2–10 s, [`crate::allan::in_motion`]), and the bias σ then come out
/// too small; the biases are written all the same, with this warning. None
/// when the noise in use is the noise given.
pub fn slow_error_warning(noise: &super::noise_meter::NoiseReport) -> Option<String> {
    let ratio = [noise.in_use[0] / noise.given[0], noise.in_use[1] / noise.given[1]];
    (ratio[0] > 1.0 || ratio[1] > 1.0).then(|| {
        format!(
            "the IMU's white noise in motion was raised beyond the figures given (gyro ×{:.1}, accelerometer ×{:.1}). \
             Either the IMU has errors the estimator is not given — an uncalibrated scale or misalignment grows with \
             the motion (tumble calibrate, then --calibration) — or the platform shakes it: that also makes its biases \
             wander more than the random walk given allows, and the bias σ may then be several times too small \
             (EuRoC: 3–10×); give the noise the platform shows in use (tumble allan --groundtruth on a recording with \
             a motion capture, then --noise; docs/vio.md, \"Given the noise its IMU shows in flight\")",
            ratio[0], ratio[1]
        )
    })
}

/// IMU-only dead reckoning from the first estimate to the last frame time:
/// end position \[m\] with the initial bias held.
fn imu_only_end(input: &VioInput, opts: &VioOptions, first: &FrameEstimate, t_end: f64) -> Vector3<f64> {
    let bias = (Vector3::from(first.bias_accel), Vector3::from(first.bias_gyro));
    let (pim, _) = preintegrate(&input.imu, first.t, t_end, bias, opts.noise.imu);
    let q = first.rotation;
    let r = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(q[0], q[1], q[2], q[3])).to_rotation_matrix();
    let g = Vector3::new(0.0, 0.0, -opts.noise.gravity);
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
    let distance_m = path_length(pos.iter().copied(), PATH_STEP_M);
    let closed_loop_error_m = match (pos.first(), pos.last()) {
        (Some(a), Some(b)) => (b - a).norm(),
        _ => f64::NAN,
    };
    let imu_only_closed_loop_error_m = match (first, e.last()) {
        (Some(a), Some(b)) => (imu_only_end(input, opts, a, b.t) - Vector3::from(a.position)).norm(),
        _ => f64::NAN,
    };
    let mut solve: Vec<f64> = e.iter().map(|x| x.solve_s * 1e3).collect();
    let mut warnings = result.warnings.clone();
    warnings.extend(result.noise.as_ref().and_then(slow_error_warning));
    let evaluation = input.groundtruth.as_ref().and_then(|gt| {
        let opts = EvalOptions {
            alignment: Alignment::PosYaw,
            bias_after_s: bias_from_s,
            piece_starts_s: piece_starts_s(input, result),
            ..EvalOptions::default()
        };
        evaluate(&trajectory(input, result), Some(&bias_track(input, result)), gt, &opts)
            .map_err(|err| warnings.push(format!("evaluation against the ground truth: {err}")))
            .ok()
    });
    let m = evaluation.as_ref().map(|ev| &ev.metrics);
    let returns = evaluation.as_ref().map(|ev| {
        let (a, b) = (ev.pairs[0].gt.translation.vector, ev.pairs[ev.pairs.len() - 1].gt.translation.vector);
        (a - b).norm() < 0.05
    });
    // The white noise in use at the end (measured in motion, or as given).
    let in_use =
        result.noise.map_or([opts.noise.imu.gyro_noise_density, opts.noise.imu.accel_noise_density], |n| n.in_use);
    Summary {
        duration_s,
        distance_m,
        groundtruth_distance_m: m.map(|m| m.distance_m),
        closed_loop_error_m,
        imu_only_closed_loop_error_m,
        returns_to_start: returns,
        realtime_factor: if result.wall_s > 0.0 { duration_s / result.wall_s } else { f64::INFINITY },
        frames: e.len(),
        keyframes: e.iter().filter(|x| x.keyframe).count(),
        resets: result.resets,
        starts: result.starts.clone(),
        clock_t0_s: input.t0_ns as f64 * 1e-9,
        residuals: result.residuals,
        residual_gap: result.residuals.gap(),
        solve_ms_median: percentile(&mut solve, 0.5),
        solve_ms_p95: percentile(&mut solve, 0.95),
        ate_rmse_m: m.map(|m| m.ate_rmse_m),
        bias_rmse_gyro: m.and_then(|m| m.bias_rmse_gyro),
        bias_rmse_accel: m.and_then(|m| m.bias_rmse_accel),
        bias_rmse_from_s: first.map_or(0.0, |f| f.t) + bias_from_s,
        bias_allan_std_gyro: allan_steady_std(in_use[0], opts.noise.imu.gyro_random_walk),
        bias_allan_std_accel: allan_steady_std(in_use[1], opts.noise.imu.accel_random_walk),
        noise: result.noise,
        camera: result.camera.clone(),
        window_length: super::window_scale::window_scale(input, result),
        blind_s: result.blind_spans.iter().map(|[a, b]| b - a).sum(),
        blind_longest_s: result.blind_spans.iter().map(|[a, b]| b - a).fold(0.0, f64::max),
        warnings,
        evaluation,
    }
}

impl Summary {
    /// The distance walked \[m\]: the ground truth's when known, else the
    /// estimated path's.
    pub fn walked_m(&self) -> f64 {
        self.groundtruth_distance_m.unwrap_or(self.distance_m)
    }

    /// Closed-loop error as a percentage of [`Summary::walked_m`].
    pub fn closed_loop_percent(&self) -> f64 {
        100.0 * self.closed_loop_error_m / self.walked_m().max(1e-9)
    }

    /// The bias RMSEs (of the error norm) over the steady-state std the noise
    /// coefficients predict for the norm (`√3` × [`Summary::bias_allan_std_gyro`]
    /// and `_accel`): (gyro, accel), with ground truth.
    pub fn bias_rmse_ratios(&self) -> Option<(f64, f64)> {
        let norm = 3f64.sqrt();
        Some((
            self.bias_rmse_gyro? / (norm * self.bias_allan_std_gyro),
            self.bias_rmse_accel? / (norm * self.bias_allan_std_accel),
        ))
    }

    /// Whether the ground truth shows a path that does not return to its
    /// start: the distance between the last and the first position is then
    /// no closed-loop error.
    pub fn ends_elsewhere(&self) -> bool {
        self.returns_to_start == Some(false)
    }

    /// What the distance between the last and the first position is (see
    /// [`Summary::ends_elsewhere`]).
    pub fn loop_label(&self) -> &'static str {
        if self.ends_elsewhere() {
            "end-to-start distance (the ground truth does not return to its start)"
        } else {
            "closed-loop error"
        }
    }

    /// A few lines for the terminal.
    pub fn table(&self) -> String {
        let opt = |v: Option<f64>, unit: &str| v.map_or("—".to_string(), |x| format!("{x:.4} {unit}"));
        let ratios = self.bias_rmse_ratios().map_or(String::new(), |(g, a)| {
            format!(
                " = {g:.1}× and {a:.1}× the steady state √(N·K) predicts ({:.1e} rad/s, {:.1e} m/s² per axis)",
                self.bias_allan_std_gyro, self.bias_allan_std_accel
            )
        });
        format!(
            "duration {:.1} s, path {:.2} m{}, {} frames ({} keyframes), {} resets{}\n\
             {}: fused {:.3} m ({:.3} % of the {} path) vs IMU only {:.3} m\n\
             ATE (position+yaw aligned) {}\n\
             bias RMSE after {:.1} s: gyro {}, accel {}{}\n\
             {}{}{}{}{}speed: {:.1}× real time; per-frame solve median {:.2} ms, 95th percentile {:.2} ms",
            self.duration_s,
            self.distance_m,
            self.groundtruth_distance_m.map_or(String::new(), |d| format!(" (ground truth {d:.2} m)")),
            self.frames,
            self.keyframes,
            self.resets,
            if self.starts.len() > 1 {
                format!(" (the trajectory is in {} pieces, each in a frame of its own)", self.starts.len())
            } else {
                String::new()
            },
            self.loop_label(),
            self.closed_loop_error_m,
            self.closed_loop_percent(),
            if self.groundtruth_distance_m.is_some() { "ground-truth" } else { "estimated" },
            self.imu_only_closed_loop_error_m,
            opt(self.ate_rmse_m, "m"),
            self.bias_rmse_from_s,
            opt(self.bias_rmse_gyro, "rad/s"),
            opt(self.bias_rmse_accel, "m/s²"),
            ratios,
            self.evaluation
                .as_ref()
                .and_then(|ev| ev.metrics.bias_nees_gyro_axes.zip(ev.metrics.bias_nees_accel_axes))
                .map_or(String::new(), |(g, a)| format!("{}\n", crate::eval::nees_line(g, a))),
            self.noise.map_or(String::new(), |n| format!("{}\n", n.line())),
            self.camera.as_ref().map_or(String::new(), |c| format!("{}\n", c.line())),
            self.window_length.as_ref().map_or(String::new(), |w| format!("{}\n", w.line())),
            if self.blind_s > 0.0 {
                format!(
                    "blind (fewer than {} features, IMU only): {:.1} s in all, longest {:.1} s\n",
                    super::estimator::BLIND_FEATURES,
                    self.blind_s,
                    self.blind_longest_s
                )
            } else {
                String::new()
            },
            self.realtime_factor,
            self.solve_ms_median,
            self.solve_ms_p95,
        )
    }
}

/// The estimated trajectory of a run (TUM times: `t0_ns` + frame time).
pub fn trajectory(input: &VioInput, result: &VioResult) -> Trajectory {
    let e = &result.estimates;
    Trajectory {
        t_ns: e.iter().map(|x| input.t0_ns + (x.t * 1e9).round() as i64).collect(),
        p: e.iter().map(|x| x.position).collect(),
        q: e.iter().map(|x| x.rotation).collect(),
        ..Default::default()
    }
}

/// Where the run's trajectory begins again in a frame of its own, on the
/// recording's clock \[s\] ([`VioResult::starts`], for
/// [`EvalOptions::piece_starts_s`]).
pub fn piece_starts_s(input: &VioInput, result: &VioResult) -> Vec<f64> {
    result.starts.iter().map(|t| input.t0_ns as f64 * 1e-9 + t).collect()
}

/// The estimated biases of a run with their marginal σ.
pub fn bias_track(input: &VioInput, result: &VioResult) -> BiasTrack {
    let e = &result.estimates;
    BiasTrack {
        t_ns: e.iter().map(|x| input.t0_ns + (x.t * 1e9).round() as i64).collect(),
        accel: e.iter().map(|x| x.bias_accel).collect(),
        gyro: e.iter().map(|x| x.bias_gyro).collect(),
        accel_std: Some(e.iter().map(|x| x.std[3]).collect()),
        gyro_std: Some(e.iter().map(|x| x.std[4]).collect()),
        keyframe: Some(e.iter().map(|x| x.keyframe).collect()),
    }
}

/// Write `trajectory.txt` (TUM), `biases.csv` and `summary.json` into `dir`,
/// and with a ground truth the evaluation (`eval/metrics.json` and plots).
pub fn write_outputs(
    dir: &Path,
    input: &VioInput,
    result: &VioResult,
    summary: &Summary,
) -> Result<Vec<PathBuf>, VioError> {
    crate::io::staging::write_staged(dir, |stage| write_unstaged(stage, input, result, summary))
}

fn write_unstaged(
    dir: &Path,
    input: &VioInput,
    result: &VioResult,
    summary: &Summary,
) -> Result<Vec<PathBuf>, VioError> {
    let traj = dir.join("trajectory.txt");
    write_tum(&traj, &trajectory(input, result)).map_err(|e| e.to_string())?;
    let biases = dir.join("biases.csv");
    write_biases(&biases, &bias_track(input, result)).map_err(|e| e.to_string())?;
    let sj = dir.join("summary.json");
    let text = serde_json::to_string_pretty(summary).map_err(|e| e.to_string())?;
    std::fs::write(&sj, text).map_err(|e| format!("{}: {e}", sj.display()))?;
    let mut files = vec![traj, biases, sj];
    if let Some(ev) = &summary.evaluation {
        files.extend(write_report(&dir.join("eval"), ev)?);
    }
    Ok(files)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn allan_steady_std_solves_the_riccati_equation() {
        // Kalman–Bucy: dP/dt = k² − P²/n² = 0 at P = σ².
        let (n, k) = (5.25e-3, 2e-5);
        let p = allan_steady_std(n, k).powi(2);
        assert!((k * k - p * p / (n * n)).abs() < 1e-12 * k * k, "{p}");
    }

    #[test]
    fn a_raised_noise_warns_that_the_bias_sigma_may_be_too_small() {
        use crate::vio::noise_meter::NoiseReport;
        let given = [1.7e-4, 2.0e-3];
        let report = |in_use| NoiseReport { given, at_rest: None, in_motion: None, in_motion_largest: None, in_use };
        assert_eq!(slow_error_warning(&report(given)), None);
        let w = slow_error_warning(&report([4.9e-4, 2.0e-3])).expect("raised");
        assert!(w.contains("gyro ×2.9, accelerometer ×1.0") && w.contains("--noise"), "{w}");
    }

    #[test]
    fn path_length_ignores_frame_jitter_and_keeps_the_last_sample() {
        // 10.05 s along x at a walker's 0.1 m/s, sampled at 20 Hz, with ±2 mm
        // of sideways jitter.
        let positions: Vec<Vector3<f64>> =
            (0..=201).map(|i| Vector3::new(0.005 * i as f64, if i % 2 == 0 { 0.002 } else { -0.002 }, 0.0)).collect();
        let every_frame = path_length(positions.iter().copied(), 0.0);
        assert!(every_frame > 1.005 * 1.25, "jitter lengthens the frame-to-frame path: {every_frame}");
        let stepped = path_length(positions.iter().copied(), PATH_STEP_M);
        assert!((stepped / 1.005 - 1.0).abs() < 0.02, "{stepped}");
        assert_eq!(path_length(positions[..1].iter().copied(), PATH_STEP_M), 0.0);
        assert_eq!(path_length(std::iter::empty(), PATH_STEP_M), 0.0);
    }
}
