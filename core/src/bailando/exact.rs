//! R mode: the authors' `AC.eval()` (actor_critic.py, greedy), token for
//! token. Facts and the numbered algorithm: tools/reference/bailando/README.md.
//!
//! Two paths, as in the authors' code:
//! - AIST++ (test set): the seed is code 0 of each half of the input dance
//!   ([`seed_from_dance`]); the music gets ONE copy of its last row.
//! - Demo (music only): the seed is given (the authors hard-code
//!   (423, 12)); the music gets `(R / 8 + 1) * 8 - R` copies of its last
//!   row (1..=8), so the dance runs up to 8 tokens past the music.
//!
//! Both: K = padded rows - 1 steps; step k sees the window of the last
//! `c = min(k + 1, block_size - 1)` tokens with the music rows
//! `lo + 1 ..= k + 1` in the same slots (no look-ahead), positions from 0
//! in every window; then every token is decoded ([`decode`]): the up and
//! down halves and the root velocity, integrated from 0.

use crate::arena::{Arena, ArenaError, Carve, Planner};
use crate::bailando::config::{BailandoConfig, DOWN_JOINTS, POSE_DIM, UP_JOINTS};
use crate::bailando::gpt::{logits_len, max_context, window_logits, GptScratch};
use crate::bailando::model::Model;
use crate::error::{check_len, Buffer, Error};
use crate::input;
use crate::nn::conv_stack::ConvScratch;
use crate::nn::sampler::argmax;
use crate::nn::{vq_decoder, vq_encoder};

/// The loader pads dances (and the demo's music) to whole multiples of
/// this many rows, always adding at least one (`move` in the configs).
pub const MOVE: usize = 8;

/// Which of the authors' eval paths.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MusicPadding {
    /// AIST++ test path: one copy of the last row.
    Aist,
    /// Demo path: `(R / MOVE + 1) * MOVE - R` copies.
    Demo,
}

/// Music rows after the loader's padding (`rows` >= 1).
pub fn padded_rows(padding: MusicPadding, rows: usize) -> usize {
    match padding {
        MusicPadding::Aist => rows + 1,
        MusicPadding::Demo => (rows / MOVE + 1) * MOVE,
    }
}

/// Sampling steps K for `rows` music rows: tokens out = K + 1 (the seed first).
pub fn steps(padding: MusicPadding, rows: usize) -> usize {
    padded_rows(padding, rows) - 1
}

/// Working memory of [`sample`].
struct SampleScratch<'s> {
    gpt: GptScratch<'s>,
    /// (block_size - 1, n_music): the window's music rows.
    music: &'s mut [f32],
    /// (vocab_up + vocab_down).
    logits: &'s mut [f32],
    /// (block_size - 1, 2): the window's tokens.
    toks: &'s mut [u32],
}

fn sample_scratch<'s, A: Carve<'s>>(
    a: &mut A,
    cfg: &BailandoConfig,
) -> Result<SampleScratch<'s>, ArenaError> {
    let mc = max_context(cfg);
    Ok(SampleScratch {
        gpt: GptScratch::carve(a, cfg, mc)?,
        music: a.f32(mc * cfg.gpt.n_music as usize)?,
        logits: a.f32(logits_len(cfg))?,
        toks: a.u32(2 * mc)?,
    })
}

/// Scratch bytes of [`sample`] (any base address).
pub fn sample_scratch_bytes(cfg: &BailandoConfig) -> Option<usize> {
    let mut p = Planner::new();
    sample_scratch(&mut p, cfg).ok()?;
    p.total_for_any_base()
}

