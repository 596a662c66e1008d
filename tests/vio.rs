//! The sliding-window VIO on simulated data with known truth, on real EuRoC
//! V1_01 (EqVIO's tracks), and on degenerate input.

mod common;

use common::vio::*;
use tumble::sim::{simulate, Scenario, SimConfig};
use tumble::vio::{read_eqvio, run, summarize, Init, VioInput, VioOptions, VioResult};

#[test]
fn simulated_walk_closes_the_loop_far_better_than_the_imu_alone() {
    let (input, opts) = walk(120.0, 3);
    let (out, s) = run_without_resets(&input, &opts, 30.0);
    assert_eq!(s.returns_to_start, Some(true));
    // Fused drift: a small fraction of the distance walked (0.075 % here; 0.73 %
    // with the window solved at every frame and keyframes by mean parallax,
    // 1.4 % with keyframes every 10 px / 0.5 s as well); IMU-only: orders of
    // magnitude more.
    assert!(s.groundtruth_distance_m.is_some());
    assert!(s.closed_loop_percent() < 0.3, "{} %", s.closed_loop_percent());
    assert!(s.imu_only_closed_loop_error_m > 20.0 * s.closed_loop_error_m);
    assert!(s.ate_rmse_m.unwrap() < 0.15);
    // The windows' lengths (the scale they carry) against the truth, in their σ.
    let w = s.window_length.as_ref().expect("window lengths");
    println!("{}", w.line());
    let z = w.normalized_error_rms.unwrap();
    assert!((0.5..2.0).contains(&z) && w.relative_sigma_median < 0.05, "{}", w.line());
    // Bias RMSE after convergence against the steady-state std the noise
    // coefficients predict, √(N·K): the issue asks for ≤ 2×. The gyro's is met
    // here; the accelerometer's is not (3.6×, 4.6× before the per-axis noise:
    // its bias is seen only through the motion).
    let (gyro_ratio, accel_ratio) = s.bias_rmse_ratios().unwrap();
    println!("bias RMSE / predicted steady state: gyro {gyro_ratio:.2}, accel {accel_ratio:.2}");
    assert!(gyro_ratio < 2.0, "{gyro_ratio}");
    // Normalized gyro-bias errors against the reported σ after convergence.
    let gt = input.groundtruth.as_ref().unwrap();
    let (mut z2, mut n) = (0.0, 0usize);
    for e in out.estimates.iter().filter(|e| e.t > 30.0 && e.std[4][0].is_finite()) {
        let bt = gt.bias_gyro.as_ref().unwrap()[truth_index(&input, e.t)];
        for ((b, t), s) in e.bias_gyro.iter().zip(bt).zip(e.std[4]) {
            z2 += ((b - t) / s).powi(2);
            n += 1;
        }
    }
    let nees = z2 / n as f64;
    println!("gyro bias: mean normalized squared error {nees:.2} over {n} components (1 = consistent)");
    // 1.18 with each axis' own noise and the bias instability in the random
    // walk; 0.47 with the triad's largest-axis figures (x/y σ pessimistic, z
    // optimistic), which this bound refuses.
    assert!(n > 1000 && nees < 2.0 && nees > 0.6, "{nees}");
    // The evaluation's per-axis figure over its own window (from 30 s after the first estimate).
    let axes = s.evaluation.as_ref().unwrap().metrics.bias_nees_gyro_axes.unwrap();
    assert!(axes.iter().all(|z| (0.2..4.0).contains(z)), "{axes:?}");
    // The static start holds still: nothing triangulates at rest, and before
    // rest was detected against the pixel noise the velocity drifted as the
    // IMU's (0.17 m in 2 s on seed 10's 6-minute walk; here 0.134 m; now 0.014 m).
    let truth_at = |t: f64| nalgebra::Vector3::from(gt.p[truth_index(&input, t)]);
    let (p0, g0) = (nalgebra::Vector3::from(out.estimates[0].position), truth_at(out.estimates[0].t));
    let drift = out
        .estimates
        .iter()
        .take_while(|e| (truth_at(e.t) - g0).norm() < 1e-3)
        .map(|e| (nalgebra::Vector3::from(e.position) - p0).norm())
        .fold(0.0, f64::max);
    println!("largest displacement while at rest: {drift:.3} m");
    assert!(drift < 0.03, "{drift} m");
    // No keyframe jumps off and back: the rotation from one frame to the next
    // against the truth's. A gross outlier triangulated into a new landmark
    // once pulled single keyframe solves 1–3° off (99.9th percentile 1.65°
    // here); now 0.50°.
    let q = |q: [f64; 4]| nalgebra::UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(q[0], q[1], q[2], q[3]));
    let mut steps: Vec<f64> = out
        .estimates
        .windows(2)
        .map(|w| {
            let (ka, kb) = (truth_index(&input, w[0].t), truth_index(&input, w[1].t));
            let truth = q(gt.q[ka]).inverse() * q(gt.q[kb]);
            let est = q(w[0].rotation).inverse() * q(w[1].rotation);
            truth.angle_to(&est).to_degrees()
        })
        .collect();
    steps.sort_by(f64::total_cmp);
    let p999 = steps[steps.len() * 999 / 1000];
    println!("frame-to-frame rotation error: 99.9th percentile {p999:.2}°, largest {:.2}°", steps[steps.len() - 1]);
    assert!(p999 < 1.0, "{p999}°");
}

/// Largest displacement \[m\] of the estimate from its position at `from`
/// over the frames in `[from, to]` \[s\].
fn displacement(out: &VioResult, from: f64, to: f64) -> f64 {
    let mut frames = out.estimates.iter().filter(|e| e.t >= from && e.t <= to);
    let p0 = nalgebra::Vector3::from(frames.next().expect("frames in the span").position);
    frames.map(|e| (nalgebra::Vector3::from(e.position) - p0).norm()).fold(0.0, f64::max)
}

