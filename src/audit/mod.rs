//! The model-discrepancy audit (`tumble audit`): find where the calibrated
//! model and the measurements disagree, name the missing effect, add it, show
//! the gap shrink.
//!
//! For a calibration recording the model predicts, for every static interval,
//! a specific force of norm g and zero rate, and for every motion between two
//! intervals a rotation that turns the first gravity direction into the second.
//! Biases wander as random walks (from the Allan coefficients). The **gap** is
//! χ²/dof − 1 of the whitened residuals (floored at 0): 0 when the noise
//! explains everything.
//!
//! Each candidate [`Effect`] is a parametric extension of the sensor model
//! ([`tumble_factors::imu_effects`]); it is fitted jointly with the
//! calibration by the solver and scored by an F-test (the χ² drop per added
//! parameter against the remaining χ²/dof) and by ΔBIC. The most significant
//! candidate (largest ΔBIC) is added when its p-value is below
//! `alpha / candidates` (Bonferroni) and its ΔBIC is positive; then the search
//! repeats until nothing passes.
//!
//! The two time offsets of the vocabulary do not show in a calibration
//! recording; [`vio`] audits a VIO run for them.
//!
//! ```no_run
//! use tumble::audit::{audit, AuditOptions};
//! use tumble::calib::ImuCalibration;
//! use tumble::io::{open_recording, RecordingOptions};
//! let rec = open_recording("tumble_asl/".as_ref(), &RecordingOptions::default()).unwrap();
//! let cal = ImuCalibration::read("calibration.json".as_ref()).unwrap();
//! let result = audit(&rec, &cal, &AuditOptions::default()).unwrap();
//! println!("{}", result.verdict());
//! ```

pub mod data;
pub mod fit;
pub mod report;
pub mod vio;

pub use data::AuditData;
pub use tumble_factors::imu_effects::Effect;

use crate::calib::{calibrate, CalibOptions, ImuCalibration};
use crate::io::ImuNoise;
use crate::io::ImuRecording;
use fit::{Fit, Noise};
use nalgebra::{DMatrix, Vector3};
use rayon::prelude::*;
use statrs::distribution::{ContinuousCDF, FisherSnedecor};
use tumble_factors::imu_calib::{AccelParams, GyroMatrix};
use tumble_factors::imu_effects::Layout;

/// Bias random walks assumed without a noise file: gyro \[rad/s²/√Hz\] and
/// accelerometer \[m/s³/√Hz\] — generous for consumer MEMS, so slow bias wander
/// is not mistaken for drift.
pub const DEFAULT_RANDOM_WALK: (f64, f64) = (1e-4, 1e-3);

/// Smallest temperature span over the static intervals for testing temperature effects \[°C\].
pub const MIN_TEMPERATURE_SPAN: f64 = 1.0;

/// Options of [`audit`].
#[derive(Clone, Debug)]
pub struct AuditOptions {
    /// Noise of the IMU (only the random walks are used; the white noise is
    /// measured in the static intervals). `None`: [`DEFAULT_RANDOM_WALK`].
    pub noise: Option<ImuNoise>,
    /// Family-wise significance level; each candidate is tested at `alpha / candidates`.
    pub alpha: f64,
    /// Most effects to add.
    pub max_effects: usize,
    /// Candidates (default: every effect of the vocabulary the sensor model can fit).
    pub candidates: Vec<Effect>,
    /// Static-interval detection (the gravity is the calibration's).
    pub detection: CalibOptions,
}

impl Default for AuditOptions {
    fn default() -> Self {
        AuditOptions {
            noise: None,
            alpha: 1e-3,
            max_effects: 4,
            candidates: Effect::ALL.into_iter().filter(|e| e.in_sensor_model()).collect(),
            detection: CalibOptions::default(),
        }
    }
}

impl AuditOptions {
    /// Check every option once, before any work ([`audit`] calls it).
    pub fn validate(&self) -> Result<(), crate::OptionError> {
        if !(self.alpha > 0.0 && self.alpha < 1.0) {
            return Err(crate::OptionError::new("--alpha", format!("must be in (0, 1), got {}", self.alpha)));
        }
        self.detection.validate()
    }
}

