//! `duolando dance`: one command from a leader clip and music to a watchable
//! result. Runs R mode (the authors' evaluation pipeline; with `--topk K` a
//! streaming session that samples instead) and writes, into
//! `--out DIR`, the browser viewer `index.html`, `follower.glb` (both
//! dancers), `leader.bvh`, `follower.bvh`, npy arrays and `summary.json`.
//! See docs/CLI.md for every flag, default and file.
//!
//! With no `--leader`, `--music` or `--model`, it dances the bundled demo
//! clip with the bundled demo model (`assets/`, found under the current
//! directory, then under the workspace the binary was compiled in), and
//! then the bundled solo dancer (a Bailando model) to its music into
//! `DIR/solo/`; the two pages link to each other.

pub mod inputs;
pub mod leader_bvh;
pub mod solo;
pub mod transflower;

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, Context, Result};
use duolando_core::duolando::config::{ModelConfig, POSE_DIM, ROT_DIM};
use duolando_core::duolando::exact::{self, Seed};
use duolando_core::duolando::model::Model;
use duolando_core::duolando::session::{Preset, Sampling, SessionConfig};
use serde_json::json;

use self::inputs::{Leader, Music, SeedChoice};
use crate::cli::generate::{generate_exact, generate_streaming, seed_tokens, Generated};
use crate::npy::read_f32_2d;
use crate::export::{as_frames, write_all, GroupErrors, Motion};
use crate::skeleton::body::{interpenetration, radius_scale, CLOSE_PELVIS_M};
use crate::skeleton::retarget::measure_skeleton;
use crate::skeleton::Skeleton;
use crate::model_file::ModelFile;
use crate::npy::write_f32;
use crate::viewer::{write_index_html, ViewerData, ViewerLink};

pub use inputs::{find_asset, face_to_face_start, COMPILED_ASSETS, DEFAULT_SEED_DISTANCE_M};

