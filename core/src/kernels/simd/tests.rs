//! The kernels of the quantise-once int8 GEMM, the 16-wide tiles and axpy
//! against their scalar twins, for every variant this CPU can run
//! (ggml-style named error limits; `core/src/tests/simd.rs` covers the
//! older dots and tiles). On aarch64 these run under qemu (`.ci/aarch64.sh`).

use super::{scalar, Tile, Q8_BLOCK, Q8_BLOCK_BYTES, TM, TN};
use crate::kernels::{
    expand_q4, linear, F16Rows, F32Rows, Matrix, Q4Rows, Q8Rows, RowMatrix, Q4_BLOCK_BYTES,
};

/// SIMD int8 GEMM vs scalar twin: the per-block i32 sums are exact; only
/// the f32 sum across blocks and lanes is reordered: limit * sum_b
/// |wd_b xd_b| sum_i |w_i q_i|.
const SIMD_VS_SCALAR_GEMM_Q8: f64 = 1e-6;
/// 16-wide f32 / f16 tiles vs the scalar tile twin: limit * sum |w_i x_i|.
const SIMD_VS_SCALAR_TILE_512: f64 = 1e-6;
/// SIMD axpy (one FMA rounding) vs the scalar twin (two roundings):
/// limit * (|y| + |a x|) per element.
const SIMD_VS_SCALAR_AXPY: f64 = 2.5e-7;
/// Quantise-once `linear` vs per-row `Matrix::dot` (same quantisation,
/// summation order only): limit * (1 + sum |w_i x_i|).
const Q8_LINEAR_VS_ROW_DOTS: f64 = 2e-6;

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

/// Stored Q8Block32 bytes of `w` (as the converter writes them).
fn q8_bytes(w: &[f32]) -> Vec<u8> {
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

/// Stored Q4Block32 bytes of `w` (as the converter writes them).
fn q4_bytes(w: &[f32]) -> Vec<u8> {
    let mut out = Vec::new();
    for b in w.chunks_exact(Q8_BLOCK) {
        let amax = b.iter().fold(0.0f32, |m, v| m.max(v.abs()));
        let d = half::f16::from_f32(amax / 7.0);
        let inv = if d.to_f32() > 0.0 {
            1.0 / d.to_f32()
        } else {
            0.0
        };
        let q = |v: f32| ((v * inv).round().clamp(-8.0, 7.0) as i32 + 8) as u8;
        out.extend(d.to_le_bytes());
        out.extend((0..16).map(|j| q(b[j]) | (q(b[j + 16]) << 4)));
    }
    out
}

/// The stored `Q4Block32x8` group of 8 Q4Block32 rows (first `nb` blocks):
/// per block, half `h` of every row side by side, then the scales.
fn q4_group(rows: &[Vec<u8>], nb: usize) -> Vec<u8> {
    let mut group = vec![0u8; nb * (128 + 16)];
    for (j, row) in rows.iter().enumerate().take(8) {
        for b in 0..nb {
            let blk = &row[b * Q4_BLOCK_BYTES..(b + 1) * Q4_BLOCK_BYTES];
            for h in 0..2 {
                group[128 * b + 64 * h + 8 * j..128 * b + 64 * h + 8 * j + 8]
                    .copy_from_slice(&blk[2 + 8 * h..2 + 8 * h + 8]);
            }
            group[128 * nb + 16 * b + 2 * j..128 * nb + 16 * b + 2 * j + 2]
                .copy_from_slice(&blk[..2]);
        }
    }
    group
}

type Gemm<const M: usize> =
    fn([&[u8]; TN], [&[f32]; TN], [&[i8]; M], [&[f32]; M], [&[i32]; M]) -> [[f32; TN]; M];

/// One ISA's kernels as plain fns (the constructor checked the CPU).
struct Variant {
    name: &'static str,
    quantise: fn(&[f32], &mut [i8], &mut [f32], &mut [i32]),
    scales: fn(&[u8], &mut [f32]),
    g1: Gemm<1>,
    g2: Gemm<2>,
    g3: Gemm<3>,
    g4: Gemm<4>,
    tile_f32: Option<fn([&[f32]; TN], [&[f32]; TM]) -> Tile>,
    tile_f16: Option<fn([&[u16]; TN], [&[f32]; TM]) -> Tile>,
    axpy: fn(f32, &[f32], &mut [f32]),
}

#[allow(unsafe_code)]
fn variants() -> Vec<Variant> {
    #[allow(unused_mut)]
    let mut v = Vec::new();
    #[cfg(target_arch = "x86_64")]
    {
        use super::x86;
        use std::is_x86_feature_detected as has;
        let avx2 = has!("avx2") && has!("fma") && has!("f16c");
        let avx512 =
            avx2 && has!("avx512f") && has!("avx512bw") && has!("avx512dq") && has!("avx512vl");
        // SAFETY (every closure below): the features of the kernel it calls
        // were detected on this CPU just above.
        if avx2 {
            v.push(Variant {
                name: "avx2",
                quantise: |x, q, d, c| unsafe { x86::quantise_q8_corr(x, q, d, c) },
                scales: |r, o| unsafe { x86::q8_scales(r, o) },
                g1: |w, wd, q, d, c| unsafe { x86::gemm_q8_avx2(w, wd, q, d, c) },
                g2: |w, wd, q, d, c| unsafe { x86::gemm_q8_avx2(w, wd, q, d, c) },
                g3: |w, wd, q, d, c| unsafe { x86::gemm_q8_avx2(w, wd, q, d, c) },
                g4: |w, wd, q, d, c| unsafe { x86::gemm_q8_avx2(w, wd, q, d, c) },
                tile_f32: None,
                tile_f16: None,
                axpy: |a, x, y| unsafe { x86::axpy_f32(a, x, y) },
            });
        }
        if avx512 {
            v.push(Variant {
                name: "avx512",
                quantise: |x, q, d, c| unsafe { x86::quantise_q8_corr_512(x, q, d, c) },
                scales: |r, o| unsafe { x86::q8_scales(r, o) },
                g1: |w, wd, q, d, c| unsafe { x86::gemm_q8_512(w, wd, q, d, c) },
                g2: |w, wd, q, d, c| unsafe { x86::gemm_q8_512(w, wd, q, d, c) },
                g3: |w, wd, q, d, c| unsafe { x86::gemm_q8_512(w, wd, q, d, c) },
                g4: |w, wd, q, d, c| unsafe { x86::gemm_q8_512(w, wd, q, d, c) },
                tile_f32: Some(|w, x| unsafe { x86::tile_f32_512(w, x) }),
                tile_f16: Some(|w, x| unsafe { x86::tile_f16_512(w, x) }),
                axpy: |a, x, y| unsafe { x86::axpy_f32(a, x, y) },
            });
        }
        if avx512 && has!("avx512vnni") {
            v.push(Variant {
                name: "avx512vnni",
                quantise: |x, q, d, c| unsafe { x86::quantise_q8_corr_512(x, q, d, c) },
                scales: |r, o| unsafe { x86::q8_scales(r, o) },
                g1: |w, wd, q, d, c| unsafe { x86::gemm_q8_vnni(w, wd, q, d, c) },
                g2: |w, wd, q, d, c| unsafe { x86::gemm_q8_vnni(w, wd, q, d, c) },
                g3: |w, wd, q, d, c| unsafe { x86::gemm_q8_vnni(w, wd, q, d, c) },
                g4: |w, wd, q, d, c| unsafe { x86::gemm_q8_vnni(w, wd, q, d, c) },
                tile_f32: None,
                tile_f16: None,
                axpy: |a, x, y| unsafe { x86::axpy_f32(a, x, y) },
            });
        }
    }
    #[cfg(all(target_arch = "aarch64", target_feature = "neon"))]
    {
        use super::neon;
        // SAFETY (every closure): NEON is enabled for this build.
        v.push(Variant {
            name: "neon",
            quantise: |x, q, d, c| unsafe { neon::quantise_q8_corr(x, q, d, c) },
            scales: scalar::q8_scales,
            g1: |w, wd, q, d, c| unsafe { neon::gemm_q8(w, wd, q, d, c) },
            g2: |w, wd, q, d, c| unsafe { neon::gemm_q8(w, wd, q, d, c) },
            g3: |w, wd, q, d, c| unsafe { neon::gemm_q8(w, wd, q, d, c) },
            g4: |w, wd, q, d, c| unsafe { neon::gemm_q8(w, wd, q, d, c) },
            tile_f32: None,
            tile_f16: None,
            axpy: |a, x, y| unsafe { neon::axpy_f32(a, x, y) },
        });
        if std::arch::is_aarch64_feature_detected!("dotprod") {
            // SAFETY (every closure): NEON is enabled and dotprod detected.
            v.push(Variant {
                name: "neondot",
                quantise: |x, q, d, c| unsafe { neon::quantise_q8_corr(x, q, d, c) },
                scales: scalar::q8_scales,
                g1: |w, wd, q, d, c| unsafe { neon::gemm_q8_dot(w, wd, q, d, c) },
                g2: |w, wd, q, d, c| unsafe { neon::gemm_q8_dot(w, wd, q, d, c) },
                g3: |w, wd, q, d, c| unsafe { neon::gemm_q8_dot(w, wd, q, d, c) },
                g4: |w, wd, q, d, c| unsafe { neon::gemm_q8_dot(w, wd, q, d, c) },
                tile_f32: None,
                tile_f16: None,
                axpy: |a, x, y| unsafe { neon::axpy_f32(a, x, y) },
            });
        }
    }
    v
}

#[test]
fn variants_exist_where_expected() {
    let names: Vec<&str> = variants().iter().map(|v| v.name).collect();
    eprintln!("int8 GEMM variants tested on this machine: {names:?}");
    if cfg!(target_arch = "aarch64") {
        assert!(names.contains(&"neon"));
    }
}

/// Blocks with ties (`k + 0.5` after scaling), zeros, NaN and Inf, and random ones.
fn quantiser_inputs(r: &mut Rng) -> Vec<f32> {
    let mut x = r.vec(32 * 40);
    // amax 127 -> scale 1, inv 1: exact ties.
    for (i, v) in x[..32].iter_mut().enumerate() {
        *v = if i == 0 {
            127.0
        } else {
            (i as f32 - 16.0) + 0.5
        };
    }
    x[33] = -127.0;
    x[34] = 0.499_999_97;
    x[35] = -2.5;
    x[64..96].fill(0.0);
    x[100] = f32::NAN;
    x[130] = f32::INFINITY;
    x[170] = -f32::INFINITY;
    x[200] = 1e-38;
    // Block 8: every |x| < 1.5e-36, so 1 / scale overflows: all zero, scale 0.
    for (i, v) in x[256..288].iter_mut().enumerate() {
        *v = (i as f32 - 10.0) * 1e-39;
    }
    x
}

#[test]
fn quantiser_is_bit_identical_to_scalar_twin() {
    let mut r = Rng(11);
    let x = quantiser_inputs(&mut r);
    let nb = x.len() / Q8_BLOCK;
    let (mut q0, mut d0, mut c0) = (vec![0i8; x.len()], vec![0f32; nb], vec![0i32; 2 * nb]);
    scalar::quantise_q8_corr(&x, &mut q0, &mut d0, &mut c0);
    // The twin is the reference quantiser plus the correction.
    let (mut q1, mut d1) = (vec![0i8; x.len()], vec![0f32; nb]);
    super::quantise_q8(&x, &mut q1, &mut d1);
    assert_eq!(q0, q1);
    assert!(
        q0[256..288].iter().all(|&v| v == 0) && d0[8] == 0.0,
        "a block whose 1 / scale overflows quantises to zero"
    );
    assert_eq!(
        d0.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
        d1.iter().map(|v| v.to_bits()).collect::<Vec<_>>()
    );
    for (b, qb) in q0.chunks_exact(Q8_BLOCK).enumerate() {
        assert_eq!(
            c0[2 * b] + c0[2 * b + 1],
            -128 * qb.iter().map(|&v| v as i32).sum::<i32>()
        );
        assert_eq!(
            c0[2 * b],
            -128 * (0..4)
                .map(|g| qb[8 * g..8 * g + 4].iter().map(|&v| v as i32).sum::<i32>())
                .sum::<i32>()
        );
    }
    // Every block count up to the whole input (odd counts end on a lone block;
    // counts of 16k + 4 .. 16k + 15 end on a partial group of the AVX-512
    // kernel), each output followed by sentinels no kernel may write.
    for v in variants() {
        for n in 0..=nb {
            let (mut qs, mut ds, mut cs) = (
                vec![0x55i8; 32 * n + 64],
                vec![-7.0f32; n + 16],
                vec![12345i32; 2 * n + 32],
            );
            let (q, d, c) = (&mut qs[..32 * n], &mut ds[..n], &mut cs[..2 * n]);
            (v.quantise)(&x[..32 * n], q, d, c);
            let (q, d, c) = (q.to_vec(), d.to_vec(), c.to_vec());
            assert!(
                qs[32 * n..].iter().all(|&s| s == 0x55)
                    && ds[n..].iter().all(|&s| s == -7.0)
                    && cs[2 * n..].iter().all(|&s| s == 12345),
                "{} ({n} blocks): a write past the outputs",
                v.name
            );
            assert_eq!(q, q0[..32 * n], "{} ({n} blocks): quantised values", v.name);
            let bits = |d: &[f32]| d.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&d), bits(&d0[..n]), "{} ({n} blocks): scales", v.name);
            assert_eq!(c, c0[..2 * n], "{} ({n} blocks): corrections", v.name);
        }
    }
}

#[test]
fn q8_scales_match_scalar_twin() {
    let mut r = Rng(3);
    for nb in 0..40 {
        let row = q8_bytes(&r.vec(nb * Q8_BLOCK));
        let mut want = vec![0f32; nb];
        scalar::q8_scales(&row, &mut want);
        for v in variants() {
            let mut got = vec![f32::NAN; nb];
            (v.scales)(&row, &mut got);
            assert_eq!(got, want, "{} nb={nb}", v.name);
        }
    }
}

fn check(name: &str, got: f32, want: f32, scale: f64, limit: f64) {
    let err = (got as f64 - want as f64).abs();
    assert!(
        err <= limit * scale + 1e-30,
        "{name}: {got} vs {want}, err {err:e} > {limit:e} * {scale:e}"
    );
}

/// Every variant's `gemm_q8::<M>` (M = 1..=4) against the scalar twin, on
/// every block count 0..=12 and larger odd / even ones, rows longer than
/// the common prefix, and the extreme -128 weight against +-127.
#[test]
fn gemm_q8_matches_scalar_twin() {
    let mut r = Rng(0x5151_7777);
    for v in variants() {
        for nb in (0..=12).chain([31, 48, 96]) {
            let n = nb * Q8_BLOCK;
            let mut wb: Vec<Vec<u8>> = (0..TN)
                .map(|j| q8_bytes(&r.vec(n + 32 * (j % 2))))
                .collect();
            if nb > 0 {
                wb[1][2] = 0x80; // -128
            }
            let mut qs = vec![vec![0i8; n + 32]; 4];
            let mut ds = vec![vec![0f32; nb + 1]; 4];
            let mut cs = vec![vec![0i32; 2 * nb + 2]; 4];
            for m in 0..4 {
                let mut x = r.vec(n + 32);
                if m == 3 && n > 0 {
                    x[0] = 1e4;
                }
                if m == 2 && n > 0 {
                    x[0] = -30.0; // -> -127 with the largest weight
                    x[1] = 3.0;
                }
                super::scalar::quantise_q8_corr(&x, &mut qs[m], &mut ds[m], &mut cs[m]);
            }
            let mut wds = vec![vec![0f32; nb + 1]; TN];
            for j in 0..TN {
                scalar::q8_scales(&wb[j], &mut wds[j]);
            }
            let w: [&[u8]; TN] = core::array::from_fn(|j| &wb[j][..]);
            let wd: [&[f32]; TN] = core::array::from_fn(|j| &wds[j][..nb]);
            let q = |m: usize| &qs[m][..];
            let d = |m: usize| &ds[m][..];
            let c = |m: usize| &cs[m][..];
            let scale = |m: usize, j: usize| -> f64 {
                (0..nb)
                    .map(|b| {
                        let blk = &w[j][b * Q8_BLOCK_BYTES + 2..(b + 1) * Q8_BLOCK_BYTES];
                        let s: i64 = blk
                            .iter()
                            .zip(&qs[m][b * 32..(b + 1) * 32])
                            .map(|(&a, &c)| ((a as i8 as i64) * c as i64).abs())
                            .sum();
                        (wd[j][b] as f64 * ds[m][b] as f64).abs() * s as f64
                    })
                    .sum()
            };
            let want4 = scalar::gemm_q8::<4>(
                w,
                wd,
                core::array::from_fn(q),
                core::array::from_fn(d),
                core::array::from_fn(c),
            );
            let got: Vec<Vec<[f32; TN]>> = vec![
                (v.g1)(w, wd, [q(0)], [d(0)], [c(0)]).to_vec(),
                (v.g2)(w, wd, [q(0), q(1)], [d(0), d(1)], [c(0), c(1)]).to_vec(),
                (v.g3)(
                    w,
                    wd,
                    [q(0), q(1), q(2)],
                    [d(0), d(1), d(2)],
                    [c(0), c(1), c(2)],
                )
                .to_vec(),
                (v.g4)(
                    w,
                    wd,
                    core::array::from_fn(q),
                    core::array::from_fn(d),
                    core::array::from_fn(c),
                )
                .to_vec(),
            ];
            for (mm, g) in got.iter().enumerate() {
                for (m, row) in g.iter().enumerate() {
                    for j in 0..TN {
                        check(
                            &format!("{} gemm_q8::<{}> nb={nb} [{m}][{j}]", v.name, mm + 1),
                            row[j],
                            want4[m][j],
                            scale(m, j),
                            SIMD_VS_SCALAR_GEMM_Q8,
                        );
                    }
                }
            }
            // The twin is the pairwise blocked dot (`dot_q8`).
            for m in 0..4 {
                for j in 0..TN {
                    let want =
                        scalar::dot_q8(&w[j][..nb * Q8_BLOCK_BYTES], &qs[m][..n], &ds[m][..nb]);
                    assert_eq!(
                        want4[m][j], want,
                        "scalar gemm_q8 is the pairwise dot_q8 twin"
                    );
                }
            }
        }
        // Extremes: every weight -128 or 127 against -127 / 127.
        let mut w = vec![0u8; 2 * Q8_BLOCK_BYTES];
        for blk in w.chunks_exact_mut(Q8_BLOCK_BYTES) {
            blk[..2].copy_from_slice(&half::f16::from_f32(1.0).to_le_bytes());
            for (i, b) in blk[2..].iter_mut().enumerate() {
                *b = if i % 2 == 0 { 0x80 } else { 0x7f };
            }
        }
        let q: Vec<i8> = (0..64)
            .map(|i| if i % 2 == 0 { -127 } else { 127 })
            .collect();
        let mut c = vec![0i32; 4];
        let (mut qq, mut dd) = (vec![0i8; 64], vec![0f32; 2]);
        let xf: Vec<f32> = q.iter().map(|&v| v as f32).collect();
        scalar::quantise_q8_corr(&xf, &mut qq, &mut dd, &mut c);
        assert_eq!((qq.clone(), dd.clone()), (q.clone(), vec![1.0, 1.0]));
        let wd = [1.0f32; 2];
        let t = (v.g1)(
            [&w, &w, &w, &w],
            [&wd, &wd, &wd, &wd],
            [&q],
            [&[1.0, 1.0]],
            [&c],
        );
        assert_eq!(
            t[0][0],
            2.0 * (16.0 * 128.0 * 127.0 + 16.0 * 127.0 * 127.0),
            "{}: extreme int8 values",
            v.name
        );
    }
}

