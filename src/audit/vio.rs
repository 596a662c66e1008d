//! The audit of a VIO run: the time offsets between camera and IMU and
//! between accelerometer and gyro, which a calibration recording cannot show
//! (its static intervals do not depend on timing, and a motion's integrated
//! rotation only on its start and end).
//!
//! The model's prediction is the estimator's own: every measurement residual
//! (reprojection, IMU and bias random walk) at the estimate it had when its
//! oldest state left the window ([`ResidualTally`]), whitened by the pixel σ
//! and the IMU noise. The **gap** is χ²/dof − 1 of those residuals.
//!
//! A candidate offset is fitted by its profile likelihood: the run is repeated
//! with the input corrected by trial offsets ([`VioInput::with_time_offsets`]),
//! each run solved by the sliding-window solver, and χ²/dof is minimized over
//! the offset (a grid of [`VioAuditOptions::step_s`], widened while the
//! minimum is at its edge, then the vertex of a least-squares parabola through
//! the runs around the best one). A VIO run's χ² is smooth in the offset only
//! up to a scatter of a few tenths of a percent — keyframe, outlier and
//! triangulation decisions change with any change of the input — so the
//! offset's σ comes from the parabola's own scatter, and the test is a
//! Student-t test of the fitted offset against the starting one (Bonferroni
//! over the candidates, with ΔBIC > 0 from the parabola's χ² drop). The most
//! significant candidate is added, then the search repeats.
//!
//! ```no_run
//! use tumble::audit::vio::{audit_vio, VioAuditOptions};
//! use tumble::vio::VioInput;
//! let input = VioInput::from_asl("flight_asl/".as_ref(), None).unwrap();
//! let audit = audit_vio(&input, &VioAuditOptions::default(), None).unwrap();
//! println!("{}", audit.verdict());
//! ```

use super::AuditError;
use super::{CandidateScore, Effect};
use crate::calib::ImuCalibration;
use crate::plot::{ScatterChart, Series, AXIS_COLORS};
use crate::vio::{run, ResidualTally, VioInput, VioOptions};
use crate::OptionError;
use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;
use statrs::distribution::{ContinuousCDF, StudentsT};
use std::fmt::Write as _;
use std::path::Path;

/// Options of [`audit_vio`].
#[derive(Clone, Debug)]
pub struct VioAuditOptions {
    /// The estimator's options (covariances are switched off: not needed here).
    pub vio: VioOptions,
    /// Family-wise significance level; each candidate is tested at `alpha / candidates`.
    pub alpha: f64,
    /// Candidates: `camera_imu_time_offset`, `accel_gyro_time_offset` (others are ignored with a note).
    pub candidates: Vec<Effect>,
    /// Spacing of the offset grid \[s\].
    pub step_s: f64,
    /// Largest offset searched \[s\].
    pub max_offset_s: f64,
    /// Most offsets to add.
    pub max_effects: usize,
}

/// Keyframe parallax the audit's runs use at most \[px\] (see [`VioAuditOptions::new`]).
pub const AUDIT_KEYFRAME_PARALLAX_PX: f64 = 10.0;
/// Longest keyframe interval the audit's runs use \[s\] (see [`VioAuditOptions::new`]).
pub const AUDIT_KEYFRAME_INTERVAL_S: f64 = 0.5;

impl Default for VioAuditOptions {
    fn default() -> Self {
        VioAuditOptions::new(VioOptions::default())
    }
}

impl VioAuditOptions {
    /// Check every option once, before any work ([`audit_vio`] calls it).
    pub fn validate(&self) -> Result<(), OptionError> {
        if !(self.alpha > 0.0 && self.alpha < 1.0) {
            return Err(OptionError::new("--alpha", format!("must be in (0, 1), got {}", self.alpha)));
        }
        if !(self.step_s.is_finite() && self.step_s > 0.0 && self.step_s <= 0.02) {
            return Err(OptionError::new("--offset-step-ms", format!("must be in (0, 20], got {}", 1e3 * self.step_s)));
        }
        OptionError::positive("--max-offset", self.max_offset_s, "seconds")?;
        self.vio.validate()
    }

