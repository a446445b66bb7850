//! R mode (DESIGN.md §3 R): the authors' evaluation pipeline reproduced
//! token for token (gpt2t.py `eval`, GPT2nt `sample` with `shift=None`,
//! the test loader of datasets/dd100lf_all2.py), greedy.
//!
//! 1. Truncate to `T4 = T - T % hop` frames (the loader's `seq_len//4*4`).
//! 2. Normalise the leader ([`crate::duolando::motion`]) and encode each part over the
//!    whole sequence -> leader tokens `(T4/hop)` per part.
//! 3. Seed: 5 tokens, or the follower's first frames: body tokens = code 0
//!    of encoding the first `hop` frames; translation token = code 0 of
//!    encoding `20 * (root_f - root_l)` over all given frames (pass the
//!    whole follower sequence to match the authors' eval exactly).
//! 4. `K = (T4 - music_motion_rate) // ds - look_forward` steps. Step k:
//!    context `c = min(k+1, block_size-1)`, window start `w = k+1-c`;
//!    follower tokens `[w, k+1)`, music frames `music_motion_rate +
//!    [w*ds, (k+1+lf)*ds)`, leader tokens `[w, k+1+lf)`; everything in the
//!    window is recomputed; argmax of each head is appended.
//! 5. Decode all K+1 tokens per part and the translation; follower root =
//!    `(root_l - root_l[0]) + transl / 20`; hands and joints de-normalised;
//!    finally every joint `+ root_l[0]` (the leader's input coordinates).

use crate::arena::{Arena, ArenaError, Carve, Planner};
use crate::duolando::config::{ModelConfig, Part, POSE_DIM, ROT_DIM};
use crate::duolando::gpt::{head_rows, logits_len, max_context, window_logits, GptScratch, Window};
use crate::duolando::model::Model;
use crate::duolando::motion::{denormalise, gather_part, normalise, scatter_part};
use crate::duolando::vq_decoder::{decode, Output};
use crate::duolando::vq_encoder::encode;
use crate::error::{check_at_least, check_len, Buffer, Error};
use crate::input;
use crate::nn::conv_stack::ConvScratch;
use crate::nn::sampler::argmax;

/// Follower tokens per row: up, down, lhand, rhand, transl.
pub const TOKEN_COLUMNS: usize = 5;
/// Scale of the relative translation fed to the translation VQ-VAE.
pub const TRANSL_SCALE: f32 = 20.0;

/// How the follower starts.
#[derive(Clone, Copy, Debug)]
pub enum Seed<'x> {
    /// Tokens up, down, lhand, rhand, transl.
    Tokens([u32; 5]),
    /// Raw follower frames (F, 165), F >= hop and F <= T (see module doc).
    FollowerFrames(&'x [f32]),
}

/// Inputs of [`generate`].
#[derive(Clone, Copy, Debug)]
pub struct ExactInputs<'x> {
    /// Leader joints (T, 165), world coordinates, 30 fps.
    pub leader_pos3d: &'x [f32],
    /// Music features (>= T4 rows, n_music); rows past T4 are ignored.
    pub music: &'x [f32],
    pub seed: Seed<'x>,
}

/// Caller buffers [`generate`] fills (sizes from [`output_shape`]).
#[derive(Debug)]
pub struct ExactOutputs<'o> {
    /// (K+1, 5): row 0 = seed, columns up, down, lhand, rhand, transl.
    pub tokens: &'o mut [u32],
    /// (hop*(K+1), 165) absolute joints in the leader's input coordinates.
    pub follower_pos3d: &'o mut [f32],
    /// (hop*(K+1), 495) raw rotation-decoder output (55 row-major 3x3).
    pub follower_rotmat: &'o mut [f32],
    /// Optional (T4/hop, 4) leader tokens (up, down, lhand, rhand).
    pub leader_tokens: Option<&'o mut [u32]>,
}

/// Sizes of one R-mode run over `T` input frames.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct OutputShape {
    /// Frames used (`T4`).
    pub frames_in: usize,
    /// Leader tokens per part (`T4 / hop`).
    pub leader_tokens: usize,
    /// Generation steps `K`.
    pub steps: usize,
    /// Token rows `K + 1`.
    pub token_rows: usize,
    /// Output frames `hop * (K + 1)`.
    pub frames_out: usize,
}

