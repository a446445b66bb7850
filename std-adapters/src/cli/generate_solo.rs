//! `duolando generate` on a solo model (Bailando): R mode, the authors'
//! `AC.eval()` token for token, or S mode (`--mode streaming`: a
//! `bailando::session::Session` fed the track, with the budget of
//! `--preset` / `--dec-future` / `--shift`). `--dance` selects the AIST++ test path
//! (the seed is the first codes of the encoded dance; the music gets one
//! copy of its last row), `--seed-tokens up,down` the music-only demo path
//! (the music padded to a multiple of 8 rows plus up to 8). Writes
//! `tokens.npy` (K+1, 2: up, down; row 0 the seed) and `pos3d.npy`
//! (N, 72): what the authors' eval saves as `pred_position`.

use std::path::Path;

use anyhow::{bail, Context, Result};
use duolando_core::bailando::config::POSE_DIM;
use duolando_core::bailando::exact::{self, MusicPadding};
use duolando_core::bailando::model::Model;
use duolando_core::bailando::session::{Session, SessionConfig};
use duolando_core::format::DuoFile;

use super::generate::{Args, Mode};
use crate::engine_errors::describe;
use crate::npy::{read_f32_2d, write_f32, write_i64};

pub fn run_bailando(args: &Args, duo: &DuoFile<'_>) -> Result<()> {
    let model = Model::from_duo(duo).map_err(|e| {
        anyhow::anyhow!(
            "{}: {}",
            args.model.display(),
            crate::engine_errors::describe_bind(&e)
        )
    })?;
    if args.leader.is_some() || args.follower_start.is_some() {
        bail!("{} is a Bailando model (a solo dancer): it takes no leader; give --music and --dance or --seed-tokens up,down", args.model.display());
    }
    let Some(music) = args.music.as_ref() else {
        bail!("{} is a Bailando model: --music (Bailando features (R, >= 438) at 7.5 fps) is required", args.model.display());
    };
    let run = match args.mode {
        Mode::Exact => bailando_exact(
            &model,
            music,
            args.dance.as_deref(),
            args.seed_tokens.as_deref(),
            &args.model,
        )?,
        Mode::Streaming => {
            let sc = args.budget.solo_config(&model.cfg)?;
            bailando_streaming(
                &model,
                music,
                args.dance.as_deref(),
                args.seed_tokens.as_deref(),
                &args.model,
                &sc,
            )?
        }
    };
    let SoloRun {
        tokens,
        pos3d: pos,
        steps: k,
        frames,
        music_rows,
        path,
    } = run;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create {}", args.out.display()))?;
    let toks: Vec<i64> = tokens.iter().map(|&t| t as i64).collect();
    write_i64(&args.out.join("tokens.npy"), &toks, &[k + 1, 2])?;
    write_f32(&args.out.join("pos3d.npy"), &pos, &[frames, POSE_DIM])?;
    eprintln!(
        "Bailando, {} mode, {path}: {} music rows -> {k} steps, {} tokens, {frames} frames at 60 fps -> {}",
        if matches!(args.mode, Mode::Exact) { "exact" } else { "streaming" },
        music_rows,
        k + 1,
        args.out.display()
    );
    Ok(())
}

/// "up,down" within the vocabularies.
pub fn parse_seed(s: &str, vocab: [u32; 2]) -> Result<[u32; 2]> {
    let v: Vec<&str> = s.split(',').map(str::trim).collect();
    if v.len() != 2 {
        bail!("--seed-tokens {s:?}: a Bailando model takes two tokens, \"up,down\"");
    }
    let mut out = [0u32; 2];
    for (i, x) in v.iter().enumerate() {
        let t: u32 = x
            .parse()
            .with_context(|| format!("--seed-tokens {s:?}: {x:?} is not a token number"))?;
        if t >= vocab[i] {
            bail!(
                "--seed-tokens {s:?}: token {t} of the {} stream is outside its vocabulary 0..{}",
                ["up", "down"][i],
                vocab[i]
            );
        }
        out[i] = t;
    }
    Ok(out)
}

