//! The C API against the S golden `streaming_tiny_minimum`
//! (tests/fixtures/README.md "S goldens"): a session driven only through
//! the `duo_*` functions (rlib) reproduces the golden follower positions
//! within 1e-4 m, its quaternions are the nearest rotations of the golden
//! raw rotation matrices, and the input policy holds: rejected NaN / Inf /
//! out-of-range frames leave the session unchanged (same output as a clean
//! run), caller-memory sessions and sessions on other threads agree.

mod common;
use common::golden::*;
use common::*;
use std::ffi::c_char;
use std::path::Path;
use std::ptr;

use duolando::batch::*;
use duolando::frames::{DuoFollowerFrame, DuoLeaderFrame};
use duolando::model::*;
use duolando::result::{duo_last_error_message, DuoResult};
use duolando::session::*;

#[test]
fn library_session_matches_the_golden_and_ignores_bad_frames() {
    // SAFETY: every C entry point below is called with NULL (where the test checks NULL handling) or with pointers to live locals of the documented sizes; handles come from the library and are freed once.
    let g = golden();
    let m = open();
    let c = config(&m, &g);
    let mut s = ptr::null_mut();
    assert_eq!(
        unsafe { duo_session_new(m.0, &c, g.seed.as_ptr(), &mut s) },
        DuoResult::Ok,
        "{}",
        last_error()
    );
    let mut lat = 99;
    assert_eq!(
        unsafe { duo_session_latency_frames(s, &mut lat) },
        DuoResult::Ok
    );
    // No track yet: the latency with music pushed music_lookahead tokens
    // ahead, 4 (d + 1) - 1 = 3 at the minimum budget (0 with the track).
    assert_eq!(lat as u64, 3);
    let clean = drive(s, &g, Noise::None);
    assert_eq!(
        unsafe { duo_session_latency_frames(s, &mut lat) },
        DuoResult::Ok
    );
    assert_eq!(lat as u64, 0);
    check_against_golden(&clean, &g);
    // Reset: the same run again, now with rejected bad frames interleaved.
    assert_eq!(
        unsafe { duo_session_reset(s, g.seed.as_ptr()) },
        DuoResult::Ok
    );
    let noisy = drive(s, &g, Noise::BadFrames);
    assert!(noisy == clean, "rejected frames changed the session");
    // Freeing the model first is allowed: the session holds a reference.
    unsafe { duo_model_free(m.0) };
    unsafe { duo_session_free(s) };
}

#[test]
fn caller_memory_and_threads_agree() {
    // SAFETY: every C entry point below is called with NULL (where the test checks NULL handling) or with pointers to live locals of the documented sizes; handles come from the library and are freed once.
    let g = golden();
    let m = open();
    let c = config(&m, &g);
    let mut bytes = 0usize;
    assert_eq!(
        unsafe { duo_session_bytes(m.0, &c, &mut bytes) },
        DuoResult::Ok
    );
    // Odd address on purpose: any alignment is accepted.
    let mut mem = vec![0u8; bytes + 1];
    let mut s = ptr::null_mut();
    let small = unsafe {
        duo_session_new_in(
            m.0,
            &c,
            g.seed.as_ptr(),
            mem.as_mut_ptr().add(1),
            bytes - 1,
            &mut s,
        )
    };
    assert_eq!(small, DuoResult::BufferTooSmall);
    assert!(s.is_null());
    assert_eq!(
        unsafe {
            duo_session_new_in(
                m.0,
                &c,
                g.seed.as_ptr(),
                mem.as_mut_ptr().add(1),
                bytes,
                &mut s,
            )
        },
        DuoResult::Ok,
        "{}",
        last_error()
    );
    let reference = drive(s, &g, Noise::None);
    check_against_golden(&reference, &g);
    unsafe { duo_session_free(s) };

    let results: Vec<Vec<DuoFollowerFrame>> = std::thread::scope(|scope| {
        let handles: Vec<_> = (0..4)
            .map(|_| {
                let (m, g, c) = (&m, &g, &c);
                scope.spawn(move || {
                    let mut s = ptr::null_mut();
                    assert_eq!(
                        unsafe { duo_session_new(m.0, c, g.seed.as_ptr(), &mut s) },
                        DuoResult::Ok
                    );
                    let out = drive(s, g, Noise::None);
                    unsafe { duo_session_free(s) };
                    out
                })
            })
            .collect();
        handles.into_iter().map(|h| h.join().unwrap()).collect()
    });
    for r in results {
        assert!(r == reference);
    }
    unsafe { duo_model_free(m.0) };
}

