//! `duolando generate`: run the model over a whole leader clip and music
//! track read from `.npy` files and write the follower as `.npy` files.
//!
//! `--mode exact` is R mode (docs/ARCHITECTURE.md): the authors' evaluation
//! pipeline token for token (greedy). `--mode streaming` drives a streaming
//! session frame by frame (S, docs/STREAMING.md) with the latency budget
//! of `--preset` / `--lookahead` / ... and writes the same files.

use std::io::IsTerminal;
use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use clap::ValueEnum;
use duolando_core::duolando::config::{POSE_DIM, ROT_DIM};
use duolando_core::duolando::exact::{self, ExactInputs, ExactOutputs, Seed};
use duolando_core::duolando::model::Model;
use duolando_core::duolando::session::SessionConfig;

use crate::engine_errors::describe;
use crate::model_file::ModelFile;
use crate::npy::{read_f32_2d, write_f32, write_i64};
use crate::streaming::run_streaming_with;

#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum Mode {
    /// R mode: the original evaluation pipeline, token for token.
    Exact,
    /// S mode: a streaming session fed frame by frame (fixed memory, bounded latency).
    Streaming,
}

#[derive(clap::Args, Debug)]
pub struct Args {
    /// The `.duo` model.
    #[arg(long)]
    pub model: PathBuf,
    /// Duolando: leader joint positions, (T, 165) float32, metres, SMPL-X order, 30 fps.
    #[arg(long)]
    pub leader: Option<PathBuf>,
    /// Music features: Duolando (T, 54) float32 at 30 fps; Bailando (R,
    /// >= 438) at 7.5 fps, its first n_music columns read (`duolando
    /// features --for duolando|bailando` makes them). Transflower: use --input.
    #[arg(long)]
    pub music: Option<PathBuf>,
    /// Transflower: one input modality's whole array, MODALITY=FILE.npy
    /// (the scaled features, (T, d) float32, e.g.
    /// `expmap_scaled_20=seq.expmap_scaled_20.npy`), or a style label
    /// (MODALITY=FILE.npy of one integer, or MODALITY=N); once per input
    /// modality of the model (`duolando inspect` lists them).
    #[arg(long = "input", value_name = "MODALITY=FILE")]
    pub input: Vec<String>,
    /// Transflower: replay recorded base samples, (N, C, H) float32, one
    /// per generated frame (the reference's noise.npy layout).
    #[arg(long, conflicts_with = "seed")]
    pub noise: Option<PathBuf>,
    /// Transflower: seed of the engine's base-sample RNG (default 0;
    /// deterministic, not the authors' torch streams).
    #[arg(long)]
    pub seed: Option<u64>,
    /// Transflower: the motion features' scaler (JSON written by
    /// tools/transflower_scalers.py from the authors' `*_scaler.pkl`). With
    /// it the generated frames are also unscaled and placed on a skeleton:
    /// `output_unscaled.npy`, `positions.npy` (N, J, 3), `dancer.glb`,
    /// `dancer.bvh`, npy exports and `index.html` (docs/TRANSFLOWER.md
    /// "Motion to a skeleton").
    #[arg(long)]
    pub scaler: Option<PathBuf>,
    /// Transflower, with --scaler: the skeleton the features were made on,
    /// a BVH file (its hierarchy; centimetres when taller than 5 units).
    /// Default: the built-in table (the authors' mixamo.bvh body, metres).
    #[arg(long)]
    pub skeleton: Option<PathBuf>,
    /// Seed tokens: Duolando "up,down,lhand,rhand,transl"; Bailando
    /// "up,down", which selects the authors' music-only demo path (its
    /// music padding; the authors' demo seed is 423,12).
    #[arg(long, conflicts_with_all = ["follower_start", "dance"])]
    pub seed_tokens: Option<String>,
    /// Bailando: a dance, (T, 72) float32 SMPL joint positions at 60 fps,
    /// whose first codes seed the dancer: the authors' AIST++ test path.
    #[arg(long, conflicts_with = "follower_start")]
    pub dance: Option<PathBuf>,
    /// The follower's first frames, (F, 165) float32 (F >= 4; 4 as in the original eval).
    #[arg(long)]
    pub follower_start: Option<PathBuf>,
    #[arg(long, value_enum, default_value = "exact")]
    pub mode: Mode,
    /// Streaming budget (with --mode streaming).
    #[command(flatten)]
    pub budget: crate::cli::budget::BudgetArgs,
    /// With --mode streaming: stop at the last leader frame like a live
    /// session that never learns the leader ended, instead of draining
    /// (by default the session is told the leader ended and outputs R's
    /// frame count, docs/STREAMING.md §2 "Drain").
    #[arg(long)]
    pub no_drain: bool,
    /// Output directory (created).
    #[arg(long, short)]
    pub out: PathBuf,    /// Threads the large matrix products are split over (the output does not
    /// depend on it). Default: every core, at most 8.
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=64))]
    pub threads: Option<u32>,
}

