//! LayerNorm over the last axis.

use super::simd;

/// `nn.LayerNorm` default epsilon.
pub const LN_EPS: f32 = 1e-5;

/// `y = (x - mean) / sqrt(var + eps) * w + b` per row of width `w.len()`;
/// biased variance, as PyTorch. `x`, `y`: (n, C). Each row by
/// [`simd::layernorm_row`] (8 lane sums; SIMD variants bit-identical to
/// the scalar twin).
pub fn layernorm(x: &[f32], w: &[f32], b: &[f32], y: &mut [f32]) {
    let c = w.len();
    if c == 0 {
        return;
    }
    for (xr, yr) in x.chunks_exact(c).zip(y.chunks_exact_mut(c)) {
        simd::layernorm_row(xr, w, b, LN_EPS, yr);
    }
}
