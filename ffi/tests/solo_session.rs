//! Solo (Bailando) models through the C API: a model of either family
//! opens, `duo_model_get_info` describes its skeleton and music, a session
//! made with the "exact" preset and fed the golden music reproduces the
//! authors' positions (tests/fixtures/bailando_rollout_btiny_demo_odd,
//! within R's 1e-5 m), in library and caller memory, from live rows and
//! from a track; every Duolando-only entry point is a named refusal that
//! leaves the session unchanged.

mod common;
use common::*;
use std::ffi::CString;
use std::ptr;

use duolando::batch::*;
use duolando::frames::{DuoFollowerFrame, DuoLeaderFrame};
use duolando::model::*;
use duolando::result::DuoResult;
use duolando::session::*;
use duolando_std::npy::{read_f32_2d, read_i64_2d};

/// R's tolerance on positions (tests/bailando_exact.rs).
const POS_TOL: f32 = 1e-5;



fn open() -> *mut DuoModel {
    open_model(&fixture("bailando_btiny/model.duo"))
}

fn preset(m: *const DuoModel, name: &str) -> DuoSessionConfig {
    let mut c = DuoSessionConfig::default();
    let n = CString::new(name).unwrap();
    // SAFETY: live model, NUL-terminated name, writable config.
    assert_eq!(
        unsafe { duo_session_config_preset(m, n.as_ptr(), &mut c) },
        DuoResult::Ok,
        "{}",
        last_error()
    );
    c
}

/// Every frame of `s` after its music (all rows, live or as a track) and
/// the end.
fn dance(s: *mut DuoSession, music: &[f32], live: bool) -> Vec<f32> {
    let mut out = Vec::new();
    let mut f = [0f32; 72];
    let mut pull = |out: &mut Vec<f32>| loop {
        let mut index = u64::MAX;
        // SAFETY: a live session, 72 writable floats, a writable index.
        match unsafe { duo_session_pull_positions(s, f.as_mut_ptr(), 72, &mut index) } {
            DuoResult::Ok => {
                assert_eq!(index as usize, out.len() / 72);
                out.extend_from_slice(&f);
            }
            DuoResult::NotReady => break,
            r => panic!("{r:?}: {}", last_error()),
        }
    };
    if live {
        for row in music.chunks_exact(438) {
            // SAFETY: a live session and 438 readable floats.
            assert_eq!(
                unsafe { duo_session_push_music(s, row.as_ptr(), row.len()) },
                DuoResult::Ok,
                "{}",
                last_error()
            );
            pull(&mut out);
        }
    } else {
        // SAFETY: a live session and the whole track readable.
        assert_eq!(
            unsafe { duo_session_set_music_track(s, music.as_ptr(), music.len()) },
            DuoResult::Ok,
            "{}",
            last_error()
        );
    }
    // SAFETY: a live session.
    assert_eq!(
        unsafe { duo_session_finish(s) },
        DuoResult::Ok,
        "{}",
        last_error()
    );
    pull(&mut out);
    out
}

