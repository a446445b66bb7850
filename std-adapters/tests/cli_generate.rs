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
    Command::new(env!("CARGO_BIN_EXE_duolando"))
        .args(args)
        .output()
        .unwrap()
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
    let err = got
        .data
        .iter()
        .zip(&want.data)
        .map(|(a, b)| (a - b).abs())
        .fold(0f32, f32::max);
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
        &[
            "generate",
            "--model",
            p(&model),
            "--leader",
            p(&roll.join("music.npy")),
            "--music",
            p(&roll.join("music.npy")),
            "--seed-tokens",
            "1,2,3,4,5",
            "--out",
            p(&dir),
        ],
        &["music.npy", "165 columns"],
    );
    // Missing file.
    expect_failure(
        &[
            "generate",
            "--model",
            p(&model),
            "--leader",
            p(&dir.join("nope.npy")),
            "--music",
            p(&roll.join("music.npy")),
            "--seed-tokens",
            "1,2,3,4,5",
            "--out",
            p(&dir),
        ],
        &["nope.npy"],
    );
    // Malformed and out-of-vocabulary seed tokens.
    expect_failure(
        &[
            "generate",
            "--model",
            p(&model),
            "--leader",
            p(&roll.join("leader_pos3d.npy")),
            "--music",
            p(&roll.join("music.npy")),
            "--seed-tokens",
            "1,2,x,4,5",
            "--out",
            p(&dir),
        ],
        &["'x'"],
    );
    expect_failure(
        &[
            "generate",
            "--model",
            p(&model),
            "--leader",
            p(&roll.join("leader_pos3d.npy")),
            "--music",
            p(&roll.join("music.npy")),
            "--seed-tokens",
            "1,2,3,4,100000",
            "--out",
            p(&dir),
        ],
        &["vocabulary"],
    );
    // Music shorter than the leader.
    let short = dir.join("short_music.npy");
    write_f32(&short, &vec![0.0; 8 * 54], &[8, 54]).unwrap();
    expect_failure(
        &[
            "generate",
            "--model",
            p(&model),
            "--leader",
            p(&roll.join("leader_pos3d.npy")),
            "--music",
            p(&short),
            "--seed-tokens",
            "1,2,3,4,5",
            "--out",
            p(&dir),
        ],
        &["short_music.npy", "music frames"],
    );
    // NaN in the leader.
    let leader = read_f32_2d(&roll.join("leader_pos3d.npy"), Some(165), "l").unwrap();
    let mut data = leader.data.clone();
    data[1000] = f32::NAN;
    let nan = dir.join("nan_leader.npy");
    write_f32(&nan, &data, &[leader.rows, 165]).unwrap();
    expect_failure(
        &[
            "generate",
            "--model",
            p(&model),
            "--leader",
            p(&nan),
            "--music",
            p(&roll.join("music.npy")),
            "--seed-tokens",
            "1,2,3,4,5",
            "--out",
            p(&dir),
        ],
        &["NaN"],
    );
    // Not a model.
    expect_failure(
        &[
            "generate",
            "--model",
            p(&roll.join("music.npy")),
            "--leader",
            p(&roll.join("leader_pos3d.npy")),
            "--music",
            p(&roll.join("music.npy")),
            "--seed-tokens",
            "1,2,3,4,5",
            "--out",
            p(&dir),
        ],
        &["music.npy"],
    );
}

