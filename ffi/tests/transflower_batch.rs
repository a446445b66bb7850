//! Transflower sessions stepped through a `duo_step_batch`
//! (`duo_transflower_step_batch_*`, `duo_step_batch_step`): on the paper
//! fixture (the committed model.duo) and the slide fixture (published
//! windows, 125 frames; converted in memory), presets "exact" and
//! "realtime", three sessions of different seeds (one for batches only
//! in caller memory, one for batches only in library memory, one with its
//! own step memory), their audio pushed in different chunks, give the
//! frames each gives stepped alone, bit for bit, from a batch in library
//! or in caller memory; the sizes (a batched session holds less; a byte
//! short is refused); every refusal of the header's order, by index, the
//! sessions unchanged; the buffer rule.

mod common;
use common::*;
use std::ffi::CString;
use std::path::Path;
use std::ptr;

use duolando::batch::*;
use duolando::model::*;
use duolando::result::DuoResult;
use duolando::session::*;
use duolando::transflower::*;
use duolando::transflower_batch::*;
use duolando_std::npy::read_f32_2d;



/// A Transflower model with its seed motion and audio rows.
struct Case {
    m: *mut DuoModel,
    info: DuoTransflowerInfo,
    seed: Vec<f32>,
    audio: Vec<f32>,
}

impl Case {
    /// `transflower_<name>`: its model.duo, or (None there) its weights
    /// converted in memory and opened by copy.
    fn load(name: &str) -> Case {
        let dir = fixture(&format!("transflower_{name}"));
        let mut m = ptr::null_mut();
        let duo = dir.join("model.duo");
        if duo.exists() {
            let p = CString::new(duo.to_str().unwrap()).unwrap();
            // SAFETY: a NUL-terminated path and a live out-pointer.
            assert_eq!(
                unsafe { duo_model_open_file(p.as_ptr(), &mut m) },
                DuoResult::Ok
            );
        } else {
            use duolando_std::convert::transflower::*;
            let h = dir.join("hparams.yaml");
            let cfg = parse_transflower_config(&h, &std::fs::read_to_string(&h).unwrap()).unwrap();
            let w = dir.join("model.safetensors");
            let (bytes, _) = convert_transflower(
                &cfg,
                (&w, &std::fs::read(&w).unwrap()),
                duolando_std::duo_writer::StoreAs::F32,
                Path::new("<memory>"),
            )
            .unwrap();
            // SAFETY: `bytes.len()` readable bytes (copied) and a live out-pointer.
            assert_eq!(
                unsafe { duo_model_open_copy(bytes.as_ptr(), bytes.len(), &mut m) },
                DuoResult::Ok,
                "{}",
                last_error()
            );
        }
        let mut info = DuoTransflowerInfo::default();
        // SAFETY: live model, writable struct.
        assert_eq!(
            unsafe { duo_transflower_get_info(m, &mut info) },
            DuoResult::Ok
        );
        let motion = read_f32_2d(&dir.join("in_expmap_scaled_20.npy"), None, "m")
            .unwrap()
            .data;
        let audio = read_f32_2d(&dir.join("in_audio_feats_scaled_20.npy"), None, "a")
            .unwrap()
            .data;
        Case {
            m,
            seed: motion[..(info.seed_rows * info.channels) as usize].to_vec(),
            audio,
            info,
        }
    }

    fn preset(&self, name: &str) -> DuoTransflowerConfig {
        let mut c = DuoTransflowerConfig::default();
        let n = CString::new(name).unwrap();
        // SAFETY: live model, NUL-terminated name, writable config.
        assert_eq!(
            unsafe { duo_transflower_config_preset(self.m, n.as_ptr(), &mut c) },
            DuoResult::Ok
        );
        c
    }

    fn bytes(&self, c: &DuoTransflowerConfig) -> usize {
        let mut n = 0;
        // SAFETY: live model, valid config, writable size.
        assert_eq!(
            unsafe { duo_transflower_session_bytes(self.m, c, &mut n) },
            DuoResult::Ok,
            "{}",
            last_error()
        );
        n
    }

