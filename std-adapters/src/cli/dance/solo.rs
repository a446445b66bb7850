//! `duolando dance --music SONG` without a leader: a solo dancer (a
//! Bailando model, by default the bundled `assets/bailando_demo.duo`) to a
//! song. R mode on the authors' music-only path (the music padded to whole
//! tokens, the seed tokens given; with `--topk K` a streaming session at
//! the reference preset that samples each token among the K most probable),
//! then the same outputs as the duet:
//! `index.html` (one dancer, with the audio), `dancer.glb`, `dancer.bvh`,
//! npy arrays and `summary.json`, at the model's 60 fps. Bailando's SMPL
//! 24 joints are shown and exported on the SMPL-X rig
//! (`skeleton::smpl24`); `dancer_smpl24.npy` holds the model's own joints.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, Context, Result};
use duolando_core::bailando::config::{FPS, POSE_DIM};
use duolando_core::bailando::exact::MusicPadding;
use duolando_core::bailando::model::Model;
use serde_json::json;

use super::inputs::{check_finite, extension};
use crate::cli::generate_solo::{exact_rows, parse_seed, streaming_rows};
use duolando_core::bailando::session::{Preset as SoloPreset, SessionConfig as SoloConfig};
use duolando_core::nn::sampler::Sampling;
use crate::export::{write_dancers, GroupErrors, Motion};
use crate::model_file::ModelFile;
use crate::music::bailando::{BEAT_COL, FEATURE_DIM, FRAME_RATE, SAMPLE_RATE};
use crate::music::extractor::Extractor;
use crate::npy::{read_f32_2d, write_f32, write_i64};
use crate::skeleton::smpl24::to_smplx;
use crate::viewer::{write_index_html, ViewerData, ViewerLink};

/// The bundled solo model.
pub const DEMO_SOLO_MODEL: &str = "bailando_demo.duo";
/// Its music (the first 20 s of a held-out take, 3840 Hz), which the bare
/// demo (`dance --out DIR`) dances to after the duet.
pub const DEMO_SOLO_MUSIC: &str = "bailando_demo_music.wav";
/// Seed tokens (up, down) of the bundled solo model (tools/train/bailando:
/// its most common pair after the first 2 s of a training take). The
/// authors' demo uses (423, 12) for their published model.
pub const DEMO_SOLO_SEED: [u32; 2] = [217, 94];
/// `--topk` of the bundled solo model when none is given: greedy decoding
/// holds one pose on it, top-3 sampling dances (docs/DEMO_MODEL.md,
/// "Bailando demo model"); `--model assets/bailando_demo.duo` without
/// `--topk` runs greedy R mode as for any other model.
pub const DEMO_SOLO_TOPK: u32 = 3;

/// Music rows of a solo model: (R, n_music) at 7.5 per second.
struct SoloMusic {
    rows: Vec<f32>,
    n: usize,
    cols: usize,
    audio: Option<PathBuf>,
    tempo_bpm: Option<f64>,
}

fn load_music(path: &Path, n_music: usize, model: &Path) -> Result<SoloMusic> {
    if extension(path) == "npy" {
        let a = read_f32_2d(path, None, &format!("music features (R, >= {n_music}) at 7.5 rows/s, as `duolando features --for bailando` writes"))?;
        if a.cols < n_music {
            bail!("{}: {} columns per row, the model {} reads {n_music} (`duolando features --for bailando`)", path.display(), a.cols, model.display());
        }
        check_finite(path, &a.data, a.cols, "music")?;
        if a.rows == 0 {
            bail!("{}: no music rows", path.display());
        }
        return Ok(SoloMusic { rows: a.data, n: a.rows, cols: a.cols, audio: None, tempo_bpm: None });
    }
    if n_music > FEATURE_DIM {
        bail!("{}: audio gives {FEATURE_DIM} music features per row but the model {} reads {n_music}; pass a (R, {n_music}) .npy", path.display(), model.display());
    }
    let y = crate::audio::load_mono(path, SAMPLE_RATE)?;
    let f = Extractor::bailando().features(&y).with_context(|| format!("{}: cannot compute Bailando's music features from this audio", path.display()))?;
    if f.frames == 0 {
        bail!("{}: too short for one music row", path.display());
    }
    Ok(SoloMusic { rows: f.data, n: f.frames, cols: f.dim, audio: Some(path.to_path_buf()), tempo_bpm: Some(f.tempo_bpm) })
}

