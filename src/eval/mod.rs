//! Trajectory evaluation the way the field reports it (`tumble eval`):
//! absolute trajectory error after alignment ([`Alignment`], Umeyama),
//! relative pose error over travelled distances, and bias errors against
//! EuRoC's ground-truth bias columns, with plots and `metrics.json`.
//!
//! The estimate is paired with the ground truth at the estimate's times: the
//! ground-truth position and biases are interpolated linearly, its rotation by
//! slerp, between samples at most [`EvalOptions::max_gap_s`] apart.
//!
//! ```
//! use tumble::eval::{evaluate, Alignment, EvalOptions};
//! use tumble::io::trajectory::Trajectory;
//! let gt = Trajectory {
//!     t_ns: (0..200).map(|i| i * 5_000_000).collect(),
//!     p: (0..200).map(|i| { let a = i as f64 * 0.03; [a.cos(), a.sin(), 0.01 * i as f64] }).collect(),
//!     q: vec![[1.0, 0.0, 0.0, 0.0]; 200],
//!     ..Default::default()
//! };
//! // The estimate: every 10th pose, shifted by 1 m.
//! let mut est = Trajectory::default();
//! for i in (0..200).step_by(10) {
//!     est.t_ns.push(gt.t_ns[i]);
//!     est.p.push([gt.p[i][0] + 1.0, gt.p[i][1], gt.p[i][2]]);
//!     est.q.push(gt.q[i]);
//! }
//! let e = evaluate(&est, None, &gt, &EvalOptions { alignment: Alignment::Se3, ..Default::default() }).unwrap();
//! assert!(e.metrics.ate_rmse_m < 1e-9);
//! ```

mod align;
mod report;

pub use align::{align, best_rotation, best_yaw, Alignment, Similarity};
pub use report::write_report;

use crate::io::biases::BiasTrack;
use crate::io::trajectory::Trajectory;
use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion, Vector3};
use serde::Serialize;

/// What to evaluate and how.
#[derive(Debug, Clone)]
pub struct EvalOptions {
    /// The alignment before the absolute errors (default position+yaw, VIO's gauge).
    pub alignment: Alignment,
    /// Distances for the relative pose error \[m\]; empty: 10, 20, 30, 40 and 50 % of the path.
    pub rpe_distances: Vec<f64>,
    /// Bias errors count from this many seconds after the first estimate (convergence skipped) \[s\].
    pub bias_after_s: f64,
    /// Largest ground-truth gap to interpolate across \[s\].
    pub max_gap_s: f64,
    /// Times on the estimate's clock \[s\] at which it begins again in a
    /// frame of its own (a VIO run restarted: `summary.json`'s `starts`).
    /// Each piece is aligned by itself and relative errors are measured
    /// within pieces; empty: the estimate is one piece.
    pub piece_starts_s: Vec<f64>,
}

impl EvalOptions {
    /// Check every option once, before any work ([`evaluate`] calls it).
    pub fn validate(&self) -> Result<(), crate::OptionError> {
        if let Some(d) = self.rpe_distances.iter().find(|d| !(d.is_finite() && **d > 0.0)) {
            return Err(crate::OptionError::new(
                "--rpe-distances",
                format!("must be positive distances in metres, got {d}"),
            ));
        }
        if !(self.max_gap_s.is_finite() && self.max_gap_s > 0.0) {
            return Err(crate::OptionError::new(
                "--max-gap",
                format!("must be a positive time in seconds, got {}", self.max_gap_s),
            ));
        }
        if !self.bias_after_s.is_finite() {
            return Err(crate::OptionError::new("--bias-after", "must be a finite number of seconds"));
        }
        if let Some(t) = self.piece_starts_s.iter().find(|t| !t.is_finite()) {
            return Err(crate::OptionError::new("--pieces", format!("must be times in seconds, got {t}")));
        }
        if let Some(w) = self.piece_starts_s.windows(2).find(|w| w[1] <= w[0]) {
            return Err(crate::OptionError::new(
                "--pieces",
                format!("must be increasing times, got {} s after {} s", w[1], w[0]),
            ));
        }
        Ok(())
    }
}

