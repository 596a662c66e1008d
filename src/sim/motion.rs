//! True motions with analytic derivatives: the hand tumble, a static log, the
//! 6-minute hand-held loop and an EuRoC-like flight.
//!
//! Frames: world `W` with z up and gravity `g_W = [0, 0, −g]`; body `B` is the
//! IMU (accelerometer) frame. `R` maps body to world. The angular rate is in
//! the body frame, so a gyro measures `ω_B` and an accelerometer measures the
//! specific force `R⁻¹ (a_W − g_W)`.

use super::SimError;
use nalgebra::{Matrix3, Rotation3, UnitQuaternion, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::f64::consts::PI;
use tumble_solvers::lie::{so3_exp, so3_right_jacobian};

/// The true state at one instant.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Kinematics {
    /// Orientation world ← body.
    pub rotation: Matrix3<f64>,
    /// Position in the world \[m\].
    pub position: Vector3<f64>,
    /// Velocity in the world \[m/s\].
    pub velocity: Vector3<f64>,
    /// Acceleration in the world \[m/s²\].
    pub acceleration: Vector3<f64>,
    /// Angular rate in the body frame \[rad/s\].
    pub omega: Vector3<f64>,
}

impl Kinematics {
    /// Specific force in the body frame \[m/s²\] under gravity magnitude `g`.
    pub fn specific_force(&self, g: f64) -> Vector3<f64> {
        self.rotation.transpose() * (self.acceleration + Vector3::new(0.0, 0.0, g))
    }
    /// Orientation as a unit quaternion.
    pub fn quaternion(&self) -> UnitQuaternion<f64> {
        UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(self.rotation))
    }
}

/// A motion: the true state at any time in `[0, duration]` \[s\].
pub trait Motion: Send + Sync {
    /// State at `t` \[s\].
    fn at(&self, t: f64) -> Kinematics;
    /// Length \[s\].
    fn duration(&self) -> f64;
}

/// Quintic minimum-jerk blend s(u) on u ∈ \[0, 1\] with its first two derivatives in u.
pub(super) fn min_jerk(u: f64) -> (f64, f64, f64) {
    let u = u.clamp(0.0, 1.0);
    let (u2, u3) = (u * u, u * u * u);
    (
        10.0 * u3 - 15.0 * u3 * u + 6.0 * u3 * u2,
        30.0 * u2 - 60.0 * u3 + 30.0 * u3 * u,
        60.0 * u - 180.0 * u2 + 120.0 * u3,
    )
}

/// `∫₀ᵘ s(v) dv` of the minimum-jerk blend `s` of [`min_jerk`]: `2.5u⁴ − 3u⁵ + u⁶` (u ∈ \[0, 1\]).
pub(super) fn min_jerk_integral(u: f64) -> f64 {
    u.powi(4) * (2.5 - 3.0 * u + u * u)
}

/// A motionless sensor in a fixed orientation.
#[derive(Debug, Clone)]
pub struct Static {
    /// Orientation world ← body.
    pub rotation: Matrix3<f64>,
    /// Length \[s\].
    pub duration: f64,
}

impl Motion for Static {
    fn at(&self, _t: f64) -> Kinematics {
        Kinematics {
            rotation: self.rotation,
            position: Vector3::zeros(),
            velocity: Vector3::zeros(),
            acceleration: Vector3::zeros(),
            omega: Vector3::zeros(),
        }
    }
    fn duration(&self) -> f64 {
        self.duration
    }
}

/// The paper's hand-tumble recording: a static start, then poses held still,
/// joined by smooth rotations with a little translation.
#[derive(Debug, Clone)]
pub struct Tumble {
    /// Segments in time order.
    segments: Vec<Segment>,
    duration: f64,
}

#[derive(Debug, Clone)]
struct Segment {
    start: f64,
    length: f64,
    r0: Matrix3<f64>,
    phi: Vector3<f64>,
    p0: Vector3<f64>,
    dp: Vector3<f64>,
}

