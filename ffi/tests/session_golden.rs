//! The C API against the S golden `streaming_tiny_minimum`
//! (tests/fixtures/README.md "S goldens"): a session driven only through
//! the `duo_*` functions (rlib) reproduces the golden follower positions
//! within 1e-4 m, its quaternions are the nearest rotations of the golden
//! raw rotation matrices, and the input policy holds: rejected NaN / Inf /
//! out-of-range frames leave the session unchanged (same output as a clean
//! run), caller-memory sessions and sessions on other threads agree.

use std::ffi::{c_char, CStr, CString};
use std::path::{Path, PathBuf};
use std::ptr;

use duolando::frames::{DuoFollowerFrame, DuoLeaderFrame, DuoVec3};
use duolando::model::*;
use duolando::result::{duo_last_error_message, DuoResult};
use duolando::session::*;
use duolando_std::npy::{read_f32_2d, read_i64_2d};
use duolando_std::skeleton::rotation::{mat_from_quat, nearest_rotation};

/// Tolerance of the S goldens on positions and rotations (metres / matrix entries).
const MOTION_ABS: f32 = 1e-4;

fn fixtures() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/fixtures")
}

fn last_error() -> String {
    // SAFETY: every C entry point below is called with NULL (where the test checks NULL handling) or with pointers to live locals of the documented sizes; handles come from the library and are freed once.
    let mut buf = vec![0 as c_char; 512];
    unsafe { duo_last_error_message(buf.as_mut_ptr(), buf.len()) };
    unsafe { CStr::from_ptr(buf.as_ptr()) }.to_string_lossy().into_owned()
}

struct Golden {
    leader: Vec<DuoLeaderFrame>,
    music: Vec<f32>,
    seed: [u32; 5],
    pos: Vec<f32>,
    rot: Vec<f32>,
    frames: usize,
    config: serde_json::Value,
}

fn golden() -> Golden {
    // SAFETY: every C entry point below is called with NULL (where the test checks NULL handling) or with pointers to live locals of the documented sizes; handles come from the library and are freed once.
    let dir = fixtures().join("streaming_tiny_minimum");
    // The goldens' meta.json may hold Python's bare `Infinity` (not JSON).
    let text = std::fs::read_to_string(dir.join("meta.json")).unwrap().replace("Infinity", "null");
    let meta: serde_json::Value = serde_json::from_str(&text).unwrap();
    let inputs = dir.join(meta["inputs"].as_str().unwrap());
    let t4 = meta["T4"].as_u64().unwrap() as usize;
    let l = read_f32_2d(&inputs.join("leader_pos3d.npy"), Some(165), "leader").unwrap();
    let leader = (0..t4)
        .map(|f| {
            let mut fr = DuoLeaderFrame::default();
            for j in 0..55 {
                let p = &l.data[f * 165 + 3 * j..f * 165 + 3 * j + 3];
                fr.joints[j] = DuoVec3 { x: p[0], y: p[1], z: p[2] };
            }
            fr
        })
        .collect();
    let m = read_f32_2d(&inputs.join("music.npy"), None, "music").unwrap();
    let seed: Vec<u32> = read_i64_2d(&dir.join("seed_tokens.npy"), None, "seed").unwrap().data.iter().map(|&t| t as u32).collect();
    let pos = read_f32_2d(&dir.join("follower_pos3d.npy"), Some(165), "pos").unwrap();
    let rot = read_f32_2d(&dir.join("follower_rotmat.npy"), Some(495), "rot").unwrap();
    Golden {
        leader,
        music: m.data[..t4 * m.cols].to_vec(),
        seed: seed.try_into().unwrap(),
        frames: pos.rows,
        pos: pos.data,
        rot: rot.data,
        config: meta["config"].clone(),
    }
}

struct Model(*mut DuoModel);
unsafe impl Send for Model {}
unsafe impl Sync for Model {}

