//! Evaluation aids that join the simulator and the VIO: a simulated recording
//! as a VIO input, a real IMU with ground truth seen by a simulated camera,
//! and estimator settings matching a simulation. They sit above both `sim`
//! and `vio`, so that neither imports the other.

use crate::io::{asl, trajectory::Trajectory};
use crate::model::calibration::ImuCalibration;
use crate::model::geometry::{from_nalgebra, to_nalgebra};
use crate::model::ImuData;
use crate::sim::{CameraSettings, SimConfig, Simulation, TriadModel};
use crate::vio::input::with_calibrated_offsets;
use crate::vio::VioError;
use crate::vio::{Frame, ImuNoise, StereoCamera, VioInput, VioOptions};
use crate::InputError;
use nalgebra::{Matrix3, UnitQuaternion, Vector3};

impl VioInput {
    /// The simulator's walk or flight: IMU corrected with the true `T`, `K`
    /// (the calibration a perfect `tumble calibrate` would give), so the
    /// remaining biases are the simulated turn-on bias and its drift; tracks in
    /// pixels; ground truth at the frame times with the true biases in the body frame.
    pub fn from_simulation(sim: &Simulation) -> Result<VioInput, VioError> {
        Self::from_simulation_calibrated(sim, None)
    }

    /// As [`VioInput::from_simulation`], but the IMU corrected with an
    /// estimated `calibration` (e.g. from `tumble calibrate` on the same
    /// simulated IMU's tumble) instead of the true `T`, `K`: what a user's
    /// pipeline does. The ground-truth biases are then what the calibration
    /// leaves of the simulated ones, `(T K)⁻¹_est (b_true − b_est)`.
    pub fn from_simulation_calibrated(
        sim: &Simulation,
        calibration: Option<&ImuCalibration>,
    ) -> Result<VioInput, VioError> {
        let tracks = sim.tracks.as_ref().ok_or("the simulation has no camera")?;
        let m = &sim.config.imu;
        // The simulator applies T and K only when their effects are on.
        let inv = |t: &TriadModel| -> Result<Matrix3<f64>, String> {
            let tm = if m.effects.misalignment {
                Matrix3::from_fn(|r, c| t.misalignment[r][c])
            } else {
                Matrix3::identity()
            };
            let k = if m.effects.scale { Vector3::from(t.scale) } else { Vector3::repeat(1.0) };
            (tm * Matrix3::from_diagonal(&k)).try_inverse().ok_or("singular T K".to_string())
        };
        // Raw-bias-to-body maps and the bias the correction already removes.
        let (ma, mg, ba0, bg0, imu) = match calibration {
            Some(cal) => {
                let ma = cal.accel.inverse_matrix().ok_or("calibration: singular accelerometer T K")?;
                let mg = cal.gyro.inverse_matrix().ok_or("calibration: singular gyro T K")?;
                (ma, mg, cal.accel.b, cal.gyro.b, sim.imu.to_recording().calibrated(Some(cal)))
            }
            None => {
                let (ma, mg) = (inv(&m.accel)?, inv(&m.gyro)?);
                let imu = ImuData {
                    t: sim.imu.t.clone(),
                    gyro: sim.imu.gyro.iter().map(|g| mg * Vector3::from(*g)).collect(),
                    acc: sim.imu.accel.iter().map(|a| ma * Vector3::from(*a)).collect(),
                };
                (ma, mg, Vector3::zeros(), Vector3::zeros(), imu)
            }
        };
        let mut frames: Vec<Frame> = tracks.frames.iter().map(|&t| Frame { t, features: Vec::new() }).collect();
        let mut fi = 0;
        for o in &tracks.observations {
            while fi + 1 < frames.len() && frames[fi].t < o.t {
                fi += 1;
            }
            frames[fi].features.push((o.track, o.uv));
        }
        let cs = &sim.config.camera;
        let body_from_camera = from_nalgebra(&cs.body_from_camera());
        let stereo = simulated_stereo(cs, &frames, &tracks.stereo);
        let mut gt = Trajectory::default();
        let (mut bga, mut baa) = (Vec::new(), Vec::new());
        for &t in &tracks.frames {
            let k = sim.motion.at(t);
            let q = UnitQuaternion::from_matrix(&k.rotation);
            gt.t_ns.push(sim.config.t0_ns + (t * 1e9).round() as i64);
            gt.p.push([k.position.x, k.position.y, k.position.z]);
            gt.q.push([q.w, q.i, q.j, q.k]);
            let i = ((t * m.rate_hz).round() as usize / sim.imu.bias_every).min(sim.imu.bias_gyro.len() - 1);
            let bg = mg * (Vector3::from(sim.imu.bias_gyro[i]) - bg0);
            let ba = ma * (Vector3::from(sim.imu.bias_accel[i]) - ba0);
            bga.push([bg.x, bg.y, bg.z]);
            baa.push([ba.x, ba.y, ba.z]);
        }
        gt.bias_gyro = Some(bga);
        gt.bias_accel = Some(baa);
        Ok(with_calibrated_offsets(
            VioInput {
                name: format!("simulated {:?} (seed {})", sim.scenario, sim.seed).to_lowercase(),
                t0_ns: sim.config.t0_ns,
                imu,
                frames,
                camera: cs.model(),
                body_from_camera,
                stereo,
                groundtruth: Some(gt),
                noise: Some(ImuNoise::from_model(m)),
                images: Vec::new(),
            },
            calibration,
        ))
    }

