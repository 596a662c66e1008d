//! `tumble apply`: write a corrected recording in the layout it was read from.

use crate::error::OutputError;
use crate::io::imu_write::{write_asl_imu, write_imu_columns, write_imu_tk_pair};
use crate::io::Stored;
use crate::io::{ImuRecording, RecordingOptions};
use crate::model::calibration::ImuCalibration;
use std::path::{Path, PathBuf};

/// Write `rec` (already corrected) into `out` in the layout of `input`: an
/// ASL folder gets `out/mav0/imu0/data.csv`; imu_tk's pair keeps its two file
/// names; a text file keeps its name, column order and time unit. A ROS
/// recording (bag, MCAP, rosbag2 folder or `.db3`) gets the ASL layout, which
/// `tumble convert` also writes and every estimator's ASL/EuRoC reader reads.
pub fn write_like_input(
    rec: &ImuRecording,
    input: &Path,
    opts: &RecordingOptions,
    out: &Path,
) -> Result<Vec<PathBuf>, OutputError> {
    let name = |p: &Path| -> Result<PathBuf, String> {
        let f = p.file_name().ok_or_else(|| format!("{}: not a file", p.display()))?;
        Ok(out.join(f))
    };
    let err = |e: crate::InputError| e.to_string();
    // Never overwrite what was read: the raw recording is the user's only copy.
    let read: Vec<PathBuf> =
        rec.sources.iter().chain([&input.to_path_buf()]).filter_map(|p| p.canonicalize().ok()).collect();
    let guard = |p: &Path| -> Result<(), OutputError> {
        match p.canonicalize() {
            Ok(c) if read.contains(&c) => Err(OutputError::Failed(format!(
                "{}: is the input; write the corrected recording into another folder (--out)",
                p.display()
            ))),
            _ => Ok(()),
        }
    };
    // A folder (ASL, rosbag2) or a ROS file: the ASL layout.
    if input.is_dir() || crate::io::ros::Storage::of(input).ok().flatten().is_some() {
        let p = out.join("mav0").join("imu0").join("data.csv");
        guard(&p)?;
        write_asl_imu(&p, rec).map_err(err)?;
        return Ok(vec![p]);
    }
    let ext = input.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
    if let Some(g) = &opts.gyro_file {
        let (a, g) = (name(input)?, name(g)?);
        guard(&a)?;
        guard(&g)?;
        write_imu_tk_pair(&a, &g, rec, opts.format.time_unit).map_err(err)?;
        return Ok(vec![a, g]);
    }
    let mut p = name(input)?;
    if ext.as_deref() == Some("gz") {
        p.set_extension("");
    }
    guard(&p)?;
    write_imu_columns(&p, rec, &opts.format.columns, opts.format.time_unit).map_err(err)?;
    Ok(vec![p])
}

/// Why a calibration cannot be applied to a recording.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ApplyError {
    /// The recording's samples are read in other units than the calibration was made on.
    #[error(
        "{calibration}: the {what} was calibrated on {expected} input but this recording's {what} is read as {got}"
    )]
    Units {
        /// The calibration file.
        calibration: PathBuf,
        /// `accelerometer` or `gyro`.
        what: &'static str,
        /// The calibration's input units (`SI` or `counts`).
        expected: &'static str,
        /// The recording's (`SI` or `counts`).
        got: &'static str,
    },
    /// A calibration matrix cannot be inverted.
    #[error("{}: calibration matrices are singular", .0.display())]
    Singular(PathBuf),
}

/// A recording corrected by [`apply_calibration`].
#[derive(Debug, Clone)]
pub struct Applied {
    /// The corrected recording (SI units).
    pub recording: ImuRecording,
    /// The effects applied beyond eq. 16 (their ids).
    pub effects: Vec<String>,
    /// Problems applying them (see [`Corrector::warnings_for`](crate::model::calibration::Corrector::warnings_for)).
    pub warnings: Vec<String>,
    /// What else was done (the accelerometer resampled for an accel–gyro offset).
    pub notes: Vec<String>,
}

/// Correct `rec` with `cal` (read from `calibration`, named in errors): eq. 16
/// and the audit's effects, and the accelerometer resampled onto the gyro's
/// stamps when the calibration has an accel–gyro time offset. The recording's
/// units must be those the calibration was made on.
pub fn apply_calibration(
    mut rec: ImuRecording,
    cal: &ImuCalibration,
    calibration: &Path,
) -> Result<Applied, ApplyError> {
    let name = |u: &str| if u == "counts" { "counts" } else { "SI" };
    let read_as = |stored: Stored| if stored == Stored::RawCounts { "counts" } else { "SI" };
    for (what, stored, expected) in [
        ("accelerometer", rec.accel_units, cal.units.accel_input.as_str()),
        ("gyro", rec.gyro_units, cal.units.gyro_input.as_str()),
    ] {
        if read_as(stored) != name(expected) {
            return Err(ApplyError::Units {
                calibration: calibration.to_path_buf(),
                what,
                expected: name(expected),
                got: read_as(stored),
            });
        }
    }
    let corr = cal.corrector().ok_or_else(|| ApplyError::Singular(calibration.to_path_buf()))?;
    let warnings = corr.warnings_for(&rec);
    (rec.accel, rec.gyro) = corr.correct_recording(&rec);
    let mut notes = Vec::new();
    if let Some(o) = cal.time_offsets.filter(|o| o.accel_gyro_s != 0.0) {
        rec.accel = crate::io::imu::resample_delayed(&rec.t, &rec.accel, o.accel_gyro_s);
        notes.push(format!(
            "accelerometer resampled onto the gyro's stamps (accel–gyro offset {:+.3} ms)",
            1e3 * o.accel_gyro_s
        ));
    }
    rec.accel_units = Stored::Si;
    rec.gyro_units = Stored::Si;
    let effects = if corr.has_effects() { cal.effect_ids() } else { Vec::new() };
    Ok(Applied { recording: rec, effects, warnings, notes })
}
