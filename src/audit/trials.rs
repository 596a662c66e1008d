//! Trials of the audit on simulated hand tumbles with known hidden effects:
//! every form of every family, sized as datasheets give them and varied per
//! seed (size, warm-up, motion), with and without a noise file. The tests and
//! `cargo run --release --example audit_forms` run them; the README's table
//! comes from the example.
//!
//! ```no_run
//! use tumble::audit::trials::{run_trial, Case, NoiseMode};
//! let case = Case::all().into_iter().find(|c| c.name == "gyro_nonlinearity_odd").unwrap();
//! let t = run_trial(&case, 100, NoiseMode::Estimated).unwrap();
//! println!("{}: first {:?}, shrink {:.0} %", case.name, t.found.first(), 100.0 * t.shrink);
//! ```

use super::{audit, Audit, AuditError, AuditOptions, Effect};
use crate::calib::{calibrate, CalibOptions};
use crate::io::ImuNoise;
use crate::sim::{hide_effect, simulate, Motion, Scenario, SimConfig, TemperatureTrace, Tumble};

/// Gyro full scale the nonlinearity trials use \[rad/s\]: ±500 °/s, a range a
/// hand tumble (turns of 0.5–4 rad/s on average) is recorded at (`lsb` = range / 32768).
pub const TRIAL_GYRO_RANGE: f64 = 500.0 * std::f64::consts::PI / 180.0;

/// How much a trial's turns differ in rate (`TumbleSettings::turn_rate_ratio`):
/// from half to twice the recording's mean rate.
pub const TRIAL_TURN_RATE_RATIO: f64 = 2.0;

/// Whether the audit gets the simulator's noise or estimates the walks.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum NoiseMode {
    /// `AuditOptions::noise` from the simulated model (`--noise imu.yaml`).
    File,
    /// No noise file: the walks come from the recording.
    Estimated,
}

/// What a trial expects.
#[derive(Clone, Debug, PartialEq)]
pub enum Expect {
    /// Nothing added.
    Nothing,
    /// This effect (family and form) named first, the hidden effect's part of
    /// the gap shrunk ≥ 80 % by it ([`Trial::shrink_of_effect`]).
    First(Effect),
    /// Every one of these added.
    All(Vec<Effect>),
    /// One of the two added first and reported as confounded with the other.
    Confounded(Effect, Effect),
}

/// One kind of trial: hidden effects with sizes drawn per seed.
#[derive(Clone, Debug)]
pub struct Case {
    /// Name in tables.
    pub name: &'static str,
    /// `(hide_effect name, smallest strength, largest strength)`; the strength
    /// is drawn log-uniformly per seed (nonlinearity forms: % of full scale).
    pub hidden: Vec<(&'static str, f64, f64)>,
    /// Temperature trace linear in time (a slow warm-up), the confounding case.
    pub linear_warmup: bool,
    /// The verdict wanted.
    pub expect: Expect,
}

impl Case {
    /// Every case: the forms of each family, a clean recording, two effects at
    /// once, and temperature confounded with time.
    pub fn all() -> Vec<Case> {
        use Effect::*;
        let one = |name: &'static str, lo: f64, hi: f64, e: Effect| Case {
            name,
            hidden: vec![(name, lo, hi)],
            linear_warmup: false,
            expect: Expect::First(e),
        };
        vec![
            one("g_sensitivity", 1.0, 3.0, GyroGSensitivity),
            one("temperature_bias", 2.0, 5.0, TemperatureBias),
            one("temperature_bias_quadratic", 2.0, 5.0, TemperatureBiasQuadratic),
            one("temperature_scale", 10.0, 20.0, TemperatureScale),
            one("temperature_scale_quadratic", 10.0, 20.0, TemperatureScaleQuadratic),
            one("gyro_nonlinearity_even", 2.0, 5.0, GyroScaleNonlinearity),
            one("gyro_nonlinearity_odd", 12.0, 24.0, GyroScaleNonlinearityOdd),
            one("gyro_nonlinearity_cubic", 20.0, 40.0, GyroScaleNonlinearityCubic),
            one("gyro_nonlinearity_asymmetric", 0.5, 1.0, GyroScaleAsymmetry),
            one("accel_nonlinearity_even", 2.0, 5.0, AccelScaleNonlinearity),
            one("accel_nonlinearity_odd", 8.0, 16.0, AccelScaleNonlinearityOdd),
            one("accel_nonlinearity_cubic", 30.0, 60.0, AccelScaleNonlinearityCubic),
            one("accel_nonlinearity_asymmetric", 1.0, 2.0, AccelScaleAsymmetry),
            one("bias_drift", 2.0, 4.0, BiasDrift),
            Case { name: "clean", hidden: Vec::new(), linear_warmup: false, expect: Expect::Nothing },
            Case {
                name: "g_sensitivity + accel_nonlinearity_odd",
                hidden: vec![("g_sensitivity", 1.0, 3.0), ("accel_nonlinearity_odd", 8.0, 16.0)],
                linear_warmup: false,
                expect: Expect::All(vec![GyroGSensitivity, AccelScaleNonlinearityOdd]),
            },
            Case {
                name: "temperature_bias, warm-up linear in time",
                hidden: vec![("temperature_bias", 2.0, 5.0)],
                linear_warmup: true,
                expect: Expect::Confounded(TemperatureBias, BiasDrift),
            },
        ]
    }
}

