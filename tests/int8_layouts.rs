//! The two int8 layouts (`Q8Block32` rows, `Q8Block32x8` row groups) hold
//! the same numbers and compute the same products, under every ISA this
//! CPU runs (one test: the kernel choice is process-wide):
//! - the x8 writer keeps every row's blocks (expanded rows equal the plain
//!   ones byte for byte), padded last groups included;
//! - the generic row reads (`row_into`, `dot`, `axpy`) are bit-identical;
//! - `linear` is bit-identical wherever both take the same kernel (the
//!   packed 8-row tile from 4 activation rows on under AVX512-VNNI, the
//!   4-row tile on every other ISA, for rows up to `Q4_FAST_COLS`), and within the int8 kernels' summation
//!   limit of the exact block sums elsewhere (x8 takes the packed tile from
//!   one row on under VNNI);
//! - an x8 row's output never depends on how many rows share the call.

use duolando::duo_writer::{quantise_q8_block32, quantise_q8_block32x8};
use duolando_core::kernels::simd::{self, f16_to_f32};
use duolando_core::kernels::{linear, Matrix, Q8Rows, Q8x8Rows, RowMatrix};

struct Rng(u64);
impl Rng {
    fn f(&mut self) -> f32 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 40) as f32 / (1u64 << 24) as f32 * 2.0 - 1.0
    }
    fn vec(&mut self, n: usize) -> Vec<f32> {
        (0..n).map(|_| self.f()).collect()
    }
}

/// |kernel - exact| <= limit * (1 + sum_b |w_scale x_scale isum_b|): the
/// per-block i32 sums are exact, only the f32 sum over blocks and lanes
/// differs between kernels.
const INT8_KERNEL_VS_EXACT: f64 = 1e-6;

fn bits(v: &[f32]) -> Vec<u32> {
    v.iter().map(|f| f.to_bits()).collect()
}

/// Exact f64 value of `linear` over the quantised weights and activations,
/// and its magnitude (the sum of |block terms|).
fn exact(plain: &Q8Rows<'_>, x: &[f32], o: usize, i: usize) -> (Vec<f64>, Vec<f64>) {
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
                let isum: i64 = blk[2..].iter().zip(&q[b * 32..(b + 1) * 32]).map(|(&w, &v)| w as i8 as i64 * v as i64).sum();
                want[a * o + c] += s * isum as f64;
                mag[a * o + c] += (s * isum as f64).abs();
            }
        }
    }
    (want, mag)
}

#[test]
#[allow(unsafe_code)]
fn q8x8_computes_what_q8_computes_under_every_isa() {
    let wide = duolando_core::kernels::linear::Q4_FAST_COLS + 32; // wider than the expansion buffer
    let shapes = [(32usize, 1usize), (32, 13), (96, 8), (768, 70), (768, 3), (3072, 24), (3104, 9), (wide, 11)];
    for isa in duolando::simd::supported() {
        // SAFETY: `supported` lists only ISAs this CPU has.
        unsafe { simd::set_isa(isa) };
        let mut r = Rng(0x5151);
        for &(i, o) in &shapes {
            let w = r.vec(o * i);
            let q8 = quantise_q8_block32(&w);
            let x8 = quantise_q8_block32x8(&w, i);
            assert_eq!(x8.len(), o.div_ceil(8) * 8 * i / 32 * 34, "x8 bytes ({o}, {i})");
            let plain = Q8Rows::new(&q8, o, i).unwrap();
            let packed = Q8x8Rows::new(&x8, o, i).unwrap();
            assert!(Q8x8Rows::new(&x8[..x8.len() - 1], o, i).is_none());
            assert!(Q8x8Rows::new(&x8, o, i + 16).is_none());
            let mut row = vec![0u8; i / 32 * 34];
            let (mut ra, mut rb) = (vec![0f32; i], vec![0f32; i]);
            let xa = r.vec(i);
            for c in 0..o {
                packed.expand(c, 0, i / 32, &mut row);
                assert_eq!(&row[..], plain.row(c), "{isa:?} ({o}, {i}) row {c} expanded");
                plain.row_into(c, &mut ra);
                packed.row_into(c, &mut rb);
                assert_eq!(bits(&ra), bits(&rb), "{isa:?} row_into {c}");
                assert_eq!(plain.dot(c, &xa).to_bits(), packed.dot(c, &xa).to_bits(), "{isa:?} dot {c}");
                let (mut ya, mut yb) = (xa.clone(), xa.clone());
                plain.axpy(c, 0.37, &mut ya);
                packed.axpy(c, 0.37, &mut yb);
                assert_eq!(bits(&ya), bits(&yb), "{isa:?} axpy {c}");
            }
            let (mp, mx) = (Matrix::Q8(plain), Matrix::Q8x8(packed));
            assert_eq!(mx.weight_bytes(), x8.len());
            let rows = 9;
            let x = r.vec(rows * i);
            let bias = r.vec(o);
            let mut alone = vec![0f32; rows * o];
            for a in 0..rows {
                linear(&x[a * i..(a + 1) * i], &mx, Some(&bias), &mut alone[a * o..(a + 1) * o]);
            }
            for n in 1..=rows {
                let (mut yp, mut yx) = (vec![f32::NAN; n * o], vec![f32::NAN; n * o]);
                linear(&x[..n * i], &mp, Some(&bias), &mut yp);
                linear(&x[..n * i], &mx, Some(&bias), &mut yx);
                assert_eq!(bits(&yx), bits(&alone[..n * o]), "{isa:?} ({o}, {i}): x8 rows alone vs {n} together");
                // VNNI: plain packs per call from 4 rows (and up to PACK_BLOCKS
                // blocks). Elsewhere x8 rows are expanded for the same tile
                // up to Q4_FAST_COLS wide, beyond which x8 takes the chunked path.
                let same_kernel = if simd::packed_q8_fast() { n >= 4 && i / 32 <= simd::PACK_BLOCKS } else { i <= wide - 32 };
                if same_kernel {
                    assert_eq!(bits(&yx), bits(&yp), "{isa:?} ({o}, {i}) {n} rows: x8 vs plain");
                }
                let (want, mag) = exact(&plain, &x[..n * i], o, i);
                for k in 0..n * o {
                    let bound = INT8_KERNEL_VS_EXACT * (1.0 + mag[k]);
                    for (name, y) in [("plain", &yp), ("x8", &yx)] {
                        let err = (y[k] as f64 - bias[k % o] as f64 - want[k]).abs();
                        assert!(err <= bound, "{isa:?} {name} ({o}, {i}) {n} rows [{k}]: err {err:e} > {bound:e}");
                    }
                }
            }
        }
    }
    // SAFETY: the best ISA is among the supported ones.
    unsafe { simd::set_isa(duolando::simd::detect()) };
}
