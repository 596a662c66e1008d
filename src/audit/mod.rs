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
//! calibration by the solver and scored by an F-test (the drop of −2 ln L
//! per added parameter against the remaining χ²/dof) and by ΔBIC. The most
//! significant candidate (largest ΔBIC) is added when its p-value is below
//! `alpha / candidates` (Bonferroni) and its ΔBIC is positive; then the search
//! repeats until nothing passes. Effects come in families of alternative
//! forms (scale nonlinearity even, odd, cubic or sign-asymmetric; temperature
//! linear or quadratic): the form is the one with the largest ΔBIC, and once
//! one form is added the family's other forms leave the search.
//!
//! Without a noise file the bias random walks are estimated from the
//! recording ([`fit::solve_walks`]) with every candidate family in the model,
//! so that a drift, a temperature effect or an orientation-dependent bias is
//! not absorbed by the walk; the search then runs at these walks.
//!
//! After the search the whitened residuals left are tested for structure
//! against their regressors (`structure`); what no effect explains is
//! reported with its share of the gap, and two effects that explain the same
//! residual are reported as confounded.
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

pub(crate) mod data;
#[doc(hidden)]
pub mod fit;
mod recordings;
pub(crate) mod report;
mod run;
pub(crate) mod structure;
pub mod trials;
pub mod vio;

pub use data::AuditData;
pub use recordings::{audit_recordings, EffectAcross, RecordingsAudit};
pub use report::{summary_table, write as write_report};
pub use run::{audit, audit_with_progress, MAX_STATIC_RATE};
pub use tumble_factors::imu_effects::Effect;

use crate::calib::{CalibOptions, ImuCalibration};
use crate::io::ImuNoise;
use fit::Fit;
use statrs::distribution::{ContinuousCDF, FisherSnedecor};

/// Where the estimate of the bias random walks starts without a noise file:
/// gyro \[rad/s²/√Hz\] and accelerometer \[m/s³/√Hz\], typical of consumer
/// MEMS (the estimate moves from there; see [`fit::solve_walks`]).
pub const INITIAL_RANDOM_WALK: (f64, f64) = (1e-3, 1e-2);

/// Degrees of freedom below which a triad's estimated walk is reported as not
/// determined: a variance estimated from `ν` of them is uncertain by `√(2/ν)`,
/// ±45 % at 10 (the VIO's noise meter asks as many).
pub const WALK_DETERMINED_DOF: f64 = 10.0;

/// ΔBIC below which two explanations are not told apart (2 ln of a Bayes
/// factor of 20, "strong evidence" on Kass and Raftery's scale).
pub const DISTINGUISHABLE_BIC: f64 = 6.0;

/// Largest ratio between a candidate's likelihood ratio (its χ² drop) and its
/// Wald statistic (`θᵀ C⁻¹ θ`), either way, for the drop to be tested.
/// Both estimate the same χ²_p when the model is close to linear in the
/// effect over the step the fit took, which the F-test's p-value assumes (on
/// identifiable effects they agree within 0.80–1.13, measured over 453
/// candidates of the simulated trials). An effect the recording cannot tell
/// from the calibration's own parameters — odd nonlinearities when every turn
/// is a quarter turn at one speed about a body axis — lets the fit crawl along
/// that trade-off and drop χ² by 100+ with parameters within 2σ of zero
/// (Wald 4): a drop the χ² distribution does not describe.
pub const MAX_LR_WALD_RATIO: f64 = 2.0;

/// Smallest temperature span over the static intervals for testing temperature effects \[°C\].
pub const MIN_TEMPERATURE_SPAN: f64 = 1.0;

/// Options of [`audit`].
#[derive(Clone, Debug)]
pub struct AuditOptions {
    /// Noise of the IMU (only the random walks are used; the white noise is
    /// measured in the static intervals). `None`: the walks are estimated from
    /// the recording with each model.
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
    /// BIC improvement `Δχ² − p ln(n)`, n the static and motion residuals (positive favours the effect).
    pub delta_bic: f64,
    /// Gap with the effect.
    pub gap: f64,
    /// Passes the significance test.
    pub significant: bool,
    /// Wald statistic of its parameters (see [`Fit::effect_wald`]).
    pub wald: f64,
    /// False for a drop that passes the significance test but whose likelihood
    /// ratio and Wald statistic disagree by more than [`MAX_LR_WALD_RATIO`]:
    /// the test does not apply and the candidate is not significant (true for
    /// every drop that is not significant anyway).
    pub testable: bool,
}

/// How far above the size of its estimate a bound on an effect's parameter
/// lies, in σ: 1.96, a two-sided 95 % interval of one parameter.
pub const BOUND_SIGMAS: f64 = 1.96;

