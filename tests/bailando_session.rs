//! Bailando S mode (`bailando::session`): at the exact preset the
//! authors' goldens (tokens exact, positions within R's tolerance), at
//! every other budget its own oracle built from R's functions (the GPT
//! over the chunked windows the budget schedules, the decoders over the
//! token prefix a frame waits for), batched stepping bit for bit equal to
//! sessions alone, no allocation after the arena, and named refusals that
//! leave the session unchanged.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::path::Path;

use duolando::convert::bailando::convert_bailando;
use duolando::convert::parse_bailando_config;
use duolando::duo_writer::StoreAs;
use duolando::model_file::ModelFile;
use duolando::npy::{read_f32_2d, read_i64_2d};
use duolando_core::bailando::config::{BailandoConfig, DOWN_JOINTS, POSE_DIM, UP_JOINTS};
use duolando_core::bailando::exact::{padded_rows, MusicPadding};
use duolando_core::bailando::gpt::{logits_len, max_context, window_logits, GptScratch};
use duolando_core::bailando::model::Model;
use duolando_core::bailando::session::{
    dec_future_max, window_rows, CacheSchedule, Preset, Session, SessionConfig, StepBatch,
    PREFILL_CHUNK,
};
use duolando_core::error::{Buffer, Error, Setting};
use duolando_core::nn::conv_stack::ConvScratch;
use duolando_core::nn::kv_store::KvType;
use duolando_core::nn::sampler::{argmax, Sampling};
use duolando_core::nn::vq_decoder;
use duolando_core::nn::window::window_context;
use duolando_tests::{fixture, max_errors};

/// R's position tolerance (tests/bailando_exact.rs).
const POS_TOL: f32 = 1e-5;

struct Counting;
thread_local! {
    static COUNTING: Cell<bool> = const { Cell::new(false) };
    static COUNT: Cell<usize> = const { Cell::new(0) };
}
// SAFETY: every method forwards to `System` unchanged (plus a thread-local
// counter), so `System`'s guarantees are ours.
unsafe impl GlobalAlloc for Counting {
    // SAFETY (all methods): GlobalAlloc's contract, forwarded to `System`.
    unsafe fn alloc(&self, l: Layout) -> *mut u8 {
        if COUNTING.with(|c| c.get()) {
            COUNT.with(|c| c.set(c.get() + 1));
        }
        // SAFETY: forwards the caller's layout to the system allocator unchanged.
        unsafe { System.alloc(l) }
    }
    // SAFETY: see `alloc`.
    unsafe fn dealloc(&self, p: *mut u8, l: Layout) {
        // SAFETY: `p` was allocated by `System` with layout `l`.
        unsafe { System.dealloc(p, l) }
    }
    // SAFETY: see `alloc`.
    unsafe fn realloc(&self, p: *mut u8, l: Layout, n: usize) -> *mut u8 {
        if COUNTING.with(|c| c.get()) {
            COUNT.with(|c| c.set(c.get() + 1));
        }
        // SAFETY: as in `alloc`/`dealloc`.
        unsafe { System.realloc(p, l, n) }
    }
}
#[global_allocator]
static GLOBAL: Counting = Counting;

fn allocations_during(f: impl FnOnce()) -> usize {
    COUNT.with(|c| c.set(0));
    COUNTING.with(|c| c.set(true));
    f();
    COUNTING.with(|c| c.set(false));
    COUNT.with(|c| c.get())
}

/// A fixture model converted to a `.duo` in memory (f32), as a user's.
fn model_file(name: &str, yaml: &str) -> (BailandoConfig, ModelFile) {
    let dir = fixture(&format!("bailando_{name}"));
    let path = dir.join(yaml);
    let cfg = parse_bailando_config(&path, &std::fs::read_to_string(&path).unwrap()).unwrap();
    let (g, v) = (
        std::fs::read(dir.join("gpt.safetensors")).unwrap(),
        std::fs::read(dir.join("vqvae.safetensors")).unwrap(),
    );
    let (bytes, _) = convert_bailando(
        &cfg,
        (&dir.join("gpt.safetensors"), &g),
        (&dir.join("vqvae.safetensors"), &v),
        StoreAs::F32,
        Path::new("<memory>"),
    )
    .unwrap();
    (cfg, ModelFile::from_bytes(bytes).unwrap())
}