/// What [`generate_exact`] produced.
pub struct Generated {
    /// (K+1, 5) up, down, lhand, rhand, transl; row 0 = seed.
    pub tokens: Vec<u32>,
    /// (F, 165) world positions in the leader's input coordinates.
    pub follower_pos3d: Vec<f32>,
    /// (F, 495) raw rotation-decoder output.
    pub follower_rotmat: Vec<f32>,
    pub frames: usize,
    pub token_rows: usize,
}

/// Parses "a,b,c,d,e" into five tokens.
pub fn parse_seed_tokens(s: &str) -> Result<[u32; 5]> {
    let v: Vec<&str> = s.split(',').map(str::trim).collect();
    if v.len() != 5 {
        bail!("--seed-tokens needs 5 comma-separated tokens (up,down,lhand,rhand,transl), got {}", v.len());
    }
    let mut out = [0u32; 5];
    for (o, t) in out.iter_mut().zip(&v) {
        *o = t.parse().with_context(|| format!("--seed-tokens: '{t}' is not a non-negative integer"))?;
    }
    Ok(out)
}

/// Runs R mode on in-memory inputs, with a progress bar on a terminal.
pub fn generate_exact(model: &Model<'_>, leader: &[f32], music: &[f32], seed: Seed<'_>) -> Result<Generated> {
    let cfg = &model.cfg;
    let t = leader.len() / POSE_DIM;
    let shape = exact::output_shape(cfg, t)
        .with_context(|| format!("the leader clip has {t} frames; at least {} are needed", cfg.hop()))?;
    let scratch_len = exact::scratch_bytes(cfg, t).context("the clip is too long for this model's scratch plan")?;
    let mut scratch = vec![0u8; scratch_len];
    let mut g = Generated {
        tokens: vec![0; shape.token_rows * 5],
        follower_pos3d: vec![0.0; shape.frames_out * POSE_DIM],
        follower_rotmat: vec![0.0; shape.frames_out * ROT_DIM],
        frames: shape.frames_out,
        token_rows: shape.token_rows,
    };
    let bar = progress_bar(shape.steps as u64, "generating", "steps");
    let result = exact::generate(
        model,
        &ExactInputs { leader_pos3d: leader, music, seed },
        &mut scratch,
        &mut ExactOutputs {
            tokens: &mut g.tokens,
            follower_pos3d: &mut g.follower_pos3d,
            follower_rotmat: &mut g.follower_rotmat,
            leader_tokens: None,
        },
        &mut |done, _| {
            if let Some(b) = &bar {
                b.set_position(done as u64);
            }
        },
    );
    if let Some(b) = bar {
        b.finish_and_clear();
    }
    result.map_err(|e| anyhow::anyhow!("generation failed: {}", describe(&e)))?;
    Ok(g)
}