fn open() -> Model {
    // SAFETY: every C entry point below is called with NULL (where the test checks NULL handling) or with pointers to live locals of the documented sizes; handles come from the library and are freed once.
    let p = CString::new(fixtures().join("tiny/model.duo").to_str().unwrap()).unwrap();
    let mut m = ptr::null_mut();
    assert_eq!(unsafe { duo_model_open_file(p.as_ptr(), &mut m) }, DuoResult::Ok, "{}", last_error());
    Model(m)
}

fn config(m: &Model, g: &Golden) -> DuoSessionConfig {
    // SAFETY: every C entry point below is called with NULL (where the test checks NULL handling) or with pointers to live locals of the documented sizes; handles come from the library and are freed once.
    let mut c = DuoSessionConfig::default();
    assert_eq!(unsafe { duo_session_config_minimum(m.0, &mut c) }, DuoResult::Ok);
    let get = |k: &str| g.config[k].as_u64().unwrap() as u32;
    c.lookahead = get("lookahead");
    c.enc_future = get("enc_future");
    c.dec_future = get("dec_future");
    c.shift = get("shift");
    c.music_lookahead = get("music_lookahead");
    c
}

/// How a run is disturbed.
#[derive(Clone, Copy, PartialEq)]
enum Noise {
    None,
    /// Before every 7th frame, push a bad frame (NaN, Inf, or 1e9 m) first.
    BadFrames,
}

/// Drives `session` over the golden; returns every pulled frame.
fn drive(s: *mut DuoSession, g: &Golden, noise: Noise) -> Vec<DuoFollowerFrame> {
    // SAFETY: every C entry point below is called with NULL (where the test checks NULL handling) or with pointers to live locals of the documented sizes; handles come from the library and are freed once.
    assert_eq!(unsafe { duo_session_set_music_track(s, g.music.as_ptr(), g.music.len()) }, DuoResult::Ok, "{}", last_error());
    let mut out = Vec::new();
    let mut f = DuoFollowerFrame::default();
    for (i, frame) in g.leader.iter().enumerate() {
        if noise == Noise::BadFrames && i % 7 == 3 {
            let mut bad = *frame;
            bad.joints[i % 55].y = [f32::NAN, f32::INFINITY, 1e9][i % 3];
            assert_eq!(unsafe { duo_session_push_leader(s, &bad) }, DuoResult::NonFiniteInput);
            assert!(last_error().contains("session unchanged"), "{}", last_error());
        }
        match unsafe { duo_session_push_leader(s, frame) } {
            DuoResult::Ok => {}
            // Past the music track's last step no frame comes out; the
            // leader frames pile up until the session refuses more.
            DuoResult::Backlog if out.len() == g.frames => break,
            r => panic!("frame {i}: {r:?} {}", last_error()),
        }
        loop {
            match unsafe { duo_session_pull_follower(s, &mut f) } {
                DuoResult::Ok => out.push(f),
                DuoResult::NotReady => break,
                r => panic!("pull: {r:?} {}", last_error()),
            }
        }
    }
    out
}

fn check_against_golden(out: &[DuoFollowerFrame], g: &Golden) {
    check_within(out, g, MOTION_ABS, "C API");
}

fn check_within(out: &[DuoFollowerFrame], g: &Golden, pos_tol: f32, what: &str) {
    assert_eq!(out.len(), g.frames);
    let mut pos_err = 0.0f32;
    let mut rot_err = 0.0f32;
    for (i, f) in out.iter().enumerate() {
        assert_eq!(f.index, i as u64);
        for j in 0..55 {
            let p = f.positions[j];
            let w = &g.pos[i * 165 + 3 * j..i * 165 + 3 * j + 3];
            pos_err = pos_err.max((p.x - w[0]).abs()).max((p.y - w[1]).abs()).max((p.z - w[2]).abs());
            let q = f.rotations[j];
            let r = mat_from_quat([q.x, q.y, q.z, q.w]);
            let raw = &g.rot[i * 495 + 9 * j..i * 495 + 9 * j + 9];
            let want = nearest_rotation(&[[raw[0], raw[1], raw[2]], [raw[3], raw[4], raw[5]], [raw[6], raw[7], raw[8]]]);
            for a in 0..3 {
                for b in 0..3 {
                    rot_err = rot_err.max((r[a][b] - want[a][b]).abs());
                }
            }
        }
        assert_eq!(f.root, f.positions[0]);
    }
    eprintln!("{what} vs streaming_tiny_minimum: {} frames, max |pos err| {pos_err:.2e} m, max |rot err| {rot_err:.2e}", out.len());
    assert!(pos_err <= pos_tol, "{what}: positions: {pos_err}");
    // The projection amplifies raw-matrix error by at most the inverse of
    // the smallest singular-value gap; 10x leaves ample room.
    assert!(rot_err <= 10.0 * pos_tol, "{what}: rotations: {rot_err}");
}

