//! A recorded trajectory as a smooth motion an IMU can be simulated along.
//!
//! A motion capture's positions hold accelerations no IMU on the body feels
//! (the tracker's own noise, EuRoC's Leica above 2 Hz), and a path
//! interpolated linearly between samples has no acceleration between them
//! and an impulse at each. [`SmoothedReplay`] averages the recording with a
//! Gaussian in time, so its velocity, acceleration and rate are smooth: an
//! IMU simulated along it ([`super::simulate_imu`]) measures exactly the
//! motion its positions and rotations describe. The recording's flight,
//! without its fastest shakes.

use super::motion::{Kinematics, Motion};
use super::{simulate_imu, ImuModel, SimError};
use crate::io::trajectory::Trajectory;
use crate::io::ImuRecording;
use nalgebra::{Quaternion, UnitQuaternion, Vector3};

/// Samples within this many σ of an instant enter its mean. A sample's
/// weight there is e⁻⁴⁰, below a double's rounding, so no step appears
/// where samples enter and leave the mean: cut at 4 σ (e⁻⁸), those steps
/// became spikes of acceleration that made a VIO's windows 3–5 % short.
const REACH_SIGMAS: f64 = 9.0;

/// Step of the central differences that give velocity, acceleration and rate \[s\].
const DIFFERENCE_STEP_S: f64 = 1e-3;

/// A trajectory averaged by a Gaussian of width `sigma_s` in time: positions
/// averaged, rotations averaged as quaternions (on one hemisphere) and
/// normalized. Time 0 is [`SmoothedReplay::t0_ns`], the first instant whose
/// mean has the Gaussian's whole reach within the recording.
///
/// ```
/// use tumble::io::trajectory::Trajectory;
/// use tumble::sim::{Motion, SmoothedReplay};
/// // 10 s at 100 Hz along x at 1 m/s, rotating about z at 0.1 rad/s.
/// let mut tr = Trajectory::default();
/// for i in 0..1000 {
///     let t = i as f64 * 0.01;
///     tr.t_ns.push((t * 1e9) as i64);
///     tr.p.push([t, 0.0, 0.0]);
///     tr.q.push([(0.05 * t).cos(), 0.0, 0.0, (0.05 * t).sin()]);
/// }
/// let m = SmoothedReplay::new(&tr, 0.05).unwrap();
/// let k = m.at(2.0);
/// assert!((k.velocity.x - 1.0).abs() < 1e-6 && k.acceleration.norm() < 1e-4);
/// assert!((k.omega.z - 0.1).abs() < 1e-6);
/// ```
#[derive(Debug, Clone)]
pub struct SmoothedReplay {
    t: Vec<f64>,
    p: Vec<Vector3<f64>>,
    q: Vec<Quaternion<f64>>,
    sigma_s: f64,
    /// The recording's time of this motion's time 0 \[ns\].
    pub t0_ns: i64,
    duration: f64,
}

impl SmoothedReplay {
    /// `tr` smoothed by a Gaussian of `sigma_s` \[s\]. Errors: a width that is
    /// not positive; positions or rotations not one per stamp; stamps out
    /// of order, or further apart than the width (the mean there would rest
    /// on a sample or two, or on none); a recording shorter than 1 s beyond
    /// the Gaussian's reach at both ends.
    pub fn new(tr: &Trajectory, sigma_s: f64) -> Result<SmoothedReplay, SimError> {
        if !(sigma_s.is_finite() && sigma_s > 0.0) {
            return Err(format!("smoothing width must be positive, found {sigma_s} s").into());
        }
        let first = *tr.t_ns.first().ok_or("the trajectory is empty")?;
        if tr.p.len() != tr.t_ns.len() || tr.q.len() != tr.t_ns.len() {
            return Err(format!(
                "the trajectory has {} stamps, {} positions and {} rotations",
                tr.t_ns.len(),
                tr.p.len(),
                tr.q.len()
            )
            .into());
        }
        let t: Vec<f64> = tr.t_ns.iter().map(|&t| (t - first) as f64 * 1e-9).collect();
        if let Some(k) = t.windows(2).position(|w| !(w[1] > w[0] && w[1] - w[0] <= sigma_s)) {
            return Err(format!(
                "the trajectory's samples {k} and {} are {:.3} s apart at {:.3} s: they must be in order and at most \
                 the smoothing width ({sigma_s} s) apart",
                k + 1,
                t[k + 1] - t[k],
                t[k]
            )
            .into());
        }
        let reach = REACH_SIGMAS * sigma_s;
        let duration = t[t.len() - 1] - 2.0 * reach;
        if duration < 1.0 {
            return Err(format!(
                "the trajectory spans {:.2} s: at least 1 s beyond {reach:.2} s at each end is needed to smooth it",
                t[t.len() - 1]
            )
            .into());
        }
        Ok(SmoothedReplay {
            t,
            p: tr.p.iter().map(|p| Vector3::from(*p)).collect(),
            q: tr.q.iter().map(|q| Quaternion::new(q[0], q[1], q[2], q[3])).collect(),
            sigma_s,
            t0_ns: first + (reach * 1e9).round() as i64,
            duration,
        })
    }