/// Settings of the [`Tumble`] motion.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TumbleSettings {
    /// Initial static period \[s\].
    pub initial_static_s: f64,
    /// Number of held poses after it.
    pub poses: usize,
    /// Shortest and longest hold \[s\].
    pub hold_s: [f64; 2],
    /// Mean rotation rate of the hand between poses \[rad/s\].
    pub turn_rate: f64,
    /// How much the hand's rate varies from turn to turn: each turn's mean
    /// rate is `turn_rate` times a factor drawn log-uniformly in
    /// `[1/turn_rate_ratio, turn_rate_ratio]` (≥ 1; 1: every turn alike, so
    /// every turn peaks at the same rate). A hand turns some poses quickly and
    /// some slowly; only turns at different rates tell a rate nonlinearity's
    /// forms apart (`ω²` against `|ω|` integrate alike over turns of one rate).
    pub turn_rate_ratio: f64,
    /// Largest translation between poses \[m\].
    pub max_shift_m: f64,
    /// Hold only axis-aligned poses (each turn is a quarter turn about a body
    /// axis, as when an IMU in a box is laid on each of its faces in turn; the
    /// Ferraris et al. protocol). Such poses cannot separate the accelerometer's
    /// misalignments from its scales (see docs/calibration.md).
    pub axis_aligned: bool,
}

impl Default for TumbleSettings {
    fn default() -> Self {
        TumbleSettings {
            initial_static_s: 50.0,
            poses: 50,
            hold_s: [1.5, 3.0],
            turn_rate: 1.2,
            turn_rate_ratio: 1.0,
            max_shift_m: 0.05,
            axis_aligned: false,
        }
    }
}

impl Tumble {
    /// A random tumble: orientations drawn so consecutive poses differ by
    /// 40°–140° (every axis gets excited), deterministic for `seed`.
    pub fn new(s: &TumbleSettings, seed: u64) -> Tumble {
        let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x7475_6d62);
        // The rates draw from a stream of their own, so that a ratio of 1 leaves
        // every other draw (and the recordings of earlier versions) unchanged.
        let mut rates = ChaCha8Rng::seed_from_u64(seed ^ 0x7261_7465);
        let log_ratio = s.turn_rate_ratio.max(1.0).ln();
        let mut segments = Vec::new();
        let mut r = Matrix3::identity();
        let mut p = Vector3::zeros();
        let mut t = 0.0;
        let mut hold = |t: &mut f64, len: f64, r: Matrix3<f64>, p: Vector3<f64>| {
            segments.push(Segment {
                start: *t,
                length: len,
                r0: r,
                phi: Vector3::zeros(),
                p0: p,
                dp: Vector3::zeros(),
            });
            *t += len;
        };
        hold(&mut t, s.initial_static_s, r, p);
        let mut turns = Vec::new();
        for _ in 0..s.poses {
            let axis = loop {
                let v =
                    Vector3::new(rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0));
                let n: f64 = v.norm();
                if n > 0.1 && n <= 1.0 {
                    break v / n;
                }
            };
            let angle = rng.random_range(40f64.to_radians()..140f64.to_radians());
            let (phi, angle) = if s.axis_aligned {
                let axis = Vector3::ith(rng.random_range(0..3), 1.0);
                let sign = if rng.random_bool(0.5) { 1.0 } else { -1.0 };
                (axis * sign * PI / 2.0, PI / 2.0)
            } else {
                (axis * angle, angle)
            };
            let dp =
                Vector3::new(rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0))
                    * s.max_shift_m
                    / 3f64.sqrt();
            // Keep the device near its start.
            let dp = dp - p * 0.5;
            let rate = if log_ratio > 0.0 {
                s.turn_rate * rates.random_range(-log_ratio..log_ratio).exp()
            } else {
                s.turn_rate
            };
            let len = (angle / rate).max(0.8);
            turns.push((len, phi, dp, rng.random_range(s.hold_s[0]..=s.hold_s[1])));
        }
        let mut segs = segments;
        for (len, phi, dp, hold_len) in turns {
            segs.push(Segment { start: t, length: len, r0: r, phi, p0: p, dp });
            t += len;
            r *= so3_exp(&phi);
            p += dp;
            segs.push(Segment {
                start: t,
                length: hold_len,
                r0: r,
                phi: Vector3::zeros(),
                p0: p,
                dp: Vector3::zeros(),
            });
            t += hold_len;
        }
        Tumble { segments: segs, duration: t }
    }

    /// The held (static) intervals `[start, end]` \[s\], the initial one first.
    pub fn static_intervals(&self) -> Vec<[f64; 2]> {
        self.segments.iter().filter(|s| s.phi == Vector3::zeros()).map(|s| [s.start, s.start + s.length]).collect()
    }
}

