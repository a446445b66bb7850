//! Kernel speed per weight type and per instruction set, all in one run
//! (ratios are what to compare on a shared machine; absolute times are
//! not): `linear` (x W^T + b) at the model's shapes for 1..290 activation
//! rows, with enough distinct weight matrices that the small-batch cases
//! read their weights from memory (bandwidth-bound), and the attention
//! kernel at the R step's coordinated-attention shape and at one streaming
//! append (10 rows against a full f16 cache), attention as per-head GEMMs
//! (Transflower's encoder layers: `matmul` against the dot-product tiles
//! it replaced, alternated call by call), and the VQ decoders'
//! conv-transpose `z` from f16 rows against int8 in GEMM order.
//! int8 is measured in both stored layouts: `Q8Block32` rows (`int8`) and
//! `Q8Block32x8` row groups (`int8x8`, what `convert --dtype int8` writes).
//!
//! The int8 activation quantiser at the R step's and the S step's shapes
//! comes first.
//!
//! Then (issue #40) the int8 multiply-accumulate peak of each ISA (the
//! register-only probes of `simd::peak`) and each int8 GEMM shape the
//! engine runs (R step, re-prefill chunk, 16 sessions, S step, LAT push:
//! `duolando::kernel_bench::SHAPES`) through `linear` with `Q8Block32x8`
//! weights, its GMAC/s and fraction of that ISA's peak, under every ISA
//! (as `duolando bench --kernels`).
//!
//! `cargo bench -p duolando --bench kernels` (`-- quick` for fewer repeats,
//! `-- attention` for the attention lines alone, `-- quantiser` for the
//! quantiser's, `-- peak` for the peak and GEMM-shape lines alone).

use std::time::Instant;

use duolando::duo_writer::{quantise_q8_block32, quantise_q8_block32x8};
use duolando_core::kernels::simd::{self, Isa};
use duolando_core::kernels::{
    attention, attention_ahead, attention_staircase, gemm_attention_work, linear, linear_xw, F16Rows, F32Rows, KvRows, Matrix, Q8Rows,
    RowData, TiledCausalMask, Ungrouped, X8Rows,
};

mod common;
use common::Rng;

/// Median seconds of `reps` calls of `f` after one warm-up.
fn time(reps: usize, mut f: impl FnMut()) -> f64 {
    f();
    let mut t: Vec<f64> = (0..reps)
        .map(|_| {
            let s = Instant::now();
            f();
            s.elapsed().as_secs_f64()
        })
        .collect();
    t.sort_by(|a, b| a.partial_cmp(b).unwrap());
    t[t.len() / 2]
}

/// `simd::quantise_q8_corr` over R-step and S-step shapes (rows x width),
/// ns per value under each ISA and the ratio to the first (best) one.
fn quantiser_lines(isas: &[Isa], reps: usize, r: &mut Rng) {
    for &(n, i) in &[(290usize, 768usize), (290, 3072), (10, 3072)] {
        let x = r.vec(n * i);
        let (mut q, mut d, mut c) = (
            vec![0i8; n * i],
            vec![0f32; n * i / 32],
            vec![0i32; n * i / 16],
        );
        let mut line = format!("quantise_q8_corr {n}x{i}:");
        let mut best = None;
        for &isa in isas {
            // SAFETY: `supported` lists only ISAs this CPU has.
            unsafe { simd::set_isa(isa) };
            let t = time(reps.max(5) * 4, || {
                simd::quantise_q8_corr(&x, &mut q, &mut d, &mut c);
                std::hint::black_box(&q);
            });
            let b = *best.get_or_insert(t);
            line += &format!(
                "  [{isa:?}] {:.3} ns/value ({:.2}x)",
                t * 1e9 / (n * i) as f64,
                t / b
            );
        }
        println!("{line}");
    }
    duolando::simd::init();
}

