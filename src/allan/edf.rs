//! Confidence intervals of Allan-type deviations: noise identification by
//! the lag-1 autocorrelation (Riley & Greenhall 2004), equivalent degrees of
//! freedom by Greenhall & Riley's algorithm ("Uncertainty of stability
//! variances based on finite differences", 2004 — the method Stable32 uses),
//! and χ² intervals.
//!
//! Noise types are the power-law exponents α of the frequency spectrum
//! S_y(f) ∝ f^α: +2 white phase (IMU quantization, Q), +1 flicker phase,
//! 0 white frequency (angle/velocity random walk, N), −1 flicker frequency
//! (bias instability, B), −2 random-walk frequency (rate random walk, K),
//! −3 and −4 for the Hadamard variance only.

use super::deviation::sum4;
use statrs::distribution::{ChiSquared, ContinuousCDF};

/// Power-law noise exponent α identified at cluster size m from the lag-1
/// autocorrelation of the m-averaged series, as Stable32 does; `x` is the
/// phase from [`super::deviation::phase_of`], `dmax` the difference order of
/// the variance (2 Allan, 3 Hadamard). None when fewer than 30 averages fit.
pub fn noise_id(x: &[f64], m: usize, dmax: usize) -> Option<i32> {
    if m == 0 || (x.len() - 1) / m < 30 {
        return None;
    }
    // 2²⁰ averages pin the lag-1 autocorrelation to ±0.001; more add nothing.
    let n = ((x.len() - 1) / m).min(1 << 20);
    // The sums of m samples (the autocorrelation does not see the scale of
    // the averages), in huge pages where the system has them: up to a
    // million values, faulted in by a few 2 MiB pages instead of 2048.
    let mut series = Vec::new();
    crate::io::mem::reserve_huge(&mut series, n);
    series.extend((0..n).map(|k| x[(k + 1) * m] - x[k * m]));
    detrend(&mut series);
    let mut d = 0usize;
    loop {
        let r1 = lag1_acf(&series);
        let rho = r1 / (1.0 + r1);
        if rho < 0.25 || d >= dmax {
            let a = -(2.0 * rho).round() as i32 - 2 * d as i32;
            return Some(a.clamp(-(2 * dmax as i32) + 2, 2));
        }
        difference_in_place(&mut series);
        d += 1;
    }
}

/// Removes the least-squares line from `v`.
fn detrend(v: &mut [f64]) {
    let n = v.len() as f64;
    let tm = (n - 1.0) / 2.0;
    let mean = sum4(0, v.len(), |i| v[i]) / n;
    let sxy = sum4(0, v.len(), |i| (i as f64 - tm) * (v[i] - mean));
    // Σ (i − tm)² over i < n.
    let sxx = n * (n * n - 1.0) / 12.0;
    let b = if sxx > 0.0 { sxy / sxx } else { 0.0 };
    for (i, y) in v.iter_mut().enumerate() {
        *y -= mean + b * (i as f64 - tm);
    }
}

/// v(i) ← v(i+1) − v(i); one element shorter.
fn difference_in_place(v: &mut Vec<f64>) {
    for i in 1..v.len() {
        v[i - 1] = v[i] - v[i - 1];
    }
    v.pop();
}

/// The lag-1 autocorrelation of `v` about its mean (0 for a constant series).
fn lag1_acf(v: &[f64]) -> f64 {
    let mean = sum4(0, v.len(), |i| v[i]) / v.len() as f64;
    let num = sum4(1, v.len(), |i| (v[i - 1] - mean) * (v[i] - mean));
    let den = sum4(0, v.len(), |i| (v[i] - mean) * (v[i] - mean));
    if den > 0.0 {
        num / den
    } else {
        0.0
    }
}

/// Generalized autocovariance kernel sw(t) of Greenhall's eq. (7).
fn sw(t: f64, alpha: i32) -> f64 {
    let lnabs = |t: f64| if t == 0.0 { 0.0 } else { t.abs().ln() };
    match alpha {
        2 => -t.abs(),
        1 => t * t * lnabs(t),
        0 => t.abs().powi(3),
        -1 => t.powi(4) * lnabs(t),
        -2 => t.abs().powi(5),
        -3 => t.powi(6) * lnabs(t),
        _ => t.abs().powi(7),
    }
}

