//! How the estimator finds its first state ([`super::Init`]): a given state,
//! a static start (gyro bias, gravity direction, zero velocity from a window
//! at rest), or the closed-form solution over a moving start ([`super::init`]).

use super::window::InitState;
use super::{Init, InitOptions, NoiseOptions, VioInput};
use crate::model::geometry::{gravity_aligned, pose};
use nalgebra::{UnitQuaternion, Vector3, Vector6};
use tumble_factors::imu_preint::PreintegrationParams;

/// Velocity prior σ of a start in motion (the closed form's accuracy) \[m/s\].
const MOTION_V_SIGMA: f64 = 0.1;
/// Roll/pitch prior σ of a start in motion \[rad\] (2°).
const MOTION_TILT_SIGMA: f64 = 0.035;
/// Gyro-bias prior σ of a start in motion whose features did not determine
/// the bias \[rad/s\]: a raw MEMS gyro's turn-on bias is a few °/s (EuRoC's
/// ADIS16448 0.08 rad/s = 4.4 °/s about z), so 0.1 rad/s (5.7 °/s) leaves it
/// to the window; a calibrated one (`tumble calibrate`) is far inside.
const MOTION_GYRO_BIAS_SIGMA: f64 = 0.1;
/// Largest change of the mean gyro rate between quarters of a window at rest \[rad/s\].
const REST_GYRO_STEP: f64 = 0.02;
/// Largest change of the mean specific force between quarters of a window at rest \[m/s²\].
const REST_ACCEL_STEP: f64 = 0.3;

/// Why a static start did not work (yet).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum AtRest {
    /// Not enough IMU data before the frame.
    TooEarly,
    /// The IMU moved in the window.
    Moving,
}

/// The initializer, its options, and why its last attempt in motion failed.
#[derive(Debug)]
pub(crate) struct Startup {
    /// How to initialize.
    init: InitOptions,
    /// Gravity \[m/s²\] and whether a static start's measured noise is used
    /// ([`NoiseOptions::from_static`]).
    gravity: f64,
    from_static: bool,
    /// Why the last initialization in motion failed (for the error when none worked).
    pub failure: Option<String>,
    /// The white-noise densities a static start measured, `[gyro, accel]`.
    pub at_rest: Option<[f64; 2]>,
}

impl Startup {
    /// An initializer with the run's options.
    pub fn new(init: &InitOptions, noise: &NoiseOptions) -> Startup {
        Startup {
            init: init.clone(),
            gravity: noise.gravity,
            from_static: noise.from_static,
            failure: None,
            at_rest: None,
        }
    }

