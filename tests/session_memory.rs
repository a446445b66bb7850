//! The streaming session's memory contract: `Model::session_bytes` is
//! exactly what it needs (enough at any address, one 64-byte line less
//! fails cleanly), nothing allocates after `Session::new`, the state does
//! not grow, and one `Model` serves sessions on several threads at once.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

use duolando::model_file::ModelFile;
use duolando::npy::read_f32_2d;
use duolando_core::duolando::model::Model;
use duolando_core::duolando::session::{
    CacheSchedule, FollowerFrame, Sampling, Session, SessionConfig,
};
use duolando_core::error::{Buffer, Error};
use duolando_tests::fixture;

/// Counts heap allocations made by the current thread while enabled.
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
        // SAFETY: `p` was allocated by `System` with layout `l` (see `alloc`).
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

struct Clip {
    leader: Vec<f32>,
    music: Vec<f32>,
}

fn clip() -> Clip {
    let d = fixture("rollout_tiny_long");
    Clip {
        leader: read_f32_2d(&d.join("leader_pos3d.npy"), Some(165), "leader")
            .unwrap()
            .data,
        music: read_f32_2d(&d.join("music.npy"), None, "music")
            .unwrap()
            .data,
    }
}

/// Pushes the whole clip (music frame by frame unless a track was set,
/// then the leader frame), pulling after every push; returns the pulled
/// frames' positions.
fn drive(s: &mut Session<'_>, c: &Clip, n_music: usize, out: &mut Vec<f32>) -> Result<(), Error> {
    let mut f = FollowerFrame::default();
    let live = s.config().music_lookahead == 0;
    for i in 0..c.leader.len() / 165 {
        if live {
            s.push_music_frame(&c.music[i * n_music..(i + 1) * n_music])?;
        }
        match s.push_leader_frame(&c.leader[i * 165..(i + 1) * 165]) {
            // The track ends: its last tokens have no music look-ahead, so no
            // step can run and leader frames back up.
            Err(Error::Backlog { .. }) if !live => break,
            r => r?,
        }
        while s.pull_follower_frame(&mut f)? {
            out.extend_from_slice(&f.positions);
        }
    }
    Ok(())
}

fn live_config(model: &Model<'_>) -> SessionConfig {
    // Music pushed live, in lockstep with the leader: no music look-ahead.
    let shift = SessionConfig::reference(&model.cfg).shift;
    let mut sc = SessionConfig::with(&model.cfg, 4, 3, 3, shift);
    sc.music_lookahead = 0;
    sc.sampling = Sampling::TopK { k: 3, rng_seed: 7 };
    sc
}

/// `bytes` bytes of `buf` (>= bytes + 64 long) starting 1 byte past a
/// 64-byte line: the worst alignment an arena can have.
fn worst_aligned(buf: &mut [u8], bytes: usize) -> &mut [u8] {
    let off = (64 - buf.as_ptr() as usize % 64) % 64 + 1;
    &mut buf[off..off + bytes]
}

/// `len` bytes of `buf` (>= len + 64 long) starting on a 64-byte line.
fn line_aligned(buf: &mut [u8], len: usize) -> &mut [u8] {
    let off = (64 - buf.as_ptr() as usize % 64) % 64;
    &mut buf[off..off + len]
}

