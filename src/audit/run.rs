//! The audit of a calibration recording, stage by stage (see
//! [`audit_with_progress`]).

use super::fit::{self, Fit, Noise};
use super::structure;
use super::{
    Audit, AuditData, AuditError, AuditIteration, AuditOptions, CandidateScore, Effect, DISTINGUISHABLE_BIC,
    INITIAL_RANDOM_WALK, MAX_LR_WALD_RATIO, MIN_TEMPERATURE_SPAN, WALK_DETERMINED_DOF,
};
use crate::calib::{calibrate, CalibOptions, ImuCalibration};
use crate::io::ImuRecording;
use nalgebra::{DMatrix, Vector3};
use rayon::prelude::*;
use tumble_factors::imu_calib::{AccelParams, GyroMatrix};
use tumble_factors::imu_effects::{Layout, NonlinearityForm};

/// Run the audit of a calibration recording against `calibration`.
pub fn audit(rec: &ImuRecording, calibration: &ImuCalibration, opts: &AuditOptions) -> Result<Audit, AuditError> {
    audit_with_progress(rec, calibration, opts, &mut |_| {})
}

/// [`audit`], with a line to `progress` as each stage starts and each round
/// ends (an audit of a long recording without a noise file takes tens of
/// seconds).
///
/// The stages: the static intervals (the calibration's detection, kept
/// where the calibrated gyro is still) → the candidates this recording can
/// test → the bias random walks (given, or estimated with every candidate
/// family in the model) → forward selection, one effect per round → the
/// residuals left tested for structure → the calibration with the effects.
pub fn audit_with_progress(
    rec: &ImuRecording,
    calibration: &ImuCalibration,
    opts: &AuditOptions,
    progress: &mut dyn FnMut(&str),
) -> Result<Audit, AuditError> {
    let fail = |m: String| AuditError(format!("{}: {m}", rec.source_name()));
    opts.validate().map_err(|e| fail(e.to_string()))?;
    let (accel, gyro, gyro_bias) = calibration.inverse_params().map_err(|e| fail(e.to_string()))?;
    let mut notes = Vec::new();
    let data = static_data(rec, calibration, opts, &mut notes).map_err(fail)?;
    let candidates = testable_candidates(&data, opts, &mut notes);
    let start = fit::start_values(&data, accel, gyro, gyro_bias);
    let scales = (calibration.gyro.mean_scale(), calibration.accel.mean_scale());
    let (noise, walk_degrees_of_freedom) =
        walks(&data, &start, &candidates, opts, scales, progress, &mut notes).map_err(fail)?;
    let base = fit::solve(&data, &noise, &Layout { effects: Vec::new() }, &start).map_err(|e| fail(e.to_string()))?;
    let selection = select(&data, &noise, &base, &candidates, opts, progress, &mut notes);
    progress("testing the residuals left for structure");
    let structure = structure::test(&data, &noise, &selection.current).map_err(|e| fail(e.to_string()))?;
    let calibration = calibrated(calibration, &data, &noise, &selection.current).map_err(|e| fail(e.to_string()))?;
    Ok(Audit {
        data,
        base,
        iterations: selection.iterations,
        last_round: selection.last_round,
        calibration,
        random_walk_axes: noise.walks,
        walks_estimated: opts.noise.is_none(),
        walk_degrees_of_freedom,
        structure,
        alpha: opts.alpha,
        notes,
    })
}

/// The static intervals' data: the calibration's detection (only the
/// detection is used: a calibration of this recording that fails its verdict
/// still found the static intervals), kept where the calibrated gyro is still.
fn static_data(
    rec: &ImuRecording,
    calibration: &ImuCalibration,
    opts: &AuditOptions,
    notes: &mut Vec<String>,
) -> Result<AuditData, String> {
    let (_, gyro, gyro_bias) = calibration.inverse_params().map_err(|e| e.to_string())?;
    let detection = CalibOptions { gravity: calibration.gravity, ..opts.detection.clone() };
    let detected = match calibrate(rec, &detection) {
        Ok(r) => r,
        Err(e) => match e.diagnosis {
            Some(d) => *d,
            None => return Err(format!("static intervals: {}", e.message)),
        },
    };
    let intervals = still_intervals(rec, &detected.intervals, &gyro, &gyro_bias, 0.5 * detection.window_s, notes);
    let data = AuditData::new(rec, &intervals, calibration.gravity).map_err(|e| e.to_string())?;
    let unsettled = crate::calib::detect::unsettled(&data.within, opts.alpha);
    if !unsettled.is_empty() {
        notes.push(format!(
            "inside the static intervals {} (the halves' means differ by that many times the variance the white \
             noise gives): {}; the intervals' means carry it as noise the model does not have",
            crate::calib::detect::describe(&unsettled),
            crate::calib::detect::UNSETTLED_CAUSES
        ));
    }
    Ok(data)
}

