//! The VIO's online camera calibration, and starts and shocks the features
//! contradict (simulated walks and EuRoC's imu_april).

mod common;

use common::vio::*;
use nalgebra::Vector3;
use tumble::sim::{simulate, Scenario, SimConfig};
use tumble::vio::{run, summarize, Estimate, VioInput, VioOptions};

/// The camera's `T_BC` and time offset estimated online from a wrong start
/// (2° about an oblique axis, 3 cm, stamps 8 ms late) on a simulated walk
/// with known truth (4 rad/s RMS, which needs the IMU's motion over the
/// offset, not a constant rate: `ExposureMotion`). Measured: 0.016°, 1.6 mm,
/// 0.023 ms (0.018°, 2.0 mm, 0.037 ms before the frames after the start were
/// given the window's solve when few landmarks place them).
#[test]
fn online_camera_calibration_converges_on_a_simulated_walk() {
    let (input, opts) = walk(80.0, 1);
    let (c, rotation_deg, translation_m, td_error, _) = calibrate_online(input, opts, Vector3::new(0.02, -0.02, 0.02));
    assert!(c.extrinsics_auto.is_none() && c.extrinsics_estimated);
    assert!(rotation_deg < 0.1, "rotation error {rotation_deg}°");
    assert!(translation_m < 0.005, "translation error {translation_m} m");
    assert!(td_error.abs() < 2e-4, "time offset error {td_error} s");
    assert!(c.rotation_change_deg > 1.5 && c.translation_change_m > 0.02, "it moved: {c:?}");
}

/// The same on a fast walk (the paper's loop in 40 s, up to several rad/s,
/// where 8 ms turn the camera by 1–2° per frame). The triangulation, the
/// prediction gate and the landmarks' positions placed each camera at its
/// state's stamp while the window's factors placed it at the exposure the
/// estimated time offset gives, so once that offset was estimated the rays
/// of new tracks missed one another and the estimate was withdrawn and
/// started again, 1–38 times on seeds 1–8 (18 on this one). Now all of them
/// move the pose to the exposure (`body_at_exposure`): no restart on seeds
/// 2–8; seed 1 restarts twice at 4–6 s, before the calibration is freed,
/// flown with the given one 2° and 8 ms off (measured 2026-11-29).
#[test]
fn online_camera_calibration_on_a_fast_walk_does_not_restart() {
    let (input, opts) = walk(40.0, 4);
    let (_, rotation_deg, translation_m, td_error, out) =
        calibrate_online(input, opts, Vector3::new(0.02, -0.02, 0.02));
    assert_eq!(out.resets, 0);
    assert!(rotation_deg < 0.2, "rotation error {rotation_deg}°");
    assert!(translation_m < 0.01, "translation error {translation_m} m");
    assert!(td_error.abs() < 5e-4, "time offset error {td_error} s");
}

/// The same on the real imu_april (real IMU, the target's corners as
/// features), from EuRoC's calibration made wrong by 2° and 3 cm and its
/// stamps shifted by 8 ms: the time offset comes back within 0.02 ms; `T_BC`
/// lands 0.23° and 8 mm from EuRoC's (Kalibr's) figures — where it lands from
/// EuRoC's own start too, and within 0.08° and 1–2 mm of tumble's batch rig
/// calibration of this recording with EuRoC's intrinsics (docs/vio.md).
#[test]
fn online_camera_calibration_on_imu_april() {
    let (Some(dir), Some(cams)) = (common::shared("euroc/imu_april"), common::shared("euroc/V1_01_easy_micro")) else {
        return;
    };
    let (input, _) = VioInput::from_target_recording(&dir, &dir.join("target.yaml"), &cams).unwrap();
    let mut opts = VioOptions::default();
    input.apply_noise(None, &mut opts.noise.imu);
    let rotation = Vector3::new(1.0, -1.0, 1.0).normalize() * 2f64.to_radians();
    let (_, rotation_deg, translation_m, td_error, out) = calibrate_online(input, opts, rotation);
    assert!(td_error.abs() < 5e-4, "time offset error {td_error} s");
    assert!(rotation_deg < 0.3, "rotation {rotation_deg}° from EuRoC's");
    assert!(translation_m < 0.015, "translation {translation_m} m from EuRoC's");
    // The frames after the start in motion are placed by the landmarks (they
    // are solved with the window until enough landmarks can place one): the
    // IMU's prediction stays within the gate and nothing goes blind before
    // the target leaves the image at 55.8 s. (When these frames were left to
    // the IMU from a gyro bias of 0, the first keyframe was 38 px off and
    // 0.9 s went blind; ATE 0.127 m, now 0.015 m: docs/vio.md.)
    assert!(out.blind_spans.iter().all(|s| s[0] > 50.0), "{:?}", out.blind_spans);
}