#[test]
fn no_allocation_after_new_and_the_arena_is_exact() {
    let file = ModelFile::open(fixture("tiny/model.duo")).unwrap();
    let duo = file.duo().unwrap();
    let model = Model::from_duo(&duo).unwrap();
    let n_music = model.cfg.gpt.music.n_in as usize;
    let c = clip();
    let staggered = SessionConfig {
        schedule: CacheSchedule::Staggered,
        ..SessionConfig::reference(&model.cfg)
    };
    for sc in [
        SessionConfig::reference(&model.cfg),
        SessionConfig::minimum(&model.cfg),
        live_config(&model),
        staggered,
    ] {
        let bytes = model.session_bytes(&sc).unwrap();
        // Exactly `bytes` at the worst alignment (63 bytes past a line) is enough.
        let mut buf = vec![0u8; bytes + 64];
        let arena = worst_aligned(&mut buf, bytes);
        let mut out = Vec::with_capacity(c.leader.len() * 2);
        let mut s = Session::new(&model, arena, &sc, [1, 2, 3, 4, 5]).unwrap();
        if sc.music_lookahead > 0 {
            s.set_music_track(&c.music).unwrap();
        }
        let n = allocations_during(|| drive(&mut s, &c, n_music, &mut out).unwrap());
        assert_eq!(n, 0, "{sc:?}: {n} heap allocations while streaming");
        assert!(s.steps() > 50, "{sc:?}: only {} steps", s.steps());
        assert!(out.iter().all(|v| v.is_finite()));
        // A 64-byte-aligned arena needs at most `bytes - 63`; one line less than that fails cleanly.
        let len = bytes - 63 - 64;
        let mut small = vec![0u8; len + 64];
        match Session::new(&model, line_aligned(&mut small, len), &sc, [1, 2, 3, 4, 5]) {
            Err(Error::Arena(_)) => {}
            Err(e) => panic!("{sc:?}: wrong error for a short arena: {e:?}"),
            Ok(_) => panic!(
                "{sc:?}: a session fit in {len} < {bytes} - 63 bytes: session_bytes is not exact"
            ),
        };
    }
}

#[test]
fn reset_reproduces_the_first_run_without_allocating() {
    let file = ModelFile::open(fixture("tiny/model.duo")).unwrap();
    let duo = file.duo().unwrap();
    let model = Model::from_duo(&duo).unwrap();
    let n_music = model.cfg.gpt.music.n_in as usize;
    let c = clip();
    let sc = live_config(&model);
    let mut arena = vec![0u8; model.session_bytes(&sc).unwrap()];
    let mut s = Session::new(&model, &mut arena, &sc, [3, 1, 4, 1, 5]).unwrap();
    let (mut a, mut b) = (Vec::with_capacity(1 << 20), Vec::with_capacity(1 << 20));
    drive(&mut s, &c, n_music, &mut a).unwrap();
    let n = allocations_during(|| {
        s.reset([3, 1, 4, 1, 5]).unwrap();
        drive(&mut s, &c, n_music, &mut b).unwrap();
    });
    assert_eq!(n, 0);
    assert!(!a.is_empty());
    assert_eq!(
        a, b,
        "a reset session must replay bit for bit (same seed, same RNG seed)"
    );
}

#[test]
fn one_model_serves_sessions_on_four_threads() {
    let file = ModelFile::open(fixture("tiny2/model.duo")).unwrap();
    let duo = file.duo().unwrap();
    let model = Model::from_duo(&duo).unwrap();
    let n_music = model.cfg.gpt.music.n_in as usize;
    let d = fixture("rollout_tiny2_frames");
    let c = Clip {
        leader: read_f32_2d(&d.join("leader_pos3d.npy"), Some(165), "leader")
            .unwrap()
            .data,
        music: read_f32_2d(&d.join("music.npy"), None, "music")
            .unwrap()
            .data,
    };
    let sc = live_config(&model);
    let single = {
        let mut arena = vec![0u8; model.session_bytes(&sc).unwrap()];
        let mut s = Session::new(&model, &mut arena, &sc, [0, 1, 2, 3, 4]).unwrap();
        let mut out = Vec::new();
        drive(&mut s, &c, n_music, &mut out).unwrap();
        out
    };
    assert!(!single.is_empty());
    let (model, c, sc) = (&model, &c, &sc);
    std::thread::scope(|scope| {
        let handles: Vec<_> = (0..4)
            .map(|_| {
                scope.spawn(move || {
                    let mut arena = vec![0u8; model.session_bytes(sc).unwrap()];
                    let mut s = Session::new(model, &mut arena, sc, [0, 1, 2, 3, 4]).unwrap();
                    let mut out = Vec::new();
                    drive(&mut s, c, n_music, &mut out).unwrap();
                    out
                })
            })
            .collect();
        for h in handles {
            assert_eq!(
                h.join().unwrap(),
                single,
                "a session on another thread must give the same frames"
            );
        }
    });
}