    /// A session of `c`, in library memory or in `memory` (kept by the caller).
    fn session(&self, c: &DuoTransflowerConfig, memory: Option<&mut [u8]>) -> *mut DuoSession {
        let mut s = ptr::null_mut();
        // SAFETY: live model, valid config, seed of the given length, no
        // labels; `memory` (if any) outlives the session (the caller's).
        let r = unsafe {
            match memory {
                None => duo_transflower_session_new(
                    self.m,
                    c,
                    self.seed.as_ptr(),
                    self.seed.len(),
                    ptr::null(),
                    0,
                    &mut s,
                ),
                Some(mem) => duo_transflower_session_new_in(
                    self.m,
                    c,
                    self.seed.as_ptr(),
                    self.seed.len(),
                    ptr::null(),
                    0,
                    mem.as_mut_ptr().cast(),
                    mem.len(),
                    &mut s,
                ),
            }
        };
        assert_eq!(r, DuoResult::Ok, "{}", last_error());
        s
    }

    fn push(&self, s: *mut DuoSession, rows: &[f32]) {
        // SAFETY: a live session and `rows.len()` readable floats.
        assert_eq!(
            unsafe { duo_session_push_music(s, rows.as_ptr(), rows.len()) },
            DuoResult::Ok,
            "{}",
            last_error()
        );
    }

    /// Pulls every frame made or makeable into `out` (frame indices checked).
    fn pull_all(&self, s: *mut DuoSession, out: &mut Vec<f32>) {
        let c = self.info.channels as usize;
        let mut frame = vec![0f32; c];
        loop {
            let mut index = u64::MAX;
            // SAFETY: a live session and a writable frame of `c` floats.
            let r = unsafe { duo_transflower_pull_frame(s, frame.as_mut_ptr(), c, &mut index) };
            if r == DuoResult::NotReady {
                return;
            }
            assert_eq!(r, DuoResult::Ok, "{}", last_error());
            assert_eq!(index as usize, out.len() / c);
            out.extend_from_slice(&frame);
        }
    }

    /// The session of `c` alone: audio row by row, every frame pulled.
    fn alone(&self, c: &DuoTransflowerConfig) -> Vec<f32> {
        let s = self.session(&DuoTransflowerConfig { batched: 0, ..*c }, None);
        let mut out = Vec::new();
        for row in self.audio.chunks_exact(self.info.audio_features as usize) {
            self.push(s, row);
            self.pull_all(s, &mut out);
        }
        // SAFETY: a session of the library, freed once.
        unsafe { duo_session_free(s) };
        out
    }

    /// `sessions` stepped through `batch`, session k's audio pushed
    /// `chunks[k]` rows at a time; returns each one's frames and whether a
    /// call stepped some sessions and skipped others.
    fn batched(
        &self,
        batch: *mut DuoStepBatch,
        sessions: &[*mut DuoSession],
        chunks: &[usize],
    ) -> (Vec<Vec<f32>>, bool) {
        let d = self.info.audio_features as usize;
        let rows = self.audio.len() / d;
        let mut out = vec![Vec::new(); sessions.len()];
        let mut fed = vec![0usize; sessions.len()];
        let mut partial = false;
        while fed.iter().any(|&f| f < rows) {
            for (k, &s) in sessions.iter().enumerate() {
                let to = (fed[k] + chunks[k]).min(rows);
                if to > fed[k] {
                    self.push(s, &self.audio[fed[k] * d..to * d]);
                    fed[k] = to;
                }
            }
            loop {
                let (mut stepped, mut failed) = (usize::MAX, 0usize);
                // SAFETY: a live batch and `sessions.len()` live, distinct sessions.
                let r = unsafe {
                    duo_step_batch_step(
                        batch,
                        sessions.as_ptr(),
                        sessions.len(),
                        &mut stepped,
                        &mut failed,
                    )
                };
                assert_eq!((r, failed), (DuoResult::Ok, NO_SESSION), "{}", last_error());
                partial |= stepped > 0 && stepped < sessions.len();
                for (k, &s) in sessions.iter().enumerate() {
                    self.pull_all(s, &mut out[k]);
                }
                if stepped == 0 {
                    break;
                }
            }
        }
        (out, partial)
    }

    fn batch(&self, memory: Option<&mut [u8]>) -> *mut DuoStepBatch {
        let mut b = ptr::null_mut();
        // SAFETY: live model, writable out; `memory` outlives the batch (the caller's).
        let r = unsafe {
            match memory {
                None => duo_transflower_step_batch_new(self.m, &mut b),
                Some(mem) => {
                    duo_transflower_step_batch_new_in(self.m, mem.as_mut_ptr(), mem.len(), &mut b)
                }
            }
        };
        assert_eq!(r, DuoResult::Ok, "{}", last_error());
        b
    }
}

