//! Transflower models through the C API: the model opens and describes
//! itself (`duo_model_get_info`, `duo_transflower_get_info`); a session of
//! the "exact" preset, its audio pushed row by row, replaying the recorded
//! noise, gives R's frames bit for bit (the engine's `exact::generate` on
//! the same file) and within the goldens' tolerance of the authors'
//! output; the seeded RNG = R with `Seeded`; reset replays; every
//! Duolando / Bailando entry point on it is a named refusal; bad counts,
//! NaN and another family's model are refused with the session unchanged.

mod common;
use common::*;
use std::ffi::CString;
use std::path::{Path, PathBuf};
use std::ptr;

use duolando::model::*;
use duolando::result::DuoResult;
use duolando::session::*;
use duolando::transflower::*;
use duolando_core::format::DuoFile;
use duolando_core::transflower::exact::{
    generate, generate_scratch_bytes, steps, Input, Replay, Seeded,
};
use duolando_core::transflower::model::Model;
use duolando_std::npy::read_f32_2d;

fn case() -> PathBuf {
    fixture("transflower_paper")
}



fn npy3(path: &Path) -> Vec<f32> {
    let bytes = std::fs::read(path).unwrap();
    npyz::NpyFile::new(bytes.as_slice())
        .unwrap()
        .into_vec::<f32>()
        .unwrap()
}

/// R's frames (N, C) on the same file: noise replayed, or seeded.
fn r_frames(noise: Option<&[f32]>, seed: u64) -> Vec<f32> {
    let bytes = std::fs::read(case().join("model.duo")).unwrap();
    let aligned = duolando_runtime::model_file::AlignedBytes::copy_from(&bytes);
    let duo = DuoFile::parse(aligned.as_bytes()).unwrap();
    let model = Model::from_duo(&duo).unwrap();
    let motion = read_f32_2d(&case().join("in_expmap_scaled_20.npy"), None, "m")
        .unwrap()
        .data;
    let audio = read_f32_2d(&case().join("in_audio_feats_scaled_20.npy"), None, "a")
        .unwrap()
        .data;
    let inputs = [Input::Rows(&motion), Input::Rows(&audio)];
    let n = steps(&model.cfg, &inputs).unwrap();
    let mut scratch = vec![0u8; generate_scratch_bytes(&model.cfg).unwrap()];
    let mut out = vec![0f32; n * model.cfg.channels()];
    match noise {
        Some(z) => generate(
            &model,
            &inputs,
            &mut Replay { noise: z },
            &mut scratch,
            &mut out,
        )
        .unwrap(),
        None => generate(
            &model,
            &inputs,
            &mut Seeded::new(seed, &model.cfg),
            &mut scratch,
            &mut out,
        )
        .unwrap(),
    };
    out
}

/// Pushes the audio one row at a time and pulls every frame it allows.
fn run(
    s: *mut DuoSession,
    info: &DuoTransflowerInfo,
    audio: &[f32],
    noise: Option<&[f32]>,
) -> Vec<f32> {
    let (c, d, nz) = (
        info.channels as usize,
        info.audio_features as usize,
        info.noise_floats as usize,
    );
    let mut out = Vec::new();
    let mut frame = vec![0f32; c];
    // Past the replayed noise (the pull that finds no frame after the last
    // one), a row of zeros: the session reads `nz` floats whatever it does
    // next, so handing it the end of `noise` read past the buffer (a flaky
    // DUO_NON_FINITE_INPUT / out-of-range refusal in CI, 2026-12-05). An
    // extra frame would still show as a length mismatch against R.
    let past_end = vec![0f32; nz];
    for row in audio.chunks_exact(d) {
        // SAFETY: a live session and `d` readable floats.
        assert_eq!(
            unsafe { duo_session_push_music(s, row.as_ptr(), d) },
            DuoResult::Ok,
            "{}",
            last_error()
        );
        loop {
            let t = out.len() / c;
            let mut index = u64::MAX;
            // SAFETY: live session, readable noise and writable frame of the given lengths.
            let r = unsafe {
                match noise {
                    Some(z) => duo_transflower_pull_frame_with_noise(
                        s,
                        z.get(t * nz..(t + 1) * nz).unwrap_or(&past_end).as_ptr(),
                        nz,
                        frame.as_mut_ptr(),
                        c,
                        &mut index,
                    ),
                    None => duo_transflower_pull_frame(s, frame.as_mut_ptr(), c, &mut index),
                }
            };
            if r == DuoResult::NotReady {
                break;
            }
            assert_eq!(r, DuoResult::Ok, "{}", last_error());
            assert_eq!(index as usize, t);
            out.extend_from_slice(&frame);
        }
    }
    out
}