/// The candidates a calibration recording can test: the sensor's own effects
/// (not those that need a VIO run), without the temperature effects when the
/// recording has no temperature or it hardly varies (each left out is noted).
fn testable_candidates(data: &AuditData, opts: &AuditOptions, notes: &mut Vec<String>) -> Vec<Effect> {
    let mut candidates: Vec<Effect> = opts.candidates.iter().copied().filter(|e| e.in_sensor_model()).collect();
    let span = data
        .statics
        .iter()
        .fold((f64::MAX, f64::MIN), |(lo, hi), s| (lo.min(s.context.dtemp), hi.max(s.context.dtemp)));
    let no_temperature = if !data.has_temperature {
        Some("no temperature column".to_string())
    } else if span.1 - span.0 < MIN_TEMPERATURE_SPAN {
        Some(format!("the temperature varies by only {:.2} °C between static intervals", span.1 - span.0))
    } else {
        None
    };
    if let Some(why) = no_temperature {
        let skipped: Vec<&str> = candidates.iter().filter(|e| e.needs_temperature()).map(|e| e.id()).collect();
        if !skipped.is_empty() {
            notes.push(format!("{why}: {} not tested", skipped.join(", ")));
        }
        candidates.retain(|e| !e.needs_temperature());
    }
    for e in &opts.candidates {
        if !e.in_sensor_model() {
            notes.push(format!("{e} needs a VIO run (`tumble audit --vio`); not tested on a calibration recording"));
        }
    }
    candidates
}

/// The noise model: the bias random walks of the noise file (per axis when
/// it has them, tumble's `axes` block), or estimated from the recording
/// ([`estimate_walks`]) with their degrees of freedom. Walks are in raw
/// units: physical ones times the sensor's mean scale `scales` (gyro, accel).
fn walks(
    data: &AuditData,
    start: &tumble_solvers::Values,
    candidates: &[Effect],
    opts: &AuditOptions,
    (kg, ka): (f64, f64),
    progress: &mut dyn FnMut(&str),
    notes: &mut Vec<String>,
) -> Result<(Noise, Option<fit::Walks>), String> {
    let (rw_g, rw_a) = match &opts.noise {
        Some(n) => match &n.axes {
            Some(x) => (x.gyroscope_random_walk, x.accelerometer_random_walk),
            None => ([n.gyroscope_random_walk; 3], [n.accelerometer_random_walk; 3]),
        },
        None => ([INITIAL_RANDOM_WALK.0; 3], [INITIAL_RANDOM_WALK.1; 3]),
    };
    let noise = Noise::new(data, start, (rw_g.map(|w| w * kg), rw_a.map(|w| w * ka))).map_err(|e| e.to_string())?;
    if opts.noise.is_some() {
        return Ok((noise, None));
    }
    progress(&format!(
        "estimating the bias random walks from the recording ({} static intervals; no noise file)",
        data.statics.len()
    ));
    let (noise, dof) = estimate_walks(data, noise, start, candidates, (kg, ka), notes)?;
    Ok((noise, Some(dof)))
}