impl Drop for Case {
    fn drop(&mut self) {
        // SAFETY: the model handle of this case (NULL once freed: ignored), freed once.
        unsafe { duo_model_free(self.m) };
    }
}

#[test]
fn sessions_stepped_in_a_batch_equal_sessions_alone() {
    let seeds = [3u64, 17, 42];
    for name in ["paper", "slide"] {
        let case = Case::load(name);
        for preset in ["exact", "realtime"] {
            let base = case.preset(preset);
            let cfgs: Vec<DuoTransflowerConfig> = seeds
                .iter()
                .map(|&rng_seed| DuoTransflowerConfig { rng_seed, ..base })
                .collect();
            let alone: Vec<Vec<f32>> = cfgs.iter().map(|c| case.alone(c)).collect();
            assert!(
                alone[0] != alone[1] && alone[1] != alone[2],
                "{name} {preset}: seeds"
            );
            for in_caller in [false, true] {
                // Session 0: batched, caller memory at an odd address;
                // 1: batched, library memory; 2: its own step memory.
                let batched = |c: &DuoTransflowerConfig| DuoTransflowerConfig { batched: 1, ..*c };
                let mut mem0 = vec![0u8; case.bytes(&batched(&cfgs[0])) + 1];
                let s = [
                    case.session(&batched(&cfgs[0]), Some(&mut mem0[1..])),
                    case.session(&batched(&cfgs[1]), None),
                    case.session(&cfgs[2], None),
                ];
                let mut bytes = 0;
                // SAFETY: live model, writable size.
                assert_eq!(
                    unsafe { duo_transflower_step_batch_bytes(case.m, &mut bytes) },
                    DuoResult::Ok
                );
                let mut bmem = vec![0u8; bytes + 3];
                let b = case.batch(in_caller.then_some(&mut bmem[3..]));
                let (got, partial) = case.batched(b, &s, &[1, 3, 7]);
                assert!(partial, "{name} {preset}: no call skipped a session");
                for k in 0..3 {
                    assert!(
                        !got[k].is_empty() && got[k] == alone[k],
                        "{name} {preset} (batch in caller memory: {in_caller}): session {k} ({} vs {} floats) differs from itself alone",
                        got[k].len(),
                        alone[k].len()
                    );
                }
                // SAFETY: handles of the library, freed once; the memory outlives them.
                unsafe {
                    duo_step_batch_free(b);
                    for k in s {
                        duo_session_free(k);
                    }
                }
                drop((mem0, bmem));
            }
        }
    }
}