#[test]
fn wide_tiles_match_scalar_twins() {
    let mut r = Rng(0xabcd);
    for v in variants() {
        let (Some(tf32), Some(tf16)) = (v.tile_f32, v.tile_f16) else {
            continue;
        };
        let mut ks: Vec<usize> = (0..=70).collect();
        ks.extend([255, 257, 767, 768, 1031, 3072]);
        for k in ks {
            let ws: Vec<Vec<f32>> = (0..TN).map(|j| r.vec(k + j % 2)).collect();
            let xs: Vec<Vec<f32>> = (0..TM).map(|m| r.vec(k + m)).collect();
            let w: [&[f32]; TN] = core::array::from_fn(|j| &ws[j][..]);
            let x: [&[f32]; TM] = core::array::from_fn(|m| &xs[m][..]);
            let hs: Vec<Vec<u16>> = ws
                .iter()
                .map(|w| {
                    w.iter()
                        .map(|&v| half::f16::from_f32(v).to_bits())
                        .collect()
                })
                .collect();
            let hw: [&[u16]; TN] = core::array::from_fn(|j| &hs[j][..]);
            let (g32, w32) = (tf32(w, x), scalar::tile_f32(w, x));
            let (g16, w16) = (tf16(hw, x), scalar::tile_f16(hw, x));
            for m in 0..TM {
                for j in 0..TN {
                    let s: f64 = w[j][..k]
                        .iter()
                        .zip(&x[m][..k])
                        .map(|(a, b)| (*a as f64 * *b as f64).abs())
                        .sum();
                    check(
                        &format!("{} tile_f32 k={k}", v.name),
                        g32[m][j],
                        w32[m][j],
                        s,
                        SIMD_VS_SCALAR_TILE_512,
                    );
                    let s: f64 = hw[j][..k]
                        .iter()
                        .zip(&x[m][..k])
                        .map(|(a, b)| (super::f16_to_f32(*a) as f64 * *b as f64).abs())
                        .sum();
                    check(
                        &format!("{} tile_f16 k={k}", v.name),
                        g16[m][j],
                        w16[m][j],
                        s,
                        SIMD_VS_SCALAR_TILE_512,
                    );
                }
            }
        }
    }
}

#[test]
fn axpy_matches_scalar_twin() {
    let mut r = Rng(17);
    for v in variants() {
        for n in (0..=40).chain([63, 64, 65, 768, 1001]) {
            let (x, y0) = (r.vec(n), r.vec(n));
            let a = r.f();
            let (mut got, mut want) = (y0.clone(), y0.clone());
            (v.axpy)(a, &x, &mut got);
            scalar::axpy_f32(a, &x, &mut want);
            for i in 0..n {
                let s = y0[i].abs() as f64 + (a * x[i]).abs() as f64;
                check(
                    &format!("{} axpy n={n}", v.name),
                    got[i],
                    want[i],
                    s,
                    SIMD_VS_SCALAR_AXPY,
                );
            }
        }
    }
}

/// The quantise-once `linear` (whichever ISA is selected) against per-row
/// `Matrix::dot` (the chunked path): every row tail (n mod 4), output
/// tail, and several panels (rows * in > Q8_PANEL).
#[test]
fn q8_linear_matches_row_dots() {
    let mut r = Rng(4243);
    let panel = crate::kernels::linear::Q8_PANEL;
    let shapes = [
        (1, 32, 1),
        (2, 64, 3),
        (3, 96, 5),
        (5, 768, 7),
        (9, 1056, 13),
        (10, 3072, 6),
        (panel / 768 + 5, 768, 9),
    ];
    for &(n, i, o) in &shapes {
        let (x, w, b) = (r.vec(n * i), r.vec(o * i), r.vec(o));
        let q8 = q8_bytes(&w);
        let m = Matrix::Q8(Q8Rows::new(&q8, o, i).unwrap());
        let mut y = vec![f32::NAN; n * o];
        linear(&x, &m, Some(&b), &mut y);
        let mut row = vec![0.0; i];
        for a in 0..n {
            let xa = &x[a * i..(a + 1) * i];
            for c in 0..o {
                m.row_into(c, &mut row);
                let want = b[c] + m.dot(c, xa);
                let s: f64 = row
                    .iter()
                    .zip(xa)
                    .map(|(p, q)| (*p as f64 * *q as f64).abs())
                    .sum();
                check(
                    &format!("q8 linear ({n},{i},{o}) [{a},{c}]"),
                    y[a * o + c],
                    want,
                    1.0 + s,
                    Q8_LINEAR_VS_ROW_DOTS,
                );
            }
        }
        // Unused import guard: the trait's own row count.
        if let Matrix::Q8(q) = m {
            assert_eq!(q.rows(), o);
        }
    }
}

#[test]
#[allow(unsafe_code)]
fn dot_rows_match_scalar_twin() {
    let mut r = Rng(23);
    for hd in [1, 7, 15, 16, 17, 33, 48, 63, 64, 65, 96] {
        let stride = hd + 5;
        let q = r.vec(hd);
        let k = r.vec(9 * stride + hd);
        for n in 0..=10 {
            let mut want = vec![0f32; n];
            scalar::dot_rows(&q, &k, stride, &mut want);
            let mut runs: Vec<(&str, Vec<f32>)> = Vec::new();
            #[cfg(target_arch = "x86_64")]
            {
                use std::is_x86_feature_detected as has;
                if has!("avx2") && has!("fma") {
                    let mut g = vec![0f32; n];
                    // SAFETY: avx2 and fma detected.
                    unsafe { super::x86::dot_rows(&q, &k, stride, &mut g) };
                    runs.push(("avx2", g));
                }
                if has!("avx512f") && has!("avx2") && has!("fma") {
                    let mut g = vec![0f32; n];
                    // SAFETY: avx512f, avx2 and fma detected.
                    unsafe { super::x86::dot_rows_512(&q, &k, stride, &mut g) };
                    runs.push(("avx512", g));
                }
            }
            #[cfg(all(target_arch = "aarch64", target_feature = "neon"))]
            {
                let mut g = vec![0f32; n];
                // SAFETY: NEON is enabled for this build.
                unsafe { super::neon::dot_rows(&q, &k, stride, &mut g) };
                runs.push(("neon", g));
            }
            for (name, g) in runs {
                for j in 0..n {
                    let s: f64 = q
                        .iter()
                        .zip(&k[j * stride..])
                        .map(|(a, b)| (*a as f64 * *b as f64).abs())
                        .sum();
                    check(
                        &format!("{name} dot_rows hd={hd} j={j}"),
                        g[j],
                        want[j],
                        s,
                        SIMD_VS_SCALAR_TILE_512,
                    );
                }
            }
        }
    }
}

/// The packed 8-row kernel (selected ISA's variant when it has one, and the
/// AVX512-VNNI variant directly where the CPU has it) against two calls of
/// the scalar 4-row twin, M = 1..=8.
/// The f32 bits of packed-kernel rows.
fn bits8(t: &[[f32; 8]]) -> Vec<[u32; 8]> {
    t.iter().map(|r| r.map(f32::to_bits)).collect()
}

/// Calls `f(m0, k)` for every run of `k` (1..=8) activation rows out of 8.
#[allow(dead_code)]
fn for_row_counts(f: &mut dyn FnMut(usize, usize)) {
    for k in 1..=8 {
        for m0 in 0..=8 - k {
            f(m0, k);
        }
    }
}

/// The f32 steps every SIMD packed kernel performs (AVX512-VNNI, AMX, AVX2,
/// NEON dotprod), written out: per row and block, the exact i32 block dot
/// converted, times `s_n,b * xd_b`, fused into the even or the odd blocks'
/// sum; the two sums added at the end. The kernels must equal it bit for
/// bit, so an x8 file gives the same numbers on every such CPU.
fn packed_paired_model(w: super::PackedQ8<'_>, q: &[&[i8]], d: &[&[f32]]) -> Vec<[f32; 8]> {
    let nb = q
        .iter()
        .map(|r| r.len() / Q8_BLOCK)
        .chain(d.iter().map(|r| r.len()))
        .fold(w.blocks(), usize::min);
    q.iter()
        .zip(d)
        .map(|(qm, dm)| {
            core::array::from_fn(|n| {
                let mut acc = [0.0f32; 2];
                for b in 0..nb {
                    let isum: i32 = (0..Q8_BLOCK)
                        .map(|i| w.value(b, n, i) as i32 * qm[b * Q8_BLOCK + i] as i32)
                        .sum();
                    acc[b % 2] = (isum as f32)
                        .mul_add(super::f16_to_f32(w.scale_bits(b, n)) * dm[b], acc[b % 2]);
                }
                acc[0] + acc[1]
            })
        })
        .collect()
}

/// Dispatches a run of `q.len()` (1..=8) rows to the AVX2 packed kernel,
/// or (`vnni`) the AVX-VNNI one.
///
/// # Safety
/// The CPU must support avx2, fma and f16c, and avxvnni where `vnni`.
#[cfg(target_arch = "x86_64")]
#[allow(unsafe_code)]
unsafe fn packed_rows_avx2(
    w: super::PackedQ8<'_>,
    q: &[&[i8]],
    d: &[&[f32]],
    c: &[&[i32]],
    vnni: bool,
) -> Vec<[f32; 8]> {
    macro_rules! call {
        ($($k:literal)*) => {
            match q.len() {
                // SAFETY: the caller's features.
                $($k => unsafe {
                    let (q, d, c) = (core::array::from_fn(|m| q[m]), core::array::from_fn(|m| d[m]), core::array::from_fn(|m| c[m]));
                    if vnni {
                        super::x86::gemm_q8_packed_avxvnni::<$k>(w, q, d, c)
                    } else {
                        super::x86::gemm_q8_packed_avx2::<$k>(w, q, d, c)
                    }
                }.to_vec(),)*
                _ => unreachable!(),
            }
        };
    }
    call!(1 2 3 4 5 6 7 8)
}

/// Dispatches a run of `q.len()` (1..=8) rows to the NEON dotprod packed kernel.
///
/// # Safety
/// The CPU must support neon and dotprod.
#[cfg(target_arch = "aarch64")]
#[allow(unsafe_code)]
unsafe fn packed_rows_dot(
    w: super::PackedQ8<'_>,
    q: &[&[i8]],
    d: &[&[f32]],
    c: &[&[i32]],
    i8mm: bool,
) -> Vec<[f32; 8]> {
    macro_rules! call {
        ($($k:literal)*) => {
            match q.len() {
                // SAFETY: the caller's features.
                $($k => unsafe {
                    let (q, d, c) = (core::array::from_fn(|m| q[m]), core::array::from_fn(|m| d[m]), core::array::from_fn(|m| c[m]));
                    if i8mm {
                        super::neon::gemm_q8_packed_i8mm::<$k>(w, q, d, c)
                    } else {
                        super::neon::gemm_q8_packed_dot::<$k>(w, q, d, c)
                    }
                }.to_vec(),)*
                _ => unreachable!(),
            }
        };
    }
    call!(1 2 3 4 5 6 7 8)
}

#[test]
#[allow(unsafe_code)]
fn packed_gemm_q8_matches_scalar_twin() {
    use super::{Q8Pack8, PACK_ROWS};
    let mut r = Rng(0x8888);
    for nb in [0, 1, 2, 3, 7, 24, 95, 96] {
        let n = nb * Q8_BLOCK;
        let mut wb: Vec<Vec<u8>> = (0..PACK_ROWS).map(|_| q8_bytes(&r.vec(n))).collect();
        if nb > 0 {
            wb[3][2] = 0x80;
        }
        let mut wds = vec![vec![0f32; nb]; PACK_ROWS];
        for j in 0..PACK_ROWS {
            scalar::q8_scales(&wb[j], &mut wds[j]);
        }
        let mut pack = Q8Pack8::new();
        super::q8_pack8(core::array::from_fn(|j| &wb[j][..]), nb, &mut pack);
        let mut qs = vec![vec![0i8; n]; 8];
        let mut ds = vec![vec![0f32; nb]; 8];
        let mut cs = vec![vec![0i32; 2 * nb]; 8];
        for m in 0..8 {
            let mut x = r.vec(n);
            if m == 5 && n > 0 {
                x[0] = 1e4;
            }
            scalar::quantise_q8_corr(&x, &mut qs[m], &mut ds[m], &mut cs[m]);
        }
        let q: [&[i8]; 8] = core::array::from_fn(|m| &qs[m][..]);
        let d: [&[f32]; 8] = core::array::from_fn(|m| &ds[m][..]);
        let c: [&[i32]; 8] = core::array::from_fn(|m| &cs[m][..]);
        let mut want = [[0f32; 8]; 8];
        for half in 0..2 {
            let w: [&[u8]; TN] = core::array::from_fn(|j| &wb[4 * half + j][..]);
            let wd: [&[f32]; TN] = core::array::from_fn(|j| &wds[4 * half + j][..]);
            for m0 in [0, 4] {
                let t = scalar::gemm_q8::<4>(
                    w,
                    wd,
                    core::array::from_fn(|i| q[m0 + i]),
                    core::array::from_fn(|i| d[m0 + i]),
                    core::array::from_fn(|i| c[m0 + i]),
                );
                for i in 0..4 {
                    for j in 0..4 {
                        want[m0 + i][4 * half + j] = t[i][j];
                    }
                }
            }
        }
        let (mut pv, mut ps) = (
            vec![0u8; nb * super::PACK_BLOCK_VALUES],
            vec![0u8; nb * super::PACK_BLOCK_SCALES],
        );
        scalar::q8_pack8(core::array::from_fn(|j| &wb[j][..]), nb, &mut pv, &mut ps);
        let view = pack.view();
        assert_eq!(
            (view.v, view.s),
            (&pv[..], &ps[..]),
            "dispatched packing vs scalar twin nb={nb}"
        );
        // The packed layout holds each row's stored values and scale bits.
        for j in 0..PACK_ROWS {
            for b in 0..nb {
                let blk = &wb[j][b * Q8_BLOCK_BYTES..(b + 1) * Q8_BLOCK_BYTES];
                assert_eq!(view.scale_bits(b, j), u16::from_le_bytes([blk[0], blk[1]]));
                assert!(
                    (0..Q8_BLOCK).all(|i| view.value(b, j, i) == blk[2 + i] as i8),
                    "row {j} block {b}"
                );
            }
        }
        #[cfg(target_arch = "x86_64")]
        if std::is_x86_feature_detected!("avx512f")
            && std::is_x86_feature_detected!("avx512bw")
            && std::is_x86_feature_detected!("avx512dq")
            && std::is_x86_feature_detected!("avx512vl")
        {
            let (mut xv, mut xs) = (
                vec![0u8; nb * super::PACK_BLOCK_VALUES],
                vec![0u8; nb * super::PACK_BLOCK_SCALES],
            );
            // SAFETY: avx512f/bw/dq/vl detected (avx2 implied on every such CPU).
            unsafe {
                super::x86::q8_pack8(core::array::from_fn(|j| &wb[j][..]), nb, &mut xv, &mut xs)
            };
            assert_eq!(
                (&xv, &xs),
                (&pv, &ps),
                "avx512 packing vs scalar twin nb={nb}"
            );
        }
        // A stored group (values then scales, as a Q8Block32x8 file holds it) reads the same.
        let group: Vec<u8> = pv.iter().chain(&ps).copied().collect();
        let stored = super::PackedQ8::from_group(&group, nb).unwrap();
        assert!(
            super::PackedQ8::from_group(&group[..group.len().saturating_sub(1)], nb).is_none()
                || nb == 0
        );
        let twin = scalar::gemm_q8_packed::<8>(view, q, d, c);
        assert_eq!(
            scalar::gemm_q8_packed::<8>(stored, q, d, c),
            twin,
            "stored group vs stack pack nb={nb}"
        );
        assert_eq!(twin, want, "scalar packed twin nb={nb}");
        let mut got: Vec<(&str, [[f32; 8]; 8])> = vec![
            ("dispatched", super::gemm_q8_packed::<8>(view, q, d, c)),
            (
                "dispatched, stored group",
                super::gemm_q8_packed::<8>(stored, q, d, c),
            ),
        ];
        #[cfg(target_arch = "x86_64")]
        {
            use std::is_x86_feature_detected as has;
            if has!("avx512f")
                && has!("avx512bw")
                && has!("avx512dq")
                && has!("avx512vl")
                && has!("avx512vnni")
                && has!("avx2")
                && has!("fma")
                && has!("f16c")
            {
                // SAFETY: every feature of the kernel detected above.
                let v8 = unsafe { super::x86::gemm_q8_packed_vnni::<8>(view, q, d, c) };
                got.push(("avx512vnni", v8));
                // SAFETY: as above.
                let t3 = unsafe {
                    super::x86::gemm_q8_packed_vnni::<3>(
                        stored,
                        [q[2], q[3], q[4]],
                        [d[2], d[3], d[4]],
                        [c[2], c[3], c[4]],
                    )
                };
                let mut g = v8;
                g[2..5].copy_from_slice(&t3);
                got.push(("avx512vnni M=3", g));
            }
            // The 32-byte kernels (AVX2, AVX-VNNI): 8 rows in one call, then
            // every row count gives each row the numbers it gets among 8.
            let vnni_cpu = has!("avxvnni");
            for (name, vnni) in [("avx2", false), ("avxvnni", true)] {
                if !(has!("avx2") && has!("fma") && has!("f16c")) || (vnni && !vnni_cpu) {
                    continue;
                }
                // SAFETY: every feature of the kernel detected above.
                let a8 = unsafe { packed_rows_avx2(view, &q, &d, &c, vnni) };
                got.push((name, a8.clone().try_into().unwrap()));
                for_row_counts(&mut |m0, k| {
                    // SAFETY: as above.
                    let t = unsafe {
                        packed_rows_avx2(
                            stored,
                            &q[m0..m0 + k],
                            &d[m0..m0 + k],
                            &c[m0..m0 + k],
                            vnni,
                        )
                    };
                    assert_eq!(
                        bits8(&t),
                        bits8(&a8[m0..m0 + k]),
                        "{name} rows {m0}..{} nb={nb}",
                        m0 + k
                    );
                });
            }
        }
        // The NEON kernels (sdot, smmla): 8 rows in one call, then every row
        // count gives each row the numbers it gets among 8.
        #[cfg(target_arch = "aarch64")]
        for (name, i8mm) in [("neondot", false), ("neoni8mm", true)] {
            use std::arch::is_aarch64_feature_detected as has;
            if !has!("dotprod") || (i8mm && !has!("i8mm")) {
                continue;
            }
            // SAFETY: neon (baseline), dotprod and (where used) i8mm detected.
            let a8 = unsafe { packed_rows_dot(view, &q, &d, &c, i8mm) };
            got.push((name, a8.clone().try_into().unwrap()));
            for_row_counts(&mut |m0, k| {
                // SAFETY: as above.
                let t = unsafe {
                    packed_rows_dot(stored, &q[m0..m0 + k], &d[m0..m0 + k], &c[m0..m0 + k], i8mm)
                };
                assert_eq!(
                    bits8(&t),
                    bits8(&a8[m0..m0 + k]),
                    "{name} rows {m0}..{} nb={nb}",
                    m0 + k
                );
            });
        }
        // Every SIMD variant performs the paired f32 steps: the same bits on every such CPU.
        let model = bits8(&packed_paired_model(view, &q, &d));
        for (name, g) in &got {
            if !name.starts_with("dispatched") || super::packed_q8_fast() {
                assert_eq!(
                    bits8(g),
                    model,
                    "{name}: the paired f32 steps, bit for bit, nb={nb}"
                );
            }
        }
        for (name, g) in got {
            for m in 0..8 {
                for j in 0..8 {
                    let s: f64 = (0..nb)
                        .map(|b| {
                            let blk = &wb[j][b * Q8_BLOCK_BYTES + 2..(b + 1) * Q8_BLOCK_BYTES];
                            let a: i64 = blk
                                .iter()
                                .zip(&qs[m][b * 32..(b + 1) * 32])
                                .map(|(&w, &x)| ((w as i8 as i64) * x as i64).abs())
                                .sum();
                            (wds[j][b] as f64 * ds[m][b] as f64).abs() * a as f64
                        })
                        .sum();
                    check(
                        &format!("{name} packed nb={nb} [{m}][{j}]"),
                        g[m][j],
                        want[m][j],
                        s,
                        SIMD_VS_SCALAR_GEMM_Q8,
                    );
                }
            }
        }
    }
}

/// Dispatches a run of `q.len()` (1..=12) rows to the packed kernel that
/// `linear` calls ([`super::gemm_q8_packed_ahead`], at most 12 rows per
/// call), prefetching `ahead`.
fn packed_rows_dispatched(
    w: super::PackedQ8<'_>,
    q: &[&[i8]],
    d: &[&[f32]],
    c: &[&[i32]],
    ahead: &[u8],
) -> Vec<[f32; 8]> {
    macro_rules! call {
        ($($k:literal)*) => {
            match q.len() {
                $($k => super::gemm_q8_packed_ahead::<$k>(w, core::array::from_fn(|m| q[m]), core::array::from_fn(|m| d[m]), core::array::from_fn(|m| c[m]), ahead).to_vec(),)*
                _ => unreachable!(),
            }
        };
    }
    call!(1 2 3 4 5 6 7 8 9 10 11 12)
}

