//! Streaming reader of numeric text tables (CSV or whitespace separated), the
//! engine under every IMU and trajectory text format.
//!
//! The file is read in blocks of a few MiB (plain or gzip-compressed, by the
//! `.gz` extension); each block is cut at line ends and parsed on all cores.
//! Numbers are parsed with `fast-float2`; nanosecond timestamps as integers so
//! 19-digit EuRoC stamps keep every digit. Memory stays at the output plus one
//! block.

use crate::error::InputError;
use rayon::prelude::*;
use std::io::Read;
use std::path::Path;

/// Unit of a timestamp column.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TimeUnit {
    /// Seconds.
    S,
    /// Milliseconds.
    Ms,
    /// Microseconds.
    Us,
    /// Nanoseconds.
    Ns,
}

impl TimeUnit {
    /// Nanoseconds per unit.
    pub fn ns_per_unit(self) -> f64 {
        match self {
            TimeUnit::S => 1e9,
            TimeUnit::Ms => 1e6,
            TimeUnit::Us => 1e3,
            TimeUnit::Ns => 1.0,
        }
    }
    /// Parse `s`, `ms`, `us`/`µs`, `ns`.
    pub fn parse(s: &str) -> Option<TimeUnit> {
        match s {
            "s" => Some(TimeUnit::S),
            "ms" => Some(TimeUnit::Ms),
            "us" | "µs" => Some(TimeUnit::Us),
            "ns" => Some(TimeUnit::Ns),
            _ => None,
        }
    }
}

/// Which columns to take (0-based) from each data line.
#[derive(Debug, Clone)]
pub struct TableSpec {
    /// Timestamp column and its unit; None for files without one (rows then
    /// get `t_ns = 0` and the caller stamps them from a known rate).
    pub time: Option<(usize, TimeUnit)>,
    /// Value columns, in output order.
    pub values: Vec<usize>,
    /// What each value column is (for messages), same length as `values`.
    pub names: Vec<String>,
}

/// The parsed table: absolute times \[ns\], the chosen columns, and source lines.
#[derive(Debug, Clone, Default)]
pub struct Table {
    /// Timestamp of each row \[ns\].
    pub t_ns: Vec<i64>,
    /// One vector per requested value column.
    pub columns: Vec<Vec<f64>>,
    /// 1-based line number of each row.
    pub lines: Vec<u32>,
    /// The header line, if the file had one (first non-comment line that is not numeric).
    pub header: Option<String>,
}

const BLOCK: usize = 8 << 20;

/// Read a numeric table from `path` (a `.gz` suffix means gzip).
pub fn read_table(path: &Path, spec: &TableSpec) -> Result<Table, InputError> {
    let file = std::fs::File::open(path).map_err(|e| InputError::file(path, format!("cannot open: {e}")))?;
    let gz = path.extension().is_some_and(|e| e.eq_ignore_ascii_case("gz"));
    let reader: Box<dyn Read> = if gz { Box::new(flate2::read::MultiGzDecoder::new(file)) } else { Box::new(file) };
    parse_table_from(path, reader, spec)
}

