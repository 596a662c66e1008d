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
//!   sum of squared differences is the squared norm of the rate filtered by a
//!   kernel of d blocks of m samples. One FFT autocorrelation R of the rate,
//!   with prefix sums of R and δ·R, gives the full-convolution norm in O(d)
//!   per τ; the outputs where the kernel overhangs the record's ends are
//!   subtracted from the phase in O(m) (see [`RateCorrelation`]). The FFT's
//!   round-off is measured on a few lags recomputed exactly, and for every τ
//!   that bound is compared with the result; where it could reach
//!   [`CORRELATION_TOLERANCE`] relative, that τ is computed directly.
//!
//! Definitions follow NIST SP 1065 (Riley, *Handbook of Frequency Stability
//! Analysis*) and reproduce Stable32.

use realfft::RealFftPlanner;
use serde::{Deserialize, Serialize};

/// Which Allan-type variance to compute.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
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

impl std::str::FromStr for DeviationKind {
    type Err = super::AllanError;
    fn from_str(s: &str) -> Result<DeviationKind, super::AllanError> {
        let k = DeviationKind::NAMES.iter().position(|n| *n == s.trim()).ok_or_else(|| {
            super::AllanError::Invalid(format!("unknown deviation `{s}` (kinds: {})", DeviationKind::NAMES.join(", ")))
        })?;
        Ok(DeviationKind::ALL[k])
    }
}

