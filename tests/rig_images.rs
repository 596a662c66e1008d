//! The rig calibration's image path measured end to end on rendered frames
//! (feature `opencv`): `tumble sim rig --images` renders a rig waved before a
//! checkerboard; the detector's corners are compared with the exact
//! projections, and `calibrate_rig` from the images with the truth.
#![cfg(feature = "opencv")]

mod common;

use std::collections::HashMap;
use tumble::rig::{calibrate_rig, RigInput, RigOptions};
use tumble::sim::render::ImageSettings;
use tumble::sim::rig_recording::{rig_settings, write_rig_recording};

/// 12 s at 10 frames a second (120 frames, the default exposure, noise,
/// vignetting and flicker). Measured (release, 2026-12-03): 103 of the 104
/// frames that show the whole board detected, corners' mean offset (+0.006,
/// +0.008) px, median 0.035 px, largest 0.13 px; every calibrated parameter
/// within 1.7 σ of the truth. The bounds are the (mean offset 0.02 px,
/// median 0.15 px, |z| 4) and a mislabelled view (an error over 1 px).
#[test]
fn rendered_checkerboard_frames_calibrate_to_the_truth() {
    let dir = std::env::temp_dir().join(format!("tumble_rig_images_{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let mut settings = rig_settings(12.0, 0.0);
    settings.camera.rate_hz = 10.0;
    let sim = write_rig_recording(&settings, Some(&ImageSettings::default()), 1, &dir, &mut |_, _| {}).unwrap();
    let opts = RigOptions::default();
    let input = RigInput::from_asl(&dir, &dir.join("target.yaml"), None, None, &opts).unwrap();

    // The detector against the exact projections (the rendered recording's corners have no noise added).
    let n = settings.target.corner_count();
    let truth: HashMap<(i64, usize), [f64; 2]> =
        sim.input.cameras[0].views.iter().flat_map(|v| v.corners.iter().map(move |c| ((v.t_ns, c.id), c.uv))).collect();
    let t0 = input.cameras[0].views[0].t_ns - sim.input.cameras[0].views[0].t_ns;
    let whole = sim.input.cameras[0].views.iter().filter(|v| v.corners.len() == n).count();
    let detected = input.cameras[0].views.iter().filter(|v| !v.corners.is_empty()).count();
    let (mut offset, mut errors) = ([0.0; 2], Vec::new());
    for v in &input.cameras[0].views {
        for c in &v.corners {
            let exact = truth[&(v.t_ns - t0, c.id)];
            let d = [c.uv[0] - exact[0], c.uv[1] - exact[1]];
            offset = [offset[0] + d[0], offset[1] + d[1]];
            errors.push(d[0].hypot(d[1]));
        }
    }
    errors.sort_by(f64::total_cmp);
    let count = errors.len() as f64;
    let offset = offset.map(|o| o / count);
    let median = errors[errors.len() / 2];
    let largest = errors[errors.len() - 1];
    println!(
        "detected {detected} of {whole} frames showing the whole board; corners' mean offset ({:+.4}, {:+.4}) px, \
         median {median:.4} px, largest {largest:.3} px",
        offset[0], offset[1]
    );
    assert!(detected as f64 >= 0.85 * whole as f64, "{detected} of {whole}");
    assert!(offset.iter().all(|o| o.abs() <= 0.02), "{offset:?}");
    assert!(median <= 0.15 && largest < 1.0, "median {median}, largest {largest}");

    // The calibration from the detected corners against the truth.
    let rig = calibrate_rig(&input, &opts, &mut |_| {}).unwrap();
    assert!(rig.converged && rig.refusal().is_none(), "{:?}", rig.refusal());
    let z = common::camera_errors(&rig, 0, &sim.truth, &sim.truth.t_bc).2;
    println!("z (rotation, translation, fx fy cx cy, time offset): {z:+.2?}");
    assert!(z.iter().all(|z| z.abs() <= 4.0), "{z:?}");
    let _ = std::fs::remove_dir_all(&dir);
}
