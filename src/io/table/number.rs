//! The fast path of the table reader: one pass over a line, numbers parsed
//! with SWAR digit runs and Clinger's exact fast path (`fast-float2`
//! otherwise); anything unusual returns `None` and the line goes through the
//! general path, which gives the exact error.

use super::{Field, Row, TimeUnit};

/// Exact powers of ten up to 10²² (the range where Clinger's fast path is exact).
const POW10: [f64; 23] = [
    1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9, 1e10, 1e11, 1e12, 1e13, 1e14, 1e15, 1e16, 1e17, 1e18, 1e19, 1e20,
    1e21, 1e22,
];

/// The eight bytes at `b[i..i + 8]` as a decimal number, if all are digits
/// (SWAR: one 64-bit load, a check and three multiplies).
#[inline(always)]
pub(super) fn eight_digits(b: &[u8], i: usize) -> Option<u64> {
    let bytes: [u8; 8] = b.get(i..i + 8)?.try_into().ok()?;
    let v = u64::from_le_bytes(bytes);
    let all_digits = ((v & 0xF0F0_F0F0_F0F0_F0F0)
        | ((v.wrapping_add(0x0606_0606_0606_0606) & 0xF0F0_F0F0_F0F0_F0F0) >> 4))
        == 0x3333_3333_3333_3333;
    if !all_digits {
        return None;
    }
    let mut v = v.wrapping_sub(0x3030_3030_3030_3030);
    v = v.wrapping_mul(10).wrapping_add(v >> 8);
    let lo = (v & 0x0000_00FF_0000_00FF).wrapping_mul(100 + (1_000_000 << 32));
    let hi = ((v >> 16) & 0x0000_00FF_0000_00FF).wrapping_mul(1 + (10_000 << 32));
    Some(lo.wrapping_add(hi) >> 32)
}

/// Append the decimal digits at `b[*i..]` to `mant` while it has room (else
/// clear `exact`); returns (digits read, digits kept in the mantissa).
#[inline(always)]
pub(super) fn accumulate_digits(b: &[u8], i: &mut usize, mant: &mut u64, exact: &mut bool) -> (u32, i32) {
    let (mut read, mut kept) = (0, 0);
    while let Some(&c) = b.get(*i) {
        let d = c.wrapping_sub(b'0');
        if d > 9 {
            break;
        }
        if *mant < 100_000_000_000_000_000 {
            *mant = *mant * 10 + u64::from(d);
            kept += 1;
        } else {
            *exact = false;
        }
        read += 1;
        *i += 1;
    }
    (read, kept)
}

/// Skip an optional sign at `b[*i]`; true when it was '-'.
#[inline(always)]
pub(super) fn take_sign(b: &[u8], i: &mut usize) -> bool {
    match b.get(*i) {
        Some(b'-') => {
            *i += 1;
            true
        }
        Some(b'+') => {
            *i += 1;
            false
        }
        _ => false,
    }
}