    /// The audit's defaults around the estimator options `vio`, with five
    /// changes: the triad's single noise figures instead of per-axis ones
    /// (see the comment in the body); no covariances (not needed); midpoint IMU integration —
    /// zero-order hold lags the motion by half a sample period, a time offset
    /// of the estimator's own that the audit would otherwise find;
    /// keyframes at least every [`AUDIT_KEYFRAME_PARALLAX_PX`] /
    /// [`AUDIT_KEYFRAME_INTERVAL_S`], with no shortest interval — more, shorter IMU factors carry the
    /// accelerometer–gyro offset into the χ² (with the estimator's default
    /// 20 px / 1 s a hidden 10 ms offset was missed); and the whole window
    /// solved at every frame, the estimator these figures were validated with.
    pub fn new(vio: VioOptions) -> Self {
        let mut vio = vio;
        vio.solver.covariances = false;
        vio.window.keyframe_parallax_px = vio.window.keyframe_parallax_px.min(AUDIT_KEYFRAME_PARALLAX_PX);
        vio.window.keyframe_max_interval_s = vio.window.keyframe_max_interval_s.min(AUDIT_KEYFRAME_INTERVAL_S);
        vio.window.keyframe_min_interval_s = 0.0;
        vio.window.solve_every_frame = true;
        vio.noise.imu.scheme = tumble_factors::imu_preint::Scheme::Midpoint;
        // The triad's single (largest-axis) noise figures, not the per-axis
        // ones: the profiles need a VIO that keeps its vision at the wrong
        // offsets it tries. With the BMI055's per-axis figures (gyro x/y 5×
        // tighter) the VIO trusted the IMU enough to drop most reprojections
        // under a hidden 10 ms camera–IMU offset (2 900 residual rows instead
        // of 19 000) and the χ² profile lost its parabola (p 5e-4 instead of
        // 2e-7 for the same offset found).
        vio.noise.imu.axes = None;
        VioAuditOptions {
            vio,
            alpha: 1e-3,
            candidates: vec![Effect::CameraImuTimeOffset, Effect::AccelGyroTimeOffset],
            step_s: 0.004,
            max_offset_s: 0.06,
            max_effects: 2,
        }
    }
}

/// χ² of the run against one offset, for the report's profile plot.
#[derive(Clone, Debug, serde::Serialize)]
pub struct OffsetProfile {
    /// The effect whose offset was varied.
    pub effect: String,
    /// Round of the search (0 first).
    pub round: usize,
    /// `(offset [s], χ²/dof)` of every run, sorted by offset.
    pub points: Vec<(f64, f64)>,
}

/// One added offset.
#[derive(Clone, Debug)]
pub struct VioAuditIteration {
    /// The effect added.
    pub effect: Effect,
    /// Its score (params: the offset \[s\]).
    pub score: CandidateScore,
    /// Gap before and after adding it.
    pub gap_before: f64,
    /// See `gap_before`.
    pub gap_after: f64,
    /// Every candidate's score in this round.
    pub candidates: Vec<CandidateScore>,
}

/// Result of [`audit_vio`].
#[derive(Clone, Debug)]
pub struct VioAudit {
    /// The run on the input as given.
    pub base: ResidualTally,
    /// Effects added, in order.
    pub iterations: Vec<VioAuditIteration>,
    /// Scores of the last round (none significant).
    pub last_round: Vec<CandidateScore>,
    /// The run with the offsets found.
    pub final_tally: ResidualTally,
    /// Offsets found, relative to the input as given: camera–IMU,
    /// accelerometer–gyro \[s\] (0 for one not added).
    pub offsets: [f64; 2],
    /// Their standard deviations \[s\] (NaN when not fitted).
    pub offsets_std: [f64; 2],
    /// Every profile evaluated.
    pub profiles: Vec<OffsetProfile>,
    /// Things the user should know.
    pub notes: Vec<String>,
}

impl VioAudit {
    /// The effects added.
    pub fn effects_added(&self) -> Vec<Effect> {
        self.iterations.iter().map(|i| i.effect).collect()
    }

    /// One line for the terminal.
    pub fn verdict(&self) -> String {
        let (g0, g1) = (self.base.gap(), self.final_tally.gap());
        if self.iterations.is_empty() {
            return format!("no time offset found: the VIO's residuals are explained (gap {g0:.3})");
        }
        let found: Vec<String> = self
            .iterations
            .iter()
            .map(|i| format!("{} {:+.2} ms", i.effect, 1e3 * i.score.params.first().copied().unwrap_or(f64::NAN)))
            .collect();
        let shrink = if g0 > 0.0 { 100.0 * (1.0 - g1 / g0) } else { 0.0 };
        format!("missing effect(s): {} — gap {g0:.3} → {g1:.3} ({shrink:.0} % smaller)", found.join(", "))
    }
}