#[test]
fn sizes_memory_and_batched_sessions() {
    let mut case = Case::load("paper");
    let c = case.preset("realtime");
    let (full, state) = (
        case.bytes(&c),
        case.bytes(&DuoTransflowerConfig { batched: 1, ..c }),
    );
    assert!(state < full, "{state} >= {full}");
    let mut bytes = 0usize;
    let mut b = ptr::null_mut();
    // SAFETY: every call passes NULL where the test checks NULL handling,
    // or live handles and buffers of at least the stated lengths.
    unsafe {
        assert_eq!(
            duo_transflower_step_batch_bytes(case.m, &mut bytes),
            DuoResult::Ok
        );
        assert!(bytes > 0);
        eprintln!("paper fixture: session {full} B, batched session {state} B, batch {bytes} B");
        // Not a setting: batched 2.
        let mut n = 0;
        assert_eq!(
            duo_transflower_session_bytes(
                case.m,
                &DuoTransflowerConfig { batched: 2, ..c },
                &mut n
            ),
            DuoResult::InvalidArgument
        );
        assert!(last_error().contains("batched is 2"), "{}", last_error());
        // NULLs.
        assert_eq!(
            duo_transflower_step_batch_bytes(ptr::null(), &mut bytes),
            DuoResult::NullParameter
        );
        assert_eq!(
            duo_transflower_step_batch_bytes(case.m, ptr::null_mut()),
            DuoResult::NullParameter
        );
        assert_eq!(
            duo_transflower_step_batch_new(ptr::null(), &mut b),
            DuoResult::NullParameter
        );
        assert_eq!(
            duo_transflower_step_batch_new(case.m, ptr::null_mut()),
            DuoResult::NullParameter
        );
        // Caller memory: a byte short names the size; the buffer rule.
        let mut mem = vec![0u8; bytes + 1];
        assert_eq!(
            duo_transflower_step_batch_new_in(case.m, mem[1..].as_mut_ptr(), bytes - 1, &mut b),
            DuoResult::BufferTooSmall
        );
        assert!(
            last_error().contains(&bytes.to_string()),
            "{}",
            last_error()
        );
        let a = duo_transflower_step_batch_new_in(case.m, ptr::null_mut(), 0, &mut b);
        let ma = last_error();
        let z = duo_transflower_step_batch_new_in(case.m, mem.as_mut_ptr(), 0, &mut b);
        assert_eq!(
            (a, ma),
            (z, last_error()),
            "memory: NULL/0 as a pointer with 0"
        );
        assert_eq!(a, DuoResult::BufferTooSmall);
        assert_eq!(
            duo_transflower_step_batch_new_in(case.m, ptr::null_mut(), bytes, &mut b),
            DuoResult::NullParameter
        );
        assert!(b.is_null(), "nothing made");
        // Another family's model, each way.
        let duo = CString::new(fixture("tiny/model.duo").to_str().unwrap()).unwrap();
        let mut dm = ptr::null_mut();
        assert_eq!(duo_model_open_file(duo.as_ptr(), &mut dm), DuoResult::Ok);
        assert_eq!(
            duo_transflower_step_batch_new(dm, &mut b),
            DuoResult::InvalidArgument
        );
        assert!(last_error().contains("Duolando"), "{}", last_error());
        assert_eq!(
            duo_transflower_step_batch_bytes(dm, &mut bytes),
            DuoResult::InvalidArgument
        );
        let mut sc = DuoSessionConfig::default();
        assert_eq!(duo_session_config_minimum(dm, &mut sc), DuoResult::Ok);
        assert_eq!(
            duo_step_batch_new(case.m, &sc, 2, &mut b),
            DuoResult::InvalidArgument
        );
        assert!(last_error().contains("Transflower"), "{}", last_error());
        assert!(b.is_null());
        duo_model_free(dm);

        // A batched session in caller memory of exactly its size: its
        // pulls never step (DUO_NOT_READY with its audio in, with or
        // without noise); its batch makes the frames.
        let bc = DuoTransflowerConfig { batched: 1, ..c };
        let mut smem = vec![0u8; state];
        let s = case.session(&bc, Some(&mut smem));
        case.push(s, &case.audio);
        let ch = case.info.channels as usize;
        let mut f = vec![0f32; ch];
        let z = vec![0.5f32; case.info.noise_floats as usize];
        assert_eq!(
            duo_transflower_pull_frame(s, f.as_mut_ptr(), ch, ptr::null_mut()),
            DuoResult::NotReady
        );
        assert_eq!(
            duo_transflower_pull_frame_with_noise(
                s,
                z.as_ptr(),
                z.len(),
                f.as_mut_ptr(),
                ch,
                ptr::null_mut()
            ),
            DuoResult::NotReady
        );
        // The batch in caller memory of exactly its size at an odd address;
        // the model freed before the batch and the session (they hold it).
        let b = case.batch(Some(&mut mem[1..]));
        let alone = case.alone(&c);
        duo_model_free(case.m);
        case.m = ptr::null_mut();
        let mut got = Vec::new();
        let mut stepped = 0;
        while duo_step_batch_step(b, [s].as_ptr(), 1, &mut stepped, ptr::null_mut())
            == DuoResult::Ok
            && stepped == 1
        {
            case.pull_all(s, &mut got);
        }
        assert!(!got.is_empty() && got == alone);
        duo_step_batch_free(b);
        duo_session_free(s);
        drop((smem, mem));
    }
}

