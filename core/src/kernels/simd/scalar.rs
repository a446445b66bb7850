//! Scalar reference twins of every SIMD kernel (ggml's `_ref`): the
//! definition each SIMD variant is tested against, and the path taken on
//! targets without a SIMD variant.

use super::{f16_to_f32, pairwise, Tile, Q8_BLOCK, Q8_BLOCK_BYTES, TM, TN};

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
    let nb = (w.len() / Q8_BLOCK_BYTES).min(xq.len() / Q8_BLOCK).min(xd.len());
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
/// kernel is tested against).
#[inline]
pub fn tile_f32(w: [&[f32]; TN], x: [&[f32]; TM]) -> Tile {
    let k = common(&w, &x);
    pairwise(|m, n| dot_f32(&w[n][..k], &x[m][..k]))
}

/// Tile twin of [`dot_f16`] (over the shortest row, as [`tile_f32`]).
#[inline]
pub fn tile_f16(w: [&[u16]; TN], x: [&[f32]; TM]) -> Tile {
    let k = common(&w, &x);
    pairwise(|m, n| dot_f16(&w[n][..k], &x[m][..k]))
}

/// The fewest int8 blocks of any row of a tile.
#[inline]
pub(crate) fn common_blocks(w: &[&[u8]; TN], xq: &[&[i8]; TM], xd: &[&[f32]; TM]) -> usize {
    let nbw = w.iter().map(|r| r.len() / Q8_BLOCK_BYTES).min().unwrap_or(0);
    xq.iter().map(|r| r.len() / Q8_BLOCK).chain(xd.iter().map(|r| r.len())).min().unwrap_or(0).min(nbw)
}

/// Tile twin of [`dot_q8`] (over the fewest blocks of any row).
#[inline]
pub fn tile_q8(w: [&[u8]; TN], xq: [&[i8]; TM], xd: [&[f32]; TM]) -> Tile {
    let nb = common_blocks(&w, &xq, &xd);
    pairwise(|m, n| dot_q8(&w[n][..nb * Q8_BLOCK_BYTES], &xq[m][..nb * Q8_BLOCK], &xd[m][..nb]))
}
