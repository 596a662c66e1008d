//! Streaming reader of numeric text tables (CSV or whitespace separated), the
//! engine under every IMU and trajectory text format.
//!
//! Regular files are memory-mapped; `.gz` files and other readers are
//! streamed in 8 MiB blocks. Each block is cut at line ends into pieces parsed
//! on all cores straight into the output. Lines go through a one-pass parser
//! (plain decimals, SWAR digit runs, Clinger's exact fast path, `fast-float2`
//! otherwise); anything else falls back to a general path that gives the
//! exact error. Nanosecond timestamps are parsed as integers so 19-digit EuRoC
//! stamps keep every digit. Memory is the output plus the block (or the
//! mapping's page cache).

use crate::error::InputError;
use rayon::prelude::*;
use std::io::Read;
use std::mem::MaybeUninit;
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
#[derive(Debug, Clone, Default)]
pub struct TableSpec {
    /// Timestamp column and its unit; None for files without one (rows then
    /// get `t_ns = 0` and the caller stamps them from a known rate).
    pub time: Option<(usize, TimeUnit)>,
    /// Value columns, in output order.
    pub values: Vec<usize>,
    /// What each value column is (for messages), same length as `values`.
    pub names: Vec<String>,
    /// Column triples read as `[x, y, z]` rows (an IMU's gyro and accelerometer).
    pub triads: Vec<[usize; 3]>,
    /// What each triad is (for messages), same length as `triads`.
    pub triad_names: Vec<String>,
    /// Accept `NaN` values (meaning "unknown", e.g. an uncomputed standard
    /// deviation); infinities are refused all the same.
    pub allow_nan: bool,
}

/// Source line of each row, stored as anchors: from row `r` on, rows sit on
/// consecutive lines starting at `line`, until the next anchor (a blank or
/// comment line, or a new parse piece). A few entries instead of one per row.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct LineMap {
    anchors: Vec<(usize, usize)>,
}

impl LineMap {
    /// 1-based line number of row `i`.
    pub fn line(&self, i: usize) -> usize {
        let k = self.anchors.partition_point(|a| a.0 <= i);
        match k {
            0 => i + 1,
            _ => {
                let (r, l) = self.anchors[k - 1];
                l + (i - r)
            }
        }
    }
    /// The map of the rows from `a` on, renumbered to start at row 0.
    pub fn slice(&self, a: usize) -> LineMap {
        let first = (0, self.line(a));
        let rest = self.anchors.iter().filter(|x| x.0 > a).map(|&(r, l)| (r - a, l));
        LineMap { anchors: std::iter::once(first).chain(rest).collect() }
    }
    fn push(&mut self, row: usize, line: usize) {
        if self.anchors.last().is_some_and(|&(r, l)| line == l + (row - r)) {
            return;
        }
        self.anchors.push((row, line));
    }
}

/// The parsed table: absolute times \[ns\], the chosen columns, and source lines.
#[derive(Debug, Clone, Default)]
pub struct Table {
    /// Timestamp of each row \[ns\].
    pub t_ns: Vec<i64>,
    /// One vector per requested value column.
    pub columns: Vec<Vec<f64>>,
    /// One vector per requested triad.
    pub triads: Vec<Vec<[f64; 3]>>,
    /// Source line of each row.
    pub lines: LineMap,
    /// The header line, if the file had one (first non-comment line that is not numeric).
    pub header: Option<String>,
}

/// Streamed block size.
mod number;
use number::fast_row;
#[cfg(test)]
use number::{eight_digits, parse_number};

const BLOCK: usize = 8 << 20;
/// Slice of a memory-mapped file parsed at once.
const MAPPED_BLOCK: usize = 64 << 20;

