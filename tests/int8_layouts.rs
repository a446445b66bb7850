//! The row layouts (`Q8Block32`, `Q4Block32`) and their row-group layouts
//! (`Q8Block32x8`, `Q4Block32x8`) hold the same numbers and compute the same
//! products, under every ISA this CPU runs (one test: the kernel choice is
//! process-wide):
//! - the x8 writers keep every row's blocks (expanded rows equal the plain
//!   ones' Q8 expansion byte for byte), padded last groups included;
//! - the generic row reads (`row_into`, `dot`, `axpy`) are bit-identical;
//! - `linear` is bit-identical wherever both take the same kernel (the
//!   packed 8-row tile from 4 activation rows on under AVX512-VNNI, the
//!   4-row tile under scalar and NEON without dotprod, for rows up to
//!   `Q4_FAST_COLS`), and within the int8 kernels' summation limit of the
//!   exact block sums elsewhere (x8 takes the packed tile from one row on
//!   under AVX512-VNNI, AVX-512, AVX2 and NEON dotprod);
//! - an x8 row's output never depends on how many rows share the call (under
//!   AVX512-VNNI, 16 and 17 rows take tile pairs and the 16-row kernel,
//!   `simd::gemm_q8_pair`, against the 8-row kernel of a row alone).

use duolando::duo_writer::{
    quantise_q4_block32, quantise_q4_block32x8, quantise_q8_block32, quantise_q8_block32x8,
};
use duolando_core::kernels::simd::{self, f16_to_f32};
use duolando_core::kernels::{expand_q4, linear, Matrix, Q4Rows, Q8Rows, RowMatrix, X8Rows};
use duolando_tests::Rng;

/// |kernel - exact| <= limit * (1 + sum_b |w_scale x_scale| sum_i |w_i q_i|):
/// the per-lane i32 sums are exact, only the f32 sum over lanes and blocks
/// differs between kernels.
const INT8_KERNEL_VS_EXACT: f64 = 1e-6;

fn bits(v: &[f32]) -> Vec<u32> {
    v.iter().map(|f| f.to_bits()).collect()
}

/// Exact f64 value of `linear` over the quantised weights and activations,
/// and its magnitude (per block |scales| times sum |w q|).
fn exact(plain: &Q8Rows<'_>, x: &[f32], o: usize, i: usize) -> (Vec<f64>, Vec<f64>) {
    // `plain`: the Q8Block32 rows (a Q4 matrix's exact expansion for Q4).
    let n = x.len() / i;
    let nb = i / 32;
    let (mut want, mut mag) = (vec![0.0; n * o], vec![0.0; n * o]);
    for a in 0..n {
        let (mut q, mut d) = (vec![0i8; i], vec![0f32; nb]);
        simd::quantise_q8(&x[a * i..(a + 1) * i], &mut q, &mut d);
        for c in 0..o {
            let row = plain.row(c);
            for b in 0..nb {
                let blk = &row[b * 34..(b + 1) * 34];
                let s = f16_to_f32(u16::from_le_bytes([blk[0], blk[1]])) as f64 * d[b] as f64;
                let terms = || {
                    blk[2..]
                        .iter()
                        .zip(&q[b * 32..(b + 1) * 32])
                        .map(|(&w, &v)| w as i8 as i64 * v as i64)
                };
                want[a * o + c] += s * terms().sum::<i64>() as f64;
                // Kernels sum lanes of partial block sums in f32: bound by sum |w q|.
                mag[a * o + c] += s.abs() * terms().map(i64::abs).sum::<i64>() as f64;
            }
        }
    }
    (want, mag)
}