/// The header's order, by index: 1. the call (batch NULL or of the
/// other family, n 0, n above DUO_MAX_BATCH, sessions NULL) with
/// DUO_NO_SESSION; 2. the sessions (NULL, twice, another family, another
/// model); 4. backlog; nothing changes on a refusal.
#[test]
fn step_refusals_come_in_the_stated_order() {
    let case = Case::load("paper");
    let other = Case::load("paper");
    let c = DuoTransflowerConfig {
        pending_frames: 2,
        ..case.preset("exact")
    };
    let b = case.batch(None);
    let mk = |k: &Case| k.session(&DuoTransflowerConfig { batched: 1, ..c }, None);
    let s: Vec<*mut DuoSession> = (0..4).map(|_| mk(&case)).collect();
    let stranger = mk(&other);
    // Sessions 1 and 3 backlogged: two frames made, none pulled.
    let d = case.info.audio_features as usize;
    let window = case.info.audio_window as usize;
    for &k in &s {
        case.push(k, &case.audio[..(window + 2) * d]);
    }
    let step = |ss: &[*mut DuoSession], n: usize| {
        let (mut stepped, mut failed) = (777usize, 12345usize);
        // SAFETY: a live batch; `ss` holds at least `n` pointers (NULL or live).
        let r = unsafe { duo_step_batch_step(b, ss.as_ptr(), n, &mut stepped, &mut failed) };
        (r, failed, stepped, last_error())
    };
    for _ in 0..2 {
        assert_eq!(step(&[s[1], s[3]], 2).0, DuoResult::Ok);
    }
    let none = NO_SESSION;
    // 1. The call.
    let mut failed = 5usize;
    // SAFETY: NULL batch with live sessions: refused before they are read.
    let r = unsafe {
        duo_step_batch_step(ptr::null_mut(), s.as_ptr(), 2, ptr::null_mut(), &mut failed)
    };
    assert_eq!((r, failed), (DuoResult::NullParameter, none));
    let (r, f, stepped, _) = step(&[], 0);
    assert_eq!(
        (r, f, stepped),
        (DuoResult::Ok, none, 0),
        "n == 0 does nothing"
    );
    // SAFETY: n == 0 with NULL sessions: nothing read.
    let r = unsafe { duo_step_batch_step(b, ptr::null(), 0, ptr::null_mut(), ptr::null_mut()) };
    assert_eq!(r, DuoResult::Ok);
    let many = vec![s[0]; DUO_MAX + 1];
    let (r, f, stepped, msg) = step(&many, many.len());
    assert_eq!(
        (r, f, stepped),
        (DuoResult::InvalidArgument, none, 777),
        "{msg}"
    );
    let (mut st, mut fl) = (0usize, 0usize);
    // SAFETY: NULL sessions with n > 0.
    let r = unsafe { duo_step_batch_step(b, ptr::null(), 2, &mut st, &mut fl) };
    assert_eq!((r, fl), (DuoResult::NullParameter, none));
    assert!(
        last_error().contains("sessions is NULL"),
        "{}",
        last_error()
    );
    // The other family's call and batch, even with n == 0.
    let lf = duolando::frames::DuoLeaderFrame::default();
    // SAFETY: a live batch, n == 0.
    let r = unsafe { duo_step_batch_push_leader(b, ptr::null(), &lf, 0, &mut fl) };
    assert_eq!((r, fl), (DuoResult::InvalidArgument, none));
    assert!(
        last_error().contains("duo_step_batch_step") && last_error().contains("Transflower"),
        "{}",
        last_error()
    );
    let duo = CString::new(fixture("tiny/model.duo").to_str().unwrap()).unwrap();
    let (mut dm, mut db, mut ds) = (ptr::null_mut(), ptr::null_mut(), ptr::null_mut());
    let mut sc = DuoSessionConfig::default();
    // SAFETY: live out-pointers; a NUL-terminated path; 5 seed tokens.
    unsafe {
        assert_eq!(duo_model_open_file(duo.as_ptr(), &mut dm), DuoResult::Ok);
        assert_eq!(duo_session_config_minimum(dm, &mut sc), DuoResult::Ok);
        assert_eq!(duo_step_batch_new(dm, &sc, 2, &mut db), DuoResult::Ok);
        assert_eq!(
            duo_session_new(dm, &sc, [1u32, 2, 3, 4, 5].as_ptr(), &mut ds),
            DuoResult::Ok
        );
        let r = duo_step_batch_step(db, [ds].as_ptr(), 1, &mut st, &mut fl);
        assert_eq!((r, fl), (DuoResult::InvalidArgument, none));
        assert!(
            last_error().contains("duo_step_batch_push_leader"),
            "{}",
            last_error()
        );
        // A Transflower session handed to a Duolando batch.
        let r = duo_step_batch_push_leader(db, [ds, s[0]].as_ptr(), [lf, lf].as_ptr(), 2, &mut fl);
        assert_eq!((r, fl), (DuoResult::InvalidArgument, 1));
        assert!(
            last_error().contains("sessions[1] is a session of a Transflower model"),
            "{}",
            last_error()
        );
    }
    // 2. The sessions: a Duolando session handed to this batch.
    let (r, f, _, msg) = step(&[s[0], ds], 2);
    assert_eq!((r, f), (DuoResult::InvalidArgument, 1), "{msg}");
    assert!(
        msg.contains("sessions[1] is a session of a Duolando model"),
        "{msg}"
    );
    // Another model at 4 before the backlogged session 1.
    let five = [s[0], s[1], s[2], s[3], stranger];
    let (r, f, _, msg) = step(&five, 5);
    assert_eq!((r, f), (DuoResult::InvalidArgument, 4), "{msg}");
    assert!(
        msg.contains("sessions[4] is a session of another model"),
        "{msg}"
    );
    // A repeated session at 3 before another model at 4.
    let (r, f, _, msg) = step(&[s[0], s[1], s[2], s[0], stranger], 5);
    assert_eq!((r, f), (DuoResult::InvalidArgument, 3), "{msg}");
    assert!(msg.contains("sessions[3] is sessions[0] again"), "{msg}");
    // A NULL session at 2 before a repeat at 3 and another model at 4.
    let (r, f, _, _) = step(&[s[0], s[1], ptr::null_mut(), s[0], stranger], 5);
    assert_eq!((r, f), (DuoResult::NullParameter, 2));
    assert!(
        last_error().contains("sessions[2] is NULL"),
        "{}",
        last_error()
    );
    // 4. Backlog: the first backlogged session, 1 (not 3).
    let (r, f, stepped, msg) = step(&s, 4);
    assert_eq!((r, f, stepped), (DuoResult::Backlog, 1, 777), "{msg}");
    assert!(
        msg.contains("sessions[1]: the session is full (2 of 2 frames made and not pulled)"),
        "{msg}"
    );
    // Nobody changed: 0 and 2 (and the stranger) make no frame before a
    // good call, then the frames of a fresh session alone.
    let mut fresh = Vec::new();
    let alone = case.alone(&c);
    for &k in &[s[0], s[2]] {
        let mut f0 = Vec::new();
        case.pull_all(k, &mut f0);
        assert!(f0.is_empty());
    }
    case.push(s[0], &case.audio[(window + 2) * d..]);
    let mut two = Vec::new();
    loop {
        let (r, _, stepped, msg) = step(&[s[0], s[2]], 2);
        assert_eq!(r, DuoResult::Ok, "{msg}");
        case.pull_all(s[0], &mut fresh);
        case.pull_all(s[2], &mut two);
        if stepped == 0 {
            break;
        }
    }
    assert!(!fresh.is_empty() && fresh == alone);
    assert!(two.len() == 3 * case.info.channels as usize && alone.starts_with(&two));
    // SAFETY: handles of the library, freed once.
    unsafe {
        duo_step_batch_free(b);
        duo_step_batch_free(db);
        duo_step_batch_free(ptr::null_mut());
        for k in s.into_iter().chain([stranger, ds]) {
            duo_session_free(k);
        }
        duo_model_free(dm);
    }
}