/// What a run did.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ExactSummary {
    pub shape: OutputShape,
    /// Peak scratch bytes used (<= [`scratch_bytes`]).
    pub scratch_used: usize,
}

/// Output sizes for `t_frames` input frames; None if fewer than one hop.
pub fn output_shape(cfg: &ModelConfig, t_frames: usize) -> Option<OutputShape> {
    let hop = cfg.hop();
    let t4 = t_frames / hop * hop;
    if t4 < hop {
        return None;
    }
    let ds = cfg.gpt.music.downsample_rate as usize;
    let mmr = cfg.music_motion_rate as usize;
    let steps = (t4.saturating_sub(mmr) / ds).saturating_sub(cfg.gpt.look_forward as usize);
    Some(OutputShape {
        frames_in: t4,
        leader_tokens: t4 / hop,
        steps,
        token_rows: steps + 1,
        frames_out: hop * (steps + 1),
    })
}

/// Widest part input (3J) and codebook row over every VQ-VAE.
fn widths(cfg: &ModelConfig) -> (usize, usize, usize) {
    let mut pos = 3usize;
    let mut rot = 0usize;
    let mut emb = 0usize;
    for vq in cfg.parts.iter().chain(core::iter::once(&cfg.transl)) {
        pos = pos.max(vq.in_channels as usize);
        rot = rot.max(vq.rot_channels as usize);
        emb = emb.max(vq.emb_width as usize);
    }
    (pos, rot, emb)
}

/// Kept for the whole run.
struct Persistent<'s> {
    /// (4, T4/hop) leader tokens, part-major.
    leader: &'s mut [u32],
}

impl<'s> Persistent<'s> {
    fn carve<A: Carve<'s>>(a: &mut A, sh: &OutputShape) -> Result<Self, ArenaError> {
        Ok(Persistent {
            leader: a.u32(
                sh.leader_tokens
                    .checked_mul(4)
                    .ok_or(ArenaError::Overflow)?,
            )?,
        })
    }
}

/// Phase 1: normalisation and encoding.
struct EncodePhase<'s> {
    /// (T4, 165) normalised poses.
    norm: &'s mut [f32],
    /// (T4, max in_channels) one part's input.
    part: &'s mut [f32],
    /// (T4/hop, max emb) features.
    feat: &'s mut [f32],
    /// (T4/hop) codes.
    codes: &'s mut [u32],
    conv: ConvScratch<'s>,
}

impl<'s> EncodePhase<'s> {
    fn carve<A: Carve<'s>>(
        a: &mut A,
        cfg: &ModelConfig,
        sh: &OutputShape,
    ) -> Result<Self, ArenaError> {
        let (pos, _, emb) = widths(cfg);
        let ov = ArenaError::Overflow;
        let t = sh.frames_in;
        Ok(EncodePhase {
            norm: a.f32(t.checked_mul(POSE_DIM).ok_or(ov)?)?,
            part: a.f32(t.checked_mul(pos).ok_or(ov)?)?,
            feat: a.f32(sh.leader_tokens.checked_mul(emb).ok_or(ov)?)?,
            codes: a.u32(sh.leader_tokens)?,
            conv: ConvScratch::carve(a, &cfg.vqs(), t)?,
        })
    }
}

/// Phase 2: the step loop.
struct StepPhase<'s> {
    gpt: GptScratch<'s>,
    /// (sum of head rows) logits of one step.
    logits: &'s mut [f32],
}

impl<'s> StepPhase<'s> {
    fn carve<A: Carve<'s>>(a: &mut A, cfg: &ModelConfig) -> Result<Self, ArenaError> {
        Ok(StepPhase {
            gpt: GptScratch::carve(a, cfg, max_context(cfg))?,
            logits: a.f32(logits_len(cfg))?,
        })
    }
}

/// Phase 3: decoding.
struct DecodePhase<'s> {
    /// (K+1) one column of tokens.
    codes: &'s mut [u32],
    /// (frames_out, max(in, rot) channels) one decoder's output.
    out: &'s mut [f32],
    /// (frames_out, 3) decoded relative translation.
    transl: &'s mut [f32],
    conv: ConvScratch<'s>,
}