#[test]
fn a_solo_session_dances_the_golden() {
    let dir = fixture("bailando_rollout_btiny_demo_odd");
    let music = read_f32_2d(&dir.join("music.npy"), Some(438), "music").unwrap();
    let tokens = read_i64_2d(&dir.join("tokens.npy"), Some(2), "tokens").unwrap();
    let want = read_f32_2d(&dir.join("pos3d.npy"), Some(72), "pos3d").unwrap();
    let seed = [tokens.data[0] as u32, tokens.data[1] as u32];
    let m = open();
    let mut info = DuoModelInfo::default();
    // SAFETY: a live model and a writable info.
    assert_eq!(unsafe { duo_model_get_info(m, &mut info) }, DuoResult::Ok);
    assert_eq!(
        (
            info.family,
            info.joints,
            info.music_features,
            info.fps,
            info.frames_per_token,
            info.look_forward
        ),
        (1, 24, 438, 60, 8, 0)
    );
    let mut c = preset(m, "exact");
    c.music_buffer_frames = music.rows as u32;
    for (live, in_caller) in [(true, false), (false, false), (true, true)] {
        let mut s = ptr::null_mut();
        let mut mem = Vec::new();
        if in_caller {
            let mut n = 0usize;
            // SAFETY: live model, valid config, writable size.
            assert_eq!(unsafe { duo_session_bytes(m, &c, &mut n) }, DuoResult::Ok);
            mem = vec![0u8; n];
            // SAFETY: `n` writable bytes kept until the session is freed; 2 seed tokens.
            assert_eq!(
                unsafe { duo_session_new_in(m, &c, seed.as_ptr(), mem.as_mut_ptr(), n, &mut s) },
                DuoResult::Ok,
                "{}",
                last_error()
            );
        } else {
            // SAFETY: live model, valid config, 2 seed tokens, writable out.
            assert_eq!(
                unsafe { duo_session_new(m, &c, seed.as_ptr(), &mut s) },
                DuoResult::Ok,
                "{}",
                last_error()
            );
        }
        let mut lat = 99;
        // SAFETY: live session, writable out.
        assert_eq!(
            unsafe { duo_session_latency_frames(s, &mut lat) },
            DuoResult::Ok
        );
        assert_eq!(lat, 8 * c.dec_future);
        let got = dance(s, &music.data, live);
        assert_eq!(got.len(), want.data.len(), "live {live}: frames");
        let err = got
            .iter()
            .zip(&want.data)
            .map(|(a, b)| (a - b).abs())
            .fold(0f32, f32::max);
        assert!(
            err <= POS_TOL,
            "live {live} caller memory {in_caller}: max abs err {err:e}"
        );
        // SAFETY: a live session, freed once; its memory outlives it.
        unsafe { duo_session_free(s) };
        drop(mem);
    }
    // SAFETY: a live model, freed once.
    unsafe { duo_model_free(m) };
}