/// Which slot of the offsets an effect moves.
fn slot(e: Effect) -> Option<usize> {
    match e {
        Effect::CameraImuTimeOffset => Some(0),
        Effect::AccelGyroTimeOffset => Some(1),
        _ => None,
    }
}

/// The run's residuals with the input corrected by `offsets`.
fn tally(input: &VioInput, opts: &VioOptions, offsets: [f64; 2]) -> Result<ResidualTally, AuditError> {
    let shifted = input.with_time_offsets(offsets[0], offsets[1]);
    let r = run(&shifted, opts, None)?;
    if r.residuals.dof() == 0 {
        return Err("no residual left the window (too short a run, or no keyframe marginalized)".into());
    }
    Ok(r.residuals)
}

/// A profile's minimum: offset, its σ, its run's residuals, and the test of
/// the offset against the starting one.
struct Minimum {
    offset: f64,
    std: f64,
    tally: ResidualTally,
    /// χ² drop from the starting offset to the minimum on the fitted parabola.
    delta_chi2: f64,
    /// Student-t statistic of (offset − start) / σ, and its degrees of freedom.
    t: f64,
    t_dof: usize,
}

/// Minimize χ²/dof over the offset in slot `k` (the others fixed at `at`).
///
/// χ²/dof of a VIO run is smooth in the offset only up to a scatter of a few
/// tenths of a percent (keyframe, outlier and triangulation decisions change
/// with any input change, even of a microsecond), which dwarfs the statistical
/// resolution of a 10⁵-residual run. So the minimum is the vertex of a
/// least-squares parabola through the runs within ±2.5 steps of the best one,
/// and its σ comes from that fit's own scatter (plus the χ² curvature's σ).
fn profile(
    input: &VioInput,
    opts: &VioAuditOptions,
    at: [f64; 2],
    k: usize,
    runs: &mut dyn FnMut(usize),
) -> Result<(Minimum, Vec<(f64, f64)>), AuditError> {
    let h = opts.step_s;
    let eval = |xs: &[f64]| -> Vec<(f64, Result<ResidualTally, AuditError>)> {
        xs.par_iter()
            .map(|&x| {
                let mut o = at;
                o[k] = x;
                (x, tally(input, &opts.vio, o))
            })
            .collect()
    };
    let mut pts: Vec<(f64, ResidualTally)> = Vec::new();
    let mut add = |xs: &[f64], pts: &mut Vec<(f64, ResidualTally)>| {
        let xs: Vec<f64> = xs.iter().copied().filter(|x| pts.iter().all(|p| (p.0 - x).abs() > 1e-3 * h)).collect();
        runs(xs.len());
        for (x, r) in eval(&xs) {
            // A run that fails at a trial offset is only a missing point of the profile.
            if let Ok(t) = r {
                pts.push((x, t));
            }
        }
        pts.sort_by(|a, b| a.0.total_cmp(&b.0));
    };
    let c = at[k];
    add(&[c - 2.0 * h, c - h, c, c + h, c + 2.0 * h], &mut pts);
    loop {
        if pts.len() < 3 {
            return Err(format!("only {} of the trial runs succeeded", pts.len()).into());
        }
        let i = argmin(&pts);
        let next = if i == 0 {
            pts[0].0 - h
        } else if i == pts.len() - 1 {
            pts[i].0 + h
        } else {
            break;
        };
        if (next - c).abs() > opts.max_offset_s {
            return Err(format!("the minimum lies beyond ±{:.0} ms", 1e3 * opts.max_offset_s).into());
        }
        add(&[next, next + (next - pts[i].0)], &mut pts);
    }
    // Two steps either side of the best run, a parabola through them, a run at its vertex, the parabola again.
    let best = pts[argmin(&pts)].0;
    add(&[best - 2.0 * h, best - h, best + h, best + 2.0 * h], &mut pts);
    let mut fit = fit_parabola(&pts, best, 2.5 * h).ok_or("no minimum in the profile (χ² not convex there)")?;
    if (fit.vertex - best).abs() < 2.0 * h {
        add(&[fit.vertex], &mut pts);
        fit = fit_parabola(&pts, best, 2.5 * h).ok_or("no minimum in the profile (χ² not convex there)")?;
    }
    let nearest = (0..pts.len())
        .min_by(|&a, &b| (pts[a].0 - fit.vertex).abs().total_cmp(&(pts[b].0 - fit.vertex).abs()))
        .expect("points");
    let tally = pts[nearest].1;
    let dof = tally.dof().max(1) as f64;
    // The χ² curvature's own σ (Δχ² = χ²/dof at one σ), added to the scatter's.
    let s2 = per_dof(&tally).max(1.0);
    let std = (fit.vertex_var + s2 / (fit.a * dof)).sqrt();
    let curve = pts.iter().map(|p| (p.0, per_dof(&p.1))).collect();
    let min = Minimum {
        offset: fit.vertex,
        std,
        tally,
        delta_chi2: fit.a * (c - fit.vertex).powi(2) * dof,
        t: (fit.vertex - c) / std,
        t_dof: fit.dof,
    };
    Ok((min, curve))
}