#[test]
fn bad_frames_are_refused_and_leave_the_session_unchanged() {
    let file = ModelFile::open(fixture("tiny/model.duo")).unwrap();
    let duo = file.duo().unwrap();
    let model = Model::from_duo(&duo).unwrap();
    let n_music = model.cfg.gpt.music.n_in as usize;
    let c = clip();
    let sc = live_config(&model);
    let clean = {
        let mut arena = vec![0u8; model.session_bytes(&sc).unwrap()];
        let mut s = Session::new(&model, &mut arena, &sc, [1, 1, 1, 1, 1]).unwrap();
        let mut out = Vec::new();
        drive(&mut s, &c, n_music, &mut out).unwrap();
        out
    };
    let mut arena = vec![0u8; model.session_bytes(&sc).unwrap()];
    let mut s = Session::new(&model, &mut arena, &sc, [1, 1, 1, 1, 1]).unwrap();
    let mut out = Vec::new();
    let mut f = FollowerFrame::default();
    let mut bad = [0.5f32; 165];
    for i in 0..c.leader.len() / 165 {
        if i % 37 == 5 {
            bad[(i * 7) % 165] = [f32::NAN, f32::INFINITY, f32::NEG_INFINITY][i % 3];
            assert!(matches!(
                s.push_leader_frame(&bad),
                Err(Error::NonFinite { .. })
            ));
            let mut m = c.music[..n_music].to_vec();
            m[i % n_music] = f32::NAN;
            assert!(matches!(
                s.push_music_frame(&m),
                Err(Error::NonFinite { .. })
            ));
            assert!(matches!(
                s.push_leader_frame(&bad[..100]),
                Err(Error::Length { .. })
            ));
            // Finite but out of range (input policy, docs/ROBUSTNESS.md §3).
            let mut huge = c.leader[i * 165..(i + 1) * 165].to_vec();
            huge[(i * 11) % 165] = [1e30, -2e4, f32::MAX][i % 3];
            let e = s.push_leader_frame(&huge);
            assert_eq!(
                e,
                Err(Error::OutOfRange {
                    buffer: Buffer::LeaderPos3d,
                    index: (i * 11) % 165
                })
            );
            let mut m = c.music[i * n_music..(i + 1) * n_music].to_vec();
            m[0] = -1e30;
            assert_eq!(
                s.push_music_frame(&m),
                Err(Error::OutOfRange {
                    buffer: Buffer::Music,
                    index: 0
                })
            );
        }
        s.push_music_frame(&c.music[i * n_music..(i + 1) * n_music])
            .unwrap();
        s.push_leader_frame(&c.leader[i * 165..(i + 1) * 165])
            .unwrap();
        while s.pull_follower_frame(&mut f).unwrap() {
            out.extend_from_slice(&f.positions);
        }
    }
    assert_eq!(
        out, clean,
        "refused frames must not change what the session computes"
    );
}

