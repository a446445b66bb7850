//! x86_64 AVX2 + FMA + F16C variants of the [`super::scalar`] kernels.
//! Every function is `unsafe` only because of `#[target_feature]`: the
//! caller must have checked that the CPU supports avx2, fma and f16c
//! (the dispatchers in `super` do, via `Isa::Avx2`). All memory access goes
//! through `chunks_exact` sub-slices, so loads are in bounds by construction.
//! The AVX-512 (F/BW/VNNI) and AVX-VNNI variants live beside their AVX2
//! twins, one file per kind of operation:
//!
//! | file | what |
//! |---|---|
//! | `tiles` | dot products and TM x TN tiles (f32, f16, Q8) on AVX2; f32 / f16 tiles on AVX-512 |
//! | `quantise` | the activation quantiser (Q8 blocks and corrections) |
//! | `gemm_q8` | int8 GEMMs over row-major Q8 weights (VNNI, AVX-512BW, AVX2) |
//! | `packed` | int8 GEMMs over packed weights (`PackedQ8`: VNNI, AVX-VNNI, AVX2) and the packer |
//! | `dot_rows`, `axpy_rows` | the attention's scores (a query against key rows) and weighted value sums |
//! | `softmax` | `exp` on 8 / 16 lanes, the shifted exponential sum, scale-and-max |
//! | `elementwise` | LayerNorm rows, GELU, bias/activation epilogues, f16 conversions |
//!
//! Every file sees this module's imports and shared constants (`use
//! super::*`); the tile pair kernel is in `super::tile_pair`, AMX in
//! `super::amx`.

use super::{distinct_rows, Tile, Q8_BLOCK, Q8_BLOCK_BYTES, TM, TN};

// The tiled kernels walk the weight rows two at a time (8 f32 accumulators
// for a 4x2 sub-tile, plus two weight and one activation register).
const _: () = assert!(TN.is_multiple_of(2));

mod axpy_rows;
mod dot_rows;
mod elementwise;
mod gemm_q8;
mod packed;
mod quantise;
mod softmax;
mod tiles;

pub use axpy_rows::*;
pub use dot_rows::*;
pub use elementwise::*;
pub use gemm_q8::*;
pub use packed::*;
pub use quantise::*;
pub use softmax::*;
pub use tiles::*;
