//! Duolando sessions bound to a `duo_step_batch` (`duo_session_new_batched`,
//! `_new_batched_in`, `duo_session_batched_bytes`): the state alone in
//! their memory, the batch's step memory borrowed for each call. Their
//! frames equal those of sessions with their own memory bit for bit
//! (every call that runs the model: creation, leader and music pushes, a
//! track, finish and the drained pulls, reset; alone and in
//! `duo_step_batch_push_leader`), on one thread or several sharing the
//! batch, and the batch outlives `duo_step_batch_free` while a session is
//! bound to it; random call sequences give the twin's results and frames
//! call for call.

mod common;
use common::golden::*;
use common::*;
use std::ptr;

use duolando::batch::*;
use duolando::batched_session::*;
use duolando::frames::{DuoFollowerFrame, DuoLeaderFrame};
use duolando::model::*;
use duolando::result::DuoResult;
use duolando::session::*;
use duolando::transflower_batch::duo_transflower_step_batch_new;

/// Music frames of the golden (n_music floats each).
fn music_frames(g: &Golden) -> Vec<&[f32]> {
    let n = g.music.len() / g.leader.len();
    g.music.chunks(n).collect()
}

/// Drives `s` with music pushed frame by frame ahead of its leader (no
/// track; `ahead` frames ahead), one leader frame at a time (`batch` None: the session's own
/// call; else `duo_step_batch_push_leader` with `batch`), then finishes
/// and pulls the drained frames.
fn drive_live(
    s: *mut DuoSession,
    g: &Golden,
    leader: &[DuoLeaderFrame],
    ahead: usize,
    batch: Option<*mut DuoStepBatch>,
) -> Vec<DuoFollowerFrame> {
    // SAFETY: `s` and `batch` are live handles of the caller; every
    // pointer below is to a live local of the documented size.
    let music = music_frames(g);
    let mut pushed = 0;
    let mut out = Vec::new();
    for (i, f) in leader.iter().enumerate() {
        // Music `ahead` frames ahead of the leader (the configuration's
        // music look-ahead and a step's frames), as far as the session takes.
        while pushed < music.len().min(i + ahead) {
            let x = music[pushed];
            match unsafe { duo_session_push_music(s, x.as_ptr(), x.len()) } {
                DuoResult::Ok => pushed += 1,
                DuoResult::Backlog => break,
                r => panic!("music {pushed}: {r:?} {}", last_error()),
            }
        }
        let r = match batch {
            None => unsafe { duo_session_push_leader(s, f) },
            Some(b) => {
                let mut failed = 0usize;
                unsafe { duo_step_batch_push_leader(b, &s, f, 1, &mut failed) }
            }
        };
        match r {
            DuoResult::Ok => {}
            // Past the music's last step no frame comes out; the leader
            // frames pile up until the session refuses more (as in `drive`).
            DuoResult::Backlog if pushed == music.len() => break,
            r => panic!("leader {i}: {r:?} {}", last_error()),
        }
        pull_all(s, &mut out);
    }
    assert_eq!(
        unsafe { duo_session_finish(s) },
        DuoResult::Ok,
        "{}",
        last_error()
    );
    pull_all(s, &mut out);
    out
}

/// Music frames pushed ahead of the leader under `c`: its music
/// look-ahead and two tokens more.
fn ahead(c: &DuoSessionConfig) -> usize {
    4 * (c.music_lookahead as usize + 2)
}

fn new_own(m: &Model, c: &DuoSessionConfig, seed: &[u32; 5]) -> *mut DuoSession {
    let mut s = ptr::null_mut();
    // SAFETY: live model, config and seed; `s` writable.
    let r = unsafe { duo_session_new(m.0, c, seed.as_ptr(), &mut s) };
    assert_eq!(r, DuoResult::Ok, "{}", last_error());
    s
}

fn new_bound(
    m: &Model,
    c: &DuoSessionConfig,
    seed: &[u32; 5],
    batch: *mut DuoStepBatch,
) -> *mut DuoSession {
    let mut s = ptr::null_mut();
    // SAFETY: live model, config, seed and batch; `s` writable.
    let r = unsafe { duo_session_new_batched(m.0, c, seed.as_ptr(), batch, &mut s) };
    assert_eq!(r, DuoResult::Ok, "{}", last_error());
    s
}

fn new_batch(m: &Model, c: &DuoSessionConfig, n: usize) -> *mut DuoStepBatch {
    let mut b = ptr::null_mut();
    // SAFETY: live model and config; `b` writable.
    let r = unsafe { duo_step_batch_new(m.0, c, n, &mut b) };
    assert_eq!(r, DuoResult::Ok, "{}", last_error());
    b
}