/// What R mode made of one music track on a Bailando model.
pub struct SoloRun {
    /// (K+1, 2) up, down; row 0 the seed.
    pub tokens: Vec<u32>,
    /// (frames, 72) `pred_position`.
    pub pos3d: Vec<f32>,
    pub steps: usize,
    pub frames: usize,
    pub music_rows: usize,
    /// Which of the authors' eval paths ran, in words.
    pub path: &'static str,
}

/// R mode on `music_path` (R, >= n_music) with the AIST++ path (`dance`:
/// a (T, 72) .npy) or the demo path (`seed_tokens` "up,down"); every
/// input error names its file. `model_path` labels messages.
pub fn bailando_exact(
    model: &Model<'_>,
    music_path: &Path,
    dance: Option<&Path>,
    seed_tokens: Option<&str>,
    model_path: &Path,
) -> Result<SoloRun> {
    let SoloInputs {
        music,
        padding,
        seed,
        path,
    } = solo_inputs(model, music_path, dance, seed_tokens, model_path)?;
    let mut run = exact_rows(model, &music.data, music.cols, padding, seed)
        .map_err(|e| anyhow::anyhow!("{}: {e:#}", music_path.display()))?;
    run.path = path;
    Ok(run)
}

/// R mode on music rows in memory (`music` (R, cols), the first
/// `n_music` columns read).
pub fn exact_rows(
    model: &Model<'_>,
    music: &[f32],
    cols: usize,
    padding: MusicPadding,
    seed: [u32; 2],
) -> Result<SoloRun> {
    let cfg = model.cfg;
    let rows = music.len() / cols.max(1);
    let k = exact::steps(padding, rows);
    let mut tokens = vec![0u32; (k + 1) * 2];
    let mut scratch = vec![0u8; exact::sample_scratch_bytes(&cfg).context("config too large")?];
    exact::sample(model, music, cols, padding, seed, &mut scratch, &mut tokens)
        .map_err(|e| anyhow::anyhow!("{}", describe(&e)))?;
    let frames = (k + 1) * cfg.hop();
    let mut pos = vec![0f32; frames * POSE_DIM];
    let mut scratch =
        vec![0u8; exact::decode_scratch_bytes(&cfg, k + 1).context("too many tokens")?];
    exact::decode(model, &tokens, &mut scratch, &mut pos)
        .map_err(|e| anyhow::anyhow!("decoding: {}", describe(&e)))?;
    let path = path_name(padding);
    Ok(SoloRun {
        tokens,
        pos3d: pos,
        steps: k,
        frames,
        music_rows: rows,
        path,
    })
}

/// S mode on the same inputs as [`bailando_exact`]: a session is given the
/// whole track (its first `n_music` columns), told the music ended (the
/// same padding as R's path), and pulled to the end.
pub fn bailando_streaming(
    model: &Model<'_>,
    music_path: &Path,
    dance: Option<&Path>,
    seed_tokens: Option<&str>,
    model_path: &Path,
    sc: &SessionConfig,
) -> Result<SoloRun> {
    let SoloInputs {
        music,
        padding,
        seed,
        path,
    } = solo_inputs(model, music_path, dance, seed_tokens, model_path)?;
    let mut run = streaming_rows(model, &music.data, music.cols, padding, seed, sc)
        .map_err(|e| anyhow::anyhow!("{}: {e:#}", music_path.display()))?;
    run.path = path;
    Ok(run)
}

