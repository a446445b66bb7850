//! `duolando compare`: how closely two ways of running the model agree on
//! one clip (definitions: docs/STREAMING.md §7, `crate::agreement`).
//!
//! Without `--against`: streaming (S, with the given budget) against exact
//! (R) on the same model: one-step agreement (S forced on R's history),
//! free-running agreement, follower joint error.
//! With `--against B.duo`: model A against model B in one mode (e.g. an
//! int8 conversion against the f32 one): free-running agreement and joint
//! error, plus one-step agreement in streaming mode (A forced on B's
//! history).

use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use duolando_core::duolando::config::POSE_DIM;
use duolando_core::duolando::exact::Seed;
use duolando_core::duolando::model::Model;
use serde_json::{json, Map, Value};

use crate::agreement::{free_run, joint_error_mm, one_step, TokenAgreement, STREAMS};
use crate::cli::budget::BudgetArgs;
use crate::cli::dance::inputs::{require_asset, DEMO_FOLLOWER_START, DEMO_LEADER, DEMO_MODEL, DEMO_MUSIC};
use crate::cli::generate::{generate_exact, parse_seed_tokens, seed_tokens, Generated, Mode};
use crate::engine_errors::describe;
use crate::model_file::ModelFile;
use crate::npy::read_f32_2d;
use crate::streaming::run_streaming;

#[derive(clap::Args, Debug)]
pub struct Args {
    /// The model (default: the bundled demo model).
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// A second model to compare against (same config; e.g. another dtype).
    #[arg(long)]
    pub against: Option<PathBuf>,
    /// Mode of both runs with --against (without it: streaming vs exact).
    #[arg(long, value_enum, default_value = "exact")]
    pub mode: Mode,
    /// Leader joint positions (T, 165) .npy (default: the bundled demo clip).
    #[arg(long)]
    pub leader: Option<PathBuf>,
    /// Music features (T, 54) .npy (default: the bundled demo features).
    #[arg(long)]
    pub music: Option<PathBuf>,
    /// Seed tokens "up,down,lhand,rhand,transl".
    #[arg(long, conflicts_with = "follower_start")]
    pub seed_tokens: Option<String>,
    /// The follower's first frames (F, 165) .npy (default with the demo clip: the bundled start).
    #[arg(long)]
    pub follower_start: Option<PathBuf>,
    /// Bailando models (with --against, exact mode): the dance (T, 72)
    /// whose first codes seed both runs (the AIST++ path); or give
    /// --seed-tokens up,down (the demo path).
    #[arg(long, conflicts_with = "follower_start")]
    pub dance: Option<PathBuf>,
    #[command(flatten)]
    pub budget: BudgetArgs,
    /// Also write the figures as one flat JSON object.
    #[arg(long)]
    pub json: Option<PathBuf>,
}

fn agreement_fields(out: &mut Map<String, Value>, prefix: &str, a: &TokenAgreement) {
    out.insert(prefix.to_string(), json!(a.all));
    for (s, v) in STREAMS.iter().zip(a.per_stream) {
        out.insert(format!("{prefix}_{s}"), json!(v));
    }
}