    /// An IMU of `model` simulated along this motion under gravity `g`
    /// \[m/s²\] (`seed` draws its noise): the recording, stamped from
    /// [`SmoothedReplay::t0_ns`], and the truth at its stamps (position,
    /// rotation, velocity and the true biases) — a dataset's IMU and ground
    /// truth for the same path.
    pub fn simulate(&self, model: &ImuModel, g: f64, seed: u64) -> (ImuRecording, Trajectory) {
        let sim = simulate_imu(self, model, g, seed, 1);
        let mut imu = sim.to_recording();
        imu.t0_ns = self.t0_ns;
        let mut truth = Trajectory::default();
        let mut v = Vec::with_capacity(sim.t.len());
        for (i, &t) in sim.t.iter().enumerate() {
            let k = self.at(t);
            let q = k.quaternion();
            truth.t_ns.push(imu.t_ns(i));
            truth.p.push(k.position.into());
            truth.q.push([q.w, q.i, q.j, q.k]);
            v.push(k.velocity.into());
        }
        (truth.v, truth.bias_gyro, truth.bias_accel) = (Some(v), Some(sim.bias_gyro), Some(sim.bias_accel));
        (imu, truth)
    }

    /// Position \[m\] and rotation world ← body at recording time `t` \[s\] from its first sample.
    fn pose(&self, t: f64) -> (Vector3<f64>, UnitQuaternion<f64>) {
        let reach = REACH_SIGMAS * self.sigma_s;
        let lo = self.t.partition_point(|&s| s < t - reach);
        let hi = self.t.partition_point(|&s| s <= t + reach);
        let near = self.q[self.t.partition_point(|&s| s <= t).clamp(1, self.t.len() - 1)];
        let (mut sum, mut p, mut q) = (0.0, Vector3::zeros(), Quaternion::new(0.0, 0.0, 0.0, 0.0));
        for i in lo..hi {
            let d = (self.t[i] - t) / self.sigma_s;
            let w = (-0.5 * d * d).exp();
            sum += w;
            p += self.p[i] * w;
            q += if self.q[i].dot(&near) < 0.0 { -self.q[i] } else { self.q[i] } * w;
        }
        (p / sum, UnitQuaternion::from_quaternion(q / sum))
    }
}