/// S mode on music rows in memory (`music` (R, cols), the first `n_music`
/// columns read): a session is given the whole track, told the music ended
/// (`padding`, as R's path), and pulled to the end.
pub fn streaming_rows(
    model: &Model<'_>,
    music: &[f32],
    cols: usize,
    padding: MusicPadding,
    seed: [u32; 2],
    sc: &SessionConfig,
) -> Result<SoloRun> {
    let nm = model.cfg.gpt.n_music as usize;
    let n_rows = music.len() / cols.max(1);
    if cols < nm {
        bail!("music rows of {cols} values; the model reads {nm}");
    }
    let sc = SessionConfig {
        music_buffer_rows: (n_rows as u32).max(1),
        ..*sc
    };
    let mut arena = vec![
        0u8;
        model
            .session_bytes(&sc)
            .map_err(|e| anyhow::anyhow!("session: {}", describe(&e)))?
    ];
    let mut s = Session::new(model, &mut arena, &sc, seed)
        .map_err(|e| anyhow::anyhow!("session: {}", describe(&e)))?;
    let rows: Vec<f32> = music
        .chunks_exact(cols)
        .flat_map(|r| r[..nm].iter().copied())
        .collect();
    let err = |e: duolando_core::error::Error| anyhow::anyhow!("{}", describe(&e));
    s.push_music(&rows).map_err(err)?;
    s.finish(padding).map_err(err)?;
    let mut tokens = seed.to_vec();
    let mut pos = Vec::new();
    let mut f = [0f32; POSE_DIM];
    loop {
        while s.frames_ready() > 0 {
            s.pull(&mut f).map_err(err)?;
            pos.extend_from_slice(&f);
        }
        match s.step().map_err(err)? {
            Some(r) => tokens.extend_from_slice(&r.token),
            None => break,
        }
    }
    while s.pull(&mut f).map_err(err)?.is_some() {
        pos.extend_from_slice(&f);
    }
    if !s.done() {
        bail!("the session did not reach the end of the music (an engine bug)");
    }
    let k = tokens.len() / 2 - 1;
    Ok(SoloRun {
        tokens,
        frames: pos.len() / POSE_DIM,
        pos3d: pos,
        steps: k,
        music_rows: n_rows,
        path: path_name(padding),
    })
}

/// Which of the authors' eval paths a music padding is.
fn path_name(padding: MusicPadding) -> &'static str {
    match padding {
        MusicPadding::Aist => "AIST++ test path",
        MusicPadding::Demo => "demo path (seed given)",
    }
}

/// The inputs of a solo run, read and checked, every error naming its file.
struct SoloInputs {
    music: crate::npy::Array2<f32>,
    padding: MusicPadding,
    seed: [u32; 2],
    path: &'static str,
}

fn solo_inputs(
    model: &Model<'_>,
    music_path: &Path,
    dance: Option<&Path>,
    seed_tokens: Option<&str>,
    model_path: &Path,
) -> Result<SoloInputs> {
    let cfg = model.cfg;
    let nm = cfg.gpt.n_music as usize;
    let music = read_f32_2d(
        music_path,
        None,
        &format!("music features (R, >= {nm}) at 7.5 fps"),
    )?;
    if music.cols < nm {
        bail!("{}: {} columns per row, the model reads {nm} (Bailando's features: `duolando features --for bailando`)", music_path.display(), music.cols);
    }
    if music.rows == 0 {
        bail!("{}: no music rows", music_path.display());
    }
    let (padding, seed, path) = match (dance, seed_tokens) {
        (Some(d), None) => {
            let dance = read_f32_2d(d, Some(POSE_DIM), "dance joint positions (T, 72)")?;
            if dance.rows == 0 {
                bail!("{}: no dance frames", d.display());
            }
            let mut scratch = vec![0u8; exact::dance_scratch_bytes(&cfg, dance.rows).context("dance too long")?];
            let seed = exact::seed_from_dance(model, &dance.data, &mut scratch).map_err(|e| anyhow::anyhow!("{}: {}", d.display(), describe(&e)))?;
            (MusicPadding::Aist, seed, "AIST++ test path (seed from the dance)")
        }
        (None, Some(s)) => (MusicPadding::Demo, parse_seed(s, cfg.gpt.vocab)?, "demo path (seed given)"),
        _ => bail!("{} is a Bailando model: give --dance (the AIST++ test path) or --seed-tokens up,down (the demo path)", model_path.display()),
    };
    Ok(SoloInputs {
        music,
        padding,
        seed,
        path,
    })
}
