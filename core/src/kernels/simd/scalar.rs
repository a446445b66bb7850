//! Scalar reference twins of every SIMD kernel (ggml's `_ref`): the
//! definition each SIMD variant is tested against, and the path taken on
//! targets without a SIMD variant.

use super::{
    distinct_rows, f16_to_f32, pairwise, pairwise_rows, Tile, Q8_BLOCK, Q8_BLOCK_BYTES, TM, TN,
};

/// `a . b` over `min(len)` with 8 independent accumulators (the summation
/// order SIMD variants approximate; they differ by rounding only).
#[inline]
pub fn dot_f32(a: &[f32], b: &[f32]) -> f32 {
    let n = a.len().min(b.len());
    let (a, b) = (&a[..n], &b[..n]);
    let mut acc = [0.0f32; 8];
    let (ac, ar) = a.split_at(n - n % 8);
    let (bc, br) = b.split_at(n - n % 8);
    for (x, y) in ac.chunks_exact(8).zip(bc.chunks_exact(8)) {
        for l in 0..8 {
            acc[l] += x[l] * y[l];
        }
    }
    let mut tail = 0.0f32;
    for (x, y) in ar.iter().zip(br) {
        tail += x * y;
    }
    ((acc[0] + acc[4]) + (acc[1] + acc[5])) + ((acc[2] + acc[6]) + (acc[3] + acc[7])) + tail
}

/// `w . x` with `w` IEEE binary16 bit patterns, converted exactly to f32.
#[inline]
pub fn dot_f16(w: &[u16], x: &[f32]) -> f32 {
    let n = w.len().min(x.len());
    let mut acc = [0.0f32; 8];
    let (wc, wr) = w[..n].split_at(n - n % 8);
    let (xc, xr) = x[..n].split_at(n - n % 8);
    for (a, b) in wc.chunks_exact(8).zip(xc.chunks_exact(8)) {
        for l in 0..8 {
            acc[l] += f16_to_f32(a[l]) * b[l];
        }
    }
    let mut tail = 0.0f32;
    for (a, b) in wr.iter().zip(xr) {
        tail += f16_to_f32(*a) * b;
    }
    ((acc[0] + acc[4]) + (acc[1] + acc[5])) + ((acc[2] + acc[6]) + (acc[3] + acc[7])) + tail
}

/// Blocked int8 dot: `w` holds `nb` blocks of [f16 scale, 32 x i8], `xq`
/// `32 nb` quantised activations with per-block f32 scales `xd` (nb).
/// Per block the integer dot is exact in i32; the block results are
/// scaled and summed in f32, block by block.
#[inline]
pub fn dot_q8(w: &[u8], xq: &[i8], xd: &[f32]) -> f32 {
    let nb = (w.len() / Q8_BLOCK_BYTES)
        .min(xq.len() / Q8_BLOCK)
        .min(xd.len());
    let mut sum = 0.0f32;
    for b in 0..nb {
        let blk = &w[b * Q8_BLOCK_BYTES..(b + 1) * Q8_BLOCK_BYTES];
        let d = f16_to_f32(u16::from_le_bytes([blk[0], blk[1]]));
        let xs = &xq[b * Q8_BLOCK..(b + 1) * Q8_BLOCK];
        let mut isum = 0i32;
        for (&wq, &xv) in blk[2..].iter().zip(xs) {
            isum += (wq as i8 as i32) * (xv as i32);
        }
        sum += (d * xd[b]) * isum as f32;
    }
    sum
}

/// The shortest row length of a tile (every pair is dotted over it).
#[inline]
pub(crate) fn common<A, B>(w: &[&[A]; TN], x: &[&[B]; TM]) -> usize {
    let kw = w.iter().map(|r| r.len()).min().unwrap_or(0);
    x.iter().map(|r| r.len()).min().unwrap_or(0).min(kw)
}

/// Tile twin of [`dot_f32`]: `out[m][n] = dot_f32(w[n][..k], x[m][..k])`
/// with `k` the shortest row of the tile (the reference every tiled SIMD
/// kernel is tested against). Activation rows repeated at the end of `x`
/// are computed once ([`distinct_rows`]: the same numbers).
#[inline]
pub fn tile_f32(w: [&[f32]; TN], x: [&[f32]; TM]) -> Tile {
    let k = common(&w, &x);
    pairwise_rows(distinct_rows(&x), |m, n| dot_f32(&w[n][..k], &x[m][..k]))
}