#[test]
#[allow(unsafe_code)]
fn x8_groups_compute_what_their_rows_compute_under_every_isa() {
    let wide = duolando_core::kernels::linear::Q4_FAST_COLS + 32; // wider than the expansion buffer
    let shapes = [
        (32usize, 1usize),
        (32, 13),
        (96, 8),
        (768, 70),
        (768, 3),
        (3072, 24),
        (3104, 9),
        (wide, 11),
    ];
    for isa in duolando::simd::supported() {
        // SAFETY: `supported` lists only ISAs this CPU has.
        unsafe { simd::set_isa(isa) };
        let mut r = Rng(0x5151);
        for &(i, o) in &shapes {
            let w = r.vec(o * i);
            let (q8, q4) = (quantise_q8_block32(&w), quantise_q4_block32(&w));
            // The Q8Block32 rows a Q4 matrix encodes (exact).
            let mut q4_as_q8 = vec![0u8; o * i / 32 * 34];
            expand_q4(&q4, &mut q4_as_q8);
            let (x8, x4) = (quantise_q8_block32x8(&w, i), quantise_q4_block32x8(&w, i));
            assert_eq!(
                x8.len(),
                o.div_ceil(8) * 8 * i / 32 * 34,
                "x8 bytes ({o}, {i})"
            );
            assert_eq!(
                x4.len(),
                o.div_ceil(8) * 8 * i / 32 * 18,
                "q4 x8 bytes ({o}, {i})"
            );
            assert!(
                X8Rows::new(&x8[..x8.len() - 1], o, i).is_none()
                    && X8Rows::new_q4(&x4[..x4.len() - 1], o, i).is_none()
            );
            assert!(X8Rows::new(&x8, o, i + 16).is_none() && X8Rows::new(&x4, o, i).is_none());
            let cases = [
                (
                    "int8",
                    Matrix::Q8(Q8Rows::new(&q8, o, i).unwrap()),
                    X8Rows::new(&x8, o, i).unwrap(),
                    Q8Rows::new(&q8, o, i).unwrap(),
                    x8.len(),
                ),
                (
                    "q4",
                    Matrix::Q4(Q4Rows::new(&q4, o, i).unwrap()),
                    X8Rows::new_q4(&x4, o, i).unwrap(),
                    Q8Rows::new(&q4_as_q8, o, i).unwrap(),
                    x4.len(),
                ),
            ];
            for (name, mp, packed, as_q8, bytes) in cases {
                let mut row = vec![0u8; i / 32 * 34];
                let (mut ra, mut rb) = (vec![0f32; i], vec![0f32; i]);
                let xa = r.vec(i);
                for c in 0..o {
                    packed.expand(c, 0, i / 32, &mut row);
                    assert_eq!(
                        &row[..],
                        as_q8.row(c),
                        "{isa:?} {name} ({o}, {i}) row {c} expanded"
                    );
                    mp.row_into(c, &mut ra);
                    packed.row_into(c, &mut rb);
                    assert_eq!(bits(&ra), bits(&rb), "{isa:?} {name} row_into {c}");
                    assert_eq!(
                        mp.dot(c, &xa).to_bits(),
                        packed.dot(c, &xa).to_bits(),
                        "{isa:?} {name} dot {c}"
                    );
                    let (mut ya, mut yb) = (xa.clone(), xa.clone());
                    match mp {
                        Matrix::Q8(m) => m.axpy(c, 0.37, &mut ya),
                        Matrix::Q4(m) => m.axpy(c, 0.37, &mut ya),
                        _ => unreachable!(),
                    }
                    packed.axpy(c, 0.37, &mut yb);
                    assert_eq!(bits(&ya), bits(&yb), "{isa:?} {name} axpy {c}");
                }
                let mx = Matrix::X8(packed);
                assert_eq!(mx.weight_bytes(), bytes);
                // Up to 17 rows: calls of 5 + 5 (10) under VNNI; 16 and 17 rows
                // take tile pairs (calls of 8 + 8, 6 + 6 + 5) where a pair fits.
                let rows = 17;
                let x = r.vec(rows * i);
                let bias = r.vec(o);
                let mut alone = vec![0f32; rows * o];
                for a in 0..rows {
                    linear(
                        &x[a * i..(a + 1) * i],
                        &mx,
                        Some(&bias),
                        &mut alone[a * o..(a + 1) * o],
                    );
                }
                for n in 1..=rows {
                    let (mut yp, mut yx) = (vec![f32::NAN; n * o], vec![f32::NAN; n * o]);
                    linear(&x[..n * i], &mp, Some(&bias), &mut yp);
                    linear(&x[..n * i], &mx, Some(&bias), &mut yx);
                    assert_eq!(
                        bits(&yx),
                        bits(&alone[..n * o]),
                        "{isa:?} {name} ({o}, {i}): x8 rows alone vs {n} together"
                    );
                    // VNNI: the row layouts pack per call from 4 rows (and up
                    // to PACK_BLOCKS blocks). AVX2, AVX-512 and NEON dotprod
                    // read x8 groups in place with the packed kernel, the row
                    // layouts take the 4-row tile: never the same kernel.
                    // Elsewhere x8 rows are expanded for the same tile up to
                    // Q4_FAST_COLS wide, beyond which x8 takes the chunked
                    // path (and so does Q4).
                    let same_kernel = if simd::q8_packing_pays() {
                        n >= 4 && i / 32 <= simd::PACK_BLOCKS && i < wide
                    } else if simd::packed_q8_fast() {
                        false
                    } else {
                        i < wide || name == "q4"
                    };
                    if same_kernel {
                        assert_eq!(
                            bits(&yx),
                            bits(&yp),
                            "{isa:?} {name} ({o}, {i}) {n} rows: x8 vs rows"
                        );
                    }
                    let (want, mag) = exact(&as_q8, &x[..n * i], o, i);
                    for k in 0..n * o {
                        let bound = INT8_KERNEL_VS_EXACT * (1.0 + mag[k]);
                        for (what, y) in [("rows", &yp), ("x8", &yx)] {
                            let err = (y[k] as f64 - bias[k % o] as f64 - want[k]).abs();
                            assert!(err <= bound, "{isa:?} {name} {what} ({o}, {i}) {n} rows [{k}]: err {err:e} > {bound:e}");
                        }
                    }
                }
            }
        }
    }
    // SAFETY: the best ISA is among the supported ones.
    unsafe { simd::set_isa(duolando::simd::detect()) };
}