fn argmin(pts: &[(f64, ResidualTally)]) -> usize {
    (0..pts.len()).min_by(|&a, &b| per_dof(&pts[a].1).total_cmp(&per_dof(&pts[b].1))).expect("points")
}

/// χ²/dof: runs at different offsets keep slightly different residuals (keyframe,
/// outlier and triangulation decisions move with the offset), so they are compared per degree of freedom.
fn per_dof(t: &ResidualTally) -> f64 {
    t.chi2() / t.dof().max(1) as f64
}

/// `y ≈ a (x − vertex)² + c` fitted by least squares.
struct Parabola {
    a: f64,
    vertex: f64,
    /// Variance of the vertex from the fit's scatter.
    vertex_var: f64,
    /// Points − 3.
    dof: usize,
}

/// Least-squares parabola of χ²/dof against the offset over the points within
/// `half` of `centre`; `None` unless it opens upwards with at least 4 points.
fn fit_parabola(pts: &[(f64, ResidualTally)], centre: f64, half: f64) -> Option<Parabola> {
    let near: Vec<(f64, f64)> =
        pts.iter().filter(|p| (p.0 - centre).abs() <= half).map(|p| ((p.0 - centre) / half, per_dof(&p.1))).collect();
    if near.len() < 4 {
        return None;
    }
    let x = DMatrix::from_fn(near.len(), 3, |r, c| near[r].0.powi(c as i32));
    let y = DVector::from_iterator(near.len(), near.iter().map(|p| p.1));
    let xtx_inv = (x.transpose() * &x).try_inverse()?;
    let p = &xtx_inv * x.transpose() * &y;
    if p[2] <= 0.0 {
        return None;
    }
    let dof = near.len() - 3;
    let s2 = (&y - &x * &p).norm_squared() / dof as f64;
    // vertex u = −p1 / (2 p2) in scaled units; its gradient in (p0, p1, p2).
    let u = -p[1] / (2.0 * p[2]);
    let g = DVector::from_vec(vec![0.0, -1.0 / (2.0 * p[2]), p[1] / (2.0 * p[2] * p[2])]);
    let var_u = s2 * (g.transpose() * &xtx_inv * &g)[0];
    Some(Parabola { a: p[2] / (half * half), vertex: centre + u * half, vertex_var: var_u * half * half, dof })
}

/// The score of an offset: the drop of χ² on the fitted parabola (ΔBIC from
/// it), and a two-sided Student-t test of the offset against its start with
/// the parabola's scatter (the `f` column holds t²).
fn offset_score(e: Effect, m: &Minimum, threshold: f64) -> CandidateScore {
    let p_value = StudentsT::new(0.0, 1.0, m.t_dof.max(1) as f64).map(|d| 2.0 * d.sf(m.t.abs())).unwrap_or(1.0);
    let rows = m.tally.reprojection_rows + m.tally.imu_rows;
    let delta_bic = m.delta_chi2 - (rows.max(1) as f64).ln();
    CandidateScore {
        effect: e.id().to_string(),
        dof_added: 1,
        params: vec![m.offset],
        params_std: vec![m.std],
        chi2: m.tally.chi2(),
        delta_chi2: m.delta_chi2,
        f: m.t * m.t,
        p_value,
        delta_bic,
        gap: m.tally.gap(),
        significant: p_value < threshold && delta_bic > 0.0,
        wald: m.t * m.t,
        testable: true,
    }
}

