//! Where a recorded ground truth follows the IMU it was recorded with.
//!
//! A camera simulated along a recorded path moves as the path says, down to
//! its last millimetre; a real camera moves as the body does, which the IMU
//! feels. Where the ground truth holds motion the IMU does not feel (a laser
//! tracker's or a motion capture's own jitter), a simulated camera would
//! report accelerations that no IMU explains, and an estimator fitting both
//! then shrinks its scale: the regressor (the camera's motion) carries noise
//! the response (the IMU) lacks, and least squares dilutes the slope. On
//! EuRoC's Machine Hall (a Leica tracker) the ground truth's accelerations
//! stop following the IMU's above about 2 Hz (correlation 0.34 at 2–3 Hz,
//! 0.07 at 5–8 Hz) while in the Vicon room they follow it to 8 Hz.
//!
//! [`position_smoothing`] measures, band by band, how the ground truth's
//! accelerations correlate with the IMU's (both in the world frame, through
//! the ground truth's rotation) and returns the scale of the Gaussian that
//! cuts between the bands where they agree and those where they do not;
//! [`body_path`] then follows the ground truth below the cut and the IMU's
//! own motion above it. The rotation is left as it is: a ground
//! truth's orientation is usually the IMU's own gyro fused in (EuRoC's
//! follows the gyro with correlation 1.000 in every band).

use super::motion::{Motion, Replay};
use crate::model::ImuData;
use nalgebra::Vector3;

/// Grid step of the comparison \[s\] (200 Hz: EuRoC's IMU and ground-truth rate).
const STEP_S: f64 = 0.005;

/// Octave bands compared: Gaussian scales `STEP_S · 2^k` for `k` in
/// `0..=BANDS` (5 ms to 640 ms, about 32 Hz down to 0.25 Hz).
const BANDS: usize = 7;

/// Correlation below which a band's ground truth is not followed. With an
/// exact IMU a correlation of 0.5 means the ground truth's own noise holds
/// three quarters of the band's power: what the camera would move by there is
/// mostly not motion.
pub const MIN_BAND_CORRELATION: f64 = 0.5;

/// One octave band's comparison.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BandCorrelation {
    /// The band's frequencies \[Hz\] (between the two Gaussian scales' cut-offs `1/(2πσ)`).
    pub hz: [f64; 2],
    /// Correlation of the ground truth's and the IMU's acceleration in the band.
    pub correlation: f64,
}

/// The outcome: the bands and where the agreeing ones end.
#[derive(Debug, Clone, PartialEq)]
pub struct Smoothing {
    /// The bands, finest first.
    pub bands: Vec<BandCorrelation>,
    /// σ \[s\] of the Gaussian that cuts below the first band that does not
    /// agree ([`body_path`]'s argument; 0: every band agrees, no cut).
    pub sigma_s: f64,
}

impl Smoothing {
    /// One line for a user: where the cut fell and why (None without one).
    pub fn note(&self) -> Option<String> {
        if self.sigma_s == 0.0 {
            return None;
        }
        // The coarsest band left out: where the agreement ends.
        let worst = self.bands.iter().rev().find(|b| b.correlation < MIN_BAND_CORRELATION)?;
        Some(format!(
            "above {:.1} Hz the ground truth's accelerations do not follow the IMU's (correlation {:.2} at \
             {:.1}–{:.1} Hz): the simulated camera follows the ground truth below, the IMU's own motion above \
             (a Gaussian of {:.0} ms between them), as a camera on the body would",
            cutoff_hz(self.sigma_s),
            worst.correlation,
            worst.hz[0],
            worst.hz[1],
            self.sigma_s * 1e3
        ))
    }
}

/// The frequency \[Hz\] a Gaussian of scale `sigma` \[s\] halves the power at, roughly: `1/(2πσ)`.
fn cutoff_hz(sigma: f64) -> f64 {
    1.0 / (2.0 * std::f64::consts::PI * sigma)
}

