//! VQ-VAE encoder (`Encoder` of the authors' encdec.py, one level; the
//! same module in Bailando and Duolando):
//! `[Conv1d(k=2s, s, p=s/2) -> Resnet1D] x down_t -> Conv1d(k3, p1)`,
//! then the quantiser. Time-major activations (T, C).

use crate::error::{check_len, Buffer, Error};
use crate::nn::conv_stack::{conv, resnet, ConvScratch};
use crate::nn::quantizer::quantise;
use crate::nn::weights::VqW;

/// Pre-quantisation features of `x` (T, in_channels) into `feat`
/// (T / hop, emb_width). `T` must be a positive multiple of the hop and at
/// most `s.rows`. Returns the number of tokens.
pub fn encode_features(
    vq: &VqW<'_>,
    x: &[f32],
    s: &mut ConvScratch<'_>,
    feat: &mut [f32],
) -> Result<usize, Error> {
    let c_in = vq.cfg.in_channels as usize;
    let hop = vq.cfg.hop().unwrap_or(0) as usize;
    if c_in == 0 || x.len() % c_in != 0 {
        return Err(Error::Ragged {
            buffer: Buffer::Pose,
            len: x.len(),
            row: c_in,
        });
    }
    let t = x.len() / c_in;
    if hop == 0 || t == 0 || t % hop != 0 {
        return Err(Error::TooShort {
            buffer: Buffer::Pose,
            frames: t,
            min: hop,
        });
    }
    if t > s.rows {
        return Err(Error::Length {
            buffer: Buffer::Pose,
            len: t,
            expected: s.rows,
        });
    }
    let n_tok = t / hop;
    let emb = vq.cfg.emb_width as usize;
    check_len(Buffer::Features, feat.len(), n_tok * emb)?;
    let (mut src, mut dst): (&mut [f32], &mut [f32]) = (&mut s.a[..], &mut s.b[..]);
    let mut len = t;
    for (i, (down, res)) in vq.encoder.stages.iter().enumerate() {
        let out_len = len / down.geom.stride;
        let y = &mut dst[..out_len * down.c_out];
        if i == 0 {
            conv(down, x, y, s.col);
        } else {
            conv(down, &src[..len * down.c_in], y, s.col);
        }
        resnet(res, y, out_len, s.r, s.h, s.col);
        core::mem::swap(&mut src, &mut dst);
        len = out_len;
    }
    let out = &vq.encoder.out;
    conv(out, &src[..len * out.c_in], feat, s.col);
    Ok(n_tok)
}

/// Features and codes of `x` (T, in_channels): `feat` (T/hop, emb),
/// `codes` (T/hop).
pub fn encode(
    vq: &VqW<'_>,
    x: &[f32],
    s: &mut ConvScratch<'_>,
    feat: &mut [f32],
    codes: &mut [u32],
) -> Result<(), Error> {
    let n = encode_features(vq, x, s, feat)?;
    check_len(Buffer::Codes, codes.len(), n)?;
    let emb = vq.cfg.emb_width as usize;
    quantise(&vq.codebook, feat, codes, &mut s.r[..emb], s.kk)
}