#[test]
fn session_argument_checks() {
    // SAFETY: every C entry point below is called with NULL (where the test checks NULL handling) or with pointers to live locals of the documented sizes; handles come from the library and are freed once.
    let g = golden();
    let m = open();
    let c = config(&m, &g);
    let mut dummy = 0u8;
    let sentinel = (&mut dummy as *mut u8).cast::<DuoSession>();
    let mut s = sentinel;
    let mut bad = c;
    bad.shift = 0;
    assert_eq!(
        unsafe { duo_session_new(m.0, &bad, g.seed.as_ptr(), &mut s) },
        DuoResult::InvalidArgument
    );
    let mut bad = c;
    bad.sampling = 7;
    assert_eq!(
        unsafe { duo_session_new(m.0, &bad, g.seed.as_ptr(), &mut s) },
        DuoResult::InvalidArgument
    );
    assert!(last_error().contains("sampling"), "{}", last_error());
    let big = [1_000_000u32; 5];
    assert_eq!(
        unsafe { duo_session_new(m.0, &c, big.as_ptr(), &mut s) },
        DuoResult::InvalidArgument
    );
    assert_eq!(
        unsafe { duo_session_new(ptr::null(), &c, g.seed.as_ptr(), &mut s) },
        DuoResult::NullParameter
    );
    assert_eq!(
        unsafe { duo_session_new(m.0, ptr::null(), g.seed.as_ptr(), &mut s) },
        DuoResult::NullParameter
    );
    assert_eq!(
        unsafe { duo_session_new(m.0, &c, ptr::null(), &mut s) },
        DuoResult::NullParameter
    );
    assert_eq!(
        unsafe { duo_session_new(m.0, &c, g.seed.as_ptr(), ptr::null_mut()) },
        DuoResult::NullParameter
    );
    assert_eq!(s, sentinel);

    assert_eq!(
        unsafe { duo_session_new(m.0, &c, g.seed.as_ptr(), &mut s) },
        DuoResult::Ok
    );
    let mut f = DuoFollowerFrame {
        index: 77,
        ..Default::default()
    };
    assert_eq!(
        unsafe { duo_session_pull_follower(s, &mut f) },
        DuoResult::NotReady
    );
    assert_eq!(f.index, 77);
    let music = vec![0.0f32; 54];
    assert_eq!(
        unsafe { duo_session_push_music(s, music.as_ptr(), 53) },
        DuoResult::InvalidArgument
    );
    assert_eq!(
        unsafe { duo_session_push_music(s, ptr::null(), 0) },
        DuoResult::InvalidArgument
    );
    assert_eq!(
        unsafe { duo_session_push_music(s, ptr::null(), 54) },
        DuoResult::NullParameter
    );
    let mut nan = music.clone();
    nan[5] = f32::NAN;
    assert_eq!(
        unsafe { duo_session_push_music(s, nan.as_ptr(), 54) },
        DuoResult::NonFiniteInput
    );
    assert!(
        last_error().contains("NaN at flat index 5"),
        "{}",
        last_error()
    );
    // The length is checked before any value: a bad value past the frame
    // (or anywhere in a frame of the wrong length) is refused as a length.
    let mut long = vec![0.0f32; 55];
    long[54] = f32::NAN;
    assert_eq!(
        unsafe { duo_session_push_music(s, long.as_ptr(), 55) },
        DuoResult::InvalidArgument,
        "{}",
        last_error()
    );
    long[54] = 1e22;
    assert_eq!(
        unsafe { duo_session_set_music_track(s, long.as_ptr(), 55) },
        DuoResult::InvalidArgument,
        "{}",
        last_error()
    );
    let mut track = vec![0.0f32; 108];
    track[60] = 1e22;
    assert_eq!(
        unsafe { duo_session_set_music_track(s, track.as_ptr(), 108) },
        DuoResult::NonFiniteInput
    );
    assert!(
        last_error().contains("music track value 1e22 at flat index 60"),
        "{}",
        last_error()
    );
    assert_eq!(
        unsafe { duo_session_push_leader(s, ptr::null()) },
        DuoResult::NullParameter
    );
    assert_eq!(
        unsafe { duo_session_push_leader(ptr::null_mut(), &g.leader[0]) },
        DuoResult::NullParameter
    );
    assert_eq!(
        unsafe { duo_session_reset(s, big.as_ptr()) },
        DuoResult::InvalidArgument
    );
    let mut tokens = [9u32; 5];
    let n = 8usize;
    let flat: Vec<f32> = g.leader[..n]
        .iter()
        .flat_map(|fr| fr.joints.iter().flat_map(|v| [v.x, v.y, v.z]))
        .collect();
    assert_eq!(
        unsafe { duo_model_seed_tokens(m.0, flat.as_ptr(), flat.as_ptr(), n, tokens.as_mut_ptr()) },
        DuoResult::Ok,
        "{}",
        last_error()
    );
    assert_eq!(
        unsafe { duo_session_reset(s, tokens.as_ptr()) },
        DuoResult::Ok
    );
    assert_eq!(
        unsafe { duo_model_seed_tokens(m.0, flat.as_ptr(), flat.as_ptr(), 1, tokens.as_mut_ptr()) },
        DuoResult::InvalidArgument
    );
    unsafe { duo_session_free(s) };
    unsafe { duo_session_free(ptr::null_mut()) };
    unsafe { duo_model_free(m.0) };
}

#[test]
fn staggered_cache_and_f16_cache_settings() {
    // SAFETY: every C entry point below is called with NULL (where the test checks NULL handling) or with pointers to live locals of the documented sizes; handles come from the library and are freed once.
    let g = golden();
    let m = open();
    let base = config(&m, &g);
    let run = |c: DuoSessionConfig| {
        let mut s = ptr::null_mut();
        assert_eq!(
            unsafe { duo_session_new(m.0, &c, g.seed.as_ptr(), &mut s) },
            DuoResult::Ok,
            "{}",
            last_error()
        );
        let out = drive(s, &g, Noise::None);
        unsafe { duo_session_free(s) };
        out
    };
    check_within(
        &run(DuoSessionConfig {
            staggered: 1,
            ..base
        }),
        &g,
        MOTION_ABS,
        "staggered",
    );
    check_within(
        &run(DuoSessionConfig {
            staggered: 2,
            ..base
        }),
        &g,
        MOTION_ABS,
        "spread",
    );
    // The presets' schedule is spread (2); one cache re-prefilled at each
    // jump (0) gives the same frames.
    assert_eq!(base.staggered, 2, "the presets take the spread schedule");
    check_within(
        &run(DuoSessionConfig {
            staggered: 0,
            ..base
        }),
        &g,
        MOTION_ABS,
        "re-prefill",
    );
    // f16 K/V: same tokens on this golden; motion within a looser bound.
    check_within(
        &run(DuoSessionConfig { kv: KV_F16, ..base }),
        &g,
        1e-2,
        "f16 K/V",
    );
    let mut s = ptr::null_mut();
    for bad in [
        DuoSessionConfig { kv: 2, ..base },
        DuoSessionConfig {
            staggered: 3,
            ..base
        },
    ] {
        assert_eq!(
            unsafe { duo_session_new(m.0, &bad, g.seed.as_ptr(), &mut s) },
            DuoResult::InvalidArgument
        );
    }
    assert!(s.is_null());
    let (mut b32, mut b16) = (0usize, 0usize);
    assert_eq!(
        unsafe { duo_session_bytes(m.0, &base, &mut b32) },
        DuoResult::Ok
    );
    assert_eq!(
        unsafe { duo_session_bytes(m.0, &DuoSessionConfig { kv: KV_F16, ..base }, &mut b16) },
        DuoResult::Ok
    );
    assert!(b16 < b32, "f16 cache is smaller: {b16} vs {b32}");
    unsafe { duo_model_free(m.0) };
}