impl Motion for Tumble {
    fn at(&self, t: f64) -> Kinematics {
        let i = self.segments.partition_point(|s| s.start <= t).saturating_sub(1);
        let s = &self.segments[i];
        let (b, db, ddb) = min_jerk((t - s.start) / s.length);
        let (db, ddb) = (db / s.length, ddb / (s.length * s.length));
        Kinematics {
            rotation: s.r0 * so3_exp(&(s.phi * b)),
            position: s.p0 + s.dp * b,
            velocity: s.dp * db,
            acceleration: s.dp * ddb,
            omega: s.phi * db,
        }
    }
    fn duration(&self) -> f64 {
        self.duration
    }
}

/// A smooth periodic 3-vector: `Σ_k a_k sin(2π n_k t / T + φ_k)` per axis,
/// with integer `n_k`, so value and derivatives return to their start at `T`.
#[derive(Debug, Clone)]
pub(super) struct Harmonics {
    period: f64,
    terms: Vec<(Vector3<f64>, f64, Vector3<f64>)>, // amplitude, harmonic number, phase
}

impl Harmonics {
    pub(super) fn random(rng: &mut ChaCha8Rng, period: f64, harmonics: &[f64], amplitude: Vector3<f64>) -> Harmonics {
        let terms = harmonics
            .iter()
            .map(|&n| {
                let a = amplitude.map(|x| x * rng.random_range(0.5..1.0)) / harmonics.len() as f64;
                let ph = Vector3::new(
                    rng.random_range(0.0..2.0 * PI),
                    rng.random_range(0.0..2.0 * PI),
                    rng.random_range(0.0..2.0 * PI),
                );
                (a, n, ph)
            })
            .collect();
        Harmonics { period, terms }
    }
    /// Value minus its value at 0, first and second derivative.
    pub(super) fn eval(&self, t: f64) -> (Vector3<f64>, Vector3<f64>, Vector3<f64>) {
        let mut v = Vector3::zeros();
        let mut d = Vector3::zeros();
        let mut dd = Vector3::zeros();
        for (a, n, ph) in &self.terms {
            let w = 2.0 * PI * n / self.period;
            for k in 0..3 {
                let arg = w * t + ph[k];
                v[k] += a[k] * (arg.sin() - ph[k].sin());
                d[k] += a[k] * w * arg.cos();
                dd[k] -= a[k] * w * w * arg.sin();
            }
        }
        (v, d, dd)
    }
}

/// Smooth 0→1 ramp over `[0, ramp]` and 1→0 over `[T − ramp, T]`, with derivatives.
pub(super) fn envelope(t: f64, total: f64, ramp: f64) -> (f64, f64, f64) {
    if t < ramp {
        let (s, ds, dds) = min_jerk(t / ramp);
        (s, ds / ramp, dds / (ramp * ramp))
    } else if t > total - ramp {
        let (s, ds, dds) = min_jerk((total - t) / ramp);
        (s, -ds / ramp, dds / (ramp * ramp))
    } else {
        (1.0, 0.0, 0.0)
    }
}

/// Periodic motion that starts and ends at rest at the same pose: position and
/// rotation vector are harmonics under a start/stop envelope. Used for the
/// hand-held loop and for the flight.
#[derive(Debug, Clone)]
pub struct Loop {
    duration: f64,
    rest_s: f64,
    ramp_s: f64,
    centre: Vector3<f64>,
    r0: Matrix3<f64>,
    pos: Harmonics,
    rot: Harmonics,
}