#[test]
fn unpulled_frames_back_up_into_a_clean_refusal() {
    let file = ModelFile::open(fixture("tiny2/model.duo")).unwrap();
    let duo = file.duo().unwrap();
    let model = Model::from_duo(&duo).unwrap();
    let mut sc = SessionConfig::minimum(&model.cfg);
    sc.pending_frames = 8;
    let c = clip();
    let mut arena = vec![0u8; model.session_bytes(&sc).unwrap()];
    let mut s = Session::new(&model, &mut arena, &sc, [0, 0, 0, 0, 0]).unwrap();
    s.set_music_track(&c.music[..600 * model.cfg.gpt.music.n_in as usize])
        .unwrap();
    let mut refused_at = None;
    for i in 0..100 {
        match s.push_leader_frame(&c.leader[i * 165..(i + 1) * 165]) {
            Ok(()) => {}
            Err(Error::Backlog { held, capacity, .. }) => {
                assert_eq!(held, capacity);
                refused_at = Some(i);
                break;
            }
            Err(e) => panic!("{e:?}"),
        }
    }
    // Latency 0: 1 + pending_frames leader frames may wait for a pull.
    assert_eq!(refused_at, Some(9));
    let mut f = FollowerFrame::default();
    let mut pulled = 0;
    while s.pull_follower_frame(&mut f).unwrap() {
        assert_eq!(f.index, pulled);
        pulled += 1;
    }
    assert_eq!(pulled, 9);
    s.push_leader_frame(&c.leader[9 * 165..10 * 165]).unwrap();
}

/// The decoded-frame ring holds `pending_frames + hop + 1` frames, not the
/// whole latency: a caller that lets frames back up into `Backlog` before
/// pulling them all gets every frame, equal to those of a caller pulling
/// after every push (an evicted frame would answer `Evicted`).
#[test]
fn frames_backed_up_to_the_refusal_are_all_kept() {
    let c = clip();
    for (name, preset, pending) in [
        ("tiny", "reference", 0u32),
        ("tiny", "reference", 5),
        ("tiny2", "minimum", 0),
        ("tiny2", "minimum", 3),
        ("tiny", "live", 2),
    ] {
        let file = ModelFile::open(fixture(&format!("{name}/model.duo"))).unwrap();
        let duo = file.duo().unwrap();
        let model = Model::from_duo(&duo).unwrap();
        let mut sc = match preset {
            "reference" => SessionConfig::reference(&model.cfg),
            "minimum" => SessionConfig::minimum(&model.cfg),
            _ => SessionConfig::with(
                &model.cfg,
                1,
                0,
                0,
                SessionConfig::reference(&model.cfg).shift,
            ),
        };
        sc.pending_frames = pending;
        let n_music = model.cfg.gpt.music.n_in as usize;
        let frames = c.leader.len() / 165;
        let track = &c.music[..frames.min(c.music.len() / n_music) * n_music];
        let run = |eager: bool| -> Vec<(u64, Vec<f32>)> {
            let mut arena = vec![0u8; model.session_bytes(&sc).unwrap()];
            let mut s = Session::new(&model, &mut arena, &sc, [0, 0, 0, 0, 0]).unwrap();
            s.set_music_track(track).unwrap();
            let mut f = FollowerFrame::default();
            let mut out = Vec::new();
            let mut refusals = 0;
            let mut pull_all = |s: &mut Session<'_>, out: &mut Vec<(u64, Vec<f32>)>| {
                while s.pull_follower_frame(&mut f).unwrap() {
                    out.push((f.index, f.positions.to_vec()));
                }
            };
            let mut i = 0;
            while i < frames {
                match s.push_leader_frame(&c.leader[i * 165..(i + 1) * 165]) {
                    Ok(()) => i += 1,
                    Err(Error::Backlog {
                        buffer: Buffer::FollowerPos3d,
                        ..
                    }) => {
                        // Pulling frees the backlog, unless no step can run any
                        // more (the end of the music track).
                        let before = out.len();
                        pull_all(&mut s, &mut out);
                        if out.len() == before {
                            break;
                        }
                        refusals += 1;
                        continue;
                    }
                    Err(Error::Backlog {
                        buffer: Buffer::Music,
                        ..
                    }) => break,
                    Err(e) => panic!("{name} {preset}: frame {i}: {e:?}"),
                }
                if eager {
                    pull_all(&mut s, &mut out);
                }
            }
            pull_all(&mut s, &mut out);
            assert!(
                eager || refusals > 0,
                "{name} {preset} {pending}: the backlog was never reached"
            );
            out
        };
        let eager = run(true);
        let backed_up = run(false);
        assert!(eager.len() > 100, "{name} {preset}: {} frames", eager.len());
        assert_eq!(backed_up.len(), eager.len(), "{name} {preset} {pending}");
        assert!(
            backed_up == eager,
            "{name} {preset} {pending}: frames differ"
        );
    }
}

