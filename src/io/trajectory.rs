//! Trajectories: EuRoC/ASL ground truth (`t[ns], p, q(w,x,y,z), v, b_w, b_a`)
//! and the TUM format (`t[s] x y z qx qy qz qw`), read and written.

use super::table::{read_table, LineMap, TableSpec, TimeUnit};
use crate::error::InputError;
use std::io::Write;
use std::path::Path;

/// A timed sequence of body poses in a world frame, with optional velocity and biases.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Trajectory {
    /// Time of each state \[ns\].
    pub t_ns: Vec<i64>,
    /// Position of the body in the world frame \[m\].
    pub p: Vec<[f64; 3]>,
    /// Orientation world←body as a unit quaternion `[w, x, y, z]`.
    pub q: Vec<[f64; 4]>,
    /// Velocity in the world frame \[m/s\] (ASL ground truth only).
    pub v: Option<Vec<[f64; 3]>>,
    /// Gyro bias \[rad/s\] (ASL ground truth only).
    pub bias_gyro: Option<Vec<[f64; 3]>>,
    /// Accelerometer bias \[m/s²\] (ASL ground truth only).
    pub bias_accel: Option<Vec<[f64; 3]>>,
}

impl Trajectory {
    /// Number of states.
    pub fn len(&self) -> usize {
        self.t_ns.len()
    }
    /// True when empty.
    pub fn is_empty(&self) -> bool {
        self.t_ns.is_empty()
    }

    /// The states with times in `[from_ns, to_ns]` \[ns\].
    pub fn between(&self, from_ns: i64, to_ns: i64) -> Trajectory {
        let a = self.t_ns.partition_point(|&t| t < from_ns);
        let b = self.t_ns.partition_point(|&t| t <= to_ns).max(a);
        let part = |v: &Option<Vec<[f64; 3]>>| v.as_ref().map(|v| v[a..b].to_vec());
        Trajectory {
            t_ns: self.t_ns[a..b].to_vec(),
            p: self.p[a..b].to_vec(),
            q: self.q[a..b].to_vec(),
            v: part(&self.v),
            bias_gyro: part(&self.bias_gyro),
            bias_accel: part(&self.bias_accel),
        }
    }

    /// A trajectory from TUM rows held in memory (`t x y z qx qy qz qw`, `t`
    /// in seconds), checked as a TUM file would be: finite values, strictly
    /// increasing times and unit quaternions, each refused by its row (named
    /// as `row N` of `name`).
    pub fn from_tum_rows(name: &str, rows: &[[f64; 8]]) -> Result<Trajectory, InputError> {
        let file = Path::new(name);
        if let Some(row) = rows.iter().position(|r| r.iter().any(|v| !v.is_finite())) {
            return Err(InputError::file(file, format!("row {row}: a value is not a finite number")));
        }
        let mut tr = Trajectory {
            t_ns: rows.iter().map(|r| (r[0] * 1e9).round() as i64).collect(),
            p: rows.iter().map(|r| [r[1], r[2], r[3]]).collect(),
            q: rows.iter().map(|r| [r[7], r[4], r[5], r[6]]).collect(),
            ..Trajectory::default()
        };
        check_times_and_quaternions(file, &mut tr, &LineMap::default())?;
        Ok(tr)
    }
}

fn triads(cols: &[Vec<f64>], first: usize) -> Vec<[f64; 3]> {
    (0..cols[first].len()).map(|i| [cols[first][i], cols[first + 1][i], cols[first + 2][i]]).collect()
}

fn check_times_and_quaternions(path: &Path, tr: &mut Trajectory, lines: &LineMap) -> Result<(), InputError> {
    for (i, w) in tr.t_ns.windows(2).enumerate() {
        if w[1] <= w[0] {
            let what = if w[1] == w[0] { "repeats" } else { "goes backwards from" };
            return Err(InputError::at(path, lines.line(i + 1), format!("timestamp {what} the previous line's"))
                .with_hint("a trajectory needs strictly increasing times"));
        }
    }
    for (i, q) in tr.q.iter_mut().enumerate() {
        let n = q.iter().map(|x| x * x).sum::<f64>().sqrt();
        if (n - 1.0).abs() > 1e-2 {
            return Err(InputError::at(path, lines.line(i), format!("quaternion norm is {n:.4}, not 1"))
                .with_hint("check the column order (ASL: qw qx qy qz; TUM: qx qy qz qw)"));
        }
        q.iter_mut().for_each(|x| *x /= n);
    }
    Ok(())
}

