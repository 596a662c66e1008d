//! The sliding-window VIO on simulated data with known truth, on real EuRoC
//! V1_01 (EqVIO's tracks), and on degenerate input.

mod common;

use tumble::sim::{simulate, Scenario, SimConfig};
use tumble::vio::{read_eqvio, run, summarize, VioInput, VioOptions};

fn walk(duration: f64, seed: u64) -> (VioInput, VioOptions) {
    let cfg = SimConfig { duration_s: Some(duration), ..SimConfig::default() };
    let sim = simulate(Scenario::Walk, &cfg, seed).unwrap();
    (VioInput::from_simulation(&sim).unwrap(), VioOptions::for_simulation(&cfg))
}

#[test]
fn simulated_walk_closes_the_loop_far_better_than_the_imu_alone() {
    let (input, opts) = walk(120.0, 3);
    let out = run(&input, &opts, None).unwrap();
    let s = summarize(&input, &opts, &out, 30.0);
    println!("{}", s.table());
    assert_eq!(s.returns_to_start, Some(true));
    assert_eq!(out.resets, 0, "{:?}", out.warnings);
    // Fused drift: about a percent of the path; IMU-only: orders of magnitude more.
    // (Rounding alone moves it: 0.89 % with nalgebra's dense Cholesky, 1.12 %
    // with faer's — the same equations solved in another order.)
    assert!(s.closed_loop_error_m < 0.015 * s.distance_m, "{}", s.closed_loop_error_m);
    assert!(s.imu_only_closed_loop_error_m > 20.0 * s.closed_loop_error_m);
    assert!(s.ate_rmse_m.unwrap() < 0.15);
    // Normalized gyro-bias errors against the reported σ after convergence.
    let gt = input.groundtruth.as_ref().unwrap();
    let (mut z2, mut n) = (0.0, 0usize);
    for e in out.estimates.iter().filter(|e| e.t > 30.0 && e.std[4][0].is_finite()) {
        let k = gt.t_ns.partition_point(|&t| t < input.t0_ns + (e.t * 1e9).round() as i64).min(gt.len() - 1);
        let bt = gt.bias_gyro.as_ref().unwrap()[k];
        for ((b, t), s) in e.bias_gyro.iter().zip(bt).zip(e.std[4]) {
            z2 += ((b - t) / s).powi(2);
            n += 1;
        }
    }
    let nees = z2 / n as f64;
    println!("gyro bias: mean normalized squared error {nees:.2} over {n} components (1 = consistent)");
    assert!(n > 1000 && nees < 4.0 && nees > 0.05, "{nees}");
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
    let opts = VioOptions { pixel_sigma: 1.93, ..VioOptions::default() };
    let out = run(&input, &opts, None).unwrap();
    let s = summarize(&input, &opts, &out, 10.0);
    println!("{}", s.table());
    assert_eq!(out.resets, 0, "{:?}", out.warnings);
    assert!(s.ate_rmse_m.unwrap() < 0.15, "ATE {:?}", s.ate_rmse_m);
    assert!(s.bias_rmse_gyro.unwrap() < 0.005, "{:?}", s.bias_rmse_gyro);
    assert!(s.bias_rmse_accel.unwrap() < 0.2, "{:?}", s.bias_rmse_accel);
    // The drone vibrates while it sits: reported, not silently absorbed.
    assert!(out.warnings.iter().any(|w| w.contains("vibration")));
}

fn finite(out: &tumble::vio::VioResult) -> bool {
    out.estimates.iter().all(|e| e.position.iter().chain(&e.velocity).chain(&e.bias_accel).all(|x| x.is_finite()))
}

#[test]
fn frames_without_features_warn_and_recover() {
    let (mut input, opts) = walk(40.0, 5);
    for f in input.frames.iter_mut().filter(|f| f.t > 15.0 && f.t < 17.0) {
        f.features.clear();
    }
    let out = run(&input, &opts, None).unwrap();
    assert!(finite(&out));
    assert!(out.warnings.iter().any(|w| w.contains("no features")), "{:?}", out.warnings);
    assert!(out.warnings.iter().any(|w| w.contains("features back")), "{:?}", out.warnings);
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
fn pure_rotation_triangulates_nothing_and_stays_finite() {
    let (mut input, opts) = walk(40.0, 7);
    // Every feature keeps its pixel: no parallax at all (a camera that only rotates
    // about its centre sees the same — no depth can be triangulated).
    let first = input.frames[0].features.clone();
    for f in input.frames.iter_mut() {
        f.features = first.clone();
    }
    let out = run(&input, &opts, None).unwrap();
    assert!(finite(&out));
    assert!(out.estimates.iter().all(|e| e.landmarks == 0 || e.t > 0.0));
}

#[test]
fn a_start_in_motion_is_refused_with_advice() {
    let (mut input, opts) = walk(40.0, 8);
    // Drop the first 5 s: the recording starts while moving.
    let k = input.imu.t.partition_point(|&t| t < 5.0);
    input.imu.t.drain(..k);
    input.imu.gyro.drain(..k);
    input.imu.acc.drain(..k);
    input.frames.retain(|f| f.t > 5.0 && f.t < 8.0);
    let err = run(&input, &opts, None).unwrap_err();
    assert!(err.contains("at rest") && err.contains("--init-from-groundtruth"), "{err}");
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

/// An ASL folder with images but no tracks: the estimator says how to get tracks;
/// the frontend tracks them (feature `opencv`) or names the feature to enable.
#[test]
fn image_folders_go_through_the_frontend() {
    let Some(micro) = common::shared("euroc/V1_01_easy_micro") else { return };
    let err = VioInput::from_asl(&micro, None).unwrap_err().to_string();
    assert!(err.contains("tracks.csv") && err.contains("frontend"), "{err}");
    let ds = tumble::io::asl::read_asl(&micro, &Default::default()).unwrap();
    let opts = tumble::vio::frontend::FrontendOptions::default();
    let tracked = tumble::vio::frontend::track_asl(&ds, 0, &opts, &mut |_, _| {});
    if cfg!(feature = "opencv") {
        let (obs, stats) = tracked.unwrap();
        let input = VioInput::from_dataset(ds, None, Some(obs)).unwrap();
        assert_eq!(input.frames.len(), stats.frames);
    } else {
        let err = tracked.unwrap_err();
        assert!(err.contains("--features opencv") && err.contains("libopencv-dev"), "{err}");
    }
}

/// Real V1_02 IMU (40 s) with a simulated camera flying its ground-truth path
/// (the shared data hold no V1_02 images): real inertial errors, simulated vision.
#[test]
fn real_v1_02_imu_with_a_simulated_camera() {
    let Some(dir) = common::shared("euroc/V1_02_medium_40s") else { return };
    let ds = tumble::io::asl::read_asl(&dir, &Default::default()).unwrap();
    let cam = tumble::sim::CameraSettings::default();
    let input = VioInput::from_dataset_with_simulated_camera(ds, None, &cam, 1).unwrap();
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
    for (opt, arg) in [
        ("--keyframe-parallax", "--keyframe-parallax=0"),
        ("--keyframe-interval", "--keyframe-interval=-1"),
        ("--keyframe-parallax", "--keyframe-parallax=nan"),
    ] {
        let o = std::process::Command::new(env!("CARGO_BIN_EXE_tumble"))
            .args(["vio", "/nonexistent/walk", "--out", out.to_str().unwrap(), arg])
            .output()
            .unwrap();
        let e = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success() && e.contains(&format!("{opt} must be a positive")), "{arg}: {e}");
    }
    assert!(!out.exists(), "nothing is written for a refused run");
}