/// The greedy actor: `music` (R, width) rows of which the first `n_music`
/// columns are read (the authors cut wider arrays the same way), padded
/// as `padding` says; `tokens` ((K + 1) * 2, K = [`steps`]) receives the
/// seed then one (up, down) pair per step.
pub fn sample(
    model: &Model<'_>,
    music: &[f32],
    width: usize,
    padding: MusicPadding,
    seed: [u32; 2],
    scratch: &mut [u8],
    tokens: &mut [u32],
) -> Result<(), Error> {
    let cfg = &model.cfg;
    let nm = cfg.gpt.n_music as usize;
    if width < nm || music.is_empty() || !music.len().is_multiple_of(width) {
        return Err(Error::Ragged {
            buffer: Buffer::Music,
            len: music.len(),
            row: width.max(nm),
        });
    }
    input::check(Buffer::Music, music)?;
    let rows = music.len() / width;
    let k_steps = steps(padding, rows);
    check_len(Buffer::Tokens, tokens.len(), (k_steps + 1) * 2)?;
    for (j, &v) in seed.iter().enumerate() {
        if v >= cfg.gpt.vocab[j] {
            return Err(Error::Token {
                stream: j as u8,
                token: v,
                vocab: cfg.gpt.vocab[j],
            });
        }
    }
    let mut a = Arena::new(scratch);
    let SampleScratch {
        gpt: mut gs,
        music: win_music,
        logits,
        toks: win_toks,
    } = sample_scratch(&mut a, cfg)?;
    let bs1 = max_context(cfg);
    let vu = cfg.gpt.vocab[0] as usize;
    tokens[..2].copy_from_slice(&seed);
    for k in 0..k_steps {
        let c = (k + 1).min(bs1);
        let lo = k + 1 - c;
        win_toks[..2 * c].copy_from_slice(&tokens[2 * lo..2 * (k + 1)]);
        for p in 0..c {
            // Padded row i is row min(i, R - 1): the padding copies the last row.
            let r = (lo + 1 + p).min(rows - 1);
            win_music[p * nm..(p + 1) * nm].copy_from_slice(&music[r * width..r * width + nm]);
        }
        window_logits(
            model,
            &win_toks[..2 * c],
            &win_music[..c * nm],
            &mut gs,
            logits,
        )?;
        tokens[2 * (k + 1)] = argmax(&logits[..vu]);
        tokens[2 * (k + 1) + 1] = argmax(&logits[vu..]);
    }
    Ok(())
}

/// Dance frames after the loader's padding (`frames` >= 1).
pub fn padded_frames(frames: usize) -> usize {
    (frames / MOVE + 1) * MOVE
}

/// Working memory of [`seed_from_dance`] for a dance padded to `T'` frames.
struct DanceScratch<'s> {
    conv: ConvScratch<'s>,
    /// (T', 45): one half's encoder input (the up half is the wider).
    part: &'s mut [f32],
    /// (T', emb_width): encoder features (T'/hop rows used).
    feat: &'s mut [f32],
    /// (T'): codes (T'/hop used).
    codes: &'s mut [u32],
}

fn dance_scratch<'s, A: Carve<'s>>(
    a: &mut A,
    cfg: &BailandoConfig,
    frames: usize,
) -> Result<DanceScratch<'s>, ArenaError> {
    let t = padded_frames(frames);
    let emb = cfg
        .parts
        .iter()
        .map(|p| p.emb_width as usize)
        .max()
        .unwrap_or(0);
    Ok(DanceScratch {
        conv: ConvScratch::carve(a, &cfg.vqs(), t)?,
        part: a.f32(
            t.checked_mul(UP_JOINTS.len() * 3)
                .ok_or(ArenaError::Overflow)?,
        )?,
        feat: a.f32(t.checked_mul(emb).ok_or(ArenaError::Overflow)?)?,
        codes: a.u32(t)?,
    })
}

/// Scratch bytes of [`seed_from_dance`] for `frames` dance frames.
pub fn dance_scratch_bytes(cfg: &BailandoConfig, frames: usize) -> Option<usize> {
    let mut p = Planner::new();
    dance_scratch(&mut p, cfg, frames).ok()?;
    p.total_for_any_base()
}

/// The AIST++ path's seed: the dance (T, 72) world joint positions made
/// pelvis-relative (the pelvis keeps its world position), padded with
/// copies of its last row to [`padded_frames`], each half encoded over the
/// whole sequence (the down half with its pelvis channels zeroed); the
/// seed is each half's first code.
pub fn seed_from_dance(
    model: &Model<'_>,
    dance: &[f32],
    scratch: &mut [u8],
) -> Result<[u32; 2], Error> {
    if dance.is_empty() || dance.len() % POSE_DIM != 0 {
        return Err(Error::Ragged {
            buffer: Buffer::Pose,
            len: dance.len(),
            row: POSE_DIM,
        });
    }
    input::check(Buffer::Pose, dance)?;
    let frames = dance.len() / POSE_DIM;
    let t = padded_frames(frames);
    let mut a = Arena::new(scratch);
    let DanceScratch {
        mut conv,
        part,
        feat,
        codes,
    } = dance_scratch(&mut a, &model.cfg, frames)?;
    let mut seed = [0u32; 2];
    for (h, joints) in [&UP_JOINTS[..], &DOWN_JOINTS[..]].into_iter().enumerate() {
        let w = joints.len() * 3;
        for f in 0..t {
            let row = &dance[f.min(frames - 1) * POSE_DIM..][..POSE_DIM];
            for (i, &j) in joints.iter().enumerate() {
                for d in 0..3 {
                    let j = j as usize;
                    // Joint 0 is the pelvis (world position; zeroed in the
                    // down half); every other joint is made pelvis-relative.
                    part[f * w + 3 * i + d] = if j == 0 { 0.0 } else { row[3 * j + d] - row[d] };
                }
            }
        }
        let vq = &model.parts[h];
        let n = t / vq.cfg.hop().unwrap_or(1).max(1) as usize;
        let emb = vq.cfg.emb_width as usize;
        vq_encoder::encode(
            vq,
            &part[..t * w],
            &mut conv,
            &mut feat[..n * emb],
            &mut codes[..n],
        )?;
        seed[h] = codes[0];
    }
    Ok(seed)
}