/// What the recording says of one parameter of an effect the audit did not
/// add: its estimate against the final model, and the size it is below
/// with 95 % confidence.
#[derive(Clone, Debug, serde::Serialize)]
pub struct EffectBound {
    /// The effect (its id).
    pub effect: String,
    /// The parameter ([`Effect::param_names`]).
    pub parameter: &'static str,
    /// Its estimate \[`unit`\].
    pub value: f64,
    /// Its standard deviation (scaled by max(1, χ²/dof)) \[`unit`\].
    pub std: f64,
    /// `|value| + BOUND_SIGMAS · std` \[`unit`\].
    pub bound: f64,
    /// Its unit ([`Effect::param_unit`]), in the calibrated frame.
    pub unit: &'static str,
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
    /// The family's other forms with their ΔBIC, best first.
    pub other_forms: Vec<(Effect, f64)>,
    /// Effects of other families that explain the same residual about as well
    /// (significant this round, ΔBIC within [`DISTINGUISHABLE_BIC`], and no
    /// longer significant once this effect is in): the recording cannot tell
    /// them apart.
    pub confounded_with: Vec<Effect>,
    /// The fit after adding it.
    pub fit: Fit,
}

impl AuditIteration {
    /// Whether the form within the family is determined (the next form's ΔBIC
    /// is at least [`DISTINGUISHABLE_BIC`] lower).
    pub fn form_determined(&self) -> bool {
        self.other_forms.first().is_none_or(|(_, b)| self.score.delta_bic - b >= DISTINGUISHABLE_BIC)
    }

    /// The effect with its form and what could not be decided, for reports.
    pub fn describe(&self) -> String {
        let e = self.effect;
        let mut s = format!("{} ({})", e.family(), e.form());
        if !self.form_determined() {
            let (o, b) = self.other_forms[0];
            s += &format!(
                " [form not determined: {} fits about as well, ΔBIC {:.1} vs {:.1}]",
                o.form(),
                b,
                self.score.delta_bic
            );
        }
        for c in &self.confounded_with {
            s += &format!(" [confounded with {c}: {}]", confounding_advice(e, *c));
        }
        s
    }
}

/// What recording would tell `a` and `b` apart.
pub fn confounding_advice(a: Effect, b: Effect) -> &'static str {
    let fam = |e: Effect| e.family();
    let pair = |x: &str, y: &str| (fam(a) == x && fam(b) == y) || (fam(a) == y && fam(b) == x);
    if pair("temperature_bias", "bias_drift") || pair("temperature_scale", "bias_drift") {
        "the temperature changes monotonically with time here; a recording whose temperature goes up and down \
         (or stays constant for as long) would tell them apart"
    } else if pair("temperature_bias", "temperature_scale") {
        "a recording with the same temperatures at more varied orientations and rates would tell them apart"
    } else {
        "this recording cannot tell them apart; a longer one with more varied orientations and rates could"
    }
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
    /// Random walks used per axis \[raw units/√s\]: gyro, accel.
    pub random_walk_axes: fit::Walks,
    /// Whether the walks were estimated from the recording (no noise file).
    pub walks_estimated: bool,
    /// When estimated: the degrees of freedom the estimate rests on per axis
    /// (gyro x y z, accelerometer x y z; [`fit::walk_degrees_of_freedom`]).
    pub walk_degrees_of_freedom: Option<fit::Walks>,
    /// Structure left in the final model's residuals.
    pub structure: Vec<structure::Structure>,
    /// The family-wise significance level used.
    pub alpha: f64,
    /// Things the user should know.
    pub notes: Vec<String>,
}