/// Read a numeric table from `path`: memory-mapped and parsed in parallel
/// blocks, or streamed through gzip when the name ends in `.gz`.
pub fn read_table(path: &Path, spec: &TableSpec) -> Result<Table, InputError> {
    let file = open_file(path)?;
    let gz = path.extension().is_some_and(|e| e.eq_ignore_ascii_case("gz"));
    let size = file.metadata().map(|m| m.len() as usize).unwrap_or(0);
    if gz || size == 0 {
        return parse_table_from(path, flate2_or_plain(file, gz), spec);
    }
    // SAFETY: the map is read-only and dropped before returning; a file changed
    // by another process while it is read gives garbage numbers or a parse
    // error, never unsoundness visible to safe code here (we only read bytes).
    let map = unsafe { memmap2::MmapOptions::new().populate().map(&file) }
        .map_err(|e| InputError::file(path, format!("cannot map: {e}")))?;
    #[cfg(unix)]
    let _ = map.advise(memmap2::Advice::Sequential);
    let mut p = Parser::new(path, spec);
    let mut start = 0;
    while start < map.len() {
        let end = if map.len() - start <= MAPPED_BLOCK {
            map.len()
        } else {
            memchr::memchr(b'\n', &map[start + MAPPED_BLOCK..])
                .map(|q| start + MAPPED_BLOCK + q + 1)
                .unwrap_or(map.len())
        };
        if start == 0 {
            p.reserve_for(size, &map[..end]);
        }
        p.feed(&map[start..end])?;
        start = end;
    }
    p.finish()
}

/// Open a file to read, refusing a directory by name (mapping one fails with
/// "No such device").
pub fn open_file(path: &Path) -> Result<std::fs::File, InputError> {
    if path.is_dir() {
        return Err(InputError::file(path, "is a folder, not a file")
            .with_hint("give the file inside it (or pass the folder where a command takes an ASL dataset)"));
    }
    std::fs::File::open(path).map_err(|e| InputError::file(path, format!("cannot open: {e}")))
}

/// Text the table readers cannot read: UTF-16 (a byte-order mark, or NUL
/// bytes between ASCII characters) or binary data.
fn check_text(path: &Path, head: &[u8]) -> Result<(), InputError> {
    let head = &head[..head.len().min(4096)];
    let utf16 = head.starts_with(&[0xFF, 0xFE]) || head.starts_with(&[0xFE, 0xFF]);
    if utf16 || head.contains(&0) {
        let what = if utf16 || head.iter().skip(1).step_by(2).take(64).all(|&b| b == 0) {
            "is UTF-16 text"
        } else {
            "holds binary data (NUL bytes), not text"
        };
        return Err(InputError::file(path, what.to_string())
            .with_hint("save it as UTF-8 (or ASCII) text, e.g. `iconv -f UTF-16 -t UTF-8 IN > OUT`"));
    }
    Ok(())
}

fn flate2_or_plain(file: std::fs::File, gz: bool) -> Box<dyn Read> {
    if gz {
        Box::new(flate2::read::MultiGzDecoder::new(file))
    } else {
        Box::new(file)
    }
}

/// The header line of a table file (looking at its first 64 KiB only).
pub fn peek_header(path: &Path) -> Result<Option<String>, InputError> {
    let file = open_file(path)?;
    let gz = path.extension().is_some_and(|e| e.eq_ignore_ascii_case("gz"));
    let mut head = Vec::with_capacity(1 << 16);
    flate2_or_plain(file, gz)
        .take(1 << 16)
        .read_to_end(&mut head)
        .map_err(|e| InputError::file(path, format!("read failed: {e}")))?;
    check_text(path, &head)?;
    let cut = memchr::memrchr(b'\n', &head).map(|q| q + 1).unwrap_or(head.len());
    Ok(detect_layout(path, &head[..cut], 0)?.2)
}

/// Parse a numeric table from any reader, streamed in blocks; `path` names it in errors.
pub fn parse_table_from(path: &Path, mut reader: impl Read, spec: &TableSpec) -> Result<Table, InputError> {
    let mut p = Parser::new(path, spec);
    let mut buf: Vec<u8> = Vec::new();
    let mut eof = false;
    while !eof {
        // Append up to one block; fewer bytes than asked means end of input.
        let n = (&mut reader)
            .take(BLOCK as u64)
            .read_to_end(&mut buf)
            .map_err(|e| InputError::file(path, format!("read failed: {e}")))?;
        eof = n < BLOCK;
        // Parse up to the last complete line (everything at EOF).
        let cut = if eof { buf.len() } else { memchr::memrchr(b'\n', &buf).map(|q| q + 1).unwrap_or(0) };
        if cut == 0 && !eof {
            if buf.len() > 64 * BLOCK {
                return Err(InputError::at(path, p.line_no + 1, "line longer than 512 MiB: not a text table"));
            }
            continue;
        }
        p.feed(&buf[..cut])?;
        buf.drain(..cut);
    }
    p.finish()
}

/// Parsing state across blocks of complete lines.
struct Parser<'a> {
    path: &'a Path,
    spec: &'a TableSpec,
    plan: Vec<Field>,
    out: Table,
    line_no: usize,
    layout: Option<Layout>,
}