#[test]
fn library_session_matches_the_golden_and_ignores_bad_frames() {
    // SAFETY: every C entry point below is called with NULL (where the test checks NULL handling) or with pointers to live locals of the documented sizes; handles come from the library and are freed once.
    let g = golden();
    let m = open();
    let c = config(&m, &g);
    let mut s = ptr::null_mut();
    assert_eq!(unsafe { duo_session_new(m.0, &c, g.seed.as_ptr(), &mut s) }, DuoResult::Ok, "{}", last_error());
    let mut lat = 99;
    assert_eq!(unsafe { duo_session_latency_frames(s, &mut lat) }, DuoResult::Ok);
    assert_eq!(lat as u64, 0);
    let clean = drive(s, &g, Noise::None);
    check_against_golden(&clean, &g);
    // Reset: the same run again, now with rejected bad frames interleaved.
    assert_eq!(unsafe { duo_session_reset(s, g.seed.as_ptr()) }, DuoResult::Ok);
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
    assert_eq!(unsafe { duo_session_bytes(m.0, &c, &mut bytes) }, DuoResult::Ok);
    // Odd address on purpose: any alignment is accepted.
    let mut mem = vec![0u8; bytes + 1];
    let mut s = ptr::null_mut();
    let small = unsafe { duo_session_new_in(m.0, &c, g.seed.as_ptr(), mem.as_mut_ptr().add(1), bytes - 1, &mut s) };
    assert_eq!(small, DuoResult::BufferTooSmall);
    assert!(s.is_null());
    assert_eq!(unsafe { duo_session_new_in(m.0, &c, g.seed.as_ptr(), mem.as_mut_ptr().add(1), bytes, &mut s) }, DuoResult::Ok, "{}", last_error());
    let reference = drive(s, &g, Noise::None);
    check_against_golden(&reference, &g);
    unsafe { duo_session_free(s) };

    let results: Vec<Vec<DuoFollowerFrame>> = std::thread::scope(|scope| {
        let handles: Vec<_> = (0..4)
            .map(|_| {
                let (m, g, c) = (&m, &g, &c);
                scope.spawn(move || {
                    let mut s = ptr::null_mut();
                    assert_eq!(unsafe { duo_session_new(m.0, c, g.seed.as_ptr(), &mut s) }, DuoResult::Ok);
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
    assert_eq!(unsafe { duo_session_new(m.0, &bad, g.seed.as_ptr(), &mut s) }, DuoResult::InvalidArgument);
    let mut bad = c;
    bad.sampling = 7;
    assert_eq!(unsafe { duo_session_new(m.0, &bad, g.seed.as_ptr(), &mut s) }, DuoResult::InvalidArgument);
    assert!(last_error().contains("sampling"), "{}", last_error());
    let big = [1_000_000u32; 5];
    assert_eq!(unsafe { duo_session_new(m.0, &c, big.as_ptr(), &mut s) }, DuoResult::InvalidArgument);
    assert_eq!(unsafe { duo_session_new(ptr::null(), &c, g.seed.as_ptr(), &mut s) }, DuoResult::NullParameter);
    assert_eq!(unsafe { duo_session_new(m.0, ptr::null(), g.seed.as_ptr(), &mut s) }, DuoResult::NullParameter);
    assert_eq!(unsafe { duo_session_new(m.0, &c, ptr::null(), &mut s) }, DuoResult::NullParameter);
    assert_eq!(unsafe { duo_session_new(m.0, &c, g.seed.as_ptr(), ptr::null_mut()) }, DuoResult::NullParameter);
    assert_eq!(s, sentinel);

    assert_eq!(unsafe { duo_session_new(m.0, &c, g.seed.as_ptr(), &mut s) }, DuoResult::Ok);
    let mut f = DuoFollowerFrame { index: 77, ..Default::default() };
    assert_eq!(unsafe { duo_session_pull_follower(s, &mut f) }, DuoResult::NotReady);
    assert_eq!(f.index, 77);
    let music = vec![0.0f32; 54];
    assert_eq!(unsafe { duo_session_push_music(s, music.as_ptr(), 53) }, DuoResult::InvalidArgument);
    assert_eq!(unsafe { duo_session_push_music(s, ptr::null(), 0) }, DuoResult::NullParameter);
    let mut nan = music.clone();
    nan[5] = f32::NAN;
    assert_eq!(unsafe { duo_session_push_music(s, nan.as_ptr(), 54) }, DuoResult::NonFiniteInput);
    assert_eq!(unsafe { duo_session_push_leader(s, ptr::null()) }, DuoResult::NullParameter);
    assert_eq!(unsafe { duo_session_push_leader(ptr::null_mut(), &g.leader[0]) }, DuoResult::NullParameter);
    assert_eq!(unsafe { duo_session_reset(s, big.as_ptr()) }, DuoResult::InvalidArgument);
    let mut tokens = [9u32; 5];
    let n = 8usize;
    let flat: Vec<f32> = g.leader[..n].iter().flat_map(|fr| fr.joints.iter().flat_map(|v| [v.x, v.y, v.z])).collect();
    assert_eq!(unsafe { duo_model_seed_tokens(m.0, flat.as_ptr(), flat.as_ptr(), n, tokens.as_mut_ptr()) }, DuoResult::Ok, "{}", last_error());
    assert_eq!(unsafe { duo_session_reset(s, tokens.as_ptr()) }, DuoResult::Ok);
    assert_eq!(unsafe { duo_model_seed_tokens(m.0, flat.as_ptr(), flat.as_ptr(), 1, tokens.as_mut_ptr()) }, DuoResult::InvalidArgument);
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
        assert_eq!(unsafe { duo_session_new(m.0, &c, g.seed.as_ptr(), &mut s) }, DuoResult::Ok, "{}", last_error());
        let out = drive(s, &g, Noise::None);
        unsafe { duo_session_free(s) };
        out
    };
    check_within(&run(DuoSessionConfig { staggered: 1, ..base }), &g, MOTION_ABS, "staggered");
    check_within(&run(DuoSessionConfig { staggered: 2, ..base }), &g, MOTION_ABS, "spread");
    // f16 K/V: same tokens on this golden; motion within a looser bound.
    check_within(&run(DuoSessionConfig { kv: KV_F16, ..base }), &g, 1e-2, "f16 K/V");
    let mut s = ptr::null_mut();
    for bad in [DuoSessionConfig { kv: 2, ..base }, DuoSessionConfig { staggered: 3, ..base }] {
        assert_eq!(unsafe { duo_session_new(m.0, &bad, g.seed.as_ptr(), &mut s) }, DuoResult::InvalidArgument);
    }
    assert!(s.is_null());
    let (mut b32, mut b16) = (0usize, 0usize);
    assert_eq!(unsafe { duo_session_bytes(m.0, &base, &mut b32) }, DuoResult::Ok);
    assert_eq!(unsafe { duo_session_bytes(m.0, &DuoSessionConfig { kv: KV_F16, ..base }, &mut b16) }, DuoResult::Ok);
    assert!(b16 < b32, "f16 cache is smaller: {b16} vs {b32}");
    unsafe { duo_model_free(m.0) };
}
