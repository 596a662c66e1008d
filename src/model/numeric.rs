//! Small numeric helpers the estimators share.

/// Median of a slice (reordered); None when empty.
pub fn median(x: &mut [f64]) -> Option<f64> {
    if x.is_empty() {
        return None;
    }
    let m = x.len() / 2;
    x.select_nth_unstable_by(m, f64::total_cmp);
    Some(x[m])
}

/// The `p`-quantile of `v` (sorted in place; the nearest rank), NaN when empty.
pub fn percentile(v: &mut [f64], p: f64) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(|a, b| a.total_cmp(b));
    v[((v.len() - 1) as f64 * p).round() as usize]
}