/// Every preset of the one list (`Preset::ALL`, what `duolando inspect`
/// lists) is accepted by every command that takes `--preset` (generate in
/// streaming mode, compare); a name outside the list is refused naming it.
#[test]
fn every_listed_preset_is_accepted_by_every_command() {
    let fx = fixtures();
    let roll = fx.join("rollout_tiny_short");
    let seed = read_i64_2d(&roll.join("seed_tokens.npy"), Some(5), "seed").unwrap();
    let seed: Vec<String> = seed.data.iter().map(|t| t.to_string()).collect();
    let seed = seed.join(",");
    let model = fx.join("tiny/model.duo");
    let o = duolando(&["inspect", p(&model), "--json"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let listed: Vec<String> = v["streaming"]["budgets"]
        .as_array()
        .unwrap()
        .iter()
        .map(|b| b["budget"].as_str().unwrap().to_string())
        .collect();
    let core: Vec<&str> = duolando_core::duolando::session::Preset::ALL
        .iter()
        .map(|p| p.name())
        .collect();
    assert_eq!(listed, core);
    assert!(listed.iter().any(|n| n == "interactive") && listed.iter().any(|n| n == "live-music"));
    let (leader, music) = (roll.join("leader_pos3d.npy"), roll.join("music.npy"));
    for name in &listed {
        let out = tmp(&format!("preset-{name}"));
        let common = [
            "--model",
            p(&model),
            "--leader",
            p(&leader),
            "--music",
            p(&music),
            "--seed-tokens",
            &seed,
            "--preset",
            name,
        ];
        let mut args = vec!["generate", "--mode", "streaming", "--out", p(&out)];
        args.extend_from_slice(&common);
        let o = duolando(&args);
        assert!(
            o.status.success(),
            "generate --preset {name}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
        let mut args = vec!["compare"];
        args.extend_from_slice(&common);
        let o = duolando(&args);
        assert!(
            o.status.success(),
            "compare --preset {name}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
    }
    let out = tmp("preset-bad");
    let o = duolando(&[
        "generate",
        "--mode",
        "streaming",
        "--model",
        p(&model),
        "--leader",
        p(&roll.join("leader_pos3d.npy")),
        "--music",
        p(&roll.join("music.npy")),
        "--seed-tokens",
        &seed,
        "--preset",
        "fastest",
        "--out",
        p(&out),
    ]);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("fastest") && err.contains("live-music"),
        "{err}"
    );
}

/// `generate --mode streaming` drains by default: as many frames and
/// token rows as R on the same clip (rollout_tiny_long: K = 120, 484
/// frames) wherever the music look-ahead is R's; without the drain, the frames a session that never learns the
/// end gives, which are the first frames of the drained run.
#[test]
fn generate_streaming_drains_to_r_frame_count() {
    let fx = fixtures();
    let roll = fx.join("rollout_tiny_long");
    let model = fx.join("tiny/model.duo");
    let (leader, music, start) = (
        roll.join("leader_pos3d.npy"),
        roll.join("music.npy"),
        roll.join("follower_start.npy"),
    );
    let run = |extra: &[&str], name: &str| {
        let out = tmp(name);
        let mut args = vec![
            "generate",
            "--mode",
            "streaming",
            "--model",
            p(&model),
            "--leader",
            p(&leader),
            "--music",
            p(&music),
            "--follower-start",
            p(&start),
            "--out",
            p(&out),
        ];
        args.extend_from_slice(extra);
        let o = duolando(&args);
        assert!(
            o.status.success(),
            "{name}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
        let pos = read_f32_2d(&out.join("follower_pos3d.npy"), Some(165), "pos").unwrap();
        let tok = read_i64_2d(&out.join("tokens.npy"), Some(5), "tokens").unwrap();
        (pos, tok)
    };
    let want = read_f32_2d(&roll.join("follower_pos3d.npy"), Some(165), "pos").unwrap();
    let want_tok = read_i64_2d(&roll.join("tokens.npy"), Some(5), "tokens").unwrap();
    for preset in ["reference", "interactive", "live-music", "minimum"] {
        let (pos, tok) = run(&["--preset", preset], &format!("drain-{preset}"));
        let (pos0, tok0) = run(
            &["--preset", preset, "--no-drain"],
            &format!("nodrain-{preset}"),
        );
        eprintln!(
            "{preset}: drained {} frames / {} token rows, without drain {} / {}; R {} / {}",
            pos.rows, tok.rows, pos0.rows, tok0.rows, want.rows, want_tok.rows
        );
        // live-music (music look-ahead 0 < look_forward) already streamed more
        // steps than R's K (K_S = Q - a - e = 150 - 6 = 144): the drain keeps
        // them and decodes their tail, 4 (144 + 1) frames; every other preset
        // ends on R's count.
        let expect = if preset == "live-music" {
            (580, 145)
        } else {
            (want.rows, want_tok.rows)
        };
        assert_eq!(
            (pos.rows, tok.rows),
            expect,
            "{preset}: drained run vs R ({} frames)",
            want.rows
        );
        assert!(pos0.rows <= pos.rows && tok0.rows <= tok.rows);
        assert_eq!(
            &tok.data[..tok0.data.len()],
            &tok0.data[..],
            "{preset}: the drain changed streamed tokens"
        );
        assert_eq!(
            &pos.data[..pos0.data.len()],
            &pos0.data[..],
            "{preset}: the drain changed streamed frames"
        );
        if preset == "reference" {
            assert!(
                pos0.rows < pos.rows,
                "the reference budget loses its tail without the drain"
            );
        }
    }
}

/// A Bailando model through the binary: both of the authors' eval paths
/// give the golden tokens and positions (AIST++ with --dance, demo with
/// --seed-tokens), and the Duolando-only inputs are refused by name.
#[test]
fn generate_bailando_matches_the_goldens_on_both_paths() {
    let fx = fixtures();
    let model = fx.join("bailando_btiny/model.duo");
    for (name, path_args) in [("btiny_aist_slide", "dance"), ("btiny_demo_odd", "seed")] {
        let roll = fx.join(format!("bailando_rollout_{name}"));
        let meta: serde_json::Value =
            serde_json::from_slice(&std::fs::read(roll.join("meta.json")).unwrap()).unwrap();
        let out = tmp(name);
        let seed = format!("{},{}", meta["seed_tokens"][0], meta["seed_tokens"][1]);
        let music = roll.join("music.npy");
        // R, and S at its exact preset (the same numbers).
        for mode in [
            &["--mode", "exact"][..],
            &["--mode", "streaming", "--preset", "exact"][..],
        ] {
            let mut args = vec![
                "generate",
                "--model",
                p(&model),
                "--music",
                p(&music),
                "--out",
                p(&out),
            ];
            args.extend(mode.iter().copied());
            let dance = roll.join("dance.npy");
            if path_args == "dance" {
                args.extend(["--dance", p(&dance)]);
            } else {
                args.extend(["--seed-tokens", &seed]);
            }
            let o = duolando(&args);
            assert!(
                o.status.success(),
                "{name} {mode:?}: {}",
                String::from_utf8_lossy(&o.stderr)
            );
            let got = read_i64_2d(&out.join("tokens.npy"), Some(2), "tokens").unwrap();
            let want = read_i64_2d(&roll.join("tokens.npy"), Some(2), "tokens").unwrap();
            assert_eq!(got.data, want.data, "{name} {mode:?}: tokens");
            let got = read_f32_2d(&out.join("pos3d.npy"), Some(72), "pos3d").unwrap();
            let want = read_f32_2d(&roll.join("pos3d.npy"), Some(72), "pos3d").unwrap();
            assert_eq!(got.rows, want.rows, "{name} {mode:?}: frames");
            let err = got
                .data
                .iter()
                .zip(&want.data)
                .map(|(a, b)| (a - b).abs())
                .fold(0f32, f32::max);
            assert!(
                err <= 1e-5,
                "{name} {mode:?}: positions max abs err {err:e}"
            );
        }
    }
    let roll = fx.join("bailando_rollout_btiny_demo_odd");
    let music = roll.join("music.npy");
    let out = tmp("bailando-bad");
    for (args, want) in [
        (vec!["--seed-tokens", "1,2,3,4,5"], "two tokens"),
        (vec!["--seed-tokens", "1,99"], "outside its vocabulary"),
        (
            vec!["--leader", p(&music), "--seed-tokens", "1,2"],
            "takes no leader",
        ),
        (vec![], "give --dance"),
        (
            vec![
                "--seed-tokens",
                "1,2",
                "--mode",
                "streaming",
                "--preset",
                "live-music",
            ],
            "live-music is a Duolando preset; a Bailando model takes",
        ),
        (
            vec![
                "--seed-tokens",
                "1,2",
                "--mode",
                "streaming",
                "--lookahead",
                "2",
            ],
            "--lookahead is a Duolando setting",
        ),
        (
            vec![
                "--seed-tokens",
                "1,2",
                "--mode",
                "streaming",
                "--shift",
                "99",
            ],
            "--shift 99 is outside its range",
        ),
    ] {
        let mut a = vec![
            "generate",
            "--model",
            p(&model),
            "--music",
            p(&music),
            "--out",
            p(&out),
        ];
        a.extend(args.iter().copied());
        let o = duolando(&a);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(1), "{args:?}: {err}");
        assert!(err.contains(want), "{args:?}: {err}");
    }
    // Music narrower than the model reads.
    let narrow = out.join("narrow.npy");
    write_f32(&narrow, &[0.0; 20], &[2, 10]).unwrap();
    let o = duolando(&[
        "generate",
        "--model",
        p(&fx.join("bailando_btiny/model.duo")),
        "--music",
        p(&narrow),
        "--seed-tokens",
        "1,2",
        "--out",
        p(&out),
    ]);
    assert!(
        String::from_utf8_lossy(&o.stderr).contains("the model reads 438"),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    // A Duolando model given --dance, or no --leader.
    let o = duolando(&[
        "generate",
        "--model",
        p(&fx.join("tiny/model.duo")),
        "--music",
        p(&roll.join("music.npy")),
        "--dance",
        p(&roll.join("music.npy")),
        "--out",
        p(&out),
    ]);
    assert!(
        String::from_utf8_lossy(&o.stderr).contains("--dance is for Bailando"),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let o = duolando(&[
        "generate",
        "--model",
        p(&fx.join("tiny/model.duo")),
        "--music",
        p(&roll.join("music.npy")),
        "--seed-tokens",
        "1,2,3,4,5",
        "--out",
        p(&out),
    ]);
    assert!(
        String::from_utf8_lossy(&o.stderr).contains("--leader"),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
}

#[test]
fn exact_mode_refuses_streaming_flags_by_name_instead_of_ignoring_them() {
    // `generate --mode exact --topk 3` used to run greedy R and say nothing.
    let fx = fixtures();
    let roll = fx.join("rollout_tiny_short");
    let out = tmp("exact-flags");
    let duo_model = fx.join("tiny/model.duo");
    let (leader, music) = (roll.join("leader_pos3d.npy"), roll.join("music.npy"));
    let duo_base = [
        "generate",
        "--model",
        p(&duo_model),
        "--leader",
        p(&leader),
        "--music",
        p(&music),
        "--seed-tokens",
        "1,2,3,4,5",
        "--out",
        p(&out),
    ];
    let broll = fx.join("bailando_rollout_btiny_demo_odd");
    let solo_model = fx.join("bailando_btiny/model.duo");
    let solo_music = broll.join("music.npy");
    let solo_base = [
        "generate",
        "--model",
        p(&solo_model),
        "--music",
        p(&solo_music),
        "--seed-tokens",
        "1,2",
        "--out",
        p(&out),
    ];
    for base in [&duo_base[..], &solo_base[..]] {
        for (flags, named) in [
            (&["--topk", "3"][..], "--topk"),
            (&["--temperature", "0.8"][..], "--temperature"),
            (&["--rng-seed", "7"][..], "--rng-seed"),
            (&["--preset", "minimum"][..], "--preset"),
            (&["--shift", "4"][..], "--shift"),
            (&["--spread"][..], "--spread"),
            (&["--reprefill"][..], "--reprefill"),
            (&["--kv", "f16"][..], "--kv"),
        ] {
            let mut args = base.to_vec();
            args.extend(["--mode", "exact"]);
            args.extend(flags);
            expect_failure(&args, &[named, "--mode streaming"]);
        }
    }
    let mut args = duo_base.to_vec();
    args.push("--no-drain");
    expect_failure(&args, &["--no-drain", "--mode streaming"]);
    // Without them, exact mode runs (the default mode too).
    let o = duolando(&duo_base);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}

/// The presets keep the GPT cache with the spread schedule; `--reprefill`
/// (one cache, re-filled at each window jump) and `--spread` write the same
/// files, for a Duolando and a Bailando model, and `--reprefill` with
/// another schedule flag is refused.
#[test]
fn reprefill_and_the_presets_spread_schedule_write_the_same_files() {
    let fx = fixtures();
    let roll = fx.join("rollout_tiny_long");
    let broll = fx.join("bailando_rollout_btiny_demo_odd");
    let (model, leader, music, start) = (
        fx.join("tiny/model.duo"),
        roll.join("leader_pos3d.npy"),
        roll.join("music.npy"),
        roll.join("follower_start.npy"),
    );
    let (solo_model, solo_music) = (fx.join("bailando_btiny/model.duo"), broll.join("music.npy"));
    let cases: [(&str, Vec<&str>, &str, usize); 2] = [
        (
            "duo",
            vec![
                "--model",
                p(&model),
                "--leader",
                p(&leader),
                "--music",
                p(&music),
                "--follower-start",
                p(&start),
                "--shift",
                "4",
            ],
            "follower_pos3d.npy",
            165,
        ),
        (
            "solo",
            vec![
                "--model",
                p(&solo_model),
                "--music",
                p(&solo_music),
                "--seed-tokens",
                "1,2",
                "--shift",
                "3",
            ],
            "pos3d.npy",
            72,
        ),
    ];
    for (name, base, pos, width) in cases {
        let mut outs = Vec::new();
        for flag in [None, Some("--spread"), Some("--reprefill")] {
            let out = tmp(&format!(
                "sched-{name}-{}",
                flag.unwrap_or("preset").trim_start_matches('-')
            ));
            let mut args = vec!["generate", "--mode", "streaming", "--out", p(&out)];
            args.extend(&base);
            args.extend(flag);
            let o = duolando(&args);
            assert!(
                o.status.success(),
                "{name} {flag:?}: {}",
                String::from_utf8_lossy(&o.stderr)
            );
            let toks = std::fs::read(out.join("tokens.npy")).unwrap();
            let frames = read_f32_2d(&out.join(pos), Some(width), "pos").unwrap();
            assert!(frames.rows > 0, "{name} {flag:?}: no frames");
            outs.push((
                toks,
                frames.data.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
            ));
        }
        assert_eq!(
            outs[0], outs[1],
            "{name}: the presets' schedule is not --spread's"
        );
        assert_eq!(
            outs[0], outs[2],
            "{name}: --reprefill gives other tokens or frames"
        );
        let out = tmp(&format!("sched-{name}-both"));
        let mut args = vec!["generate", "--mode", "streaming", "--out", p(&out)];
        args.extend(&base);
        args.extend(["--reprefill", "--spread"]);
        expect_failure(&args, &["--reprefill", "--spread"]);
    }
}
