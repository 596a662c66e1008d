//! The visual frontend (feature `opencv`): tracks follow a known image motion
//! to a fraction of a pixel, the real EuRoC images give long tracks with the
//! floors below, and bad images are refused with the file named.
#![cfg(feature = "opencv")]

use std::collections::HashMap;
use tumble::factors::camera::{CameraModel, Distortion};
use tumble::io::asl::read_asl;
use tumble::vio::frontend::{
    moving_window, read_gray, track_asl, track_asl_stereo, track_camera, FrontendOptions, FrontendStats, KltTracker,
};

mod common;

/// Track frames of a window moving over the first V1_01 image; returns the
/// error of every tracked position against where the known motion takes the
/// feature's first position \[px\], sorted, and the statistics.
fn known_motion_errors(equalize: bool) -> Option<(Vec<f64>, FrontendStats)> {
    let micro = common::shared("euroc/V1_01_easy_micro")?;
    let ds = read_asl(&micro, &Default::default()).unwrap();
    let base = read_gray(&ds.cameras[0].frames[0].1).unwrap();
    let (frames, maps) = moving_window(&base, [600, 380], 40, [1.2, -0.6], 0.05).unwrap();
    let cam = CameraModel { fx: 458.0, fy: 457.0, cx: 300.0, cy: 190.0, distortion: Distortion::None };
    let mut tracker = KltTracker::new(cam, FrontendOptions { equalize, ..Default::default() });
    let mut first: HashMap<u64, (usize, [f64; 2])> = HashMap::new();
    let mut errors = Vec::new();
    for (k, img) in frames.iter().enumerate() {
        for (id, uv) in tracker.track(img).unwrap() {
            let &mut (k0, p0) = first.entry(id).or_insert((k, uv));
            if k0 == k {
                continue;
            }
            // Back to the first frame through map k0, forward through map k.
            let m0 = maps[k0];
            let a = m0.fixed_view::<2, 2>(0, 0).try_inverse().unwrap();
            let q = a * (nalgebra::Vector2::new(p0[0], p0[1]) - m0.column(2));
            let expect = maps[k].fixed_view::<2, 2>(0, 0) * q + maps[k].column(2);
            errors.push(((expect.x - uv[0]).powi(2) + (expect.y - uv[1]).powi(2)).sqrt());
        }
    }
    errors.sort_by(|a, b| a.total_cmp(b));
    let (median, p95) = (errors[errors.len() / 2], errors[errors.len() * 95 / 100]);
    let s = tracker.stats();
    println!(
        "known motion (equalize {equalize}): {} tracked positions, error median {median:.3} px, 95th percentile {p95:.3} px\n  {}",
        errors.len(),
        s.line()
    );
    Some((errors, s))
}

/// Tracks follow a known image motion (1.34 px and 0.05° per frame, 40 frames).
#[test]
fn tracks_follow_a_known_motion() {
    let Some((errors, s)) = known_motion_errors(false) else { return };
    let (median, p95) = (errors[errors.len() / 2], errors[errors.len() * 95 / 100]);
    assert!(errors.len() > 3000, "{}", errors.len());
    assert!(median < 0.1 && p95 < 0.4, "median {median}, p95 {p95}");
    assert!(s.features_per_frame > 120.0 && s.fb_ratio > 0.95 && s.inlier_ratio > 0.95, "{}", s.line());
    // With CLAHE the tracks drift more (its tiles do not move with the scene), within a pixel.
    let (errors, _) = known_motion_errors(true).unwrap();
    let (median, p95) = (errors[errors.len() / 2], errors[errors.len() * 95 / 100]);
    assert!(median < 0.25 && p95 < 1.2, "equalized: median {median}, p95 {p95}");
}