/// Audit a VIO input for the time offsets of [`VioAuditOptions::candidates`].
/// `progress` is called with the number of VIO runs done so far.
pub fn audit_vio(
    input: &VioInput,
    opts: &VioAuditOptions,
    mut progress: Option<&mut dyn FnMut(usize)>,
) -> Result<VioAudit, AuditError> {
    opts.validate().map_err(|e| e.to_string())?;
    let mut notes = Vec::new();
    let mut candidates = Vec::new();
    for &e in &opts.candidates {
        match slot(e) {
            Some(_) => candidates.push(e),
            None => notes.push(format!("{e} is a sensor-model effect: audit the calibration recording for it")),
        }
    }
    if !(opts.step_s > 0.0 && opts.max_offset_s >= opts.step_s) {
        return Err(format!(
            "the offset step ({} s) must be > 0 and ≤ the largest offset ({} s)",
            opts.step_s, opts.max_offset_s
        )
        .into());
    }
    let mut done = 0;
    let mut runs = |n: usize| {
        done += n;
        if let Some(p) = progress.as_mut() {
            p(done);
        }
    };
    let mut offsets = [0.0; 2];
    let mut offsets_std = [f64::NAN; 2];
    let base = tally(input, &opts.vio, offsets).map_err(|e| format!("{}: the VIO run failed: {e}", input.name))?;
    runs(1);
    let mut current = base;
    let (mut iterations, mut last_round, mut profiles) = (Vec::new(), Vec::new(), Vec::new());
    while iterations.len() < opts.max_effects {
        let remaining: Vec<Effect> = candidates
            .iter()
            .copied()
            .filter(|e| !iterations.iter().any(|i: &VioAuditIteration| i.effect == *e))
            .collect();
        if remaining.is_empty() {
            break;
        }
        let threshold = opts.alpha / remaining.len() as f64;
        let mut scores = Vec::new();
        let mut best: Option<(Effect, CandidateScore, Minimum)> = None;
        for e in remaining {
            let k = slot(e).expect("time-offset candidates only");
            let (m, curve) = match profile(input, opts, offsets, k, &mut runs) {
                Ok(x) => x,
                Err(why) => {
                    notes.push(format!("{e}: not fitted ({why})"));
                    continue;
                }
            };
            profiles.push(OffsetProfile { effect: e.id().into(), round: iterations.len(), points: curve });
            let s = offset_score(e, &m, threshold);
            if s.significant && best.as_ref().is_none_or(|b| s.delta_bic > b.1.delta_bic) {
                best = Some((e, s.clone(), m));
            }
            scores.push(s);
        }
        scores.sort_by(|a, b| b.delta_bic.total_cmp(&a.delta_bic));
        let Some((effect, s, m)) = best else {
            last_round = scores;
            break;
        };
        let k = slot(effect).expect("time-offset candidates only");
        offsets[k] = m.offset;
        offsets_std[k] = m.std;
        iterations.push(VioAuditIteration {
            effect,
            gap_before: current.gap(),
            gap_after: m.tally.gap(),
            score: s,
            candidates: scores,
        });
        current = m.tally;
    }
    Ok(VioAudit { base, iterations, last_round, final_tally: current, offsets, offsets_std, profiles, notes })
}

/// `audit.json` of a VIO audit, in the calibration audit's layout: the
/// iterations (`params` holds `offset_s`), `effects_added`, the gaps, and the
/// offsets, profiles and notes.
pub fn json(a: &VioAudit) -> serde_json::Value {
    use serde_json::json;
    let iterations: Vec<serde_json::Value> = a
        .iterations
        .iter()
        .map(|it| super::report::iteration_json(it.effect, &it.score, it.gap_before, it.gap_after, &it.candidates))
        .collect();
    json!({
        "kind": "vio",
        "iterations": iterations,
        "effects_added": a.effects_added().iter().map(|e| e.id()).collect::<Vec<_>>(),
        "initial_gap": a.base.gap(),
        "final_gap": a.final_tally.gap(),
        "final_chi2_per_dof": per_dof(&a.final_tally),
        "initial_residuals": a.base,
        "final_residuals": a.final_tally,
        "time_offsets": {
            "camera_imu_s": a.offsets[0], "camera_imu_s_std": a.offsets_std[0],
            "accel_gyro_s": a.offsets[1], "accel_gyro_s_std": a.offsets_std[1],
        },
        "last_round": a.last_round,
        "profiles": a.profiles,
        "verdict": a.verdict(),
        "notes": a.notes,
    })
}