/// The seed tokens of `seed` (R's rule for follower frames, against `leader`).
pub fn seed_tokens(model: &Model<'_>, seed: Seed<'_>, leader: &[f32]) -> Result<[u32; 5]> {
    match seed {
        Seed::Tokens(t) => Ok(t),
        Seed::FollowerFrames(f) => {
            let frames = f.len() / POSE_DIM;
            let mut scratch = vec![0u8; exact::seed_scratch_bytes(&model.cfg, frames).context("seed frames too long")?];
            exact::seed_tokens(model, f, leader, &mut scratch)
                .map_err(|e| anyhow::anyhow!("the follower start frames cannot seed the model: {}", describe(&e)))
        }
    }
}

/// Runs S mode on in-memory inputs (a session fed frame by frame), with a
/// progress bar on a terminal.
/// With `drain`, the session is told the leader ended after the last frame
/// ([`duolando_core::duolando::session::Session::finish`]) and every frame it then
/// outputs is kept.
pub fn generate_streaming(model: &Model<'_>, leader: &[f32], music: &[f32], sc: &SessionConfig, seed: [u32; 5], drain: bool) -> Result<Generated> {
    let t = leader.len() / POSE_DIM;
    let bar = progress_bar(t as u64, "streaming", "frames");
    let run = run_streaming_with(model, leader, music, sc, seed, None, drain, &mut |done, _| {
        if let Some(b) = &bar {
            b.set_position(done as u64);
        }
    });
    if let Some(b) = bar {
        b.finish_and_clear();
    }
    let run = run.map_err(|e| anyhow::anyhow!("streaming failed: {}", describe(&e)))?;
    Ok(Generated {
        token_rows: run.tokens.len() / 5,
        frames: run.frames_out(),
        tokens: run.tokens,
        follower_pos3d: run.pos,
        follower_rotmat: run.rot,
    })
}

fn progress_bar(len: u64, msg: &'static str, unit: &str) -> Option<indicatif::ProgressBar> {
    if !std::io::stderr().is_terminal() || len == 0 {
        return None;
    }
    let b = indicatif::ProgressBar::new(len);
    b.set_style(
        indicatif::ProgressStyle::with_template(&format!("{{msg}} [{{bar:40}}] {{pos}}/{{len}} {unit}, {{eta}} left"))
            .expect("static template")
            .progress_chars("=> "),
    );
    b.set_message(msg);
    Some(b)
}

/// Writes `tokens.npy`, `follower_pos3d.npy`, `follower_rotmat.npy` into `dir`.
pub fn write_outputs(dir: &Path, g: &Generated) -> Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let tokens: Vec<i64> = g.tokens.iter().map(|&t| t as i64).collect();
    write_i64(&dir.join("tokens.npy"), &tokens, &[g.token_rows, 5])?;
    write_f32(&dir.join("follower_pos3d.npy"), &g.follower_pos3d, &[g.frames, POSE_DIM])?;
    write_f32(&dir.join("follower_rotmat.npy"), &g.follower_rotmat, &[g.frames, ROT_DIM])?;
    Ok(())
}

/// Refuses Transflower's flags on a model of another family, by name.
fn refuse_transflower_flags(args: &Args, family: &str) -> Result<()> {
    let flags = [
        ("--input", !args.input.is_empty()),
        ("--noise", args.noise.is_some()),
        ("--seed", args.seed.is_some()),
        ("--scaler", args.scaler.is_some()),
        ("--skeleton", args.skeleton.is_some()),
    ];
    for (flag, on) in flags {
        if on {
            bail!("{flag} is for Transflower models; {} is a {family} model (it takes --music{})", args.model.display(), if family == "Duolando" { ", --leader and --seed-tokens or --follower-start" } else { " and --dance or --seed-tokens" });
        }
    }
    Ok(())
}

