//! Every SIMD kernel against its scalar twin (ggml-style named error
//! limits, random lengths including every tail), the scalar twins against
//! f64 references, the activation quantiser's error bound, and the generic
//! `linear` over f16 / int8 matrices against naive references.
#![allow(unsafe_code)]

use crate::kernels::simd::{self, scalar, Tile, Q8_BLOCK, Q8_BLOCK_BYTES, TM, TN};
use crate::kernels::*;

/// SIMD vs scalar twin (f32 and f16 dots): |simd - scalar| <= limit * sum |a_i b_i|
/// (only the summation order differs, plus FMA's single rounding).
const SIMD_VS_SCALAR_DOT: f64 = 1e-6;
/// SIMD vs scalar int8 dot: the per-block i32 sums are exact, only the f32
/// sum across blocks is reordered: limit * sum_b |scale_b * isum_b|.
const SIMD_VS_SCALAR_Q8: f64 = 1e-6;
/// Scalar twins vs f64 over the same (already rounded) inputs.
const SCALAR_VS_F64: f64 = 1e-6;

struct Rng(u64);
impl Rng {
    fn u(&mut self) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0
    }
    fn f(&mut self) -> f32 {
        (self.u() >> 40) as f32 / (1u64 << 24) as f32 * 2.0 - 1.0
    }
    fn vec(&mut self, n: usize) -> Vec<f32> {
        (0..n).map(|_| self.f() * 3.0).collect()
    }
}

/// Lengths: every residue mod 32 around the unroll sizes, plus random ones.
fn lengths(r: &mut Rng) -> Vec<usize> {
    let mut v: Vec<usize> = (0..=70).collect();
    v.extend([255, 256, 257, 767, 768, 1023, 1024, 1025, 3072, 4099]);
    v.extend((0..40).map(|_| (r.u() % 5000) as usize));
    v
}

pub(super) fn f16_bits(x: &[f32]) -> Vec<u16> {
    x.iter()
        .map(|&v| half::f16::from_f32(v).to_bits())
        .collect()
}

/// Quantises `w` (len multiple of 32) into stored Q8Block32 bytes, like the converter.
pub(super) fn q8_bytes(w: &[f32]) -> Vec<u8> {
    let mut out = Vec::new();
    for b in w.chunks_exact(Q8_BLOCK) {
        let amax = b.iter().fold(0.0f32, |m, v| m.max(v.abs()));
        let d = half::f16::from_f32(amax / 127.0);
        let inv = if d.to_f32() > 0.0 {
            1.0 / d.to_f32()
        } else {
            0.0
        };
        out.extend(d.to_le_bytes());
        out.extend(
            b.iter()
                .map(|&v| (v * inv).round().clamp(-127.0, 127.0) as i8 as u8),
        );
    }
    out
}

fn abs_sum(a: &[f32], b: &[f32]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (*x as f64 * *y as f64).abs())
        .sum()
}

fn check_dot(name: &str, got: f32, want: f32, scale: f64, limit: f64, n: usize) {
    let err = (got as f64 - want as f64).abs();
    assert!(
        err <= limit * scale + 1e-30,
        "{name} n={n}: {got} vs {want}, err {err:e} > {limit:e} * {scale:e}"
    );
}

/// The three kernels of one ISA, as plain fns (the caller checked the CPU).
struct Variant {
    name: &'static str,
    dot_f32: fn(&[f32], &[f32]) -> f32,
    dot_f16: fn(&[u16], &[f32]) -> f32,
    dot_q8: fn(&[u8], &[i8], &[f32]) -> f32,
    tile_f32: fn([&[f32]; TN], [&[f32]; TM]) -> Tile,
    tile_f16: fn([&[u16]; TN], [&[f32]; TM]) -> Tile,
    tile_q8: fn([&[u8]; TN], [&[i8]; TM], [&[f32]; TM]) -> Tile,
}

