//! Writes a [`Simulation`] as an ASL dataset folder, the layout every
//! pipeline reads real recordings in, plus the truth:
//!
//! ```text
//! OUT/mav0/imu0/data.csv                       t[ns], ω [rad/s], a [m/s²] (+ temperature [degC])
//! OUT/mav0/imu0/sensor.yaml                    rate and Kalibr noise figures of the model
//! OUT/mav0/cam0/{data.csv,tracks.csv,sensor.yaml}   when a camera was simulated
//! OUT/mav0/state_groundtruth_estimate0/data.csv     p, q, v, b_w, b_a
//! OUT/truth.json                               every parameter, the seed, static intervals
//! OUT/truth/{landmarks.csv,observations.csv}   landmark positions, which landmark each observation sees and where it projects
//! ```

use super::imu::SimulatedImu;
use super::SimError;
use super::{SimulatedTracks, Simulation};
use crate::error::InputError;
use crate::io::trajectory::{write_asl_groundtruth, Trajectory};
use nalgebra::Isometry3;
use rayon::prelude::*;
use std::io::Write;
use std::path::{Path, PathBuf};

fn werr(path: &Path, e: std::io::Error) -> InputError {
    InputError::file(path, format!("cannot write: {e}"))
}

fn create(path: &Path) -> Result<std::io::BufWriter<std::fs::File>, InputError> {
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir).map_err(|e| werr(dir, e))?;
    }
    let f = std::fs::File::create(path).map_err(|e| werr(path, e))?;
    Ok(std::io::BufWriter::with_capacity(1 << 20, f))
}

fn push_f64(out: &mut Vec<u8>, x: f64) {
    out.push(b',');
    out.extend_from_slice(ryu::Buffer::new().format(x).as_bytes());
}

/// Format samples `range` of the IMU CSV, in parallel pieces, in order.
fn format_imu_rows(imu: &SimulatedImu, t0_ns: i64, rate_hz: f64, range: std::ops::Range<usize>) -> Vec<Vec<u8>> {
    const PIECE: usize = 1 << 13;
    let dt_ns = 1e9 / rate_hz;
    let starts: Vec<usize> = range.clone().step_by(PIECE).collect();
    starts
        .into_par_iter()
        .map(|s| {
            let mut out = Vec::with_capacity(PIECE * 100);
            let mut ib = itoa::Buffer::new();
            for i in s..(s + PIECE).min(range.end) {
                out.extend_from_slice(ib.format(t0_ns + (i as f64 * dt_ns).round() as i64).as_bytes());
                for &x in imu.gyro[i].iter().chain(imu.accel[i].iter()) {
                    // 1e-9 resolution: far below any IMU's LSB, and half the bytes
                    // (+ 0.0 turns −0 into 0).
                    push_f64(&mut out, (x * 1e9).round() / 1e9 + 0.0);
                }
                if let Some(tc) = &imu.temperature {
                    push_f64(&mut out, (tc[i] * 1e3).round() / 1e3 + 0.0);
                }
                out.push(b'\n');
            }
            out
        })
        .collect()
}

/// Simulate and write at once: each chunk of IMU samples is formatted as soon
/// as it is final and written by a second thread while the next chunk is
/// simulated. Then the rest of the folder as [`write_asl`] does.
///
/// Errors: a configuration or motion the simulator refuses reads
/// `simulation: …`; a file that cannot be written is named with its path.
pub fn simulate_and_write(
    scenario: super::Scenario,
    config: &super::SimConfig,
    seed: u64,
    out: &Path,
) -> Result<Simulation, SimError> {
    simulate_and_write_with(scenario, config, seed, out, &mut |_, _| {})
}