/// Sessions stepped through a `duo_step_batch` give, bit for bit, the
/// frames of the same sessions stepped alone; session 0 (the golden's
/// leader) matches the golden. Library and caller memory for the batch
/// and the sessions; a bad frame in the batch's call changes no session.
#[test]
fn sessions_stepped_in_a_batch_equal_sessions_alone() {
    // SAFETY: every C entry point below is called with NULL (where the test checks NULL handling) or with pointers to live locals of the documented sizes; handles come from the library and are freed once.
    let g = golden();
    let m = open();
    let c = config(&m, &g);
    const N: usize = 3;
    let leaders: Vec<Vec<DuoLeaderFrame>> = (0..N).map(|k| leader_of(&g, k)).collect();
    // Alone.
    let alone: Vec<Vec<DuoFollowerFrame>> = leaders
        .iter()
        .map(|l| {
            let mut s = ptr::null_mut();
            assert_eq!(
                unsafe { duo_session_new(m.0, &c, g.seed.as_ptr(), &mut s) },
                DuoResult::Ok
            );
            let out = drive(
                s,
                &Golden {
                    leader: l.clone(),
                    ..golden()
                },
                Noise::None,
            );
            unsafe { duo_session_free(s) };
            out
        })
        .collect();
    check_against_golden(&alone[0], &g);
    assert!(
        alone[1] != alone[0] && alone[2] != alone[0],
        "the leaders should give different dances"
    );

    for caller_memory in [false, true] {
        let mut session_mem = Vec::new();
        let mut batch_mem;
        let mut batch = ptr::null_mut();
        if caller_memory {
            let mut bytes = 0usize;
            assert_eq!(
                unsafe { duo_step_batch_bytes(m.0, &c, N, &mut bytes) },
                DuoResult::Ok,
                "{}",
                last_error()
            );
            batch_mem = vec![0u8; bytes + 1];
            let small = unsafe {
                duo_step_batch_new_in(
                    m.0,
                    &c,
                    N,
                    batch_mem.as_mut_ptr().add(1),
                    bytes - 1,
                    &mut batch,
                )
            };
            assert_eq!(small, DuoResult::BufferTooSmall);
            assert!(batch.is_null());
            assert_eq!(
                unsafe {
                    duo_step_batch_new_in(
                        m.0,
                        &c,
                        N,
                        batch_mem.as_mut_ptr().add(1),
                        bytes,
                        &mut batch,
                    )
                },
                DuoResult::Ok,
                "{}",
                last_error()
            );
        } else {
            assert_eq!(
                unsafe { duo_step_batch_new(m.0, &c, N, &mut batch) },
                DuoResult::Ok,
                "{}",
                last_error()
            );
        }
        let sessions: Vec<*mut DuoSession> = (0..N)
            .map(|k| {
                let mut s = ptr::null_mut();
                if caller_memory && k == 1 {
                    let mut bytes = 0usize;
                    assert_eq!(
                        unsafe { duo_session_bytes(m.0, &c, &mut bytes) },
                        DuoResult::Ok
                    );
                    session_mem = vec![0u8; bytes];
                    assert_eq!(
                        unsafe {
                            duo_session_new_in(
                                m.0,
                                &c,
                                g.seed.as_ptr(),
                                session_mem.as_mut_ptr(),
                                bytes,
                                &mut s,
                            )
                        },
                        DuoResult::Ok
                    );
                } else {
                    assert_eq!(
                        unsafe { duo_session_new(m.0, &c, g.seed.as_ptr(), &mut s) },
                        DuoResult::Ok
                    );
                }
                assert_eq!(
                    unsafe { duo_session_set_music_track(s, g.music.as_ptr(), g.music.len()) },
                    DuoResult::Ok
                );
                s
            })
            .collect();
        let mut out: Vec<Vec<DuoFollowerFrame>> = vec![Vec::new(); N];
        for i in 0..g.leader.len() {
            let frames: Vec<DuoLeaderFrame> = leaders.iter().map(|l| l[i]).collect();
            if i % 5 == 2 {
                // A bad frame for session 1: refused, naming it; nobody changes.
                let mut bad = frames.clone();
                bad[1].joints[3].z = f32::NAN;
                let mut failed = 0usize;
                assert_eq!(
                    unsafe {
                        duo_step_batch_push_leader(
                            batch,
                            sessions.as_ptr(),
                            bad.as_ptr(),
                            N,
                            &mut failed,
                        )
                    },
                    DuoResult::NonFiniteInput
                );
                assert_eq!(failed, 1);
            }
            let mut failed = 0usize;
            match unsafe {
                duo_step_batch_push_leader(
                    batch,
                    sessions.as_ptr(),
                    frames.as_ptr(),
                    N,
                    &mut failed,
                )
            } {
                DuoResult::Ok => assert_eq!(failed, duolando::batch::NO_SESSION),
                // Past the track's end no frame comes out (as in `drive`).
                DuoResult::Backlog if out[0].len() == g.frames => {
                    assert_eq!(failed, 0);
                    break;
                }
                r => panic!("frame {i}: {r:?} {}", last_error()),
            }
            for (s, o) in sessions.iter().zip(&mut out) {
                pull_all(*s, o);
            }
        }
        for k in 0..N {
            assert!(out[k] == alone[k], "session {k} (caller memory {caller_memory}): batched frames differ from the session alone");
        }
        unsafe { duo_step_batch_free(batch) };
        for s in sessions {
            unsafe { duo_session_free(s) };
        }
    }
    unsafe { duo_model_free(m.0) };
}