pub fn run(args: Args) -> Result<()> {
    let threads = args.threads.map_or_else(crate::workers::default_threads, |n| n as usize);
    crate::workers::set_threads(threads).with_context(|| format!("starting {threads} threads"))?;
    let file = ModelFile::open(&args.model)?;
    super::print_kernels();
    let duo = file.duo()?;
    if matches!(args.mode, Mode::Exact) && duo.config().family() != duolando_core::family::Family::Transflower {
        // (Transflower names its own streaming flags below.)
        if let Some(flag) = args.budget.first_given() {
            bail!("--{flag} sets a streaming session (--mode streaming); --mode exact runs the authors' evaluation: greedy, over R's window, with no budget");
        }
        if args.no_drain {
            bail!("--no-drain is a streaming flag (--mode streaming); --mode exact outputs every frame R generates");
        }
    }
    match duo.config().family() {
        duolando_core::family::Family::Bailando => {
            refuse_transflower_flags(&args, "Bailando")?;
            return super::generate_solo::run_bailando(&args, &duo);
        }
        duolando_core::family::Family::Transflower => return super::generate_transflower::run_transflower(&args, &duo),
        duolando_core::family::Family::Duolando => refuse_transflower_flags(&args, "Duolando")?,
    }
    if args.dance.is_some() {
        bail!("--dance is for Bailando models; {} is a Duolando model (give --leader and --seed-tokens or --follower-start)", args.model.display());
    }
    let model = Model::from_duo(&duo)
        .map_err(|e| anyhow::anyhow!("{}: {}", args.model.display(), crate::engine_errors::describe_bind(&e)))?;
    let n_music = model.cfg.gpt.music.n_in as usize;
    let Some(leader_path) = args.leader.as_ref() else {
        bail!("{} is a Duolando model: --leader (the leader's joint positions) is required", args.model.display());
    };
    if args.seed_tokens.is_none() && args.follower_start.is_none() {
        bail!("{} is a Duolando model: give --seed-tokens up,down,lhand,rhand,transl or --follower-start", args.model.display());
    }
    let leader = read_f32_2d(leader_path, Some(POSE_DIM), "leader joint positions (T, 165)")?;
    let Some(music_path) = args.music.as_ref() else {
        bail!("{} is a Duolando model: --music (music features (T, {n_music}) at 30 fps) is required", args.model.display());
    };
    let music = read_f32_2d(music_path, Some(n_music), &format!("music features (T, {n_music})"))?;
    let t4 = leader.rows / model.cfg.hop() * model.cfg.hop();
    if music.rows < t4 {
        bail!(
            "{}: {} music frames for {} leader frames ({} used after truncation to a multiple of {}); both are 30 fps and must cover the same time",
            music_path.display(),
            music.rows,
            leader.rows,
            t4,
            model.cfg.hop()
        );
    }
    let start;
    let seed = match (&args.seed_tokens, &args.follower_start) {
        (Some(s), _) => Seed::Tokens(parse_seed_tokens(s)?),
        (None, Some(p)) => {
            start = read_f32_2d(p, Some(POSE_DIM), "follower start frames (F, 165)")?;
            Seed::FollowerFrames(&start.data)
        }
        (None, None) => bail!("give --seed-tokens or --follower-start"),
    };
    let started = std::time::Instant::now();
    let g = match args.mode {
        Mode::Exact => generate_exact(&model, &leader.data, &music.data, seed)?,
        Mode::Streaming => {
            let sc = args.budget.config(&model.cfg)?;
            let seed = seed_tokens(&model, seed, &leader.data)?;
            let g = generate_streaming(&model, &leader.data[..t4 * POSE_DIM], &music.data, &sc, seed, !args.no_drain)?;
            eprintln!("streaming: latency {} frames ({:.2} s at 30 fps)", sc.latency_frames(model.cfg.hop() as u32), sc.latency_frames(model.cfg.hop() as u32) as f64 / 30.0);
            g
        }
    };
    write_outputs(&args.out, &g)?;
    eprintln!(
        "wrote {} follower frames ({} token rows) to {} in {:.1} s",
        g.frames,
        g.token_rows,
        args.out.display(),
        started.elapsed().as_secs_f64()
    );
    Ok(())
}
