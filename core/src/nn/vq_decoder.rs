//! VQ-VAE decoder (`Decoder` of the authors' encdec.py, one level; the
//! same module in Bailando and Duolando): codebook rows -> `Conv1d(k3) ->
//! [Resnet1D (reversed dilations) -> ConvTranspose1d(k=2s, s, p=s/2)] x
//! down_t -> Conv1d(k3)`.

use crate::error::{check_len, Buffer, Error};
use crate::kernels::conv_transpose1d;
use crate::nn::conv_stack::{conv, resnet, ConvScratch};
use crate::nn::quantizer::dequantise;
use crate::nn::weights::{DecoderW, VqW};

/// Decodes `codes` (N) of `vq`'s codebook with its decoder `dec` (its
/// positions, rotations or root velocity) into `out` (N * hop, dec's
/// output channels). `N * hop` must be at most `s.rows`. `stream` names
/// the codes in errors.
pub fn decode(
    vq: &VqW<'_>,
    dec: &DecoderW<'_>,
    codes: &[u32],
    stream: u8,
    s: &mut ConvScratch<'_>,
    out: &mut [f32],
) -> Result<(), Error> {
    let hop = vq.cfg.hop().unwrap_or(0) as usize;
    let n = codes.len();
    let frames = n * hop;
    if n == 0 || frames > s.rows {
        return Err(Error::Length {
            buffer: Buffer::Codes,
            len: n,
            expected: s.rows / hop.max(1),
        });
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
        conv_transpose1d(
            &src[..len * up.c_in],
            &up.w,
            up.b,
            up.kernel,
            up.stride,
            up.pad,
            &mut dst[..out_len * up.c_out],
            s.z,
        );
        core::mem::swap(&mut src, &mut dst);
        len = out_len;
    }
    conv(&dec.out, &src[..len * dec.out.c_in], out, s.col);
    Ok(())
}