/// Where the bands of `replay`'s accelerations that follow `imu`'s end
/// (times on the replay's axis, \[s\]); None when the two overlap too
/// briefly to compare (under ten times the coarsest band's scale).
pub fn position_smoothing(replay: &Replay, imu: &ImuData) -> Option<Smoothing> {
    let (a_gt, a_imu) = accelerations(replay, imu)?;
    let sigmas: Vec<f64> = (0..=BANDS).map(|k| STEP_S * f64::from(1u32 << k)).collect();
    let smooth_all = |a: &[[f64; 3]]| sigmas.iter().map(|s| gaussian(a, s / STEP_S)).collect::<Vec<_>>();
    let (s_gt, s_imu) = (smooth_all(&a_gt), smooth_all(&a_imu));
    // Edges, where the widest kernel reached past the ends, stay out.
    let edge = (4.0 * sigmas[BANDS] / STEP_S).ceil() as usize;
    let bands: Vec<BandCorrelation> = (0..BANDS)
        .map(|k| {
            let band = |s: &[Vec<[f64; 3]>], i: usize, c: usize| s[k][i][c] - s[k + 1][i][c];
            let (mut gi, mut gg, mut ii) = (0.0, 0.0, 0.0);
            for i in edge..a_gt.len() - edge {
                for c in 0..3 {
                    let (g, m) = (band(&s_gt, i, c), band(&s_imu, i, c));
                    gi += g * m;
                    gg += g * g;
                    ii += m * m;
                }
            }
            let correlation = if gg > 0.0 && ii > 0.0 { gi / (gg * ii).sqrt() } else { 0.0 };
            BandCorrelation { hz: [cutoff_hz(sigmas[k + 1]), cutoff_hz(sigmas[k])], correlation }
        })
        .collect();
    // The finest band from which every coarser one agrees.
    let keep_from = (0..=BANDS).find(|&k| bands[k..].iter().all(|b| b.correlation >= MIN_BAND_CORRELATION))?;
    let sigma_s = if keep_from == 0 { 0.0 } else { sigmas[keep_from] };
    Some(Smoothing { bands, sigma_s })
}

/// The ground truth's acceleration (second differences of its positions) and
/// the IMU's specific force in the world frame (through the ground truth's
/// rotation; gravity is a constant the bands take out), on one grid.
#[allow(clippy::type_complexity)]
fn accelerations(replay: &Replay, imu: &ImuData) -> Option<(Vec<[f64; 3]>, Vec<[f64; 3]>)> {
    let (t0, t1) = (replay.start().max(*imu.t.first()?), replay.duration().min(*imu.t.last()?));
    let n = ((t1 - t0) / STEP_S).floor() as usize;
    let min_len = 10.0 * STEP_S * f64::from(1u32 << BANDS) / STEP_S;
    if imu.t.len() < 2 || (n as f64) < min_len {
        return None;
    }
    let at = |i: usize| t0 + i as f64 * STEP_S;
    let (mut a_gt, mut a_imu) = (Vec::with_capacity(n), Vec::with_capacity(n));
    for i in 1..n - 1 {
        let k = replay.at(at(i));
        let (pm, p, pp) = (replay.at(at(i - 1)).position, k.position, replay.at(at(i + 1)).position);
        let a = (pp - 2.0 * p + pm) / (STEP_S * STEP_S);
        let f = k.rotation * imu.at(at(i)).0;
        a_gt.push([a.x, a.y, a.z]);
        a_imu.push([f.x, f.y, f.z]);
    }
    Some((a_gt, a_imu))
}

/// The path a camera on the body flies along a recorded ground truth
/// `recorded` (time from the IMU's first sample): [`body_path`] with the
/// cut [`position_smoothing`] finds against `imu`, or the ground truth as
/// it is when every band agrees. Returns the path and a note for the user
/// on where the cut fell (None without one).
pub fn camera_path(recorded: Replay, imu: &ImuData) -> (Replay, Option<String>) {
    let smoothing = position_smoothing(&recorded, imu);
    let note = smoothing.as_ref().and_then(|s| s.note());
    let path = match &smoothing {
        Some(s) if s.sigma_s > 0.0 => body_path(&recorded, imu, s.sigma_s),
        _ => recorded,
    };
    (path, note)
}

