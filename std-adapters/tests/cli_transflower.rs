//! Transflower through the `duolando` binary: `convert` (hparams.yaml +
//! state dict), `generate --mode exact` with the recorded base samples
//! replayed (`--noise`) equals the goldens of the authors' classes, the
//! seeded sampler is deterministic, `inspect` shows the config; bad inputs
//! and flags of the other families fail with messages naming them.

use std::path::{Path, PathBuf};
use std::process::Command;

use duolando::npy::{read_f32_2d, write_f32};

fn fixtures() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/fixtures")
}

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("duo-cli-tf-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// (exit code, stdout, stderr).
fn duolando(args: &[&str]) -> (Option<i32>, String, String) {
    let o = Command::new(env!("CARGO_BIN_EXE_duolando"))
        .args(args)
        .output()
        .unwrap();
    (
        o.status.code(),
        String::from_utf8_lossy(&o.stdout).into_owned(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    )
}

fn p(path: &Path) -> String {
    path.to_str().unwrap().to_string()
}

fn case(c: &str) -> PathBuf {
    fixtures().join(format!("transflower_{c}"))
}

/// `duolando convert` of a fixture case into `dir`/model.duo.
fn convert(c: &str, dir: &Path) -> PathBuf {
    let out = dir.join(format!("{c}.duo"));
    let (code, stdout, e) = duolando(&[
        "convert",
        "--config",
        &p(&case(c).join("hparams.yaml")),
        "--weights",
        &p(&case(c).join("model.safetensors")),
        "-o",
        &p(&out),
    ]);
    assert_eq!(code, Some(0), "{e}");
    assert!(
        stdout.contains("Transflower") && stdout.contains("is_initialized"),
        "{stdout}"
    );
    out
}

/// `--input MOD=FILE` for every input file of a case (in_<mod>.npy).
fn input_args(c: &str) -> Vec<String> {
    let mut v = Vec::new();
    let mut names: Vec<String> = std::fs::read_dir(case(c))
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .filter(|n| n.starts_with("in_"))
        .collect();
    names.sort();
    for n in names {
        let m = n.trim_start_matches("in_").trim_end_matches(".npy");
        v.push("--input".into());
        v.push(format!("{m}={}", p(&case(c).join(&n))));
    }
    v
}

fn generate(model: &Path, inputs: &[String], extra: &[&str], out: &Path) -> (Option<i32>, String) {
    let mut args: Vec<String> = vec!["generate".into(), "--model".into(), p(model)];
    args.extend(inputs.iter().cloned());
    args.extend(extra.iter().map(|s| s.to_string()));
    args.extend(["--out".into(), p(out)]);
    let (code, _, e) = duolando(&args.iter().map(String::as_str).collect::<Vec<_>>());
    (code, e)
}

/// (shape, values) of a float32 .npy.
fn npy(path: &Path) -> (Vec<u64>, Vec<f32>) {
    let bytes = std::fs::read(path).unwrap();
    let f = npyz::NpyFile::new(bytes.as_slice()).unwrap();
    (f.shape().to_vec(), f.into_vec::<f32>().unwrap())
}

/// The paper, label (a style label, Student-t base) and slide (published
/// windows, 125 frames) cases: output.npy is the golden (N, 1, C), within
/// 4 x the reference's own float32-vs-float64 difference.
#[test]
fn generate_with_recorded_noise_matches_the_goldens() {
    let dir = tmp("golden");
    for c in ["paper", "label", "slide"] {
        let model = convert(c, &dir);
        let out = dir.join(format!("{c}-out"));
        let (code, e) = generate(
            &model,
            &input_args(c),
            &["--noise", &p(&case(c).join("noise.npy")), "--mode", "exact"],
            &out,
        );
        assert_eq!(code, Some(0), "{c}: {e}");
        assert!(e.contains("replayed"), "{e}");
        let (shape, got) = npy(&out.join("output.npy"));
        let (want_shape, want) = npy(&case(c).join("output.npy"));
        assert_eq!(shape, want_shape, "{c}");
        let meta: serde_json::Value =
            serde_json::from_slice(&std::fs::read(case(c).join("meta.json")).unwrap()).unwrap();
        let tol = 4.0
            * meta["f32_vs_f64_output_max_rel_err_per_step"]
                .as_array()
                .unwrap()
                .iter()
                .map(|v| v.as_f64().unwrap() as f32)
                .fold(0.0, f32::max);
        let scale = want.iter().fold(1f32, |m, v| m.max(v.abs()));
        let err = got
            .iter()
            .zip(&want)
            .map(|(a, b)| (a - b).abs())
            .fold(0f32, f32::max)
            / scale;
        assert!(err <= tol, "{c}: rel err {err:e} > {tol:e}");
    }
}

/// `--mode streaming`: the exact preset is R bit for bit (noise replayed,
/// and seeded); the stale-rows presets give as many finite frames, not R's;
/// `--refresh 1` is the exact preset whatever the preset's other settings.
#[test]
fn streaming_exact_preset_is_r() {
    let dir = tmp("stream");
    for c in ["label", "slide"] {
        let model = convert(c, &dir);
        let run = |extra: &[&str], name: &str| {
            let out = dir.join(format!("{c}-{name}"));
            let (code, e) = generate(&model, &input_args(c), extra, &out);
            assert_eq!(code, Some(0), "{c} {extra:?}: {e}");
            std::fs::read(out.join("output.npy")).unwrap()
        };
        let noise = p(&case(c).join("noise.npy"));
        let r = run(&["--noise", &noise], "r");
        assert!(
            r == run(
                &[
                    "--noise",
                    &noise,
                    "--mode",
                    "streaming",
                    "--preset",
                    "exact"
                ],
                "s"
            ),
            "{c}: streaming exact != R"
        );
        assert!(
            r == run(
                &[
                    "--noise",
                    &noise,
                    "--mode",
                    "streaming",
                    "--preset",
                    "realtime",
                    "--refresh",
                    "1",
                    "--kv",
                    "f16"
                ],
                "s1"
            ),
            "{c}: refresh 1 != R"
        );
        assert!(
            run(&["--seed", "3"], "r3")
                == run(
                    &["--seed", "3", "--mode", "streaming", "--preset", "exact"],
                    "s3"
                ),
            "{c}: seeded streaming exact != R"
        );
        for preset in ["reference", "realtime"] {
            let out = dir.join(format!("{c}-{preset}"));
            let (code, e) = generate(
                &model,
                &input_args(c),
                &["--noise", &noise, "--mode", "streaming", "--preset", preset],
                &out,
            );
            assert_eq!(code, Some(0), "{e}");
            assert!(e.contains(&format!("preset {preset}")), "{e}");
            let (shape, v) = npy(&out.join("output.npy"));
            let (want_shape, _) = npy(&case(c).join("output.npy"));
            assert_eq!(shape, want_shape);
            assert!(v.iter().all(|x| x.is_finite()));
        }
    }
}

/// `--seed`: the same seed, the same frames; another seed, others; no
/// seed = seed 0.
#[test]
fn seeded_generation_is_deterministic() {
    let dir = tmp("seed");
    let model = convert("label", &dir);
    let run = |extra: &[&str], name: &str| {
        let out = dir.join(name);
        let (code, e) = generate(&model, &input_args("label"), extra, &out);
        assert_eq!(code, Some(0), "{e}");
        npy(&out.join("output.npy")).1
    };
    let (a, b, c, d) = (
        run(&["--seed", "7"], "a"),
        run(&["--seed", "7"], "b"),
        run(&["--seed", "8"], "c"),
        run(&[], "d"),
    );
    assert!(a == b);
    assert!(a != c);
    assert!(d == run(&["--seed", "0"], "e"));
    assert!(a.iter().all(|v| v.is_finite()));
}

/// Bad inputs and other families' flags: a named error, exit 1, nothing written.
#[test]
fn bad_inputs_are_refused_by_name() {
    let dir = tmp("bad");
    let model = convert("paper", &dir);
    let c = case("paper");
    let motion = format!("expmap_scaled_20={}", p(&c.join("in_expmap_scaled_20.npy")));
    let audio = format!(
        "audio_feats_scaled_20={}",
        p(&c.join("in_audio_feats_scaled_20.npy"))
    );
    let noise = p(&c.join("noise.npy"));
    let a = read_f32_2d(&c.join("in_audio_feats_scaled_20.npy"), Some(7), "audio").unwrap();
    let m = read_f32_2d(&c.join("in_expmap_scaled_20.npy"), Some(11), "motion").unwrap();
    let short_audio = dir.join("short_audio.npy");
    write_f32(&short_audio, &a.data[..13 * 7], &[13, 7]).unwrap();
    let short_motion = dir.join("short_motion.npy");
    write_f32(&short_motion, &m.data[..11 * 11], &[11, 11]).unwrap();
    let nan = dir.join("nan_audio.npy");
    let mut v = a.data.clone();
    v[3 * 7 + 2] = f32::NAN;
    write_f32(&nan, &v, &[a.rows, 7]).unwrap();
    let wide = dir.join("wide_audio.npy");
    write_f32(&wide, &vec![0.5; a.rows * 8], &[a.rows, 8]).unwrap();
    let cases: Vec<(Vec<String>, &str)> = vec![
        (
            vec!["--input".into(), motion.clone()],
            "input modality `audio_feats_scaled_20` is missing",
        ),
        (
            vec![
                "--input".into(),
                motion.clone(),
                "--input".into(),
                audio.clone(),
                "--input".into(),
                format!("music={}", p(&wide)),
            ],
            "no input modality `music`",
        ),
        (
            vec![
                "--input".into(),
                motion.clone(),
                "--input".into(),
                format!("audio_feats_scaled_20={}", p(&wide)),
            ],
            "with 7 columns per row",
        ),
        (
            vec![
                "--input".into(),
                motion.clone(),
                "--input".into(),
                format!("audio_feats_scaled_20={}", p(&short_audio)),
            ],
            "has 13 rows, at least 14",
        ),
        (
            vec![
                "--input".into(),
                format!("expmap_scaled_20={}", p(&short_motion)),
                "--input".into(),
                audio.clone(),
            ],
            "motion seed `expmap_scaled_20` has 11 rows",
        ),
        (
            vec![
                "--input".into(),
                motion.clone(),
                "--input".into(),
                format!("audio_feats_scaled_20={}", p(&nan)),
            ],
            "at row 3, column 2",
        ),
        (
            vec![
                "--input".into(),
                motion.clone(),
                "--input".into(),
                audio.clone(),
                "--noise".into(),
                p(&c.join("output.npy")),
            ],
            "base samples of shape",
        ),
        (
            vec![
                "--input".into(),
                motion.clone(),
                "--input".into(),
                audio.clone(),
                "--leader".into(),
                noise.clone(),
            ],
            "--leader does not apply",
        ),
        (
            vec![
                "--input".into(),
                motion.clone(),
                "--input".into(),
                audio.clone(),
                "--music".into(),
                noise.clone(),
            ],
            "--music does not apply",
        ),
        (
            vec![
                "--input".into(),
                motion.clone(),
                "--input".into(),
                audio.clone(),
                "--seed-tokens".into(),
                "1,2".into(),
            ],
            "--seed-tokens does not apply",
        ),
        (
            vec![
                "--input".into(),
                motion.clone(),
                "--input".into(),
                audio.clone(),
                "--mode".into(),
                "streaming".into(),
                "--preset".into(),
                "live-music".into(),
            ],
            "--preset live-music is another family's preset; a Transflower model takes exact, reference, realtime",
        ),
        (
            vec![
                "--input".into(),
                motion.clone(),
                "--input".into(),
                audio.clone(),
                "--lookahead".into(),
                "3".into(),
            ],
            "--lookahead is a Duolando / Bailando setting",
        ),
        (
            vec![
                "--input".into(),
                motion.clone(),
                "--input".into(),
                audio.clone(),
                "--refresh".into(),
                "3".into(),
            ],
            "--preset, --refresh and --kv set a streaming session",
        ),
        (
            vec![
                "--input".into(),
                motion.clone(),
                "--input".into(),
                audio.clone(),
                "--mode".into(),
                "streaming".into(),
                "--refresh".into(),
                "0".into(),
            ],
            "--refresh 0 is outside its range",
        ),
    ];
    for (i, (args, words)) in cases.iter().enumerate() {
        let out = dir.join(format!("out{i}"));
        let (code, e) = generate(&model, args, &[], &out);
        assert_eq!(code, Some(1), "{words}: {e}");
        assert!(e.contains(words), "expected {words:?} in: {e}");
        assert!(
            !out.join("output.npy").exists(),
            "{words}: an output was written"
        );
    }
    // A style label outside the model's labels.
    let label_model = convert("label", &dir);
    let lc = case("label");
    let args: Vec<String> = vec![
        "--input".into(),
        "dance_style=7".into(),
        "--input".into(),
        format!(
            "expmap_cr_scaled_20={}",
            p(&lc.join("in_expmap_cr_scaled_20.npy"))
        ),
        "--input".into(),
        format!(
            "audio_feats_scaled_20={}",
            p(&lc.join("in_audio_feats_scaled_20.npy"))
        ),
    ];
    let (code, e) = generate(&label_model, &args, &[], &dir.join("label-bad"));
    assert_eq!(code, Some(1));
    assert!(e.contains("style label 7") && e.contains("0..5"), "{e}");
    // Transflower's flags on a Duolando model.
    let (code, e) = generate(
        &fixtures().join("tiny/model.duo"),
        &["--input".into(), motion],
        &[],
        &dir.join("duo"),
    );
    assert_eq!(code, Some(1));
    assert!(e.contains("--input is for Transflower models"), "{e}");
}

/// `convert` refuses the other families' flags and what the engine does
/// not implement, by name.
#[test]
fn convert_refusals_are_named() {
    let dir = tmp("convert");
    let c = case("paper");
    let (hp, w) = (p(&c.join("hparams.yaml")), p(&c.join("model.safetensors")));
    let out = p(&dir.join("m.duo"));
    let (code, _, e) = duolando(&[
        "convert",
        "--config",
        &hp,
        "--weights",
        &w,
        "--gpt",
        &w,
        "-o",
        &out,
    ]);
    assert_eq!(code, Some(1));
    assert!(e.contains("drop --gpt"), "{e}");
    let (code, _, e) = duolando(&["convert", "--config", &hp, "-o", &out]);
    assert_eq!(code, Some(1));
    assert!(e.contains("--weights") && e.contains("required"), "{e}");
    let b = fixtures().join("bailando_btiny");
    let (code, _, e) = duolando(&[
        "convert",
        "--config",
        &p(&b.join("actor_critic.yaml")),
        "--weights",
        &w,
        "-o",
        &out,
    ]);
    assert_eq!(code, Some(1));
    assert!(
        e.contains("--weights is for Transflower") && e.contains("Bailando"),
        "{e}"
    );
    let residual = dir.join("hparams.yaml");
    std::fs::write(
        &residual,
        std::fs::read_to_string(c.join("hparams.yaml"))
            .unwrap()
            .replace("residual: false", "residual: true"),
    )
    .unwrap();
    let (code, _, e) = duolando(&[
        "convert",
        "--config",
        &p(&residual),
        "--weights",
        &w,
        "-o",
        &out,
    ]);
    assert_eq!(code, Some(1));
    assert!(e.contains("`residual: True`"), "{e}");
    assert!(!dir.join("m.duo").exists());
}

/// `inspect` shows a Transflower file's config and sizes (text and JSON).
#[test]
fn inspect_shows_the_config() {
    let model = fixtures().join("transflower_paper/model.duo");
    let (code, text, e) = duolando(&["inspect", &p(&model)]);
    assert_eq!(code, Some(0), "{e}");
    for words in [
        "Transflower model",
        "input expmap_scaled_20",
        "motion (output, fed back)",
        "audio_feats_scaled_20",
        "flow 3 steps, norm batchnorm",
        "216 tensors",
        "streaming (S)",
        "realtime   refresh  16 (f16 kept keys/values)",
    ] {
        assert!(text.contains(words), "{words:?} not in:\n{text}");
    }
    let (code, json, e) = duolando(&["inspect", &p(&model), "--json", "--frames", "20"]);
    assert_eq!(code, Some(0), "{e}");
    let v: serde_json::Value = serde_json::from_str(&json).unwrap();
    assert_eq!(v["family"], "Transflower");
    assert_eq!(v["format_version"], 2);
    assert_eq!(v["config"]["input_modalities"][1]["dim"], 7);
    assert_eq!(v["config"]["douts"], 11);
    assert_eq!(v["r_mode"]["requested"]["output_frames"], 20 - 14 + 1);
    assert!(v["r_mode"]["one_minute"]["scratch_bytes"].as_u64().unwrap() > 0);
    // Each session preset's arena is the library's figure.
    let presets = v["streaming"]["presets"].as_array().unwrap();
    assert_eq!(presets.len(), 3);
    assert_eq!(presets[0]["name"], "exact");
    assert_eq!(presets[0]["refresh"], 1);
    assert!(
        presets[2]["arena_bytes"].as_u64().unwrap() > presets[0]["arena_bytes"].as_u64().unwrap()
    );
}
