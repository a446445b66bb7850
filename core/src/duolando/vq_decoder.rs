//! VQ-VAE decoders (`Decoder` of models/encdec.py, one level): codebook
//! rows -> `Conv1d(k3) -> [Resnet1D (reversed dilations) ->
//! ConvTranspose1d(k=2s, s, p=s/2)] x down_t -> Conv1d(k3)`.

use crate::nn::conv_stack::{conv, resnet, ConvScratch};
use crate::error::{check_len, Buffer, Error};
use crate::kernels::conv_transpose1d;
use crate::arena::{Arena, Planner};
use crate::duolando::config::ModelConfig;
use crate::limits::VqWhich;
use crate::nn::weights::{DecoderW, VqW};
use crate::duolando::model::Model;
use crate::nn::quantizer::dequantise;

/// Which decoder of a VQ-VAE to run.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Output {
    /// `decoders`: positions (in_channels per frame).
    Position,
    /// `decoders_rot`: rotations (rot_channels per frame).
    Rotation,
}

/// Decodes `codes` (N) into `out` (N * hop, channels of `which`).
/// `N * hop` must be at most `s.rows`. `stream` names the codes in errors.
pub fn decode(vq: &VqW<'_>, which: Output, codes: &[u32], stream: u8, s: &mut ConvScratch<'_>, out: &mut [f32]) -> Result<(), Error> {
    let dec: &DecoderW<'_> = match which {
        Output::Position => &vq.pos,
        Output::Rotation => vq.rot.as_ref().ok_or(Error::Length { buffer: Buffer::Output, len: 0, expected: 0 })?,
    };
    let hop = vq.cfg.hop().unwrap_or(0) as usize;
    let n = codes.len();
    let frames = n * hop;
    if n == 0 || frames > s.rows {
        return Err(Error::Length { buffer: Buffer::Codes, len: n, expected: s.rows / hop.max(1) });
    }
    check_len(Buffer::Output, out.len(), frames * dec.out.c_out)?;
    let emb = vq.cfg.emb_width as usize;
    let q = &mut s.h[..n * emb];
    dequantise(&vq.codebook, codes, stream, q)?;
    let (mut src, mut dst): (&mut [f32], &mut [f32]) = (&mut s.a[..], &mut s.b[..]);
    conv(&dec.input, q, &mut src[..n * dec.input.c_out], s.col);
    let mut len = n;
    for (res, up) in &dec.stages {
        resnet(res, src, len, s.r, s.h, s.col);
        let out_len = len * up.stride;
        conv_transpose1d(&src[..len * up.c_in], &up.w, up.b, up.kernel, up.stride, up.pad, &mut dst[..out_len * up.c_out], s.z);
        core::mem::swap(&mut src, &mut dst);
        len = out_len;
    }
    conv(&dec.out, &src[..len * dec.out.c_in], out, s.col);
    Ok(())
}

/// Scratch bytes of [`decode_codes`] for `n_codes` codes (any base address).
pub fn scratch_bytes(cfg: &ModelConfig, n_codes: usize) -> Option<usize> {
    let mut p = Planner::new();
    ConvScratch::carve(&mut p, cfg, n_codes.checked_mul(cfg.hop())?).ok()?;
    p.total_for_any_base()
}

/// One VQ-VAE decoder with byte scratch: `codes` (N) -> `out` (N * hop,
/// channels of `output`).
pub fn decode_codes(model: &Model<'_>, which: VqWhich, output: Output, codes: &[u32], scratch: &mut [u8], out: &mut [f32]) -> Result<(), Error> {
    let vq = model.vq(which);
    let stream = match which {
        VqWhich::Part(p) => p as u8,
        VqWhich::Transl => 4,
    };
    let mut a = Arena::new(scratch);
    let mut s = ConvScratch::carve(&mut a, &model.cfg, codes.len().saturating_mul(model.cfg.hop()))?;
    decode(vq, output, codes, stream, &mut s, out)
}