impl Audit {
    /// Random walks used \[raw units/√s\]: gyro, accel (root mean square of the axes).
    pub fn random_walk(&self) -> (f64, f64) {
        (fit::pooled(&self.random_walk_axes.0), fit::pooled(&self.random_walk_axes.1))
    }
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
        let unexplained = structure::summary(&self.structure);
        let p_left = self.final_fit().p_value();
        let mut v = if self.iterations.is_empty() && p_left >= self.alpha && unexplained.is_empty() {
            format!("no missing effect found: the model explains the data (gap {g0:.3})")
        } else if self.iterations.is_empty() {
            format!("no effect of the vocabulary explains the gap ({g0:.3}, p {p_left:.1e})")
        } else {
            let names: Vec<String> = self.iterations.iter().map(|i| i.describe()).collect();
            let shrink = if g0 > 0.0 { 100.0 * (1.0 - g1 / g0) } else { 0.0 };
            let left = if g0 > 0.0 { 100.0 * g1 / g0 } else { 0.0 };
            let mut v = format!(
                "missing effect(s): {} — gap {g0:.3} → {g1:.3} ({shrink:.0} % smaller, {left:.0} % of it left",
                names.join(", ")
            );
            v += &if p_left < self.alpha {
                format!(", unexplained: p {p_left:.1e})")
            } else {
                ", within the noise)".into()
            };
            v
        };
        if !unexplained.is_empty() {
            v += &format!("; {unexplained}");
        } else if p_left < self.alpha {
            v += &format!("; {}", self.where_the_gap_is());
        }
        if let Some(dof) = self.walks_undetermined() {
            v += &format!(
                "; the bias walks were estimated from a recording that does not determine them ({dof:.1} degrees \
                 of freedom for the less determined sensor), so what it says of slow drifts (temperature, bias \
                 drift) rests on an uncertain walk: give --noise"
            );
        }
        let untested = self.untestable();
        if !untested.is_empty() {
            v += &format!(
                "; not testable on this recording (their fits trade off against the calibration's own parameters): {}",
                untested.join(", ")
            );
        }
        v
    }

    /// Bounds on the effects not added: every parameter of every candidate of
    /// the last round (fitted against the final model, none significant),
    /// where its fit is testable (its χ² drop and Wald statistic agree). Empty
    /// when the search stopped at `max_effects` or ran out of candidates.
    pub fn bounds(&self) -> Vec<EffectBound> {
        let mut out = Vec::new();
        for c in self.last_round.iter().filter(|c| c.testable) {
            let Some(e) = Effect::from_id(&c.effect) else { continue };
            for (i, (&value, &std)) in c.params.iter().zip(&c.params_std).enumerate() {
                out.push(EffectBound {
                    effect: c.effect.clone(),
                    parameter: e.param_names().get(i).copied().unwrap_or(""),
                    value,
                    std,
                    bound: value.abs() + BOUND_SIGMAS * std,
                    unit: e.param_unit(i),
                });
            }
        }
        out
    }

    /// When the walks were estimated from a recording that does not determine
    /// them: the degrees of freedom of the less determined sensor (below
    /// [`WALK_DETERMINED_DOF`]).
    pub fn walks_undetermined(&self) -> Option<f64> {
        let dof = run::least_determined(&self.walk_degrees_of_freedom?);
        (dof < WALK_DETERMINED_DOF).then_some(dof)
    }

    /// Candidates that passed the significance test in some round but whose χ²
    /// drop and Wald statistic disagree ([`CandidateScore::testable`]), once each.
    pub fn untestable(&self) -> Vec<String> {
        let mut out: Vec<String> = Vec::new();
        let rounds = self.iterations.iter().map(|i| i.candidates.as_slice()).chain([self.last_round.as_slice()]);
        for c in rounds.flatten().filter(|c| !c.testable) {
            if !out.contains(&c.effect) {
                out.push(c.effect.clone());
            }
        }
        out
    }

    /// Which residual group carries most of the final fit's excess χ², for a
    /// gap without structure against any regressor.
    fn where_the_gap_is(&self) -> String {
        let f = self.final_fit();
        let names = ["|a| − g at rest", "gyro at rest", "motion direction", "gyro bias walk", "accel bias walk"];
        let worst = (0..5)
            .filter(|&g| f.dims[g] > 0)
            .max_by(|&a, &b| {
                let excess = |g: usize| f.chi2_groups[g] - f.dims[g] as f64;
                excess(a).total_cmp(&excess(b))
            })
            .unwrap_or(0);
        let head = format!(
            "it lies mostly in the {} residuals (χ²/n {:.2}) without structure against time, temperature, orientation \
             or rate",
            names[worst],
            f.chi2_groups[worst] / f.dims[worst].max(1) as f64
        );
        // The readings whose restlessness inside the intervals reaches that group.
        let reaches = |r: &str| match worst {
            0 => r.starts_with("accel") || r.starts_with("|accel|"),
            1 => r.starts_with("gyro"),
            2 => !r.starts_with("|accel|"),
            _ => true,
        };
        let unsettled: Vec<&crate::calib::detect::WithinInterval> =
            crate::calib::detect::unsettled(&self.data.within, self.alpha)
                .into_iter()
                .filter(|w| reaches(&w.reading))
                .collect();
        if unsettled.is_empty() {
            format!("{head}: noise above what the static intervals show (vibration, timing), or an effect outside the vocabulary")
        } else {
            format!(
                "{head}; inside the static intervals {}: {}",
                crate::calib::detect::describe(&unsettled),
                crate::calib::detect::UNSETTLED_CAUSES
            )
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

impl CandidateScore {
    /// Score an effect from `(drop of −2 ln L when it is added, χ² with it,
    /// dof with it, measurement count n)`: F-test of the drop per added parameter
    /// against the remaining χ²/dof, ΔBIC = drop − p ln(n);
    /// significant when the p-value is below `threshold` and ΔBIC > 0. With
    /// fixed noise the drop is the χ² drop.
    pub fn from_drop(
        effect: Effect,
        (drop, chi2, dof, residuals): (f64, f64, usize, usize),
        params: Vec<f64>,
        params_std: Vec<f64>,
        gap: f64,
        threshold: f64,
    ) -> CandidateScore {
        let p = effect.dim();
        let delta = drop.max(0.0);
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
            wald: delta,
            testable: true,
        }
    }
}
