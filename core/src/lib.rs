//! duolando-core: `#![no_std]`, no-alloc inference for dance-generation
//! models. Every buffer lives in caller-provided memory.
//!
//! Layout: the shared parts once ([`kernels`] math, [`nn`] building
//! blocks, [`format`] the `.duo` container, [`arena`] memory, [`input`]
//! policy, [`limits`] caps), each family in its own folder named after its
//! paper's concepts ([`duolando`], [`bailando`], [`transflower`]).
#![cfg_attr(not(test), no_std)]
// Unsafe code is denied everywhere except `kernels::simd` (intrinsics) and
// `kernels::parallel` (split-GEMM output views), which allow it with a
// SAFETY comment on every block.
#![deny(unsafe_code)]

pub mod arena;
pub mod bailando;
pub mod duolando;
pub mod error;
pub mod family;
pub mod format;
pub mod input;
pub mod kernels;
pub mod limits;
pub mod nn;
pub mod tensor;
pub mod transflower;

pub use duolando::model::Model;
pub use error::Error;

#[cfg(test)]
mod tests;