/// The int8 MAC peak per probe this CPU runs, then per ISA its probe and
/// every GEMM shape of `kernel_bench::SHAPES` with its fraction of it.
fn peak_lines(isas: &[Isa], reps: usize, quick: bool) {
    let cpu = duolando::kernel_bench::cpu_name();
    let mut line = format!("int8 MAC peaks on {cpu} (register-only probes, 1 thread):");
    for p in duolando::kernel_bench::probes() {
        line += &format!(
            "  {} {:.1} GMAC/s",
            p.name(),
            duolando::kernel_bench::peak_gmacs(p).expect("probe equals its twin")
        );
    }
    println!("{line}");
    let weights = duolando::kernel_bench::Weights::new(quick);
    for &isa in isas {
        // SAFETY: `supported` lists only ISAs this CPU has.
        unsafe { simd::set_isa(isa) };
        let rep = duolando::kernel_bench::run(&weights, reps).expect("kernel bench");
        for l in rep.lines(&format!("[{} | {cpu}] ", duolando::simd::describe())) {
            println!("{l}");
        }
    }
    duolando::simd::init();
}

fn main() {
    let quick = std::env::args().any(|a| a == "quick");
    let reps = if quick { 3 } else { 7 };
    // `attention`: only the attention lines (the linear and conv lines take minutes).
    let only_attention = std::env::args().any(|a| a == "attention");
    let isas = duolando::simd::supported();
    println!("ISAs on this CPU (best first): {isas:?}");
    // The linear lines measure AVX512-VNNI once more with the AMX tiles where they run.
    let mut variants: Vec<(Isa, bool)> = isas.iter().map(|&i| (i, false)).collect();
    if isas.contains(&Isa::Avx512Vnni) && duolando::simd::amx_usable() {
        variants.insert(0, (Isa::Avx512Vnni, true));
    }
    let mut r = Rng(0x1234_5678);
    // The int8 activation quantiser (every int8 GEMM's input rows, once per call), per ISA.
    let only_quantiser = std::env::args().any(|a| a == "quantiser");
    let only_peak = std::env::args().any(|a| a == "peak");
    if !only_attention && !only_peak {
        quantiser_lines(&isas, reps, &mut r);
    }
    if only_quantiser {
        return;
    }
    if !only_attention {
        peak_lines(&isas, reps, quick);
    }
    if only_peak {
        return;
    }
    // (out, in): the MLP's two matrices (the largest of the model).
    for &(o, i) in if only_attention {
        &[][..]
    } else {
        &[(3072usize, 768usize), (768, 3072)][..]
    } {
        // 64 MB of f32 weights per set: beyond the last-level cache.
        let mats = (64 << 20) / (o * i * 4);
        let wf: Vec<Vec<f32>> = (0..mats).map(|_| r.vec(o * i)).collect();
        let wh: Vec<Vec<u16>> = wf
            .iter()
            .map(|w| {
                w.iter()
                    .map(|&v| half::f16::from_f32(v).to_bits())
                    .collect()
            })
            .collect();
        let wq: Vec<Vec<u8>> = wf.iter().map(|w| quantise_q8_block32(w)).collect();
        let wx: Vec<Vec<u8>> = wf.iter().map(|w| quantise_q8_block32x8(w, i)).collect();
        let b = r.vec(o);
        for &n in &[1usize, 10, 16, 64, 290] {
            let x = r.vec(n * i);
            let mut y = vec![0.0f32; n * o];
            let reps_n = if n >= 64 { reps.min(3) } else { reps };
            let sets = if n >= 64 { 1 } else { mats };
            let mut line = format!("linear {o}x{i} n={n:>3}:");
            let mut base = None;
            for &(isa, amx) in &variants {
                // SAFETY: `supported` lists only ISAs this CPU has; AMX is
                // switched on only where `amx_usable` got the tile permission.
                unsafe {
                    simd::set_isa(isa);
                    amx_switch(amx);
                }
                let label = if amx {
                    format!("{isa:?}+AMX")
                } else {
                    format!("{isa:?}")
                };
                let mut per = Vec::new();
                for (name, pick) in [("f32", 0), ("f16", 1), ("int8", 2), ("int8x8", 3)] {
                    let t = time(reps_n, || {
                        for k in 0..sets {
                            let m = match pick {
                                0 => Matrix::F32(F32Rows::new(&wf[k], o, i).unwrap()),
                                1 => Matrix::F16(F16Rows::new(&wh[k], o, i).unwrap()),
                                2 => Matrix::Q8(Q8Rows::new(&wq[k], o, i).unwrap()),
                                _ => Matrix::X8(X8Rows::new(&wx[k], o, i).unwrap()),
                            };
                            linear(&x, &m, Some(&b), &mut y);
                        }
                        std::hint::black_box(&y);
                    }) / sets as f64;
                    per.push((name, t));
                }
                let f32t = per[0].1;
                base.get_or_insert(per.clone());
                line += &format!(
                    "  [{label}] {}",
                    per.iter()
                        .map(|(nm, t)| format!(
                            "{nm} {:.3} ms ({:.1} GMAC/s, {:.2}x f32)",
                            t * 1e3,
                            (n * o * i) as f64 / t / 1e9,
                            f32t / t
                        ))
                        .collect::<Vec<_>>()
                        .join(", ")
                );
            }
            println!("{line}");
        }
    }
    // The VQ decoders' ConvTranspose1d (512 -> 512 x k=4): `z` for n input
    // rows from f16 weights in PyTorch order (`linear_xw`, what f16 files
    // and int8 files before 2026-12-03 run) and from int8 weights in GEMM
    // order (`linear` over `Q8Block32x8`, what int8 files run now); n = 1-2
    // is one session's step, 16-32 a 16-session `step_many`.
    let (ci, zk) = (512usize, 2048usize);
    let mats = (64 << 20) / (ci * zk * 4);
    let wf: Vec<Vec<f32>> = (0..mats).map(|_| r.vec(ci * zk)).collect();
    let wh: Vec<Vec<u16>> = wf
        .iter()
        .map(|w| {
            w.iter()
                .map(|&v| half::f16::from_f32(v).to_bits())
                .collect()
        })
        .collect();
    // GEMM order (zk, ci) of the same values.
    let wx: Vec<Vec<u8>> = wf
        .iter()
        .map(|w| {
            quantise_q8_block32x8(
                &(0..zk * ci)
                    .map(|k| w[(k % ci) * zk + k / ci])
                    .collect::<Vec<f32>>(),
                ci,
            )
        })
        .collect();
    for &n in if only_attention {
        &[][..]
    } else {
        &[1usize, 2, 16, 32][..]
    } {
        let x = r.vec(n * ci);
        let mut z = vec![0.0f32; n * zk];
        let mut line = format!("conv-transpose z {ci}->{zk} n={n:>2}:");
        for &(isa, amx) in &variants {
            // SAFETY: as for the linear lines.
            unsafe {
                simd::set_isa(isa);
                amx_switch(amx);
            }
            let label = if amx {
                format!("{isa:?}+AMX")
            } else {
                format!("{isa:?}")
            };
            let rows = time(reps, || {
                for w in &wh {
                    linear_xw(&x, &Matrix::F16(F16Rows::new(w, ci, zk).unwrap()), &mut z);
                }
                std::hint::black_box(&z);
            }) / mats as f64;
            let gemm = time(reps, || {
                for w in &wx {
                    linear(
                        &x,
                        &Matrix::X8(X8Rows::new(w, zk, ci).unwrap()),
                        None,
                        &mut z,
                    );
                }
                std::hint::black_box(&z);
            }) / mats as f64;
            line += &format!(
                "  [{label}] f16 x W {:.3} ms, int8x8 GEMM order {:.3} ms ({:.2}x)",
                rows * 1e3,
                gemm * 1e3,
                gemm / rows
            );
        }
        println!("{line}");
    }
    drop((wf, wh, wx));
    // SAFETY: turning the tiles off is always sound.
    unsafe { amx_switch(false) };
    // Attention at the R step's coordinated-attention shape: 290 rows, C 768, 12 heads.
    let (t, streams, c, nh) = (29usize, 10usize, 768usize, 12usize);
    let n = t * streams;
    let (q, k, v) = (r.vec(n * c), r.vec(n * c), r.vec(n * c));
    let mut out = vec![0.0f32; n * c];
    let mut scores = vec![0.0f32; n];
    let mask = TiledCausalMask {
        t_q: t,
        t_k: t,
        q_pos0: 0,
    };
    let mut line = format!("attention {n}x{n} C={c} heads={nh}:");
    for isa in &isas {
        // SAFETY: as above.
        unsafe { simd::set_isa(*isa) };
        let s = time(reps, || {
            attention(&q, &k[..], &v[..], c, nh, &mask, &mut scores, &mut out)
        });
        let alone = time(reps, || {
            attention(
                &q,
                &k[..],
                &v[..],
                c,
                nh,
                &Ungrouped(mask),
                &mut scores,
                &mut out,
            )
        });
        // What R mode runs for these layers since 2026-12-08: per-head GEMMs
        // over the position-major staircase (`attention_staircase`).
        let mut work = vec![0.0f32; gemm_attention_work(n, n, c / nh).unwrap()];
        let gemm = time(reps, || {
            assert!(attention_staircase(&q, &k, &v, c, nh, t, &mut work, &mut out));
        });
        line += &format!(
            "  [{isa:?}] {:.2} ms (queries alone {:.2} ms: {:.2}x; as GEMMs, attention_staircase, {:.2} ms: {:.2}x)",
            s * 1e3,
            alone * 1e3,
            s / alone,
            gemm * 1e3,
            gemm / s
        );
    }
    println!("{line}");
    // Attention as per-head GEMMs (Transflower's encoder layers: 260 rows,
    // width 800, 10 heads of 80): the scores q_h k_h^T (inner length 80) and
    // the output p_h v_h (inner length 260), through `matmul` (the right
    // operand row-major: k_h^T, v_h) against the dot-product tiles of
    // `linear` (k_h and v_h^T as the "weights"), what ran until 2026-12-06.
    // The two forms alternate call by call, so both see the same machine.
    let (n_tf, hd, heads) = (260usize, 80usize, 10usize);
    let (qh, kh, vh) = (r.vec(n_tf * hd), r.vec(n_tf * hd), r.vec(n_tf * hd));
    let transpose = |x: &[f32], rows: usize, cols: usize| {
        let mut t = vec![0.0f32; rows * cols];
        for i in 0..rows {
            for j in 0..cols {
                t[j * rows + i] = x[i * cols + j];
            }
        }
        t
    };
    let (kt, vt) = (transpose(&kh, n_tf, hd), transpose(&vh, n_tf, hd));
    let probs: Vec<f32> = r.vec(n_tf * n_tf).iter().map(|x| x.abs() / n_tf as f32).collect();
    let (mut s_out, mut o_out) = (vec![0.0f32; n_tf * n_tf], vec![0.0f32; n_tf * hd]);
    let mut line = format!("attention as GEMMs {n_tf} rows, {heads} heads of {hd}:");
    for isa in &isas {
        // SAFETY: as above.
        unsafe { simd::set_isa(*isa) };
        let (mut tiles, mut mm) = (Vec::new(), Vec::new());
        for _ in 0..3 * reps {
            let t0 = Instant::now();
            for _ in 0..heads {
                linear(&qh, &Matrix::F32(F32Rows::new(&kh, n_tf, hd).unwrap()), None, &mut s_out);
                linear(&probs, &Matrix::F32(F32Rows::new(&vt, hd, n_tf).unwrap()), None, &mut o_out);
            }
            tiles.push(t0.elapsed().as_secs_f64());
            let t0 = Instant::now();
            for _ in 0..heads {
                duolando_core::kernels::matmul(&qh, &kt, n_tf, hd, n_tf, &mut s_out);
                duolando_core::kernels::matmul(&probs, &vh, n_tf, n_tf, hd, &mut o_out);
            }
            mm.push(t0.elapsed().as_secs_f64());
            std::hint::black_box((&s_out, &o_out));
        }
        let med = |v: &mut Vec<f64>| {
            v.sort_by(|a, b| a.partial_cmp(b).unwrap());
            v[v.len() / 2]
        };
        let (tt, tm) = (med(&mut tiles), med(&mut mm));
        let macs = (heads * 2 * n_tf * n_tf * hd) as f64;
        line += &format!(
            "  [{isa:?}] matmul {:.2} ms ({:.1} GMAC/s), dot tiles {:.2} ms ({:.1} GMAC/s): {:.2}x",
            tm * 1e3,
            macs / tm / 1e9,
            tt * 1e3,
            macs / tt / 1e9,
            tt / tm
        );
    }
    println!("{line}");
    // Attention of one S-step append: the 10 new rows of one position against
    // a full f16 cache (290 keys, read in place), as in every streaming step.
    let to_f16 = |v: &[f32]| {
        v.iter()
            .map(|&x| half::f16::from_f32(x).to_bits())
            .collect::<Vec<u16>>()
    };
    let (k16, v16) = (to_f16(&k), to_f16(&v));
    let mask = TiledCausalMask {
        t_q: 1,
        t_k: t,
        q_pos0: t - 1,
    };
    let mut line = format!("attention S append {streams}x{n} f16 K/V C={c} heads={nh}:");
    for isa in &isas {
        // SAFETY: as above.
        unsafe { simd::set_isa(*isa) };
        let (kr, vr) = (
            KvRows::one(RowData::F16(&k16)),
            KvRows::one(RowData::F16(&v16)),
        );
        let s = time(reps * 20, || {
            attention(
                &q[..streams * c],
                kr,
                vr,
                c,
                nh,
                &mask,
                &mut scores,
                &mut out[..streams * c],
            )
        });
        let alone = time(reps * 20, || {
            attention(
                &q[..streams * c],
                kr,
                vr,
                c,
                nh,
                &Ungrouped(mask),
                &mut scores,
                &mut out[..streams * c],
            )
        });
        line += &format!(
            "  [{isa:?}] {:.3} ms (queries alone {:.3} ms: {:.2}x)",
            s * 1e3,
            alone * 1e3,
            s / alone
        );
    }
    println!("{line}");
    // The appends of 16 sessions x 12 layers in one `step_many`, each over its
    // own cache (192 caches, 171 MB: read cold from memory), against as many
    // appends over one cache (hot): how much of the memory time is hidden.
    let caches: Vec<(Vec<u16>, Vec<u16>)> = (0..16 * 12)
        .map(|_| (to_f16(&r.vec(n * c)), to_f16(&r.vec(n * c))))
        .collect();
    let mut line = format!(
        "attention S append x{} caches (16 sessions x 12 layers):",
        caches.len()
    );
    for isa in &isas {
        // SAFETY: as above.
        unsafe { simd::set_isa(*isa) };
        let cold = time(reps, || {
            for (kc, vc) in &caches {
                let (kr, vr) = (KvRows::one(RowData::F16(kc)), KvRows::one(RowData::F16(vc)));
                attention(
                    &q[..streams * c],
                    kr,
                    vr,
                    c,
                    nh,
                    &mask,
                    &mut scores,
                    &mut out[..streams * c],
                );
            }
        });
        // As `step_many` attends them: the next session's keys and values
        // prefetched while this one computes (`attention_ahead`).
        let ahead = time(reps, || {
            for (i, (kc, vc)) in caches.iter().enumerate() {
                let (kr, vr) = (KvRows::one(RowData::F16(kc)), KvRows::one(RowData::F16(vc)));
                let next = caches.get(i + 1).map_or([&[][..], &[][..]], |(kn, vn)| {
                    [bytemuck::cast_slice(kn), bytemuck::cast_slice(vn)]
                });
                attention_ahead(
                    &q[..streams * c],
                    kr,
                    vr,
                    c,
                    nh,
                    &mask,
                    &mut scores,
                    &mut out[..streams * c],
                    next,
                );
            }
        });
        let (kr, vr) = (
            KvRows::one(RowData::F16(&caches[0].0)),
            KvRows::one(RowData::F16(&caches[0].1)),
        );
        let hot = time(reps, || {
            for _ in 0..caches.len() {
                attention(
                    &q[..streams * c],
                    kr,
                    vr,
                    c,
                    nh,
                    &mask,
                    &mut scores,
                    &mut out[..streams * c],
                );
            }
        });
        // The same caches head-major (a session's GPT cache): each head's
        // rows one contiguous stretch.
        fn hm(d: &[u16], n: usize, hd: usize) -> KvRows<'_> {
            KvRows::head_major(RowData::F16(d), n, n, hd).unwrap()
        }
        let cold_hm = time(reps, || {
            for (kc, vc) in &caches {
                attention(
                    &q[..streams * c],
                    hm(kc, n, c / nh),
                    hm(vc, n, c / nh),
                    c,
                    nh,
                    &mask,
                    &mut scores,
                    &mut out[..streams * c],
                );
            }
        });
        let ahead_hm = time(reps, || {
            for (i, (kc, vc)) in caches.iter().enumerate() {
                let next = caches.get(i + 1).map_or([&[][..], &[][..]], |(kn, vn)| {
                    [bytemuck::cast_slice(kn), bytemuck::cast_slice(vn)]
                });
                attention_ahead(
                    &q[..streams * c],
                    hm(kc, n, c / nh),
                    hm(vc, n, c / nh),
                    c,
                    nh,
                    &mask,
                    &mut scores,
                    &mut out[..streams * c],
                    next,
                );
            }
        });
        line += &format!(
            "  [{isa:?}] {:.2} ms (the next cache prefetched meanwhile {:.2} ms: {:.2}x; one hot cache {:.2} ms: {:.2}x; head-major {:.2} ms, prefetched {:.2} ms: {:.2}x / {:.2}x row-major)",
            cold * 1e3,
            ahead * 1e3,
            ahead / cold,
            hot * 1e3,
            cold / hot,
            cold_hm * 1e3,
            ahead_hm * 1e3,
            cold_hm / cold,
            ahead_hm / ahead
        );
    }
    println!("{line}");
    drop(caches);
    // The softmax exponentials and the MLP's GELU against libm in the same run
    // (the R step's 290-key scores; one MLP hidden of 290 rows).
    let libm_exp = |s: &mut [f32], max: f32| {
        s.iter_mut().fold(0.0f32, |a, v| {
            *v = libm::expf(*v - max);
            a + *v
        })
    };
    let libm_gelu = |x: &mut [f32]| {
        x.iter_mut()
            .for_each(|v| *v = 0.5 * *v * (1.0 + libm::erff(*v * std::f32::consts::FRAC_1_SQRT_2)))
    };
    let x0: Vec<f32> = r.vec(290 * 4 * c).iter().map(|v| v * 4.0).collect();
    let mut x = x0.clone();
    let mut line = format!("exp (softmax, rows of 290) / GELU ({} values):", x0.len());
    let t_libm_exp = time(reps, || {
        x.copy_from_slice(&x0);
        for row in x.chunks_mut(290) {
            std::hint::black_box(libm_exp(row, 1.0));
        }
    });
    let t_libm_gelu = time(reps, || {
        x.copy_from_slice(&x0);
        libm_gelu(&mut x);
        std::hint::black_box(&x);
    });
    line += &format!(
        "  [libm] exp {:.2} ms, GELU {:.2} ms",
        t_libm_exp * 1e3,
        t_libm_gelu * 1e3
    );
    for isa in &isas {
        // SAFETY: as above.
        unsafe { simd::set_isa(*isa) };
        let te = time(reps, || {
            x.copy_from_slice(&x0);
            for row in x.chunks_mut(290) {
                std::hint::black_box(simd::exp_shifted_sum(row, 1.0));
            }
        });
        let tg = time(reps, || {
            x.copy_from_slice(&x0);
            simd::gelu_inplace(&mut x);
            std::hint::black_box(&x);
        });
        line += &format!(
            "  [{isa:?}] exp {:.2} ms ({:.1}x libm), GELU {:.2} ms ({:.1}x libm)",
            te * 1e3,
            t_libm_exp / te,
            tg * 1e3,
            t_libm_gelu / tg
        );
    }
    println!("{line}");
}

/// Switches the AMX int8 tiles on or off (x86_64; nothing elsewhere).
///
/// # Safety
/// With `on`: as `simd::amx::enable`.
#[allow(unused_variables)]
unsafe fn amx_switch(on: bool) {
    #[cfg(target_arch = "x86_64")]
    // SAFETY: the caller's.
    unsafe {
        simd::amx::enable(on)
    };
}
