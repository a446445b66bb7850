//! duolando-core: `#![no_std]`, no-alloc inference for the Duolando
//! dance-accompaniment model. Every buffer lives in caller-provided memory.
#![cfg_attr(not(test), no_std)]
#![forbid(unsafe_code)]

pub mod arena;
pub mod config;
pub mod kernels;
pub mod format;
pub mod limits;
pub mod presets;
pub mod schema;
pub mod tensor;

#[cfg(test)]
mod tests;