/// A frame whose features all disagree with the IMU's prediction (here they
/// are moved 60 px for 0.3 s, as a stamp jump would) is not placed by them:
/// the prediction gate keeps every observation out, and the span is
/// reported as blind, naming the gate.
#[test]
fn features_that_disagree_with_the_prediction_are_reported_blind() {
    let (mut input, opts) = walk(40.0, 5);
    for f in input.frames.iter_mut().filter(|f| f.t > 20.0 && f.t < 20.3) {
        for (_, uv) in f.features.iter_mut() {
            uv[0] += 60.0;
        }
    }
    let out = run(&input, &opts, None).unwrap();
    assert!(finite(&out));
    let gated = out.warnings.iter().find(|w| w.contains("prediction gate: the IMU's prediction is off"));
    assert!(gated.is_some_and(|w| w.starts_with("vision lost at 20.0")), "{:?}", out.warnings);
    assert!(out.blind_spans.iter().any(|s| (s[0] - 20.0).abs() < 0.1 && s[1] > 20.2), "{:?}", out.blind_spans);
}

/// Run `input` with its `T_BC` turned by `rotation` \[rad, camera frame\] and
/// moved 3 cm, its stamps 8 ms late, both estimated online; the estimate and
/// its errors: rotation \[deg\], translation \[m\], time offset \[s\]; and the run.
fn calibrate_online(
    input: VioInput,
    opts: VioOptions,
    rotation: Vector3<f64>,
) -> (tumble::vio::CameraEstimate, f64, f64, f64, tumble::vio::VioResult) {
    let (c, errors, out) = calibrate_online_as(input, opts, Estimate::On, rotation, Vector3::new(0.03, 0.0, 0.0));
    (c, errors.0.norm().to_degrees(), errors.1.norm(), errors.2, out)
}

/// [`calibrate_online`] with both parameters estimated `mode`, the
/// translation moved by `translation` \[m, camera frame\]; the errors are the
/// rotation's (a rotation vector about the camera's axes \[rad\]), the
/// translation's per camera axis \[m\] and the time offset's \[s\].
fn calibrate_online_as(
    input: VioInput,
    mut opts: VioOptions,
    mode: Estimate,
    rotation: Vector3<f64>,
    translation: Vector3<f64>,
) -> (tumble::vio::CameraEstimate, (Vector3<f64>, Vector3<f64>, f64), tumble::vio::VioResult) {
    let shift = 0.008;
    let (input, correct) = input.with_camera_error(rotation, translation, shift);
    opts.camera.extrinsics = mode;
    opts.camera.time_offset = mode;
    let out = run(&input, &opts, None).unwrap();
    assert_eq!(out.resets, 0, "{:?}", out.warnings);
    let c = out.camera.clone().expect("an online estimate");
    let rotation = c.rotation_error(&correct);
    let rotation_deg = rotation.norm().to_degrees();
    let translation = c.translation_error(&correct);
    let td_error = c.time_offset_s + shift;
    println!(
        "{}\nerror: {rotation_deg:.3}°, [{:.1} {:.1} {:.1}] mm (camera axes), {:.3} ms",
        c.line(),
        translation.x * 1e3,
        translation.y * 1e3,
        translation.z * 1e3,
        td_error * 1e3
    );
    (c, (rotation, translation, td_error), out)
}