/// Every run of 1-12 activation rows out of 12 (`linear` hands the packed
/// kernel up to 12 rows per call), int8 and 4-bit groups, with and without
/// bytes to prefetch: under the selected kernel each row gets the paired
/// f32 steps' bits where it is a SIMD packed variant, else the scalar
/// twin's bits for that row alone.
#[test]
fn packed_kernel_runs_of_up_to_12_rows_give_each_row_its_numbers() {
    use super::{PackedQ8, Q8Pack8, PACK_ROWS};
    const ROWS: usize = 12;
    let mut r = Rng(0x1212);
    for nb in [1usize, 2, 3, 24, 96] {
        let n = nb * Q8_BLOCK;
        let rows8: Vec<Vec<u8>> = (0..PACK_ROWS).map(|_| q8_bytes(&r.vec(n))).collect();
        let mut pack = Q8Pack8::new();
        super::q8_pack8(core::array::from_fn(|j| &rows8[j][..]), nb, &mut pack);
        let rows4: Vec<Vec<u8>> = (0..PACK_ROWS).map(|_| q4_bytes(&r.vec(n))).collect();
        let group4 = q4_group(&rows4, nb);
        let g4 = PackedQ8::from_q4_group(&group4, nb).unwrap();
        let mut qs = vec![vec![0i8; n]; ROWS];
        let mut ds = vec![vec![0f32; nb]; ROWS];
        let mut cs = vec![vec![0i32; 2 * nb]; ROWS];
        for m in 0..ROWS {
            scalar::quantise_q8_corr(&r.vec(n), &mut qs[m], &mut ds[m], &mut cs[m]);
        }
        let q: Vec<&[i8]> = qs.iter().map(|v| &v[..]).collect();
        let d: Vec<&[f32]> = ds.iter().map(|v| &v[..]).collect();
        let c: Vec<&[i32]> = cs.iter().map(|v| &v[..]).collect();
        let ahead = vec![7u8; 3000];
        for (name, w) in [("int8", pack.view()), ("q4", g4)] {
            let want: Vec<[u32; 8]> = if super::packed_q8_fast() {
                bits8(&packed_paired_model(w, &q, &d))
            } else {
                (0..ROWS)
                    .flat_map(|m| bits8(&scalar::gemm_q8_packed::<1>(w, [q[m]], [d[m]], [c[m]])))
                    .collect()
            };
            for k in 1..=ROWS {
                for m0 in 0..=ROWS - k {
                    let a = if m0 % 2 == 0 { &ahead[..] } else { &[] };
                    let t = packed_rows_dispatched(
                        w,
                        &q[m0..m0 + k],
                        &d[m0..m0 + k],
                        &c[m0..m0 + k],
                        a,
                    );
                    assert_eq!(
                        bits8(&t),
                        want[m0..m0 + k],
                        "{name} rows {m0}..{} nb={nb}",
                        m0 + k
                    );
                }
            }
        }
    }
}

#[test]
#[allow(unsafe_code)]
fn axpy_f16_matches_scalar_twin() {
    let mut r = Rng(29);
    for n in (0..=20).chain([63, 64, 65, 512, 1001]) {
        let w: Vec<u16> = r
            .vec(n)
            .iter()
            .map(|&v| half::f16::from_f32(v).to_bits())
            .collect();
        let y0 = r.vec(n);
        let a = r.f();
        let mut want = y0.clone();
        scalar::axpy_f16(a, &w, &mut want);
        let mut got = y0.clone();
        super::axpy_f16(a, &w, &mut got);
        #[cfg(target_arch = "x86_64")]
        if std::is_x86_feature_detected!("avx2")
            && std::is_x86_feature_detected!("fma")
            && std::is_x86_feature_detected!("f16c")
        {
            got = y0.clone();
            // SAFETY: avx2, fma, f16c detected.
            unsafe { super::x86::axpy_f16(a, &w, &mut got) };
        }
        for i in 0..n {
            let s = y0[i].abs() as f64 + (a * super::f16_to_f32(w[i])).abs() as f64;
            check(
                &format!("axpy_f16 n={n}"),
                got[i],
                want[i],
                s,
                SIMD_VS_SCALAR_AXPY,
            );
        }
    }
}

/// A row's `linear` output (int8, f16, f32) must not depend on how many other rows
/// share the call (a batched step of several sessions must equal single
/// steps bit for bit): 1..9 rows, at the model's shapes, under the
/// dispatched kernels (packed 8-row VNNI tile from 4 rows on, unpacked
/// tile below).
#[test]
fn linear_rows_do_not_depend_on_the_batch() {
    let mut r = Rng(99);
    for &(i, o) in &[(768usize, 64usize), (3072, 24), (256, 40)] {
        let w = r.vec(o * i);
        let q8 = q8_bytes(&w);
        let q4 = q4_bytes(&w);
        let h: Vec<u16> = w
            .iter()
            .map(|&v| half::f16::from_f32(v).to_bits())
            .collect();
        let x8 = x8_bytes(&q8, o, i);
        // 12 rows: at 3072 inputs more than 10 rows take the full panel, fewer the small one.
        let rows = 12;
        let x = r.vec(rows * i);
        for m in [
            Matrix::X8(crate::kernels::X8Rows::new(&x8, o, i).unwrap()),
            Matrix::Q8(Q8Rows::new(&q8, o, i).unwrap()),
            Matrix::Q4(Q4Rows::new(&q4, o, i).unwrap()),
            Matrix::F16(F16Rows::new(&h, o, i).unwrap()),
            Matrix::F32(F32Rows::new(&w, o, i).unwrap()),
        ] {
            let mut alone = vec![0.0f32; rows * o];
            for a in 0..rows {
                linear(
                    &x[a * i..(a + 1) * i],
                    &m,
                    None,
                    &mut alone[a * o..(a + 1) * o],
                );
            }
            for n in 2..=rows {
                let mut y = vec![0.0f32; n * o];
                linear(&x[..n * i], &m, None, &mut y);
                for (k, (a, b)) in y.iter().zip(&alone).enumerate() {
                    assert_eq!(
                        a.to_bits(),
                        b.to_bits(),
                        "in {i} out {o}: {n} rows, element {k}: {a} vs {b} alone"
                    );
                }
            }
        }
    }
}

/// The stored `Q8Block32x8` groups of `Q8Block32` rows (`o` a multiple of 8).
fn x8_bytes(q8: &[u8], o: usize, i: usize) -> Vec<u8> {
    let (nb, q8r) = (i / Q8_BLOCK, Q8Rows::new(q8, o, i).unwrap());
    let mut x8 = Vec::new();
    for g in 0..o / 8 {
        let mut pack = super::Q8Pack8::new();
        super::q8_pack8(core::array::from_fn(|j| q8r.row(8 * g + j)), nb, &mut pack);
        let v = pack.view();
        x8.extend_from_slice(&v.v[..nb * super::PACK_BLOCK_VALUES]);
        x8.extend_from_slice(&v.s[..nb * super::PACK_BLOCK_SCALES]);
    }
    x8
}

#[test]
fn group_blocks_expand_to_their_values() {
    // Random int8 and 4-bit groups of 3 blocks: every row's block as Q8Block32 bytes.
    let mut r = Rng(23);
    let nb = 3;
    for q4 in [false, true] {
        let per = if q4 {
            super::PACK_BLOCK_NIBBLES
        } else {
            super::PACK_BLOCK_VALUES
        };
        let bytes: Vec<u8> = (0..nb * (per + super::PACK_BLOCK_SCALES))
            .map(|_| r.u() as u8)
            .collect();
        let g = if q4 {
            super::PackedQ8::from_q4_group(&bytes, nb)
        } else {
            super::PackedQ8::from_group(&bytes, nb)
        }
        .unwrap();
        for b in 0..nb {
            for n in 0..super::PACK_ROWS {
                let mut got = [0u8; Q8_BLOCK_BYTES];
                g.q8_block_of_row(b, n, &mut got);
                let mut want = [0u8; Q8_BLOCK_BYTES];
                want[..2].copy_from_slice(&g.scale_bits(b, n).to_le_bytes());
                for i in 0..Q8_BLOCK {
                    want[2 + i] = g.value(b, n, i) as u8;
                }
                assert_eq!(got, want, "q4 {q4}, block {b}, row {n}");
            }
        }
    }
}

#[test]
fn linear_each_equals_one_linear_per_matrix() {
    use crate::kernels::{linear_each, X8Rows};
    let mut r = Rng(5);
    for &i in &[768usize, 3072, 256] {
        // Three matrices of different heights (the int8 ones share one quantised panel).
        let outs = [64usize, 24, 40];
        let w: Vec<Vec<f32>> = outs.iter().map(|&o| r.vec(o * i)).collect();
        let q8: Vec<Vec<u8>> = w.iter().map(|w| q8_bytes(w)).collect();
        let x8: Vec<Vec<u8>> = q8
            .iter()
            .zip(&outs)
            .map(|(q, &o)| x8_bytes(q, o, i))
            .collect();
        let q4: Vec<Vec<u8>> = w.iter().map(|w| q4_bytes(w)).collect();
        let h: Vec<Vec<u16>> = w
            .iter()
            .map(|w| {
                w.iter()
                    .map(|&v| half::f16::from_f32(v).to_bits())
                    .collect()
            })
            .collect();
        let b: Vec<Vec<f32>> = outs.iter().map(|&o| r.vec(o)).collect();
        let sets: Vec<[Matrix<'_>; 3]> = vec![
            core::array::from_fn(|k| Matrix::X8(X8Rows::new(&x8[k], outs[k], i).unwrap())),
            core::array::from_fn(|k| Matrix::Q8(Q8Rows::new(&q8[k], outs[k], i).unwrap())),
            core::array::from_fn(|k| Matrix::Q4(Q4Rows::new(&q4[k], outs[k], i).unwrap())),
            core::array::from_fn(|k| Matrix::F16(F16Rows::new(&h[k], outs[k], i).unwrap())),
            // Mixed layouts: one call per matrix.
            [
                Matrix::X8(X8Rows::new(&x8[0], outs[0], i).unwrap()),
                Matrix::Q8(Q8Rows::new(&q8[1], outs[1], i).unwrap()),
                Matrix::F32(F32Rows::new(&w[2], outs[2], i).unwrap()),
            ],
        ];
        // Up to 12 rows: at 3072 inputs more than 10 rows take the full panel.
        for n in [1usize, 4, 9, 11, 12] {
            let x = r.vec(n * i);
            for m in &sets {
                let want: Vec<Vec<f32>> = (0..3)
                    .map(|k| {
                        let mut y = vec![0.0f32; n * outs[k]];
                        linear(&x, &m[k], Some(&b[k]), &mut y);
                        y
                    })
                    .collect();
                // One spare row of output room: only n rows are written.
                let mut got: Vec<Vec<f32>> =
                    outs.iter().map(|&o| vec![7.0f32; (n + 1) * o]).collect();
                let [g0, g1, g2] = &mut got[..] else {
                    unreachable!()
                };
                linear_each(
                    &x,
                    [&m[0], &m[1], &m[2]],
                    [Some(&b[0][..]), Some(&b[1][..]), Some(&b[2][..])],
                    [&mut g0[..], &mut g1[..], &mut g2[..]],
                );
                for k in 0..3 {
                    let bits = |v: &[f32]| v.iter().map(|f| f.to_bits()).collect::<Vec<_>>();
                    assert_eq!(
                        bits(&got[k][..n * outs[k]]),
                        bits(&want[k]),
                        "in {i}, {n} rows, matrix {k}"
                    );
                    assert!(
                        got[k][n * outs[k]..].iter().all(|&v| v == 7.0),
                        "in {i}, {n} rows, matrix {k}: spare row written"
                    );
                }
            }
        }
    }
}

/// The Q4Block32 layout: element j of a block in the low nibble of byte j,
/// element j + 16 in the high nibble, value = scale * (nibble - 8).
#[test]
fn q4_block_layout() {
    let mut blk = [0u8; Q4_BLOCK_BYTES];
    blk[..2].copy_from_slice(&half::f16::from_f32(0.5).to_le_bytes());
    for j in 0..16 {
        blk[2 + j] = (j as u8) | ((15 - j as u8) << 4);
    }
    let m = Q4Rows::new(&blk, 1, 32).unwrap();
    let mut row = [0.0f32; 32];
    m.row_into(0, &mut row);
    for j in 0..16 {
        assert_eq!(row[j], 0.5 * (j as f32 - 8.0), "element {j}");
        assert_eq!(row[j + 16], 0.5 * (7.0 - j as f32), "element {}", j + 16);
    }
    let mut y = [1.0f32; 32];
    m.axpy(0, 2.0, &mut y);
    for j in 0..32 {
        assert_eq!(y[j], 1.0 + 2.0 * row[j]);
    }
    assert!(Q4Rows::new(&blk[..17], 1, 32).is_none());
    assert!(Q4Rows::new(&blk, 1, 16).is_none());
}

/// Q4 weights compute exactly what the Q8 blocks they expand to compute
/// (same scale, values -8..7): dots, rows and `linear` (the int8 panel
/// path, up to `Q4_FAST_COLS` inputs) are bit-identical, so the int8
/// kernels and their twins cover Q4; wider rows take the generic chunked
/// path, checked against its own row dots.
#[test]
fn q4_matches_its_q8_expansion_bit_for_bit() {
    let mut r = Rng(4747);
    let wide = crate::kernels::linear::Q4_FAST_COLS + 32;
    for &(n, i, o) in &[
        (1usize, 32usize, 3usize),
        (3, 96, 5),
        (5, 768, 7),
        (9, 1056, 13),
        (2, 3072, 6),
        (12, 768, 9),
        (3, wide, 5),
    ] {
        let (x, w) = (r.vec(n * i), r.vec(o * i));
        let q4 = q4_bytes(&w);
        let mut q8 = vec![0u8; o * i / Q8_BLOCK * Q8_BLOCK_BYTES];
        expand_q4(&q4, &mut q8);
        let (m4, m8) = (
            Q4Rows::new(&q4, o, i).unwrap(),
            Q8Rows::new(&q8, o, i).unwrap(),
        );
        let (mut r4, mut r8) = (vec![0.0f32; i], vec![0.0f32; i]);
        for c in 0..o {
            m4.row_into(c, &mut r4);
            m8.row_into(c, &mut r8);
            assert_eq!(r4, r8, "row {c}");
            // Within a quarter step of the f32 weights (round to nearest on the f16 scale's grid).
            for (k, (&a, &b)) in r4.iter().zip(&w[c * i..(c + 1) * i]).enumerate() {
                let blk = &w[c * i + k / 32 * 32..c * i + k / 32 * 32 + 32];
                let d = half::f16::from_f32(blk.iter().fold(0.0f32, |m, v| m.max(v.abs())) / 7.0)
                    .to_f32();
                assert!(
                    (a - b).abs() <= 0.5 * d * 1.001 + 1e-7,
                    "({i},{o}) [{c},{k}]: {a} vs {b}, step {d}"
                );
            }
            for a in 0..n {
                let xa = &x[a * i..(a + 1) * i];
                assert_eq!(
                    m4.dot(c, xa).to_bits(),
                    m8.dot(c, xa).to_bits(),
                    "dot ({n},{i},{o}) [{a},{c}]"
                );
            }
        }
        let m = Matrix::Q4(m4);
        let mut y = vec![f32::NAN; n * o];
        linear(&x, &m, None, &mut y);
        if i <= crate::kernels::linear::Q4_FAST_COLS {
            let mut y8 = vec![f32::NAN; n * o];
            linear(&x, &Matrix::Q8(m8), None, &mut y8);
            let bits = |v: &[f32]| v.iter().map(|f| f.to_bits()).collect::<Vec<_>>();
            assert_eq!(
                bits(&y),
                bits(&y8),
                "linear ({n},{i},{o}): Q4 vs its Q8 expansion"
            );
        }
        // ... and against its own row dots (the chunked path).
        for a in 0..n {
            let xa = &x[a * i..(a + 1) * i];
            for c in 0..o {
                m.row_into(c, &mut r4);
                let s: f64 = r4
                    .iter()
                    .zip(xa)
                    .map(|(p, q)| (*p as f64 * *q as f64).abs())
                    .sum();
                check(
                    &format!("q4 linear ({n},{i},{o}) [{a},{c}]"),
                    y[a * o + c],
                    m.dot(c, xa),
                    1.0 + s,
                    Q8_LINEAR_VS_ROW_DOTS,
                );
            }
        }
    }
}

/// Inputs for the exp / GELU twins: a dense sweep, the clamp edges, the
/// zero region, and pseudo-random scores.
fn exp_inputs() -> std::vec::Vec<f32> {
    let mut v: std::vec::Vec<f32> = (-4000..=4000).map(|i| i as f32 * 0.0231).collect();
    v.extend([
        0.0,
        -0.0,
        1e-30,
        -1e-30,
        88.29,
        88.3,
        88.31,
        200.0,
        -87.29,
        -87.3,
        -87.31,
        -200.0,
        f32::NEG_INFINITY,
        f32::INFINITY,
        f32::MIN_POSITIVE,
    ]);
    let mut r = Rng(99);
    v.extend((0..997).map(|_| r.f() * 30.0));
    v
}

/// `exp_shifted_sum` (AVX2, AVX-512) is bit-identical to its scalar twin,
/// values and sum, on every length tail; the twin is within 2.5e-7 relative of libm.
#[test]
#[allow(unsafe_code)]
fn exp_matches_scalar_twin_and_libm() {
    let xs = exp_inputs();
    for &x in &xs {
        let (got, want) = (scalar::exp(x), libm::expf(x.min(88.3)));
        if x >= -87.3 {
            let rel = ((got as f64 - want as f64) / want as f64).abs();
            assert!(rel <= 2.5e-7, "exp({x}) = {got}, libm {want}: rel {rel:e}");
        } else {
            assert_eq!(got, 0.0, "exp({x})");
        }
    }
    assert!(scalar::exp(f32::NAN).is_nan());
    #[cfg(target_arch = "x86_64")]
    if std::is_x86_feature_detected!("avx2") {
        for n in (0..=40).chain([63, 64, 65, 290, xs.len()]) {
            let max = xs[..n].iter().fold(f32::NEG_INFINITY, |m, &v| m.max(v));
            let (mut a, mut b) = (xs[..n].to_vec(), xs[..n].to_vec());
            let sa = scalar::exp_shifted_sum(&mut a, max);
            // SAFETY: avx2 detected.
            let sb = unsafe { super::x86::exp_shifted_sum(&mut b, max) };
            assert_eq!(sa.to_bits(), sb.to_bits(), "sum n={n}");
            for (i, (p, q)) in a.iter().zip(&b).enumerate() {
                assert_eq!(p.to_bits(), q.to_bits(), "n={n} i={i} x={}", xs[i]);
            }
            if std::is_x86_feature_detected!("avx512f") {
                let mut c = xs[..n].to_vec();
                // SAFETY: avx512f (and avx2) detected.
                let sc = unsafe { super::x86::exp_shifted_sum_512(&mut c, max) };
                assert_eq!(sa.to_bits(), sc.to_bits(), "avx512 sum n={n}");
                for (i, (p, q)) in a.iter().zip(&c).enumerate() {
                    assert_eq!(p.to_bits(), q.to_bits(), "avx512 n={n} i={i} x={}", xs[i]);
                }
            }
        }
        let (mut a, mut b) = ([f32::NAN; 9], [f32::NAN; 9]);
        scalar::exp_shifted_sum(&mut a, 0.0);
        // SAFETY: avx2 detected.
        unsafe { super::x86::exp_shifted_sum(&mut b, 0.0) };
        assert!(a.iter().chain(&b).all(|v| v.is_nan()), "NaN stays NaN");
        if std::is_x86_feature_detected!("avx512f") {
            let mut c = [f32::NAN; 19];
            // SAFETY: avx512f (and avx2) detected.
            unsafe { super::x86::exp_shifted_sum_512(&mut c, 0.0) };
            assert!(c.iter().all(|v| v.is_nan()), "avx512: NaN stays NaN");
        }
    }
    #[cfg(all(target_arch = "aarch64", target_feature = "neon"))]
    for n in (0..=40).chain([63, 64, 65, 290, xs.len()]) {
        let max = xs[..n].iter().fold(f32::NEG_INFINITY, |m, &v| m.max(v));
        let (mut a, mut b) = (xs[..n].to_vec(), xs[..n].to_vec());
        let sa = scalar::exp_shifted_sum(&mut a, max);
        // SAFETY: NEON is enabled for this build.
        let sb = unsafe { super::neon::exp_shifted_sum(&mut b, max) };
        assert_eq!(sa.to_bits(), sb.to_bits(), "neon sum n={n}");
        for (i, (p, q)) in a.iter().zip(&b).enumerate() {
            assert_eq!(p.to_bits(), q.to_bits(), "neon n={n} i={i} x={}", xs[i]);
        }
    }
}

