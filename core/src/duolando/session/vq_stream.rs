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
use crate::duolando::motion::{gather_part, scatter_part};
use crate::duolando::session::batch::{
    at, conv_scratch, for_chunks, states, BatchError, StepScratch, MAX_BATCH,
};
use crate::duolando::session::state::{State, FRAME_WIDTH};
use crate::duolando::session::Session;
use crate::error::Error;
use crate::nn::quantizer::{dequantise, nearest};
use crate::nn::stream_conv::{StackW, StreamStack};

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
        let model = ss[g].model;
        let hop = model.cfg.hop();
        let conv = &mut conv_scratch(sc.pool, &sc.dims).map_err(at(g))?;
        {
            let mut sts = states(ss, chunk)?;
            // The pelvis channel is zeroed for encoding (R's leader input).
            for st in sts.iter_mut() {
                for f in 0..hop {
                    st.block[f * POSE_DIM..f * POSE_DIM + 3].fill(0.0);
                }
            }
            for (p, part) in Part::ALL.iter().enumerate() {
                let vq = &model.parts[p];
                let w = vq.cfg.in_channels as usize;
                let mut stacks: Vec<&mut StreamStack<'_>, MAX_BATCH> = Vec::new();
                let mut cols: Vec<&[f32], MAX_BATCH> = Vec::new();
                for st in sts.iter_mut() {
                    let State {
                        block,
                        part_in,
                        enc,
                        ..
                    } = &mut **st;
                    gather_part(*part, &block[..hop * POSE_DIM], &mut part_in[..hop * w]);
                    stacks.push(&mut enc[p]).map_err(|_| (g, Error::State))?;
                    cols.push(&part_in[..hop * w])
                        .map_err(|_| (g, Error::State))?;
                }
                StreamStack::push_many(&mut stacks, StackW::Encoder(&vq.encoder), &cols, conv)
                    .map_err(at(g))?;
            }
        }
        // Sessions whose code `q = tokens - 1 - e` is now computable.
        let mut ready: Vec<usize, MAX_BATCH> = Vec::new();
        let mut qs: Vec<usize, MAX_BATCH> = Vec::new();
        for &i in chunk {
            let s = &ss[i];
            if let Some(q) = (s.frames / hop).checked_sub(1 + s.cfg.enc_future as usize) {
                ready.push(i).map_err(|_| (i, Error::State))?;
                qs.push(q).map_err(|_| (i, Error::State))?;
            }
        }
        if ready.is_empty() {
            return Ok(());
        }
        let mut codes = [[0u32; 4]; MAX_BATCH];
        {
            let mut sts = states(ss, &ready)?;
            for p in 0..4 {
                let vq = &model.parts[p];
                let emb = vq.cfg.emb_width as usize;
                let mut stacks: Vec<&StreamStack<'_>, MAX_BATCH> = Vec::new();
                let mut outs: Vec<&mut [f32], MAX_BATCH> = Vec::new();
                for st in sts.iter_mut() {
                    let State { enc, feat, .. } = &mut **st;
                    stacks.push(&enc[p]).map_err(|_| (g, Error::State))?;
                    outs.push(&mut feat[..emb]).map_err(|_| (g, Error::State))?;
                }
                StreamStack::output_many(
                    &stacks,
                    StackW::Encoder(&vq.encoder),
                    &qs,
                    1,
                    conv,
                    &mut outs,
                )
                .map_err(at(ready[0]))?;
                drop((stacks, outs));
                for (j, st) in sts.iter().enumerate() {
                    codes[j][p] = nearest(
                        &vq.codebook,
                        &st.kk[p * st.kk_stride..(p + 1) * st.kk_stride],
                        &st.feat[..emb],
                    );
                }
            }
        }
        for (j, &i) in ready.iter().enumerate() {
            let s = &mut *ss[i];
            s.codes += 1;
            s.last_code = Some(codes[j]);
            s.st.codes.push(&codes[j]).map_err(at(i))?;
        }
        Ok(())
    })
}

