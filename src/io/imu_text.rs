//! IMU recordings in plain text: a declared column map and units, one file
//! holding both sensors or imu_tk's pair of `t x y z` files.
//!
//! ```
//! use tumble::io::{ImuColumns, ImuTextFormat, GyroUnit, AccelUnit, TimeUnit};
//! // A CSV "time [ms], ax, ay, az [g], gx, gy, gz [deg/s]":
//! let fmt = ImuTextFormat {
//!     columns: ImuColumns::parse("t,ax,ay,az,gx,gy,gz").unwrap(),
//!     time_unit: TimeUnit::Ms,
//!     gyro_unit: GyroUnit::DegPerS,
//!     accel_unit: AccelUnit::G,
//!     ..ImuTextFormat::default()
//! };
//! assert_eq!(fmt.columns.accel, Some([1, 2, 3]));
//! ```

use super::imu::{ImuRecording, Stored};
use super::table::{peek_header, read_table, Table, TableSpec, TimeUnit};
use super::validate::{validate, ValidateOptions};
use crate::error::InputError;
use crate::OptionError;
use rayon::prelude::*;
use std::path::Path;

pub use crate::model::STANDARD_GRAVITY;

/// Unit of the gyro columns.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum GyroUnit {
    /// rad/s.
    RadPerS,
    /// deg/s.
    DegPerS,
    /// Raw counts: `(raw − offset) · scale` \[rad/s\]; kept raw when `scale` is None.
    Counts {
        /// rad/s per count, if known.
        scale: Option<f64>,
        /// Zero-rate offset \[counts\].
        offset: f64,
    },
}

/// Unit of the accelerometer columns.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum AccelUnit {
    /// m/s².
    MetersPerS2,
    /// Standard gravities (9.80665 m/s²).
    G,
    /// Raw counts: `(raw − offset) · scale` \[m/s²\]; kept raw when `scale` is None.
    Counts {
        /// m/s² per count, if known.
        scale: Option<f64>,
        /// Zero-g offset \[counts\].
        offset: f64,
    },
}

impl GyroUnit {
    /// Parse `rad/s`, `deg/s`, `counts` or `counts:SCALE[:OFFSET]`.
    pub fn parse(s: &str) -> Result<GyroUnit, OptionError> {
        match s {
            "rad/s" => Ok(GyroUnit::RadPerS),
            "deg/s" => Ok(GyroUnit::DegPerS),
            _ => parse_counts(s)
                .map(|(scale, offset)| GyroUnit::Counts { scale, offset })
                .map_err(|m| OptionError::new("--gyro-unit", format!("cannot be read: {m}"))),
        }
    }
    fn convert(self, v: f64) -> f64 {
        match self {
            GyroUnit::RadPerS => v,
            GyroUnit::DegPerS => v.to_radians(),
            GyroUnit::Counts { scale: Some(s), offset } => (v - offset) * s,
            GyroUnit::Counts { scale: None, .. } => v,
        }
    }
    fn stored(self) -> Stored {
        if matches!(self, GyroUnit::Counts { scale: None, .. }) {
            Stored::RawCounts
        } else {
            Stored::Si
        }
    }
}

impl AccelUnit {
    /// Parse `m/s2` (or `m/s^2`, `m/s²`), `g`, `counts` or `counts:SCALE[:OFFSET]`.
    pub fn parse(s: &str) -> Result<AccelUnit, OptionError> {
        match s {
            "m/s2" | "m/s^2" | "m/s²" => Ok(AccelUnit::MetersPerS2),
            "g" => Ok(AccelUnit::G),
            _ => parse_counts(s)
                .map(|(scale, offset)| AccelUnit::Counts { scale, offset })
                .map_err(|m| OptionError::new("--accel-unit", format!("cannot be read: {m}"))),
        }
    }
    fn convert(self, v: f64) -> f64 {
        match self {
            AccelUnit::MetersPerS2 => v,
            AccelUnit::G => v * STANDARD_GRAVITY,
            AccelUnit::Counts { scale: Some(s), offset } => (v - offset) * s,
            AccelUnit::Counts { scale: None, .. } => v,
        }
    }
    fn stored(self) -> Stored {
        if matches!(self, AccelUnit::Counts { scale: None, .. }) {
            Stored::RawCounts
        } else {
            Stored::Si
        }
    }
}