struct Golden {
    music: Vec<f32>,
    padding: MusicPadding,
    seed: [u32; 2],
    tokens: Vec<u32>,
    pos: Vec<f32>,
}

fn golden(name: &str, cfg: &BailandoConfig) -> Golden {
    let dir = fixture(&format!("bailando_rollout_{name}"));
    let meta: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join("meta.json")).unwrap()).unwrap();
    let m = read_f32_2d(&dir.join("music.npy"), None, "music").unwrap();
    let nm = cfg.gpt.n_music as usize;
    let music = m
        .data
        .chunks_exact(m.cols)
        .flat_map(|r| r[..nm].to_vec())
        .collect();
    let padding = if meta["path"].as_str().unwrap() == "aist" {
        MusicPadding::Aist
    } else {
        MusicPadding::Demo
    };
    let tokens: Vec<u32> = read_i64_2d(&dir.join("tokens.npy"), Some(2), "tokens")
        .unwrap()
        .data
        .iter()
        .map(|&t| t as u32)
        .collect();
    let pos = read_f32_2d(&dir.join("pos3d.npy"), Some(POSE_DIM), "pos3d")
        .unwrap()
        .data;
    Golden {
        music,
        padding,
        seed: [tokens[0], tokens[1]],
        tokens,
        pos,
    }
}

/// Every frame of a session fed `music` (live: one row, then every frame
/// it gives; or the whole track first), then finished.
fn run(
    s: &mut Session<'_>,
    music: &[f32],
    nm: usize,
    padding: MusicPadding,
    live: bool,
) -> (Vec<u32>, Vec<f32>) {
    let mut frames = Vec::new();
    let mut f = [0f32; POSE_DIM];
    let mut pull_all = |s: &mut Session<'_>, frames: &mut Vec<f32>| {
        while let Some(i) = s.pull(&mut f).unwrap() {
            assert_eq!(i as usize, frames.len() / POSE_DIM);
            frames.extend_from_slice(&f);
        }
    };
    if live {
        for row in music.chunks_exact(nm) {
            s.push_music(row).unwrap();
            pull_all(s, &mut frames);
        }
    } else {
        s.push_music(music).unwrap();
    }
    s.finish(padding).unwrap();
    pull_all(s, &mut frames);
    assert!(s.done());
    let tokens = (0..s.tokens())
        .flat_map(|i| s.token(i).map(|t| t.to_vec()).unwrap_or_default())
        .collect();
    (tokens, frames)
}

const GOLDENS: [(&str, &str, &str); 8] = [
    ("btiny_aist_min", "btiny", "actor_critic.yaml"),
    ("btiny_aist_slide", "btiny", "actor_critic.yaml"),
    ("btiny_demo_min", "btiny", "actor_critic_demo.yaml"),
    ("btiny_demo_odd", "btiny", "actor_critic_demo.yaml"),
    ("btiny2_aist_odd", "btiny2", "actor_critic.yaml"),
    ("btiny2_aist_short", "btiny2", "actor_critic.yaml"),
    ("btiny2_demo_exact", "btiny2", "actor_critic_demo.yaml"),
    ("btiny2_demo_slide", "btiny2", "actor_critic_demo.yaml"),
];

