//! The streaming VQ-VAE encoders (leader frames -> leader codes) and
//! decoders (follower tokens -> follower frames) of a step, for every
//! session of a batch at once: each conv unit of a stack is computed for
//! all sessions' new columns together (`StreamStack::push_many` /
//! `output_many`), so its weights are read once per batch, not once per
//! session. A single session runs the same code as a batch of one.
//! Numbers are those of each session's own stacks, bit for bit
//! (row-independent kernels; tested in tests/step_many.rs).

use heapless::Vec;

use crate::duolando::config::{Part, POSE_DIM, ROT_DIM};
use crate::duolando::model::Model;
use crate::duolando::motion::{gather_part, scatter_part};
use crate::duolando::session::batch::{
    at, conv_scratch, for_chunks, states, BatchError, StepScratch, MAX_BATCH,
};
use crate::duolando::session::state::{State, FRAME_WIDTH};
use crate::duolando::session::Session;
use crate::error::Error;
use crate::nn::quantizer::{dequantise, nearest};
use crate::nn::stream_conv::{StackW, StreamStack};
use crate::nn::weights::{DecoderW, VqW};

/// Every session holding a complete token its encoders have not seen:
/// pushes the token's `hop` frames into the 4 part encoders and, once
/// token `q + e` is in, emits leader code `q` (`Session::code`, for the
/// leader LATs).
pub(super) fn encode(
    ss: &mut [&mut Session<'_>],
    sc: &mut StepScratch<'_>,
) -> Result<(), BatchError> {
    let due = |s: &Session<'_>| s.frames / s.model.cfg.hop() > s.st.enc[0].pushed();
    for_chunks(ss, sc.dims.n, due, |ss, chunk| {
        let g = chunk[0];
        let hop = ss[g].model.cfg.hop();
        let conv = &mut conv_scratch(sc.pool, &sc.dims).map_err(at(g))?;
        // Sessions whose code `q = tokens - 1 - e` is computable after this
        // push: they push and encode in one pass over each conv unit's
        // weights (`push_output_many`); the others push only.
        let (mut ready, mut qs, mut rest) = (
            Vec::<usize, MAX_BATCH>::new(),
            Vec::<usize, MAX_BATCH>::new(),
            Vec::<usize, MAX_BATCH>::new(),
        );
        for &i in chunk {
            let s = &ss[i];
            let pushed = match (s.frames / hop).checked_sub(1 + s.cfg.enc_future as usize) {
                Some(q) => ready.push(i).is_ok() && qs.push(q).is_ok(),
                None => rest.push(i).is_ok(),
            };
            if !pushed {
                return Err((i, Error::State));
            }
        }
        let codes = push_blocks(ss, &rest, None, conv)?;
        debug_assert!(codes.is_empty());
        let codes = push_blocks(ss, &ready, Some(&qs), conv)?;
        for (j, &i) in ready.iter().enumerate() {
            let s = &mut *ss[i];
            s.codes += 1;
            s.last_code = Some(codes[j]);
            s.st.codes.push(&codes[j]).map_err(at(i))?;
        }
        Ok(())
    })
}

/// The token's `hop` leader frames in each session's `block` into its 4
/// part encoders; with `qs`, each part's code `qs[j]` of session
/// `group[j]` after the push, in the same pass (the nearest codebook row
/// to the encoder's feature column), returned per session.
fn push_blocks(
    ss: &mut [&mut Session<'_>],
    group: &[usize],
    qs: Option<&[usize]>,
    conv: &mut crate::nn::stream_conv::StreamScratch<'_>,
) -> Result<Vec<[u32; 4], MAX_BATCH>, BatchError> {
    let mut codes: Vec<[u32; 4], MAX_BATCH> = Vec::new();
    let Some(&g) = group.first() else {
        return Ok(codes);
    };
    let model = ss[g].model;
    let hop = model.cfg.hop();
    let mut sts = states(ss, group)?;
    // The pelvis channel is zeroed for encoding (R's leader input).
    for st in sts.iter_mut() {
        for f in 0..hop {
            st.block[f * POSE_DIM..f * POSE_DIM + 3].fill(0.0);
        }
        if qs.is_some() {
            codes.push([0; 4]).map_err(|_| (g, Error::State))?;
        }
    }
    for (p, part) in Part::ALL.iter().enumerate() {
        let vq = &model.parts[p];
        let w = vq.cfg.in_channels as usize;
        let emb = vq.cfg.emb_width as usize;
        let mut stacks: Vec<&mut StreamStack<'_>, MAX_BATCH> = Vec::new();
        let mut cols: Vec<&[f32], MAX_BATCH> = Vec::new();
        let mut outs: Vec<&mut [f32], MAX_BATCH> = Vec::new();
        for st in sts.iter_mut() {
            let State {
                block,
                part_in,
                enc,
                feat,
                ..
            } = &mut **st;
            gather_part(*part, &block[..hop * POSE_DIM], &mut part_in[..hop * w]);
            stacks.push(&mut enc[p]).map_err(|_| (g, Error::State))?;
            cols.push(&part_in[..hop * w])
                .map_err(|_| (g, Error::State))?;
            outs.push(&mut feat[..emb]).map_err(|_| (g, Error::State))?;
        }
        let enc = StackW::Encoder(&vq.encoder);
        match qs {
            Some(qs) => {
                StreamStack::push_output_many(&mut stacks, enc, &cols, qs, 1, conv, &mut outs)
                    .map_err(at(g))?
            }
            None => StreamStack::push_many(&mut stacks, enc, &cols, conv).map_err(at(g))?,
        }
        drop((stacks, cols, outs));
        if qs.is_some() {
            for (j, st) in sts.iter().enumerate() {
                codes[j][p] = nearest(
                    &vq.codebook,
                    &st.kk[p * st.kk_stride..(p + 1) * st.kk_stride],
                    &st.feat[..emb],
                );
            }
        }
    }
    Ok(codes)
}

/// Feeds follower token `toks[j]` of session `chunk[j]` (at most
/// `sc.dims.n` sessions, increasing indices) to its 9 decoders; once token
/// `q + d` is in, the `hop` frames of token `q` are final and wait for
/// pulling. The sessions whose frames become final with this token push it
/// and compute those frames in one pass over each conv unit's weights
/// (`StreamStack::push_output_many`); the others push only.
pub(super) fn decode(
    ss: &mut [&mut Session<'_>],
    chunk: &[usize],
    toks: &[[u32; 5]],
    sc: &mut StepScratch<'_>,
) -> Result<(), BatchError> {
    let Some(&g) = chunk.first() else {
        return Ok(());
    };
    if toks.len() != chunk.len() || chunk.len() > sc.dims.n {
        return Err((g, Error::State));
    }
    let hop = ss[g].model.cfg.hop();
    let conv = &mut conv_scratch(sc.pool, &sc.dims).map_err(at(g))?;
    // Token q = dec_fed - d becomes final with this one: frames from t = hop q.
    let (mut ready, mut ready_toks, mut ts) = (
        Vec::<usize, MAX_BATCH>::new(),
        Vec::<[u32; 5], MAX_BATCH>::new(),
        Vec::<usize, MAX_BATCH>::new(),
    );
    let (mut rest, mut rest_toks) = (
        Vec::<usize, MAX_BATCH>::new(),
        Vec::<[u32; 5], MAX_BATCH>::new(),
    );
    for (&i, t) in chunk.iter().zip(toks) {
        let s = &ss[i];
        let pushed = match s.dec_fed.checked_sub(s.cfg.dec_future as usize) {
            Some(q) => {
                ready.push(i).is_ok() && ready_toks.push(*t).is_ok() && ts.push(hop * q).is_ok()
            }
            None => rest.push(i).is_ok() && rest_toks.push(*t).is_ok(),
        };
        if !pushed {
            return Err((i, Error::State));
        }
    }
    push_tokens(ss, &rest, &rest_toks, None, conv)?;
    push_tokens(ss, &ready, &ready_toks, Some(&ts), conv)?;
    for &i in chunk {
        ss[i].dec_fed += 1;
    }
    pend_frames(ss, &ready)
}

/// Token `toks[j]` into the 9 decoders of session `group[j]`; with `ts`,
/// each decoder's frames `[ts[j], ts[j] + hop)` after the push, in the same
/// pass, scattered into the session's `frames` rows.
fn push_tokens(
    ss: &mut [&mut Session<'_>],
    group: &[usize],
    toks: &[[u32; 5]],
    ts: Option<&[usize]>,
    conv: &mut crate::nn::stream_conv::StreamScratch<'_>,
) -> Result<(), BatchError> {
    let Some(&g) = group.first() else {
        return Ok(());
    };
    let model = ss[g].model;
    let hop = model.cfg.hop();
    let mut sts = states(ss, group)?;
    if ts.is_some() {
        for st in sts.iter_mut() {
            st.frames[..hop * FRAME_WIDTH].fill(0.0);
        }
    }
    for p in 0..5 {
        let vq = vq_of(model, p);
        let emb = vq.cfg.emb_width as usize;
        for (st, t) in sts.iter_mut().zip(toks) {
            dequantise(&vq.codebook, &t[p..p + 1], p as u8, &mut st.feat[..emb]).map_err(at(g))?;
        }
        for rot in [false, true] {
            let Some((w, ch)) = decoder_of(vq, rot) else {
                continue;
            };
            let mut stacks: Vec<&mut StreamStack<'_>, MAX_BATCH> = Vec::new();
            let mut cols: Vec<&[f32], MAX_BATCH> = Vec::new();
            let mut outs: Vec<&mut [f32], MAX_BATCH> = Vec::new();
            for st in sts.iter_mut() {
                let State {
                    dec_pos,
                    dec_rot,
                    feat,
                    dec_out,
                    ..
                } = &mut **st;
                let stack = if rot {
                    dec_rot.get_mut(p).and_then(|r| r.as_mut())
                } else {
                    dec_pos.get_mut(p)
                };
                stacks
                    .push(stack.ok_or((g, Error::State))?)
                    .map_err(|_| (g, Error::State))?;
                cols.push(&feat[..emb]).map_err(|_| (g, Error::State))?;
                outs.push(&mut dec_out[..hop * ch])
                    .map_err(|_| (g, Error::State))?;
            }
            let w = StackW::Decoder(w);
            match ts {
                Some(ts) => {
                    StreamStack::push_output_many(&mut stacks, w, &cols, ts, hop, conv, &mut outs)
                        .map_err(at(g))?
                }
                None => StreamStack::push_many(&mut stacks, w, &cols, conv).map_err(at(g))?,
            }
            drop((stacks, cols, outs));
            if ts.is_some() {
                for st in sts.iter_mut() {
                    put_decoded(st, p, rot, hop, ch);
                }
            }
        }
    }
    Ok(())
}

/// Decoder `p`'s (rotation decoder's, if `rot`) `hop` frames in `dec_out`
/// (hop, ch) into their columns of the session's `frames` rows: a part's
/// positions (normalised pose) or rotations, or the translation (p = 4).
fn put_decoded(st: &mut State<'_>, p: usize, rot: bool, hop: usize, ch: usize) {
    let State {
        frames, dec_out, ..
    } = st;
    for f in 0..hop {
        let row = &mut frames[f * FRAME_WIDTH..(f + 1) * FRAME_WIDTH];
        let out = &dec_out[f * ch..(f + 1) * ch];
        match Part::ALL.get(p) {
            Some(&part) if rot => {
                scatter_part(part, 9, out, &mut row[POSE_DIM..POSE_DIM + ROT_DIM])
            }
            Some(&part) => scatter_part(part, 3, out, &mut row[..POSE_DIM]),
            None => row[POSE_DIM + ROT_DIM..POSE_DIM + ROT_DIM + 3].copy_from_slice(&out[..3]),
        }
    }
}

/// A model's VQ-VAEs in decoding order: the 4 parts, then the translation.
fn vq_of<'m, 'a>(model: &'m Model<'a>, p: usize) -> &'m VqW<'a> {
    if p < 4 {
        &model.parts[p]
    } else {
        &model.transl
    }
}

/// Decoder `rot` (rotation if true, else position) of `vq` and its output
/// channels; `None` where the VQ-VAE has no rotation decoder.
fn decoder_of<'m, 'a>(vq: &'m VqW<'a>, rot: bool) -> Option<(&'m DecoderW<'a>, usize)> {
    if rot {
        vq.rot.as_ref().map(|d| (d, vq.cfg.rot_channels as usize))
    } else {
        Some((&vq.pos, vq.cfg.in_channels as usize))
    }
}

/// The assembled frames of every session of `ready` into its pending ring.
fn pend_frames(ss: &mut [&mut Session<'_>], ready: &[usize]) -> Result<(), BatchError> {
    let Some(&g) = ready.first() else {
        return Ok(());
    };
    let hop = ss[g].model.cfg.hop();
    for &i in ready {
        let s = &mut *ss[i];
        let State {
            frames, pending, ..
        } = &mut s.st;
        for f in 0..hop {
            pending
                .push(&frames[f * FRAME_WIDTH..(f + 1) * FRAME_WIDTH])
                .map_err(at(i))?;
        }
        s.decoded += hop;
    }
    Ok(())
}

/// The `hop` frames `[ts[j], ts[j] + hop)` of session `ready[j]` from its 9
/// decoders' current prefix, assembled and pushed to its pending ring.
fn frames_of(
    ss: &mut [&mut Session<'_>],
    ready: &[usize],
    ts: &[usize],
    conv: &mut crate::nn::stream_conv::StreamScratch<'_>,
) -> Result<(), BatchError> {
    let Some(&g) = ready.first() else {
        return Ok(());
    };
    let model = ss[g].model;
    let hop = model.cfg.hop();
    {
        let mut sts = states(ss, ready)?;
        // (hop, FRAME_WIDTH) rows: normalised pose (165) | rotations (495) | translation (3).
        for st in sts.iter_mut() {
            st.frames[..hop * FRAME_WIDTH].fill(0.0);
        }
        for p in 0..5 {
            let vq = vq_of(model, p);
            for rot in [false, true] {
                let Some((w, ch)) = decoder_of(vq, rot) else {
                    continue;
                };
                decoder_frames(
                    &mut sts,
                    p,
                    rot,
                    StackW::Decoder(w),
                    ts,
                    hop,
                    hop * ch,
                    conv,
                )
                .map_err(at(ready[0]))?;
                for st in sts.iter_mut() {
                    put_decoded(st, p, rot, hop, ch);
                }
            }
        }
    }
    pend_frames(ss, ready)
}

/// A drained session ([`Session::finish`]): leader code `codes` (the
/// next) from the 4 part encoders run on every whole token pushed, with
/// the end padding there (S's truncated prefix at the sequence end).
pub(super) fn encode_end(s: &mut Session<'_>, sc: &mut StepScratch<'_>) -> Result<(), Error> {
    let model = s.model;
    let q = s.codes;
    let conv = &mut conv_scratch(sc.pool, &sc.dims)?;
    let mut code = [0u32; 4];
    for (p, c) in code.iter_mut().enumerate() {
        let vq = &model.parts[p];
        let emb = vq.cfg.emb_width as usize;
        let State {
            enc,
            feat,
            kk,
            kk_stride,
            ..
        } = &mut s.st;
        StreamStack::output_many(
            &[&enc[p]],
            StackW::Encoder(&vq.encoder),
            &[q],
            1,
            conv,
            &mut [&mut feat[..emb]],
        )?;
        *c = nearest(
            &vq.codebook,
            &kk[p * *kk_stride..(p + 1) * *kk_stride],
            &feat[..emb],
        );
    }
    s.codes += 1;
    s.last_code = Some(code);
    s.st.codes.push(&code)
}

/// A drained session whose steps are done: the frames of the next token
/// not yet decoded, from the decoders run on the whole token sequence
/// (R's decoding of its end).
pub(super) fn decode_end(
    ss: &mut [&mut Session<'_>],
    sc: &mut StepScratch<'_>,
) -> Result<(), BatchError> {
    if ss.len() != 1 {
        return Err((0, Error::State));
    }
    let hop = ss[0].model.cfg.hop();
    let t = ss[0].decoded / hop * hop;
    let conv = &mut conv_scratch(sc.pool, &sc.dims).map_err(at(0))?;
    frames_of(ss, &[0], &[t], conv)
}

/// Frames `[ts[j], ts[j] + hop)` of decoder `p` (position, or rotation if
/// `rot`) of every state into its `dec_out[..len]`.
#[allow(clippy::too_many_arguments)]
fn decoder_frames(
    sts: &mut [&mut State<'_>],
    p: usize,
    rot: bool,
    w: StackW<'_, '_>,
    ts: &[usize],
    hop: usize,
    len: usize,
    conv: &mut crate::nn::stream_conv::StreamScratch<'_>,
) -> Result<(), Error> {
    let mut stacks: Vec<&StreamStack<'_>, MAX_BATCH> = Vec::new();
    let mut outs: Vec<&mut [f32], MAX_BATCH> = Vec::new();
    for st in sts.iter_mut() {
        let State {
            dec_pos,
            dec_rot,
            dec_out,
            ..
        } = &mut **st;
        let stack = if rot {
            dec_rot
                .get(p)
                .and_then(|r| r.as_ref())
                .ok_or(Error::State)?
        } else {
            dec_pos.get(p).ok_or(Error::State)?
        };
        stacks.push(stack).map_err(|_| Error::State)?;
        outs.push(&mut dec_out[..len]).map_err(|_| Error::State)?;
    }
    StreamStack::output_many(&stacks, w, ts, hop, conv, &mut outs)
}