/// Duolando-only entry points and settings are refused by name; the
/// session is unchanged (its dance afterwards is the clean one).
#[test]
fn duolando_only_calls_are_named_refusals() {
    let m = open();
    let dir = fixture("bailando_rollout_btiny_demo_odd");
    let music = read_f32_2d(&dir.join("music.npy"), Some(438), "music").unwrap();
    let mut c = preset(m, "interactive");
    c.music_buffer_frames = music.rows as u32;
    let seed = [3u32, 2];
    for (field, set) in [
        ("lookahead", 0usize),
        ("enc_future", 1),
        ("music_lookahead", 2),
        ("lat_past", 3),
        ("staggered", 4),
    ] {
        let mut bad = c;
        *[
            &mut bad.lookahead,
            &mut bad.enc_future,
            &mut bad.music_lookahead,
            &mut bad.lat_past,
            &mut bad.staggered,
        ][set] = 1;
        let mut n = 0usize;
        // SAFETY: live model, valid config, writable size.
        assert_eq!(
            unsafe { duo_session_bytes(m, &bad, &mut n) },
            DuoResult::InvalidArgument
        );
        assert!(
            last_error().contains(&format!("config.{field} is 1")),
            "{}",
            last_error()
        );
    }
    let unknown = CString::new("live-music").unwrap();
    let mut out = DuoSessionConfig::default();
    // SAFETY: live model, NUL-terminated name, writable config.
    assert_eq!(
        unsafe { duo_session_config_preset(m, unknown.as_ptr(), &mut out) },
        DuoResult::InvalidArgument
    );
    assert!(
        last_error()
            .contains("for a Bailando model (presets: exact, reference, interactive, minimum)"),
        "{}",
        last_error()
    );
    let mut toks = [0u32; 5];
    let frames = [0f32; 165 * 4];
    // SAFETY: live model, readable frames, writable tokens.
    assert_eq!(
        unsafe { duo_model_seed_tokens(m, frames.as_ptr(), frames.as_ptr(), 4, toks.as_mut_ptr()) },
        DuoResult::InvalidArgument
    );
    assert!(
        last_error().contains("this is a Bailando model"),
        "{}",
        last_error()
    );
    let mut bb = 0usize;
    // SAFETY: live model, valid config, writable size.
    assert_eq!(
        unsafe { duo_step_batch_bytes(m, &c, 2, &mut bb) },
        DuoResult::InvalidArgument
    );

    let mut s = ptr::null_mut();
    // SAFETY: live model, valid config, 2 seed tokens, writable out.
    assert_eq!(
        unsafe { duo_session_new(m, &c, seed.as_ptr(), &mut s) },
        DuoResult::Ok,
        "{}",
        last_error()
    );
    let first = &music.data[..438];
    // SAFETY: a live session and readable frames/rows throughout.
    unsafe {
        assert_eq!(
            duo_session_push_music(s, first.as_ptr(), first.len()),
            DuoResult::Ok
        );
        assert_eq!(
            duo_session_push_leader(s, &DuoLeaderFrame::default()),
            DuoResult::InvalidArgument
        );
        assert!(
            last_error()
                .contains("duo_session_push_leader: this session's model is a Bailando model"),
            "{}",
            last_error()
        );
        // The family is refused before the frame's values are read.
        let mut nan = DuoLeaderFrame::default();
        nan.joints[0].x = f32::NAN;
        assert_eq!(
            duo_session_push_leader(s, &nan),
            DuoResult::InvalidArgument
        );
        let mut ff = DuoFollowerFrame::default();
        assert_eq!(
            duo_session_pull_follower(s, &mut ff),
            DuoResult::InvalidArgument
        );
        let mut small = [0f32; 165];
        assert_eq!(
            duo_session_pull_positions(s, small.as_mut_ptr(), 165, ptr::null_mut()),
            DuoResult::InvalidArgument
        );
        assert!(
            last_error().contains("24 joints x 3 = 72 floats"),
            "{}",
            last_error()
        );
        assert_eq!(
            duo_session_push_music(s, first.as_ptr(), 437),
            DuoResult::InvalidArgument
        );
        let mut nan = first.to_vec();
        nan[5] = f32::NAN;
        assert_eq!(
            duo_session_push_music(s, nan.as_ptr(), nan.len()),
            DuoResult::NonFiniteInput
        );
        assert!(last_error().contains("at flat index 5"), "{}", last_error());
        assert_eq!(
            duo_session_set_music_track(s, music.data.as_ptr(), music.data.len()),
            DuoResult::InvalidArgument,
            "a track after a row"
        );
        let mut batch = ptr::null_mut();
        let d = preset_duolando_free_batch(&mut batch);
        let sessions = [s];
        let mut failed = 0usize;
        if let Some(b) = d {
            assert_eq!(
                duo_step_batch_push_leader(
                    b,
                    sessions.as_ptr(),
                    &DuoLeaderFrame::default(),
                    1,
                    &mut failed
                ),
                DuoResult::InvalidArgument
            );
            assert!(last_error().contains("Bailando"), "{}", last_error());
            duo_step_batch_free(b);
        }
        // Unchanged: the rest of the music gives the clean dance.
        let rest = dance(s, &music.data[438..], true);
        let mut s2 = ptr::null_mut();
        assert_eq!(
            duo_session_new(m, &c, seed.as_ptr(), &mut s2),
            DuoResult::Ok
        );
        let clean = dance(s2, &music.data, true);
        assert_eq!(rest, clean);
        // Finish again does nothing; reset with 2 tokens starts over.
        assert_eq!(duo_session_finish(s), DuoResult::Ok);
        assert_eq!(
            duo_session_reset(s, [600u32, 0].as_ptr()),
            DuoResult::InvalidArgument
        );
        assert_eq!(duo_session_reset(s, seed.as_ptr()), DuoResult::Ok);
        assert_eq!(dance(s, &music.data, false), clean);
        duo_session_free(s);
        duo_session_free(s2);
        duo_model_free(m);
    }
}

/// A step batch of the Duolando fixture (a solo session handed to it is
/// refused by family).
fn preset_duolando_free_batch(out: &mut *mut DuoStepBatch) -> Option<*mut DuoStepBatch> {
    let p = CString::new(fixture("tiny/model.duo").to_str().unwrap()).unwrap();
    let mut m = ptr::null_mut();
    // SAFETY: a NUL-terminated path and live out-pointers; the model is freed after the batch is made (a batch holds no model reference).
    unsafe {
        assert_eq!(duo_model_open_file(p.as_ptr(), &mut m), DuoResult::Ok);
        let mut c = DuoSessionConfig::default();
        assert_eq!(duo_session_config_minimum(m, &mut c), DuoResult::Ok);
        let r = duo_step_batch_new(m, &c, 2, out);
        duo_model_free(m);
        (r == DuoResult::Ok).then_some(*out)
    }
}