impl<'s> DecodePhase<'s> {
    fn carve<A: Carve<'s>>(
        a: &mut A,
        cfg: &ModelConfig,
        sh: &OutputShape,
    ) -> Result<Self, ArenaError> {
        let (pos, rot, _) = widths(cfg);
        let ov = ArenaError::Overflow;
        let f = sh.frames_out;
        Ok(DecodePhase {
            codes: a.u32(sh.token_rows)?,
            out: a.f32(f.checked_mul(pos.max(rot)).ok_or(ov)?)?,
            transl: a.f32(f.checked_mul(3).ok_or(ov)?)?,
            conv: ConvScratch::carve(a, &cfg.vqs(), f)?,
        })
    }
}

fn plan(cfg: &ModelConfig, sh: &OutputShape) -> Result<(usize, [usize; 3]), ArenaError> {
    let mut p = Planner::new();
    Persistent::carve(&mut p, sh)?;
    let mut phases = [Planner::new(); 3];
    EncodePhase::carve(&mut phases[0], cfg, sh)?;
    StepPhase::carve(&mut phases[1], cfg)?;
    DecodePhase::carve(&mut phases[2], cfg, sh)?;
    Ok((
        p.bytes(),
        [phases[0].bytes(), phases[1].bytes(), phases[2].bytes()],
    ))
}

/// Scratch bytes [`generate`] needs for `t_frames` input frames, for a
/// buffer at any address. None if the config is invalid or sizes overflow.
pub fn scratch_bytes(cfg: &ModelConfig, t_frames: usize) -> Option<usize> {
    cfg.validate().ok()?;
    let sh = output_shape(cfg, t_frames)?;
    let (pers, phases) = plan(cfg, &sh).ok()?;
    let mut total = Planner::new();
    total.add(pers).ok()?;
    total.add(phases.iter().copied().max().unwrap_or(0)).ok()?;
    total.total_for_any_base()
}

fn rows(buffer: Buffer, x: &[f32], row: usize) -> Result<usize, Error> {
    if row == 0 || x.len() % row != 0 {
        return Err(Error::Ragged {
            buffer,
            len: x.len(),
            row,
        });
    }
    Ok(x.len() / row)
}

