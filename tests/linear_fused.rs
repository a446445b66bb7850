//! `linear_each` (one quantised panel for the query, key and value
//! projections) gives what one `linear` per matrix gives, bit for bit, and
//! so do `linear_with` / `linear_each_with` quantising into caller memory
//! (R mode's block scratch: one panel for a whole window, or panels of a
//! room's rows); `linear_gelu_with` (GELU in the GEMM's epilogue) gives
//! `linear_with` then `gelu_inplace`, with and without a bias, on
//! every kernel set this CPU runs (the AMX tiles on and off where they run)
//! and on one thread and two. Rows 1 to 290, so the unpacked and packed
//! int8 tiles, the AMX row groups, the small and the full quantised panel
//! and several panels. Its own test binary: it switches the process-wide
//! kernels.

use duolando::duo_writer::{quantise_q4_block32x8, quantise_q8_block32, quantise_q8_block32x8};
use duolando_core::arena::{Arena, Planner};
use duolando_core::kernels::simd::{self, Isa};
use duolando_core::kernels::{
    gelu_inplace, linear, linear_each, linear_each_with, linear_gelu_with, linear_with, F16Rows,
    F32Rows, Matrix, Q8Room, Q8Rows, X8Rows,
};
use duolando_tests::Rng;

fn bits(v: &[f32]) -> Vec<u32> {
    v.iter().map(|f| f.to_bits()).collect()
}