/// Working memory of [`decode`] for `n` tokens (N = n * hop frames).
struct DecodeScratch<'s> {
    conv: ConvScratch<'s>,
    /// (N, 45): one decoder's output (the up half is the widest).
    out: &'s mut [f32],
    /// (n): one half's codes.
    codes: &'s mut [u32],
}

fn decode_scratch<'s, A: Carve<'s>>(
    a: &mut A,
    cfg: &BailandoConfig,
    n_tokens: usize,
) -> Result<DecodeScratch<'s>, ArenaError> {
    let n = n_tokens
        .checked_mul(cfg.hop())
        .ok_or(ArenaError::Overflow)?;
    Ok(DecodeScratch {
        conv: ConvScratch::carve(a, &cfg.vqs(), n)?,
        out: a.f32(
            n.checked_mul(UP_JOINTS.len() * 3)
                .ok_or(ArenaError::Overflow)?,
        )?,
        codes: a.u32(n_tokens)?,
    })
}

/// Scratch bytes of [`decode`] for `n_tokens` tokens per half.
pub fn decode_scratch_bytes(cfg: &BailandoConfig, n_tokens: usize) -> Option<usize> {
    let mut p = Planner::new();
    decode_scratch(&mut p, cfg, n_tokens).ok()?;
    p.total_for_any_base()
}

/// Decodes `tokens` (n, 2) into `pos3d` (n * hop, 72): what the authors'
/// eval saves as `pred_position`. The down half's pelvis slot holds the
/// root velocity v (its own pelvis output is discarded); the root is
/// `r[0] = 0, r[i] = r[i-1] + v[i-1]` (float32, in order), the pelvis is
/// `r` and every other joint gets `r` added.
pub fn decode(
    model: &Model<'_>,
    tokens: &[u32],
    scratch: &mut [u8],
    pos3d: &mut [f32],
) -> Result<(), Error> {
    let cfg = &model.cfg;
    if tokens.is_empty() || tokens.len() % 2 != 0 {
        return Err(Error::Ragged {
            buffer: Buffer::Tokens,
            len: tokens.len(),
            row: 2,
        });
    }
    let n_tok = tokens.len() / 2;
    let n = n_tok * cfg.hop();
    check_len(Buffer::Output, pos3d.len(), n * POSE_DIM)?;
    let mut a = Arena::new(scratch);
    let DecodeScratch {
        mut conv,
        out,
        codes,
    } = decode_scratch(&mut a, cfg, n_tok)?;
    for (h, joints) in [&UP_JOINTS[..], &DOWN_JOINTS[..]].into_iter().enumerate() {
        for (i, c) in codes.iter_mut().enumerate() {
            *c = tokens[2 * i + h];
        }
        let vq = &model.parts[h];
        let w = joints.len() * 3;
        vq_decoder::decode(vq, &vq.pos, codes, h as u8, &mut conv, &mut out[..n * w])?;
        for f in 0..n {
            for (i, &j) in joints.iter().enumerate() {
                let j = j as usize;
                pos3d[f * POSE_DIM + 3 * j..][..3].copy_from_slice(&out[f * w + 3 * i..][..3]);
            }
        }
    }
    // The root velocity replaces the down half's pelvis (joint 0) output.
    vq_decoder::decode(
        &model.parts[1],
        &model.root,
        codes,
        1,
        &mut conv,
        &mut out[..n * 3],
    )?;
    let mut r = [0.0f32; 3];
    for f in 0..n {
        if f > 0 {
            for d in 0..3 {
                r[d] += out[(f - 1) * 3 + d];
            }
        }
        let row = &mut pos3d[f * POSE_DIM..(f + 1) * POSE_DIM];
        row[..3].copy_from_slice(&r);
        for j in 1..POSE_DIM / 3 {
            for d in 0..3 {
                row[3 * j + d] += r[d];
            }
        }
    }
    Ok(())
}
