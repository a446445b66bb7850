//! Duolando's VQ-VAE encoders by name (a body part or the translation),
//! with byte scratch; the encoder itself is [`crate::nn::vq_encoder`].

use crate::arena::{Arena, Planner};
use crate::duolando::config::ModelConfig;
use crate::duolando::model::Model;
use crate::error::Error;
use crate::limits::VqWhich;
use crate::nn::conv_stack::ConvScratch;
pub use crate::nn::vq_encoder::{encode, encode_features};

/// Scratch bytes of [`encode_part`] over `frames` frames (any base address).
pub fn scratch_bytes(cfg: &ModelConfig, frames: usize) -> Option<usize> {
    let mut p = Planner::new();
    ConvScratch::carve(&mut p, &cfg.vqs(), frames).ok()?;
    p.total_for_any_base()
}

/// One VQ-VAE encoder + quantiser with byte scratch: `x` (T, in_channels)
/// as given (the pipeline's first-joint zeroing is NOT applied here; see
/// [`crate::duolando::motion::gather_part`]) -> `feat` (T/hop, emb), `codes` (T/hop).
pub fn encode_part(
    model: &Model<'_>,
    which: VqWhich,
    x: &[f32],
    scratch: &mut [u8],
    feat: &mut [f32],
    codes: &mut [u32],
) -> Result<(), Error> {
    let vq = model.vq(which);
    let frames = x.len() / (vq.cfg.in_channels as usize).max(1);
    let mut a = Arena::new(scratch);
    let mut s = ConvScratch::carve(&mut a, &model.cfg.vqs(), frames)?;
    encode(vq, x, &mut s, feat, codes)
}