/// Tile twin of [`dot_f16`] (over the shortest row, as [`tile_f32`]).
#[inline]
pub fn tile_f16(w: [&[u16]; TN], x: [&[f32]; TM]) -> Tile {
    let k = common(&w, &x);
    pairwise_rows(distinct_rows(&x), |m, n| dot_f16(&w[n][..k], &x[m][..k]))
}

/// The fewest int8 blocks of any row of a tile.
#[inline]
pub(crate) fn common_blocks(w: &[&[u8]; TN], xq: &[&[i8]; TM], xd: &[&[f32]; TM]) -> usize {
    let nbw = w
        .iter()
        .map(|r| r.len() / Q8_BLOCK_BYTES)
        .min()
        .unwrap_or(0);
    xq.iter()
        .map(|r| r.len() / Q8_BLOCK)
        .chain(xd.iter().map(|r| r.len()))
        .min()
        .unwrap_or(0)
        .min(nbw)
}

/// Tile twin of [`dot_q8`] (over the fewest blocks of any row).
#[inline]
pub fn tile_q8(w: [&[u8]; TN], xq: [&[i8]; TM], xd: [&[f32]; TM]) -> Tile {
    let nb = common_blocks(&w, &xq, &xd);
    pairwise(|m, n| {
        dot_q8(
            &w[n][..nb * Q8_BLOCK_BYTES],
            &xq[m][..nb * Q8_BLOCK],
            &xd[m][..nb],
        )
    })
}

/// Twin of [`super::quantise_q8_corr`]: [`super::quantise_q8`] plus the
/// VNNI offset corrections per block and lane parity: `c[2b + j] = -128 *
/// sum(q[32b + i])` over the `i` with `(i % 8) / 4 == j`.
pub fn quantise_q8_corr(x: &[f32], q: &mut [i8], d: &mut [f32], c: &mut [i32]) {
    super::quantise_q8(x, q, d);
    for (cb, qb) in c
        .chunks_exact_mut(2)
        .zip(q.chunks_exact(Q8_BLOCK))
        .take(x.len() / Q8_BLOCK)
    {
        for (j, cj) in cb.iter_mut().enumerate() {
            *cj = -128
                * qb.iter()
                    .enumerate()
                    .filter(|(i, _)| (i % 8) / 4 == j)
                    .map(|(_, &v)| v as i32)
                    .sum::<i32>();
        }
    }
}

/// Twin of [`super::q8_scales`].
pub fn q8_scales(row: &[u8], out: &mut [f32]) {
    for (o, blk) in out.iter_mut().zip(row.chunks_exact(Q8_BLOCK_BYTES)) {
        *o = f16_to_f32(u16::from_le_bytes([blk[0], blk[1]]));
    }
}

/// The fewest blocks of any argument of [`gemm_q8`].
#[inline]
pub(crate) fn gemm_blocks<const M: usize>(
    w: &[&[u8]; TN],
    wd: &[&[f32]; TN],
    xq: &[&[i8]; M],
    xd: &[&[f32]; M],
    xc: &[&[i32]; M],
) -> usize {
    let a = w
        .iter()
        .map(|r| r.len() / Q8_BLOCK_BYTES)
        .chain(wd.iter().map(|r| r.len()))
        .min()
        .unwrap_or(0);
    let b = xq
        .iter()
        .map(|r| r.len() / Q8_BLOCK)
        .chain(xd.iter().map(|r| r.len()))
        .chain(xc.iter().map(|r| r.len() / 2))
        .min()
        .unwrap_or(0);
    a.min(b)
}

/// Twin of [`super::gemm_q8`]: per pair, block by block, the exact i32 block
/// dot scaled by `wd * xd` and summed in f32 (as [`dot_q8`]; `xc` unused).
pub fn gemm_q8<const M: usize>(
    w: [&[u8]; TN],
    wd: [&[f32]; TN],
    xq: [&[i8]; M],
    xd: [&[f32]; M],
    xc: [&[i32]; M],
) -> [[f32; TN]; M] {
    let nb = gemm_blocks(&w, &wd, &xq, &xd, &xc);
    let mut out = [[0.0f32; TN]; M];
    for (m, row) in out.iter_mut().enumerate() {
        for (n, o) in row.iter_mut().enumerate() {
            let mut sum = 0.0f32;
            for b in 0..nb {
                let wq = &w[n][b * Q8_BLOCK_BYTES + 2..(b + 1) * Q8_BLOCK_BYTES];
                let xs = &xq[m][b * Q8_BLOCK..(b + 1) * Q8_BLOCK];
                let isum: i32 = wq
                    .iter()
                    .zip(xs)
                    .map(|(&a, &c)| (a as i8 as i32) * c as i32)
                    .sum();
                sum += (wd[n][b] * xd[m][b]) * isum as f32;
            }
            *o = sum;
        }
    }
    out
}