/// A bound session, in library and in caller memory, gives the frames of
/// a session with its own memory, bit for bit: a track and its own leader
/// pushes (with bad frames refused), live music with leader frames through
/// a batch, finish and the drained pulls, reset; and it keeps working after
/// its batch's `duo_step_batch_free`.
#[test]
fn bound_sessions_equal_sessions_with_their_own_memory() {
    // SAFETY: every C entry point below is called with pointers to live
    // locals of the documented sizes; handles come from the library and
    // are freed once.
    let g = golden();
    let m = open();
    let c = config(&m, &g);
    let own = new_own(&m, &c, &g.seed);
    let want_track = drive(own, &g, Noise::None);
    check_against_golden(&want_track, &g);
    assert_eq!(
        unsafe { duo_session_reset(own, g.seed.as_ptr()) },
        DuoResult::Ok
    );
    let mirrored = leader_of(&g, 1);
    let want_live = drive_live(own, &g, &mirrored, ahead(&c), None);
    assert!(
        want_live.len() > want_track.len() / 2,
        "{}",
        want_live.len()
    );
    unsafe { duo_session_free(own) };

    let (mut own_bytes, mut bound_bytes) = (0usize, 0usize);
    assert_eq!(
        unsafe { duo_session_bytes(m.0, &c, &mut own_bytes) },
        DuoResult::Ok
    );
    assert_eq!(
        unsafe { duo_session_batched_bytes(m.0, &c, &mut bound_bytes) },
        DuoResult::Ok,
        "{}",
        last_error()
    );
    assert!(bound_bytes < own_bytes, "{bound_bytes} vs {own_bytes}");
    let mut mem = vec![0u8; bound_bytes + 1];

    for caller_memory in [false, true] {
        let batch = new_batch(&m, &c, 2);
        let s = if caller_memory {
            let mut s = ptr::null_mut();
            let base = unsafe { mem.as_mut_ptr().add(1) };
            let short = unsafe {
                duo_session_new_batched_in(
                    m.0,
                    &c,
                    g.seed.as_ptr(),
                    batch,
                    base,
                    bound_bytes - 1,
                    &mut s,
                )
            };
            assert_eq!(short, DuoResult::BufferTooSmall);
            assert!(
                last_error().contains("duo_session_batched_bytes"),
                "{}",
                last_error()
            );
            assert!(s.is_null());
            let r = unsafe {
                duo_session_new_batched_in(
                    m.0,
                    &c,
                    g.seed.as_ptr(),
                    batch,
                    base,
                    bound_bytes,
                    &mut s,
                )
            };
            assert_eq!(r, DuoResult::Ok, "{}", last_error());
            s
        } else {
            new_bound(&m, &c, &g.seed, batch)
        };
        let what = if caller_memory {
            "caller memory"
        } else {
            "library memory"
        };
        assert!(
            drive(s, &g, Noise::BadFrames) == want_track,
            "{what}: a bound session's frames differ (track, its own pushes)"
        );
        assert_eq!(
            unsafe { duo_session_reset(s, g.seed.as_ptr()) },
            DuoResult::Ok
        );
        assert!(
            drive_live(s, &g, &mirrored, ahead(&c), Some(batch)) == want_live,
            "{what}: a bound session's frames differ (live music, batch pushes, finish)"
        );
        // The caller's reference goes; the session's keeps the batch.
        unsafe { duo_step_batch_free(batch) };
        assert_eq!(
            unsafe { duo_session_reset(s, g.seed.as_ptr()) },
            DuoResult::Ok
        );
        assert!(
            drive_live(s, &g, &mirrored, ahead(&c), None) == want_live,
            "{what}: after duo_step_batch_free"
        );
        unsafe { duo_session_free(s) };
    }
    unsafe { duo_model_free(m.0) };
}

/// Sessions bound to one batch, each driven on its own thread at once:
/// the batch's step memory is lent to one call at a time, and each
/// session's frames are those it makes alone.
#[test]
fn sessions_on_several_threads_share_their_batch() {
    // SAFETY: as above; each session is used by its own thread only, the
    // batch (shared) only through the sessions bound to it.
    let g = golden();
    let m = open();
    let c = config(&m, &g);
    let leaders: Vec<Vec<DuoLeaderFrame>> = (0..3).map(|k| leader_of(&g, k)).collect();
    let alone: Vec<Vec<DuoFollowerFrame>> = leaders
        .iter()
        .map(|l| {
            let s = new_own(&m, &c, &g.seed);
            let out = drive_live(s, &g, l, ahead(&c), None);
            unsafe { duo_session_free(s) };
            out
        })
        .collect();
    assert!(
        alone[0] != alone[1],
        "the leaders should give different dances"
    );
    let batch = new_batch(&m, &c, 1);
    struct Handle(*mut DuoSession);
    // SAFETY: a session may move between threads (the header's thread rule).
    unsafe impl Send for Handle {}
    let sessions: Vec<Handle> = (0..3)
        .map(|_| Handle(new_bound(&m, &c, &g.seed, batch)))
        .collect();
    // Freed before the threads start: the sessions keep it.
    unsafe { duo_step_batch_free(batch) };
    let outs: Vec<Vec<DuoFollowerFrame>> = std::thread::scope(|scope| {
        let joins: Vec<_> = sessions
            .into_iter()
            .zip(&leaders)
            .map(|(h, l)| {
                let g = &g;
                scope.spawn(move || {
                    let h = h;
                    let out = drive_live(h.0, g, l, ahead(&c), None);
                    unsafe { duo_session_free(h.0) };
                    out
                })
            })
            .collect();
        joins.into_iter().map(|j| j.join().unwrap()).collect()
    });
    for k in 0..3 {
        assert!(
            outs[k] == alone[k],
            "session {k} on its thread differs from alone"
        );
    }
    unsafe { duo_model_free(m.0) };
}