#[test]
fn exact_preset_gives_r_frames() {
    let m = open_model(&case().join("model.duo"));
    let mut mi = DuoModelInfo::default();
    let mut info = DuoTransflowerInfo::default();
    // SAFETY: live model, writable structs.
    unsafe {
        assert_eq!(duo_model_get_info(m, &mut mi), DuoResult::Ok);
        assert_eq!(duo_transflower_get_info(m, &mut info), DuoResult::Ok);
    }
    assert_eq!(
        (mi.family, mi.joints, mi.fps, mi.music_features),
        (2, 0, 20, info.audio_features)
    );
    assert_eq!(
        (info.channels, info.inputs, info.labels, info.noise_floats),
        (11, 2, 0, 11 * 3)
    );
    let motion = read_f32_2d(&case().join("in_expmap_scaled_20.npy"), None, "m")
        .unwrap()
        .data;
    let audio = read_f32_2d(&case().join("in_audio_feats_scaled_20.npy"), None, "a")
        .unwrap()
        .data;
    let seed = &motion[..(info.seed_rows * info.channels) as usize];
    let noise = npy3(&case().join("noise.npy"));
    let mut cfg = DuoTransflowerConfig::default();
    let name = CString::new("exact").unwrap();
    // SAFETY: live model, NUL-terminated name, writable config.
    assert_eq!(
        unsafe { duo_transflower_config_preset(m, name.as_ptr(), &mut cfg) },
        DuoResult::Ok
    );
    assert_eq!(cfg.refresh, 1);
    let mut s = ptr::null_mut();
    // SAFETY: live model, valid config, seed of the given length, no labels.
    assert_eq!(
        unsafe {
            duo_transflower_session_new(m, &cfg, seed.as_ptr(), seed.len(), ptr::null(), 0, &mut s)
        },
        DuoResult::Ok,
        "{}",
        last_error()
    );
    let got = run(s, &info, &audio, Some(&noise));
    let want = r_frames(Some(&noise), 0);
    assert!(
        !got.is_empty() && got == want,
        "replayed noise: {} vs {} floats, or values differ",
        got.len(),
        want.len()
    );
    // The authors' output (the golden) within its tolerance is R's test;
    // here: R itself. Seeded: reset with seed 5 = R with Seeded::new(5).
    // SAFETY: live session.
    assert_eq!(
        unsafe { duo_transflower_session_reset(s, 5) },
        DuoResult::Ok
    );
    let seeded = run(s, &info, &audio, None);
    assert!(
        seeded == r_frames(None, 5),
        "seeded session != R with Seeded::new(5)"
    );
    // In caller memory (at an odd address): the same frames, no allocation
    // of the session; a byte short is DUO_BUFFER_TOO_SMALL giving the size.
    let mut bytes = 0usize;
    // SAFETY: live model, valid config, writable size.
    assert_eq!(
        unsafe { duo_transflower_session_bytes(m, &cfg, &mut bytes) },
        DuoResult::Ok
    );
    let mut mem = vec![0u8; bytes + 1];
    let mut s2 = ptr::null_mut();
    // SAFETY: live model, valid config, seed of the given length, `bytes - 1`
    // writable bytes from offset 1.
    let short = unsafe {
        duo_transflower_session_new_in(
            m,
            &cfg,
            seed.as_ptr(),
            seed.len(),
            ptr::null(),
            0,
            mem[1..].as_mut_ptr().cast(),
            bytes - 1,
            &mut s2,
        )
    };
    assert_eq!(short, DuoResult::BufferTooSmall);
    assert!(
        last_error().contains(&bytes.to_string()),
        "{}",
        last_error()
    );
    assert!(s2.is_null());
    // SAFETY: as above with `bytes` bytes, kept until the session is freed.
    assert_eq!(
        unsafe {
            duo_transflower_session_new_in(
                m,
                &cfg,
                seed.as_ptr(),
                seed.len(),
                ptr::null(),
                0,
                mem[1..].as_mut_ptr().cast(),
                bytes,
                &mut s2,
            )
        },
        DuoResult::Ok,
        "{}",
        last_error()
    );
    let placed = run(s2, &info, &audio, Some(&noise));
    assert!(placed == want, "a session in caller memory differs from R");
    // SAFETY: handles from the library, freed once; `mem` outlives s2.
    unsafe {
        duo_session_free(s2);
        duo_session_free(s);
        duo_model_free(m);
    }
    drop(mem);
}