#[test]
fn step_many_allocates_nothing_and_its_batch_arena_is_exact() {
    use duolando_core::duolando::session::StepBatch;
    let file = ModelFile::open(fixture("tiny/model.duo")).unwrap();
    let duo = file.duo().unwrap();
    let model = Model::from_duo(&duo).unwrap();
    let n_music = model.cfg.gpt.music.n_in as usize;
    let c = clip();
    let sc = live_config(&model);
    let n = 3;
    let mut arenas: Vec<Vec<u8>> = (0..n)
        .map(|_| vec![0u8; model.session_bytes(&sc).unwrap()])
        .collect();
    let mut sessions: Vec<Session<'_>> = arenas
        .iter_mut()
        .enumerate()
        .map(|(i, a)| Session::new(&model, a, &sc, [i as u32, 1, 2, 3, 4]).unwrap())
        .collect();
    let bytes = StepBatch::bytes(&model.cfg, &sc, n).unwrap();
    // Exactly `bytes` at the worst alignment is enough; a 64-byte-aligned arena one line short of `bytes - 63` is not.
    let mut buf = vec![0u8; bytes + 64];
    let mut batch = StepBatch::new(&model.cfg, &sc, n, worst_aligned(&mut buf, bytes)).unwrap();
    let mut small = vec![0u8; bytes];
    assert!(matches!(
        StepBatch::new(&model.cfg, &sc, n, line_aligned(&mut small, bytes - 127)),
        Err(Error::Arena(_))
    ));
    let frames = c.leader.len() / 165;
    let mut refs: Vec<&mut Session<'_>> = sessions.iter_mut().collect();
    let mut f = FollowerFrame::default();
    let mut pulled = 0usize;
    let allocs = allocations_during(|| {
        for t in 0..frames {
            for s in refs.iter_mut() {
                s.push_music_frame(&c.music[t * n_music..(t + 1) * n_music])
                    .unwrap();
            }
            let x = &c.leader[t * 165..(t + 1) * 165];
            Session::step_many(&mut refs, &[x, x, x], &mut batch).unwrap();
            for s in refs.iter_mut() {
                while s.pull_follower_frame(&mut f).unwrap() {
                    pulled += 1;
                }
            }
        }
    });
    assert_eq!(
        allocs, 0,
        "{allocs} heap allocations while stepping {n} sessions together"
    );
    assert!(pulled > 3 * 100, "only {pulled} frames pulled");
}