/// The walks from the recording, with every candidate family in the model
/// so that none of them can hide in the walk: richest model first; a model
/// the recording cannot support (a singular information matrix) gives way to
/// a smaller one. Notes what was estimated, and when the recording does not
/// determine it.
fn estimate_walks(
    data: &AuditData,
    noise: Noise,
    start: &tumble_solvers::Values,
    candidates: &[Effect],
    (kg, ka): (f64, f64),
    notes: &mut Vec<String>,
) -> Result<(Noise, fit::Walks), String> {
    let floor = (fit::MIN_RANDOM_WALK.0 * kg, fit::MIN_RANDOM_WALK.1 * ka);
    let mut tried = Vec::new();
    let mut result = None;
    for layout in saturated(candidates) {
        match fit::solve_walks(data, &noise, &layout, start, true, floor) {
            Ok(r) => {
                result = Some(r);
                break;
            }
            Err(e) => tried.push(format!("with {} effects: {e}", layout.effects.len())),
        }
    }
    let Some((sat, n)) = result else {
        return Err(format!("the bias random walks could not be estimated ({})", tried.join("; ")));
    };
    let axes = |w: &[f64; 3], k: f64| w.iter().map(|x| format!("{:.2e}", x / k)).collect::<Vec<_>>().join(", ");
    notes.push(format!(
        "no noise file: bias random walks estimated from the recording (with {} candidate effects in the model), \
         x, y, z: gyro {} rad/s²/√Hz, accel {} m/s³/√Hz",
        sat.layout.effects.len(),
        axes(&n.walks.0, kg),
        axes(&n.walks.1, ka)
    ));
    let r = fit::walk_degrees_of_freedom(data, &n, &sat).map_err(|e| e.to_string())?;
    if least_determined(&r) < WALK_DETERMINED_DOF {
        let dof = |x: &[f64; 3]| x.iter().map(|v| format!("{v:.1}")).collect::<Vec<_>>().join(", ");
        notes.push(format!(
            "the bias random walks are not determined by this recording: their estimates rest on {} (gyro) and \
             {} (accel) degrees of freedom, x, y, z, where a walk needs about {WALK_DETERMINED_DOF:.0} per sensor \
             (a hand tumble's holds measure a bias change over a few seconds less precisely than the walk moves \
             it). A slow drift (temperature, bias drift) is judged against walks uncertain by a factor of several \
             either way — too large a walk hides one, too small a walk makes one of the wander: give --noise \
             (`tumble allan` on a static recording) for a firm verdict on it",
            dof(&r.0),
            dof(&r.1)
        ));
    }
    Ok((n, r))
}

/// What forward selection found.
struct Selection {
    /// The model with every effect added.
    current: Fit,
    iterations: Vec<AuditIteration>,
    /// The last round's scores when it added nothing.
    last_round: Vec<CandidateScore>,
}

/// Forward selection: each round fits every candidate of a family not yet in
/// the model, adds the most significant (Bonferroni over the round), until
/// none is or `max_effects` are in.
fn select(
    data: &AuditData,
    noise: &Noise,
    base: &Fit,
    candidates: &[Effect],
    opts: &AuditOptions,
    progress: &mut dyn FnMut(&str),
    notes: &mut Vec<String>,
) -> Selection {
    let mut current = base.clone();
    let mut iterations: Vec<AuditIteration> = Vec::new();
    let mut last_round = Vec::new();
    let mut rounds: Vec<Vec<CandidateScore>> = Vec::new();
    while iterations.len() < opts.max_effects {
        let families: Vec<&str> = current.layout.effects.iter().map(|e| e.family()).collect();
        let remaining: Vec<Effect> = candidates.iter().copied().filter(|e| !families.contains(&e.family())).collect();
        if remaining.is_empty() {
            break;
        }
        let round = iterations.len() + 1;
        progress(&format!("round {round}: fitting {} candidates", remaining.len()));
        let (scores, best) = score_round(data, noise, &current, &remaining, opts.alpha, round, notes);
        rounds.push(scores.clone());
        let Some((s, f)) = best else {
            last_round = scores;
            break;
        };
        let effect = Effect::from_id(&s.effect).expect("scored effects come from the vocabulary");
        progress(&format!(
            "round {round}: {} is the most significant (gap {:.3} → {:.3})",
            effect,
            current.gap(),
            f.gap()
        ));
        let other_forms = scores
            .iter()
            .filter(|c| c.testable)
            .filter_map(|c| Effect::from_id(&c.effect).map(|e| (e, c.delta_bic)))
            .filter(|(e, _)| *e != effect && e.family() == effect.family())
            .collect();
        iterations.push(AuditIteration {
            effect,
            gap_before: current.gap(),
            gap_after: f.gap(),
            score: s,
            candidates: scores,
            other_forms,
            confounded_with: Vec::new(),
            fit: f.clone(),
        });
        current = f;
    }
    mark_confounded(&mut iterations, &rounds);
    Selection { current, iterations, last_round }
}