/// Eq. (8): kernel filtered by the F-point average (F = ∞ for the unmodified
/// variances at large m).
fn sx(t: f64, f: f64, alpha: i32) -> f64 {
    if f.is_infinite() {
        return sw(t, alpha + 2);
    }
    f * f * (2.0 * sw(t, alpha) - sw(t - 1.0 / f, alpha) - sw(t + 1.0 / f, alpha))
}

/// Eq. (9): the d-th difference of the kernel.
fn sz(t: f64, f: f64, alpha: i32, d: usize) -> f64 {
    let c: &[f64] = match d {
        1 => &[2.0, -1.0],
        2 => &[6.0, -4.0, 1.0],
        _ => &[20.0, -15.0, 6.0, -1.0],
    };
    let mut s = c[0] * sx(t, f, alpha);
    for (k, &ck) in c.iter().enumerate().skip(1) {
        s += ck * (sx(t - k as f64, f, alpha) + sx(t + k as f64, f, alpha));
    }
    s
}

/// Eq. (10): the basic sum.
fn basic_sum(j: f64, mm: f64, s: f64, f: f64, alpha: i32, d: usize) -> f64 {
    let mut total = sz(0.0, f, alpha, d).powi(2) + (1.0 - j / mm) * sz(j / s, f, alpha, d).powi(2);
    let mut k = 1.0;
    while k < j {
        total += 2.0 * (1.0 - k / mm) * sz(k / s, f, alpha, d).powi(2);
        k += 1.0;
    }
    total
}

/// Table 1 of Greenhall & Riley (modified variances, large r): (a0, a1).
fn table1(alpha: i32, d: usize) -> (f64, f64) {
    let t: [[(f64, f64); 3]; 7] = [
        [(2.0 / 3.0, 1.0 / 3.0), (7.0 / 9.0, 0.5), (22.0 / 25.0, 2.0 / 3.0)],
        [(0.840, 0.345), (0.997, 0.616), (1.141, 0.843)],
        [(1.079, 0.368), (1.033, 0.607), (1.184, 0.848)],
        [(f64::NAN, f64::NAN), (1.048, 0.534), (1.180, 0.816)],
        [(f64::NAN, f64::NAN), (1.302, 0.535), (1.175, 0.777)],
        [(f64::NAN, f64::NAN), (f64::NAN, f64::NAN), (1.194, 0.703)],
        [(f64::NAN, f64::NAN), (f64::NAN, f64::NAN), (1.489, 0.702)],
    ];
    t[(2 - alpha) as usize][d - 1]
}

/// Table 2 (unmodified variances, large r): (a0, a1).
fn table2(alpha: i32, d: usize) -> (f64, f64) {
    let t: [[(f64, f64); 3]; 7] = [
        [(1.5, 0.5), (35.0 / 18.0, 1.0), (231.0 / 100.0, 1.5)],
        [(78.6, 25.2), (790.0, 410.0), (9950.0, 6520.0)],
        [(2.0 / 3.0, 1.0 / 6.0), (2.0 / 3.0, 1.0 / 3.0), (7.0 / 9.0, 0.5)],
        [(f64::NAN, f64::NAN), (0.852, 0.375), (0.997, 0.617)],
        [(f64::NAN, f64::NAN), (1.079, 0.368), (1.033, 0.607)],
        [(f64::NAN, f64::NAN), (f64::NAN, f64::NAN), (1.053, 0.553)],
        [(f64::NAN, f64::NAN), (f64::NAN, f64::NAN), (1.302, 0.535)],
    ];
    t[(2 - alpha) as usize][d - 1]
}

/// Table 3 (flicker phase, unmodified): (b0, b1).
fn table3(d: usize) -> (f64, f64) {
    [(6.0, 4.0), (15.23, 12.0), (47.8, 40.0)][d - 1]
}

