//! A LAT whose inputs are narrower than the model width (the music LAT:
//! 54-wide frames, C 128 in the demo model, 768 at full size) keeps those
//! inputs for the positions waiting for their look-ahead and applies
//! `cond_emb` to them again when their queries run, instead of keeping the
//! C-wide residual rows: the same output rows bit for bit, in less memory.
//! Both kinds side by side in one push and apart, f16 and int8 weights,
//! bursts of 1-4 positions. A LAT whose inputs are tokens (the leader
//! LATs) keeps their ids (4 bytes a position, not a C-wide row) and embeds
//! them again: the same rows as a LAT keeping residuals.

use duolando::convert::storage_for;
use duolando::duo_writer::StoreAs;
use duolando_core::arena::{Arena, Planner};
use duolando_core::duolando::model::Model;
use duolando_core::duolando::session::lat_stream::{
    max_keys, LatIn, LatInputs, LatStepScratch, LatStream,
};
use duolando_core::nn::block::BlockScratch;
use duolando_core::nn::kv_store::KvType;
use duolando_tests::{demo_model, restore_as, Rng};

/// `f` on the demo model in f16 and again re-stored as int8 (the kernels this CPU selects).
fn each_demo_model(f: impl Fn(&str, &Model<'_>)) {
    duolando::simd::init();
    let f16 = demo_model();
    let int8 = restore_as(&f16, &|spec| storage_for(StoreAs::Q8Block32, spec));
    for (name, file) in [("f16", &f16), ("int8", &int8)] {
        let duo = file.duo().unwrap();
        f(name, &Model::from_duo(&duo).unwrap());
    }
}

fn bits(v: &[f32]) -> Vec<u32> {
    v.iter().map(|x| x.to_bits()).collect()
}

#[test]
fn kept_inputs_give_the_rows_of_kept_residuals() {
    each_demo_model(|name, model| {
        let w = &model.gpt.music;
        let (c, n_in) = (model.cfg.gpt.n_embd as usize, w.cfg.n_in as usize);
        assert!(
            n_in < c,
            "the demo model's music inputs are narrower than C"
        );
        let (ds, layers) = (w.cfg.downsample_rate as usize, w.cfg.n_layer as usize);
        let (past, fut, burst) = (5 * ds, 3 * ds, ds.min(4));
        let size = |width: usize| {
            let mut p = Planner::new();
            LatStream::carve(
                &mut p,
                KvType::F16,
                layers,
                ds,
                c,
                LatIn::Rows(width),
                past,
                fut,
                burst,
            )
            .unwrap();
            p.bytes()
        };
        assert!(
            size(n_in) + (fut + burst) * (c - n_in) * 4 <= size(c),
            "{name}: {} vs {}",
            size(n_in),
            size(c)
        );
        let (mut ba, mut bb) = (vec![0u8; size(n_in) + 64], vec![0u8; size(c) + 64]);
        let (mut aa, mut ab) = (Arena::new(&mut ba), Arena::new(&mut bb));
        let mut inputs = LatStream::carve(
            &mut aa,
            KvType::F16,
            layers,
            ds,
            c,
            LatIn::Rows(n_in),
            past,
            fut,
            burst,
        )
        .unwrap();
        let mut residuals = LatStream::carve(
            &mut ab,
            KvType::F16,
            layers,
            ds,
            c,
            LatIn::Rows(c),
            past,
            fut,
            burst,
        )
        .unwrap();
        let mut sb = vec![0u8; 4 << 20];
        let mut sa = Arena::new(&mut sb);
        let mut s = LatStepScratch::carve(&mut sa, c, ds, 2, 2 * burst, n_in).unwrap();
        let mut blk =
            BlockScratch::carve_keys(&mut sa, 2 * burst, max_keys(past, fut).max(2 * burst), c)
                .unwrap();
        let mut r = Rng(0x1a7);
        let (mut rows, mut pushed) = (0usize, 0usize);
        for step in 0..40 {
            let cnt = 1 + step % burst;
            let x = r.vec(cnt * n_in);
            let mut out = vec![f32::NAN; 2 * c];
            let mut made = [false; 2];
            // Alternately both LATs in one push (mixed kinds) and one push each.
            if step % 2 == 0 {
                let xx: Vec<f32> = x.iter().chain(&x).copied().collect();
                LatStream::push_many(
                    w,
                    &mut [&mut inputs, &mut residuals],
                    &[cnt, cnt],
                    LatInputs::Rows(&xx),
                    &mut s,
                    &mut blk,
                    &mut out,
                    &mut made,
                )
                .unwrap();
            } else {
                let (o0, o1) = out.split_at_mut(c);
                let (m0, m1) = made.split_at_mut(1);
                LatStream::push_many(
                    w,
                    &mut [&mut inputs],
                    &[cnt],
                    LatInputs::Rows(&x),
                    &mut s,
                    &mut blk,
                    o0,
                    m0,
                )
                .unwrap();
                LatStream::push_many(
                    w,
                    &mut [&mut residuals],
                    &[cnt],
                    LatInputs::Rows(&x),
                    &mut s,
                    &mut blk,
                    o1,
                    m1,
                )
                .unwrap();
            }
            pushed += cnt;
            assert_eq!(made[0], made[1], "{name} step {step}");
            if made[0] {
                rows += 1;
                assert!(out.iter().all(|v| v.is_finite()), "{name} step {step}");
                assert_eq!(
                    bits(&out[..c]),
                    bits(&out[c..]),
                    "{name} step {step}: row {rows}"
                );
            }
        }
        assert_eq!(inputs.pushed(), pushed);
        assert!(rows >= 4, "{name}: {rows} rows");
    });
}

#[test]
fn kept_tokens_give_the_rows_of_kept_residuals() {
    each_demo_model(|name, model| {
        for part in 0..4 {
            let w = &model.gpt.leaders[part];
            let table = &model.gpt.tok_emb[part];
            let c = model.cfg.gpt.n_embd as usize;
            let (ds, layers) = (w.cfg.downsample_rate as usize, w.cfg.n_layer as usize);
            assert_eq!(ds, 1, "leader LATs take one token a position");
            let (past, fut) = (5, 3 + part);
            let size = |input: LatIn| {
                let mut p = Planner::new();
                LatStream::carve(&mut p, KvType::F16, layers, ds, c, input, past, fut, 1).unwrap();
                p.bytes()
            };
            // A held id is 4 bytes where a residual row is 4C (the ids' ring rounded up to 64 bytes).
            assert!(
                size(LatIn::Tokens) + (fut + 1) * c * 4 <= size(LatIn::Rows(c)) + 64,
                "{name}: {} vs {}",
                size(LatIn::Tokens),
                size(LatIn::Rows(c))
            );
            let (mut ba, mut bb) = (
                vec![0u8; size(LatIn::Tokens) + 64],
                vec![0u8; size(LatIn::Rows(c)) + 64],
            );
            let (mut aa, mut ab) = (Arena::new(&mut ba), Arena::new(&mut bb));
            let mut tokens = LatStream::carve(
                &mut aa,
                KvType::F16,
                layers,
                ds,
                c,
                LatIn::Tokens,
                past,
                fut,
                1,
            )
            .unwrap();
            let mut residuals = LatStream::carve(
                &mut ab,
                KvType::F16,
                layers,
                ds,
                c,
                LatIn::Rows(c),
                past,
                fut,
                1,
            )
            .unwrap();
            let mut sb = vec![0u8; 4 << 20];
            let mut sa = Arena::new(&mut sb);
            let mut s = LatStepScratch::carve(&mut sa, c, ds, 2, 2, c).unwrap();
            let mut blk =
                BlockScratch::carve_keys(&mut sa, 2, max_keys(past, fut).max(2), c).unwrap();
            let mut r = Rng(0x70c + part as u64);
            let vocab = table.rows() as u32;
            let mut rows = 0usize;
            for step in 0..30 {
                let id = (r.vec(1)[0].abs() * 1e4) as u32 % vocab;
                let mut out = vec![f32::NAN; 2 * c];
                let mut made = [false; 2];
                if step % 2 == 0 {
                    let ids = [id, id];
                    LatStream::push_many(
                        w,
                        &mut [&mut tokens, &mut residuals],
                        &[1, 1],
                        LatInputs::Tokens(&ids, table),
                        &mut s,
                        &mut blk,
                        &mut out,
                        &mut made,
                    )
                    .unwrap();
                } else {
                    let (o0, o1) = out.split_at_mut(c);
                    let (m0, m1) = made.split_at_mut(1);
                    LatStream::push_many(
                        w,
                        &mut [&mut tokens],
                        &[1],
                        LatInputs::Tokens(&[id], table),
                        &mut s,
                        &mut blk,
                        o0,
                        m0,
                    )
                    .unwrap();
                    LatStream::push_many(
                        w,
                        &mut [&mut residuals],
                        &[1],
                        LatInputs::Tokens(&[id], table),
                        &mut s,
                        &mut blk,
                        o1,
                        m1,
                    )
                    .unwrap();
                }
                assert_eq!(made[0], made[1], "{name} part {part} step {step}");
                if made[0] {
                    rows += 1;
                    assert!(
                        out.iter().all(|v| v.is_finite()),
                        "{name} part {part} step {step}"
                    );
                    assert_eq!(
                        bits(&out[..c]),
                        bits(&out[c..]),
                        "{name} part {part} step {step}: row {rows}"
                    );
                }
            }
            assert_eq!(rows, 30 - fut, "{name} part {part}");
            // A token outside the table is refused.
            let mut out = vec![0.0; c];
            let e = LatStream::push_many(
                w,
                &mut [&mut tokens],
                &[1],
                LatInputs::Tokens(&[vocab], table),
                &mut s,
                &mut blk,
                &mut out,
                &mut [false],
            );
            assert!(e.is_err(), "{name} part {part}: token {vocab} of {vocab}");
        }
    });
}