/// Twin of [`super::axpy_f32`]: `y += a * x` (separate multiply and add).
#[inline]
pub fn axpy_f32(a: f32, x: &[f32], y: &mut [f32]) {
    for (yi, xi) in y.iter_mut().zip(x) {
        *yi += a * xi;
    }
}

/// Twin of [`super::dot_rows`]: one [`dot_f32`] per key row.
#[inline]
pub fn dot_rows(q: &[f32], k: &[f32], stride: usize, out: &mut [f32]) {
    let hd = q.len();
    for (j, o) in out.iter_mut().enumerate() {
        *o = dot_f32(q, &k[j * stride..j * stride + hd]);
    }
}

/// Twin of [`super::dot_rows_f16`]: one [`dot_f16`] per binary16 key row
/// (the same operations in the same order as [`dot_rows`] on the widened
/// rows: bit-identical to it).
#[inline]
pub fn dot_rows_f16(q: &[f32], k: &[u16], stride: usize, out: &mut [f32]) {
    let hd = q.len();
    for (j, o) in out.iter_mut().enumerate() {
        *o = dot_f16(&k[j * stride..j * stride + hd], q);
    }
}

/// Twin of [`super::gemm_q8_packed`] (block by block, exact i32 block sums,
/// as [`gemm_q8`]).
pub fn gemm_q8_packed<const M: usize>(
    w: super::PackedQ8<'_>,
    xq: [&[i8]; M],
    xd: [&[f32]; M],
    _xc: [&[i32]; M],
) -> [[f32; 8]; M] {
    let nb = xq
        .iter()
        .map(|r| r.len() / Q8_BLOCK)
        .chain(xd.iter().map(|r| r.len()))
        .fold(w.blocks(), usize::min);
    let mut out = [[0.0f32; 8]; M];
    for (m, row) in out.iter_mut().enumerate() {
        for (n, o) in row.iter_mut().enumerate() {
            let mut sum = 0.0f32;
            for b in 0..nb {
                let isum: i32 = (0..Q8_BLOCK)
                    .map(|i| w.value(b, n, i) as i32 * xq[m][b * Q8_BLOCK + i] as i32)
                    .sum();
                sum += (f16_to_f32(w.scale_bits(b, n)) * xd[m][b]) * isum as f32;
            }
            *o = sum;
        }
    }
    out
}

/// Twin of [`super::q8_pack8`] (layout documented at [`super::PackedQ8`]).
pub fn q8_pack8(rows: [&[u8]; 8], nb: usize, v: &mut [u8], s: &mut [u8]) {
    use super::{PACK_BLOCK_SCALES as PS, PACK_BLOCK_VALUES as PV};
    for b in 0..nb.min(v.len() / PV).min(s.len() / PS) {
        for (n, row) in rows.iter().enumerate() {
            let blk = &row[b * Q8_BLOCK_BYTES..(b + 1) * Q8_BLOCK_BYTES];
            for g in 0..4 {
                v[PV * b + 64 * g + 8 * n..PV * b + 64 * g + 8 * n + 8]
                    .copy_from_slice(&blk[2 + 8 * g..2 + 8 * g + 8]);
            }
            s[PS * b + 2 * n..PS * b + 2 * n + 2].copy_from_slice(&blk[..2]);
        }
    }
}

/// Rows `j < coef.len()` of `rows` (row `j` at `j * stride`, `y.len()`
/// floats) that are whole: the others are left out by every variant.
#[inline]
pub(crate) fn whole_rows(coef: usize, len: usize, stride: usize, n: usize) -> usize {
    if len < n {
        return 0;
    }
    coef.min((len - n).checked_div(stride).map_or(usize::MAX, |r| r + 1))
}

/// Twin of [`super::axpy_rows_f32`]: [`axpy_f32`] row after row.
#[inline]
pub fn axpy_rows_f32(coef: &[f32], x: &[f32], stride: usize, y: &mut [f32]) {
    let n = y.len();
    for (j, &a) in coef
        .iter()
        .enumerate()
        .take(whole_rows(coef.len(), x.len(), stride, n))
    {
        axpy_f32(a, &x[j * stride..j * stride + n], y);
    }
}

/// Twin of [`super::axpy_rows_f16`]: [`axpy_f16`] row after row.
#[inline]
pub fn axpy_rows_f16(coef: &[f32], w: &[u16], stride: usize, y: &mut [f32]) {
    let n = y.len();
    for (j, &a) in coef
        .iter()
        .enumerate()
        .take(whole_rows(coef.len(), w.len(), stride, n))
    {
        axpy_f16(a, &w[j * stride..j * stride + n], y);
    }
}

