//! Allan-type deviations of a frequency-like series (a gyro rate, an
//! accelerometer reading) over cluster sizes m, computed exactly.
//!
//! Every deviation here is a finite difference of the *phase* x (the running
//! integral of the series): the Allan variance uses second differences
//! x(i+2m) − 2x(i+m) + x(i), the Hadamard variance third differences, the
//! modified Allan variance second differences averaged over m start points.
//!
//! * The phase is a prefix sum carried with compensated (two-sum) addition,
//!   so every stored x(i) is the correctly rounded exact sum, however long the
//!   log (a 24-hour 1 kHz log has 8.6·10⁷ samples).
//! * **Direct path**: one pass of length N per m (O(N) per τ).
//! * **Correlation path** (overlapping Allan and Hadamard with many τ): the
//!   sum of squared differences expands into autocorrelations of x at lags m,
//!   2m, 3m over windows that differ from the full series only by O(m) samples
//!   at the ends. One FFT gives the full autocorrelation at every lag, so each τ
//!   then costs O(m) instead of O(N) — the work is shared across all τ. The
//!   phase is detrended first (differences of order ≥ 2 ignore a linear trend),
//!   and for every τ a bound on the FFT's round-off is compared with the
//!   result; where it could reach 10⁻¹⁰ relative, that τ is computed directly.
//!
//! Definitions follow NIST SP 1065 (Riley, *Handbook of Frequency Stability
//! Analysis*) and reproduce Stable32.

use realfft::RealFftPlanner;
use serde::{Deserialize, Serialize};

/// Which Allan-type variance to compute.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum DeviationKind {
    /// Overlapping Allan deviation (the default for IMU noise identification).
    Oadev,
    /// Non-overlapping Allan deviation (clusters side by side).
    Adev,
    /// Modified Allan deviation (separates white and flicker phase noise).
    Mdev,
    /// Time deviation, τ·MDEV/√3 (in units of the series × seconds).
    Tdev,
    /// Non-overlapping Hadamard deviation (insensitive to linear drift).
    Hdev,
    /// Overlapping Hadamard deviation.
    Ohdev,
}

impl DeviationKind {
    /// Order of the phase difference (2 for Allan, 3 for Hadamard).
    pub fn difference_order(self) -> usize {
        match self {
            Self::Hdev | Self::Ohdev => 3,
            _ => 2,
        }
    }

    /// Whether the estimator uses every start point (stride 1).
    pub fn overlapping(self) -> bool {
        !matches!(self, Self::Adev | Self::Hdev)
    }

    /// Whether it is a modified (phase-averaged) variance.
    pub fn modified(self) -> bool {
        matches!(self, Self::Mdev | Self::Tdev)
    }

    /// The largest cluster size the estimator can use on `n` samples.
    pub fn max_m(self, n: usize) -> usize {
        match self {
            Self::Mdev | Self::Tdev => n / 3,
            Self::Hdev | Self::Ohdev => n / 3,
            _ => n / 2,
        }
    }

    /// Human name as printed in reports.
    pub fn name(self) -> &'static str {
        match self {
            Self::Oadev => "overlapping Allan deviation",
            Self::Adev => "Allan deviation",
            Self::Mdev => "modified Allan deviation",
            Self::Tdev => "time deviation",
            Self::Hdev => "Hadamard deviation",
            Self::Ohdev => "overlapping Hadamard deviation",
        }
    }
}

/// The phase x(0..=n) of a series y(0..n) with its mean removed, in units of
/// samples × y: x(0) = 0, x(i+1) = x(i) + (y(i) − ȳ), carried with two-sum
/// compensation so each value is the rounded exact sum.
pub fn phase_of(y: &[f64]) -> Vec<f64> {
    let mean = mean_compensated(y);
    let mut x = Vec::with_capacity(y.len() + 1);
    x.push(0.0);
    let (mut hi, mut lo) = (0.0f64, 0.0f64);
    for &v in y {
        let d = v - mean;
        let s = hi + d;
        let bb = s - hi;
        let err = (hi - (s - bb)) + (d - bb);
        hi = s;
        lo += err;
        // Renormalize so `hi` is the rounded value of hi + lo.
        let t = hi + lo;
        lo -= t - hi;
        hi = t;
        x.push(hi);
    }
    x
}