fn parse_counts(s: &str) -> Result<(Option<f64>, f64), String> {
    let mut it = s.split(':');
    if it.next() != Some("counts") {
        return Err(format!("unknown unit '{s}'"));
    }
    let num = |x: Option<&str>, what: &str| -> Result<Option<f64>, String> {
        x.map(|t| t.parse::<f64>().map_err(|_| format!("counts {what} '{t}' is not a number"))).transpose()
    };
    let scale = num(it.next(), "scale")?;
    let offset = num(it.next(), "offset")?.unwrap_or(0.0);
    if let Some(extra) = it.next() {
        return Err(format!("'{s}': `counts:SCALE:OFFSET` takes two numbers, `{extra}` is a third"));
    }
    match scale {
        Some(k) if !(k.is_finite() && k != 0.0) => {
            Err(format!("counts scale must be a finite non-zero number (units per count), got {k}"))
        }
        _ if !offset.is_finite() => Err(format!("counts offset must be finite, got {offset}")),
        _ => Ok((scale, offset)),
    }
}

/// 0-based column indices of time, gyro, accelerometer and temperature.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ImuColumns {
    /// Timestamp column; None when the file has none (then the nominal rate
    /// must be given and sample `i` is stamped `i / rate`).
    pub time: Option<usize>,
    /// Gyro x, y, z columns.
    pub gyro: Option<[usize; 3]>,
    /// Accelerometer x, y, z columns.
    pub accel: Option<[usize; 3]>,
    /// Temperature column \[°C\].
    pub temperature: Option<usize>,
}

impl Default for ImuColumns {
    /// EuRoC order: `t, gx, gy, gz, ax, ay, az`.
    fn default() -> Self {
        ImuColumns { time: Some(0), gyro: Some([1, 2, 3]), accel: Some([4, 5, 6]), temperature: None }
    }
}

impl ImuColumns {
    /// Parse a comma-separated list naming each column in file order:
    /// `t`, `gx gy gz`, `ax ay az`, `temp`, and `_` for a column to skip.
    /// Without `t`, samples are stamped from the nominal rate.
    pub fn parse(spec: &str) -> Result<ImuColumns, OptionError> {
        Self::parse_spec(spec).map_err(|m| OptionError::new("--columns", format!("cannot be read: {m}")))
    }

    fn parse_spec(spec: &str) -> Result<ImuColumns, String> {
        let mut time = None;
        let mut gyro = [None; 3];
        let mut accel = [None; 3];
        let mut temperature = None;
        for (i, name) in spec.split(',').map(str::trim).enumerate() {
            let slot = match name {
                "t" | "time" => &mut time,
                "gx" => &mut gyro[0],
                "gy" => &mut gyro[1],
                "gz" => &mut gyro[2],
                "ax" => &mut accel[0],
                "ay" => &mut accel[1],
                "az" => &mut accel[2],
                "temp" | "temperature" => &mut temperature,
                "_" => continue,
                other => {
                    return Err(format!(
                        "unknown column name '{other}' (use t, gx, gy, gz, ax, ay, az, temp or _ to skip)"
                    ))
                }
            };
            if slot.replace(i).is_some() {
                return Err(format!("column '{name}' named twice"));
            }
        }
        let triad = |v: [Option<usize>; 3], what: &str| -> Result<Option<[usize; 3]>, String> {
            match v {
                [Some(x), Some(y), Some(z)] => Ok(Some([x, y, z])),
                [None, None, None] => Ok(None),
                _ => Err(format!("{what}: name all three axes or none")),
            }
        };
        let cols = ImuColumns { time, gyro: triad(gyro, "gyro")?, accel: triad(accel, "accelerometer")?, temperature };
        if cols.gyro.is_none() && cols.accel.is_none() {
            return Err("neither gyro nor accelerometer columns named".into());
        }
        Ok(cols)
    }
}

/// How to read an IMU text file.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ImuTextFormat {
    /// Column map.
    pub columns: ImuColumns,
    /// Unit of the time column.
    pub time_unit: TimeUnit,
    /// Unit of the gyro columns.
    pub gyro_unit: GyroUnit,
    /// Unit of the accelerometer columns.
    pub accel_unit: AccelUnit,
    /// Checks run after reading.
    pub validate: ValidateOptions,
}

