//! `duolando dance --model transflower.duo --music song.mp3 --out DIR
//! [--audio-scaler A.json] [--madmom NETWORKS] [--scaler M.json]
//! [--motion-seed S.npy] [--seed N]`: a Transflower dancer to an audio file, in one command.
//!
//! The audio becomes the model's 85-d input (`music::transflower`,
//! standardised with `--audio-scaler`: docs/TRANSFLOWER.md "Audio
//! features"), written as `DIR/audio_features.npy`; the motion seed is
//! `--motion-seed` (scaled features, at least the window's rows) or zeros
//! (the training data's mean pose after the scaler), written as
//! `DIR/motion_seed.npy`; then exactly `duolando generate --model M
//! --input AUDIO=DIR/audio_features.npy --input MOTION=DIR/motion_seed.npy
//! --seed N [--scaler M.json] --out DIR` runs (R mode): `output.npy`, and
//! with `--scaler` the skeleton, glb, bvh and viewer.
//!
//! Files beside the model stand in for absent flags: for `M.duo`,
//! `M.audio_scaler.json` (`--audio-scaler`), `M.motion_scaler.json`
//! (`--scaler`) and `M.motion_seed.npy` (`--motion-seed`), as the bundled
//! demo ships them, and `M.madmom_downbeats.bin` (`--madmom`: a user's
//! converted copy, for a model trained on madmom's beat columns) ([`Sidecars`]).

use std::path::Path;

use anyhow::{bail, Context, Result};
use clap::Parser;
use duolando_core::family::Family;
use duolando_core::transflower::model::Model;

use super::Args;
use crate::engine_errors::describe_transflower_model;
use crate::model_file::ModelFile;
use crate::cli::features::{read_audio_scaler, transflower_file_features};
use crate::music::transflower as tfa;
use crate::npy::{read_f32_2d, write_f32};

/// Whether `path` is a Transflower `.duo` (false for another family; errors
/// for an unreadable file are left to the caller's own open).
pub fn is_transflower(path: &Path) -> bool {
    ModelFile::open(path)
        .ok()
        .and_then(|f| f.duo().ok().map(|d| d.config().family() == Family::Transflower))
        .unwrap_or(false)
}

/// The Transflower-only flags, refused on the other families by name.
pub fn refuse_flags(args: &Args) -> Result<()> {
    for (set, flag) in [
        (args.seed.is_some(), "--seed"),
        (args.audio_scaler.is_some(), "--audio-scaler"),
        (args.scaler.is_some(), "--scaler"),
        (args.motion_seed.is_some(), "--motion-seed"),
        (args.madmom.is_some(), "--madmom"),
    ] {
        if set {
            bail!("{flag} is for a Transflower model (--model M.duo of family Transflower)");
        }
    }
    Ok(())
}

/// The files a Transflower `.duo` may carry beside it (`M.duo` ->
/// `M.<suffix>`): what a trained model needs besides its weights.
pub struct Sidecars;

impl Sidecars {
    pub const AUDIO_SCALER: &'static str = "audio_scaler.json";
    pub const MOTION_SCALER: &'static str = "motion_scaler.json";
    pub const MOTION_SEED: &'static str = "motion_seed.npy";
    /// madmom's downbeat networks (`--madmom`), for a model trained on
    /// madmom's beat columns: the user's own converted copy (never shipped).
    pub const MADMOM: &'static str = "madmom_downbeats.bin";

    /// `M.<suffix>` beside `model` when it is a file.
    pub fn find(model: &Path, suffix: &str) -> Option<std::path::PathBuf> {
        let stem = model.file_stem()?.to_str()?;
        let p = model.with_file_name(format!("{stem}.{suffix}"));
        p.is_file().then_some(p)
    }

    /// The flag's path, else the file beside the model (said on stderr).
    fn or_beside(
        flag: &Option<std::path::PathBuf>,
        model: &Path,
        suffix: &str,
        what: &str,
    ) -> Option<std::path::PathBuf> {
        flag.clone().or_else(|| {
            let p = Self::find(model, suffix)?;
            eprintln!("{what}: {} (beside the model)", p.display());
            Some(p)
        })
    }
}

/// `duolando generate`'s flags, parsed from the command line `run` builds.
#[derive(Parser)]
struct Generate {
    #[command(flatten)]
    args: crate::cli::generate::Args,
}

