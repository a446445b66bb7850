//! `duolando compare` and `duolando generate --mode streaming` end to end:
//! the figures equal those of the Python study
//! (`tests/fixtures/streaming_compare/<model>.json`, written by
//! `tools/streaming_study.py fixtures --write`), and streaming generation
//! writes the S golden's outputs.

use std::path::{Path, PathBuf};
use std::process::Command;

use duolando::npy::{read_f32_2d, read_i64_2d};
use serde_json::Value;

fn fixtures() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/fixtures")
}

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("duo-cmp-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn duolando(args: &[String]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_duolando"))
        .args(args)
        .output()
        .unwrap()
}

fn s(p: &Path) -> String {
    p.to_str().unwrap().to_string()
}

fn expected(model: &str) -> Value {
    serde_json::from_slice(
        &std::fs::read(fixtures().join(format!("streaming_compare/{model}.json"))).unwrap(),
    )
    .unwrap()
}

/// Runs `compare` for one setting of the study and checks every figure.
fn check(model: &str, setting: &str) {
    let fx = fixtures();
    let exp = expected(model);
    let inputs = fx.join(exp["inputs"].as_str().unwrap());
    let want = &exp["settings"][setting];
    let out = tmp(&format!("{model}-{setting}"));
    let json = out.join("figures.json");
    let mut args: Vec<String> = ["compare", "--model"].map(String::from).to_vec();
    args.push(s(&fx.join(format!("{model}/model.duo"))));
    for (flag, file) in [("--leader", "leader_pos3d.npy"), ("--music", "music.npy")] {
        args.push(flag.into());
        args.push(s(&inputs.join(file)));
    }
    if inputs.join("follower_start.npy").exists() {
        args.push("--follower-start".into());
        args.push(s(&inputs.join("follower_start.npy")));
    } else {
        let t = read_i64_2d(&inputs.join("seed_tokens.npy"), Some(5), "seed").unwrap();
        args.push("--seed-tokens".into());
        args.push(
            t.data
                .iter()
                .map(|v| v.to_string())
                .collect::<Vec<_>>()
                .join(","),
        );
    }
    for k in ["lookahead", "enc_future", "dec_future", "shift"] {
        args.push(format!("--{}", k.replace('_', "-")));
        args.push(want[k].as_u64().unwrap().to_string());
    }
    args.push("--json".into());
    args.push(s(&json));
    let o = duolando(&args);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let got: Value = serde_json::from_slice(&std::fs::read(&json).unwrap()).unwrap();
    for key in [
        "latency_frames",
        "one_step_steps",
        "free_run_steps",
        "joint_err_frames",
    ] {
        assert_eq!(got[key], want[key], "{model} {setting}: {key}");
    }
    // Token counts are exact; the study stored them as float32 ratios.
    for (key, v) in want.as_object().unwrap() {
        if key.starts_with("token_agreement") || key == "free_run_agreement" {
            let (g, w) = (got[key].as_f64().unwrap(), v.as_f64().unwrap());
            assert!((g - w).abs() < 1e-6, "{model} {setting}: {key} {g} vs {w}");
        }
    }
    for key in ["mean_joint_err_mm", "max_joint_err_mm"] {
        let (g, w) = (got[key].as_f64().unwrap(), want[key].as_f64().unwrap());
        assert!(
            (g - w).abs() < 0.05,
            "{model} {setting}: {key} {g} vs {w} mm"
        );
    }
}

#[test]
fn tiny_default_matches_the_study() {
    check("tiny", "default");
}

#[test]
fn tiny_minimum_matches_the_study() {
    check("tiny", "minimum");
}

#[test]
fn tiny2_exact_window_matches_the_study() {
    check("tiny2", "exact-window");
}

#[test]
fn tiny2_mid_matches_the_study() {
    check("tiny2", "mid");
}

