//! Allan-variance noise identification (paper §3; IEEE Std 952/1554).
//!
//! * [`deviation`]: exact overlapping / non-overlapping Allan, modified Allan,
//!   time and Hadamard deviations, sharing work across τ through one FFT.
//! * [`edf`]: noise identification and confidence intervals (Greenhall's
//!   equivalent degrees of freedom, χ² intervals), as Stable32 computes them.
//! * [`identify`](mod@identify): the noise coefficients Q, N, B, K, R by the IEEE read-offs
//!   and by a weighted non-negative least-squares fit, each with an interval.
//! * `disturbance`: knocks and steps in a static log, and the longest span free of them.
//! * `report`: a whole static recording → `allan.json`, Kalibr `imu.yaml`,
//!   plots and a terminal table (what `tumble allan` runs).
//!
//! ```
//! use tumble::allan::{allan_deviation, AllanOptions};
//! // 100 000 samples of white noise at 100 Hz with density 0.01 unit/√Hz.
//! let mut s = 1u64;
//! let y: Vec<f64> = (0..100_000).map(|_| {
//!     // Sum of 12 uniforms − 6 ≈ standard normal.
//!     (0..12).map(|_| { s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
//!         (s >> 11) as f64 / (1u64 << 53) as f64 }).sum::<f64>() - 6.0
//! }).map(|g| g * 0.01 * 100f64.sqrt()).collect();
//! let curve = allan_deviation(&y, 0.01, &AllanOptions::default()).unwrap();
//! // White noise: σ(τ) = N/√τ, so σ(1 s)·√1 ≈ 0.01.
//! let i = curve.tau.iter().position(|&t| (t - 1.0).abs() < 1e-9).unwrap();
//! assert!((curve.dev[i] - 0.01).abs() < 0.0005);
//! ```

pub mod deviation;
pub(crate) mod disturbance;
pub mod edf;
mod edge_sums;
#[doc(hidden)]
pub mod identify;
pub mod in_motion;
pub(crate) mod report;
mod run;

pub use deviation::DeviationKind;
pub use disturbance::{
    check_static, static_disturbances, Disturbance, DisturbanceKind, MAX_STATIC_TILT_DEG, MOTION_SPAN_S,
};
pub use identify::{identify, Coefficient, Identification, NoiseTerms};
pub use report::{AllanReport, AllanRunOptions, AxisStat};
pub use run::{run_allan, run_allan_with_progress};

use serde::{Deserialize, Serialize};

/// Which averaging times τ to evaluate.
#[derive(Clone, Debug, PartialEq)]
pub enum TauGrid {
    /// Log-spaced cluster sizes, about this many per decade (distinct m only).
    LogSpaced(usize),
    /// m = 1, 2, 4, 8, …
    Octave,
    /// Every m from 1 to the largest allowed.
    All,
    /// These τ \[s\], each rounded to the nearest whole number of samples
    /// (duplicates removed), as allantools does with `taus=`.
    Explicit(Vec<f64>),
}

/// Options of [`allan_deviation`].
#[derive(Clone, Debug)]
pub struct AllanOptions {
    /// Estimator.
    pub kind: DeviationKind,
    /// τ values.
    pub taus: TauGrid,
    /// Largest τ as a fraction of the record length (0.1 = T/10, the usual
    /// limit past which too few clusters remain); values ≥ 1 allow the
    /// estimator's own maximum.
    pub max_tau_fraction: f64,
    /// Confidence level of the intervals (0.683 = the 1-σ convention).
    pub confidence: f64,
}

impl Default for AllanOptions {
    fn default() -> Self {
        Self { kind: DeviationKind::Oadev, taus: TauGrid::LogSpaced(20), max_tau_fraction: 0.1, confidence: 0.683 }
    }
}

impl AllanOptions {
    /// Check every option once, before any work: the confidence level lies
    /// strictly between 0 and 1, the largest τ fraction is positive, a
    /// log-spaced grid has at least one τ per decade, explicit τ are positive.
    pub fn validate(&self) -> Result<(), AllanError> {
        if !(self.confidence > 0.0 && self.confidence < 1.0) {
            return Err(AllanError::Invalid(format!(
                "the confidence level (--confidence) must lie strictly between 0 and 1, got {}",
                self.confidence
            )));
        }
        if self.max_tau_fraction.is_nan() || self.max_tau_fraction <= 0.0 {
            return Err(AllanError::Invalid(format!(
                "the largest τ fraction (--max-tau-fraction) must be positive, got {}",
                self.max_tau_fraction
            )));
        }
        match &self.taus {
            TauGrid::LogSpaced(0) => {
                Err(AllanError::Invalid("a log-spaced τ grid needs at least one τ per decade".into()))
            }
            TauGrid::Explicit(t) if t.iter().any(|x| !(x.is_finite() && *x > 0.0)) => {
                Err(AllanError::Invalid(format!("explicit τ must be positive numbers of seconds, got {t:?}")))
            }
            _ => Ok(()),
        }
    }
}