/// Every refusal of `duo_step_batch_push_leader` and of the batch
/// constructors, each leaving the sessions unchanged.
#[test]
fn step_batch_argument_checks() {
    // SAFETY: every C entry point below is called with NULL (where the test checks NULL handling) or with pointers to live locals of the documented sizes; handles come from the library and are freed once.
    let g = golden();
    let m = open();
    let other = open();
    let c = config(&m, &g);
    let header = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../include/duolando.h"),
    )
    .unwrap();
    assert!(header.contains(&format!(
        "#define DUO_MAX_BATCH {}",
        duolando_core::duolando::session::MAX_BATCH
    )));
    assert!(
        header.contains("#define DUO_NO_SESSION ((size_t)-1)")
            && duolando::batch::NO_SESSION == usize::MAX
    );

    let mut batch = ptr::null_mut();
    let mut bytes = 0usize;
    for n in [0, duolando_core::duolando::session::MAX_BATCH + 1] {
        assert_eq!(
            unsafe { duo_step_batch_new(m.0, &c, n, &mut batch) },
            DuoResult::InvalidArgument
        );
        assert!(last_error().contains("DUO_MAX_BATCH"), "{}", last_error());
        assert_eq!(
            unsafe { duo_step_batch_bytes(m.0, &c, n, &mut bytes) },
            DuoResult::InvalidArgument
        );
    }
    assert_eq!(
        unsafe { duo_step_batch_new(ptr::null(), &c, 2, &mut batch) },
        DuoResult::NullParameter
    );
    assert_eq!(
        unsafe { duo_step_batch_new(m.0, ptr::null(), 2, &mut batch) },
        DuoResult::NullParameter
    );
    assert_eq!(
        unsafe { duo_step_batch_new(m.0, &c, 2, ptr::null_mut()) },
        DuoResult::NullParameter
    );
    assert_eq!(
        unsafe { duo_step_batch_bytes(m.0, &c, 2, ptr::null_mut()) },
        DuoResult::NullParameter
    );
    assert_eq!(
        unsafe { duo_step_batch_new_in(m.0, &c, 2, ptr::null_mut(), 1 << 20, &mut batch) },
        DuoResult::NullParameter
    );
    assert_eq!(
        unsafe { duo_step_batch_new(m.0, &DuoSessionConfig { shift: 0, ..c }, 2, &mut batch) },
        DuoResult::InvalidArgument
    );
    assert!(batch.is_null());
    assert_eq!(
        unsafe { duo_step_batch_new(m.0, &c, 2, &mut batch) },
        DuoResult::Ok
    );

    let new = |model: &Model, cfg: &DuoSessionConfig| {
        let mut s = ptr::null_mut();
        assert_eq!(
            unsafe { duo_session_new(model.0, cfg, g.seed.as_ptr(), &mut s) },
            DuoResult::Ok,
            "{}",
            last_error()
        );
        assert_eq!(
            unsafe { duo_session_set_music_track(s, g.music.as_ptr(), g.music.len()) },
            DuoResult::Ok
        );
        s
    };
    let (a, b) = (new(&m, &c), new(&m, &c));
    let on_other = new(&other, &c);
    let frames = [g.leader[0], g.leader[0]];
    let push = |ss: &[*mut DuoSession], fr: *const DuoLeaderFrame, n: usize| {
        let mut failed = 12345usize;
        let r = unsafe { duo_step_batch_push_leader(batch, ss.as_ptr(), fr, n, &mut failed) };
        (r, failed)
    };
    let none = duolando::batch::NO_SESSION;
    assert_eq!(push(&[a, b], frames.as_ptr(), 0), (DuoResult::Ok, none));
    assert_eq!(
        push(&[a, b, a], [g.leader[0]; 3].as_ptr(), 3),
        (DuoResult::InvalidArgument, none)
    );
    assert_eq!(
        push(&[a, a], frames.as_ptr(), 2),
        (DuoResult::InvalidArgument, 1)
    );
    assert!(
        last_error().contains("sessions[1] is sessions[0] again"),
        "{}",
        last_error()
    );
    assert_eq!(
        push(&[a, ptr::null_mut()], frames.as_ptr(), 2),
        (DuoResult::NullParameter, 1)
    );
    assert_eq!(
        push(&[a, on_other], frames.as_ptr(), 2),
        (DuoResult::InvalidArgument, 1)
    );
    assert!(last_error().contains("another model"), "{}", last_error());
    let mut bad = frames;
    bad[0].joints[0].x = 1e9;
    assert_eq!(
        push(&[a, b], bad.as_ptr(), 2),
        (DuoResult::NonFiniteInput, 0)
    );
    assert_eq!(
        push(&[a, b], ptr::null(), 2),
        (DuoResult::NullParameter, none)
    );
    let mut failed = 7usize;
    assert_eq!(
        unsafe { duo_step_batch_push_leader(batch, ptr::null(), frames.as_ptr(), 2, &mut failed) },
        DuoResult::NullParameter
    );
    assert_eq!(failed, none);
    assert_eq!(
        unsafe {
            duo_step_batch_push_leader(
                ptr::null_mut(),
                [a, b].as_ptr(),
                frames.as_ptr(),
                2,
                ptr::null_mut(),
            )
        },
        DuoResult::NullParameter
    );
    // None of the refused calls took a frame: `a` still has its whole run ahead, as a fresh session.
    let fresh = new(&m, &c);
    let mut outs = [Vec::new(), Vec::new()];
    for (i, frame) in g.leader.iter().enumerate().take(40) {
        assert_eq!(
            push(&[a, b], [*frame; 2].as_ptr(), 2),
            (DuoResult::Ok, none),
            "frame {i}: {}",
            last_error()
        );
        assert_eq!(
            unsafe { duo_session_push_leader(fresh, frame) },
            DuoResult::Ok
        );
        pull_all(a, &mut outs[0]);
        pull_all(fresh, &mut outs[1]);
    }
    assert!(!outs[0].is_empty() && outs[0] == outs[1]);
    for s in [a, b, on_other, fresh] {
        unsafe { duo_session_free(s) };
    }
    unsafe { duo_step_batch_free(batch) };
    unsafe { duo_step_batch_free(ptr::null_mut()) };
    unsafe { duo_model_free(m.0) };
    unsafe { duo_model_free(other.0) };
}