impl<'a> Parser<'a> {
    fn new(path: &'a Path, spec: &'a TableSpec) -> Self {
        let out = Table {
            columns: vec![Vec::new(); spec.values.len()],
            triads: vec![Vec::new(); spec.triads.len()],
            ..Table::default()
        };
        Parser { path, spec, plan: plan(spec), out, line_no: 0, layout: None }
    }

    /// Reserve the output for a `size`-byte input whose first bytes are `head`.
    fn reserve_for(&mut self, size: usize, head: &[u8]) {
        let lines = memchr::memchr_iter(b'\n', head).count().max(1);
        let est = (size as f64 / (head.len() as f64 / lines as f64) * 1.01) as usize + 1024;
        super::mem::reserve_huge(&mut self.out.t_ns, est);
        self.out.columns.iter_mut().for_each(|c| super::mem::reserve_huge(c, est));
        self.out.triads.iter_mut().for_each(|c| super::mem::reserve_huge(c, est));
    }

    /// Parse a block of complete lines.
    fn feed(&mut self, body: &[u8]) -> Result<(), InputError> {
        let body = if self.layout.is_none() {
            if self.line_no == 0 {
                check_text(self.path, body)?;
            }
            let (skip, lay, header, lines) = detect_layout(self.path, body, self.line_no)?;
            self.line_no += lines;
            if header.is_some() {
                self.out.header = header;
            }
            self.layout = lay;
            &body[skip..]
        } else {
            body
        };
        match self.layout {
            Some(lay) => {
                self.line_no = parse_block(self.path, body, self.line_no, lay, self.spec, &self.plan, &mut self.out)?
            }
            None => self.line_no += memchr::memchr_iter(b'\n', body).count(),
        }
        Ok(())
    }

    fn finish(self) -> Result<Table, InputError> {
        if self.out.t_ns.is_empty() {
            return Err(InputError::file(self.path, "no data rows (the file is empty or holds only comments/header)")
                .with_hint("check the path and that the file is a numeric table"));
        }
        Ok(self.out)
    }
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

/// Rows a piece wrote and its line anchors `(row, line)`.
type PieceResult = (usize, Vec<(usize, usize)>);

/// One piece's share of the output rows (not yet initialized).
struct PieceOut<'a> {
    t_ns: &'a mut [MaybeUninit<i64>],
    columns: Vec<&'a mut [MaybeUninit<f64>]>,
    triads: Vec<&'a mut [MaybeUninit<[f64; 3]>]>,
}

/// Split the spare capacity of `v` (at least `counts.iter().sum()`) into one slice per count.
fn split_spare<'a, T>(v: &'a mut Vec<T>, counts: &[usize]) -> Vec<&'a mut [MaybeUninit<T>]> {
    let mut rest = v.spare_capacity_mut();
    counts
        .iter()
        .map(|&n| {
            let (h, r) = std::mem::take(&mut rest).split_at_mut(n);
            rest = r;
            h
        })
        .collect()
}

