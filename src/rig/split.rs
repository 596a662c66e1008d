//! Stage 8: the recording checks itself. The joint solve again on the first
//! and on the second half of the frames (each from the whole recording's
//! solution), every estimated parameter compared, and the whole recording's
//! σ widened to cover what the halves show ([`crate::model::split`]).

use super::init::RateIntegral;
use super::solve::{camera_result, joint_solve, start_from_solution, Joint, Start};
use super::{CameraResult, RigError, RigInput, RigOptions, RigResult};
use crate::model::split::{HalfComparison, SplitCheck};
use tumble_solvers::lie::so3_log;

/// Fewest frames in a half for the check to run: each half must hold a
/// calibration of its own (the joint solve estimates ~20 parameters per
/// camera from corners and ~15 per frame from the IMU).
pub const MIN_FRAMES_PER_HALF: usize = 100;

/// One half's estimate: each camera's calibration and the time offset with its σ \[s\].
struct HalfEstimate {
    cameras: Vec<CameraResult>,
    time_offset: (f64, f64),
}

/// Compare the halves of the recording and widen `rig`'s σ to cover their
/// differences; `rig.split` holds the comparison (None, with a note, when a
/// half is too short or its solve does not converge).
pub(super) fn check_halves(
    input: &RigInput,
    o: &RigOptions,
    start: &Start,
    joint: &Joint,
    gyro_integral: &RateIntegral,
    rig: &mut RigResult,
    progress: &mut dyn FnMut(&str),
) -> Result<(), RigError> {
    let n = start.frames.len();
    if n < 2 * MIN_FRAMES_PER_HALF {
        rig.notes.push(format!(
            "{n} frames: too few to check the calibration on each half of the recording (σ not checked)"
        ));
        return Ok(());
    }
    // The halves are solved at once, one per core; their progress is
    // reported afterwards, in order.
    let solve_half = |h: usize, range: std::ops::Range<usize>| -> Result<(Vec<String>, Option<_>), RigError> {
        let mut log = vec![format!("split check: joint solve on half {} ({} frames)", h + 1, range.len())];
        let half = start_from_solution(start, joint, range.clone(), joint.offset()?)?;
        let j = joint_solve(input, o, &half, gyro_integral, &mut |m: &str| log.push(format!("  {m}")))?;
        if !j.converged {
            return Ok((log, None));
        }
        let cameras =
            (0..input.cameras.len()).map(|c| camera_result(input, o, &half, &j, c)).collect::<Result<_, _>>()?;
        let time_offset = j.time_offset(&half, o)?;
        let span = |k: usize| start.frames[k].t - start.frames[0].t;
        let label =
            format!("frames {}–{} ({:.1}–{:.1} s)", range.start, range.end - 1, span(range.start), span(range.end - 1));
        Ok((log, Some((label, HalfEstimate { cameras, time_offset }))))
    };
    let (first, second) = rayon::join(|| solve_half(0, 0..n / 2), || solve_half(1, n / 2..n));
    let mut halves = Vec::new();
    for (h, solved) in [first, second].into_iter().enumerate() {
        let (log, estimate) = solved?;
        log.iter().for_each(|m| progress(m));
        match estimate {
            Some(e) => halves.push(e),
            None => {
                rig.notes.push(format!("the joint solve on half {} did not converge: σ not checked", h + 1));
                return Ok(());
            }
        }
    }
    let [(l1, a), (l2, b)]: [(String, HalfEstimate); 2] =
        halves.try_into().map_err(|_| RigError::Internal("two halves expected".into()))?;
    let check = SplitCheck { halves: [l1, l2], parameters: compare(rig, &a, &b, o.estimate_time_offset) };
    widen(rig, &check);
    let rms = check.rms_z();
    progress(&format!("split check: RMS normalized difference of the halves {rms:.2} (≈ 1 when the σ are honest)"));
    let disagreements = check.describe_disagreements();
    if !disagreements.is_empty() {
        rig.notes.push(format!(
            "the two halves of the recording disagree beyond their σ — {}; the σ given are widened to cover it, and \
             these parameters are at best weak: the recording does not settle them (its halves see different motion \
             or parts of the image, or the model lacks a term){}",
            disagreements.join("; "),
            if check.disagreements().iter().any(|p| !p.parameter.contains("time offset")) {
                ". Kalibr's two steps help here: calibrate the cameras' intrinsics on a camera-only recording with \
                 the target filling the image's corners, then pass them with --intrinsics"
            } else {
                ""
            }
        ));
    }
    rig.split = Some(check);
    Ok(())
}

