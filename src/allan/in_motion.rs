//! The IMU's error in motion against a ground truth: what a sensor shows
//! on its platform in use (rotors running, a vehicle's vibration), which a
//! static log on a desk does not.
//!
//! [`error_in_motion`] takes an IMU recording and a ground truth of the
//! body (IMU) frame's pose, and returns a recording of what the IMU reads
//! beyond the truth's motion: `gyro − ω_truth` and `accel − Rᵀ(a_truth + g ẑ)`,
//! less the truth's biases when it carries them (EuRoC's ground truth does),
//! over the span in which the platform moves. Its Allan analysis
//! ([`super::run_allan`], disturbances kept: in motion everything would be
//! one) gives the noise an estimator should assume on that platform
//! (`tumble allan --groundtruth`).
//!
//! Why not the datasheet's or the desk's figures: EuRoC's ADIS16448 shows in
//! flight a gyro error flat at 0.4–1.5·10⁻³ rad/s from 0.5 to 10 s, 5–18×
//! what its figures allow there (`docs/vio.md`, "The bias random walk in
//! flight"). An estimator given the desk's walks claims biases several times
//! more precise than they are.
//!
//! The truth's rate is the rotation between consecutive poses over their
//! interval, at its middle; its acceleration the velocity's difference (the
//! positions' second difference when it has no velocities), in the world
//! frame, whose z axis is up (gravity `−g ẑ`). Both are interpolated
//! linearly to the IMU's stamps. At short τ the result includes the truth's
//! own noise, differentiated (it falls as 1/τ, quantization noise to the
//! Allan fit); from about 0.5 s on it is the IMU's. The truth's orientation
//! error enters as an accelerometer error of `g·δθ` (0.1° gives 0.017 m/s²):
//! to an estimator whose camera agrees with that truth it is the same thing.

use crate::io::trajectory::Trajectory;
use crate::io::{ImuRecording, Stored};
use nalgebra::{Quaternion, UnitQuaternion, Vector3};

/// Speed above which the platform counts as moving \[m/s\].
pub const MOVING_SPEED_M_S: f64 = 0.2;

/// Margin kept from the first and last moment above [`MOVING_SPEED_M_S`]
/// \[s\]: take-off and landing, where the truth's derivatives are least sure.
pub const MOVING_MARGIN_S: f64 = 2.0;

/// The shortest span of motion analysed \[s\]: an Allan curve needs τ of
/// a few seconds with tens of terms each.
pub const MIN_SPAN_S: f64 = 20.0;

/// Where the error was taken, for the report.
#[derive(Clone, Debug, PartialEq)]
pub struct MotionSpan {
    /// Start and end on the IMU's clock (relative to its first sample) \[s\].
    pub from_s: f64,
    /// End \[s\].
    pub to_s: f64,
    /// Whether the truth's biases were subtracted.
    pub biases_removed: bool,
}