#[test]
fn refusals_name_the_family_and_leave_the_session_unchanged() {
    let m = open_model(&case().join("model.duo"));
    let mut info = DuoTransflowerInfo::default();
    // SAFETY: live model, writable struct.
    unsafe { duo_transflower_get_info(m, &mut info) };
    let motion = read_f32_2d(&case().join("in_expmap_scaled_20.npy"), None, "m")
        .unwrap()
        .data;
    let audio = read_f32_2d(&case().join("in_audio_feats_scaled_20.npy"), None, "a")
        .unwrap()
        .data;
    let seed = &motion[..(info.seed_rows * info.channels) as usize];
    let mut cfg = DuoTransflowerConfig::default();
    let name = CString::new("realtime").unwrap();
    let bad_name = CString::new("interactive").unwrap();
    // SAFETY: every call below passes NULL where the test checks NULL
    // handling, or live handles and buffers of the stated lengths.
    unsafe {
        assert_eq!(
            duo_transflower_config_preset(m, bad_name.as_ptr(), &mut cfg),
            DuoResult::InvalidArgument
        );
        assert!(
            last_error().contains("exact, reference, realtime"),
            "{}",
            last_error()
        );
        assert_eq!(
            duo_transflower_config_preset(m, name.as_ptr(), &mut cfg),
            DuoResult::Ok
        );
        let mut sc = DuoSessionConfig::default();
        assert_eq!(
            duo_session_config_reference(m, &mut sc),
            DuoResult::InvalidArgument
        );
        assert!(last_error().contains("Transflower"), "{}", last_error());
        let mut bytes = 0usize;
        assert_eq!(
            duo_transflower_session_bytes(m, &cfg, &mut bytes),
            DuoResult::Ok
        );
        assert!(bytes > 0);
        let mut s = ptr::null_mut();
        let bad = DuoTransflowerConfig { refresh: 0, ..cfg };
        assert_eq!(
            duo_transflower_session_new(m, &bad, seed.as_ptr(), seed.len(), ptr::null(), 0, &mut s),
            DuoResult::InvalidArgument
        );
        assert!(last_error().contains("refresh"), "{}", last_error());
        assert_eq!(
            duo_transflower_session_new(
                m,
                &cfg,
                seed.as_ptr(),
                seed.len() - 1,
                ptr::null(),
                0,
                &mut s
            ),
            DuoResult::InvalidArgument
        );
        assert_eq!(
            duo_transflower_session_new(
                m,
                &cfg,
                seed.as_ptr(),
                seed.len(),
                [1u32].as_ptr(),
                1,
                &mut s
            ),
            DuoResult::InvalidArgument
        );
        let mut nan = seed.to_vec();
        nan[2] = f32::NAN;
        assert_eq!(
            duo_transflower_session_new(m, &cfg, nan.as_ptr(), nan.len(), ptr::null(), 0, &mut s),
            DuoResult::NonFiniteInput
        );
        assert_eq!(
            duo_transflower_session_new(m, &cfg, ptr::null(), seed.len(), ptr::null(), 0, &mut s),
            DuoResult::NullParameter
        );
        assert!(s.is_null());
        assert_eq!(
            duo_transflower_session_new(m, &cfg, seed.as_ptr(), seed.len(), ptr::null(), 0, &mut s),
            DuoResult::Ok,
            "{}",
            last_error()
        );
        let c = info.channels as usize;
        let d = info.audio_features as usize;
        let mut frame = vec![0f32; c];
        // Nothing pushed: not ready.
        assert_eq!(
            duo_transflower_pull_frame(s, frame.as_mut_ptr(), c, ptr::null_mut()),
            DuoResult::NotReady
        );
        // The other families' calls.
        let lf = duolando::frames::DuoLeaderFrame::default();
        assert_eq!(duo_session_push_leader(s, &lf), DuoResult::InvalidArgument);
        assert!(last_error().contains("Transflower"), "{}", last_error());
        let mut pos = vec![0f32; 72];
        assert_eq!(
            duo_session_pull_positions(s, pos.as_mut_ptr(), 72, ptr::null_mut()),
            DuoResult::InvalidArgument
        );
        assert_eq!(duo_session_finish(s), DuoResult::InvalidArgument);
        assert_eq!(
            duo_session_reset(s, [0u32; 5].as_ptr()),
            DuoResult::InvalidArgument
        );
        assert_eq!(
            duo_session_set_music_track(s, audio.as_ptr(), d),
            DuoResult::InvalidArgument
        );
        let mut lat = 0u32;
        assert_eq!(
            duo_session_latency_frames(s, &mut lat),
            DuoResult::InvalidArgument
        );
        // Bad audio: none, ragged, NaN, the motion input; refused whole.
        assert_eq!(
            duo_session_push_music(s, std::ptr::null(), 0),
            DuoResult::InvalidArgument
        );
        assert!(last_error().contains("n_features is 0"), "{}", last_error());
        assert_eq!(
            duo_session_push_music(s, audio.as_ptr(), d + 1),
            DuoResult::InvalidArgument
        );
        let mut bad_row = audio[..d].to_vec();
        bad_row[1] = f32::INFINITY;
        assert_eq!(
            duo_session_push_music(s, bad_row.as_ptr(), d),
            DuoResult::NonFiniteInput
        );
        assert_eq!(
            duo_transflower_push_input(s, 0, audio.as_ptr(), c),
            DuoResult::InvalidArgument
        );
        assert!(last_error().contains("motion"), "{}", last_error());
        assert_eq!(
            duo_transflower_push_input(s, 9, audio.as_ptr(), d),
            DuoResult::InvalidArgument
        );
        // All the audio through push_input (the last input): frames come.
        assert_eq!(
            duo_transflower_push_input(s, 1, audio.as_ptr(), audio.len()),
            DuoResult::Ok,
            "{}",
            last_error()
        );
        assert_eq!(
            duo_transflower_pull_frame(s, frame.as_mut_ptr(), c + 1, ptr::null_mut()),
            DuoResult::InvalidArgument
        );
        let mut index = 9u64;
        assert_eq!(
            duo_transflower_pull_frame(s, frame.as_mut_ptr(), c, &mut index),
            DuoResult::Ok,
            "{}",
            last_error()
        );
        assert_eq!(index, 0);
        assert!(frame.iter().all(|v| v.is_finite()));
        let z = vec![f32::NAN; info.noise_floats as usize];
        assert_eq!(
            duo_transflower_pull_frame_with_noise(
                s,
                z.as_ptr(),
                z.len(),
                frame.as_mut_ptr(),
                c,
                &mut index
            ),
            DuoResult::NonFiniteInput
        );
        assert_eq!(
            duo_transflower_pull_frame_with_noise(
                s,
                z.as_ptr(),
                3,
                frame.as_mut_ptr(),
                c,
                &mut index
            ),
            DuoResult::InvalidArgument
        );
        assert!(
            last_error().contains("noise") && !last_error().contains("encoder"),
            "{}",
            last_error()
        );
        assert_eq!(
            duo_transflower_pull_frame(s, frame.as_mut_ptr(), c, &mut index),
            DuoResult::Ok
        );
        assert_eq!(index, 1);
        // Audio past the feed's room: DUO_BACKLOG in the model's words.
        let mut pushed = 0;
        while pushed < 100_000 && duo_session_push_music(s, audio.as_ptr(), d) == DuoResult::Ok {
            pushed += 1;
        }
        assert!(pushed < 100_000, "no backlog");
        assert_eq!(
            duo_session_push_music(s, audio.as_ptr(), d),
            DuoResult::Backlog
        );
        let msg = last_error();
        assert!(
            msg.contains("input_buffer_rows")
                && !msg.contains("follower")
                && !msg.contains("leader"),
            "{msg}"
        );
        // A Duolando model: the Transflower calls refuse it.
        let duo = open_model(&case().join("../tiny/model.duo"));
        assert_eq!(
            duo_transflower_get_info(duo, &mut info),
            DuoResult::InvalidArgument
        );
        assert!(last_error().contains("Duolando"), "{}", last_error());
        duo_session_free(s);
        duo_model_free(duo);
        duo_model_free(m);
    }
}