/// The constructors' refusals, in the header's order, and the sizes.
#[test]
fn batched_session_refusals() {
    // SAFETY: every C entry point below is called with NULL (where the
    // test checks NULL handling) or with pointers to live locals of the
    // documented sizes; handles come from the library and are freed once.
    let g = golden();
    let m = open();
    let c = config(&m, &g);
    let batch = new_batch(&m, &c, 1);
    let seed = g.seed.as_ptr();
    let mut s = ptr::null_mut();
    let mut new = |model: *const DuoModel, cfg: *const DuoSessionConfig, seed: *const u32, b| {
        let r = unsafe { duo_session_new_batched(model, cfg, seed, b, &mut s) };
        (r, last_error())
    };
    assert_eq!(
        new(ptr::null(), &c, seed, batch).0,
        DuoResult::NullParameter
    );
    assert_eq!(
        new(m.0, ptr::null(), seed, batch).0,
        DuoResult::NullParameter
    );
    let (r, msg) = new(m.0, &DuoSessionConfig { shift: 0, ..c }, seed, batch);
    assert_eq!(r, DuoResult::InvalidArgument, "{msg}");
    assert!(msg.contains("shift"), "{msg}");
    assert_eq!(new(m.0, &c, ptr::null(), batch).0, DuoResult::NullParameter);
    let (r, msg) = new(m.0, &c, seed, ptr::null_mut());
    assert_eq!(r, DuoResult::NullParameter);
    assert!(msg.ends_with("batch is NULL"), "{msg}");
    let big = [1_000_000u32; 5];
    let (r, msg) = new(m.0, &c, big.as_ptr(), batch);
    assert_eq!(r, DuoResult::InvalidArgument, "{msg}");
    assert!(msg.contains("outside its vocabulary"), "{msg}");
    // A model of another family; a batch of another family; a batch whose
    // step memory is another model's (tiny2: another width).
    let solo = Model(open_model(&fixture("bailando_btiny/model.duo")));
    let (r, msg) = new(solo.0, &c, seed, batch);
    assert_eq!(r, DuoResult::InvalidArgument, "{msg}");
    assert!(msg.contains("needs a Duolando model"), "{msg}");
    let tf = Model(open_model(&fixture("transflower_paper/model.duo")));
    let mut tf_batch = ptr::null_mut();
    assert_eq!(
        unsafe { duo_transflower_step_batch_new(tf.0, &mut tf_batch) },
        DuoResult::Ok
    );
    let (r, msg) = new(m.0, &c, seed, tf_batch);
    assert_eq!(r, DuoResult::InvalidArgument, "{msg}");
    assert!(msg.contains("a Duolando batch"), "{msg}");
    let other = Model(open_model(&fixture("tiny2/model.duo")));
    let mut oc = DuoSessionConfig::default();
    assert_eq!(
        unsafe { duo_session_config_reference(other.0, &mut oc) },
        DuoResult::Ok
    );
    let small = {
        let mut b = ptr::null_mut();
        assert_eq!(
            unsafe { duo_step_batch_new(other.0, &oc, 1, &mut b) },
            DuoResult::Ok,
            "{}",
            last_error()
        );
        b
    };
    let (r, msg) = new(m.0, &c, seed, small);
    assert_eq!(r, DuoResult::InvalidArgument, "{msg}");
    assert!(
        msg.contains("more step memory than the batch holds"),
        "{msg}"
    );
    assert!(s.is_null(), "no session on a refusal");
    assert_eq!(
        unsafe { duo_session_new_batched(m.0, &c, seed, batch, ptr::null_mut()) },
        DuoResult::NullParameter
    );
    // Sizes: NULLs, and the buffer rule of `memory`.
    let mut bytes = 0usize;
    assert_eq!(
        unsafe { duo_session_batched_bytes(ptr::null(), &c, &mut bytes) },
        DuoResult::NullParameter
    );
    assert_eq!(
        unsafe { duo_session_batched_bytes(m.0, ptr::null(), &mut bytes) },
        DuoResult::NullParameter
    );
    assert_eq!(
        unsafe { duo_session_batched_bytes(m.0, &c, ptr::null_mut()) },
        DuoResult::NullParameter
    );
    assert_eq!(
        unsafe { duo_session_batched_bytes(m.0, &c, &mut bytes) },
        DuoResult::Ok
    );
    let mut nothing = [0u8; 8];
    assert_eq!(
        unsafe { duo_session_new_batched_in(m.0, &c, seed, batch, ptr::null_mut(), 0, &mut s) },
        DuoResult::BufferTooSmall
    );
    assert_eq!(
        unsafe {
            duo_session_new_batched_in(m.0, &c, seed, batch, nothing.as_mut_ptr(), 0, &mut s)
        },
        DuoResult::BufferTooSmall
    );
    assert_eq!(
        unsafe { duo_session_new_batched_in(m.0, &c, seed, batch, ptr::null_mut(), bytes, &mut s) },
        DuoResult::NullParameter
    );
    assert!(last_error().ends_with("memory is NULL"), "{}", last_error());
    assert!(s.is_null());
    for b in [small, tf_batch, batch] {
        unsafe { duo_step_batch_free(b) };
    }
    for model in [m, solo, tf, other] {
        unsafe { duo_model_free(model.0) };
    }
}