impl Loop {
    /// The paper's hand-held walk: 6 minutes inside a 1 m cube, back at the start.
    pub fn handheld(duration: f64, seed: u64) -> Loop {
        let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x77616c6b);
        let pos = Harmonics::random(&mut rng, duration - 10.0, &[17.0, 41.0, 83.0], Vector3::new(0.22, 0.22, 0.2));
        let rot = Harmonics::random(&mut rng, duration - 10.0, &[23.0, 53.0, 97.0], Vector3::new(0.35, 0.35, 0.8));
        Loop {
            duration,
            rest_s: 3.0,
            ramp_s: 2.0,
            centre: Vector3::new(0.0, 0.0, 1.2),
            r0: Matrix3::identity(),
            pos,
            rot,
        }
    }
    /// A rig waved in front of a calibration target, as for a camera–IMU
    /// calibration: within ±15 cm and about ±0.3 rad on every axis, at
    /// periods of 1–4 s (turn rates up to ≈ 1.5 rad/s), looking along world
    /// +x from around the origin; still for 3 s at both ends.
    pub fn target_wave(duration: f64, seed: u64) -> Loop {
        Loop::target_wave_with(duration, seed, Vector3::new(0.3, 0.3, 0.2), Vector3::new(0.8, 0.8, 0.8))
    }
    /// [`Loop::target_wave`] with other amplitudes of position \[m\] and
    /// rotation vector \[rad\] per body axis (each the sum of three harmonics'
    /// amplitudes, drawn between half and all of it): zeros leave an axis unexcited.
    pub fn target_wave_with(duration: f64, seed: u64, position: Vector3<f64>, rotation: Vector3<f64>) -> Loop {
        let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x72696700);
        let period = duration - 10.0;
        let cycles = |s: f64| [period / 3.7 * s, period / 2.3 * s, period / 1.3 * s].map(f64::round);
        let pos = Harmonics::random(&mut rng, period, &cycles(1.0), position);
        let rot = Harmonics::random(&mut rng, period, &cycles(1.1), rotation);
        Loop { duration, rest_s: 3.0, ramp_s: 2.0, centre: Vector3::zeros(), r0: Matrix3::identity(), pos, rot }
    }
    /// A ground robot's motion: [`Loop::target_wave_with`] within ±0.6 m in
    /// the horizontal plane, turning about the vertical only (up to about
    /// ±1 rad), at a fixed height. A camera–IMU translation along the
    /// vertical is unobservable from it.
    pub fn planar(duration: f64, seed: u64) -> Loop {
        Loop::target_wave_with(duration, seed, Vector3::new(0.6, 0.6, 0.0), Vector3::new(0.0, 0.0, 1.0))
    }
    /// An EuRoC-like flight: a few metres in a room, faster and with larger yaw.
    pub fn flight(duration: f64, seed: u64) -> Loop {
        let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x666c7900);
        let pos = Harmonics::random(&mut rng, duration - 10.0, &[3.0, 7.0, 11.0], Vector3::new(1.5, 1.5, 0.5));
        let rot = Harmonics::random(&mut rng, duration - 10.0, &[5.0, 13.0, 29.0], Vector3::new(0.2, 0.2, 1.0));
        Loop {
            duration,
            rest_s: 3.0,
            ramp_s: 2.0,
            centre: Vector3::new(0.0, 0.0, 1.5),
            r0: Matrix3::identity(),
            pos,
            rot,
        }
    }
}

impl Motion for Loop {
    fn at(&self, t: f64) -> Kinematics {
        let moving = self.duration - 2.0 * self.rest_s;
        let tm = (t - self.rest_s).clamp(0.0, moving);
        let active = t > self.rest_s && t < self.duration - self.rest_s;
        let (e, de, dde) = if active { envelope(tm, moving, self.ramp_s) } else { (0.0, 0.0, 0.0) };
        let (q, dq, ddq) = self.pos.eval(tm);
        let (th, dth, _) = self.rot.eval(tm);
        let theta = th * e;
        let dtheta = dth * e + th * de;
        Kinematics {
            rotation: self.r0 * so3_exp(&theta),
            position: self.centre + q * e,
            velocity: dq * e + q * de,
            acceleration: ddq * e + dq * (2.0 * de) + q * dde,
            omega: so3_right_jacobian(&theta) * dtheta,
        }
    }
    fn duration(&self) -> f64 {
        self.duration
    }
}

/// Length \[s\] of the slow-down before and of the speed-up after each pause of
/// a [`Paused`] motion (minimum-jerk in speed).
pub const PAUSE_RAMP_S: f64 = 1.0;

/// A motion that stops on the way: the inner motion's time runs at speed 1
/// except around each pause, where it slows to a standstill over
/// [`PAUSE_RAMP_S`], stands still for the pause's length and speeds up again
/// over [`PAUSE_RAMP_S`]. Each pause makes the motion `length + PAUSE_RAMP_S`
/// seconds longer. Used for stop-and-go walks.
#[derive(Debug, Clone)]
pub struct Paused<M> {
    inner: M,
    /// `(start of the slow-down, length of the standstill)` \[s\], in this
    /// motion's time, sorted and apart.
    pauses: Vec<(f64, f64)>,
}