/// The outcome of one trial.
#[derive(Clone, Debug)]
pub struct Trial {
    /// Seed.
    pub seed: u64,
    /// Strengths drawn, per hidden effect.
    pub strengths: Vec<f64>,
    /// Temperature rise of the warm-up \[°C\] (0 without temperature effects).
    pub warmup_c: f64,
    /// Effects added, in order.
    pub found: Vec<Effect>,
    /// Gap before, and after the first effect.
    pub gaps: (f64, f64),
    /// Gap of the same seed's recording without the hidden effects (the same
    /// motion and noise draws): the part of the gap the noise makes, which no
    /// effect can explain. `None` for cases that expect nothing.
    pub gap_clean: Option<f64>,
    /// `1 − after/before` of the first effect.
    pub shrink: f64,
    /// The share of the hidden effects' own gap (`before − gap_clean`) that
    /// the first effect removed: `(before − after)/(before − gap_clean)`, 1
    /// when the gap left is no larger than the clean recording's. What
    /// "the gap shrunk ≥ 80 %" is judged on; equal to `shrink` when the noise
    /// leaves no gap.
    pub shrink_of_effect: f64,
    /// Whether the audit determined the first effect's form (no other form of
    /// its family within [`super::DISTINGUISHABLE_BIC`]).
    pub form_determined: bool,
    /// Effects reported confounded with the first.
    pub confounded: Vec<Effect>,
    /// The verdict.
    pub verdict: String,
    /// Whether it met its [`Expect`].
    pub passed: bool,
    /// Whether the first effect added belongs to no hidden family (anything
    /// added to a clean recording): a wrong name, worse than none.
    pub wrong_first: bool,
}

/// A number in \[0, 1) from `seed` and `salt` (splitmix64), so each seed draws its own sizes.
fn unit(seed: u64, salt: u64) -> f64 {
    let mut z = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15).wrapping_add(salt.wrapping_mul(0xBF58_476D_1CE4_E5B9));
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
}

/// Simulate the case for `seed`, calibrate without the effects, audit.
pub fn run_trial(case: &Case, seed: u64, mode: NoiseMode) -> Result<Trial, AuditError> {
    let (cfg, strengths, warmup_c) = config(case, seed)?;
    let a = simulate_and_audit(&cfg, seed, mode, AuditOptions::default().max_effects)?;
    let gap_clean = match case.expect {
        Expect::Nothing => None,
        _ => {
            // Only its gap before any effect is wanted: no search.
            let clean = Case { hidden: Vec::new(), expect: Expect::Nothing, ..case.clone() };
            Some(simulate_and_audit(&config(&clean, seed)?.0, seed, mode, 0)?.base.gap())
        }
    };
    Ok(judge(case, seed, strengths, warmup_c, gap_clean, &a))
}

