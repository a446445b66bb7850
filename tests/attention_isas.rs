//! R mode's coordinated attention and a LAT's band as per-head GEMMs
//! (`attention_staircase`, `attention_band`) give the same bits on every SIMD ISA of this
//! CPU: its GEMM (`simd::matmul::rows_times`) sums each value in the same
//! order on each. One test in its own binary: it switches the process's ISA.

use duolando_core::kernels::simd::{self, Isa};
use duolando_core::kernels::{attention_band, attention_staircase, gemm_attention_work};

#[test]
#[allow(unsafe_code)]
fn gemm_attention_is_bit_identical_across_simd_isas() {
    let mut seed = 0x2468_ace1u64;
    let mut rnd = move || {
        seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((seed >> 40) as f32 / (1u64 << 24) as f32 - 0.5) * 2.0
    };
    let isas: Vec<Isa> = duolando::simd::supported()
        .into_iter()
        .filter(|&i| i != Isa::Scalar)
        .collect();
    for (c, nh, streams, t) in [(768, 12, 10, 29), (96, 1, 3, 7), (40, 2, 10, 4)] {
        let n = streams * t;
        let (q, k, v): (Vec<f32>, Vec<f32>, Vec<f32>) = (
            (0..n * c).map(|_| rnd()).collect(),
            (0..n * c).map(|_| rnd()).collect(),
            (0..n * c).map(|_| rnd()).collect(),
        );
        let mut work = vec![0.0f32; gemm_attention_work(n, n, c / nh).unwrap()];
        let mut first: Option<(Isa, Vec<f32>)> = None;
        for &isa in &isas {
            // SAFETY: `supported` lists only ISAs this CPU has.
            unsafe { simd::set_isa(isa) };
            let mut out = vec![f32::NAN; n * c];
            assert!(attention_staircase(
                &q, &k, &v, c, nh, t, &mut work, &mut out
            ));
            assert!(out.iter().all(|x| x.is_finite()));
            match &first {
                None => first = Some((isa, out)),
                Some((i0, o0)) => assert!(
                    o0.iter().zip(&out).all(|(a, b)| a.to_bits() == b.to_bits()),
                    "{isa:?} differs from {i0:?}: c {c}, streams {streams}, t {t}"
                ),
            }
        }
    }
    // SAFETY: as above.
    unsafe { simd::set_isa(duolando::simd::detect()) };
}