/// The exact preset gives the authors' tokens and frames, live and with
/// the track pushed ahead, f32 and f16 K/V (f16: tokens compared only
/// where the goldens' margins allow; reported).
#[test]
fn exact_preset_gives_the_goldens() {
    for (name, model, yaml) in GOLDENS {
        let (cfg, file) = model_file(model, yaml);
        let duo = file.duo().unwrap();
        let m = Model::from_duo(&duo).unwrap();
        let g = golden(name, &cfg);
        let nm = cfg.gpt.n_music as usize;
        let rows = g.music.len() / nm;
        for live in [true, false] {
            let sc = SessionConfig {
                music_buffer_rows: rows as u32,
                ..SessionConfig::preset(&cfg, Preset::Exact)
            };
            let mut arena = vec![0u8; m.session_bytes(&sc).unwrap()];
            let mut s = Session::new(&m, &mut arena, &sc, g.seed).unwrap();
            // The session keeps the last block_size tokens: compare the tail.
            let (tokens, frames) = run(&mut s, &g.music, nm, g.padding, live);
            let n_tok = padded_rows(g.padding, rows);
            assert_eq!(s.tokens(), n_tok, "{name}");
            assert_eq!(
                &tokens[..],
                &g.tokens[g.tokens.len() - tokens.len()..],
                "{name} live {live}: tokens"
            );
            assert_eq!(frames.len(), g.pos.len(), "{name}: frames");
            let (abs, _) = max_errors(&frames, &g.pos);
            eprintln!(
                "{name} live {live}: {} frames, max abs err {abs:.2e}",
                frames.len() / POSE_DIM
            );
            assert!(
                abs <= POS_TOL,
                "{name} live {live}: positions max abs err {abs:e}"
            );
        }
    }
}

/// R's functions over the windows and prefixes a budget schedules: the
/// tokens (greedy) and, for each token q, its frames decoded from tokens
/// `..=min(q + d, last)` (what S has when it gives them).
fn oracle(
    m: &Model<'_>,
    music: &[f32],
    padding: MusicPadding,
    seed: [u32; 2],
    d: usize,
    shift: usize,
) -> (Vec<u32>, Vec<f32>) {
    let cfg = &m.cfg;
    let nm = cfg.gpt.n_music as usize;
    let rows = music.len() / nm;
    let n_tok = padded_rows(padding, rows);
    let win = window_rows(cfg);
    let mut bytes = vec![0u8; 8 << 20];
    let mut a = duolando_core::arena::Arena::new(&mut bytes);
    let mut gs = GptScratch::carve(&mut a, cfg, max_context(cfg)).unwrap();
    let mut logits = vec![0f32; logits_len(cfg)];
    let mut tokens = seed.to_vec();
    let vu = cfg.gpt.vocab[0] as usize;
    for k in 0..n_tok - 1 {
        let c = window_context(k, win, shift);
        let lo = k + 1 - c;
        let mus: Vec<f32> = (lo..=k)
            .flat_map(|j| music[(j + 1).min(rows - 1) * nm..][..nm].to_vec())
            .collect();
        window_logits(m, &tokens[2 * lo..2 * (k + 1)], &mus, &mut gs, &mut logits).unwrap();
        tokens.push(argmax(&logits[..vu]));
        tokens.push(argmax(&logits[vu..]));
    }
    // Token q's frames from the decoders run on tokens ..=q + d, the root
    // integrated over the velocities of each token as it was given.
    let hop = cfg.hop();
    let mut frames = Vec::new();
    let mut r = [0f32; 3];
    for q in 0..n_tok {
        let last = (q + d).min(n_tok - 1);
        let n = (last + 1) * hop;
        let mut bytes = vec![0u8; 64 << 20];
        let mut a = duolando_core::arena::Arena::new(&mut bytes);
        let mut conv = ConvScratch::carve(&mut a, &cfg.vqs(), n).unwrap();
        let mut outs: Vec<Vec<f32>> = Vec::new();
        for (h, w) in [
            (0usize, UP_JOINTS.len() * 3),
            (1, DOWN_JOINTS.len() * 3),
            (2, 3),
        ] {
            let vq = &m.parts[h.min(1)];
            let dec = if h == 2 { &m.root } else { &vq.pos };
            let codes: Vec<u32> = (0..=last).map(|i| tokens[2 * i + h.min(1)]).collect();
            let mut out = vec![0f32; n * w];
            vq_decoder::decode(vq, dec, &codes, h.min(1) as u8, &mut conv, &mut out).unwrap();
            outs.push(out);
        }
        for f in q * hop..(q + 1) * hop {
            let mut row = [0f32; POSE_DIM];
            for (h, joints) in [&UP_JOINTS[..], &DOWN_JOINTS[..]].into_iter().enumerate() {
                for (i, &j) in joints.iter().enumerate() {
                    row[3 * j as usize..][..3]
                        .copy_from_slice(&outs[h][(f * joints.len() + i) * 3..][..3]);
                }
            }
            row[..3].copy_from_slice(&r);
            for j in 1..POSE_DIM / 3 {
                for k in 0..3 {
                    row[3 * j + k] += r[k];
                }
            }
            for k in 0..3 {
                r[k] += outs[2][f * 3 + k];
            }
            frames.extend_from_slice(&row);
        }
    }
    (tokens, frames)
}

