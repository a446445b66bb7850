//! Streaming ("truncated-prefix") form of one VQ-VAE conv stack
//! (docs/STREAMING.md §3.2 encoder, §3.7 decoders; `StreamConv` in
//! tools/reference/streaming.py is the executable spec).
//!
//! A stack is a chain of *units*: every `Conv1d`, every whole residual
//! block `x + conv1x1(relu(conv_dil(relu(x))))` and every
//! `ConvTranspose1d`. Input columns arrive a few at a time (encoder: `hop`
//! frames per push; decoder: one dequantised code per push). After any
//! push, output column `t` of the stack equals column `t` of the original
//! stack run on everything pushed so far, with its own zero padding at the
//! end of that prefix (what `vq_encoder::encode_features` /
//! `vq_decoder::decode` compute on the prefix).
//!
//! A column is *settled* once no longer prefix can change it (it reads no
//! end padding). Each unit keeps a ring of its settled input columns; a
//! push computes the newly settled outputs of every unit (one batched conv
//! per unit) and appends them to the next unit's ring (the last unit's to
//! the output ring). Unsettled columns (the *tail*) are computed only when
//! [`StreamStack::output`] asks for one: the cone of the requested columns,
//! unit by unit, from ring + tail of the unit below, zeros past the end.
//! At a lag of [`future_max`] or more no tail is ever computed.
//!
//! Several stacks of one geometry (the same stack of several sessions) can
//! be pushed and read together ([`StreamStack::push_many`],
//! [`StreamStack::output_many`]): unit after unit, every stack's new
//! columns (or tail cone) are gathered one after another and computed as
//! one segmented conv (`conv1d_segs`, `conv_transpose1d_segs`), so the
//! unit's weights are read once per kernel tile for all of them. Each
//! stack's columns are bit for bit those of its own push (row-independent
//! kernels); the single-stack calls are the same code on one stack.
//!
//! Every capacity (rings, output ring, scratch) comes from an integer
//! simulation of the settled counts ([`StackPlan`]), the same code path the
//! stack runs, so an [`Arena`](crate::arena::Arena) and a
//! [`Planner`](crate::arena::Planner) get the same sizes and no read can
//! leave a ring (a read outside one is an `Err`, never a panic).
//!
//! Buffers are time-major: a column block of `n` columns of `c` channels is
//! `(n, c)`, as everywhere in the engine.
//!
//! | file | what |
//! |---|---|
//! | `geometry` | units (conv, residual block, transposed conv) and which input columns an output column reads |
//! | `plan` | settled / total columns per unit, and every capacity from their simulation ([`StackPlan`], [`ScratchNeed`], [`future_max`]) |
//! | `scratch` | [`StreamScratch`], shared by the stacks of a model |
//! | `ring` | the ring of settled columns |
//! | `unit_weights` | a unit's weights checked against its geometry |
//! | `stack` | [`StreamStack`]: push, settle, read outputs and tails |

use heapless::Vec;

use crate::arena::{ArenaError, Carve};
use crate::duolando::config::ModelConfig;
use crate::error::{Buffer, Error};
use crate::kernels::{
    conv1d, conv1d_col_len, conv1d_segs, conv_transpose1d_segs, convt_z_len, relu_inplace,
    ConvGeom, ConvSeg, Matrix,
};
use crate::limits::{MAX_DEPTH, MAX_DILATION, MAX_DOWNSAMPLE, MAX_DOWN_T, MAX_STRIDE, MAX_WIDTH};
use crate::nn::names::dilation;
use crate::nn::vq_config::VqConfig;
use crate::nn::weights::{ConvTW, ConvW, DecoderW, EncoderW, ResBlockW};

/// Most stacks one [`StreamStack::push_many`] / [`StreamStack::output_many`]
/// computes together (the sessions of a batch).
pub const MAX_STACKS: usize = 64;

/// Most units of one stack: decoder `1 + down_t * (depth + 1) + 1`.
pub const MAX_UNITS: usize = (MAX_DOWN_T * (MAX_DEPTH + 1)) as usize + 2;

/// Which conv stack of a VQ-VAE.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StackKind {
    /// `[Conv1d(k=2s, s, p=s/2) -> Resnet1D] x down_t -> Conv1d(k3, p1)`;
    /// `hop` frames (in_channels) in per push, one feature (emb_width) out.
    Encoder,
    /// `Conv1d(k3) -> [Resnet1D(reversed) -> ConvT(k=2s, s, p=s/2)] x down_t
    /// -> Conv1d(k3)`; one code (emb_width) in per push, `hop` frames out.
    Decoder,
}

/// The weights of one stack (the kind must match the stack's).
#[derive(Clone, Copy, Debug)]
pub enum StackW<'r, 'a> {
    Encoder(&'r EncoderW<'a>),
    Decoder(&'r DecoderW<'a>),
}

mod geometry;
mod plan;
mod ring;
mod scratch;
mod stack;
#[cfg(test)]
mod tests;
mod unit_weights;

pub use geometry::*;
pub use plan::*;
use ring::*;
pub use scratch::*;
pub use stack::*;
use unit_weights::*;