/// Feeds follower token `toks[j]` of session `chunk[j]` (at most
/// `sc.dims.n` sessions, increasing indices) to its 9 decoders; once token
/// `q + d` is in, the `hop` frames of token `q` are final and wait for
/// pulling.
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
    let model = ss[g].model;
    let hop = model.cfg.hop();
    let conv = &mut conv_scratch(sc.pool, &sc.dims).map_err(at(g))?;
    {
        let mut sts = states(ss, chunk)?;
        for p in 0..5 {
            let vq = if p < 4 {
                &model.parts[p]
            } else {
                &model.transl
            };
            let emb = vq.cfg.emb_width as usize;
            for (st, t) in sts.iter_mut().zip(toks) {
                dequantise(&vq.codebook, &t[p..p + 1], p as u8, &mut st.feat[..emb])
                    .map_err(at(g))?;
            }
            let mut stacks: Vec<&mut StreamStack<'_>, MAX_BATCH> = Vec::new();
            let mut rots: Vec<&mut StreamStack<'_>, MAX_BATCH> = Vec::new();
            let mut cols: Vec<&[f32], MAX_BATCH> = Vec::new();
            for st in sts.iter_mut() {
                let State {
                    dec_pos,
                    dec_rot,
                    feat,
                    ..
                } = &mut **st;
                stacks
                    .push(&mut dec_pos[p])
                    .map_err(|_| (g, Error::State))?;
                if vq.rot.is_some() {
                    let r = dec_rot
                        .get_mut(p)
                        .and_then(|r| r.as_mut())
                        .ok_or((g, Error::State))?;
                    rots.push(r).map_err(|_| (g, Error::State))?;
                }
                cols.push(&feat[..emb]).map_err(|_| (g, Error::State))?;
            }
            StreamStack::push_many(&mut stacks, StackW::Decoder(&vq.pos), &cols, conv)
                .map_err(at(g))?;
            if let Some(rot) = vq.rot.as_ref() {
                StreamStack::push_many(&mut rots, StackW::Decoder(rot), &cols, conv)
                    .map_err(at(g))?;
            }
        }
    }
    // Sessions whose token q's frames are now final, and t = hop q.
    let mut ready: Vec<usize, MAX_BATCH> = Vec::new();
    let mut ts: Vec<usize, MAX_BATCH> = Vec::new();
    for &i in chunk {
        let s = &mut *ss[i];
        s.dec_fed += 1;
        if let Some(q) = s.dec_fed.checked_sub(1 + s.cfg.dec_future as usize) {
            ready.push(i).map_err(|_| (i, Error::State))?;
            ts.push(hop * q).map_err(|_| (i, Error::State))?;
        }
    }
    frames_of(ss, &ready, &ts, conv)
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
    let mut sts = states(ss, ready)?;
    // (hop, FRAME_WIDTH) rows: normalised pose (165) | rotations (495) | translation (3).
    for st in sts.iter_mut() {
        st.frames[..hop * FRAME_WIDTH].fill(0.0);
    }
    for (p, part) in Part::ALL.iter().enumerate() {
        let vq = &model.parts[p];
        let w = vq.cfg.in_channels as usize;
        decoder_frames(
            &mut sts,
            p,
            false,
            StackW::Decoder(&vq.pos),
            ts,
            hop,
            hop * w,
            conv,
        )
        .map_err(at(ready[0]))?;
        for st in sts.iter_mut() {
            for f in 0..hop {
                scatter_part(
                    *part,
                    3,
                    &st.dec_out[f * w..(f + 1) * w],
                    &mut st.frames[f * FRAME_WIDTH..f * FRAME_WIDTH + POSE_DIM],
                );
            }
        }
        if let Some(rot) = vq.rot.as_ref() {
            let r = vq.cfg.rot_channels as usize;
            decoder_frames(
                &mut sts,
                p,
                true,
                StackW::Decoder(rot),
                ts,
                hop,
                hop * r,
                conv,
            )
            .map_err(at(ready[0]))?;
            for st in sts.iter_mut() {
                for f in 0..hop {
                    let dst = &mut st.frames
                        [f * FRAME_WIDTH + POSE_DIM..f * FRAME_WIDTH + POSE_DIM + ROT_DIM];
                    scatter_part(*part, 9, &st.dec_out[f * r..(f + 1) * r], dst);
                }
            }
        }
    }
    decoder_frames(
        &mut sts,
        4,
        false,
        StackW::Decoder(&model.transl.pos),
        ts,
        hop,
        hop * 3,
        conv,
    )
    .map_err(at(ready[0]))?;
    for (st, &i) in sts.iter_mut().zip(ready.iter()) {
        let State {
            frames,
            dec_out,
            pending,
            ..
        } = &mut **st;
        for f in 0..hop {
            let base = f * FRAME_WIDTH + POSE_DIM + ROT_DIM;
            frames[base..base + 3].copy_from_slice(&dec_out[f * 3..f * 3 + 3]);
            pending
                .push(&frames[f * FRAME_WIDTH..(f + 1) * FRAME_WIDTH])
                .map_err(at(i))?;
        }
    }
    drop(sts);
    for &i in ready.iter() {
        ss[i].decoded += hop;
    }
    Ok(())
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