#[test]
fn generate_streaming_writes_the_s_golden() {
    let fx = fixtures();
    let g = fx.join("streaming_tiny_mid_odd");
    let roll = fx.join("rollout_tiny_odd");
    let out = tmp("gen-stream");
    let seed = read_i64_2d(&g.join("seed_tokens.npy"), Some(5), "seed").unwrap();
    let args: Vec<String> = vec![
        "generate".into(),
        "--mode".into(),
        "streaming".into(),
        "--model".into(),
        s(&fx.join("tiny/model.duo")),
        "--leader".into(),
        s(&roll.join("leader_pos3d.npy")),
        "--music".into(),
        s(&roll.join("music.npy")),
        "--seed-tokens".into(),
        seed.data
            .iter()
            .map(|v| v.to_string())
            .collect::<Vec<_>>()
            .join(","),
        "--lookahead".into(),
        "6".into(),
        "--enc-future".into(),
        "4".into(),
        "--dec-future".into(),
        "4".into(),
        "--shift".into(),
        "15".into(),
        // The golden is S without an end (a drained run adds the tail: cli_generate).
        "--no-drain".into(),
        "-o".into(),
        s(&out),
    ];
    let o = duolando(&args);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let tokens = read_i64_2d(&out.join("tokens.npy"), Some(5), "tokens").unwrap();
    assert_eq!(
        tokens.data,
        read_i64_2d(&g.join("tokens.npy"), Some(5), "tokens")
            .unwrap()
            .data
    );
    let pos = read_f32_2d(&out.join("follower_pos3d.npy"), Some(165), "pos").unwrap();
    let want = read_f32_2d(&g.join("follower_pos3d.npy"), Some(165), "pos").unwrap();
    assert_eq!(pos.rows, want.rows);
    let err = pos
        .data
        .iter()
        .zip(&want.data)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0f32, f32::max);
    assert!(err <= 1e-4, "max |pos err| {err}");
}

#[test]
fn compare_rejects_a_budget_outside_the_model() {
    let fx = fixtures();
    let roll = fx.join("rollout_tiny2_tokens");
    let args: Vec<String> = vec![
        "compare".into(),
        "--model".into(),
        s(&fx.join("tiny2/model.duo")),
        "--leader".into(),
        s(&roll.join("leader_pos3d.npy")),
        "--music".into(),
        s(&roll.join("music.npy")),
        "--seed-tokens".into(),
        "0,0,0,0,0".into(),
        "--lookahead".into(),
        "99".into(),
    ];
    let o = duolando(&args);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("--lookahead 99") && err.contains("largest allowed: 5"),
        "{err}"
    );
}

/// Bailando models in exact mode: a model against itself agrees fully
/// with zero joint error; its f16 conversion samples the same tokens
/// (measured on this golden) with a small joint error; without --against,
/// S against R: at the exact preset equal, at a smaller decoder future the
/// same tokens (the window slides) and a joint error, at a jumping window
/// a one-step agreement below 1 on these random weights; a leader or a
/// Duolando preset is a named refusal.
#[test]
fn compare_bailando_models() {
    let fx = fixtures();
    let dir = tmp("bailando");
    let m = fx.join("bailando_btiny/model.duo");
    let roll = fx.join("bailando_rollout_btiny_aist_slide");
    let f16 = dir.join("f16.duo");
    let b = fx.join("bailando_btiny");
    let o = duolando(
        &[
            "convert",
            "--config",
            &s(&b.join("actor_critic.yaml")),
            "--gpt",
            &s(&b.join("gpt.safetensors")),
            "--vqvae",
            &s(&b.join("vqvae.safetensors")),
            "--dtype",
            "f16",
            "-o",
            &s(&f16),
        ]
        .map(String::from),
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let run = |against: &Path, name: &str| -> Value {
        let json = dir.join(name);
        let o = duolando(
            &[
                "compare",
                "--model",
                &s(&m),
                "--against",
                &s(against),
                "--music",
                &s(&roll.join("music.npy")),
                "--dance",
                &s(&roll.join("dance.npy")),
                "--json",
                &s(&json),
            ]
            .map(String::from),
        );
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        serde_json::from_slice(&std::fs::read(&json).unwrap()).unwrap()
    };
    let same = run(&m, "same.json");
    assert_eq!(same["free_run_agreement"], 1.0);
    assert_eq!(same["mean_joint_err_mm"], 0.0);
    assert_eq!(same["free_run_steps"], 37);
    assert_eq!(same["joint_err_frames"], 304);
    let half = run(&f16, "f16.json");
    assert_eq!(half["free_run_agreement"], 1.0, "{half}");
    let err = half["max_joint_err_mm"].as_f64().unwrap();
    assert!(err > 0.0 && err < 5.0, "f16 max joint error {err} mm");
    let sr = |extra: &[&str], name: &str| -> Value {
        let json = dir.join(name);
        let mut a = vec![
            "compare".to_string(),
            "--model".into(),
            s(&m),
            "--music".into(),
            s(&roll.join("music.npy")),
            "--dance".into(),
            s(&roll.join("dance.npy")),
            "--json".into(),
            s(&json),
        ];
        a.extend(extra.iter().map(|x| x.to_string()));
        let o = duolando(&a);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        assert!(
            String::from_utf8_lossy(&o.stdout).contains("streaming"),
            "{}",
            String::from_utf8_lossy(&o.stdout)
        );
        serde_json::from_slice(&std::fs::read(&json).unwrap()).unwrap()
    };
    let exact = sr(&["--preset", "exact"], "s_exact.json");
    assert_eq!(
        (
            exact["one_step_agreement"].as_f64(),
            exact["free_run_agreement"].as_f64(),
            exact["max_joint_err_mm"].as_f64()
        ),
        (Some(1.0), Some(1.0), Some(0.0)),
        "{exact}"
    );
    let d0 = sr(&["--preset", "exact", "--dec-future", "0"], "s_d0.json");
    assert_eq!(d0["free_run_agreement"], 1.0, "{d0}");
    assert!(d0["max_joint_err_mm"].as_f64().unwrap() > 0.0, "{d0}");
    assert_eq!(d0["latency_frames"], 0);
    let jump = sr(&["--preset", "reference"], "s_ref.json");
    assert!(jump["one_step_agreement"].as_f64().unwrap() < 1.0, "{jump}");
    for (extra, want) in [
        (vec!["--preset", "live-music"], "Duolando preset"),
        (
            vec!["--against", "x.duo", "--leader", "l.npy"],
            "solo dancer",
        ),
    ] {
        let mut a = vec![
            "compare".to_string(),
            "--model".into(),
            s(&m),
            "--music".into(),
            s(&roll.join("music.npy")),
            "--dance".into(),
            s(&roll.join("dance.npy")),
        ];
        a.extend(extra.iter().map(|x| x.to_string()));
        let o = duolando(&a);
        let e = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(1), "{e}");
        assert!(e.contains(want), "{e}");
    }
}