/// A walk that stops twice on the way: the estimate holds still while the
/// camera does and walks on afterwards (rest is detected anew at each stop:
/// 0.023 and 0.019 m of motion, 7–8 mm/s; without rest detection the first
/// stop moved 0.042 m at 32 mm/s).
#[test]
fn a_stop_and_go_walk_holds_still_at_each_stop() {
    let cfg = SimConfig { duration_s: Some(60.0), pauses_s: vec![[20.0, 4.0], [40.0, 3.0]], ..SimConfig::default() };
    let sim = simulate(Scenario::Walk, &cfg, 1).unwrap();
    assert_eq!(sim.static_intervals, vec![[21.0, 25.0], [41.0, 44.0]]);
    assert_eq!(sim.motion.duration(), 60.0 + 4.0 + 3.0 + 2.0);
    for (scenario, pauses) in [(Scenario::Static, vec![[20.0, 4.0]]), (Scenario::Walk, vec![[20.0, 4.0], [21.0, 1.0]])]
    {
        let err = simulate(scenario, &SimConfig { pauses_s: pauses, ..cfg.clone() }, 1).err().unwrap().to_string();
        assert!(err.starts_with("pauses_s: "), "{err}");
    }
    let (input, opts) = (VioInput::from_simulation(&sim).unwrap(), VioOptions::for_simulation(&cfg));
    let (out, s) = run_without_resets(&input, &opts, 20.0);
    assert_eq!(s.returns_to_start, Some(true));
    assert!(s.closed_loop_percent() < 0.5, "{} %", s.closed_loop_percent());
    for [a, b] in &sim.static_intervals {
        // The first 0.5 s (`zero_velocity_span_s`) of a stop still moves as the velocity
        // estimate does at the stop; after it, the stop is detected.
        let from = a + 0.5;
        let (all, detected) = (displacement(&out, *a, *b), displacement(&out, from, *b));
        let speeds: Vec<f64> = out
            .estimates
            .iter()
            .filter(|e| e.t >= from && e.t <= *b)
            .map(|e| nalgebra::Vector3::from(e.velocity).norm())
            .collect();
        let mean_speed = speeds.iter().sum::<f64>() / speeds.len() as f64;
        println!(
            "stop {a}–{b} s: the estimate moves {all:.3} m, {detected:.3} m once at rest, at {:.1} mm/s on average",
            mean_speed * 1e3
        );
        assert!(all < 0.05 && detected < 0.03 && mean_speed < 0.01, "{all} m, {detected} m, {mean_speed} m/s");
    }
}

/// The 2-minute walk of seed 12 once marginalized a landmark no factor
/// constrained next to a tight gyro-bias random walk: the prior lost every row
/// (NaN in its eigen-decomposition), the window's position slid by metres from
/// one solve to the next, and the loop closed within 21 %.
#[test]
fn a_window_with_an_unconstrained_landmark_keeps_its_prior() {
    let (input, opts) = walk(120.0, 12);
    let (_, s) = run_without_resets(&input, &opts, 30.0);
    // 0.59 % and ATE 0.041 m now (the worst of the twelve 2-minute walks);
    // 20.7 % and 2.2 m with the prior lost.
    assert!(s.closed_loop_percent() < 1.0, "{} %", s.closed_loop_percent());
    assert!(s.ate_rmse_m.unwrap() < 0.1, "ATE {:?}", s.ate_rmse_m);
}

/// The CI benchmark's 30 s flight (the 60 s one time-compressed): new
/// landmarks were checked in front of the cameras at the rays' midpoint, not
/// where the window holds them (on the anchor's ray); one could lie behind an
/// older camera, the next solve failed at its start, and the window was reset
/// three times (ATE 0.44 m).
#[test]
fn a_fast_flight_triangulates_only_landmarks_in_front_of_every_camera() {
    let (input, opts) = simulated(Scenario::Flight, 30.0, 11);
    let (_, s) = run_without_resets(&input, &opts, 10.0);
    assert!(s.ate_rmse_m.unwrap() < 0.1, "ATE {:?}", s.ate_rmse_m);
}

#[test]
fn real_euroc_v1_01_with_eqvio_tracks() {
    let (Some(csv), Some(gt)) =
        (common::shared("euroc/eqvio_V1_01_30s.csv"), common::shared("euroc/groundtruth/V1_01_easy.csv"))
    else {
        return;
    };
    let input = read_eqvio(&csv, Some(&gt)).unwrap();
    assert_eq!(input.imu.t.len(), 6001);
    assert_eq!(input.frames.len(), 601);
    let opts = VioOptions::with_pixel_sigma(1.93);
    let (out, s) = run_without_resets(&input, &opts, 10.0);
    assert!(s.ate_rmse_m.unwrap() < 0.15, "ATE {:?}", s.ate_rmse_m);
    assert!(s.bias_rmse_gyro.unwrap() < 0.005, "{:?}", s.bias_rmse_gyro);
    assert!(s.bias_rmse_accel.unwrap() < 0.2, "{:?}", s.bias_rmse_accel);
    // The drone vibrates while it sits: reported, not silently absorbed.
    assert!(out.warnings.iter().any(|w| w.contains("vibration")));
}

#[test]
fn frames_without_features_warn_and_recover() {
    let (mut input, opts) = walk(40.0, 5);
    for f in input.frames.iter_mut().filter(|f| f.t > 15.0 && f.t < 17.0) {
        f.features.clear();
    }
    let out = run(&input, &opts, None).unwrap();
    assert!(finite(&out));
    assert!(out.warnings.iter().any(|w| w.contains("vision lost at 15.0")), "{:?}", out.warnings);
    assert!(out.warnings.iter().any(|w| w.contains("features back at 17.0")), "{:?}", out.warnings);
    // One blind span, from the first frame without features to the first with them.
    assert_eq!(out.blind_spans.len(), 1, "{:?}", out.blind_spans);
    let [a, b] = out.blind_spans[0];
    assert!((a - 15.0).abs() < 0.06 && (b - 17.0).abs() < 0.06, "{a} {b}");
    let s = summarize(&input, &opts, &out, 10.0);
    assert!(s.ate_rmse_m.unwrap() < 0.5, "{}", s.table());
}