impl<M: Motion> Paused<M> {
    /// Pause `inner` at `pauses`: `[start of the slow-down, standstill length]`
    /// \[s\] in the paused motion's time. Pauses must have positive lengths,
    /// follow one another after the previous one's speed-up and end before
    /// the paused motion does.
    pub fn new(inner: M, pauses: &[[f64; 2]]) -> Result<Paused<M>, SimError> {
        let mut end_of_last = 0.0;
        let total = inner.duration() + pauses.iter().map(|p| p[1] + PAUSE_RAMP_S).sum::<f64>();
        for (i, &[at, length]) in pauses.iter().enumerate() {
            if !(at.is_finite() && length.is_finite() && length > 0.0) {
                return Err((format!(
                    "pause {}: start {at} s and length {length} s must be finite, the length positive",
                    i + 1
                ))
                .into());
            }
            if at < end_of_last {
                return Err((format!(
                    "pause {} starts at {at} s, before {}'s speed-up ends at {end_of_last} s (pauses are sorted and {PAUSE_RAMP_S} s ramps apart)",
                    i + 1,
                    if i == 0 { "the motion".to_string() } else { format!("pause {i}") }
                )).into());
            }
            end_of_last = at + length + 2.0 * PAUSE_RAMP_S;
        }
        if end_of_last > total {
            return Err(format!("the last pause ends at {end_of_last} s, after the paused motion's {total} s").into());
        }
        Ok(Paused { inner, pauses: pauses.iter().map(|p| (p[0], p[1])).collect() })
    }

    /// The inner motion's time at `t` with its first and second derivatives.
    fn warp(&self, t: f64) -> (f64, f64, f64) {
        let r = PAUSE_RAMP_S;
        let mut lost = 0.0;
        for &(at, length) in &self.pauses {
            let u = t - at;
            if u <= 0.0 {
                break;
            }
            if u < r {
                let (s, ds, _) = min_jerk(u / r);
                return (t - lost - r * min_jerk_integral(u / r), 1.0 - s, -ds / r);
            }
            if u < r + length {
                return (at + 0.5 * r - lost, 0.0, 0.0);
            }
            if u < 2.0 * r + length {
                let w = (u - r - length) / r;
                let (s, ds, _) = min_jerk(w);
                return (at + 0.5 * r - lost + r * min_jerk_integral(w), s, ds / r);
            }
            lost += length + r;
        }
        (t - lost, 1.0, 0.0)
    }

    /// The standstills `[start, end]` \[s\].
    pub fn standstills(&self) -> Vec<[f64; 2]> {
        self.pauses.iter().map(|&(at, length)| [at + PAUSE_RAMP_S, at + PAUSE_RAMP_S + length]).collect()
    }
}

impl<M: Motion> Motion for Paused<M> {
    fn at(&self, t: f64) -> Kinematics {
        let (tau, speed, accel) = self.warp(t);
        let k = self.inner.at(tau);
        Kinematics {
            velocity: k.velocity * speed,
            acceleration: k.acceleration * (speed * speed) + k.velocity * accel,
            omega: k.omega * speed,
            ..k
        }
    }
    fn duration(&self) -> f64 {
        self.inner.duration() + self.pauses.iter().map(|p| p.1 + PAUSE_RAMP_S).sum::<f64>()
    }
}

