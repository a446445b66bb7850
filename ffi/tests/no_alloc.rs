//! docs/C_API.md: "Nothing allocates after creation". A counting global
//! allocator (this test binary only) checks it over whole runs of the tiny
//! fixture: leader pushes, pulls and resets of a session alone, and pushes
//! of sessions stepped together through a `duo_step_batch` (refused calls
//! excepted: a failure writes its message), one of them bound to the batch
//! (`duo_session_new_batched`) and driven alone too; Transflower sessions and their
//! step batch in caller memory, from creation on.

use std::alloc::{GlobalAlloc, Layout, System};
use std::path::Path;
use std::ptr;

use duolando::batch::*;
use duolando::frames::{DuoFollowerFrame, DuoLeaderFrame, DuoVec3};
use duolando::model::*;
use duolando::result::DuoResult;
use duolando::session::*;
use duolando_std::npy::read_f32_2d;

/// Counts the heap allocations of this thread (the test's; the harness's
/// other threads are not counted).
struct Counting;

thread_local! {
    static COUNT: std::cell::Cell<usize> = const { std::cell::Cell::new(0) };
}

// SAFETY: every method forwards to `System` unchanged (plus a thread-local
// counter), so `System`'s guarantees are ours.
unsafe impl GlobalAlloc for Counting {
    // SAFETY (all methods): GlobalAlloc's contract, forwarded to `System`.
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        let _ = COUNT.try_with(|c| c.set(c.get() + 1));
        // SAFETY: forwards the caller's layout to the system allocator unchanged.
        unsafe { System.alloc(layout) }
    }
    // SAFETY: see `alloc`.
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: `ptr` was allocated by `System` with `layout` (see `alloc`).
        unsafe { System.dealloc(ptr, layout) }
    }
    // SAFETY: see `alloc`.
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        let _ = COUNT.try_with(|c| c.set(c.get() + 1));
        // SAFETY: as in `alloc`/`dealloc`.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

/// Allocations of this thread so far.
fn allocations() -> usize {
    COUNT.with(|c| c.get())
}

#[test]
fn pushes_pulls_and_batched_steps_allocate_nothing() {
    // SAFETY: every C entry point below is called with pointers to live locals of the documented sizes; handles come from the library and are freed once.
    let fx = Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/fixtures");
    let l = read_f32_2d(
        &fx.join("rollout_tiny_odd/leader_pos3d.npy"),
        Some(165),
        "leader",
    )
    .unwrap();
    let frames = l.rows / 4 * 4;
    let leader: Vec<DuoLeaderFrame> = (0..frames)
        .map(|f| {
            let mut fr = DuoLeaderFrame::default();
            for (j, v) in fr.joints.iter_mut().enumerate() {
                let p = &l.data[f * 165 + 3 * j..];
                *v = DuoVec3 {
                    x: p[0],
                    y: p[1],
                    z: p[2],
                };
            }
            fr
        })
        .collect();
    let music = read_f32_2d(&fx.join("rollout_tiny_odd/music.npy"), Some(54), "music")
        .unwrap()
        .data[..frames * 54]
        .to_vec();
    let path = std::ffi::CString::new(fx.join("tiny/model.duo").to_str().unwrap()).unwrap();
    let mut m = ptr::null_mut();
    assert_eq!(
        unsafe { duo_model_open_file(path.as_ptr(), &mut m) },
        DuoResult::Ok
    );
    let mut c = DuoSessionConfig::default();
    assert_eq!(
        unsafe { duo_session_config_minimum(m, &mut c) },
        DuoResult::Ok
    );
    let seed = [1u32, 2, 3, 4, 5];
    const N: usize = 3;
    let mut batch = ptr::null_mut();
    assert_eq!(
        unsafe { duo_step_batch_new(m, &c, N, &mut batch) },
        DuoResult::Ok
    );
    // Session 1 is bound to the batch (its step memory the batch's).
    let sessions: Vec<*mut DuoSession> = (0..N)
        .map(|k| {
            let mut s = ptr::null_mut();
            let r = match k {
                1 => unsafe {
                    duolando::batched_session::duo_session_new_batched(
                        m,
                        &c,
                        seed.as_ptr(),
                        batch,
                        &mut s,
                    )
                },
                _ => unsafe { duo_session_new(m, &c, seed.as_ptr(), &mut s) },
            };
            assert_eq!(r, DuoResult::Ok);
            assert_eq!(
                unsafe { duo_session_set_music_track(s, music.as_ptr(), music.len()) },
                DuoResult::Ok
            );
            s
        })
        .collect();
    let rows: Vec<[DuoLeaderFrame; N]> = leader.iter().map(|f| [*f; N]).collect();
    let mut f = DuoFollowerFrame::default();
    let (mut pulled, mut alone) = (0usize, 0usize);

    // Allocations of the successful calls only: the refusal at the music
    // track's end (leader frames pile up until `DUO_BACKLOG`) writes its
    // message, and each phase stops there.
    let mut during = 0;
    let mut mark = allocations();
    for (i, row) in rows.iter().enumerate() {
        let mut failed = 0usize;
        match unsafe {
            duo_step_batch_push_leader(batch, sessions.as_ptr(), row.as_ptr(), N, &mut failed)
        } {
            DuoResult::Ok => {}
            DuoResult::Backlog => break,
            r => panic!("frame {i}: {r:?}"),
        }
        for &s in &sessions {
            while unsafe { duo_session_pull_follower(s, &mut f) } == DuoResult::Ok {
                pulled += 1;
            }
        }
        during += allocations() - mark;
        mark = allocations();
    }
    // A session alone, after a reset: one with its own step memory, one
    // bound to the batch (each call borrows the batch's, under its lock).
    for s in [sessions[0], sessions[1]] {
        mark = allocations();
        assert_eq!(
            unsafe { duo_session_reset(s, seed.as_ptr()) },
            DuoResult::Ok
        );
        assert_eq!(
            unsafe { duo_session_set_music_track(s, music.as_ptr(), music.len()) },
            DuoResult::Ok
        );
        for frame in &leader {
            if unsafe { duo_session_push_leader(s, frame) } != DuoResult::Ok {
                break;
            }
            while unsafe { duo_session_pull_follower(s, &mut f) } == DuoResult::Ok {
                alone += 1;
            }
            during += allocations() - mark;
            mark = allocations();
        }
    }

    assert!(
        pulled > N * frames / 2 && alone > 2 * frames / 2,
        "{pulled} / {alone} frames"
    );
    assert_eq!(
        during, 0,
        "{during} allocations while stepping ({pulled} batched frames, {alone} alone)"
    );
    for s in sessions {
        unsafe { duo_session_free(s) };
    }
    unsafe { duo_step_batch_free(batch) };
    unsafe { duo_model_free(m) };
}