/// Twin of [`super::axpy_f16`].
#[inline]
pub fn axpy_f16(a: f32, w: &[u16], y: &mut [f32]) {
    for (yi, &wi) in y.iter_mut().zip(w) {
        *yi += a * f16_to_f32(wi);
    }
}

/// Constants of [`exp`] (Cephes `expf`: `x = n ln 2 + r`, ln 2 split in two
/// parts for an exact `n ln 2`, a degree-5 polynomial in `r`).
pub mod exp_c {
    pub const HI: f32 = 88.3;
    pub const LO: f32 = -87.3;
    pub const LOG2E: f32 = core::f32::consts::LOG2_E;
    pub const C1: f32 = 0.693_359_4;
    pub const C2: f32 = -2.121_944_4e-4;
    pub const P: [f32; 6] = [
        1.987_569_1e-4,
        1.398_199_9e-3,
        8.333_452e-3,
        4.166_579_6e-2,
        0.166_666_65,
        0.500_000_01,
    ];
}

/// `e^x` (max relative error ~2e-7 against libm; 0 below -87.3, inputs
/// above 88.3 read as 88.3, NaN stays NaN). Plain IEEE multiplies and adds
/// (no FMA), so the SIMD variants are bit-identical to it.
#[inline]
pub fn exp(x: f32) -> f32 {
    use exp_c::*;
    let x = if x > HI { HI } else { x };
    if x < LO {
        return 0.0;
    }
    let fx = libm::floorf(x * LOG2E + 0.5);
    let r = x - fx * C1;
    let r = r - fx * C2;
    let z = r * r;
    let mut y = P[0];
    for p in &P[1..] {
        y = y * r + p;
    }
    let y = y * z + r + 1.0;
    // 2^n with n = fx in [-126, 127] (NaN: any bits; y is NaN then).
    let n = fx as i32;
    y * f32::from_bits(((n + 127) as u32) << 23)
}

/// Twin of [`super::scale_max`]: in 16 independent lanes (so it
/// vectorizes where no SIMD variant runs), the rest in order.
pub fn scale_max(s: &mut [f32], scale: f32, max: f32) -> f32 {
    let mut lanes = [f32::NEG_INFINITY; 16];
    let mut chunks = s.chunks_exact_mut(16);
    for chunk in &mut chunks {
        for (x, m) in chunk.iter_mut().zip(&mut lanes) {
            *x *= scale;
            *m = m.max(*x);
        }
    }
    let mut max = max;
    for x in chunks.into_remainder() {
        *x *= scale;
        max = max.max(*x);
    }
    lanes.iter().fold(max, |a, &b| a.max(b))
}

/// `s[i] = e^(s[i] - max)` ([`exp`]); returns their sum in 8 lane sums
/// reduced like [`dot_f32`] (the softmax numerator and denominator).
#[inline]
pub fn exp_shifted_sum(s: &mut [f32], max: f32) -> f32 {
    let n = s.len();
    let (body, tail) = s.split_at_mut(n - n % 8);
    let mut acc = [0.0f32; 8];
    for c in body.chunks_exact_mut(8) {
        for l in 0..8 {
            c[l] = exp(c[l] - max);
            acc[l] += c[l];
        }
    }
    let mut t = 0.0f32;
    for v in tail {
        *v = exp(*v - max);
        t += *v;
    }
    reduce8(acc, t)
}

/// The 8 lane sums of an 8-wide SIMD loop and the in-order sum of the
/// tail, reduced in the one order every variant uses.
#[inline]
pub fn reduce8(a: [f32; 8], tail: f32) -> f32 {
    ((a[0] + a[4]) + (a[1] + a[5])) + ((a[2] + a[6]) + (a[3] + a[7])) + tail
}

/// LayerNorm's mean: the 8 lane sums of `x[..body]` (`body` a multiple of
/// 8) with the tail `x[body..]` added in order ([`reduce8`]).
#[inline]
pub fn ln_mean(lanes: [f32; 8], x: &[f32], body: usize) -> f32 {
    reduce8(lanes, x[body..].iter().fold(0.0, |t, &v| t + v)) / x.len() as f32
}

/// LayerNorm's `1 / sqrt(var + eps)` (biased variance): the 8 lane sums of
/// `(x - mean)^2` over `x[..body]` with the tail added in order.
#[inline]
pub fn ln_inv_std(lanes: [f32; 8], x: &[f32], body: usize, mean: f32, eps: f32) -> f32 {
    let var = reduce8(
        lanes,
        x[body..]
            .iter()
            .fold(0.0, |t, &v| t + (v - mean) * (v - mean)),
    ) / x.len() as f32;
    1.0 / libm::sqrtf(var + eps)
}