/// The papers' per-clip metrics of one run's follower (docs/EVAL.md), as
/// `<who>_bas` (beat align score against the music's beat column),
/// `<who>_bed` (beat echo degree against the leader of the same frames)
/// and `<who>_fsr` (foot-skating ratio, percent); a metric that cannot be
/// computed on this clip (no beats, too short, not 54 music columns) is
/// null and named in `<who>_metrics_not_computed`. FID and Div compare
/// sets, not one clip: `eval` on folders (docs/EVAL.md). Over the first
/// `frames` frames (the two runs' common length: S without a drain stops
/// earlier than R).
#[allow(clippy::too_many_arguments)]
fn clip_metrics(out: &mut Map<String, Value>, who: &str, frames: usize, follower: &[f32], leader: &[f32], music: &[f32], music_cols: usize) {
    use crate::eval::{bas, bed, footskate};
    let frames = frames.min(follower.len() / POSE_DIM).min(leader.len() / POSE_DIM);
    let (f, l) = (&follower[..frames * POSE_DIM], &leader[..frames * POSE_DIM]);
    let mut missing = Vec::new();
    let mut put = |name: &str, v: Result<f64, crate::eval::EvalError>| {
        let v = v.map_err(|e| missing.push(format!("{name}: {e}"))).ok();
        out.insert(format!("{who}_{name}"), json!(v));
    };
    put("bas", bas::clip_score(f, music, music_cols));
    put("bed", bed::duet_score(f, l));
    put("fsr", footskate::clip_counts(f).map(|c| footskate::ratio(&[c])));
    if !missing.is_empty() {
        out.insert(format!("{who}_metrics_not_computed"), json!(missing));
    }
}

fn open(path: &PathBuf) -> Result<ModelFile> {
    ModelFile::open(path).with_context(|| format!("cannot open the model {}", path.display()))
}