/// Score of one candidate effect against the current model.
#[derive(Clone, Debug, serde::Serialize)]
pub struct CandidateScore {
    /// The effect.
    pub effect: String,
    /// Parameters it adds.
    pub dof_added: usize,
    /// Fitted parameters.
    pub params: Vec<f64>,
    /// Their standard deviations.
    pub params_std: Vec<f64>,
    /// χ² with the effect.
    pub chi2: f64,
    /// χ² drop.
    pub delta_chi2: f64,
    /// F statistic `(Δχ²/p) / (χ²/(dof − p))`.
    pub f: f64,
    /// Its p-value.
    pub p_value: f64,
    /// BIC improvement `Δχ² − p ln(residuals)` (positive favours the effect).
    pub delta_bic: f64,
    /// Gap with the effect.
    pub gap: f64,
    /// Passes the significance test.
    pub significant: bool,
}

/// One added effect.
#[derive(Clone, Debug)]
pub struct AuditIteration {
    /// The effect added.
    pub effect: Effect,
    /// Its score.
    pub score: CandidateScore,
    /// Gap before and after adding it.
    pub gap_before: f64,
    /// See `gap_before`.
    pub gap_after: f64,
    /// Every candidate's score in this round.
    pub candidates: Vec<CandidateScore>,
    /// The fit after adding it.
    pub fit: Fit,
}

/// The audit's result.
pub struct Audit {
    /// The data compared.
    pub data: AuditData,
    /// Fit of the calibration as given (re-solved jointly, no effect).
    pub base: Fit,
    /// Effects added, in order.
    pub iterations: Vec<AuditIteration>,
    /// Scores of the last round (none significant), when the search stopped for that reason.
    pub last_round: Vec<CandidateScore>,
    /// The calibration with the effects (re-solved jointly).
    pub calibration: ImuCalibration,
    /// Random walks used \[raw units/√s\]: gyro, accel.
    pub random_walk: (f64, f64),
    /// Things the user should know.
    pub notes: Vec<String>,
}

impl Audit {
    /// The final fit.
    pub fn final_fit(&self) -> &Fit {
        self.iterations.last().map(|i| &i.fit).unwrap_or(&self.base)
    }
    /// The effects added.
    pub fn effects_added(&self) -> Vec<Effect> {
        self.iterations.iter().map(|i| i.effect).collect()
    }
    /// One line for the terminal.
    pub fn verdict(&self) -> String {
        let (g0, g1) = (self.base.gap(), self.final_fit().gap());
        if self.iterations.is_empty() {
            format!("no missing effect found: the model explains the data (gap {g0:.3})")
        } else {
            let names: Vec<&str> = self.iterations.iter().map(|i| i.effect.id()).collect();
            let shrink = if g0 > 0.0 { 100.0 * (1.0 - g1 / g0) } else { 0.0 };
            format!("missing effect(s): {} — gap {g0:.3} → {g1:.3} ({shrink:.0} % smaller)", names.join(", "))
        }
    }
}

/// Why an audit could not run.
#[derive(Debug, Clone)]
pub struct AuditError(pub String);

crate::error::message_error_conversions!(AuditError, AuditError);

impl From<crate::vio::VioError> for AuditError {
    fn from(e: crate::vio::VioError) -> AuditError {
        AuditError(e.to_string())
    }
}

impl std::fmt::Display for AuditError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}
impl std::error::Error for AuditError {}

