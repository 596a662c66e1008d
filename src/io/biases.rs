//! Bias tracks: the `biases.csv` that `tumble vio` writes and `tumble eval`
//! reads — `t[ns], b_a (3) [m/s²], b_g (3) [rad/s]` and optionally their
//! standard deviations (6) and a keyframe flag.

use super::table::{read_table, TableSpec, TimeUnit};
use crate::error::InputError;
use std::io::Write;
use std::path::Path;

/// Estimated IMU biases over time, with their 1σ when known.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct BiasTrack {
    /// Time of each row \[ns\].
    pub t_ns: Vec<i64>,
    /// Accelerometer bias \[m/s²\].
    pub accel: Vec<[f64; 3]>,
    /// Gyro bias \[rad/s\].
    pub gyro: Vec<[f64; 3]>,
    /// Standard deviation of the accelerometer bias \[m/s²\].
    pub accel_std: Option<Vec<[f64; 3]>>,
    /// Standard deviation of the gyro bias \[rad/s\].
    pub gyro_std: Option<Vec<[f64; 3]>>,
    /// Whether each row was a keyframe (when the file says).
    pub keyframe: Option<Vec<bool>>,
}

const HEADER: &str = "#timestamp [ns],b_a_x [m/s^2],b_a_y,b_a_z,b_g_x [rad/s],b_g_y,b_g_z,std_b_a_x,std_b_a_y,std_b_a_z,std_b_g_x,std_b_g_y,std_b_g_z,keyframe";

/// Number of fields on the first data line (not blank, not a comment, starting with a digit).
fn fields_on_first_data_line(path: &Path) -> Result<usize, InputError> {
    let text = std::fs::read_to_string(path).map_err(|e| InputError::file(path, format!("cannot read: {e}")))?;
    let line = text
        .lines()
        .map(str::trim)
        .find(|l| !l.is_empty() && !l.starts_with('#') && l.starts_with(|c: char| c.is_ascii_digit() || c == '-'))
        .ok_or_else(|| InputError::file(path, "no data lines"))?;
    Ok(line.split(|c: char| c == ',' || c.is_ascii_whitespace()).filter(|f| !f.is_empty()).count())
}

/// Read a bias track: 7 columns (`t[ns], b_a, b_g`), 13 (with the standard
/// deviations) or 14 (and a keyframe flag 0/1). Times must increase strictly.
pub fn read_biases(path: &Path) -> Result<BiasTrack, InputError> {
    let n = fields_on_first_data_line(path)?;
    if n != 7 && n != 13 && n != 14 {
        return Err(InputError::file(path, format!("a bias track has 7, 13 or 14 columns, this one {n}"))
            .with_hint("t[ns], b_a_x, b_a_y, b_a_z, b_g_x, b_g_y, b_g_z [, their 6 std devs [, keyframe]]"));
    }
    let names = [
        "b_a_x",
        "b_a_y",
        "b_a_z",
        "b_g_x",
        "b_g_y",
        "b_g_z",
        "std_b_a_x",
        "std_b_a_y",
        "std_b_a_z",
        "std_b_g_x",
        "std_b_g_y",
        "std_b_g_z",
        "keyframe",
    ];
    let spec = TableSpec {
        time: Some((0, TimeUnit::Ns)),
        values: (1..n).collect(),
        names: names[..n - 1].iter().map(|s| s.to_string()).collect(),
        allow_nan: true,
        ..TableSpec::default()
    };
    let table = read_table(path, &spec)?;
    for (i, w) in table.t_ns.windows(2).enumerate() {
        if w[1] <= w[0] {
            return Err(InputError::at(path, table.lines.line(i + 1), "timestamp does not increase")
                .with_hint("a bias track needs strictly increasing times"));
        }
    }
    let c = &table.columns;
    // NaN means "unknown" for a standard deviation, nowhere else.
    if let Some((k, i)) = (0..6.min(n - 1))
        .chain((n == 14).then_some(12))
        .find_map(|k| c[k].iter().position(|v| v.is_nan()).map(|i| (k, i)))
    {
        return Err(InputError::at(
            path,
            table.lines.line(i),
            format!("{} (column {}) is not finite (NaN)", names[k], k + 2),
        )
        .with_hint("only the standard deviations may be NaN (unknown)"));
    }
    let triad =
        |k: usize| -> Vec<[f64; 3]> { (0..table.t_ns.len()).map(|i| [c[k][i], c[k + 1][i], c[k + 2][i]]).collect() };
    for (k, name) in [(6, "std_b_a"), (9, "std_b_g")] {
        if n >= 13 {
            if let Some(i) =
                c[k..k + 3].iter().flat_map(|col| col.iter().enumerate()).find(|(_, v)| **v < 0.0).map(|x| x.0)
            {
                return Err(InputError::at(path, table.lines.line(i), format!("{name} is negative")));
            }
        }
    }
    Ok(BiasTrack {
        t_ns: table.t_ns.clone(),
        accel: triad(0),
        gyro: triad(3),
        accel_std: (n >= 13).then(|| triad(6)),
        gyro_std: (n >= 13).then(|| triad(9)),
        keyframe: (n == 14).then(|| c[12].iter().map(|&v| v != 0.0).collect()),
    })
}

/// Write a bias track: 14 columns when both standard deviations are known
/// (keyframe 0 when unknown), the 7 columns `t, b_a, b_g` otherwise.
pub fn write_biases(path: &Path, b: &BiasTrack) -> Result<(), InputError> {
    let io_err = |e: std::io::Error| InputError::file(path, format!("cannot write: {e}"));
    let f = std::fs::File::create(path).map_err(io_err)?;
    let mut w = std::io::BufWriter::new(f);
    let stds = b.accel_std.as_ref().zip(b.gyro_std.as_ref());
    let header = if stds.is_some() { HEADER } else { &HEADER[..HEADER.find(",std_b_a_x").unwrap_or(HEADER.len())] };
    writeln!(w, "{header}").map_err(io_err)?;
    let mut line = String::new();
    for i in 0..b.t_ns.len() {
        line.clear();
        line.push_str(&b.t_ns[i].to_string());
        let mut push = |v: &[f64; 3]| v.iter().for_each(|x| line.push_str(&format!(",{x}")));
        push(&b.accel[i]);
        push(&b.gyro[i]);
        if let Some((sa, sg)) = stds {
            push(&sa[i]);
            push(&sg[i]);
            let kf = b.keyframe.as_ref().is_some_and(|k| k[i]);
            line.push_str(if kf { ",1" } else { ",0" });
        }
        writeln!(w, "{line}").map_err(io_err)?;
    }
    w.flush().map_err(io_err)
}