/// Random call sequences (three seeds) on a session with its own memory
/// and its twin bound to a batch: music pushes, leader frames (the bound
/// one's through its own call or the batch's, at random), pulls, resets
/// and finishes, the batch's handle freed at a random call. Every result
/// and every frame of the two are the same.
#[test]
fn random_call_sequences_agree_with_the_twin() {
    // SAFETY: every C entry point below is called with pointers to live
    // locals of the documented sizes; handles come from the library and
    // are freed once.
    let g = golden();
    let m = open();
    let c = config(&m, &g);
    let music = music_frames(&g);
    for seed in [1u64, 2, 3] {
        let mut rng = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
        let mut next = |n: u64| {
            rng ^= rng << 13;
            rng ^= rng >> 7;
            rng ^= rng << 17;
            rng % n
        };
        let own = new_own(&m, &c, &g.seed);
        let mut batch = new_batch(&m, &c, 1);
        let bound = new_bound(&m, &c, &g.seed, batch);
        let free_at = next(600);
        let (mut li, mut mi) = (0usize, 0usize);
        let (mut frames, mut calls) = (0usize, 0usize);
        for call in 0..600u64 {
            if call == free_at {
                unsafe { duo_step_batch_free(batch) };
                batch = ptr::null_mut();
            }
            let op = next(100);
            let (a, b) = match op {
                0..=29 if mi < music.len() => {
                    let x = music[mi];
                    mi += 1;
                    unsafe {
                        (
                            duo_session_push_music(own, x.as_ptr(), x.len()),
                            duo_session_push_music(bound, x.as_ptr(), x.len()),
                        )
                    }
                }
                0..=69 => {
                    let f = g.leader[li % g.leader.len()];
                    li += 1;
                    let a = unsafe { duo_session_push_leader(own, &f) };
                    let b = if !batch.is_null() && next(2) == 0 {
                        let mut failed = 0usize;
                        unsafe { duo_step_batch_push_leader(batch, &bound, &f, 1, &mut failed) }
                    } else {
                        unsafe { duo_session_push_leader(bound, &f) }
                    };
                    (a, b)
                }
                70..=96 => {
                    let (mut fa, mut fb) =
                        (DuoFollowerFrame::default(), DuoFollowerFrame::default());
                    let r = unsafe {
                        (
                            duo_session_pull_follower(own, &mut fa),
                            duo_session_pull_follower(bound, &mut fb),
                        )
                    };
                    assert!(fa == fb, "seed {seed} call {call}: pulled frames differ");
                    frames += (r.0 == DuoResult::Ok) as usize;
                    r
                }
                97 => unsafe { (duo_session_finish(own), duo_session_finish(bound)) },
                _ => {
                    (li, mi) = (0, 0);
                    unsafe {
                        (
                            duo_session_reset(own, g.seed.as_ptr()),
                            duo_session_reset(bound, g.seed.as_ptr()),
                        )
                    }
                }
            };
            assert_eq!(a, b, "seed {seed} call {call} (op {op}): {}", last_error());
            calls += 1;
        }
        eprintln!("seed {seed}: {frames} frames in {calls} calls");
        assert!(frames > 0, "seed {seed}: no frame in {calls} calls");
        unsafe {
            duo_session_free(own);
            duo_session_free(bound);
            duo_step_batch_free(batch);
        }
    }
    unsafe { duo_model_free(m.0) };
}