#[test]
fn imu_gaps_warn_and_recover() {
    let (mut input, opts) = walk(40.0, 6);
    let keep: Vec<usize> =
        (0..input.imu.t.len()).filter(|&i| !(input.imu.t[i] > 12.0 && input.imu.t[i] < 12.2)).collect();
    input.imu.t = keep.iter().map(|&i| input.imu.t[i]).collect();
    input.imu.gyro = keep.iter().map(|&i| input.imu.gyro[i]).collect();
    input.imu.acc = keep.iter().map(|&i| input.imu.acc[i]).collect();
    let out = run(&input, &opts, None).unwrap();
    assert!(finite(&out));
    assert!(out.warnings.iter().any(|w| w.contains("IMU gap")), "{:?}", out.warnings);
}

#[test]
#[ignore = "long trial: CI runs it (cargo test -- --ignored)"]
fn pure_rotation_triangulates_nothing_and_stays_finite() {
    let (mut input, opts) = walk(40.0, 7);
    // Every feature keeps its pixel: no parallax at all (a camera that only rotates
    // about its centre sees the same — no depth can be triangulated). 15 s of it: the
    // start in motion is tried again at every frame (docs/vio.md, "Starting").
    input.frames.retain(|f| f.t < 15.0);
    let first = input.frames[0].features.clone();
    for f in input.frames.iter_mut() {
        f.features = first.clone();
    }
    let out = run(&input, &opts, None).unwrap();
    assert!(finite(&out));
    assert!(out.estimates.iter().all(|e| e.landmarks == 0 || e.t > 0.0));
}

#[test]
fn a_static_start_refuses_a_moving_recording_with_advice() {
    let (mut input, opts) = walk_started_in_motion(40.0, 8, 5.0);
    input.frames.retain(|f| f.t < 8.0);
    let mut opts = opts;
    opts.init.mode = Init::Static;
    let err = run(&input, &opts, None).unwrap_err().to_string();
    assert!(err.contains("at rest") && err.contains("--init auto") && err.contains("--init-from-groundtruth"), "{err}");
    // In motion but without features there is nothing to observe scale with.
    for f in &mut input.frames {
        f.features.clear();
    }
    opts.init.mode = Init::Motion;
    let err = run(&input, &opts, None).unwrap_err().to_string();
    assert!(err.contains("observes scale") && err.contains("landmarks"), "{err}");
}

#[test]
fn a_start_in_motion_is_initialized_by_the_closed_form() {
    let (input, opts) = walk_started_in_motion(60.0, 8, 6.0);
    assert_eq!(opts.init.mode, Init::Auto);
    let (out, s) = run_without_resets(&input, &opts, 20.0);
    assert!(out.warnings.iter().any(|w| w.contains("initialized in motion")), "{:?}", out.warnings);
    // The first state against the truth: speed and tilt (yaw is the gauge).
    let gt = input.groundtruth.as_ref().unwrap();
    let first = &out.estimates[0];
    let k = truth_index(&input, first.t);
    // True velocity by central difference of the ground-truth positions.
    let p = |i: usize| nalgebra::Vector3::from(gt.p[i]);
    let v_true = (p(k + 1) - p(k - 1)) / ((gt.t_ns[k + 1] - gt.t_ns[k - 1]) as f64 * 1e-9);
    let up = |q: [f64; 4]| {
        q_body_up(&nalgebra::UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(q[0], q[1], q[2], q[3])))
    };
    let tilt_deg = up(first.rotation).angle(&up(gt.q[k])).to_degrees();
    let dv = (nalgebra::Vector3::from(first.velocity).norm() - v_true.norm()).abs();
    println!("initial speed error {dv:.3} m/s of {:.3} m/s, tilt error {tilt_deg:.2}°", v_true.norm());
    assert!(v_true.norm() > 0.05, "the start must be in motion: {v_true}");
    // Within the start's priors (0.1 m/s, 2° per axis; the closed form takes the
    // biases as zero, and this IMU's accelerometer bias alone tilts by 0.7°).
    assert!(dv < 0.1 && tilt_deg < 4.0, "speed error {dv}, tilt error {tilt_deg}°");
    // The window then keeps the tilt as well as after a start at rest.
    let half = &out.estimates[out.estimates.len() / 2..];
    let tilt2: f64 =
        half.iter().map(|e| up(e.rotation).angle(&up(gt.q[truth_index(&input, e.t)])).to_degrees().powi(2)).sum();
    let tilt_rms = (tilt2 / half.len() as f64).sqrt();
    println!("tilt error over the second half: {tilt_rms:.2}° RMS");
    // (0.8° here.)
    assert!(tilt_rms < 2.5, "{tilt_rms}°");
    assert!(s.ate_rmse_m.unwrap() < 0.15, "ATE {:?}", s.ate_rmse_m);
}

/// A 40 s walk seen by two cameras 0.11 m apart (EuRoC's baseline).
fn stereo_walk(seed: u64) -> (SimConfig, tumble::sim::Simulation) {
    let mut cfg = SimConfig { duration_s: Some(40.0), ..SimConfig::default() };
    cfg.camera.stereo_baseline_m = 0.11;
    let sim = simulate(Scenario::Walk, &cfg, seed).unwrap();
    (cfg, sim)
}