/// Parse a numeric table from any reader; `path` names it in errors.
pub fn parse_table_from(path: &Path, mut reader: impl Read, spec: &TableSpec) -> Result<Table, InputError> {
    let mut out = Table { columns: vec![Vec::new(); spec.values.len()], ..Table::default() };
    let mut buf: Vec<u8> = Vec::with_capacity(BLOCK + 4096);
    let mut line_no: usize = 0; // lines consumed so far
    let mut layout: Option<Layout> = None;
    let mut eof = false;
    while !eof {
        let start = buf.len();
        buf.resize(start + BLOCK, 0);
        let mut filled = start;
        while filled < buf.len() {
            let n = reader.read(&mut buf[filled..]).map_err(|e| InputError::file(path, format!("read failed: {e}")))?;
            if n == 0 {
                eof = true;
                break;
            }
            filled += n;
        }
        buf.truncate(filled);
        // Parse up to the last complete line (everything at EOF).
        let cut = if eof { buf.len() } else { memchr::memrchr(b'\n', &buf).map(|p| p + 1).unwrap_or(0) };
        if cut == 0 && !eof {
            if buf.len() > 64 * BLOCK {
                return Err(InputError::at(path, line_no + 1, "line longer than 512 MiB: not a text table"));
            }
            continue;
        }
        let body = &buf[..cut];
        let body = if layout.is_none() {
            let (skip, lay, header, lines) = detect_layout(path, body, line_no)?;
            line_no += lines;
            if header.is_some() {
                out.header = header;
            }
            layout = lay;
            &body[skip..]
        } else {
            body
        };
        if let Some(lay) = layout {
            line_no = parse_block(path, body, line_no, lay, spec, &mut out)?;
        } else {
            line_no += memchr::memchr_iter(b'\n', body).count();
        }
        buf.drain(..cut);
    }
    if out.t_ns.is_empty() {
        return Err(InputError::file(path, "no data rows (the file is empty or holds only comments/header)")
            .with_hint("check the path and that the file is a numeric table"));
    }
    Ok(out)
}

#[derive(Clone, Copy)]
struct Layout {
    comma: bool,
}

fn is_comment(line: &[u8]) -> bool {
    let t = trim(line);
    t.is_empty() || t[0] == b'#' || t[0] == b'%'
}

fn trim(mut s: &[u8]) -> &[u8] {
    while let [first, rest @ ..] = s {
        if first.is_ascii_whitespace() {
            s = rest;
        } else {
            break;
        }
    }
    while let [rest @ .., last] = s {
        if last.is_ascii_whitespace() {
            s = rest;
        } else {
            break;
        }
    }
    s
}

/// Find the first data line: skip comments and one header line. Returns the
/// bytes consumed, the layout (None if no data line in this block), the header,
/// and the lines consumed.
fn detect_layout(
    path: &Path,
    body: &[u8],
    line0: usize,
) -> Result<(usize, Option<Layout>, Option<String>, usize), InputError> {
    let mut pos = 0;
    let mut lines = 0;
    let mut header = None;
    let mut text_header = false;
    while pos < body.len() {
        let end = memchr::memchr(b'\n', &body[pos..]).map(|p| pos + p + 1).unwrap_or(body.len());
        let line = &body[pos..end];
        if is_comment(line) {
            if header.is_none() {
                let t = trim(line);
                if t.first() == Some(&b'#') && t.len() > 1 {
                    // EuRoC puts its column names in a '#' comment line.
                    header = Some(String::from_utf8_lossy(&t[1..]).trim().to_string());
                }
            }
            pos = end;
            lines += 1;
            continue;
        }
        let t = trim(line);
        let comma = t.contains(&b',');
        let first = first_field(t, comma);
        if fast_float2::parse::<f64, _>(first).is_err() {
            if text_header {
                return Err(InputError::at(
                    path,
                    line0 + lines + 1,
                    format!("expected numbers after the header line, found '{}'", String::from_utf8_lossy(first)),
                ));
            }
            text_header = true;
            header = Some(String::from_utf8_lossy(t).to_string());
            pos = end;
            lines += 1;
            continue;
        }
        return Ok((pos, Some(Layout { comma }), header, lines));
    }
    Ok((pos, None, header, lines))
}

fn first_field(t: &[u8], comma: bool) -> &[u8] {
    let end = if comma {
        memchr::memchr(b',', t).unwrap_or(t.len())
    } else {
        t.iter().position(|c| c.is_ascii_whitespace()).unwrap_or(t.len())
    };
    trim(&t[..end])
}