/// Parse a plain decimal (`-12.5`, `3e-4`) starting at `b[i]`; returns the
/// value and the index after it. Correctly rounded: the mantissa ≤ 2⁵³ and
/// |exponent| ≤ 22 case is exact (Clinger), anything else goes to fast-float2.
/// None when no number starts here.
#[inline(always)]
pub(super) fn parse_number(b: &[u8], mut i: usize) -> Option<(f64, usize)> {
    let start = i;
    let neg = take_sign(b, &mut i);
    let mut mant: u64 = 0;
    let mut exp: i32 = 0;
    let mut digits = 0;
    let mut exact = true;
    digits += accumulate_digits(b, &mut i, &mut mant, &mut exact).0;
    if b.get(i) == Some(&b'.') {
        i += 1;
        // Eight digits at a time while the mantissa has room for them.
        while mant < 10_000_000_000 {
            match eight_digits(b, i) {
                Some(v) => {
                    mant = mant * 100_000_000 + v;
                    exp -= 8;
                    digits += 8;
                    i += 8;
                }
                None => break,
            }
        }
        let (read, kept) = accumulate_digits(b, &mut i, &mut mant, &mut exact);
        digits += read;
        exp -= kept;
    }
    if digits == 0 {
        return None;
    }
    if matches!(b.get(i), Some(b'e') | Some(b'E')) {
        let mut j = i + 1;
        let eneg = take_sign(b, &mut j);
        let mut e: i32 = 0;
        let mut ed = 0;
        while let Some(&c) = b.get(j) {
            let d = c.wrapping_sub(b'0');
            if d > 9 {
                break;
            }
            e = e.saturating_mul(10).saturating_add(i32::from(d));
            ed += 1;
            j += 1;
        }
        if ed == 0 {
            return None;
        }
        exp = exp.saturating_add(if eneg { -e } else { e });
        i = j;
    }
    if exact && mant <= (1u64 << 53) && (-22..=22).contains(&exp) {
        let m = mant as f64;
        let v = if exp < 0 { m / POW10[(-exp) as usize] } else { m * POW10[exp as usize] };
        return Some((if neg { -v } else { v }, i));
    }
    let v: f64 = fast_float2::parse(&b[start..i]).ok()?;
    // Overflow to infinity is left to the general path, which reports it.
    v.is_finite().then_some((v, i))
}

/// The common case of a data line, parsed in one pass without splitting:
/// every needed field a plain number, separated by one comma (optionally
/// padded with blanks) or by blanks. `s` starts at the line and may run past
/// its end. Returns where the last needed field ended, or None for anything
/// else (the general path then parses the line or reports the error).
#[inline]
pub(super) fn fast_row(s: &[u8], comma: bool, plan: &[Field], vals: &mut Row) -> Option<usize> {
    let mut i = 0;
    let n = s.len();
    let blank = |c: u8| c == b' ' || c == b'\t';
    while i < n && blank(s[i]) {
        i += 1;
    }
    vals.time = 0;
    for (k, f) in plan.iter().enumerate() {
        if k > 0 {
            while i < n && blank(s[i]) {
                i += 1;
            }
            if comma {
                if i >= n || s[i] != b',' {
                    return None;
                }
                i += 1;
                while i < n && blank(s[i]) {
                    i += 1;
                }
            } else if i >= n || s[i] == b'\n' || s[i] == b'\r' {
                return None;
            }
        }
        match *f {
            Field::Skip => {
                while i < n && !(if comma { s[i] == b',' } else { blank(s[i]) }) && s[i] != b'\n' && s[i] != b'\r' {
                    i += 1;
                }
            }
            Field::Time(TimeUnit::Ns) => {
                let st = i;
                let mut v: i64 = 0;
                while v < 10_000_000_000 {
                    match eight_digits(s, i) {
                        Some(e) => {
                            v = v * 100_000_000 + e as i64;
                            i += 8;
                        }
                        None => break,
                    }
                }
                while i < n {
                    let d = s[i].wrapping_sub(b'0');
                    if d > 9 {
                        break;
                    }
                    v = v.checked_mul(10).and_then(|x| x.checked_add(i64::from(d)))?;
                    i += 1;
                }
                if i == st {
                    return None;
                }
                vals.time = v;
            }
            Field::Time(u) => {
                let (v, j) = parse_number(s, i)?;
                let ns = v * u.ns_per_unit();
                if ns.is_nan() || ns.abs() > 9.2e18 {
                    return None;
                }
                vals.time = ns.round() as i64;
                i = j;
            }
            Field::Value(k) => {
                let (v, j) = parse_number(s, i)?;
                vals.values[k] = v;
                i = j;
            }
            Field::Triad(g, a) => {
                let (v, j) = parse_number(s, i)?;
                vals.triads[g][a] = v;
                i = j;
            }
        }
        // The field must end here.
        if i < n && !matches!(s[i], b',' | b' ' | b'\t' | b'\n' | b'\r') {
            return None;
        }
    }
    Some(i)
}
