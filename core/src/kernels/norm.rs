//! LayerNorm over the last axis.

/// `nn.LayerNorm` default epsilon.
pub const LN_EPS: f32 = 1e-5;

/// `y = (x - mean) / sqrt(var + eps) * w + b` per row of width `w.len()`;
/// biased variance, as PyTorch. `x`, `y`: (n, C).
pub fn layernorm(x: &[f32], w: &[f32], b: &[f32], y: &mut [f32]) {
    let c = w.len();
    if c == 0 {
        return;
    }
    for (xr, yr) in x.chunks_exact(c).zip(y.chunks_exact_mut(c)) {
        let mean = xr.iter().sum::<f32>() / c as f32;
        let var = xr.iter().map(|v| (v - mean) * (v - mean)).sum::<f32>() / c as f32;
        let inv = 1.0 / libm::sqrtf(var + LN_EPS);
        for i in 0..c {
            yr[i] = (xr[i] - mean) * inv * w[i] + b[i];
        }
    }
}