/// [`simulate_and_write`], calling `progress(done, total)` after each
/// rendered frame when the config asks for images (`SimConfig::images`).
pub fn simulate_and_write_with(
    scenario: super::Scenario,
    config: &super::SimConfig,
    seed: u64,
    out: &Path,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<Simulation, SimError> {
    let mut done = None;
    crate::io::staging::write_staged(out, |stage| -> Result<Vec<PathBuf>, SimError> {
        done = Some(simulate_and_write_into(scenario, config, seed, stage, progress)?);
        crate::io::staging::files_under(stage).map_err(|e| SimError::from(format!("{}: {e}", stage.display())))
    })?;
    done.ok_or_else(|| SimError::from("the simulation wrote nothing"))
}

/// [`simulate_and_write`] into `out` directly (a staging folder).
fn simulate_and_write_into(
    scenario: super::Scenario,
    config: &super::SimConfig,
    seed: u64,
    out: &Path,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<Simulation, SimError> {
    let refused = |m: SimError| format!("simulation: {m}");
    config.check().map_err(refused)?;
    if config.images.is_some() {
        super::images::check_renderable(scenario, config)?;
    }
    let csv = out.join("mav0").join("imu0").join("data.csv");
    let mut w = create(&csv).map_err(|e| e.to_string())?;
    let (tx, rx) = std::sync::mpsc::sync_channel::<Vec<Vec<u8>>>(2);
    let sim = std::thread::scope(|scope| -> Result<Simulation, String> {
        let writer = scope.spawn(move || -> std::io::Result<()> {
            for pieces in rx {
                for p in pieces {
                    w.write_all(&p)?;
                }
            }
            w.flush()
        });
        let (t0, rate) = (config.t0_ns, config.imu.rate_hz);
        let mut header_sent = false;
        let mut send = |imu: &SimulatedImu, range: std::ops::Range<usize>| {
            let mut pieces = Vec::new();
            if !header_sent {
                pieces.push(crate::io::imu_write::asl_imu_header(imu.temperature.is_some()).into_bytes());
                header_sent = true;
            }
            pieces.extend(format_imu_rows(imu, t0, rate, range));
            // A send fails only if the writer stopped on an error, reported below.
            let _ = tx.send(pieces);
        };
        let sim = super::simulate_with(scenario, config, seed, &mut send);
        drop(tx);
        let written = writer.join().map_err(|_| InputError::file(&csv, "writer thread panicked").to_string())?;
        written.map_err(|e| werr(&csv, e).to_string())?;
        sim.map_err(refused)
    })?;
    write_rest(&sim, out).map_err(|e| e.to_string())?;
    if let Some(images) = &config.images {
        super::images::write_images(&sim, images, out, progress)?;
    }
    Ok(sim)
}

/// Write the IMU CSV of an in-memory simulation.
fn write_imu_csv(path: &Path, sim: &Simulation) -> Result<(), InputError> {
    let mut w = create(path)?;
    w.write_all(crate::io::imu_write::asl_imu_header(sim.imu.temperature.is_some()).as_bytes())
        .map_err(|e| werr(path, e))?;
    let n = sim.imu.t.len();
    for c0 in (0..n).step_by(1 << 18) {
        for piece in format_imu_rows(&sim.imu, sim.config.t0_ns, sim.config.imu.rate_hz, c0..(c0 + (1 << 18)).min(n)) {
            w.write_all(&piece).map_err(|e| werr(path, e))?;
        }
    }
    w.flush().map_err(|e| werr(path, e))
}

pub(crate) fn write_text(path: &Path, text: &str) -> Result<(), InputError> {
    let mut w = create(path)?;
    w.write_all(text.as_bytes()).map_err(|e| werr(path, e))?;
    w.flush().map_err(|e| werr(path, e))
}

fn worst(v: &[f64; 3]) -> f64 {
    v.iter().copied().fold(0.0, f64::max)
}

fn imu_yaml(sim: &Simulation) -> String {
    let m = &sim.config.imu;
    let header = format!(
        "Simulated by tumble (scenario {:?}, seed {}). Noise figures: worst axis of the model, continuous time, SI.",
        sim.scenario, sim.seed
    );
    let noise = [&m.gyro.noise_density, &m.gyro.random_walk, &m.accel.noise_density, &m.accel.random_walk].map(worst);
    imu_sensor_yaml(&header, "simulated BMI055-like IMU", m.rate_hz, noise)
        + &crate::io::ImuNoise::from_model(m).axes.map_or(String::new(), |a| {
            format!(
                "# Per axis [x, y, z], the random walks with the bias instability folded in (tumble's key):\n{}",
                a.yaml_block()
            )
        })
}

/// An ASL `imu0/sensor.yaml` (IMU frame = body frame) with `header` as its
/// comment line, at `rate_hz`, with the noise figures `[gyro white noise,
/// gyro random walk, accel white noise, accel random walk]` (Kalibr's units).
pub(crate) fn imu_sensor_yaml(header: &str, comment: &str, rate_hz: f64, noise: [f64; 4]) -> String {
    let [gn, gw, an, aw] = noise;
    format!(
        "%YAML:1.0\n# {header}\nsensor_type: imu\ncomment: {comment}\nT_BS:\n  cols: 4\n  rows: 4\n  data: [1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0]\nrate_hz: {rate_hz}\ngyroscope_noise_density: {gn:e}\ngyroscope_random_walk: {gw:e}\naccelerometer_noise_density: {an:e}\naccelerometer_random_walk: {aw:e}\n"
    )
}

/// An ASL `camN/sensor.yaml` of camera `c` mounted at `body_from_camera`.
pub(crate) fn camera_sensor_yaml(
    c: &super::CameraSettings,
    body_from_camera: &Isometry3<f64>,
    comment: &str,
) -> String {
    let data: Vec<String> = body_from_camera.to_homogeneous().transpose().iter().map(|x| format!("{x}")).collect();
    let model = match c.distortion_model {
        super::camera::DistortionKind::RadialTangential => "radial-tangential",
        super::camera::DistortionKind::Equidistant => "equidistant",
    };
    format!(
        "%YAML:1.0\nsensor_type: camera\ncomment: {comment}\nT_BS:\n  cols: 4\n  rows: 4\n  data: [{}]\nrate_hz: {}\nresolution: [{}, {}]\ncamera_model: pinhole\nintrinsics: [{}, {}, {}, {}]\ndistortion_model: {model}\ndistortion_coefficients: [{}, {}, {}, {}]\n",
        data.join(", "),
        c.rate_hz,
        c.resolution[0],
        c.resolution[1],
        c.intrinsics[0],
        c.intrinsics[1],
        c.intrinsics[2],
        c.intrinsics[3],
        c.distortion_coefficients[0],
        c.distortion_coefficients[1],
        c.distortion_coefficients[2],
        c.distortion_coefficients[3],
    )
}

/// The ground truth at the configured rate (every k-th IMU sample).
pub fn groundtruth(sim: &Simulation) -> Trajectory {
    let rate = sim.config.imu.rate_hz;
    let step = sim.imu.bias_every;
    let mut tr = Trajectory {
        v: Some(Vec::new()),
        bias_gyro: Some(Vec::new()),
        bias_accel: Some(Vec::new()),
        ..Trajectory::default()
    };
    let dt_ns = 1e9 / rate;
    for (j, i) in (0..sim.imu.t.len()).step_by(step).enumerate() {
        let k = sim.motion.at(sim.imu.t[i]);
        let q = k.quaternion();
        tr.t_ns.push(sim.config.t0_ns + (i as f64 * dt_ns).round() as i64);
        tr.p.push(k.position.into());
        tr.q.push([q.w, q.i, q.j, q.k]);
        if let (Some(v), Some(bg), Some(ba)) = (&mut tr.v, &mut tr.bias_gyro, &mut tr.bias_accel) {
            v.push(k.velocity.into());
            bg.push(sim.imu.bias_gyro[j]);
            ba.push(sim.imu.bias_accel[j]);
        }
    }
    tr
}

/// What a simulated camera writes beside its frames: `sensor.yaml`,
/// `data.csv`, its tracks and their truth.
pub(crate) struct CameraFiles<'a> {
    /// The camera (and its stereo partner, with a baseline).
    pub camera: &'a super::CameraSettings,
    /// The `comment:` of its `sensor.yaml`.
    pub comment: &'a str,
    /// Whether its frames are rendered: the tracks then go to `truth/`, for
    /// the estimators to track the images instead.
    pub images: bool,
}

impl CameraFiles<'_> {
    /// Write `mav0/cam0/` (and `cam1/` with a stereo baseline) and the tracks'
    /// truth (`truth/observations.csv`, `truth/landmarks.csv`) of `tracks`
    /// into `out`, each frame time `t` \[s\] stamped `stamp_ns(t)`.
    pub fn write(&self, tracks: &SimulatedTracks, stamp_ns: &dyn Fn(f64) -> i64, out: &Path) -> Result<(), InputError> {
        let (c, ns) = (self.camera, stamp_ns);
        let mav0 = out.join("mav0");
        let cam = mav0.join("cam0");
        write_text(&cam.join("sensor.yaml"), &camera_sensor_yaml(c, &c.body_from_camera(), self.comment))?;
        let mut frames = String::from("#timestamp [ns],filename\n");
        for &t in &tracks.frames {
            frames.push_str(&format!("{0},{0}.png\n", ns(t)));
        }
        write_text(&cam.join("data.csv"), &frames)?;
        // A tracks file (full precision, unlike the frontend's `write_tracks`).
        let track_rows = |obs: &[super::camera::Observation]| {
            let mut text = String::from("#timestamp [ns],track_id,u [px],v [px]\n");
            for o in obs {
                text.push_str(&format!("{},{},{},{}\n", ns(o.t), o.track, o.uv[0], o.uv[1]));
            }
            text
        };
        let mut truth_obs = String::from("#timestamp [ns],track_id,landmark_id,outlier,u_true [px],v_true [px]\n");
        for o in &tracks.observations {
            let [u, v] = o.true_uv;
            truth_obs.push_str(&format!("{},{},{},{},{u},{v}\n", ns(o.t), o.track, o.landmark, u8::from(o.outlier)));
        }
        // With images the estimators track them: the simulated tracks (exact
        // projections plus the configured noise) go to truth/ beside the rest.
        let track_dir = if self.images { out.join("truth") } else { cam.clone() };
        write_text(&track_dir.join("tracks.csv"), &track_rows(&tracks.observations))?;
        if c.stereo_baseline_m > 0.0 {
            // The second camera's matches beside cam0's tracks, as `tumble
            // track --stereo` writes them, and its sensor.yaml in cam1/.
            write_text(&track_dir.join("tracks_cam1.csv"), &track_rows(&tracks.stereo))?;
            let cam1 = mav0.join("cam1");
            write_text(&cam1.join("sensor.yaml"), &camera_sensor_yaml(c, &c.body_from_second_camera(), self.comment))?;
            write_text(&cam1.join("data.csv"), &frames)?;
        }
        write_text(&out.join("truth").join("observations.csv"), &truth_obs)?;
        let mut lm = String::from("#landmark_id,x [m],y [m],z [m]\n");
        for (j, p) in tracks.landmarks.iter().enumerate() {
            lm.push_str(&format!("{j},{},{},{}\n", p[0], p[1], p[2]));
        }
        write_text(&out.join("truth").join("landmarks.csv"), &lm)
    }
}