/// Flags of `duolando dance`.
#[derive(clap::Args, Debug)]
#[command(group(clap::ArgGroup::new("sampling").multiple(true).args(["topk", "temperature"])))]
pub struct Args {
    /// Leader motion: (T, 165) float .npy (world joint positions, metres, 30 fps) or a 30 fps .bvh
    /// with the SMPL-X joint names. Default: the bundled demo clip.
    #[arg(long, requires = "music")]
    pub leader: Option<PathBuf>,
    /// Music: an audio file (WAV, MP3, OGG Vorbis, FLAC) or (T, 54) features .npy at 30 fps.
    /// Default: the bundled demo clip's music. Without --leader: a solo dance to this music by a
    /// Bailando model (default assets/bailando_demo.duo; features .npy (R, 438) at 7.5 rows/s).
    #[arg(long)]
    pub music: Option<PathBuf>,
    /// The `.duo` model. Default: assets/demo.duo.
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// The follower's first frames, (F, 165) float .npy, F >= 4.
    #[arg(long, conflicts_with = "seed_tokens")]
    pub follower_start: Option<PathBuf>,
    /// Seed tokens "up,down,lhand,rhand,transl" instead of start frames ("up,down" for a solo dance).
    #[arg(long)]
    pub seed_tokens: Option<String>,
    /// Output directory (created; existing files of the same names are replaced).
    #[arg(long, short)]
    pub out: PathBuf,
    /// Where the follower's rotations in follower.glb / follower.bvh / follower_rotmat.npy come from:
    /// `fitted` (default) fits them to the decoded positions the viewer shows, one length per bone;
    /// `decoder` uses the model's rotation decoder (projected to rotations), which can disagree
    /// with the positions.
    #[arg(long, value_enum, default_value_t = FollowerRotations::Fitted)]
    pub follower_rotations: FollowerRotations,
    /// The true follower of the same take, (T', 165) float .npy with T' >= the duet's frames (world
    /// positions, frame-aligned with the leader), e.g. from `duolando synth`: its interpenetration with
    /// the leader is reported next to the model's in summary.json.
    #[arg(long)]
    pub true_follower: Option<PathBuf>,
    /// Threads the large matrix products are split over (the output does not
    /// depend on it). Default: every core, at most 8.
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=64))]
    pub threads: Option<u32>,
    /// Duet or solo (Bailando): sample each token uniformly among the K most
    /// probable (the authors' `samplek`) in a streaming session at the
    /// reference preset, instead of R's greedy evaluation: a livelier dancer
    /// that jitters more (docs/DEMO_MODEL.md "Sampling instead of greedy
    /// decoding"). Not for Transflower (it samples already: --seed).
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..))]
    pub topk: Option<u32>,
    /// Duet or solo: sample each token with its probability under
    /// softmax(logits / T) among the --topk best (64 without --topk), in
    /// the same streaming session: the likely tokens most of the time, a
    /// near-equal one as often as the model rates it (T: 0.001..=100;
    /// docs/DEMO_MODEL.md "Tempered sampling").
    #[arg(long)]
    pub temperature: Option<f32>,
    /// Seed of --topk's or --temperature's sampling (the same seed gives
    /// the same dance).
    #[arg(long, requires = "sampling")]
    pub rng_seed: Option<u64>,
    /// Transflower: seed of the engine's base-sample RNG (default 0).
    #[arg(long)]
    pub seed: Option<u64>,
    /// Transflower: the audio features' scaler (the authors'
    /// `audio_feats_scaled_20_scaler.pkl` through tools/transflower_scalers.py, 85 columns).
    #[arg(long)]
    pub audio_scaler: Option<PathBuf>,
    /// Transflower: madmom's downbeat networks (converted from a madmom
    /// install by tools/madmom_weights.py) for the audio's beat/downbeat
    /// columns, as the authors computed them; without it the engine's beat
    /// tracker stands in.
    #[arg(long, value_name = "NETWORKS")]
    pub madmom: Option<PathBuf>,
    /// Transflower: the motion features' scaler; with it the dancer is placed
    /// on a skeleton (glb, bvh, viewer), as `generate --scaler`.
    #[arg(long)]
    pub scaler: Option<PathBuf>,
    /// Transflower: the motion seed, (T, C) float32 scaled features, T >= the
    /// model's motion window. Default: zeros (the mean pose).
    #[arg(long)]
    pub motion_seed: Option<PathBuf>,
}

/// Where the exported follower's rotations come from (`--follower-rotations`).
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum FollowerRotations {
    /// Fitted to the decoded positions (what the viewer shows) on a rigid rig
    /// with the clip's median bone lengths.
    Fitted,
    /// The rotation decoder's output, projected to the nearest rotations.
    Decoder,
}

impl FollowerRotations {
    fn name(self) -> &'static str {
        match self {
            FollowerRotations::Fitted => "fitted",
            FollowerRotations::Decoder => "decoder",
        }
    }
}

/// An export farther than this (metres, worst joint) from the positions the
/// viewer shows is pointed out on stderr.
const FIT_WARN_M: f32 = 0.05;

/// The sampling rule of `--topk`, `--temperature` and `--rng-seed`
/// ([`crate::cli::budget::sampling`]); None (R's greedy evaluation)
/// without the first two (`--rng-seed` alone is a usage error).
fn chosen_sampling(args: &Args) -> Result<Option<Sampling>> {
    crate::cli::budget::sampling(args.topk, args.temperature, args.rng_seed.unwrap_or(0))
}

/// The rule in words, for the stage lines and `summary.json`.
fn describe(s: &Sampling) -> String {
    match *s {
        Sampling::Greedy => "greedy".into(),
        Sampling::TopK { k, rng_seed } => format!("top-{k} sampling, seed {rng_seed}"),
        Sampling::Softmax { k, temperature_milli, rng_seed } => {
            format!("softmax sampling at temperature {} among the {k} best, seed {rng_seed}", temperature_milli as f32 / 1000.0)
        }
    }
}

