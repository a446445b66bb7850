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
/// `--refresh 1` on the (not rolling) reference preset is the exact preset
/// whatever the kept K/V type.
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
                    "reference",
                    "--refresh",
                    "1",
                    "--kv",
                    "f16"
                ],
                "s1"
            ),
            "{c}: refresh 1 (not rolling) != R"
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
            "--preset live-music is a Duolando preset; a Transflower model takes exact, reference, realtime",
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
        "realtime   refresh  16 rolling (f16 kept keys/values)",
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

fn motion_fixture(name: &str) -> PathBuf {
    fixtures().join("transflower_motion").join(name)
}

/// Bone lengths of (N, J, 3) positions: |P_j - P_parent| per frame.
fn bone_lengths(pos: &[f32], parents: &[Option<usize>], frame: usize) -> Vec<f32> {
    let j = parents.len();
    let at = |k: usize| &pos[(frame * j + k) * 3..(frame * j + k) * 3 + 3];
    parents
        .iter()
        .enumerate()
        .filter_map(|(k, q)| {
            q.map(|q| {
                (0..3)
                    .map(|i| (at(k)[i] - at(q)[i]).powi(2))
                    .sum::<f32>()
                    .sqrt()
            })
        })
        .collect()
}

/// `--scaler` on the slide case (the published 69 output features, 125
/// frames): the motion outputs are written; positions.npy is the library's
/// decode of output.npy on the built-in skeleton, its bones keep the
/// table's lengths in every frame, the root height is the unscaled
/// Hips_Yposition column; the exports hold every frame; S mode's exact
/// preset writes the same positions.
#[test]
fn generate_with_scaler_writes_the_motion_on_a_skeleton() {
    use duolando::transflower_motion::{
        decode, layout::Layout, scaler::Scaler, skeleton::TfSkeleton,
    };
    let dir = tmp("motion");
    let model = convert("slide", &dir);
    let scaler = motion_fixture("hand_full/scaler.json");
    let out = dir.join("out");
    let (code, e) = generate(
        &model,
        &input_args("slide"),
        &[
            "--noise",
            &p(&case("slide").join("noise.npy")),
            "--scaler",
            &p(&scaler),
        ],
        &out,
    );
    assert_eq!(code, Some(0), "{e}");
    assert!(e.contains("motion on a skeleton"), "{e}");
    let (shape, scaled) = npy(&out.join("output.npy"));
    let n = shape[0] as usize;
    assert_eq!(n, 125);
    let skel = TfSkeleton::default();
    let (pshape, pos) = npy(&out.join("positions.npy"));
    assert_eq!(pshape, [125, 22, 3]);
    let sc = Scaler::read(&scaler).unwrap();
    let layout = Layout::new(&skel, 69).unwrap();
    let unscaled = sc.unscale(&scaled);
    let want: Vec<f32> = decode(&unscaled, &layout, &skel)
        .positions
        .iter()
        .map(|&v| v as f32)
        .collect();
    assert_eq!(pos, want, "positions.npy is the library's decode");
    let table: Vec<f32> = skel
        .offsets
        .iter()
        .skip(1)
        .map(|o| (o[0] * o[0] + o[1] * o[1] + o[2] * o[2]).sqrt() as f32)
        .collect();
    for t in [0, 1, 64, 124] {
        for (k, (a, b)) in bone_lengths(&pos, &skel.parents, t)
            .iter()
            .zip(&table)
            .enumerate()
        {
            assert!((a - b).abs() < 2e-5, "frame {t} bone {k}: {a} vs table {b}");
        }
        assert!(
            (pos[t * 66 + 1] as f64 - unscaled[t * 69 + 64]).abs() < 1e-5,
            "root height of frame {t}"
        );
    }
    let (ushape, u) = npy(&out.join("output_unscaled.npy"));
    assert_eq!(ushape, [125, 1, 69]);
    assert_eq!(u[64], unscaled[64] as f32);
    let (s24, _) = npy(&out.join("dancer_smpl24.npy"));
    assert_eq!(s24, [125, 72]);
    let (pos3d, _) = npy(&out.join("dancer_pos3d.npy"));
    assert_eq!(pos3d, [125, 165]);
    let bvh = std::fs::read_to_string(out.join("dancer.bvh")).unwrap();
    assert!(
        bvh.contains("Frames: 125") && bvh.contains("Frame Time: 0.0500000"),
        "{}",
        &bvh[bvh.find("MOTION").unwrap()..][..60]
    );
    assert!(std::fs::metadata(out.join("dancer.glb")).unwrap().len() > 1000);
    assert!(std::fs::read_to_string(out.join("index.html"))
        .unwrap()
        .contains("Transflower"));
    let summary: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("motion.json")).unwrap()).unwrap();
    assert_eq!(summary["joints"].as_array().unwrap().len(), 22);
    assert_eq!(summary["units"], "metres");
    // The same run on the hand-made skeleton: its 23 joints.
    let out2 = dir.join("out-hand");
    let extra = [
        "--noise",
        &p(&case("slide").join("noise.npy")),
        "--scaler",
        &p(&scaler),
        "--skeleton",
        &p(&motion_fixture("hand.bvh")),
    ];
    let (code, e) = generate(&model, &input_args("slide"), &extra, &out2);
    assert_eq!(code, Some(0), "{e}");
    assert_eq!(npy(&out2.join("positions.npy")).0, [125, 23, 3]);
    // S mode's exact preset (R bit for bit) writes the same motion.
    let out3 = dir.join("out-streaming");
    let noise = p(&case("slide").join("noise.npy"));
    let extra = [
        "--noise",
        &noise,
        "--mode",
        "streaming",
        "--preset",
        "exact",
        "--scaler",
        &p(&scaler),
    ];
    let (code, e) = generate(&model, &input_args("slide"), &extra, &out3);
    assert_eq!(code, Some(0), "{e}");
    assert_eq!(
        npy(&out3.join("positions.npy")).1,
        pos,
        "streaming exact positions = R's"
    );
}

