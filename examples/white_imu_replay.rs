//! A recording's path flown again by an IMU that has exactly the noise the
//! estimator is told: white noise and a bias random walk per axis from an
//! `imu.yaml`, nothing else (no scale, misalignment, vibration or
//! quantization). It tells the estimator's own inconsistency from the real
//! sensor's unmodelled errors: run `tumble vio` on the real recording and on
//! this one, with the same noise file and a simulated camera, and compare
//! the windows' normalized length errors.
//!
//! The path is the recording's ground truth smoothed by a Gaussian of 50 ms
//! (the tracker's positions hold accelerations the IMU does not feel), so
//! it is the recording's flight without its fastest shakes. Writes
//! `OUT/mav0/imu0/data.csv` and `OUT/mav0/state_groundtruth_estimate0/data.csv`
//! (the smoothed path at the IMU's stamps, with the true velocity and biases).
//!
//! ```sh
//! cargo run --release --example white_imu_replay -- $TUMBLE_DATA/euroc/full_imu/MH_03_medium white_mh03 v2_01_flight/imu.yaml [SEED]
//! cargo run --release -- vio white_mh03 --simulate-camera --mono --noise v2_01_flight/imu.yaml --out vio_white
//! ```

use nalgebra::{Quaternion, UnitQuaternion, Vector3};
use std::io::Write;
use std::path::Path;
use tumble::io::trajectory::{write_asl_groundtruth, Trajectory};
use tumble::sim::{simulate_imu, Effects, ImuModel, Kinematics, Motion};

/// Width of the Gaussian the ground truth is smoothed with \[s\].
const SMOOTHING_S: f64 = 0.05;

/// Samples within this many [`SMOOTHING_S`] of an instant enter its mean: the
/// weight at the edge (e⁻⁴⁰) is far below a double's rounding, so the path
/// has no steps where samples enter and leave.
const REACH: f64 = 9.0;

/// Gravity the IMU is simulated under \[m/s²\] (the estimator's default).
const GRAVITY: f64 = 9.81;

/// The ground truth smoothed by a Gaussian in time: positions averaged,
/// rotations averaged as quaternions (on one hemisphere) and normalized.
struct Smoothed {
    t: Vec<f64>,
    p: Vec<Vector3<f64>>,
    q: Vec<Quaternion<f64>>,
    end: f64,
}

impl Smoothed {
    fn new(gt: &Trajectory) -> Result<Smoothed, String> {
        let t0 = *gt.t_ns.first().ok_or("the ground truth is empty")?;
        let t: Vec<f64> = gt.t_ns.iter().map(|&t| (t - t0) as f64 * 1e-9).collect();
        let end = t[t.len() - 1] - REACH * SMOOTHING_S;
        if end <= 1.0 {
            return Err(format!("the ground truth spans {:.2} s: too short to smooth", t[t.len() - 1]));
        }
        Ok(Smoothed {
            t,
            p: gt.p.iter().map(|p| Vector3::from(*p)).collect(),
            q: gt.q.iter().map(|q| Quaternion::new(q[0], q[1], q[2], q[3])).collect(),
            end,
        })
    }

    /// Position \[m\] and rotation world ← body at `t` \[s\].
    fn pose(&self, t: f64) -> (Vector3<f64>, UnitQuaternion<f64>) {
        let lo = self.t.partition_point(|&s| s < t - REACH * SMOOTHING_S);
        let hi = self.t.partition_point(|&s| s <= t + REACH * SMOOTHING_S);
        let near = self.q[self.t.partition_point(|&s| s <= t).clamp(1, self.t.len() - 1)];
        let (mut sum, mut p, mut q) = (0.0, Vector3::zeros(), Quaternion::new(0.0, 0.0, 0.0, 0.0));
        for i in lo..hi {
            let d = (self.t[i] - t) / SMOOTHING_S;
            let w = (-0.5 * d * d).exp();
            sum += w;
            p += self.p[i] * w;
            q += if self.q[i].dot(&near) < 0.0 { -self.q[i] } else { self.q[i] } * w;
        }
        (p / sum, UnitQuaternion::from_quaternion(q / sum))
    }
}

impl Motion for Smoothed {
    fn at(&self, t: f64) -> Kinematics {
        let h = 1e-3;
        let (p, q) = self.pose(t + REACH * SMOOTHING_S);
        let ((pm, qm), (pp, qp)) = (self.pose(t + REACH * SMOOTHING_S - h), self.pose(t + REACH * SMOOTHING_S + h));
        Kinematics {
            rotation: *q.to_rotation_matrix().matrix(),
            position: p,
            velocity: (pp - pm) / (2.0 * h),
            acceleration: (pp - 2.0 * p + pm) / (h * h),
            omega: (qm.inverse() * qp).scaled_axis() / (2.0 * h),
        }
    }
    fn duration(&self) -> f64 {
        self.end - REACH * SMOOTHING_S
    }
}