/// Rotation vector from `a` to `b` in `a`'s frame (`Log(aᵀ b)`).
#[cfg(test)]
fn relative_rotation(a: &Matrix3<f64>, b: &Matrix3<f64>) -> Vector3<f64> {
    tumble_solvers::lie::so3_log(&(a.transpose() * b))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Velocity, acceleration and body rate agree with central differences of
    /// position, velocity and orientation.
    fn check_derivatives(m: &dyn Motion) {
        let h = 1e-5;
        let mut t = 0.37;
        while t < m.duration() - 0.01 {
            let (a, b, c) = (m.at(t - h), m.at(t), m.at(t + h));
            let v = (c.position - a.position) / (2.0 * h);
            let acc = (c.velocity - a.velocity) / (2.0 * h);
            let w = relative_rotation(&a.rotation, &c.rotation) / (2.0 * h);
            assert!((v - b.velocity).norm() < 1e-5 * (1.0 + v.norm()), "v at {t}: {v} vs {}", b.velocity);
            assert!((acc - b.acceleration).norm() < 1e-4 * (1.0 + acc.norm()), "a at {t}");
            assert!((w - b.omega).norm() < 1e-5 * (1.0 + w.norm()), "ω at {t}: {w} vs {}", b.omega);
            t += 0.713;
        }
    }

    #[test]
    fn analytic_derivatives_match_numeric() {
        check_derivatives(&Tumble::new(&TumbleSettings { initial_static_s: 2.0, poses: 10, ..Default::default() }, 3));
        check_derivatives(&Loop::handheld(60.0, 4));
        check_derivatives(&Loop::flight(60.0, 5));
        check_derivatives(&Paused::new(Loop::handheld(60.0, 4), &[[10.3, 3.0], [20.0, 0.5]]).unwrap());
    }

    /// Each turn's mean rate: its angle over its length (turns of at least
    /// 0.8 s are the ones no clamp shortened).
    fn turn_rates(t: &Tumble) -> Vec<f64> {
        t.segments
            .iter()
            .filter(|s| s.phi != Vector3::zeros() && s.length > 0.8)
            .map(|s| s.phi.norm() / s.length)
            .collect()
    }

    #[test]
    fn turns_differ_in_rate_by_the_ratio_asked_and_the_poses_stay() {
        let base = TumbleSettings { poses: 40, ..Default::default() };
        let one = Tumble::new(&base, 7);
        assert!(turn_rates(&one).iter().all(|r| (r - base.turn_rate).abs() < 1e-12));
        let varied = Tumble::new(&TumbleSettings { turn_rate_ratio: 2.0, ..base.clone() }, 7);
        let rates = turn_rates(&varied);
        assert!(rates.iter().all(|r| *r >= 0.5 * base.turn_rate - 1e-12 && *r <= 2.0 * base.turn_rate + 1e-12));
        let (lo, hi) = rates.iter().fold((f64::MAX, f64::MIN), |(a, b), &r| (a.min(r), b.max(r)));
        assert!(hi / lo > 2.0, "rates {lo:.2}–{hi:.2} rad/s");
        // The rates draw from their own stream: the poses and holds are the same.
        let turns = |t: &Tumble| t.segments.iter().map(|s| (s.phi, s.dp)).collect::<Vec<_>>();
        assert_eq!(turns(&one), turns(&varied));
        assert_eq!(one.static_intervals().len(), varied.static_intervals().len());
    }

    #[test]
    fn a_paused_motion_stands_still_and_then_goes_on_as_before() {
        let inner = Loop::handheld(60.0, 4);
        let m = Paused::new(inner.clone(), &[[10.0, 3.0], [30.0, 2.0]]).unwrap();
        assert_eq!(m.duration(), 60.0 + 4.0 + 3.0);
        assert_eq!(m.standstills(), vec![[11.0, 14.0], [31.0, 33.0]]);
        for t in [11.0, 12.5, 13.999, 31.0, 32.9] {
            let k = m.at(t);
            assert!(k.velocity.norm() == 0.0 && k.acceleration.norm() == 0.0 && k.omega.norm() == 0.0, "{t}");
        }
        // Before the first pause it is the inner motion; after a pause, the inner
        // motion shifted by the pause's length plus one ramp.
        for (t, shift) in [(5.0, 0.0), (20.0, 4.0), (50.0, 7.0), (67.0, 7.0)] {
            let (a, b) = (m.at(t), inner.at(t - shift));
            assert!((a.position - b.position).norm() < 1e-12 && (a.velocity - b.velocity).norm() < 1e-12, "{t}");
        }
        // Inner time runs on continuously through the ramps.
        let mut last = m.warp(0.0).0;
        for k in 1..=6700 {
            let tau = m.warp(k as f64 * 0.01).0;
            assert!(tau >= last && tau - last <= 0.01 + 1e-12, "{k}");
            last = tau;
        }
        assert!(Paused::new(Loop::handheld(60.0, 4), &[[10.0, 3.0], [14.0, 1.0]])
            .unwrap_err()
            .to_string()
            .contains("pause 2"));
        assert!(Paused::new(Loop::handheld(60.0, 4), &[[10.0, 0.0]]).is_err());
        assert!(Paused::new(Loop::handheld(60.0, 4), &[[60.0, 3.0]]).unwrap_err().to_string().contains("after"));
    }

    #[test]
    fn loop_returns_to_start_and_stays_in_its_volume() {
        let m = Loop::handheld(360.0, 1);
        let (a, b) = (m.at(0.0), m.at(360.0));
        assert!((a.position - b.position).norm() < 1e-12 && relative_rotation(&a.rotation, &b.rotation).norm() < 1e-12);
        let mut t = 0.0;
        while t < 360.0 {
            let k = m.at(t);
            let d = k.position - m.centre;
            assert!(d.x.abs() <= 0.5 && d.y.abs() <= 0.5 && d.z.abs() <= 0.5, "{t}: {d}");
            t += 0.05;
        }
    }

    #[test]
    fn tumble_has_its_holds() {
        let m = Tumble::new(&TumbleSettings::default(), 9);
        let holds = m.static_intervals();
        assert_eq!(holds.len(), 51);
        assert!(holds[0] == [0.0, 50.0]);
        for h in &holds[1..] {
            let k = m.at(0.5 * (h[0] + h[1]));
            assert!(k.omega.norm() == 0.0 && k.velocity.norm() == 0.0);
        }
    }
}

