//! duolando-core: `#![no_std]`, no-alloc inference for the Duolando
//! dance-accompaniment model. Every buffer lives in caller-provided memory.
//!
//! Data flow (R mode, see docs/ARCHITECTURE.md): [`motion`] normalisation
//! -> [`vq_encoder`] + [`quantizer`] (leader tokens) -> per step
//! [`gpt`] ([`lat`] + [`coordinated_attention`] over [`block`]s) ->
//! [`sampler`] -> [`vq_decoder`] -> [`motion`] de-normalisation;
//! orchestrated by [`exact`]. Weights: [`model`] (bound from a `.duo`
//! file, names from [`schema`]). Memory: [`arena`]. Math: [`kernels`].
#![cfg_attr(not(test), no_std)]
// Unsafe code is denied everywhere except `kernels::simd` (intrinsics) and
// `kernels::parallel` (split-GEMM output views), which allow it with a
// SAFETY comment on every block.
#![deny(unsafe_code)]

pub mod arena;
pub mod block;
pub mod config;
pub mod conv_stack;
pub mod coordinated_attention;
pub mod error;
pub mod exact;
pub mod format;
pub mod gpt;
pub mod input;
pub mod kernels;
pub mod lat;
pub mod limits;
pub mod model;
pub mod motion;
pub mod presets;
pub mod quantizer;
pub mod sampler;
pub mod schema;
pub mod session;
pub mod stream_conv;
pub mod tensor;
pub mod vq_decoder;
pub mod vq_encoder;

pub use error::Error;
pub use model::Model;

#[cfg(test)]
mod tests;