/// Parse complete lines of `body` (line numbering continues from `line0`),
/// in parallel pieces, appending to `out`. Returns the new line count.
fn parse_block(
    path: &Path,
    body: &[u8],
    line0: usize,
    lay: Layout,
    spec: &TableSpec,
    out: &mut Table,
) -> Result<usize, InputError> {
    let threads = rayon::current_num_threads().max(1);
    let pieces = if body.len() < (1 << 20) { 1 } else { threads * 2 };
    let mut bounds = vec![0usize];
    for k in 1..pieces {
        let target = body.len() * k / pieces;
        let b = *bounds.last().expect("non-empty");
        if target <= b {
            continue;
        }
        match memchr::memchr(b'\n', &body[target..]) {
            Some(p) => bounds.push(target + p + 1),
            None => break,
        }
    }
    bounds.push(body.len());
    bounds.dedup();
    let parts: Vec<Result<(Table, usize), InputError>> = bounds
        .par_windows(2)
        .map(|w| {
            let piece = &body[w[0]..w[1]];
            let n_lines = memchr::memchr_iter(b'\n', piece).count() + usize::from(!piece.ends_with(b"\n"));
            Ok((parse_piece(path, piece, lay, spec)?, n_lines))
        })
        .collect();
    let mut line = line0;
    for part in parts {
        let (mut t, n_lines) = part.map_err(|mut e| {
            e.line = e.line.map(|l| l + line);
            e
        })?;
        // Piece-local errors are offset above; piece-local lines here.
        out.t_ns.append(&mut t.t_ns);
        for (dst, src) in out.columns.iter_mut().zip(t.columns.iter_mut()) {
            dst.append(src);
        }
        out.lines.extend(t.lines.iter().map(|&l| (l as usize + line) as u32));
        line += n_lines;
    }
    Ok(line)
}

/// Parse one piece; line numbers are piece-local (1-based).
fn parse_piece(path: &Path, piece: &[u8], lay: Layout, spec: &TableSpec) -> Result<Table, InputError> {
    let mut t = Table { columns: vec![Vec::new(); spec.values.len()], ..Table::default() };
    let want = spec.values.iter().copied().chain(spec.time.map(|t| t.0)).max().unwrap_or(0) + 1;
    let mut fields: Vec<&[u8]> = Vec::with_capacity(16);
    for (i, raw) in piece.split(|&c| c == b'\n').enumerate() {
        let line_no = i + 1;
        if raw.is_empty() || is_comment(raw) {
            continue;
        }
        let s = trim(raw);
        fields.clear();
        if lay.comma {
            fields.extend(s.split(|&c| c == b',').map(trim));
        } else {
            fields.extend(s.split(|c| c.is_ascii_whitespace()).filter(|f| !f.is_empty()));
        }
        if fields.len() < want {
            return Err(InputError::at(
                path,
                line_no,
                format!("line has {} fields, {} needed (column {} is used)", fields.len(), want, want),
            )
            .with_hint("a short last line usually means the file was truncated while being written"));
        }
        t.t_ns.push(match spec.time {
            Some((tc, unit)) => parse_time(path, line_no, fields[tc], unit)?,
            None => 0,
        });
        for (k, &c) in spec.values.iter().enumerate() {
            let f = fields[c];
            let v: f64 = fast_float2::parse(f).map_err(|_| {
                InputError::at(
                    path,
                    line_no,
                    format!("{} (column {}): '{}' is not a number", spec.names[k], c + 1, String::from_utf8_lossy(f)),
                )
            })?;
            if !v.is_finite() {
                return Err(InputError::at(
                    path,
                    line_no,
                    format!("{} (column {}) is not finite ({})", spec.names[k], c + 1, String::from_utf8_lossy(f)),
                ));
            }
            t.columns[k].push(v);
        }
        t.lines.push(line_no as u32);
    }
    Ok(t)
}