/// `softmax_runs` (AVX2, AVX-512: one call per row) gives the bits of its
/// scalar twin (the same body over the scalar pieces), probabilities and
/// sum, for the coordinated attention's run layouts (10 runs of 1..29 keys
/// in rows of 290), one run, no run, runs that only see zero weights, and a
/// planted score far above the others (a sum of one).
#[test]
#[allow(unsafe_code)]
fn softmax_runs_match_the_scalar_twin() {
    let mut r = Rng(7);
    let mut layouts: Vec<(usize, Vec<(usize, usize)>)> = (1..=29)
        .map(|seen| (290, (0..10).map(|s| (29 * s, 29 * s + seen)).collect()))
        .collect();
    layouts.push((290, vec![(0, 290)]));
    layouts.push((40, vec![]));
    layouts.push((40, vec![(3, 3), (5, 21), (21, 40)]));
    for (n, runs) in &layouts {
        for case in 0..3 {
            let mut row: Vec<f32> = (0..*n).map(|_| r.f() * 8.0).collect();
            if case == 1 {
                row.iter_mut().for_each(|v| *v = -1.0e30);
            }
            if case == 2 && *n > 6 {
                row[6] = 1.0e4;
            }
            let scale = 0.125f32;
            let mut want = row.clone();
            let ws = super::softmax_runs_with(&mut want, runs, scale, scalar::scale_max, scalar::exp_shifted_sum);
            let check = |name: &str, got: &[f32], gs: f32| {
                assert_eq!(ws.to_bits(), gs.to_bits(), "{name} sum, n={n} runs={runs:?} case {case}");
                for (i, (p, q)) in want.iter().zip(got).enumerate() {
                    assert_eq!(p.to_bits(), q.to_bits(), "{name} n={n} i={i} case {case}");
                }
            };
            #[cfg(target_arch = "x86_64")]
            if std::is_x86_feature_detected!("avx2") {
                let mut got = row.clone();
                // SAFETY: avx2 detected.
                let gs = unsafe { super::x86::softmax_runs_avx2(&mut got, runs, scale) };
                check("avx2", &got, gs);
                if std::is_x86_feature_detected!("avx512f") {
                    let mut got = row.clone();
                    // SAFETY: avx512f (and avx2) detected.
                    let gs = unsafe { super::x86::softmax_runs_512(&mut got, runs, scale) };
                    check("avx512", &got, gs);
                }
            }
            let mut got = row.clone();
            let gs = super::softmax_runs(&mut got, runs, scale);
            check("dispatched", &got, gs);
        }
    }
}

/// GELU (AVX2, AVX-512: whole 32-value pairs, a 16-value rest, a masked
/// tail) is bit-identical to its scalar twin; the twin is within
/// 1e-7 (1 + |x|) of `0.5 x (1 + libm::erff(x / sqrt 2))`.
#[test]
#[allow(unsafe_code)]
fn gelu_matches_scalar_twin_and_libm() {
    let xs: std::vec::Vec<f32> = exp_inputs().into_iter().filter(|v| v.is_finite()).collect();
    for &x in &xs {
        let want = 0.5 * x as f64 * (1.0 + libm::erff(x * core::f32::consts::FRAC_1_SQRT_2) as f64);
        let got = scalar::gelu(x) as f64;
        assert!(
            (got - want).abs() <= 1e-7 * (1.0 + x.abs() as f64),
            "gelu({x}) = {got}, libm {want}"
        );
    }
    #[cfg(target_arch = "x86_64")]
    if std::is_x86_feature_detected!("avx2") {
        for n in (0..=20).chain([32, 33, 40, 48, 64, 65, xs.len()]) {
            let (mut a, mut b) = (xs[..n].to_vec(), xs[..n].to_vec());
            scalar::gelu_inplace(&mut a);
            // SAFETY: avx2 detected.
            unsafe { super::x86::gelu_inplace(&mut b) };
            for (i, (p, q)) in a.iter().zip(&b).enumerate() {
                assert_eq!(p.to_bits(), q.to_bits(), "n={n} x={}", xs[i]);
            }
            if std::is_x86_feature_detected!("avx512f") {
                let mut c = xs[..n].to_vec();
                // SAFETY: avx512f detected.
                unsafe { super::x86::gelu_inplace_512(&mut c) };
                for (i, (p, q)) in a.iter().zip(&c).enumerate() {
                    assert_eq!(p.to_bits(), q.to_bits(), "avx512 n={n} x={}", xs[i]);
                }
            }
        }
    }
    #[cfg(all(target_arch = "aarch64", target_feature = "neon"))]
    for n in (0..=20).chain([64, 65, xs.len()]) {
        let (mut a, mut b) = (xs[..n].to_vec(), xs[..n].to_vec());
        scalar::gelu_inplace(&mut a);
        // SAFETY: NEON is enabled for this build.
        unsafe { super::neon::gelu_inplace(&mut b) };
        for (i, (p, q)) in a.iter().zip(&b).enumerate() {
            assert_eq!(p.to_bits(), q.to_bits(), "neon n={n} x={}", xs[i]);
        }
    }
}

/// `bias_act_rows` (AVX-512: four rows' GELUs interleaved; the dispatcher
/// under every ISA this CPU runs) equals the twin row by row, bit for bit,
/// for 0-9 rows, with and without a bias and GELU.
#[test]
#[allow(unsafe_code)]
fn bias_act_rows_equal_the_twin_row_by_row() {
    let mut r = Rng(0xb1a6);
    let xs: std::vec::Vec<f32> = exp_inputs().into_iter().filter(|v| v.is_finite()).collect();
    let b: [f32; 16] = core::array::from_fn(|_| r.vec(1)[0]);
    for n in 0..=9 {
        let rows: std::vec::Vec<[f32; 16]> = (0..n)
            .map(|m| core::array::from_fn(|j| xs[(37 * m + 5 * j) % xs.len()]))
            .collect();
        for (bias, gelu) in [
            (None, false),
            (Some(&b), false),
            (Some(&b), true),
            (None, true),
        ] {
            let want: std::vec::Vec<[f32; 16]> = rows
                .iter()
                .map(|t| {
                    let mut y = [0.0f32; 16];
                    scalar::bias_act(t, bias.map(|b| &b[..]), gelu, &mut y);
                    y
                })
                .collect();
            let bits =
                |v: &[[f32; 16]]| v.iter().flatten().map(|x| x.to_bits()).collect::<Vec<_>>();
            let mut got = rows.clone();
            super::bias_act_rows(&mut got, bias, gelu);
            assert_eq!(
                bits(&got),
                bits(&want),
                "dispatch rows={n} bias={} gelu={gelu}",
                bias.is_some()
            );
            #[cfg(target_arch = "x86_64")]
            if std::is_x86_feature_detected!("avx2") {
                let mut got = rows.clone();
                // SAFETY: avx2 detected.
                unsafe { super::x86::bias_act_rows_avx2(&mut got, bias, gelu) };
                assert_eq!(
                    bits(&got),
                    bits(&want),
                    "avx2 rows={n} bias={} gelu={gelu}",
                    bias.is_some()
                );
            }
            #[cfg(target_arch = "x86_64")]
            if std::is_x86_feature_detected!("avx512f") {
                let mut got = rows.clone();
                // SAFETY: avx512f detected.
                unsafe { super::x86::bias_act_rows_512(&mut got, bias, gelu) };
                assert_eq!(
                    bits(&got),
                    bits(&want),
                    "avx512 rows={n} bias={} gelu={gelu}",
                    bias.is_some()
                );
            }
        }
    }
}

/// The GEMM epilogue `bias_act` (AVX-512: the sum and GELU on 16 lanes,
/// masked tails; the dispatcher on every variant this CPU runs) is
/// bit-identical to its twin, with and without a bias and GELU, and
/// writes nothing past the shortest slice.
#[test]
#[allow(unsafe_code)]
fn bias_act_matches_scalar_twin() {
    let mut r = Rng(0xb1a5);
    let xs: std::vec::Vec<f32> = exp_inputs().into_iter().filter(|v| v.is_finite()).collect();
    for n in (0..=20).chain([31, 32, 33, 48, 64, 65, xs.len()]) {
        let t = &xs[..n];
        let b = r.vec(n + 3);
        for (bias, gelu) in [
            (None, false),
            (Some(&b[..n]), false),
            (Some(&b[..n]), true),
            (None, true),
        ] {
            let mut want = vec![0.0f32; n];
            scalar::bias_act(t, bias, gelu, &mut want);
            for (j, w) in want.iter().enumerate() {
                let s = bias.map_or(0.0, |b| b[j]) + t[j];
                assert_eq!(
                    w.to_bits(),
                    if gelu { scalar::gelu(s) } else { s }.to_bits(),
                    "twin n={n} j={j}"
                );
            }
            // One more output slot than values: it must stay as it was.
            let mut got = vec![-3.0f32; n + 1];
            super::bias_act(t, bias, gelu, &mut got);
            assert_eq!(
                got[..n].iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
                want.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
                "dispatch n={n} bias={} gelu={gelu}",
                bias.is_some()
            );
            assert_eq!(got[n], -3.0);
            #[cfg(target_arch = "x86_64")]
            if std::is_x86_feature_detected!("avx512f") {
                let mut got = vec![-3.0f32; n + 1];
                // SAFETY: avx512f detected.
                unsafe { super::x86::bias_act_512(t, bias, gelu, &mut got) };
                for j in 0..n {
                    assert_eq!(
                        got[j].to_bits(),
                        want[j].to_bits(),
                        "avx512 n={n} j={j} bias={} gelu={gelu}",
                        bias.is_some()
                    );
                }
                assert_eq!(got[n], -3.0, "avx512 wrote past the values");
            }
        }
    }
}

/// `widen_f16` (F16C / NEON) is bit-identical to its twin on every binary16
/// pattern (NaNs compared as NaN), at every tail length.
#[test]
#[allow(unsafe_code)]
fn widen_f16_matches_scalar_twin() {
    let all: std::vec::Vec<u16> = (0..=u16::MAX).collect();
    let mut want = std::vec![0.0f32; all.len()];
    scalar::widen_f16(&all, &mut want);
    for (h, w) in all.iter().zip(&want) {
        let exact = half::f16::from_bits(*h).to_f32();
        assert!(
            w.to_bits() == exact.to_bits() || (w.is_nan() && exact.is_nan()),
            "{h:#06x}"
        );
    }
    let same = |a: &[f32], b: &[f32], what: &str| {
        for (i, (x, y)) in a.iter().zip(b).enumerate() {
            assert!(
                x.to_bits() == y.to_bits() || (x.is_nan() && y.is_nan()),
                "{what} {:#06x}",
                all[i]
            );
        }
    };
    #[cfg(target_arch = "x86_64")]
    if std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("f16c") {
        for n in (0..=17).chain([all.len()]) {
            let mut got = std::vec![0.0f32; n];
            // SAFETY: avx2 and f16c detected.
            unsafe { super::x86::widen_f16(&all[..n], &mut got) };
            same(&got, &want[..n], "avx2");
        }
    }
    #[cfg(all(target_arch = "aarch64", target_feature = "neon"))]
    for n in (0..=17).chain([all.len()]) {
        let mut got = std::vec![0.0f32; n];
        // SAFETY: NEON is enabled for this build.
        unsafe { super::neon::widen_f16(&all[..n], &mut got) };
        same(&got, &want[..n], "neon");
    }
}

/// A [`Workers`](crate::kernels::parallel::Workers) stand-in for the split
/// tests: 3 "threads", run one after another in reverse order on the
/// calling thread, jobs counted per calling thread (so a kernel call of a
/// test running in parallel is never counted as this test's split).
struct ReversePool;

std::thread_local! {
    static REVERSE_JOBS: core::cell::Cell<usize> = const { core::cell::Cell::new(0) };
}

/// Split jobs the pool ran for the current thread so far.
fn reverse_jobs() -> usize {
    REVERSE_JOBS.with(|j| j.get())
}

// SAFETY: `run` calls each `task(i)`, `i < n`, exactly once and returns after them.
unsafe impl crate::kernels::parallel::Workers for ReversePool {
    fn threads(&self) -> usize {
        3
    }
    fn run(&self, n: usize, task: &(dyn Fn(usize) + Sync)) {
        REVERSE_JOBS.with(|j| j.set(j.get() + 1));
        (0..n).rev().for_each(task);
    }
}

static REVERSE: ReversePool = ReversePool;
static REVERSE_INSTALLED: crate::kernels::parallel::Installed =
    crate::kernels::parallel::Installed(&REVERSE);
/// Held by every test that installs or removes the (process-wide) pool, so
/// one test's `set_workers(None)` never lands inside another's split call.
static POOL_LOCK: std::sync::Mutex<()> = std::sync::Mutex::new(());

fn pool_lock() -> std::sync::MutexGuard<'static, ()> {
    POOL_LOCK.lock().unwrap_or_else(|e| e.into_inner())
}

/// `linear` split over a pool's output-column ranges equals the one-thread
/// call bit for bit, for every weight type and path (int8 unpacked and
/// packed tiles, two int8 panels, the generic f32/f16/wide-Q4 path), with
/// output counts that are and are not multiples of the split alignment.
#[test]
fn split_gemm_matches_one_thread_bit_for_bit() {
    let _pool = pool_lock();
    use crate::kernels::parallel::{set_workers, split_count};
    // Other tests of this binary run while the pool is installed; they see
    // the same values (this is what the test shows), so only the
    // one-thread reference below needs the pool off, and nothing else
    // installs one.
    let mut r = Rng(2024);
    let wide = crate::kernels::linear::Q4_FAST_COLS + 64;
    for &(n, i, o) in &[
        (1usize, 768usize, 203usize),
        (5, 768, 203),
        (9, 256, 520),
        (3, 3072, 67),
        (50, 768, 96),
        (2, wide, 40),
    ] {
        let w = r.vec(o * i);
        let (q8, q4) = (q8_bytes(&w), q4_bytes(&w));
        let h: Vec<u16> = w
            .iter()
            .map(|&v| half::f16::from_f32(v).to_bits())
            .collect();
        let (x, b) = (r.vec(n * i), r.vec(o));
        for m in [
            Matrix::Q8(Q8Rows::new(&q8, o, i).unwrap()),
            Matrix::Q4(Q4Rows::new(&q4, o, i).unwrap()),
            Matrix::F16(F16Rows::new(&h, o, i).unwrap()),
            Matrix::F32(F32Rows::new(&w, o, i).unwrap()),
        ] {
            set_workers(None);
            let mut one = vec![f32::NAN; n * o];
            linear(&x, &m, Some(&b), &mut one);
            set_workers(Some(&REVERSE_INSTALLED));
            let jobs = reverse_jobs();
            let mut split = vec![f32::NAN; n * o];
            linear(&x, &m, Some(&b), &mut split);
            set_workers(None);
            assert!(
                reverse_jobs() > jobs,
                "({n},{i},{o}) {:?}: not split",
                m.rows()
            );
            for (k, (a, s)) in one.iter().zip(&split).enumerate() {
                assert_eq!(
                    a.to_bits(),
                    s.to_bits(),
                    "({n},{i},{o}) element {k}: one thread {a}, split {s}"
                );
            }
        }
    }
    // Too little work, or too few columns for two ranges: not split.
    set_workers(Some(&REVERSE_INSTALLED));
    let (small, narrow) = (split_count(512, 1024), split_count(15, 1 << 30));
    set_workers(None);
    assert_eq!((small, narrow), (1, 1));
}

/// `layernorm_row` (AVX2 / NEON) is bit-identical to its scalar twin at
/// every width 0..=70 and the model's 768 / 3072 (tails included, rows with
/// a large offset, where the mean matters), and the twin is within 1e-5 of
/// an f64 LayerNorm.
#[test]
#[allow(unsafe_code)]
fn layernorm_matches_scalar_twin_and_f64() {
    let mut r = Rng(777);
    for n in (0..=70).chain([768, 3072]) {
        for offset in [0.0f32, 40.0] {
            let x: std::vec::Vec<f32> = r.vec(n).iter().map(|v| 3.0 * v + offset).collect();
            let (w, b) = (r.vec(n), r.vec(n));
            let mut want = std::vec![f32::NAN; n];
            scalar::layernorm_row(&x, &w, &b, 1e-5, &mut want);
            if n > 1 {
                let mean = x.iter().map(|&v| v as f64).sum::<f64>() / n as f64;
                let var = x.iter().map(|&v| (v as f64 - mean).powi(2)).sum::<f64>() / n as f64;
                for i in 0..n {
                    let e = (x[i] as f64 - mean) / (var + 1e-5).sqrt() * w[i] as f64 + b[i] as f64;
                    assert!(
                        (want[i] as f64 - e).abs() <= 1e-5 * (1.0 + e.abs()),
                        "n={n} offset {offset} [{i}]: {} vs f64 {e}",
                        want[i]
                    );
                }
            }
            let mut got = std::vec![f32::NAN; n];
            #[cfg(target_arch = "x86_64")]
            if std::is_x86_feature_detected!("avx2") {
                // SAFETY: avx2 detected.
                unsafe { super::x86::layernorm_row(&x, &w, &b, 1e-5, &mut got) };
                assert_eq!(
                    got.iter()
                        .map(|v| v.to_bits())
                        .collect::<std::vec::Vec<_>>(),
                    want.iter()
                        .map(|v| v.to_bits())
                        .collect::<std::vec::Vec<_>>(),
                    "avx2 n={n}"
                );
            }
            #[cfg(all(target_arch = "aarch64", target_feature = "neon"))]
            {
                // SAFETY: NEON is enabled for this build.
                unsafe { super::neon::layernorm_row(&x, &w, &b, 1e-5, &mut got) };
                assert_eq!(
                    got.iter()
                        .map(|v| v.to_bits())
                        .collect::<std::vec::Vec<_>>(),
                    want.iter()
                        .map(|v| v.to_bits())
                        .collect::<std::vec::Vec<_>>(),
                    "neon n={n}"
                );
            }
            let _ = &mut got;
        }
    }
}

/// `split_cols` hands each task a disjoint range of output columns, cut at
/// multiples of `SPLIT_ALIGN`, that together cover every column of every
/// row exactly once (small enough for Miri).
#[test]
fn split_cols_ranges_cover_every_column_once() {
    let _pool = pool_lock();
    use crate::kernels::parallel::{set_workers, split_cols, SPLIT_ALIGN};
    for n_out in [16usize, 17, 40, 41, 64] {
        let rows = 3;
        let mut y = std::vec![0.0f32; rows * n_out];
        let ranges = std::sync::Mutex::new(std::vec::Vec::new());
        set_workers(Some(&REVERSE_INSTALLED));
        split_cols(&mut y, n_out, usize::MAX, |mut cols| {
            let (lo, hi) = (cols.lo(), cols.hi());
            ranges.lock().unwrap().push((lo, hi));
            for i in 0..rows {
                for v in cols.seg(i, lo, hi) {
                    *v += 1.0;
                }
            }
        });
        set_workers(None);
        let mut ranges = ranges.into_inner().unwrap();
        ranges.sort();
        assert!(ranges.len() >= 2, "{n_out} columns not split: {ranges:?}");
        assert_eq!(ranges[0].0, 0);
        assert_eq!(ranges.last().unwrap().1, n_out);
        for w in ranges.windows(2) {
            assert_eq!(
                w[0].1, w[1].0,
                "{n_out}: ranges {ranges:?} leave a gap or overlap"
            );
        }
        assert!(
            ranges
                .iter()
                .all(|&(lo, hi)| lo % SPLIT_ALIGN == 0 && lo < hi),
            "{n_out}: {ranges:?}"
        );
        assert!(
            y.iter().all(|&v| v == 1.0),
            "{n_out}: some column written other than once: {y:?}"
        );
    }
}