impl DeviationKind {
    /// The names `FromStr` takes, in order.
    pub const NAMES: [&'static str; 6] = ["oadev", "adev", "mdev", "tdev", "hdev", "ohdev"];
    const ALL: [DeviationKind; 6] = [
        DeviationKind::Oadev,
        DeviationKind::Adev,
        DeviationKind::Mdev,
        DeviationKind::Tdev,
        DeviationKind::Hdev,
        DeviationKind::Ohdev,
    ];
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
/// samples × y: x(0) = 0, x(i+1) = x(i) + (y(i) − ȳ), each value the rounded
/// sum carried with Knuth's two-sum compensation (as if in twice the
/// precision).
pub fn phase_of(y: &[f64]) -> Vec<f64> {
    let mean = mean_compensated(y);
    running_sums(y.len(), |i| y[i] - mean)
}

/// The running sums p(0) = 0, p(k) = Σ_{i<k} v(i), k = 0 … len, each the
/// rounded value of a sum carried in two parts: the running sum `hi` and its
/// accumulated rounding error `lo`, from Knuth's two-sum at every step
/// (Ogita, Rump & Oishi's Sum2: as accurate as summing in twice the
/// precision). Only the add into `hi` is on the loop's dependency chain —
/// four times shorter than Kahan's compensation, where every add is.
fn running_sums(len: usize, v: impl Fn(usize) -> f64) -> Vec<f64> {
    let mut p = Vec::new();
    crate::io::mem::reserve_huge(&mut p, len + 1);
    p.push(0.0);
    let (mut hi, mut lo) = (0.0f64, 0.0f64);
    for i in 0..len {
        let d = v(i);
        let s = hi + d;
        let bb = s - hi;
        lo += (hi - (s - bb)) + (d - bb);
        hi = s;
        p.push(hi + lo);
    }
    p
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

/// A running sum with Kahan compensation.
#[derive(Clone, Copy, Debug, Default)]
struct Kahan {
    sum: f64,
    compensation: f64,
}

impl Kahan {
    fn add(&mut self, v: f64) {
        let y = v - self.compensation;
        let t = self.sum + y;
        self.compensation = (t - self.sum) - y;
        self.sum = t;
    }

    fn value(&self) -> f64 {
        self.sum
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
    let (mut sum, mut count) = (Kahan::default(), 0usize);
    let mut i = 0;
    while i <= last {
        let mut v = 0.0;
        for (k, &ck) in c.iter().enumerate() {
            v += ck * x[i + k * m];
        }
        sum.add(v * v);
        count += 1;
        i += stride;
    }
    (sum.value(), count)
}

/// Modified Allan variance sum: Σ_j (Σ_{i=j}^{j+m−1} Δ²x(i))² over
/// j = 0 … len − 3m, by a sliding window. Returns (sum, count).
fn modified_sum(x: &[f64], m: usize) -> (f64, usize) {
    let n = x.len();
    let d2 = |i: usize| x[i + 2 * m] - 2.0 * x[i + m] + x[i];
    // The running window and the sum of its squares, both compensated.
    let mut inner = Kahan::default();
    for i in 0..m {
        inner.add(d2(i));
    }
    let count = n - 3 * m + 1;
    let mut sum = Kahan::default();
    for j in 0..count {
        sum.add(inner.value() * inner.value());
        if j + 1 < count {
            inner.add(d2(j + m) - d2(j));
        }
    }
    (sum.value(), count)
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

/// Autocorrelation of the (mean-free) rate y, shared by all τ of one series.
///
/// The sum of squared order-d phase differences at spacing m is the squared
/// norm of y filtered by a kernel of d blocks of m equal weights. Over the
/// *full* convolution that norm is Σ_δ K(δ)·R(δ), with K the kernel's
/// autocorrelation — piecewise linear between multiples of m — so with prefix
/// sums of R(δ) and δ·R(δ) it costs O(d) per τ. The outputs where the kernel
/// hangs over an end of the record are then subtracted, computed directly
/// from the phase (O(m)). Working on y rather than the phase keeps the
/// numbers small: no cancellation of huge phase correlations for drifting
/// sensors. Working memory: the FFT buffers (≈ 2 × 8 bytes × (N + max lag)),
/// then 5 × 8 bytes × max lag for R, its two prefix sums and those of the
/// squared phase near both ends.
pub struct RateCorrelation<'a> {
    /// The phase x(0..=N) (its differences are y).
    x: &'a [f64],
    /// R(δ) = Σ_j y(j) y(j+δ), δ = 0 … max_lag (R(0) exact).
    r: Vec<f64>,
    /// p0(k) = Σ_{δ=1}^{k} R(δ), p1(k) = Σ_{δ=1}^{k} δ·R(δ) ([`running_sums`]).
    p0: Vec<f64>,
    p1: Vec<f64>,
    /// Bound on the absolute round-off of any R(δ), δ ≥ 1.
    r_error: f64,
    /// head_sq(k) = Σ_{j=1}^{k} (x(j) − x(0))², tail_sq(k) = Σ_{i=N−k}^{N−1} (x(i) − x(N))².
    head_sq: Vec<f64>,
    tail_sq: Vec<f64>,
}

/// One real-FFT planner per process, so that all axes of a recording (same
/// length) share the plans and their twiddle tables.
fn planner() -> &'static std::sync::Mutex<RealFftPlanner<f64>> {
    static PLANNER: std::sync::OnceLock<std::sync::Mutex<RealFftPlanner<f64>>> = std::sync::OnceLock::new();
    PLANNER.get_or_init(|| std::sync::Mutex::new(RealFftPlanner::new()))
}

/// Block weights of the rate kernel of an order-d phase difference.
fn block_weights(d: usize) -> &'static [f64] {
    match d {
        2 => &[-1.0, 1.0],
        _ => &[1.0, -2.0, 1.0],
    }
}

impl<'a> RateCorrelation<'a> {
    /// Correlations of the rate under the phase `x`, up to lag `max_lag`.
    pub fn new(x: &'a [f64], max_lag: usize) -> Self {
        use rayon::prelude::*;
        let n = x.len() - 1;
        let max_lag = max_lag.min(n.saturating_sub(1));
        let y = |j: usize| x[j + 1] - x[j];
        let nfft = fast_len(n + max_lag + 1);
        let fwd = planner().lock().unwrap_or_else(|e| e.into_inner()).plan_fft_forward(nfft);
        let mut buf = crate::io::mem::filled_huge(nfft, 0.0);
        buf[..n].par_iter_mut().enumerate().for_each(|(j, v)| *v = y(j));
        let mut spec = crate::io::mem::filled_huge(nfft / 2 + 1, realfft::num_complex::Complex::new(0.0, 0.0));
        fwd.process(&mut buf, &mut spec).expect("buffer sizes come from the plan");
        // The power spectrum P is real and even, so its inverse transform is
        // its forward transform (real part): mirror P into the real buffer
        // and reuse the forward plan (no second plan and its twiddle table).
        buf.par_iter_mut().enumerate().for_each(|(k, v)| *v = spec[k.min(nfft - k)].norm_sqr());
        fwd.process(&mut buf, &mut spec).expect("buffer sizes come from the plan");
        buf.truncate(max_lag + 1);
        buf.par_iter_mut().enumerate().for_each(|(j, v)| *v = spec[j].re);
        drop(spec);
        let scale = 1.0 / nfft as f64;
        buf.shrink_to_fit();
        buf.par_iter_mut().for_each(|v| *v *= scale);
        // Exact R(0), and the FFT's round-off measured on a few lags
        // recomputed exactly, with a factor 10 of margin over the largest
        // difference seen (never below ε·R(0)·√log2 n, the order that
        // round-off theory gives).
        let lags: Vec<usize> = (0..=4usize).map(|j| max_lag * j / 4).collect();
        let exact: Vec<f64> = lags.par_iter().map(|&lag| dot_compensated(n - lag, |j| y(j) * y(j + lag))).collect();
        let seen = lags.iter().zip(&exact).skip(1).map(|(&lag, e)| (buf[lag] - e).abs()).fold(0.0, f64::max);
        buf[0] = exact[0];
        let r_error = (10.0 * seen).max(f64::EPSILON * exact[0] * (nfft as f64).log2().sqrt());
        // Only up to the largest m ≤ max_lag/2 is ever used at the ends.
        let ends = (max_lag / 2 + 1).min(n);
        let ((p0, p1), (head_sq, tail_sq)) = rayon::join(
            || {
                rayon::join(
                    || running_sums(max_lag, |k| buf[k + 1]),
                    || running_sums(max_lag, |k| (k + 1) as f64 * buf[k + 1]),
                )
            },
            || {
                rayon::join(
                    || running_sums(ends, |k| (x[k + 1] - x[0]).powi(2)),
                    || running_sums(ends, |k| (x[n - 1 - k] - x[n]).powi(2)),
                )
            },
        );
        Self { x, r: buf, p0, p1, r_error, head_sq, tail_sq }
    }

    /// Σ over the edge outputs of the order-d filter at spacing m (where the
    /// kernel hangs over an end): the record's ends held constant, i.e. the
    /// phase clamped to x(0) before the start and to x(N) after the end.
    /// Outputs with a single phase point inside come from prefix sums; for
    /// d = 2 those with two inside are `pairs` (from [`Self::pair_edges`]).
    fn edges(&self, m: usize, d: usize, pairs: f64) -> f64 {
        let x = self.x;
        let n = x.len() - 1;
        let c = coefficients(d);
        let (x0, xn) = (x[0], x[n]);
        // Left: output i = j − b·m (b = number of clamped terms), j ∈ [1, m].
        let mut s = c[d] * c[d] * self.head_sq[m];
        // Right: output i with b terms inside, i ∈ [N − b·m, N − (b−1)·m − 1].
        s += c[0] * c[0] * self.tail_sq[m];
        if d == 2 {
            return s + pairs;
        }
        for b in 1..d {
            let jmax = if b == 1 { m - 1 } else { m };
            s += sum4(1, jmax + 1, |j| {
                let u: f64 = (b..=d).map(|k| c[k] * (x[j + (k - b) * m] - x0)).sum();
                u * u
            });
        }
        for b in 2..=d {
            let ilo = if b == d { n + 1 - d * m } else { n - b * m };
            s += sum4(ilo, n - (b - 1) * m, |i| {
                let u: f64 = (0..b).map(|k| c[k] * (x[i + k * m] - xn)).sum();
                u * u
            });
        }
        s
    }

    /// The order-2 edge outputs with two phase points inside, for each m of
    /// `ms` that has a correlation-path sum (0 for the others): Σ (c₁·x(j) +
    /// c₂·x(j+m) + offset)² at the left end and its mirror at the right,
    /// summed for batches of neighbouring m together ([`edge_sums`]).
    fn pair_edges(&self, ms: &[usize]) -> Vec<f64> {
        use super::edge_sums::{pair_sums, End, BATCH};
        use rayon::prelude::*;
        let x = self.x;
        let n = x.len() - 1;
        let c = coefficients(2);
        let mut valid: Vec<usize> = ms.iter().copied().filter(|&m| self.has_sum(m, 2)).collect();
        valid.sort_unstable();
        valid.dedup();
        let sums: Vec<f64> = valid
            .par_chunks(BATCH)
            .flat_map_iter(|batch| {
                let left = pair_sums(x, batch, End::Left, c[1], c[2], -(c[1] + c[2]) * x[0]);
                let right = pair_sums(x, batch, End::Right, c[1], c[0], -(c[0] + c[1]) * x[n]);
                left.into_iter().zip(right).map(|(l, r)| l + r)
            })
            .collect();
        ms.iter().map(|m| valid.binary_search(m).map_or(0.0, |i| sums[i])).collect()
    }

    /// Whether the correlations reach the order-d kernel at m.
    fn has_sum(&self, m: usize, d: usize) -> bool {
        m > 0 && d * m <= self.r.len() && d * m < self.x.len()
    }

    /// The overlapping order-d variance sum for m, with its error bound, or
    /// None if the kernel is longer than the computed correlations; `pairs`
    /// as in [`Self::edges`].
    fn overlapping_sum(&self, m: usize, d: usize, pairs: f64) -> Option<(f64, f64, usize)> {
        let n = self.x.len() - 1;
        if !self.has_sum(m, d) {
            return None;
        }
        let w = block_weights(d);
        // K at multiples of m: K_s = m·Σ_{q−p=s} w_p w_q.
        let k_at = |s: usize| -> f64 { (0..d - s.min(d)).map(|p| w[p] * w[p + s]).sum::<f64>() * m as f64 };
        let mut total = k_at(0) * self.r[0];
        let mut bound = 0.0;
        let mf = m as f64;
        for seg in 0..d {
            let lo = (seg * m).max(1);
            let hi = (seg + 1) * m - 1;
            let (k0, k1) = (k_at(seg), k_at(seg + 1));
            let slope = (k1 - k0) / mf;
            let s0 = self.p0[hi] - self.p0[lo - 1];
            let s1 = self.p1[hi] - self.p1[lo - 1];
            let base = (seg * m) as f64;
            total += 2.0 * (k0 * s0 + slope * (s1 - base * s0));
            // Round-off: the R values, and the prefix sums' own rounding.
            let kmax = k0.abs().max(k1.abs());
            bound += 2.0 * kmax * mf * self.r_error;
            let prefix_mag = self.p0[hi].abs() + self.p0[lo - 1].abs();
            let prefix1_mag = self.p1[hi].abs() + self.p1[lo - 1].abs();
            bound += 2.0 * f64::EPSILON * (kmax * prefix_mag + slope.abs() * (prefix1_mag + base * prefix_mag));
        }
        let s = total - self.edges(m, d, pairs);
        Some((s, bound, n + 1 - d * m))
    }
}

/// Σ f(i) for from ≤ i < to in four interleaved accumulators (independent
/// dependency chains: several times faster than one running sum).
pub(crate) fn sum4(from: usize, to: usize, f: impl Fn(usize) -> f64) -> f64 {
    let mut acc = [0.0f64; 4];
    let mut i = from;
    while i + 4 <= to {
        for (k, a) in acc.iter_mut().enumerate() {
            *a += f(i + k);
        }
        i += 4;
    }
    let mut s = (acc[0] + acc[1]) + (acc[2] + acc[3]);
    while i < to {
        s += f(i);
        i += 1;
    }
    s
}

/// Σ f(i) for i < n with Kahan compensation, in [`DOT_LANES`] interleaved
/// lanes: each lane's compensated add is a chain of four dependent adds, so
/// enough independent lanes let it run at the speed of the loads.
fn dot_compensated(n: usize, f: impl Fn(usize) -> f64) -> f64 {
    let mut s = [0.0f64; DOT_LANES];
    let mut c = [0.0f64; DOT_LANES];
    let full = n / DOT_LANES * DOT_LANES;
    let mut i = 0;
    while i < full {
        for k in 0..DOT_LANES {
            let v = f(i + k) - c[k];
            let t = s[k] + v;
            c[k] = (t - s[k]) - v;
            s[k] = t;
        }
        i += DOT_LANES;
    }
    for j in full..n {
        let v = f(j) - c[0];
        let t = s[0] + v;
        c[0] = (t - s[0]) - v;
        s[0] = t;
    }
    // Combine the lanes with their compensations.
    let mut total = Kahan::default();
    for k in 0..DOT_LANES {
        total.add(s[k]);
        total.add(-c[k]);
    }
    total.value()
}

/// Lanes of [`dot_compensated`]: four-add chains of four cycles each need 16
/// lanes to issue one element per cycle.
const DOT_LANES: usize = 16;

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

/// Largest relative round-off bound accepted from the correlation path; a τ
/// whose bound is larger is computed directly. (10⁻⁸ is three orders below
/// the 5 printed digits of Stable32 and far below any interval.)
pub const CORRELATION_TOLERANCE: f64 = 1e-8;

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
    const DIRECT_BELOW: usize = 1;
    let d = kind.difference_order();
    let n = x.len();
    let use_corr =
        kind.overlapping() && !kind.modified() && n > 4096 && ms.iter().filter(|&&m| m >= DIRECT_BELOW).count() > 24;
    let corr = if use_corr {
        let max_m = ms.iter().copied().filter(|&m| d * m < n).max().unwrap_or(0);
        Some(RateCorrelation::new(x, d * max_m))
    } else {
        None
    };
    let pairs = match &corr {
        Some(c) if d == 2 => c.pair_edges(ms),
        _ => vec![0.0; ms.len()],
    };
    let scale = if d == 2 { 2.0 } else { 6.0 };
    ms.par_iter()
        .zip(pairs)
        .map(|(&m, pairs)| {
            let out = match &corr {
                Some(c) if m >= DIRECT_BELOW => match c.overlapping_sum(m, d, pairs) {
                    Some((s, err, count)) if s > 0.0 && err <= CORRELATION_TOLERANCE * s => {
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
            let d = kind.difference_order();
            let corr = RateCorrelation::new(&x, d * 6000);
            let ms = [1, 2, 16, 17, 100, 999, 3000, 6000];
            let pairs = if d == 2 { corr.pair_edges(&ms) } else { vec![0.0; ms.len()] };
            for (&m, pairs) in ms.iter().zip(pairs) {
                let (s, _, count) = corr.overlapping_sum(m, d, pairs).unwrap();
                let scale = if kind.difference_order() == 2 { 2.0 } else { 6.0 };
                let v = s / (scale * (m * m) as f64 * count as f64);
                let (vd, cd) = variance_direct(&x, m, kind).unwrap();
                assert_eq!(count, cd);
                assert!(((v - vd) / vd).abs() < 1e-10, "{kind:?} m={m}: {v} vs {vd}");
            }
        }
    }

    #[test]
    fn variances_agree_with_the_direct_sums_to_their_tolerance_on_a_drifting_series() {
        // A large offset, a strong random walk and a quadratic drift: the
        // correlation path's cancellation is worst here, and any τ it cannot
        // vouch for to 10⁻⁸ must come from the direct sum.
        let n = 60_000;
        let mut rw = 0.0;
        let y: Vec<f64> = series(n)
            .iter()
            .enumerate()
            .map(|(i, u)| {
                rw += 0.05 * (u - 0.3);
                1e4 + u + rw + 1e-6 * (i as f64).powi(2)
            })
            .collect();
        let x = phase_of(&y);
        let mut ms: Vec<usize> = (0..60).map(|k| (10f64.powf(k as f64 * 4.4 / 59.0)) as usize).collect();
        ms.dedup();
        for kind in [DeviationKind::Oadev, DeviationKind::Ohdev] {
            let got = variances(&x, &ms, kind, &|| {});
            for (&m, v) in ms.iter().zip(got) {
                let Some((vd, cd)) = variance_direct(&x, m, kind) else {
                    assert!(v.is_none(), "{kind:?} m={m} is too long for the record");
                    continue;
                };
                let (v, count) = v.unwrap();
                assert_eq!(count, cd);
                // The accuracy docs/allan.md promises, whatever the constant.
                assert!(((v - vd) / vd).abs() < 1e-8, "{kind:?} m={m}: {v} vs {vd}");
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
