//! Accelerometer and gyro recorded as separate streams with their own stamps
//! and rates (RealSense D4xx's `/camera/accel/sample` and
//! `/camera/gyro/sample`, phone loggers, two text files), merged onto the
//! gyro's stamps; and a temperature trace joined to an IMU by time.
//!
//! The gyro's stamps are kept because the gyro is the faster stream on every
//! such sensor and its samples enter the attitude integration directly; the
//! accelerometer is read between its two neighbouring samples by linear
//! interpolation (exact for a signal linear over one accelerometer period,
//! which a sensor's own anti-alias filter makes a good approximation).
//! Gyro samples outside the accelerometer's span are dropped, never
//! extrapolated.

/// One sensor's samples: stamps \[ns\] and a triad per stamp.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Stream {
    /// Stamps \[ns\], in any order (sorted by [`merge_onto_gyro`]).
    pub t_ns: Vec<i64>,
    /// One triad per stamp.
    pub v: Vec<[f64; 3]>,
}

impl Stream {
    fn sorted(mut self) -> Stream {
        if self.t_ns.windows(2).any(|w| w[1] < w[0]) {
            let mut idx: Vec<usize> = (0..self.t_ns.len()).collect();
            idx.sort_by_key(|&i| self.t_ns[i]);
            self = Stream {
                t_ns: idx.iter().map(|&i| self.t_ns[i]).collect(),
                v: idx.iter().map(|&i| self.v[i]).collect(),
            };
        }
        self
    }
    /// Median stamp interval \[s\] (0 with fewer than two samples).
    pub fn median_period(&self) -> f64 {
        let t: Vec<f64> = self.t_ns.iter().map(|&t| t as f64 * 1e-9).collect();
        crate::io::validate::median_period(&t)
    }
}

/// Both streams on the gyro's stamps, and what merging did.
#[derive(Debug, Clone, Default)]
pub struct Merged {
    /// Stamps \[ns\] (the gyro's, inside the accelerometer's span).
    pub t_ns: Vec<i64>,
    /// Gyro samples.
    pub gyro: Vec<[f64; 3]>,
    /// Accelerometer read at the gyro's stamps.
    pub accel: Vec<[f64; 3]>,
    /// Gyro samples (in stamp order) dropped before the accelerometer's first
    /// stamp: the first merged sample is the gyro's sample of this index.
    pub first_kept: usize,
    /// One line on the rates and what was merged.
    pub note: String,
    /// Gaps in the accelerometer stream that were interpolated across, and dropped duplicates.
    pub warnings: Vec<String>,
}

/// A gap is an interval longer than this many median periods (one missing
/// sample makes an interval of two periods; jitter stays well under 1.5).
const GAP_FACTOR: f64 = 1.5;

/// Why two split streams cannot be merged (the caller names the file).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{0}")]
pub struct MergeError(pub String);

impl From<&str> for MergeError {
    fn from(s: &str) -> MergeError {
        MergeError(s.to_string())
    }
}

impl From<String> for MergeError {
    fn from(s: String) -> MergeError {
        MergeError(s)
    }
}

/// Merge split streams onto the gyro's stamps (see the module doc).
/// Errors say which stream is too short or when they do not overlap.
pub fn merge_onto_gyro(gyro: Stream, accel: Stream) -> Result<Merged, MergeError> {
    if gyro.t_ns.len() != gyro.v.len() || accel.t_ns.len() != accel.v.len() {
        return Err("a stream has a different number of stamps and samples".into());
    }
    let gyro = gyro.sorted();
    let mut accel = accel.sorted();
    for (s, what) in [(&gyro, "gyro"), (&accel, "accelerometer")] {
        if s.t_ns.len() < 2 {
            return Err(format!("the {what} stream has {} sample(s): too few to merge", s.t_ns.len()).into());
        }
    }
    let mut warnings = Vec::new();
    // Equal accelerometer stamps cannot be interpolated between: keep the first.
    let n0 = accel.t_ns.len();
    let keep: Vec<bool> = (0..n0).map(|i| i == 0 || accel.t_ns[i] != accel.t_ns[i - 1]).collect();
    let dups = keep.iter().filter(|k| !**k).count();
    if dups > 0 {
        let mut k = keep.iter();
        accel.v.retain(|_| *k.next().unwrap_or(&true));
        let mut k = keep.iter();
        accel.t_ns.retain(|_| *k.next().unwrap_or(&true));
        warnings.push(format!("{dups} accelerometer samples repeat the previous stamp: the first of each kept"));
    }
    let (pa, pg) = (accel.median_period(), gyro.median_period());
    let gaps: Vec<f64> =
        accel.t_ns.windows(2).map(|w| (w[1] - w[0]) as f64 * 1e-9).filter(|&d| d > GAP_FACTOR * pa).collect();
    if !gaps.is_empty() {
        warnings.push(format!(
            "{} gaps in the accelerometer stream (longer than {GAP_FACTOR} periods of {:.3} ms), largest {:.3} s: \
             interpolated across",
            gaps.len(),
            pa * 1e3,
            gaps.iter().fold(0.0f64, |a, &b| a.max(b))
        ));
    }
    let (a0, a1) = (accel.t_ns[0], accel.t_ns[accel.t_ns.len() - 1]);
    let mut out = Merged::default();
    let mut j = 0;
    let mut dropped = 0;
    for (&t, &w) in gyro.t_ns.iter().zip(&gyro.v) {
        if t < a0 || t > a1 {
            dropped += 1;
            if t < a0 {
                out.first_kept += 1;
            }
            continue;
        }
        while j + 2 < accel.t_ns.len() && accel.t_ns[j + 1] <= t {
            j += 1;
        }
        let (ta, tb) = (accel.t_ns[j], accel.t_ns[j + 1]);
        let s = ((t - ta) as f64 / (tb - ta) as f64).clamp(0.0, 1.0);
        let (va, vb) = (accel.v[j], accel.v[j + 1]);
        out.t_ns.push(t);
        out.gyro.push(w);
        out.accel.push([0, 1, 2].map(|k| va[k] + s * (vb[k] - va[k])));
    }
    if out.t_ns.len() < 2 {
        return Err(format!(
            "the gyro ({:.3}–{:.3} s) and accelerometer ({:.3}–{:.3} s) streams do not overlap",
            gyro.t_ns[0] as f64 * 1e-9,
            gyro.t_ns[gyro.t_ns.len() - 1] as f64 * 1e-9,
            a0 as f64 * 1e-9,
            a1 as f64 * 1e-9
        )
        .into());
    }
    out.note = format!(
        "gyro at {:.1} Hz and accelerometer at {:.1} Hz merged onto the gyro's stamps (accelerometer interpolated \
         linearly); {} gyro samples outside the accelerometer's span dropped",
        1.0 / pg,
        1.0 / pa,
        dropped
    );
    out.warnings = warnings;
    Ok(out)
}

