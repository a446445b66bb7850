//! `linear` with the AMX tile kernel on gives what it gives with the
//! AVX512-VNNI kernels alone, bit for bit (int8 and 4-bit row groups, int8
//! rows packed per call; 1 to 160 activation rows, so whole 12- and 8-row groups (100: a call of 84 rows before one of 16),
//! partial ones and several stack panels; 1 to 5 weight tiles, so whole
//! tile pairs, a single last tile and partial tiles; one thread and two): the kernel
//! choice may depend on the number of rows without changing a number, as
//! `Session::step_many`'s bit-identity needs. Runs only where the CPU has
//! AMX-INT8 and Linux grants the tile permission; says so when skipped.
//! Its own test binary: it switches the process-wide kernels.

use duolando::duo_writer::{quantise_q4_block32x8, quantise_q8_block32, quantise_q8_block32x8};
use duolando_core::kernels::simd::{self, Isa};
use duolando_core::kernels::{linear, Matrix, Q8Rows, X8Rows};
use duolando_tests::Rng;

fn bits(v: &[f32]) -> Vec<u32> {
    v.iter().map(|f| f.to_bits()).collect()
}

#[test]
#[allow(unsafe_code)]
fn linear_with_amx_tiles_equals_linear_without() {
    if !(duolando::simd::supported().contains(&Isa::Avx512Vnni) && duolando::simd::amx_usable()) {
        eprintln!("skipped: this CPU or OS does not run AMX-INT8 tiles");
        return;
    }
    // SAFETY: AVX512-VNNI is supported (checked above), and `amx_usable`
    // checked the AMX CPUID bits and got the tile permission.
    unsafe { simd::set_isa(Isa::Avx512Vnni) };
    let mut r = Rng(0xa11a);
    for &(i, o) in &[(768usize, 40usize), (3072, 24), (96, 8), (512, 17), (32, 9)] {
        let w = r.vec(o * i);
        let (q8, x8, x4) = (
            quantise_q8_block32(&w),
            quantise_q8_block32x8(&w, i),
            quantise_q4_block32x8(&w, i),
        );
        let cases = [
            ("int8 x8", Matrix::X8(X8Rows::new(&x8, o, i).unwrap())),
            ("q4 x8", Matrix::X8(X8Rows::new_q4(&x4, o, i).unwrap())),
            ("int8 rows", Matrix::Q8(Q8Rows::new(&q8, o, i).unwrap())),
        ];
        let bias = r.vec(o);
        for n in [1usize, 15, 16, 17, 24, 28, 33, 40, 64, 70, 100, 103, 160] {
            let mut x = r.vec(n * i);
            x[(n / 2) * i] = 40.0; // one outlier block
            for threads in [1usize, 2] {
                duolando::workers::set_threads(threads).unwrap();
                for (name, m) in &cases {
                    let mut got = [vec![f32::NAN; n * o], vec![f32::NAN; n * o]];
                    for (on, y) in [false, true].into_iter().zip(got.iter_mut()) {
                        // SAFETY: as above.
                        unsafe { simd::amx::enable(on) };
                        assert_eq!(simd::amx::enabled(), on);
                        linear(&x, m, Some(&bias), y);
                    }
                    assert!(
                        got[0].iter().all(|v| v.is_finite()),
                        "{name} ({o}, {i}) {n} rows"
                    );
                    assert_eq!(
                        bits(&got[1]),
                        bits(&got[0]),
                        "{name} ({o}, {i}), {n} rows, {threads} threads: AMX vs VNNI"
                    );
                }
            }
        }
    }
    // SAFETY: turning the kernel off is always sound.
    unsafe { simd::amx::enable(false) };
    duolando::workers::set_threads(1).unwrap();
}