/// Runs R mode. `scratch` >= [`scratch_bytes`]; `progress(done, total)`
/// is called after every step. Nothing allocates; every length is checked
/// before use; outputs are fully written on success.
pub fn generate(
    model: &Model<'_>,
    inp: &ExactInputs<'_>,
    scratch: &mut [u8],
    out: &mut ExactOutputs<'_>,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<ExactSummary, Error> {
    let cfg = &model.cfg;
    let hop = cfg.hop();
    let t = rows(Buffer::LeaderPos3d, inp.leader_pos3d, POSE_DIM)?;
    let sh = output_shape(cfg, t).ok_or(Error::TooShort {
        buffer: Buffer::LeaderPos3d,
        frames: t,
        min: hop,
    })?;
    let n_music = cfg.gpt.music.n_in as usize;
    let music_frames = rows(Buffer::Music, inp.music, n_music)?;
    if music_frames < sh.frames_in {
        return Err(Error::TooShort {
            buffer: Buffer::Music,
            frames: music_frames,
            min: sh.frames_in,
        });
    }
    let leader = &inp.leader_pos3d[..sh.frames_in * POSE_DIM];
    let music = &inp.music[..sh.frames_in * n_music];
    input::check(Buffer::LeaderPos3d, leader)?;
    input::check(Buffer::Music, music)?;
    check_len(
        Buffer::Tokens,
        out.tokens.len(),
        sh.token_rows * TOKEN_COLUMNS,
    )?;
    check_len(
        Buffer::FollowerPos3d,
        out.follower_pos3d.len(),
        sh.frames_out * POSE_DIM,
    )?;
    check_len(
        Buffer::FollowerRotmat,
        out.follower_rotmat.len(),
        sh.frames_out * ROT_DIM,
    )?;
    if let Some(l) = out.leader_tokens.as_deref() {
        check_len(Buffer::LeaderTokens, l.len(), sh.leader_tokens * 4)?;
    }
    let seed_frames = match inp.seed {
        Seed::Tokens(tok) => {
            let vocab = cfg.gpt.vocab;
            for (j, &v) in tok.iter().enumerate() {
                if v >= vocab[j] {
                    return Err(Error::Token {
                        stream: j as u8,
                        token: v,
                        vocab: vocab[j],
                    });
                }
            }
            0
        }
        Seed::FollowerFrames(f) => {
            let n = rows(Buffer::SeedFrames, f, POSE_DIM)? / hop * hop;
            if n < hop {
                return Err(Error::TooShort {
                    buffer: Buffer::SeedFrames,
                    frames: n,
                    min: hop,
                });
            }
            if n > sh.frames_in {
                return Err(Error::Length {
                    buffer: Buffer::SeedFrames,
                    len: n,
                    expected: sh.frames_in,
                });
            }
            input::check(Buffer::SeedFrames, &f[..n * POSE_DIM])?;
            n
        }
    };

    let mut arena = Arena::new(scratch);
    let pers = Persistent::carve(&mut arena, &sh)?;
    let base_used = arena.used();
    let rest = arena.into_rest();
    let mut peak = base_used;

    // Phase 1: leader tokens and the seed.
    {
        let mut a = Arena::new(&mut *rest);
        let mut ph = EncodePhase::carve(&mut a, cfg, &sh)?;
        peak = peak.max(base_used + a.used());
        encode_leader(
            model,
            leader,
            &sh,
            ph.norm,
            ph.part,
            ph.feat,
            ph.codes,
            &mut ph.conv,
            pers.leader,
        )?;
        let seed = match inp.seed {
            Seed::Tokens(tok) => tok,
            Seed::FollowerFrames(f) => {
                let f = &f[..seed_frames * POSE_DIM];
                encode_seed(
                    model,
                    f,
                    leader,
                    ph.norm,
                    ph.part,
                    ph.feat,
                    ph.codes,
                    &mut ph.conv,
                )?
            }
        };
        out.tokens[..TOKEN_COLUMNS].copy_from_slice(&seed);
        if let Some(l) = out.leader_tokens.as_deref_mut() {
            for i in 0..sh.leader_tokens {
                for p in 0..4 {
                    l[i * 4 + p] = pers.leader[p * sh.leader_tokens + i];
                }
            }
        }
    }

    // Phase 2: the step loop (no allocation inside).
    {
        let mut a = Arena::new(&mut *rest);
        let ph = StepPhase::carve(&mut a, cfg)?;
        peak = peak.max(base_used + a.used());
        run_steps(model, music, pers.leader, &sh, ph, out.tokens, progress)?;
    }

    // Phase 3: decode and de-normalise.
    {
        let mut a = Arena::new(&mut *rest);
        let mut ph = DecodePhase::carve(&mut a, cfg, &sh)?;
        peak = peak.max(base_used + a.used());
        decode_follower(model, leader, &sh, &mut ph, out)?;
    }
    Ok(ExactSummary {
        shape: sh,
        scratch_used: peak,
    })
}

/// Buffers of [`seed_tokens`] for `frames` seed frames.
struct SeedPhase<'s> {
    /// (hop, 165) normalised first frames.
    norm: &'s mut [f32],
    /// (frames, max(in_channels, 3)) one part's input / the relative translation.
    part: &'s mut [f32],
    /// (frames / hop, max emb) features.
    feat: &'s mut [f32],
    /// (frames / hop) codes.
    codes: &'s mut [u32],
    conv: ConvScratch<'s>,
}

impl<'s> SeedPhase<'s> {
    fn carve<A: Carve<'s>>(
        a: &mut A,
        cfg: &ModelConfig,
        frames: usize,
    ) -> Result<Self, ArenaError> {
        let (pos, _, emb) = widths(cfg);
        let ov = ArenaError::Overflow;
        let n = frames / cfg.hop().max(1);
        Ok(SeedPhase {
            norm: a.f32(cfg.hop().checked_mul(POSE_DIM).ok_or(ov)?)?,
            part: a.f32(frames.checked_mul(pos.max(3)).ok_or(ov)?)?,
            feat: a.f32(n.checked_mul(emb).ok_or(ov)?)?,
            codes: a.u32(n)?,
            conv: ConvScratch::carve(a, &cfg.vqs(), frames)?,
        })
    }
}

/// Scratch bytes of [`seed_tokens`] for `frames` seed frames (any base address).
pub fn seed_scratch_bytes(cfg: &ModelConfig, frames: usize) -> Option<usize> {
    let mut p = Planner::new();
    SeedPhase::carve(&mut p, cfg, frames).ok()?;
    p.total_for_any_base()
}