fn variants() -> Vec<Variant> {
    #[allow(unused_mut)]
    let mut v = Vec::new();
    #[cfg(target_arch = "x86_64")]
    if std::is_x86_feature_detected!("avx2")
        && std::is_x86_feature_detected!("fma")
        && std::is_x86_feature_detected!("f16c")
    {
        // SAFETY (all six): the CPU supports avx2, fma and f16c (checked above).
        v.push(Variant {
            name: "avx2",
            dot_f32: |a, b| unsafe { simd::x86::dot_f32(a, b) },
            dot_f16: |w, x| unsafe { simd::x86::dot_f16(w, x) },
            dot_q8: |w, q, d| unsafe { simd::x86::dot_q8(w, q, d) },
            tile_f32: |w, x| unsafe { simd::x86::tile_f32(w, x) },
            tile_f16: |w, x| unsafe { simd::x86::tile_f16(w, x) },
            tile_q8: |w, q, d| unsafe { simd::x86::tile_q8(w, q, d) },
        });
    }
    #[cfg(all(target_arch = "aarch64", target_feature = "neon"))]
    // SAFETY (all six): NEON is enabled for this build.
    v.push(Variant {
        name: "neon",
        dot_f32: |a, b| unsafe { simd::neon::dot_f32(a, b) },
        dot_f16: |w, x| unsafe { simd::neon::dot_f16(w, x) },
        dot_q8: |w, q, d| unsafe { simd::neon::dot_q8(w, q, d) },
        // NEON tiles are pairwise NEON dots for now (no register blocking).
        tile_f32: |w, x| unsafe { simd::neon::tile_f32(w, x) },
        tile_f16: |w, x| unsafe { simd::neon::tile_f16(w, x) },
        tile_q8: |w, q, d| unsafe { simd::neon::tile_q8(w, q, d) },
    });
    v
}

#[test]
fn a_simd_variant_exists_where_expected() {
    let names: Vec<&str> = variants().iter().map(|v| v.name).collect();
    eprintln!("SIMD variants tested on this machine: {names:?}");
    if cfg!(target_arch = "aarch64") {
        assert_eq!(names, ["neon"]);
    }
}

#[test]
fn simd_f32_and_f16_dots_match_scalar_twins() {
    let mut r = Rng(0x9e37_79b9_7f4a_7c15);
    for v in variants() {
        for n in lengths(&mut r) {
            let (a, b) = (r.vec(n), r.vec(n));
            let scale = abs_sum(&a, &b);
            check_dot(
                &format!("{} dot_f32", v.name),
                (v.dot_f32)(&a, &b),
                scalar::dot_f32(&a, &b),
                scale,
                SIMD_VS_SCALAR_DOT,
                n,
            );
            let h = f16_bits(&a);
            let hf: Vec<f32> = h.iter().map(|&x| simd::f16_to_f32(x)).collect();
            let scale = abs_sum(&hf, &b);
            check_dot(
                &format!("{} dot_f16", v.name),
                (v.dot_f16)(&h, &b),
                scalar::dot_f16(&h, &b),
                scale,
                SIMD_VS_SCALAR_DOT,
                n,
            );
        }
    }
}

#[test]
fn simd_f16_conversion_is_exact_for_every_bit_pattern() {
    for v in variants() {
        for h in 0..=u16::MAX {
            // Eight lanes so the vector path (not the scalar tail) converts it.
            let w = [h, 0, 0, 0, 0, 0, 0, 0];
            let x = [1.0f32, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];
            let got = (v.dot_f16)(&w, &x);
            let want = simd::f16_to_f32(h);
            assert!(
                got == want || (got.is_nan() && want.is_nan()),
                "{}: f16 {h:#06x} -> {got} (want {want})",
                v.name
            );
        }
    }
}