impl Default for ImuTextFormat {
    /// EuRoC's `imu0/data.csv`: ns, rad/s, m/s².
    fn default() -> Self {
        ImuTextFormat {
            columns: ImuColumns::default(),
            time_unit: TimeUnit::Ns,
            gyro_unit: GyroUnit::RadPerS,
            accel_unit: AccelUnit::MetersPerS2,
            validate: ValidateOptions::default(),
        }
    }
}

/// A recording from samples held in memory (a caller's arrays: the Python
/// bindings), read as a file with these units would be: times `t` \[s\] and
/// rows of gyro x y z and accelerometer x y z converted to SI (raw counts
/// without a scale stay raw), a non-finite value refused by its row (0-based,
/// named `row N` in `name`'s messages as a file's line would be), then the
/// readers' checks (`checks`). `name` stands for the file in messages.
pub fn recording_from_samples(
    name: &str,
    t: Vec<f64>,
    gyro: &[[f64; 3]],
    accel: &[[f64; 3]],
    (gyro_unit, accel_unit): (GyroUnit, AccelUnit),
    checks: &ValidateOptions,
) -> Result<ImuRecording, InputError> {
    let file = Path::new(name);
    if gyro.len() != t.len() || accel.len() != t.len() {
        return Err(InputError::file(
            file,
            format!(
                "{} times, {} gyro rows and {} accelerometer rows: one of each per sample",
                t.len(),
                gyro.len(),
                accel.len()
            ),
        ));
    }
    let bad = |row: usize, what: &str| InputError::file(file, format!("row {row}: {what} is not a finite number"));
    if let Some(row) = t.iter().position(|v| !v.is_finite()) {
        return Err(bad(row, "the time"));
    }
    for (rows, what) in [(gyro, "a gyro value"), (accel, "an accelerometer value")] {
        if let Some(row) = rows.iter().position(|r| r.iter().any(|v| !v.is_finite())) {
            return Err(bad(row, what));
        }
    }
    let mut rec = ImuRecording {
        sources: vec![file.to_path_buf()],
        t,
        gyro: gyro.iter().map(|r| r.map(|v| gyro_unit.convert(v))).collect(),
        accel: accel.iter().map(|r| r.map(|v| accel_unit.convert(v))).collect(),
        gyro_units: gyro_unit.stored(),
        accel_units: accel_unit.stored(),
        ..ImuRecording::default()
    };
    validate(&mut rec, checks)?;
    Ok(rec)
}

/// Read one IMU text file (CSV or whitespace; `.gz` allowed) and validate it.
///
/// A column whose header name starts with `temperature` is used as the
/// temperature column when the format names none.
pub fn read_imu_text(path: &Path, fmt: &ImuTextFormat) -> Result<ImuRecording, InputError> {
    let c = &fmt.columns;
    let mut spec = TableSpec { time: c.time.map(|tc| (tc, fmt.time_unit)), ..TableSpec::default() };
    for (triad, what) in [(c.gyro, "gyro"), (c.accel, "accel")] {
        if let Some(ix) = triad {
            spec.triads.push(ix);
            spec.triad_names.push(what.into());
        }
    }
    let temperature = c.temperature.or_else(|| header_temperature_column(peek_header(path).ok().flatten().as_deref()));
    if let Some(tc) = temperature {
        spec.values.push(tc);
        spec.names.push("temperature".into());
    }
    let rate = match (c.time, fmt.validate.nominal_rate) {
        (Some(_), _) => None,
        (None, Some(r)) if r.is_finite() && r > 0.0 => Some(r),
        (None, _) => {
            return Err(InputError::file(path, "the column map has no time column and no nominal rate is given")
                .with_hint("name the time column (t) or give the sample rate"))
        }
    };
    let mut table = read_table(path, &spec)?;
    if let Some(r) = rate {
        table.t_ns.par_iter_mut().enumerate().for_each(|(i, t)| *t = (i as f64 * 1e9 / r).round() as i64);
    }
    let mut rec = recording_from_table(path, table, fmt);
    validate(&mut rec, &fmt.validate)?;
    Ok(rec)
}

fn header_temperature_column(header: Option<&str>) -> Option<usize> {
    let h = header?;
    let sep = if h.contains(',') { ',' } else { ' ' };
    h.split(sep).filter(|s| !s.trim().is_empty()).position(|name| name.trim().to_lowercase().starts_with("temperature"))
}