/// DUO_MAX_BATCH as the header states it.
const DUO_MAX: usize = 64;

/// The buffer rule on the batch's buffers (session_golden.rs
/// `every_buffer_follows_the_null_rule` lists them): `sessions` NULL
/// with n 0 = a pointer with 0 (both do nothing), NULL with n > 0 is
/// DUO_NULL_PARAMETER (checked above); `memory`: in
/// `sizes_memory_and_batched_sessions`.
#[test]
fn sessions_follow_the_null_rule() {
    let case = Case::load("paper");
    let b = case.batch(None);
    let s = case.session(&case.preset("exact"), None);
    let header = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../include/duolando.h"),
    )
    .unwrap();
    assert!(header.contains(&format!("#define DUO_MAX_BATCH {DUO_MAX}\n")));
    let (mut s1, mut f1, mut s2, mut f2) = (9usize, 9usize, 9usize, 9usize);
    // SAFETY: a live batch, n == 0 (the pointers are not read).
    let (a, z) = unsafe {
        (
            duo_step_batch_step(b, ptr::null(), 0, &mut s1, &mut f1),
            duo_step_batch_step(b, [s].as_ptr(), 0, &mut s2, &mut f2),
        )
    };
    assert_eq!((a, s1, f1), (z, s2, f2));
    assert_eq!((a, s1, f1), (DuoResult::Ok, 0, NO_SESSION));
    // SAFETY: handles of the library, freed once.
    unsafe {
        duo_session_free(s);
        duo_step_batch_free(b);
    }
}