/// Mean with Neumaier compensation.
pub(crate) fn mean_compensated(y: &[f64]) -> f64 {
    let (mut s, mut c) = (0.0f64, 0.0f64);
    for &v in y {
        let t = s + v;
        if s.abs() >= v.abs() {
            c += (s - t) + v;
        } else {
            c += (v - t) + s;
        }
        s = t;
    }
    if y.is_empty() {
        0.0
    } else {
        (s + c) / y.len() as f64
    }
}

/// Binomial difference coefficients of order d (alternating signs), d ≤ 3.
fn coefficients(d: usize) -> &'static [f64] {
    match d {
        2 => &[1.0, -2.0, 1.0],
        _ => &[-1.0, 3.0, -3.0, 1.0],
    }
}

/// Sum of squared order-d differences of `x` at spacing m, with start points
/// 0, stride, 2·stride, … (all start points i with i + d·m ≤ len − 1).
/// Returns (sum, count).
fn difference_sum(x: &[f64], m: usize, d: usize, stride: usize) -> (f64, usize) {
    let c = coefficients(d);
    let last = x.len() - 1 - d * m; // last start index
    let (mut s, mut comp, mut count) = (0.0f64, 0.0f64, 0usize);
    let mut i = 0;
    while i <= last {
        let mut v = 0.0;
        for (k, &ck) in c.iter().enumerate() {
            v += ck * x[i + k * m];
        }
        // Kahan on the (positive) squares.
        let yv = v * v - comp;
        let t = s + yv;
        comp = (t - s) - yv;
        s = t;
        count += 1;
        i += stride;
    }
    (s, count)
}

/// Modified Allan variance sum: Σ_j (Σ_{i=j}^{j+m−1} Δ²x(i))² over
/// j = 0 … len − 3m, by a sliding window. Returns (sum, count).
fn modified_sum(x: &[f64], m: usize) -> (f64, usize) {
    let n = x.len();
    let d2 = |i: usize| x[i + 2 * m] - 2.0 * x[i + m] + x[i];
    let mut inner = 0.0;
    let mut inner_c = 0.0; // compensation of the running window
    for i in 0..m {
        let y = d2(i) - inner_c;
        let t = inner + y;
        inner_c = (t - inner) - y;
        inner = t;
    }
    let count = n - 3 * m + 1;
    let (mut s, mut comp) = (0.0f64, 0.0f64);
    for j in 0..count {
        let yv = inner * inner - comp;
        let t = s + yv;
        comp = (t - s) - yv;
        s = t;
        if j + 1 < count {
            let delta = d2(j + m) - d2(j);
            let y = delta - inner_c;
            let t = inner + y;
            inner_c = (t - inner) - y;
            inner = t;
        }
    }
    (s, count)
}

/// The variance (not deviation) for one m by the direct O(N) path, or None
/// if the series is too short for this m.
pub fn variance_direct(x: &[f64], m: usize, kind: DeviationKind) -> Option<(f64, usize)> {
    let n_phase = x.len();
    let d = kind.difference_order();
    let mf = m as f64;
    match kind {
        DeviationKind::Mdev | DeviationKind::Tdev => {
            if m == 0 || n_phase < 3 * m + 1 {
                return None;
            }
            let (s, count) = modified_sum(x, m);
            Some((s / (2.0 * mf.powi(4) * count as f64), count))
        }
        _ => {
            if m == 0 || n_phase < d * m + 1 {
                return None;
            }
            let stride = if kind.overlapping() { 1 } else { m };
            let (s, count) = difference_sum(x, m, d, stride);
            let scale = if d == 2 { 2.0 } else { 6.0 };
            Some((s / (scale * mf * mf * count as f64), count))
        }
    }
}

/// Autocorrelation of a detrended phase, shared by all τ of one series.
pub struct PhaseCorrelation {
    /// Detrended phase z(i).
    z: Vec<f64>,
    /// R(k) = Σ_i z(i) z(i+k) for k = 0 … max_lag.
    r: Vec<f64>,
    /// Prefix sums of z² (compensated): p(k) = Σ_{i<k} z(i)².
    sq_prefix: Vec<f64>,
    /// Bound on the absolute round-off of any R(k).
    r_error: f64,
}