/// The seed tokens R derives from follower frames (module doc, step 3),
/// for callers that seed a streaming session: body tokens from the first
/// `hop` follower frames, the translation token from
/// `20 * (follower root - leader root)` over every given frame.
/// `follower`, `leader`: (F, 165) raw world joints over the same frames,
/// `F` a positive multiple of hop (extra frames are ignored).
pub fn seed_tokens(
    model: &Model<'_>,
    follower: &[f32],
    leader: &[f32],
    scratch: &mut [u8],
) -> Result<[u32; 5], Error> {
    let hop = model.cfg.hop();
    let f = rows(Buffer::SeedFrames, follower, POSE_DIM)? / hop * hop;
    if f < hop {
        return Err(Error::TooShort {
            buffer: Buffer::SeedFrames,
            frames: f,
            min: hop,
        });
    }
    let l = rows(Buffer::LeaderPos3d, leader, POSE_DIM)?;
    if l < f {
        return Err(Error::TooShort {
            buffer: Buffer::LeaderPos3d,
            frames: l,
            min: f,
        });
    }
    let (follower, leader) = (&follower[..f * POSE_DIM], &leader[..f * POSE_DIM]);
    input::check(Buffer::SeedFrames, follower)?;
    input::check(Buffer::LeaderPos3d, leader)?;
    let mut a = Arena::new(scratch);
    let mut ph = SeedPhase::carve(&mut a, &model.cfg, f)?;
    encode_seed(
        model,
        follower,
        leader,
        ph.norm,
        ph.part,
        ph.feat,
        ph.codes,
        &mut ph.conv,
    )
}

/// Step 2 of the module doc: leader codes per part into `leader` (4, n_tok).
#[allow(clippy::too_many_arguments)]
fn encode_leader(
    model: &Model<'_>,
    leader: &[f32],
    sh: &OutputShape,
    norm: &mut [f32],
    part: &mut [f32],
    feat: &mut [f32],
    codes: &mut [u32],
    conv: &mut ConvScratch<'_>,
    out: &mut [u32],
) -> Result<(), Error> {
    let (t, n) = (sh.frames_in, sh.leader_tokens);
    for (raw, o) in leader
        .chunks_exact(POSE_DIM)
        .zip(norm.chunks_exact_mut(POSE_DIM))
    {
        normalise(raw, o);
    }
    for (p, part_id) in Part::ALL.iter().enumerate() {
        let vq = &model.parts[p];
        let w = vq.cfg.in_channels as usize;
        let emb = vq.cfg.emb_width as usize;
        gather_part(*part_id, &norm[..t * POSE_DIM], &mut part[..t * w]);
        encode(
            vq,
            &part[..t * w],
            conv,
            &mut feat[..n * emb],
            &mut codes[..n],
        )?;
        out[p * n..(p + 1) * n].copy_from_slice(&codes[..n]);
    }
    Ok(())
}

/// Step 3 of the module doc, from follower frames `f` (F, 165).
#[allow(clippy::too_many_arguments)]
fn encode_seed(
    model: &Model<'_>,
    f: &[f32],
    leader: &[f32],
    norm: &mut [f32],
    part: &mut [f32],
    feat: &mut [f32],
    codes: &mut [u32],
    conv: &mut ConvScratch<'_>,
) -> Result<[u32; 5], Error> {
    let hop = model.cfg.hop();
    let frames = f.len() / POSE_DIM;
    let mut seed = [0u32; 5];
    for (raw, o) in f[..hop * POSE_DIM]
        .chunks_exact(POSE_DIM)
        .zip(norm.chunks_exact_mut(POSE_DIM))
    {
        normalise(raw, o);
    }
    for (p, part_id) in Part::ALL.iter().enumerate() {
        let vq = &model.parts[p];
        let (w, emb) = (vq.cfg.in_channels as usize, vq.cfg.emb_width as usize);
        gather_part(*part_id, &norm[..hop * POSE_DIM], &mut part[..hop * w]);
        encode(
            vq,
            &part[..hop * w],
            conv,
            &mut feat[..emb],
            &mut codes[..1],
        )?;
        seed[p] = codes[0];
    }
    // Relative translation 20 * (root_f - root_l) over every given frame.
    let tr = &mut part[..frames * 3];
    for i in 0..frames {
        for a in 0..3 {
            tr[i * 3 + a] = (f[i * POSE_DIM + a] - leader[i * POSE_DIM + a]) * TRANSL_SCALE;
        }
    }
    let vq = &model.transl;
    let (n, emb) = (frames / hop, vq.cfg.emb_width as usize);
    encode(vq, tr, conv, &mut feat[..n * emb], &mut codes[..n])?;
    seed[4] = codes[0];
    Ok(seed)
}