/// `text` with C comments removed.
fn strip_c_comments(text: &str) -> String {
    let mut out = String::new();
    let mut rest = text;
    while let Some(i) = rest.find("/*") {
        out.push_str(&rest[..i]);
        rest = rest[i..].find("*/").map_or("", |j| &rest[i + j + 2..]);
    }
    out.push_str(rest);
    out
}

/// The header's functions with a buffer: a pointer parameter directly
/// followed by a `size_t` one (its element count), as (function, pointer
/// parameter) pairs.
fn header_buffers() -> std::collections::BTreeSet<(String, String)> {
    let header = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../include/duolando.h"),
    )
    .unwrap();
    let code: String = strip_c_comments(&header)
        .lines()
        .filter(|l| !l.trim_start().starts_with('#'))
        .map(|l| format!("{l}\n"))
        .collect();
    let mut out = std::collections::BTreeSet::new();
    for decl in code.split(';') {
        let Some(open) = decl.find('(') else { continue };
        let name = decl[..open]
            .split_whitespace()
            .last()
            .unwrap_or("")
            .trim_start_matches('*');
        if !name.starts_with("duo_") || decl.contains("typedef") {
            continue;
        }
        let params: Vec<&str> = decl[open + 1..decl.rfind(')').unwrap()]
            .split(',')
            .map(str::trim)
            .collect();
        for w in params.windows(2) {
            if w[0].contains('*') && w[1].starts_with("size_t ") && !w[1].contains('*') {
                let p = w[0].rsplit(['*', ' ']).next().unwrap();
                out.insert((name.to_string(), p.to_string()));
            }
        }
    }
    out
}