    /// Try to initialize at frame `index` (time `t`) by the mode of the
    /// [`InitOptions`], with the IMU noise `imu` in use. A static start may
    /// raise `imu`'s white-noise densities to what it measured (with
    /// [`NoiseOptions::from_static`]); what it measured and what it did go to
    /// `warnings`.
    pub fn initialize(
        &mut self,
        input: &VioInput,
        imu: &mut PreintegrationParams,
        warnings: &mut Vec<String>,
        index: usize,
        t: f64,
    ) -> Option<InitState> {
        match &self.init.mode {
            Init::Given { q, p, v, bias_accel, bias_gyro, t: t0 } => {
                if t < *t0 {
                    return None;
                }
                let uq = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(q[0], q[1], q[2], q[3]));
                let b =
                    Vector6::new(bias_accel[0], bias_accel[1], bias_accel[2], bias_gyro[0], bias_gyro[1], bias_gyro[2]);
                Some(InitState::at_rest(
                    pose(uq.to_rotation_matrix().matrix(), &Vector3::from(*p)),
                    Vector3::from(*v),
                    b,
                ))
            }
            Init::Static => {
                initialize_static(input, &self.init, self.from_static, imu, warnings, t).ok().map(|(s, m)| {
                    self.at_rest = Some(m);
                    s
                })
            }
            Init::Motion => self.initialize_moving(input, imu, warnings, index, t),
            Init::Auto => match initialize_static(input, &self.init, self.from_static, imu, warnings, t) {
                Ok((state, measured)) => {
                    self.at_rest = Some(measured);
                    Some(state)
                }
                Err(AtRest::Moving) => self.initialize_moving(input, imu, warnings, index, t),
                Err(AtRest::TooEarly) => None,
            },
        }
    }

    /// [`Init::Motion`] at frame `index`: the closed form over the frames of
    /// the last `motion_window_s`, or of twice that when the shorter window
    /// saw too little parallax; `None` (tried again at the next frame) while
    /// the window is too short or does not observe scale.
    fn initialize_moving(
        &mut self,
        input: &VioInput,
        imu: &PreintegrationParams,
        warnings: &mut Vec<String>,
        index: usize,
        t: f64,
    ) -> Option<InitState> {
        let frames = &input.frames;
        let mut failure = None;
        for span in [self.init.motion_window_s, 2.0 * self.init.motion_window_s] {
            let first = frames.partition_point(|f| f.t < t - span);
            if frames.first().is_none_or(|f| t - f.t < span - 1e-9) || index < first + 3 {
                break;
            }
            let window: Vec<usize> = (first..=index).collect();
            match super::init::closed_form(input, &window, imu, self.gravity) {
                Ok(m) => {
                    let bias_gyro = m.bias_gyro.unwrap_or_else(Vector3::zeros);
                    let stereo = match m.stereo_observations {
                        0 => String::new(),
                        n => format!(", {n} stereo matches"),
                    };
                    warnings.push(format!(
                        "initialized in motion at {t:.3} s from {} frames and {} landmarks{stereo} (speed {:.2} m/s, free gravity {:.2} m/s², gyro bias [{:.4}, {:.4}, {:.4}] rad/s)",
                        window.len(),
                        m.landmarks,
                        m.velocity.norm(),
                        m.free_gravity,
                        bias_gyro.x,
                        bias_gyro.y,
                        bias_gyro.z
                    ));
                    return Some(InitState {
                        x: pose(&m.rotation, &Vector3::zeros()),
                        v: m.velocity,
                        b: Vector6::new(0.0, 0.0, 0.0, bias_gyro.x, bias_gyro.y, bias_gyro.z),
                        v_sigma: MOTION_V_SIGMA,
                        tilt_sigma: Some(MOTION_TILT_SIGMA),
                        // The features' estimate when they determined it,
                        // else nothing is known of a raw gyro's bias.
                        gyro_bias_sigma: m.bias_gyro.is_none().then_some(MOTION_GYRO_BIAS_SIGMA),
                        in_motion: true,
                    });
                }
                Err(why) => failure = Some(format!("at {t:.3} s over {span:.1} s: {why}")),
            }
        }
        if failure.is_some() {
            self.failure = failure;
        }
        None
    }
}