/// Leader codes ahead of the music wait in the session (as codes, not as
/// condition rows) up to the `Backlog { Music }` refusal; music pushed then
/// lets them through. The follower equals that of a caller pushing music
/// and leader frames in step (every frame, bit for bit).
#[test]
fn leader_codes_waiting_for_music_up_to_the_refusal_are_all_kept() {
    let c = clip();
    for (name, preset) in [
        ("tiny", "reference"),
        ("tiny2", "reference"),
        ("tiny", "live"),
    ] {
        let file = ModelFile::open(fixture(&format!("{name}/model.duo"))).unwrap();
        let duo = file.duo().unwrap();
        let model = Model::from_duo(&duo).unwrap();
        let mut sc = match preset {
            "reference" => SessionConfig::reference(&model.cfg),
            _ => SessionConfig::with(
                &model.cfg,
                1,
                0,
                0,
                SessionConfig::reference(&model.cfg).shift,
            ),
        };
        // Room for every frame of the clip: the follower backlog never refuses first.
        sc.pending_frames = 1 << 12;
        let n_music = model.cfg.gpt.music.n_in as usize;
        let frames = (c.leader.len() / 165).min(c.music.len() / n_music);
        let music = |t: usize| &c.music[t * n_music..(t + 1) * n_music];
        let leader = |t: usize| &c.leader[t * 165..(t + 1) * 165];
        let pull_all = |s: &mut Session<'_>, out: &mut Vec<Vec<f32>>| {
            let mut f = FollowerFrame::default();
            while s.pull_follower_frame(&mut f).unwrap() {
                out.push(f.positions.iter().chain(&f.rotations).copied().collect());
            }
        };
        // In step: music frame t, then leader frame t.
        let mut arena = vec![0u8; model.session_bytes(&sc).unwrap()];
        let mut s = Session::new(&model, &mut arena, &sc, [0, 0, 0, 0, 0]).unwrap();
        let mut want = Vec::new();
        for t in 0..frames {
            s.push_music_frame(music(t)).unwrap();
            s.push_leader_frame(leader(t)).unwrap();
        }
        pull_all(&mut s, &mut want);
        // Leader frames first, up to the refusal; then music until it takes more.
        let mut arena = vec![0u8; model.session_bytes(&sc).unwrap()];
        let mut s = Session::new(&model, &mut arena, &sc, [0, 0, 0, 0, 0]).unwrap();
        let (mut got, mut m, mut refusals) = (Vec::new(), 0, 0);
        for t in 0..frames {
            loop {
                match s.push_leader_frame(leader(t)) {
                    Ok(()) => break,
                    Err(Error::Backlog {
                        buffer: Buffer::Music,
                        held,
                        capacity,
                    }) => {
                        assert_eq!(held, capacity, "{name} {preset}: frame {t}");
                        refusals += 1;
                        assert!(
                            m < frames,
                            "{name} {preset}: refused with every music frame in"
                        );
                        s.push_music_frame(music(m)).unwrap();
                        m += 1;
                    }
                    Err(e) => panic!("{name} {preset}: frame {t}: {e:?}"),
                }
            }
        }
        while m < frames {
            s.push_music_frame(music(m)).unwrap();
            m += 1;
        }
        pull_all(&mut s, &mut got);
        assert!(
            refusals > 0,
            "{name} {preset}: the music backlog was never reached"
        );
        assert!(want.len() > 100, "{name} {preset}: {} frames", want.len());
        assert_eq!(got.len(), want.len(), "{name} {preset}");
        assert!(got == want, "{name} {preset}: frames differ");
    }
}