fn binomial(n: u64, k: u64) -> f64 {
    (0..k).fold(1.0, |acc, i| acc * (n - i) as f64 / (i + 1) as f64)
}

/// Equivalent degrees of freedom of a variance estimate (Greenhall & Riley
/// 2004) for noise exponent `alpha`, difference order `d` (2 Allan, 3
/// Hadamard), cluster size `m` and `n_phase` phase points. The noise exponent
/// is clamped to the range the variance converges for (α + 2d > 1).
pub fn edf_greenhall(alpha: i32, d: usize, m: usize, n_phase: usize, overlapping: bool, modified: bool) -> f64 {
    let alpha = alpha.clamp(2 - 2 * d as i32, 2);
    let mf = m as f64;
    let f = if modified { 1.0 } else { mf };
    let s = if overlapping { mf } else { 1.0 };
    let l = mf / f + mf * d as f64;
    let mm = 1.0 + (s * (n_phase as f64 - l) / mf).floor();
    if mm < 1.0 {
        return 1.0;
    }
    let j = mm.min((d as f64 + 1.0) * s);
    let j_max = 100.0;
    let r = mm / s;
    let dd = d as f64;
    let inv = if modified {
        if j <= j_max {
            basic_sum(j, mm, s, 1.0, alpha, d) / (sz(0.0, 1.0, alpha, d).powi(2) * mm)
        } else if r > dd + 1.0 {
            let (a0, a1) = table1(alpha, d);
            (a0 - a1 / r) / r
        } else {
            let mp = j_max / r;
            basic_sum(j_max, j_max, mp, 1.0, alpha, d) / (sz(0.0, 1.0, alpha, d).powi(2) * j_max)
        }
    } else if alpha <= 0 {
        if j <= j_max {
            let fp = if mf * (dd + 1.0) <= j_max { mf } else { f64::INFINITY };
            basic_sum(j, mm, s, fp, alpha, d) / (sz(0.0, fp, alpha, d).powi(2) * mm)
        } else if r > dd + 1.0 {
            let (a0, a1) = table2(alpha, d);
            (a0 - a1 / r) / r
        } else {
            let mp = j_max / r;
            basic_sum(j_max, j_max, mp, f64::INFINITY, alpha, d) / (sz(0.0, f64::INFINITY, alpha, d).powi(2) * j_max)
        }
    } else if alpha == 1 {
        if j <= j_max {
            basic_sum(j, mm, s, mf, 1, d) / (sz(0.0, mf, 1, d).powi(2) * mm)
        } else if r > dd + 1.0 {
            let (a0, a1) = table2(1, d);
            let (b0, b1) = table3(d);
            (a0 - a1 / r) / ((b0 + b1 * mf.ln()).powi(2) * r)
        } else {
            let mp = j_max / r;
            let (b0, b1) = table3(d);
            basic_sum(j_max, j_max, mp, mp, 1, d) / ((b0 + b1 * mf.ln()).powi(2) * j_max)
        }
    } else {
        // α = 2, unmodified: closed form (valid for r > d; clamped below).
        let a0 = binomial(4 * d as u64, 2 * d as u64) / binomial(2 * d as u64, d as u64).powi(2);
        let a1 = dd / 2.0;
        (a0 - a1 / r.max(dd + 1.0)) / mm
    };
    (1.0 / inv).max(1.0)
}

/// Two-sided confidence interval (lo, hi) of a deviation `dev` with `edf`
/// degrees of freedom at confidence `level` (0.683 for the 1-σ convention of
/// Stable32): dev·√(edf/χ²) at the upper and lower tail quantiles.
pub fn confidence_interval(dev: f64, edf: f64, level: f64) -> (f64, f64) {
    let Ok(chi) = ChiSquared::new(edf) else {
        return (f64::NAN, f64::NAN);
    };
    let tail = (1.0 - level) / 2.0;
    let hi_q = chi2_quantile(&chi, edf, 1.0 - tail);
    let lo_q = chi2_quantile(&chi, edf, tail);
    (dev * (edf / hi_q).sqrt(), dev * (edf / lo_q).sqrt())
}