#[test]
#[allow(unsafe_code)]
fn linear_each_equals_one_linear_per_matrix() {
    let amx = duolando::simd::amx_usable();
    let mut variants: Vec<(Isa, bool)> = duolando::simd::supported()
        .into_iter()
        .map(|i| (i, false))
        .collect();
    if amx && variants.iter().any(|v| v.0 == Isa::Avx512Vnni) {
        variants.push((Isa::Avx512Vnni, true));
    }
    let mut r = Rng(0xf00d);
    for &i in &[768usize, 3072] {
        // Query/key/value-like matrices of different heights.
        let outs = [48usize, 24, 40];
        let k = 0.5 / (i as f32).sqrt();
        let w: Vec<Vec<f32>> = outs
            .iter()
            .map(|&o| r.vec(o * i).iter().map(|v| k * v).collect())
            .collect();
        let q8: Vec<Vec<u8>> = w.iter().map(|w| quantise_q8_block32(w)).collect();
        let x8: Vec<Vec<u8>> = w.iter().map(|w| quantise_q8_block32x8(w, i)).collect();
        let x4: Vec<Vec<u8>> = w.iter().map(|w| quantise_q4_block32x8(w, i)).collect();
        let h: Vec<Vec<u16>> = w
            .iter()
            .map(|w| {
                w.iter()
                    .map(|&v| half::f16::from_f32(v).to_bits())
                    .collect()
            })
            .collect();
        let b: Vec<Vec<f32>> = outs
            .iter()
            .map(|&o| r.vec(o).iter().map(|v| 0.2 * v).collect())
            .collect();
        let sets: Vec<(&str, [Matrix<'_>; 3])> = vec![
            (
                "int8 x8",
                core::array::from_fn(|m| Matrix::X8(X8Rows::new(&x8[m], outs[m], i).unwrap())),
            ),
            (
                "q4 x8",
                core::array::from_fn(|m| Matrix::X8(X8Rows::new_q4(&x4[m], outs[m], i).unwrap())),
            ),
            (
                "int8 rows",
                core::array::from_fn(|m| Matrix::Q8(Q8Rows::new(&q8[m], outs[m], i).unwrap())),
            ),
            (
                "f16",
                core::array::from_fn(|m| Matrix::F16(F16Rows::new(&h[m], outs[m], i).unwrap())),
            ),
            (
                "f32",
                core::array::from_fn(|m| Matrix::F32(F32Rows::new(&w[m], outs[m], i).unwrap())),
            ),
        ];
        for n in [1usize, 3, 4, 10, 11, 16, 17, 160, 290] {
            let x = r.vec(n * i);
            for &(isa, on) in &variants {
                // SAFETY: `supported` lists only ISAs this CPU runs; AMX is
                // switched on only where `amx_usable` got the tile permission.
                unsafe {
                    simd::set_isa(isa);
                    simd::amx::enable(on);
                }
                for threads in [1usize, 2] {
                    duolando::workers::set_threads(threads).unwrap();
                    for (name, m) in &sets {
                        let what = format!(
                            "{name}, in {i}, {n} rows, {isa:?}{}, {threads} threads",
                            if on { "+AMX" } else { "" }
                        );
                        let want: Vec<Vec<f32>> = (0..3)
                            .map(|k| {
                                let mut y = vec![0.0f32; n * outs[k]];
                                linear(&x, &m[k], Some(&b[k]), &mut y);
                                y
                            })
                            .collect();
                        let mut got: Vec<Vec<f32>> =
                            outs.iter().map(|&o| vec![f32::NAN; n * o]).collect();
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
                            assert!(want[k].iter().all(|v| v.is_finite()), "{what}, matrix {k}");
                            assert_eq!(
                                bits(&got[k]),
                                bits(&want[k]),
                                "linear_each, {what}, matrix {k}"
                            );
                        }
                        // Caller rooms: all the rows, about a third of them, and none.
                        for room_rows in [n, n.div_ceil(3) + 1, 0] {
                            let values = room_rows * i;
                            let mut plan = Planner::new();
                            Q8Room::carve(&mut plan, values).unwrap();
                            let mut mem = vec![0u8; plan.total_for_any_base().unwrap()];
                            let mut arena = Arena::new(&mut mem);
                            let mut room = Q8Room::carve(&mut arena, values).unwrap();
                            let what = format!("{what}, a room of {room_rows} rows");
                            for k in 0..3 {
                                let mut y = vec![f32::NAN; n * outs[k]];
                                linear_with(&x, &m[k], Some(&b[k]), &mut y, &mut room);
                                assert_eq!(
                                    bits(&y),
                                    bits(&want[k]),
                                    "linear_with, {what}, matrix {k}"
                                );
                                // GELU in the epilogue: the numbers of GELU after the GEMM, with a bias and without.
                                for bias in [Some(&b[k][..]), None] {
                                    let mut after = vec![f32::NAN; n * outs[k]];
                                    linear_with(&x, &m[k], bias, &mut after, &mut room);
                                    gelu_inplace(&mut after);
                                    let mut y = vec![f32::NAN; n * outs[k]];
                                    linear_gelu_with(&x, &m[k], bias, &mut y, &mut room);
                                    assert_eq!(
                                        bits(&y),
                                        bits(&after),
                                        "linear_gelu_with, {what}, matrix {k}, bias {}",
                                        bias.is_some()
                                    );
                                }
                            }
                            let mut got: Vec<Vec<f32>> =
                                outs.iter().map(|&o| vec![f32::NAN; n * o]).collect();
                            let [g0, g1, g2] = &mut got[..] else {
                                unreachable!()
                            };
                            linear_each_with(
                                &x,
                                [&m[0], &m[1], &m[2]],
                                [Some(&b[0][..]), Some(&b[1][..]), Some(&b[2][..])],
                                [&mut g0[..], &mut g1[..], &mut g2[..]],
                                &mut room,
                            );
                            for k in 0..3 {
                                assert_eq!(
                                    bits(&got[k]),
                                    bits(&want[k]),
                                    "linear_each_with, {what}, matrix {k}"
                                );
                            }
                        }
                    }
                }
            }
        }
    }
    // SAFETY: turning the kernel off is always sound; the best ISA is supported.
    unsafe { simd::amx::enable(false) };
    duolando::simd::init();
    duolando::workers::set_threads(1).unwrap();
}