/// Parse complete lines of `body` (line numbering continues from `line0`),
/// in parallel pieces writing straight into `out`'s spare capacity, so page
/// faults and parsing are shared by all threads. Returns the new line count.
fn parse_block(
    path: &Path,
    body: &[u8],
    line0: usize,
    lay: Layout,
    spec: &TableSpec,
    plan: &[Field],
    out: &mut Table,
) -> Result<usize, InputError> {
    let threads = rayon::current_num_threads().max(1);
    let pieces = if body.len() < (1 << 20) { 1 } else { threads * 4 };
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
    // Lines per piece (a last line without '\n' counts too): the most rows it can give.
    let counts: Vec<usize> = bounds
        .par_windows(2)
        .map(|w| {
            let piece = &body[w[0]..w[1]];
            memchr::memchr_iter(b'\n', piece).count() + usize::from(!piece.is_empty() && !piece.ends_with(b"\n"))
        })
        .collect();
    let total: usize = counts.iter().sum();
    let base = out.t_ns.len();
    super::mem::reserve_huge(&mut out.t_ns, total);
    out.columns.iter_mut().for_each(|c| super::mem::reserve_huge(c, total));
    out.triads.iter_mut().for_each(|c| super::mem::reserve_huge(c, total));
    let mut t_parts = split_spare(&mut out.t_ns, &counts).into_iter();
    let mut c_parts: Vec<_> = out.columns.iter_mut().map(|c| split_spare(c, &counts).into_iter()).collect();
    let mut g_parts: Vec<_> = out.triads.iter_mut().map(|c| split_spare(c, &counts).into_iter()).collect();
    let outs: Vec<PieceOut<'_>> = counts
        .iter()
        .map(|_| PieceOut {
            t_ns: t_parts.next().expect("one part per piece"),
            columns: c_parts.iter_mut().map(|p| p.next().expect("one part per piece")).collect(),
            triads: g_parts.iter_mut().map(|p| p.next().expect("one part per piece")).collect(),
        })
        .collect();
    let results: Vec<Result<PieceResult, InputError>> = outs
        .into_par_iter()
        .zip(bounds.par_windows(2))
        .map(|(o, w)| parse_piece(path, &body[w[0]..w[1]], lay, spec, plan, o))
        .collect();
    // Offset piece-local line numbers; close the holes left by blank/comment lines.
    let mut line = line0;
    let mut write = 0;
    let mut read = 0;
    for (r, &n) in results.into_iter().zip(&counts) {
        let (rows, anchors) = r.map_err(|mut e| {
            e.line = e.line.map(|l| l + line);
            e
        })?;
        if write != read {
            out.t_ns.spare_capacity_mut().copy_within(read..read + rows, write);
            for c in out.columns.iter_mut() {
                c.spare_capacity_mut().copy_within(read..read + rows, write);
            }
            for c in out.triads.iter_mut() {
                c.spare_capacity_mut().copy_within(read..read + rows, write);
            }
        }
        for (r, l) in anchors {
            out.lines.push(base + write + r, line + l);
        }
        write += rows;
        read += n;
        line += n;
    }
    // SAFETY: each piece initialized the first `rows` slots of its part (it
    // writes row by row and reports how many), and the loop above moved them
    // to be contiguous, so the first `write` spare slots of every vector are
    // initialized.
    unsafe {
        out.t_ns.set_len(base + write);
        for c in out.columns.iter_mut() {
            c.set_len(base + write);
        }
        for c in out.triads.iter_mut() {
            c.set_len(base + write);
        }
    }
    Ok(line)
}

/// Split a trimmed data line into fields.
fn split_fields<'a>(s: &'a [u8], comma: bool, fields: &mut Vec<&'a [u8]>) {
    fields.clear();
    if comma {
        let mut start = 0;
        for p in memchr::memchr_iter(b',', s) {
            fields.push(trim(&s[start..p]));
            start = p + 1;
        }
        fields.push(trim(&s[start..]));
    } else {
        fields.extend(s.split(|c| c.is_ascii_whitespace()).filter(|f| !f.is_empty()));
    }
}

/// Parse one piece into its output slices; line numbers are piece-local
/// (1-based). Returns the rows written (slots `0..rows` of every part are
/// initialized) and the line anchors (row, line).
fn parse_piece(
    path: &Path,
    piece: &[u8],
    lay: Layout,
    spec: &TableSpec,
    plan: &[Field],
    o: PieceOut<'_>,
) -> Result<PieceResult, InputError> {
    let PieceOut { t_ns, mut columns, mut triads } = o;
    let mut anchors = Vec::new();
    let mut skipped = true;
    let mut fields: Vec<&[u8]> = Vec::with_capacity(16);
    let mut row = 0;
    let mut start = 0;
    let mut line_no = 0;
    let mut vals = Row::default();
    while start < piece.len() {
        let rest = &piece[start..];
        let end = match fast_row(rest, lay.comma, plan, &mut vals) {
            Some(i) => {
                // Usually the line ends right after the last needed field.
                let mut j = i;
                while j < rest.len() && matches!(rest[j], b' ' | b'\t' | b'\r') {
                    j += 1;
                }
                if j >= rest.len() || rest[j] == b'\n' {
                    start + j
                } else {
                    memchr::memchr(b'\n', &rest[j..]).map(|p| start + j + p).unwrap_or(piece.len())
                }
            }
            None => {
                let end = memchr::memchr(b'\n', rest).map(|p| start + p).unwrap_or(piece.len());
                let line = &piece[start..end];
                if is_comment(line) {
                    skipped = true;
                    line_no += 1;
                    start = end + 1;
                    continue;
                }
                split_fields(trim(line), lay.comma, &mut fields);
                slow_row(path, line_no + 1, &fields, plan, spec, &mut vals)?;
                end
            }
        };
        start = end + 1;
        line_no += 1;
        if skipped {
            anchors.push((row, line_no));
            skipped = false;
        }
        t_ns[row].write(vals.time);
        for (c, v) in columns.iter_mut().zip(&vals.values) {
            c[row].write(*v);
        }
        for (c, v) in triads.iter_mut().zip(&vals.triads) {
            c[row].write(*v);
        }
        row += 1;
    }
    Ok((row, anchors))
}