/// The header's buffer rule on every Transflower buffer: NULL with count
/// 0 is answered as a non-NULL pointer with count 0; NULL with a count is
/// DUO_NULL_PARAMETER (the list: session_golden.rs
/// `every_buffer_follows_the_null_rule`).
#[test]
fn buffers_follow_the_null_rule() {
    let m = open_model(&case().join("model.duo"));
    let mut info = DuoTransflowerInfo::default();
    let mut cfg = DuoTransflowerConfig::default();
    let name = CString::new("exact").unwrap();
    let motion = read_f32_2d(&case().join("in_expmap_scaled_20.npy"), None, "m")
        .unwrap()
        .data;
    let audio = read_f32_2d(&case().join("in_audio_feats_scaled_20.npy"), None, "a")
        .unwrap()
        .data;
    let one = [0f32; 1];
    let label = [0u32; 1];
    // SAFETY: every call passes NULL where the rule is checked, or live
    // handles and buffers of at least the stated lengths.
    unsafe {
        duo_transflower_get_info(m, &mut info);
        duo_transflower_config_preset(m, name.as_ptr(), &mut cfg);
        let seed = &motion[..(info.seed_rows * info.channels) as usize];
        let c = info.channels as usize;
        let same = |a: DuoResult, b: DuoResult, what: &str| {
            let ma = last_error();
            assert_eq!(
                a, b,
                "{what}: NULL with 0 answered otherwise than a pointer with 0"
            );
            ma
        };
        let mut s = ptr::null_mut();
        // seed_motion
        let a = duo_transflower_session_new(m, &cfg, ptr::null(), 0, ptr::null(), 0, &mut s);
        let ma = last_error();
        let b = duo_transflower_session_new(m, &cfg, one.as_ptr(), 0, ptr::null(), 0, &mut s);
        assert_eq!((a, ma), (b, last_error()), "seed_motion");
        assert_eq!(a, DuoResult::InvalidArgument);
        assert_eq!(
            duo_transflower_session_new(m, &cfg, ptr::null(), seed.len(), ptr::null(), 0, &mut s),
            DuoResult::NullParameter
        );
        // labels (this model takes none: 0 is right, NULL or not)
        assert_eq!(
            duo_transflower_session_new(
                m,
                &cfg,
                seed.as_ptr(),
                seed.len(),
                label.as_ptr(),
                0,
                &mut s
            ),
            DuoResult::Ok
        );
        duo_session_free(s);
        assert_eq!(
            duo_transflower_session_new(m, &cfg, seed.as_ptr(), seed.len(), ptr::null(), 1, &mut s),
            DuoResult::NullParameter
        );
        assert_eq!(
            duo_transflower_session_new(m, &cfg, seed.as_ptr(), seed.len(), ptr::null(), 0, &mut s),
            DuoResult::Ok
        );
        // memory (new_in): NULL with 0 = a pointer with 0 (too small).
        let mut mem = vec![0u8; 64];
        let mut s2 = ptr::null_mut();
        let a = duo_transflower_session_new_in(
            m,
            &cfg,
            seed.as_ptr(),
            seed.len(),
            ptr::null(),
            0,
            ptr::null_mut(),
            0,
            &mut s2,
        );
        let ma = last_error();
        let b = duo_transflower_session_new_in(
            m,
            &cfg,
            seed.as_ptr(),
            seed.len(),
            ptr::null(),
            0,
            mem.as_mut_ptr().cast(),
            0,
            &mut s2,
        );
        assert_eq!((a, ma), (b, last_error()), "memory");
        assert_eq!(a, DuoResult::BufferTooSmall);
        assert_eq!(
            duo_transflower_session_new_in(
                m,
                &cfg,
                seed.as_ptr(),
                seed.len(),
                ptr::null(),
                0,
                ptr::null_mut(),
                64,
                &mut s2,
            ),
            DuoResult::NullParameter
        );
        // seed_motion and labels through new_in: as through new.
        let a = duo_transflower_session_new_in(
            m,
            &cfg,
            ptr::null(),
            0,
            ptr::null(),
            0,
            mem.as_mut_ptr().cast(),
            64,
            &mut s2,
        );
        let ma = last_error();
        let b = duo_transflower_session_new_in(
            m,
            &cfg,
            one.as_ptr(),
            0,
            ptr::null(),
            0,
            mem.as_mut_ptr().cast(),
            64,
            &mut s2,
        );
        assert_eq!((a, ma), (b, last_error()), "seed_motion (new_in)");
        assert_eq!(
            duo_transflower_session_new_in(
                m,
                &cfg,
                seed.as_ptr(),
                seed.len(),
                ptr::null(),
                1,
                mem.as_mut_ptr().cast(),
                64,
                &mut s2,
            ),
            DuoResult::NullParameter
        );
        assert!(s2.is_null(), "no session made");
        // rows
        let a = duo_transflower_push_input(s, 1, ptr::null(), 0);
        let ma = last_error();
        let b = duo_transflower_push_input(s, 1, one.as_ptr(), 0);
        assert_eq!((a, ma), (b, last_error()), "rows");
        assert_eq!(a, DuoResult::InvalidArgument);
        assert_eq!(
            duo_transflower_push_input(s, 1, ptr::null(), 5),
            DuoResult::NullParameter
        );
        assert_eq!(
            duo_session_push_music(s, audio.as_ptr(), audio.len()),
            DuoResult::Ok
        );
        // out (pull_frame and with_noise); noise
        let mut frame = vec![0f32; c];
        let z = vec![0.1f32; info.noise_floats as usize];
        let ma = same(
            duo_transflower_pull_frame(s, ptr::null_mut(), 0, ptr::null_mut()),
            DuoResult::InvalidArgument,
            "out",
        );
        assert_eq!(
            duo_transflower_pull_frame(s, frame.as_mut_ptr(), 0, ptr::null_mut()),
            DuoResult::InvalidArgument
        );
        assert_eq!(last_error(), ma);
        assert_eq!(
            duo_transflower_pull_frame(s, ptr::null_mut(), c, ptr::null_mut()),
            DuoResult::NullParameter
        );
        let a = duo_transflower_pull_frame_with_noise(
            s,
            z.as_ptr(),
            z.len(),
            ptr::null_mut(),
            0,
            ptr::null_mut(),
        );
        let ma = last_error();
        let b = duo_transflower_pull_frame_with_noise(
            s,
            z.as_ptr(),
            z.len(),
            frame.as_mut_ptr(),
            0,
            ptr::null_mut(),
        );
        assert_eq!((a, ma), (b, last_error()), "out (with noise)");
        assert_eq!(
            duo_transflower_pull_frame_with_noise(
                s,
                z.as_ptr(),
                z.len(),
                ptr::null_mut(),
                c,
                ptr::null_mut()
            ),
            DuoResult::NullParameter
        );
        let a = duo_transflower_pull_frame_with_noise(
            s,
            ptr::null(),
            0,
            frame.as_mut_ptr(),
            c,
            ptr::null_mut(),
        );
        let ma = last_error();
        let b = duo_transflower_pull_frame_with_noise(
            s,
            one.as_ptr(),
            0,
            frame.as_mut_ptr(),
            c,
            ptr::null_mut(),
        );
        assert_eq!((a, ma), (b, last_error()), "noise");
        assert_eq!(a, DuoResult::InvalidArgument);
        assert_eq!(
            duo_transflower_pull_frame_with_noise(
                s,
                ptr::null(),
                z.len(),
                frame.as_mut_ptr(),
                c,
                ptr::null_mut()
            ),
            DuoResult::NullParameter
        );
        // Nothing was made by the refused calls: the first frame is index 0.
        let mut index = 7u64;
        assert_eq!(
            duo_transflower_pull_frame_with_noise(
                s,
                z.as_ptr(),
                z.len(),
                frame.as_mut_ptr(),
                c,
                &mut index
            ),
            DuoResult::Ok
        );
        assert_eq!(index, 0);
        duo_session_free(s);
        duo_model_free(m);
    }
}
