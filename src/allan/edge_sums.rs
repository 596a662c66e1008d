//! The inner loop of the Allan variance's edge terms (a quarter of an Allan
//! sweep's time when done one cluster size at a time): the sums of
//! squares of two-point phase combinations where a second-difference kernel
//! hangs over an end of the record.
//!
//! For a cluster size m the left edge pairs x(p) with x(p + m), p = 1 … m−1,
//! and the right edge x(p) with x(p − m), p = N+1−m … N−1. Done one m at a
//! time, each pair streams two values, and for m beyond the second-level
//! cache (~10⁵) at the third-level cache's bandwidth. Done for a batch of
//! neighbouring m at once, in tiles of positions p, the shared x(p) are read
//! from the first-level cache by every m of the batch, and the partners
//! x(p ± mₖ) of neighbouring mₖ are the same values a few thousand positions
//! apart, which the cache may still hold. Measured on one core of the
//! development machine for m near 10⁶: 0.26 ns a pair against 0.58 one m at
//! a time.

/// Cluster sizes summed together (a batch's partner streams lie within
/// (m_last − m_first) values of each other, which must fit in the cache).
pub(crate) const BATCH: usize = 8;

/// Which end of the record the pairs lie at.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum End {
    /// p = 1 … m−1, partner x(p + m).
    Left,
    /// p = N+1−m … N−1, partner x(p − m).
    Right,
}

/// For each m of `ms` (ascending, at most [`BATCH`], each with 1 ≤ m and
/// 2m ≤ N = x.len() − 1): Σ_p (cs·x(p) + co·x(partner) + offset)² over the
/// pairs of the `end` (see [`End`]).
pub(crate) fn pair_sums(x: &[f64], ms: &[usize], end: End, cs: f64, co: f64, offset: f64) -> Vec<f64> {
    assert!(ms.len() <= BATCH && ms.windows(2).all(|w| w[0] < w[1]));
    assert!(ms.iter().all(|&m| m >= 1 && 2 * m < x.len()));
    let mut out = [0.0; BATCH];
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma") {
        // SAFETY: the CPU supports AVX2 and FMA, checked just above.
        unsafe { pair_sums_fma(x, ms, end, [cs, co, offset], &mut out) };
        return out[..ms.len()].to_vec();
    }
    batch::<false>(x, ms, end, [cs, co, offset], &mut out);
    out[..ms.len()].to_vec()
}

/// [`batch`] compiled for AVX2 with fused multiply-adds (checked at run
/// time: the binary stays portable).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn pair_sums_fma(x: &[f64], ms: &[usize], end: End, coefficients: [f64; 3], out: &mut [f64; BATCH]) {
    batch::<true>(x, ms, end, coefficients, out)
}

/// Lanes per step: one 256-bit vector twice.
const WIDTH: usize = 8;

/// Steps per tile: 2048 shared values, 16 KiB, well inside the first-level
/// cache next to the partner streams passing through it.
const TILE: usize = 256;

/// a·b + c, fused where `FMA`.
#[inline(always)]
fn mul_add<const FMA: bool>(a: f64, b: f64, c: f64) -> f64 {
    if FMA {
        a.mul_add(b, c)
    } else {
        a * b + c
    }
}

/// The sums of [`pair_sums`], in steps of [`WIDTH`] shared positions, the
/// steps in tiles of [`TILE`]: each m of the batch adds the steps of a tile
/// its pairs cover in whole; each m's last partial step is summed alone.
#[inline(always)]
fn batch<const FMA: bool>(x: &[f64], ms: &[usize], end: End, [cs, co, offset]: [f64; 3], out: &mut [f64; BATCH]) {
    let n = x.len() - 1;
    let mut acc = [[0.0f64; WIDTH]; BATCH];
    // Pairs of m: m − 1, in full steps (m − 1) / WIDTH.
    let full = |m: usize| (m - 1) / WIDTH;
    let steps = ms.last().map_or(0, |&m| full(m));
    // The first position of step c, and of m's partner.
    let start = |c: usize| match end {
        End::Left => 1 + WIDTH * c,
        End::Right => n - WIDTH * (c + 1),
    };
    let partner = |p: usize, m: usize| match end {
        End::Left => p + m,
        End::Right => p - m,
    };
    // Steps in tiles whose shared values stay in the first-level cache
    // while each m of the batch streams its partners past them.
    for tile in (0..steps).step_by(TILE) {
        for (k, &m) in ms.iter().enumerate() {
            let mut lanes = acc[k];
            for c in tile..(tile + TILE).min(full(m)) {
                let p = start(c);
                let q = partner(p, m);
                let shared: &[f64; WIDTH] = x[p..p + WIDTH].try_into().expect("WIDTH values");
                let other: &[f64; WIDTH] = x[q..q + WIDTH].try_into().expect("WIDTH values");
                for l in 0..WIDTH {
                    let w = mul_add::<FMA>(co, other[l], mul_add::<FMA>(cs, shared[l], offset));
                    lanes[l] = mul_add::<FMA>(w, w, lanes[l]);
                }
            }
            acc[k] = lanes;
        }
    }
    for (k, &m) in ms.iter().enumerate() {
        // The positions left after m's full steps.
        let rest = match end {
            End::Left => 1 + WIDTH * full(m)..m,
            End::Right => n + 1 - m..n - WIDTH * full(m),
        };
        let tail: f64 = rest
            .map(|p| {
                let w = cs * x[p] + co * x[partner(p, m)] + offset;
                w * w
            })
            .sum();
        out[k] = acc[k].iter().sum::<f64>() + tail;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Σ over the pairs one at a time, as the definition reads.
    fn direct(x: &[f64], m: usize, end: End, cs: f64, co: f64, offset: f64) -> f64 {
        let n = x.len() - 1;
        let positions = match end {
            End::Left => 1..m,
            End::Right => n + 1 - m..n,
        };
        positions
            .map(|p| {
                let q = if end == End::Left { p + m } else { p - m };
                (cs * x[p] + co * x[q] + offset).powi(2)
            })
            .sum()
    }

    #[test]
    fn batched_sums_equal_the_pairs_one_by_one() {
        let x: Vec<f64> = (0..1001).map(|i| ((i * 7919) % 113) as f64 * 0.01 - 0.3 + (i as f64).sqrt()).collect();
        // Batches with m below one step, at a step's edge, and apart.
        for ms in [&[1usize, 2, 3][..], &[7, 8, 9, 16, 17], &[1, 40, 41, 42, 100, 250, 499, 500], &[333]] {
            for end in [End::Left, End::Right] {
                let got = pair_sums(&x, ms, end, -2.0, 1.0, 0.25);
                let mut portable = [0.0; BATCH];
                batch::<false>(&x, ms, end, [-2.0, 1.0, 0.25], &mut portable);
                for (k, &m) in ms.iter().enumerate() {
                    let want = direct(&x, m, end, -2.0, 1.0, 0.25);
                    assert!((got[k] - want).abs() <= 1e-12 * want, "{end:?} m={m}: {} vs {want}", got[k]);
                    assert!((portable[k] - want).abs() <= 1e-12 * want, "{end:?} m={m} portable");
                }
            }
        }
    }
}