/// Run the audit of a calibration recording against `calibration`.
pub fn audit(rec: &ImuRecording, calibration: &ImuCalibration, opts: &AuditOptions) -> Result<Audit, AuditError> {
    let fail = |m: String| AuditError(format!("{}: {m}", rec.source_name()));
    opts.validate().map_err(|e| fail(e.to_string()))?;
    let (accel, gyro, gyro_bias) = calibration.inverse_params().map_err(|e| fail(e.to_string()))?;
    let detection = CalibOptions { gravity: calibration.gravity, ..opts.detection.clone() };
    // Only the detection is used: a calibration of this recording that fails its
    // verdict still found the static intervals.
    let detected = match calibrate(rec, &detection) {
        Ok(r) => r,
        Err(e) => match e.diagnosis {
            Some(d) => *d,
            None => return Err(fail(format!("static intervals: {}", e.message))),
        },
    };
    let mut notes = Vec::new();
    let intervals = still_intervals(rec, &detected.intervals, &gyro, &gyro_bias, 0.5 * detection.window_s, &mut notes);
    let data = AuditData::new(rec, &intervals, calibration.gravity).map_err(|e| fail(e.to_string()))?;
    // Random walks in raw units: physical ones times the sensor scale (raw per physical unit).
    let (rw_g, rw_a) = match &opts.noise {
        Some(n) => (n.gyroscope_random_walk, n.accelerometer_random_walk),
        None => {
            notes.push(format!(
                "no noise file: bias random walks assumed {:.0e} rad/s²/√Hz (gyro) and {:.0e} m/s³/√Hz (accel); \
                 pass --noise imu.yaml from `tumble allan` for a sharper test of bias drift",
                DEFAULT_RANDOM_WALK.0, DEFAULT_RANDOM_WALK.1
            ));
            DEFAULT_RANDOM_WALK
        }
    };
    let random_walk = (rw_g * calibration.gyro.mean_scale(), rw_a * calibration.accel.mean_scale());
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
    let start = fit::start_values(&data, accel, gyro, gyro_bias);
    let noise = Noise::new(&data, &start, random_walk.0, random_walk.1).map_err(|e| fail(e.to_string()))?;
    let base = fit::solve(&data, &noise, &Layout { effects: Vec::new() }, &start).map_err(|e| fail(e.to_string()))?;
    let mut current = base.clone();
    let mut iterations = Vec::new();
    let mut last_round = Vec::new();
    while iterations.len() < opts.max_effects {
        let remaining: Vec<Effect> =
            candidates.iter().copied().filter(|e| !current.layout.effects.contains(e)).collect();
        if remaining.is_empty() {
            break;
        }
        let threshold = opts.alpha / remaining.len() as f64;
        let fits: Vec<(Effect, Result<Fit, AuditError>)> = remaining
            .par_iter()
            .map(|&e| {
                let mut layout = current.layout.clone();
                layout.effects.push(e);
                (e, fit::solve(&data, &noise, &layout, &current.values))
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
            let s = score(e, &current, &f, threshold);
            if s.significant && best.as_ref().is_none_or(|b| s.delta_bic > b.0.delta_bic) {
                best = Some((s.clone(), f));
            }
            scores.push(s);
        }
        scores.sort_by(|a, b| b.delta_bic.total_cmp(&a.delta_bic));
        let Some((s, f)) = best else {
            last_round = scores;
            break;
        };
        let effect = Effect::from_id(&s.effect).expect("scored effects come from the vocabulary");
        iterations.push(AuditIteration {
            effect,
            gap_before: current.gap(),
            gap_after: f.gap(),
            score: s,
            candidates: scores,
            fit: f.clone(),
        });
        current = f;
    }
    let calibration = calibrated(calibration, &data, &noise, &current).map_err(|e| fail(e.to_string()))?;
    Ok(Audit { data, base, iterations, last_round, calibration, random_walk, notes })
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
    CandidateScore::from_chi2(
        effect,
        (current.chi2(), with.chi2(), with.dof(), with.residuals()),
        with.effect(j),
        with.effect_std.get(j).cloned().unwrap_or_default(),
        with.gap(),
        threshold,
    )
}

impl CandidateScore {
    /// Score an effect from `(χ² without it, χ² with it, dof with it, residual
    /// count)`: F-test of the χ² drop per added parameter against the
    /// remaining χ²/dof, ΔBIC = Δχ² − p ln(residuals); significant when the
    /// p-value is below `threshold` and ΔBIC > 0.
    pub fn from_chi2(
        effect: Effect,
        (chi2_before, chi2, dof, residuals): (f64, f64, usize, usize),
        params: Vec<f64>,
        params_std: Vec<f64>,
        gap: f64,
        threshold: f64,
    ) -> CandidateScore {
        let p = effect.dim();
        let delta = (chi2_before - chi2).max(0.0);
        let dof = dof.max(1) as f64;
        let f = (delta / p as f64) / (chi2 / dof).max(1e-300);
        let p_value = FisherSnedecor::new(p as f64, dof).map(|d| d.sf(f)).unwrap_or(1.0);
        let delta_bic = delta - p as f64 * (residuals.max(1) as f64).ln();
        CandidateScore {
            effect: effect.id().to_string(),
            dof_added: p,
            params,
            params_std,
            chi2,
            delta_chi2: delta,
            f,
            p_value,
            delta_bic,
            gap,
            significant: p_value < threshold && delta_bic > 0.0,
        }
    }
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