/// Build the recording from a table whose triads are gyro then accelerometer
/// (those present) and whose only value column, if any, is the temperature.
/// Reuses the table's buffers: units are converted in place.
fn recording_from_table(path: &Path, table: Table, fmt: &ImuTextFormat) -> ImuRecording {
    let t0 = table.t_ns.first().copied().unwrap_or(0);
    let mut triads = table.triads.into_iter();
    let mut take = |present: bool| if present { triads.next().unwrap_or_default() } else { Vec::new() };
    let mut gyro = take(fmt.columns.gyro.is_some());
    let mut accel = take(fmt.columns.accel.is_some());
    if fmt.gyro_unit != GyroUnit::RadPerS {
        gyro.par_iter_mut().for_each(|w| *w = w.map(|v| fmt.gyro_unit.convert(v)));
    }
    if fmt.accel_unit != AccelUnit::MetersPerS2 {
        accel.par_iter_mut().for_each(|a| *a = a.map(|v| fmt.accel_unit.convert(v)));
    }
    ImuRecording {
        sources: vec![path.to_path_buf()],
        topic: None,
        t0_ns: t0,
        // In place: an i64 buffer becomes the f64 one.
        t: table.t_ns.into_iter().map(|x| (x - t0) as f64 * 1e-9).collect(),
        gyro,
        accel,
        temperature: table.columns.into_iter().next(),
        gyro_units: fmt.gyro_unit.stored(),
        accel_units: fmt.accel_unit.stored(),
        lines: table.lines,
        warnings: Vec::new(),
    }
}

/// Read imu_tk's pair of files (`t x y z` each, same timestamps line by line,
/// or each with its own stamps and rate: then merged onto the gyro's stamps,
/// see [`super::split`]):
/// the accelerometer file in `accel_unit`, the gyro file in `gyro_unit`, time in `time_unit`.
pub fn read_imu_tk(
    accel_path: &Path,
    gyro_path: &Path,
    time_unit: TimeUnit,
    accel_unit: AccelUnit,
    gyro_unit: GyroUnit,
    checks: &ValidateOptions,
) -> Result<ImuRecording, InputError> {
    let one = |path: &Path, what: &str| {
        let spec = TableSpec {
            time: Some((0, time_unit)),
            triads: vec![[1, 2, 3]],
            triad_names: vec![what.into()],
            ..TableSpec::default()
        };
        read_table(path, &spec)
    };
    let acc = one(accel_path, "accel")?;
    let gyr = one(gyro_path, "gyro")?;
    let paired = acc.t_ns.len() == gyr.t_ns.len() && acc.t_ns.iter().zip(&gyr.t_ns).all(|(a, g)| (a - g).abs() <= 1000);
    let mut notes = Vec::new();
    let one = |t: Vec<Vec<[f64; 3]>>| t.into_iter().next().unwrap_or_default();
    // Files that do not pair line by line are two streams with their own
    // stamps (a phone, a RealSense, a dropped line): merged onto the gyro's.
    let (t_ns, triads, lines) = if paired {
        (acc.t_ns, vec![one(gyr.triads), one(acc.triads)], acc.lines)
    } else {
        use super::split::{merge_onto_gyro, Stream};
        let m = merge_onto_gyro(
            Stream { t_ns: gyr.t_ns, v: one(gyr.triads) },
            Stream { t_ns: acc.t_ns, v: one(acc.triads) },
        )
        .map_err(|e| InputError::file(gyro_path, format!("with {}: {e}", accel_path.display())))?;
        notes.push(format!("{} + {}: {}", accel_path.display(), gyro_path.display(), m.note));
        notes.extend(m.warnings.iter().map(|w| format!("{}: {w}", accel_path.display())));
        (m.t_ns, vec![m.gyro, m.accel], gyr.lines.slice(m.first_kept))
    };
    let fmt = ImuTextFormat {
        columns: ImuColumns { time: Some(0), gyro: Some([1, 2, 3]), accel: Some([4, 5, 6]), temperature: None },
        time_unit,
        gyro_unit,
        accel_unit,
        validate: checks.clone(),
    };
    let table = Table { t_ns, triads, lines, ..Table::default() };
    let mut rec = recording_from_table(accel_path, table, &fmt);
    rec.sources.push(gyro_path.to_path_buf());
    rec.warnings.extend(notes);
    validate(&mut rec, checks)?;
    Ok(rec)
}