/// Bad scaler and skeleton files are refused by name before anything runs
/// (no output.npy), and the flags are refused on the other families.
#[test]
fn bad_scalers_and_skeletons_are_refused_by_name() {
    let dir = tmp("motion-bad");
    let model = convert("slide", &dir);
    let noise = p(&case("slide").join("noise.npy"));
    let good = std::fs::read_to_string(motion_fixture("hand_full/scaler.json")).unwrap();
    let run = |name: &str, extra: &[&str]| {
        let out = dir.join(name);
        let mut args = vec!["--noise", noise.as_str()];
        args.extend_from_slice(extra);
        let (code, e) = generate(&model, &input_args("slide"), &args, &out);
        assert_eq!(code, Some(1), "{name}: {e}");
        assert!(
            !out.join("output.npy").exists(),
            "{name}: refused before anything is written"
        );
        e
    };
    let write = |name: &str, text: &str| {
        let f = dir.join(name);
        std::fs::write(&f, text).unwrap();
        p(&f)
    };
    // Another feature set's width (the tool's 7-column self-test).
    let e = run(
        "width",
        &["--scaler", &p(&motion_fixture("scaler_selftest.json"))],
    );
    assert!(
        e.contains("scaler_selftest.json") && e.contains("7 columns") && e.contains("has 69"),
        "{e}"
    );
    // NaN (JSON has none: the file is not a scaler file), zero scale, wrong width field.
    let nan = good.replacen("\"mean\": [\n", "\"mean\": [\n NaN,\n", 1);
    let e = run("nan", &["--scaler", &write("nan.json", &nan)]);
    assert!(
        e.contains("nan.json") && e.contains("not a scaler file"),
        "{e}"
    );
    let v: serde_json::Value = serde_json::from_str(&good).unwrap();
    let mut zero = v.clone();
    zero["scale"][5] = serde_json::json!(0.0);
    let e = run(
        "zero",
        &["--scaler", &write("zero.json", &zero.to_string())],
    );
    assert!(
        e.contains("zero.json") && e.contains("`scale`[5] = 0 is not > 0"),
        "{e}"
    );
    let mut short = v.clone();
    short["mean"].as_array_mut().unwrap().pop();
    let e = run(
        "short",
        &["--scaler", &write("short.json", &short.to_string())],
    );
    assert!(e.contains("`mean` has 68 values, `width` says 69"), "{e}");
    // Unreadable and missing files.
    let e = run("missing", &["--scaler", &p(&dir.join("nope.json"))]);
    assert!(
        e.contains("cannot read the scaler") && e.contains("nope.json"),
        "{e}"
    );
    let e = run(
        "garbage",
        &["--scaler", &write("garbage.json", "\u{1}\u{2} not json")],
    );
    assert!(
        e.contains("garbage.json") && e.contains("not a scaler file"),
        "{e}"
    );
    // A skeleton without --scaler; a BVH lacking the pipeline's joints; not a BVH.
    let e = run(
        "skel-alone",
        &["--skeleton", &p(&motion_fixture("hand.bvh"))],
    );
    assert!(e.contains("give --scaler too"), "{e}");
    let small = write("small.bvh", "HIERARCHY\nROOT Hips\n{\nOFFSET 0 0 0\nCHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation\nJOINT Spine\n{\nOFFSET 0 10 0\nCHANNELS 3 Zrotation Xrotation Yrotation\nEnd Site\n{\nOFFSET 0 10 0\n}\n}\n}\nMOTION\nFrames: 0\nFrame Time: 0.05\n");
    let e = run(
        "skel-small",
        &[
            "--scaler",
            &p(&motion_fixture("hand_full/scaler.json")),
            "--skeleton",
            &small,
        ],
    );
    assert!(
        e.contains("small.bvh") && e.contains("lacks 19 of the 20 joints"),
        "{e}"
    );
    let e = run(
        "skel-bad",
        &[
            "--scaler",
            &p(&motion_fixture("hand_full/scaler.json")),
            "--skeleton",
            &write("bad.bvh", "HIERARCHY\nROOT\n"),
        ],
    );
    assert!(e.contains("bad.bvh"), "{e}");
    // A model whose output fits no skeleton (the tiny paper case: 11 features).
    let paper = convert("paper", &dir);
    let mut w11 = v.clone();
    w11["width"] = serde_json::json!(11);
    w11["mean"] = serde_json::json!(vec![0.0; 11]);
    w11["scale"] = serde_json::json!(vec![1.0; 11]);
    let out = dir.join("w11");
    let (code, e) = generate(
        &paper,
        &input_args("paper"),
        &["--scaler", &write("w11.json", &w11.to_string())],
        &out,
    );
    assert_eq!(code, Some(1));
    assert!(
        e.contains("11 features per frame do not fit") && e.contains("expmap_scaled_20"),
        "{e}"
    );
    assert!(!out.join("output.npy").exists());
    // Transflower's flags on a Duolando model.
    let (code, e) = generate(
        &fixtures().join("tiny/model.duo"),
        &[],
        &["--scaler", &p(&motion_fixture("hand_full/scaler.json"))],
        &dir.join("duo"),
    );
    assert_eq!(code, Some(1));
    assert!(e.contains("--scaler is for Transflower models"), "{e}");
}