impl Motion for SmoothedReplay {
    fn at(&self, t: f64) -> Kinematics {
        let (h, t) = (DIFFERENCE_STEP_S, t + REACH_SIGMAS * self.sigma_s);
        let (p, q) = self.pose(t);
        let ((pm, qm), (pp, qp)) = (self.pose(t - h), self.pose(t + h));
        Kinematics {
            rotation: *q.to_rotation_matrix().matrix(),
            position: p,
            velocity: (pp - pm) / (2.0 * h),
            acceleration: (pp - 2.0 * p + pm) / (h * h),
            omega: (qm.inverse() * qp).scaled_axis() / (2.0 * h),
        }
    }
    fn duration(&self) -> f64 {
        self.duration
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A recording of `seconds` at 200 Hz along a circle of radius 2 m at 1 rad/s.
    fn circle(seconds: f64) -> Trajectory {
        let mut tr = Trajectory::default();
        for i in 0..(seconds * 200.0) as usize {
            let t = i as f64 / 200.0;
            tr.t_ns.push(1_000_000_000 + (t * 1e9) as i64);
            tr.p.push([2.0 * t.cos(), 2.0 * t.sin(), 1.0]);
            tr.q.push([(0.5 * t).cos(), 0.0, 0.0, (0.5 * t).sin()]);
        }
        tr
    }

    #[test]
    fn a_circle_keeps_its_speed_and_its_centripetal_acceleration() {
        let m = SmoothedReplay::new(&circle(10.0), 0.05).unwrap();
        assert_eq!(m.t0_ns, 1_000_000_000 + 450_000_000);
        // A Gaussian of σ shrinks a circle at ω by e^{−ω²σ²/2}.
        let shrink = (-0.5f64 * 0.05 * 0.05).exp();
        for t in [0.0, 1.7, 5.0, m.duration()] {
            let k = m.at(t);
            assert!((k.velocity.norm() - 2.0 * shrink).abs() < 1e-6, "{}", k.velocity.norm());
            assert!((k.acceleration.norm() - 2.0 * shrink).abs() < 1e-4, "{}", k.acceleration.norm());
            assert!((k.omega - Vector3::z()).norm() < 1e-6, "{}", k.omega);
        }
    }

    #[test]
    fn a_noiseless_imu_along_it_integrates_back_to_its_path() {
        let m = SmoothedReplay::new(&circle(10.0), 0.05).unwrap();
        let silent = crate::io::ImuNoise {
            accelerometer_noise_density: 0.0,
            accelerometer_random_walk: 0.0,
            gyroscope_noise_density: 0.0,
            gyroscope_random_walk: 0.0,
            axes: None,
        };
        let mut model = silent.noise_only_model();
        model.effects.bias = false;
        let (imu, truth) = m.simulate(&model, 9.81, 1);
        assert_eq!(imu.t_ns(0), m.t0_ns);
        assert_eq!(truth.t_ns.len(), imu.len());
        // The specific force of the first sample is the truth's: the
        // centripetal 2e^{−σ²/2} m/s² towards the centre, and gravity.
        let q = truth.q[0];
        let r = UnitQuaternion::from_quaternion(Quaternion::new(q[0], q[1], q[2], q[3]));
        let world = r * Vector3::from(imu.accel[0]) - Vector3::new(0.0, 0.0, 9.81);
        let centre = -Vector3::new(truth.p[0][0], truth.p[0][1], 0.0).normalize();
        assert!((world - centre * 2.0 * (-0.5f64 * 0.05 * 0.05).exp()).norm() < 1e-3, "{world}");
        assert!((Vector3::from(imu.gyro[0]) - Vector3::z()).norm() < 1e-6);
    }

    #[test]
    fn too_short_or_unsmoothed_is_refused() {
        assert!(SmoothedReplay::new(&circle(1.5), 0.05).unwrap_err().to_string().contains("spans"));
        assert!(SmoothedReplay::new(&circle(10.0), 0.0).unwrap_err().to_string().contains("positive"));
        assert!(SmoothedReplay::new(&Trajectory::default(), 0.05).is_err());
        let mut gap = circle(10.0);
        gap.t_ns.drain(400..500);
        gap.p.drain(400..500);
        gap.q.drain(400..500);
        let e = SmoothedReplay::new(&gap, 0.05).unwrap_err().to_string();
        assert!(e.contains("samples 399 and 400 are 0.505 s apart at 1.995 s"), "{e}");
        let mut short = circle(10.0);
        short.q.pop();
        assert!(SmoothedReplay::new(&short, 0.05).unwrap_err().to_string().contains("1999 rotations"));
        let mut unordered = circle(10.0);
        unordered.t_ns.swap(10, 11);
        assert!(SmoothedReplay::new(&unordered, 0.05).unwrap_err().to_string().contains("in order"));
    }
}
