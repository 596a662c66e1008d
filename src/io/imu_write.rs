//! Writers of IMU recordings in the layouts the readers accept: an ASL
//! `imu0/data.csv`, imu_tk's pair of `t x y z` files, and a text table in a
//! declared column order. Values are written as stored (SI after correction).

use super::imu::ImuRecording;
use super::imu_text::ImuColumns;
use super::table::TimeUnit;
use crate::error::InputError;
use std::io::Write;
use std::path::Path;

/// Header of an ASL (EuRoC) `imu0/data.csv`.
pub fn asl_imu_header(temperature: bool) -> String {
    let mut header = String::from("#timestamp [ns],w_RS_S_x [rad s^-1],w_RS_S_y [rad s^-1],w_RS_S_z [rad s^-1],a_RS_S_x [m s^-2],a_RS_S_y [m s^-2],a_RS_S_z [m s^-2]");
    if temperature {
        header.push_str(",temperature [degC]");
    }
    header.push('\n');
    header
}

fn create(path: &Path) -> Result<std::io::BufWriter<std::fs::File>, InputError> {
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(|e| InputError::file(dir, format!("cannot create: {e}")))?;
    }
    let f = std::fs::File::create(path).map_err(|e| InputError::file(path, format!("cannot create: {e}")))?;
    Ok(std::io::BufWriter::with_capacity(1 << 20, f))
}

fn num(x: f64) -> String {
    ryu::Buffer::new().format(x).to_string()
}

/// Time of sample `i` in `unit`, from the recording's absolute nanoseconds.
fn time_in(rec: &ImuRecording, i: usize, unit: TimeUnit) -> String {
    match unit {
        TimeUnit::Ns => rec.t_ns(i).to_string(),
        u => num(rec.t_ns(i) as f64 / u.ns_per_unit()),
    }
}

/// Write an ASL `data.csv` (ns, rad/s, m/s², temperature when present).
pub fn write_asl_imu(path: &Path, rec: &ImuRecording) -> Result<(), InputError> {
    let mut w = create(path)?;
    let io = |e: std::io::Error| InputError::file(path, e.to_string());
    w.write_all(asl_imu_header(rec.temperature.is_some()).as_bytes()).map_err(io)?;
    for i in 0..rec.len() {
        let (g, a) = (rec.gyro[i], rec.accel[i]);
        let mut line = format!(
            "{},{},{},{},{},{},{}",
            rec.t_ns(i),
            num(g[0]),
            num(g[1]),
            num(g[2]),
            num(a[0]),
            num(a[1]),
            num(a[2])
        );
        if let Some(t) = &rec.temperature {
            line.push(',');
            line.push_str(&num(t[i]));
        }
        line.push('\n');
        w.write_all(line.as_bytes()).map_err(io)?;
    }
    w.flush().map_err(io)
}

/// Write imu_tk's two files (`t x y z`, time in `unit`).
pub fn write_imu_tk_pair(accel: &Path, gyro: &Path, rec: &ImuRecording, unit: TimeUnit) -> Result<(), InputError> {
    for (path, v) in [(accel, &rec.accel), (gyro, &rec.gyro)] {
        let mut w = create(path)?;
        let io = |e: std::io::Error| InputError::file(path, e.to_string());
        for (i, s) in v.iter().enumerate() {
            writeln!(w, "{} {} {} {}", time_in(rec, i, unit), num(s[0]), num(s[1]), num(s[2])).map_err(io)?;
        }
        w.flush().map_err(io)?;
    }
    Ok(())
}

/// Write a comma-separated table with the columns where `columns` puts them
/// (skipped columns are written as 0), time in `unit`, and a header line.
pub fn write_imu_columns(
    path: &Path,
    rec: &ImuRecording,
    columns: &ImuColumns,
    unit: TimeUnit,
) -> Result<(), InputError> {
    let mut slots: Vec<(usize, &str)> = Vec::new();
    if let Some(t) = columns.time {
        slots.push((t, "t"));
    }
    for (cols, names) in [(columns.gyro, ["gx", "gy", "gz"]), (columns.accel, ["ax", "ay", "az"])] {
        if let Some(c) = cols {
            for k in 0..3 {
                slots.push((c[k], names[k]));
            }
        }
    }
    if let (Some(c), Some(_)) = (columns.temperature, &rec.temperature) {
        slots.push((c, "temp"));
    }
    let width = slots.iter().map(|s| s.0 + 1).max().unwrap_or(0);
    let mut header = vec!["_"; width];
    for &(c, name) in &slots {
        header[c] = name;
    }
    let mut w = create(path)?;
    let io = |e: std::io::Error| InputError::file(path, e.to_string());
    writeln!(w, "# {}", header.join(",")).map_err(io)?;
    for i in 0..rec.len() {
        let mut row = vec!["0".to_string(); width];
        for &(c, name) in &slots {
            row[c] = match name {
                "t" => time_in(rec, i, unit),
                "gx" | "gy" | "gz" => num(rec.gyro[i][(name.as_bytes()[1] - b'x') as usize]),
                "ax" | "ay" | "az" => num(rec.accel[i][(name.as_bytes()[1] - b'x') as usize]),
                _ => num(rec.temperature.as_ref().map(|t| t[i]).unwrap_or(0.0)),
            };
        }
        writeln!(w, "{}", row.join(",")).map_err(io)?;
    }
    w.flush().map_err(io)
}