/// Why an evaluation cannot be made.
#[derive(Debug, thiserror::Error)]
pub enum EvalError {
    /// An option cannot work.
    #[error(transparent)]
    Options(#[from] crate::OptionError),
    /// A file cannot be read (named with its line).
    #[error(transparent)]
    File(#[from] crate::InputError),
    /// The trajectories cannot be compared (the message says why).
    #[error("{0}")]
    Invalid(String),
}

crate::error::message_error_conversions!(EvalError, EvalError::Invalid);

/// The files an evaluation reads (see [`EvalInputs::read`]).
#[derive(Debug, Clone)]
pub struct EvalInputs {
    /// The estimated trajectory.
    pub estimate: Trajectory,
    /// The ground truth.
    pub groundtruth: Trajectory,
    /// The estimate's bias track, when there is one.
    pub biases: Option<BiasTrack>,
    /// The bias file read, when there is one.
    pub biases_file: Option<std::path::PathBuf>,
    /// Where the estimate begins again in a frame of its own \[s, its
    /// clock\] ([`EvalOptions::piece_starts_s`]), from `summary.json` beside
    /// it; empty when it is one piece or there is no such file.
    pub piece_starts_s: Vec<f64>,
}

impl EvalInputs {
    /// Read the estimate and the ground truth (TUM or ASL), and the bias track
    /// `biases` or, when not given, `biases.csv` beside the estimate when it is there.
    /// A `summary.json` of `tumble vio` beside the estimate gives its pieces.
    pub fn read(
        estimate: &std::path::Path,
        groundtruth: &std::path::Path,
        biases: Option<&std::path::Path>,
    ) -> Result<EvalInputs, crate::InputError> {
        use crate::io::{biases::read_biases, trajectory::read_trajectory};
        let est = read_trajectory(estimate)?;
        let gt = read_trajectory(groundtruth)?;
        let beside = estimate.with_file_name("biases.csv");
        let biases_file = match biases {
            Some(b) => Some(b.to_path_buf()),
            None => beside.is_file().then_some(beside),
        };
        let biases = biases_file.as_deref().map(read_biases).transpose()?;
        let summary = estimate.with_file_name("summary.json");
        let piece_starts_s = if summary.is_file() { read_piece_starts(&summary)? } else { Vec::new() };
        Ok(EvalInputs { estimate: est, groundtruth: gt, biases, biases_file, piece_starts_s })
    }
}

/// The pieces a `tumble vio` summary lists: its `starts` \[s\] on the
/// recording's clock (`clock_t0_s` + each), when there is more than one.
fn read_piece_starts(path: &std::path::Path) -> Result<Vec<f64>, crate::InputError> {
    use crate::InputError;
    let text = std::fs::read_to_string(path).map_err(|e| InputError::file(path, e))?;
    let json: serde_json::Value =
        serde_json::from_str(&text).map_err(|e| InputError::at(path, e.line(), format!("not JSON: {e}")))?;
    let Some(starts) = json.get("starts") else { return Ok(Vec::new()) };
    let starts: Vec<f64> = starts
        .as_array()
        .and_then(|a| a.iter().map(|v| v.as_f64()).collect())
        .ok_or_else(|| InputError::file(path, "`starts` is not a list of times in seconds"))?;
    if starts.len() < 2 {
        return Ok(Vec::new());
    }
    let t0 = json.get("clock_t0_s").and_then(|v| v.as_f64()).ok_or_else(|| {
        InputError::file(path, format!("lists {} starts but no `clock_t0_s` to place them on", starts.len()))
            .with_hint("written by an older tumble: run `tumble vio` again, or move the summary away")
    })?;
    Ok(starts.iter().map(|s| t0 + s).collect())
}

impl Default for EvalOptions {
    fn default() -> Self {
        EvalOptions {
            alignment: Alignment::PosYaw,
            rpe_distances: Vec::new(),
            bias_after_s: 0.0,
            max_gap_s: 0.1,
            piece_starts_s: Vec::new(),
        }
    }
}

/// Relative pose error over one travelled distance.
#[derive(Debug, Clone, Serialize)]
pub struct RpeEntry {
    /// Travelled distance along the ground truth between the two poses \[m\].
    pub distance_m: f64,
    /// Pose pairs measured.
    pub pairs: usize,
    /// RMS of the relative translation error \[m\].
    pub trans_rmse_m: f64,
    /// Mean relative translation error \[m\].
    pub trans_mean_m: f64,
    /// Median relative translation error \[m\].
    pub trans_median_m: f64,
    /// Mean relative translation error as a percentage of the distance \[%\].
    pub trans_mean_percent: f64,
    /// Mean relative rotation error \[deg\].
    pub rot_mean_deg: f64,
}

/// The figures of an evaluation (`metrics.json`).
#[derive(Debug, Clone, Serialize)]
pub struct Metrics {
    /// Alignment used.
    pub alignment: Alignment,
    /// Scale of the alignment (1 unless sim3; of the longest piece when the
    /// estimate is in pieces).
    pub scale: f64,
    /// The pieces of the estimate, each aligned by itself (one unless
    /// [`EvalOptions::piece_starts_s`] splits it).
    pub pieces: Vec<Piece>,
    /// Estimated poses paired with the ground truth.
    pub matched: usize,
    /// Estimated poses outside the ground truth's span or in its gaps, or
    /// in a piece too short to align by itself.
    pub unmatched: usize,
    /// Time from the first to the last paired pose \[s\].
    pub duration_s: f64,
    /// Ground-truth path length over the paired span \[m\].
    pub distance_m: f64,
    /// RMS of the aligned position errors (absolute trajectory error) \[m\].
    pub ate_rmse_m: f64,
    /// Mean aligned position error \[m\].
    pub ate_mean_m: f64,
    /// Median aligned position error \[m\].
    pub ate_median_m: f64,
    /// Largest aligned position error \[m\].
    pub ate_max_m: f64,
    /// RMS of the aligned rotation errors \[deg\] (the alignment's rotation
    /// from the positions).
    pub rotation_rmse_deg: f64,
    /// RMS of the rotation errors \[deg\] with the alignment's rotation taken
    /// from the orientations instead ([`orientation_alignment`]). Over a path
    /// that spans little, the positions fix the alignment's rotation poorly,
    /// and `rotation_rmse_deg` then holds that error as well (EuRoC's
    /// `imu_april`, ±0.8 m: 0.60° of it).
    pub rotation_rmse_oriented_deg: f64,
    /// Relative pose errors, one entry per distance.
    pub rpe: Vec<RpeEntry>,
    /// RMS of the gyro bias error norm after `bias_from_s` \[rad/s\] (ground truth with biases only).
    pub bias_rmse_gyro: Option<f64>,
    /// RMS of the accelerometer bias error norm after `bias_from_s` \[m/s²\].
    pub bias_rmse_accel: Option<f64>,
    /// Per-axis gyro bias RMSE \[rad/s\].
    pub bias_rmse_gyro_axes: Option<[f64; 3]>,
    /// Per-axis accelerometer bias RMSE \[m/s²\].
    pub bias_rmse_accel_axes: Option<[f64; 3]>,
    /// Per-axis mean squared normalized gyro bias error, ((b̂ − b)/σ)², over
    /// the compared samples with a finite σ: 1 when the reported σ fits the
    /// errors, above 1 when it is optimistic (needs the bias track's σ).
    pub bias_nees_gyro_axes: Option<[f64; 3]>,
    /// The same for the accelerometer bias.
    pub bias_nees_accel_axes: Option<[f64; 3]>,
    /// Bias samples compared.
    pub bias_samples: usize,
    /// Bias errors count from this time, seconds after the first estimate \[s\].
    pub bias_from_s: f64,
    /// What the reader should know (unmatched poses, missing bias columns, …).
    pub warnings: Vec<String>,
}

/// A piece of the estimate: a span estimated in one frame, aligned by itself.
#[derive(Debug, Clone, Serialize)]
pub struct Piece {
    /// Its first paired pose, seconds since the first estimated pose \[s\].
    pub from_s: f64,
    /// Its last paired pose \[s\].
    pub to_s: f64,
    /// Its poses paired with the ground truth.
    pub matched: usize,
    /// RMS of its aligned position errors \[m\].
    pub ate_rmse_m: f64,
    /// Scale of its alignment (1 unless sim3).
    pub scale: f64,
}

/// One estimated pose paired with the ground truth.
#[derive(Debug, Clone, Copy)]
pub struct Pair {
    /// Seconds since the first estimated pose.
    pub t: f64,
    /// The piece it belongs to (an index into [`Evaluation::similarities`]
    /// and [`Metrics::pieces`]).
    pub piece: usize,
    /// Estimated pose (world ← body), before alignment.
    pub est: Isometry3<f64>,
    /// Ground-truth pose at the same time.
    pub gt: Isometry3<f64>,
}

/// An evaluation: the figures and what the plots need.
#[derive(Debug, Clone)]
pub struct Evaluation {
    /// The figures.
    pub metrics: Metrics,
    /// The paired poses.
    pub pairs: Vec<Pair>,
    /// The alignment applied to each piece of the estimate.
    pub similarities: Vec<Similarity>,
    /// Aligned position error of each pair \[m\].
    pub position_errors: Vec<f64>,
    /// Rotation error of each pair, its piece's alignment applied \[deg\].
    pub rotation_errors: Vec<f64>,
    /// The whole ground-truth trajectory (for the top view), times in seconds since the first estimate.
    pub groundtruth: Trajectory,
    /// Bias comparison rows: time \[s since the first estimate\], estimate, its σ, ground truth — gyro then accel.
    pub bias_rows: Vec<BiasRow>,
}

/// Estimated and true biases at one time.
#[derive(Debug, Clone, Copy)]
pub struct BiasRow {
    /// Seconds since the first estimated pose.
    pub t: f64,
    /// Estimated gyro bias \[rad/s\] and its σ (NaN when unknown).
    pub gyro: ([f64; 3], [f64; 3]),
    /// Estimated accelerometer bias \[m/s²\] and its σ (NaN when unknown).
    pub accel: ([f64; 3], [f64; 3]),
    /// Ground-truth gyro and accelerometer biases, when the ground truth has them.
    pub truth: Option<([f64; 3], [f64; 3])>,
}

fn quat(q: [f64; 4]) -> UnitQuaternion<f64> {
    UnitQuaternion::from_quaternion(Quaternion::new(q[0], q[1], q[2], q[3]))
}

/// Pose from a position and a rotation `[w, x, y, z]`.
pub(crate) fn iso(p: [f64; 3], q: [f64; 4]) -> Isometry3<f64> {
    Isometry3::from_parts(Translation3::new(p[0], p[1], p[2]), quat(q))
}

fn lerp3(a: [f64; 3], b: [f64; 3], w: f64) -> [f64; 3] {
    [a[0] + w * (b[0] - a[0]), a[1] + w * (b[1] - a[1]), a[2] + w * (b[2] - a[2])]
}

/// Where `t_ns` falls in `t`: `(k, w)` with the value `(1−w)·x[k] + w·x[k+1]`,
/// or None outside the span or across a gap longer than `max_gap_ns`.
fn bracket(t: &[i64], t_ns: i64, max_gap_ns: f64) -> Option<(usize, f64)> {
    let k = t.partition_point(|&s| s <= t_ns);
    if k == 0 {
        return None;
    }
    if t[k - 1] == t_ns {
        return Some((k - 1, 0.0));
    }
    if k >= t.len() || (t[k] - t[k - 1]) as f64 > max_gap_ns {
        return None;
    }
    Some((k - 1, (t_ns - t[k - 1]) as f64 / (t[k] - t[k - 1]) as f64))
}

/// Ground-truth pose at `t_ns` (None outside its span or in a gap).
pub(crate) fn pose_at(gt: &Trajectory, t_ns: i64, max_gap_ns: f64) -> Option<Isometry3<f64>> {
    let (k, w) = bracket(&gt.t_ns, t_ns, max_gap_ns)?;
    if w == 0.0 {
        return Some(iso(gt.p[k], gt.q[k]));
    }
    let q = quat(gt.q[k]).slerp(&quat(gt.q[k + 1]), w);
    let p = lerp3(gt.p[k], gt.p[k + 1], w);
    Some(Isometry3::from_parts(Translation3::new(p[0], p[1], p[2]), q))
}

/// Ground-truth biases `(gyro, accel)` at `t_ns`, interpolated (None without
/// bias columns, outside the span or in a gap).
pub(crate) fn biases_at(gt: &Trajectory, t_ns: i64, max_gap_ns: f64) -> Option<([f64; 3], [f64; 3])> {
    let (bg, ba) = gt.bias_gyro.as_ref().zip(gt.bias_accel.as_ref())?;
    let (k, w) = bracket(&gt.t_ns, t_ns, max_gap_ns)?;
    let k1 = (k + 1).min(gt.len() - 1);
    Some((lerp3(bg[k], bg[k1], w), lerp3(ba[k], ba[k1], w)))
}

fn stats(v: &[f64]) -> (f64, f64, f64, f64) {
    if v.is_empty() {
        return (f64::NAN, f64::NAN, f64::NAN, f64::NAN);
    }
    let n = v.len() as f64;
    let rmse = (v.iter().map(|x| x * x).sum::<f64>() / n).sqrt();
    let mean = v.iter().sum::<f64>() / n;
    let mut s = v.to_vec();
    s.sort_by(|a, b| a.total_cmp(b));
    let median = s[s.len() / 2];
    (rmse, mean, median, s[s.len() - 1])
}

/// Relative pose errors over `distances` (metres along the ground truth),
/// between poses of one piece; each piece's translations are multiplied by
/// its alignment's scale first.
fn relative_errors(pieces: &[&[Pair]], distances: &[f64], similarities: &[Similarity]) -> Vec<RpeEntry> {
    let mut along: Vec<Vec<f64>> = Vec::with_capacity(pieces.len());
    for piece in pieces {
        let mut a = vec![0.0; piece.len()];
        for i in 1..piece.len() {
            a[i] = a[i - 1] + (piece[i].gt.translation.vector - piece[i - 1].gt.translation.vector).norm();
        }
        along.push(a);
    }
    let scaled = |x: &Pair| {
        let mut e = x.est;
        e.translation.vector *= similarities[x.piece].scale;
        e
    };
    distances
        .iter()
        .filter_map(|&d| {
            let (mut trans, mut rot, mut pct) = (Vec::new(), Vec::new(), Vec::new());
            for (pairs, along) in pieces.iter().zip(&along) {
                for i in 0..pairs.len() {
                    let j = along.partition_point(|&a| a < along[i] + d);
                    if j >= pairs.len() {
                        break;
                    }
                    let dg = pairs[i].gt.inverse() * pairs[j].gt;
                    let de = scaled(&pairs[i]).inverse() * scaled(&pairs[j]);
                    let e = dg.inverse() * de;
                    trans.push(e.translation.vector.norm());
                    rot.push(e.rotation.angle().to_degrees());
                    pct.push(100.0 * e.translation.vector.norm() / (along[j] - along[i]).max(1e-12));
                }
            }
            if trans.is_empty() {
                return None;
            }
            let (rmse, mean, median, _) = stats(&trans);
            Some(RpeEntry {
                distance_m: d,
                pairs: trans.len(),
                trans_rmse_m: rmse,
                trans_mean_m: mean,
                trans_median_m: median,
                trans_mean_percent: stats(&pct).1,
                rot_mean_deg: stats(&rot).1,
            })
        })
        .collect()
}

/// Align each piece of `pairs` (consecutive pairs of one [`Pair::piece`])
/// by itself. A piece too short or too straight to align is left out with a
/// warning, unless it is the only one (then its error is the evaluation's);
/// the pieces kept are numbered again from 0.
fn align_pieces(
    pairs: Vec<Pair>,
    kind: Alignment,
    warnings: &mut Vec<String>,
) -> Result<(Vec<Pair>, Vec<Similarity>), EvalError> {
    let total = pairs.chunk_by(|a, b| a.piece == b.piece).count();
    let (mut kept, mut similarities) = (Vec::with_capacity(pairs.len()), Vec::new());
    for piece in pairs.chunk_by(|a, b| a.piece == b.piece) {
        let pe: Vec<Vector3<f64>> = piece.iter().map(|p| p.est.translation.vector).collect();
        let pg: Vec<Vector3<f64>> = piece.iter().map(|p| p.gt.translation.vector).collect();
        let sim = if piece.len() < 3 {
            Err(EvalError::Invalid(format!("only {} paired poses", piece.len())))
        } else {
            align(&pe, &pg, kind)
        };
        match sim {
            Ok(sim) => {
                kept.extend(piece.iter().map(|p| Pair { piece: similarities.len(), ..*p }));
                similarities.push(sim);
            }
            Err(e) if total == 1 => return Err(e),
            Err(e) => warnings.push(format!(
                "the piece of the estimate over {:.2}–{:.2} s cannot be aligned by itself ({e}): \
                 its {} poses are left out",
                piece[0].t,
                piece[piece.len() - 1].t,
                piece.len()
            )),
        }
    }
    if similarities.is_empty() {
        return Err(format!("none of the estimate's {total} pieces can be aligned by itself").into());
    }
    if similarities.len() > 1 {
        warnings.push(format!(
            "the estimate is in {} pieces, each in a frame of its own: each is aligned by itself, \
             and relative errors are measured within pieces",
            similarities.len()
        ));
    }
    Ok((kept, similarities))
}

/// The default relative-error distances: 10–50 % of the path, rounded to two significant digits.
fn default_distances(path_m: f64) -> Vec<f64> {
    if path_m.is_nan() || path_m <= 0.0 {
        return Vec::new();
    }
    [0.1, 0.2, 0.3, 0.4, 0.5].iter().map(|f| format!("{:.1e}", f * path_m).parse().unwrap_or(f * path_m)).collect()
}

/// The per-axis bias NEES as one line: `bias error² / σ² (1 = consistent): gyro x y z, accel x y z`.
pub fn nees_line(gyro: [f64; 3], accel: [f64; 3]) -> String {
    let f = |v: [f64; 3]| format!("{:.2} {:.2} {:.2}", v[0], v[1], v[2]);
    format!("bias error²/σ² per axis (1 = consistent σ): gyro {}, accel {}", f(gyro), f(accel))
}

/// Compare bias estimates with the ground truth's bias columns.
fn compare_biases(
    biases: &BiasTrack,
    gt: &Trajectory,
    t0_ns: i64,
    opts: &EvalOptions,
    m: &mut Metrics,
) -> Vec<BiasRow> {
    let max_gap_ns = opts.max_gap_s * 1e9;
    let truth = gt.bias_gyro.as_ref().zip(gt.bias_accel.as_ref());
    if truth.is_none() {
        m.warnings.push("the ground truth has no bias columns: bias errors not computed".into());
    }
    let nan = [f64::NAN; 3];
    let mut rows = Vec::with_capacity(biases.t_ns.len());
    let (mut sg, mut sa, mut n) = ([0.0; 3], [0.0; 3], 0usize);
    // Normalized squared errors per axis: sums and counts (gyro, accel).
    let (mut zg, mut za, mut ng, mut na) = ([0.0; 3], [0.0; 3], 0usize, 0usize);
    let sigma = |std: &Option<Vec<[f64; 3]>>, i: usize| {
        std.as_ref().map(|s| s[i]).filter(|s| s.iter().all(|x| x.is_finite() && *x > 0.0))
    };
    for i in 0..biases.t_ns.len() {
        let t = (biases.t_ns[i] - t0_ns) as f64 * 1e-9;
        let at = biases_at(gt, biases.t_ns[i], max_gap_ns);
        if let (Some((bg, ba)), true) = (at, t >= opts.bias_after_s) {
            for a in 0..3 {
                sg[a] += (biases.gyro[i][a] - bg[a]).powi(2);
                sa[a] += (biases.accel[i][a] - ba[a]).powi(2);
            }
            n += 1;
            for (est, truth, std, z, count) in [
                (&biases.gyro[i], bg, sigma(&biases.gyro_std, i), &mut zg, &mut ng),
                (&biases.accel[i], ba, sigma(&biases.accel_std, i), &mut za, &mut na),
            ] {
                if let Some(std) = std {
                    for a in 0..3 {
                        z[a] += ((est[a] - truth[a]) / std[a]).powi(2);
                    }
                    *count += 1;
                }
            }
        }
        rows.push(BiasRow {
            t,
            gyro: (biases.gyro[i], biases.gyro_std.as_ref().map_or(nan, |s| s[i])),
            accel: (biases.accel[i], biases.accel_std.as_ref().map_or(nan, |s| s[i])),
            truth: at,
        });
    }
    m.bias_samples = n;
    if n > 0 {
        let axes = |s: [f64; 3]| s.map(|x| (x / n as f64).sqrt());
        m.bias_rmse_gyro = Some((sg.iter().sum::<f64>() / n as f64).sqrt());
        m.bias_rmse_accel = Some((sa.iter().sum::<f64>() / n as f64).sqrt());
        m.bias_rmse_gyro_axes = Some(axes(sg));
        m.bias_rmse_accel_axes = Some(axes(sa));
        let mean = |z: [f64; 3], k: usize| (k > 0).then(|| z.map(|x| x / k as f64));
        m.bias_nees_gyro_axes = mean(zg, ng);
        m.bias_nees_accel_axes = mean(za, na);
    } else if truth.is_some() {
        m.warnings.push(format!(
            "no bias estimate falls inside the ground truth after {:.1} s: bias errors not computed",
            opts.bias_after_s
        ));
    }
    rows
}

/// The rotation (ground truth ← estimate) that best aligns the paired
/// orientations in the chordal sense, `argmax_A tr(Aᵀ Σ R_gt R_estᵀ)`
/// ([`best_rotation`]); about the vertical alone for
/// [`Alignment::PosYaw`] ([`best_yaw`]); the identity for
/// [`Alignment::None`] or when the SVD does not converge.
pub fn orientation_alignment(pairs: &[Pair], kind: Alignment) -> UnitQuaternion<f64> {
    let m: nalgebra::Matrix3<f64> =
        pairs.iter().map(|p| (p.gt.rotation * p.est.rotation.inverse()).to_rotation_matrix().into_inner()).sum();
    match kind {
        Alignment::None => UnitQuaternion::identity(),
        Alignment::PosYaw => UnitQuaternion::from_axis_angle(&Vector3::z_axis(), align::best_yaw(&m)),
        Alignment::Se3 | Alignment::Sim3 => align::best_rotation(&m)
            .map_or_else(UnitQuaternion::identity, |(r, _, _)| UnitQuaternion::from_rotation_matrix(&r)),
    }
}

/// Evaluate `est` (and optionally its bias track) against `gt`.
///
/// Errors when fewer than 3 estimated poses fall inside the ground truth
/// (with both spans in the message — usually different clocks or time units)
/// or when the geometry does not determine the alignment.
pub fn evaluate(
    est: &Trajectory,
    biases: Option<&BiasTrack>,
    gt: &Trajectory,
    opts: &EvalOptions,
) -> Result<Evaluation, EvalError> {
    opts.validate()?;
    if est.is_empty() || gt.is_empty() {
        return Err(
            format!("nothing to compare: {} estimated poses, {} ground-truth poses", est.len(), gt.len()).into()
        );
    }
    let t0_ns = est.t_ns[0];
    let pairs = pair_poses(est, gt, opts)?;
    let paired = pairs.len();
    let mut warnings = Vec::new();
    let (pairs, similarities) = align_pieces(pairs, opts.alignment, &mut warnings)?;
    let aligned = |p: &Pair| similarities[p.piece].apply(&p.est.translation.vector);
    let position_errors: Vec<f64> = pairs.iter().map(|p| (aligned(p) - p.gt.translation.vector).norm()).collect();
    let align_q: Vec<UnitQuaternion<f64>> =
        similarities.iter().map(|s| UnitQuaternion::from_rotation_matrix(&s.rotation)).collect();
    let rotation_errors: Vec<f64> = pairs
        .iter()
        .map(|p| (p.gt.rotation.inverse() * align_q[p.piece] * p.est.rotation).angle().to_degrees())
        .collect();
    let slices: Vec<&[Pair]> = pairs.chunk_by(|a, b| a.piece == b.piece).collect();
    let rot_err_oriented = oriented_rotation_errors(&slices, opts.alignment);
    let travelled = |piece: &[Pair]| -> f64 {
        piece.windows(2).map(|w| (w[1].gt.translation.vector - w[0].gt.translation.vector).norm()).sum()
    };
    let distance_m: f64 = slices.iter().map(|p| travelled(p)).sum();
    let distances =
        if opts.rpe_distances.is_empty() { default_distances(distance_m) } else { opts.rpe_distances.clone() };
    let (ate_rmse_m, ate_mean_m, ate_median_m, ate_max_m) = stats(&position_errors);
    let pieces = pieces(&slices, &position_errors, &similarities);
    let longest = pieces.iter().max_by_key(|p| p.matched).map_or(1.0, |p| p.scale);
    let matched = pairs.len();
    let mut metrics = Metrics {
        alignment: opts.alignment,
        scale: longest,
        matched,
        unmatched: est.len() - matched,
        duration_s: pairs[matched - 1].t - pairs[0].t,
        distance_m,
        ate_rmse_m,
        ate_mean_m,
        ate_median_m,
        ate_max_m,
        rotation_rmse_deg: stats(&rotation_errors).0,
        rotation_rmse_oriented_deg: stats(&rot_err_oriented).0,
        rpe: relative_errors(&slices, &distances, &similarities),
        pieces,
        bias_rmse_gyro: None,
        bias_rmse_accel: None,
        bias_rmse_gyro_axes: None,
        bias_rmse_accel_axes: None,
        bias_nees_gyro_axes: None,
        bias_nees_accel_axes: None,
        bias_samples: 0,
        bias_from_s: opts.bias_after_s,
        warnings,
    };
    coverage_warnings(&mut metrics, (paired, est.len()), gt, opts, &distances);
    let bias_rows = match biases {
        Some(b) => compare_biases(b, gt, t0_ns, opts, &mut metrics),
        None => Vec::new(),
    };
    let mut groundtruth = gt.clone();
    groundtruth.t_ns.iter_mut().for_each(|t| *t -= t0_ns);
    Ok(Evaluation { metrics, pairs, similarities, position_errors, rotation_errors, groundtruth, bias_rows })
}

/// A stamp span for messages.
fn span(t: &[i64]) -> String {
    format!("{:.3}–{:.3} s", t[0] as f64 * 1e-9, t[t.len() - 1] as f64 * 1e-9)
}

/// Each estimated pose with the ground truth at its stamp (interpolated,
/// within `max_gap_s`) and the piece it belongs to; at least three.
fn pair_poses(est: &Trajectory, gt: &Trajectory, opts: &EvalOptions) -> Result<Vec<Pair>, EvalError> {
    let t0_ns = est.t_ns[0];
    let max_gap_ns = opts.max_gap_s * 1e9;
    // Seconds of an epoch clock resolve ~0.2 µs in f64: a pose within 1 µs
    // of a piece's start is its first.
    let starts_ns: Vec<i64> = opts.piece_starts_s.iter().map(|s| (s * 1e9).round() as i64 - 1_000).collect();
    let mut pairs = Vec::with_capacity(est.len());
    for i in 0..est.len() {
        if let Some(g) = pose_at(gt, est.t_ns[i], max_gap_ns) {
            let piece = starts_ns.partition_point(|&s| s <= est.t_ns[i]);
            pairs.push(Pair { t: (est.t_ns[i] - t0_ns) as f64 * 1e-9, piece, est: iso(est.p[i], est.q[i]), gt: g });
        }
    }
    if pairs.len() < 3 {
        return Err(format!(
            "only {} of {} estimated poses fall inside the ground truth (estimate {}, ground truth {}); \
             are both on the same clock and in the same time unit?",
            pairs.len(),
            est.len(),
            span(&est.t_ns),
            span(&gt.t_ns)
        )
        .into());
    }
    Ok(pairs)
}

/// Rotation errors \[deg\] with each piece's orientations aligned on their own
/// ([`orientation_alignment`]).
fn oriented_rotation_errors(slices: &[&[Pair]], alignment: Alignment) -> Vec<f64> {
    let mut out = Vec::new();
    for piece in slices {
        let oriented = orientation_alignment(piece, alignment);
        out.extend(piece.iter().map(|p| (p.gt.rotation.inverse() * oriented * p.est.rotation).angle().to_degrees()));
    }
    out
}

/// Each piece's span, pairs, ATE and scale.
fn pieces(slices: &[&[Pair]], position_errors: &[f64], similarities: &[Similarity]) -> Vec<Piece> {
    let mut first = 0;
    slices
        .iter()
        .map(|piece| {
            let errors = &position_errors[first..first + piece.len()];
            first += piece.len();
            Piece {
                from_s: piece[0].t,
                to_s: piece[piece.len() - 1].t,
                matched: piece.len(),
                ate_rmse_m: stats(errors).0,
                scale: similarities[piece[0].piece].scale,
            }
        })
        .collect()
}

/// Warnings on what was not compared: poses outside the ground truth
/// (`paired` of `total`), relative errors over distances longer than the path.
fn coverage_warnings(
    metrics: &mut Metrics,
    (paired, total): (usize, usize),
    gt: &Trajectory,
    opts: &EvalOptions,
    distances: &[f64],
) {
    if paired < total {
        metrics.warnings.push(format!(
            "{} of {} estimated poses lie outside the ground truth ({}) or in its gaps > {} s; they are not counted",
            total - paired,
            total,
            span(&gt.t_ns),
            opts.max_gap_s
        ));
    }
    if metrics.rpe.len() < distances.len() {
        let skipped: Vec<String> = distances
            .iter()
            .filter(|d| !metrics.rpe.iter().any(|r| r.distance_m == **d))
            .map(|d| format!("{d}"))
            .collect();
        metrics.warnings.push(format!(
            "relative errors over {} m skipped: the paired path is only {:.2} m long",
            skipped.join(", "),
            metrics.distance_m
        ));
    }
}

impl Metrics {
    /// A few lines for the terminal.
    pub fn table(&self) -> String {
        let mut s = format!(
            "{} poses paired over {:.1} s and {:.2} m of ground truth ({} unpaired)\n\
             ATE ({} aligned{}): RMSE {:.4} m, mean {:.4} m, median {:.4} m, max {:.4} m; rotation RMSE {:.3}° \
             ({:.3}° aligned by the orientations)\n",
            self.matched,
            self.duration_s,
            self.distance_m,
            self.unmatched,
            self.alignment.name(),
            if self.alignment == Alignment::Sim3 { format!(", scale {:.4}", self.scale) } else { String::new() },
            self.ate_rmse_m,
            self.ate_mean_m,
            self.ate_median_m,
            self.ate_max_m,
            self.rotation_rmse_deg,
            self.rotation_rmse_oriented_deg
        );
        if self.pieces.len() > 1 {
            let each: Vec<String> = self
                .pieces
                .iter()
                .map(|p| format!("{:.1}–{:.1} s ATE {:.4} m", p.from_s, p.to_s, p.ate_rmse_m))
                .collect();
            s.push_str(&format!("{} pieces, each aligned by itself: {}\n", self.pieces.len(), each.join("; ")));
        }
        for r in &self.rpe {
            s.push_str(&format!(
                "RPE over {:>6.2} m ({:>5} pairs): translation RMSE {:.4} m (mean {:.2} %), rotation mean {:.3}°\n",
                r.distance_m, r.pairs, r.trans_rmse_m, r.trans_mean_percent, r.rot_mean_deg
            ));
        }
        if let (Some(g), Some(a)) = (self.bias_rmse_gyro, self.bias_rmse_accel) {
            s.push_str(&format!(
                "bias RMSE after {:.1} s ({} samples): gyro {:.3e} rad/s, accel {:.3e} m/s²\n",
                self.bias_from_s, self.bias_samples, g, a
            ));
        }
        if let (Some(g), Some(a)) = (self.bias_nees_gyro_axes, self.bias_nees_accel_axes) {
            s.push_str(&format!("{}\n", nees_line(g, a)));
        }
        s
    }
}