/// Simulate `cfg`, calibrate, audit with at most `max_effects` added.
fn simulate_and_audit(cfg: &SimConfig, seed: u64, mode: NoiseMode, max_effects: usize) -> Result<Audit, AuditError> {
    let sim = simulate(Scenario::Tumble, cfg, seed).map_err(|e| e.to_string())?;
    let rec = sim.imu.to_recording();
    let cal = calibrate(&rec, &CalibOptions { gravity: cfg.gravity, ..Default::default() }).map_err(|e| e.message)?;
    let noise = (mode == NoiseMode::File).then(|| ImuNoise::from_model(&cfg.imu));
    audit(&rec, &cal.calibration, &AuditOptions { noise, max_effects, ..Default::default() })
}

/// The simulator configuration of `case` for `seed`: sizes drawn, a warm-up of
/// 5–15 °C for temperature effects, a hand turning at 1–2 rad/s on average,
/// each turn at half to twice that (a hand's turns differ; at one rate the
/// nonlinearity's forms integrate alike over every turn).
pub fn config(case: &Case, seed: u64) -> Result<(SimConfig, Vec<f64>, f64), AuditError> {
    let mut cfg = SimConfig::default();
    cfg.imu.gyro.range = TRIAL_GYRO_RANGE;
    cfg.imu.gyro.lsb = TRIAL_GYRO_RANGE / 32768.0;
    cfg.tumble.turn_rate = 1.0 + 1.0 * unit(seed, 1);
    cfg.tumble.turn_rate_ratio = TRIAL_TURN_RATE_RATIO;
    let mut strengths = Vec::new();
    for (k, (name, lo, hi)) in case.hidden.iter().enumerate() {
        let s = lo * (hi / lo).powf(unit(seed, 10 + k as u64));
        hide_effect(&mut cfg, name, s).map_err(|e| e.to_string())?;
        strengths.push(s);
    }
    let mut warmup_c = 0.0;
    if cfg.imu.effects.temperature {
        warmup_c = 5.0 + 10.0 * unit(seed, 2);
        let tau = if case.linear_warmup { 20_000.0 } else { 100.0 + 100.0 * unit(seed, 3) };
        // end chosen so the first ~240 s rise by warmup_c: start + (end − start)(1 − e^(−240/τ)).
        let rise = 1.0 - (-240.0 / tau).exp();
        cfg.imu.temperature = TemperatureTrace {
            start: 10.0,
            end: 10.0 + warmup_c / rise,
            warmup_s: tau,
            reference: 10.0,
            // A warm-up linear in time has no ripple: the default's 0.5 °C over
            // 300 s let the largest drifts (Δχ² ≈ 600) tell temperature from time
            // by ΔBIC 6–10, so the recording was not confounded.
            ripple: if case.linear_warmup { 0.0 } else { TemperatureTrace::default().ripple },
            ..Default::default()
        };
        // A quadratic temperature curve is sized as a sensor would be: its
        // largest change over the temperatures recorded (from power-on, the
        // reference, to the end) is the drift the linear coefficient drawn
        // gives over them. Its curvature, which tells it from a linear one,
        // shows as a sagitta over the temperatures the tumbling covers that
        // does not depend on where the curve turns around; the turn-around is
        // put where it makes that largest change least for a given curvature,
        // the middle of the temperatures recorded (inside the tumbling's,
        // after an initial rest that takes a third of the warm-up). Sized by
        // the tumbling's span alone, with the turn-around in its middle, the
        // curve swung by several times the linear drift between power-on and
        // the turns: a gyro scale 20 % off at ×16, which the calibration
        // rightly refused.
        let duration = Tumble::new(&cfg.tumble, seed).duration();
        let trace = &cfg.imu.temperature;
        let hi = trace.at(duration) - trace.reference;
        let vertex = 0.5 * hi;
        for t in [&mut cfg.imu.gyro, &mut cfg.imu.accel] {
            for k in 0..3 {
                for (linear, quadratic) in [
                    (&mut t.temperature_bias[k], &mut t.temperature_bias_quadratic[k]),
                    (&mut t.temperature_scale[k], &mut t.temperature_scale_quadratic[k]),
                ] {
                    if *quadratic != 0.0 {
                        // q (hi/2)² = |linear| · |hi|, vertex where q (ΔT − vertex)² is least.
                        *quadratic = quadratic.signum() * 4.0 * linear.abs() / hi.abs().max(f64::EPSILON);
                        *linear = -2.0 * *quadratic * vertex;
                    }
                }
            }
        }
    }
    Ok((cfg, strengths, warmup_c))
}