/// The IMU's error against the ground truth `truth` (world ← body poses,
/// world z up, on the IMU's clock) over the span in which the body moves
/// faster than [`MOVING_SPEED_M_S`], [`MOVING_MARGIN_S`] in from both ends:
/// a recording (SI units, the IMU's stamps within that span) of
/// `gyro − ω_truth − b_g` \[rad/s\] and `accel − Rᵀ(a_truth + g ẑ) − b_a`
/// \[m/s²\], the biases subtracted when `truth` carries them. `gravity`
/// \[m/s²\] is the local magnitude.
///
/// Errors name the recording and what is missing: raw counts, a truth that
/// does not overlap the IMU, a platform that never moves.
///
/// ```
/// use tumble::allan::in_motion::error_in_motion;
/// use tumble::io::{trajectory::Trajectory, ImuRecording};
/// // A body circling at 0.5 rad/s on a 1 m radius (0.5 m/s, yaw turning with it),
/// // and an ideal IMU on it.
/// let (n, dt, w) = (6000, 0.005, 0.5);
/// let pose = |t: f64| ([(w * t).cos(), (w * t).sin(), 0.0], w * t);
/// let mut truth = Trajectory::default();
/// for i in 0..n {
///     let t = i as f64 * dt;
///     let (p, yaw) = pose(t);
///     truth.t_ns.push((t * 1e9).round() as i64);
///     truth.p.push(p);
///     truth.q.push([(yaw / 2.0).cos(), 0.0, 0.0, (yaw / 2.0).sin()]);
/// }
/// let mut imu = ImuRecording::default();
/// for i in 0..n {
///     imu.t.push(i as f64 * dt);
///     imu.gyro.push([0.0, 0.0, w]);
///     // Centripetal w² r towards the centre is −x in the body frame; gravity up.
///     imu.accel.push([-w * w, 0.0, 9.81]);
/// }
/// let (err, span) = error_in_motion(&imu, &truth, 9.81).unwrap();
/// assert!(span.to_s - span.from_s > 20.0);
/// assert!(err.gyro.iter().all(|g| g.iter().all(|x| x.abs() < 1e-6)));
/// assert!(err.accel.iter().all(|a| a.iter().all(|x| x.abs() < 1e-3)));
/// ```
pub fn error_in_motion(
    imu: &ImuRecording,
    truth: &Trajectory,
    gravity: f64,
) -> Result<(ImuRecording, MotionSpan), super::AllanError> {
    let name = imu.source_name();
    if imu.gyro_units != Stored::Si || imu.accel_units != Stored::Si {
        return Err(super::AllanError::Invalid(format!(
            "{name}: the IMU is in raw counts; its error against a ground truth needs SI units"
        )));
    }
    let n = truth.len();
    if n < 3 || truth.q.len() != n || truth.p.len() != n {
        return Err(super::AllanError::Invalid(format!(
            "{name}: the ground truth has {n} poses; at least 3 are needed"
        )));
    }
    let t: Vec<f64> = truth.t_ns.iter().map(|s| (s - imu.t0_ns) as f64 * 1e-9).collect();
    if t.windows(2).any(|w| w[1] <= w[0]) {
        return Err(super::AllanError::Invalid(format!("{name}: the ground truth's stamps do not increase")));
    }
    let imu_end = imu.duration();
    if t[n - 1].min(imu_end) - t[0].max(0.0) < MIN_SPAN_S {
        return Err(super::AllanError::Invalid(format!(
            "{name}: the ground truth covers {:.1}–{:.1} s on the IMU's clock and the IMU 0–{imu_end:.1} s: they \
             share less than {MIN_SPAN_S} s (is the truth on another clock?)",
            t[0],
            t[n - 1]
        )));
    }
    let q = |i: usize| {
        let [w, x, y, z] = truth.q[i];
        UnitQuaternion::from_quaternion(Quaternion::new(w, x, y, z))
    };
    // Velocity at the truth's stamps: its own, else the positions' central differences.
    let v: Vec<Vector3<f64>> = match &truth.v {
        Some(v) if v.len() == n => v.iter().map(|x| Vector3::from(*x)).collect(),
        _ => (0..n)
            .map(|i| {
                let (a, b) = (i.saturating_sub(1), (i + 1).min(n - 1));
                (Vector3::from(truth.p[b]) - Vector3::from(truth.p[a])) / (t[b] - t[a])
            })
            .collect(),
    };
    let moving: Vec<f64> = t.iter().zip(&v).filter(|(_, v)| v.norm() > MOVING_SPEED_M_S).map(|(t, _)| *t).collect();
    let (Some(first), Some(last)) = (moving.first(), moving.last()) else {
        return Err(super::AllanError::Invalid(format!(
            "{name}: the ground truth never moves faster than {MOVING_SPEED_M_S} m/s"
        )));
    };
    // The derivatives live at the midpoints between truth stamps.
    let mid: Vec<f64> = t.windows(2).map(|w| 0.5 * (w[0] + w[1])).collect();
    let from = (first + MOVING_MARGIN_S).max(mid[0]).max(imu.t.first().copied().unwrap_or(f64::INFINITY));
    let to = (last - MOVING_MARGIN_S).min(mid[mid.len() - 1]).min(imu_end);
    if to - from < MIN_SPAN_S {
        return Err(super::AllanError::Invalid(format!(
            "{name}: the ground truth and the IMU share {:.1} s of motion (from {from:.1} to {to:.1} s on the IMU's \
             clock); at least {MIN_SPAN_S} s are needed",
            (to - from).max(0.0),
        )));
    }
    let g = Vector3::new(0.0, 0.0, gravity);
    let (rate, force): (Vec<Vector3<f64>>, Vec<Vector3<f64>>) = (0..n - 1)
        .map(|i| {
            let dt = t[i + 1] - t[i];
            // The relative rotation's own axis and angle: a truth whose
            // quaternions flip sign between samples turns no more for it.
            let turn = (q(i).inverse() * q(i + 1)).scaled_axis();
            let half = q(i) * UnitQuaternion::from_scaled_axis(0.5 * turn);
            let accel = (v[i + 1] - v[i]) / dt;
            (turn / dt, half.inverse() * (accel + g))
        })
        .unzip();
    let mut out = imu.slice_time(from, to);
    let shift = (out.t0_ns - imu.t0_ns) as f64 * 1e-9;
    let vectors = |x: &Vec<[f64; 3]>| x.iter().map(|b| Vector3::from(*b)).collect::<Vec<_>>();
    let biases = truth
        .bias_gyro
        .as_ref()
        .zip(truth.bias_accel.as_ref())
        .filter(|(g, a)| g.len() == n && a.len() == n)
        .map(|(g, a)| (vectors(g), vectors(a)));
    for k in 0..out.len() {
        let s = out.t[k] + shift;
        let (bg, ba) =
            biases.as_ref().map_or((Vector3::zeros(), Vector3::zeros()), |(g, a)| (interp(&t, g, s), interp(&t, a, s)));
        let e_g = Vector3::from(out.gyro[k]) - interp(&mid, &rate, s) - bg;
        let e_a = Vector3::from(out.accel[k]) - interp(&mid, &force, s) - ba;
        out.gyro[k] = e_g.into();
        out.accel[k] = e_a.into();
    }
    out.temperature = None;
    Ok((out, MotionSpan { from_s: from, to_s: to, biases_removed: biases.is_some() }))
}