impl std::str::FromStr for TauGrid {
    type Err = AllanError;
    /// A count of log-spaced τ per decade, `octave` or `all` (`tumble allan --taus`).
    fn from_str(v: &str) -> Result<TauGrid, AllanError> {
        match v {
            "octave" => Ok(TauGrid::Octave),
            "all" => Ok(TauGrid::All),
            v => v.parse().ok().filter(|&p: &usize| p > 0).map(TauGrid::LogSpaced).ok_or_else(|| {
                AllanError::Invalid(format!("--taus takes a count per decade, `octave` or `all`, got `{v}`"))
            }),
        }
    }
}

/// A span of a recording, seconds from its start (`tumble allan --span A:B`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TimeSpan {
    /// Start \[s\] (0 when the text leaves it empty).
    pub start_s: f64,
    /// End \[s\] (infinite when the text leaves it empty).
    pub end_s: f64,
}

impl std::str::FromStr for TimeSpan {
    type Err = AllanError;
    /// `A:B` seconds from the start of the recording (either end may be empty).
    fn from_str(s: &str) -> Result<TimeSpan, AllanError> {
        let (a, b) = s
            .split_once(':')
            .ok_or_else(|| AllanError::Invalid(format!("--span: expected START:END in seconds, got `{s}`")))?;
        let num = |v: &str, default: f64| -> Result<f64, AllanError> {
            if v.trim().is_empty() {
                return Ok(default);
            }
            v.trim()
                .parse::<f64>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| AllanError::Invalid(format!("--span: `{v}` is not a number of seconds")))
        };
        let (a, b) = (num(a, 0.0)?, num(b, f64::INFINITY)?);
        if b <= a {
            return Err(AllanError::Invalid(format!("--span: end {b} is not after start {a}")));
        }
        Ok(TimeSpan { start_s: a, end_s: b })
    }
}

/// A deviation curve with its confidence band.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct AllanCurve {
    /// Estimator used.
    pub kind: DeviationKind,
    /// Sample period τ0 \[s\].
    pub tau0: f64,
    /// Cluster sizes m (τ = m·τ0).
    pub m: Vec<usize>,
    /// Averaging times τ \[s\].
    pub tau: Vec<f64>,
    /// Deviation σ(τ), in the units of the series (TDEV: units × s).
    pub dev: Vec<f64>,
    /// Lower end of the confidence interval.
    pub dev_lo: Vec<f64>,
    /// Upper end of the confidence interval.
    pub dev_hi: Vec<f64>,
    /// Number of difference terms averaged at each τ.
    pub n_terms: Vec<usize>,
    /// Power-law noise exponent α used for the interval (S_y ∝ f^α).
    pub alpha: Vec<i32>,
    /// Equivalent degrees of freedom at each τ.
    pub edf: Vec<f64>,
    /// Confidence level of `dev_lo`/`dev_hi`.
    pub confidence: f64,
}

impl AllanCurve {
    /// This curve's settings with no points.
    fn emptied(&self) -> AllanCurve {
        AllanCurve {
            m: Vec::new(),
            tau: Vec::new(),
            dev: Vec::new(),
            dev_lo: Vec::new(),
            dev_hi: Vec::new(),
            n_terms: Vec::new(),
            alpha: Vec::new(),
            edf: Vec::new(),
            ..*self
        }
    }

    /// Append one τ: its deviation, the terms averaged, the noise type and the
    /// EDF; the interval at the curve's confidence level.
    fn push_point(&mut self, m: usize, tau: f64, dev: f64, n_terms: usize, alpha: i32, edf: f64) {
        let (lo, hi) = edf::confidence_interval(dev, edf, self.confidence);
        self.m.push(m);
        self.tau.push(tau);
        self.dev.push(dev);
        self.dev_lo.push(lo);
        self.dev_hi.push(hi);
        self.n_terms.push(n_terms);
        self.alpha.push(alpha);
        self.edf.push(edf);
    }