/// Step 4 of the module doc: fills token rows 1..=K.
fn run_steps(
    model: &Model<'_>,
    music: &[f32],
    leader: &[u32],
    sh: &OutputShape,
    ph: StepPhase<'_>,
    tokens: &mut [u32],
    progress: &mut dyn FnMut(usize, usize),
) -> Result<(), Error> {
    let cfg = &model.cfg;
    let (ds, lf) = (
        cfg.gpt.music.downsample_rate as usize,
        cfg.gpt.look_forward as usize,
    );
    let mmr = cfg.music_motion_rate as usize;
    let n_music = cfg.gpt.music.n_in as usize;
    let m = max_context(cfg);
    let n = sh.leader_tokens;
    let heads = head_rows(cfg);
    let StepPhase { mut gpt, logits } = ph;
    for k in 0..sh.steps {
        let c = (k + 1).min(m);
        let w = k + 1 - c;
        let end = k + 1 + lf;
        let music_win = &music[(mmr + w * ds) * n_music..(mmr + end * ds) * n_music];
        let lead = |p: usize| &leader[p * n + w..p * n + end];
        let win = Window {
            c,
            music: music_win,
            leader: [lead(0), lead(1), lead(2), lead(3)],
            follower: &tokens[w * TOKEN_COLUMNS..(k + 1) * TOKEN_COLUMNS],
        };
        window_logits(model, &win, &mut gpt, logits)?;
        let mut off = 0;
        for (j, rows) in heads.iter().enumerate() {
            tokens[(k + 1) * TOKEN_COLUMNS + j] = argmax(&logits[off..off + rows]);
            off += rows;
        }
        progress(k + 1, sh.steps);
    }
    Ok(())
}

/// Step 5 of the module doc.
fn decode_follower(
    model: &Model<'_>,
    leader: &[f32],
    sh: &OutputShape,
    ph: &mut DecodePhase<'_>,
    out: &mut ExactOutputs<'_>,
) -> Result<(), Error> {
    let f = sh.frames_out;
    let rows = sh.token_rows;
    check_at_least(Buffer::LeaderPos3d, leader.len(), f * POSE_DIM)?;
    let column = |codes: &mut [u32], j: usize, tokens: &[u32]| {
        for (i, c) in codes.iter_mut().enumerate() {
            *c = tokens[i * TOKEN_COLUMNS + j];
        }
    };
    for (p, part) in Part::ALL.iter().enumerate() {
        let vq = &model.parts[p];
        column(&mut ph.codes[..rows], p, out.tokens);
        let w = vq.cfg.in_channels as usize;
        decode(
            vq,
            Output::Position,
            &ph.codes[..rows],
            p as u8,
            &mut ph.conv,
            &mut ph.out[..f * w],
        )?;
        scatter_part(*part, 3, &ph.out[..f * w], out.follower_pos3d);
        let r = vq.cfg.rot_channels as usize;
        decode(
            vq,
            Output::Rotation,
            &ph.codes[..rows],
            p as u8,
            &mut ph.conv,
            &mut ph.out[..f * r],
        )?;
        scatter_part(*part, 9, &ph.out[..f * r], out.follower_rotmat);
    }
    column(&mut ph.codes[..rows], 4, out.tokens);
    decode(
        &model.transl,
        Output::Position,
        &ph.codes[..rows],
        4,
        &mut ph.conv,
        &mut ph.transl[..f * 3],
    )?;
    let root0 = [leader[0], leader[1], leader[2]];
    for i in 0..f {
        let pose = &mut out.follower_pos3d[i * POSE_DIM..(i + 1) * POSE_DIM];
        for a in 0..3 {
            pose[a] = (leader[i * POSE_DIM + a] - root0[a]) + ph.transl[i * 3 + a] / TRANSL_SCALE;
        }
        denormalise(pose);
        for (j, v) in pose.iter_mut().enumerate() {
            *v += root0[j % 3];
        }
    }
    Ok(())
}