    /// A dataset with an IMU and a ground truth but no camera, seen by a
    /// simulated camera (`cam`) that flies the ground-truth path through a room
    /// of random landmarks around it: real IMU, simulated vision — for
    /// evaluating the estimator on real inertial data without images.
    ///
    /// The camera flies the path the IMU felt: where the ground truth's
    /// positions hold motion the IMU does not (a tracker's jitter), the IMU's
    /// own motion replaces them in those bands (see `sim::replay_bands`);
    /// the returned notes say where and why.
    pub fn from_dataset_with_simulated_camera(
        ds: asl::AslDataset,
        calibration: Option<&ImuCalibration>,
        cam: &CameraSettings,
        seed: u64,
    ) -> Result<(VioInput, Vec<String>), InputError> {
        let gt = ds.groundtruth.as_ref().ok_or_else(|| {
            InputError::file(&ds.root, "no ground truth (state_groundtruth_estimate0/, gt0/ or mocap0/)")
                .with_hint("a simulated camera needs the true path to look from")
        })?;
        let t0 = ds.imu.t0_ns;
        let recorded =
            crate::sim::motion::Replay::new(gt, t0).map_err(|e| InputError::file(&ds.root, e.to_string()))?;
        let imu = ds.imu.calibrated(calibration);
        let (motion, note) = crate::sim::replay_bands::camera_path(recorded, &imu);
        let notes: Vec<String> = note.into_iter().collect();
        let (scene, cam) = crate::sim::camera::room_around(motion.positions(), cam);
        let tracks = crate::sim::camera::simulate_tracks(&motion, &cam, &scene, seed);
        // Frames where both the ground truth and the IMU are.
        let start = (gt.t_ns.iter().copied().find(|&t| t >= t0).unwrap_or(t0) - t0) as f64 * 1e-9;
        let end = match ds.imu.len() {
            0 => 0.0,
            n => (ds.imu.t_ns(n - 1) - t0) as f64 * 1e-9,
        };
        let mut frames: Vec<Frame> = Vec::new();
        for o in tracks.observations.iter().filter(|o| o.t >= start && o.t <= end) {
            match frames.last_mut() {
                Some(f) if f.t == o.t => f.features.push((o.track, o.uv)),
                _ => frames.push(Frame { t: o.t, features: vec![(o.track, o.uv)] }),
            }
        }
        let body_from_camera = from_nalgebra(&cam.body_from_camera());
        let stereo = simulated_stereo(&cam, &frames, &tracks.stereo);
        let noise = ds.imu_noise();
        let input = with_calibrated_offsets(
            VioInput {
                name: format!("{} (simulated camera)", ds.root.display()),
                t0_ns: t0,
                imu,
                frames,
                camera: cam.model(),
                body_from_camera,
                stereo,
                groundtruth: ds.groundtruth,
                noise,
                images: Vec::new(),
            },
            calibration,
        );
        Ok((input, notes))
    }
}