/// The calibration with the offsets found added to its own (a VIO input built
/// with a calibration is already corrected by the calibration's offsets, so
/// what the audit finds is the remainder).
pub fn with_offsets(cal: &ImuCalibration, a: &VioAudit) -> ImuCalibration {
    let mut o = cal.time_offsets.unwrap_or_default();
    for it in &a.iterations {
        let (v, s) = (it.score.params[0], it.score.params_std[0]);
        match it.effect {
            Effect::CameraImuTimeOffset => (o.camera_imu_s, o.camera_imu_s_std) = (o.camera_imu_s + v, s),
            Effect::AccelGyroTimeOffset => (o.accel_gyro_s, o.accel_gyro_s_std) = (o.accel_gyro_s + v, s),
            _ => {}
        }
    }
    ImuCalibration { time_offsets: Some(o), ..cal.clone() }
}

/// Write `audit.json`, `audit.md`, `audit_time_offsets.png` (χ²/dof of every
/// run against the offset tried) and, when a calibration was given,
/// `calibration.json` with the offsets, into `dir`.
pub fn write(a: &VioAudit, calibration: Option<&ImuCalibration>, dir: &Path) -> Result<Vec<String>, AuditError> {
    let paths = crate::io::staging::write_staged(dir, |stage| {
        write_unstaged(a, calibration, stage).map(|names| names.iter().map(|n| stage.join(n)).collect::<Vec<_>>())
    })?;
    Ok(paths.iter().filter_map(|p| p.file_name().map(|n| n.to_string_lossy().into_owned())).collect())
}

fn write_unstaged(a: &VioAudit, calibration: Option<&ImuCalibration>, dir: &Path) -> Result<Vec<String>, AuditError> {
    let put = |name: &str, text: String| super::report::put_file(dir, name, text);
    let mut written = vec![put("audit.json", serde_json::to_string_pretty(&json(a)).map_err(|e| e.to_string())?)?];
    if let Some(c) = calibration {
        let file = crate::model::calibration::CalibrationFile::from(&with_offsets(c, a));
        written.push(put("calibration.json", serde_json::to_string_pretty(&file).map_err(|e| e.to_string())?)?);
    }
    let figure = "audit_time_offsets.png";
    if !a.profiles.is_empty() {
        profile_figure(a, &dir.join(figure))?;
    }
    let mut md = String::from("# Audit of a VIO run: time offsets\n\n");
    let _ = writeln!(md, "{}\n", a.verdict());
    md.push_str("| step | effect | offset [ms] | σ [ms] | p-value | ΔBIC | gap |\n|---|---|---|---|---|---|---|\n");
    let _ = writeln!(md, "| 0 | as given | | | | | {:.4} |", a.base.gap());
    let mut row = |step: &str, name: &str, s: &CandidateScore, gap: f64| {
        let (x, sd) = (1e3 * s.params[0], 1e3 * s.params_std[0]);
        let (p, bic) = (s.p_value, s.delta_bic);
        let _ = writeln!(md, "| {step} | {name} | {x:+.3} | {sd:.3} | {p:.1e} | {bic:.1} | {gap:.4} |");
    };
    for (i, it) in a.iterations.iter().enumerate() {
        row(&(i + 1).to_string(), it.effect.id(), &it.score, it.gap_after);
    }
    for s in &a.last_round {
        row("–", &format!("{} (not significant)", s.effect), s, s.gap);
    }
    if !a.profiles.is_empty() {
        let _ = writeln!(md, "\n![χ²/dof against the offset]({figure})");
    }
    for n in &a.notes {
        let _ = writeln!(md, "\n- {n}");
    }
    written.push(put("audit.md", md)?);
    if !a.profiles.is_empty() {
        written.push(figure.into());
    }
    Ok(written)
}

fn profile_figure(a: &VioAudit, path: &Path) -> Result<(), AuditError> {
    let series = a
        .profiles
        .iter()
        .enumerate()
        .flat_map(|(i, p)| {
            let color = AXIS_COLORS[i % AXIS_COLORS.len()];
            let pts: Vec<(f64, f64)> = p.points.iter().map(|(x, y)| (1e3 * x, *y)).collect();
            [
                Series { label: String::new(), color, points: pts.clone(), line: true },
                Series { label: format!("{} (round {})", p.effect, p.round + 1), color, points: pts, line: false },
            ]
        })
        .collect();
    ScatterChart {
        title: "VIO residuals against the time offset tried".into(),
        x_label: "offset [ms]".into(),
        y_label: "χ²/dof".into(),
        series,
        ..Default::default()
    }
    .write_png(path, 900, 500)?;
    Ok(())
}
