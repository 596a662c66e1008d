//! Static-interval detection (imu_tk's detector): a sample is static when the
//! variance of the accelerometer over a window centred on it is below
//! `k · σ²_init`, where `σ²_init` is the variance of the initial static period
//! (both as the norm of the per-axis variance vector, in raw units²).

/// A run of samples `[start, end)` (indices into the recording).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub struct Interval {
    /// First sample.
    pub start: usize,
    /// One past the last sample.
    pub end: usize,
}

impl Interval {
    /// Number of samples.
    pub fn len(&self) -> usize {
        self.end - self.start
    }
    /// True when empty.
    pub fn is_empty(&self) -> bool {
        self.end <= self.start
    }
}

/// Norm of the per-axis variance of `x` \[raw units²\].
pub fn variance_norm(x: &[[f64; 3]]) -> f64 {
    var3(x).iter().map(|v| v * v).sum::<f64>().sqrt()
}

pub use crate::io::validate::mean3;

/// Per-axis (population) variance of `x`.
pub fn var3(x: &[[f64; 3]]) -> [f64; 3] {
    let m = mean3(x);
    let n = x.len().max(1) as f64;
    let mut v = [0.0; 3];
    for s in x {
        for k in 0..3 {
            v[k] += (s[k] - m[k]).powi(2);
        }
    }
    v.map(|s| s / n)
}

/// Norm of the per-axis variance over a window of `w` samples (odd) centred
/// on each sample; `f64::INFINITY` where the window does not fit.
/// Running sums about the first sample keep raw counts (≈ 3·10⁴) exact enough.
pub fn sliding_variance_norm(x: &[[f64; 3]], w: usize) -> Vec<f64> {
    let n = x.len();
    let h = w / 2;
    let w = 2 * h + 1;
    let mut out = vec![f64::INFINITY; n];
    if n < w {
        return out;
    }
    let o = x[0];
    let mut s = [0.0; 3];
    let mut s2 = [0.0; 3];
    let add = |s: &mut [f64; 3], s2: &mut [f64; 3], v: &[f64; 3], sign: f64| {
        for k in 0..3 {
            let d = v[k] - o[k];
            s[k] += sign * d;
            s2[k] += sign * d * d;
        }
    };
    for v in &x[..w] {
        add(&mut s, &mut s2, v, 1.0);
    }
    let wf = w as f64;
    for c in h..n - h {
        if c > h {
            add(&mut s, &mut s2, &x[c + h], 1.0);
            add(&mut s, &mut s2, &x[c - h - 1], -1.0);
        }
        let mut q = 0.0;
        for k in 0..3 {
            let var = (s2[k] / wf - (s[k] / wf).powi(2)).max(0.0);
            q += var * var;
        }
        out[c] = q.sqrt();
    }
    out
}

/// Runs of consecutive samples with `score < threshold` at least `min_len` long.
pub fn intervals_below(score: &[f64], threshold: f64, min_len: usize) -> Vec<Interval> {
    let mut out = Vec::new();
    let mut start = None;
    for (i, &s) in score.iter().chain(std::iter::once(&f64::INFINITY)).enumerate() {
        match (s < threshold, start) {
            (true, None) => start = Some(i),
            (false, Some(a)) => {
                if i - a >= min_len.max(1) {
                    out.push(Interval { start: a, end: i });
                }
                start = None;
            }
            _ => {}
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sliding_matches_direct() {
        let x: Vec<[f64; 3]> =
            (0..200).map(|i| [(i as f64 * 0.37).sin() * 5.0 + 3e4, (i as f64).sqrt(), (i % 7) as f64]).collect();
        let s = sliding_variance_norm(&x, 11);
        for c in 5..195 {
            let d = variance_norm(&x[c - 5..=c + 5]);
            assert!((s[c] - d).abs() < 1e-6 * d.max(1.0), "{c}: {} vs {d}", s[c]);
        }
        assert!(s[4].is_infinite() && s[195].is_infinite());
    }

    #[test]
    fn runs() {
        let s = [0.0, 0.0, 5.0, 0.0, 0.0, 0.0, 5.0, 0.0];
        assert_eq!(intervals_below(&s, 1.0, 2), vec![Interval { start: 0, end: 2 }, Interval { start: 3, end: 6 }]);
        assert_eq!(intervals_below(&s, 1.0, 3), vec![Interval { start: 3, end: 6 }]);
    }
}
