//! `duolando generate` end to end through the binary: outputs equal the R
//! goldens, and bad inputs fail with messages naming the file.

use std::path::{Path, PathBuf};
use std::process::Command;

use duolando::npy::{read_f32_2d, read_i64_2d, write_f32};

fn fixtures() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/fixtures")
}

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("duo-cli-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn duolando(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_duolando")).args(args).output().unwrap()
}

fn p(path: &Path) -> &str {
    path.to_str().unwrap()
}

#[test]
fn generate_exact_matches_the_golden_rollout() {
    let fx = fixtures();
    let roll = fx.join("rollout_tiny_long");
    let out = tmp("golden");
    let o = duolando(&[
        "generate",
        "--model",
        p(&fx.join("tiny/model.duo")),
        "--leader",
        p(&roll.join("leader_pos3d.npy")),
        "--music",
        p(&roll.join("music.npy")),
        "--follower-start",
        p(&roll.join("follower_start.npy")),
        "--mode",
        "exact",
        "--out",
        p(&out),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let got = read_i64_2d(&out.join("tokens.npy"), Some(5), "tokens").unwrap();
    let want = read_i64_2d(&roll.join("tokens.npy"), Some(5), "tokens").unwrap();
    assert_eq!(got, want);
    let got = read_f32_2d(&out.join("follower_pos3d.npy"), Some(165), "pos").unwrap();
    let want = read_f32_2d(&roll.join("follower_pos3d.npy"), Some(165), "pos").unwrap();
    assert_eq!(got.rows, want.rows);
    let err = got.data.iter().zip(&want.data).map(|(a, b)| (a - b).abs()).fold(0f32, f32::max);
    assert!(err <= 1e-4, "max pos err {err}");
    let rot = read_f32_2d(&out.join("follower_rotmat.npy"), Some(495), "rot").unwrap();
    assert_eq!(rot.rows, want.rows);
}

#[test]
fn generate_with_seed_tokens_matches_the_golden_rollout() {
    let fx = fixtures();
    let roll = fx.join("rollout_tiny_short");
    let seed = read_i64_2d(&roll.join("seed_tokens.npy"), Some(5), "seed").unwrap();
    let seed: Vec<String> = seed.data.iter().map(|t| t.to_string()).collect();
    let out = tmp("tokens");
    let o = duolando(&[
        "generate",
        "--model",
        p(&fx.join("tiny/model.duo")),
        "--leader",
        p(&roll.join("leader_pos3d.npy")),
        "--music",
        p(&roll.join("music.npy")),
        "--seed-tokens",
        &seed.join(","),
        "--out",
        p(&out),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let got = read_i64_2d(&out.join("tokens.npy"), Some(5), "tokens").unwrap();
    let want = read_i64_2d(&roll.join("tokens.npy"), Some(5), "tokens").unwrap();
    assert_eq!(got, want);
}

fn expect_failure(args: &[&str], needles: &[&str]) {
    let o = duolando(args);
    assert!(!o.status.success(), "expected failure for {args:?}");
    let msg = String::from_utf8_lossy(&o.stderr);
    for n in needles {
        assert!(msg.contains(n), "message for {args:?} lacks '{n}':\n{msg}");
    }
    assert!(!msg.contains("panicked"), "{msg}");
}

#[test]
fn bad_inputs_fail_with_messages_naming_the_file() {
    let fx = fixtures();
    let roll = fx.join("rollout_tiny_short");
    let model = fx.join("tiny/model.duo");
    let dir = tmp("bad");
    // Music given where the leader is expected: wrong column count.
    expect_failure(
        &["generate", "--model", p(&model), "--leader", p(&roll.join("music.npy")), "--music", p(&roll.join("music.npy")), "--seed-tokens", "1,2,3,4,5", "--out", p(&dir)],
        &["music.npy", "165 columns"],
    );
    // Missing file.
    expect_failure(
        &["generate", "--model", p(&model), "--leader", p(&dir.join("nope.npy")), "--music", p(&roll.join("music.npy")), "--seed-tokens", "1,2,3,4,5", "--out", p(&dir)],
        &["nope.npy"],
    );
    // Malformed and out-of-vocabulary seed tokens.
    expect_failure(
        &["generate", "--model", p(&model), "--leader", p(&roll.join("leader_pos3d.npy")), "--music", p(&roll.join("music.npy")), "--seed-tokens", "1,2,x,4,5", "--out", p(&dir)],
        &["'x'"],
    );
    expect_failure(
        &["generate", "--model", p(&model), "--leader", p(&roll.join("leader_pos3d.npy")), "--music", p(&roll.join("music.npy")), "--seed-tokens", "1,2,3,4,100000", "--out", p(&dir)],
        &["vocabulary"],
    );
    // Music shorter than the leader.
    let short = dir.join("short_music.npy");
    write_f32(&short, &vec![0.0; 8 * 54], &[8, 54]).unwrap();
    expect_failure(
        &["generate", "--model", p(&model), "--leader", p(&roll.join("leader_pos3d.npy")), "--music", p(&short), "--seed-tokens", "1,2,3,4,5", "--out", p(&dir)],
        &["short_music.npy", "music frames"],
    );
    // NaN in the leader.
    let leader = read_f32_2d(&roll.join("leader_pos3d.npy"), Some(165), "l").unwrap();
    let mut data = leader.data.clone();
    data[1000] = f32::NAN;
    let nan = dir.join("nan_leader.npy");
    write_f32(&nan, &data, &[leader.rows, 165]).unwrap();
    expect_failure(
        &["generate", "--model", p(&model), "--leader", p(&nan), "--music", p(&roll.join("music.npy")), "--seed-tokens", "1,2,3,4,5", "--out", p(&dir)],
        &["NaN"],
    );
    // Not a model.
    expect_failure(
        &["generate", "--model", p(&roll.join("music.npy")), "--leader", p(&roll.join("leader_pos3d.npy")), "--music", p(&roll.join("music.npy")), "--seed-tokens", "1,2,3,4,5", "--out", p(&dir)],
        &["music.npy"],
    );
}