/// One parsed row.
struct Row {
    time: i64,
    values: [f64; MAX_FIELDS],
    triads: [[f64; 3]; MAX_FIELDS / 3],
}

impl Default for Row {
    fn default() -> Self {
        Row { time: 0, values: [0.0; MAX_FIELDS], triads: [[0.0; 3]; MAX_FIELDS / 3] }
    }
}

/// Most value columns (and triads × 3) a table may ask for.
pub const MAX_FIELDS: usize = 48;

/// The general path: fields already split; exact error messages.
fn slow_row(
    path: &Path,
    line_no: usize,
    fields: &[&[u8]],
    plan: &[Field],
    spec: &TableSpec,
    vals: &mut Row,
) -> Result<(), InputError> {
    let want = plan.len();
    if fields.len() < want {
        return Err(InputError::at(
            path,
            line_no,
            format!("line has {} fields, {} needed (column {} is used)", fields.len(), want, want),
        )
        .with_hint("a short last line usually means the file was truncated while being written"));
    }
    for (c, f) in plan.iter().enumerate() {
        let text = fields[c];
        let name = match *f {
            Field::Skip => continue,
            Field::Time(unit) => {
                vals.time = parse_time(path, line_no, text, unit)?;
                continue;
            }
            Field::Value(k) => spec.names[k].clone(),
            Field::Triad(g, a) => format!("{} {}", spec.triad_names[g], ["x", "y", "z"][a]),
        };
        let v: f64 = fast_float2::parse(text).map_err(|_| {
            InputError::at(
                path,
                line_no,
                format!("{name} (column {}): '{}' is not a number", c + 1, String::from_utf8_lossy(text)),
            )
        })?;
        if !(v.is_finite() || spec.allow_nan && v.is_nan()) {
            return Err(InputError::at(
                path,
                line_no,
                format!("{name} (column {}) is not finite ({})", c + 1, String::from_utf8_lossy(text)),
            ));
        }
        match *f {
            Field::Value(k) => vals.values[k] = v,
            Field::Triad(g, a) => vals.triads[g][a] = v,
            _ => {}
        }
    }
    if spec.time.is_none() {
        vals.time = 0;
    }
    Ok(())
}

/// What to do with each field of a line, up to the last one needed.
#[derive(Clone, Copy)]
enum Field {
    Skip,
    Time(TimeUnit),
    Value(usize),
    Triad(usize, usize),
}

fn plan(spec: &TableSpec) -> Vec<Field> {
    let all = spec.values.iter().copied().chain(spec.triads.iter().flatten().copied()).chain(spec.time.map(|t| t.0));
    let want = all.max().unwrap_or(0) + 1;
    let mut p = vec![Field::Skip; want];
    if let Some((c, u)) = spec.time {
        p[c] = Field::Time(u);
    }
    for (k, &c) in spec.values.iter().enumerate().take(MAX_FIELDS) {
        p[c] = Field::Value(k);
    }
    for (g, t) in spec.triads.iter().enumerate().take(MAX_FIELDS / 3) {
        for (a, &c) in t.iter().enumerate() {
            p[c] = Field::Triad(g, a);
        }
    }
    p
}

fn parse_time(path: &Path, line: usize, f: &[u8], unit: TimeUnit) -> Result<i64, InputError> {
    let bad = || InputError::at(path, line, format!("timestamp '{}' is not a number", String::from_utf8_lossy(f)));
    if unit == TimeUnit::Ns && !f.is_empty() && f.iter().all(u8::is_ascii_digit) {
        return f.iter().try_fold(0i64, |acc, &c| acc.checked_mul(10)?.checked_add(i64::from(c - b'0'))).ok_or_else(
            || InputError::at(path, line, format!("timestamp '{}' overflows", String::from_utf8_lossy(f))),
        );
    }
    if unit == TimeUnit::Ns && f.iter().all(|c| c.is_ascii_digit() || *c == b'-') {
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
mod tests;