/// `compare` reports the papers' per-clip metrics of both runs (BAS
/// against the music's beats, BED against the leader, the foot-skating
/// ratio) over the frames both runs have: each equals the metric computed
/// on what `generate` writes for that run (R: `--mode exact`; S: the same
/// budget without a drain), cut to those frames.
#[test]
fn compare_reports_the_papers_clip_metrics_of_s_beside_r() {
    use duolando::eval::{bas, bed, footskate};
    let assets = Path::new(env!("CARGO_MANIFEST_DIR")).join("../assets");
    if !assets.join("demo.duo").is_file() {
        eprintln!("skipped: no assets/demo.duo");
        return;
    }
    let dir = tmp("metrics");
    let json = dir.join("cmp.json");
    let o = duolando(&["compare".into(), "--json".into(), s(&json)]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v: Value = serde_json::from_slice(&std::fs::read(&json).unwrap()).unwrap();
    let frames = v["joint_err_frames"].as_u64().unwrap() as usize;
    let leader = read_f32_2d(&assets.join("demo_leader_pos3d.npy"), Some(165), "leader").unwrap();
    let music = read_f32_2d(&assets.join("demo_music.npy"), Some(54), "music").unwrap();
    for (who, mode) in [("r", "exact"), ("s", "streaming")] {
        let out = dir.join(mode);
        let mut args: Vec<String> = ["generate", "--mode", mode].map(String::from).to_vec();
        for (flag, file) in [
            ("--model", "demo.duo"),
            ("--leader", "demo_leader_pos3d.npy"),
            ("--music", "demo_music.npy"),
            ("--follower-start", "demo_follower_start.npy"),
        ] {
            args.push(flag.into());
            args.push(s(&assets.join(file)));
        }
        if mode == "streaming" {
            args.push("--no-drain".into());
        }
        args.extend(["--out".into(), s(&out)]);
        let o = duolando(&args);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let f = read_f32_2d(&out.join("follower_pos3d.npy"), Some(165), "follower").unwrap();
        assert!(f.rows >= frames, "{who}: {} frames", f.rows);
        let (f, l) = (&f.data[..frames * 165], &leader.data[..frames * 165]);
        let want = [
            ("bas", bas::clip_score(f, &music.data, 54).unwrap()),
            ("bed", bed::duet_score(f, l).unwrap()),
            (
                "fsr",
                footskate::ratio(&[footskate::clip_counts(f).unwrap()]),
            ),
        ];
        for (m, w) in want {
            let got = v[format!("{who}_{m}")].as_f64().unwrap_or(f64::NAN);
            assert_eq!(got, w, "{who}_{m}");
        }
    }
    assert!(v.get("r_metrics_not_computed").is_none(), "{v}");
}