/// The header's rule, "NULL with count 0 is an empty buffer, answered
/// exactly as a non-NULL one with count 0; NULL with a count is
/// DUO_NULL_PARAMETER", on every function of the header that takes a
/// buffer (found in the header, so a new one fails this test until it is
/// listed and checked here).
#[test]
fn every_buffer_follows_the_null_rule() {
    // SAFETY: every C entry point below is called with NULL (where the test checks NULL handling) or with pointers to live locals of the documented sizes; handles come from the library and are freed once.
    let checked: &[(&str, &str)] = &[
        ("duo_last_error_message", "buf"),
        ("duo_model_open_bytes", "bytes"),
        ("duo_model_open_copy", "bytes"),
        ("duo_model_seed_tokens", "leader_pos3d"),
        ("duo_session_new_in", "memory"),
        ("duo_session_set_music_track", "track"),
        ("duo_session_push_music", "features"),
        ("duo_session_pull_positions", "out"),
        ("duo_step_batch_new_in", "memory"),
        ("duo_step_batch_push_leader", "frames"),
    ];
    // Checked in ffi/tests/batched_session.rs (`batched_session_refusals`).
    let batched: &[(&str, &str)] = &[("duo_session_new_batched_in", "memory")];
    // Transflower's: checked in ffi/tests/transflower_session.rs
    // (`buffers_follow_the_null_rule`, on a Transflower model) and, for
    // its step batches, ffi/tests/transflower_batch.rs
    // (`sessions_follow_the_null_rule`, `sizes_memory_and_batched_sessions`).
    let transflower: &[(&str, &str)] = &[
        ("duo_transflower_step_batch_new_in", "memory"),
        ("duo_step_batch_step", "sessions"),
        ("duo_transflower_session_new", "seed_motion"),
        ("duo_transflower_session_new", "labels"),
        ("duo_transflower_session_new_in", "seed_motion"),
        ("duo_transflower_session_new_in", "labels"),
        ("duo_transflower_session_new_in", "memory"),
        ("duo_transflower_push_input", "rows"),
        ("duo_transflower_pull_frame", "out"),
        ("duo_transflower_pull_frame_with_noise", "noise"),
        ("duo_transflower_pull_frame_with_noise", "out"),
    ];
    // A struct pointer followed by a count that is not its length.
    let not_buffers: &[(&str, &str)] = &[
        ("duo_step_batch_bytes", "config"),
        ("duo_step_batch_new", "config"),
        ("duo_step_batch_new_in", "config"),
    ];
    let want: std::collections::BTreeSet<(String, String)> = checked
        .iter()
        .chain(batched)
        .chain(transflower)
        .chain(not_buffers)
        .map(|(f, p)| (f.to_string(), p.to_string()))
        .collect();
    assert_eq!(
        header_buffers(),
        want,
        "a function of the header takes a buffer: check it here"
    );

    let g = golden();
    let m = open();
    let c = config(&m, &g);
    let nothing = [0u8; 64];
    let aligned = duolando_runtime::model_file::AlignedBytes::copy_from(&[0u8; 64]);
    let mut dummy = 0u8;
    let sentinel = (&mut dummy as *mut u8).cast::<DuoModel>();

    // duo_last_error_message: NULL buf writes nothing, whatever len.
    assert_eq!(
        unsafe { duo_session_push_music(ptr::null_mut(), ptr::null(), 0) },
        DuoResult::NullParameter
    );
    let full = unsafe { duo_last_error_message(ptr::null_mut(), 0) };
    assert!(full > 0);
    assert_eq!(
        unsafe { duo_last_error_message(ptr::null_mut(), 100) },
        full
    );
    let mut buf = [0x55 as c_char; 4];
    assert_eq!(unsafe { duo_last_error_message(buf.as_mut_ptr(), 0) }, full);
    assert_eq!(buf, [0x55 as c_char; 4]);

    // Models from empty bytes: not a model, NULL or not.
    for opener in [duo_model_open_bytes, duo_model_open_copy] {
        let mut out = sentinel;
        assert_eq!(
            unsafe { opener(ptr::null(), 0, &mut out) },
            DuoResult::BadModel
        );
        let null_msg = last_error();
        assert!(
            null_msg.ends_with("buffer of 0 bytes is shorter than the 24-byte .duo prefix"),
            "{null_msg}"
        );
        for p in [aligned.as_bytes().as_ptr(), nothing[1..].as_ptr()] {
            assert_eq!(unsafe { opener(p, 0, &mut out) }, DuoResult::BadModel);
            assert_eq!(last_error(), null_msg);
        }
        assert_eq!(
            unsafe { opener(ptr::null(), 64, &mut out) },
            DuoResult::NullParameter
        );
        assert!(last_error().ends_with("bytes is NULL"), "{}", last_error());
        assert_eq!(out, sentinel);
    }

    // Seed tokens from no frames: too few frames, NULL or not.
    let mut tokens = [7u32; 5];
    let flat = vec![0.0f32; 8 * 165];
    let empty = [0.0f32; 1];
    for (f, l) in [
        (ptr::null(), ptr::null()),
        (empty.as_ptr(), empty.as_ptr()),
        (ptr::null(), empty.as_ptr()),
        (empty.as_ptr(), ptr::null()),
    ] {
        assert_eq!(
            unsafe { duo_model_seed_tokens(m.0, f, l, 0, tokens.as_mut_ptr()) },
            DuoResult::InvalidArgument,
            "{}",
            last_error()
        );
        assert!(last_error().contains("0 frames"), "{}", last_error());
    }
    assert_eq!(
        unsafe { duo_model_seed_tokens(m.0, ptr::null(), flat.as_ptr(), 8, tokens.as_mut_ptr()) },
        DuoResult::NullParameter
    );
    assert!(
        last_error().ends_with("follower_pos3d is NULL"),
        "{}",
        last_error()
    );
    assert_eq!(
        unsafe { duo_model_seed_tokens(m.0, flat.as_ptr(), ptr::null(), 8, tokens.as_mut_ptr()) },
        DuoResult::NullParameter
    );
    assert!(
        last_error().ends_with("leader_pos3d is NULL"),
        "{}",
        last_error()
    );
    assert_eq!(tokens, [7; 5]);

    // Caller memory of 0 bytes: too small, NULL or not; NULL with a length: NULL.
    let mut bytes = 0usize;
    assert_eq!(
        unsafe { duo_session_bytes(m.0, &c, &mut bytes) },
        DuoResult::Ok
    );
    let mut mem = nothing;
    let mut s = ptr::null_mut();
    assert_eq!(
        unsafe { duo_session_new_in(m.0, &c, g.seed.as_ptr(), ptr::null_mut(), 0, &mut s) },
        DuoResult::BufferTooSmall
    );
    assert_eq!(
        unsafe { duo_session_new_in(m.0, &c, g.seed.as_ptr(), mem.as_mut_ptr(), 0, &mut s) },
        DuoResult::BufferTooSmall
    );
    assert_eq!(
        unsafe { duo_session_new_in(m.0, &c, g.seed.as_ptr(), ptr::null_mut(), bytes, &mut s) },
        DuoResult::NullParameter
    );
    assert!(last_error().ends_with("memory is NULL"), "{}", last_error());
    let mut batch = ptr::null_mut();
    assert_eq!(
        unsafe { duo_step_batch_bytes(m.0, &c, 2, &mut bytes) },
        DuoResult::Ok
    );
    assert_eq!(
        unsafe { duo_step_batch_new_in(m.0, &c, 2, ptr::null_mut(), 0, &mut batch) },
        DuoResult::BufferTooSmall
    );
    assert_eq!(
        unsafe { duo_step_batch_new_in(m.0, &c, 2, mem.as_mut_ptr(), 0, &mut batch) },
        DuoResult::BufferTooSmall
    );
    assert_eq!(
        unsafe { duo_step_batch_new_in(m.0, &c, 2, ptr::null_mut(), bytes, &mut batch) },
        DuoResult::NullParameter
    );
    assert!(s.is_null() && batch.is_null());

    let new = || {
        let mut s = ptr::null_mut();
        assert_eq!(
            unsafe { duo_session_new(m.0, &c, g.seed.as_ptr(), &mut s) },
            DuoResult::Ok
        );
        s
    };
    // Music frames of 0 floats: a wrong count, NULL or not.
    let (a, b) = (new(), new());
    let music = [0.0f32; 54];
    assert_eq!(
        unsafe { duo_session_push_music(a, ptr::null(), 0) },
        DuoResult::InvalidArgument
    );
    let null_msg = last_error();
    assert_eq!(
        unsafe { duo_session_push_music(a, music.as_ptr(), 0) },
        DuoResult::InvalidArgument
    );
    assert_eq!(last_error(), null_msg);
    assert!(null_msg.contains("has 0 values, 54 expected"), "{null_msg}");
    assert_eq!(
        unsafe { duo_session_push_music(a, ptr::null(), 54) },
        DuoResult::NullParameter
    );
    // An empty track: what `(s, buf, 0)` does, NULL or not (accepted, and
    // music is then given), and both sessions then answer alike.
    let r_null = unsafe { duo_session_set_music_track(a, ptr::null(), 0) };
    let r_buf = unsafe { duo_session_set_music_track(b, music.as_ptr(), 0) };
    assert_eq!(
        (r_null, r_buf),
        (DuoResult::Ok, DuoResult::Ok),
        "{}",
        last_error()
    );
    for s in [a, b] {
        assert_eq!(
            unsafe { duo_session_set_music_track(s, g.music.as_ptr(), g.music.len()) },
            DuoResult::InvalidArgument
        );
        assert_eq!(
            unsafe { duo_session_push_music(s, music.as_ptr(), 54) },
            DuoResult::InvalidArgument
        );
    }
    assert_eq!(
        unsafe { duo_session_set_music_track(a, ptr::null(), 54) },
        DuoResult::NullParameter
    );
    // Positions into 0 floats: a wrong count, NULL or not; NULL with a count: NULL.
    let mut pos = [0.0f32; 165];
    assert_eq!(
        unsafe { duo_session_pull_positions(a, ptr::null_mut(), 0, ptr::null_mut()) },
        DuoResult::InvalidArgument
    );
    let null_msg = last_error();
    assert!(
        null_msg.contains("n_floats is 0; a frame of this model has 55 joints x 3 = 165 floats"),
        "{null_msg}"
    );
    assert_eq!(
        unsafe { duo_session_pull_positions(a, pos.as_mut_ptr(), 0, ptr::null_mut()) },
        DuoResult::InvalidArgument
    );
    assert_eq!(last_error(), null_msg);
    assert_eq!(
        unsafe { duo_session_pull_positions(a, ptr::null_mut(), 165, ptr::null_mut()) },
        DuoResult::NullParameter
    );
    assert_eq!(
        unsafe { duo_session_pull_positions(a, pos.as_mut_ptr(), 165, ptr::null_mut()) },
        DuoResult::NotReady
    );

    // A batch call of 0 sessions does nothing, NULL lists or not.
    assert_eq!(
        unsafe { duo_step_batch_new(m.0, &c, 2, &mut batch) },
        DuoResult::Ok
    );
    let frames = [g.leader[0]; 2];
    for (ss, fr) in [
        (ptr::null(), ptr::null()),
        ([a, b].as_ptr(), frames.as_ptr()),
        (ptr::null(), frames.as_ptr()),
    ] {
        let mut failed = 0usize;
        assert_eq!(
            unsafe { duo_step_batch_push_leader(batch, ss, fr, 0, &mut failed) },
            DuoResult::Ok
        );
        assert_eq!(failed, NO_SESSION);
    }
    let mut failed = 0usize;
    assert_eq!(
        unsafe { duo_step_batch_push_leader(batch, [a, b].as_ptr(), ptr::null(), 2, &mut failed) },
        DuoResult::NullParameter
    );
    assert_eq!(
        unsafe { duo_step_batch_push_leader(batch, ptr::null(), frames.as_ptr(), 2, &mut failed) },
        DuoResult::NullParameter
    );
    unsafe { duo_step_batch_free(batch) };
    for s in [a, b] {
        unsafe { duo_session_free(s) };
    }
    unsafe { duo_model_free(m.0) };
}