/// `auto` on a motion that turns about the vertical only (as a ground robot
/// or a cart does; Yang et al., RA-L 2019, show the camera's translation
/// along that axis is then unobservable): the vertical is the camera's y
/// axis here. `auto` holds that direction at the given value, says so, and
/// reports the σ the data leave there (about the prior's); the rotation, the
/// other two translations and the time offset are estimated. Measured (seed
/// 1): held "translation along y" (σ 0.85 of the prior's), errors 0.11°,
/// x 0.4 mm, z 1.2 mm, 0.19 ms; `on` estimates all six and lands 6–53 mm
/// from the truth along y on seeds 1–5 (docs/vio.md).
#[test]
fn auto_holds_what_a_turn_about_one_axis_cannot_determine() {
    let cfg = SimConfig { duration_s: Some(60.0), ..SimConfig::default() };
    let motion = Box::new(tumble::sim::Loop::planar(60.0, 1));
    let scene = tumble::sim::Scene::Room(Vector3::zeros());
    let sim = tumble::sim::simulate_motion(Scenario::Walk, motion, scene, &cfg, 1).unwrap();
    let input = VioInput::from_simulation(&sim).unwrap();
    let opts = VioOptions::for_simulation(&cfg);
    // 2 cm off along the unobservable axis too.
    let moved = Vector3::new(0.02, 0.02, 0.0);
    let (c, (rotation, t, td_error), _) =
        calibrate_online_as(input, opts, Estimate::Auto, Vector3::new(0.02, -0.02, 0.02), moved);
    let auto = c.extrinsics_auto.as_ref().expect("auto");
    assert!(auto.freed_at_s.is_some() && auto.determined_at_s.is_none(), "{auto:?}");
    let held: Vec<&str> = auto.held.iter().map(|(d, _)| d.as_str()).collect();
    assert_eq!(held, ["translation along y"], "{auto:?}");
    assert!(c.line().contains("not determined by this motion along translation along y"), "{}", c.line());
    // Held at the given value there: its error stays, within the σ reported.
    assert!((t.y - 0.02).abs() < 1e-3, "{t}");
    assert!(c.translation_sigma_m[1] > 0.025, "{:?}", c.translation_sigma_m);
    // The determined directions converge.
    let rotation_deg = rotation.norm().to_degrees();
    assert!(rotation_deg < 0.3 && t.x.abs() < 0.005 && t.z.abs() < 0.005, "{rotation_deg}° {t}");
    assert!(td_error.abs() < 5e-4, "{td_error}");
    assert!(c.time_offset_auto.as_ref().is_some_and(|a| a.determined_at_s.is_some() && a.held.is_empty()));
}

/// A start in motion the features contradict is withdrawn and made again.
/// EuRoC V2_01 (real IMU, simulated camera) started 40 s in: slow (0.26 m/s)
/// on a gyro whose 0.08 rad/s bias the first features did not determine, the
/// closed form came out 5° and 0.44 m/s off; no landmark could be
/// triangulated from its poses, and the IMU flew on alone to 300 m/s and an
/// ATE of 6 km, with nothing reported for 68 s (`Window::contradicted_start`).
#[test]
fn a_start_in_motion_the_features_contradict_is_made_again() {
    let Some(seq) = common::shared("euroc/full_imu/V2_01_easy") else { return };
    let source = tumble::vio::VioSource { simulate_camera: Some(1), ..Default::default() };
    let mut input = tumble::vio::VioInput::open(&seq, &source, &mut |_, _| {}).unwrap().input;
    input.drop_before(40.0);
    let mut opts = VioOptions::default();
    input.apply_noise(None, &mut opts.noise.imu);
    let out = run(&input, &opts, None).unwrap();
    let restarts: Vec<&String> = out.warnings.iter().filter(|w| w.contains("contradicted by the features")).collect();
    println!("{restarts:#?}");
    assert!(!restarts.is_empty(), "{:?}", out.warnings);
    assert_eq!(out.resets, restarts.len(), "{:?}", out.warnings);
    // The contradicted starts' estimates are withdrawn: what remains begins
    // at the last start and never flies off.
    let t_last = out.init_time.expect("initialized");
    assert!((out.estimates[0].t - t_last).abs() < 1e-6, "first estimate at {} s", out.estimates[0].t);
    let fastest = out.estimates.iter().map(|e| nalgebra::Vector3::from(e.velocity).norm()).fold(0.0, f64::max);
    let s = summarize(&input, &opts, &out, 10.0);
    println!("fastest {fastest:.2} m/s, ATE {:.3} m", s.ate_rmse_m.unwrap());
    assert!(fastest < 3.0, "{fastest} m/s");
    assert!(s.ate_rmse_m.unwrap() < 0.1, "ATE {:?}", s.ate_rmse_m);
}