pub fn run(args: Args) -> Result<()> {
    let model_path = match &args.model {
        Some(p) => p.clone(),
        None => require_asset(DEMO_MODEL, "model")?,
    };
    let file = open(&model_path)?;
    super::print_kernels();
    let duo = file.duo()?;
    if duo.config().family() == duolando_core::family::Family::Bailando {
        return compare_bailando(&args, &model_path, &duo);
    }
    let model = Model::from_duo(&duo).map_err(|e| anyhow::anyhow!("{}: {}", model_path.display(), crate::engine_errors::describe_bind(&e)))?;
    let n_music = model.cfg.gpt.music.n_in as usize;
    let demo_inputs = args.leader.is_none() && args.music.is_none();
    let leader_path = match &args.leader {
        Some(p) => p.clone(),
        None => require_asset(DEMO_LEADER, "leader clip")?,
    };
    let music_path = match &args.music {
        Some(p) => p.clone(),
        None => require_asset(DEMO_MUSIC, "music features")?,
    };
    let leader = read_f32_2d(&leader_path, Some(POSE_DIM), "leader joint positions (T, 165)")?;
    let music = read_f32_2d(&music_path, Some(n_music), &format!("music features (T, {n_music})"))?;
    let hop = model.cfg.hop();
    let t4 = leader.rows / hop * hop;
    if music.rows < t4 {
        bail!("{}: {} music frames for {} leader frames; both are 30 fps and must cover the same time", music_path.display(), music.rows, t4);
    }
    let start;
    let start_path = match (&args.follower_start, demo_inputs && args.seed_tokens.is_none()) {
        (Some(p), _) => Some(p.clone()),
        (None, true) => Some(require_asset(DEMO_FOLLOWER_START, "follower start")?),
        (None, false) => None,
    };
    let seed = match (&args.seed_tokens, &start_path) {
        (Some(s), _) => Seed::Tokens(parse_seed_tokens(s)?),
        (None, Some(p)) => {
            start = read_f32_2d(p, Some(POSE_DIM), "follower start frames (F, 165)")?;
            Seed::FollowerFrames(&start.data)
        }
        (None, None) => bail!("give --seed-tokens or --follower-start"),
    };
    let leader = &leader.data[..t4 * POSE_DIM];
    let sc = args.budget.config(&model.cfg)?;
    let seed5 = seed_tokens(&model, seed, leader)?;
    let mut out = Map::new();

    match &args.against {
        None => {
            // S vs R on one model.
            let r = generate_exact(&model, leader, &music.data, seed)?;
            let stream = |forced: Option<&[u32]>| {
                run_streaming(&model, leader, &music.data, &sc, seed5, forced, &mut |_, _| {})
                    .map_err(|e| anyhow::anyhow!("streaming failed: {}", describe(&e)))
            };
            let forced = stream(Some(&r.tokens))?;
            let free = stream(None)?;
            let os = one_step(&forced.pred, &r.tokens);
            let fr = free_run(&free.tokens, &r.tokens);
            let (mean, max, frames) = joint_error_mm(&free.pos, &r.follower_pos3d);
            agreement_fields(&mut out, "token_agreement", &os);
            out.insert("free_run_agreement".into(), json!(fr.all));
            out.insert("mean_joint_err_mm".into(), json!(mean));
            out.insert("max_joint_err_mm".into(), json!(max));
            out.insert("latency_frames".into(), json!(free.latency_frames));
            out.insert("one_step_steps".into(), json!(os.rows));
            out.insert("free_run_steps".into(), json!(fr.rows));
            out.insert("joint_err_frames".into(), json!(frames));
            out.insert("arena_bytes".into(), json!(free.arena_bytes));
            // Both over the frames both runs have (`joint_err_frames`).
            clip_metrics(&mut out, "r", frames, &r.follower_pos3d, leader, &music.data, music.cols);
            clip_metrics(&mut out, "s", frames, &free.pos, leader, &music.data, music.cols);
            println!("streaming (S) vs exact (R), {} on {} ({} frames)", model_path.display(), leader_path.display(), t4);
        }
        Some(b_path) => {
            let b_file = open(b_path)?;
            let b_duo = b_file.duo()?;
            let b = Model::from_duo(&b_duo).map_err(|e| anyhow::anyhow!("{}: {}", b_path.display(), crate::engine_errors::describe_bind(&e)))?;
            if b.cfg != model.cfg {
                bail!("{} and {} have different configs; compare conversions of the same checkpoint", model_path.display(), b_path.display());
            }
            let gen = |m: &Model<'_>| -> Result<(Generated, Option<Vec<u32>>)> {
                match args.mode {
                    Mode::Exact => Ok((generate_exact(m, leader, &music.data, seed)?, None)),
                    Mode::Streaming => {
                        let r = run_streaming(m, leader, &music.data, &sc, seed5, None, &mut |_, _| {})
                            .map_err(|e| anyhow::anyhow!("streaming failed: {}", describe(&e)))?;
                        let frames = r.frames_out();
                        Ok((Generated { token_rows: r.tokens.len() / 5, frames, tokens: r.tokens, follower_pos3d: r.pos, follower_rotmat: r.rot }, None))
                    }
                }
            };
            let (ga, _) = gen(&model)?;
            let (gb, _) = gen(&b)?;
            let fr = free_run(&ga.tokens, &gb.tokens);
            agreement_fields(&mut out, "free_run_agreement", &fr);
            if let Mode::Streaming = args.mode {
                let forced = run_streaming(&model, leader, &music.data, &sc, seed5, Some(&gb.tokens), &mut |_, _| {})
                    .map_err(|e| anyhow::anyhow!("streaming failed: {}", describe(&e)))?;
                agreement_fields(&mut out, "token_agreement", &one_step(&forced.pred, &gb.tokens));
            }
            let (mean, max, frames) = joint_error_mm(&ga.follower_pos3d, &gb.follower_pos3d);
            out.insert("mean_joint_err_mm".into(), json!(mean));
            out.insert("max_joint_err_mm".into(), json!(max));
            out.insert("free_run_steps".into(), json!(fr.rows));
            out.insert("joint_err_frames".into(), json!(frames));
            clip_metrics(&mut out, "a", frames, &ga.follower_pos3d, leader, &music.data, music.cols);
            clip_metrics(&mut out, "b", frames, &gb.follower_pos3d, leader, &music.data, music.cols);
            println!("{} vs {} ({:?} mode) on {} ({} frames)", model_path.display(), b_path.display(), args.mode, leader_path.display(), t4);
        }
    }
    for (k, v) in [("lookahead", sc.lookahead), ("enc_future", sc.enc_future), ("dec_future", sc.dec_future), ("shift", sc.shift)] {
        out.insert(k.into(), json!(v));
    }
    for (k, v) in &out {
        println!("  {k:<28} {v}");
    }
    if let Some(p) = &args.json {
        std::fs::write(p, serde_json::to_string_pretty(&Value::Object(out))? + "\n").with_context(|| format!("cannot write {}", p.display()))?;
        eprintln!("wrote {}", p.display());
    }
    Ok(())
}