/// `y[i] = (x[i] - mean) * inv * w[i] + b[i]` for `i` in `from..x.len()`
/// (the scalar rows, or a SIMD variant's tail).
#[inline]
pub fn ln_affine(x: &[f32], w: &[f32], b: &[f32], mean: f32, inv: f32, y: &mut [f32], from: usize) {
    for i in from..x.len() {
        y[i] = (x[i] - mean) * inv * w[i] + b[i];
    }
}

/// One LayerNorm row: `y = (x - mean) * inv * w + b`, `inv = 1 / sqrt(var +
/// eps)`, biased variance (PyTorch), over the shortest of the four slices;
/// mean and variance as 8 lane sums ([`reduce8`]), no fused multiply-add,
/// so the SIMD variants (which share [`ln_mean`], [`ln_inv_std`] and
/// [`ln_affine`] for their tails) are bit-identical to it.
pub fn layernorm_row(x: &[f32], w: &[f32], b: &[f32], eps: f32, y: &mut [f32]) {
    let n = x.len().min(w.len()).min(b.len()).min(y.len());
    if n == 0 {
        return;
    }
    let x = &x[..n];
    let body = n - n % 8;
    let lanes = |f: &dyn Fn(f32) -> f32| {
        let mut acc = [0.0f32; 8];
        for c in x[..body].chunks_exact(8) {
            for l in 0..8 {
                acc[l] += f(c[l]);
            }
        }
        acc
    };
    let mean = ln_mean(lanes(&|v| v), x, body);
    let inv = ln_inv_std(lanes(&|v| (v - mean) * (v - mean)), x, body, mean, eps);
    ln_affine(x, w, b, mean, inv, y, 0);
}

/// Constants of [`gelu`]: Abramowitz & Stegun 7.1.26 for erf (max absolute
/// error 1.5e-7).
pub mod erf_c {
    pub const P: f32 = 0.327_591_1;
    pub const A: [f32; 5] = [
        1.061_405_4,
        -1.453_152,
        1.421_413_8,
        -0.284_496_74,
        0.254_829_6,
    ];
}

/// Exact GELU (`nn.GELU()` default) `0.5 x (1 + erf(x / sqrt 2))`, erf by
/// [`erf_c`] with [`exp`]; plain multiplies, adds and one divide, so the
/// SIMD variants are bit-identical to it.
#[inline]
pub fn gelu(x: f32) -> f32 {
    use erf_c::*;
    let u = x * core::f32::consts::FRAC_1_SQRT_2;
    let a = if u < 0.0 { -u } else { u };
    let t = 1.0 / (1.0 + P * a);
    let mut y = A[0];
    for c in &A[1..] {
        y = y * t + c;
    }
    let e = 1.0 - y * t * exp(-(a * a));
    let erf = if u < 0.0 { -e } else { e };
    0.5 * x * (1.0 + erf)
}

/// [`gelu`] over a slice.
#[inline]
pub fn gelu_inplace(x: &mut [f32]) {
    for v in x {
        *v = gelu(*v);
    }
}

/// Twin of [`super::bias_act`]: `y[j] = b[j] + t[j]` (`0 + t[j]` without
/// a bias), then [`gelu`] of it where `gelu_too`, over the shortest slice.
#[inline]
pub fn bias_act(t: &[f32], b: Option<&[f32]>, gelu_too: bool, y: &mut [f32]) {
    match b {
        Some(b) => y
            .iter_mut()
            .zip(t)
            .zip(b)
            .for_each(|((yo, v), bj)| *yo = bj + v),
        None => y.iter_mut().zip(t).for_each(|(yo, v)| *yo = 0.0 + v),
    }
    if gelu_too {
        let n = t.len().min(b.map_or(t.len(), <[f32]>::len)).min(y.len());
        gelu_inplace(&mut y[..n]);
    }
}

/// Twin of [`super::narrow_f16`]: `half::f16::from_f32` per value.
#[inline]
pub fn narrow_f16(src: &[f32], dst: &mut [u16]) {
    for (s, d) in src.iter().zip(dst.iter_mut()) {
        *d = half::f16::from_f32(*s).to_bits();
    }
}

/// `dst[i] = f32(src[i])` for binary16 bits (exact) over the shorter length.
#[inline]
pub fn widen_f16(src: &[u16], dst: &mut [f32]) {
    for (s, d) in src.iter().zip(dst.iter_mut()) {
        *d = f16_to_f32(*s);
    }
}