/// [`Init::Static`] at time `t`: the last `static_window_s` of IMU data must
/// be at rest (means over its quarters agree, so vibration averages out).
/// Returns the start and the white-noise densities `[gyro, accel]` the
/// samples' spread shows; with `from_static`, the densities of the noise
/// `in_use` raised to them where they exceed them.
pub(crate) fn initialize_static(
    input: &VioInput,
    init: &InitOptions,
    from_static: bool,
    in_use: &mut PreintegrationParams,
    warnings: &mut Vec<String>,
    t: f64,
) -> Result<(InitState, [f64; 2]), AtRest> {
    let imu = &input.imu;
    let w = init.static_window_s;
    let (i0, i1) = (imu.t.partition_point(|&s| s < t - w), imu.t.partition_point(|&s| s <= t));
    if t - w < imu.t.first().copied().unwrap_or(f64::INFINITY) - 1e-9 || i1 < i0 + 10 {
        return Err(AtRest::TooEarly);
    }
    let quarter = (i1 - i0) / 4;
    let mean = |a: usize, b: usize, g: bool| -> Vector3<f64> {
        let s: Vector3<f64> = (a..b).map(|k| if g { imu.gyro[k] } else { imu.acc[k] }).sum();
        s / (b - a) as f64
    };
    let (mut dg, mut da) = (0.0f64, 0.0f64);
    let (gm, am) = (mean(i0, i1, true), mean(i0, i1, false));
    for q in 0..4 {
        let (a, b) = (i0 + q * quarter, i0 + (q + 1) * quarter);
        dg = dg.max((mean(a, b, true) - gm).amax());
        da = da.max((mean(a, b, false) - am).amax());
    }
    if dg > REST_GYRO_STEP || da > REST_ACCEL_STEP {
        return Err(AtRest::Moving);
    }
    let rate = (i1 - i0) as f64 / w;
    let std = |g: bool, m: &Vector3<f64>| -> f64 {
        let s: f64 = (i0..i1).map(|k| (if g { imu.gyro[k] } else { imu.acc[k] } - m).norm_squared() / 3.0).sum();
        (s / (i1 - i0) as f64).sqrt()
    };
    let (sa, sg) = (std(false, &am) / rate.sqrt(), std(true, &gm) / rate.sqrt());
    let apply = from_static;
    let action = if apply { "using the measured value" } else { "kept (--noise-from-static uses it)" };
    let params = in_use;
    for (what, unit, measured, density) in [
        ("accelerometer", "m/s²/√Hz, vibration?", sa, &mut params.accel_noise_density),
        ("gyroscope", "rad/s/√Hz", sg, &mut params.gyro_noise_density),
    ] {
        if measured > 1.5 * *density {
            warnings.push(format!(
                "the {what} at rest is noisier than the noise model says ({measured:.2e} vs {:.2e} {unit}): {action}",
                *density
            ));
            if apply {
                *density = measured;
            }
        }
    }
    let r = gravity_aligned(&am);
    let b = Vector6::new(0.0, 0.0, 0.0, gm.x, gm.y, gm.z);
    Ok((InitState::at_rest(pose(&r, &Vector3::zeros()), Vector3::zeros(), b), [sg, sa]))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::ImuData;
    use crate::vio::Frame;
    use crate::vio::VioOptions;
    use nalgebra::Matrix3;

    /// `seconds` of IMU at 200 Hz, tilted 10° about x, gyro bias 0.01 rad/s, with `wiggle` rad/s after 1 s.
    fn input(seconds: f64, wiggle: f64) -> VioInput {
        let r = tumble_solvers::lie::so3_exp(&Vector3::new(10f64.to_radians(), 0.0, 0.0));
        let f = r.transpose() * Vector3::new(0.0, 0.0, 9.81);
        let n = (seconds * 200.0) as usize;
        let imu = ImuData {
            t: (0..n).map(|k| k as f64 / 200.0).collect(),
            gyro: (0..n).map(|k| Vector3::new(0.01, 0.0, if k > 200 && k % 2 == 0 { wiggle } else { 0.0 })).collect(),
            acc: vec![f; n],
        };
        VioInput::for_tests(imu, vec![Frame { t: seconds - 0.01, features: Vec::new() }])
    }

    #[test]
    fn a_static_start_finds_tilt_and_gyro_bias() {
        let inp = input(1.5, 0.0);
        let mut opts = VioOptions::default();
        let mut warnings = Vec::new();
        let (s, _) = initialize_static(&inp, &opts.init, false, &mut opts.noise.imu, &mut warnings, 1.4).unwrap();
        assert!((s.b[3] - 0.01).abs() < 1e-12 && s.b[4].abs() < 1e-12);
        let (r, _) = crate::model::geometry::parts(&s.x);
        let up = r.transpose() * Vector3::z();
        assert!((up - Matrix3::identity().column(2)).norm() > 0.1, "tilted");
        assert!((r * (inp.imu.acc[0] / 9.81) - Vector3::z()).norm() < 1e-9);
        assert!(warnings.is_empty(), "{warnings:?}");
    }

    #[test]
    fn a_static_start_waits_for_data_and_refuses_motion() {
        let inp = input(1.5, 0.0);
        let mut opts = VioOptions::default();
        assert_eq!(
            initialize_static(&inp, &opts.init, false, &mut opts.noise.imu, &mut Vec::new(), 0.5).err(),
            Some(AtRest::TooEarly)
        );
        let moving = input(1.5, 0.2);
        assert_eq!(
            initialize_static(&moving, &opts.init, false, &mut opts.noise.imu, &mut Vec::new(), 1.4).err(),
            Some(AtRest::Moving)
        );
        // Auto falls back to the motion start, which has no frames to work with yet.
        let mut startup = Startup::new(&opts.init, &opts.noise);
        assert!(startup.initialize(&moving, &mut opts.noise.imu, &mut Vec::new(), 0, 1.4).is_none());
    }
}