/// Every budget equals its oracle: window shifts from 1 to sliding,
/// decoder futures from 0 to the maximum, both eval paths, f32 K/V.
#[test]
fn budgets_equal_their_oracles() {
    for (name, model, yaml) in [GOLDENS[1], GOLDENS[3], GOLDENS[7]] {
        let (cfg, file) = model_file(model, yaml);
        let duo = file.duo().unwrap();
        let m = Model::from_duo(&duo).unwrap();
        let g = golden(name, &cfg);
        let nm = cfg.gpt.n_music as usize;
        let rows = g.music.len() / nm;
        let win = window_rows(&cfg) as u32;
        let dmax = dec_future_max(&cfg);
        for (d, shift) in [
            (0, 1),
            (1, win / 2),
            (dmax / 2, win - 1),
            (dmax, 3),
            (0, win),
        ] {
            let (want_t, want_f) =
                oracle(&m, &g.music, g.padding, g.seed, d as usize, shift as usize);
            let mut reprefill = None;
            for schedule in [CacheSchedule::Reprefill, CacheSchedule::Spread] {
                let sc = SessionConfig {
                    music_buffer_rows: rows as u32,
                    schedule,
                    ..SessionConfig::with(d, shift)
                };
                let mut arena = vec![0u8; m.session_bytes(&sc).unwrap()];
                let mut s = Session::new(&m, &mut arena, &sc, g.seed).unwrap();
                let (tokens, frames) = run(&mut s, &g.music, nm, g.padding, true);
                assert_eq!(
                    &tokens[..],
                    &want_t[want_t.len() - tokens.len()..],
                    "{name} d {d} s {shift} {schedule:?}: tokens"
                );
                let (abs, _) = max_errors(&frames, &want_f);
                eprintln!("{name} d {d} shift {shift} {schedule:?}: {} frames, max abs err vs oracle {abs:.2e}, rows re-prefilled {}, appended ahead {}", frames.len() / POSE_DIM, s.prefilled, s.spread_rows);
                assert!(
                    abs <= POS_TOL,
                    "{name} d {d} s {shift}: positions max abs err {abs:e}"
                );
                // The spread schedule computes the same numbers, re-prefilling
                // (at most) the first jump's rows instead of every jump's.
                match reprefill.take() {
                    None => reprefill = Some((frames, s.prefilled)),
                    Some((f, p)) => {
                        assert!(
                            f.iter()
                                .zip(&frames)
                                .all(|(a, b)| a.to_bits() == b.to_bits()),
                            "{name} d {d} s {shift}: spread differs from reprefill"
                        );
                        if p > 2 * win as usize {
                            assert!(s.prefilled < p / 2, "{name} d {d} s {shift}: spread re-prefilled {} rows, reprefill {p}", s.prefilled);
                        }
                    }
                }
            }
        }
    }
}

