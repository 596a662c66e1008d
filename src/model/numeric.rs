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
