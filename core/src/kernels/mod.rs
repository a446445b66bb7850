//! Scalar compute kernels. Every kernel takes flat row-major slices with
//! explicit shapes and never allocates; sizes are checked by the callers
//! (the modules named after the paper), which own the buffer plans.
//!
//! Weight-side generic: every kernel that reads a weight matrix is written
//! once against [`RowMatrix`] ("a weight row dotted with / added to f32
//! activations") and dispatched once per call through [`Matrix`], so f16 and
//! int8 weights are a new `RowMatrix` impl plus one enum arm, not new
//! kernels. The innermost dot products are ISA-dispatched in [`simd`]
//! (scalar reference twins + AVX2 / NEON variants, each tested against
//! its twin).

pub mod activation;
pub mod attention;
pub mod attention_gemm;
pub mod conv;
pub mod kv_rows;
pub mod linear;
pub mod matmul;
pub mod norm;
pub mod parallel;
pub mod simd;
pub mod weights;

pub use activation::{gelu_inplace, relu_inplace, relu_into};
pub use attention::{
    attention, attention_ahead, BandMask, GemmMask, Mask, TiledCausalMask, Ungrouped,
};
pub use attention_gemm::{attention_band, attention_staircase, gemm_attention_work};
pub use conv::{
    conv1d, conv1d_col_len, conv1d_segs, conv_transpose1d, conv_transpose1d_segs, convt_z_len,
    ConvGeom, ConvSeg, ConvTWeight, CONV_TILE,
};
pub use kv_rows::{KvRows, RowData};
pub use linear::{
    linear, linear_each, linear_each_with, linear_gelu_with, linear_with, linear_xw, Q8Room,
};
pub use matmul::matmul;
pub use norm::{layernorm, LN_EPS};
pub use weights::{
    dot, expand_q4, DenseElem, DenseRows, ExpandsToQ8, F16Rows, F32Rows, Matrix, Q4Rows, Q8Rows,
    RowMatrix, X8Rows, Q4_BLOCK_BYTES, Q8X8_ROWS,
};