/// `attention` split over a pool's query ranges equals the one-thread call
/// bit for bit (band and tiled-causal masks, a mask of many runs that takes
/// the key-by-key path, and more keys than a split takes).
#[test]
fn split_attention_matches_one_thread_bit_for_bit() {
    let _pool = pool_lock();
    use crate::kernels::parallel::set_workers;
    use crate::kernels::{attention, BandMask, Mask, TiledCausalMask};
    /// Every other key (more runs than a query remembers).
    struct Comb;
    impl Mask for Comb {
        fn allowed(&self, _: usize, kj: usize) -> bool {
            kj % 2 == 0
        }
    }
    fn run(
        m: &dyn Fn(&[f32], &[f32], &[f32], &mut [f32], &mut [f32]),
        nq: usize,
        nk: usize,
        c: usize,
        r: &mut Rng,
        split_expected: bool,
    ) {
        let (q, k, v) = (r.vec(nq * c), r.vec(nk * c), r.vec(nk * c));
        let mut scores = std::vec![0.0f32; nk];
        set_workers(None);
        let mut one = std::vec![f32::NAN; nq * c];
        m(&q, &k, &v, &mut scores, &mut one);
        set_workers(Some(&REVERSE_INSTALLED));
        let jobs = reverse_jobs();
        let mut split = std::vec![f32::NAN; nq * c];
        m(&q, &k, &v, &mut scores, &mut split);
        set_workers(None);
        assert_eq!(
            reverse_jobs() > jobs,
            split_expected,
            "({nq},{nk},{c}): split or not"
        );
        for (i, (a, b)) in one.iter().zip(&split).enumerate() {
            assert_eq!(
                a.to_bits(),
                b.to_bits(),
                "({nq},{nk},{c}) element {i}: {a} vs {b}"
            );
        }
    }
    let mut r = Rng(31);
    let (c, nh) = (64usize, 4usize);
    let band = BandMask {
        radius: 9,
        q_pos0: 3,
        k_pos0: 0,
    };
    run(
        &|q, k, v, s, o| attention(q, k, v, c, nh, &band, s, o),
        40,
        60,
        c,
        &mut r,
        true,
    );
    let tiled = TiledCausalMask {
        t_q: 6,
        t_k: 30,
        q_pos0: 20,
    };
    run(
        &|q, k, v, s, o| attention(q, k, v, c, nh, &tiled, s, o),
        30,
        150,
        c,
        &mut r,
        true,
    );
    run(
        &|q, k, v, s, o| attention(q, k, v, c, nh, &Comb, s, o),
        12,
        200,
        c,
        &mut r,
        true,
    );
    let wide = crate::kernels::attention::SPLIT_MAX_KEYS + 8;
    run(
        &|q, k, v, s, o| attention(q, k, v, c, nh, &band, s, o),
        9,
        wide,
        c,
        &mut r,
        false,
    );
}

/// The f16 K/V readers (`dot_rows_f16`, `axpy_f16`) of every variant this
/// CPU runs equal the same variant's f32 kernel on the exactly widened rows,
/// bit for bit (an f16 cache read in place computes what widening it first
/// computed), and track the scalar twin within the f32 kernels' limits.
#[test]
#[allow(unsafe_code)]
fn f16_row_readers_equal_f32_kernels_on_widened_rows() {
    /// (variant, f16 reader, f32 kernel of the same variant).
    ///
    /// # Safety
    /// Both kernels need the variant's CPU features (pushed only where detected).
    type DotRows = (
        &'static str,
        unsafe fn(&[f32], &[u16], usize, &mut [f32]),
        unsafe fn(&[f32], &[f32], usize, &mut [f32]),
    );
    /// (variant, f16 axpy, f32 axpy of the same variant).
    ///
    /// # Safety
    /// As for `DotRows`.
    type Axpy = (
        &'static str,
        unsafe fn(f32, &[u16], &mut [f32]),
        unsafe fn(f32, &[f32], &mut [f32]),
    );
    let mut dots: Vec<DotRows> = vec![(
        "scalar",
        |q, k, s, o| scalar::dot_rows_f16(q, k, s, o),
        |q, k, s, o| scalar::dot_rows(q, k, s, o),
    )];
    let mut axpys: Vec<Axpy> = vec![(
        "scalar",
        |a, w, y| scalar::axpy_f16(a, w, y),
        |a, x, y| scalar::axpy_f32(a, x, y),
    )];
    #[cfg(target_arch = "x86_64")]
    {
        use std::is_x86_feature_detected as has;
        if has!("avx2") && has!("fma") && has!("f16c") {
            dots.push(("avx2", super::x86::dot_rows_f16, super::x86::dot_rows));
            axpys.push(("avx2", super::x86::axpy_f16, super::x86::axpy_f32));
        }
        if has!("avx512f")
            && has!("avx512bw")
            && has!("avx512vl")
            && has!("avx2")
            && has!("fma")
            && has!("f16c")
        {
            dots.push((
                "avx512",
                super::x86::dot_rows_512_f16,
                super::x86::dot_rows_512,
            ));
        }
    }
    #[cfg(all(target_arch = "aarch64", target_feature = "neon"))]
    {
        dots.push(("neon", super::neon::dot_rows_f16, super::neon::dot_rows));
        axpys.push(("neon", super::neon::axpy_f16, super::neon::axpy_f32));
    }
    let mut r = Rng(41);
    let h = |v: &[f32]| -> Vec<u16> {
        v.iter()
            .map(|&x| half::f16::from_f32(x).to_bits())
            .collect()
    };
    let widen = |v: &[u16]| -> Vec<f32> { v.iter().map(|&b| super::f16_to_f32(b)).collect() };
    for hd in [1, 3, 4, 7, 15, 16, 17, 33, 48, 63, 64, 65, 96] {
        let stride = hd + 3;
        let q = r.vec(hd);
        let k16 = h(&r.vec(9 * stride + hd));
        let kw = widen(&k16);
        for n in 0..=10 {
            let mut twin = vec![0f32; n];
            scalar::dot_rows_f16(&q, &k16, stride, &mut twin);
            for &(name, f16k, f32k) in &dots {
                let (mut a, mut b) = (vec![0f32; n], vec![0f32; n]);
                // SAFETY: each variant was pushed only where its CPU features were detected.
                unsafe { f16k(&q, &k16, stride, &mut a) };
                // SAFETY: as above.
                unsafe { f32k(&q, &kw, stride, &mut b) };
                for j in 0..n {
                    assert_eq!(
                        a[j].to_bits(),
                        b[j].to_bits(),
                        "{name} dot_rows_f16 hd={hd} j={j}: {} vs {}",
                        a[j],
                        b[j]
                    );
                    let s: f64 = q
                        .iter()
                        .zip(&kw[j * stride..])
                        .map(|(x, y)| (*x as f64 * *y as f64).abs())
                        .sum();
                    check(
                        &format!("{name} dot_rows_f16 vs twin hd={hd} j={j}"),
                        a[j],
                        twin[j],
                        s,
                        SIMD_VS_SCALAR_TILE_512,
                    );
                }
            }
        }
    }
    for n in (0..=20).chain([63, 64, 65, 512, 1001]) {
        let w16 = h(&r.vec(n));
        let ww = widen(&w16);
        let (y0, a) = (r.vec(n), r.f());
        for &(name, f16k, f32k) in &axpys {
            let (mut g, mut want) = (y0.clone(), y0.clone());
            // SAFETY: as above.
            unsafe { f16k(a, &w16, &mut g) };
            // SAFETY: as above.
            unsafe { f32k(a, &ww, &mut want) };
            for i in 0..n {
                assert_eq!(
                    g[i].to_bits(),
                    want[i].to_bits(),
                    "{name} axpy_f16 n={n} i={i}"
                );
            }
        }
    }
}

/// `attention` over key/value rows given as two runs (a ring's wrap) or
/// head-major (a GPT cache), in f32 or f16, equals the call on one
/// contiguous f32 copy bit for bit, for
/// every split point (band, tiled-causal and many-run masks; the values
/// are f16-exact so the f16 storage holds the same numbers), and so does
/// `attention_ahead` with bytes to prefetch meanwhile.
#[test]
fn attention_over_split_and_f16_rows_equals_contiguous() {
    use crate::kernels::{
        attention, attention_ahead, BandMask, KvRows, Mask, RowData, TiledCausalMask,
    };
    struct Comb;
    impl Mask for Comb {
        fn allowed(&self, _: usize, kj: usize) -> bool {
            kj % 2 == 0
        }
    }
    let mut r = Rng(43);
    let (c, nh) = (96usize, 3usize);
    let round = |v: Vec<f32>| -> Vec<f32> {
        v.into_iter()
            .map(|x| half::f16::from_f32(x).to_f32())
            .collect()
    };
    let check_mask = |m: &dyn Fn(&[f32], KvRows<'_>, KvRows<'_>, &mut [f32], &mut [f32]),
                      nq: usize,
                      nk: usize,
                      r: &mut Rng| {
        let (q, k, v) = (r.vec(nq * c), round(r.vec(nk * c)), round(r.vec(nk * c)));
        let (k16, v16): (Vec<u16>, Vec<u16>) = (
            k.iter()
                .map(|&x| half::f16::from_f32(x).to_bits())
                .collect(),
            v.iter()
                .map(|&x| half::f16::from_f32(x).to_bits())
                .collect(),
        );
        let mut scores = vec![0f32; nk];
        let mut want = vec![f32::NAN; nq * c];
        m(
            &q,
            KvRows::from(&k[..]),
            KvRows::from(&v[..]),
            &mut scores,
            &mut want,
        );
        // Head-major copies (a session's GPT cache): 3 rows of room beyond
        // the visible ones, NaN, so a misread row shows; the run ends at the
        // last head's last visible row.
        let (hd, cap) = (c / nh, nk + 3);
        let head_major = |src: &[f32]| -> Vec<f32> {
            let mut d = vec![f32::NAN; nh * cap * hd];
            for j in 0..nk {
                for h in 0..nh {
                    d[(h * cap + j) * hd..][..hd].copy_from_slice(&src[j * c + h * hd..][..hd]);
                }
            }
            d.truncate(((nh - 1) * cap + nk) * hd);
            d
        };
        let (kh, vh) = (head_major(&k), head_major(&v));
        let bits16 = |d: &[f32]| -> Vec<u16> {
            d.iter()
                .map(|&x| half::f16::from_f32(x).to_bits())
                .collect()
        };
        let (kh16, vh16) = (bits16(&kh), bits16(&vh));
        let hm = |d| KvRows::head_major(d, nk, cap, hd).unwrap();
        assert_eq!(
            hm(RowData::F32(&kh)).rows(c + hd),
            0,
            "a width of more heads than held has no rows"
        );
        assert_eq!(
            hm(RowData::F32(&kh[..kh.len() - 1])).rows(c),
            0,
            "a short run has no rows"
        );
        assert!(
            KvRows::head_major(RowData::F32(&kh), cap + 1, cap, hd).is_none()
                && KvRows::head_major(RowData::F32(&kh), nk, cap, 0).is_none()
        );
        // Head-major copies of the first `split` rows alone (NaN beyond), per split.
        let splits = [0, 1, nk / 3, nk / 2, nk - 1, nk];
        let head_major_first = |src: &[f32], split: usize| -> Vec<f32> {
            let mut d = head_major(src);
            for h in 0..nh {
                for j in split..nk {
                    if let Some(x) = d.get_mut((h * cap + j) * hd..(h * cap + j + 1) * hd) {
                        x.fill(f32::NAN);
                    }
                }
            }
            d
        };
        let (mut hk, mut hv) = (vec![Vec::new(); nk + 1], vec![Vec::new(); nk + 1]);
        let (mut hk16, mut hv16) = (vec![Vec::new(); nk + 1], vec![Vec::new(); nk + 1]);
        for &sp in &splits {
            hk[sp] = head_major_first(&k, sp);
            hv[sp] = head_major_first(&v, sp);
            hk16[sp] = bits16(&hk[sp]);
            hv16[sp] = bits16(&hv[sp]);
        }
        for split in splits {
            let cut = split * c;
            let hmt = |d, tail| KvRows::head_major_then(d, split, cap, hd, tail).unwrap();
            let cases = [
                (
                    "f32 two runs",
                    KvRows::two(RowData::F32(&k[..cut]), RowData::F32(&k[cut..])),
                    KvRows::two(RowData::F32(&v[..cut]), RowData::F32(&v[cut..])),
                ),
                (
                    "f16 two runs",
                    KvRows::two(RowData::F16(&k16[..cut]), RowData::F16(&k16[cut..])),
                    KvRows::two(RowData::F16(&v16[..cut]), RowData::F16(&v16[cut..])),
                ),
                (
                    "f16 one run",
                    KvRows::one(RowData::F16(&k16)),
                    KvRows::one(RowData::F16(&v16)),
                ),
                (
                    "f32 head-major",
                    hm(RowData::F32(&kh)),
                    hm(RowData::F32(&vh)),
                ),
                (
                    "f16 head-major",
                    hm(RowData::F16(&kh16)),
                    hm(RowData::F16(&vh16)),
                ),
                // The first `split` rows head-major, the rest row-major after them (a GPT cache and its newest rows).
                (
                    "f16 head-major then f16 rows",
                    hmt(RowData::F16(&hk16[split]), RowData::F16(&k16[cut..])),
                    hmt(RowData::F16(&hv16[split]), RowData::F16(&v16[cut..])),
                ),
                (
                    "f16 head-major then f32 rows",
                    hmt(RowData::F16(&hk16[split]), RowData::F32(&k[cut..])),
                    hmt(RowData::F16(&hv16[split]), RowData::F32(&v[cut..])),
                ),
                (
                    "f32 head-major then f32 rows",
                    hmt(RowData::F32(&hk[split]), RowData::F32(&k[cut..])),
                    hmt(RowData::F32(&hv[split]), RowData::F32(&v[cut..])),
                ),
            ];
            // Three runs: a wrapped ring's two runs (the first `split` rows
            // cut in two), then the newest rows kept apart as f32 (a LAT's
            // ring and its push's rows: `KvRows::then`).
            let half = (split / 2) * c;
            fn three<'x>(a: RowData<'x>, b: RowData<'x>, t: &'x [f32]) -> KvRows<'x> {
                KvRows::two(a, b).then(RowData::F32(t)).unwrap()
            }
            let ring_then = [
                (
                    "f16 ring (two runs) then f32 rows",
                    three(RowData::F16(&k16[..half]), RowData::F16(&k16[half..cut]), &k[cut..]),
                    three(RowData::F16(&v16[..half]), RowData::F16(&v16[half..cut]), &v[cut..]),
                ),
                (
                    "f32 ring (two runs) then f32 rows",
                    three(RowData::F32(&k[..half]), RowData::F32(&k[half..cut]), &k[cut..]),
                    three(RowData::F32(&v[..half]), RowData::F32(&v[half..cut]), &v[cut..]),
                ),
                (
                    "f16 ring (one run) then f32 rows",
                    KvRows::one(RowData::F16(&k16[..cut]))
                        .then(RowData::F32(&k[cut..]))
                        .unwrap(),
                    KvRows::one(RowData::F16(&v16[..cut]))
                        .then(RowData::F32(&v[cut..]))
                        .unwrap(),
                ),
            ];
            if half > 0 && cut < k.len() {
                assert!(
                    ring_then[0].1.then(RowData::F32(&k[cut..])).is_none(),
                    "a fourth run is refused"
                );
            }
            for (name, kr, vr) in cases.into_iter().chain(ring_then) {
                assert_eq!(kr.rows(c), nk);
                let mut got = vec![f32::NAN; nq * c];
                m(&q, kr, vr, &mut scores, &mut got);
                for (i, (a, b)) in got.iter().zip(&want).enumerate() {
                    assert_eq!(
                        a.to_bits(),
                        b.to_bits(),
                        "{name} split {split} ({nq}x{nk}) element {i}: {a} vs {b}"
                    );
                }
            }
        }
    };
    let band = BandMask {
        radius: 7,
        q_pos0: 5,
        k_pos0: 0,
    };
    check_mask(
        &|q, k, v, s, o| attention(q, k, v, c, nh, &band, s, o),
        12,
        25,
        &mut r,
    );
    let tiled = TiledCausalMask {
        t_q: 3,
        t_k: 8,
        q_pos0: 4,
    };
    check_mask(
        &|q, k, v, s, o| attention(q, k, v, c, nh, &tiled, s, o),
        9,
        40,
        &mut r,
    );
    check_mask(
        &|q, k, v, s, o| attention(q, k, v, c, nh, &Comb, s, o),
        2,
        150,
        &mut r,
    );
    // The same with other rows prefetched meanwhile (`attention_ahead`: the
    // next session's keys and values in a batch): no number changes.
    let (ka, va) = (vec![3u8; 5000], vec![5u8; 70]);
    let (nq, nk) = (10usize, 40usize);
    let (q, k, v) = (r.vec(nq * c), r.vec(nk * c), r.vec(nk * c));
    let k16: Vec<u16> = k
        .iter()
        .map(|&x| half::f16::from_f32(x).to_bits())
        .collect();
    let v16: Vec<u16> = v
        .iter()
        .map(|&x| half::f16::from_f32(x).to_bits())
        .collect();
    let append = TiledCausalMask {
        t_q: 1,
        t_k: 4,
        q_pos0: 3,
    };
    let mut scores = vec![0f32; nk];
    for (kr, vr) in [
        (KvRows::from(&k[..]), KvRows::from(&v[..])),
        (
            KvRows::one(RowData::F16(&k16)),
            KvRows::one(RowData::F16(&v16)),
        ),
    ] {
        /// One attention call given what it prefetches (keys, values).
        type Attend<'x> = &'x dyn Fn(&[u8], &[u8], &mut [f32], &mut [f32]);
        let masks: [Attend<'_>; 3] = [
            &|a, b, s, o| attention_ahead(&q, kr, vr, c, nh, &band, s, o, [a, b]),
            &|a, b, s, o| attention_ahead(&q, kr, vr, c, nh, &append, s, o, [a, b]),
            &|a, b, s, o| attention_ahead(&q, kr, vr, c, nh, &Comb, s, o, [a, b]),
        ];
        for m in masks {
            let mut want = vec![f32::NAN; nq * c];
            m(&[], &[], &mut scores, &mut want);
            for (a, b) in [(&ka[..], &va[..]), (&[][..], &ka[..]), (&va[..], &[][..])] {
                let mut got = vec![f32::NAN; nq * c];
                m(a, b, &mut scores, &mut got);
                assert!(
                    got.iter()
                        .zip(&want)
                        .all(|(x, y)| x.to_bits() == y.to_bits()),
                    "attention_ahead changed a number"
                );
            }
        }
    }
}

/// A 4-bit row group (`PackedQ8::from_q4_group`: each row's two 8-byte
/// halves of nibbles side by side, then the scales) holds the values of the
/// Q8 expansion of its rows, and the packed tile (dispatched, scalar twin,
/// and AVX512-VNNI where the CPU has it, whose nibbles enter `vpdpbusd` as
/// stored with the correction shifted to `-8 sum(q)`) computes exactly
/// what it computes on the packed expansion: the i32 lane sums are equal.
/// A packed kernel's 8 x 8 outputs against the scalar twin's, within the
/// int8 GEMM limit of the block sums' magnitude (`rows`: the weight rows
/// as Q8Block32 rows; `qs`, `ds`: the quantised activation rows).
#[allow(dead_code)]
fn check_packed_rows(
    name: &str,
    got: [[f32; 8]; 8],
    twin: [[f32; 8]; 8],
    rows: &[Vec<u8>],
    qs: &[Vec<i8>],
    ds: &[Vec<f32>],
    nb: usize,
) {
    for m in 0..8 {
        for j in 0..8 {
            let s: f64 = (0..nb)
                .map(|b| {
                    let blk = &rows[j][b * Q8_BLOCK_BYTES..(b + 1) * Q8_BLOCK_BYTES];
                    let ws = super::f16_to_f32(u16::from_le_bytes([blk[0], blk[1]])) as f64;
                    let a: i64 = blk[2..]
                        .iter()
                        .zip(&qs[m][b * 32..(b + 1) * 32])
                        .map(|(&w, &x)| ((w as i8 as i64) * x as i64).abs())
                        .sum();
                    (ws * ds[m][b] as f64).abs() * a as f64
                })
                .sum();
            check(
                &format!("{name} nb={nb} [{m}][{j}]"),
                got[m][j],
                twin[m][j],
                s,
                SIMD_VS_SCALAR_GEMM_Q8,
            );
        }
    }
}