impl PhaseCorrelation {
    /// Correlations of the phase `x` up to lag `max_lag`.
    pub fn new(x: &[f64], max_lag: usize) -> Self {
        let n = x.len();
        let z = detrend_linear(x);
        let nfft = fast_len(n + max_lag + 1);
        let mut planner = RealFftPlanner::<f64>::new();
        let fwd = planner.plan_fft_forward(nfft);
        let inv = planner.plan_fft_inverse(nfft);
        let mut buf = vec![0.0; nfft];
        buf[..n].copy_from_slice(&z);
        let mut spec = fwd.make_output_vec();
        fwd.process(&mut buf, &mut spec).expect("buffer sizes come from the plan");
        for c in spec.iter_mut() {
            *c = realfft::num_complex::Complex::new(c.norm_sqr(), 0.0);
        }
        inv.process(&mut spec, &mut buf).expect("buffer sizes come from the plan");
        drop(spec);
        let scale = 1.0 / nfft as f64;
        buf.truncate(max_lag + 1);
        for v in buf.iter_mut() {
            *v *= scale;
        }
        let mut sq_prefix = Vec::with_capacity(n + 1);
        let (mut s, mut c) = (0.0f64, 0.0f64);
        sq_prefix.push(0.0);
        for &v in &z {
            let y = v * v - c;
            let t = s + y;
            c = (t - s) - y;
            s = t;
            sq_prefix.push(s);
        }
        // FFT round-off grows like ε·log2(n) relative to the largest
        // correlation R(0); a factor 8 of margin.
        let r_error = 8.0 * f64::EPSILON * (nfft as f64).log2() * s;
        Self { z, r: buf, sq_prefix, r_error }
    }

    /// Σ_{i=s}^{s+len−1} z(i) z(i+lag).
    fn window(&self, lag: usize, start: usize, len: usize) -> f64 {
        if lag == 0 {
            return self.sq_prefix[start + len] - self.sq_prefix[start];
        }
        let n = self.z.len();
        let z = &self.z;
        let head: f64 = (0..start).map(|i| z[i] * z[i + lag]).sum();
        let tail: f64 = (start + len..n - lag).map(|i| z[i] * z[i + lag]).sum();
        self.r[lag] - head - tail
    }

    /// The overlapping order-d variance sum for m, with its error bound, or
    /// None if lag d·m is beyond the computed correlations.
    fn overlapping_sum(&self, m: usize, d: usize) -> Option<(f64, f64, usize)> {
        let n = self.z.len();
        if d * m >= self.r.len() || n < d * m + 1 {
            return None;
        }
        let c = coefficients(d);
        let len = n - d * m;
        let mut s = 0.0;
        let mut weight = 0.0;
        for k in 0..=d {
            for l in k..=d {
                let w = if k == l { c[k] * c[k] } else { 2.0 * c[k] * c[l] };
                s += w * self.window((l - k) * m, k * m, len);
                if k != l {
                    weight += w.abs();
                }
            }
        }
        Some((s, weight * self.r_error, len))
    }
}

/// Subtract the least-squares line from x (indices as abscissa).
fn detrend_linear(x: &[f64]) -> Vec<f64> {
    let n = x.len() as f64;
    let tm = (n - 1.0) / 2.0;
    let xm = mean_compensated(x);
    let mut sxy = 0.0;
    let mut sxx = 0.0;
    for (i, &v) in x.iter().enumerate() {
        let dt = i as f64 - tm;
        sxy += dt * (v - xm);
        sxx += dt * dt;
    }
    let slope = if sxx > 0.0 { sxy / sxx } else { 0.0 };
    x.iter().enumerate().map(|(i, &v)| v - xm - slope * (i as f64 - tm)).collect()
}

/// Smallest length ≥ n of the form 2^a·3^b (fast for the FFT).
fn fast_len(n: usize) -> usize {
    let mut best = n.next_power_of_two();
    let mut p3 = 1usize;
    while p3 < best {
        let mut v = p3;
        while v < n {
            v *= 2;
        }
        best = best.min(v);
        p3 *= 3;
    }
    best
}

