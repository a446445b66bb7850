//! `duolando inspect` through the binary: the tiny fixture's config and
//! sizes in text and JSON, and a named error for a file that is not a model.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn tiny() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/fixtures/tiny/model.duo")
}

fn inspect(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_duolando"))
        .arg("inspect")
        .args(args)
        .output()
        .unwrap()
}

#[test]
fn inspect_prints_the_tiny_config() {
    let m = tiny();
    let o = inspect(&[m.to_str().unwrap()]);
    let s = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    for want in [
        "gpt n_embd 32 heads 4 base 2 head 2 block_size 30 look_forward 29",
        "lat music  n_in 54",
        "vq up     in 48 rot 144 width 16",
        "dtype f32",
        "parameters",
        "R mode is offline",
        "reference    a 29 e 22 d 22 shift 15: latency 291 frames (9.70 s)",
        "minimum      a 0 e 0 d 0 shift 15: latency 0 frames (0.00 s)",
        "latency with music pushed live 291 frames; 2 GPT window rows a step",
    ] {
        assert!(s.contains(want), "missing '{want}' in:\n{s}");
    }
}

#[test]
fn inspect_json_parses_and_agrees_with_the_file() {
    let m = tiny();
    let o = inspect(&[m.to_str().unwrap(), "--json", "--frames", "600"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(v["config"]["gpt"]["n_embd"], 32);
    assert_eq!(
        v["config"]["gpt"]["vocab"],
        serde_json::json!([64, 64, 64, 64, 64])
    );
    assert_eq!(v["file_bytes"], std::fs::metadata(&m).unwrap().len());
    let tensors = v["tensors"].as_u64().unwrap();
    assert!(tensors > 0);
    let per: u64 = v["dtypes"]
        .as_object()
        .unwrap()
        .values()
        .map(|d| d["tensors"].as_u64().unwrap())
        .sum();
    assert_eq!(per, tensors);
    let params: u64 = v["dtypes"]
        .as_object()
        .unwrap()
        .values()
        .map(|d| d["params"].as_u64().unwrap())
        .sum();
    assert_eq!(params, v["params"].as_u64().unwrap());
    // 600 frames: the rollout_tiny_long golden has K = 120 steps, 484 frames.
    let r = &v["r_mode"]["requested"];
    assert_eq!(
        (r["steps"].as_u64(), r["output_frames"].as_u64()),
        (Some(120), Some(484))
    );
    assert!(v["r_mode"]["one_minute"]["scratch_bytes"].as_u64().unwrap() > 0);
    assert_eq!(v["r_mode"]["one_minute"]["input_frames"], 1800);
    // The tiny fixture has the published geometry: e_max = d_max = 22 (docs/STREAMING.md §1).
    assert_eq!(
        (
            v["streaming"]["enc_future_max"].as_u64(),
            v["streaming"]["dec_future_max"].as_u64()
        ),
        (Some(22), Some(22))
    );
    let b = &v["streaming"]["budgets"];
    // Preset::ALL: reference, interactive, live-music, minimum.
    let names: Vec<&str> = b
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x["budget"].as_str().unwrap())
        .collect();
    assert_eq!(names, ["reference", "interactive", "live-music", "minimum"]);
    assert_eq!(b[0]["latency_frames"], 291);
    assert_eq!(b[1]["latency_frames"], 31);
    assert_eq!(
        (
            b[2]["latency_frames"].as_u64(),
            b[2]["live_latency_frames"].as_u64(),
            b[2]["music_lookahead"].as_u64()
        ),
        (Some(31), Some(31), Some(0))
    );
    assert_eq!(
        (
            b[3]["latency_frames"].as_u64(),
            b[3]["live_latency_frames"].as_u64()
        ),
        (Some(0), Some(3))
    );
    // The arena figure is Model::session_bytes of that budget.
    let file = duolando::model_file::ModelFile::open(&m).unwrap();
    let duo = file.duo().unwrap();
    let model = duolando_core::duolando::model::Model::from_duo(&duo).unwrap();
    let sc = duolando_core::duolando::session::SessionConfig::reference(&model.cfg);
    assert_eq!(
        b[0]["arena_bytes"].as_u64(),
        Some(model.session_bytes(&sc).unwrap() as u64)
    );
    // One GPT cache, and that session bound to a step batch (its state alone).
    let one = duolando_core::duolando::session::SessionConfig {
        schedule: duolando_core::duolando::session::CacheSchedule::Reprefill,
        ..sc
    };
    let (own, bound) = (
        b[0]["arena_bytes_reprefill"].as_u64().unwrap(),
        b[0]["arena_bytes_reprefill_bound"].as_u64().unwrap(),
    );
    assert_eq!(own, model.session_bytes(&one).unwrap() as u64);
    assert_eq!(bound, model.batched_session_bytes(&one).unwrap() as u64);
    assert!(bound < own, "{bound} vs {own}");
    // Every preset's spread step computes two GPT window rows (shift 15 of a
    // 29-row window: its own and one of the next window's).
    for x in b.as_array().unwrap() {
        assert_eq!(x["shift"].as_u64(), Some(15), "{x}");
        assert_eq!(x["gpt_rows_per_step"].as_u64(), Some(2), "{x}");
    }
}

#[test]
fn inspect_names_a_bad_file() {
    let dir = std::env::temp_dir().join(format!("duo-inspect-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let bad = dir.join("bad.duo");
    std::fs::write(&bad, b"not a model at all, just some bytes to read").unwrap();
    for path in [bad.clone(), dir.join("missing.duo")] {
        let o = inspect(&[path.to_str().unwrap()]);
        let e = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(1), "{e}");
        assert!(
            e.contains(path.to_str().unwrap()) && !e.contains("panicked"),
            "{e}"
        );
    }
}

/// A model with a NaN (then an infinite) weight: `inspect` and `generate`
/// refuse it at open, naming the tensor and the element (docs/FORMAT.md
/// rule 15), where before it opened and generated NaN frames.
#[test]
fn inspect_and_generate_refuse_a_non_finite_weight_by_name() {
    let fx = tiny().parent().unwrap().parent().unwrap().to_path_buf();
    let mut bytes = std::fs::read(tiny()).unwrap();
    // The last tensor's last non-zero byte (zero padding follows); the
    // tiny fixture is all f32 and payloads are 64-byte aligned.
    let last = bytes.iter().rposition(|&b| b != 0).unwrap();
    let at = last & !3;
    let dir = std::env::temp_dir().join(format!("duo-nan-weight-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    for (value, word) in [(f32::NAN, "NaN"), (f32::NEG_INFINITY, "-inf")] {
        bytes[at..at + 4].copy_from_slice(&value.to_le_bytes());
        let bad = dir.join("nan.duo");
        std::fs::write(&bad, &bytes).unwrap();
        let roll = fx.join("rollout_tiny_long");
        let gen_out = dir.join("out");
        let runs = [
            inspect(&[bad.to_str().unwrap()]),
            Command::new(env!("CARGO_BIN_EXE_duolando"))
                .args(["generate", "--model", bad.to_str().unwrap()])
                .args(["--leader", roll.join("leader_pos3d.npy").to_str().unwrap()])
                .args(["--music", roll.join("music.npy").to_str().unwrap()])
                .args([
                    "--follower-start",
                    roll.join("follower_start.npy").to_str().unwrap(),
                ])
                .args(["--out", gen_out.to_str().unwrap()])
                .output()
                .unwrap(),
        ];
        for o in runs {
            let e = String::from_utf8_lossy(&o.stderr);
            assert_eq!(o.status.code(), Some(1), "{e}");
            assert!(
                e.contains(bad.to_str().unwrap())
                    && e.contains("weight element")
                    && e.contains(&format!("is {word}")),
                "{e}"
            );
            assert!(
                e.contains('`') && !e.contains("panicked"),
                "the tensor is named: {e}"
            );
        }
        assert!(
            !gen_out.join("follower_pos3d.npy").exists(),
            "nothing generated"
        );
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// A Bailando model: its family, config, rates and R-mode sizes, in text
/// and JSON.
#[test]
fn inspect_prints_a_bailando_model() {
    let m =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/fixtures/bailando_btiny/model.duo");
    let o = inspect(&[m.to_str().unwrap()]);
    let s = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    for want in [
        "Bailando model",
        "format v2",
        "gpt n_embd 32 heads 4 base 1 head 1 block_size 8 vocab up/down [24, 24] n_music 438",
        "vq down   in 27 rot 0 width 16",
        "8 frames per token at 60 fps, SMPL 24 joints",
        "1 min: 450 music rows -> 455 steps, 3648 output frames",
        "streaming (S): latency = 8 x dec_future frames; dec_future_max 9",
        "interactive dec_future 2 shift 5: latency 16 frames",
    ] {
        assert!(s.contains(want), "missing {want:?} in:\n{s}");
    }
    let o = inspect(&[m.to_str().unwrap(), "--json"]);
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(j["family"], "Bailando");
    assert_eq!(j["format_version"], 2);
    assert_eq!(j["derived"]["joints"], 24);
    assert_eq!(j["config"]["gpt"]["n_music"], 438);
}