#[test]
fn simd_q8_dot_matches_scalar_twin() {
    let mut r = Rng(0x1234_5678_9abc_def1);
    for v in variants() {
        for nb in (0..=40).chain([96, 128]) {
            let n = nb * Q8_BLOCK;
            let w = q8_bytes(&r.vec(n));
            let x = r.vec(n);
            let (mut q, mut d) = (vec![0i8; n], vec![0f32; nb]);
            simd::quantise_q8(&x, &mut q, &mut d);
            let scale: f64 = (0..nb)
                .map(|b| {
                    let blk = &w[b * Q8_BLOCK_BYTES..(b + 1) * Q8_BLOCK_BYTES];
                    let isum: i64 = blk[2..]
                        .iter()
                        .zip(&q[b * 32..(b + 1) * 32])
                        .map(|(&a, &c)| (a as i8 as i64) * c as i64)
                        .sum();
                    (simd::f16_to_f32(u16::from_le_bytes([blk[0], blk[1]])) as f64
                        * d[b] as f64
                        * isum as f64)
                        .abs()
                })
                .sum();
            check_dot(
                &format!("{} dot_q8", v.name),
                (v.dot_q8)(&w, &q, &d),
                scalar::dot_q8(&w, &q, &d),
                scale,
                SIMD_VS_SCALAR_Q8,
                n,
            );
        }
        // Extremes: -128 weights (never written by the converter, legal in a
        // file) against +-127 activations must not saturate.
        let mut w = vec![0u8; Q8_BLOCK_BYTES];
        w[..2].copy_from_slice(&half::f16::from_f32(1.0).to_le_bytes());
        for (i, b) in w[2..].iter_mut().enumerate() {
            *b = if i % 2 == 0 { 0x80 } else { 0x7f };
        }
        let q: Vec<i8> = (0..32)
            .map(|i| if i % 2 == 0 { -127 } else { 127 })
            .collect();
        let want = 16.0 * 128.0 * 127.0 + 16.0 * 127.0 * 127.0;
        assert_eq!(
            (v.dot_q8)(&w, &q, &[1.0]),
            want,
            "{}: extreme int8 values",
            v.name
        );
        assert_eq!(scalar::dot_q8(&w, &q, &[1.0]), want);
    }
}

#[test]
fn scalar_twins_match_f64() {
    let mut r = Rng(77);
    for n in lengths(&mut r) {
        let (a, b) = (r.vec(n), r.vec(n));
        let exact: f64 = a.iter().zip(&b).map(|(x, y)| *x as f64 * *y as f64).sum();
        let err = (scalar::dot_f32(&a, &b) as f64 - exact).abs();
        assert!(
            err <= SCALAR_VS_F64 * abs_sum(&a, &b) + 1e-30,
            "dot_f32 n={n}: err {err:e}"
        );
        let h = f16_bits(&a);
        let exact: f64 = h
            .iter()
            .zip(&b)
            .map(|(x, y)| simd::f16_to_f32(*x) as f64 * *y as f64)
            .sum();
        let err = (scalar::dot_f16(&h, &b) as f64 - exact).abs();
        assert!(
            err <= SCALAR_VS_F64 * abs_sum(&a, &b) * 1.01 + 1e-30,
            "dot_f16 n={n}: err {err:e}"
        );
    }
}

#[test]
fn activation_quantiser_error_is_half_a_step() {
    let mut r = Rng(5);
    let mut x = r.vec(32 * 50);
    x[32..64].fill(0.0); // an all-zero block
    x[64] = 1e30; // one huge value in a block
    let (mut q, mut d) = (vec![0i8; x.len()], vec![0f32; 50]);
    simd::quantise_q8(&x, &mut q, &mut d);
    assert_eq!(d[1], 0.0);
    assert!(q[32..64].iter().all(|&v| v == 0));
    for (b, (xb, qb)) in x.chunks_exact(32).zip(q.chunks_exact(32)).enumerate() {
        for (&xv, &qv) in xb.iter().zip(qb) {
            assert!((-127..=127).contains(&qv));
            let err = (xv - d[b] * qv as f32).abs();
            assert!(
                err <= 0.5001 * d[b] + 1e-30 * xv.abs(),
                "block {b}: {xv} -> {qv} * {}",
                d[b]
            );
        }
    }
}