/// The path the body moved along, for a camera to fly: `replay`'s positions
/// below the cut-off of a Gaussian of `sigma_s` \[s\], the IMU's own motion
/// above it (`imu` on the replay's time axis), rotations as recorded.
///
/// Dropping the bands above the cut-off would leave the camera still where
/// the body shook (a drone's 2–8 Hz motion, 0.15–0.25 m/s² rms on EuRoC,
/// which the Vicon confirms where it sees it) and hand the IMU accelerations
/// no camera explains. The IMU's motion there is the body's to within its
/// white noise (a density of 0.013 m/s²/√Hz moves a path by under 0.1 mm
/// above 2 Hz). The two are joined as `p_imu + T(p_gt − p_imu)` with `T` the
/// low-pass Tukey's twicing makes of the Gaussian, `2G − G∘G`: exact on
/// quadratics (the double integral's drift from gravity and bias), and a
/// 0.5 Hz swing keeps 99.9 % of its size under an 80 ms Gaussian (`G`
/// alone: 97 %).
pub fn body_path(replay: &Replay, imu: &ImuData, sigma_s: f64) -> Replay {
    let (t, q) = replay.samples();
    let p_gt = replay.positions();
    let n = t.len();
    if n < 3 || imu.t.len() < 2 || sigma_s <= 0.0 {
        return replay.clone();
    }
    // The IMU's acceleration in the world frame, its mean (gravity and the
    // bias's average) taken out so that the double integral stays small.
    let mut a: Vec<Vector3<f64>> = (0..n).map(|i| q[i] * imu.at(t[i]).0).collect();
    let mean = a.iter().sum::<Vector3<f64>>() / n as f64;
    a.iter_mut().for_each(|x| *x -= mean);
    // Integrated from the ground truth's start, trapezoids between samples.
    let mut p_imu = vec![p_gt[0]; n];
    let mut v = (p_gt[1] - p_gt[0]) / (t[1] - t[0]).max(1e-9);
    for i in 1..n {
        let h = t[i] - t[i - 1];
        let a_mid = (a[i - 1] + a[i]) * 0.5;
        p_imu[i] = p_imu[i - 1] + v * h + a_mid * (0.5 * h * h);
        v += a_mid * h;
    }
    let e: Vec<[f64; 3]> = (0..n).map(|i| (p_gt[i] - p_imu[i]).into()).collect();
    let sigma = sigma_s / crate::io::validate::median_period(t);
    let g = gaussian(&e, sigma);
    let gg = gaussian(&g, sigma);
    let p = (0..n).map(|i| p_imu[i] + Vector3::from(std::array::from_fn(|c| 2.0 * g[i][c] - gg[i][c]))).collect();
    replay.with_positions(p)
}

