//! The verdict on a calibration: `ok`, `weak` (usable, with reasons) or
//! `failed` (the fit does not explain the data; nothing loadable is written).
//!
//! The thresholds are physical, not statistical: χ²/dof depends on how well
//! the initial rest predicts the noise of hand-held poses, which varies by
//! orders of magnitude between recordings that calibrate well (imu_tk's Xsens
//! recording gives 14 and 25), while a calibrated MEMS IMU carries gravity to
//! within a fraction of a degree and measures its norm to ~0.01 m/s².

use super::result::{Assessment, CalibrationResult, Verdict};

/// Largest RMS of `|a| − g` over the poses after calibration \[m/s²\] (1 % of
/// g; a calibrated MEMS accelerometer reaches ~0.01): above it the model or
/// the detected poses are wrong.
pub const MAX_ACCEL_RMS_M_S2: f64 = 0.1;

/// Largest RMS angle between the gravity direction the calibrated gyro
/// carries through a turn and the one measured after it \[rad\] (5.7°;
/// calibrations that work reach < 1°).
pub const MAX_GYRO_RMS_RAD: f64 = 0.1;

/// Largest ratio of the gyro matrix's singular values: the axes of one gyro
/// chip differ in scale by a few per cent, not by half.
pub const MAX_GYRO_ANISOTROPY: f64 = 1.5;

/// Largest relative σ of a scale for an `ok` verdict: a calibration should
/// beat the datasheet's scale tolerance (±1–3 %).
pub const MAX_SCALE_REL_SIGMA: f64 = 0.01;

impl Assessment {
    /// Judge a calibration (see the module's thresholds).
    pub fn of(r: &CalibrationResult, not_determined: Vec<String>, ambiguity: Option<(f64, f64, f64)>) -> Assessment {
        let mut failed = Vec::new();
        let mut weak = Vec::new();
        if r.accel_fit.rms > MAX_ACCEL_RMS_M_S2 {
            failed.push(format!(
                "the accelerometer fit does not explain the poses: |a| − g has RMS {:.3} m/s² after calibration \
                 (limit {MAX_ACCEL_RMS_M_S2}; calibrated MEMS reach ~0.01): poses that were not still, or the wrong gravity",
                r.accel_fit.rms
            ));
        }
        if r.gyro_fit.rms > MAX_GYRO_RMS_RAD {
            failed.push(format!(
                "the gyroscope fit does not explain the turns: the calibrated gyro carries gravity {:.1}° off on \
                 average (limit {:.1}°): holds too short to tell poses from turns, or turns the gyro saturated on",
                r.gyro_fit.rms.to_degrees(),
                MAX_GYRO_RMS_RAD.to_degrees()
            ));
        }
        if let Some(m) = r.calibration.gyro.inverse_matrix() {
            let sv = m.svd(false, false).singular_values;
            if !(sv.min() > 0.0 && sv.max() / sv.min() <= MAX_GYRO_ANISOTROPY) {
                failed.push(format!(
                    "the gyroscope matrix is far from a rotation-free scale (singular values {:.3}, {:.3}, {:.3}; the \
                     axes of one chip agree within a few per cent)",
                    sv[0], sv[1], sv[2]
                ));
            }
        }
        if let Some((kept, other, ratio)) = ambiguity {
            failed.push(format!(
                "the turns cannot tell the gyro scale {kept:.4} from {other:.4} (χ² only {ratio:.2}× apart): turns \
                 about a single axis alias; turn about tilted axes between poses"
            ));
        }
        if !not_determined.is_empty() {
            weak.push(format!(
                "not determined by these poses, left near the prior of no misalignment (σ about the prior's): {} — \
                 add poses tilted between the axes",
                not_determined.join(", ")
            ));
        }
        for (name, fit) in [("accelerometer", &r.accel_fit), ("gyroscope", &r.gyro_fit)] {
            if !fit.converged {
                weak.push(format!("the {name} fit stopped at the iteration cap after {} iterations", fit.iterations));
            }
        }
        if let Some(split) = &r.split {
            weak.extend(
                split
                    .describe_disagreements()
                    .into_iter()
                    .map(|d| format!("{d}: the recording does not settle it (its σ is widened to cover the halves)")),
            );
        }
        for (name, t) in [("accelerometer", &r.calibration.accel), ("gyroscope", &r.calibration.gyro)] {
            for (axis, k, sd) in [("x", t.k.x, t.k_std.x), ("y", t.k.y, t.k_std.y), ("z", t.k.z, t.k_std.z)] {
                if sd.is_nan() || sd > MAX_SCALE_REL_SIGMA * k.abs() {
                    weak.push(format!(
                        "the {name} scale K_{axis} is uncertain: σ {:.1} % (limit {:.0} %)",
                        100.0 * sd / k.abs(),
                        100.0 * MAX_SCALE_REL_SIGMA
                    ));
                }
            }
        }
        let verdict = if !failed.is_empty() {
            Verdict::Failed
        } else if !weak.is_empty() {
            Verdict::Weak
        } else {
            Verdict::Ok
        };
        failed.extend(weak);
        Assessment { verdict, reasons: failed, not_determined }
    }
}