/// `linear` over F16 and Q8 matrices (the generic path, whichever ISA is
/// selected) against f64 loops over the dequantised weights; for int8 the
/// bound is the analytic activation-quantisation error sum_i |w_i| d_b / 2.
#[test]
fn linear_over_f16_and_q8_matches_naive() {
    let mut r = Rng(99);
    for &(n, i, o) in &[
        (1, 32, 1),
        (3, 64, 70),
        (7, 768, 33),
        (2, 2048, 5),
        (4, 3072, 9),
    ] {
        let (x, w, b) = (r.vec(n * i), r.vec(o * i), r.vec(o));
        let h = f16_bits(&w);
        let q8 = q8_bytes(&w);
        let mats = [
            ("f16", Matrix::F16(F16Rows::new(&h, o, i).unwrap())),
            ("q8", Matrix::Q8(Q8Rows::new(&q8, o, i).unwrap())),
        ];
        for (name, m) in mats {
            let mut y = vec![0.0; n * o];
            linear(&x, &m, Some(&b), &mut y);
            let mut row = vec![0.0; i];
            for a in 0..n {
                let xa = &x[a * i..(a + 1) * i];
                let (mut xq, mut xd) = (vec![0i8; i], vec![0f32; i / 32]);
                simd::quantise_q8(xa, &mut xq, &mut xd);
                for c in 0..o {
                    m.row_into(c, &mut row);
                    let want: f64 = b[c] as f64
                        + row
                            .iter()
                            .zip(xa)
                            .map(|(p, q)| *p as f64 * *q as f64)
                            .sum::<f64>();
                    let mut bound = 1e-5 * (1.0 + abs_sum(&row, xa));
                    if name == "q8" {
                        bound += row
                            .chunks(32)
                            .zip(&xd)
                            .map(|(wb, d)| {
                                wb.iter().map(|v| v.abs() as f64).sum::<f64>() * *d as f64 * 0.5
                            })
                            .sum::<f64>();
                    }
                    let err = (y[a * o + c] as f64 - want).abs();
                    assert!(
                        err <= bound,
                        "{name} ({n},{i},{o}) [{a},{c}]: {} vs {want}, err {err:e} > {bound:e}",
                        y[a * o + c]
                    );
                }
            }
        }
    }
}

/// A tile variant: its name, its f32 tile and its f16 tile.
type Tiles = (
    &'static str,
    fn([&[f32]; TN], [&[f32]; TM]) -> Tile,
    fn([&[u16]; TN], [&[f32]; TM]) -> Tile,
);

/// Every f32 / f16 tile this CPU runs: the SIMD variants, the 16-wide one
/// where the CPU has AVX-512, and the scalar twin.
fn every_tile() -> Vec<Tiles> {
    let mut tiles: Vec<Tiles> = variants()
        .iter()
        .map(|v| (v.name, v.tile_f32, v.tile_f16))
        .collect();
    #[cfg(target_arch = "x86_64")]
    if std::is_x86_feature_detected!("avx512f")
        && std::is_x86_feature_detected!("avx512bw")
        && std::is_x86_feature_detected!("avx512vl")
        && std::is_x86_feature_detected!("fma")
        && std::is_x86_feature_detected!("f16c")
    {
        // SAFETY (both): the CPU supports the 16-wide tiles' features (checked above).
        tiles.push((
            "avx512",
            |w, x| unsafe { simd::x86::tile_f32_512(w, x) },
            |w, x| unsafe { simd::x86::tile_f16_512(w, x) },
        ));
    }
    tiles.push(("scalar", scalar::tile_f32, scalar::tile_f16));
    tiles
}