/// χ² quantile to full precision: Wilson–Hilferty's approximation refined
/// by Newton steps on the regularized-gamma CDF.
fn chi2_quantile(chi: &ChiSquared, k: f64, p: f64) -> f64 {
    use statrs::distribution::Continuous;
    // Wilson–Hilferty: ((χ²/k)^(1/3) is nearly normal with mean 1 − 2/(9k)).
    let z = normal_quantile(p);
    let h = 2.0 / (9.0 * k);
    let mut x = (k * (1.0 - h + z * h.sqrt()).powi(3)).max(1e-3 * k.min(1.0));
    if k > 1e5 {
        // Wilson–Hilferty's relative error is below 2·10⁻⁹ here.
        return x;
    }
    for _ in 0..50 {
        let f = chi.cdf(x) - p;
        let d = chi.pdf(x);
        if d <= 0.0 || !d.is_finite() {
            break;
        }
        let step = f / d;
        let next = (x - step).max(x / 10.0);
        if (next - x).abs() <= 1e-14 * x {
            x = next;
            break;
        }
        x = next;
    }
    x
}

/// Standard normal quantile (Acklam's rational approximation, |error| < 1.2e-9,
/// enough for a starting point).
#[allow(clippy::excessive_precision)]
fn normal_quantile(p: f64) -> f64 {
    let a = [
        -3.969683028665376e1,
        2.209460984245205e2,
        -2.759285104469687e2,
        1.383577518672690e2,
        -3.066479806614716e1,
        2.506628277459239,
    ];
    let b =
        [-5.447609879822406e1, 1.615858368580409e2, -1.556989798598866e2, 6.680131188771972e1, -1.328068155288572e1];
    let c = [
        -7.784894002430293e-3,
        -3.223964580411365e-1,
        -2.400758277161838,
        -2.549732539343734,
        4.374664141464968,
        2.938163982698783,
    ];
    let d = [7.784695709041462e-3, 3.224671290700398e-1, 2.445134137142996, 3.754408661907416];
    let tail = |q: f64| {
        (((((c[0] * q + c[1]) * q + c[2]) * q + c[3]) * q + c[4]) * q + c[5])
            / ((((d[0] * q + d[1]) * q + d[2]) * q + d[3]) * q + 1.0)
    };
    if p < 0.02425 {
        tail((-2.0 * p.ln()).sqrt())
    } else if p > 1.0 - 0.02425 {
        -tail((-2.0 * (1.0 - p).ln()).sqrt())
    } else {
        let q = p - 0.5;
        let r = q * q;
        (((((a[0] * r + a[1]) * r + a[2]) * r + a[3]) * r + a[4]) * r + a[5]) * q
            / (((((b[0] * r + b[1]) * r + b[2]) * r + b[3]) * r + b[4]) * r + 1.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn white_fm_edf_grows_with_data() {
        let a = edf_greenhall(0, 2, 1, 1000, true, false);
        let b = edf_greenhall(0, 2, 1, 100_000, true, false);
        assert!(a > 100.0 && b > 50.0 * a, "{a} {b}");
    }

    #[test]
    fn chi_square_interval_brackets_and_shrinks() {
        let (lo, hi) = confidence_interval(1.0, 10.0, 0.683);
        assert!(lo < 1.0 && hi > 1.0);
        let (lo2, hi2) = confidence_interval(1.0, 1000.0, 0.683);
        assert!(lo2 > lo && hi2 < hi);
        assert!(((1.0 - lo2) - 0.022).abs() < 0.002, "{lo2}");
    }

    #[test]
    fn chi_square_quantiles_match_tables() {
        // scipy.stats.chi2.ppf values.
        for (k, p, want) in
            [(10.0, 0.1585, 5.678_656_885_f64), (782.03, 0.8415, 821.587_610_07), (2.5, 0.05, 0.210_758_112_36)]
        {
            let chi = ChiSquared::new(k).unwrap();
            let q = chi2_quantile(&chi, k, p);
            assert!((q - want).abs() < 1e-9 * want, "k={k} p={p}: {q} vs {want}");
            assert!((chi.cdf(q) - p).abs() < 1e-12);
        }
    }
}