/// A recorded trajectory replayed as a motion (e.g. EuRoC's ground truth), so
/// that a simulated camera can observe a real path: position linear, rotation
/// slerp between samples; velocity, acceleration and rate by central
/// differences. Time 0 is the recording's `t0_ns`.
///
/// For poses only: with positions linear between samples the acceleration
/// is zero between them and an impulse at each, so never simulate an IMU
/// along it — [`super::SmoothedReplay`] is the recording as a smooth motion.
#[derive(Debug, Clone)]
pub struct Replay {
    t: Vec<f64>,
    p: Vec<Vector3<f64>>,
    q: Vec<UnitQuaternion<f64>>,
}

impl Replay {
    /// Replay `tr` with time measured from `t0_ns` \[ns\]; samples before `t0_ns` are dropped.
    /// Errors on fewer than two samples after `t0_ns`.
    pub fn new(tr: &crate::io::trajectory::Trajectory, t0_ns: i64) -> Result<Replay, SimError> {
        let (mut t, mut p, mut q) = (Vec::new(), Vec::new(), Vec::new());
        for i in 0..tr.len() {
            if tr.t_ns[i] < t0_ns {
                continue;
            }
            t.push((tr.t_ns[i] - t0_ns) as f64 * 1e-9);
            p.push(Vector3::from(tr.p[i]));
            let [w, x, y, z] = tr.q[i];
            q.push(UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(w, x, y, z)));
        }
        if t.len() < 2 {
            return Err("the trajectory has fewer than two samples after the start time".into());
        }
        Ok(Replay { t, p, q })
    }

    /// The positions replayed \[m\], in time order.
    pub fn positions(&self) -> &[Vector3<f64>] {
        &self.p
    }

    /// Time of the first sample \[s\].
    pub fn start(&self) -> f64 {
        self.t[0]
    }

    /// Sample times \[s\] and rotations (world ← body), in time order.
    pub fn samples(&self) -> (&[f64], &[UnitQuaternion<f64>]) {
        (&self.t, &self.q)
    }

    /// The same path with other positions \[m\] (one per sample).
    pub fn with_positions(&self, p: Vec<Vector3<f64>>) -> Replay {
        debug_assert_eq!(p.len(), self.p.len());
        Replay { p, ..self.clone() }
    }

    fn pose(&self, t: f64) -> (Vector3<f64>, UnitQuaternion<f64>) {
        let t = t.clamp(self.t[0], self.t[self.t.len() - 1]);
        let k = self.t.partition_point(|&s| s <= t).clamp(1, self.t.len() - 1);
        let w = ((t - self.t[k - 1]) / (self.t[k] - self.t[k - 1])).clamp(0.0, 1.0);
        (self.p[k - 1].lerp(&self.p[k], w), self.q[k - 1].slerp(&self.q[k], w))
    }
}

impl Motion for Replay {
    fn at(&self, t: f64) -> Kinematics {
        let h = 1e-3;
        let (p, q) = self.pose(t);
        let ((pm, qm), (pp, qp)) = (self.pose(t - h), self.pose(t + h));
        let velocity = (pp - pm) / (2.0 * h);
        let acceleration = (pp - 2.0 * p + pm) / (h * h);
        let omega = (qm.inverse() * qp).scaled_axis() / (2.0 * h);
        Kinematics { rotation: *q.to_rotation_matrix().matrix(), position: p, velocity, acceleration, omega }
    }
    fn duration(&self) -> f64 {
        self.t[self.t.len() - 1]
    }
}