/// Sessions of different budgets and lengths stepped together give each
/// session's own frames, bit for bit, and hold no step memory of their
/// own; no allocation once the arenas exist.
#[test]
fn batched_sessions_equal_sessions_alone_without_allocating() {
    let (cfg, file) = model_file("btiny2", "actor_critic_demo.yaml");
    let duo = file.duo().unwrap();
    let m = Model::from_duo(&duo).unwrap();
    let g = golden("btiny2_demo_slide", &cfg);
    let nm = cfg.gpt.n_music as usize;
    let rows = g.music.len() / nm;
    let win = window_rows(&cfg) as u32;
    let cfgs = [
        SessionConfig {
            kv: KvType::F16,
            ..SessionConfig::with(2, win / 2)
        },
        SessionConfig {
            sampling: Sampling::TopK { k: 4, rng_seed: 7 },
            schedule: CacheSchedule::Spread,
            ..SessionConfig::with(0, win - 2)
        },
        SessionConfig::with(dec_future_max(&cfg), win),
    ];
    let lens = [rows, rows - 3, rows / 2];
    // Alone.
    let mut alone = Vec::new();
    for (sc, &n) in cfgs.iter().zip(&lens) {
        let mut arena = vec![0u8; m.session_bytes(sc).unwrap()];
        let mut s = Session::new(&m, &mut arena, sc, g.seed).unwrap();
        alone.push(run(&mut s, &g.music[..n * nm], nm, MusicPadding::Demo, true).1);
    }
    // Together: one row each, one batch step, pull everything.
    let mut arenas: Vec<Vec<u8>> = cfgs
        .iter()
        .map(|sc| vec![0u8; m.batched_session_bytes(sc).unwrap()])
        .collect();
    assert!(cfgs
        .iter()
        .all(|sc| m.batched_session_bytes(sc).unwrap() < m.session_bytes(sc).unwrap()));
    let mut batch_arena = vec![0u8; StepBatch::bytes(&cfg, 3).unwrap()];
    let mut batch = StepBatch::new(&cfg, 3, &mut batch_arena).unwrap();
    let mut ss: Vec<Session<'_>> = arenas
        .iter_mut()
        .zip(&cfgs)
        .map(|(a, sc)| Session::new_batched(&m, a, sc, g.seed).unwrap())
        .collect();
    assert_eq!(
        ss[0].step(),
        Err(Error::State),
        "a batched session has no step memory of its own"
    );
    let mut together: Vec<Vec<f32>> = vec![Vec::new(); 3];
    let mut f = [0f32; POSE_DIM];
    {
        for r in 0..rows {
            for (i, s) in ss.iter_mut().enumerate() {
                if r < lens[i] {
                    s.push_music(&g.music[r * nm..(r + 1) * nm]).unwrap();
                    if r + 1 == lens[i] {
                        s.finish(MusicPadding::Demo).unwrap();
                    }
                }
            }
            loop {
                let stepped = {
                    let [a, b, c] = &mut ss[..] else {
                        unreachable!()
                    };
                    batch.step(&mut [a, b, c]).unwrap()
                };
                for (i, s) in ss.iter_mut().enumerate() {
                    while s.pull(&mut f).unwrap().is_some() {
                        together[i].extend_from_slice(&f);
                    }
                }
                if stepped == 0 {
                    break;
                }
            }
        }
    }
    for i in 0..3 {
        assert!(ss[i].done(), "session {i} done");
        assert_eq!(together[i].len(), alone[i].len(), "session {i}: frames");
        assert!(
            together[i]
                .iter()
                .zip(&alone[i])
                .all(|(a, b)| a.to_bits() == b.to_bits()),
            "session {i}: batched frames differ from alone"
        );
    }
    // A second run into pre-sized outputs: the session calls allocate nothing.
    for s in ss.iter_mut() {
        s.reset(g.seed).unwrap();
    }
    for v in together.iter_mut() {
        v.clear();
        v.reserve(alone[0].len() + 64 * POSE_DIM);
    }
    let allocs = allocations_during(|| {
        for r in 0..rows {
            for s in ss.iter_mut() {
                s.push_music(&g.music[r * nm..(r + 1) * nm]).unwrap();
            }
            let [a, b, c] = &mut ss[..] else {
                unreachable!()
            };
            batch.step(&mut [a, b, c]).unwrap();
            for (i, s) in ss.iter_mut().enumerate() {
                while s.pull(&mut f).unwrap().is_some() {
                    together[i].extend_from_slice(&f);
                }
            }
        }
    });
    assert_eq!(allocs, 0, "allocations while stepping");
}