/// The session of a sampling rule: the reference preset (the model's
/// whole look-ahead and conv futures), `s` as its sampling.
fn sampling_session(cfg: &ModelConfig, s: Sampling, model_path: &Path) -> Result<SessionConfig> {
    let mut sc = SessionConfig::preset(cfg, Preset::Reference);
    sc.sampling = s;
    if let Err((setting, value, max)) = sc.check(cfg) {
        bail!("--{} {value} is outside its range for {} (largest allowed: {max})", crate::cli::budget::flag(setting), model_path.display());
    }
    Ok(sc)
}

/// Prints a numbered stage line on stderr.
fn stage(n: usize, what: &str) {
    eprintln!("[{n}/5] {what}");
}

/// Picks the seed from `args` (see [`inputs::choose_seed`]).
fn choose_seed(args: &Args, demo: bool, leader: &Leader, cfg: &ModelConfig, model: &Path) -> Result<(SeedChoice, String)> {
    inputs::choose_seed(args.seed_tokens.as_deref(), args.follower_start.as_deref(), demo, leader, cfg, model)
}

/// Checks that the leader and music are long enough and cover each other.
fn check_lengths(cfg: &ModelConfig, leader: &Leader, leader_path: &Path, music: &Music, music_path: &Path, model: &Path) -> Result<exact::OutputShape> {
    let need = cfg.music_motion_rate as usize + cfg.gpt.music.downsample_rate as usize * (cfg.gpt.look_forward as usize + 1);
    let shape = exact::output_shape(cfg, leader.frames).filter(|s| s.steps > 0);
    let Some(shape) = shape else {
        bail!(
            "{}: the leader clip has {} frames ({:.1} s at 30 fps); the model {} needs at least {need} frames ({:.1} s)",
            leader_path.display(),
            leader.frames,
            leader.frames as f64 / 30.0,
            model.display(),
            need as f64 / 30.0
        );
    };
    if music.frames < shape.frames_in {
        bail!(
            "{}: the music has {} frames ({:.1} s at 30 fps) but the leader {} has {} ({} used); the music must cover the whole dance",
            music_path.display(),
            music.frames,
            music.frames as f64 / 30.0,
            leader_path.display(),
            leader.frames,
            shape.frames_in
        );
    }
    Ok(shape)
}

/// Music shorter than the leader clip: the dance ends with the music, so the
/// leader is cut to the music's length (a note says so) instead of refused.
/// Whether what is left is long enough is [`check_lengths`]'s question.
fn cut_leader_to_music(leader: &mut Leader, leader_path: &Path, music: &Music, music_path: &Path) {
    if music.frames >= leader.frames {
        return;
    }
    eprintln!(
        "      note: the music {} has {} frames ({:.1} s), the leader {} has {} ({:.1} s): the leader is cut to the music",
        music_path.display(),
        music.frames,
        music.frames as f64 / 30.0,
        leader_path.display(),
        leader.frames,
        leader.frames as f64 / 30.0
    );
    leader.frames = music.frames;
    leader.pos3d.truncate(music.frames * POSE_DIM);
}

/// Copies the audio next to the viewer as `music.<ext>`; returns the name.
pub(crate) fn copy_audio(src: &Path, dir: &Path) -> Result<String> {
    let ext: String = inputs::extension(src).chars().filter(char::is_ascii_alphanumeric).collect();
    let name = if ext.is_empty() { "music".to_string() } else { format!("music.{ext}") };
    let dst = dir.join(&name);
    let same = std::fs::canonicalize(src).ok().zip(std::fs::canonicalize(&dst).ok()).is_some_and(|(a, b)| a == b);
    if !same {
        std::fs::copy(src, &dst).with_context(|| format!("cannot copy {} to {}", src.display(), dst.display()))?;
    }
    Ok(name)
}

/// Distinct token ids per stream (up, down, lhand, rhand, transl).
fn distinct_tokens(g: &Generated) -> Vec<usize> {
    (0..5)
        .map(|c| {
            let mut v: Vec<u32> = g.tokens.iter().skip(c).step_by(5).copied().collect();
            v.sort_unstable();
            v.dedup();
            v.len()
        })
        .collect()
}

