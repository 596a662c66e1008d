//! Static-interval detection (after imu_tk's detector): a sample is static
//! when the variance over a window centred on it, each axis in units of its
//! own variance at rest ([`axis_noise`], [`axis_ratio`]), is below `k` times
//! the rest's; and whether the intervals found were still ([`WithinInterval`]).

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

pub use crate::io::validate::{mean3, var3};
use crate::model::numeric::{kth_smallest, median};

/// The level of a recording's quietest windows: the 5th percentile of the
/// finite values of a sliding-variance score (`None` when there are none).
pub fn quietest(score: &[f64]) -> Option<f64> {
    let mut v: Vec<f64> = score.iter().copied().filter(|x| x.is_finite()).collect();
    let k = v.len() / 20;
    (!v.is_empty()).then(|| kth_smallest(&mut v, k))
}

/// Norm of the per-axis variance over a window of `w` samples (odd) centred
/// on each sample; `f64::INFINITY` where the window does not fit.
pub fn sliding_variance_norm(x: &[[f64; 3]], w: usize) -> Vec<f64> {
    norms(&sliding_variance(x, w))
}

/// Norm of each per-axis variance of [`sliding_variance`] (∞ stays ∞).
pub fn norms(var: &[[f64; 3]]) -> Vec<f64> {
    var.iter().map(|v| v.iter().map(|x| x * x).sum::<f64>().sqrt()).collect()
}

/// Per-axis variance over a window of `w` samples (odd) centred on each
/// sample; `f64::INFINITY` where the window does not fit.
/// Running sums about the first sample keep raw counts (≈ 3·10⁴) exact enough.
pub fn sliding_variance(x: &[[f64; 3]], w: usize) -> Vec<[f64; 3]> {
    let n = x.len();
    let h = w / 2;
    let w = 2 * h + 1;
    let mut out = vec![[f64::INFINITY; 3]; n];
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
        out[c] = std::array::from_fn(|k| (s2[k] / wf - (s[k] / wf).powi(2)).max(0.0));
    }
    out
}

/// Each axis's noise variance at rest: the variance of `rest` per axis, at
/// least the quantization's `q²/12` (`q` the axis's smallest step between
/// consecutive samples), so that an axis whose reading sits on one count does
/// not divide by zero. An axis that never changes falls back to the largest
/// axis's variance.
pub fn axis_noise(rest: &[[f64; 3]]) -> [f64; 3] {
    let var = var3(rest);
    let step = |k: usize| {
        rest.windows(2).map(|p| (p[1][k] - p[0][k]).abs()).filter(|d| *d > 0.0).fold(f64::INFINITY, f64::min)
    };
    let largest = var.iter().copied().fold(0.0, f64::max);
    std::array::from_fn(|k| {
        let q = step(k);
        if q.is_finite() {
            var[k].max(q * q / 12.0)
        } else {
            largest
        }
    })
}

/// Detection score per sample: the windowed variance whitened by the noise at
/// rest, `(1/3) Σ_k var_k / noise_k` (1 at rest). Each axis counts in units of
/// its own noise: the norm of the variances is ruled by the noisiest axis,
/// under whose noise a slow turn that the quieter axes see hides.
pub fn axis_ratio(var: &[[f64; 3]], noise: &[f64; 3]) -> Vec<f64> {
    var.iter().map(|v| (0..3).map(|k| v[k] / noise[k].max(1e-300)).sum::<f64>() / 3.0).collect()
}

