//! The scratch every stack of a model shares (one stack at a time).

use super::*;

/// Working memory of every stack of a model (sized for the widest stack
/// and every lag `0..=future_max`), for up to `n` stacks computed together
/// ([`StreamStack::push_many`]); carve once per session (`n = 1`) or per
/// batch of sessions.
#[derive(Default)]
pub struct StreamScratch<'s> {
    /// (cols, c_in) input columns of one unit, gathered contiguous.
    pub(super) g: &'s mut [f32],
    /// (cols, inner) residual block inner activations.
    pub(super) h: &'s mut [f32],
    /// (cols, width) residual block 1x1 output.
    pub(super) r: &'s mut [f32],
    /// (cols, c_out) outputs of one unit: the settled batch of a push, or
    /// (ping-pong with `tb`) the tails of `output`.
    pub(super) ta: &'s mut [f32],
    /// (cols, c_out) the other tail buffer.
    pub(super) tb: &'s mut [f32],
    /// The kernel tile of one unit: `conv1d`'s im2col tile or
    /// `conv_transpose1d`'s (a unit is one or the other, so one region
    /// of the larger size serves both).
    pub(super) tile: &'s mut [f32],
}

impl<'s> StreamScratch<'s> {
    /// Scratch for `n` stacks of needs at most `need` ([`ScratchNeed::for_model`]).
    pub fn carve<A: Carve<'s>>(a: &mut A, need: ScratchNeed, n: usize) -> Result<Self, ArenaError> {
        let per = |f: usize| f.checked_mul(n).ok_or(ArenaError::Overflow);
        Ok(StreamScratch {
            g: a.f32(per(need.g)?)?,
            h: a.f32(per(need.h)?)?,
            r: a.f32(per(need.r)?)?,
            ta: a.f32(per(need.t)?)?,
            tb: a.f32(per(need.t)?)?,
            tile: a.f32(need.col.max(need.z))?,
        })
    }
}

impl<'s> StreamScratch<'s> {
    /// Scratch for one stack of any VQ-VAE of `cfg` at a time.
    pub fn for_model<A: Carve<'s>>(a: &mut A, cfg: &ModelConfig) -> Result<Self, ArenaError> {
        StreamScratch::carve(
            a,
            ScratchNeed::for_model(cfg).ok_or(ArenaError::Overflow)?,
            1,
        )
    }
}