/// Variances of `kind` at each cluster size in `ms` for the phase `x`
/// (from [`phase_of`]), as (variance in units of y², number of terms).
/// Uses the correlation path when it pays; `progress` is called once per m.
pub fn variances(
    x: &[f64],
    ms: &[usize],
    kind: DeviationKind,
    progress: &(dyn Fn() + Sync),
) -> Vec<Option<(f64, usize)>> {
    use rayon::prelude::*;
    const DIRECT_BELOW: usize = 16;
    let d = kind.difference_order();
    let n = x.len();
    let use_corr =
        kind.overlapping() && !kind.modified() && n > 4096 && ms.iter().filter(|&&m| m >= DIRECT_BELOW).count() > 24;
    let corr = if use_corr {
        let max_m = ms.iter().copied().filter(|&m| d * m < n).max().unwrap_or(0);
        Some(PhaseCorrelation::new(x, d * max_m))
    } else {
        None
    };
    let scale = if d == 2 { 2.0 } else { 6.0 };
    ms.par_iter()
        .map(|&m| {
            let out = match &corr {
                Some(c) if m >= DIRECT_BELOW => match c.overlapping_sum(m, d) {
                    Some((s, err, count)) if s > 0.0 && err <= 1e-10 * s => {
                        let mf = m as f64;
                        Some((s / (scale * mf * mf * count as f64), count))
                    }
                    _ => variance_direct(x, m, kind),
                },
                _ => variance_direct(x, m, kind),
            };
            progress();
            out
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn series(n: usize) -> Vec<f64> {
        // Deterministic white + random-walk mix.
        let mut s = 0x1234_5678_9abc_def0u64;
        let mut rw = 0.0;
        (0..n)
            .map(|_| {
                s ^= s << 13;
                s ^= s >> 7;
                s ^= s << 17;
                let u = (s >> 11) as f64 / (1u64 << 53) as f64 - 0.5;
                rw += 1e-3 * u;
                0.3 + u + rw
            })
            .collect()
    }

    #[test]
    fn correlation_path_equals_direct() {
        let y = series(20_000);
        let x = phase_of(&y);
        for kind in [DeviationKind::Oadev, DeviationKind::Ohdev] {
            let corr = PhaseCorrelation::new(&x, kind.difference_order() * 3000);
            for m in [16, 17, 100, 999, 3000] {
                let (s, _, count) = corr.overlapping_sum(m, kind.difference_order()).unwrap();
                let scale = if kind.difference_order() == 2 { 2.0 } else { 6.0 };
                let v = s / (scale * (m * m) as f64 * count as f64);
                let (vd, cd) = variance_direct(&x, m, kind).unwrap();
                assert_eq!(count, cd);
                assert!(((v - vd) / vd).abs() < 1e-10, "{kind:?} m={m}: {v} vs {vd}");
            }
        }
    }

    #[test]
    fn modified_sum_matches_definition() {
        let y = series(500);
        let x = phase_of(&y);
        for m in [1, 2, 7, 50] {
            let (v, count) = variance_direct(&x, m, DeviationKind::Mdev).unwrap();
            let mut s = 0.0;
            for j in 0..x.len() - 3 * m + 1 {
                let inner: f64 = (j..j + m).map(|i| x[i + 2 * m] - 2.0 * x[i + m] + x[i]).sum();
                s += inner * inner;
            }
            let want = s / (2.0 * (m as f64).powi(4) * (x.len() - 3 * m + 1) as f64);
            assert_eq!(count, x.len() - 3 * m + 1);
            assert!(((v - want) / want).abs() < 1e-12);
        }
    }

    #[test]
    fn phase_is_exact_for_long_constant_series() {
        // A constant series has zero phase after removing its mean, even over 10⁶ samples.
        let y = vec![0.1; 1_000_000];
        let x = phase_of(&y);
        assert!(x.iter().all(|v| v.abs() < 1e-9));
    }

    #[test]
    fn fast_len_is_smooth_and_large_enough() {
        for n in [1, 5, 1000, 1025, 3_600_001] {
            let l = fast_len(n);
            assert!(l >= n);
            let mut v = l;
            while v % 2 == 0 {
                v /= 2;
            }
            while v % 3 == 0 {
                v /= 3;
            }
            assert_eq!(v, 1);
        }
    }
}