/// The per-frame PnP ground truth of a target recording (see
/// [`VioInput::from_target_recording`]).
#[derive(Debug, Clone, PartialEq)]
pub struct TargetTruth {
    /// Frames with a PnP pose, of all frames with corners.
    pub posed: usize,
    /// Frames with corners.
    pub frames: usize,
    /// Median RMS reprojection error of the PnP poses \[px\].
    pub median_rms_px: f64,
}

/// Largest RMS reprojection \[px\] of a PnP pose kept as ground truth: the
/// corners of a sharp image reproject within a few tenths of a pixel; a
/// blurred or partly wrong detection does not give a pose to judge by.
pub const TARGET_TRUTH_MAX_RMS_PX: f64 = 1.0;

/// Fewest corners a PnP ground-truth pose is made from.
pub const TARGET_TRUTH_MIN_CORNERS: usize = 20;

impl VioInput {
    /// A recording in front of a calibration target as a VIO input with a
    /// ground truth: `dir` (ASL, `mav0/imu0/data.csv` and `mav0/cam0/corners.csv`
    /// as `tumble calibrate-rig` reads them) and its `target` (Kalibr yaml);
    /// cam0's model and pose in the IMU frame, and the IMU noise, from the ASL
    /// folder `cameras` (`camN/sensor.yaml`, `imu0/sensor.yaml`, e.g. EuRoC's or
    /// `tumble calibrate-rig`'s). Every corner is a feature whose track id is its
    /// corner id on the target (`4·tag + corner` for an AprilGrid). The ground
    /// truth is a PnP per frame with those cameras ([`crate::rig::init::refine_view_pose`];
    /// frames with ≥ [`TARGET_TRUTH_MIN_CORNERS`] corners reprojecting within
    /// [`TARGET_TRUTH_MAX_RMS_PX`]), in a world whose z is up: the target frame
    /// turned by the mean specific force over the recording (gravity, as the
    /// motion's accelerations average out), so that a position + yaw
    /// alignment applies.
    pub fn from_target_recording(
        dir: &std::path::Path,
        target: &std::path::Path,
        cameras: &std::path::Path,
    ) -> Result<(VioInput, TargetTruth), VioError> {
        let target = crate::model::target::Target::read(target)?;
        let ds = asl::read_asl(dir, &Default::default())?;
        let cams = asl::read_asl(cameras, &Default::default())?;
        let cam = cams.cameras.first().ok_or_else(|| InputError::file(cameras, "holds no cam0/sensor.yaml"))?;
        let model = cam.model.ok_or_else(|| InputError::file(cameras, "cam0/sensor.yaml has no intrinsics"))?;
        let body_imu = cams.imu_sensor.as_ref().map_or_else(nalgebra::Isometry3::identity, |s| s.t_bs);
        let t_bc = body_imu.inverse()
            * cam.t_bs.ok_or_else(|| {
                InputError::file(cameras, "cam0/sensor.yaml has no T_BS (its pose in the body frame)")
            })?;
        let views = crate::io::target::read_corners(&ds.root.join("cam0"), &target)?;
        let t0 = ds.imu.t0_ns;
        let imu = ds.imu.calibrated(None);
        let mut frames = Vec::new();
        let mut poses: Vec<(i64, nalgebra::Isometry3<f64>)> = Vec::new();
        let mut rms = Vec::new();
        let with_corners = views.iter().filter(|v| !v.corners.is_empty()).count();
        for v in &views {
            let t = (v.t_ns - t0) as f64 * 1e-9;
            frames.push(Frame { t, features: v.corners.iter().map(|c| (c.id as u64, c.uv)).collect() });
            if v.corners.len() < TARGET_TRUTH_MIN_CORNERS {
                continue;
            }
            let Some((t_ct, e)) = crate::rig::init::refine_view_pose(v, &model) else { continue };
            if e > TARGET_TRUTH_MAX_RMS_PX {
                continue;
            }
            rms.push(e);
            let t_ct = to_nalgebra(&t_ct);
            // Target ← body = (camera ← target)⁻¹ · (body ← camera)⁻¹.
            poses.push((v.t_ns, t_ct.inverse() * t_bc.inverse()));
        }
        if poses.len() < 2 {
            return Err(InputError::file(&ds.root, "fewer than two frames give a PnP pose of the target").into());
        }
        // Gravity's direction in the target frame: the mean specific force.
        let mut up = Vector3::zeros();
        for (t_ns, p) in &poses {
            let (acc, _) = imu.at((t_ns - t0) as f64 * 1e-9);
            up += p.rotation * acc;
        }
        let r_wt = UnitQuaternion::rotation_between(&up, &Vector3::z())
            .ok_or_else(|| InputError::file(&ds.root, "no IMU samples at the frames"))?;
        let mut gt = Trajectory::default();
        for (t_ns, p) in &poses {
            let q = r_wt * p.rotation;
            let x = r_wt * p.translation.vector;
            gt.t_ns.push(*t_ns);
            gt.p.push([x.x, x.y, x.z]);
            gt.q.push([q.w, q.i, q.j, q.k]);
        }
        rms.sort_by(f64::total_cmp);
        let truth = TargetTruth { posed: poses.len(), frames: with_corners, median_rms_px: rms[rms.len() / 2] };
        let input = VioInput {
            name: format!("{} (target corners as features)", ds.root.display()),
            t0_ns: t0,
            imu,
            frames,
            camera: model,
            body_from_camera: from_nalgebra(&t_bc),
            stereo: None,
            groundtruth: Some(gt),
            noise: cams.imu_noise(),
            images: Vec::new(),
        };
        Ok((input, truth))
    }
}