/// A Bailando model on one music track: without `--against`, S (the
/// budget of `--preset` / `--dec-future` / `--shift`) against R, with the
/// one-step agreement of S's window schedule on R's history; with
/// `--against B.duo`, two models (e.g. an int8 conversion against the f32
/// one) in one mode. Free-running token agreement per stream, joint error.
fn compare_bailando(args: &Args, model_path: &std::path::Path, duo: &duolando_core::format::DuoFile<'_>) -> Result<()> {
    use duolando_core::bailando::model::Model as BModel;
    use super::generate_solo::{bailando_exact, bailando_streaming};
    if args.leader.is_some() || args.follower_start.is_some() {
        bail!("{} is a Bailando model (a solo dancer): it takes no leader; give --music with --dance or --seed-tokens up,down", model_path.display());
    }
    let Some(music) = &args.music else { bail!("{} is a Bailando model: --music (R, 438) is required", model_path.display()) };
    let a = BModel::from_duo(duo).map_err(|e| anyhow::anyhow!("{}: {}", model_path.display(), crate::engine_errors::describe_bind(&e)))?;
    let (dance, seed) = (args.dance.as_deref(), args.seed_tokens.as_deref());
    let Some(b_path) = &args.against else {
        let sc = args.budget.solo_config(&a.cfg)?;
        let (ra, rs) = (bailando_exact(&a, music, dance, seed, model_path)?, bailando_streaming(&a, music, dance, seed, model_path, &sc)?);
        let one = solo_one_step(&a, &ra.tokens, sc.shift as usize, music)?;
        let (all, per, steps) = crate::agreement::free_run_of(&rs.tokens, &ra.tokens, 2);
        let (mean, max, frames) = crate::agreement::joint_error_mm_of(&rs.pos3d, &ra.pos3d, duolando_core::bailando::config::N_JOINTS);
        let mut out = Map::new();
        out.insert("one_step_agreement".into(), json!(one));
        out.insert("free_run_agreement".into(), json!(all));
        out.insert("free_run_agreement_up".into(), json!(per[0]));
        out.insert("free_run_agreement_down".into(), json!(per[1]));
        out.insert("free_run_steps".into(), json!(steps));
        out.insert("mean_joint_err_mm".into(), json!(mean));
        out.insert("max_joint_err_mm".into(), json!(max));
        out.insert("joint_err_frames".into(), json!(frames));
        out.insert("dec_future".into(), json!(sc.dec_future));
        out.insert("shift".into(), json!(sc.shift));
        out.insert("latency_frames".into(), json!(sc.latency_frames(a.cfg.hop() as u32)));
        println!("{}: streaming (--preset {}, dec_future {}, shift {}) vs exact (Bailando, {}) on {}", model_path.display(), args.budget.preset, sc.dec_future, sc.shift, ra.path, music.display());
        return print_json(out, args);
    };
    if matches!(args.mode, Mode::Streaming) {
        bail!("{} is a Bailando model: --against compares two models in exact mode (S against R: leave out --against)", model_path.display());
    }
    let b_file = open(b_path)?;
    let b_duo = b_file.duo()?;
    let b = BModel::from_duo(&b_duo).map_err(|e| anyhow::anyhow!("{}: {}", b_path.display(), crate::engine_errors::describe_bind(&e)))?;
    if a.cfg != b.cfg {
        bail!("{} and {} have different configs; compare conversions of the same checkpoint", model_path.display(), b_path.display());
    }
    let run = |m: &BModel<'_>, p: &std::path::Path| bailando_exact(m, music, dance, seed, p);
    let (ra, rb) = (run(&a, model_path)?, run(&b, b_path)?);
    let (all, per, steps) = crate::agreement::free_run_of(&ra.tokens, &rb.tokens, 2);
    let (mean, max, frames) = crate::agreement::joint_error_mm_of(&ra.pos3d, &rb.pos3d, duolando_core::bailando::config::N_JOINTS);
    let mut out = Map::new();
    out.insert("free_run_agreement".into(), json!(all));
    out.insert("free_run_agreement_up".into(), json!(per[0]));
    out.insert("free_run_agreement_down".into(), json!(per[1]));
    out.insert("free_run_steps".into(), json!(steps));
    out.insert("mean_joint_err_mm".into(), json!(mean));
    out.insert("max_joint_err_mm".into(), json!(max));
    out.insert("joint_err_frames".into(), json!(frames));
    println!("{} vs {} (Bailando, exact mode, {}) on {}", model_path.display(), b_path.display(), ra.path, music.display());
    print_json(out, args)
}