/// Per-axis mean over a window of `w` samples (odd) centred on each sample;
/// NaN where the window does not fit.
pub fn sliding_mean(x: &[[f64; 3]], w: usize) -> Vec<[f64; 3]> {
    let h = w / 2;
    let n = x.len();
    let mut out = vec![[f64::NAN; 3]; n];
    if n < 2 * h + 1 {
        return out;
    }
    let o = x[0];
    let mut prefix = vec![[0.0; 3]; n + 1];
    for (i, v) in x.iter().enumerate() {
        prefix[i + 1] = std::array::from_fn(|k| prefix[i][k] + (v[k] - o[k]));
    }
    let wf = (2 * h + 1) as f64;
    for c in h..n - h {
        out[c] = std::array::from_fn(|k| o[k] + (prefix[c + h + 1][k] - prefix[c - h][k]) / wf);
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

/// The initial rest: the samples whose mean gives the gyro bias and whose
/// variance is the detector's reference. Several parts when a knock that did
/// not move the IMU was cut out of it.
#[derive(Debug, Clone, PartialEq)]
pub struct InitialRest {
    /// The still runs, in time order (sample indices).
    pub parts: Vec<Interval>,
    /// True when found from the data, false when given (`--init-static`).
    pub detected: bool,
}

impl InitialRest {
    /// The first `n` samples, as given by the user.
    pub fn given(n: usize) -> InitialRest {
        InitialRest { parts: vec![Interval { start: 0, end: n }], detected: false }
    }
    /// Samples in the rest.
    pub fn samples(&self) -> usize {
        self.parts.iter().map(Interval::len).sum()
    }
    /// First sample and one past the last (the knocks cut out included).
    pub fn span(&self) -> Interval {
        Interval { start: self.parts[0].start, end: self.parts[self.parts.len() - 1].end }
    }
    /// The rest's samples of `x` (gyro or accelerometer), the cut-out knocks excluded.
    pub fn collect(&self, x: &[[f64; 3]]) -> Vec<[f64; 3]> {
        self.parts.iter().flat_map(|p| x[p.start..p.end].iter().copied()).collect()
    }
}

/// A window counts as still in [`find_initial_rest`] when both its
/// accelerometer and its gyro variance are below this many times the
/// recording's quietest windows (5th percentile). Windowed variances of white
/// noise scatter by less than ±50 % over 50 samples, and a hand turn raises
/// them by orders of magnitude.
pub const REST_FACTOR: f64 = 10.0;

/// Largest tilt across a short disturbance for the rests on both sides of it
/// to count as one \[deg\]: a knock that leaves the IMU where it was (0.05°)
/// does not end the initial rest; a new pose does.
pub const MAX_KNOCK_TILT_DEG: f64 = 0.5;

/// Fraction of the recording in which the initial rest must start.
pub const EARLY_FRACTION: f64 = 0.25;

/// Find the initial static period from the data: windows are still when
/// both sliding variances (`accel_score`, `gyro_score`, windows of `w`
/// samples) are below [`REST_FACTOR`] × their quietest 5 % and the mean rate
/// is near that of the quiet windows; still runs separated by a knock (at
/// most half a window of shaking; a turn by hand takes longer, even one about
/// the vertical that leaves gravity where it was) and tilted by less than
/// [`MAX_KNOCK_TILT_DEG`] are one rest with the disturbance cut out; each run
/// loses half a window at both ends (where a turn starts and ends slowly); the
/// longest rest of at least `min_samples` that starts in the first
/// [`EARLY_FRACTION`] of the recording is returned.
pub fn find_initial_rest(
    accel: &[[f64; 3]],
    gyro: &[[f64; 3]],
    accel_score: &[f64],
    gyro_score: &[f64],
    w: usize,
    min_samples: usize,
) -> Option<InitialRest> {
    let (qa, qg) = (quietest(accel_score)?.max(1e-300), quietest(gyro_score)?.max(1e-300));
    let mut ratio: Vec<f64> = accel_score.iter().zip(gyro_score).map(|(a, g)| (a / qa).max(g / qg)).collect();
    // Mid-turn the rate is high but flat, its variance low: a still window's mean
    // rate must also be near the rate of the quiet windows (the bias).
    let mean = sliding_mean(gyro, w);
    let quiet_means: Vec<[f64; 3]> =
        mean.iter().zip(&ratio).filter(|(_, r)| **r < REST_FACTOR).map(|(m, _)| *m).collect();
    if quiet_means.is_empty() {
        return None;
    }
    let bias: [f64; 3] = std::array::from_fn(|k| {
        let mut v: Vec<f64> = quiet_means.iter().map(|m| m[k]).collect();
        median(&mut v).unwrap_or(f64::NAN)
    });
    for (r, m) in ratio.iter_mut().zip(&mean) {
        let d2: f64 = (0..3).map(|k| (m[k] - bias[k]).powi(2)).sum();
        *r = r.max(d2 / qg);
    }
    let h = w / 2;
    let n = accel.len();
    // Runs of still window centres; runs separated by a knock (a gap of at most one
    // window plus half a window of shaking) are one rest if gravity did not move.
    let direction = |iv: &Interval| nalgebra::Vector3::from(mean3(&accel[iv.start..iv.end])).normalize();
    let mut rests: Vec<Vec<Interval>> = Vec::new();
    for run in intervals_below(&ratio, REST_FACTOR, 1) {
        if let Some(last) = rests.last_mut() {
            let prev = last[last.len() - 1];
            let tilt = direction(&prev).angle(&direction(&run)).to_degrees();
            if run.start <= prev.end + w + h && tilt < MAX_KNOCK_TILT_DEG {
                last.push(run);
                continue;
            }
        }
        rests.push(vec![run]);
    }
    // The samples: each run of centres less half a window at both ends (the slow
    // start and end of a turn stay below the variance threshold for a while, and
    // their rate would bias the mean), except at the start of the recording.
    let rests = rests.into_iter().map(|runs| {
        runs.into_iter()
            .map(|r| Interval { start: if r.start <= h { 0 } else { r.start + h }, end: r.end.saturating_sub(h) })
            .filter(|r| !r.is_empty())
            .collect::<Vec<_>>()
    });
    let early = (n as f64 * EARLY_FRACTION) as usize;
    rests
        .filter(|parts| !parts.is_empty())
        .map(|parts| InitialRest { parts, detected: true })
        .filter(|r| r.span().start <= early && r.samples() >= min_samples)
        .max_by_key(InitialRest::samples)
}

/// Whether a reading stays put inside the static intervals: its two halves'
/// means against the white noise of its samples.
///
/// The calibration and the audit weigh each interval's mean as `σ²/n`, white
/// noise over `n` samples, and compare the means across intervals, where
/// every effect the audit knows shows. Inside an interval none varies, so a
/// difference between the halves beyond the noise is something else: a
/// sensor settling after the turn before, an interval not quite at rest,
/// noise that is not white over seconds (flicker, a table that shakes). Its
/// interval means then scatter more than `σ²/n`: a calibration's χ²/dof (and
/// so its inflated σ) carries it, and an audit's gap that no effect explains.
/// Per interval the halves of `h` samples differ by `d`, of variance `2σ²/h`
/// under white noise; `T = Σ d²/(2σ²/h)` is χ² with one degree of freedom
/// per interval. Each interval contributes its central stretch of the median
/// interval's length (a long initial rest would otherwise measure the bias
/// walk over tens of seconds), with `σ²` from [`axis_noise`] of that stretch
/// (at least the quantization's).
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct WithinInterval {
    /// What was measured: `gyro x`, `accel z`, `|accel|`.
    pub reading: String,
    /// `T / m`: how many times the white noise's variance the halves differ by (1 for white noise).
    pub ratio: f64,
    /// Intervals measured (`m`, the degrees of freedom).
    pub intervals: usize,
    /// Probability of a `T` at least this large under white noise.
    pub p_value: f64,
}

impl WithinInterval {
    /// The seven tests: the gyro's axes, the accelerometer's axes and its
    /// norm (`accel`, `gyro`: raw samples), over `intervals`.
    pub fn measure_all(accel: &[[f64; 3]], gyro: &[[f64; 3]], intervals: &[Interval]) -> Vec<WithinInterval> {
        let norm: Vec<[f64; 3]> = norms(accel).into_iter().map(|n| [n, 0.0, 0.0]).collect();
        let mut within = Vec::new();
        for (triad, x) in [("gyro", gyro), ("accel", accel)] {
            for (k, axis) in ["x", "y", "z"].into_iter().enumerate() {
                within.extend(WithinInterval::measure(format!("{triad} {axis}"), x, k, intervals));
            }
        }
        within.extend(WithinInterval::measure("|accel|".into(), &norm, 0, intervals));
        within
    }

    /// The test on column `k` of `x` over `intervals`; `None` with fewer than
    /// 8 intervals of 8 samples.
    pub fn measure(reading: String, x: &[[f64; 3]], k: usize, intervals: &[Interval]) -> Option<WithinInterval> {
        use statrs::distribution::{ChiSquared, ContinuousCDF};
        let mut lens: Vec<usize> = intervals.iter().map(|iv| iv.len()).collect();
        lens.sort_unstable();
        let typical = lens.get(lens.len() / 2).copied().unwrap_or(0);
        let (mut t, mut m) = (0.0, 0usize);
        for iv in intervals {
            let len = iv.len().min(typical) & !1;
            if len < 8 {
                continue;
            }
            let start = iv.start + (iv.len() - len) / 2;
            let s = &x[start..start + len];
            let h = len / 2;
            let d = mean3(&s[..h])[k] - mean3(&s[h..])[k];
            t += d * d / (2.0 * axis_noise(s)[k].max(1e-300) / h as f64);
            m += 1;
        }
        (m >= 8).then(|| WithinInterval {
            reading,
            ratio: t / m as f64,
            intervals: m,
            p_value: ChiSquared::new(m as f64).map(|c| c.sf(t)).unwrap_or(1.0),
        })
    }
}

/// What a significant [`WithinInterval`] test means, for a warning or a verdict.
pub const UNSETTLED_CAUSES: &str =
    "the sensor settles after each turn, a pose is not quite still, or its noise is not white over seconds";

/// The level at which `tumble calibrate` reports poses that were not still
/// (the audit's default `--alpha`).
pub const STILLNESS_ALPHA: f64 = 1e-3;

/// The tests of `within` significant at `alpha` after Bonferroni's correction
/// over all of them.
pub fn unsettled(within: &[WithinInterval], alpha: f64) -> Vec<&WithinInterval> {
    let n = within.len().max(1) as f64;
    within.iter().filter(|w| w.p_value < alpha / n).collect()
}

/// "the accel z moves 16.2× (p 1e-40), …" for a verdict or a note.
pub fn describe(tests: &[&WithinInterval]) -> String {
    let parts: Vec<String> =
        tests.iter().map(|w| format!("the {} moves {:.1}× (p {:.1e})", w.reading, w.ratio, w.p_value)).collect();
    parts.join(", ")
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

    fn still(n: usize, level: f64, seed: u64) -> Vec<[f64; 3]> {
        let mut state = seed;
        let mut r = move || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((state >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * level
        };
        (0..n).map(|_| [r(), r(), 9.81 + r()]).collect()
    }

    #[test]
    fn initial_rest_is_found_and_bridges_a_knock() {
        // 1.5 s still, a knock (spike, no tilt), 1.5 s still, then 21 s of turning.
        let mut a = still(300, 0.01, 1);
        a[150] = [0.5, -0.4, 10.5];
        a.extend((0..2100).map(|i| [9.81 * (i as f64 / 30.0).sin(), 0.0, 9.81]));
        let g: Vec<[f64; 3]> = (0..a.len()).map(|i| [if i < 300 { 0.0 } else { (i as f64 / 7.0).cos() }; 3]).collect();
        let (sa, sg) = (sliding_variance_norm(&a, 11), sliding_variance_norm(&g, 11));
        let rest = find_initial_rest(&a, &g, &sa, &sg, 11, 100).unwrap();
        assert!(rest.detected);
        assert_eq!(rest.parts.len(), 2, "{rest:?}");
        assert_eq!(rest.span().start, 0);
        assert!((290..=300).contains(&rest.span().end), "{rest:?}");
        // Nothing still and long enough early on.
        assert!(find_initial_rest(&a, &g, &sa, &sg, 11, 400).is_none());
    }

    #[test]
    fn runs() {
        let s = [0.0, 0.0, 5.0, 0.0, 0.0, 0.0, 5.0, 0.0];
        assert_eq!(intervals_below(&s, 1.0, 2), vec![Interval { start: 0, end: 2 }, Interval { start: 3, end: 6 }]);
        assert_eq!(intervals_below(&s, 1.0, 3), vec![Interval { start: 3, end: 6 }]);
    }
}

#[cfg(test)]
mod within_tests {
    use super::*;
    use rand::SeedableRng;
    use rand_distr::{Distribution, StandardNormal};

    /// 40 intervals of 300–700 samples of white noise (σ 2 on x), 50 samples of turn between them.
    fn recording(seed: u64, drift: f64) -> (Vec<[f64; 3]>, Vec<Interval>) {
        let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
        let (mut x, mut intervals) = (Vec::new(), Vec::new());
        for k in 0..40 {
            let n = 300 + (k * 37) % 400;
            let start = x.len();
            for i in 0..n {
                // A settling after the turn: an exponential of 2 s (200 samples) on x.
                let settle = drift * (-(i as f64) / 200.0).exp() * if k % 2 == 0 { 1.0 } else { -1.0 };
                let (e, f): (f64, f64) = (StandardNormal.sample(&mut rng), StandardNormal.sample(&mut rng));
                x.push([2.0 * e + settle, 0.5 * f, 1.0]);
            }
            intervals.push(Interval { start, end: x.len() });
            x.extend((0..50).map(|_| [100.0, 100.0, 100.0]));
        }
        (x, intervals)
    }

    #[test]
    fn white_noise_stays_put_and_a_settling_does_not() {
        let mut rejected = 0;
        for seed in 0..40 {
            let (x, iv) = recording(seed, 0.0);
            let t: Vec<WithinInterval> =
                (0..2).filter_map(|k| WithinInterval::measure(format!("axis {k}"), &x, k, &iv)).collect();
            assert_eq!(t.len(), 2);
            assert!(t.iter().all(|w| w.intervals == 40 && (0.4..2.0).contains(&w.ratio)), "{t:?}");
            rejected += unsettled(&t, 1e-2).len();
            // A constant axis (one quantization step) is not flagged either.
            let c = WithinInterval::measure("constant".into(), &x, 2, &iv).unwrap();
            assert!(c.ratio == 0.0 && c.p_value == 1.0, "{c:?}");
        }
        // 80 tests at a 0.5 % level each (1 % over two): about 0.4 expected.
        assert!(rejected <= 3, "{rejected} of 80 white-noise axes flagged");
        // A settling of 0.5 σ at the start of each interval is found on x alone.
        let (x, iv) = recording(1, 1.0);
        let t: Vec<WithinInterval> =
            (0..2).filter_map(|k| WithinInterval::measure(format!("axis {k}"), &x, k, &iv)).collect();
        let found = unsettled(&t, 1e-3);
        assert_eq!(found.len(), 1, "{t:?}");
        assert_eq!(found[0].reading, "axis 0");
        assert!(describe(&found).starts_with("the axis 0 moves"), "{}", describe(&found));
    }
}