/// A stereo folder as `tumble sim walk --stereo-baseline 0.11` writes it: the
/// second camera's matches (cam0/tracks_cam1.csv, cam1/sensor.yaml) make the
/// closed form observe scale from the first 1.5 s of the slow start, where
/// cam0 alone has to wait for faster walking. Without the second camera
/// (`--mono`) the same folder initializes later.
#[test]
fn stereo_matches_initialize_the_slow_start() {
    let (cfg, sim) = stereo_walk(3);
    let dir = std::env::temp_dir().join(format!("tumble_stereo_{}", std::process::id()));
    tumble::sim::write_asl(&sim, &dir).unwrap();
    let mut opts = VioOptions::for_simulation(&cfg);
    opts.init.mode = Init::Motion;
    let first_estimate = |stereo: bool| {
        let ds = tumble::io::asl::read_asl(&dir, &Default::default()).unwrap();
        let input = VioInput::from_dataset(ds, None, None, stereo).unwrap();
        assert_eq!(input.stereo.is_some(), stereo);
        let out = run(&input, &opts, None).unwrap();
        assert_eq!(out.resets, 0, "{:?}", out.warnings);
        let init = out.warnings.iter().find(|w| w.contains("initialized in motion")).cloned().unwrap_or_default();
        println!("stereo {stereo}: {init}");
        assert_eq!(init.contains("stereo matches"), stereo, "{init}");
        let first = &out.estimates[0];
        let truth = sim.motion.at(first.t);
        let v = nalgebra::Vector3::from(first.velocity);
        (first.t, (v.norm() - truth.velocity.norm()).abs())
    };
    let (t_stereo, dv_stereo) = first_estimate(true);
    let (t_mono, _) = first_estimate(false);
    println!("first state at {t_stereo:.2} s with stereo (speed error {dv_stereo:.3} m/s), {t_mono:.2} s without");
    assert!(t_stereo < t_mono, "stereo {t_stereo} s, mono {t_mono} s");
    // Within the start's prior (0.1 m/s); the closed form takes the biases as
    // zero (here, at rest, it gives 0.08 m/s).
    assert!(dv_stereo < 0.1, "speed error {dv_stereo} m/s");
    std::fs::remove_dir_all(&dir).ok();
}

/// `window.stereo` (the default): the second camera's matches also enter
/// the window (more reprojection rows than cam0's alone) and the run stays
/// sound. Measured: ATE 0.0093 m against 0.0125 m with cam1 in the
/// initialization only (docs/findings/vio.md, "Stereo in the window").
#[test]
fn stereo_matches_in_the_window() {
    let (cfg, sim) = stereo_walk(3);
    let input = VioInput::from_simulation(&sim).unwrap();
    let rows_and_ate = |stereo_window: bool| {
        let mut opts = VioOptions::for_simulation(&cfg);
        opts.window.stereo = stereo_window;
        let out = run(&input, &opts, None).unwrap();
        assert_eq!(out.resets, 0, "{:?}", out.warnings);
        let s = summarize(&input, &opts, &out, 10.0);
        println!("stereo window {stereo_window}:\n{}", s.table());
        (s.residuals.reprojection_rows, s.ate_rmse_m.unwrap())
    };
    let (rows_mono, _) = rows_and_ate(false);
    let (rows_stereo, ate) = rows_and_ate(true);
    assert!(rows_stereo as f64 > 1.3 * rows_mono as f64, "{rows_stereo} rows with stereo, {rows_mono} without");
    assert!(ate < 0.15, "ATE {ate} m");
}

/// The online camera calibration estimates cam0 alone: with a second camera
/// the run keeps cam1's matches out of the window (a warning says so)
/// instead of refusing the input, and estimates no more reprojection rows
/// than cam0's alone give.
#[test]
fn online_calibration_keeps_the_second_camera_out_of_the_window() {
    let (cfg, sim) = stereo_walk(3);
    let input = VioInput::from_simulation(&sim).unwrap();
    let mut opts = VioOptions::for_simulation(&cfg);
    opts.camera.extrinsics = tumble::vio::Estimate::On;
    let out = run(&input, &opts, None).unwrap();
    assert!(out.warnings.iter().any(|w| w.contains("first camera alone")), "{:?}", out.warnings);
    opts.window.stereo = false;
    let mono = run(&input, &opts, None).unwrap();
    assert_eq!(out.residuals.reprojection_rows, mono.residuals.reprojection_rows);
}

/// The second camera's files are checked like the first's: a match at a time
/// cam0 has no observation names its line; matches without cam1/ are refused.
#[test]
fn malformed_stereo_matches_name_file_and_line() {
    let (_, sim) = stereo_walk(1);
    let dir = std::env::temp_dir().join(format!("tumble_stereo_bad_{}", std::process::id()));
    tumble::sim::write_asl(&sim, &dir).unwrap();
    let matches = dir.join("mav0/cam0/tracks_cam1.csv");
    let text = std::fs::read_to_string(&matches).unwrap();
    let load = || {
        let ds = tumble::io::asl::read_asl(&dir, &Default::default()).unwrap();
        VioInput::from_dataset(ds, None, None, true).map(|_| ()).unwrap_err().to_string()
    };
    // The last observation moved 1 ns past the last frame.
    let mut lines: Vec<String> = text.lines().map(String::from).collect();
    let n = lines.len();
    let (t, rest) = lines[n - 1].split_once(',').unwrap();
    lines[n - 1] = format!("{},{rest}", t.parse::<i64>().unwrap() + 1);
    std::fs::write(&matches, lines.join("\n") + "\n").unwrap();
    let err = load();
    assert!(err.contains(&format!("tracks_cam1.csv:{n}")) && err.contains("no cam0 observation"), "{err}");
    std::fs::write(&matches, &text).unwrap();
    std::fs::remove_dir_all(dir.join("mav0/cam1")).unwrap();
    let err = load();
    assert!(err.contains("tracks_cam1.csv") && err.contains("cam1/"), "{err}");
    std::fs::remove_dir_all(&dir).ok();
    // Inputs built in code are checked too: one match list per frame, two
    // cameras apart.
    let mut input = VioInput::from_simulation(&sim).unwrap();
    input.check().unwrap();
    let st = input.stereo.as_mut().unwrap();
    st.features.pop();
    assert!(input.check().unwrap_err().to_string().contains("features for"));
    let mut input = VioInput::from_simulation(&sim).unwrap();
    input.stereo.as_mut().unwrap().body_from_camera = input.body_from_camera;
    assert!(input.check().unwrap_err().to_string().contains("no stereo baseline"));
}