/// A session's own scratch holds a whole re-prefill, so a window jump runs
/// its missing rows with the new row in one pass; a batch of one holds 9
/// window rows, so the same jumps (10 rows at the exact preset here) run in
/// chunks first. Both give the same tokens and frames, bit for bit.
#[test]
fn a_jump_in_one_pass_equals_the_jump_in_chunks() {
    let (cfg, file) = model_file("btiny2", "actor_critic_demo.yaml");
    let duo = file.duo().unwrap();
    let m = Model::from_duo(&duo).unwrap();
    let g = golden("btiny2_demo_slide", &cfg);
    let nm = cfg.gpt.n_music as usize;
    let win = window_rows(&cfg) as u32;
    assert!(
        win as usize > 1 + PREFILL_CHUNK,
        "the fixture's window must outgrow a chunk"
    );
    // The re-prefill schedule (the presets' spread one re-prefills once).
    for sc in [
        SessionConfig::with(dec_future_max(&cfg), win),
        SessionConfig {
            kv: KvType::F16,
            ..SessionConfig::with(2, win - 1)
        },
        SessionConfig::with(0, win / 2),
    ] {
        let sc = SessionConfig {
            schedule: CacheSchedule::Reprefill,
            ..sc
        };
        let mut arena = vec![0u8; m.session_bytes(&sc).unwrap()];
        let mut alone = Session::new(&m, &mut arena, &sc, g.seed).unwrap();
        let (toks_alone, frames_alone) = run(&mut alone, &g.music, nm, MusicPadding::Demo, true);

        let mut arena = vec![0u8; m.batched_session_bytes(&sc).unwrap()];
        let mut s = Session::new_batched(&m, &mut arena, &sc, g.seed).unwrap();
        let mut batch_arena = vec![0u8; StepBatch::bytes(&cfg, 1).unwrap()];
        let mut batch = StepBatch::new(&cfg, 1, &mut batch_arena).unwrap();
        let mut frames = Vec::new();
        let mut f = [0f32; POSE_DIM];
        let rows = g.music.len() / nm;
        for r in 0..rows {
            s.push_music(&g.music[r * nm..(r + 1) * nm]).unwrap();
            if r + 1 == rows {
                s.finish(MusicPadding::Demo).unwrap();
            }
            while batch.step(&mut [&mut s]).unwrap() > 0 {
                while s.pull(&mut f).unwrap().is_some() {
                    frames.extend_from_slice(&f);
                }
            }
        }
        assert!(s.done());
        let toks: Vec<u32> = (0..s.tokens())
            .flat_map(|i| s.token(i).map(|t| t.to_vec()).unwrap_or_default())
            .collect();
        let shift = sc.shift;
        assert!(
            alone.prefilled > 0,
            "shift {shift}: the window never jumped"
        );
        assert_eq!(s.prefilled, alone.prefilled, "shift {shift}: rows re-run");
        assert_eq!(toks, toks_alone, "shift {shift}: tokens");
        assert_eq!(frames.len(), frames_alone.len(), "shift {shift}: frames");
        assert!(
            frames
                .iter()
                .zip(&frames_alone)
                .all(|(a, b)| a.to_bits() == b.to_bits()),
            "shift {shift}: chunked jumps give other frames"
        );
    }
}

