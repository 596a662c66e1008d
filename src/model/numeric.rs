//! Small numeric helpers the estimators share.

/// Median of a slice (reordered; the upper one of an even count); None when empty.
pub fn median(x: &mut [f64]) -> Option<f64> {
    let m = x.len() / 2;
    (!x.is_empty()).then(|| kth_smallest(x, m))
}

/// The `k`-th smallest value of `v` (0-based, `k < v.len()`), as sorting
/// would give it, in linear time (the order of `v` changes).
pub fn kth_smallest(v: &mut [f64], k: usize) -> f64 {
    *v.select_nth_unstable_by(k, f64::total_cmp).1
}

/// The `p`-quantile of `v` (sorted in place; the nearest rank), NaN when empty.
pub fn percentile(v: &mut [f64], p: f64) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(|a, b| a.total_cmp(b));
    v[((v.len() - 1) as f64 * p).round() as usize]
}