/// An IMU with the noise of `noise` and nothing else, sampled at 200 Hz.
fn white_imu(noise: &tumble::io::ImuNoise) -> ImuModel {
    // The per-axis figures where the file gives them, else the worst axis' on all three.
    let axes = noise.axes.unwrap_or(tumble::io::ImuNoiseAxes {
        accelerometer_noise_density: [noise.accelerometer_noise_density; 3],
        accelerometer_random_walk: [noise.accelerometer_random_walk; 3],
        gyroscope_noise_density: [noise.gyroscope_noise_density; 3],
        gyroscope_random_walk: [noise.gyroscope_random_walk; 3],
    });
    let mut model = ImuModel::bmi055();
    model.gyro.noise_density = axes.gyroscope_noise_density;
    model.gyro.random_walk = axes.gyroscope_random_walk;
    model.gyro.bias = [0.002, -0.001, 0.001];
    model.accel.noise_density = axes.accelerometer_noise_density;
    model.accel.random_walk = axes.accelerometer_random_walk;
    model.accel.bias = [0.05, -0.03, 0.04];
    model.effects = Effects {
        misalignment: false,
        scale: false,
        nonlinearity: false,
        bias: true,
        random_walk: true,
        bias_instability: false,
        white_noise: true,
        temperature: false,
        g_sensitivity: false,
        quantization: false,
        saturation: false,
        bias_drift: false,
        jitter: false,
    };
    model
}

fn run(src: &Path, out: &Path, noise: &Path, seed: u64) -> Result<(), String> {
    let ds = tumble::io::asl::read_asl(src, &Default::default()).map_err(|e| e.to_string())?;
    let gt = ds.groundtruth.ok_or_else(|| format!("{}: no ground truth", src.display()))?;
    let noise = tumble::io::ImuNoise::read(noise).map_err(|e| e.to_string())?;
    let path = Smoothed::new(&gt)?;
    let sim = simulate_imu(&path, &white_imu(&noise), GRAVITY, seed, 1);
    let t0_ns = gt.t_ns[0] + (REACH * SMOOTHING_S * 1e9) as i64;
    let stamp = |t: f64| t0_ns + (t * 1e9).round() as i64;
    let mav = out.join("mav0");
    let io = |e: std::io::Error| format!("{}: {e}", out.display());
    std::fs::create_dir_all(mav.join("imu0")).map_err(io)?;
    std::fs::create_dir_all(mav.join("state_groundtruth_estimate0")).map_err(io)?;
    let mut f = std::io::BufWriter::new(std::fs::File::create(mav.join("imu0/data.csv")).map_err(io)?);
    writeln!(f, "#timestamp [ns],w_RS_S_x [rad s^-1],w_RS_S_y [rad s^-1],w_RS_S_z [rad s^-1],a_RS_S_x [m s^-2],a_RS_S_y [m s^-2],a_RS_S_z [m s^-2]").map_err(io)?;
    for (i, &t) in sim.t.iter().enumerate() {
        let (g, a) = (sim.gyro[i], sim.accel[i]);
        writeln!(f, "{},{},{},{},{},{},{}", stamp(t), g[0], g[1], g[2], a[0], a[1], a[2]).map_err(io)?;
    }
    f.flush().map_err(io)?;
    let mut truth = Trajectory::default();
    let (mut v, mut bg, mut ba) = (Vec::new(), Vec::new(), Vec::new());
    for (i, &t) in sim.t.iter().enumerate() {
        let k = path.at(t);
        let q = k.quaternion();
        truth.t_ns.push(stamp(t));
        truth.p.push(k.position.into());
        truth.q.push([q.w, q.i, q.j, q.k]);
        v.push(k.velocity.into());
        bg.push(sim.bias_gyro[i]);
        ba.push(sim.bias_accel[i]);
    }
    (truth.v, truth.bias_gyro, truth.bias_accel) = (Some(v), Some(bg), Some(ba));
    write_asl_groundtruth(&mav.join("state_groundtruth_estimate0/data.csv"), &truth).map_err(|e| e.to_string())?;
    println!(
        "{}: {} IMU samples over {:.1} s along {}'s smoothed path",
        out.display(),
        sim.t.len(),
        path.duration(),
        src.display()
    );
    Ok(())
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let usage = "usage: white_imu_replay RECORDING OUT NOISE_YAML [SEED]";
    if !(3..=4).contains(&args.len()) {
        eprintln!("{usage}");
        std::process::exit(2);
    }
    let seed = match args.get(3).map(|s| s.parse::<u64>()) {
        None => 1,
        Some(Ok(s)) => s,
        Some(Err(_)) => {
            eprintln!("SEED must be a whole number, found {:?}\n{usage}", args[3]);
            std::process::exit(2);
        }
    };
    if let Err(e) = run(Path::new(&args[0]), Path::new(&args[1]), Path::new(&args[2]), seed) {
        eprintln!("error: {e}");
        std::process::exit(1);
    }
}
