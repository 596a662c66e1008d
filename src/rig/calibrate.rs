//! `tumble calibrate-rig`'s stages in order ([`calibrate_rig`]); each stage
//! is a function of [`super::solve`], the recording's self-check
//! [`super::split`]'s.

use super::init::RateIntegral;
use super::solve::{
    calibrate_cameras, coarse_time_offset, frame_slots, hand_eye_rotations, joint_solve, note_weak_parameters, results,
    start_from_solution, starting_state, FrameSlot, Joint, Start,
};
use super::{RigError, RigInput, RigOptions, RigResult};
use std::time::Instant;

/// A joint solve whose time offset moved the frames by more than this
/// \[s\] is solved again with the frames placed there: the first-order move
/// of a pose misses `½ α td²` — 2.5e-5 rad at 1 ms and a hand's 50 rad/s²,
/// 1 % of a pixel's angle at a 460 px focal length — which grows as td².
const RESLOT_OFFSET_S: f64 = 1e-3;
/// At most this many solves again (each moves the frames by the offset found).
const MAX_RESLOTS: usize = 2;

/// Calibrate the rig; `progress` receives one line per stage.
///
/// The stages, each a function below: every camera alone (intrinsics, view
/// poses) → the coarse time offset (rotation rates) → the frames → the
/// camera–IMU rotations (hand–eye) → the starting state (gravity, world,
/// body poses, velocities) → the joint solve → the results and their verdicts.
pub fn calibrate_rig(input: &RigInput, o: &RigOptions, progress: &mut dyn FnMut(&str)) -> Result<RigResult, RigError> {
    o.validate()?;
    let t0 = Instant::now();
    let n_cams = input.cameras.len();
    if input.imu.t.len() < 2 || n_cams == 0 {
        return Err(RigError::Recording(format!(
            "{} IMU sample(s) and {n_cams} camera(s): nothing to calibrate",
            input.imu.t.len()
        )));
    }
    let mut notes = Vec::new();
    // Samples are point samples at their stamps: the midpoint rule, not a
    // zero-order hold, which would lag the IMU by half a sample period
    // (2.5 ms at 200 Hz) and bias the time offset by as much.
    let mut params = input.noise;
    params.scheme = tumble_factors::imu_preint::Scheme::Midpoint;
    let (starts, mut view_poses) = calibrate_cameras(input, o, progress)?;
    let gyro_integral = RateIntegral::new(&input.imu);
    let coarse = coarse_time_offset(input, o, &view_poses[0], &gyro_integral, &mut notes, progress);
    let td0 = coarse.as_ref().map_or(0.0, |c| c.0);
    let mut frames = frame_slots(input, &view_poses, td0)?;
    let (r_bc, hand_eye_rms, set_aside) = hand_eye_rotations(input, &frames, &mut view_poses, params, progress)?;
    if set_aside > 0 {
        frames = frame_slots(input, &view_poses, td0)?;
    }
    let state = starting_state(input, &frames, &view_poses, &r_bc)?;
    let start = Start { cameras: starts, frames, hand_eye_rms, state, params, frame_offset: td0 };
    let (start, joint) = joint_solve_in_place(input, o, start, &gyro_integral, progress)?;
    let mut rig = results(input, o, &start, &joint, coarse, notes)?;
    super::split::check_halves(input, o, &start, &joint, &gyro_integral, &mut rig, progress)?;
    rig.seconds = t0.elapsed().as_secs_f64();
    note_weak_parameters(&mut rig);
    Ok(rig)
}

/// The joint solve, and again with the frames moved by the offset it found
/// while that offset exceeds [`RESLOT_OFFSET_S`]: the offset variable
/// moves each frame's pose to first order (along the rate and the
/// velocity); the IMU's intervals between frames stay where the frames
/// were placed. Returns the start the final solve began from and its result.
fn joint_solve_in_place(
    input: &RigInput,
    o: &RigOptions,
    mut start: Start,
    gyro_integral: &RateIntegral,
    progress: &mut dyn FnMut(&str),
) -> Result<(Start, Joint), RigError> {
    let mut joint = joint_solve(input, o, &start, gyro_integral, progress)?;
    for _ in 0..MAX_RESLOTS {
        let offset = joint.offset()?;
        if offset.abs() <= RESLOT_OFFSET_S {
            break;
        }
        progress(&format!("frames moved by the {:.1} ms of time offset found: joint solve again", offset * 1e3));
        let mut moved = start_from_solution(&start, &joint, 0..start.frames.len(), 0.0)?;
        let (t_first, t_last) = (input.imu.t[0], input.imu.t[input.imu.t.len() - 1]);
        let inside: Vec<usize> =
            (0..moved.frames.len()).filter(|&k| (t_first..t_last).contains(&(moved.frames[k].t + offset))).collect();
        moved.frames =
            inside.iter().map(|&k| FrameSlot { t: moved.frames[k].t + offset, ..moved.frames[k].clone() }).collect();
        moved.state.body = inside.iter().map(|&k| moved.state.body[k]).collect();
        moved.state.vel = inside.iter().map(|&k| moved.state.vel[k]).collect();
        moved.state.bias = inside.iter().map(|&k| moved.state.bias[k]).collect();
        moved.frame_offset += offset;
        joint = joint_solve(input, o, &moved, gyro_integral, progress)?;
        start = moved;
    }
    Ok((start, joint))
}