/// One round: every `remaining` candidate added to `current` and scored
/// (Bonferroni threshold `alpha` over the round), best first, with the most
/// significant testable one and its fit; a failed fit or a candidate the
/// recording cannot test is noted.
fn score_round(
    data: &AuditData,
    noise: &Noise,
    current: &Fit,
    remaining: &[Effect],
    alpha: f64,
    round: usize,
    notes: &mut Vec<String>,
) -> (Vec<CandidateScore>, Option<(CandidateScore, Fit)>) {
    let threshold = alpha / remaining.len() as f64;
    let fits: Vec<(Effect, Result<Fit, AuditError>)> = remaining
        .par_iter()
        .map(|&e| {
            let mut layout = current.layout.clone();
            layout.effects.push(e);
            (e, fit::solve(data, noise, &layout, &current.values))
        })
        .collect();
    let mut scores = Vec::new();
    let mut best: Option<(CandidateScore, Fit)> = None;
    for (e, f) in fits {
        let f = match f {
            Ok(f) => f,
            Err(m) => {
                notes.push(format!("{e}: fit failed ({m})"));
                continue;
            }
        };
        let s = score(e, current, &f, threshold);
        if s.significant && best.as_ref().is_none_or(|b| s.delta_bic > b.0.delta_bic) {
            best = Some((s.clone(), f));
        }
        scores.push(s);
    }
    scores.sort_by(|a, b| b.delta_bic.total_cmp(&a.delta_bic));
    for c in scores.iter().filter(|c| !c.testable) {
        let would = if Effect::from_id(&c.effect).and_then(|e| e.nonlinearity()).is_some() {
            "turns of different sizes and speeds, about other axes than the body's, would"
        } else {
            "more varied poses and turns might"
        };
        notes.push(format!(
            "round {round}: {} not tested — its fit trades off against the calibration's own parameters on this \
             recording (χ² drop {:.1}, but {:.1} from its parameters and their covariance): the recording cannot \
             tell it from the calibration ({would})",
            c.effect, c.delta_chi2, c.wald
        ));
    }
    (scores, best)
}

/// The degrees of freedom of the sensor whose walks rest on fewer (each
/// triad's axes summed).
pub(super) fn least_determined(r: &fit::Walks) -> f64 {
    r.0.iter().sum::<f64>().min(r.1.iter().sum())
}

/// The models the walks are estimated with, richest first: of every candidate
/// family the richest form — temperature effects quadratic, scale
/// nonlinearity even and odd (the other two forms are close to these) — so a
/// drift, a temperature effect or an orientation-dependent bias is fitted, not
/// taken for walk; then without the nonlinearities; then without any effect.
fn saturated(candidates: &[Effect]) -> Vec<Layout> {
    let keep = |e: &Effect| match e.family() {
        "temperature_bias" | "temperature_scale" => e.id().ends_with("_quadratic"),
        "gyro_scale_nonlinearity" | "accel_scale_nonlinearity" => {
            matches!(e.nonlinearity(), Some((_, NonlinearityForm::Even | NonlinearityForm::Odd)))
        }
        _ => true,
    };
    let all: Vec<Effect> = candidates.iter().copied().filter(keep).collect();
    let linear: Vec<Effect> = all.iter().copied().filter(|e| e.nonlinearity().is_none()).collect();
    vec![Layout { effects: all }, Layout { effects: linear }, Layout { effects: Vec::new() }]
}

/// Mark, for each added effect, the significant effects of other families
/// with a ΔBIC within [`DISTINGUISHABLE_BIC`] of it whose drop mostly
/// vanished in the next round (less than a quarter left): they explained the
/// same residual. `rounds[i]` are the scores of round `i`.
fn mark_confounded(iterations: &mut [AuditIteration], rounds: &[Vec<CandidateScore>]) {
    for (i, it) in iterations.iter_mut().enumerate() {
        let Some(next) = rounds.get(i + 1) else { continue };
        it.confounded_with = it
            .candidates
            .iter()
            .filter(|c| c.significant && it.score.delta_bic - c.delta_bic < DISTINGUISHABLE_BIC)
            .filter_map(|c| Effect::from_id(&c.effect).map(|e| (e, c.delta_chi2)))
            .filter(|(e, _)| e.family() != it.effect.family())
            .filter(|(e, drop)| {
                next.iter().find(|n| n.effect == e.id()).is_some_and(|n| n.delta_chi2 < 0.25 * drop && !n.significant)
            })
            .map(|(e, _)| e)
            .collect();
    }
}

/// Largest mean rate of a static interval \[rad/s\] (3 °/s): far above any bias
/// or effect of a MEMS gyro once its turn-on bias is removed, far below a hand's turn.
pub const MAX_STATIC_RATE: f64 = 0.05;