/// A session made by `Session::new_batched` holds its state alone
/// (`Model::batched_session_bytes`, exact at the worst alignment, one line
/// less refused) and steps in a `StepBatch`'s memory: through `step_many`
/// or inside `with_batch`, without allocating. Alone, every call that could
/// run a step answers `Error::State` and changes nothing. Its frames equal
/// those of a session with its own step memory, bit for bit.
#[test]
fn a_batched_session_holds_its_state_alone() {
    use duolando_core::duolando::session::StepBatch;
    let file = ModelFile::open(fixture("tiny/model.duo")).unwrap();
    let duo = file.duo().unwrap();
    let model = Model::from_duo(&duo).unwrap();
    let n_music = model.cfg.gpt.music.n_in as usize;
    let c = clip();
    let sc = live_config(&model);
    let (own, alone) = (
        model.session_bytes(&sc).unwrap(),
        model.batched_session_bytes(&sc).unwrap(),
    );
    let batch_bytes = StepBatch::bytes(&model.cfg, &sc, 2).unwrap();
    assert!(
        alone + 1024 < own,
        "state alone {alone} B, with step memory {own} B"
    );
    // (A batch made for another model, declared first: a session and the
    // batches it borrows share one lifetime.)
    let other = duolando_core::duolando::presets::duolando_published();
    let other_sc = SessionConfig::minimum(&other);
    let mut ob = vec![0u8; StepBatch::bytes(&other, &other_sc, 1).unwrap()];
    let mut other_batch = StepBatch::new(&other, &other_sc, 1, &mut ob).unwrap();
    let mut batch_buf = vec![0u8; batch_bytes + 64];
    let mut batch = StepBatch::new(
        &model.cfg,
        &sc,
        2,
        worst_aligned(&mut batch_buf, batch_bytes),
    )
    .unwrap();
    let mut small = vec![0u8; alone];
    assert!(matches!(
        Session::new_batched(
            &model,
            line_aligned(&mut small, alone - 127),
            &sc,
            [0, 1, 2, 3, 4],
            &mut batch
        ),
        Err(Error::Arena(_))
    ));
    let mut buf = vec![0u8; alone + 64];
    let mut s = Session::new_batched(
        &model,
        worst_aligned(&mut buf, alone),
        &sc,
        [0, 1, 2, 3, 4],
        &mut batch,
    )
    .unwrap();
    let mut own_buf = vec![0u8; own];
    let mut twin = Session::new(&model, &mut own_buf, &sc, [0, 1, 2, 3, 4]).unwrap();
    assert!(!s.has_step_memory() && twin.has_step_memory());
    // Alone: refused, nothing changes.
    let x = &c.leader[..165];
    assert_eq!(s.push_leader_frame(x), Err(Error::State));
    assert_eq!(s.push_music_frame(&c.music[..n_music]), Err(Error::State));
    assert_eq!(s.set_music_track(&c.music), Err(Error::State));
    assert_eq!(s.reset([1, 1, 1, 1, 1]), Err(Error::State));
    assert_eq!((s.frames_pushed(), s.steps()), (0, 0));
    // A batch made for another model does not fit.
    assert_eq!(
        s.with_batch(&mut other_batch, |s| s
            .push_music_frame(&c.music[..n_music]))
            .err(),
        Some(Error::State)
    );
    let frames = c.leader.len() / 165;
    // Room for every frame beforehand: the test's own vectors must not allocate inside the count.
    let (mut got, mut want) = (
        Vec::with_capacity(frames * 660),
        Vec::with_capacity(frames * 660),
    );
    let mut f = FollowerFrame::default();
    let allocs = allocations_during(|| {
        for t in 0..frames {
            let m = &c.music[t * n_music..(t + 1) * n_music];
            s.with_batch(&mut batch, |s| s.push_music_frame(m))
                .unwrap()
                .unwrap();
            twin.push_music_frame(m).unwrap();
            let x = &c.leader[t * 165..(t + 1) * 165];
            // Even frames through step_many (both kinds in one batch), odd ones inside with_batch.
            if t % 2 == 0 {
                Session::step_many(&mut [&mut s], &[x], &mut batch).unwrap();
            } else {
                s.with_batch(&mut batch, |s| s.push_leader_frame(x))
                    .unwrap()
                    .unwrap();
            }
            twin.push_leader_frame(x).unwrap();
            while s.pull_follower_frame(&mut f).unwrap() {
                got.extend(f.positions.iter().chain(&f.rotations).map(|v| v.to_bits()));
            }
            while twin.pull_follower_frame(&mut f).unwrap() {
                want.extend(f.positions.iter().chain(&f.rotations).map(|v| v.to_bits()));
            }
        }
    });
    assert_eq!(
        allocs, 0,
        "{allocs} heap allocations while stepping a batched session"
    );
    assert!(
        want.len() > 100 * (165 + 495),
        "only {} values pulled",
        want.len()
    );
    assert!(
        got == want,
        "a batched session's frames differ from its twin's"
    );
    assert!(!s.has_step_memory(), "the batch's memory was given back");
    // Reset inside with_batch runs again from the start.
    s.with_batch(&mut batch, |s| s.reset([0, 1, 2, 3, 4]))
        .unwrap()
        .unwrap();
    assert_eq!((s.frames_pushed(), s.steps()), (0, 0));
}