/// The world's up direction seen in the body frame.
fn q_body_up(q: &nalgebra::UnitQuaternion<f64>) -> nalgebra::Vector3<f64> {
    q.inverse() * nalgebra::Vector3::z()
}

#[test]
fn malformed_eqvio_files_name_file_and_line() {
    let dir = std::env::temp_dir().join(format!("tumble_vio_bad_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let header = "row_type,t_abs,t_rel,seq,frame_idx,landmark_id,gx,gy,gz,ax,ay,az,bgx,bgy,bgz,bax,bay,baz,u_norm,v_norm,key,value\n";
    for (body, want) in [
        ("imu,1.0,0,1,,,0.1,0.2,nan,0,0,9.8,0,0,0,0,0,0,,,,\n", "bad.csv:2"),
        ("imu,1.0,0,1,,,0.1,0.2\n", "columns"),
        ("bogus,1\n", "unknown row type"),
        ("vision_feature,1.0,0,0,0,-3,,,,,,,,,,,,,0.1,0.2,,\n", "landmark_id"),
    ] {
        let f = dir.join("bad.csv");
        std::fs::write(&f, format!("{header}{body}")).unwrap();
        let e = read_eqvio(&f, None).unwrap_err().to_string();
        assert!(e.contains("bad.csv") && e.contains(want), "{e}");
    }
}

/// An ASL folder with images but no tracks: the estimator says how to get
/// tracks, and without the feature `opencv` the frontend names it (with the
/// feature, `tests/frontend.rs` tracks the same folder into the estimator).
#[cfg(not(feature = "opencv"))]
#[test]
fn image_folders_name_the_frontend_they_need() {
    let Some(micro) = common::shared("euroc/V1_01_easy_micro") else { return };
    let err = VioInput::from_asl(&micro, None).unwrap_err().to_string();
    assert!(err.contains("tracks.csv") && err.contains("frontend"), "{err}");
    let ds = tumble::io::asl::read_asl(&micro, &Default::default()).unwrap();
    let opts = tumble::vio::frontend::FrontendOptions::default();
    let err = tumble::vio::frontend::track_asl(&ds, 0, &opts, &mut |_, _| {}).unwrap_err().to_string();
    assert!(err.contains("--features opencv") && err.contains("libopencv-dev"), "{err}");
}

/// Real V1_02 IMU (40 s) with a simulated camera flying its ground-truth path
/// (the shared data hold no V1_02 images): real inertial errors, simulated vision.
#[test]
fn real_v1_02_imu_with_a_simulated_camera() {
    let Some(dir) = common::shared("euroc/V1_02_medium_40s") else { return };
    let ds = tumble::io::asl::read_asl(&dir, &Default::default()).unwrap();
    let cam = tumble::sim::CameraSettings::default();
    let (input, notes) = VioInput::from_dataset_with_simulated_camera(ds, None, &cam, 1).unwrap();
    println!("{notes:?}");
    let opts = VioOptions::default();
    let out = run(&input, &opts, None).unwrap();
    let s = summarize(&input, &opts, &out, 10.0);
    println!("V1_02, 40 s real IMU + simulated camera:\n{}", s.table());
    assert_eq!(s.resets, 0);
    assert!(s.duration_s > 35.0 && s.ate_rmse_m.unwrap() < 0.15, "{}", s.table());
    assert!(s.bias_rmse_gyro.unwrap() < 3e-3 && s.bias_rmse_accel.unwrap() < 0.15, "{}", s.table());
    // Without a ground truth there is nothing to fly along.
    let mut bare = tumble::io::asl::read_asl(&dir, &Default::default()).unwrap();
    bare.groundtruth = None;
    let err = VioInput::from_dataset_with_simulated_camera(bare, None, &cam, 1).unwrap_err().to_string();
    assert!(err.contains("no ground truth"), "{err}");
}

/// `tumble vio` refuses keyframe settings that cannot work, naming the option,
/// before it reads any input.
#[test]
fn vio_command_refuses_bad_keyframe_settings() {
    let out = std::env::temp_dir().join(format!("tumble_vio_keyframes_{}", std::process::id()));
    for (arg, expected) in [
        ("--keyframe-parallax=0", "--keyframe-parallax must be a positive"),
        ("--keyframe-interval=-1", "--keyframe-interval must be a positive"),
        ("--keyframe-parallax=nan", "--keyframe-parallax must be a positive"),
        ("--keyframe-min-interval=1", "--keyframe-min-interval must be at least 0 and shorter than"),
    ] {
        let o = std::process::Command::new(env!("CARGO_BIN_EXE_tumble"))
            .args(["vio", "/nonexistent/walk", "--out", out.to_str().unwrap(), arg])
            .output()
            .unwrap();
        let e = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success() && e.contains(expected), "{arg}: {e}");
    }
    assert!(!out.exists(), "nothing is written for a refused run");
}

/// The paper's walk as a person walks it: a lap of the simulated corridor at
/// about 1 m/s (68 m in 90 s) closes within 0.50 % (0.35 m, measured
/// 2026-11-29; seed 1 moves by tens of % with any change to the estimator)
/// of the path, against 1.3 km for the IMU alone. Over 6 minutes (five laps,
/// 347 m) the corridor walks close within 0.1–0.2 % (docs/vio.md).
#[test]
fn a_corridor_lap_closes_the_loop() {
    let (input, opts) = simulated(Scenario::Corridor, 90.0, 1);
    let (_, s) = run_without_resets(&input, &opts, 30.0);
    assert_eq!(s.returns_to_start, Some(true));
    let truth = s.groundtruth_distance_m.unwrap();
    assert!((67.8..75.0).contains(&truth), "{truth} m");
    assert!(s.closed_loop_percent() < 1.0, "{} %", s.closed_loop_percent());
    assert!(s.imu_only_closed_loop_error_m > 100.0 * s.closed_loop_error_m);
    assert!(s.ate_rmse_m.unwrap() < 0.3, "{:?}", s.ate_rmse_m);
}

/// A simulated walk written as an ASL folder, with one file changed by `edit`, opened as `tumble vio` does.
fn open_edited(name: &str, edit: impl Fn(&std::path::Path)) -> Result<VioInput, String> {
    let dir = std::env::temp_dir().join(format!("tumble-vio-input-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let cfg = SimConfig { duration_s: Some(40.0), ..SimConfig::default() };
    tumble::sim::simulate_and_write(Scenario::Walk, &cfg, 2, &dir).unwrap();
    edit(&dir.join("mav0"));
    let opened = (|| -> Result<VioInput, Box<dyn std::error::Error>> {
        let ds = tumble::io::asl::read_asl(&dir, &Default::default())?;
        let mut input = VioInput::from_dataset(ds, None, None, false)?;
        if let Some(w) = input.limit_to_imu()? {
            return Err(w.into());
        }
        Ok(input)
    })();
    std::fs::remove_dir_all(&dir).unwrap();
    opened.map_err(|e| e.to_string())
}

/// Rewrite every data line of a CSV with `f` (header kept).
fn rewrite(path: &std::path::Path, f: impl Fn(&str) -> Option<String>) {
    let text = std::fs::read_to_string(path).unwrap();
    let out: Vec<String> =
        text.lines().filter_map(|l| if l.starts_with('#') { Some(l.to_string()) } else { f(l) }).collect();
    std::fs::write(path, out.join("\n") + "\n").unwrap();
}

#[test]
fn camera_and_imu_that_do_not_fit_together_are_named() {
    assert!(open_edited("clean", |_| {}).is_ok());
    // The IMU stops 15 s before the camera: the frames after it are dropped, and said so.
    let e = open_edited("short_imu", |m| {
        rewrite(&m.join("imu0/data.csv"), |l| {
            let t: i64 = l.split(',').next().unwrap().parse().unwrap();
            (t < 1_700_000_025_000_000_000).then(|| l.to_string())
        })
    })
    .unwrap_err();
    assert!(e.contains("after the IMU's samples are not used"), "{e}");
    // IMU stamps on another clock (seconds since boot, in ns): no overlap.
    let e = open_edited("clocks", |m| {
        rewrite(&m.join("imu0/data.csv"), |l| {
            let (t, rest) = l.split_once(',').unwrap();
            Some(format!("{},{rest}", t.parse::<i64>().unwrap() - 1_699_999_000_000_000_000))
        })
    })
    .unwrap_err();
    assert!(e.contains("do not overlap in time"), "{e}");
    // Tracks stamped in microseconds.
    let e = open_edited("track_units", |m| {
        rewrite(&m.join("cam0/tracks.csv"), |l| {
            let (t, rest) = l.split_once(',').unwrap();
            Some(format!("{},{rest}", t.parse::<i64>().unwrap() / 1000))
        })
    })
    .unwrap_err();
    assert!(e.contains("tracks.csv:2:") && e.contains("matches no image"), "{e}");
    // A 0×0 camera.
    let e = open_edited("resolution", |m| {
        let y = m.join("cam0/sensor.yaml");
        let text = std::fs::read_to_string(&y).unwrap().replace("resolution: [752, 480]", "resolution: [0, 0]");
        std::fs::write(&y, text).unwrap();
    })
    .unwrap_err();
    assert!(e.contains("resolution must be"), "{e}");
}

/// EuRoC's calibration sequence with its real corners as features (track id =
/// corner id) and EuRoC's calibration of cam0, against a per-frame PnP of the
/// corners: within 2 cm (measured 0.016 m, rotation RMSE 0.86° — the issue's
/// 0.5° is not reached). Its start is in motion with the raw IMU's 0.08 rad/s
/// gyro bias: held at 0 ± 5e-3 rad/s the start drifted 1 m and 8° (ATE 0.08 m).
#[test]
fn imu_april_with_its_corners_as_features_tracks_the_pnp_poses() {
    let (Some(dir), Some(cams)) = (common::shared("euroc/imu_april"), common::shared("euroc/V1_01_easy_micro")) else {
        return;
    };
    let (input, truth) = VioInput::from_target_recording(&dir, &dir.join("target.yaml"), &cams).unwrap();
    assert!(truth.posed > 1300 && truth.median_rms_px < 0.6, "{truth:?}");
    let mut opts = VioOptions::default();
    input.apply_noise(None, &mut opts.noise.imu);
    let out = run(&input, &opts, None).unwrap();
    assert_eq!(out.resets, 0, "{:?}", out.warnings);
    let gt = input.groundtruth.as_ref().unwrap();
    let eval_opts = tumble::eval::EvalOptions { alignment: tumble::eval::Alignment::Se3, ..Default::default() };
    let ev = tumble::eval::evaluate(&tumble::vio::trajectory(&input, &out), None, gt, &eval_opts).unwrap();
    println!("ATE {:.4} m, rotation RMSE {:.2}°", ev.metrics.ate_rmse_m, ev.metrics.rotation_rmse_deg);
    assert!(ev.metrics.ate_rmse_m < 0.02, "ATE {}", ev.metrics.ate_rmse_m);
    assert!(ev.metrics.rotation_rmse_deg < 1.0, "rotation RMSE {}°", ev.metrics.rotation_rmse_deg);
    // The target leaves the image for a second at 55.8 s: reported as a blind span.
    assert!(out.blind_spans.iter().any(|[a, b]| *a > 55.0 && b - a > 0.5), "{:?}", out.blind_spans);
}

/// A whole EuRoC sequence (real IMU, a simulated camera along the ground
/// truth): the rotors shake the IMU far beyond its datasheet figures; the
/// window's IMU residuals show it in the accelerometer and its noise in use
/// rises (measured: ×9.6), with no reset. The gyro's residuals stay within
/// its datasheet figure (measured 1.36e-4 against 1.70e-4 rad/s/√Hz): the
/// ×2.9 read with the landmarks' bearings fixed at their anchor pixels was
/// that pixel noise, which moved the keyframes' rotations (docs/findings/vio.md).
#[test]
fn a_whole_euroc_sequence_measures_its_vibration_in_flight() {
    let Some(seq) = common::shared("euroc/full_imu/V1_02_medium") else { return };
    let source = tumble::vio::VioSource { simulate_camera: Some(1), ..Default::default() };
    let input = tumble::vio::VioInput::open(&seq, &source, &mut |_, _| {}).unwrap().input;
    let opts = VioOptions::default();
    let (out, s) = run_without_resets(&input, &opts, 10.0);
    let noise = out.noise.expect("measured");
    println!("{}", noise.line());
    assert!(noise.in_use[1] > 3.0 * noise.given[1], "{}", noise.line());
    // The bias σ that rest on the datasheet's walk are flagged (docs/vio.md,
    // "The bias random walk in flight").
    assert!(s.warnings.iter().any(|w| w.contains("bias σ may then be several times too small")), "{:?}", s.warnings);
    let m = &s.evaluation.as_ref().unwrap().metrics;
    let (g, a) = (m.bias_nees_gyro_axes.unwrap(), m.bias_nees_accel_axes.unwrap());
    let mean = (g.iter().sum::<f64>() + a.iter().sum::<f64>()) / 6.0;
    println!("bias NEES gyro {g:?}, accel {a:?}, mean {mean:.2}");
    // Measured (2026-12-05): 8.8 with the noise raised, 18.6 with the
    // datasheet's kept (`--fixed-noise`); 7.5 with keyframes at every
    // other frame (no `window.keyframe_min_interval_s`), which made this
    // flight's windows 0.6 s long.
    assert!(mean < 10.0, "bias NEES mean {mean}");
    assert!(s.ate_rmse_m.unwrap() < 0.08, "ATE {:?}", s.ate_rmse_m);
}

/// MH_03 and the noise its platform shows in flight measured on another
/// flight (V2_01, `tumble allan --groundtruth`), when the shared data hold both.
fn machine_hall_and_flight_noise(gravity: f64) -> Option<(std::path::PathBuf, tumble::io::ImuNoise)> {
    let seq = common::shared("euroc/full_imu/MH_03_medium")?;
    let other = common::shared("euroc/full_imu/V2_01_easy")?;
    let ds = tumble::io::asl::read_asl(&other, &Default::default()).unwrap();
    let truth = ds.groundtruth.as_ref().expect("V2_01's ground truth");
    let (noise, _) = tumble::allan::in_motion::noise_in_motion(&ds.imu, truth, gravity).unwrap();
    Some((seq, noise))
}

/// The path's length against the truth's and the windows' length errors,
/// printed, then held to `path_within` (relative) and `rms_below` (σ).
fn assert_path_and_windows(s: &tumble::vio::Summary, path_within: f64, rms_below: f64) {
    let (path, truth) = (s.distance_m, s.groundtruth_distance_m.expect("a ground truth"));
    let windows = s.window_length.as_ref().expect("windows measured");
    println!("path {path:.2} m of {truth:.2} m, ATE {:?}; {}", s.ate_rmse_m, windows.line());
    assert!((path / truth - 1.0).abs() < path_within, "path {path} m against {truth} m");
    assert!(windows.normalized_error_rms.unwrap() < rms_below, "{}", windows.line());
}

/// A Machine Hall flight (MH_03, 131 s, 131 m; EuRoC's Leica ground truth)
/// with the camera simulated along it keeps its scale. The tracker's
/// positions hold accelerations above 2 Hz that the IMU does not feel; a
/// camera flying them made the estimate 17 % short (ATE 0.90 m) with these
/// options. The camera now flies the body's path (the IMU's motion above the
/// cut: `sim::replay_bands`). Measured (release, 2026-12-05, keyframes at
/// least 0.15 s apart): path +0.90 %, ATE 0.106 m, 0 resets (−0.86 % and
/// 0.108 m without that interval; −1.7 % and 0.19 m with `--inverse-depth-only` earlier).
#[test]
fn a_machine_hall_flight_keeps_its_scale() {
    let Some(seq) = common::shared("euroc/full_imu/MH_03_medium") else { return };
    let source = tumble::vio::VioSource { simulate_camera: Some(1), ..Default::default() };
    let opened = tumble::vio::VioInput::open(&seq, &source, &mut |_, _| {}).unwrap();
    let cut = opened.notes.iter().find(|n| n.contains("the IMU's own motion above")).expect("a cut is noted");
    println!("{cut}");
    assert!(cut.contains("above 2.0 Hz"), "{cut}");
    let opts = VioOptions::default();
    let (_, s) = run_without_resets(&opened.input, &opts, 10.0);
    let (path, truth) = (s.distance_m, s.groundtruth_distance_m.expect("a ground truth"));
    println!("path {path:.2} m of {truth:.2} m, ATE {:?}", s.ate_rmse_m);
    assert!((path / truth - 1.0).abs() < 0.03, "path {path} m against {truth} m");
    assert!(s.ate_rmse_m.unwrap() < 0.3, "ATE {:?}", s.ate_rmse_m);
}

/// The same Machine Hall flight with two cameras, as EuRoC records it (cam1
/// 0.11 m to cam0's right; the shared copy keeps no camera calibration, so
/// the baseline is given here as `tumble vio` takes it from a full EuRoC
/// folder), and the noise its IMU shows in flight measured on another
/// flight (V2_01, `tumble allan --groundtruth`): the baseline fixes the far
/// landmarks' depths and the scale holds, its σ covering its error. Bounds:
/// ATE ≤ 0.15 m, path within 1 %, no reset, and the windows' length errors
/// within 2 of their σ (RMS). Measured (release, 2026-12-05): ATE 0.024 m,
/// path 130.31 m of 130.69 m, windows −0.07 % with RMS 0.59 σ; one camera
/// with the same noise: ATE 0.128 m, path −0.02 %, windows −0.21 % with RMS 1.39 σ.
#[test]
fn a_machine_hall_flight_with_two_cameras_and_another_flights_noise_keeps_its_scale() {
    let mut opts = VioOptions::default();
    let Some((seq, noise)) = machine_hall_and_flight_noise(opts.noise.gravity) else { return };
    let source = tumble::vio::VioSource {
        simulate_camera: Some(1),
        simulated_stereo_baseline_m: Some(0.11),
        ..Default::default()
    };
    let input = tumble::vio::VioInput::open(&seq, &source, &mut |_, _| {}).unwrap().input;
    input.apply_noise(Some(noise), &mut opts.noise.imu);
    let (_, s) = run_without_resets(&input, &opts, 10.0);
    assert_path_and_windows(&s, 0.01, 2.0);
    assert!(s.ate_rmse_m.unwrap() < 0.15, "ATE {:?}", s.ate_rmse_m);
}

/// The hall's single-camera windows are honest when the IMU is what the
/// estimator is told: an IMU with V2_01's flight noise and nothing else
/// (`ImuNoise::noise_only_model`), flown along MH_03's ground truth smoothed
/// by 50 ms, one simulated camera. The real IMU in the same setup (the test
/// above with one camera) gives windows at 1.39 σ RMS; this one 0.82 σ
/// (release, 2026-12-06; seeds 1–3 of the IMU: 0.72–0.97), the path within
/// 0.1 %: what the real flight leaves uncovered is its IMU's, not the
/// estimator's (docs/findings/vio.md). Bounds: RMS < 1.5, path within 1 %,
/// no reset.
#[test]
fn a_halls_windows_with_one_camera_are_honest_when_the_imu_is_what_it_is_told() {
    let mut opts = VioOptions::default();
    let Some((seq, noise)) = machine_hall_and_flight_noise(opts.noise.gravity) else { return };
    let mut ds = tumble::io::asl::read_asl(&seq, &Default::default()).unwrap();
    let path = tumble::sim::SmoothedReplay::new(ds.groundtruth.as_ref().expect("MH_03's ground truth"), 0.05).unwrap();
    let (imu, truth) = path.simulate(&noise.noise_only_model(), opts.noise.gravity, 1);
    (ds.imu, ds.groundtruth) = (imu, Some(truth));
    let cam = tumble::sim::CameraSettings::default();
    let (input, _) = VioInput::from_dataset_with_simulated_camera(ds, None, &cam, 1).unwrap();
    input.apply_noise(Some(noise), &mut opts.noise.imu);
    let (_, s) = run_without_resets(&input, &opts, 10.0);
    assert_path_and_windows(&s, 0.01, 1.5);
}

/// A blackout in a real flight (V1_02's IMU, the simulated camera's features
/// removed for 3 s from 30 s on): reported where it starts and ends, flown on
/// the IMU alone without a reset, and once the features return the estimate
/// is as good as without the blackout. Measured: blind 30.05–33.0 s; from
/// 35 s on (aligned by itself) ATE 0.021 m, against 0.056 m over the whole
/// run without the blackout; orientation error over 30–35 s 0.21° RMS once
/// aligned by the orientations. With 10 s blind (not tested here): 0 resets
/// on V1_02, V1_03, V2_01 and imu_april too, ATE from 2 s after the return
/// 0.06–0.11 m (docs/vio.md).
#[test]
fn a_blackout_in_a_real_flight_is_reported_and_survived() {
    let Some(seq) = common::shared("euroc/full_imu/V1_02_medium") else { return };
    let source = tumble::vio::VioSource { simulate_camera: Some(1), ..Default::default() };
    let mut input = tumble::vio::VioInput::open(&seq, &source, &mut |_, _| {}).unwrap().input;
    for f in input.frames.iter_mut().filter(|f| f.t > 30.0 && f.t < 33.0) {
        f.features.clear();
    }
    let mut opts = VioOptions::default();
    input.apply_noise(None, &mut opts.noise.imu);
    let out = run(&input, &opts, None).unwrap();
    assert_eq!(out.resets, 0, "{:?}", out.warnings);
    assert!(out.warnings.iter().any(|w| w.starts_with("vision lost at 30.0")), "{:?}", out.warnings);
    assert!(out.warnings.iter().any(|w| w.starts_with("features back at 33.0")), "{:?}", out.warnings);
    assert!(
        matches!(out.blind_spans[..], [[a, b]] if (a - 30.0).abs() < 0.1 && (b - 33.0).abs() < 0.1),
        "{:?}",
        out.blind_spans
    );
    let gt = input.groundtruth.as_ref().unwrap();
    let segment = |from: f64, to: f64| {
        let mut part = out.clone();
        part.estimates.retain(|e| e.t > from && e.t <= to);
        let traj = tumble::vio::trajectory(&input, &part);
        tumble::eval::evaluate(&traj, None, gt, &tumble::eval::EvalOptions::default()).unwrap().metrics
    };
    let blind = segment(30.0, 35.0);
    let after = segment(35.0, f64::INFINITY);
    println!(
        "30-35 s: ATE {:.3} m, rotation {:.2}° (orientations aligned); from 35 s: ATE {:.3} m",
        blind.ate_rmse_m, blind.rotation_rmse_oriented_deg, after.ate_rmse_m
    );
    assert!(blind.rotation_rmse_oriented_deg < 1.0, "{blind:?}");
    assert!(after.ate_rmse_m < 0.04, "ATE after the blackout {} m", after.ate_rmse_m);
}