/// `y` (stamped `ts`, increasing) at `t`, linear between samples, held at the ends.
fn interp(ts: &[f64], y: &[Vector3<f64>], t: f64) -> Vector3<f64> {
    let i = ts.partition_point(|x| *x < t);
    if i == 0 {
        return y[0];
    }
    if i >= ts.len() {
        return y[ts.len() - 1];
    }
    let a = (t - ts[i - 1]) / (ts[i] - ts[i - 1]);
    y[i - 1] * (1.0 - a) + y[i] * a
}

/// [`super::run_allan_with_progress`] on the IMU's [`error_in_motion`]
/// against `truth`: the noise the IMU shows on its platform in use, as
/// `tumble allan --groundtruth` writes it. Disturbances are kept (in motion
/// everything would be one: `opts.cut_disturbances` is not used); the report's
/// warnings say over which span and against what the error was taken.
pub fn run_allan_in_motion(
    imu: &ImuRecording,
    truth: &Trajectory,
    gravity: f64,
    opts: &super::AllanRunOptions,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<(super::AllanReport, MotionSpan), super::AllanError> {
    crate::error::OptionError::earth_gravity(gravity, "the accelerometer's error is taken against it")
        .map_err(|e| super::AllanError::Invalid(e.to_string()))?;
    let (error, span) = error_in_motion(imu, truth, gravity)?;
    let opts = super::AllanRunOptions { cut_disturbances: false, ..opts.clone() };
    let mut report = super::run_allan_with_progress(&error, &opts, progress)?;
    report.source = format!("{}, in motion against its ground truth", report.source);
    report.warnings.insert(
        0,
        format!(
            "in motion: the IMU's error against the ground truth's motion{} over {:.1}–{:.1} s of the recording \
             (where it moves faster than {MOVING_SPEED_M_S} m/s, {MOVING_MARGIN_S} s in from both ends); below \
             about 0.5 s the curves include the ground truth's own noise, differentiated",
            if span.biases_removed { " and biases" } else { "" },
            span.from_s,
            span.to_s
        ),
    );
    Ok((report, span))
}

/// The noise the IMU shows on its platform in use, as the VIO takes it
/// (`tumble vio --noise` of `tumble allan --groundtruth`'s imu.yaml, each
/// axis's own figures): [`run_allan_in_motion`] with the default options,
/// reduced to its Kalibr coefficients. `gravity` \[m/s²\].
pub fn noise_in_motion(
    imu: &ImuRecording,
    truth: &Trajectory,
    gravity: f64,
) -> Result<(crate::io::ImuNoise, MotionSpan), super::AllanError> {
    let (report, span) = run_allan_in_motion(imu, truth, gravity, &Default::default(), &|_, _| {})?;
    let noise = report.kalibr.as_ref().map(|k| k.imu_noise()).ok_or_else(|| {
        super::AllanError::Invalid(format!(
            "no noise identified in motion over {:.1}–{:.1} s: {}",
            span.from_s,
            span.to_s,
            report.warnings.join("; ")
        ))
    })?;
    Ok((noise, span))
}