/// The cores of the detected intervals (`trim_s` cut from both ends), without
/// those that turn steadily (a constant-rate turn about gravity keeps the
/// accelerometer still and passes the variance test) or hold motion (gyro
/// variance above twice the median interval's).
fn still_intervals(
    rec: &ImuRecording,
    intervals: &[crate::calib::detect::Interval],
    gyro: &GyroMatrix,
    bias: &Vector3<f64>,
    trim_s: f64,
    notes: &mut Vec<String>,
) -> Vec<crate::calib::detect::Interval> {
    use crate::calib::detect::{mean3, variance_norm, Interval};
    let mg = tumble_factors::imu_calib::gyro_matrix(gyro);
    // The detector's window reaches half its width into the motions: keep the core.
    let period = rec.duration() / (rec.len().max(2) - 1) as f64;
    let margin = ((trim_s / period).round() as usize).max(1);
    let cores: Vec<Interval> = intervals
        .iter()
        .map(|iv| {
            let m = margin.min(iv.len() / 4);
            Interval { start: iv.start + m, end: iv.end - m }
        })
        .collect();
    let var: Vec<f64> = cores.iter().map(|iv| variance_norm(&rec.gyro[iv.start..iv.end])).collect();
    let mut sorted = var.clone();
    sorted.sort_by(f64::total_cmp);
    let median = sorted[sorted.len() / 2];
    let mut out = Vec::new();
    for (k, iv) in cores.iter().enumerate() {
        let mean = Vector3::from(mean3(&rec.gyro[iv.start..iv.end]));
        let rate = (mg * (mean - bias)).norm();
        let why = if k > 0 && rate > MAX_STATIC_RATE {
            format!("turns at {:.1} °/s", rate.to_degrees())
        } else if k > 0 && var[k] > 2.0 * median {
            format!("its gyro varies {:.1}× more than a typical interval's (motion inside)", var[k] / median)
        } else {
            out.push(*iv);
            continue;
        };
        notes.push(format!(
            "static interval {:.2}–{:.2} s (line {}) {why}: not static, left out",
            rec.t[iv.start],
            rec.t[iv.end - 1],
            rec.lines.line(iv.start)
        ));
    }
    out
}

fn score(effect: Effect, current: &Fit, with: &Fit, threshold: f64) -> CandidateScore {
    let j = with.layout.effects.len() - 1;
    let s = CandidateScore::from_drop(
        effect,
        (current.chi2() - with.chi2(), with.chi2(), with.dof(), with.measurements()),
        with.effect(j),
        with.effect_std.get(j).cloned().unwrap_or_default(),
        with.gap(),
        threshold,
    );
    let wald = with.effect_wald.get(j).copied().unwrap_or(f64::INFINITY);
    let ratio = wald / s.delta_chi2.max(1e-300);
    let testable =
        !s.significant || (ratio.is_finite() && (1.0 / MAX_LR_WALD_RATIO..=MAX_LR_WALD_RATIO).contains(&ratio));
    CandidateScore { wald, testable, significant: s.significant && testable, ..s }
}

/// The calibration re-solved with the effects, in the paper's convention.
fn calibrated(
    given: &ImuCalibration,
    data: &AuditData,
    noise: &Noise,
    fit: &Fit,
) -> Result<ImuCalibration, AuditError> {
    let a = *fit.values.get::<AccelParams>(fit::KEY_ACCEL).map_err(|e| e.to_string())?;
    let g = *fit.values.get::<GyroMatrix>(fit::KEY_GYRO).map_err(|e| e.to_string())?;
    let b = *fit.values.get::<Vector3<f64>>(fit::key_bias(0)).map_err(|e| e.to_string())?;
    let [ca, cg, cb] = fit::calibration_covariance(data, noise, fit)?;
    let mut x = [0.0; 12];
    x[..9].copy_from_slice(g.as_slice());
    x[9..].copy_from_slice(b.as_slice());
    let mut cov = DMatrix::zeros(12, 12);
    cov.view_mut((0, 0), (9, 9)).copy_from(&cg);
    cov.view_mut((9, 9), (3, 3)).copy_from(&cb);
    let effects = crate::calib::ModelEffects {
        reference_temperature_c: data.reference_temperature,
        reference_time_s: data.reference_time,
        effects: fit
            .layout
            .effects
            .iter()
            .enumerate()
            .map(|(j, e)| crate::calib::EffectTerm::new(*e, &fit.effect(j), fit.effect_std.get(j).map(Vec::as_slice)))
            .collect(),
    };
    Ok(ImuCalibration {
        accel: crate::calib::accel_triad(&a, &ca, 1.0),
        gyro: crate::calib::gyro_triad(&x, &cov),
        gravity: given.gravity,
        units: given.units.clone(),
        effects: (!effects.effects.is_empty()).then_some(effects),
        time_offsets: given.time_offsets,
    })
}
