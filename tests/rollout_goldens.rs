//! Greedy R-mode rollouts token for token against the goldens of the Python
//! reference (`tools/make_fixtures.py`; the reference itself reproduces the
//! authors' code bit for bit, see tools/reference/compare_original.py).

use duolando::model_file::ModelFile;
use duolando::npy::{read_f32_2d, read_i64_2d};
use duolando_tests::{fixture, max_errors, rollout_model, run_rollout, Tol};

fn check(name: &str) {
    let dir = fixture(&format!("rollout_{name}"));
    let meta: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join("meta.json")).unwrap()).unwrap();
    let file = ModelFile::open(fixture(&format!("{}/model.duo", rollout_model(name)))).unwrap();
    let run = run_rollout(&file, name);
    assert_eq!(run.steps as u64, meta["K"].as_u64().unwrap(), "K");
    assert_eq!(
        run.progress_calls, run.steps,
        "progress called once per step"
    );
    let want_tokens = read_i64_2d(&dir.join("tokens.npy"), Some(5), "tokens").unwrap();
    let got: Vec<i64> = run.tokens.iter().map(|&t| t as i64).collect();
    let first_diff = got.iter().zip(&want_tokens.data).position(|(a, b)| a != b);
    assert_eq!(
        first_diff, None,
        "{name}: first token mismatch at flat index {first_diff:?}"
    );
    assert_eq!(got.len(), want_tokens.data.len());
    let want_leader =
        read_i64_2d(&dir.join("leader_tokens.npy"), Some(4), "leader tokens").unwrap();
    let got_leader: Vec<i64> = run.leader_tokens.iter().map(|&t| t as i64).collect();
    assert_eq!(got_leader, want_leader.data, "{name}: leader tokens");
    let want_pos = read_f32_2d(&dir.join("follower_pos3d.npy"), Some(165), "pos").unwrap();
    let want_rot = read_f32_2d(&dir.join("follower_rotmat.npy"), Some(495), "rot").unwrap();
    let (pos_abs, _) = max_errors(&run.pos, &want_pos.data);
    let (rot_abs, _) = max_errors(&run.rot, &want_rot.data);
    eprintln!(
        "{name}: {} token rows identical; max |pos err| {pos_abs:.2e} m, max |rot err| {rot_abs:.2e}",
        want_tokens.rows
    );
    assert!(
        pos_abs <= Tol::MotionAbs.limit(),
        "{name}: follower_pos3d max error {pos_abs}"
    );
    assert!(
        rot_abs <= Tol::MotionAbs.limit(),
        "{name}: follower_rotmat max error {rot_abs}"
    );
}

/// T = 600: 120 steps, the 29-token window slides 91 times.
#[test]
fn tiny_long_seeded_from_follower_frames() {
    check("tiny_long");
}

#[test]
fn tiny_short_seeded_from_tokens() {
    check("tiny_short");
}

/// T = 251 is truncated to 248 as the original loader does.
#[test]
fn tiny_odd_length_is_truncated() {
    check("tiny_odd");
}

/// A second config (block 8, look-ahead 5, depth 2, vocab 48): the engine is config-generic.
#[test]
fn tiny2_seeded_from_follower_frames() {
    check("tiny2_frames");
}

#[test]
fn tiny2_seeded_from_tokens() {
    check("tiny2_tokens");
}
