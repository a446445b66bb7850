//! The S golden `streaming_tiny_minimum` (tests/fixtures/README.md "S
//! goldens") read for the C API tests, a session driven over it through
//! the `duo_*` functions, and the comparison with its frames.

use super::*;
use duolando::frames::{DuoFollowerFrame, DuoLeaderFrame, DuoVec3};
use duolando::model::*;
use duolando::result::DuoResult;
use duolando::session::*;
use duolando_std::npy::{read_f32_2d, read_i64_2d};
use duolando_std::skeleton::rotation::{mat_from_quat, nearest_rotation};
/// Tolerance of the S goldens on positions and rotations (metres / matrix entries).
pub const MOTION_ABS: f32 = 1e-4;

pub struct Golden {
    pub leader: Vec<DuoLeaderFrame>,
    pub music: Vec<f32>,
    pub seed: [u32; 5],
    pub pos: Vec<f32>,
    pub rot: Vec<f32>,
    pub frames: usize,
    pub config: serde_json::Value,
}

pub fn golden() -> Golden {
    // SAFETY: every C entry point below is called with NULL (where the test checks NULL handling) or with pointers to live locals of the documented sizes; handles come from the library and are freed once.
    let dir = fixture("streaming_tiny_minimum");
    // The goldens' meta.json may hold Python's bare `Infinity` (not JSON).
    let text = std::fs::read_to_string(dir.join("meta.json"))
        .unwrap()
        .replace("Infinity", "null");
    let meta: serde_json::Value = serde_json::from_str(&text).unwrap();
    let inputs = dir.join(meta["inputs"].as_str().unwrap());
    let t4 = meta["T4"].as_u64().unwrap() as usize;
    let l = read_f32_2d(&inputs.join("leader_pos3d.npy"), Some(165), "leader").unwrap();
    let leader = (0..t4)
        .map(|f| {
            let mut fr = DuoLeaderFrame::default();
            for j in 0..55 {
                let p = &l.data[f * 165 + 3 * j..f * 165 + 3 * j + 3];
                fr.joints[j] = DuoVec3 {
                    x: p[0],
                    y: p[1],
                    z: p[2],
                };
            }
            fr
        })
        .collect();
    let m = read_f32_2d(&inputs.join("music.npy"), None, "music").unwrap();
    let seed: Vec<u32> = read_i64_2d(&dir.join("seed_tokens.npy"), None, "seed")
        .unwrap()
        .data
        .iter()
        .map(|&t| t as u32)
        .collect();
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

pub struct Model(pub *mut DuoModel);
unsafe impl Send for Model {}
unsafe impl Sync for Model {}

pub fn open() -> Model {
    Model(open_model(&fixture("tiny/model.duo")))
}

pub fn config(m: &Model, g: &Golden) -> DuoSessionConfig {
    // SAFETY: every C entry point below is called with NULL (where the test checks NULL handling) or with pointers to live locals of the documented sizes; handles come from the library and are freed once.
    let mut c = DuoSessionConfig::default();
    assert_eq!(
        unsafe { duo_session_config_minimum(m.0, &mut c) },
        DuoResult::Ok
    );
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
pub enum Noise {
    None,
    /// Before every 7th frame, push a bad frame (NaN, Inf, or 1e9 m) first.
    BadFrames,
}

/// Drives `session` over the golden; returns every pulled frame.
pub fn drive(s: *mut DuoSession, g: &Golden, noise: Noise) -> Vec<DuoFollowerFrame> {
    // SAFETY: every C entry point below is called with NULL (where the test checks NULL handling) or with pointers to live locals of the documented sizes; handles come from the library and are freed once.
    assert_eq!(
        unsafe { duo_session_set_music_track(s, g.music.as_ptr(), g.music.len()) },
        DuoResult::Ok,
        "{}",
        last_error()
    );
    let mut out = Vec::new();
    for (i, frame) in g.leader.iter().enumerate() {
        if noise == Noise::BadFrames && i % 7 == 3 {
            let mut bad = *frame;
            bad.joints[i % 55].y = [f32::NAN, f32::INFINITY, 1e9][i % 3];
            assert_eq!(
                unsafe { duo_session_push_leader(s, &bad) },
                DuoResult::NonFiniteInput
            );
            assert!(
                last_error().contains("session unchanged"),
                "{}",
                last_error()
            );
        }
        match unsafe { duo_session_push_leader(s, frame) } {
            DuoResult::Ok => {}
            // Past the music track's last step no frame comes out; the
            // leader frames pile up until the session refuses more.
            DuoResult::Backlog if out.len() == g.frames => break,
            r => panic!("frame {i}: {r:?} {}", last_error()),
        }
        pull_all(s, &mut out);
    }
    out
}

pub fn check_against_golden(out: &[DuoFollowerFrame], g: &Golden) {
    check_within(out, g, MOTION_ABS, "C API");
}

pub fn check_within(out: &[DuoFollowerFrame], g: &Golden, pos_tol: f32, what: &str) {
    assert_eq!(out.len(), g.frames);
    let mut pos_err = 0.0f32;
    let mut rot_err = 0.0f32;
    for (i, f) in out.iter().enumerate() {
        assert_eq!(f.index, i as u64);
        for j in 0..55 {
            let p = f.positions[j];
            let w = &g.pos[i * 165 + 3 * j..i * 165 + 3 * j + 3];
            pos_err = pos_err
                .max((p.x - w[0]).abs())
                .max((p.y - w[1]).abs())
                .max((p.z - w[2]).abs());
            let q = f.rotations[j];
            let r = mat_from_quat([q.x, q.y, q.z, q.w]);
            let raw = &g.rot[i * 495 + 9 * j..i * 495 + 9 * j + 9];
            let want = nearest_rotation(&[
                [raw[0], raw[1], raw[2]],
                [raw[3], raw[4], raw[5]],
                [raw[6], raw[7], raw[8]],
            ]);
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

/// The golden's leader frames moved: session `k` of a batch dances to
/// its own leader (x mirrored for odd `k`, raised `0.05 k` m).
pub fn leader_of(g: &Golden, k: usize) -> Vec<DuoLeaderFrame> {
    let mut v = g.leader.clone();
    for f in &mut v {
        for j in &mut f.joints {
            if k % 2 == 1 {
                j.x = -j.x;
            }
            j.y += 0.05 * k as f32;
        }
    }
    v
}

/// Pulls every ready frame of `s` into `out`.
pub fn pull_all(s: *mut DuoSession, out: &mut Vec<DuoFollowerFrame>) {
    // SAFETY: `s` is a live session of the caller.
    let mut f = DuoFollowerFrame::default();
    loop {
        match unsafe { duo_session_pull_follower(s, &mut f) } {
            DuoResult::Ok => out.push(f),
            DuoResult::NotReady => break,
            r => panic!("pull: {r:?} {}", last_error()),
        }
    }
}