/// `duo_step_batch_push_leader` checks in one order (the header): the
/// call, then every session (NULL, twice, another model), then every
/// frame, then every session's backlog; each case below has refusals of
/// two classes where index order and class order disagree.
#[test]
fn step_batch_refusals_come_in_the_stated_order() {
    // SAFETY: every C entry point below is called with NULL (where the test checks NULL handling) or with pointers to live locals of the documented sizes; handles come from the library and are freed once.
    let g = golden();
    let m = open();
    let other = open();
    let c = config(&m, &g);
    let new = |model: &Model| {
        let mut s = ptr::null_mut();
        assert_eq!(
            unsafe { duo_session_new(model.0, &c, g.seed.as_ptr(), &mut s) },
            DuoResult::Ok,
            "{}",
            last_error()
        );
        assert_eq!(
            unsafe { duo_session_set_music_track(s, g.music.as_ptr(), g.music.len()) },
            DuoResult::Ok
        );
        s
    };
    // Session 1 and 3 backlogged: leader frames pushed, none pulled, up to the refusal.
    let s: Vec<*mut DuoSession> = (0..5)
        .map(|i| if i == 4 { new(&other) } else { new(&m) })
        .collect();
    for &k in &[s[1], s[3]] {
        let mut pushed = 0;
        while unsafe { duo_session_push_leader(k, &g.leader[pushed]) } == DuoResult::Ok {
            pushed += 1;
            assert!(
                pushed < g.leader.len(),
                "no backlog before the golden's end"
            );
        }
        assert_eq!(
            unsafe { duo_session_push_leader(k, &g.leader[pushed]) },
            DuoResult::Backlog
        );
    }
    let mut batch = ptr::null_mut();
    assert_eq!(
        unsafe { duo_step_batch_new(m.0, &c, 5, &mut batch) },
        DuoResult::Ok
    );
    let push = |ss: &[*mut DuoSession], fr: &[DuoLeaderFrame]| {
        let mut failed = 12345usize;
        let r = unsafe {
            duo_step_batch_push_leader(batch, ss.as_ptr(), fr.as_ptr(), ss.len(), &mut failed)
        };
        (r, failed, last_error())
    };
    let good = [g.leader[0]; 5];
    let bad_at = |i: usize| {
        let mut f = good;
        f[i].joints[7].y = f32::INFINITY;
        f
    };
    let dup = [s[0], s[1], s[2], s[0], s[4]];
    // Another model at 4 before a backlogged session 1.
    let (r, f, msg) = push(&s, &good);
    assert_eq!((r, f), (DuoResult::InvalidArgument, 4), "{msg}");
    assert!(
        msg.contains("sessions[4]") && msg.contains("another model"),
        "{msg}"
    );
    // Another model at 4 before a bad frame 0.
    let (r, f, _) = push(&s, &bad_at(0));
    assert_eq!((r, f), (DuoResult::InvalidArgument, 4));
    // A repeated session at 3 before a bad frame 0 and another model at 4.
    let (r, f, msg) = push(&dup, &bad_at(0));
    assert_eq!((r, f), (DuoResult::InvalidArgument, 3), "{msg}");
    assert!(msg.contains("sessions[3] is sessions[0] again"), "{msg}");
    // A NULL session at 2 before another model at 4 and a bad frame 0.
    let (r, f, _) = push(&[s[0], s[1], ptr::null_mut(), s[3], s[4]], &bad_at(0));
    assert_eq!((r, f), (DuoResult::NullParameter, 2));
    // Without the stranger: a bad frame 3 before the backlogged session 1.
    let four = &s[..4];
    let (r, f, msg) = push(four, &bad_at(3)[..4]);
    assert_eq!((r, f), (DuoResult::NonFiniteInput, 3), "{msg}");
    // Good frames: the first backlogged session, 1 (not 3).
    let (r, f, msg) = push(four, &good[..4]);
    assert_eq!((r, f), (DuoResult::Backlog, 1), "{msg}");
    // Nobody changed: session 0 and 2 then step as fresh sessions do.
    let fresh = new(&m);
    let (mut a, mut b) = (Vec::new(), Vec::new());
    for frame in g.leader.iter().take(24) {
        assert_eq!(push(&[s[0], s[2]], &[*frame; 2]).0, DuoResult::Ok);
        assert_eq!(
            unsafe { duo_session_push_leader(fresh, frame) },
            DuoResult::Ok
        );
        pull_all(s[0], &mut a);
        pull_all(fresh, &mut b);
    }
    assert!(!a.is_empty() && a == b);
    unsafe { duo_step_batch_free(batch) };
    for k in s.into_iter().chain([fresh]) {
        unsafe { duo_session_free(k) };
    }
    unsafe { duo_model_free(m.0) };
    unsafe { duo_model_free(other.0) };
}