/// A temperature trace `(stamp [ns], °C)` read at `t_ns` by linear
/// interpolation, held at its first and last value outside its span.
/// Returns the values and how many stamps lie more than one trace period
/// outside the span (0 when the trace covers the recording).
pub fn join_temperature(t_ns: &[i64], trace: &[(i64, f64)]) -> (Vec<f64>, usize) {
    let mut tr = trace.to_vec();
    tr.sort_by_key(|p| p.0);
    tr.dedup_by_key(|p| p.0);
    if tr.is_empty() {
        return (Vec::new(), t_ns.len());
    }
    let period = if tr.len() > 1 { (tr[tr.len() - 1].0 - tr[0].0) / (tr.len() as i64 - 1) } else { 0 };
    let (first, last) = (tr[0], tr[tr.len() - 1]);
    let mut outside = 0;
    let mut j = 0;
    let v = t_ns
        .iter()
        .map(|&t| {
            if t < first.0 - period || t > last.0 + period {
                outside += 1;
            }
            if t <= first.0 {
                return first.1;
            }
            if t >= last.0 {
                return last.1;
            }
            while tr[j + 1].0 < t {
                j += 1;
            }
            let (a, b) = (tr[j], tr[j + 1]);
            a.1 + (b.1 - a.1) * (t - a.0) as f64 / (b.0 - a.0) as f64
        })
        .collect();
    (v, outside)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn accel_is_interpolated_at_gyro_stamps_and_the_span_is_respected() {
        // Gyro at 400 Hz from 0; accelerometer at 250 Hz from 1 ms, a ramp a = t [s].
        let gyro = Stream { t_ns: (0..400).map(|i| i * 2_500_000).collect(), v: vec![[0.1, 0.0, 0.0]; 400] };
        let at: Vec<i64> = (0..200).map(|i| 1_000_000 + i * 4_000_000).collect();
        let accel = Stream { v: at.iter().map(|&t| [t as f64 * 1e-9, 0.0, 9.8]).collect(), t_ns: at.clone() };
        let m = merge_onto_gyro(gyro, accel).unwrap();
        assert_eq!((m.t_ns[0], m.first_kept), (2_500_000, 1)); // the gyro's 0 precedes the first accelerometer sample
        assert_eq!(*m.t_ns.last().unwrap(), 795_000_000);
        for (t, a) in m.t_ns.iter().zip(&m.accel) {
            assert!((a[0] - *t as f64 * 1e-9).abs() < 1e-12);
        }
        assert!(m.note.contains("400.0 Hz") && m.note.contains("250.0 Hz"), "{}", m.note);
        assert!(m.warnings.is_empty());
    }

    #[test]
    fn gaps_duplicates_and_no_overlap_are_reported() {
        let gyro = Stream { t_ns: (0..100).map(|i| i * 1_000_000).collect(), v: vec![[0.0; 3]; 100] };
        let mut at: Vec<i64> =
            (0..50).map(|i| i * 2_000_000).filter(|t| !(40_000_000..60_000_000).contains(t)).collect();
        at.insert(3, at[2]);
        let accel = Stream { v: vec![[0.0, 0.0, 9.8]; at.len()], t_ns: at };
        let m = merge_onto_gyro(gyro.clone(), accel).unwrap();
        assert!(m.warnings.iter().any(|w| w.contains("repeat the previous stamp")), "{:?}", m.warnings);
        assert!(m.warnings.iter().any(|w| w.contains("1 gaps") && w.contains("0.022 s")), "{:?}", m.warnings);
        let late = Stream { t_ns: vec![1_000_000_000, 1_010_000_000], v: vec![[0.0; 3]; 2] };
        assert!(merge_onto_gyro(gyro, late).unwrap_err().0.contains("do not overlap"));
    }

    #[test]
    fn temperature_is_interpolated_and_held() {
        let (v, outside) = join_temperature(&[0, 5, 10, 30], &[(0, 20.0), (10, 21.0), (20, 23.0)]);
        assert_eq!(v, vec![20.0, 20.5, 21.0, 23.0]);
        assert_eq!(outside, 0);
        let (_, outside) = join_temperature(&[100], &[(0, 20.0), (10, 21.0)]);
        assert_eq!(outside, 1);
    }
}