/// Write the simulation into `out` (created if needed).
pub fn write_asl(sim: &Simulation, out: &Path) -> Result<(), InputError> {
    write_imu_csv(&out.join("mav0").join("imu0").join("data.csv"), sim)?;
    write_rest(sim, out)
}

/// Everything but the IMU CSV.
fn write_rest(sim: &Simulation, out: &Path) -> Result<(), InputError> {
    let mav0 = out.join("mav0");
    write_text(&mav0.join("imu0").join("sensor.yaml"), &imu_yaml(sim))?;
    let gt = mav0.join("state_groundtruth_estimate0").join("data.csv");
    create(&gt)?;
    write_asl_groundtruth(&gt, &groundtruth(sim))?;
    let t0 = sim.config.t0_ns;
    if let Some(tr) = &sim.tracks {
        let comment = if sim.config.images.is_some() {
            "simulated camera (rendered images in data/)"
        } else {
            "simulated camera (no images; features in tracks.csv)"
        };
        let files = CameraFiles { camera: &sim.config.camera, comment, images: sim.config.images.is_some() };
        files.write(tr, &|t| sim.stamp_ns(t), out)?;
    }
    let truth = serde_json::json!({
        "generator": format!("tumble {}", env!("CARGO_PKG_VERSION")),
        "scenario": sim.scenario,
        "seed": sim.seed,
        "t0_ns": t0,
        "samples": sim.imu.t.len(),
        "duration_s": sim.motion.duration(),
        "gravity": sim.config.gravity,
        "static_intervals_s": sim.static_intervals,
        "config": sim.config,
        "convention": "ω̃ = T_g K_g(1+s_T ΔT) f_g(ω) + b_g + η_g + G a + n_g; ã = T_a K_a(1+s_T ΔT) f_a(a) + b_a + η_a + n_a; f(x) = x + c⊙x²; matrices row major; body = accelerometer frame; camera time offset: image stamped t taken at IMU time t + offset",
    });
    let text = serde_json::to_string_pretty(&truth).map_err(|e| InputError::file(out, format!("truth: {e}")))?;
    write_text(&out.join("truth.json"), &text)
}