/// The simulated second camera, when the settings have one: its
/// observations put on the frames of the same times.
fn simulated_stereo(
    cam: &CameraSettings,
    frames: &[Frame],
    obs: &[crate::sim::camera::Observation],
) -> Option<StereoCamera> {
    if cam.stereo_baseline_m <= 0.0 {
        return None;
    }
    let mut features = vec![Vec::new(); frames.len()];
    for o in obs {
        let k = frames.partition_point(|f| f.t < o.t - 1e-9);
        if frames.get(k).is_some_and(|f| (f.t - o.t).abs() < 1e-9) {
            features[k].push((o.track, o.uv));
        }
    }
    Some(StereoCamera {
        camera: cam.model(),
        body_from_camera: from_nalgebra(&cam.body_from_second_camera()),
        features,
    })
}

impl VioInput {
    /// The same recording with a wrong camera calibration, to test its online
    /// estimation ([`crate::vio::CameraCalibrationOptions`]): the given `T_BC`
    /// turned by `rotation` (a rotation vector in the camera frame \[rad\]) and
    /// moved by `translation` (camera frame \[m\]), and every frame stamped
    /// `shift` later \[s\] — whose true time offset (t_imu = t_cam + td) is then
    /// the old one minus `shift`. Returns the input and the correct `T_BC`.
    pub fn with_camera_error(
        mut self,
        rotation: Vector3<f64>,
        translation: Vector3<f64>,
        shift: f64,
    ) -> (VioInput, tumble_solvers::sophus_lie::Isometry3F64) {
        let correct = self.body_from_camera;
        let delta = crate::model::geometry::pose(
            UnitQuaternion::from_scaled_axis(rotation).to_rotation_matrix().matrix(),
            &translation,
        );
        self.body_from_camera = correct * delta;
        for f in &mut self.frames {
            f.t += shift;
        }
        (self, correct)
    }
}

impl VioOptions {
    /// Defaults with the noise, gravity and pixel noise a simulation was made with
    /// (what `tumble allan` and the camera's specification would tell).
    pub fn for_simulation(cfg: &SimConfig) -> VioOptions {
        let mut o = VioOptions::default();
        o.noise.gravity = cfg.gravity;
        o.noise.pixel_sigma = cfg.camera.pixel_noise_px.max(0.1);
        ImuNoise::from_model(&cfg.imu).apply(&mut o.noise.imu);
        o
    }
}