/// Messages of the C API use the C names (`config.top_k`, not `topk`).
#[test]
fn messages_name_the_c_fields() {
    // SAFETY: every C entry point below is called with NULL (where the test checks NULL handling) or with pointers to live locals of the documented sizes; handles come from the library and are freed once.
    let g = golden();
    let m = open();
    let c = DuoSessionConfig {
        sampling: SAMPLING_TOP_K,
        top_k: 0,
        ..config(&m, &g)
    };
    let mut bytes = 0usize;
    assert_eq!(
        unsafe { duo_session_bytes(m.0, &c, &mut bytes) },
        DuoResult::InvalidArgument
    );
    let msg = last_error();
    assert!(msg.contains("top_k = 0") && !msg.contains("topk"), "{msg}");
    for (field, bad) in [
        (
            "lookahead",
            DuoSessionConfig {
                lookahead: 999,
                ..c
            },
        ),
        (
            "music_lookahead",
            DuoSessionConfig {
                music_lookahead: 999,
                ..c
            },
        ),
        ("lat_past", DuoSessionConfig { lat_past: 999, ..c }),
        ("shift", DuoSessionConfig { shift: 0, ..c }),
        (
            "pending_frames",
            DuoSessionConfig {
                pending_frames: u32::MAX,
                ..c
            },
        ),
        (
            "music_buffer_frames",
            DuoSessionConfig {
                music_buffer_frames: u32::MAX,
                ..c
            },
        ),
    ] {
        let bad = DuoSessionConfig { top_k: 4, ..bad };
        assert_eq!(
            unsafe { duo_session_bytes(m.0, &bad, &mut bytes) },
            DuoResult::InvalidArgument,
            "{field}"
        );
        assert!(
            last_error().contains(&format!("{field} = ")),
            "{field}: {}",
            last_error()
        );
    }
    unsafe { duo_model_free(m.0) };
}