/// `found` is `want`, or both are odd forms of one triad's scale nonlinearity
/// (`n ω|ω|` and `n ω³` differ too little over a hand's rates to be told
/// apart, and the audit says so: "form not determined").
pub fn same_form(found: Effect, want: Effect) -> bool {
    use tumble_factors::imu_effects::NonlinearityForm::{Cubic, Odd};
    found == want
        || match (found.nonlinearity(), want.nonlinearity()) {
            (Some((t, f)), Some((u, g))) => t == u && matches!(f, Odd | Cubic) && matches!(g, Odd | Cubic),
            _ => false,
        }
}

fn judge(case: &Case, seed: u64, strengths: Vec<f64>, warmup_c: f64, gap_clean: Option<f64>, a: &Audit) -> Trial {
    let found = a.effects_added();
    let first = a.iterations.first();
    let gaps = (a.base.gap(), first.map(|i| i.gap_after).unwrap_or(a.base.gap()));
    // The share of the gap above `floor` the first effect removed. Shrunk
    // fully when no more than `floor` is left, even from `floor` itself (an
    // effect can be significant while χ²/dof stays below 1).
    let shrink_above = |floor: f64| {
        if gaps.1 <= floor {
            1.0
        } else if gaps.0 > floor {
            (gaps.0 - gaps.1) / (gaps.0 - floor)
        } else {
            0.0
        }
    };
    let (shrink, shrink_of_effect) = (shrink_above(0.0), shrink_above(gap_clean.unwrap_or(0.0)));
    let confounded = first.map(|i| i.confounded_with.clone()).unwrap_or_default();
    let passed = match &case.expect {
        Expect::Nothing => found.is_empty(),
        Expect::First(e) => found.first().is_some_and(|f| same_form(*f, *e)) && shrink_of_effect >= 0.8,
        Expect::All(es) => es.iter().all(|e| found.iter().any(|f| same_form(*f, *e))),
        Expect::Confounded(x, y) => match found.first() {
            Some(f) if f.family() == x.family() => confounded.iter().any(|c| c.family() == y.family()),
            Some(f) if f.family() == y.family() => confounded.iter().any(|c| c.family() == x.family()),
            _ => false,
        },
    };
    let hidden: Vec<&str> = match &case.expect {
        Expect::Nothing => Vec::new(),
        Expect::First(e) => vec![e.family()],
        Expect::All(es) => es.iter().map(|e| e.family()).collect(),
        Expect::Confounded(x, y) => vec![x.family(), y.family()],
    };
    let wrong_first = found.first().is_some_and(|f| !hidden.contains(&f.family()));
    Trial {
        seed,
        strengths,
        warmup_c,
        found,
        gaps,
        gap_clean,
        shrink,
        shrink_of_effect,
        form_determined: first.is_some_and(|i| i.form_determined()),
        confounded,
        verdict: a.verdict(),
        passed,
        wrong_first,
    }
}