/// Activation rows repeated at the end of a tile (a partial tile's padding:
/// the same slice again) get the numbers of distinct copies of those rows,
/// bit for bit, under every f32 / f16 tile (they compute such rows once:
/// `simd::distinct_rows`); other repeats are computed as they come.
#[test]
fn simd_tiles_give_repeated_rows_the_numbers_of_copies() {
    let tiles = every_tile();
    let mut r = Rng(0xd15c_0123_4567_89ab);
    for (name, tf32, tf16) in tiles {
        for k in [1usize, 7, 8, 15, 16, 17, 100, 768, 1536] {
            let ws: Vec<Vec<f32>> = (0..TN).map(|_| r.vec(k)).collect();
            let hs: Vec<Vec<u16>> = ws.iter().map(|w| f16_bits(w)).collect();
            let w: [&[f32]; TN] = std::array::from_fn(|j| &ws[j][..]);
            let hw: [&[u16]; TN] = std::array::from_fn(|j| &hs[j][..]);
            let xs: Vec<Vec<f32>> = (0..TM).map(|_| r.vec(k)).collect();
            // Which distinct row each tile row reads.
            let patterns: [[usize; TM]; 6] = [
                [0, 0, 0, 0],
                [0, 1, 1, 1],
                [0, 1, 2, 2],
                [0, 1, 2, 3],
                [0, 0, 1, 1],
                [0, 1, 0, 1],
            ];
            for pat in patterns {
                let shared: [&[f32]; TM] = std::array::from_fn(|m| &xs[pat[m]][..]);
                let copies: Vec<Vec<f32>> = pat.iter().map(|&p| xs[p].clone()).collect();
                let apart: [&[f32]; TM] = std::array::from_fn(|m| &copies[m][..]);
                let bits = |t: Tile| t.map(|row| row.map(f32::to_bits));
                assert_eq!(
                    bits(tf32(w, shared)),
                    bits(tf32(w, apart)),
                    "{name} tile_f32 k={k} rows {pat:?}"
                );
                assert_eq!(
                    bits(tf16(hw, shared)),
                    bits(tf16(hw, apart)),
                    "{name} tile_f16 k={k} rows {pat:?}"
                );
            }
        }
    }
}

/// Each row of a 2-4-row f32 / f16 tile gets the numbers of that row's
/// 1-row tile, bit for bit, under every tile variant (the scalar one
/// included): per entry one accumulation in the same order, whether the
/// tile takes its weight rows side by side or one after another (AVX-512
/// takes them one after another up to `SEQ_TILE_VALUES` activation
/// values: k = 768 at 4 rows, 1536 at 2; longer k stays side by side).
#[test]
fn tile_rows_equal_one_row_tiles_bit_for_bit() {
    let tiles = every_tile();
    let mut r = Rng(0x0e0e_1234_0f0f_5678);
    for (name, tf32, tf16) in tiles {
        for k in [
            1usize, 15, 16, 17, 100, 512, 767, 768, 769, 1024, 1025, 1536, 1537, 2048,
        ] {
            let ws: Vec<Vec<f32>> = (0..TN).map(|_| r.vec(k)).collect();
            let hs: Vec<Vec<u16>> = ws.iter().map(|w| f16_bits(w)).collect();
            let w: [&[f32]; TN] = std::array::from_fn(|j| &ws[j][..]);
            let hw: [&[u16]; TN] = std::array::from_fn(|j| &hs[j][..]);
            let xs: Vec<Vec<f32>> = (0..TM).map(|_| r.vec(k)).collect();
            let bits = |t: Tile| t.map(|row| row.map(f32::to_bits));
            let alone: Vec<(Tile, Tile)> = xs
                .iter()
                .map(|x| (tf32(w, [&x[..]; TM]), tf16(hw, [&x[..]; TM])))
                .collect();
            for rows in 2..=TM {
                // Rows past `rows` repeat the last one (a partial tile's padding).
                let x: [&[f32]; TM] = std::array::from_fn(|m| &xs[m.min(rows - 1)][..]);
                let (t32, t16) = (bits(tf32(w, x)), bits(tf16(hw, x)));
                for m in 0..TM {
                    let (a32, a16) = (
                        bits(alone[m.min(rows - 1)].0),
                        bits(alone[m.min(rows - 1)].1),
                    );
                    assert_eq!(t32[m], a32[0], "{name} tile_f32 k={k} rows={rows} row {m}");
                    assert_eq!(t16[m], a16[0], "{name} tile_f16 k={k} rows={rows} row {m}");
                }
            }
        }
    }
}