/// The solo dance of `args` (no leader) with the model at `model_path`.
/// `see_also`: a link in the page's header (the bare demo's back to its duet).
pub fn run(args: &super::Args, model_path: &Path, demo_model: bool, threads: usize, t_all: Instant, see_also: Option<ViewerLink<'_>>) -> Result<()> {
    let Some(music_path) = &args.music else { bail!("a solo dance needs --music (an audio file or Bailando features .npy)") };
    for (given, flag) in [
        (args.follower_start.is_some(), "--follower-start"),
        (args.true_follower.is_some(), "--true-follower"),
    ] {
        if given {
            bail!("{flag} is for a duet (a Duolando model with --leader); {} dances solo", model_path.display());
        }
    }
    eprintln!("[1/4] model {}, {threads} thread(s)", model_path.display());
    let file = ModelFile::open(model_path)?;
    super::super::print_kernels();
    let duo = file.duo()?;
    let model = Model::from_duo(&duo).map_err(|e| anyhow::anyhow!("{}: {}", model_path.display(), crate::engine_errors::describe_bind(&e)))?;
    let cfg = model.cfg;

    eprintln!("[2/4] music {}", music_path.display());
    let music = load_music(music_path, cfg.gpt.n_music as usize, model_path)?;
    let (seed, seed_text) = match &args.seed_tokens {
        Some(s) => (parse_seed(s, cfg.gpt.vocab)?, format!("tokens {s} (--seed-tokens)")),
        None if demo_model => (DEMO_SOLO_SEED, format!("tokens {},{} (the demo model's start)", DEMO_SOLO_SEED[0], DEMO_SOLO_SEED[1])),
        None => (DEMO_SOLO_SEED, format!("tokens {},{} (none given: --seed-tokens up,down chooses the start)", DEMO_SOLO_SEED[0], DEMO_SOLO_SEED[1])),
    };
    eprintln!(
        "      {} music rows ({:.1} s){}; seed: {seed_text}",
        music.n,
        music.n as f64 / FRAME_RATE,
        music.tempo_bpm.map(|b| format!(", {b:.1} BPM")).unwrap_or_default()
    );

    let t = Instant::now();
    let chosen = super::chosen_sampling(args)?;
    let sampling = chosen.or(demo_model.then_some(Sampling::TopK { k: DEMO_SOLO_TOPK, rng_seed: 0 }));
    if demo_model && chosen.is_none() {
        eprintln!("      sampling: top-{DEMO_SOLO_TOPK} (the demo model's default; greedy holds one pose on it)");
    }
    let (run, mode) = match sampling {
        None => (exact_rows(&model, &music.rows, music.cols, MusicPadding::Demo, seed), "exact (R), music-only path".to_string()),
        Some(s) => {
            // `--topk K` / `--temperature T`: a streaming session at the
            // reference preset (the decoders' whole future: R's frames for
            // its tokens), each token drawn among the K most probable
            // (uniformly: the authors' `samplek`; or by its tempered probability).
            let sc = SoloConfig { sampling: s, ..SoloConfig::preset(&cfg, SoloPreset::Reference) };
            if let Err((setting, value, max)) = sc.check(&cfg) {
                bail!("--{} {value} is outside its range for {} (largest allowed: {max})", crate::cli::budget::flag(setting), model_path.display());
            }
            (streaming_rows(&model, &music.rows, music.cols, MusicPadding::Demo, seed, &sc), format!("streaming (S), reference preset, {}", super::describe(&s)))
        }
    };
    let run = run.map_err(|e| anyhow::anyhow!("{}: {e:#}", music_path.display()))?;
    eprintln!("[3/4] generated {} steps ({mode}) in {:.1} s", run.steps, t.elapsed().as_secs_f64());
    let t_generate = t.elapsed().as_secs_f64();

    eprintln!("[4/4] exporting glTF, BVH, npy and the viewer");
    let dir = &args.out;
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create the output directory {}", dir.display()))?;
    let smplx = to_smplx(&run.pos3d);
    let motion = Motion::from_positions(&smplx, "generated solo dancer")?;
    let export_err = GroupErrors::between(&motion.positions, &smplx);
    write_dancers(dir, "dancer.glb", &[("dancer", &motion)], FPS as f32)?;
    write_f32(&dir.join("dancer_smpl24.npy"), &run.pos3d, &[run.frames, POSE_DIM])?;
    let tokens: Vec<i64> = run.tokens.iter().map(|&t| t as i64).collect();
    write_i64(&dir.join("tokens.npy"), &tokens, &[run.steps + 1, 2])?;
    let audio_name = music.audio.as_deref().map(|a| super::copy_audio(a, dir)).transpose()?;
    // A beat row lights its token's first frame (8 frames per row).
    let hop = cfg.hop();
    let beats: Option<Vec<f32>> = (music.cols > BEAT_COL).then(|| {
        (0..run.frames).map(|f| if f % hop == 0 && f / hop < music.n { music.rows[(f / hop) * music.cols + BEAT_COL] } else { 0.0 }).collect()
    });
    let title = format!("duolando: solo dance to {}", music_path.file_name().map(|n| n.to_string_lossy()).unwrap_or_default());
    let page = write_index_html(
        dir,
        &ViewerData { title: &title, fps: FPS as f32, leader_pos3d: None, follower_pos3d: &smplx, beats: beats.as_deref(), tokens: None, audio_file: audio_name.as_deref(), see_also },
    )
    .with_context(|| format!("cannot write the viewer into {}", dir.display()))?;
    let distinct = |h: usize| {
        let mut v: Vec<u32> = run.tokens.iter().skip(h).step_by(2).copied().collect();
        v.sort_unstable();
        v.dedup();
        v.len()
    };
    let mut files: Vec<String> = ["index.html", "dancer.glb", "dancer.bvh", "dancer_pos3d.npy", "dancer_rotmat.npy", "dancer_smpl24.npy", "tokens.npy", "summary.json"].map(String::from).to_vec();
    files.extend(audio_name.clone());
    let summary = json!({
        "model": model_path.display().to_string(),
        "family": "bailando",
        "mode": mode,
        "kernels": crate::simd::describe(),
        "threads": threads,
        "fps": FPS,
        "music": { "file": music_path.display().to_string(), "rows": music.n, "audio": audio_name, "tempo_bpm": music.tempo_bpm },
        "seed": seed_text,
        "steps": run.steps,
        "frames": run.frames,
        "seconds": run.frames as f64 / FPS as f64,
        "distinct_tokens": { "up_down": [distinct(0), distinct(1)] },
        "export_error_m": export_err,
        "timings_s": { "generate": t_generate, "total": t_all.elapsed().as_secs_f64() },
        "files": files,
    });
    let summary_path = dir.join("summary.json");
    std::fs::write(&summary_path, serde_json::to_string_pretty(&summary)? + "\n").with_context(|| format!("cannot write {}", summary_path.display()))?;
    eprintln!("done in {:.1} s: {} frames ({:.1} s at {FPS} fps), {} tokens", t_all.elapsed().as_secs_f64(), run.frames, run.frames as f64 / FPS as f64, run.steps + 1);
    eprintln!("wrote {}: {}", dir.display(), files.join(", "));
    eprintln!("open the viewer: {} (double-click it, or `xdg-open {0}` / `chromium {0}`)", page.display());
    Ok(())
}