/// Bad input: a named error and the session unchanged.
#[test]
fn refusals_are_named_and_change_nothing() {
    let (cfg, file) = model_file("btiny", "actor_critic_demo.yaml");
    let duo = file.duo().unwrap();
    let m = Model::from_duo(&duo).unwrap();
    let nm = cfg.gpt.n_music as usize;
    let sc = SessionConfig {
        music_buffer_rows: 3,
        ..SessionConfig::preset(&cfg, Preset::Interactive)
    };
    let mut arena = vec![0u8; m.session_bytes(&sc).unwrap()];
    // Settings and seeds.
    let bad = SessionConfig {
        dec_future: dec_future_max(&cfg) + 1,
        ..sc
    };
    assert!(matches!(
        m.session_bytes(&bad),
        Err(Error::Setting {
            setting: Setting::DecFuture,
            ..
        })
    ));
    assert!(matches!(
        Session::new(&m, &mut vec![0u8; 64], &sc, [0, 0]),
        Err(Error::Arena(_))
    ));
    let vocab = cfg.gpt.vocab;
    assert_eq!(
        Session::new(&m, &mut arena, &sc, [vocab[0], 0]).err(),
        Some(Error::Token {
            stream: 0,
            token: vocab[0],
            vocab: vocab[0]
        })
    );
    let mut arena = vec![0u8; m.session_bytes(&sc).unwrap()];
    let mut s = Session::new(&m, &mut arena, &sc, [1, 2]).unwrap();
    let mut f = [0f32; POSE_DIM];
    assert_eq!(
        s.pull(&mut f[..10]),
        Err(Error::Length {
            buffer: Buffer::Output,
            len: 10,
            expected: POSE_DIM
        })
    );
    assert_eq!(
        s.finish(MusicPadding::Demo),
        Err(Error::State),
        "finish before any music"
    );
    let row = vec![0.5f32; nm];
    assert_eq!(
        s.push_music(&row[..nm - 1]),
        Err(Error::Ragged {
            buffer: Buffer::Music,
            len: nm - 1,
            row: nm
        })
    );
    let mut nan = row.clone();
    nan[1] = f32::NAN;
    assert_eq!(
        s.push_music(&nan),
        Err(Error::NonFinite {
            buffer: Buffer::Music,
            index: 1
        })
    );
    assert_eq!(s.music_rows(), 0);
    // Backlog: row 0 is never read, rows 1.. wait for steps; 3 may wait.
    let four: Vec<f32> = row.iter().cycle().take(5 * nm).copied().collect();
    assert!(matches!(
        s.push_music(&four),
        Err(Error::Backlog {
            buffer: Buffer::Music,
            held: 0,
            capacity: 3
        })
    ));
    assert_eq!(s.music_rows(), 0, "all or none");
    s.push_music(&four[..4 * nm]).unwrap();
    assert!(matches!(
        s.push_music(&row),
        Err(Error::Backlog {
            buffer: Buffer::Music,
            held: 3,
            capacity: 3
        })
    ));
    // Pulling steps the session and frees music room.
    while s.pull(&mut f).unwrap().is_some() {}
    assert_eq!(s.tokens(), 4);
    s.push_music(&row).unwrap();
    s.finish(MusicPadding::Demo).unwrap();
    assert_eq!(s.push_music(&row), Err(Error::State), "music after the end");
    assert_eq!(s.finish(MusicPadding::Demo), Err(Error::State));
    while s.pull(&mut f).unwrap().is_some() {}
    assert!(s.done());
    assert_eq!(s.tokens(), 8, "5 rows padded to 8 (the demo path)");
    assert!(s.reset([vocab[0], 0]).is_err());
    assert_eq!(s.tokens(), 8, "a refused reset changes nothing");
    s.reset([1, 2]).unwrap();
    assert_eq!((s.tokens(), s.music_rows(), s.frames_ready()), (1, 0, 0));
}