/// A start in motion whose prediction the features refute before it is
/// confirmed is withdrawn and made again. imu_april started 45 s in, flown at
/// up to 2 rad/s with the camera's `T_BC` 2° and 3 cm off and its stamps 8 ms
/// late (estimated online, held until the start is confirmed): the first
/// start put 87 of 96 observations beyond the prediction gate 0.8 s later,
/// and, carried on, the estimate wandered 3.5 m from the truth over the next
/// 4 s (ATE 0.91 m over a motion of ±0.8 m) with no failure reported
/// (`Window::unconfirmed`; docs/vio.md).
#[test]
fn a_start_in_motion_the_prediction_gate_refutes_is_made_again() {
    let (Some(dir), Some(cams)) = (common::shared("euroc/imu_april"), common::shared("euroc/V1_01_easy_micro")) else {
        return;
    };
    let (input, _) = VioInput::from_target_recording(&dir, &dir.join("target.yaml"), &cams).unwrap();
    let rotation = Vector3::new(1.0, -1.0, 1.0).normalize() * 2f64.to_radians();
    let (mut input, _) = input.with_camera_error(rotation, Vector3::new(0.03, 0.0, 0.0), 0.008);
    input.drop_before(45.0);
    let mut opts = VioOptions::default();
    opts.camera.extrinsics = Estimate::On;
    opts.camera.time_offset = Estimate::On;
    input.apply_noise(None, &mut opts.noise.imu);
    let out = run(&input, &opts, None).unwrap();
    let refuted: Vec<&String> = out
        .warnings
        .iter()
        .filter(|w| w.contains("contradicted by the features") && w.contains("prediction gate"))
        .collect();
    println!("{refuted:#?}");
    assert!(!refuted.is_empty(), "{:?}", out.warnings);
    let s = summarize(&input, &opts, &out, 10.0);
    println!("ATE {:.3} m, {} resets", s.ate_rmse_m.unwrap(), out.resets);
    assert!(s.ate_rmse_m.unwrap() < 0.1, "ATE {:?}", s.ate_rmse_m);
}

/// A shock the IMU misreads: the gyro reads 2 rad/s too much about x over
/// the second after `from` \[s\].
fn gyro_shock(input: &mut VioInput, from: f64) {
    for (t, g) in input.imu.t.iter().zip(input.imu.gyro.iter_mut()) {
        if *t > from && *t < from + 1.0 {
            g.x += 2.0;
        }
    }
}

/// Every start measures the noise over the figures given to the run. A new
/// start after a withdrawn one took the last one's figures in use as its
/// given ones, so each start scaled them again (a run restarted 30 times
/// ended with "given" gyro noise 20× the model's). Here the simulated IMU is
/// 4× noisier than the figures given, so the meter raises them within the
/// first 20 s; a shock at 30 s (the gyro reads 2 rad/s too much about x for
/// 1 s) is withdrawn and the estimator starts again.
#[test]
fn every_start_measures_the_noise_over_the_figures_given() {
    let mut cfg = SimConfig { duration_s: Some(60.0), ..SimConfig::default() };
    let opts = VioOptions::for_simulation(&cfg);
    for triad in [&mut cfg.imu.gyro, &mut cfg.imu.accel] {
        triad.noise_density = triad.noise_density.map(|n| 4.0 * n);
    }
    let mut input = VioInput::from_simulation(&simulate(Scenario::Walk, &cfg, 3).unwrap()).unwrap();
    gyro_shock(&mut input, 30.0);
    let out = run(&input, &opts, None).unwrap();
    let noise = out.noise.expect("the noise was measured in motion");
    println!("{} resets; {}", out.resets, noise.line());
    let given = [opts.noise.imu.gyro_noise_density, opts.noise.imu.accel_noise_density];
    // The meter raised the figures, and there was a new start after it.
    assert!(out.resets >= 1 && noise.in_use[0] > 2.0 * given[0], "{} resets, {noise:?}", out.resets);
    assert_eq!(noise.given, given);
}