/// SIMD tile vs scalar tile twin, every entry: |simd - scalar| <= limit *
/// sum |w_i x_i| (summation order and FMA rounding only).
const SIMD_VS_SCALAR_TILE: f64 = 1e-6;
/// SIMD int8 tile vs scalar twin: exact i32 (partial) block sums, reordered
/// f32 sum across blocks and lanes: limit * sum_b |scale_b| sum_i |w_i x_i|.
const SIMD_VS_SCALAR_TILE_Q8: f64 = 1e-6;

/// Tiles over every column tail (k = 0..=70 and larger odd lengths), rows
/// longer than the tile's shortest one (only the common prefix counts) and repeated rows
/// (how `linear` pads row / output tails).
#[test]
fn simd_tiles_match_scalar_twins() {
    let mut r = Rng(0xfeed_beef_1234_5678);
    for v in variants() {
        let mut ks: Vec<usize> = (0..=70).collect();
        ks.extend([255, 257, 767, 768, 1024, 1031, 3072]);
        for k in ks {
            let ws: Vec<Vec<f32>> = (0..TN).map(|j| r.vec(k + j % 2)).collect();
            let xs: Vec<Vec<f32>> = (0..TM).map(|m| r.vec(k + m)).collect();
            let repeat = k % 3 == 0; // repeated last rows, as `linear` pads tails
            let w: [&[f32]; TN] = std::array::from_fn(|j| {
                if repeat && j > 0 {
                    &ws[0][..]
                } else {
                    &ws[j][..]
                }
            });
            let x: [&[f32]; TM] = std::array::from_fn(|m| {
                if repeat && m > 1 {
                    &xs[1][..]
                } else {
                    &xs[m][..]
                }
            });
            let (got, want) = ((v.tile_f32)(w, x), scalar::tile_f32(w, x));
            let hs: Vec<Vec<u16>> = ws.iter().map(|w| f16_bits(w)).collect();
            let hw: [&[u16]; TN] = std::array::from_fn(|j| &hs[j][..]);
            let (got16, want16) = ((v.tile_f16)(hw, x), scalar::tile_f16(hw, x));
            for m in 0..TM {
                for j in 0..TN {
                    let scale = abs_sum(&w[j][..k], &x[m][..k]);
                    check_dot(
                        &format!("{} tile_f32 [{m}][{j}]", v.name),
                        got[m][j],
                        want[m][j],
                        scale,
                        SIMD_VS_SCALAR_TILE,
                        k,
                    );
                    assert_eq!(
                        want[m][j],
                        scalar::dot_f32(&w[j][..k], &x[m][..k]),
                        "scalar tile_f32 is the pairwise twin"
                    );
                    let hf: Vec<f32> = hw[j][..k].iter().map(|&b| simd::f16_to_f32(b)).collect();
                    let scale = abs_sum(&hf, &x[m][..k]);
                    check_dot(
                        &format!("{} tile_f16 [{m}][{j}]", v.name),
                        got16[m][j],
                        want16[m][j],
                        scale,
                        SIMD_VS_SCALAR_TILE,
                        k,
                    );
                }
            }
        }
        for nb in (0..=12).chain([24, 32, 96]) {
            let n = nb * Q8_BLOCK;
            let wb: Vec<Vec<u8>> = (0..TN).map(|_| q8_bytes(&r.vec(n))).collect();
            let mut qs = vec![vec![0i8; n]; TM];
            let mut ds = vec![vec![0f32; nb]; TM];
            for m in 0..TM {
                let mut x = r.vec(n);
                if m == 3 && n > 0 {
                    x[0] = 1e4; // one block with a large scale
                }
                simd::quantise_q8(&x, &mut qs[m], &mut ds[m]);
            }
            let w: [&[u8]; TN] = std::array::from_fn(|j| &wb[j][..]);
            let q: [&[i8]; TM] = std::array::from_fn(|m| &qs[m][..]);
            let d: [&[f32]; TM] = std::array::from_fn(|m| &ds[m][..]);
            let (got, want) = ((v.tile_q8)(w, q, d), scalar::tile_q8(w, q, d));
            for m in 0..TM {
                for j in 0..TN {
                    let scale: f64 = (0..nb)
                        .map(|b| {
                            let blk = &w[j][b * Q8_BLOCK_BYTES..(b + 1) * Q8_BLOCK_BYTES];
                            let isum: i64 = blk[2..]
                                .iter()
                                .zip(&q[m][b * 32..(b + 1) * 32])
                                .map(|(&a, &c)| ((a as i8 as i64) * c as i64).abs())
                                .sum();
                            (simd::f16_to_f32(u16::from_le_bytes([blk[0], blk[1]])) as f64
                                * d[m][b] as f64
                                * isum as f64)
                                .abs()
                        })
                        .sum();
                    check_dot(
                        &format!("{} tile_q8 [{m}][{j}]", v.name),
                        got[m][j],
                        want[m][j],
                        scale,
                        SIMD_VS_SCALAR_TILE_Q8,
                        n,
                    );
                }
            }
        }
    }
}