fn print_json(out: Map<String, Value>, args: &Args) -> Result<()> {
    for (k, v) in &out {
        println!("  {k:<28} {v}");
    }
    if let Some(p) = &args.json {
        std::fs::write(p, serde_json::to_string_pretty(&Value::Object(out))? + "\n").with_context(|| format!("cannot write {}", p.display()))?;
        eprintln!("wrote {}", p.display());
    }
    Ok(())
}

/// One-step agreement of S's window schedule: at every step `k`, the
/// greedy choice of the GPT over the window S uses (`window_context(k, m,
/// shift)`; S computes exactly this window, tests/bailando_session.rs)
/// fed R's own history, against R's token `k + 1` (both heads).
fn solo_one_step(m: &duolando_core::bailando::model::Model<'_>, r_tokens: &[u32], shift: usize, music_path: &std::path::Path) -> Result<f64> {
    use duolando_core::bailando::gpt::{logits_len, max_context, window_logits, GptScratch};
    let cfg = &m.cfg;
    let nm = cfg.gpt.n_music as usize;
    let music = read_f32_2d(music_path, None, "music features")?;
    let rows = music.rows;
    let win = max_context(cfg);
    let mut bytes = vec![0u8; duolando_core::bailando::exact::sample_scratch_bytes(cfg).context("config too large")?];
    let mut a = duolando_core::arena::Arena::new(&mut bytes);
    let mut gs = GptScratch::carve(&mut a, cfg, win).map_err(|e| anyhow::anyhow!("scratch: {e:?}"))?;
    let mut logits = vec![0f32; logits_len(cfg)];
    let vu = cfg.gpt.vocab[0] as usize;
    let n = r_tokens.len() / 2;
    let (mut same, mut total) = (0usize, 0usize);
    let mut mus = Vec::with_capacity(win * nm);
    for k in 0..n.saturating_sub(1) {
        let c = duolando_core::nn::window::window_context(k, win, shift);
        let lo = k + 1 - c;
        mus.clear();
        for j in lo..=k {
            let r = (j + 1).min(rows - 1);
            mus.extend_from_slice(&music.data[r * music.cols..r * music.cols + nm]);
        }
        window_logits(m, &r_tokens[2 * lo..2 * (k + 1)], &mus, &mut gs, &mut logits).map_err(|e| anyhow::anyhow!("{}", describe(&e)))?;
        let pred = [duolando_core::nn::sampler::argmax(&logits[..vu]), duolando_core::nn::sampler::argmax(&logits[vu..])];
        same += (0..2).filter(|&h| pred[h] == r_tokens[2 * (k + 1) + h]).count();
        total += 2;
    }
    Ok(if total == 0 { 1.0 } else { same as f64 / total as f64 })
}