/// `x` convolved with a Gaussian of `sigma` samples (truncated at 4σ);
/// beyond the ends `x` is continued by its point reflection (`2x₀ − x_k`),
/// so that a line stays a line up to the ends. `sigma ≤ 0.5` leaves it as
/// it is.
pub(crate) fn gaussian(x: &[[f64; 3]], sigma: f64) -> Vec<[f64; 3]> {
    if sigma <= 0.5 || x.len() < 2 {
        return x.to_vec();
    }
    let half = (4.0 * sigma).ceil() as isize;
    let w: Vec<f64> = (-half..=half).map(|k| (-0.5 * (k as f64 / sigma).powi(2)).exp()).collect();
    let total: f64 = w.iter().sum();
    let last = x.len() as isize - 1;
    let at = |j: isize, c: usize| -> f64 {
        if j < 0 {
            2.0 * x[0][c] - x[(-j).min(last) as usize][c]
        } else if j > last {
            2.0 * x[last as usize][c] - x[(2 * last - j).max(0) as usize][c]
        } else {
            x[j as usize][c]
        }
    };
    (0..x.len() as isize)
        .map(|i| {
            let mut s = [0.0; 3];
            for (k, wk) in (-half..=half).zip(&w) {
                for (c, sc) in s.iter_mut().enumerate() {
                    *sc += wk * at(i + k, c);
                }
            }
            s.map(|v| v / total)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::trajectory::Trajectory;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    /// A path swinging at 0.3 Hz and 0.7 Hz, sampled at 200 Hz, with an IMU
    /// that feels exactly its motion; `jitter` metres of white noise on the
    /// recorded positions.
    fn recording(jitter: f64) -> (Replay, ImuData) {
        let mut rng = rand::rngs::StdRng::seed_from_u64(4);
        let noise = Normal::new(0.0, jitter.max(1e-300)).unwrap();
        let (w1, w2) = (2.0 * std::f64::consts::PI * 0.3, 2.0 * std::f64::consts::PI * 0.7);
        let n = 12_000;
        let mut tr = Trajectory::default();
        let mut imu = ImuData::default();
        for i in 0..n {
            let t = i as f64 * 0.005;
            let p = [(w1 * t).sin(), 0.5 * (w2 * t).cos(), 0.2 * (w1 * t).cos()];
            let a =
                [-w1 * w1 * (w1 * t).sin(), -0.5 * w2 * w2 * (w2 * t).cos(), -0.2 * w1 * w1 * (w1 * t).cos() + 9.81];
            tr.t_ns.push((t * 1e9) as i64);
            tr.p.push(p.map(|x| x + if jitter > 0.0 { noise.sample(&mut rng) } else { 0.0 }));
            tr.q.push([1.0, 0.0, 0.0, 0.0]);
            imu.t.push(t);
            imu.acc.push(a.into());
            imu.gyro.push(nalgebra::Vector3::zeros());
        }
        (Replay::new(&tr, 0).unwrap(), imu)
    }

    #[test]
    fn a_ground_truth_the_imu_follows_is_not_smoothed() {
        let (replay, imu) = recording(0.0);
        let s = position_smoothing(&replay, &imu).unwrap();
        assert_eq!(s.sigma_s, 0.0, "{s:?}");
        assert!(s.note().is_none());
    }

    #[test]
    fn a_jittery_ground_truth_keeps_only_the_bands_the_imu_follows() {
        // 1 mm of white jitter: its acceleration (≈ √2·1e-3/h² per sample)
        // swamps the fine bands, the 0.3–0.7 Hz swings stay.
        let (replay, imu) = recording(1e-3);
        let s = position_smoothing(&replay, &imu).unwrap();
        assert!(s.sigma_s >= 0.04, "{s:?}");
        assert!(s.bands.last().unwrap().correlation > 0.9, "{s:?}");
        assert!(s.note().unwrap().contains("the IMU's own motion above"));
        // The body's path keeps the swings and loses most of the jitter.
        let body = body_path(&replay, &imu, s.sigma_s);
        let rms = |r: &Replay| {
            let errors: Vec<f64> = (50..550)
                .map(|k| {
                    let t = k as f64 * 0.1;
                    let w = 2.0 * std::f64::consts::PI;
                    let truth = nalgebra::Vector3::new(
                        (w * 0.3 * t).sin(),
                        0.5 * (w * 0.7 * t).cos(),
                        0.2 * (w * 0.3 * t).cos(),
                    );
                    (r.at(t).position - truth).norm_squared()
                })
                .collect();
            (errors.iter().sum::<f64>() / errors.len() as f64).sqrt()
        };
        let (before, after) = (rms(&replay), rms(&body));
        assert!(before > 1.5e-3 && after < 0.4 * before, "{before} → {after}");
    }

    #[test]
    fn gaussian_keeps_a_constant_and_a_line() {
        let x: Vec<[f64; 3]> = (0..100).map(|i| [1.0, i as f64, 0.0]).collect();
        let y = gaussian(&x, 3.0);
        for i in [0, 1, 50, 98, 99] {
            assert!((y[i][0] - 1.0).abs() < 1e-12 && (y[i][1] - i as f64).abs() < 1e-9, "{i}: {:?}", y[i]);
        }
    }
}
