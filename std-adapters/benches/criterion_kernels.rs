//! Criterion benches of the kernels and of one streaming step, with
//! criterion's statistics (confidence intervals, change detection between
//! runs): `linear` at the MLP shape (3072x768) for f32 / f16 / int8 weights
//! and 1 / 16 / 290 activation rows, the attention kernel at the R step's
//! coordinated-attention shape, and the streaming step of the tiny fixture
//! model (the full-size steps are in `duolando bench`, which also prints
//! ratios against memcpy bandwidth measured in the same run).
//!
//! `cargo bench -p duolando --bench criterion_kernels [-- FILTER]`

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use duolando::duo_writer::{quantise_q8_block32, quantise_q8_block32x8};
use duolando::model_file::ModelFile;
use duolando_core::duolando::model::Model;
use duolando_core::duolando::session::{Session, SessionConfig};
use duolando_core::kernels::{
    attention, linear, F16Rows, F32Rows, Matrix, Q8Rows, TiledCausalMask, X8Rows,
};

mod common;
use common::Rng;

fn linear_mlp(c: &mut Criterion) {
    duolando::simd::init();
    let (o, i) = (3072usize, 768usize);
    let mut r = Rng(0x5eed);
    let wf = r.vec(o * i);
    let wh: Vec<u16> = wf
        .iter()
        .map(|&v| half::f16::from_f32(v).to_bits())
        .collect();
    let wq = quantise_q8_block32(&wf);
    let wx = quantise_q8_block32x8(&wf, i);
    let b = r.vec(o);
    let mut g = c.benchmark_group("linear_3072x768");
    g.sample_size(20);
    for &n in &[1usize, 16, 290] {
        let x = r.vec(n * i);
        let mut y = vec![0.0f32; n * o];
        g.throughput(Throughput::Elements((n * o * i) as u64));
        for (name, pick) in [("f32", 0), ("f16", 1), ("int8", 2), ("int8x8", 3)] {
            g.bench_with_input(BenchmarkId::new(name, n), &n, |bch, _| {
                bch.iter(|| {
                    let m = match pick {
                        0 => Matrix::F32(F32Rows::new(&wf, o, i).unwrap()),
                        1 => Matrix::F16(F16Rows::new(&wh, o, i).unwrap()),
                        2 => Matrix::Q8(Q8Rows::new(&wq, o, i).unwrap()),
                        _ => Matrix::X8(X8Rows::new(&wx, o, i).unwrap()),
                    };
                    linear(&x, &m, Some(&b), &mut y);
                    std::hint::black_box(&y);
                })
            });
        }
    }
    g.finish();
}

fn attention_r_step(c: &mut Criterion) {
    duolando::simd::init();
    // The R step's coordinated attention: 10 streams x 29 tokens, C 768, 12 heads.
    let (t, c_dim, heads) = (290usize, 768usize, 12usize);
    let mut r = Rng(7);
    let (q, k, v) = (r.vec(t * c_dim), r.vec(t * c_dim), r.vec(t * c_dim));
    let mask = TiledCausalMask {
        t_q: 29,
        t_k: 29,
        q_pos0: 0,
    };
    let mut scores = vec![0.0f32; t];
    let mut out = vec![0.0f32; t * c_dim];
    let mut g = c.benchmark_group("attention");
    g.sample_size(20);
    g.bench_function("r_step_290x290_c768_h12", |bch| {
        bch.iter(|| {
            attention(
                &q,
                &k[..],
                &v[..],
                c_dim,
                heads,
                &mask,
                &mut scores,
                &mut out,
            );
            std::hint::black_box(&out);
        })
    });
    g.finish();
}

fn streaming_step_tiny(c: &mut Criterion) {
    duolando::simd::init();
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/fixtures");
    let mf = ModelFile::open(dir.join("tiny/model.duo")).expect("tests/fixtures/tiny/model.duo");
    let duo = mf.duo().unwrap();
    let model = Model::from_duo(&duo).unwrap();
    let sc = SessionConfig::reference(&model.cfg);
    let mut arena = vec![0u8; model.session_bytes(&sc).unwrap()];
    let n_music = model.cfg.gpt.music.n_in as usize;
    // A long synthetic track so the bench never runs out of music.
    let frames = 1 << 16;
    let mut r = Rng(3);
    let music: Vec<f32> = (0..frames * n_music).map(|_| r.f()).collect();
    let base: Vec<f32> = (0..165)
        .map(|j| (j % 3) as f32 * 0.3 + r.f() * 0.05)
        .collect();
    let mut s = Session::new(&model, &mut arena, &sc, [0, 0, 0, 0, 0]).unwrap();
    s.set_music_track(&music).unwrap();
    let mut frame = duolando_core::duolando::session::FollowerFrame::default();
    let mut leader = base.clone();
    let mut t = 0u64;
    let mut g = c.benchmark_group("session");
    g.sample_size(30);
    // One step = 4 leader frames (one token); frames are pulled as they come.
    g.bench_function("tiny_reference_one_step", |bch| {
        bch.iter(|| {
            for _ in 0..4 {
                t += 1;
                for (j, l) in leader.iter_mut().enumerate() {
                    *l = base[j] + 0.05 * ((t as f32) * 0.1 + j as f32).sin();
                }
                if s.push_leader_frame(&leader).is_err() {
                    // End of the synthetic track: start over.
                    s.reset([0, 0, 0, 0, 0]).unwrap();
                    t = 0;
                }
                while s.pull_follower_frame(&mut frame).unwrap() {}
            }
            std::hint::black_box(&frame);
        })
    });
    g.finish();
}

criterion_group!(benches, linear_mlp, attention_r_step, streaming_step_tiny);
criterion_main!(benches);