fn parse_time(path: &Path, line: usize, f: &[u8], unit: TimeUnit) -> Result<i64, InputError> {
    let bad = || InputError::at(path, line, format!("timestamp '{}' is not a number", String::from_utf8_lossy(f)));
    if unit == TimeUnit::Ns && !f.is_empty() && f.iter().all(|c| c.is_ascii_digit() || *c == b'-') {
        return std::str::from_utf8(f).ok().and_then(|s| s.parse::<i64>().ok()).ok_or_else(bad);
    }
    let v: f64 = fast_float2::parse(f).map_err(|_| bad())?;
    let ns = v * unit.ns_per_unit();
    if !ns.is_finite() || ns.abs() > 9.2e18 {
        return Err(InputError::at(
            path,
            line,
            format!("timestamp '{}' is not finite or out of range", String::from_utf8_lossy(f)),
        ));
    }
    Ok(ns.round() as i64)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn spec(n: usize) -> TableSpec {
        TableSpec {
            time: Some((0, TimeUnit::S)),
            values: (1..=n).collect(),
            names: (1..=n).map(|i| format!("v{i}")).collect(),
        }
    }

    #[test]
    fn parses_csv_whitespace_headers_and_comments() {
        let p = Path::new("x.csv");
        let t = parse_table_from(p, "#c\ntime,a,b\n0.0,1,2\n0.5, 3 ,4\n".as_bytes(), &spec(2)).unwrap();
        assert_eq!(t.t_ns, vec![0, 500_000_000]);
        assert_eq!(t.columns, vec![vec![1.0, 3.0], vec![2.0, 4.0]]);
        assert_eq!(t.lines, vec![3, 4]);
        assert_eq!(t.header.as_deref(), Some("time,a,b"));
        let t = parse_table_from(p, "  1 2 3\n\n2\t4 5\n".as_bytes(), &spec(2)).unwrap();
        assert_eq!(t.columns[1], vec![3.0, 5.0]);
        assert_eq!(t.lines, vec![1, 3]);
    }

    #[test]
    fn errors_name_line() {
        let p = Path::new("x.csv");
        let e = parse_table_from(p, "0,1,2\n1,nan,2\n".as_bytes(), &spec(2)).unwrap_err().to_string();
        assert!(e.contains("x.csv:2:") && e.contains("not finite"), "{e}");
        let e = parse_table_from(p, "0,1,2\n1,2\n".as_bytes(), &spec(2)).unwrap_err().to_string();
        assert!(e.contains("x.csv:2:") && e.contains("truncated"), "{e}");
        let e = parse_table_from(p, "".as_bytes(), &spec(2)).unwrap_err().to_string();
        assert!(e.contains("no data rows"), "{e}");
        let e = parse_table_from(p, "0,1,2\n1,x,2\n".as_bytes(), &spec(2)).unwrap_err().to_string();
        assert!(e.contains("'x' is not a number"), "{e}");
    }

    #[test]
    fn large_input_is_split_and_numbered_right() {
        let mut s = String::new();
        for i in 0..200_000 {
            s.push_str(&format!("{i},{}.5,{}\n", i, 2 * i));
        }
        s.push_str("200000,1,oops\n");
        let e = parse_table_from(Path::new("big.csv"), s.as_bytes(), &spec(2)).unwrap_err().to_string();
        assert!(e.contains("big.csv:200001:"), "{e}");
        s.truncate(s.len() - "200000,1,oops\n".len());
        let t = parse_table_from(Path::new("big.csv"), s.as_bytes(), &spec(2)).unwrap();
        assert_eq!(t.t_ns.len(), 200_000);
        assert_eq!(t.lines[199_999], 200_000);
        assert_eq!(t.columns[0][123_456], 123_456.5);
    }

    #[test]
    fn nanosecond_stamps_keep_all_digits() {
        let sp = TableSpec { time: Some((0, TimeUnit::Ns)), values: vec![1], names: vec!["a".into()] };
        let t = parse_table_from(Path::new("x"), "1403715273262142976,1\n".as_bytes(), &sp).unwrap();
        assert_eq!(t.t_ns[0], 1403715273262142976);
    }
}