/// The tiled `linear` (whichever ISA is selected) on shapes with every
/// row tail (n mod TM), output tail (out mod TN), column tail (in mod 8)
/// and int8 chunk boundary (in > ACT_CHUNK), against per-row `Matrix::dot`
/// (the untiled path): f32 and f16 agree to summation order, int8 exactly
/// up to summation order too (same per-row quantisation).
#[test]
fn tiled_linear_matches_row_dots_on_all_tails() {
    /// |tiled - row dot| <= limit * (1 + sum |w_i x_i|).
    const TILED_VS_ROWS: f64 = 2e-6;
    let mut r = Rng(4242);
    let shapes = [
        (1, 1, 1),
        (1, 32, 1),
        (2, 7, 3),
        (3, 33, 5),
        (4, 64, 4),
        (5, 96, 7),
        (6, 768, 6),
        (9, 1056, 13),
        (13, 2080, 9),
        (8, 3072, 17),
    ];
    for &(n, i, o) in &shapes {
        let (x, w, b) = (r.vec(n * i), r.vec(o * i), r.vec(o));
        let h = f16_bits(&w);
        let q8 = if i % 32 == 0 {
            Some(q8_bytes(&w))
        } else {
            None
        };
        let mut mats = vec![
            ("f32", Matrix::F32(F32Rows::new(&w, o, i).unwrap())),
            ("f16", Matrix::F16(F16Rows::new(&h, o, i).unwrap())),
        ];
        if let Some(q) = &q8 {
            mats.push(("q8", Matrix::Q8(Q8Rows::new(q, o, i).unwrap())));
        }
        for (name, m) in mats {
            let mut y = vec![f32::NAN; n * o];
            linear(&x, &m, Some(&b), &mut y);
            let mut row = vec![0.0; i];
            for a in 0..n {
                let xa = &x[a * i..(a + 1) * i];
                for c in 0..o {
                    m.row_into(c, &mut row);
                    let want = b[c] + m.dot(c, xa);
                    let err = (y[a * o + c] as f64 - want as f64).abs();
                    let bound = TILED_VS_ROWS * (1.0 + abs_sum(&row, xa));
                    assert!(
                        err <= bound,
                        "{name} ({n},{i},{o}) [{a},{c}]: {} vs {want}, err {err:e} > {bound:e}",
                        y[a * o + c]
                    );
                }
            }
        }
    }
}