/// At the published size a session is small (figures in docs/BAILANDO.md).
#[test]
fn published_session_arena() {
    let cfg = duolando_core::bailando::config::published();
    for p in Preset::ALL {
        let sc = SessionConfig::preset(&cfg, p);
        let f32kv = duolando_core::bailando::session::session_bytes_for(&cfg, &sc).unwrap();
        let f16kv = duolando_core::bailando::session::session_bytes_for(
            &cfg,
            &SessionConfig {
                kv: KvType::F16,
                ..sc
            },
        )
        .unwrap();
        let batched = duolando_core::bailando::session::batched_session_bytes_for(
            &cfg,
            &SessionConfig {
                kv: KvType::F16,
                ..sc
            },
        )
        .unwrap();
        eprintln!("published Bailando session, {}: f32 K/V {f32kv} B, f16 K/V {f16kv} B (batched state alone {batched} B)", p.name());
        // The f16 GPT cache: 12 layers x 2 x (3 x 27 x 768) halves + a tail.
        assert!(
            f16kv > 12 * 2 * 3 * 27 * 768 * 2 && f16kv < f32kv,
            "{f16kv}"
        );
        // Every preset's session within 8 MB with f16 K/V (issue #38 §5).
        assert!(f16kv <= 8_000_000, "{}: {f16kv} B", p.name());
        // A spread preset's second cache holds `shift - 1` window rows (the
        // next window's rows before its jump) and its one-row tail, no more
        // (the state alone: a session's own step scratch differs too).
        let lean = duolando_core::bailando::session::batched_session_bytes_for(
            &cfg,
            &SessionConfig {
                kv: KvType::F16,
                schedule: CacheSchedule::Reprefill,
                ..sc
            },
        )
        .unwrap();
        if sc.schedule == CacheSchedule::Spread {
            let row = 12 * 2 * 3 * 768 * 2;
            let ahead = (sc.shift as usize - 1) * row;
            assert!(
                batched >= lean + ahead && batched < lean + ahead + row,
                "{}: spread {batched} B, reprefill {lean} B",
                p.name()
            );
        } else {
            assert_eq!(batched, lean, "{}", p.name());
        }
    }
}

/// Found by the solo fuzzer: with `dec_future` 0 the first step makes two
/// tokens' frames (the seed's and token 1's); with `pending_frames` below
/// `hop` the pending ring lost frame 0 (`Evicted`). Every small
/// `pending_frames` now gives every frame.
#[test]
fn the_first_step_keeps_both_tokens_frames_at_any_pending_size() {
    let (cfg, file) = model_file("btiny", "actor_critic.yaml");
    let duo = file.duo().unwrap();
    let m = Model::from_duo(&duo).unwrap();
    let hop = cfg.hop();
    for pending in 0..=hop as u32 {
        let sc = SessionConfig {
            pending_frames: pending,
            ..SessionConfig::with(0, 1)
        };
        let mut arena = vec![0u8; m.session_bytes(&sc).unwrap()];
        let mut s = Session::new(&m, &mut arena, &sc, [1, 2]).unwrap();
        s.push_music(&vec![0.25f32; cfg.gpt.n_music as usize])
            .unwrap();
        s.finish(MusicPadding::Aist).unwrap();
        let mut f = [0f32; POSE_DIM];
        let mut n = 0;
        while let Some(i) = s.pull(&mut f).unwrap() {
            assert_eq!(i as usize, n);
            n += 1;
        }
        assert_eq!(n, 2 * hop, "pending_frames {pending}");
        assert!(s.done());
    }
}