/// The 95 real stereo-pair left images of V1_01 (the MAV still on the ground:
/// only vibration moves the image). Floors: at least 120 of the 150 features
/// per frame (the scene has texture everywhere but the bright window), mean
/// tracks of at least 30 frames (1.5 s; a still scene should keep most features
/// for the whole 4.7 s), ≥ 95 % kept by the forward–backward check and RANSAC
/// (nothing moves, so rejections are tracking failures).
#[test]
fn euroc_micro_quality_floors() {
    let Some(micro) = common::shared("euroc/V1_01_easy_micro") else { return };
    let ds = read_asl(&micro, &Default::default()).unwrap();
    let (obs, s) = track_asl(&ds, 0, &FrontendOptions::default(), &mut |_, _| {}).unwrap();
    println!("V1_01 micro cam0: {}", s.line());
    assert_eq!(s.frames, 95);
    assert!(s.features_per_frame >= 120.0, "{}", s.line());
    assert!(s.mean_track_length >= 30.0, "{}", s.line());
    assert!(s.fb_ratio >= 0.95 && s.inlier_ratio >= 0.95, "{}", s.line());
    assert!(obs.iter().all(|o| o.2[0] >= 0.0 && o.2[0] < 752.0 && o.2[1] >= 0.0 && o.2[1] < 480.0));
    // The right camera too.
    let (_, s1) = track_asl(&ds, 1, &FrontendOptions::default(), &mut |_, _| {}).unwrap();
    println!("V1_01 micro cam1: {}", s1.line());
    assert!(s1.features_per_frame >= 120.0 && s1.mean_track_length >= 30.0, "{}", s1.line());
}

#[test]
fn bad_images_are_refused_with_the_file_named() {
    let dir = std::env::temp_dir().join(format!("tumble-frontend-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let cam = CameraModel { fx: 458.0, fy: 457.0, cx: 300.0, cy: 190.0, distortion: Distortion::None };
    // Not an image.
    let junk = dir.join("junk.png");
    std::fs::write(&junk, b"\x89PNG\r\n\x1a\n truncated").unwrap();
    let err = track_camera(&[(0, junk.clone())], cam, None, &FrontendOptions::default(), &mut |_, _| {})
        .unwrap_err()
        .to_string();
    assert!(err.contains("junk.png") && err.contains("not a readable image"), "{err}");
    // Missing.
    let err = read_gray(&dir.join("missing.png")).unwrap_err().to_string();
    assert!(err.contains("missing.png"), "{err}");
    // Wrong size for the sensor.yaml resolution.
    let Some(micro) = common::shared("euroc/V1_01_easy_micro") else { return };
    let ds = read_asl(&micro, &Default::default()).unwrap();
    let frames = &ds.cameras[0].frames[..2];
    let err = track_camera(frames, cam, Some([640, 480]), &FrontendOptions::default(), &mut |_, _| {})
        .unwrap_err()
        .to_string();
    assert!(err.contains("752×480") && err.contains("640×480"), "{err}");
    // An empty image handed to the tracker.
    let mut t = KltTracker::new(cam, FrontendOptions::default());
    assert!(t.track(&opencv::core::Mat::default()).is_err());
}

/// Stereo matching on the 95 real V1_01 pairs: every match must satisfy the
/// calibrated epipolar geometry to well under a pixel and sit at a room-scale
/// depth (the MAV stands ~2 m from the mats). Measured: 31.7 % of cam0's
/// features matched, median epipolar distance 0.15 px, median depth 2.13 m;
/// most features lie on low-texture cloth where KLT between the two
/// viewpoints converges elsewhere and the forward–backward check drops it.
/// Floors: ≥ 25 % matched, ≥ 75 % of KLT's survivors pass the epipolar and
/// depth checks, median epipolar distance ≤ 0.3 px, median depth 1–4 m.
#[test]
fn euroc_micro_stereo_matches_obey_the_epipolar_geometry() {
    let Some(micro) = common::shared("euroc/V1_01_easy_micro") else { return };
    let ds = read_asl(&micro, &Default::default()).unwrap();
    let (o0, o1, s) = track_asl_stereo(&ds, &FrontendOptions::default(), &mut |_, _| {}).unwrap();
    let st = s.stereo.as_ref().unwrap();
    println!("V1_01 micro: {}", st.line());
    assert_eq!(st.pairs, 95);
    assert!(st.match_ratio() >= 0.25, "{}", st.line());
    assert!(st.epipolar_ratio() >= 0.75, "{}", st.line());
    assert!(st.median_epipolar_px() <= 0.3, "{}", st.line());
    assert!((1.0..=4.0).contains(&st.median_depth_m()), "{}", st.line());
    // Every cam1 observation belongs to a cam0 track seen at the same time.
    let seen: std::collections::HashSet<(i64, u64)> = o0.iter().map(|o| (o.0, o.1)).collect();
    assert!(o1.iter().all(|o| seen.contains(&(o.0, o.1))));
    assert_eq!(o1.len(), st.matched());
    // A folder with one camera cannot do stereo.
    let mut mono = ds.clone();
    mono.cameras.truncate(1);
    let e = track_asl_stereo(&mono, &FrontendOptions::default(), &mut |_, _| {}).unwrap_err().to_string();
    assert!(e.contains("cam0 and cam1"), "{e}");
}