pub fn run(args: Args) -> Result<()> {
    let t_all = Instant::now();
    if args.model.as_deref().is_some_and(transflower::is_transflower) {
        let threads = args.threads.map_or_else(crate::workers::default_threads, |n| n as usize);
        crate::workers::set_threads(threads).with_context(|| format!("starting {threads} threads"))?;
        return transflower::run(&args);
    }
    transflower::refuse_flags(&args)?;
    if args.leader.is_none() && args.music.is_some() {
        // Music without a leader: a solo dancer.
        let (model_path, demo_model) = match &args.model {
            Some(m) => (m.clone(), false),
            None => (inputs::require_asset(solo::DEMO_SOLO_MODEL, "solo (Bailando) model")?, true),
        };
        let threads = args.threads.map_or_else(crate::workers::default_threads, |n| n as usize);
        crate::workers::set_threads(threads).with_context(|| format!("starting {threads} threads"))?;
        return solo::run(&args, &model_path, demo_model, threads, t_all, None);
    }
    let demo = args.leader.is_none();
    // No inputs and no model: the bundled duet, then the bundled solo
    // dancer (both demos in one command; a missing solo asset skips it).
    let solo_demo = (demo && args.model.is_none()).then(solo_demo_inputs).flatten();
    let model_path = match &args.model {
        Some(m) => m.clone(),
        None => inputs::require_asset(inputs::DEMO_MODEL, "model")?,
    };
    let (leader_path, music_path) = match (&args.leader, &args.music) {
        (Some(l), Some(m)) => (l.clone(), m.clone()),
        _ => (
            inputs::require_asset(inputs::DEMO_LEADER, "leader clip")?,
            inputs::require_asset(inputs::DEMO_MUSIC, "music features")?,
        ),
    };

    let threads = args.threads.map_or_else(crate::workers::default_threads, |n| n as usize);
    crate::workers::set_threads(threads).with_context(|| format!("starting {threads} threads"))?;
    stage(1, &format!("model {}, {threads} thread(s)", model_path.display()));
    let t = Instant::now();
    let file = ModelFile::open(&model_path)?;
    super::print_kernels();
    let duo = file.duo()?;
    let model = Model::from_duo(&duo)
        .map_err(|e| anyhow::anyhow!("{}: {}", model_path.display(), crate::engine_errors::describe_bind(&e)))?;
    let cfg = model.cfg;
    let t_model = t.elapsed().as_secs_f64();

    stage(2, &format!("inputs: leader {}, music {}", leader_path.display(), music_path.display()));
    let t = Instant::now();
    let mut leader = inputs::load_leader(&leader_path)?;
    let music = inputs::load_music(&music_path, cfg.gpt.music.n_in as usize, &model_path)?;
    cut_leader_to_music(&mut leader, &leader_path, &music, &music_path);
    let shape = check_lengths(&cfg, &leader, &leader_path, &music, &music_path, &model_path)?;
    let (seed, seed_text) = choose_seed(&args, demo, &leader, &cfg, &model_path)?;
    // Read before generating, so that a bad file fails before any output.
    let true_follower = match &args.true_follower {
        None => None,
        Some(path) => {
            let a = read_f32_2d(path, Some(POSE_DIM), "true follower joint positions (T, 165), metres, 30 fps")?;
            if let Some(i) = a.data.iter().position(|v| !v.is_finite()) {
                bail!("{}: true follower[{}, {}] is not finite; expected finite positions", path.display(), i / POSE_DIM, i % POSE_DIM);
            }
            Some((path.clone(), a))
        }
    };
    eprintln!(
        "      leader {} frames ({}), music {} frames{}; seed: {seed_text}",
        leader.frames,
        leader.source,
        music.frames,
        music.tempo_bpm.map(|b| format!(" (audio, {b:.1} BPM)")).unwrap_or_default()
    );
    let t_inputs = t.elapsed().as_secs_f64();

    let seed_ref = match &seed {
        SeedChoice::Tokens(t) => Seed::Tokens(*t),
        SeedChoice::Frames(f) => Seed::FollowerFrames(f),
    };
    let sampled = match chosen_sampling(&args)? {
        None => None,
        Some(s) => Some((sampling_session(&cfg, s, &model_path)?, s)),
    };
    let mode = match &sampled {
        None => "R mode, whole clip".to_string(),
        Some((_, s)) => format!("S mode at the reference preset, {}", describe(s)),
    };
    stage(3, &format!("generating {} steps ({mode})", shape.steps));
    let t = Instant::now();
    let g = match &sampled {
        None => generate_exact(&model, &leader.pos3d, &music.features, seed_ref)?,
        Some((sc, _)) => {
            let t4 = leader.frames / cfg.hop() * cfg.hop();
            let tokens = seed_tokens(&model, seed_ref, &leader.pos3d[..t4 * POSE_DIM])?;
            generate_streaming(&model, &leader.pos3d[..t4 * POSE_DIM], &music.features, sc, tokens, true)?
        }
    };
    let t_generate = t.elapsed().as_secs_f64();

    stage(4, "exporting glTF, BVH and npy");
    let t = Instant::now();
    let dir = &args.out;
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create the output directory {}", dir.display()))?;
    // The duet is as long as the follower: the leader's last frames were
    // look-ahead only (no follower token is generated for them).
    let duet = g.frames.min(leader.frames);
    if let Some((path, a)) = &true_follower {
        if a.rows < duet {
            bail!("{}: the true follower has {} frames; expected at least the duet's {duet}", path.display(), a.rows);
        }
    }
    let leader_duet = &leader.pos3d[..duet * POSE_DIM];
    let leader_motion = Motion::from_positions(leader_duet, &format!("leader {}", leader_path.display()))?;
    let follower_motion = match args.follower_rotations {
        FollowerRotations::Fitted => Motion::from_positions(&g.follower_pos3d, "generated follower")?,
        FollowerRotations::Decoder => Motion::from_decoded(&g.follower_pos3d, Some(&g.follower_rotmat), "generated follower")?,
    };
    // How far each exported rig (FK of the glb/bvh rotations) lands from the
    // positions the viewer shows.
    let leader_err = GroupErrors::between(&leader_motion.positions, leader_duet);
    let follower_err = GroupErrors::between(&follower_motion.positions, &g.follower_pos3d);
    write_all(dir, Some(&leader_motion), &follower_motion)?;
    // The npy files hold the model's own outputs and the leader as given;
    // the rotmat files hold the proper rotations the glb/bvh use.
    write_f32(&dir.join("leader_pos3d.npy"), leader_duet, &[duet, POSE_DIM])?;
    write_f32(&dir.join("follower_pos3d.npy"), &g.follower_pos3d, &[g.frames, POSE_DIM])?;
    write_f32(&dir.join("follower_rotmat_raw.npy"), &g.follower_rotmat, &[g.frames, ROT_DIM])?;
    let tokens: Vec<i64> = g.tokens.iter().map(|&t| t as i64).collect();
    crate::npy::write_i64(&dir.join("tokens.npy"), &tokens, &[g.token_rows, 5])?;
    for (who, err) in [("leader", &leader_err), ("follower", &follower_err)] {
        if err.all.max > FIT_WARN_M {
            let why = if who == "follower" && args.follower_rotations == FollowerRotations::Decoder {
                "its rotations come from the rotation decoder (--follower-rotations decoder); the default `fitted` follows the positions"
            } else {
                "the rig keeps one length per bone, and the positions stretch or shrink bones from frame to frame"
            };
            eprintln!(
                "      note: the {who} in follower.glb / {who}.bvh is {:.3} m from its positions on average, up to {:.2} m ({why}); \
                 index.html and {who}_pos3d.npy show the positions themselves",
                err.all.mean, err.all.max
            );
        }
    }
    // How much the bodies interpenetrate (docs/DEMO_MODEL.md): the model's
    // follower, as the viewer shows it, and the true follower when given.
    let rig_scale = |pos: &[f32]| radius_scale(&measure_skeleton(&Skeleton::default(), &as_frames(pos)));
    let leader_scale = radius_scale(&leader_motion.skeleton);
    let contact = interpenetration(leader_duet, &g.follower_pos3d, leader_scale, rig_scale(&g.follower_pos3d));
    let true_contact = match &true_follower {
        None => None,
        Some((path, a)) => {
            let truth = &a.data[..duet * POSE_DIM];
            Some((path.display().to_string(), interpenetration(leader_duet, truth, leader_scale, rig_scale(truth))))
        }
    };
    eprintln!(
        "      bodies: pelvis distance min {:.2} m, under {CLOSE_PELVIS_M} m in {:.1} % of frames; capsules overlap: trunk/head {:.0} % of frames (deepest {:.2} m), with legs {:.0} % ({:.2} m){}",
        contact.pelvis_distance_m.min,
        100.0 * contact.frames_pelvis_under_0_25_m,
        100.0 * contact.trunk_capsules.frames_overlapping,
        contact.trunk_capsules.depth_max_m,
        100.0 * contact.body_capsules.frames_overlapping,
        contact.body_capsules.depth_max_m,
        true_contact.as_ref().map_or(String::new(), |(_, c)| format!(
            "; true follower: min {:.2} m, {:.1} %; {:.0} % ({:.2} m), {:.0} % ({:.2} m)",
            c.pelvis_distance_m.min,
            100.0 * c.frames_pelvis_under_0_25_m,
            100.0 * c.trunk_capsules.frames_overlapping,
            c.trunk_capsules.depth_max_m,
            100.0 * c.body_capsules.frames_overlapping,
            c.body_capsules.depth_max_m
        ))
    );
    let t_export = t.elapsed().as_secs_f64();

    stage(5, "writing the viewer and summary");
    let t = Instant::now();
    let audio_name = music.audio.as_deref().map(|a| copy_audio(a, dir)).transpose()?;
    let beats: Option<Vec<f32>> = (music.cols > crate::music::BEAT_COL).then(|| {
        (0..duet)
            .map(|f| if f < music.frames { music.features[f * music.cols + crate::music::BEAT_COL] } else { 0.0 })
            .collect()
    });
    let title = format!(
        "duolando: {} + {}",
        leader_path.file_name().map(|n| n.to_string_lossy()).unwrap_or_default(),
        music_path.file_name().map(|n| n.to_string_lossy()).unwrap_or_default()
    );
    let page = write_index_html(
        dir,
        &ViewerData {
            title: &title,
            fps: 30.0,
            leader_pos3d: Some(leader_duet),
            follower_pos3d: &g.follower_pos3d,
            beats: beats.as_deref(),
            tokens: Some(&g.tokens),
            audio_file: audio_name.as_deref(),
            see_also: solo_demo.as_ref().map(|_| ViewerLink { href: "solo/index.html", text: "the solo dancer (Bailando) \u{2192}" }),
        },
    )
    .with_context(|| format!("cannot write the viewer into {}", dir.display()))?;
    let t_viewer = t.elapsed().as_secs_f64();

    let mut files = vec![
        "index.html", "follower.glb", "leader.bvh", "follower.bvh", "leader_pos3d.npy", "leader_rotmat.npy",
        "follower_pos3d.npy", "follower_rotmat.npy", "follower_rotmat_raw.npy", "tokens.npy", "summary.json",
    ]
    .into_iter()
    .map(String::from)
    .collect::<Vec<_>>();
    files.extend(audio_name.clone());
    if solo_demo.is_some() {
        files.push(format!("{SOLO_DIR}/"));
    }
    let summary = json!({
        "model": model_path.display().to_string(),
        "solo": solo_demo.as_ref().map(|_| format!("{SOLO_DIR}/summary.json")),
        "mode": match &sampled { None => "exact (R)".to_string(), Some(_) => format!("streaming ({mode})") },
        "kernels": crate::simd::describe(),
        "threads": threads,
        "fps": 30,
        "leader": {
            "file": leader_path.display().to_string(),
            "source": leader.source,
            "frames": leader.frames,
            "frames_in_outputs": duet,
        },
        "music": {
            "file": music_path.display().to_string(),
            "frames": music.frames,
            "audio": audio_name,
            "tempo_bpm": music.tempo_bpm,
        },
        "seed": seed_text,
        "frames_used": shape.frames_in,
        "steps": shape.steps,
        "token_rows": g.token_rows,
        "follower_frames": g.frames,
        "seconds": g.frames as f64 / 30.0,
        "distinct_tokens": { "up_down_lhand_rhand_transl": distinct_tokens(&g) },
        "follower_rotations": args.follower_rotations.name(),
        "fit_error_m": { "leader": leader_motion.fit_error_m, "follower": follower_motion.fit_error_m },
        "export_error_m": { "leader": leader_err, "follower": follower_err },
        "interpenetration": {
            "follower": contact,
            "true_follower": true_contact.as_ref().map(|(f, c)| json!({"file": f, "measure": c})),
        },
        "timings_s": {
            "model": t_model, "inputs": t_inputs, "generate": t_generate, "export": t_export, "viewer": t_viewer,
            "total": t_all.elapsed().as_secs_f64(),
        },
        "files": files,
    });
    let summary_path = dir.join("summary.json");
    std::fs::write(&summary_path, serde_json::to_string_pretty(&summary)? + "\n")
        .with_context(|| format!("cannot write {}", summary_path.display()))?;

    eprintln!(
        "done in {:.1} s: {} follower frames ({:.1} s) from {} leader frames, {} token rows (generation {:.1} s)",
        t_all.elapsed().as_secs_f64(),
        g.frames,
        g.frames as f64 / 30.0,
        leader.frames,
        g.token_rows,
        t_generate
    );
    eprintln!("wrote {}: {}", dir.display(), files.join(", "));
    eprintln!("open the viewer: {} (double-click it, or `xdg-open {0}` / `chromium {0}`)", page.display());
    if let Some((model, music)) = solo_demo {
        let solo_dir = dir.join(SOLO_DIR);
        eprintln!("\nthe bundled solo dancer (Bailando) to {} into {}:", music.display(), solo_dir.display());
        let solo_args = Args {
            leader: None,
            music: Some(music),
            model: None,
            follower_start: None,
            seed_tokens: None,
            out: solo_dir,
            follower_rotations: FollowerRotations::Fitted,
            true_follower: None,
            threads: args.threads,
            topk: None,
            temperature: None,
            rng_seed: None,
            seed: None,
            audio_scaler: None,
            madmom: None,
            scaler: None,
            motion_seed: None,
        };
        let back = ViewerLink { href: "../index.html", text: "\u{2190} the duet (Duolando)" };
        solo::run(&solo_args, &model, true, threads, Instant::now(), Some(back))?;
    }
    Ok(())
}

/// Where the bare demo (`dance --out DIR`) writes its solo dancer: `DIR/solo/`.
pub const SOLO_DIR: &str = "solo";

/// The bundled solo model and its music, when both are there (else a note:
/// the duet is the demo's main job, and it runs without them).
fn solo_demo_inputs() -> Option<(PathBuf, PathBuf)> {
    match (inputs::find_asset(solo::DEMO_SOLO_MODEL), inputs::find_asset(solo::DEMO_SOLO_MUSIC)) {
        (Ok(model), Ok(music)) => Some((model, music)),
        _ => {
            eprintln!(
                "      note: assets/{} or assets/{} is missing: the demo's solo dancer is skipped",
                solo::DEMO_SOLO_MODEL,
                solo::DEMO_SOLO_MUSIC
            );
            None
        }
    }
}