#[test]
#[allow(unsafe_code)]
fn q4_groups_match_their_q8_expansion_in_the_packed_tile() {
    use super::{PackedQ8, Q8Pack8, PACK_ROWS};
    let mut r = Rng(0x4444);
    for nb in [1usize, 2, 3, 24, 96, 130] {
        let n = nb * Q8_BLOCK;
        let rows4: Vec<Vec<u8>> = (0..PACK_ROWS).map(|_| q4_bytes(&r.vec(n))).collect();
        let group = q4_group(&rows4, nb);
        let g = PackedQ8::from_q4_group(&group, nb).unwrap();
        assert!(PackedQ8::from_q4_group(&group[..group.len() - 1], nb).is_none());
        let rows8: Vec<Vec<u8>> = rows4
            .iter()
            .map(|q4| {
                let mut q8 = vec![0u8; nb * Q8_BLOCK_BYTES];
                expand_q4(q4, &mut q8);
                q8
            })
            .collect();
        for (j, q8) in rows8.iter().enumerate() {
            for b in 0..nb {
                let blk = &q8[b * Q8_BLOCK_BYTES..(b + 1) * Q8_BLOCK_BYTES];
                assert_eq!(g.scale_bits(b, j), u16::from_le_bytes([blk[0], blk[1]]));
                assert!(
                    (0..Q8_BLOCK).all(|i| g.value(b, j, i) == blk[2 + i] as i8),
                    "nb={nb} row {j} block {b}"
                );
            }
        }
        let mut qs = vec![vec![0i8; n]; 8];
        let mut ds = vec![vec![0f32; nb]; 8];
        let mut cs = vec![vec![0i32; 2 * nb]; 8];
        for m in 0..8 {
            scalar::quantise_q8_corr(&r.vec(n), &mut qs[m], &mut ds[m], &mut cs[m]);
        }
        let q: [&[i8]; 8] = core::array::from_fn(|m| &qs[m][..]);
        let d: [&[f32]; 8] = core::array::from_fn(|m| &ds[m][..]);
        let c: [&[i32]; 8] = core::array::from_fn(|m| &cs[m][..]);
        let bits = |t: [[f32; 8]; 8]| t.map(|row| row.map(f32::to_bits));
        let twin = scalar::gemm_q8_packed::<8>(g, q, d, c);
        if nb <= super::PACK_BLOCKS {
            let mut pack = Q8Pack8::new();
            super::q8_pack8(core::array::from_fn(|j| &rows8[j][..]), nb, &mut pack);
            assert_eq!(
                bits(twin),
                bits(scalar::gemm_q8_packed::<8>(pack.view(), q, d, c)),
                "scalar twin nb={nb}"
            );
            assert_eq!(
                bits(super::gemm_q8_packed::<8>(g, q, d, c)),
                bits(super::gemm_q8_packed::<8>(pack.view(), q, d, c)),
                "dispatched nb={nb}"
            );
            #[cfg(target_arch = "x86_64")]
            {
                use std::is_x86_feature_detected as has;
                if has!("avx512f")
                    && has!("avx512bw")
                    && has!("avx512dq")
                    && has!("avx512vl")
                    && has!("avx512vnni")
                    && has!("avx2")
                    && has!("fma")
                    && has!("f16c")
                {
                    // SAFETY: every feature of the kernel detected above.
                    let (a, b) = unsafe {
                        (
                            super::x86::gemm_q8_packed_vnni::<8>(g, q, d, c),
                            super::x86::gemm_q8_packed_vnni::<8>(pack.view(), q, d, c),
                        )
                    };
                    assert_eq!(
                        bits(a),
                        bits(b),
                        "avx512vnni q4 group vs packed expansion nb={nb}"
                    );
                    // SAFETY: as above.
                    let a3 = unsafe {
                        super::x86::gemm_q8_packed_vnni::<3>(
                            g,
                            [q[1], q[2], q[7]],
                            [d[1], d[2], d[7]],
                            [c[1], c[2], c[7]],
                        )
                    };
                    assert_eq!(
                        a3.map(|row| row.map(f32::to_bits)),
                        [1, 2, 7].map(|m| bits(a)[m]),
                        "M = 3 rows equal their rows of M = 8"
                    );
                }
                if has!("avx2") && has!("fma") && has!("f16c") {
                    // SAFETY: every feature of the kernel detected above.
                    let (a, b) = unsafe {
                        (
                            super::x86::gemm_q8_packed_avx2::<8>(g, q, d, c),
                            super::x86::gemm_q8_packed_avx2::<8>(pack.view(), q, d, c),
                        )
                    };
                    assert_eq!(
                        bits(a),
                        bits(b),
                        "avx2 q4 group vs packed expansion nb={nb}"
                    );
                    check_packed_rows("avx2 q4", a, twin, &rows8, &qs, &ds, nb);
                    // SAFETY: as above.
                    let a3 = unsafe {
                        super::x86::gemm_q8_packed_avx2::<3>(
                            g,
                            [q[1], q[2], q[7]],
                            [d[1], d[2], d[7]],
                            [c[1], c[2], c[7]],
                        )
                    };
                    assert_eq!(
                        a3.map(|row| row.map(f32::to_bits)),
                        [1, 2, 7].map(|m| bits(a)[m]),
                        "avx2 M = 3 rows equal their rows of M = 8"
                    );
                }
                if has!("avx2") && has!("fma") && has!("f16c") && has!("avxvnni") {
                    // SAFETY: every feature of the kernels detected above.
                    let (a, b, v) = unsafe {
                        (
                            super::x86::gemm_q8_packed_avxvnni::<8>(g, q, d, c),
                            super::x86::gemm_q8_packed_avxvnni::<8>(pack.view(), q, d, c),
                            super::x86::gemm_q8_packed_avx2::<8>(g, q, d, c),
                        )
                    };
                    assert_eq!(
                        bits(a),
                        bits(b),
                        "avxvnni q4 group vs packed expansion nb={nb}"
                    );
                    assert_eq!(bits(a), bits(v), "avxvnni q4 = avx2 q4 bit for bit nb={nb}");
                    check_packed_rows("avxvnni q4", a, twin, &rows8, &qs, &ds, nb);
                }
            }
            #[cfg(target_arch = "aarch64")]
            for (name, i8mm) in [("neondot q4", false), ("neoni8mm q4", true)] {
                use std::arch::is_aarch64_feature_detected as has;
                if !has!("dotprod") || (i8mm && !has!("i8mm")) {
                    continue;
                }
                // SAFETY: neon (baseline), dotprod and (where used) i8mm detected.
                let (a, b, dot) = unsafe {
                    (
                        packed_rows_dot(g, &q, &d, &c, i8mm),
                        packed_rows_dot(pack.view(), &q, &d, &c, i8mm),
                        super::neon::gemm_q8_packed_dot::<8>(g, q, d, c),
                    )
                };
                let a: [[f32; 8]; 8] = a.try_into().unwrap();
                let b: [[f32; 8]; 8] = b.try_into().unwrap();
                assert_eq!(bits(a), bits(b), "{name} group vs packed expansion nb={nb}");
                assert_eq!(
                    bits(a),
                    bits(dot),
                    "{name} = neondot q4 bit for bit nb={nb}"
                );
                check_packed_rows(name, a, twin, &rows8, &qs, &ds, nb);
            }
        }
    }
}

/// `axpy_rows_f32` / `axpy_rows_f16` of every variant this CPU runs equal
/// the same variant's `axpy` called row after row, bit for bit (the
/// attention's values computed in one call per run give what the per-key
/// calls gave), leave out rows that are not whole, and track the scalar
/// twin within `SIMD_VS_SCALAR_AXPY` per row.
#[test]
#[allow(unsafe_code)]
fn axpy_rows_equal_axpy_row_after_row() {
    /// (variant, rows kernel, axpy of the same variant).
    ///
    /// # Safety
    /// Both kernels need the variant's CPU features (pushed only where detected).
    type Rows32 = (
        &'static str,
        unsafe fn(&[f32], &[f32], usize, &mut [f32]),
        unsafe fn(f32, &[f32], &mut [f32]),
    );
    /// As `Rows32`, binary16 rows.
    ///
    /// # Safety
    /// As for `Rows32`.
    type Rows16 = (
        &'static str,
        unsafe fn(&[f32], &[u16], usize, &mut [f32]),
        unsafe fn(f32, &[u16], &mut [f32]),
    );
    let mut v32: Vec<Rows32> = vec![(
        "scalar",
        |c, x, s, y| scalar::axpy_rows_f32(c, x, s, y),
        |a, x, y| scalar::axpy_f32(a, x, y),
    )];
    let mut v16: Vec<Rows16> = vec![(
        "scalar",
        |c, x, s, y| scalar::axpy_rows_f16(c, x, s, y),
        |a, x, y| scalar::axpy_f16(a, x, y),
    )];
    v32.push((
        "dispatched",
        |c, x, s, y| super::axpy_rows_f32(c, x, s, y),
        |a, x, y| super::axpy_f32(a, x, y),
    ));
    v16.push((
        "dispatched",
        |c, x, s, y| super::axpy_rows_f16(c, x, s, y),
        |a, x, y| super::axpy_f16(a, x, y),
    ));
    #[cfg(target_arch = "x86_64")]
    {
        use std::is_x86_feature_detected as has;
        if has!("avx2") && has!("fma") && has!("f16c") {
            v32.push(("avx2", super::x86::axpy_rows_f32, super::x86::axpy_f32));
            v16.push(("avx2", super::x86::axpy_rows_f16, super::x86::axpy_f16));
            if has!("avx512f") {
                v32.push((
                    "avx512",
                    super::x86::axpy_rows_512_f32,
                    super::x86::axpy_f32,
                ));
                v16.push((
                    "avx512",
                    super::x86::axpy_rows_512_f16,
                    super::x86::axpy_f16,
                ));
            }
        }
    }
    #[cfg(all(target_arch = "aarch64", target_feature = "neon"))]
    {
        v32.push(("neon", super::neon::axpy_rows_f32, super::neon::axpy_f32));
        v16.push(("neon", super::neon::axpy_rows_f16, super::neon::axpy_f16));
    }
    let mut r = Rng(53);
    for n in [0, 1, 3, 4, 7, 8, 9, 15, 16, 33, 63, 64, 65, 72, 130, 200] {
        for nk in [0, 1, 2, 5, 31, 300] {
            let stride = n + 5;
            let x = r.vec(nk * stride + 2);
            let x16: Vec<u16> = x
                .iter()
                .map(|&v| half::f16::from_f32(v).to_bits())
                .collect();
            // Exactly nk whole rows; one more coefficient than rows: it is left out.
            let len = if nk == 0 { 0 } else { (nk - 1) * stride + n };
            let coef: Vec<f32> = (0..nk + 1).map(|_| r.f() * 0.1).collect();
            let y0 = r.vec(n);
            let mut twin = y0.clone();
            scalar::axpy_rows_f32(&coef, &x[..len], stride, &mut twin);
            for &(name, rows, axpy) in &v32 {
                let (mut got, mut want) = (y0.clone(), y0.clone());
                // SAFETY: each variant was pushed only where its CPU features were detected.
                unsafe { rows(&coef, &x[..len], stride, &mut got) };
                for j in 0..nk {
                    // SAFETY: as above.
                    unsafe { axpy(coef[j], &x[j * stride..j * stride + n], &mut want) };
                }
                for i in 0..n {
                    assert_eq!(
                        got[i].to_bits(),
                        want[i].to_bits(),
                        "{name} axpy_rows_f32 n={n} nk={nk} lane {i}: {} vs {}",
                        got[i],
                        want[i]
                    );
                    let s = y0[i].abs() as f64
                        + (0..nk)
                            .map(|j| (coef[j] * x[j * stride + i]).abs() as f64)
                            .sum::<f64>();
                    check(
                        &format!("{name} axpy_rows_f32 vs twin n={n} nk={nk}"),
                        got[i],
                        twin[i],
                        s,
                        SIMD_VS_SCALAR_AXPY * nk.max(1) as f64,
                    );
                }
            }
            let mut twin = y0.clone();
            scalar::axpy_rows_f16(&coef, &x16[..len], stride, &mut twin);
            for &(name, rows, axpy) in &v16 {
                let (mut got, mut want) = (y0.clone(), y0.clone());
                // SAFETY: as above.
                unsafe { rows(&coef, &x16[..len], stride, &mut got) };
                for j in 0..nk {
                    // SAFETY: as above.
                    unsafe { axpy(coef[j], &x16[j * stride..j * stride + n], &mut want) };
                }
                for i in 0..n {
                    assert_eq!(
                        got[i].to_bits(),
                        want[i].to_bits(),
                        "{name} axpy_rows_f16 n={n} nk={nk} lane {i}"
                    );
                    let s = y0[i].abs() as f64
                        + (0..nk)
                            .map(|j| {
                                (coef[j] * super::f16_to_f32(x16[j * stride + i])).abs() as f64
                            })
                            .sum::<f64>();
                    check(
                        &format!("{name} axpy_rows_f16 vs twin n={n} nk={nk}"),
                        got[i],
                        twin[i],
                        s,
                        SIMD_VS_SCALAR_AXPY * nk.max(1) as f64,
                    );
                }
            }
        }
    }
}

/// The AMX tile kernel (where this CPU has AMX-INT8 and Linux grants the
/// tile permission) equals the AVX512-VNNI packed kernel bit for bit, row
/// for row and tile for tile, on pairs of int8 and 4-bit tiles (stored, and
/// packed on the stack), for 7-64 activation rows in groups of 12 and 8
/// (at most 3 trailing rows, or fewer than 8, are left to the caller), odd and even block counts, and
/// tracks the scalar twin like the VNNI kernel does; it refuses short
/// operands, tiles of different widths and tiles wider than `PACK_BLOCKS`
/// instead of reading past them.
#[cfg(all(target_arch = "x86_64", target_os = "linux"))]
#[test]
#[allow(unsafe_code)]
fn amx_tiles_equal_the_vnni_kernel_bit_for_bit() {
    use super::amx;
    use super::tile_pair::TilePair;
    use super::{PackedQ8, PACK_BLOCKS};
    use crate::kernels::parallel::Cols;
    let vnni = cpu_runs_avx512_vnni();
    // SAFETY (whole test): the AMX calls run only where the CPU reports
    // amx-tile and amx-int8 and Linux granted the tile permission, plus
    // every VNNI feature detected above; the VNNI kernel only where `vnni`.
    let tiles = vnni && amx::cpu_has_amx_int8() && amx::request_linux_permission();
    if !tiles {
        eprintln!("skipped: this CPU or OS does not run AMX-INT8 tiles");
        return;
    }
    let mut r = Rng(0xa3a3);
    for nb in [1usize, 2, 3, 24, 95, 96] {
        let n = nb * Q8_BLOCK;
        for q4 in [false, true] {
            let two = TwoTiles::new(&mut r, nb, q4);
            let (rows, tile) = (&two.rows, two.tiles());
            let mut w = TilePair::new();
            for (t, tl) in tile.iter().enumerate() {
                assert!(unsafe { w.prepare_raw(t, *tl, false) }, "nb={nb}");
            }
            let m_rows = 64;
            let (qs, ds, cs) = q8_panel(&mut r, m_rows, nb, 17);
            let row = |m: usize| {
                (
                    &qs[m * n..(m + 1) * n],
                    &ds[m * nb..(m + 1) * nb],
                    &cs[m * 2 * nb..(m + 1) * 2 * nb],
                )
            };
            // The epilogues: none, a bias, a bias and GELU, GELU alone; over
            // 16 columns, and over 11 (the second tile partly outside the matrix).
            let bias = r.vec(amx::COLS);
            let epilogues: [(Option<&[f32]>, bool, usize); 4] = [
                (None, false, 16),
                (Some(&bias), false, 11),
                (Some(&bias), true, 16),
                (None, true, 11),
            ];
            // The window sits at columns 2.. of rows 20 wide; the rest must stay untouched.
            const W: usize = 20;
            const SENTINEL: f32 = -7.5;
            // (rows given, rows done: whole groups of 12 and 8).
            for (want_rows, want_done) in [
                (7usize, 0usize),
                (8, 8),
                (12, 12),
                (15, 12),
                (16, 16),
                (20, 20),
                (28, 28),
                (40, 40),
                (63, 60),
                (64, 64),
            ] {
                assert_eq!(
                    amx::amx_rows(nb, qs.len(), n, ds.len(), want_rows),
                    want_done
                );
                for &(b, gelu, cols) in &epilogues {
                    let mut buf = vec![SENTINEL; want_rows * W];
                    let done = unsafe {
                        amx::gemm_q8_packed_amx_raw(
                            &w,
                            &qs,
                            n,
                            &ds,
                            Cols::whole(&mut buf, W).window(0, want_rows, 2, 2 + cols),
                            b,
                            gelu,
                            rows[0][0].as_slice(),
                        )
                    };
                    assert_eq!(done, want_done, "whole groups of 12 and 8 rows only");
                    for (k, v) in buf.iter().enumerate() {
                        let (m, j) = (k / W, k % W);
                        if m >= done || j < 2 || j >= 2 + cols {
                            assert_eq!(
                                v.to_bits(),
                                SENTINEL.to_bits(),
                                "written outside the window: row {m} column {j}"
                            );
                        }
                    }
                    for m0 in (0..done).step_by(8) {
                        for (t, tl) in tile.iter().enumerate() {
                            let v = unsafe {
                                super::x86::gemm_q8_packed_vnni::<8>(
                                    *tl,
                                    core::array::from_fn(|m| row(m0 + m).0),
                                    core::array::from_fn(|m| row(m0 + m).1),
                                    core::array::from_fn(|m| row(m0 + m).2),
                                )
                            };
                            let s = scalar::gemm_q8_packed::<8>(
                                *tl,
                                core::array::from_fn(|m| row(m0 + m).0),
                                core::array::from_fn(|m| row(m0 + m).1),
                                core::array::from_fn(|m| row(m0 + m).2),
                            );
                            for m in 0..8.min(done - m0) {
                                for j in (0..8).filter(|j| 8 * t + j < cols) {
                                    let c = 8 * t + j;
                                    let got = buf[(m0 + m) * W + 2 + c];
                                    let mut want = [0f32];
                                    scalar::bias_act(
                                        &[v[m][j]],
                                        b.map(|b| &b[c..c + 1]),
                                        gelu,
                                        &mut want,
                                    );
                                    assert_eq!(
                                        got.to_bits(),
                                        want[0].to_bits(),
                                        "q4={q4} nb={nb} bias={} gelu={gelu} tile {t} row {}",
                                        b.is_some(),
                                        m0 + m
                                    );
                                    if b.is_none() && !gelu {
                                        let mag: f64 = (0..nb)
                                            .map(|bk| {
                                                let a: i64 = (0..Q8_BLOCK)
                                                    .map(|i| {
                                                        (tl.value(bk, j, i) as i64
                                                            * row(m0 + m).0[bk * 32 + i] as i64)
                                                            .abs()
                                                    })
                                                    .sum();
                                                (super::f16_to_f32(tl.scale_bits(bk, j)) as f64
                                                    * row(m0 + m).1[bk] as f64)
                                                    .abs()
                                                    * a as f64
                                            })
                                            .sum();
                                        check(
                                            &format!(
                                                "amx q4={q4} nb={nb} tile {t} [{}][{j}]",
                                                m0 + m
                                            ),
                                            got,
                                            s[m][j],
                                            mag,
                                            SIMD_VS_SCALAR_GEMM_Q8,
                                        );
                                    }
                                }
                            }
                        }
                    }
                }
            }
            // Short operands, a window wider than two tiles or a short bias are refused, not read past.
            let mut buf = vec![0f32; 8 * 32];
            let mut out = Cols::whole(&mut buf, 32);
            assert_eq!(
                unsafe {
                    amx::gemm_q8_packed_amx_raw(
                        &w,
                        &qs[..7 * n + n - 1],
                        n,
                        &ds,
                        out.window(0, 8, 0, 16),
                        None,
                        false,
                        &[],
                    )
                },
                0
            );
            assert_eq!(
                unsafe {
                    amx::gemm_q8_packed_amx_raw(
                        &w,
                        &qs,
                        n,
                        &ds[..8 * nb - 1],
                        out.window(0, 8, 0, 16),
                        None,
                        false,
                        &[],
                    )
                },
                0
            );
            assert_eq!(
                unsafe {
                    amx::gemm_q8_packed_amx_raw(
                        &w,
                        &qs,
                        n,
                        &ds,
                        out.window(0, 7, 0, 16),
                        None,
                        false,
                        &[],
                    )
                },
                0
            );
            assert_eq!(
                unsafe {
                    amx::gemm_q8_packed_amx_raw(
                        &w,
                        &qs,
                        n,
                        &ds,
                        out.window(0, 8, 0, 17),
                        None,
                        false,
                        &[],
                    )
                },
                0
            );
            assert_eq!(
                unsafe {
                    amx::gemm_q8_packed_amx_raw(
                        &w,
                        &qs,
                        n,
                        &ds,
                        out.window(0, 8, 0, 16),
                        Some(&bias[..15]),
                        false,
                        &[],
                    )
                },
                0
            );
            assert!(buf.iter().all(|v| *v == 0.0), "a refused call wrote");
            let mut out = Cols::whole(&mut buf, 32);
            // A second tile of other blocks: refused.
            if nb > 1 {
                let zeros = vec![0u8; (nb - 1) * (256 + 16)];
                let narrow = if q4 {
                    PackedQ8::from_q4_group(&zeros, nb - 1)
                } else {
                    PackedQ8::from_group(&zeros, nb - 1)
                }
                .unwrap();
                let mut w2 = TilePair::new();
                assert!(unsafe {
                    w2.prepare_raw(0, tile[0], false) && w2.prepare_raw(1, narrow, false)
                });
                assert_eq!(
                    unsafe {
                        amx::gemm_q8_packed_amx_raw(
                            &w2,
                            &qs,
                            n,
                            &ds,
                            out.window(0, 8, 0, 16),
                            None,
                            false,
                            &[],
                        )
                    },
                    0
                );
            }
        }
    }
    // Wider than the prepared room, or a third tile: refused.
    let wide = vec![0u8; (PACK_BLOCKS + 1) * (256 + 16)];
    let mut w = TilePair::new();
    assert!(!unsafe {
        w.prepare_raw(
            0,
            PackedQ8::from_group(&wide, PACK_BLOCKS + 1).unwrap(),
            false,
        )
    });
    assert!(!unsafe { w.prepare_raw(2, PackedQ8::from_group(&wide, 1).unwrap(), false) });
    let qs = vec![0i8; 8 * (PACK_BLOCKS + 1) * 32];
    let ds = vec![0f32; 8 * (PACK_BLOCKS + 1)];
    let mut buf = vec![0f32; 8 * 16];
    assert_eq!(
        unsafe {
            amx::gemm_q8_packed_amx_raw(
                &w,
                &qs,
                (PACK_BLOCKS + 1) * 32,
                &ds,
                Cols::whole(&mut buf, 16).window(0, 8, 0, 16),
                None,
                false,
                &[],
            )
        },
        0
    );
}