/// Read EuRoC/ASL ground truth: `t[ns], px, py, pz, qw, qx, qy, qz` and, when
/// present, `vx vy vz, bwx bwy bwz, bax bay baz` (17 columns).
pub fn read_asl_groundtruth(path: &Path) -> Result<Trajectory, InputError> {
    let spec8 = TableSpec {
        time: Some((0, TimeUnit::Ns)),
        values: (1..8).collect(),
        names: ["px", "py", "pz", "qw", "qx", "qy", "qz"].map(String::from).to_vec(),
        ..TableSpec::default()
    };
    let head = read_table(path, &spec8)?;
    let full = head.header.as_deref().map(|h| h.split(',').count() >= 17).unwrap_or(false);
    let (table, has_extra) = if full {
        let names =
            ["px", "py", "pz", "qw", "qx", "qy", "qz", "vx", "vy", "vz", "bwx", "bwy", "bwz", "bax", "bay", "baz"];
        let spec = TableSpec {
            time: Some((0, TimeUnit::Ns)),
            values: (1..17).collect(),
            names: names.map(String::from).to_vec(),
            ..TableSpec::default()
        };
        (read_table(path, &spec)?, true)
    } else {
        (head, false)
    };
    let c = &table.columns;
    let mut tr = Trajectory {
        t_ns: table.t_ns.clone(),
        p: triads(c, 0),
        q: (0..table.t_ns.len()).map(|i| [c[3][i], c[4][i], c[5][i], c[6][i]]).collect(),
        v: has_extra.then(|| triads(c, 7)),
        bias_gyro: has_extra.then(|| triads(c, 10)),
        bias_accel: has_extra.then(|| triads(c, 13)),
    };
    check_times_and_quaternions(path, &mut tr, &table.lines)?;
    Ok(tr)
}

/// Read a TUM trajectory: `t x y z qx qy qz qw` per line, whitespace
/// separated, `t` in seconds (or in nanoseconds when the stamps are integers
/// of more than 12 digits, as some tools write them).
pub fn read_tum(path: &Path) -> Result<Trajectory, InputError> {
    let text = std::fs::read(path).map_err(|e| InputError::file(path, format!("cannot read: {e}")))?;
    let unit = if first_field(&text).is_some_and(is_ns_stamp) { TimeUnit::Ns } else { TimeUnit::S };
    let stamps = first_stamps(&text);
    if let [(_, a), (line, b)] = stamps[..] {
        if unit == TimeUnit::S && (b - a).abs() > MAX_POSE_STEP_S {
            return Err(InputError::at(path, line, format!("the stamp steps by {} from the line before", b - a))
                .with_hint(
                    "TUM stamps are seconds (or nanoseconds of more than 12 digits); convert other units to seconds",
                ));
        }
    }
    let spec = TableSpec {
        time: Some((0, unit)),
        values: (1..8).collect(),
        names: ["x", "y", "z", "qx", "qy", "qz", "qw"].map(String::from).to_vec(),
        ..TableSpec::default()
    };
    let table = read_table(path, &spec)?;
    let c = &table.columns;
    let mut tr = Trajectory {
        t_ns: table.t_ns.clone(),
        p: triads(c, 0),
        q: (0..table.t_ns.len()).map(|i| [c[6][i], c[3][i], c[4][i], c[5][i]]).collect(),
        ..Trajectory::default()
    };
    check_times_and_quaternions(path, &mut tr, &table.lines)?;
    Ok(tr)
}

/// The first data line's first field and whether the line is comma separated.
fn first_line(text: &[u8]) -> Option<(&[u8], bool)> {
    let line = text
        .split(|&c| c == b'\n')
        .map(|l| l.trim_ascii())
        .find(|l| !l.is_empty() && l[0] != b'#' && (l[0].is_ascii_digit() || l[0] == b'-' || l[0] == b'.'))?;
    let field = line.split(|&c| c == b',' || c.is_ascii_whitespace()).next().unwrap_or(&[]);
    Some((field, line.contains(&b',')))
}

fn first_field(text: &[u8]) -> Option<&[u8]> {
    first_line(text).map(|(f, _)| f)
}

/// The largest step between a trajectory's first two stamps read as seconds
/// \[s\]: poses an hour apart are stamps in another unit (nanoseconds or
/// microseconds since a start), which would otherwise be read as seconds.
const MAX_POSE_STEP_S: f64 = 3600.0;

