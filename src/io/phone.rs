//! Phone sensor-logger exports: a folder of per-sensor CSV files, the
//! accelerometer and the gyro each with its own stamps, merged onto the
//! gyro's ([`super::split`]).
//!
//! - **Sensor Logger** (Kelvin Choi's app, iOS/Android): `Gyroscope.csv` and
//!   `TotalAcceleration.csv`, header `time,seconds_elapsed,z,y,x`, `time` in
//!   ns since the epoch, values in rad/s and m/s². Its `Accelerometer.csv` has
//!   gravity removed (the phone's own estimate subtracted) and is never read
//!   as specific force.
//! - **phyphox** (RWTH Aachen; "Export data → CSV (comma, decimal point)"):
//!   `Gyroscope.csv` with `"Time (s)","Gyroscope x (rad/s)",…` and
//!   `Accelerometer.csv` with `"Time (s)","Acceleration x (m/s^2)",…` (with
//!   gravity; its `Linear Acceleration.csv` is the one without).
//!
//! Columns are found by their header names, not their positions.

use super::imu::{ImuRecording, Stored};
use super::split::{merge_onto_gyro, Stream};
use super::table::{read_table, LineMap, TableSpec, TimeUnit};
use super::validate::{validate, ValidateOptions};
use crate::error::InputError;
use std::path::{Path, PathBuf};

/// Which logger wrote a folder.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PhoneLogger {
    /// Sensor Logger's export (`TotalAcceleration.csv` + `Gyroscope.csv`).
    SensorLogger,
    /// phyphox's CSV export (`Accelerometer.csv` + `Gyroscope.csv` with unit-suffixed headers).
    Phyphox,
}

impl PhoneLogger {
    /// The logger whose export `dir` is, if any.
    pub fn of(dir: &Path) -> Option<PhoneLogger> {
        let gyro = dir.join("Gyroscope.csv");
        let head = first_line(&gyro)?;
        if head.contains("seconds_elapsed") {
            Some(PhoneLogger::SensorLogger)
        } else if head.contains("Time (s)") {
            Some(PhoneLogger::Phyphox)
        } else {
            None
        }
    }
    /// The app's name.
    pub fn name(self) -> &'static str {
        match self {
            PhoneLogger::SensorLogger => "Sensor Logger",
            PhoneLogger::Phyphox => "phyphox",
        }
    }
}

fn first_line(p: &Path) -> Option<String> {
    use std::io::BufRead;
    let f = std::fs::File::open(p).ok()?;
    let mut s = String::new();
    std::io::BufReader::new(f).read_line(&mut s).ok()?;
    Some(s)
}

/// Header cells without quotes and spaces around them.
fn header(path: &Path) -> Result<Vec<String>, InputError> {
    let h = first_line(path).ok_or_else(|| InputError::file(path, "cannot read its header line"))?;
    let sep = if h.contains(';') && !h.contains(',') { ';' } else { ',' };
    Ok(h.trim_end().split(sep).map(|c| c.trim().trim_matches('"').to_string()).collect())
}

/// Index of the first column for which `is` holds, or an error naming what was wanted.
fn column(path: &Path, cols: &[String], what: &str, is: impl Fn(&str) -> bool) -> Result<usize, InputError> {
    cols.iter().position(|c| is(c)).ok_or_else(|| {
        InputError::at(path, 1, format!("no {what} column in the header"))
            .with_hint(format!("columns: {}", cols.join(", ")))
    })
}

/// One sensor file as a stream: the time column and the x, y, z columns found by name.
fn stream(path: &Path, logger: PhoneLogger) -> Result<(Stream, LineMap), InputError> {
    if !path.is_file() {
        return Err(InputError::file(path, "is missing from the export"));
    }
    let cols = header(path)?;
    let (time, unit, axes) = match logger {
        PhoneLogger::SensorLogger => {
            let t = column(path, &cols, "time", |c| c == "time")?;
            let ax = ["x", "y", "z"].map(|a| column(path, &cols, a, |c| c == a));
            (t, TimeUnit::Ns, ax)
        }
        PhoneLogger::Phyphox => {
            let t = column(path, &cols, "Time (s)", |c| c.starts_with("Time (s)"))?;
            // "Gyroscope x (rad/s)", "Acceleration x (m/s^2)": the axis is the word before the unit.
            let ax = ["x", "y", "z"].map(|a| {
                column(path, &cols, &format!("'… {a} (…)'"), |c| {
                    c.contains(&format!(" {a} (")) && !c.starts_with("Time")
                })
            });
            (t, TimeUnit::S, ax)
        }
    };
    let [x, y, z] = axes;
    let spec = TableSpec {
        time: Some((time, unit)),
        triads: vec![[x?, y?, z?]],
        triad_names: vec![path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default()],
        ..TableSpec::default()
    };
    let t = read_table(path, &spec)?;
    Ok((Stream { t_ns: t.t_ns, v: t.triads.into_iter().next().unwrap_or_default() }, t.lines))
}

/// Read a phone logger's export folder (see the module doc) into one recording
/// on the gyro's stamps, SI units.
pub fn read_phone_folder(dir: &Path, checks: &ValidateOptions) -> Result<ImuRecording, InputError> {
    let logger = PhoneLogger::of(dir).ok_or_else(|| {
        InputError::file(dir, "is not a Sensor Logger or phyphox export (no recognised Gyroscope.csv)")
    })?;
    let gyro_path = dir.join("Gyroscope.csv");
    let accel_path: PathBuf = match logger {
        PhoneLogger::SensorLogger => {
            let total = dir.join("TotalAcceleration.csv");
            if !total.is_file() && dir.join("Accelerometer.csv").is_file() {
                return Err(InputError::file(&total, "is missing; Accelerometer.csv has gravity removed").with_hint(
                    "enable 'Total Acceleration' (or Accelerometer + Gravity) in Sensor Logger and record again",
                ));
            }
            total
        }
        PhoneLogger::Phyphox => dir.join("Accelerometer.csv"),
    };
    let (g, lines) = stream(&gyro_path, logger)?;
    let (a, _) = stream(&accel_path, logger)?;
    let m = merge_onto_gyro(g, a).map_err(|e| InputError::file(dir, e))?;
    // Messages point at the gyro file's lines (the merged samples are its rows).
    let t0 = m.t_ns.first().copied().unwrap_or(0);
    let mut warnings = vec![format!("{} export: {}", logger.name(), m.note)];
    warnings.extend(m.warnings.iter().map(|w| format!("{}: {w}", accel_path.display())));
    let mut rec = ImuRecording {
        sources: vec![gyro_path, accel_path],
        topic: None,
        t0_ns: t0,
        t: m.t_ns.iter().map(|&t| (t - t0) as f64 * 1e-9).collect(),
        gyro: m.gyro,
        accel: m.accel,
        temperature: None,
        gyro_units: Stored::Si,
        accel_units: Stored::Si,
        lines: lines.slice(m.first_kept),
        warnings,
    };
    validate(&mut rec, checks)?;
    Ok(rec)
}