/// An IMU shock the features contradict is detected, its estimates are
/// withdrawn, and the trajectory that follows is a new piece that says so: a
/// simulated walk whose gyro reads 2 rad/s too much about x over 20–21 s.
/// The attitude that follows makes the rays of most new tracks miss one
/// another; before, the estimate flew on for 17 s (250 m/s, ATE 570 m) until
/// a position jump reset it (`Window::contradicted`).
#[test]
fn a_shock_the_features_contradict_is_withdrawn_and_the_pieces_named() {
    let (mut input, opts) = walk(40.0, 3);
    gyro_shock(&mut input, 20.0);
    let out = run(&input, &opts, None).unwrap();
    println!("{:#?}", out.warnings);
    assert!(out.warnings.iter().any(|w| w.starts_with("the estimate is contradicted by the features")));
    assert!(out.starts.len() >= 2, "{:?}", out.starts);
    let pieces = out.warnings.iter().find(|w| w.starts_with("the trajectory is in"));
    assert!(pieces.is_some_and(|w| w.contains(&format!("{} pieces", out.starts.len()))), "{:?}", out.warnings);
    let s = summarize(&input, &opts, &out, 10.0);
    assert_eq!(s.starts, out.starts);
    assert!(s.table().contains("pieces"), "{}", s.table());
    // The evaluation aligns each piece by itself: each is right.
    let m = &s.evaluation.as_ref().unwrap().metrics;
    println!("pieces: {:?}", m.pieces);
    assert_eq!(m.pieces.len(), out.starts.len());
    assert!(m.pieces.iter().all(|p| p.ate_rmse_m < 0.1), "{:?}", m.pieces);
    assert!(s.ate_rmse_m.unwrap() < 0.1, "{:?}", s.ate_rmse_m);
    // `tumble eval` on the written files finds the pieces in summary.json.
    let dir = std::env::temp_dir().join(format!("tumble-vio-pieces-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    tumble::vio::write_outputs(&dir, &input, &out, &s).unwrap();
    let gt = dir.join("groundtruth.txt");
    tumble::io::trajectory::write_tum(&gt, input.groundtruth.as_ref().unwrap()).unwrap();
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_tumble"))
        .args([
            "eval",
            "--estimate",
            dir.join("trajectory.txt").to_str().unwrap(),
            "--groundtruth",
            gt.to_str().unwrap(),
        ])
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&o.stdout);
    println!("{text}");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(text.contains(&format!("pieces: {}", out.starts.len())), "{text}");
    let ate: f64 = text.split("RMSE ").nth(1).and_then(|r| r.split(' ').next()).unwrap().parse().unwrap();
    assert!((ate - s.ate_rmse_m.unwrap()).abs() < 1e-3, "{ate}");
}

/// The online calibration's σ against its errors on the wrong-start walks
/// of seeds 1–8 (`SEEDS=1,2` runs some): per group (rotation, translation,
/// time offset) the mean of the squared normalized errors per coordinate,
/// which honest σ put near 1 (issue 64 asks for [0.5, 2]). With the
/// landmarks' bearings estimated (the default, three parameters per
/// landmark) measured 0.85, 1.36 and 1.35 (2026-12-03). With VINS-Mono's
/// inverse depth alone (`LANDMARK_BEARINGS=0`, `--inverse-depth-only`) 1.07, 5.56 and
/// 1.18: the anchor pixel's noise, counted nowhere, makes the translation's σ
/// about 2.4× too small; those bounds guard that figure.
#[test]
#[ignore = "long trial: cargo test --test vio_online -- --ignored"]
fn online_calibration_sigma_against_their_errors() {
    let seeds: Vec<u64> = std::env::var("SEEDS")
        .ok()
        .map(|s| s.split(',').map(|x| x.parse().expect("SEEDS: comma-separated integers")).collect())
        .unwrap_or_else(|| (1..=8).collect());
    // START_SCALE=0.01 starts the extrinsic 100× closer to the truth;
    // LANDMARK_BEARINGS=0 fixes the landmarks' bearings (one parameter, VINS-Mono's).
    let scale: f64 = std::env::var("START_SCALE").map_or(1.0, |s| s.parse().expect("START_SCALE: a number"));
    let bearings = !std::env::var("LANDMARK_BEARINGS").is_ok_and(|v| v == "0");
    let (mut sums, mut counts) = ([0.0f64; 3], [0usize; 3]);
    for &seed in &seeds {
        let (input, mut opts) = walk(80.0, seed);
        opts.window.landmark_bearings = bearings;
        let wrong = (Vector3::new(0.02, -0.02, 0.02) * scale, Vector3::new(0.03, 0.0, 0.0) * scale);
        let (c, (r_err, t_err, td_err), _) = calibrate_online_as(input, opts, Estimate::On, wrong.0, wrong.1);
        let z = [
            (0..3).map(|i| r_err[i].to_degrees() / c.rotation_sigma_deg[i]).collect::<Vec<f64>>(),
            (0..3).map(|i| t_err[i] / c.translation_sigma_m[i]).collect(),
            vec![td_err / c.time_offset_sigma_s],
        ];
        println!("seed {seed}: z rotation {:+.2?}, translation {:+.2?}, time offset {:+.2?}", z[0], z[1], z[2]);
        for (g, z) in z.iter().enumerate() {
            sums[g] += z.iter().map(|v| v * v).sum::<f64>();
            counts[g] += z.len();
        }
    }
    let mean = |g: usize| sums[g] / counts[g] as f64;
    println!("mean z²: rotation {:.2}, translation {:.2}, time offset {:.2}", mean(0), mean(1), mean(2));
    if bearings {
        assert!((0..3).all(|g| (0.5..=2.0).contains(&mean(g))), "{sums:?} over {counts:?}");
    } else {
        assert!(mean(0) < 2.5 && mean(1) < 6.0 && mean(2) < 2.5, "{sums:?} over {counts:?}");
    }
}