/// The query-group kernels (`dot_rows_group*`, `axpy_rows_group*`) of
/// every variant this CPU runs equal the same variant's per-query kernel
/// called for each member, bit for bit (the attention scores a group of
/// queries per key read and keeps each query's numbers), write nothing
/// between the members' rows, and track the scalar twin (the per-query
/// scalar kernels) within the per-query limits. Groups of 1-9 members
/// (blocks of `QUERY_GROUP` and their rests), heads of 1-96 lanes (the
/// masked tails, and past the 64 lanes a register block holds), with and
/// without bytes to prefetch on the side.
#[test]
#[allow(unsafe_code, clippy::type_complexity)]
fn query_groups_equal_the_per_query_kernels() {
    /// (variant, group kernel, the per-query kernel of the same variant).
    ///
    /// # Safety
    /// Both kernels need the variant's CPU features (pushed only where detected).
    type Dots<E> = (
        &'static str,
        unsafe fn(&[f32], usize, usize, usize, &[E], usize, usize, &mut [f32], usize, &[u8]),
        unsafe fn(&[f32], &[E], usize, &mut [f32]),
    );
    /// As `Dots`, for the weighted value rows.
    ///
    /// # Safety
    /// As for `Dots`.
    type Axpys<E> = (
        &'static str,
        unsafe fn(&[f32], usize, usize, &[E], usize, &mut [f32], usize, usize, usize, &[u8]),
        unsafe fn(&[f32], &[E], usize, &mut [f32]),
    );
    let mut d32: Vec<Dots<f32>> = vec![(
        "dispatched",
        |q, hd, qs, g, k, s, n, o, os, side| {
            super::dot_rows_group(q, hd, qs, g, k, s, n, o, os, side)
        },
        |q, k, s, o| super::dot_rows(q, k, s, o),
    )];
    let mut d16: Vec<Dots<u16>> = vec![(
        "dispatched",
        |q, hd, qs, g, k, s, n, o, os, side| {
            super::dot_rows_group_f16(q, hd, qs, g, k, s, n, o, os, side)
        },
        |q, k, s, o| super::dot_rows_f16(q, k, s, o),
    )];
    let mut a32: Vec<Axpys<f32>> = vec![(
        "dispatched",
        |c, cs, nk, x, s, y, ys, n, g, side| {
            super::axpy_rows_group_f32(c, cs, nk, x, s, y, ys, n, g, side)
        },
        |c, x, s, y| super::axpy_rows_f32(c, x, s, y),
    )];
    let mut a16: Vec<Axpys<u16>> = vec![(
        "dispatched",
        |c, cs, nk, x, s, y, ys, n, g, side| {
            super::axpy_rows_group_f16(c, cs, nk, x, s, y, ys, n, g, side)
        },
        |c, x, s, y| super::axpy_rows_f16(c, x, s, y),
    )];
    #[cfg(target_arch = "x86_64")]
    {
        use std::is_x86_feature_detected as has;
        if has!("avx512f")
            && has!("avx512bw")
            && has!("avx512vl")
            && has!("avx2")
            && has!("fma")
            && has!("f16c")
        {
            d32.push((
                "avx512",
                super::x86::dot_rows_512_group,
                super::x86::dot_rows_512,
            ));
            d16.push((
                "avx512",
                super::x86::dot_rows_512_group_f16,
                super::x86::dot_rows_512_f16,
            ));
            a32.push((
                "avx512",
                super::x86::axpy_rows_512_group_f32,
                super::x86::axpy_rows_512_f32,
            ));
            a16.push((
                "avx512",
                super::x86::axpy_rows_512_group_f16,
                super::x86::axpy_rows_512_f16,
            ));
        }
    }
    let to16 = |v: &[f32]| -> Vec<u16> {
        v.iter()
            .map(|&x| half::f16::from_f32(x).to_bits())
            .collect()
    };
    let mut r = Rng(97);
    // Bytes the kernels prefetch meanwhile (no result may depend on them;
    // empty, shorter and longer than a line per key).
    let sides: [Vec<u8>; 3] = [Vec::new(), vec![7; 100], vec![9; 64 * 40 + 3]];
    for g in 1..=9 {
        let side = &sides[g % 3][..];
        for hd in [1, 5, 16, 17, 40, 48, 64, 65, 80, 96] {
            for n in [0, 1, 2, 3, 29] {
                let (q_stride, stride, out_stride) = (hd + 3, hd + 11, n + 2);
                let q = r.vec((g - 1) * q_stride + hd);
                let k = r.vec(n * stride);
                let k16 = to16(&k);
                let len = (g - 1) * out_stride + n;
                let twin = |m: usize, j: usize, got: f32, name: &str, k: &dyn Fn(usize) -> f32| {
                    let qm = &q[m * q_stride..m * q_stride + hd];
                    let kj: Vec<f32> = (0..hd).map(|i| k(j * stride + i)).collect();
                    let want: f64 = qm.iter().zip(&kj).map(|(&a, &b)| a as f64 * b as f64).sum();
                    let s: f64 = qm
                        .iter()
                        .zip(&kj)
                        .map(|(&a, &b)| (a as f64 * b as f64).abs())
                        .sum();
                    check(
                        &format!("{name} g={g} hd={hd} n={n} m={m} j={j} vs twin"),
                        got,
                        want as f32,
                        s,
                        SIMD_VS_SCALAR_TILE_512,
                    );
                };
                for &(name, group, one) in &d32 {
                    let mut got = vec![f32::NAN; len];
                    // SAFETY: each variant was pushed only where its CPU features were detected.
                    unsafe {
                        group(
                            &q, hd, q_stride, g, &k, stride, n, &mut got, out_stride, side,
                        )
                    };
                    for m in 0..g {
                        let mut want = vec![0.0; n];
                        // SAFETY: as above.
                        unsafe { one(&q[m * q_stride..m * q_stride + hd], &k, stride, &mut want) };
                        for j in 0..n {
                            assert_eq!(
                                got[m * out_stride + j].to_bits(),
                                want[j].to_bits(),
                                "{name} dot_rows_group g={g} hd={hd} n={n} m={m} j={j}"
                            );
                            twin(m, j, got[m * out_stride + j], name, &|i| k[i]);
                        }
                        if m + 1 < g {
                            assert!(
                                got[m * out_stride + n..(m + 1) * out_stride]
                                    .iter()
                                    .all(|v| v.is_nan()),
                                "{name} wrote between rows"
                            );
                        }
                    }
                }
                for &(name, group, one) in &d16 {
                    let mut got = vec![f32::NAN; len];
                    // SAFETY: as above.
                    unsafe {
                        group(
                            &q, hd, q_stride, g, &k16, stride, n, &mut got, out_stride, side,
                        )
                    };
                    for m in 0..g {
                        let mut want = vec![0.0; n];
                        // SAFETY: as above.
                        unsafe {
                            one(&q[m * q_stride..m * q_stride + hd], &k16, stride, &mut want)
                        };
                        for j in 0..n {
                            assert_eq!(
                                got[m * out_stride + j].to_bits(),
                                want[j].to_bits(),
                                "{name} dot_rows_group_f16 g={g} hd={hd} n={n} m={m} j={j}"
                            );
                            twin(m, j, got[m * out_stride + j], name, &|i| {
                                super::f16_to_f32(k16[i])
                            });
                        }
                        if m + 1 < g {
                            assert!(
                                got[m * out_stride + n..(m + 1) * out_stride]
                                    .iter()
                                    .all(|v| v.is_nan()),
                                "{name} f16 wrote between rows"
                            );
                        }
                    }
                }
            }
        }
        for n in [1, 8, 15, 63, 64, 65, 128, 130] {
            for nk in [0, 1, 5, 29] {
                let (stride, coef_stride, y_stride) = (n + 5, nk + 3, n + 7);
                let x = r.vec(nk * stride);
                let x16 = to16(&x);
                let coef: Vec<f32> = (0..(g - 1) * coef_stride + nk)
                    .map(|_| r.f() * 0.1)
                    .collect();
                let y0: Vec<f32> = (0..(g - 1) * y_stride + n)
                    .map(|i| if i % y_stride < n { r.f() } else { f32::NAN })
                    .collect();
                let rows_len = if nk == 0 { 0 } else { (nk - 1) * stride + n };
                let check_rows = |name: &str,
                                  got: &[f32],
                                  per: &dyn Fn(&[f32], &mut [f32]),
                                  row: &dyn Fn(usize) -> f32| {
                    for m in 0..g {
                        let cm = &coef[m * coef_stride..m * coef_stride + nk];
                        let mut want = y0[m * y_stride..m * y_stride + n].to_vec();
                        per(cm, &mut want);
                        for i in 0..n {
                            let gv = got[m * y_stride + i];
                            assert_eq!(
                                gv.to_bits(),
                                want[i].to_bits(),
                                "{name} axpy_rows_group g={g} n={n} nk={nk} m={m} lane {i}"
                            );
                            let y = y0[m * y_stride + i] as f64;
                            let t: f64 = y
                                + (0..nk)
                                    .map(|j| cm[j] as f64 * row(j * stride + i) as f64)
                                    .sum::<f64>();
                            let s: f64 = y.abs()
                                + (0..nk)
                                    .map(|j| (cm[j] as f64 * row(j * stride + i) as f64).abs())
                                    .sum::<f64>();
                            check(
                                &format!("{name} axpy_rows_group g={g} n={n} nk={nk} vs twin"),
                                gv,
                                t as f32,
                                s,
                                SIMD_VS_SCALAR_AXPY * nk.max(1) as f64,
                            );
                        }
                        if m + 1 < g {
                            assert!(
                                got[m * y_stride + n..(m + 1) * y_stride]
                                    .iter()
                                    .all(|v| v.is_nan()),
                                "{name} axpy wrote between rows"
                            );
                        }
                    }
                };
                for &(name, group, one) in &a32 {
                    let mut got = y0.clone();
                    // SAFETY: as above.
                    unsafe {
                        group(
                            &coef,
                            coef_stride,
                            nk,
                            &x[..rows_len],
                            stride,
                            &mut got,
                            y_stride,
                            n,
                            g,
                            side,
                        )
                    };
                    // SAFETY: as above.
                    check_rows(
                        name,
                        &got,
                        &|c, y| unsafe { one(c, &x[..rows_len], stride, y) },
                        &|i| x[i],
                    );
                }
                for &(name, group, one) in &a16 {
                    let mut got = y0.clone();
                    // SAFETY: as above.
                    unsafe {
                        group(
                            &coef,
                            coef_stride,
                            nk,
                            &x16[..rows_len],
                            stride,
                            &mut got,
                            y_stride,
                            n,
                            g,
                            side,
                        )
                    };
                    // SAFETY: as above.
                    check_rows(
                        name,
                        &got,
                        &|c, y| unsafe { one(c, &x16[..rows_len], stride, y) },
                        &|i| super::f16_to_f32(x16[i]),
                    );
                }
            }
        }
    }
}

/// `exp_shifted_sum` gives the same bits whichever sign a zero maximum has
/// (the attention's `scale_max` may return either zero when the largest
/// score is zero): `s - 0.0` and `s - (-0.0)` differ only for `s = -0.0`,
/// and e^(+0) and e^(-0) are both exactly 1, on the dispatched variant and
/// the scalar twin.
#[test]
fn softmax_shift_by_a_signed_zero_is_the_same() {
    let base = [
        0.0f32, -0.0, -1.5, -0.25, 0.0, -3.0, -0.0, -7.0, -0.5, 0.0, -2.0, -0.0, -1.0, -4.0, 0.0,
        -0.125, -0.0,
    ];
    let run = |f: &dyn Fn(&mut [f32], f32) -> f32, max: f32| {
        let mut s = base.to_vec();
        let sum = f(&mut s, max);
        (
            sum.to_bits(),
            s.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
        )
    };
    for (name, f) in [
        (
            "dispatched",
            &(|s: &mut [f32], m: f32| super::exp_shifted_sum(s, m))
                as &dyn Fn(&mut [f32], f32) -> f32,
        ),
        ("scalar", &|s: &mut [f32], m: f32| {
            scalar::exp_shifted_sum(s, m)
        }),
    ] {
        let (plus, minus) = (run(f, 0.0), run(f, -0.0));
        assert_eq!(plus, minus, "{name}");
        assert_eq!(plus.1[0], 1.0f32.to_bits(), "{name}");
        assert_eq!(plus.1[1], 1.0f32.to_bits(), "{name}");
    }
}