/// The first fields of the first two data lines as numbers, with their
/// 1-based line numbers.
fn first_stamps(text: &[u8]) -> Vec<(usize, f64)> {
    text.split(|&c| c == b'\n')
        .enumerate()
        .map(|(i, l)| (i + 1, l.trim_ascii()))
        .filter(|(_, l)| !l.is_empty() && (l[0].is_ascii_digit() || l[0] == b'-' || l[0] == b'.'))
        .take(2)
        .filter_map(|(i, l)| {
            let field = l.split(|c| c.is_ascii_whitespace() || *c == b',').next()?;
            Some((i, std::str::from_utf8(field).ok()?.parse::<f64>().ok()?))
        })
        .collect()
}

/// An integer of more than 12 digits: a time stamp in nanoseconds.
fn is_ns_stamp(f: &[u8]) -> bool {
    f.len() > 12 && f.iter().all(u8::is_ascii_digit)
}

/// Read a trajectory in either format: ASL (EuRoC ground truth: comma
/// separated, `t[ns], x, y, z, qw, qx, qy, qz, …`) when the first data line
/// has commas, TUM (whitespace separated, `t x y z qx qy qz qw`, `t` in s or
/// ns) otherwise. The separator decides, not the stamp: TUM files with
/// nanosecond stamps exist, and their quaternion order differs.
pub fn read_trajectory(path: &Path) -> Result<Trajectory, InputError> {
    let text = std::fs::read(path).map_err(|e| InputError::file(path, format!("cannot read: {e}")))?;
    match first_line(&text) {
        Some((_, true)) => read_asl_groundtruth(path),
        _ => read_tum(path),
    }
}

fn io_err(path: &Path, e: std::io::Error) -> InputError {
    InputError::file(path, format!("cannot write: {e}"))
}

/// Write a trajectory in TUM format (`t[s] x y z qx qy qz qw`).
pub fn write_tum(path: &Path, tr: &Trajectory) -> Result<(), InputError> {
    let f = std::fs::File::create(path).map_err(|e| io_err(path, e))?;
    let mut w = std::io::BufWriter::new(f);
    for i in 0..tr.len() {
        let (p, q) = (tr.p[i], tr.q[i]);
        writeln!(
            w,
            "{}.{:09} {} {} {} {} {} {} {}",
            tr.t_ns[i].div_euclid(1_000_000_000),
            tr.t_ns[i].rem_euclid(1_000_000_000),
            p[0],
            p[1],
            p[2],
            q[1],
            q[2],
            q[3],
            q[0]
        )
        .map_err(|e| io_err(path, e))?;
    }
    w.flush().map_err(|e| io_err(path, e))
}

/// Write a trajectory as EuRoC/ASL ground truth (17 columns when velocity and
/// biases are present, 8 otherwise).
pub fn write_asl_groundtruth(path: &Path, tr: &Trajectory) -> Result<(), InputError> {
    let f = std::fs::File::create(path).map_err(|e| io_err(path, e))?;
    let mut w = std::io::BufWriter::new(f);
    let full = tr.v.is_some() && tr.bias_gyro.is_some() && tr.bias_accel.is_some();
    let mut header = String::from(
        "#timestamp [ns], p_RS_R_x [m], p_RS_R_y [m], p_RS_R_z [m], q_RS_w [], q_RS_x [], q_RS_y [], q_RS_z []",
    );
    if full {
        header.push_str(", v_RS_R_x [m s^-1], v_RS_R_y [m s^-1], v_RS_R_z [m s^-1], b_w_RS_S_x [rad s^-1], b_w_RS_S_y [rad s^-1], b_w_RS_S_z [rad s^-1], b_a_RS_S_x [m s^-2], b_a_RS_S_y [m s^-2], b_a_RS_S_z [m s^-2]");
    }
    writeln!(w, "{header}").map_err(|e| io_err(path, e))?;
    let mut line = String::new();
    for i in 0..tr.len() {
        line.clear();
        line.push_str(&tr.t_ns[i].to_string());
        let mut push = |v: &[f64]| {
            for x in v {
                line.push(',');
                line.push_str(ryu::Buffer::new().format(*x));
            }
        };
        push(&tr.p[i]);
        push(&tr.q[i]);
        if full {
            for series in [&tr.v, &tr.bias_gyro, &tr.bias_accel].into_iter().flatten() {
                push(&series[i]);
            }
        }
        writeln!(w, "{line}").map_err(|e| io_err(path, e))?;
    }
    w.flush().map_err(|e| io_err(path, e))
}