/// Transflower sessions for batches only and their batch, all in caller
/// memory (`_new_in`): made, fed audio, stepped through the batch
/// (`duo_step_batch_step`) and pulled without one heap allocation.
#[test]
fn transflower_batches_in_caller_memory_allocate_nothing() {
    use duolando::transflower::*;
    use duolando::transflower_batch::*;
    // SAFETY: every C entry point below is called with pointers to live locals of the documented sizes; handles come from the library and are freed once; the memory outlives them.
    let fx = Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/fixtures/transflower_paper");
    let motion = read_f32_2d(&fx.join("in_expmap_scaled_20.npy"), None, "m")
        .unwrap()
        .data;
    let audio = read_f32_2d(&fx.join("in_audio_feats_scaled_20.npy"), None, "a")
        .unwrap()
        .data;
    let path = std::ffi::CString::new(fx.join("model.duo").to_str().unwrap()).unwrap();
    let name = std::ffi::CString::new("realtime").unwrap();
    let mut m = ptr::null_mut();
    let mut info = DuoTransflowerInfo::default();
    let mut c = DuoTransflowerConfig::default();
    let (mut sb, mut bb) = (0usize, 0usize);
    unsafe {
        assert_eq!(duo_model_open_file(path.as_ptr(), &mut m), DuoResult::Ok);
        assert_eq!(duo_transflower_get_info(m, &mut info), DuoResult::Ok);
        assert_eq!(
            duo_transflower_config_preset(m, name.as_ptr(), &mut c),
            DuoResult::Ok
        );
        c.batched = 1;
        assert_eq!(duo_transflower_session_bytes(m, &c, &mut sb), DuoResult::Ok);
        assert_eq!(duo_transflower_step_batch_bytes(m, &mut bb), DuoResult::Ok);
    }
    const N: usize = 3;
    let seed = &motion[..(info.seed_rows * info.channels) as usize];
    let (d, ch) = (info.audio_features as usize, info.channels as usize);
    let mut smem = vec![0u8; N * sb];
    let mut bmem = vec![0u8; bb];
    let mut frame = vec![0f32; ch];
    let mut sessions = [ptr::null_mut(); N];
    let mut batch = ptr::null_mut();
    let mut pulled = 0usize;

    let mark = allocations();
    unsafe {
        assert_eq!(
            duo_transflower_step_batch_new_in(m, bmem.as_mut_ptr(), bb, &mut batch),
            DuoResult::Ok
        );
        for (k, (s, mem)) in sessions
            .iter_mut()
            .zip(smem.chunks_exact_mut(sb))
            .enumerate()
        {
            c.rng_seed = k as u64;
            assert_eq!(
                duo_transflower_session_new_in(
                    m,
                    &c,
                    seed.as_ptr(),
                    seed.len(),
                    ptr::null(),
                    0,
                    mem.as_mut_ptr().cast(),
                    sb,
                    s
                ),
                DuoResult::Ok
            );
        }
        for row in audio.chunks_exact(d) {
            for &s in &sessions {
                assert_eq!(duo_session_push_music(s, row.as_ptr(), d), DuoResult::Ok);
            }
            let mut stepped = 0usize;
            assert_eq!(
                duo_step_batch_step(batch, sessions.as_ptr(), N, &mut stepped, ptr::null_mut()),
                DuoResult::Ok
            );
            for &s in &sessions {
                while duo_transflower_pull_frame(s, frame.as_mut_ptr(), ch, ptr::null_mut())
                    == DuoResult::Ok
                {
                    pulled += 1;
                }
            }
        }
    }
    let during = allocations() - mark;
    assert!(pulled >= N, "{pulled} frames");
    assert_eq!(during, 0, "{during} allocations ({pulled} frames)");
    unsafe {
        for s in sessions {
            duo_session_free(s);
        }
        duo_step_batch_free(batch);
        duo_model_free(m);
    }
    drop((smem, bmem));
}