/// `scale_max` of every variant this CPU runs scales the scores exactly as
/// the twin does (bit for bit) and returns the twin's maximum (the same
/// value; zeros of either sign compare equal): every length 0-40 and a
/// long run, NaN scores skipped, a starting maximum above all scores.
#[test]
#[allow(unsafe_code)]
fn scale_max_equals_the_twin() {
    let mut r = Rng(29);
    /// (variant, kernel).
    ///
    /// # Safety
    /// The kernel needs the variant's CPU features (pushed only where detected).
    type ScaleMax = (&'static str, unsafe fn(&mut [f32], f32, f32) -> f32);
    let mut v: Vec<ScaleMax> = vec![("dispatched", |s, a, m| super::scale_max(s, a, m))];
    #[cfg(target_arch = "x86_64")]
    if std::is_x86_feature_detected!("avx512f") {
        v.push(("avx512", super::x86::scale_max_512));
    }
    #[cfg(target_arch = "x86_64")]
    if std::is_x86_feature_detected!("avx2") {
        v.push(("avx2", super::x86::scale_max_avx2));
    }
    for n in (0..=40).chain([290, 1000]) {
        for start in [f32::NEG_INFINITY, 0.0, 100.0] {
            let mut s0 = r.vec(n);
            if n > 3 {
                s0[n / 2] = f32::NAN;
                s0[n - 1] = -0.0;
            }
            let mut twin = s0.clone();
            let want = scalar::scale_max(&mut twin, 0.125, start);
            let naive = s0.iter().filter(|x| !x.is_nan()).fold(start, |m, &x| {
                if x * 0.125 > m {
                    x * 0.125
                } else {
                    m
                }
            });
            assert_eq!(want, naive, "twin n={n}");
            for &(name, f) in &v {
                let mut got = s0.clone();
                // SAFETY: pushed only where its CPU features were detected.
                let m = unsafe { f(&mut got, 0.125, start) };
                assert_eq!(m, want, "{name} n={n} start={start}");
                assert!(
                    got.iter()
                        .zip(&twin)
                        .all(|(a, b)| a.to_bits() == b.to_bits()),
                    "{name} scaled n={n}"
                );
            }
        }
    }
}

/// `narrow_f16` (F16C) rounds as its twin (`half::f16::from_f32`) does, bit
/// for bit on every non-NaN input (NaNs stay NaN): every binary16 value and
/// the midpoints and neighbours between them (the ties to even),
/// infinities, zeros, subnormals, values past the largest half, 300000
/// random bit patterns; every tail length.
#[test]
#[allow(unsafe_code)]
fn narrow_f16_matches_scalar_twin() {
    let mut xs: Vec<f32> = Vec::new();
    for h in 0..=u16::MAX {
        let v = half::f16::from_bits(h).to_f32();
        let next = half::f16::from_bits(h.wrapping_add(1)).to_f32();
        xs.push(v);
        if v.is_finite() && next.is_finite() && (h & 0x7fff) < 0x7bff {
            let mid = (v as f64 + next as f64) / 2.0;
            let m = mid as f32;
            xs.extend([
                m,
                f32::from_bits(m.to_bits().wrapping_add(1)),
                f32::from_bits(m.to_bits().wrapping_sub(1)),
            ]);
        }
    }
    xs.extend([
        f32::INFINITY,
        f32::NEG_INFINITY,
        65520.0,
        65519.99,
        1e9,
        -1e9,
        f32::MIN_POSITIVE,
        1e-30,
        -0.0,
        f32::NAN,
    ]);
    let mut r = 0x9e3779b97f4a7c15u64;
    for _ in 0..300_000 {
        r ^= r << 13;
        r ^= r >> 7;
        r ^= r << 17;
        xs.push(f32::from_bits(r as u32));
    }
    let mut want = vec![0u16; xs.len()];
    scalar::narrow_f16(&xs, &mut want);
    type Narrow = (&'static str, fn(&[f32], &mut [u16]));
    let mut variants: Vec<Narrow> = vec![("dispatched", super::narrow_f16)];
    #[cfg(target_arch = "x86_64")]
    if std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("f16c") {
        // SAFETY: avx2 and f16c detected.
        variants.push(("f16c", |s, d| unsafe { super::x86::narrow_f16(s, d) }));
    }
    let nan = |h: u16| h & 0x7c00 == 0x7c00 && h & 0x03ff != 0;
    for (name, f) in variants {
        for n in (0..=17).chain([xs.len()]) {
            let mut got = vec![0u16; n];
            f(&xs[..n], &mut got);
            for (i, (&g, &w)) in got.iter().zip(&want).enumerate() {
                assert!(
                    g == w || (nan(g) && nan(w)),
                    "{name} n={n}: {} -> {g:#06x}, twin {w:#06x}",
                    xs[i]
                );
            }
        }
    }
}

/// The prefetch shares of a kernel's blocks cover the bytes ahead once, in
/// order, at line boundaries; parts past the last (and 0 parts) are empty.
#[test]
fn prefetch_parts_cover_the_bytes_once() {
    for len in [0usize, 1, 63, 64, 65, 6528, 26112, 100_000] {
        for parts in [1usize, 2, 3, 12, 24, 96, 200] {
            let mut at = 0;
            for i in 0..parts {
                let (b0, b1) = super::part_bytes(len, i, parts);
                assert_eq!(
                    b0, at,
                    "len {len} parts {parts} part {i} starts where the last ended"
                );
                assert!(
                    b1 >= b0 && (b1 % 64 == 0 || b1 == len),
                    "len {len} parts {parts} part {i}: {b0}..{b1}"
                );
                at = b1;
            }
            assert_eq!(at, len, "len {len} parts {parts}: covered");
            assert_eq!(
                super::part_bytes(len, parts, parts).0,
                super::part_bytes(len, parts, parts).1
            );
        }
        assert_eq!(super::part_bytes(len, 0, 0), (0, 0));
    }
}

/// Whether this CPU has every feature of the AVX-512 VNNI kernels
/// (avx512f/bw/dq/vl/vnni, avx2, fma, f16c).
#[cfg(target_arch = "x86_64")]
fn cpu_runs_avx512_vnni() -> bool {
    use std::is_x86_feature_detected as has;
    has!("avx512f")
        && has!("avx512bw")
        && has!("avx512dq")
        && has!("avx512vl")
        && has!("avx512vnni")
        && has!("avx2")
        && has!("fma")
        && has!("f16c")
}

/// `rows` random activation rows of `nb` blocks quantised one after
/// another (values, block scales, 2 corrections per block), row `outlier`
/// ending in 1e4.
#[cfg(target_arch = "x86_64")]
fn q8_panel(r: &mut Rng, rows: usize, nb: usize, outlier: usize) -> (Vec<i8>, Vec<f32>, Vec<i32>) {
    let n = nb * Q8_BLOCK;
    let mut qs = vec![0i8; rows * n];
    let mut ds = vec![0f32; rows * nb];
    let mut cs = vec![0i32; rows * 2 * nb];
    for m in 0..rows {
        let mut x = r.vec(n);
        if m == outlier {
            x[n - 1] = 1e4;
        }
        scalar::quantise_q8_corr(
            &x,
            &mut qs[m * n..(m + 1) * n],
            &mut ds[m * nb..(m + 1) * nb],
            &mut cs[m * 2 * nb..(m + 1) * 2 * nb],
        );
    }
    (qs, ds, cs)
}

/// One pair call's rows `got` against the 8-row kernel `want` per tile, bit
/// for bit, and within [`SIMD_VS_SCALAR_GEMM_Q8`] of the scalar twin.
#[cfg(target_arch = "x86_64")]
fn assert_pair_call<const M: usize>(
    got: &[[f32; 2 * super::PACK_ROWS]; M],
    tile: [super::PackedQ8<'_>; 2],
    q: [&[i8]; M],
    d: [&[f32]; M],
    c: [&[i32]; M],
    what: &str,
    want: impl Fn(super::PackedQ8<'_>) -> [[f32; super::PACK_ROWS]; M],
) {
    use super::PACK_ROWS;
    for (t, tl) in tile.into_iter().enumerate() {
        let (want, twin) = (want(tl), scalar::gemm_q8_packed::<M>(tl, q, d, c));
        for m in 0..M {
            for j in 0..PACK_ROWS {
                let what = format!("{what} row {m} tile {t} column {j}");
                let g = got[m][PACK_ROWS * t + j];
                assert_eq!(g.to_bits(), want[m][j].to_bits(), "{what}");
                check(&what, g, twin[m][j], tile_row_mag(tl, j, q[m], d[m]), SIMD_VS_SCALAR_GEMM_Q8);
            }
        }
    }
}

/// The magnitude scale of weight row `j` of a packed tile dotted with one
/// quantised activation row: `sum_b |s_j,b xd_b| sum_i |w x|` (the bound
/// the scalar-twin comparisons scale by).
#[cfg(target_arch = "x86_64")]
fn tile_row_mag(tl: super::PackedQ8<'_>, j: usize, q: &[i8], d: &[f32]) -> f64 {
    (0..q.len() / Q8_BLOCK)
        .map(|bk| {
            let a: i64 = (0..Q8_BLOCK).map(|i| (tl.value(bk, j, i) as i64 * q[bk * 32 + i] as i64).abs()).sum();
            (super::f16_to_f32(tl.scale_bits(bk, j)) as f64 * d[bk] as f64).abs() * a as f64
        })
        .sum()
}

/// The first `rows` rows of a row-major panel of `keep` blocks per row as
/// the pair kernels read one call group: block b of row m at index b * rows
/// + m (values x32, scales, corrections x2).
#[cfg(target_arch = "x86_64")]
fn group_panel(q: &[i8], d: &[f32], c: &[i32], rows: usize, keep: usize) -> (Vec<i8>, Vec<f32>, Vec<i32>) {
    let (mut gq, mut gd, mut gc) = (
        vec![0i8; rows * keep * Q8_BLOCK],
        vec![0f32; rows * keep],
        vec![0i32; 2 * rows * keep],
    );
    for m in 0..rows {
        for b in 0..keep {
            let i = b * rows + m;
            assert_eq!(i, super::pair_group_index(b, m, rows));
            let src = (m * keep + b) * Q8_BLOCK;
            gq[i * Q8_BLOCK..(i + 1) * Q8_BLOCK].copy_from_slice(&q[src..src + Q8_BLOCK]);
            gd[i] = d[m * keep + b];
            gc[2 * i..2 * i + 2].copy_from_slice(&c[2 * (m * keep + b)..2 * (m * keep + b) + 2]);
        }
    }
    (gq, gd, gc)
}

/// The AVX2 pair kernel over the wide layout (`gemm_q8_pair_avx2_raw`)
/// against the AVX2 8-row kernel per tile, bit for bit, and the scalar
/// twin, for 1-8 rows, int8 and 4-bit tiles, every width up to
/// `WIDE_BLOCKS` blocks; and its refusals (wider tiles, tiles not laid out
/// wide, 0 or 9 rows, short operands).
#[cfg(target_arch = "x86_64")]
#[test]
fn wide_pair_kernel_equals_the_8_row_kernel_bit_for_bit() {
    use super::tile_pair::{gemm_q8_pair_avx2_raw, TilePair, WIDE_BLOCKS};
    use std::is_x86_feature_detected as has;
    if !(has!("avx2") && has!("fma") && has!("f16c")) {
        eprintln!("skipped: this CPU has no AVX2");
        return;
    }
    // SAFETY (whole test): avx2, fma and f16c were detected above.
    let mut r = Rng(0x31de);
    let mut checked = 0;
    for nb in [1usize, 2, 3, 7, 24, WIDE_BLOCKS - 1, WIDE_BLOCKS] {
        let n = nb * Q8_BLOCK;
        for q4 in [false, true] {
            let two = TwoTiles::new(&mut r, nb, q4);
            let tile = two.tiles();
            let mut w = TilePair::new();
            for (t, tl) in tile.iter().enumerate() {
                assert!(unsafe { w.prepare_raw_wide(t, *tl) } && !w.unsigned(), "nb={nb}");
            }
            assert!(w.wide());
            let (qs, ds, cs) = q8_panel(&mut r, PAIR_CALL_ROWS_MAX, nb, 2);
            macro_rules! check {
                ($m:literal) => {{
                    let (gq, gd, _) = group_panel(&qs, &ds, &cs, $m, nb);
                    let ahead = two.rows[1][0].as_slice();
                    let got = unsafe { gemm_q8_pair_avx2_raw::<$m>(&w, &gq, &gd, n, ahead) }.expect("runs");
                    let q: [&[i8]; $m] = core::array::from_fn(|m| &qs[m * n..(m + 1) * n]);
                    let d: [&[f32]; $m] = core::array::from_fn(|m| &ds[m * nb..(m + 1) * nb]);
                    let c: [&[i32]; $m] = core::array::from_fn(|m| &cs[2 * m * nb..2 * (m + 1) * nb]);
                    let what = format!("nb={nb} q4={q4} rows={}", $m);
                    assert_pair_call(&got, tile, q, d, c, &what, |tl| unsafe {
                        super::x86::gemm_q8_packed_avx2::<$m>(tl, q, d, c)
                    });
                    checked += 1;
                }};
            }
            check!(1);
            check!(2);
            check!(3);
            check!(4);
            check!(5);
            check!(6);
            check!(7);
            check!(8);
            // Refusals: no rows, more rows than a call takes, operands short of the rows asked for.
            let (gq, gd, _) = group_panel(&qs, &ds, &cs, 8, nb);
            assert!(unsafe { gemm_q8_pair_avx2_raw::<0>(&w, &gq, &gd, n, &[]) }.is_none());
            let (q9, d9) = ([gq.clone(), gq.clone()].concat(), [gd.clone(), gd.clone()].concat());
            assert!(unsafe { gemm_q8_pair_avx2_raw::<9>(&w, &q9, &d9, n, &[]) }.is_none());
            assert!(unsafe { gemm_q8_pair_avx2_raw::<8>(&w, &gq[1..], &gd, n, &[]) }.is_none());
            assert!(unsafe { gemm_q8_pair_avx2_raw::<8>(&w, &gq, &gd[1..], n, &[]) }.is_none());
            // A tile laid out for the VNNI kernels is not taken.
            assert!(unsafe { w.prepare_raw_avx2(1, tile[1], true) } && !w.wide());
            assert!(unsafe { gemm_q8_pair_avx2_raw::<8>(&w, &gq, &gd, n, &[]) }.is_none());
        }
    }
    assert_eq!(checked, 7 * 2 * 8);
    // Wider than the operand holds as i16: refused.
    let two = TwoTiles::new(&mut r, WIDE_BLOCKS + 1, false);
    let mut w = TilePair::new();
    assert!(!unsafe { w.prepare_raw_wide(0, two.tiles()[0]) });
}

/// The most rows of a pair call (`tile_pair::PAIR_CALL_ROWS`).
#[cfg(target_arch = "x86_64")]
const PAIR_CALL_ROWS_MAX: usize = super::tile_pair::PAIR_CALL_ROWS;

/// Two tiles of 8 random weight rows of `nb` blocks as the packed kernels
/// read them: int8 rows packed on the stack, or stored 4-bit groups.
#[cfg(target_arch = "x86_64")]
struct TwoTiles {
    rows: [Vec<Vec<u8>>; 2],
    packs: [super::Q8Pack8; 2],
    groups: [Vec<u8>; 2],
    nb: usize,
    q4: bool,
}

#[cfg(target_arch = "x86_64")]
impl TwoTiles {
    fn new(r: &mut Rng, nb: usize, q4: bool) -> Box<Self> {
        let n = nb * Q8_BLOCK;
        let rows: [Vec<Vec<u8>>; 2] = core::array::from_fn(|_| {
            (0..super::PACK_ROWS)
                .map(|_| {
                    if q4 {
                        q4_bytes(&r.vec(n))
                    } else {
                        q8_bytes(&r.vec(n))
                    }
                })
                .collect()
        });
        let groups: [Vec<u8>; 2] = core::array::from_fn(|t| {
            if q4 {
                q4_group(&rows[t], nb)
            } else {
                Vec::new()
            }
        });
        let mut two = Box::new(TwoTiles {
            rows,
            packs: [super::Q8Pack8::new(), super::Q8Pack8::new()],
            groups,
            nb,
            q4,
        });
        if !q4 {
            let TwoTiles { rows, packs, .. } = &mut *two;
            for (t, pack) in packs.iter_mut().enumerate() {
                scalar::q8_pack8(
                    core::array::from_fn(|j| &rows[t][j][..]),
                    nb,
                    &mut pack.v,
                    &mut pack.s,
                );
                pack.nb = nb;
            }
        }
        two
    }

    fn tiles(&self) -> [super::PackedQ8<'_>; 2] {
        core::array::from_fn(|t| {
            if self.q4 {
                super::PackedQ8::from_q4_group(&self.groups[t], self.nb).unwrap()
            } else {
                self.packs[t].view()
            }
        })
    }
}

/// The 16-row kernels over a prepared tile pair (AVX-512 VNNI:
/// `tile_pair::gemm_q8_pair_raw`; AVX-VNNI on 32-byte vectors:
/// `gemm_q8_pair_avxvnni_raw`, its operand laid out by `prepare_raw_avx2`,
/// byte for byte the AVX-512 layout where the CPU has both) give, per tile,
/// what the 8-row kernel of their ISA gives, bit for bit, and tracks the scalar twin within the named
/// limit of every SIMD int8 GEMM: every row count it takes
/// (1-8, each call group laid out by `pair_group_index`), odd and even
/// block counts up to `PACK_BLOCKS`, int8 and 4-bit
/// tiles, rows with an outlier, with and without a prefetch, and rows that
/// hold fewer blocks than the tiles (the kernel cuts to them). It refuses 0
/// or more than `PAIR_CALL_ROWS` rows, operands short of the rows, pairs
/// laid out signed (the AMX kernel's operand) or half signed, and tiles
/// laid out with different block counts.
#[cfg(target_arch = "x86_64")]
#[test]
#[allow(unsafe_code)]
fn tile_pair_kernel_equals_the_8_row_kernel_bit_for_bit() {
    use super::tile_pair::{gemm_q8_pair_avxvnni_raw, gemm_q8_pair_raw, TilePair, PAIR_CALL_ROWS};
    use super::{Q8Pack8, PACK_BLOCKS};
    use std::is_x86_feature_detected as has;
    let avxvnni = has!("avx2") && has!("fma") && has!("f16c") && has!("avxvnni");
    // The kernels this CPU runs: 0 AVX-512 VNNI, 1 AVX-VNNI.
    let kinds: Vec<(usize, &str)> = [(0, "avx512vnni"), (1, "avxvnni")]
        .into_iter()
        .filter(|&(k, _)| if k == 0 { cpu_runs_avx512_vnni() } else { avxvnni })
        .collect();
    if kinds.is_empty() {
        eprintln!("skipped: this CPU has neither AVX-512 VNNI nor AVX-VNNI");
        return;
    }
    // SAFETY (whole test): every feature of each kernel and of its layout
    // (`prepare_raw`, `prepare_raw_avx2`) was detected above, and a kind
    // runs only where its features are.
    let prepare = |kind: usize, p: &mut TilePair, t: usize, tl: super::PackedQ8<'_>, unsigned: bool| unsafe {
        if kind == 0 {
            p.prepare_raw(t, tl, unsigned)
        } else {
            p.prepare_raw_avx2(t, tl, unsigned)
        }
    };
    macro_rules! pair {
        ($kind:expr, $m:literal, $w:expr, $q:expr, $d:expr, $c:expr, $n:expr, $pre:expr) => {
            if $kind == 0 {
                unsafe { gemm_q8_pair_raw::<$m>($w, $q, $d, $c, $n, $pre) }
            } else {
                unsafe { gemm_q8_pair_avxvnni_raw::<$m>($w, $q, $d, $c, $n, $pre) }
            }
        };
    }
    let mut checked = 0;
    for &(kind, isa) in &kinds {
    let mut r = Rng(0x7e1e);
    for nb in [1usize, 2, 3, 7, 24, 95, PACK_BLOCKS] {
        let n = nb * Q8_BLOCK;
        for q4 in [false, true] {
            let two = TwoTiles::new(&mut r, nb, q4);
            let (rows, tile) = (&two.rows, two.tiles());
            // The operand stored signed (the AMX kernel's, which this kernel
            // refuses) and unsigned (this kernel's).
            let mut pairs = [TilePair::new(), TilePair::new()];
            for (p, unsigned) in pairs.iter_mut().zip([false, true]) {
                for (t, tl) in tile.iter().enumerate() {
                    assert!(prepare(kind, p, t, *tl, unsigned), "nb={nb}");
                }
                if kind == 0 {
                    // Both tiles in one pass (`prepare_both_raw`): the same operand
                    // and scales as the two halves, byte for byte.
                    let mut one = TilePair::new();
                    // SAFETY: kind 0 runs where AVX-512 VNNI (and f16c) was detected.
                    assert!(unsafe { one.prepare_both_raw(tile[0], tile[1], unsigned) }, "nb={nb}");
                    assert!(one.b[..nb * 512] == p.b[..nb * 512], "one pass nb={nb} q4={q4} unsigned={unsigned}");
                    assert_eq!(one.s.map(|h| h.map(|v| v.map(f32::to_bits))), p.s.map(|h| h.map(|v| v.map(f32::to_bits))));
                    assert_eq!((one.nb, one.unsigned()), (p.nb, p.unsigned()));
                }
                if kind > 0 && kinds[0].0 == 0 {
                    // Both layouts on this CPU: the same operand, byte for byte.
                    let mut other = TilePair::new();
                    for (t, tl) in tile.iter().enumerate() {
                        assert!(prepare(0, &mut other, t, *tl, unsigned));
                    }
                    assert!(other.b[..nb * 512] == p.b[..nb * 512], "layouts nb={nb} q4={q4}");
                    assert_eq!(other.s.map(|h| h.map(|v| v.map(f32::to_bits))), p.s.map(|h| h.map(|v| v.map(f32::to_bits))));
                }
            }
            let m_rows = PAIR_CALL_ROWS;
            let (qs, ds, cs) = q8_panel(&mut r, m_rows, nb, 3);
            // The panel cut to its first `keep` blocks per row (rows `keep * 32` values apart).
            let cut = |keep: usize| {
                let (mut q, mut d, mut c) = (Vec::new(), Vec::new(), Vec::new());
                for m in 0..m_rows {
                    q.extend_from_slice(&qs[m * n..m * n + keep * Q8_BLOCK]);
                    d.extend_from_slice(&ds[m * nb..m * nb + keep]);
                    c.extend_from_slice(&cs[m * 2 * nb..m * 2 * nb + 2 * keep]);
                }
                (q, d, c)
            };
            let grouped = group_panel;
            let ahead = rows[1][0].as_slice();
            macro_rules! check {
                ($m:literal) => {{
                    for (keep, pre) in [(nb, &[][..]), (nb, ahead), (nb.div_ceil(2), &[][..])] {
                        let (pq, pd, pc) = cut(keep);
                        let stride = keep * Q8_BLOCK;
                        {
 let w = &pairs[1];
                        let (gq, gd, gc) = grouped(&pq, &pd, &pc, $m, keep);
                        let got = pair!(kind, $m, w, &gq, &gd, &gc, stride, pre).expect("runs");
                        let q: [&[i8]; $m] = core::array::from_fn(|m| &pq[m * stride..(m + 1) * stride]);
                        let d: [&[f32]; $m] = core::array::from_fn(|m| &pd[m * keep..(m + 1) * keep]);
                        let c: [&[i32]; $m] = core::array::from_fn(|m| &pc[2 * m * keep..2 * (m + 1) * keep]);
                        let what = format!("{isa} nb={nb} q4={q4} rows={} keep={keep}", $m);
                        assert_pair_call(&got, tile, q, d, c, &what, |tl| unsafe {
                            if kind == 0 {
                                super::x86::gemm_q8_packed_vnni::<$m>(tl, q, d, c)
                            } else {
                                super::x86::gemm_q8_packed_avxvnni::<$m>(tl, q, d, c)
                            }
                        });
                        checked += 1;
                        }
                    }
                }};
            }
            check!(1);
            check!(2);
            check!(3);
            check!(4);
            check!(5);
            check!(6);
            check!(7);
            check!(8);
            // Refusals: no rows, more rows than a call takes, operands short of
            // the rows asked for, tiles stored signed and unsigned, tiles of
            // different widths.
            let [signed, w] = &mut pairs;
            let one = (&qs[..n], &ds[..nb], &cs[..2 * nb]);
            assert!(pair!(kind, 1, signed, one.0, one.1, one.2, n, &[]).is_none());
            assert!(prepare(kind, w, 1, tile[1], false));
            assert!(!w.unsigned());
            assert!(pair!(kind, 1, w, one.0, one.1, one.2, n, &[]).is_none());
            assert!(prepare(kind, w, 1, tile[1], true) && w.unsigned());
            assert!(pair!(kind, 0, w, &qs, &ds, &cs, n, &[]).is_none());
            let (q9, d9, c9) = (
                [qs.clone(), qs.clone()].concat(),
                [ds.clone(), ds.clone()].concat(),
                [cs.clone(), cs.clone()].concat(),
            );
            assert!(pair!(kind, 9, w, &q9, &d9, &c9, n, &[]).is_none());
            assert!(pair!(kind, 8, w, &q9, &d9, &c9, n, &[]).is_some());
            assert!(pair!(kind, 8, w, &qs[1..], &ds, &cs, n, &[]).is_none());
            assert!(pair!(kind, 8, w, &qs, &ds[1..], &cs, n, &[]).is_none());
            assert!(pair!(kind, 8, w, &qs, &ds, &cs[1..], n, &[]).is_none());
            if nb > 1 && !q4 {
                let mut narrow = Q8Pack8::new();
                scalar::q8_pack8(
                    core::array::from_fn(|j| &rows[1][j][..]),
                    nb - 1,
                    &mut narrow.v,
                    &mut narrow.s,
                );
                narrow.nb = nb - 1;
                assert!(prepare(kind, w, 1, narrow.view(), true));
                assert!(pair!(kind, 1, w, &qs, &ds, &cs, n, &[]).is_none());
            }
        }
    }
    }
    assert_eq!(checked, kinds.len() * 7 * 2 * 8 * 3);
}