pub fn run(args: &Args) -> Result<()> {
    let model_path = args.model.as_ref().context("no --model")?;
    for (set, flag) in [
        (args.leader.is_some(), "--leader"),
        (args.follower_start.is_some(), "--follower-start"),
        (args.seed_tokens.is_some(), "--seed-tokens"),
        (args.true_follower.is_some(), "--true-follower"),
        (args.topk.is_some(), "--topk"),
        (args.temperature.is_some(), "--temperature"),
        (args.rng_seed.is_some(), "--rng-seed"),
    ] {
        if set {
            bail!("{flag}: {} is a Transflower model (a solo dancer from music and a motion seed); it takes --music, --audio-scaler, --madmom, --scaler, --motion-seed, --seed", model_path.display());
        }
    }
    let Some(music) = &args.music else {
        bail!(
            "{} is a Transflower model: --music (an audio file) is required",
            model_path.display()
        );
    };
    let file = ModelFile::open(model_path)?;
    let duo = file.duo()?;
    let model = Model::from_duo(&duo).map_err(|e| {
        anyhow::anyhow!("{}: {}", model_path.display(), describe_transflower_model(&e))
    })?;
    let cfg = model.cfg;
    let motion = cfg.output_input();
    let (motion_name, channels, window) = (
        motion.name.as_str().to_string(),
        cfg.channels(),
        motion.length as usize,
    );
    let mut audio_name = None;
    for i in cfg.inputs() {
        if i.name.as_str() == motion_name {
            continue;
        }
        if i.is_discrete() {
            bail!("{}: input `{}` is a style label; dance does not choose one (use duolando features --for transflower, then generate --input)", model_path.display(), i.name.as_str());
        }
        if i.dim as usize != tfa::FEATURE_DIM || audio_name.is_some() {
            bail!(
                "{}: input `{}` has {} columns; dance makes one {}-column audio input (Transflower's audio features) besides the motion",
                model_path.display(),
                i.name.as_str(),
                i.dim,
                tfa::FEATURE_DIM
            );
        }
        audio_name = Some(i.name.as_str().to_string());
    }
    let audio_name = audio_name.with_context(|| {
        format!(
            "{}: no audio input besides the motion `{motion_name}`",
            model_path.display()
        )
    })?;
    let audio_scaler_path = Sidecars::or_beside(&args.audio_scaler, model_path, Sidecars::AUDIO_SCALER, "audio scaler");
    let motion_scaler_path = Sidecars::or_beside(&args.scaler, model_path, Sidecars::MOTION_SCALER, "motion scaler");
    let motion_seed_path = Sidecars::or_beside(&args.motion_seed, model_path, Sidecars::MOTION_SEED, "motion seed");
    let madmom_path = Sidecars::or_beside(&args.madmom, model_path, Sidecars::MADMOM, "madmom networks");
    // Read every file before writing anything.
    let audio_scaler = match &audio_scaler_path {
        Some(p) => Some(read_audio_scaler(p, "audio-scaler")?),
        None => None,
    };
    let seed_rows = match &motion_seed_path {
        Some(p) => {
            let a = read_f32_2d(p, Some(channels), &format!("motion seed (T, {channels}), scaled features"))?;
            if a.rows < window {
                bail!("--motion-seed {}: {} rows, the model's motion window is {window}", p.display(), a.rows);
            }
            if let Some(i) = a.data.iter().position(|v| !v.is_finite()) {
                bail!("--motion-seed {}: value [{}, {}] is not finite", p.display(), i / channels, i % channels);
            }
            a.data
        }
        None => vec![0.0; window * channels],
    };
    let t = std::time::Instant::now();
    let tf = transflower_file_features(music, madmom_path.as_deref(), audio_scaler.as_ref())?;
    let f = &tf.features;
    std::fs::create_dir_all(&args.out).with_context(|| format!("cannot create {}", args.out.display()))?;
    let audio_npy = args.out.join("audio_features.npy");
    let seed_npy = args.out.join("motion_seed.npy");
    write_f32(&audio_npy, &f.data, &[f.frames, f.dim])?;
    write_f32(&seed_npy, &seed_rows, &[seed_rows.len() / channels, channels])?;
    eprintln!(
        "{}: ({}, 85) audio features at 20 fps ({}; {}), {:.2} s; motion seed {}",
        music.display(),
        f.frames,
        if audio_scaler.is_some() { "scaled" } else { "UNSCALED: give --audio-scaler for a trained model" },
        tf.beats_said(),
        t.elapsed().as_secs_f64(),
        match &motion_seed_path {
            Some(p) => p.display().to_string(),
            None => format!("zeros ({window} rows: the mean pose)"),
        }
    );
    let mut cl: Vec<String> = vec![
        "generate".into(),
        "--model".into(),
        model_path.display().to_string(),
        "--input".into(),
        format!("{audio_name}={}", audio_npy.display()),
        "--input".into(),
        format!("{motion_name}={}", seed_npy.display()),
        "--seed".into(),
        args.seed.unwrap_or(0).to_string(),
        "--out".into(),
        args.out.display().to_string(),
    ];
    if let Some(s) = &motion_scaler_path {
        cl.extend(["--scaler".into(), s.display().to_string()]);
    }
    let g = Generate::try_parse_from(&cl).map_err(|e| anyhow::anyhow!("internal generate command line: {e}"))?;
    crate::cli::generate_transflower::run_transflower(&g.args, &duo)
}
