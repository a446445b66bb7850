//! Duolando's VQ-VAE decoders by name (positions or rotations of a body
//! part, or the translation), with byte scratch; the decoder itself is
//! [`crate::nn::vq_decoder`].

use crate::arena::{Arena, Planner};
use crate::duolando::config::ModelConfig;
use crate::duolando::model::Model;
use crate::error::{Buffer, Error};
use crate::limits::VqWhich;
use crate::nn::conv_stack::ConvScratch;
use crate::nn::weights::{DecoderW, VqW};

/// Which decoder of a VQ-VAE to run.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Output {
    /// `decoders`: positions (in_channels per frame).
    Position,
    /// `decoders_rot`: rotations (rot_channels per frame).
    Rotation,
}

/// Decodes `codes` (N) with the decoder `which` of `vq` into `out`
/// (N * hop, channels of `which`); see [`crate::nn::vq_decoder::decode`].
pub fn decode(
    vq: &VqW<'_>,
    which: Output,
    codes: &[u32],
    stream: u8,
    s: &mut ConvScratch<'_>,
    out: &mut [f32],
) -> Result<(), Error> {
    let dec: &DecoderW<'_> = match which {
        Output::Position => &vq.pos,
        Output::Rotation => vq.rot.as_ref().ok_or(Error::Length {
            buffer: Buffer::Output,
            len: 0,
            expected: 0,
        })?,
    };
    crate::nn::vq_decoder::decode(vq, dec, codes, stream, s, out)
}

/// Scratch bytes of [`decode_codes`] for `n_codes` codes (any base address).
pub fn scratch_bytes(cfg: &ModelConfig, n_codes: usize) -> Option<usize> {
    let mut p = Planner::new();
    ConvScratch::carve(&mut p, &cfg.vqs(), n_codes.checked_mul(cfg.hop())?).ok()?;
    p.total_for_any_base()
}

/// One VQ-VAE decoder with byte scratch: `codes` (N) -> `out` (N * hop,
/// channels of `output`).
pub fn decode_codes(
    model: &Model<'_>,
    which: VqWhich,
    output: Output,
    codes: &[u32],
    scratch: &mut [u8],
    out: &mut [f32],
) -> Result<(), Error> {
    let vq = model.vq(which);
    let stream = match which {
        VqWhich::Part(p) => p as u8,
        VqWhich::Transl => 4,
    };
    let mut a = Arena::new(scratch);
    let mut s = ConvScratch::carve(
        &mut a,
        &model.cfg.vqs(),
        codes.len().saturating_mul(model.cfg.hop()),
    )?;
    decode(vq, output, codes, stream, &mut s, out)
}