/// Every estimated parameter of both halves, against the whole recording's σ in `rig`.
fn compare(rig: &RigResult, a: &HalfEstimate, b: &HalfEstimate, time_offset: bool) -> Vec<HalfComparison> {
    let mut out = Vec::new();
    for (c, whole) in rig.cameras.iter().enumerate() {
        let (ca, cb) = (&a.cameras[c], &b.cameras[c]);
        let r = super::rotation(&whole.t_bc);
        // Rotation about the body axes away from the whole recording's [deg].
        let turn = |h: &CameraResult| so3_log(&(super::rotation(&h.t_bc) * r.transpose())).map(f64::to_degrees);
        let (ta, tb) = (turn(ca), turn(cb));
        for (i, axis) in ["x", "y", "z"].iter().enumerate() {
            out.push(HalfComparison::new(
                format!("{} T_BC rotation {axis}", whole.name),
                "deg",
                (ta[i], ca.rotation_sigma[i].to_degrees()),
                (tb[i], cb.rotation_sigma[i].to_degrees()),
                whole.rotation_sigma[i].to_degrees(),
            ));
        }
        for (i, axis) in ["x", "y", "z"].iter().enumerate() {
            out.push(HalfComparison::new(
                format!("{} T_BC translation {axis}", whole.name),
                "m",
                (ca.t_bc.translation.vector[i], ca.translation_sigma[i]),
                (cb.t_bc.translation.vector[i], cb.translation_sigma[i]),
                whole.translation_sigma[i],
            ));
        }
        if whole.intrinsics_fixed {
            continue;
        }
        let (va, vb) = (ca.model.to_vector(), cb.model.to_vector());
        for (i, name) in INTRINSICS.iter().enumerate() {
            let units = if i < 4 { "px" } else { "" };
            out.push(HalfComparison::new(
                format!("{} {name}", whole.name),
                units,
                (va[i], ca.model_sigma[i]),
                (vb[i], cb.model_sigma[i]),
                whole.model_sigma[i],
            ));
        }
    }
    if time_offset {
        out.push(HalfComparison::new(
            "time offset".into(),
            "ms",
            (a.time_offset.0 * 1e3, a.time_offset.1 * 1e3),
            (b.time_offset.0 * 1e3, b.time_offset.1 * 1e3),
            rig.time_offset_sigma_s * 1e3,
        ));
    }
    out
}

/// Names of the intrinsics vector `[fx, fy, cx, cy, c0..c3]` (radial–tangential names; equidistant's k1..k4).
const INTRINSICS: [&str; 8] = ["fx", "fy", "cx", "cy", "distortion 1", "distortion 2", "distortion 3", "distortion 4"];

/// Widen every σ of `rig` the check compared.
fn widen(rig: &mut RigResult, check: &SplitCheck) {
    for c in &mut rig.cameras {
        for (i, axis) in ["x", "y", "z"].iter().enumerate() {
            let deg = check.sigma_after(&format!("{} T_BC rotation {axis}", c.name), c.rotation_sigma[i].to_degrees());
            c.rotation_sigma[i] = deg.to_radians();
            c.translation_sigma[i] =
                check.sigma_after(&format!("{} T_BC translation {axis}", c.name), c.translation_sigma[i]);
        }
        for (i, name) in INTRINSICS.iter().enumerate() {
            c.model_sigma[i] = check.sigma_after(&format!("{} {name}", c.name), c.model_sigma[i]);
        }
    }
    rig.time_offset_sigma_s = check.sigma_after("time offset", rig.time_offset_sigma_s * 1e3) * 1e-3;
}