    /// The curve of several stretches of one record analysed as one, no
    /// difference crossing from one stretch to the next: at each cluster size
    /// the variances are averaged by their number of terms (the exact overall
    /// estimate), the degrees of freedom add (the stretches are independent)
    /// and the interval is recomputed. A τ is kept where any stretch has it;
    /// the noise type is the longest stretch's. `None` when `parts` is empty.
    pub fn joined(parts: &[AllanCurve]) -> Option<AllanCurve> {
        let longest = parts.iter().max_by_key(|c| c.m.len())?;
        if parts.len() == 1 {
            return Some(longest.clone());
        }
        let mut out = longest.emptied();
        for (i, &m) in longest.m.iter().enumerate() {
            let (mut var, mut terms, mut edf) = (0.0, 0usize, 0.0);
            for c in parts {
                if let Some(j) = c.m.iter().position(|&x| x == m) {
                    var += c.dev[j].powi(2) * c.n_terms[j] as f64;
                    terms += c.n_terms[j];
                    edf += c.edf[j];
                }
            }
            let dev = (var / terms.max(1) as f64).sqrt();
            out.push_point(m, longest.tau[i], dev, terms, longest.alpha[i], edf);
        }
        Some(out)
    }
}

/// Why an Allan analysis could not be made.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum AllanError {
    /// An option cannot work.
    #[error(transparent)]
    Options(#[from] crate::OptionError),
    /// The recording is not what an Allan analysis needs (named with its file and line).
    #[error(transparent)]
    Input(#[from] crate::InputError),
    /// The data cannot give a deviation (too few samples, no common span, …).
    #[error("{0}")]
    Invalid(String),
}

crate::error::message_error_conversions!(AllanError, AllanError::Invalid);

/// The distinct cluster sizes of a grid for `n` samples of period `tau0`.
pub fn cluster_sizes(grid: &TauGrid, n: usize, tau0: f64, kind: DeviationKind, max_tau_fraction: f64) -> Vec<usize> {
    let hard = kind.max_m(n);
    let limit = if max_tau_fraction >= 1.0 { hard } else { ((n as f64 * max_tau_fraction) as usize).min(hard) };
    let limit = limit.max(1).min(hard);
    let mut ms: Vec<usize> = match grid {
        TauGrid::LogSpaced(per_decade) => {
            let per = (*per_decade).max(1) as f64;
            let mut v = Vec::new();
            let mut k = 0;
            loop {
                let m = 10f64.powf(k as f64 / per).round() as usize;
                if m > limit {
                    break;
                }
                v.push(m);
                k += 1;
            }
            v
        }
        TauGrid::Octave => {
            std::iter::successors(Some(1usize), |m| m.checked_mul(2)).take_while(|&m| m <= limit).collect()
        }
        TauGrid::All => (1..=limit).collect(),
        TauGrid::Explicit(taus) => {
            taus.iter().map(|t| (t / tau0).round() as usize).filter(|&m| m >= 1 && m <= hard).collect()
        }
    };
    ms.sort_unstable();
    ms.dedup();
    ms
}

/// The deviation curve of one series `y` (a rate or acceleration, one axis)
/// sampled every `tau0` seconds.
pub fn allan_deviation(y: &[f64], tau0: f64, opts: &AllanOptions) -> Result<AllanCurve, AllanError> {
    allan_deviation_with_progress(y, tau0, opts, &|| {})
}

/// [`allan_deviation`] calling `progress` once per τ done.
pub fn allan_deviation_with_progress(
    y: &[f64],
    tau0: f64,
    opts: &AllanOptions,
    progress: &(dyn Fn() + Sync),
) -> Result<AllanCurve, AllanError> {
    check_input(y, tau0, 2 * opts.kind.difference_order() + 1, "sample", opts.kind)?;
    curve_from_phase(&deviation::phase_of(y), tau0, opts, progress)
}

/// How many axes [`allan_deviation_axes`] works on at once.
const AXES_AT_ONCE: usize = 2;

/// Curves of several axes (e.g. the six of an IMU), two at a time in
/// parallel: the FFT of one axis is serial, so a pair keeps two cores busy,
/// while the working memory stays at two axes' worth — measured 1.9× the
/// six-axis data at 3 M samples with τ up to N/3 (`bench_allan`), less with
/// the default τ range; with glibc, keep large blocks mmap'd
/// (`mallopt(M_MMAP_THRESHOLD, 1 MiB)`, as the `tumble` binary does) or freed
/// buffers of one axis stay in the heap while the next allocates its own.
/// `progress` is called once per τ of each axis.
pub fn allan_deviation_axes(
    axes: &[&[f64]],
    tau0: f64,
    opts: &AllanOptions,
    progress: &(dyn Fn() + Sync),
) -> Result<Vec<AllanCurve>, AllanError> {
    let mut out = Vec::with_capacity(axes.len());
    for pair in axes.chunks(AXES_AT_ONCE) {
        let results: Vec<Result<AllanCurve, AllanError>> = if pair.len() == 2 {
            let (a, b) = rayon::join(
                || allan_deviation_with_progress(pair[0], tau0, opts, progress),
                || allan_deviation_with_progress(pair[1], tau0, opts, progress),
            );
            vec![a, b]
        } else {
            vec![allan_deviation_with_progress(pair[0], tau0, opts, progress)]
        };
        for r in results {
            out.push(r?);
        }
    }
    Ok(out)
}

/// The deviation curve from *phase* samples x(i) (time error \[s\] for clock
/// data, or the integral of a rate: angle \[rad\] for a gyro) taken every
/// `tau0` seconds — the form Stable32's PHASE.DAT is in.
pub fn allan_deviation_from_phase(x: &[f64], tau0: f64, opts: &AllanOptions) -> Result<AllanCurve, AllanError> {
    check_input(x, tau0, 2 * opts.kind.difference_order() + 2, "phase sample", opts.kind)?;
    // In units of frequency × samples, as `phase_of` makes it, and without
    // the line through the end points (a frequency offset, which no Allan-type
    // deviation sees) so the rate under it has zero mean.
    let n = (x.len() - 1) as f64;
    let slope = (x[x.len() - 1] - x[0]) / n;
    let scaled: Vec<f64> = x.iter().enumerate().map(|(i, v)| (v - x[0] - slope * i as f64) / tau0).collect();
    curve_from_phase(&scaled, tau0, opts, &|| {})
}

/// Finite values, a positive period and enough samples for the estimator.
fn check_input(v: &[f64], tau0: f64, need: usize, what: &str, kind: DeviationKind) -> Result<(), AllanError> {
    if !(tau0.is_finite() && tau0 > 0.0) {
        return Err(AllanError::Invalid(format!("sample period must be positive and finite, got {tau0}")));
    }
    if let Some(i) = v.iter().position(|x| !x.is_finite()) {
        return Err(AllanError::Invalid(format!("{what} {i} is not a finite number ({})", v[i])));
    }
    if v.len() < need {
        return Err(AllanError::Invalid(format!(
            "{} {what}s are too few for the {} (need at least {need})",
            v.len(),
            kind.name()
        )));
    }
    Ok(())
}

/// The common core: `x` is the phase in units of the series × samples.
fn curve_from_phase(
    x: &[f64],
    tau0: f64,
    opts: &AllanOptions,
    progress: &(dyn Fn() + Sync),
) -> Result<AllanCurve, AllanError> {
    let kind = opts.kind;
    let n = x.len() - 1;
    let ms = cluster_sizes(&opts.taus, n, tau0, kind, opts.max_tau_fraction);
    if ms.is_empty() {
        return Err(AllanError::Invalid("no averaging time τ falls inside the record".into()));
    }
    let vars = deviation::variances(x, &ms, kind, progress);
    let d = kind.difference_order();
    use rayon::prelude::*;
    // Noise type at the octave at or below each m (it changes slowly with τ;
    // one lag-1 test per octave costs O(N) in all instead of O(N) per τ).
    let octave = |m: usize| 1usize << (usize::BITS - 1 - m.leading_zeros());
    let mut octaves: Vec<usize> = ms.iter().map(|&m| octave(m)).collect();
    octaves.dedup();
    let octave_ids: Vec<(usize, Option<i32>)> = octaves.par_iter().map(|&p| (p, edf::noise_id(x, p, d))).collect();
    let ids: Vec<Option<i32>> =
        ms.iter().map(|&m| octave_ids.iter().find(|(p, _)| *p == octave(m)).and_then(|(_, id)| *id)).collect();
    let mut curve = AllanCurve {
        kind,
        tau0,
        m: vec![],
        tau: vec![],
        dev: vec![],
        dev_lo: vec![],
        dev_hi: vec![],
        n_terms: vec![],
        alpha: vec![],
        edf: vec![],
        confidence: opts.confidence,
    };
    // Where the series is too short for the autocorrelation test, keep the
    // last identified noise type (white frequency noise if none yet).
    let mut last_alpha = ids.iter().flatten().next().copied().unwrap_or(0);
    for ((&m, v), id) in ms.iter().zip(vars).zip(ids) {
        let Some((var, count)) = v else { continue };
        let tau = m as f64 * tau0;
        let mut dev = var.max(0.0).sqrt();
        if kind == DeviationKind::Tdev {
            dev *= tau / 3f64.sqrt();
        }
        let alpha = id.unwrap_or(last_alpha);
        last_alpha = alpha;
        let e = edf::edf_greenhall(alpha, d, m, n + 1, kind.overlapping(), kind.modified());
        curve.push_point(m, tau, dev, count, alpha, e);
    }
    Ok(curve)
}
